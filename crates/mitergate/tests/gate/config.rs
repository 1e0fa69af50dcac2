//! Configuration parsing and validation.
use mitergate::gate::config::{DEFAULT_GATE_TOML, equal_load_girder_heights};
use mitergate::{GateConfig, GateError};
use proptest::prelude::*;

fn param_of(err: GateError) -> String {
    match err {
        GateError::InvalidConfig { parameter, .. } => parameter,
        other => panic!("expected InvalidConfig, got {other}"),
    }
}

#[test]
fn default_gate_parses_validates_and_round_trips() {
    let cfg = GateConfig::from_toml_str(DEFAULT_GATE_TOML).unwrap();
    assert_eq!(cfg, GateConfig::default());
    assert_eq!(cfg.gauges.len(), 7);
    let back = GateConfig::from_toml_str(&cfg.to_toml_string().unwrap()).unwrap();
    assert_eq!(cfg, back);
}

#[test]
fn invalid_parameters_are_named() {
    let mut c = GateConfig::default();
    c.girders.heights[3] = 2000.0;
    assert_eq!(param_of(c.validate().unwrap_err()), "girders.heights[3]");
    let mut c = GateConfig::default();
    c.geometry.pivot_offset = c.geometry.bearing_offset;
    assert_eq!(param_of(c.validate().unwrap_err()), "geometry.pivot_offset");
    let mut c = GateConfig::default();
    c.diaphragms.positions = vec![300.0, 200.0];
    assert_eq!(
        param_of(c.validate().unwrap_err()),
        "diaphragms.positions[1]"
    );
    let mut c = GateConfig::default();
    c.material.poisson_ratio = 0.5;
    assert_eq!(
        param_of(c.validate().unwrap_err()),
        "material.poisson_ratio"
    );
    let mut c = GateConfig::default();
    c.mesh.element_size = f64::NAN;
    assert_eq!(param_of(c.validate().unwrap_err()), "mesh.element_size");
    let mut c = GateConfig::default();
    c.gauges[2].direction = [0.0; 3];
    assert_eq!(param_of(c.validate().unwrap_err()), "gauges[2].direction");
}

#[test]
fn unknown_keys_and_bad_toml_are_parse_errors_with_location() {
    let text = DEFAULT_GATE_TOML.replace("[skin_plate]", "[skin_plate]\ncolour = 3");
    let err = GateConfig::from_toml_str(&text).unwrap_err();
    assert!(matches!(err, GateError::ConfigParse { .. }));
    assert!(err.to_string().contains("colour"), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
    /// Without active spacing limits the hydrostatic load between consecutive girders is equal.
    #[test]
    fn equal_load_girders_split_the_load_evenly(n in 3usize..14, zb in 5.0f64..40.0) {
        let h = 762.0;
        let z = equal_load_girder_heights(h, n, zb, h - zb, 0.0, 1e9);
        let load = |a: f64, b: f64| (h * b - 0.5 * b * b) - (h * a - 0.5 * a * a);
        let loads: Vec<f64> = z.windows(2).map(|w| load(w[0], w[1])).collect();
        let mean = loads.iter().sum::<f64>() / loads.len() as f64;
        for l in loads {
            // heights are rounded to 0.1 in: load changes by up to ~h * 0.05 per end
            prop_assert!((l - mean).abs() < 0.1 * h);
        }
    }
}
