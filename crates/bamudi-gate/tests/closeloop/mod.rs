//! Close-the-loop tests on simulated field records: the loop must name the effect the
//! simulator switched on (it is never told which), bring the held-out RMSE near the noise
//! level, move the gap estimate toward the truth, and add nothing to a clean record.

mod events;
mod fe_gate;
mod features;
mod scenarios;
mod track;

use bamudi_closeloop::testing::{GridCalibrator, ToyGate, toy_load};
use bamudi_closeloop::{
    CloseLoopConfig, CloseLoopOutcome, IngestConfig, MeasuredRecord, close_loop, parse_csv,
};
use mitergate::data::field::{FieldConfig, FieldEffects, FieldRecord, simulate};

/// Gap prior of the test calibrator (in), wide enough for every scenario.
pub const GAP_BOUNDS: (f64, f64) = (40.0, 200.0);

/// Simulates a record with the toy gate as the TRUE strain model.
pub fn record(cfg: FieldConfig) -> FieldRecord {
    let gate = ToyGate::default();
    simulate(&cfg, &|hu, hd, gap| gate.strain(hu, hd, gap)).unwrap()
}

/// The gate as built: influence lines 4 % stronger and local bending 6 % weaker on every gauge
/// than the drawing the loop calibrates (the truth of the as-built tests).
pub fn as_built() -> ToyGate {
    let mut truth = ToyGate::default();
    truth.influence.iter_mut().for_each(|v| *v *= 1.04);
    truth.local.iter_mut().for_each(|v| *v *= 0.94);
    truth
}

/// Runs the loop on the record's CSV text, exactly as measured data would be read.
pub fn run(rec: &FieldRecord) -> CloseLoopOutcome {
    let gauges: Vec<&str> = rec.gauge_names.iter().map(String::as_str).collect();
    let ingest = IngestConfig::new(&["h_up", "h_down"], &gauges);
    let data = parse_csv(&rec.to_csv_string(), "simulated.csv", &ingest).unwrap();
    let out = close_loop(
        &data,
        &GridCalibrator::new(ToyGate::default(), GAP_BOUNDS),
        &toy_config(&data),
    )
    .unwrap();
    // what the sensor pass did, for the reader of a failing test's output
    if let Some(s) = out.report.sensor.as_ref() {
        for f in &s.findings {
            eprintln!("  sensor finding: {}", f.describe());
        }
        for f in &s.coincident_findings {
            eprintln!(
                "  not applied (other gauges at the same time): {}",
                f.describe()
            );
        }
        for t in &s.attribution_tests {
            eprintln!(
                "  structure or sensor: {} from day {:.2}: {} (none {:.0}, structure {:.0}, {} {:.0} + {:.1})",
                t.subject,
                t.from_day,
                t.verdict,
                t.none,
                t.structure,
                t.sensor_hypothesis,
                t.sensor,
                t.penalty
            );
        }
    }
    out
}

/// Two months, hourly by default.
pub fn base(seed: u64, effects: FieldEffects) -> FieldConfig {
    FieldConfig::default().seed(seed).effects(effects)
}

/// The loop's settings for the gate-like test model: the head as the load, the gap as the
/// parameter and the field layout's column units (as `bamudi_gate::gate::close_loop_config`
/// sets them for the real gate).
pub fn toy_config(rec: &MeasuredRecord) -> CloseLoopConfig {
    let cfg = CloseLoopConfig::default()
        .load(toy_load())
        .parameter_name("gap")
        .output_unit("microstrain");
    bamudi_gate::gate::declare_field_units(cfg, rec)
}

/// Prints the loop's effects, test-window RMSE, gap and conclusion (for the closing notes).
pub fn summary(name: &str, out: &CloseLoopOutcome) {
    let r = &out.report;
    eprintln!(
        "{name}: effects {:?}; held-out rmse {:.3} -> {:.3}; theta {:.2}±{:.2} -> {:.2}±{:.2}; {}",
        r.effects
            .iter()
            .map(|e| (e.name.clone(), e.covariates.clone()))
            .collect::<Vec<_>>(),
        r.heldout_rmse_total_before,
        r.heldout_rmse_total_after,
        r.theta_before.mean,
        r.theta_before.sd,
        r.theta_after.mean,
        r.theta_after.sd,
        r.conclusion
    );
}
