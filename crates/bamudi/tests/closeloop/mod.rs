//! Close-the-loop tests on simulated field records: the loop must name the effect the
//! simulator switched on (it is never told which), bring the held-out RMSE near the noise
//! level, move the gap estimate toward the truth, and add nothing to a clean record.

mod fe_gate;
mod ingest;
mod scenarios;

use bamudi::closeloop::reference::{GridCalibrator, ToyGate};
use bamudi::closeloop::{CloseLoopConfig, CloseLoopOutcome, IngestConfig, close_loop, parse_csv};
use mitergate::field::{FieldConfig, FieldEffects, FieldRecord, simulate};

/// Gap prior of the test calibrator (in), wide enough for every scenario.
pub const GAP_BOUNDS: (f64, f64) = (40.0, 200.0);

/// Simulates a record with the toy gate as the TRUE strain model.
pub fn record(cfg: FieldConfig) -> FieldRecord {
    let gate = ToyGate::default();
    simulate(&cfg, &|hu, hd, gap| gate.strain(hu, hd, gap)).unwrap()
}

/// Runs the loop on the record's CSV text, exactly as measured data would be read.
pub fn run(rec: &FieldRecord) -> CloseLoopOutcome {
    let data = parse_csv(
        &rec.to_csv_string(),
        "simulated.csv",
        &IngestConfig::new(rec.gauge_names.clone()),
    )
    .unwrap();
    close_loop(
        &data,
        &GridCalibrator::new(ToyGate::default(), GAP_BOUNDS),
        &CloseLoopConfig::default(),
    )
    .unwrap()
}

/// Two months, hourly by default.
pub fn base(seed: u64, effects: FieldEffects) -> FieldConfig {
    FieldConfig::default().seed(seed).effects(effects)
}
