//! `LstmSettings` as a configuration-file section: the calibration engine embeds it as the
//! newtype variant of an internally tagged enum (`[estimator]` with `kind = "lstm"`), which must
//! read from TOML with defaults for missing keys and refuse unknown keys.

use seqnet::{LrSchedule, LstmSettings, Optimizer, Precision};
use serde::{Deserialize, Serialize};

/// The shape of the engine's estimator choice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum EstimatorParams {
    Lstm(LstmSettings),
    Ridge(RidgeParams),
    ExactLinear,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RidgeParams {
    lambda: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Config {
    estimator: EstimatorParams,
}

#[test]
fn internally_tagged_lstm_settings_read_from_toml_with_defaults() {
    let cfg: Config =
        toml::from_str("[estimator]\nkind = \"lstm\"\nhidden = 64\nsteps = 10\n").unwrap();
    let expected = LstmSettings {
        hidden: 64,
        steps: 10,
        ..LstmSettings::default()
    };
    assert_eq!(cfg.estimator, EstimatorParams::Lstm(expected));
    // the other variants still parse beside it
    let ridge: Config = toml::from_str("[estimator]\nkind = \"ridge\"\nlambda = 0.5\n").unwrap();
    assert_eq!(
        ridge.estimator,
        EstimatorParams::Ridge(RidgeParams { lambda: 0.5 })
    );
    let exact: Config = toml::from_str("[estimator]\nkind = \"exact_linear\"\n").unwrap();
    assert_eq!(exact.estimator, EstimatorParams::ExactLinear);
}

#[test]
fn every_field_can_be_set_from_toml() {
    let text = r#"
        [estimator]
        kind = "lstm"
        hidden = 16
        layers = 2
        steps = 5
        epochs = 200
        batch_size = 128
        learning_rate = 3e-3
        optimizer = { Sgd = { momentum = 0.9 } }
        schedule = { ReduceOnPlateau = { factor = 0.5, patience = 3, min_factor = 0.01 } }
        validation_fraction = 0.2
        patience = 20
        clip_norm = 1.0
        precision = "F64"
        threads = 2
    "#;
    let cfg: Config = toml::from_str(text).unwrap();
    let expected = LstmSettings {
        hidden: 16,
        layers: 2,
        steps: 5,
        epochs: 200,
        batch_size: 128,
        learning_rate: 3e-3,
        optimizer: Optimizer::sgd(0.9),
        schedule: LrSchedule::ReduceOnPlateau {
            factor: 0.5,
            patience: 3,
            min_factor: 0.01,
        },
        validation_fraction: 0.2,
        patience: 20,
        clip_norm: Some(1.0),
        precision: Precision::F64,
        threads: 2,
    };
    assert_eq!(cfg.estimator, EstimatorParams::Lstm(expected));
}

#[test]
fn unknown_keys_are_refused_through_the_tagged_enum() {
    let err = toml::from_str::<Config>("[estimator]\nkind = \"lstm\"\nhiden = 64\n").unwrap_err();
    assert!(err.to_string().contains("hiden"), "{err}");
    // hyper-parameters that belong to one fit, not to the settings
    for key in ["seed = 1", "n_inputs = 10", "progress = false"] {
        let text = format!("[estimator]\nkind = \"lstm\"\n{key}\n");
        assert!(toml::from_str::<Config>(&text).is_err(), "{key} accepted");
    }
}

#[test]
fn settings_round_trip_through_toml() {
    for settings in [
        LstmSettings::default(),
        LstmSettings {
            clip_norm: Some(0.5),
            schedule: LrSchedule::Step {
                every: 2,
                factor: 0.5,
            },
            ..LstmSettings::default()
        },
    ] {
        let cfg = Config {
            estimator: EstimatorParams::Lstm(settings),
        };
        let text = toml::to_string(&cfg).unwrap();
        assert_eq!(toml::from_str::<Config>(&text).unwrap(), cfg, "{text}");
    }
}
