//! Scalar minimisation by Brent's method (argmin's `BrentOpt` driven by its executor), shared
//! by the `ρ` searches of Module 2 and the conditional coefficient mode.

use crate::error::{BamudiError, Result};
use argmin::core::{CostFunction, Executor};
use argmin::solver::brent::BrentOpt;

/// One Brent search: the bracket, the starting point, tolerances and the iteration cap.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Brent {
    /// `[lo, hi]`.
    pub bracket: (f64, f64),
    /// Starting point (clamped into the bracket).
    pub start: f64,
    /// Relative tolerance.
    pub rel_tol: f64,
    /// Absolute tolerance.
    pub abs_tol: f64,
    /// Iteration cap.
    pub max_iters: u64,
}

/// A scalar cost for argmin's Brent solver.
struct FnCost<F>(F);

impl<F: Fn(f64) -> Result<f64>> CostFunction for FnCost<F> {
    type Param = f64;
    type Output = f64;
    fn cost(&self, x: &f64) -> std::result::Result<f64, argmin::core::Error> {
        (self.0)(*x).map_err(|e| argmin::core::Error::msg(e.to_string()))
    }
}

impl Brent {
    /// Minimises `f`; returns the best point and its value. `what` names the search in errors.
    /// An empty bracket (`hi <= lo`) evaluates `f` at `lo` only.
    pub(crate) fn minimise(
        &self,
        what: &str,
        f: impl Fn(f64) -> Result<f64>,
    ) -> Result<(f64, f64)> {
        let (lo, hi) = self.bracket;
        if hi <= lo {
            return Ok((lo, f(lo)?));
        }
        let solver = BrentOpt::new(lo, hi).set_tolerance(self.rel_tol, self.abs_tol);
        let res = Executor::new(FnCost(f), solver)
            .configure(|s| s.param(self.start.clamp(lo, hi)).max_iters(self.max_iters))
            .run()
            .map_err(|e| BamudiError::Numerical {
                context: format!("Brent search: {what}"),
                reason: e.to_string(),
            })?;
        let st = res.state();
        match st.best_param {
            Some(p) => Ok((p, st.best_cost)),
            None => Err(BamudiError::Numerical {
                context: format!("Brent search: {what}"),
                reason: "no point evaluated".into(),
            }),
        }
    }
}
