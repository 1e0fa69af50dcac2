//! Forward stepwise least squares for the data-driven term: a path of candidates, each step
//! adding the candidate that most lowers the fit term of BIC, `Σ_g n ln(SSE_g / n)`; stopped
//! by BIC, or cut at the length that blocked cross-validation in time prefers.

use super::generic::Candidate;
use crate::effect::FitContext;
use crate::stats::ols;
use nalgebra::DMatrix;

/// Contiguous blocks of the calibration rows for the cross-validated length (time order kept:
/// a random split of autocorrelated rows would leak).
const FOLDS: usize = 5;

/// The design `[1, z_chosen]` at `rows`.
fn design(cands: &[Candidate], rows: &[usize], chosen: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), chosen.len() + 1, |i, j| match j {
        0 => 1.0,
        _ => cands[chosen[j - 1]].z(rows[i]),
    })
}

/// The fit term of BIC of the least-squares fit of `r` at `rows` on a constant and `chosen`.
fn log_fit(cands: &[Candidate], r: &DMatrix<f64>, rows: &[usize], chosen: &[usize]) -> f64 {
    let x = design(cands, rows, chosen);
    let y = r.select_rows(rows.iter());
    let res = &y - &x * ols(&x, &y);
    let n = rows.len() as f64;
    (0..res.ncols())
        .map(|j| n * (res.column(j).norm_squared() / n).max(1e-300).ln())
        .sum()
}

/// The forward path fitted at `rows`, at most `max` long: the candidates in order of entry,
/// with the fit term before any (`fits[0]`) and after each (`fits[k]`).
fn path(
    cands: &[Candidate],
    r: &DMatrix<f64>,
    rows: &[usize],
    max: usize,
) -> (Vec<usize>, Vec<f64>) {
    let mut chosen: Vec<usize> = vec![];
    let mut fits = vec![log_fit(cands, r, rows, &chosen)];
    while chosen.len() < max.min(cands.len()) {
        let mut step: Option<(f64, usize)> = None;
        for c in (0..cands.len()).filter(|c| !chosen.contains(c)) {
            let mut trial = chosen.clone();
            trial.push(c);
            let v = log_fit(cands, r, rows, &trial);
            if step.is_none_or(|s| v < s.0) {
                step = Some((v, c));
            }
        }
        let Some((v, c)) = step else { break };
        chosen.push(c);
        fits.push(v);
    }
    (chosen, fits)
}

/// The path on the calibration rows, stopped at the first step that does not lower BIC
/// (`None`: not even the first).
pub(super) fn select_bic(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    cands: &[Candidate],
    max: usize,
) -> Option<Vec<usize>> {
    let (chosen, fits) = path(cands, r, ctx.cal, max);
    let penalty = r.ncols() as f64 * (ctx.cal.len() as f64).ln();
    let bic = |k: usize| fits[k] + (k + 1) as f64 * penalty;
    let len = (0..chosen.len())
        .find(|&k| bic(k + 1) >= bic(k))
        .unwrap_or(chosen.len());
    (len > 0).then(|| chosen[..len].to_vec())
}

/// The path on the calibration rows cut at the length with the least held-out squared error
/// over [`FOLDS`] contiguous blocks, the path rebuilt without each block (`None`: length 0,
/// the intercept alone, predicts best).
pub(super) fn select_cv(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    cands: &[Candidate],
    max: usize,
) -> Option<Vec<usize>> {
    let mut err = vec![0.0; max.min(cands.len()) + 1];
    for (train, test) in folds(ctx.cal) {
        let (chosen, _) = path(cands, r, &train, max);
        for (len, e) in err.iter_mut().enumerate() {
            let prefix = &chosen[..len.min(chosen.len())];
            *e += held_out_sse(cands, r, &train, &test, prefix);
        }
    }
    let best = (0..err.len())
        .min_by(|&a, &b| err[a].total_cmp(&err[b]))
        .unwrap_or(0);
    let (chosen, _) = path(cands, r, ctx.cal, best);
    (best > 0 && !chosen.is_empty()).then_some(chosen)
}

/// The [`FOLDS`] blocked folds of `rows` (in time order): (training rows, held-out block).
pub(super) fn folds(rows: &[usize]) -> Vec<(Vec<usize>, Vec<usize>)> {
    let n = rows.len();
    (0..FOLDS)
        .map(|k| {
            let (lo, hi) = (k * n / FOLDS, (k + 1) * n / FOLDS);
            let train = rows[..lo].iter().chain(&rows[hi..]).copied().collect();
            (train, rows[lo..hi].to_vec())
        })
        .collect()
}

/// Squared error at `test` of the least-squares fit at `train` on a constant and `chosen`.
pub(super) fn held_out_sse(
    cands: &[Candidate],
    r: &DMatrix<f64>,
    train: &[usize],
    test: &[usize],
    chosen: &[usize],
) -> f64 {
    let coef = ols(&design(cands, train, chosen), &r.select_rows(train.iter()));
    (r.select_rows(test.iter()) - design(cands, test, chosen) * coef).norm_squared()
}
