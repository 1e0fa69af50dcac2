//! The quoin block's fatigue over a field record, before and after calibration, against the
//! truth: per seed, a 60-day record of the default gate (gate model at a true gap drawn
//! uniformly in [70, 110] in, 1 µε noise, 8 vessels a day, sampled every 10 minutes so that
//! every lockage is seen) is calibrated with the close loop's calibrator (gap prior
//! U(60, 150) in, the record's loaded rows thinned to 240), and the calibrated force is pushed
//! through the quoin-block model along the whole record (`bamudi_gate::record_fatigue`).
//!
//! Prints per seed the hot spot's damage per 1,000 lockages (nominal, calibrated with its
//! 95 % band, true) and the years to crack initiation, then over all seeds how often the band
//! held the true rate at the hot spot and along the quoin.
//!
//! With a reality file (docs/reality.md) the record comes from that reality — an as-built
//! gate, another mesh or support, faulty gauges — while the calibration keeps the drawing, and
//! the true damage is that of the reality's force.
//!
//! `cargo run --release -p bamudi-gate --example record_fatigue [-- SEEDS [REALITY.toml]]`
//! (default 5 seeds, no reality)
use bamudi_gate::calibrator::GateCalibrator;
use bamudi_gate::gate;
use bamudi_gate::record_fatigue::{LoadHistory, RecordFatigueOptions, record_fatigue};
use mitergate::data::field::FieldConfig;
use mitergate::reality::Reality;
use mitergate::{GateConfig, QuoinBlockModel, QuoinBlockParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seeds: u64 = std::env::args().nth(1).map_or(Ok(5), |s| s.parse())?;
    let reality = match std::env::args().nth(2) {
        Some(p) => Reality::from_file(std::path::Path::new(&p))?,
        None => Reality::default(),
    };
    let drawing = GateConfig::default();
    let (contact, _) = mitergate::build_contact(&drawing)?;
    let calibrator = GateCalibrator::new(contact.clone(), (60.0, 150.0))?;
    let truth_contact = gate::build_truth(&reality, &drawing)?;
    let block = QuoinBlockModel::new(
        QuoinBlockParams::default(),
        contact.gate().nu_points.clone(),
    )?;
    println!(
        "seed | gap (in) | posterior gap (in) | hot spot z (in) | damage / 1,000 lockages: nominal | calibrated [95 %] | true | years: nominal | calibrated [95 %] | true"
    );
    let (mut hot_hits, mut points, mut point_hits) = (0, 0, 0);
    for seed in 1..=seeds {
        let u = (numerics::random::derive_seed(2021, seed) >> 11) as f64 / (1u64 << 53) as f64;
        let gap = 70.0 + 40.0 * u;
        let field = FieldConfig::default()
            .seed(seed)
            .duration(60.0, 10.0)
            .noise_sd(1.0)
            .gap(gap);
        let mut rec = gate::simulate_field(&field, &truth_contact)?;
        reality.apply_to_field(&mut rec);
        let data = gate::as_measured(&rec, calibrator.model(), "record.csv")?;
        let cal = calibrator.calibrate_gate(&data.x, &data.y)?;
        let x = (0..rec.len())
            .map(|i| [rec.h_up[i], rec.h_down[i]])
            .collect();
        let t0 = rec.time_unix_s[0];
        let hours = rec
            .time_unix_s
            .iter()
            .map(|t| (t - t0) as f64 / 3600.0)
            .collect();
        let history = LoadHistory::new(x, hours)?;
        let truth = |t: usize, x: &[f64; 2]| -> bamudi_gate::error::Result<Vec<f64>> {
            Ok(truth_contact.solve(x[0], x[1], rec.gap_in[t])?.forces)
        };
        let opts = RecordFatigueOptions {
            seed,
            ..RecordFatigueOptions::default()
        };
        let r = record_fatigue(
            calibrator.model(),
            cal.calibration(),
            &block,
            &history,
            Some(&truth),
            opts,
        )?;
        let h = &r.hot_spot;
        let t = h.truth.unwrap_or(f64::NAN);
        hot_hits += usize::from(h.after_lower <= t && t <= h.after_upper);
        if let Some(tr) = &r.truth {
            for b in 0..tr.len() {
                if tr[b] > 0.0 || r.after.upper[b] > 0.0 {
                    points += 1;
                    point_hits +=
                        usize::from(r.after.lower[b] <= tr[b] && tr[b] <= r.after.upper[b]);
                }
            }
        }
        let y = |v: Option<f64>| v.map_or("none".to_string(), |v| format!("{v:.3e}"));
        let post = &cal.calibration().module3().posterior;
        println!(
            "{seed} | {gap:.2} | {:.2} ± {:.2} | {:.1} | {:.3e} | {:.3e} [{:.3e}, {:.3e}] | {t:.3e} | {} | {} [{}, {}] | {}",
            post.mean()[0],
            post.sd()[0],
            h.z_in,
            h.before,
            h.after_mean,
            h.after_lower,
            h.after_upper,
            y(h.years_before),
            y(h.years_after),
            y(h.years_after_lower),
            y(h.years_after_upper),
            y(h.years_truth),
        );
    }
    println!(
        "band held the true damage rate: at the hot spot {hot_hits}/{seeds}; along the quoin {point_hits}/{points} points with damage"
    );
    Ok(())
}
