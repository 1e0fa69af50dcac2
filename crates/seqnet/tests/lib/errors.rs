//! Bad input gives a clear error value, never a panic.

use nalgebra::DMatrix;
use seqnet::{LstmParams, Optimizer, SeqError};

fn data() -> (DMatrix<f64>, DMatrix<f64>) {
    (
        DMatrix::from_fn(20, 4, |r, c| (r + c) as f64),
        DMatrix::from_fn(20, 1, |r, _| r as f64),
    )
}

#[test]
fn nan_input_is_reported_with_position() {
    let (mut x, y) = data();
    x[(7, 2)] = f64::NAN;
    let err = LstmParams::new(4, 1).fit(&x, &y).unwrap_err();
    assert!(
        matches!(
            err,
            SeqError::NonFinite {
                what: "x",
                row: 7,
                col: 2,
                ..
            }
        ),
        "{err}"
    );
    let (x, mut y) = data();
    y[(3, 0)] = f64::INFINITY;
    let err = LstmParams::new(4, 1).fit(&x, &y).unwrap_err();
    assert!(
        matches!(
            err,
            SeqError::NonFinite {
                what: "y",
                row: 3,
                col: 0,
                ..
            }
        ),
        "{err}"
    );
}

#[test]
fn bad_shapes_are_errors() {
    let (x, y) = data();
    assert!(matches!(
        LstmParams::new(5, 1).fit(&x, &y),
        Err(SeqError::Shape { what: "x", .. })
    ));
    assert!(matches!(
        LstmParams::new(4, 2).fit(&x, &y),
        Err(SeqError::Shape { what: "y", .. })
    ));
    let y_short = DMatrix::zeros(19, 1);
    assert!(matches!(
        LstmParams::new(4, 1).fit(&x, &y_short),
        Err(SeqError::Shape { what: "y", .. })
    ));
    assert!(matches!(
        LstmParams::new(4, 1).steps(3).fit(&x, &y),
        Err(SeqError::InvalidParameter { name: "steps", .. })
    ));
}

#[test]
fn bad_hyper_parameters_are_named() {
    let (x, y) = data();
    let cases: Vec<(LstmParams, &str)> = vec![
        (LstmParams::new(4, 1).hidden(0), "hidden"),
        (LstmParams::new(4, 1).layers(0), "layers"),
        (LstmParams::new(4, 1).epochs(0), "epochs"),
        (LstmParams::new(4, 1).batch_size(0), "batch_size"),
        (
            LstmParams::new(4, 1).learning_rate(f64::NAN),
            "learning_rate",
        ),
        (
            LstmParams::new(4, 1).validation_fraction(1.0),
            "validation_fraction",
        ),
        (LstmParams::new(4, 1).clip_norm(0.0), "clip_norm"),
        (LstmParams::new(4, 1).threads(0), "threads"),
        (
            LstmParams::new(4, 1).optimizer(Optimizer::sgd(1.5)),
            "optimizer",
        ),
    ];
    for (p, expected) in cases {
        match p.fit(&x, &y) {
            Err(SeqError::InvalidParameter { name, .. }) => assert_eq!(name, expected),
            other => panic!("{expected}: expected InvalidParameter, got {other:?}"),
        }
    }
}

#[test]
fn divergence_is_an_error_with_epoch_and_batch() {
    // Plain SGD with an absurd learning rate on unscaled-looking targets overflows quickly.
    let x = DMatrix::from_fn(64, 2, |r, c| ((r * 7 + c) % 5) as f64);
    let y = DMatrix::from_fn(64, 1, |r, _| (r % 3) as f64);
    let err = LstmParams::new(2, 1)
        .hidden(4)
        .optimizer(Optimizer::sgd(0.99))
        .learning_rate(1e30)
        .epochs(50)
        .batch_size(8)
        .fit(&x, &y)
        .unwrap_err();
    assert!(matches!(err, SeqError::Diverged { .. }), "{err}");
    assert!(err.to_string().contains("epoch"));
}

#[test]
fn predict_rejects_nan() {
    let (x, y) = data();
    let m = LstmParams::new(4, 1)
        .hidden(3)
        .epochs(1)
        .fit(&x, &y)
        .unwrap();
    let mut bad = x.clone();
    bad[(0, 0)] = f64::NAN;
    assert!(matches!(
        m.predict(&bad),
        Err(SeqError::NonFinite { row: 0, col: 0, .. })
    ));
}
