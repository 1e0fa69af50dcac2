//! Determinism and save/load.

use nalgebra::DMatrix;
use proptest::prelude::*;
use seqnet::{LstmParams, LstmRegressor, LstmShape, Network, Precision, SeqError};

fn tmp(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("seqnet_test_{}_{name}.json", std::process::id()))
}

fn toy(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let x = DMatrix::from_fn(n, 4, |r, c| ((r * 31 + c * 17) % 23) as f64 / 23.0 - 0.5);
    let y = DMatrix::from_fn(n, 2, |r, c| (x[(r, c)] * 2.0).sin() + x[(r, 3 - c)]);
    (x, y)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, .. ProptestConfig::default() })]
    #[test]
    fn same_seed_same_weights(shape in crate::strategies::small_shape(), seed in any::<u64>()) {
        prop_assert_eq!(Network::<f64>::init(shape, seed), Network::<f64>::init(shape, seed));
        prop_assert_eq!(Network::<f32>::init(shape, seed), Network::<f32>::init(shape, seed));
    }

    #[test]
    fn different_seed_different_weights(shape in crate::strategies::small_shape(), seed in 0u64..u64::MAX) {
        prop_assert_ne!(Network::<f64>::init(shape, seed), Network::<f64>::init(shape, seed + 1));
    }

    #[test]
    fn network_json_round_trip_is_exact(shape in crate::strategies::small_shape(), seed in any::<u64>()) {
        // Perturb by awkward values (many significant digits, tiny and huge magnitudes).
        let mut net = Network::<f64>::init(shape, seed);
        for (k, v) in net.params_mut().iter_mut().enumerate() {
            *v = *v * 1.000_000_000_000_1 + (k as f64) * 1e-300 + std::f64::consts::PI * 1e-17;
        }
        let back: Network<f64> = serde_json::from_str(&serde_json::to_string(&net).unwrap()).unwrap();
        prop_assert!(back.params().iter().zip(net.params()).all(|(a, b)| a.to_bits() == b.to_bits()));
        let net32 = Network::<f32>::init(shape, seed);
        let back32: Network<f32> = serde_json::from_str(&serde_json::to_string(&net32).unwrap()).unwrap();
        prop_assert!(back32.params().iter().zip(net32.params()).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

#[test]
fn fit_is_deterministic_for_a_seed_and_thread_count() {
    let (x, y) = toy(200);
    for threads in [1, 2] {
        let p = LstmParams::new(4, 2)
            .hidden(6)
            .steps(2)
            .epochs(3)
            .batch_size(32)
            .threads(threads);
        let a = p.clone().fit(&x, &y).unwrap();
        let b = p.clone().fit(&x, &y).unwrap();
        assert_eq!(a.predict(&x).unwrap(), b.predict(&x).unwrap());
        assert_eq!(a.history().train_loss, b.history().train_loss);
    }
}

#[test]
fn save_load_round_trip_predicts_identically() {
    let (x, y) = toy(120);
    for precision in [Precision::F32, Precision::F64] {
        let m = LstmParams::new(4, 2)
            .hidden(5)
            .layers(2)
            .steps(4)
            .epochs(2)
            .batch_size(16)
            .precision(precision)
            .fit(&x, &y)
            .unwrap();
        let path = tmp(&format!("{precision:?}"));
        m.save(&path).unwrap();
        let back = LstmRegressor::load(&path).unwrap();
        assert_eq!(back, m);
        assert_eq!(back.predict(&x).unwrap(), m.predict(&x).unwrap());
        let _ = std::fs::remove_file(path);
    }
}

#[test]
fn load_rejects_other_version_and_shape() {
    let (x, y) = toy(60);
    let m = LstmParams::new(4, 2)
        .hidden(3)
        .epochs(1)
        .batch_size(16)
        .fit(&x, &y)
        .unwrap();
    let path = tmp("version");
    m.save(&path).unwrap();
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    v["format_version"] = serde_json::json!(seqnet::FORMAT_VERSION + 1);
    std::fs::write(&path, v.to_string()).unwrap();
    assert!(matches!(
        LstmRegressor::load(&path),
        Err(SeqError::Format { .. })
    ));

    // Shape field edited so it disagrees with the stored weights.
    v["format_version"] = serde_json::json!(seqnet::FORMAT_VERSION);
    v["shape"]["hidden"] = serde_json::json!(4);
    std::fs::write(&path, v.to_string()).unwrap();
    assert!(matches!(
        LstmRegressor::load(&path),
        Err(SeqError::Format { .. })
    ));

    m.save(&path).unwrap();
    let other = LstmShape::new(4, 1, 3, 2, 2).unwrap();
    assert!(matches!(
        LstmRegressor::load_with_shape(&path, &other),
        Err(SeqError::Format { .. })
    ));
    assert!(LstmRegressor::load_with_shape(&path, m.shape()).is_ok());
    assert!(matches!(
        LstmRegressor::load(&tmp("missing")),
        Err(SeqError::Io { .. })
    ));
    let _ = std::fs::remove_file(path);
}
