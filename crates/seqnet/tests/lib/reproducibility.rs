//! Bit-for-bit reproducibility: fixed training runs give exactly the losses and predictions
//! recorded in `tests/data/repro_fixture.txt` with the code before the params/observer
//! refactor, and a model saved then (format version 1, `tests/data/model_format_v1.json`)
//! still loads and predicts the same bits.

use nalgebra::DMatrix;
use seqnet::{
    EpochReport, LrSchedule, LstmParams, LstmRegressor, LstmSettings, Optimizer, Precision,
};
use std::collections::HashMap;

/// Deterministic inputs (4 columns, offsets per column) and two smooth nonlinear outputs.
fn data(n: usize, salt: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let x = DMatrix::from_fn(n, 4, |r, c| {
        (((r + salt) * 31 + c * 17) % 23) as f64 / 23.0 - 0.5 + 0.01 * c as f64
    });
    let y = DMatrix::from_fn(n, 2, |r, c| {
        (x[(r, c)] * 2.0).sin() + x[(r, 3 - c)] * x[(r, 1)]
    });
    (x, y)
}

/// The recorded runs: every optimiser, every non-constant schedule, clipping, both precisions,
/// one and two threads, with and without a validation split, early stopping, the defaults.
fn cases() -> Vec<(&'static str, LstmParams)> {
    vec![
        (
            "f32_adam_cosine_two_layers",
            LstmParams::new(4, 2)
                .hidden(6)
                .layers(2)
                .steps(2)
                .epochs(4)
                .batch_size(16)
                .learning_rate(1e-2)
                .schedule(LrSchedule::Cosine { min_factor: 0.1 })
                .validation_fraction(0.2)
                .patience(0)
                .seed(11),
        ),
        (
            "f64_sgd_plateau_clip_threads2",
            LstmParams::new(4, 2)
                .hidden(5)
                .steps(4)
                .epochs(5)
                .batch_size(24)
                .learning_rate(0.05)
                .optimizer(Optimizer::sgd(0.9))
                .schedule(LrSchedule::ReduceOnPlateau {
                    factor: 0.5,
                    patience: 1,
                    min_factor: 0.01,
                })
                .clip_norm(0.5)
                .validation_fraction(0.0)
                .precision(Precision::F64)
                .threads(2)
                .seed(3),
        ),
        (
            "f32_step_early_stop_threads2",
            LstmParams::new(4, 2)
                .hidden(4)
                .epochs(120)
                .batch_size(8)
                .learning_rate(3e-2)
                .schedule(LrSchedule::Step {
                    every: 3,
                    factor: 0.7,
                })
                .patience(2)
                .validation_fraction(0.25)
                .threads(2)
                .seed(5),
        ),
        (
            "f64_defaults",
            LstmParams::new(4, 2)
                .epochs(3)
                .precision(Precision::F64)
                .seed(9),
        ),
    ]
}

type Case = HashMap<String, Vec<String>>;

/// The fixture: case name -> key -> the recorded words (floats in `{:?}` form).
fn fixture() -> HashMap<String, Case> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/repro_fixture.txt");
    let text = std::fs::read_to_string(path).unwrap();
    let mut cases: HashMap<String, Case> = HashMap::new();
    let mut current = String::new();
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            current = name.to_string();
            continue;
        }
        let mut words = line.split_whitespace().map(str::to_string);
        let key = words.next().unwrap();
        cases
            .entry(current.clone())
            .or_default()
            .insert(key, words.collect());
    }
    cases
}

fn floats(case: &Case, key: &str) -> Vec<u64> {
    case[key]
        .iter()
        .map(|w| w.parse::<f64>().unwrap().to_bits())
        .collect()
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|a| a.to_bits()).collect()
}

/// Row-major values of `m`.
fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    (0..m.nrows())
        .flat_map(|r| (0..m.ncols()).map(move |c| m[(r, c)]))
        .collect()
}

/// Asserts the model's history and predictions at the test inputs are the recorded bits.
fn assert_recorded(case: &Case, m: &LstmRegressor, x_test: &DMatrix<f64>, name: &str) {
    let h = m.history();
    assert_eq!(bits(&h.train_loss), floats(case, "train_loss"), "{name}");
    assert_eq!(bits(&h.val_loss), floats(case, "val_loss"), "{name}");
    assert_eq!(
        bits(&h.learning_rate),
        floats(case, "learning_rate"),
        "{name}"
    );
    assert_eq!(
        bits(&[h.best_epoch as f64, h.best_loss]),
        floats(case, "best"),
        "{name}"
    );
    assert_eq!(
        h.stopped_early.to_string(),
        case["stopped_early"][0],
        "{name}"
    );
    let pred = m.predict(x_test).unwrap();
    assert_eq!(bits(&row_major(&pred)), floats(case, "predict"), "{name}");
}

#[test]
fn fixed_runs_reproduce_the_recorded_losses_and_predictions_bit_for_bit() {
    let fx = fixture();
    let (x, y) = data(160, 0);
    let (x_test, _) = data(40, 7);
    for (name, params) in cases() {
        let m = params.fit(&x, &y).unwrap();
        assert_recorded(&fx[name], &m, &x_test, name);
    }
}

#[test]
fn observing_reports_the_history_and_changes_nothing() {
    let fx = fixture();
    let (x, y) = data(160, 0);
    let (x_test, _) = data(40, 7);
    let (name, params) = cases().swap_remove(2);
    let checked = params.check().unwrap();
    let mut reports: Vec<EpochReport> = Vec::new();
    let m = checked
        .fit_observed(&x, &y, &mut |r: &EpochReport| reports.push(*r))
        .unwrap();
    assert_recorded(&fx[name], &m, &x_test, name);
    let h = m.history();
    assert_eq!(reports.len(), h.train_loss.len());
    for (k, r) in reports.iter().enumerate() {
        assert_eq!((r.epoch, r.epochs), (k, 120));
        assert_eq!(r.train_loss, h.train_loss[k]);
        assert_eq!(r.val_loss, Some(h.val_loss[k]));
        assert_eq!(r.learning_rate, h.learning_rate[k]);
        assert_eq!(r.seconds, h.epoch_seconds[k]);
        assert!(r.best_epoch <= k && r.best_loss <= r.val_loss.unwrap());
    }
    let last = reports.last().unwrap();
    assert_eq!(
        (last.best_epoch, last.best_loss),
        (h.best_epoch, h.best_loss)
    );
}

#[test]
fn a_format_1_file_still_loads_and_predicts_the_same_bits() {
    let fx = fixture();
    let name = "f32_adam_cosine_two_layers";
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/model_format_v1.json"
    );
    let old = LstmRegressor::load(std::path::Path::new(path)).unwrap();
    let (x_test, _) = data(40, 7);
    assert_recorded(&fx[name], &old, &x_test, name);
    // the stored hyper-parameters are the ones of the recorded run
    let (_, params) = cases().swap_remove(0);
    assert_eq!(old.params(), &params.check().unwrap());
    // re-saved in the current format (`sd`, no `progress`), it reads back identically
    let tmp = std::env::temp_dir().join(format!(
        "seqnet_test_{}_resaved_v1.json",
        std::process::id()
    ));
    old.save(&tmp).unwrap();
    let text = std::fs::read_to_string(&tmp).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["format_version"], seqnet::FORMAT_VERSION);
    assert!(json["x_scaler"].get("sd").is_some() && json["params"].get("progress").is_none());
    assert_eq!(LstmRegressor::load(&tmp).unwrap(), old);
    let _ = std::fs::remove_file(tmp);
}

#[test]
fn settings_and_setters_build_the_same_parameters() {
    let by_setters = LstmParams::new(10, 12)
        .hidden(32)
        .layers(2)
        .steps(10)
        .epochs(7)
        .batch_size(64)
        .learning_rate(2e-3)
        .optimizer(Optimizer::sgd(0.5))
        .schedule(LrSchedule::Cosine { min_factor: 0.2 })
        .validation_fraction(0.3)
        .patience(4)
        .clip_norm(2.0)
        .precision(Precision::F64)
        .threads(2)
        .seed(8);
    let settings = LstmSettings {
        hidden: 32,
        layers: 2,
        steps: 10,
        epochs: 7,
        batch_size: 64,
        learning_rate: 2e-3,
        optimizer: Optimizer::sgd(0.5),
        schedule: LrSchedule::Cosine { min_factor: 0.2 },
        validation_fraction: 0.3,
        patience: 4,
        clip_norm: Some(2.0),
        precision: Precision::F64,
        threads: 2,
    };
    let by_settings = LstmParams::new(10, 12).seed(8).settings(settings.clone());
    assert_eq!(by_setters, by_settings);
    let checked = by_settings.check().unwrap();
    assert_eq!(checked.settings(), &settings);
    assert_eq!(LstmParams::from(checked), by_setters);
}
