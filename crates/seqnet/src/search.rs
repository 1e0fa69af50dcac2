//! Hyper-parameter choice by a train/test split, as Sec. 3.3.2 chooses layers and hidden units.

use crate::data::{check_matrix, select_rows, split_indices};
use crate::error::SeqError;
use crate::params::{CheckedLstmParams, LstmParams};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// The candidate grid and budget of [`select_hyperparameters`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchSpace {
    /// Hidden sizes to try.
    pub hidden: Vec<usize>,
    /// Layer counts to try.
    pub layers: Vec<usize>,
    /// At most this many candidates are trained (grid order: layers outer, hidden inner).
    pub max_candidates: usize,
    /// Epoch budget per candidate (overrides the base parameters' epochs).
    pub max_epochs: usize,
    /// Fraction of samples held out as the test set that scores candidates, in `(0, 1)`.
    pub test_fraction: f64,
}

impl Default for SearchSpace {
    /// Hidden sizes 16, 32, 64 and 1 or 2 layers; 6 candidates, 20 epochs, 20 % test split.
    fn default() -> Self {
        Self {
            hidden: vec![16, 32, 64],
            layers: vec![1, 2],
            max_candidates: 6,
            max_epochs: 20,
            test_fraction: 0.2,
        }
    }
}

/// One row of the search table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateScore {
    /// Hidden units per layer.
    pub hidden: usize,
    /// Number of layers.
    pub layers: usize,
    /// Test-set MSE averaged over outputs, each output's error divided by its test variance
    /// (so 1.0 means no better than predicting the mean).
    pub test_score: f64,
    /// Epochs actually trained (early stopping may end sooner).
    pub epochs_run: usize,
    /// Training wall time in seconds.
    pub seconds: f64,
}

/// The outcome of [`select_hyperparameters`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchResult {
    /// Base parameters with the winning hidden size and depth (epochs as in the base).
    pub best: CheckedLstmParams,
    /// Every candidate tried, in grid order.
    pub table: Vec<CandidateScore>,
}

/// Trains each candidate (hidden, layers) of `space` on a seeded training split of `x`, `y` and
/// scores it on the held-out test split; returns the best (lowest score, ties to the earlier and
/// therefore smaller candidate) and the table. Deterministic for a given base seed.
///
/// ```
/// use nalgebra::DMatrix;
/// let x = DMatrix::from_fn(80, 2, |r, c| ((r * 5 + c * 3) % 13) as f64);
/// let y = DMatrix::from_fn(80, 1, |r, _| x[(r, 0)] * 0.5 - x[(r, 1)]);
/// let space = seqnet::SearchSpace { hidden: vec![2, 4], layers: vec![1], max_candidates: 2,
///     max_epochs: 2, test_fraction: 0.25 };
/// let base = seqnet::LstmParams::new(2, 1).batch_size(16);
/// let res = seqnet::select_hyperparameters(&base, &space, &x, &y).unwrap();
/// assert_eq!(res.table.len(), 2);
/// ```
pub fn select_hyperparameters(
    base: &LstmParams,
    space: &SearchSpace,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
) -> Result<SearchResult, SeqError> {
    validate_space(space)?;
    let seed = base.clone().check()?.seed();
    check_matrix("x", x, None, x.ncols())?;
    check_matrix("y", y, Some(x.nrows()), y.ncols())?;
    // A different stream from fit's validation split (seed + 1), so the test rows are not reused.
    let (tr, te) = split_indices(x.nrows(), space.test_fraction, seed.wrapping_add(1))?;
    let (x_tr, y_tr) = (select_rows(x, &tr), select_rows(y, &tr));
    let (x_te, y_te) = (select_rows(x, &te), select_rows(y, &te));
    let mut table = Vec::new();
    let mut best: Option<(f64, LstmParams)> = None;
    let grid = space
        .layers
        .iter()
        .flat_map(|&l| space.hidden.iter().map(move |&h| (h, l)));
    for (hidden, layers) in grid.take(space.max_candidates) {
        let cand = base.clone().hidden(hidden).layers(layers);
        let model = cand.clone().epochs(space.max_epochs).fit(&x_tr, &y_tr)?;
        let score = relative_test_mse(&model.predict(&x_te)?, &y_te);
        let h = model.history();
        table.push(CandidateScore {
            hidden,
            layers,
            test_score: score,
            epochs_run: h.train_loss.len(),
            seconds: h.wall_seconds,
        });
        if best.as_ref().is_none_or(|(s, _)| score < *s) {
            best = Some((score, cand));
        }
    }
    let (_, best) = best.expect("at least one candidate is trained");
    Ok(SearchResult {
        best: best.check()?,
        table,
    })
}

/// Checks the grid and budget of a search.
fn validate_space(space: &SearchSpace) -> Result<(), SeqError> {
    let bad = |name: &'static str, reason: &str| SeqError::InvalidParameter {
        name,
        reason: reason.into(),
    };
    if space.hidden.is_empty() || space.layers.is_empty() || space.max_candidates == 0 {
        return Err(bad(
            "space",
            "needs at least one hidden size, one layer count and max_candidates >= 1",
        ));
    }
    if space.max_epochs == 0 {
        return Err(bad("max_epochs", "must be at least 1"));
    }
    if !(space.test_fraction > 0.0 && space.test_fraction < 1.0) {
        return Err(bad("test_fraction", "must be in (0, 1)"));
    }
    Ok(())
}

/// Test-set MSE averaged over outputs, each output's error divided by its test variance.
fn relative_test_mse(pred: &DMatrix<f64>, y_te: &DMatrix<f64>) -> f64 {
    let var: Vec<f64> = y_te
        .column_iter()
        .map(|c| {
            let m = c.mean();
            (c.iter().map(|v| (v - m).powi(2)).sum::<f64>() / c.len() as f64).max(f64::MIN_POSITIVE)
        })
        .collect();
    (0..y_te.ncols())
        .map(|c| {
            (0..y_te.nrows())
                .map(|r| (pred[(r, c)] - y_te[(r, c)]).powi(2))
                .sum::<f64>()
                / y_te.nrows() as f64
                / var[c]
        })
        .sum::<f64>()
        / y_te.ncols() as f64
}
