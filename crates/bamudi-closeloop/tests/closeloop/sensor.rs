//! Sensor faults made corrections, and the structure-or-sensor test that guards the gap alarm
//! (issue 58), on the toy gate (45 days hourly, gap 90 in, noise 1 microstrain). The faults are
//! written into the readings after the record is made, in shapes the loop's effect library
//! does not hold. Nothing in the sensor pass was tuned on these records: its penalties are the
//! event scan's modified BIC (`3 ln n`) and `2 ln m` for a choice among `m` hypotheses, set
//! before any of them was run.

use super::{GAP_BOUNDS, ROWS, config};
use bamudi_closeloop::testing::{GridCalibrator, ToyGate, record_with};
use bamudi_closeloop::{CloseLoopReport, MeasuredRecord, SensorAction, SensorKind, close_loop};

fn loop_on(rec: &MeasuredRecord) -> CloseLoopReport {
    let cal = GridCalibrator::new(ToyGate::default(), GAP_BOUNDS);
    close_loop(rec, &cal, &config()).unwrap().report
}

fn gap_alarm(r: &CloseLoopReport) -> bool {
    r.alarms.iter().any(|a| a.subject == "parameter")
}

fn holds(r: &CloseLoopReport, truth: f64) -> bool {
    r.theta_after.ci95.0 <= truth && truth <= r.theta_after.ci95.1
}

/// Two channels exchanged (g2 and g5), once in the calibration window (hour 400) and once in
/// the newest data (hour 900, in the test window): the exchange is named with its pair and its
/// hour, undone, the gap holds 90 in, and no gap alarm fires for a change of wiring.
#[test]
fn a_channel_exchange_is_undone_and_raises_no_gap_alarm() {
    for (seed, at) in [(31u64, 400usize), (32, 900)] {
        let mut rec = record_with(&ToyGate::default(), ROWS, seed, |_, _| 0.0).unwrap();
        for i in at..ROWS {
            rec.y.swap((i, 1), (i, 4));
        }
        let r = loop_on(&rec);
        let s = r.sensor.as_ref().expect("the sensor pass runs by default");
        eprintln!("exchange at {at}: {:?}\n{}", s.findings, r.conclusion);
        let f = s
            .findings
            .iter()
            .find(|f| f.kind == SensorKind::ChannelExchange)
            .unwrap_or_else(|| panic!("no exchange found: {:?}", s.findings));
        assert_eq!(f.gauges, vec!["g2", "g5"]);
        assert!(f.from_row.abs_diff(at) <= 2, "onset row {}", f.from_row);
        assert!(
            !gap_alarm(&r),
            "gap alarm for a wiring change: {:?}",
            r.alarms
        );
        assert!(holds(&r, 90.0), "{:?}", r.theta_after);
        // the error with every correction. Both exchanges run into the test window and the
        // exchange scan reads every row, so the report must say that the error after is not
        // fully out of sample (`fitted_on_test_rows`); the first version of this test expected
        // it only for the exchange that starts in the test window, which understated the leak
        let all = s.heldout_rmse_after_all_corrections.as_ref().unwrap();
        let total = (all.iter().map(|v| v * v).sum::<f64>() / all.len() as f64).sqrt();
        assert!(total < 1.5, "{all:?}");
        assert!(s.fitted_on_test_rows);
        if at < 648 {
            assert!(
                r.heldout_rmse_total_after < 1.5,
                "{}",
                r.heldout_rmse_total_after
            );
        }
    }
}

/// Two channels exchanged from the first row and put right at hour 100 (a wiring mistake
/// found on site): the change shows only before its hour, where no exchange from an hour to the
/// end explains it. The loop finds it there, re-calibrates with the readings relabelled before
/// and after the hour, and keeps the relabelling with the larger evidence: g2 and g5 exchanged
/// over rows 0..100, the gap held, no gap alarm.
#[test]
fn an_exchange_put_right_early_is_undone_before_its_hour() {
    let at = 100;
    let mut rec = record_with(&ToyGate::default(), ROWS, 34, |_, _| 0.0).unwrap();
    for i in 0..at {
        rec.y.swap((i, 1), (i, 4));
    }
    let r = loop_on(&rec);
    let s = r.sensor.as_ref().expect("the sensor pass runs by default");
    eprintln!("exchange before {at}: {:?}\n{}", s.findings, r.conclusion);
    let f = s
        .findings
        .iter()
        .find(|f| f.kind == SensorKind::ChannelExchange)
        .unwrap_or_else(|| panic!("no exchange found: {:?}", s.findings));
    assert_eq!(f.gauges, vec!["g2", "g5"]);
    assert_eq!(f.from_row, 0, "{f:?}");
    assert!(f.to_row.abs_diff(at) <= 2, "end row {}", f.to_row);
    assert!(
        !gap_alarm(&r),
        "gap alarm for a wiring change: {:?}",
        r.alarms
    );
    assert!(holds(&r, 90.0), "{:?}", r.theta_after);
}

/// A dead gauge (g4 reads 0 from hour 700): set aside from that hour, its cells left out of
/// the error, no effect and no gap alarm for it.
#[test]
fn a_dead_gauge_is_set_aside_from_when_it_died() {
    let mut rec = record_with(&ToyGate::default(), ROWS, 33, |_, _| 0.0).unwrap();
    for i in 700..ROWS {
        rec.y[(i, 3)] = 0.0;
    }
    let r = loop_on(&rec);
    let s = r.sensor.as_ref().unwrap();
    eprintln!("{:?}\n{}", s.findings, r.conclusion);
    let f = &s.findings[0];
    assert_eq!(
        (f.kind, f.action, f.gauges[0].as_str(), f.from_row),
        (SensorKind::Stuck, SensorAction::SetAside, "g4", 700)
    );
    assert_eq!(s.set_aside_cells, ROWS - 700);
    assert!(r.effects.is_empty(), "{:?}", r.effects);
    assert!(!gap_alarm(&r));
    // the whole-record scan reads g4 before hour 700 only: its zeros after are no noise to
    // judge a change against
    assert!(r.alarms.iter().all(|a| a.subject != "g4"), "{:?}", r.alarms);
    assert!(
        r.heldout_rmse_total_after < 1.5,
        "{}",
        r.heldout_rmse_total_after
    );
    assert!(holds(&r, 90.0), "{:?}", r.theta_after);
}

/// The gauge that tells most about the gap stuck from hour 48 (early in the calibration
/// window): set aside from then, and the calibrations read only the 48 rows before it, where no
/// gauge is set aside, instead of filling its cells with a prediction, which would lean the gap
/// towards the first calibration, made on the stuck readings. The gap holds 90 in.
#[test]
fn a_gauge_stuck_early_is_left_out_of_the_calibration_not_filled() {
    use bamudi_closeloop::CalibrationRows;
    let gate = ToyGate::default();
    let (hu, hd) = (540.0, 180.0);
    let (a, b) = (gate.strain(hu, hd, 95.0), gate.strain(hu, hd, 90.0));
    let g = (0..a.len())
        .max_by(|&i, &j| (a[i] - b[i]).abs().total_cmp(&(a[j] - b[j]).abs()))
        .unwrap();
    let at = 48;
    let mut rec = record_with(&gate, ROWS, 35, |_, _| 0.0).unwrap();
    let v = rec.y[(at - 1, g)];
    for i in at..ROWS {
        rec.y[(i, g)] = v;
    }
    let r = loop_on(&rec);
    let s = r.sensor.as_ref().unwrap();
    eprintln!(
        "stuck g{}: {:?}\n{:?}\n{}",
        g + 1,
        s.findings,
        s.calibration_rows,
        r.conclusion
    );
    let f = s
        .findings
        .iter()
        .find(|f| f.kind == SensorKind::Stuck)
        .unwrap_or_else(|| panic!("no stuck gauge found: {:?}", s.findings));
    assert_eq!(f.gauge_columns, vec![g]);
    assert!(f.from_row.abs_diff(at) <= 1, "{f:?}");
    assert!(
        matches!(
            s.calibration_rows,
            Some(CalibrationRows::WithoutSetAside { complete_rows, .. }) if complete_rows == f.from_row
        ),
        "{:?}",
        s.calibration_rows
    );
    assert!(holds(&r, 90.0), "{:?}", r.theta_after);
    assert!(!gap_alarm(&r), "{:?}", r.alarms);
    assert!(
        r.heldout_rmse_total_after < 1.5,
        "{}",
        r.heldout_rmse_total_after
    );
}

/// A real change of the gap (90 -> 100 in from hour 900, in the test window, every gauge moved
/// by the toy gate itself): the structure-or-sensor test must call it structure, so no sensor
/// correction takes it away and the gap alarm stands.
#[test]
fn a_gap_change_is_not_taken_for_a_sensor() {
    let gate = ToyGate::default();
    let mut rec = record_with(&gate, ROWS, 34, |_, _| 0.0).unwrap();
    for i in 900..ROWS {
        let (hu, hd) = (rec.x[(i, 0)], rec.x[(i, 1)]);
        let (a, b) = (gate.strain(hu, hd, 100.0), gate.strain(hu, hd, 90.0));
        for g in 0..rec.y.ncols() {
            rec.y[(i, g)] += a[g] - b[g];
        }
    }
    let r = loop_on(&rec);
    let s = r.sensor.as_ref().unwrap();
    eprintln!(
        "{:?}\n{:?}\n{}",
        s.findings, s.attribution_tests, r.conclusion
    );
    assert!(s.findings.is_empty(), "{:?}", s.findings);
    assert!(gap_alarm(&r), "{:?}", r.alarms);
    assert!(
        s.attribution_tests.iter().all(|t| t.verdict == "structure"),
        "{:?}",
        s.attribution_tests
    );
}

/// Clean records: no sensor finding (the false-finding side of the scans).
#[test]
fn clean_records_have_no_sensor_finding() {
    for seed in [41, 42, 43] {
        let rec = record_with(&ToyGate::default(), ROWS, seed, |_, _| 0.0).unwrap();
        let r = loop_on(&rec);
        let s = r.sensor.as_ref().unwrap();
        assert!(s.findings.is_empty(), "seed {seed}: {:?}", s.findings);
        assert!(r.alarms.is_empty(), "seed {seed}: {:?}", r.alarms);
    }
}

/// A drift or a change of gain on one gauge from hour 900 (day 37.5, in the test window), in
/// the newest data where the loop fits nothing: the structure-or-sensor test must call each a
/// sensor fault of the right kind on the right gauge, date it (within a day) and size it
/// (within 10 %: the fit is against the model's mean, not the true strain), and no gap alarm
/// may fire. The drift hypothesis, the onset search and the 6.6 evidence bound were worked
/// out on seeds 55-59 (drifts of 0.05-0.2 per hour on g1-g3, gains of 3-5 % on g1 and g4,
/// where a 0.2 drift on g2 raised a spurious gap alarm dated day 15.5). Seeds 61-64 were
/// meant for validation, but seed 64 (8 % on g5, whose strain swings about zero) failed and
/// led to the gain scan, so 61-64 are design cases too; seeds 65 and 66 were added after the
/// gain scan and played no part in it.
#[test]
fn a_drift_or_gain_change_on_one_gauge_is_corrected_without_a_gap_alarm() {
    let at = 900;
    let cases = [
        (61u64, 3usize, SensorKind::Drift, 0.08 * 24.0),
        (62, 4, SensorKind::Drift, 0.15 * 24.0),
        (63, 1, SensorKind::Gain, 0.04),
        (64, 4, SensorKind::Gain, 0.08),
        (65, 2, SensorKind::Gain, 0.06),
        (66, 0, SensorKind::Drift, 0.1 * 24.0),
    ];
    for (seed, g, kind, size) in cases {
        let mut rec = record_with(&ToyGate::default(), ROWS, seed, |_, _| 0.0).unwrap();
        for i in at..ROWS {
            match kind {
                SensorKind::Drift => rec.y[(i, g)] += size * (i - at) as f64 / 24.0,
                _ => rec.y[(i, g)] *= 1.0 + size,
            }
        }
        let r = loop_on(&rec);
        let s = r.sensor.as_ref().unwrap();
        let what: Vec<String> = s.findings.iter().map(|f| f.describe()).collect();
        eprintln!("{kind:?} {size} on g{}: {what:?}\n{}", g + 1, r.conclusion);
        let f = s
            .findings
            .iter()
            .find(|f| f.kind == kind && f.gauge_columns == [g])
            .unwrap_or_else(|| panic!("{kind:?} on g{} not found: {what:?}", g + 1));
        assert!(f.from_row.abs_diff(at) <= 24, "onset row {}", f.from_row);
        let got = f.size.unwrap();
        assert!(
            (got - size).abs() <= 0.1 * size,
            "size {got} against {size}"
        );
        assert!(
            !gap_alarm(&r),
            "gap alarm for a sensor fault: {:?}",
            r.alarms
        );
        assert!(holds(&r, 90.0), "{:?}", r.theta_after);
    }
}

/// Sunlight on three gauges from hour 900 (in the test window): a half-wave daily cycle of
/// 3, −2.1 and 1.5 microstrain on g2, g3 and g6, a shape no library effect holds. The
/// structure-or-sensor test's third answer takes it: a library effect from that day on (a
/// daily harmonic or the air temperature, which follows the same day), not a step on one
/// gauge and then another, and no gap alarm. The error with it is in-sample (fitted on the
/// rows from its onset) and must be back near the noise; the out-of-sample figure leaves it
/// out and is not asserted.
#[test]
fn an_effect_that_begins_late_on_several_gauges_is_an_effect_not_sensor_faults() {
    let (at, amp) = (900.0, [0.0, 3.0, -2.1, 0.0, 0.0, 1.5, 0.0]);
    let sun = move |t: f64, k: usize| {
        if t < at {
            return 0.0;
        }
        let h = t.rem_euclid(24.0);
        amp[k] * (std::f64::consts::PI * (h - 7.0) / 12.0).sin().max(0.0)
    };
    let rec = record_with(&ToyGate::default(), ROWS, 36, sun).unwrap();
    let r = loop_on(&rec);
    let o = r.onset.as_ref().expect("an onset tested");
    eprintln!(
        "{:#?}\n{:?}\n{}",
        o,
        r.sensor.as_ref().map(|s| &s.findings),
        r.conclusion
    );
    assert_eq!(o.added.len(), 1, "{o:?}");
    let e = r
        .effects
        .iter()
        .find(|e| e.parameters.iter().any(|p| p.name == "onset_day"))
        .expect("the effect from the onset is among the effects");
    let day = e
        .parameters
        .iter()
        .find(|p| p.name == "onset_day")
        .unwrap()
        .values[0];
    assert!((day - at / 24.0).abs() <= 1.0, "onset day {day}");
    let sensor_steps: Vec<_> = r
        .sensor
        .iter()
        .flat_map(|s| &s.findings)
        .filter(|f| {
            matches!(
                f.kind,
                SensorKind::Step | SensorKind::Drift | SensorKind::Gain
            )
        })
        .collect();
    assert!(sensor_steps.is_empty(), "{sensor_steps:?}");
    assert!(!gap_alarm(&r), "{:?}", r.alarms);
    assert!(holds(&r, 90.0), "{:?}", r.theta_after);
    let with = o.error_rmse_with.as_ref().unwrap();
    let total = (with.iter().map(|v| v * v).sum::<f64>() / with.len() as f64).sqrt();
    // noise sd 1. A half-wave of amplitude A has variance 0.149 A², and the daily harmonic
    // alone leaves 0.024 A² of it (0.21 microstrain² on g2): the right shape brings the error
    // to about 1.02. 1.3 leaves room for a term on the air temperature, whose daily sine is
    // the same harmonic plus a weekly swing; left as steps the panel's records stayed at
    // 1.7-1.8x the noise
    assert!(total < 1.3, "{with:?}");
}
