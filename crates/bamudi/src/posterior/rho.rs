//! `ρ` integrated analytically over its uniform prior: the exponent of the marginal
//! likelihood is quadratic in `ρ`, so the integral is a difference of normal CDFs.

use nalgebra::DMatrix;

/// The log marginal likelihood of `θ` with `α` and `ρ` integrated out, with `ρ`'s
/// conditional maximiser and precision.
pub(crate) struct ThetaTerms {
    pub(crate) log_lik: f64,
    pub(crate) rho_hat: f64,
    pub(crate) q2: f64,
}

/// `log (Φ(b) − Φ(a))` for `a < b`, accurate in both tails.
fn log_normal_interval(a: f64, b: f64) -> f64 {
    use statrs::function::erf::erfc;
    let sf = |z: f64| 0.5 * erfc(z / std::f64::consts::SQRT_2); // P(Z > z)
    if a >= 0.0 {
        // both in the upper tail: Φ(b) − Φ(a) = sf(a) − sf(b)
        let (sa, sb) = (sf(a), sf(b));
        if sa > 0.0 {
            return sa.ln() + (-(sb / sa)).ln_1p();
        }
        // sf(a) underflows: its asymptotic logarithm
        return -0.5 * a * a - (a * (2.0 * std::f64::consts::PI).sqrt()).ln();
    }
    if b <= 0.0 {
        return log_normal_interval(-b, -a);
    }
    (1.0 - sf(b) - sf(-a)).ln()
}

impl ThetaTerms {
    /// From the Gram matrix `G = [a c]ᵀ V⁻¹ [a c]`, `ln|V|`, `N_s` and `ρ`'s uniform prior.
    pub(crate) fn new(g: &DMatrix<f64>, log_det: f64, n_s: usize, (lo, hi): (f64, f64)) -> Self {
        let (q2, q1, q0) = (g[(0, 0)], g[(0, 1)], g[(1, 1)]);
        let base = -0.5 * (n_s as f64 * (2.0 * std::f64::consts::PI).ln() + log_det);
        if q2.is_nan() || q2 <= 1e-300 {
            // no response: ρ does not enter the mean
            return Self {
                log_lik: base - 0.5 * q0,
                rho_hat: 0.5 * (lo + hi),
                q2: 0.0,
            };
        }
        let rho_hat = q1 / q2;
        let sq = q2.sqrt();
        let interval = log_normal_interval(sq * (lo - rho_hat), sq * (hi - rho_hat));
        let log_lik = base - 0.5 * (q0 - q1 * q1 / q2)
            + 0.5 * (2.0 * std::f64::consts::PI / q2).ln()
            + interval
            - (hi - lo).ln();
        Self {
            log_lik,
            rho_hat,
            q2,
        }
    }
}

/// Mean and variance of `N(μ, 1/q2)` truncated to `[lo, hi]`.
pub(crate) fn truncated_moments(mu: f64, q2: f64, (lo, hi): (f64, f64)) -> (f64, f64) {
    if q2.is_nan() || q2 <= 1e-300 {
        return (0.5 * (lo + hi), (hi - lo).powi(2) / 12.0);
    }
    let sd = 1.0 / q2.sqrt();
    let (a, b) = ((lo - mu) / sd, (hi - mu) / sd);
    let phi = |z: f64| (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let z = log_normal_interval(a, b).exp().max(1e-300);
    let mean = mu + sd * (phi(a) - phi(b)) / z;
    let var = sd * sd * (1.0 + (a * phi(a) - b * phi(b)) / z - ((phi(a) - phi(b)) / z).powi(2));
    (mean.clamp(lo, hi), var.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_interval_logarithms_match_direct_values_and_survive_the_tails() {
        use statrs::distribution::{ContinuousCDF, Normal};
        let n = Normal::new(0.0, 1.0).unwrap();
        for (a, b) in [(-1.0, 1.0), (0.5, 2.0), (-3.0, -0.2), (2.0, 9.0)] {
            let direct = (n.cdf(b) - n.cdf(a)).ln();
            assert!(
                (log_normal_interval(a, b) - direct).abs() < 1e-10,
                "{a} {b}"
            );
        }
        // far in the tail the direct difference is 0; the logarithm stays finite and close to
        // the leading term −a²/2
        let far = log_normal_interval(40.0, 50.0);
        assert!(far.is_finite() && (far + 800.0).abs() < 10.0, "{far}");
    }

    #[test]
    fn truncated_normal_moments_match_the_untruncated_ones_inside_and_a_uniform_when_flat() {
        let (m, v) = truncated_moments(0.5, 1e6, (0.0, 1.0));
        assert!((m - 0.5).abs() < 1e-9 && (v - 1e-6).abs() < 1e-9);
        let (m, v) = truncated_moments(0.5, 1e-8, (0.0, 1.0));
        assert!((m - 0.5).abs() < 1e-6 && (v - 1.0 / 12.0).abs() < 1e-4);
    }
}
