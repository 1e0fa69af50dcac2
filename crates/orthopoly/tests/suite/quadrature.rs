//! Deterministic quadrature checks, including large orders.
use orthopoly::{gauss_chebyshev, gauss_hermite_prob, gauss_legendre};

fn assert_symmetric_ascending(x: &[f64], w: &[f64]) {
    let n = x.len();
    for i in 0..n {
        assert_eq!(x[i], -x[n - 1 - i], "node {i} not mirrored");
        assert_eq!(w[i], w[n - 1 - i], "weight {i} not mirrored");
        assert!(w[i] >= 0.0);
    }
    assert!(
        x.windows(2).all(|p| p[0] < p[1]),
        "nodes not strictly ascending"
    );
}

#[test]
fn gauss_legendre_large_orders() {
    for n in [100, 257, 1000] {
        let (x, w) = gauss_legendre(n, -1.0, 1.0).unwrap();
        assert_symmetric_ascending(&x, &w);
        let total: f64 = w.iter().sum();
        let m2: f64 = x.iter().zip(&w).map(|(x, w)| w * x * x).sum();
        // Sums of n positive terms: relative error <= n·eps ≈ 2e-13 for n = 1000.
        assert!((total - 2.0).abs() < 1e-12, "n={n}: {total}");
        assert!((m2 - 2.0 / 3.0).abs() < 1e-12, "n={n}: {m2}");
        // Nodes interlace with the Chebyshev-like angles: the largest node is within the
        // Bessel-zero asymptote 1 - x ≈ j₀₁²/(2 n²) (j₀₁ ≈ 2.405), to 2%.
        let gap = 1.0 - x[n - 1];
        let asymptote = 2.404_825_557_695_773f64.powi(2) / (2.0 * (n as f64 + 0.5).powi(2));
        assert!(
            (gap / asymptote - 1.0).abs() < 0.02,
            "n={n}: {gap} vs {asymptote}"
        );
    }
}

#[test]
fn gauss_hermite_large_orders() {
    for n in [100, 300, 1000] {
        let (x, w) = gauss_hermite_prob(n).unwrap();
        assert_symmetric_ascending(&x, &w);
        let total: f64 = w.iter().sum();
        let m2: f64 = x.iter().zip(&w).map(|(x, w)| w * x * x).sum();
        let sqrt_2pi = (2.0 * std::f64::consts::PI).sqrt();
        // Positive sums of n terms: n·eps relative.
        assert!((total / sqrt_2pi - 1.0).abs() < 1e-12, "n={n}: {total}");
        assert!((m2 / sqrt_2pi - 1.0).abs() < 1e-12, "n={n}: {m2}");
        // Largest node below the soft edge 2 sqrt(n) of the semicircle law.
        assert!(x[n - 1] < 2.0 * (n as f64).sqrt());
    }
}

#[test]
fn gauss_chebyshev_nodes_are_cosines() {
    let n = 7;
    let (t, w) = gauss_chebyshev(n, 0.0, 762.0).unwrap();
    for k in 0..n {
        let z = ((2 * (n - k) - 1) as f64 * std::f64::consts::PI / (2 * n) as f64).cos();
        // 762-in interval: absolute round-off ~762·eps.
        assert!((t[k] - 381.0 * (1.0 + z)).abs() < 1e-12 * 762.0);
        assert_eq!(w[k], std::f64::consts::PI / 7.0);
    }
    assert_eq!(t[3], 381.0); // middle node exactly at the centre
}

#[test]
fn small_rules_in_closed_form() {
    let (x, w) = gauss_legendre(1, 2.0, 4.0).unwrap();
    assert_eq!((x, w), (vec![3.0], vec![2.0]));
    let (x, w) = gauss_legendre(2, -1.0, 1.0).unwrap();
    // ±1/sqrt(3), weights 1: Newton polish reaches the correctly rounded value within 1 ulp.
    assert!((x[1] - 1.0 / 3f64.sqrt()).abs() < 2e-16);
    assert!((w[0] - 1.0).abs() < 4e-16);
    let (x, w) = gauss_hermite_prob(3).unwrap();
    // Roots of He_3 = x³ - 3x: 0, ±sqrt(3); weights sqrt(2π)·(1/6, 2/3, 1/6).
    let s = (2.0 * std::f64::consts::PI).sqrt();
    assert_eq!(x[1], 0.0);
    assert!((x[2] - 3f64.sqrt()).abs() < 4e-16);
    assert!((w[1] - s * 2.0 / 3.0).abs() < 1e-15 && (w[0] - s / 6.0).abs() < 1e-15);
}
