//! Covariate selection for the data-driven term by the multi-task lasso (`linfa-elasticnet`):
//! one group penalty per covariate across all gauges, so a covariate enters for every gauge or
//! for none, with the penalty chosen by blocked cross-validation in time.
//!
//! Each lasso is fitted on its rows' sufficient statistics instead of the rows themselves: with
//! the centred design `X = Q R` (thin QR), `‖Y − X W‖² = ‖Qᵀ Y − R W‖² + ‖(I − Q Qᵀ) Y‖²`, so
//! the `p x p` problem `(R, Qᵀ Y)` has the same minimiser once the penalty is rescaled for
//! linfa's `1 / (2 n)` loss (`λ' = λ n / p`). Coordinate descent then costs `p` instead of `n`
//! per column visit; the rows enter once, through the QR. That makes the honest
//! cross-validation affordable: the path is re-fitted on every fold's training rows.

use super::generic::Candidate;
use super::stepwise::{folds, held_out_sse};
use crate::effect::FitContext;
use linfa::prelude::*;
use linfa_elasticnet::MultiTaskElasticNet;
use nalgebra::DMatrix;
use ndarray::Array2;

/// Penalties on the path: `λ_max` (no covariate enters) down to `1e-3 λ_max`, log spaced.
const PATH: usize = 12;

/// One lasso problem reduced to its sufficient statistics: `r` (`m x p`, `m = min(n, p)`),
/// `qty` (`m x gauges`), and the row count `n` it stands for.
struct Reduced {
    r: Array2<f64>,
    qty: Array2<f64>,
    n: usize,
}

impl Reduced {
    /// The centred standardised candidates and residual at `rows`, reduced by a thin QR.
    fn new(cands: &[Candidate], res: &DMatrix<f64>, rows: &[usize]) -> Self {
        let x = centred(DMatrix::from_fn(rows.len(), cands.len(), |i, j| {
            cands[j].z(rows[i])
        }));
        let y = centred(res.select_rows(rows.iter()));
        let qr = x.qr();
        let (q, r) = (qr.q(), qr.r());
        let qty = q.transpose() * y;
        let to_nd = |m: &DMatrix<f64>| Array2::from_shape_fn(m.shape(), |(i, j)| m[(i, j)]);
        Self {
            r: to_nd(&r),
            qty: to_nd(&qty),
            n: rows.len(),
        }
    }

    /// The smallest penalty at which no covariate enters: `max_j ‖X_jᵀ Y‖₂ / n`
    /// (`X_jᵀ Y = R_jᵀ Qᵀ Y`).
    fn lambda_max(&self) -> f64 {
        let xty = self.r.t().dot(&self.qty);
        xty.rows()
            .into_iter()
            .map(|row| row.dot(&row).sqrt() / self.n as f64)
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE)
    }

    /// The penalties of the path, from [`Self::lambda_max`] down.
    fn path(&self) -> Vec<f64> {
        let top = self.lambda_max();
        (0..PATH)
            .map(|k| top * 10f64.powf(-3.0 * k as f64 / (PATH - 1) as f64))
            .collect()
    }

    /// The coefficient groups (candidates x gauges) of the lasso at penalty `lambda` (the
    /// penalty of the problem on all `n` rows), to linfa's duality-gap tolerance `tol`
    /// (relative to `‖Qᵀ Y‖²`) or `max_iter` sweeps; `None` when linfa refuses the problem.
    fn fit(&self, lambda: f64, tol: f64, max_iter: u32) -> Option<Array2<f64>> {
        let m = self.r.nrows().max(1);
        let data = Dataset::new(self.r.clone(), self.qty.clone());
        MultiTaskElasticNet::<f64>::lasso()
            .penalty(lambda * self.n as f64 / m as f64)
            .with_intercept(false)
            .max_iterations(max_iter)
            .tolerance(tol)
            .fit(&data)
            .ok()
            .map(|fit| fit.hyperplane().to_owned())
    }

    /// The candidates with a non-zero coefficient group at `lambda`, largest first, at most
    /// `max`; and how many groups were non-zero.
    fn selected(&self, lambda: f64, max: usize) -> (Vec<usize>, usize) {
        // the support, not the coefficients, is what selection uses: a loose gap suffices
        let Some(w) = self.fit(lambda, 1e-6, 2000) else {
            return (Vec::new(), 0);
        };
        let mut groups: Vec<(f64, usize)> = w
            .rows()
            .into_iter()
            .enumerate()
            .map(|(j, row)| (row.dot(&row).sqrt(), j))
            .filter(|(norm, _)| *norm > 1e-12)
            .collect();
        let n = groups.len();
        groups.sort_by(|a, b| b.0.total_cmp(&a.0));
        (groups.into_iter().take(max).map(|(_, j)| j).collect(), n)
    }

    /// The path's penalties down to the first whose support has more than `max` groups (the
    /// term keeps `max`, so smaller penalties only add slower, near-least-squares fits), with
    /// the selection at each.
    fn path_to(&self, max: usize) -> Vec<(f64, Vec<usize>)> {
        let mut out = vec![];
        for lambda in self.path() {
            let (chosen, n) = self.selected(lambda, max);
            out.push((lambda, chosen));
            if n > max {
                break;
            }
        }
        out
    }
}

/// `m` with each column's mean removed (the lasso's intercept, left unpenalised).
fn centred(mut m: DMatrix<f64>) -> DMatrix<f64> {
    for mut col in m.column_iter_mut() {
        let mean = col.mean();
        col.add_scalar_mut(-mean);
    }
    m
}

/// The candidates (positions in `cands`) the cross-validated group lasso selects, at most
/// `max` (the largest coefficient groups); `None` when no penalty beats the intercept alone.
///
/// The penalty is the path point whose least-squares refit on the selected candidates has the
/// least squared error over blocked folds in time, the selection re-fitted without each fold
/// (a selection made on all rows would have seen every fold it is scored on).
pub(super) fn select(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    cands: &[Candidate],
    max: usize,
) -> Option<Vec<usize>> {
    if cands.is_empty() || max == 0 {
        return None;
    }
    let path = Reduced::new(cands, r, ctx.cal).path_to(max);
    let mut errors = vec![0.0; path.len()];
    let mut none = 0.0;
    for (train, test) in &folds(ctx.cal) {
        let fold = Reduced::new(cands, r, train);
        none += held_out_sse(cands, r, train, test, &[]);
        for (k, (lambda, _)) in path.iter().enumerate() {
            errors[k] += held_out_sse(cands, r, train, test, &fold.selected(*lambda, max).0);
        }
    }
    let (best, err) = errors
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    if *err >= none {
        return None;
    }
    let chosen = path[best].1.clone();
    (!chosen.is_empty()).then_some(chosen)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reduced problem has the full problem's minimiser: the same linfa lasso fitted on the
    /// centred rows and on `(R, Qᵀ Y)` with the rescaled penalty gives the same coefficients.
    #[test]
    fn reduced_lasso_equals_the_lasso_on_all_rows() {
        let (n, p, k) = (300, 6, 3);
        // deterministic, correlated columns and a sparse truth (columns 1 and 4)
        let x = centred(DMatrix::from_fn(n, p, |i, j| {
            let t = i as f64;
            (0.37 * t * (j + 1) as f64).sin() + 0.5 * (0.11 * t).cos() + 0.01 * j as f64
        }));
        let y = centred(DMatrix::from_fn(n, k, |i, g| {
            2.0 * x[(i, 1)] - (g as f64 + 1.0) * x[(i, 4)]
                + 0.3 * ((i * 7919 % 97) as f64 / 97.0 - 0.5)
        }));
        let to_nd = |m: &DMatrix<f64>| Array2::from_shape_fn(m.shape(), |(i, j)| m[(i, j)]);
        let qr = x.clone().qr();
        let reduced = Reduced {
            r: to_nd(&qr.r()),
            qty: to_nd(&(qr.q().transpose() * &y)),
            n,
        };
        let lambda = 0.1 * reduced.lambda_max();
        let full = MultiTaskElasticNet::<f64>::lasso()
            .penalty(lambda)
            .with_intercept(false)
            .max_iterations(20_000)
            .tolerance(1e-12)
            .fit(&Dataset::new(to_nd(&x), to_nd(&y)))
            .unwrap();
        let w = reduced.fit(lambda, 1e-12, 20_000).unwrap();
        let diff = (&w - full.hyperplane())
            .mapv(f64::abs)
            .fold(0.0, |a: f64, b| a.max(*b));
        // both solvers stop at a duality-gap tolerance; 1e-5 on coefficients of size 1-3 is
        // far below any selection decision (groups enter at norms of 1e-2 and more here)
        assert!(diff < 1e-5, "max coefficient difference {diff}");
        // the two largest groups are the truth's two columns
        let mut sel = reduced.selected(lambda, 2).0;
        sel.sort_unstable();
        assert_eq!(sel, vec![1, 4]);
    }
}
