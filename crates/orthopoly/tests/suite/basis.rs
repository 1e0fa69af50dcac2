//! Deterministic tests of `Basis`: conventions, consistency between entry points, serde.
use orthopoly::{Basis, Family, Normalization};

const FAMILIES: [Family; 3] = [Family::Legendre, Family::Chebyshev, Family::Hermite];

#[test]
fn orthonormal_is_classical_divided_by_its_norm() {
    for family in FAMILIES {
        let ortho = Basis::new(family, -3.0, 5.0, 21).unwrap();
        let classical =
            Basis::with_normalization(family, -3.0, 5.0, 21, Normalization::Classical).unwrap();
        for t in [-3.0, -1.3, 0.0, 0.7, 4.2, 5.0] {
            let (o, c) = (ortho.eval(t).unwrap(), classical.eval(t).unwrap());
            let (od, cd) = (
                ortho.eval_with_derivatives(t).unwrap().1,
                classical.eval_with_derivatives(t).unwrap().1,
            );
            for n in 0..21 {
                let s = family.classical_norm_squared(n).sqrt();
                // Two independent recurrences (Jacobi vs classical) for n <= 20: each carries a
                // relative error of a few n·eps, so 1e-12 relative (plus an absolute floor for
                // values near a root) is round-off level.
                let tol = 1e-12 * (1.0 + (c[n] / s).abs());
                assert!((o[n] - c[n] / s).abs() < tol, "{family:?} n={n} t={t}");
                let tol_d = 1e-12 * (1.0 + (cd[n] / s).abs());
                assert!(
                    (od[n] - cd[n] / s).abs() < tol_d,
                    "{family:?} d n={n} t={t}"
                );
            }
        }
    }
}

#[test]
fn phi_zero_is_one_and_constant_coefficient_is_the_mean() {
    let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
    let (t, w) = basis.probability_quadrature(8).unwrap();
    // Quadratic field in lbf/in; its mean over [0, 762] in is known in closed form.
    let field: Vec<f64> = t.iter().map(|t| 3.0 + 0.01 * t * t).collect();
    let c = basis.project(&t, &field).unwrap();
    let mean = 3.0 + 0.01 * 762.0f64.powi(2) / 3.0;
    let quad_mean: f64 = field.iter().zip(&w).map(|(f, w)| f * w).sum();
    // Mean ≈ 1.9e3; exact rules and a 6-column least-squares fit leave ~1e-12 relative.
    assert!((c[0] - mean).abs() < 1e-9 * mean, "{} vs {mean}", c[0]);
    assert!((quad_mean - mean).abs() < 1e-9 * mean);
    assert!(basis.eval(123.0).unwrap()[0] == 1.0);
}

#[test]
fn matrix_rows_match_pointwise_evaluation() {
    for family in FAMILIES {
        for normalization in [Normalization::Orthonormal, Normalization::Classical] {
            let basis = Basis::with_normalization(family, 0.0, 762.0, 9, normalization).unwrap();
            let points: Vec<f64> = (0..37).map(|i| 762.0 * i as f64 / 36.0).collect();
            let l = basis.matrix(&points).unwrap();
            let dl = basis.derivative_matrix(&points).unwrap();
            for (i, &t) in points.iter().enumerate() {
                let (v, d) = basis.eval_with_derivatives(t).unwrap();
                for k in 0..9 {
                    // Same recurrence, same operation order: agreement must be exact.
                    assert_eq!(l[(i, k)], v[k], "{family:?} value ({i},{k})");
                    assert_eq!(dl[(i, k)], d[k], "{family:?} derivative ({i},{k})");
                }
                assert_eq!(basis.eval(t).unwrap(), v);
            }
        }
    }
}

#[test]
fn hermite_map_puts_a_and_b_one_standard_deviation_from_the_mean() {
    let basis = Basis::new(Family::Hermite, 95.0, 105.0, 3).unwrap(); // N(100, 5²)
    assert_eq!(basis.to_reference(100.0), 0.0);
    assert_eq!(basis.to_reference(105.0), 1.0);
    let (t, w) = basis.probability_quadrature(5).unwrap();
    let mean: f64 = t.iter().zip(&w).map(|(t, w)| t * w).sum();
    let var: f64 = t.iter().zip(&w).map(|(t, w)| (t - 100.0).powi(2) * w).sum();
    // Exact for quadratics; sums of 5 terms of size ~100 → round-off ~1e-13.
    assert!((mean - 100.0).abs() < 1e-11);
    assert!((var - 25.0).abs() < 1e-11);
    // Points far outside [a, b] are legitimate for a Hermite basis.
    assert!(basis.eval(200.0).is_ok());
}

#[test]
fn reconstruct_inverts_project_on_the_quoin() {
    let basis = Basis::new(Family::Legendre, 0.0, 762.0, 6).unwrap();
    let d: Vec<f64> = (0..509).map(|i| 762.0 * i as f64 / 508.0).collect();
    let alpha = [120.0, -35.0, 8.0, 2.5, -1.0, 0.25];
    let field = basis.reconstruct(&alpha, &d).unwrap();
    let back = basis.project(&d, &field).unwrap();
    for (a, b) in alpha.iter().zip(&back) {
        // 509 x 6 orthonormal columns have condition number ~1.1; round-off ~1e-13·|α|.
        assert!((a - b).abs() < 1e-10, "{a} vs {b}");
    }
}

#[test]
fn least_squares_fit_of_a_non_polynomial_is_the_best_approximation() {
    // The residual of a least-squares fit is orthogonal to every column of L.
    let basis = Basis::new(Family::Chebyshev, 0.0, 762.0, 5).unwrap();
    let d: Vec<f64> = (0..200).map(|i| 762.0 * i as f64 / 199.0).collect();
    let field: Vec<f64> = d.iter().map(|t| (t / 100.0).sin() * 40.0).collect();
    let c = basis.project(&d, &field).unwrap();
    let fit = basis.reconstruct(&c, &d).unwrap();
    let l = basis.matrix(&d).unwrap();
    for k in 0..5 {
        let dot: f64 = (0..d.len()).map(|i| l[(i, k)] * (field[i] - fit[i])).sum();
        // 200 terms of size <= sqrt(2)·40: round-off ~200·eps·60 ≈ 3e-12.
        assert!(dot.abs() < 1e-9, "column {k}: {dot}");
    }
    // And the fit is not trivially exact (the test would pass vacuously otherwise).
    let rms: f64 = field
        .iter()
        .zip(&fit)
        .map(|(f, g)| (f - g).powi(2))
        .sum::<f64>();
    assert!(rms > 1.0);
}

#[test]
fn serde_round_trip_and_validation_on_deserialize() {
    let basis = Basis::with_normalization(Family::Chebyshev, 1.0, 2.0, 4, Normalization::Classical)
        .unwrap();
    let json = serde_json::to_string(&basis).unwrap();
    let back: Basis = serde_json::from_str(&json).unwrap();
    assert_eq!(back, basis);
    let bad = json.replace("\"n_terms\":4", "\"n_terms\":0");
    assert_ne!(bad, json);
    let err = serde_json::from_str::<Basis>(&bad).unwrap_err().to_string();
    assert!(err.contains("n_terms"), "{err}");
}

#[test]
fn basis_is_send_and_sync() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Basis>();
}
