//! Load-path hysteresis: a different response while the load rises and while it falls.

use super::linear::{Basis, LinearTerm};
use crate::effect::{Effect, FitContext, Fitted};
use crate::error::Result;
use nalgebra::DMatrix;
use std::sync::Arc;

/// Output linear and quadratic in the load (in hundreds of its unit), with separate
/// coefficients while the load rises and while it falls (e.g. friction at a gate's quoin and
/// miter contacts while filling and emptying). Needs a declared load.
#[derive(Debug, Clone)]
pub struct LoadPathHysteresis {
    /// The load's feature name (e.g. `head`).
    pub load: String,
}

impl Effect for LoadPathHysteresis {
    fn name(&self) -> String {
        "load_path_hysteresis".into()
    }
    fn meaning(&self) -> String {
        format!(
            "load-path hysteresis: a different response while the {} rises and falls (friction \
             at contacts)",
            self.load
        )
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        if !ctx.cal.iter().any(|&i| ctx.feats.load_rate[i].abs() > 1e-9) {
            return Ok(None);
        }
        let term = LinearTerm::fit(Basis::LoadPath, ctx, r);
        let l = &self.load;
        let p = vec![
            term.parameter(0, &format!("rising_per_100_{l}"), ctx.unit),
            term.parameter(1, &format!("rising_per_100_{l}_sq"), ctx.unit),
            term.parameter(2, &format!("falling_per_100_{l}"), ctx.unit),
            term.parameter(3, &format!("falling_per_100_{l}_sq"), ctx.unit),
        ];
        let rate = format!("d_{l}_per_h");
        let cov = vec![l.clone(), rate.clone()];
        Ok(Some(Fitted::new(self, Arc::new(term), cov, p, &rate)))
    }
}
