//! Property tests: orthogonality, closed forms, exactness, projection, derivatives.
use orthopoly::{
    Basis, Family, Normalization, gauss_chebyshev, gauss_hermite_prob, gauss_legendre,
};
use proptest::prelude::*;

use super::strategies::{family, interval, map_condition, normalization};

/// Modest case counts keep the whole crate's test run to a few seconds.
fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        ..ProptestConfig::default()
    }
}

/// `He_n(x) = n! Σ_m (-1)^m x^(n-2m) / (m! (n-2m)! 2^m)`.
fn hermite_explicit(n: usize, x: f64) -> f64 {
    let fact = |k: usize| (1..=k).map(|i| i as f64).product::<f64>();
    (0..=n / 2)
        .map(|m| {
            let sign = if m % 2 == 0 { 1.0 } else { -1.0 };
            sign * fact(n) * x.powi((n - 2 * m) as i32)
                / (fact(m) * fact(n - 2 * m) * 2f64.powi(m as i32))
        })
        .sum()
}

/// Same sum with every term made positive: bounds the cancellation in `hermite_explicit`.
fn hermite_explicit_abs(n: usize, x: f64) -> f64 {
    let fact = |k: usize| (1..=k).map(|i| i as f64).product::<f64>();
    (0..=n / 2)
        .map(|m| {
            fact(n) * x.abs().powi((n - 2 * m) as i32)
                / (fact(m) * fact(n - 2 * m) * 2f64.powi(m as i32))
        })
        .sum()
}

proptest! {
    #![proptest_config(config(48))]

    /// Σ_i w_i φ_j(t_i) φ_k(t_i) = δ_jk for degrees up to 30 under the basis's own Gauss rule.
    #[test]
    fn orthonormal_under_gauss_quadrature(
        family in family(),
        (a, b) in interval(),
        j in 0usize..=30,
        k in 0usize..=30,
    ) {
        let basis = Basis::new(family, a, b, 31).unwrap();
        // 31 nodes integrate degree <= 61 >= j + k exactly.
        let (t, w) = basis.probability_quadrature(31).unwrap();
        let l = basis.matrix(&t).unwrap();
        let gram: f64 = (0..t.len()).map(|i| w[i] * l[(i, j)] * l[(i, k)]).sum();
        let expected = if j == k { 1.0 } else { 0.0 };
        // By Cauchy-Schwarz Σ w|φ_j φ_k| <= 1, so the sum's round-off is bounded by the
        // per-term relative error of the recurrences (~30·eps each) times 31 terms: ~2e-13;
        // storing nodes in physical units perturbs z by ~eps·map_condition, amplified by
        // |φ'| / |φ| (<= ~30²) — hence the (1 + κ) factor.
        let tol = 1e-12 * (1.0 + map_condition(a, b));
        prop_assert!((gram - expected).abs() < tol, "{family:?} j={j} k={k}: {gram}");
    }

    /// Chebyshev T_n(cos s) = cos(n s), n <= 30.
    #[test]
    fn chebyshev_closed_form(s in 0.0..std::f64::consts::PI, n in 0usize..=30) {
        let basis = Basis::with_normalization(
            Family::Chebyshev, -1.0, 1.0, 31, Normalization::Classical).unwrap();
        let v = basis.eval(s.cos()).unwrap();
        // |T_n| <= 1; the recurrence's error grows at most ~n² eps ≈ 2e-13 for n = 30.
        prop_assert!((v[n] - (n as f64 * s).cos()).abs() < 1e-12);
    }

    /// Legendre P_2..P_5 in closed form, anywhere on [a, b].
    #[test]
    fn legendre_closed_forms((a, b) in interval(), u in 0.0..=1.0f64) {
        let basis = Basis::with_normalization(
            Family::Legendre, a, b, 6, Normalization::Classical).unwrap();
        let t = a + u * (b - a);
        let z = basis.to_reference(t);
        let v = basis.eval(t).unwrap();
        let closed = [
            (3.0 * z * z - 1.0) / 2.0,
            (5.0 * z.powi(3) - 3.0 * z) / 2.0,
            (35.0 * z.powi(4) - 30.0 * z * z + 3.0) / 8.0,
            (63.0 * z.powi(5) - 70.0 * z.powi(3) + 15.0 * z) / 8.0,
        ];
        for (n, c) in closed.iter().enumerate() {
            // |P_n| <= 1 (z may exceed 1 by round-off only); terms of the closed forms are
            // <= 9, so both sides carry absolute round-off ~1e-15.
            prop_assert!((v[n + 2] - c).abs() < 1e-13, "n={} z={z}", n + 2);
        }
    }

    /// Probabilists' Hermite He_n from the explicit sum, n <= 12.
    #[test]
    fn hermite_closed_form(x in -8.0..8.0f64, n in 0usize..=12) {
        let basis = Basis::with_normalization(
            Family::Hermite, -1.0, 1.0, 13, Normalization::Classical).unwrap();
        let v = basis.eval(x).unwrap()[n];
        // Both sides lose accuracy only through cancellation among terms whose absolute sum
        // is `hermite_explicit_abs`; 1e-13 of it is ~500 ulps of headroom.
        let tol = 1e-13 * hermite_explicit_abs(n, x);
        prop_assert!((v - hermite_explicit(n, x)).abs() <= tol, "n={n} x={x}");
    }

    /// Gauss-Legendre integrates degree 2n-1 exactly and is not exact at degree 2n.
    #[test]
    fn gauss_legendre_exactness((a, b) in interval(), n in 1usize..=60) {
        let (t, w) = gauss_legendre(n, a, b).unwrap();
        let (c, h) = (0.5 * (a + b), 0.5 * (b - a));
        let integral = |k: i32| -> f64 {
            t.iter().zip(&w).map(|(t, w)| w * ((t - c) / h).powi(k)).sum()
        };
        // ∫_a^b z^k dt = h ∫ z^k dz = 2h/(k+1) for even k, 0 for odd k.
        let exact = |k: i32| if k % 2 == 0 { 2.0 * h / (k + 1) as f64 } else { 0.0 };
        for k in [2 * n as i32 - 2, 2 * n as i32 - 1] {
            // Σ w|z^k| <= 2h: round-off of the n-term sum and of z^k (k <= 119) is below
            // 1e-13·2h; the physical→reference round trip perturbs z by ~2 eps κ, i.e. z^k by
            // ~2 k eps κ <= 5e-14 κ relative.
            let tol = 1e-12 * 2.0 * h * (1.0 + map_condition(a, b));
            prop_assert!((integral(k) - exact(k)).abs() < tol, "n={n} k={k}");
        }
        // Degree 2n is not integrated exactly: the error is 2h·(2^{2n}(n!)^4/((2n+1)((2n)!)^3))·(2n)!
        // which is far above round-off for n <= 15.
        if n <= 15 {
            let k = 2 * n as i32;
            prop_assert!((integral(k) - exact(k)).abs() > 1e-9 * 2.0 * h);
        }
    }

    /// Gauss-Hermite: E[Z^k] = (k-1)!! for even k, 0 for odd, up to k = 2n-1.
    #[test]
    fn gauss_hermite_exactness(n in 1usize..=40) {
        let (x, w) = gauss_hermite_prob(n).unwrap();
        let total: f64 = w.iter().sum();
        let sqrt_2pi = (2.0 * std::f64::consts::PI).sqrt();
        prop_assert!((total / sqrt_2pi - 1.0).abs() < 1e-13);
        for k in 0..2 * n as i32 {
            let moment: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(k)).sum::<f64>() / total;
            let abs_moment: f64 =
                x.iter().zip(&w).map(|(x, w)| w * x.abs().powi(k)).sum::<f64>() / total;
            let exact = if k % 2 == 1 { 0.0 } else { (1..k).step_by(2).map(|i| i as f64).product() };
            // Relative to E|Z|^k (what the sum is made of): node error ~eps·|x| becomes
            // k·eps relative in x^k, k <= 79, plus the n-term sum.
            prop_assert!((moment - exact).abs() < 1e-12 * abs_moment.max(1.0), "n={n} k={k}");
        }
    }

    /// Gauss-Chebyshev integrates T_k exactly for k <= 2n-1 (weight 1/sqrt((t-a)(b-t))).
    #[test]
    fn gauss_chebyshev_exactness((a, b) in interval(), n in 1usize..=30) {
        let (t, w) = gauss_chebyshev(n, a, b).unwrap();
        let basis = Basis::with_normalization(
            Family::Chebyshev, a, b, 2 * n, Normalization::Classical).unwrap();
        let l = basis.matrix(&t).unwrap();
        for k in 0..2 * n {
            let integral: f64 = (0..n).map(|i| w[i] * l[(i, k)]).sum();
            let exact = if k == 0 { std::f64::consts::PI } else { 0.0 };
            // |T_k| <= 1, Σ w = π: absolute round-off ~n·k·eps·π < 1e-12; the physical node
            // round-off (~2 eps κ in z) is amplified by |T_k'| <= k² < 3600: ~5e-12·κ.
            let tol = 1e-11 * (1.0 + map_condition(a, b));
            prop_assert!((integral - exact).abs() < tol, "n={n} k={k}: {integral}");
        }
    }

    /// Projecting a polynomial of degree < K reproduces its coefficients.
    #[test]
    fn projection_reproduces_polynomials(
        family in family(),
        normalization in normalization(),
        (a, b) in interval(),
        n_terms in 1usize..=10,
        extra in 0usize..40,
        coefficients in proptest::collection::vec(-10.0..10.0f64, 10),
    ) {
        let basis = Basis::with_normalization(family, a, b, n_terms, normalization).unwrap();
        let n_points = n_terms + extra;
        // Chebyshev-spaced points keep the fit well conditioned: on [-1, 1] for the bounded
        // families, on ±3 standard deviations for Hermite (on [-1, 1] alone classical
        // Hermite columns are nearly collinear, cond ~1e8).
        let spread = if family == Family::Hermite { 3.0 } else { 1.0 };
        let (z, _) = gauss_chebyshev(n_points, -spread, spread).unwrap();
        let points: Vec<f64> = z.iter().map(|&z| basis.from_reference(z)).collect();
        let c = &coefficients[..n_terms];
        let values = basis.reconstruct(c, &points).unwrap();
        let back = basis.project(&points, &values).unwrap();
        let singular = basis.matrix(&points).unwrap().singular_values();
        let cond = singular.max() / singular.min();
        let scale = c.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (x, y) in c.iter().zip(&back) {
            // Zero-residual least squares: the coefficient error is bounded by ~cond(L)·eps
            // times the data scale (the values themselves carry round-off of ~K eps times the
            // largest column entry); 1e-13·cond·K is a few hundred ulps of that.
            let tol = 1e-13 * cond * scale * n_terms as f64;
            prop_assert!((x - y).abs() < tol, "{family:?} {normalization:?}: {x} vs {y}, cond {cond}");
        }
    }

    /// Derivatives match central finite differences.
    #[test]
    fn derivatives_match_finite_differences(
        family in family(),
        normalization in normalization(),
        (a, b) in interval(),
        u in 0.01..0.99f64,
    ) {
        let basis = Basis::with_normalization(family, a, b, 9, normalization).unwrap();
        let t = a + u * (b - a);
        let step = 1e-5 * (b - a);
        let (_, d) = basis.eval_with_derivatives(t).unwrap();
        let (plus, minus) = (basis.eval(t + step).unwrap(), basis.eval(t - step).unwrap());
        let half_width = 0.5 * (b - a);
        for k in 0..9 {
            let fd = (plus[k] - minus[k]) / (2.0 * step);
            // Compare d/dz (multiply by (b-a)/2). Central differences with dz = 2e-5 have
            // truncation dz²/6·|p'''| <= 1e-10·|p'''| (|p'''| < 1e5 for degree 8 on
            // |z| <= 1) and round-off ~eps·|p|/dz ≈ 1e-10: both far below 1e-5.
            let (dz_exact, dz_fd) = (d[k] * half_width, fd * half_width);
            prop_assert!(
                (dz_exact - dz_fd).abs() < 1e-5 * (1.0 + dz_exact.abs()),
                "{family:?} k={k}: {dz_exact} vs {dz_fd}"
            );
        }
    }
}
