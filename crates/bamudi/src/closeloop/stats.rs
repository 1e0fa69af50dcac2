//! Least squares and the residual adequacy checks (bias, variance, autocorrelation,
//! correlation with covariates).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Least-squares coefficients `B` (`p x g`) minimising `‖X B − Y‖` column by column, via SVD
/// (rank-deficient designs get the minimum-norm solution).
pub(crate) fn ols(x: &DMatrix<f64>, y: &DMatrix<f64>) -> DMatrix<f64> {
    let svd = x.clone().svd(true, true);
    let tol = 1e-10 * svd.singular_values.max().max(1e-300);
    svd.solve(y, tol)
        .unwrap_or_else(|_| DMatrix::zeros(x.ncols(), y.ncols()))
}

/// Rows `rows` of `m`.
pub(crate) fn select_rows(m: &DMatrix<f64>, rows: &[usize]) -> DMatrix<f64> {
    m.select_rows(rows.iter())
}

/// Mean of squares over all entries of the given rows.
pub(crate) fn mse_rows(r: &DMatrix<f64>, rows: &[usize]) -> f64 {
    let mut s = 0.0;
    for &i in rows {
        s += r.row(i).iter().map(|v| v * v).sum::<f64>();
    }
    s / (rows.len() * r.ncols()).max(1) as f64
}

/// Root mean square per column over the given rows.
pub(crate) fn rmse_per_column(r: &DMatrix<f64>, rows: &[usize]) -> Vec<f64> {
    (0..r.ncols())
        .map(|j| {
            (rows.iter().map(|&i| r[(i, j)].powi(2)).sum::<f64>() / rows.len().max(1) as f64).sqrt()
        })
        .collect()
}

/// Pearson correlation (0 when either series is constant).
pub(crate) fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// Sample autocorrelations at lags `1..=max_lag`.
pub(crate) fn autocorrelations(r: &[f64], max_lag: usize) -> Vec<f64> {
    let n = r.len();
    let m = r.iter().sum::<f64>() / n as f64;
    let c0: f64 = r.iter().map(|v| (v - m).powi(2)).sum();
    (1..=max_lag)
        .map(|k| {
            if k >= n || c0 <= 0.0 {
                return 0.0;
            }
            (k..n).map(|i| (r[i] - m) * (r[i - k] - m)).sum::<f64>() / c0
        })
        .collect()
}

/// Ljung-Box statistic `Q = n(n+2) Σ ρ_k² / (n − k)` and its chi-square p-value (`m` dof).
pub(crate) fn ljung_box(r: &[f64], lags: usize) -> (f64, f64) {
    let n = r.len() as f64;
    let rho = autocorrelations(r, lags);
    let q = n
        * (n + 2.0)
        * rho
            .iter()
            .enumerate()
            .map(|(k, p)| p * p / (n - (k + 1) as f64))
            .sum::<f64>();
    (q, chi2_sf(q, lags as f64))
}

/// Survival function of the chi-square distribution, `P(X > x)` with `k` degrees of freedom.
pub(crate) fn chi2_sf(x: f64, k: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    upper_regularized_gamma(k / 2.0, x / 2.0)
}

/// `Q(a, x) = Γ(a, x) / Γ(a)` by series (x < a + 1) or continued fraction (Numerical Recipes).
fn upper_regularized_gamma(a: f64, x: f64) -> f64 {
    let ln_front = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..500 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_front.exp()).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..500 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_front.exp() * h).clamp(0.0, 1.0)
    }
}

/// Lanczos approximation of `ln Γ(x)`, `x > 0`.
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 6] = [
        76.180_091_729_471_46,
        -86.505_320_329_416_77,
        24.014_098_240_830_91,
        -1.231_739_572_450_155,
        0.120_865_097_386_617_9e-2,
        -0.539_523_938_495_3e-5,
    ];
    let tmp = x + 5.5 - (x + 0.5) * (x + 5.5).ln();
    let mut ser = 1.000_000_000_190_015;
    for (j, g) in G.iter().enumerate() {
        ser += g / (x + 1.0 + j as f64);
    }
    -tmp + (2.506_628_274_631_000_5 * ser / x).ln()
}

/// Robust white-noise standard deviation of a series: MAD of first differences / (0.6745 √2).
/// Slow effects (drift, seasons) barely change first differences, and rare jumps (lockage
/// transitions) are outliers the median ignores.
pub(crate) fn noise_sd_from_differences(r: &[f64]) -> f64 {
    let mut d: Vec<f64> = r.windows(2).map(|w| w[1] - w[0]).collect();
    if d.is_empty() {
        return 0.0;
    }
    let med = median(&mut d);
    let mut dev: Vec<f64> = d.iter().map(|v| (v - med).abs()).collect();
    median(&mut dev) / 0.6745 / std::f64::consts::SQRT_2
}

/// Median (sorts `v` in place; 0 when `v` is empty).
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Adequacy statistics of one gauge's residuals on one window.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GaugeCheck {
    /// Gauge name.
    pub gauge: String,
    /// Mean residual (microstrain).
    pub bias: f64,
    /// Bias divided by its standard error, the standard error inflated for lag-1
    /// autocorrelation (effective sample size `n (1 − ρ₁)/(1 + ρ₁)`).
    pub bias_z: f64,
    /// Root mean square residual (microstrain).
    pub rmse: f64,
    /// Mean of squared standardised residuals `r² / predictive variance` (≈ 1 when the
    /// predictive variance is right).
    pub variance_ratio: f64,
    /// Lag-1 autocorrelation of the residuals in time order.
    pub lag1_autocorrelation: f64,
    /// Ljung-Box statistic over [`super::CloseLoopConfig::ljung_box_lags`] lags.
    pub ljung_box_q: f64,
    /// Chi-square p-value of the Ljung-Box statistic.
    pub ljung_box_p: f64,
}

/// Largest absolute correlation between residuals and one covariate over the gauges.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CovariateCorrelation {
    /// Covariate (derived features included, e.g. `d_head_per_h`).
    pub covariate: String,
    /// Largest |Pearson correlation| over the gauges.
    pub max_abs_correlation: f64,
    /// Gauge at which it occurs.
    pub gauge: String,
}

/// All adequacy checks of one window.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Adequacy {
    /// Window name (`calibration` or `heldout`).
    pub window: String,
    /// Number of rows.
    pub n: usize,
    /// Per-gauge statistics.
    pub gauges: Vec<GaugeCheck>,
    /// Correlation with every covariate, largest first.
    pub correlations: Vec<CovariateCorrelation>,
    /// Human-readable list of failed checks (empty = residuals consistent with noise).
    pub failures: Vec<String>,
}

impl Adequacy {
    /// `true` when no check failed.
    pub fn passed(&self) -> bool {
        self.failures.is_empty()
    }
}

/// Thresholds of the adequacy checks.
pub(crate) struct CheckThresholds {
    pub ljung_box_lags: usize,
    /// Family-wise significance level, Bonferroni-split over the tests of a window.
    pub significance: f64,
}

/// Runs the adequacy checks on `rows` of residuals `r` with predictive variances `var`.
pub(crate) fn adequacy(
    window: &str,
    r: &DMatrix<f64>,
    var: &DMatrix<f64>,
    rows: &[usize],
    gauges: &[String],
    features: &super::Features,
    th: &CheckThresholds,
) -> Adequacy {
    let n = rows.len();
    let n_tests = (gauges.len() * (3 + features.names.len())) as f64;
    let alpha = th.significance / n_tests;
    let z_crit = normal_quantile_upper(alpha / 2.0);
    let mut failures = Vec::new();
    let mut checks = Vec::new();
    for (j, g) in gauges.iter().enumerate() {
        let rj: Vec<f64> = rows.iter().map(|&i| r[(i, j)]).collect();
        let mean = rj.iter().sum::<f64>() / n as f64;
        let sd =
            (rj.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0).max(1.0)).sqrt();
        let rho = autocorrelations(&rj, th.ljung_box_lags.max(1));
        let lag1 = rho[0];
        let n_eff = (n as f64 * (1.0 - lag1.max(0.0)) / (1.0 + lag1.max(0.0))).max(2.0);
        let bias_z = if sd > 0.0 {
            mean / (sd / n_eff.sqrt())
        } else {
            0.0
        };
        let variance_ratio = rows
            .iter()
            .map(|&i| r[(i, j)].powi(2) / var[(i, j)].max(1e-300))
            .sum::<f64>()
            / n as f64;
        let (q, p) = ljung_box(&rj, th.ljung_box_lags);
        if bias_z.abs() > z_crit {
            failures.push(format!(
                "{window}: {g} bias {mean:.3} microstrain (z = {bias_z:.1})"
            ));
        }
        // the mean of n squared standard normals has sd sqrt(2/n)
        let var_tol = z_crit * (2.0 / n as f64).sqrt();
        if (variance_ratio - 1.0).abs() > var_tol.max(0.25) {
            failures.push(format!(
                "{window}: {g} residual variance / predictive variance = {variance_ratio:.2}"
            ));
        }
        if p < alpha {
            failures.push(format!(
                "{window}: {g} autocorrelated (lag-1 {lag1:.2}, Ljung-Box p = {p:.1e})"
            ));
        }
        checks.push(GaugeCheck {
            gauge: g.clone(),
            bias: mean,
            bias_z,
            rmse: (rj.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt(),
            variance_ratio,
            lag1_autocorrelation: lag1,
            ljung_box_q: q,
            ljung_box_p: p,
        });
    }
    // a correlation of white noise with any series has sd ≈ 1/sqrt(n)
    let corr_crit = z_crit / (n as f64).sqrt();
    let mut correlations = Vec::new();
    for (name, col) in features.names.iter().zip(&features.cols) {
        let c: Vec<f64> = rows.iter().map(|&i| col[i]).collect();
        let mut best = (0.0, 0);
        for j in 0..gauges.len() {
            let rj: Vec<f64> = rows.iter().map(|&i| r[(i, j)]).collect();
            let rho = correlation(&c, &rj).abs();
            if rho > best.0 {
                best = (rho, j);
            }
        }
        if best.0 > corr_crit {
            failures.push(format!(
                "{window}: residual of {} correlates with {name} (|r| = {:.2})",
                gauges[best.1], best.0
            ));
        }
        correlations.push(CovariateCorrelation {
            covariate: name.clone(),
            max_abs_correlation: best.0,
            gauge: gauges[best.1].clone(),
        });
    }
    correlations.sort_by(|a, b| b.max_abs_correlation.total_cmp(&a.max_abs_correlation));
    Adequacy {
        window: window.into(),
        n,
        gauges: checks,
        correlations,
        failures,
    }
}

/// Upper quantile `z` with `P(Z > z) = p` of the standard normal (Acklam's rational
/// approximation, relative error < 1.2e-9, ample for test thresholds).
pub(crate) fn normal_quantile_upper(p: f64) -> f64 {
    -normal_quantile(p.clamp(1e-300, 0.5))
}

#[allow(clippy::excessive_precision)] // published coefficients, kept verbatim
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let p_low = 0.02425;
    if p < p_low {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_sf_matches_tables() {
        // chi-square 95th percentiles: 3.841 (1 dof), 18.307 (10 dof); exact to the 3 table decimals
        assert!((chi2_sf(3.841, 1.0) - 0.05).abs() < 1e-4);
        assert!((chi2_sf(18.307, 10.0) - 0.05).abs() < 1e-4);
        assert!((chi2_sf(2.0, 2.0) - (-1.0f64).exp()).abs() < 1e-12);
    }

    #[test]
    fn normal_quantile_matches_tables() {
        // 1.959964 and 3.290527 from tables, Acklam's approximation is good to 1e-8 relative
        assert!((normal_quantile_upper(0.025) - 1.959_964).abs() < 1e-5);
        assert!((normal_quantile_upper(0.0005) - 3.290_527).abs() < 1e-5);
    }

    #[test]
    fn ols_recovers_exact_coefficients() {
        let x = DMatrix::from_fn(20, 2, |i, j| if j == 0 { 1.0 } else { i as f64 });
        let y = DMatrix::from_fn(20, 1, |i, _| 3.0 - 0.5 * i as f64);
        let b = ols(&x, &y);
        // exact data: only round-off
        assert!((b[(0, 0)] - 3.0).abs() < 1e-10 && (b[(1, 0)] + 0.5).abs() < 1e-10);
    }
}
