//! Quoin-block fatigue over a load history (`bamudi_gate::record_fatigue`) on the
//! finite-element gate (24-in elements), calibrated on a simulated field record.

use bamudi_gate::calibrator::{CalibratedGate, GateCalibrator};
use bamudi_gate::gate;
use bamudi_gate::record_fatigue::{LoadHistory, RecordFatigueOptions, record_fatigue};
use mitergate::data::field::FieldConfig;
use mitergate::quoin_block::QUOIN_BLOCK_OUTPUTS;
use mitergate::reality::Reality;
use mitergate::{ContactModel, GateConfig, QuoinBlockModel, QuoinBlockParams};
use mlmodel::{PredictionModel, UnobservableModel};
use std::sync::OnceLock;

/// The gate, its calibrator (prior U(60, 150) in) and a calibration on 20 days of a record
/// simulated at a 90-in gap (1 µε noise, seed 11).
fn calibrated() -> &'static (ContactModel, GateCalibrator, CalibratedGate) {
    static C: OnceLock<(ContactModel, GateCalibrator, CalibratedGate)> = OnceLock::new();
    C.get_or_init(|| {
        let mut cfg = GateConfig::default();
        cfg.mesh.element_size = 24.0;
        let contact = gate::build(&cfg).unwrap().0;
        let field = FieldConfig::default()
            .seed(11)
            .duration(20.0, 60.0)
            .noise_sd(1.0)
            .gap(90.0);
        let rec = gate::simulate_field(&field, &contact).unwrap();
        let calibrator = GateCalibrator::new(contact.clone(), (60.0, 150.0)).unwrap();
        let data = gate::as_measured(&rec, calibrator.model(), "fatigue.csv").unwrap();
        let cal = calibrator.calibrate_gate(&data.x, &data.y).unwrap();
        (contact, calibrator, cal)
    })
}

fn block(c: &GateCalibrator) -> QuoinBlockModel {
    let z = c.model().unobservable.coordinates().to_vec();
    QuoinBlockModel::new(QuoinBlockParams::default(), z).unwrap()
}

/// A history of clean lockages is one stress cycle of range `τ_max(x)` per lockage, so its
/// damage per 1,000 lockages is the single-condition prediction's, draw for draw: the nominal
/// profile equals the block model on the prior-mean force, and the calibrated band equals
/// `Predictor::predict_through` with the same draws (same seed). Tolerance: 1e-9 relative,
/// rounding of the sums (20 cycles) only.
#[test]
fn clean_lockages_reproduce_the_single_condition_prediction() {
    let (_, calibrator, cal) = calibrated();
    let model = calibrator.model();
    let block = block(calibrator);
    let (open, loaded) = ([120.0, 120.0], [470.0, 120.0]);
    let mut x = vec![open];
    for _ in 0..20 {
        x.extend([loaded, open]);
    }
    let hours = (0..x.len()).map(|i| i as f64 * 1.5).collect();
    let history = LoadHistory::new(x, hours).unwrap();
    let opts = RecordFatigueOptions {
        n_draws: 200,
        seed: 9,
    };
    let r = record_fatigue(model, cal.calibration(), &block, &history, None, opts).unwrap();
    assert_eq!(r.lockages, 20.0);
    let n = r.z_in.len();
    let band = cal
        .calibration()
        .predictor(model)
        .unwrap()
        .predict_through(&block, &loaded, opts.n_draws, opts.seed)
        .unwrap();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-300;
    for b in 0..n {
        let d = 3 * n + b;
        assert!(
            close(r.after.mean[b], band.mean[d]),
            "mean at {b}: {} vs {}",
            r.after.mean[b],
            band.mean[d]
        );
        assert!(close(r.after.lower[b], band.lower[d]), "lower at {b}");
        assert!(close(r.after.upper[b], band.upper[d]), "upper at {b}");
    }
    let rule = model.prior.quadrature(8).unwrap();
    let mut nominal = vec![0.0; model.unobservable.response_len()];
    let mut g = nominal.clone();
    for (t, w) in rule.nodes.iter().zip(&rule.weights) {
        model.unobservable.evaluate(&loaded, t, &mut g).unwrap();
        nominal.iter_mut().zip(&g).for_each(|(a, v)| *a += w * v);
    }
    let mut out = vec![0.0; QUOIN_BLOCK_OUTPUTS.len() * n];
    block
        .evaluate(&loaded, &[105.0], &nominal, &mut out)
        .unwrap();
    for b in 0..n {
        assert!(
            close(r.before[b], out[3 * n + b]),
            "nominal at {b}: {} vs {}",
            r.before[b],
            out[3 * n + b]
        );
    }
    assert!(
        r.after.mean.iter().any(|v| *v > 0.0),
        "no damage anywhere: the check would be empty"
    );
}

/// On a record sampled every 10 minutes (so no lockage falls between samples) from an
/// as-built gate that is not the calibration's (skin plate +8 %, girder webs −7 %, steel −3 %,
/// the example reality `examples/as_built.toml`), the lockages counted from the head's rainflow
/// cycles are the simulator's fills, to the half cycle the record may end on; and the truth's
/// damage, from the as-built gate's force, is counted on the same cycles.
#[test]
fn an_as_built_record_counts_its_lockages() {
    let (_, calibrator, cal) = calibrated();
    let reality = Reality::from_toml_str(include_str!("../../examples/as_built.toml")).unwrap();
    let mut drawing = GateConfig::default();
    drawing.mesh.element_size = 24.0;
    let as_built = gate::build_truth(&reality, &drawing).unwrap();
    let contact = &as_built;
    let field = FieldConfig::default()
        .seed(23)
        .duration(4.0, 10.0)
        .gap(90.0);
    let rec = gate::simulate_field(&field, contact).unwrap();
    let fills = rec
        .lockage_phase
        .windows(2)
        .filter(|w| w[0] != 2 && w[1] == 2)
        .count() as f64;
    let x: Vec<[f64; 2]> = rec
        .h_up
        .iter()
        .zip(&rec.h_down)
        .map(|(u, d)| [*u, *d])
        .collect();
    let hours = rec
        .time_unix_s
        .iter()
        .map(|t| (t - rec.time_unix_s[0]) as f64 / 3600.0)
        .collect();
    let history = LoadHistory::new(x, hours).unwrap();
    let truth = |t: usize, x: &[f64; 2]| -> bamudi_gate::error::Result<Vec<f64>> {
        Ok(contact.solve(x[0], x[1], rec.gap_in[t])?.forces)
    };
    let opts = RecordFatigueOptions {
        n_draws: 40,
        seed: 1,
    };
    let block = block(calibrator);
    let r = record_fatigue(
        calibrator.model(),
        cal.calibration(),
        &block,
        &history,
        Some(&truth),
        opts,
    )
    .unwrap();
    assert!(
        fills >= 10.0,
        "only {fills} fills in 4 days: the check is too small"
    );
    assert!(
        (r.lockages - fills).abs() <= 1.0,
        "{} lockages counted, {fills} fills",
        r.lockages
    );
    let truth = r.truth.as_ref().unwrap();
    assert!(truth.iter().any(|v| *v > 0.0));
    eprintln!("record fatigue hot spot: {:?}", r.hot_spot);
}
