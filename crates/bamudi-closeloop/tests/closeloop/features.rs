//! The feature library and declared column units: which candidates the data-driven term and
//! the thermal effect get, decided by declared units and never by a column's name.

use bamudi_closeloop::CloseLoopError;
use bamudi_closeloop::testing::{GridCalibrator, ToyGate, record_with};
use bamudi_closeloop::{
    CloseLoopConfig, Features, IngestConfig, MeasuredRecord, close_loop, effects,
};
use std::collections::BTreeMap;

/// `rows` rows `step_h` hours apart with covariates `a` (°F), `b` (°F), `c` (in), `phase` (a
/// code), one gauge.
fn record(rows: usize, step_h: f64) -> MeasuredRecord {
    let mut csv = String::from("time,h_up,h_down,a,b,c,phase,g1\n");
    for i in 0..rows {
        let t = i as f64 * step_h;
        let x = (t * 0.37).sin();
        csv += &format!(
            "{t},{},{},{},{},{},{},{}\n",
            300.0 + 10.0 * x,
            100.0,
            50.0 + x,
            40.0 - x * x,
            520.0 + t / 100.0,
            i % 4,
            x
        );
    }
    let ingest = IngestConfig::new(&["h_up", "h_down"], &["g1"]);
    bamudi_closeloop::parse_csv(&csv, "features.csv", &ingest).unwrap()
}

fn units(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(c, u)| (c.to_string(), u.to_string()))
        .collect()
}

#[test]
fn differences_pair_only_columns_of_one_declared_unit() {
    let rec = record(100, 1.0);
    let declared = units(&[("a", "degF"), ("b", "°F"), ("c", "in"), ("phase", "1")]);
    let f = Features::new(&rec, None, &declared);
    let derived = &f.names[f.checked..];
    assert!(derived.contains(&"a_minus_b".to_string()), "{derived:?}");
    assert!(derived.contains(&"d_a_minus_b_per_h".to_string()));
    // one column per unit, or a dimensionless code: no difference
    assert_eq!(derived.iter().filter(|n| n.contains("_minus_")).count(), 2);
    let k = f.position("a_minus_b").unwrap();
    assert_eq!(
        f.cols[k][7],
        f.cols[f.position("a").unwrap()][7] - f.cols[f.position("b").unwrap()][7]
    );
    assert!(f.lag_sources.contains(&k));
    // undeclared: no differences at all
    let f = Features::new(&rec, None, &BTreeMap::new());
    assert!(!f.names.iter().any(|n| n.contains("_minus_")));
    // the checked columns are the record's own and their rates, whatever is declared
    assert_eq!(
        &f.names[..f.checked],
        &Features::new(&rec, None, &declared).names[..f.checked]
    );
}

#[test]
fn harmonics_appear_only_where_the_record_resolves_them() {
    let has = |f: &Features, n: &str| f.position(n).is_some();
    // three days hourly: daily (24 h and 12 h), no seasonal
    let f = Features::new(&record(72, 1.0), None, &BTreeMap::new());
    assert!(has(&f, "daily_sin") && has(&f, "daily_cos") && has(&f, "semidaily_sin"));
    assert!(!has(&f, "seasonal_sin"));
    let row = 6; // 6 h: a quarter of a day
    assert!((f.cols[f.position("daily_sin").unwrap()][row] - 1.0).abs() < 1e-12);
    // one day only, or 12-hourly rows (a 24 h cycle is sampled twice): none
    assert!(!has(
        &Features::new(&record(24, 1.0), None, &BTreeMap::new()),
        "daily_sin"
    ));
    assert!(!has(
        &Features::new(&record(20, 12.0), None, &BTreeMap::new()),
        "daily_sin"
    ));
    // a year and a half, daily rows: seasonal, no daily
    let f = Features::new(&record(550, 24.0), None, &BTreeMap::new());
    assert!(has(&f, "seasonal_sin") && !has(&f, "daily_sin"));
}

/// The names of the default library's effects for `cfg`.
fn library(rec: &MeasuredRecord, cfg: &CloseLoopConfig) -> Vec<String> {
    effects::default_library(rec, cfg)
        .iter()
        .map(|e| e.name())
        .collect()
}

#[test]
fn thermal_candidates_come_from_declared_units_not_names() {
    let mut rec = record_with(&ToyGate::default(), 48, 1, |_, _| 0.0).unwrap();
    // named as no temperature would be: declared in kelvin, it is a thermal candidate
    rec.covariate_names = vec!["sensor_7".into()];
    let cfg = CloseLoopConfig::default().column_unit("sensor_7", "K");
    assert!(library(&rec, &cfg).contains(&"thermal(sensor_7)".to_string()));
    // named like a temperature but undeclared, or declared as a count: not a candidate
    rec.covariate_names = vec!["air_temp_f".into()];
    let none = CloseLoopConfig::default();
    let count = CloseLoopConfig::default().column_unit("air_temp_f", "1");
    for cfg in [none, count] {
        assert!(!library(&rec, &cfg).iter().any(|n| n.starts_with("thermal")));
    }
}

#[test]
fn a_declared_column_the_record_lacks_is_an_error_naming_key_and_file() {
    let rec = record_with(&ToyGate::default(), 48, 1, |_, _| 0.0).unwrap();
    let cal = GridCalibrator::new(ToyGate::default(), (40.0, 200.0));
    let misspelt = CloseLoopConfig::default().column_unit("air_tmp_f", "degF");
    let e = close_loop(&rec, &cal, &misspelt).unwrap_err();
    assert!(
        matches!(e, CloseLoopError::InvalidConfig { name: "column_units", ref reason }
            if reason.contains("'air_tmp_f'") && reason.contains(&rec.file)
                && reason.contains("air_temp_f")),
        "{e}"
    );
    let misspelt = CloseLoopConfig {
        temperature_columns: Some(vec!["air_tmp_f".into()]),
        ..CloseLoopConfig::default()
    };
    let e = close_loop(&rec, &cal, &misspelt).unwrap_err();
    assert!(
        matches!(
            e,
            CloseLoopError::InvalidConfig {
                name: "temperature_columns",
                ..
            }
        ),
        "{e}"
    );
    let empty = CloseLoopConfig::default().column_unit("air_temp_f", " ");
    assert!(close_loop(&rec, &cal, &empty).is_err());
}

/// A covariate declared in a temperature unit must read a temperature of a structure's
/// surroundings ([`bamudi_closeloop::TEMPERATURE_RANGE_C`]); a fault code or a wrong unit is
/// refused before any calibration, naming the file, line and column.
#[test]
fn an_absurd_temperature_is_refused_naming_line_and_column() {
    let mut rec = record_with(&ToyGate::default(), 48, 1, |_, _| 0.0).unwrap();
    let cal = GridCalibrator::new(ToyGate::default(), (40.0, 200.0));
    let k = rec
        .covariate_names
        .iter()
        .position(|c| c == "air_temp_f")
        .unwrap();
    rec.covariates[(7, k)] = -999.0;
    let cfg = CloseLoopConfig::default().column_unit("air_temp_f", "degF");
    let e = close_loop(&rec, &cal, &cfg).unwrap_err().to_string();
    let line = format!("line {}", rec.source_lines[7]);
    assert!(
        e.contains(&line) && e.contains("`air_temp_f`") && e.contains("[-148, 212] degF"),
        "{e}"
    );
    // the same column declared in kelvin: every °F reading is far below 173 K
    let kelvin = CloseLoopConfig::default().column_unit("air_temp_f", "K");
    let e = close_loop(&rec, &cal, &kelvin).unwrap_err().to_string();
    assert!(
        e.contains("`air_temp_f`") && e.contains("column_units"),
        "{e}"
    );
}

#[test]
fn units_and_selection_are_read_from_toml() {
    let text = "generic_selection = \"stepwise_cv\"\n[column_units]\nair_temp_f = \"degF\"\n";
    let cfg: CloseLoopConfig = toml::from_str(text).unwrap();
    assert_eq!(cfg.generic_selection, effects::Selection::StepwiseCv);
    assert_eq!(cfg.column_units["air_temp_f"], "degF");
    let e = toml::from_str::<CloseLoopConfig>("generic_selection = \"lasso\"\n").unwrap_err();
    assert!(e.to_string().contains("generic_selection"), "{e}");
}

/// The cross-validated selections (options, not the default) through the whole loop:
/// sun on three gauges (a half-wave daily cycle peaking at 13 h, 3-5 microstrain; the toy
/// record's air temperature is a pure daily sinusoid peaking elsewhere, plus a weekly cycle)
/// is named by a daily-periodic candidate, and the test-window error falls to within 15 % of
/// the noise (1 microstrain), as in the gate's feature tests.
///
/// Changed after it failed: the first version required a `daily*`/`semidaily*` name first. On
/// this record the air temperature is an exact daily sinusoid plus a weekly cycle, so its rate
/// `d_air_temp_f_per_h` is a daily harmonic too, and the selection took it with the 12 h
/// harmonics; the check now accepts either (the gate's feature tests, whose air temperature is
/// weather-like, keep the strict name check).
#[test]
fn stepwise_cv_names_sun_on_the_gauges_by_daily_harmonics() {
    sun_is_named_by_a_daily_candidate(effects::Selection::StepwiseCv);
}

/// The same record with the multi-task lasso (linfa's elastic net) path re-fitted per fold.
#[test]
fn group_lasso_cv_names_sun_on_the_gauges_by_daily_harmonics() {
    sun_is_named_by_a_daily_candidate(effects::Selection::GroupLassoCv);
}

fn sun_is_named_by_a_daily_candidate(selection: effects::Selection) {
    let amplitude = [0.0, 3.0, 0.0, -4.0, 5.0, 0.0, 0.0];
    let sun =
        |t: f64, g: usize| amplitude[g] * (std::f64::consts::TAU * (t - 7.0) / 24.0).sin().max(0.0);
    let rec = record_with(&ToyGate::default(), super::ROWS, 11, sun).unwrap();
    let cal = GridCalibrator::new(ToyGate::default(), (40.0, 200.0));
    let cfg = CloseLoopConfig {
        generic_selection: selection,
        ..super::config()
    };
    let r = close_loop(&rec, &cal, &cfg).unwrap().report;
    let names: Vec<_> = r
        .effects
        .iter()
        .flat_map(|e| e.covariates.clone())
        .collect();
    let daily = |c: &String| c.contains("daily") || c == "d_air_temp_f_per_h";
    assert!(names.iter().any(daily), "{:?}", r.effects);
    // the sun is visible in the test window before (else the bound below proves nothing)
    assert!(
        r.heldout_rmse_total_before > 1.15,
        "{}",
        r.heldout_rmse_total_before
    );
    assert!(
        r.heldout_rmse_total_after <= 1.15,
        "{}",
        r.heldout_rmse_total_after
    );
}
