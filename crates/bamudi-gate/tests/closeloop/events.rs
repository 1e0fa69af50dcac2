//! The whole-record event scan against issue 17's bars, on records the loop's effect library
//! does not describe: an event on one gauge starting anywhere in the last 30 % of a 60-day
//! record (after the calibration window), in three shapes, with random gauge, onset, sign and
//! magnitude; and clean records. The truth is the field simulator with the toy gate; the
//! events are written into its strains here, in forms none of the library's effects has.

use super::*;
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// An event's shape: the offset (microstrain) at `dt` days after its onset, for magnitude `m`.
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// A step (a re-zeroed gauge).
    Step,
    /// A linear creep to the full offset over `hours` (a debonding gauge).
    Creep { hours: f64 },
    /// A step that relaxes to half its size with a 2-day time constant (a slipping clamp).
    Relaxing,
}

impl Shape {
    fn offset(self, m: f64, dt_days: f64) -> f64 {
        if dt_days < 0.0 {
            return 0.0;
        }
        match self {
            Shape::Step => m,
            Shape::Creep { hours } => m * (dt_days * 24.0 / hours).min(1.0),
            Shape::Relaxing => m * (0.5 + 0.5 * (-dt_days / 2.0).exp()),
        }
    }

    /// Days after the onset over which the event builds up.
    fn ramp_days(self) -> f64 {
        match self {
            Shape::Creep { hours } => hours / 24.0,
            _ => 0.0,
        }
    }
}

/// One late event: its gauge, onset (day) and the record with it, the truth being `gate`.
fn late_event_on(
    gate: &ToyGate,
    seed: u64,
    shape: Shape,
    rng: &mut StdRng,
) -> (usize, f64, FieldRecord) {
    let cfg = base(seed, FieldEffects::default());
    let mut rec = simulate(&cfg, &|hu, hd, gap| gate.strain(hu, hd, gap)).unwrap();
    let days = 60.0;
    // the last 30 % of the record, but at least 12 h before its end: a level must hold 8 rows
    // (8 h) to be an event rather than an outlier
    let onset = 0.7 * days + rng.random::<f64>() * (0.3 * days - 0.5);
    let gauge = (rng.random::<f64>() * 7.0) as usize;
    let sign = if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
    let magnitude = sign * (3.0 + 7.0 * rng.random::<f64>());
    let t0 = rec.time_unix_s[0];
    for (row, t) in rec.time_unix_s.iter().enumerate() {
        let day = (t - t0) as f64 / 86_400.0;
        if let Some(v) = rec.strains[row][gauge].as_mut() {
            *v += shape.offset(magnitude, day - onset);
        }
    }
    (gauge, onset, rec)
}

/// One late event on the calibration's own gate.
fn late_event(seed: u64, shape: Shape, rng: &mut StdRng) -> (usize, f64, FieldRecord) {
    late_event_on(&ToyGate::default(), seed, shape, rng)
}

/// Issue 17: an event on one gauge starting anywhere in the last 30 % of the record is found
/// and dated within one day in at least 9 of 10 seeds — here for each of three shapes (30
/// records, seeds 300-329, magnitudes 3-10 microstrain against 1 microstrain of noise).
/// "Dated within one day": an alarm on that gauge whose onset lies within a day of the event's
/// build-up. The share of 95 % onset intervals holding the onset, and alarms on the six
/// untouched gauges, are printed for the closing note and bounded: at most 1 of 10 records per
/// shape may carry an alarm on another gauge (the clean-record bar below).
#[test]
fn late_events_on_one_gauge_are_found_and_dated_within_a_day() {
    let shapes = [Shape::Step, Shape::Creep { hours: 18.0 }, Shape::Relaxing];
    let mut rng = StdRng::seed_from_u64(17);
    for (k, shape) in shapes.into_iter().enumerate() {
        let (mut dated, mut covered, mut elsewhere) = (0, 0, 0);
        for i in 0..10u64 {
            let seed = 300 + 10 * k as u64 + i;
            let (gauge, onset, rec) = late_event(seed, shape, &mut rng);
            let out = run(&rec);
            let scan = out
                .report
                .events
                .as_ref()
                .expect("the scan runs by default");
            let name = &out.report.gauge_names[gauge];
            if let Some(s) = out
                .report
                .sensor
                .as_ref()
                .filter(|s| !s.findings.is_empty())
            {
                let what: Vec<String> = s.findings.iter().map(|f| f.describe()).collect();
                eprintln!("{shape:?} seed {seed} on {name} from day {onset:.2}: {what:?}");
            }
            let near = |a: &&bamudi_closeloop::Alarm| {
                &a.gauge == name
                    && a.onset_day >= onset - 1.0
                    && a.onset_day <= onset + shape.ramp_days() + 1.0
            };
            let hit = scan.alarms.iter().find(near);
            dated += usize::from(hit.is_some());
            covered += usize::from(hit.is_some_and(|a| {
                a.onset_day_interval.0 <= onset + shape.ramp_days()
                    && onset <= a.onset_day_interval.1
            }));
            elsewhere += usize::from(scan.alarms.iter().any(|a| &a.gauge != name));
        }
        eprintln!(
            "{shape:?}: dated within a day {dated}/10, 95 % onset interval holds it {covered}/10, records with an alarm on another gauge {elsewhere}/10"
        );
        assert!(dated >= 9, "{shape:?}: dated {dated} of 10");
        assert!(
            elsewhere <= 1,
            "{shape:?}: {elsewhere} records alarm elsewhere"
        );
    }
}

/// Issue 17: at most 1 false alarm over 20 clean records (seeds 200-219, 60 days hourly):
/// an alarm of the event scan or of the gap track's change alarm.
#[test]
fn clean_records_raise_at_most_one_alarm_in_twenty() {
    let alarmed: Vec<u64> = (200..220)
        .filter(|&seed| {
            let out = run(&record(base(seed, FieldEffects::default())));
            let scan = out
                .report
                .events
                .as_ref()
                .expect("the scan runs by default");
            let track = out
                .report
                .theta_track
                .as_ref()
                .expect("the track runs by default");
            eprintln!(
                "clean seed {seed}: {} alarm(s); gap now {:.2} ± {:.2}; track alarm {:?}",
                scan.alarms.len(),
                track.now.mean,
                track.now.sd,
                track.alarm
            );
            !scan.alarms.is_empty() || track.alarm.is_some()
        })
        .collect();
    eprintln!("clean records with an alarm: {alarmed:?} of seeds 200-219");
    assert!(alarmed.len() <= 1, "{alarmed:?}");
}

/// The same bar on a gate that differs from the one the loop calibrates: the truth's
/// influence lines 4 % stronger and its local bending 6 % weaker on every gauge (an as-built
/// gate), so the residual carries a load-shaped misfit the loop's model cannot remove. A step
/// on one random gauge in the last 30 % (10 seeds, 340-349) must still be found and dated
/// within a day in at least 9, with at most 1 record alarming on another gauge.
#[test]
fn late_steps_are_found_on_an_as_built_gate() {
    let truth = as_built();
    let mut rng = StdRng::seed_from_u64(34);
    let (mut dated, mut elsewhere) = (0, 0);
    for seed in 340..350 {
        let (gauge, onset, rec) = late_event_on(&truth, seed, Shape::Step, &mut rng);
        let out = run(&rec);
        let scan = out
            .report
            .events
            .as_ref()
            .expect("the scan runs by default");
        let name = &out.report.gauge_names[gauge];
        dated += usize::from(
            scan.alarms
                .iter()
                .any(|a| &a.gauge == name && (a.onset_day - onset).abs() <= 1.0),
        );
        elsewhere += usize::from(scan.alarms.iter().any(|a| &a.gauge != name));
    }
    eprintln!("as-built gate, step: dated within a day {dated}/10, alarm elsewhere {elsewhere}/10");
    assert!(dated >= 9, "dated {dated} of 10");
    assert!(elsewhere <= 1, "{elsewhere} records alarm elsewhere");
}
