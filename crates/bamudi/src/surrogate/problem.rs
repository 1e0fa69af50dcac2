//! The problem every step of Modules 2-3 reads.

use super::{check_data, input_box, seed_index, training};
use crate::data::Experiments;
use crate::error::{BamudiError, Result};
use crate::observe::Observer;
use crate::params::CalibrationConfig;
use mlmodel::{LinearObservableModel, MultiLevelModel, QuadratureRule, UnobservableModel};
use numerics::random::derive_seed;
use training::LinearParts;

/// What every step of Modules 2-3 reads: the model, the data, the checked configuration, the
/// observer, and what is derived from them once (`A`, `L`, `B`; the `θ` rule; the input box).
pub struct Problem<'a, U, O> {
    /// The multi-level model.
    pub model: &'a MultiLevelModel<U, O>,
    /// The experiments.
    pub exps: &'a Experiments,
    /// The checked configuration.
    pub cfg: &'a CalibrationConfig,
    /// `A`, `L`, `B = A L`.
    pub parts: LinearParts,
    /// Nodes and weights marginalising `θ` (Eq. 25, 27, 31).
    pub theta_rule: QuadratureRule,
    /// The box the training inputs are drawn in.
    pub x_bounds: Vec<(f64, f64)>,
    /// Receives progress.
    pub observer: &'a dyn Observer,
}

impl<'a, U: UnobservableModel, O: LinearObservableModel> Problem<'a, U, O> {
    /// Checks that the data fit the model and derives the fixed parts.
    pub fn new(
        model: &'a MultiLevelModel<U, O>,
        exps: &'a Experiments,
        cfg: &'a CalibrationConfig,
        observer: &'a dyn Observer,
    ) -> Result<Self> {
        check_data(model, exps)?;
        if !model.tolerances.is_empty() && cfg.coefficients.marginal_prior().is_none() {
            return Err(BamudiError::InvalidConfig {
                name: "coefficients",
                reason: format!(
                    "the model declares {} observable tolerance(s), which only the marginal mode \
                     integrates; use coefficients = \"marginal\" or declare none",
                    model.tolerances.len()
                ),
            });
        }
        let theta_rule = training::theta_rule(
            model.prior.as_ref(),
            &cfg.marginalisation,
            derive_seed(cfg.seed, seed_index::THETA_RULE),
        )?;
        Ok(Self {
            model,
            exps,
            cfg,
            parts: LinearParts::new(model)?,
            theta_rule,
            x_bounds: input_box(cfg, exps),
            observer,
        })
    }

    /// The `i`-th experiment's inputs.
    pub(crate) fn x_row(&self, i: usize) -> Vec<f64> {
        self.exps.x.row(i).iter().copied().collect()
    }
}
