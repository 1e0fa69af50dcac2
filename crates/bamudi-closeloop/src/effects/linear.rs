//! Effects that are linear in their parameters: a basis evaluated from the features times one
//! coefficient column per gauge, fitted by least squares on the calibration rows.

use crate::effect::{EffectParameter, FitContext, Term, param};
use crate::error::Result;
use crate::features::Features;
use crate::stats::{ols, select_rows};
use nalgebra::DMatrix;

/// The basis columns of a linear effect.
#[derive(Debug, Clone)]
pub enum Basis {
    /// A constant (gauge offset).
    Offset,
    /// Constant and time in days (gauge drift).
    Drift,
    /// Constant and a first-order-lagged feature (thermal strain).
    Thermal {
        /// Feature column.
        col: usize,
        /// Lag time constant (hours).
        tau_h: f64,
    },
    /// Load and load² while the load rises, and while it falls (load-path hysteresis; the load
    /// in hundreds of its unit).
    LoadPath,
    /// A constant and standardised feature columns, each possibly through a first-order lag
    /// (the data-driven term).
    Generic {
        /// Feature columns.
        cols: Vec<usize>,
        /// The lag time constant of each (hours; 0 = the column itself).
        lags_h: Vec<f64>,
        /// Their (lagged) means on the calibration rows.
        mean: Vec<f64>,
        /// Their standard deviations on the calibration rows.
        sd: Vec<f64>,
    },
    /// Given columns, one value per row (a user's own effect).
    Columns(Vec<Vec<f64>>),
}

/// The first-order lag `s_i = a s_{i−1} + (1 − a) v_i`, `a = exp(−Δt/τ)`.
pub(crate) fn first_order_lag(t_h: &[f64], v: &[f64], tau_h: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(v.len());
    let mut s = v[0];
    for i in 0..v.len() {
        if i > 0 {
            let a = if tau_h <= 0.0 {
                0.0
            } else {
                (-(t_h[i] - t_h[i - 1]) / tau_h).exp()
            };
            s = a * s + (1.0 - a) * v[i];
        }
        out.push(s);
    }
    out
}

/// Feature `col` through a first-order lag of `tau_h` hours (the column itself for 0).
pub(crate) fn lagged(f: &Features, col: usize, tau_h: f64) -> Vec<f64> {
    if tau_h > 0.0 {
        first_order_lag(&f.time_h, &f.cols[col], tau_h)
    } else {
        f.cols[col].clone()
    }
}

impl Basis {
    /// The basis matrix at every row (`n x p`).
    pub fn matrix(&self, f: &Features) -> DMatrix<f64> {
        let n = f.time_h.len();
        match self {
            Self::Offset => DMatrix::from_element(n, 1, 1.0),
            Self::Drift => {
                DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { f.time_h[i] / 24.0 })
            }
            Self::Thermal { col, tau_h } => {
                let lag = first_order_lag(&f.time_h, &f.cols[*col], *tau_h);
                DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { lag[i] })
            }
            Self::LoadPath => DMatrix::from_fn(n, 4, |i, j| {
                let h = f.load[i] / 100.0;
                let rate = f.load_rate[i];
                let on = if j < 2 { rate > 1e-9 } else { rate < -1e-9 };
                match (on, j % 2) {
                    (false, _) => 0.0,
                    (true, 0) => h,
                    (true, _) => h * h,
                }
            }),
            Self::Generic {
                cols,
                lags_h,
                mean,
                sd,
            } => {
                let values: Vec<Vec<f64>> = cols
                    .iter()
                    .zip(lags_h)
                    .map(|(&c, &tau)| lagged(f, c, tau))
                    .collect();
                DMatrix::from_fn(n, cols.len() + 1, |i, j| {
                    if j == 0 {
                        1.0
                    } else {
                        (values[j - 1][i] - mean[j - 1]) / sd[j - 1]
                    }
                })
            }
            Self::Columns(c) => DMatrix::from_fn(n, c.len(), |i, j| c[j][i]),
        }
    }
}

/// A linear effect's evaluation: `basis (n x p) · coef (p x N_o)`.
#[derive(Debug, Clone)]
pub struct LinearTerm {
    /// The basis.
    pub basis: Basis,
    /// Coefficients, one column per gauge.
    pub coef: DMatrix<f64>,
    /// Sum of squared residuals of the fit on the calibration rows.
    pub sse: f64,
}

impl LinearTerm {
    /// Least-squares fit of `basis` to `r` on the calibration rows.
    pub fn fit(basis: Basis, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Self {
        let bm = basis.matrix(ctx.feats);
        let coef = ols(&select_rows(&bm, ctx.cal), &select_rows(r, ctx.cal));
        let c = &bm * &coef;
        let sse = ctx
            .cal
            .iter()
            .map(|&i| (r.row(i) - c.row(i)).norm_squared())
            .sum();
        Self { basis, coef, sse }
    }

    /// Row `row` of the coefficients (one value per gauge) as a named parameter.
    pub fn parameter(&self, row: usize, name: &str, unit: &str) -> EffectParameter {
        param(name, unit, self.coef.row(row).iter().copied().collect())
    }
}

impl Term for LinearTerm {
    fn contribution(&self, ctx: &FitContext<'_>) -> Result<DMatrix<f64>> {
        Ok(self.basis.matrix(ctx.feats) * &self.coef)
    }
}
