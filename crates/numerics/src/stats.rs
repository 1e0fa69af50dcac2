//! Residual statistics: sample autocorrelations, the Ljung-Box test and the chi-square
//! survival function (the adequacy checks of `bamudi` and the close loop's residual checks).

/// Sample autocorrelations at lags `1..=max_lag`.
pub fn autocorrelations(r: &[f64], max_lag: usize) -> Vec<f64> {
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
pub fn ljung_box(r: &[f64], lags: usize) -> (f64, f64) {
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
///
/// ```
/// // the 95th percentile of chi-square with 1 degree of freedom is 3.841 (tables)
/// assert!((numerics::stats::chi2_sf(3.841, 1.0) - 0.05).abs() < 1e-4);
/// ```
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    statrs::function::gamma::gamma_ur(k / 2.0, x / 2.0)
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
    fn ljung_box_of_an_alternating_series_has_its_closed_form() {
        // ±1 alternating, n = 200: mean 0, ρ₁ = −199/200, ρ₂ = 198/200, so
        // Q = n (n + 2) (ρ₁² / 199 + ρ₂² / 198); the two sums differ only in rounding
        let n = 200.0;
        let r: Vec<f64> = (0..200)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let rho = autocorrelations(&r, 2);
        assert!((rho[0] + 199.0 / 200.0).abs() < 1e-12 && (rho[1] - 198.0 / 200.0).abs() < 1e-12);
        let want = n * (n + 2.0) * (rho[0].powi(2) / 199.0 + rho[1].powi(2) / 198.0);
        let (q, p) = ljung_box(&r, 2);
        assert!((q - want).abs() < 1e-9 * want, "{q} vs {want}");
        // chi-square with 2 dof: P(X > q) = exp(−q / 2)
        assert!((p - (-q / 2.0).exp()).abs() < 1e-12, "{p}");
        // a constant series has no autocorrelation to test
        assert_eq!(autocorrelations(&[3.0; 10], 3), vec![0.0; 3]);
    }
}
