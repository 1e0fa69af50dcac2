//! The open effect library: an [`Effect`] is a parametric term the calibrated model may lack
//! (a gauge drifting, a thermal strain, ...). The loop fits each effect of its library to the
//! residual on the rows before each evaluation origin and keeps the one that explains the most
//! cross-validated error.
//! A user adds an effect by implementing the trait; nothing in the crate changes.
//!
//! ```
//! use bamudi_closeloop::{Effect, FitContext, Fitted, LinearTerm, effects::Basis};
//! use nalgebra::DMatrix;
//! use std::sync::Arc;
//!
//! /// A gauge offset that switches on while a named covariate (e.g. `de_icing`) is above 0.5.
//! #[derive(Debug)]
//! struct SwitchedOffset(String);
//!
//! impl Effect for SwitchedOffset {
//!     fn name(&self) -> String { format!("switched_offset({})", self.0) }
//!     fn meaning(&self) -> String { "offset while a switch is on (microstrain)".into() }
//!     fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>)
//!         -> bamudi_closeloop::Result<Option<Fitted>> {
//!         let Some(col) = ctx.feats.position(&self.0) else { return Ok(None) };
//!         let on: Vec<f64> = ctx.feats.cols[col].iter().map(|v| f64::from(u8::from(*v > 0.5))).collect();
//!         let term = LinearTerm::fit(Basis::Columns(vec![on]), ctx, r);
//!         let params = vec![term.parameter(0, "offset_when_on", "microstrain")];
//!         Ok(Some(Fitted::new(self.clone(), Arc::new(term), vec![self.0.clone()], params, &self.0)))
//!     }
//! }
//! let e: Arc<dyn Effect> = Arc::new(SwitchedOffset("de_icing".into()));
//! assert_eq!(e.name(), "switched_offset(de_icing)");
//! ```

use super::CalibratedModel;
use super::features::Features;
use crate::error::Result;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Whether an effect has a physical meaning or is the data-driven fallback. A physical effect
/// is preferred unless the data-driven term beats it by the loop's margin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectKind {
    /// A named physical effect.
    Physical,
    /// A data-driven term.
    DataDriven,
}

/// A candidate missing effect.
pub trait Effect: Send + Sync + std::fmt::Debug {
    /// Machine name, unique in a library (e.g. `gauge_drift`).
    fn name(&self) -> String;
    /// Physical meaning, for the report.
    fn meaning(&self) -> String;
    /// Physical or data-driven (default: physical).
    fn kind(&self) -> EffectKind {
        EffectKind::Physical
    }
    /// Whether the loop may add the effect again after it was accepted (default: data-driven
    /// effects may, physical ones may not).
    fn repeatable(&self) -> bool {
        self.kind() == EffectKind::DataDriven
    }
    /// Whether the effect is relative to the calibrated model, so that a re-calibration
    /// must not absorb it (a parameter changing in time is: the loop then keeps the model
    /// fixed and re-fits the effect instead). Default: `false`.
    fn keeps_model_fixed(&self) -> bool {
        false
    }
    /// Fits the effect to the residual `r` (`n x N_o`) on the calibration rows of `ctx`;
    /// `None` when it does not apply (e.g. no step found, a missing column).
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>>;
}

/// How a fitted effect is evaluated at every row.
pub trait Term: Send + Sync + std::fmt::Debug {
    /// The contribution (`n x N_o`, output units) at every row of the record.
    fn contribution(&self, ctx: &FitContext<'_>) -> Result<DMatrix<f64>>;
}

/// What every fit reads.
pub struct FitContext<'a> {
    /// The record's features.
    pub feats: &'a Features,
    /// The model inputs at every row.
    pub x: &'a DMatrix<f64>,
    /// The calibration rows (the only ones a fit may use).
    pub cal: &'a [usize],
    /// The current calibrated model.
    pub model: &'a dyn CalibratedModel,
    /// Its predictive mean at every row.
    pub base_mean: &'a DMatrix<f64>,
    /// Output (gauge) names.
    pub gauges: &'a [String],
    /// The outputs' unit, for parameter reports (e.g. `microstrain`).
    pub unit: &'a str,
}

/// One named parameter block (one value per gauge, or a single value).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EffectParameter {
    /// Parameter name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Values (per gauge, in gauge order, unless the name says otherwise).
    pub values: Vec<f64>,
}

/// A fitted effect as reported in `results.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EffectReport {
    /// Effect name (see [`Effect::name`]).
    pub name: String,
    /// Physical meaning.
    pub meaning: String,
    /// Covariates the term uses.
    pub covariates: Vec<String>,
    /// Fitted parameters.
    pub parameters: Vec<EffectParameter>,
}

/// The value of the model parameter at the end of the record from an effect that moves it:
/// `(value, standard error, half-width of the 95 % interval)`.
pub type ParameterEnd = (f64, f64, f64);

/// A fitted effect.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The effect it came from (re-fitted by the back-fit).
    pub effect: Arc<dyn Effect>,
    /// Its evaluation.
    pub term: Arc<dyn Term>,
    /// Its report.
    pub report: EffectReport,
    /// Main covariate for plots.
    pub plot_covariate: String,
    /// For an effect that moves the model parameter: its value at the end of the record.
    pub parameter_end: Option<ParameterEnd>,
}

impl Fitted {
    /// A fitted effect with its report built from the effect's name and meaning.
    pub fn new(
        effect: Arc<dyn Effect>,
        term: Arc<dyn Term>,
        covariates: Vec<String>,
        parameters: Vec<EffectParameter>,
        plot_covariate: &str,
    ) -> Self {
        let report = EffectReport {
            name: effect.name(),
            meaning: effect.meaning(),
            covariates,
            parameters,
        };
        Self {
            effect,
            term,
            report,
            plot_covariate: plot_covariate.into(),
            parameter_end: None,
        }
    }
}

/// A parameter block.
pub fn param(name: &str, unit: &str, values: Vec<f64>) -> EffectParameter {
    EffectParameter {
        name: name.into(),
        unit: unit.into(),
        values,
    }
}
