//! The loop on the finite-element gate with the BA-MUDI calibrator (default gate, 24 in
//! elements; 60 days, a row every 2 hours; gap 90 in; 1 microstrain noise; prior U(60, 150) in),
//! on seed 5, not the documented demo's seed 2 (hourly, full-size calibrator: the README's FE
//! table). The loop is given the CSV text only: it is never told which effect the simulator
//! switched on.
//!
//! The record and the calibrator are half the library's default size so that the six records
//! take 4.6 min instead of about 13 (`record_config`, `test_calibrator`; the six alone on 2
//! cores, `cargo test -p bamudi-gate --test lib fe_gate`: 274.6 s). Before the change all six
//! passed at full size too; the bounds below were not changed with it.

use super::*;
use bamudi_closeloop::{Calibrator, EffectReport, MeasuredRecord, SensorKind};
use bamudi_gate::calibrator::GateCalibrator;
use bamudi_gate::gate;
use bamudi_gate::tolerance::ToleranceSpec;
use mitergate::data::field::OffsetJump;
use mitergate::{ContactModel, GateConfig};
use std::sync::OnceLock;

const NOISE: f64 = 1.0;
const TRUE_GAP: f64 = 90.0;
const SEED: u64 = 5;
/// Hours between the record's rows.
const ROW_HOURS: f64 = 2.0;

fn contact() -> &'static ContactModel {
    static C: OnceLock<ContactModel> = OnceLock::new();
    C.get_or_init(|| {
        let mut cfg = GateConfig::default();
        cfg.mesh.element_size = 24.0;
        gate::build(&cfg).unwrap().0
    })
}

/// The loop's calibrator at half the default size (120 rows per calibration, 121 `θ` grid
/// nodes; the library defaults are 240 and 241): each calibration costs a quarter of the
/// contact solves, which keeps these tests within CI time. The assertions do not depend on it:
/// the gap's posterior sd after the loop is 0.026 in at this size against 0.020 in at full
/// size (offset-jump record, measured), both far below the 0.5 in bound, and the grid's zoom
/// aims for 12 nodes in the posterior's mass at either size.
fn test_calibrator(c: &ContactModel) -> GateCalibrator {
    let cal = GateCalibrator::new(c.clone(), (60.0, 150.0)).unwrap();
    let params = cal.calibration_config().clone().into_params();
    let config = params.theta_grid_points(121).check().unwrap();
    cal.config(config).max_experiments(120)
}

/// The simulated record: 60 days, a row every [`ROW_HOURS`] (720 rows; the library default is
/// hourly). Each prediction of the loop costs a contact solve per row and support node, so
/// half the rows halve the loop's prediction cost.
fn record_config(seed: u64, fx: FieldEffects) -> FieldConfig {
    let mut cfg = FieldConfig::default().seed(seed).effects(fx);
    cfg.step_minutes = ROW_HOURS * 60.0;
    cfg
}

/// Simulates a record with the FE gate as the truth and runs the loop on its CSV text.
fn run_fe(preset: &str, seed: u64) -> CloseLoopOutcome {
    let fx = FieldEffects::default().with_preset(preset, 130.0).unwrap();
    run_fe_with(preset, fx, seed)
}

/// As [`run_fe`], with the simulator's effects given.
fn run_fe_with(preset: &str, fx: FieldEffects, seed: u64) -> CloseLoopOutcome {
    let c = contact();
    let rec = gate::simulate_field(&record_config(seed, fx), c).unwrap();
    run_loop_on(
        &rec,
        &test_calibrator(c),
        &format!("{preset} (seed {seed})"),
    )
}

/// The loop on the CSV text of `rec` with `calibrator`; prints its outcome under `label`.
fn run_loop_on(rec: &FieldRecord, calibrator: &GateCalibrator, label: &str) -> CloseLoopOutcome {
    let data = gate::as_measured(rec, calibrator.model(), "fe_gate.csv").unwrap();
    run_measured(&data, calibrator, label)
}

/// The loop on a measured record (the CSV text's reading), printing as [`run_loop_on`].
fn run_measured(
    data: &MeasuredRecord,
    calibrator: &GateCalibrator,
    label: &str,
) -> CloseLoopOutcome {
    let data = data.clone();
    let cfg = gate::close_loop_config(CloseLoopConfig::default(), &data);
    let out = close_loop(&data, calibrator, &cfg).unwrap();
    let r = &out.report;
    eprintln!(
        "FE {label}: {:?}; {}; held-out {:.3} -> {:.3}; gap {:.3} ± {:.3} -> {:.3} ± {:.3}",
        r.effects.iter().map(|e| &e.name).collect::<Vec<_>>(),
        r.conclusion,
        r.heldout_rmse_total_before,
        r.heldout_rmse_total_after,
        r.theta_before.mean,
        r.theta_before.sd,
        r.theta_after.mean,
        r.theta_after.sd,
    );
    if let (Some(t), Some(e)) = (&r.theta_track, &r.events) {
        eprintln!(
            "FE {label}: gap now from the track {:.3} ± {:.3}, change alarm {:?}; scan alarms {}",
            t.now.mean,
            t.now.sd,
            t.alarm,
            e.alarms.len()
        );
    }
    out
}

/// The loop's θ-only re-calibrations (`Calibrator::calibrate_theta`: the bootstrap draws of
/// θ's uncertainty and θ without the sensor corrections) skip the adequacy and physics checks
/// and the predictions; their θ summary must be the full calibration's, bit for bit (the
/// checks run after Module 3). On a record with an undeclared thermal strain, so that the
/// checks have something to find.
#[test]
fn fe_gate_theta_only_calibration_is_the_full_calibrations_theta() {
    let c = contact();
    let fx = FieldEffects::default()
        .with_preset("thermal", 130.0)
        .unwrap();
    let rec = gate::simulate_field(&record_config(SEED, fx), c).unwrap();
    let cal = test_calibrator(c);
    let data = gate::as_measured(&rec, cal.model(), "fe_gate.csv").unwrap();
    let rows = 0..data.x.nrows() / 2;
    let (x, y) = (
        data.x.rows_range(rows.clone()).into_owned(),
        data.y.rows_range(rows).into_owned(),
    );
    let full = cal.calibrate(&x, &y).unwrap();
    assert!(
        full.adequacy().is_some(),
        "the full calibration runs its checks"
    );
    let full = full.theta_summary();
    let only = cal.calibrate_theta(&x, &y).unwrap();
    assert_eq!(
        (
            full.mean.to_bits(),
            full.sd.to_bits(),
            full.ci95.0.to_bits(),
            full.ci95.1.to_bits()
        ),
        (
            only.mean.to_bits(),
            only.sd.to_bits(),
            only.ci95.0.to_bits(),
            only.ci95.1.to_bits()
        ),
        "{full:?} vs {only:?}"
    );
}

/// The bars for a record with one effect: the first accepted effect is `expected`
/// (checked by `names_it`), the held-out RMSE after is within 1.5x the noise, and the gap
/// ends closer to the truth than the first calibration put it, and within 0.5 in of it
/// (twenty posterior sds: 0.020 in at full size, 0.026 in at the tests' size; a tenth of the
/// +5 in bias that the effects cause before the loop).
fn assert_found(out: &CloseLoopOutcome, names_it: impl Fn(&EffectReport) -> bool) {
    let r = &out.report;
    let first = r.effects.first().expect("no effect accepted");
    assert!(names_it(first), "first effect accepted: {first:?}");
    assert!(
        r.heldout_rmse_total_after <= 1.5 * NOISE,
        "held-out RMSE {}",
        r.heldout_rmse_total_after
    );
    let (before, after) = (
        (r.theta_before.mean - TRUE_GAP).abs(),
        (r.theta_after.mean - TRUE_GAP).abs(),
    );
    assert!(
        after < 0.5 && after <= before,
        "gap {} -> {}",
        r.theta_before.mean,
        r.theta_after.mean
    );
}

/// The values of the effect's parameter whose name starts with `prefix`.
fn param<'a>(e: &'a EffectReport, prefix: &str) -> &'a [f64] {
    let p = e.parameters.iter().find(|p| p.name.starts_with(prefix));
    &p.unwrap_or_else(|| panic!("no parameter {prefix} in {e:?}"))
        .values
}

#[test]
fn fe_gate_clean_record_gets_no_effect_and_the_true_gap() {
    let out = run_fe("none", SEED);
    let r = &out.report;
    assert!(r.effects.is_empty(), "spurious effects: {:?}", r.effects);
    // the model is the truth here: held-out error at the noise level (1.5x: the bar)
    assert!(r.heldout_rmse_total_after <= 1.5 * NOISE);
    // 0.5 in: about twenty posterior sds (0.026 in measured), a tenth of the +5 in bias the paper's
    // prior-marginal coefficients gave on this gate
    assert!((r.theta_after.mean - TRUE_GAP).abs() < 0.5);
    // nothing changed in this record: no gauge and no gap alarm (stop 30 measured none on
    // this seed; the toy-gate clean records bound the rate, 0 of 20)
    assert!(r.alarms.is_empty(), "false alarms: {:?}", r.alarms);
}

/// An event in the newest data, after the calibration window (the first 60 % of 60 days):
/// gauge 6 re-zeroed by −6 microstrain 2.7 days before the end. The loop cannot fit it; the
/// whole-record scan must raise it on that gauge only, its 95 % onset interval must hold the
/// hour of the step and its 95 % size interval −6, and the conclusion must name the gauge.
#[test]
fn fe_gate_an_event_in_the_last_days_is_an_alarm() {
    let (gauge, at_day, size) = (5, 57.3, -6.0);
    let fx = FieldEffects {
        offset_jump: Some(OffsetJump {
            gauge,
            at_day,
            size_microstrain: size,
        }),
        ..Default::default()
    };
    let out = run_fe_with("late re-zero", fx, SEED);
    let r = &out.report;
    let name = &r.gauge_names[gauge];
    let alarms = &r.events.as_ref().expect("the scan runs by default").alarms;
    eprintln!("late re-zero alarms: {alarms:?}");
    assert!(alarms.iter().all(|a| &a.gauge == name), "{alarms:?}");
    // the step falls between the rows at 1374 h and 1376 h (a row every ROW_HOURS)
    let (before, after) = (
        (at_day * 24.0 / ROW_HOURS).floor() * ROW_HOURS / 24.0,
        (at_day * 24.0 / ROW_HOURS).ceil() * ROW_HOURS / 24.0,
    );
    let a = alarms
        .iter()
        .find(|a| a.onset_day_interval.0 <= after && before <= a.onset_day_interval.1)
        .unwrap_or_else(|| panic!("no alarm dated at day {at_day}: {alarms:?}"));
    assert!(
        a.size_interval.0 <= size && size <= a.size_interval.1,
        "{a:?}"
    );
    // `Test` (was `Heldout`): the alarm labels now follow the test window (from day 48)
    assert_eq!(a.window, bamudi_closeloop::AlarmWindow::Test);
    assert!(
        !r.conclusion.starts_with("no missing effect"),
        "{}",
        r.conclusion
    );
    assert!(r.conclusion.contains(name.as_str()), "{}", r.conclusion);
}

#[test]
fn fe_gate_names_an_offset_jump() {
    let out = run_fe("offset-jump", SEED);
    assert_found(&out, |e| e.name == "gauge_offset_jump");
    // the simulated step: +20 microstrain on gauge 3 at day 15; the step time is located to
    // within a day (2-hourly rows, 1 microstrain noise against a 20 microstrain step)
    let e = &out.report.effects[0];
    let (day, size) = (param(e, "jump_day"), param(e, "jump_size"));
    assert!((day[2] - 15.0).abs() < 1.0, "jump days {day:?}");
    assert!((size[2] - 20.0).abs() < 1.0, "jump sizes {size:?}");
}

#[test]
fn fe_gate_names_thermal_strain() {
    let out = run_fe("thermal", SEED);
    assert_found(&out, |e| e.name == "thermal(air_temp_f)");
    // simulated: 6 h lag, 0.6-2 microstrain/°F; the lag to 1 h, the coefficients to 0.1
    // microstrain/°F (a 40 °F temperature swing against 1 microstrain of noise)
    let e = &out.report.effects[0];
    let lag = param(e, "lag");
    assert!((lag[0] - 6.0).abs() < 1.0, "lag {lag:?}");
    let coef = param(e, "coefficient");
    for (got, want) in coef.iter().zip([1.5, -1.0, 2.0, 0.8, -1.2, 1.0, 0.6]) {
        assert!((got - want).abs() < 0.1, "coefficients {coef:?}");
    }
}

#[test]
fn fe_gate_names_gauge_drift() {
    let out = run_fe("drift", SEED);
    assert_found(&out, |e| e.name == "gauge_drift");
}

#[test]
fn fe_gate_names_the_undeclared_effect_by_its_covariate() {
    // lock-wall flexure driven by the upper pool is not in the loop's library: the generic
    // term must find it and name the upper pool among its covariates
    let out = run_fe("wall-flexure", SEED);
    assert_found(&out, |e| {
        e.name == "generic_covariate_term" && e.covariates.iter().any(|c| c == "upper_pool")
    });
}

/// A clean FE record (no simulated effect) whose readings a wiring or logger fault then
/// changes: `fault` edits the measured readings (rows × gauges, microstrain) in place.
fn run_with_sensor_fault(
    label: &str,
    seed: u64,
    fault: impl Fn(&mut nalgebra::DMatrix<f64>, &[f64]),
) -> CloseLoopOutcome {
    let c = contact();
    let calibrator = test_calibrator(c);
    let rec = gate::simulate_field(&record_config(seed, FieldEffects::default()), c).unwrap();
    let mut data = gate::as_measured(&rec, calibrator.model(), "fe_gate.csv").unwrap();
    fault(&mut data.y, &data.time_h);
    let out = run_measured(&data, &calibrator, label);
    if let Some(s) = &out.report.sensor {
        eprintln!(
            "FE {label}: sensor {:?}; tests {:?}",
            s.findings, s.attribution_tests
        );
    }
    if let Some(a) = &out.report.model_adequacy_before {
        let top: Vec<String> = a
            .sensor_faults
            .iter()
            .filter(|f| f.z.abs() > 2.0)
            .map(|f| format!("{} {} z {:.1}", f.gauge, f.kind.name(), f.z))
            .collect();
        eprintln!(
            "FE {label}: verdict {:?}; sensor signatures |z| > 2: {top:?}",
            a.verdict
        );
    }
    out
}

fn holds_true_gap(r: &bamudi_closeloop::CloseLoopReport) -> bool {
    r.theta_after.ci95.0 <= TRUE_GAP && TRUE_GAP <= r.theta_after.ci95.1
}

/// Issue 58's first case: gauge 3 reads high over the whole record (a gauge factor entered
/// wrong), a fault the effect library does not hold. Under the default prior (issue 57) the
/// discrepancy absorbs a gain on one gauge: the calibration's verdict does not attribute it
/// (measured, seed 7: gain signature z 2.6 at +4 %, 2.3 at +10 %, the verdict adequate; at +20 %
/// inadequate by leave-one-gauge-out on g3, unattributed), so the loop has no finding to
/// correct. What must hold is that the answer stays honest: the gap's 95 % interval holds
/// 90 in at every size, and the held-out error stays at the noise (1.5x, the bar).
/// Measured: 90.18 ± 0.56, 89.95 ± 0.69, 89.86 ± 0.90 in against 90.02 ± 0.11 in on a clean
/// record; the loss of precision, not a wrong gap, is the fault's cost. Seed 7: no seed of
/// this file's other tests, and nothing in the sensor pass was set on it.
#[test]
fn fe_gate_a_gain_fault_leaves_the_gap_honest() {
    for gain in [1.04, 1.10] {
        let out = run_with_sensor_fault(&format!("gain x{gain} on g3"), 7, |y, _| {
            y.column_mut(2).scale_mut(gain);
        });
        let r = &out.report;
        assert!(holds_true_gap(r), "gain {gain}: {:?}", r.theta_after);
        assert!(
            r.heldout_rmse_total_after <= 1.5 * NOISE,
            "gain {gain}: {}",
            r.heldout_rmse_total_after
        );
        // a gain the verdict attributes is corrected, never left standing
        let attributed = r
            .model_adequacy_before
            .as_ref()
            .and_then(|a| a.sensor_correction.as_ref())
            .is_some_and(|c| c.faults.iter().any(|f| f.kind.name() == "gain"));
        let corrected = r
            .sensor
            .as_ref()
            .is_some_and(|s| s.findings.iter().any(|f| f.kind == SensorKind::Gain));
        assert_eq!(attributed, corrected, "gain {gain}: {:?}", r.sensor);
    }
}

/// Issue 58's second case: gauges 2 and 5 exchanged from day 50 (in the test window: the
/// calibration window is the first 60 % of the 60 days), a change purely in the wiring. The
/// loop must name the pair and the day, undo it, hold the gap, and raise no gap alarm.
#[test]
fn fe_gate_a_channel_exchange_is_undone_without_a_gap_alarm() {
    let at_day = 50.0;
    let out = run_with_sensor_fault("g2<->g5 from day 50", 8, |y, t| {
        for i in (0..y.nrows()).filter(|&i| t[i] / 24.0 >= at_day) {
            y.swap((i, 1), (i, 4));
        }
    });
    let r = &out.report;
    let s = r.sensor.as_ref().expect("the sensor pass runs by default");
    let f = s
        .findings
        .iter()
        .find(|f| f.kind == SensorKind::ChannelExchange)
        .unwrap_or_else(|| panic!("no exchange found: {:?}", s.findings));
    assert_eq!(f.gauge_columns, vec![1, 4]);
    // dated within a row of day 50 (a row every 2 hours)
    assert!(
        (f.from_day - at_day).abs() <= ROW_HOURS / 24.0 + 1e-9,
        "{}",
        f.from_day
    );
    assert!(
        r.alarms.iter().all(|a| a.subject != "parameter"),
        "gap alarm for a wiring change: {:?}",
        r.alarms
    );
    assert!(holds_true_gap(r), "{:?}", r.theta_after);
}

/// The drawing with its skin plate `factor` x as thick, built and condensed as [`contact`].
fn skin_scaled(factor: f64) -> (GateConfig, ContactModel) {
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = 24.0;
    let drawing = cfg.clone();
    cfg.skin_plate.thickness *= factor;
    (drawing, gate::build(&cfg).unwrap().0)
}

/// The loop on a record from a gate whose skin plate is `factor` x as thick as drawn (no effect
/// switched on; seed [`SEED`]), its calibrator on the drawing, with the skin declared to a
/// relative sd of 3 % when `declared`.
fn thin_skin_loop(factor: f64, declared: bool) -> CloseLoopOutcome {
    let (drawing, thin) = skin_scaled(factor);
    let rec = gate::simulate_field(&record_config(SEED, FieldEffects::default()), &thin).unwrap();
    let skin = ToleranceSpec {
        key: "skin_plate.thickness".into(),
        relative_sd: 0.03,
    };
    let mut calibrator = test_calibrator(contact());
    if declared {
        calibrator = calibrator
            .tolerances(std::slice::from_ref(&skin), &drawing)
            .unwrap();
    }
    run_loop_on(
        &rec,
        &calibrator,
        &format!("skin x {factor} (declared: {declared})"),
    )
}

/// The loop on as-built gates it is told the tolerance of ([`thin_skin_loop`]): skins 5 % and
/// 10 % thinner than drawn, declared to 3 % (the truths −1.67 and −3.3 sd). Every calibration
/// integrates the deviation out and every prediction carries it, so the loop must accept no
/// effect, the gap must end within 0.5 in of the truth (the clean record's bound) and its 95 %
/// interval (mean ± 1.96 sd) must hold it; so must the 95 % interval of the gap now from the
/// track over the whole record.
///
/// The track's interval failed before its levels were anchored on the calibration's
/// posterior: 90.135 ± 0.023 and 90.074 ± 0.023 in (6 and 3 sd from the truth; without the
/// declaration 89.337 ± 0.022 in, 30 sd). Anchored: 90.074 ± 0.226 and 90.139 ± 0.369 in
/// (without the declaration 90.200 ± 0.410 and 89.346 ± 0.624 in).
///
/// Measured when written (`cargo test -p bamudi-gate --test lib _skin -- --include-ignored
/// --nocapture`), gap after the loop, declared against not (`the_loop_without_the_skin_tolerance`;
/// no effect accepted either way — the discrepancy absorbs a static deviation):
/// 5 % thinner 90.091 ± 0.225 in against 90.217 ± 0.409 in; 10 % thinner 90.156 ± 0.368 in
/// against 89.364 ± 0.624 in, which misses the 0.5-in bound.
///
/// **Bound loosened for the 10 % skin after it failed** (issue 57's default prior: isotropic,
/// zero-mean): 5 % thinner 90.282 ± 0.422 in (within 0.5), 10 % thinner 91.078 ± 0.729 in,
/// 1.08 in off but 1.5 sd, inside its 95 % interval. The new prior's θ intervals are the
/// calibrated ones (SBC, `docs/results/validation.md`) and wider than the previous default's;
/// with the truth 3.3 declared sds out, a point within 0.5 in is more than its own interval
/// claims. The 10 % case now asserts the interval holds the truth *and* resolves the gap to
/// an sd ≤ 1 in (a prior-wide interval cannot pass), with the point within 1.5 in (about 2 of
/// its sds); the 5 % case keeps 0.5 in. The declaration still decides the answer: without it
/// (same records, `the_loop_without_the_skin_tolerance`) the first calibration's gap is
/// 92.231 ± 0.591 and 93.038 ± 0.982 in, both intervals missing 90, with the verdict
/// INADEQUATE (a gain on SG6); the sensor pass then corrects that gain (+4.6 ± 1.0 % and
/// +8.8 ± 1.5 %) and the gap reads 90.888 ± 0.596 and 91.079 ± 0.906 in (both holding 90):
/// an honest gap, the wrong mechanism (the finding's evidence says a local deviation of the
/// structure looks the same).
#[test]
fn fe_gate_with_a_declared_tolerance_reads_an_as_built_skin() {
    for (factor, point_bound) in [(0.95, 0.5), (0.90, 1.5)] {
        let out = thin_skin_loop(factor, true);
        let r = &out.report;
        assert!(r.effects.is_empty(), "spurious effects: {:?}", r.effects);
        let (mean, sd) = (r.theta_after.mean, r.theta_after.sd);
        assert!(
            (mean - TRUE_GAP).abs() < point_bound,
            "skin x {factor}: gap {mean}"
        );
        assert!(
            sd <= 1.0,
            "skin x {factor}: gap sd {sd} in resolves nothing"
        );
        assert!(
            (mean - TRUE_GAP).abs() <= 1.96 * sd,
            "skin x {factor}: gap {mean} ± {sd}"
        );
        let now = r
            .theta_track
            .as_ref()
            .expect("the track runs by default")
            .now;
        assert!(
            (now.mean - TRUE_GAP).abs() <= 1.96 * now.sd,
            "skin x {factor}: gap now from the track {} ± {}",
            now.mean,
            now.sd
        );
        assert_reports_the_skin_reading(&out, factor);
    }
}

/// `report.md` and `results.json` give what the loop's final calibration read of the skin
/// plate, in its declared sds (truth `(factor − 1) / 0.03`), and its 95 % interval holds it.
fn assert_reports_the_skin_reading(out: &CloseLoopOutcome, factor: f64) {
    let dir = std::env::temp_dir().join(format!(
        "bamudi_skin_report_{}_{factor}",
        std::process::id()
    ));
    bamudi_gate::report::closeloop::write_report(out, None, None, &dir).unwrap();
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("## Declared tolerances") && md.contains("`skin_plate.thickness`"));
    let js: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    let t = &js["tolerances"][0];
    let (mean, sd) = (t["mean"].as_f64().unwrap(), t["sd"].as_f64().unwrap());
    let truth = (factor - 1.0) / 0.03;
    eprintln!("skin x {factor}: read {mean:+.2} ± {sd:.2} sd (truth {truth:+.2})");
    assert_eq!(t["name"], "skin_plate.thickness");
    assert!(
        (mean - truth).abs() <= 1.96 * sd,
        "skin x {factor}: read {mean} ± {sd} sd, truth {truth}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The reference of [`fe_gate_with_a_declared_tolerance_reads_an_as_built_skin`]: the same
/// records without the declaration (a measurement, printed; not run in CI).
#[test]
#[ignore = "a measurement for the documentation, not a check"]
fn the_loop_without_the_skin_tolerance() {
    for factor in [0.95, 0.90] {
        thin_skin_loop(factor, false);
    }
}

/// Issue 58 on a gate that is not the calibration's model: the skin plate 5 % thinner than
/// drawn, declared to 3 % (as in [`fe_gate_with_a_declared_tolerance_reads_an_as_built_skin`]),
/// and gauges 2 and 6 exchanged from day 45 (seed 9; no seed, pair or day of the other sensor
/// tests). The sensor pass's tests score the change against the calibrated model's
/// sensitivities, which are the drawing's, not the gate's. Checked (bounds set before the
/// first run): the exchange is named on that pair within a row of day 45, no gap alarm fires,
/// and the gap's 95 % interval holds 90 in.
#[test]
fn fe_gate_an_exchange_on_an_as_built_gate_is_undone_without_a_gap_alarm() {
    let (drawing, thin) = skin_scaled(0.95);
    let rec = gate::simulate_field(&record_config(9, FieldEffects::default()), &thin).unwrap();
    let skin = ToleranceSpec {
        key: "skin_plate.thickness".into(),
        relative_sd: 0.03,
    };
    let calibrator = test_calibrator(contact())
        .tolerances(std::slice::from_ref(&skin), &drawing)
        .unwrap();
    let mut data = gate::as_measured(&rec, calibrator.model(), "fe_gate.csv").unwrap();
    let at_day = 45.0;
    for i in (0..data.len()).filter(|&i| data.time_h[i] / 24.0 >= at_day) {
        data.y.swap((i, 1), (i, 5));
    }
    let out = run_measured(
        &data,
        &calibrator,
        "as-built skin x 0.95, g2<->g6 from day 45",
    );
    let r = &out.report;
    let s = r.sensor.as_ref().expect("the sensor pass runs by default");
    eprintln!("findings {:?}; tests {:?}", s.findings, s.attribution_tests);
    let f = s
        .findings
        .iter()
        .find(|f| f.kind == SensorKind::ChannelExchange)
        .unwrap_or_else(|| panic!("no exchange found: {:?}", s.findings));
    assert_eq!(f.gauge_columns, vec![1, 5]);
    assert!(
        (f.from_day - at_day).abs() <= ROW_HOURS / 24.0 + 1e-9,
        "{}",
        f.from_day
    );
    assert!(
        r.alarms.iter().all(|a| a.subject != "parameter"),
        "gap alarm for a wiring change: {:?}",
        r.alarms
    );
    assert!(holds_true_gap(r), "{:?}", r.theta_after);
}

/// Gauges 2 and 5 exchanged from day 30, inside the calibration window (days 0-36): the first
/// calibration is fitted to six exchanged days, so its residual misreads the exchange. The
/// close-loop panel's seed 1002 took such an exchange for a gain of -0.48 on SG5 and the gap
/// came out 60.5 ± 5.1 in for 90. Seeds 10 and 12 are the two of the four probed (10-13, no
/// other test's) on which the fixes of that failure change the outcome; each must now hold:
/// the exchange named on that pair within a row of day 30 and no other finding, no gap alarm,
/// and the gap's 95 % interval holds 90 in.
/// * seed 12: the structure-or-sensor test prefers an SG3 gain against the first calibration;
///   the exchange and that gain are re-calibrated and compared by log evidence, and the
///   exchange wins (checked with that re-calibration switched off: the exchange dropped, gains
///   of -0.028 on SG3 and -0.093 on SG5 corrected instead, a time-varying gap and four more
///   effects added, and this test fails);
/// * seed 10: the test confirms the exchange, but the scans after it read the first
///   calibration's residual, whose absorbed exchanged days showed as gain changes on SG1, SG3
///   and SG4 (four false findings before the fix); they now read a calibration on the
///   relabelled readings.
#[test]
fn fe_gate_an_exchange_inside_the_calibration_window_is_not_taken_for_a_gain() {
    let at_day = 30.0;
    for seed in [10u64, 12] {
        let out = run_with_sensor_fault(
            &format!("g2<->g5 from day 30, seed {seed}"),
            seed,
            |y, t| {
                for i in (0..y.nrows()).filter(|&i| t[i] / 24.0 >= at_day) {
                    y.swap((i, 1), (i, 4));
                }
            },
        );
        let r = &out.report;
        let s = r.sensor.as_ref().expect("the sensor pass runs by default");
        let [f] = s.findings.as_slice() else {
            panic!("seed {seed}: one finding expected: {:?}", s.findings);
        };
        assert_eq!(
            (f.kind, f.gauge_columns.as_slice()),
            (SensorKind::ChannelExchange, [1, 4].as_slice()),
            "seed {seed}"
        );
        // seed 12 through the contest by re-calibration, seed 10 through the test
        let route = match seed {
            12 => "exchange scan, re-calibrated",
            _ => "structure-or-sensor test",
        };
        assert_eq!(f.source, route, "seed {seed}: {}", f.evidence);
        // dated within a row of day 30 (a row every 2 hours)
        assert!(
            (f.from_day - at_day).abs() <= ROW_HOURS / 24.0 + 1e-9,
            "seed {seed}: {}",
            f.from_day
        );
        assert!(
            r.alarms.iter().all(|a| a.subject != "parameter"),
            "seed {seed}: gap alarm for a wiring change: {:?}",
            r.alarms
        );
        assert!(holds_true_gap(r), "seed {seed}: {:?}", r.theta_after);
    }
}

/// The close-loop panel's record of seed 1004 (hourly rows, the library's calibrator at full
/// size, the FE gate at the 24-in mesh) with SG3's readings 10 % high from day 30, inside the
/// calibration window (days 0-36). The first calibration learns days 30-36 of it, and the scans
/// dated the gain from day 35.75 and sized it +0.067; a gauge drift was added beside it and
/// the track raised a gap alarm (error 1.82x the noise). The finding is now dated again
/// against a calibration on the window's days before 25.75 and decided by re-calibration: it
/// must be the one finding, dated within a day of day 30 through that route, sized within 4 of
/// its sds of +0.10, with no gap alarm and the gap's 95 % interval holding 90 in. The same
/// dating on this file's 2-hour records at the half-size calibrator (seeds 10-17, 1004, 1005 and 2004 probed)
/// finds the day without help, so only the panel's record shows the route; at 30-40 s it is
/// left out of CI's run (`cargo test -p bamudi-gate --release --test lib -- --ignored`).
#[test]
#[ignore = "the panel's hourly record at full size: 30-40 s, outside CI's time"]
fn fe_gate_a_gain_the_first_calibration_learnt_is_dated_from_its_day() {
    let out = run_panel_record(1004, "panel seed 1004, SG3 +10 % from day 30", |y, t| {
        for i in (0..y.nrows()).filter(|&i| t[i] / 24.0 >= 30.0) {
            y[(i, 2)] *= 1.10;
        }
    });
    let f = the_one_finding(&out, SensorKind::Gain, 2);
    assert!(f.evidence.contains("dated again"), "{}", f.evidence);
    assert!((f.from_day - 30.0).abs() <= 1.0, "{}", f.from_day);
    let (k, sd) = (f.size.unwrap(), f.size_sd.unwrap());
    assert!((k - 0.10).abs() <= 4.0 * sd, "{k} ± {sd}");
    assert!(out.report.effects.is_empty(), "{:?}", out.report.effects);
}

/// The panel's seed 1000 with the gap stepping from 90 to 110 in on day 5, inside the 36-day
/// calibration window (the panel's `gap-step`, large, early: its design record). The first run
/// dated the step (4.58) and reported the track's gap, 110.21 ± 2.27 in, but its calibration
/// had read both gaps as one (107.46 in) and the test window's error was 3.88x the noise. The
/// loop must now calibrate again on the rows after the step: the gap within its interval and
/// within 0.3 in of 110 (the second run's gap was 110.02 ± 0.04), the test window within 1.5x
/// the noise (the panel's bound), and the gap's alarm standing. About a minute: out of CI's
/// run, as the tests above.
#[test]
#[ignore = "the panel's hourly record at full size, run twice: about a minute, outside CI's time"]
fn fe_gate_a_gap_step_inside_the_window_is_calibrated_after() {
    let out = run_gap_step(1000, 5.0, 110.0);
    assert_calibrated_after(&out, 5.0, 110.0);
}

/// The panel's seed 1004 with the gap stepping from 90 to 110 in on day 30, six days before the
/// calibration window's end (the panel's `gap-step`, large, middle). The first calibration
/// reads the new gap through a discrepancy fitted to both: its track swung between 96 and 112
/// in over the window's last six days, so its level did not stay put after the step and the
/// loop ran once (error 8.51x the noise, gap 114.8 ± 5.0 in). The run calibrated after the
/// step is now judged by its own track. The same bounds as the step from day 5 above. A
/// design record of that rule, as seed 1003's 8-in step from day 30 (the held-out figures are
/// in docs/closeloop.md).
#[test]
#[ignore = "the panel's hourly record at full size, run twice: about two minutes, outside CI's time"]
fn fe_gate_a_late_gap_step_whose_first_track_swings_is_calibrated_after() {
    let out = run_gap_step(1004, 30.0, 110.0);
    assert_calibrated_after(&out, 30.0, 110.0);
}

/// The panel's record of `seed` with the gap stepping from 90 in to `to` on day `day`: each row
/// from then on gets the strain difference of the contact solved at the two gaps.
fn run_gap_step(seed: u64, day: f64, to: f64) -> CloseLoopOutcome {
    let c = contact();
    let label = format!("panel seed {seed}, gap 90 -> {to} from day {day}");
    run_panel_record_with(seed, &label, |d| {
        for i in (0..d.len()).filter(|&i| d.time_h[i] / 24.0 >= day) {
            let (hu, hd) = (d.x[(i, 0)], d.x[(i, 1)]);
            let strain = |gap: f64| {
                let sol = c.solve(hu, hd, gap).unwrap();
                c.gate().strain(&sol.forces, hu, hd)
            };
            let (s1, s0) = (strain(to), strain(90.0));
            for g in 0..d.y.ncols() {
                d.y[(i, g)] += s1[g] - s0[g];
            }
        }
    })
}

/// The loop calibrated again after the step of `day`: the gap within its interval and within
/// 0.3 in of `to`, the test window within 1.5x the noise (the panel's bound), and the gap's
/// alarm standing.
fn assert_calibrated_after(out: &CloseLoopOutcome, day: f64, to: f64) {
    let r = &out.report;
    let a = r
        .after_step
        .as_ref()
        .unwrap_or_else(|| panic!("not calibrated after the step: {}", r.conclusion));
    assert!((a.step_day - day).abs() <= 1.0, "step day {}", a.step_day);
    let t = &r.theta_after;
    assert!(t.ci95.0 <= to && to <= t.ci95.1, "{t:?}");
    assert!((t.mean - to).abs() <= 0.3, "{t:?}");
    let noise = r.noise_sd_estimate;
    assert!(
        r.heldout_rmse_total_after <= 1.5 * noise,
        "{} against noise {noise}",
        r.heldout_rmse_total_after
    );
    assert!(
        r.alarms.iter().any(|a| a.subject == "parameter"),
        "{:?}",
        r.alarms
    );
}

/// The close-loop panel's hourly record of `seed` at full size with `fault` written in, run
/// through the loop (the panel's `prepare` and `one`, without the scoring).
fn run_panel_record(
    seed: u64,
    label: &str,
    fault: impl Fn(&mut nalgebra::DMatrix<f64>, &[f64]),
) -> CloseLoopOutcome {
    run_panel_record_with(seed, label, |d| fault(&mut d.y, &d.time_h))
}

/// [`run_panel_record`] with `fault` given the whole record (the water levels too).
fn run_panel_record_with(
    seed: u64,
    label: &str,
    fault: impl Fn(&mut MeasuredRecord),
) -> CloseLoopOutcome {
    let c = contact();
    let fc = FieldConfig::default().seed(seed).duration(60.0, 60.0);
    let rec = gate::simulate_field(&fc, c).unwrap();
    let calibrator = GateCalibrator::new(c.clone(), (60.0, 150.0)).unwrap();
    let mut data = gate::as_measured(&rec, calibrator.model(), "panel.csv").unwrap();
    fault(&mut data);
    run_measured(&data, &calibrator, label)
}

/// The panel's seed 1003 with SG4 stuck from day 30, inside the calibration window: the first
/// calibration fitted six frozen days, and where the inputs return (day 57) what it learnt moved
/// SG1's prediction; the gain scan read that as a gain of −0.228 on SG1 from day 57, confirmed,
/// and the test error was 3.3x the noise. The scans after the stuck scan now read a calibration
/// on the window's rows free of the set-aside cells: the stuck gauge must be the one finding,
/// with no gap alarm and the gap's interval holding 90 in. And with SG3 10 % high from day 30
/// on the same record: SG3's gain must be the one finding (two opposite gains of ±0.042 on
/// SG2 from day 57 beside it before, read against the first calibration that had learnt six
/// days of SG3's gain; they are now tested again on a calibration with SG3 corrected). 20-30 s
/// each: out of CI's run, as the test above.
#[test]
#[ignore = "the panel's hourly records at full size: about a minute, outside CI's time"]
fn fe_gate_a_fault_the_first_calibration_fitted_moves_no_other_gauge() {
    let out = run_panel_record(1003, "panel seed 1003, SG4 stuck from day 30", |y, t| {
        let first = t.iter().position(|&h| h / 24.0 >= 30.0).unwrap();
        let v = y[(first - 1, 3)];
        for i in first..y.nrows() {
            y[(i, 3)] = v;
        }
    });
    the_one_finding(&out, SensorKind::Stuck, 3);
    let out = run_panel_record(1003, "panel seed 1003, SG3 +10 % from day 30", |y, t| {
        for i in (0..y.nrows()).filter(|&i| t[i] / 24.0 >= 30.0) {
            y[(i, 2)] *= 1.10;
        }
    });
    the_one_finding(&out, SensorKind::Gain, 2);
}

/// The report's one sensor finding, which must be of `kind` on gauge column `g`, with no gap
/// alarm and the gap's 95 % interval holding the truth.
fn the_one_finding(
    out: &CloseLoopOutcome,
    kind: SensorKind,
    g: usize,
) -> &bamudi_closeloop::SensorFinding {
    let r = &out.report;
    let s = r.sensor.as_ref().expect("the sensor pass runs by default");
    let [f] = s.findings.as_slice() else {
        panic!("one finding expected: {:?}", s.findings);
    };
    assert_eq!((f.kind, f.gauge_columns.as_slice()), (kind, [g].as_slice()));
    assert!(
        r.alarms.iter().all(|a| a.subject != "parameter"),
        "gap alarm for a sensor fault: {:?}",
        r.alarms
    );
    assert!(holds_true_gap(r), "{:?}", r.theta_after);
    f
}
