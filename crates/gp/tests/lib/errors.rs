//! Bad input gives a clear error value, never a panic.

use gp::{Bounds, GpError, GpParams, Mean};
use nalgebra::DMatrix;

fn data() -> (DMatrix<f64>, Vec<f64>) {
    let x = DMatrix::from_fn(6, 2, |i, j| (i + 2 * j) as f64 + 0.1 * (i * j) as f64);
    let y = (0..6).map(|i| (i as f64).sin()).collect();
    (x, y)
}

#[test]
fn empty_data_is_rejected() {
    let err = GpParams::new().fit(&DMatrix::zeros(0, 2), &[]).unwrap_err();
    assert_eq!(err, GpError::EmptyData { name: "x" });
}

#[test]
fn mismatched_lengths_are_rejected() {
    let (x, y) = data();
    let err = GpParams::new().fit(&x, &y[..5]).unwrap_err();
    assert!(
        matches!(
            err,
            GpError::ShapeMismatch {
                name: "y",
                expected: 6,
                found: 5,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn non_finite_values_are_located() {
    let (mut x, mut y) = data();
    y[3] = f64::NAN;
    assert!(matches!(
        GpParams::new().fit(&x, &y).unwrap_err(),
        GpError::NonFinite {
            name: "y",
            row: 3,
            ..
        }
    ));
    y[3] = 0.0;
    x[(4, 1)] = f64::INFINITY;
    assert!(matches!(
        GpParams::new().fit(&x, &y).unwrap_err(),
        GpError::NonFinite {
            name: "x",
            row: 4,
            col: 1,
            ..
        }
    ));
}

#[test]
fn prediction_inputs_are_checked() {
    let (x, y) = data();
    let model = GpParams::new().restarts(0).fit(&x, &y).unwrap();
    let err = model.predict(&DMatrix::zeros(3, 3)).unwrap_err();
    assert!(matches!(
        err,
        GpError::ShapeMismatch {
            name: "x",
            expected: 2,
            found: 3,
            ..
        }
    ));
    let mut bad = DMatrix::zeros(2, 2);
    bad[(1, 0)] = f64::NAN;
    assert!(matches!(
        model.posterior_cov(&x, &bad).unwrap_err(),
        GpError::NonFinite {
            name: "x2",
            row: 1,
            col: 0,
            ..
        }
    ));
    assert!(matches!(
        model.predict(&DMatrix::zeros(0, 2)).unwrap_err(),
        GpError::EmptyData { name: "x" }
    ));
}

#[test]
fn too_few_points_for_the_mean() {
    let x = DMatrix::from_row_slice(3, 2, &[0.0, 1.0, 1.0, 0.0, 2.0, 2.0]);
    let err = GpParams::new()
        .mean(Mean::Linear)
        .fit(&x, &[1.0, 2.0, 3.0])
        .unwrap_err();
    assert_eq!(err, GpError::TooFewPoints { n: 3, p: 3 });
}

#[test]
fn constant_column_with_linear_mean_is_rejected() {
    let (mut x, y) = data();
    x.column_mut(1).fill(5.0);
    let err = GpParams::new().mean(Mean::Linear).fit(&x, &y).unwrap_err();
    assert!(
        matches!(err, GpError::InvalidParameter { name: "mean", .. }),
        "{err}"
    );
}

#[test]
fn invalid_settings_are_rejected() {
    let (x, y) = data();
    let bad = Bounds {
        length_scale: (1.0, 0.5),
        ..Default::default()
    };
    assert!(matches!(
        GpParams::new().bounds(bad).fit(&x, &y).unwrap_err(),
        GpError::InvalidParameter {
            name: "bounds.length_scale",
            ..
        }
    ));
    assert!(matches!(
        GpParams::new()
            .estimate_noise(false)
            .nugget(-1.0)
            .fit(&x, &y)
            .unwrap_err(),
        GpError::InvalidParameter { name: "nugget", .. }
    ));
    let err = GpParams::new()
        .fit_with_log_params(&x, &y, &[0.0])
        .unwrap_err();
    assert!(matches!(
        err,
        GpError::ShapeMismatch {
            name: "log_params",
            ..
        }
    ));
}

#[test]
fn duplicated_points_without_noise_use_logged_jitter() {
    // A length scale 1e4 times the data spread and a zero nugget make K numerically rank one
    // (all entries 1 to ~1e-9): plain Cholesky breaks down, the fit must succeed through jitter,
    // report it, and still predict finite values.
    let x = DMatrix::from_row_slice(6, 1, &[0.0, 1.0, 1.0, 2.0, 3.0, 4.0]);
    let y = [0.0, 1.0, 1.0, 0.5, 0.2, 0.1];
    let model = GpParams::new()
        .estimate_noise(false)
        .nugget(0.0)
        .fit_with_log_params(&x, &y, &[0.0, 9.2])
        .unwrap();
    assert!(model.diagnostics().jitter > 0.0);
    let p = model.predict(&x).unwrap();
    assert!(
        p.mean
            .iter()
            .chain(p.variance.iter())
            .all(|v| v.is_finite())
    );
}
