//! Bad input gives a descriptive error, never a panic.
use orthopoly::{Basis, Family, OrthoError, gauss_chebyshev, gauss_hermite_prob, gauss_legendre};

fn invalid_name(err: OrthoError) -> &'static str {
    match err {
        OrthoError::InvalidParameter { name, .. } => name,
        other => panic!("expected InvalidParameter, got {other:?}"),
    }
}

#[test]
fn constructor_rejects_bad_parameters() {
    let e = |a, b, k| invalid_name(Basis::new(Family::Legendre, a, b, k).unwrap_err());
    assert_eq!(e(0.0, 1.0, 0), "n_terms");
    assert_eq!(e(1.0, 1.0, 3), "b");
    assert_eq!(e(2.0, 1.0, 3), "b");
    assert_eq!(e(f64::NAN, 1.0, 3), "a");
    assert_eq!(e(0.0, f64::INFINITY, 3), "b");
    assert_eq!(e(-f64::MAX, f64::MAX, 3), "b"); // width overflows
}

#[test]
fn quadrature_rejects_bad_parameters() {
    assert_eq!(invalid_name(gauss_legendre(0, 0.0, 1.0).unwrap_err()), "n");
    assert_eq!(invalid_name(gauss_legendre(3, 1.0, 0.0).unwrap_err()), "b");
    assert_eq!(
        invalid_name(gauss_legendre(3, f64::NAN, 1.0).unwrap_err()),
        "a"
    );
    assert_eq!(invalid_name(gauss_hermite_prob(0).unwrap_err()), "n");
    assert_eq!(invalid_name(gauss_chebyshev(0, 0.0, 1.0).unwrap_err()), "n");
    assert_eq!(
        invalid_name(gauss_chebyshev(2, 0.0, f64::NEG_INFINITY).unwrap_err()),
        "b"
    );
}

#[test]
fn points_are_checked() {
    let basis = Basis::new(Family::Legendre, 0.0, 762.0, 4).unwrap();
    assert!(matches!(
        basis.matrix(&[1.0, f64::NAN]).unwrap_err(),
        OrthoError::NonFinite {
            name: "points",
            index: 1,
            ..
        }
    ));
    assert!(matches!(
        basis.derivative_matrix(&[0.0, 762.0, 763.0]).unwrap_err(),
        OrthoError::OutOfInterval { index: 2, .. }
    ));
    assert!(matches!(
        basis.eval(-0.5).unwrap_err(),
        OrthoError::OutOfInterval { index: 0, .. }
    ));
    // A grid whose last point carries round-off is still accepted.
    assert!(basis.eval(762.0 * (1.0 + 1e-15)).is_ok());
}

#[test]
fn lengths_are_checked() {
    let basis = Basis::new(Family::Hermite, 0.0, 1.0, 3).unwrap();
    let mut short = [0.0; 2];
    assert_eq!(
        basis.eval_into(0.5, &mut short).unwrap_err(),
        OrthoError::LengthMismatch {
            name: "values",
            expected: 3,
            found: 2
        }
    );
    assert!(matches!(
        basis.project(&[0.0, 1.0, 2.0], &[1.0, 2.0]).unwrap_err(),
        OrthoError::LengthMismatch {
            name: "values",
            expected: 3,
            found: 2
        }
    ));
    assert!(matches!(
        basis.reconstruct(&[1.0], &[0.0]).unwrap_err(),
        OrthoError::LengthMismatch {
            name: "coefficients",
            expected: 3,
            found: 1
        }
    ));
    assert!(matches!(
        basis
            .reconstruct(&[1.0, f64::INFINITY, 0.0], &[0.0])
            .unwrap_err(),
        OrthoError::NonFinite {
            name: "coefficients",
            index: 1,
            ..
        }
    ));
}

#[test]
fn underdetermined_projection_is_an_error() {
    let basis = Basis::new(Family::Legendre, 0.0, 10.0, 4).unwrap();
    // Too few points.
    assert!(matches!(
        basis
            .project(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0])
            .unwrap_err(),
        OrthoError::RankDeficient {
            rank: 3,
            n_terms: 4,
            n_points: 3
        }
    ));
    // Enough points, but only three distinct ones.
    let pts = [1.0, 2.0, 3.0, 3.0, 2.0, 1.0];
    assert!(matches!(
        basis.project(&pts, &[0.0; 6]).unwrap_err(),
        OrthoError::RankDeficient {
            rank: 3,
            n_terms: 4,
            n_points: 6
        }
    ));
    assert!(matches!(
        basis
            .project(&[1.0, 2.0, 3.0, 4.0], &[0.0, f64::NAN, 0.0, 0.0])
            .unwrap_err(),
        OrthoError::NonFinite {
            name: "values",
            index: 1,
            ..
        }
    ));
}

#[test]
fn errors_name_the_parameter_in_their_message() {
    let msg = Basis::new(Family::Legendre, 0.0, 762.0, 2)
        .unwrap()
        .matrix(&[800.0])
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("points[0]") && msg.contains("800") && msg.contains("762"),
        "{msg}"
    );
}
