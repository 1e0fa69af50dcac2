//! Timing script for the issue-2 anchor (run in the same session as the scikit-learn anchor):
//! fits the anchor data set (written by `scripts/gp_vs_sklearn.py`) like the scikit-learn
//! anchor (SE-ARD + white noise, zero mean on standardised outputs, default start + 5 random
//! restarts), and reports median fit time, median time to predict mean + variance at the
//! 2,500-point grid, and the LML in standardised and original units. Also prints the fits with
//! GLS constant / linear means for comparison.
//!
//! Run: `cargo run --release -p gp --example anchor_fit`
use gp::{GpParams, Kernel, Mean};
use nalgebra::DMatrix;
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/anchor_n500.csv");
    let text = std::fs::read_to_string(path)?;
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>())
                .collect::<Result<_, _>>()
        })
        .collect::<Result<_, _>>()?;
    let x = DMatrix::from_fn(rows.len(), 2, |i, j| rows[i][j]);
    let y: Vec<f64> = rows.iter().map(|r| r[2]).collect();
    let g: Vec<f64> = (0..50).map(|i| 24.0 + 720.0 * i as f64 / 49.0).collect();
    let grid = DMatrix::from_fn(2500, 2, |r, c| if c == 0 { g[r % 50] } else { g[r / 50] });

    for mean in [Mean::Zero, Mean::Constant, Mean::Linear] {
        let params = GpParams::new()
            .kernel(Kernel::SquaredExponential { ard: true })
            .mean(mean)
            .restarts(5)
            .seed(0);
        let repeats = if mean == Mean::Zero { 5 } else { 1 };
        let mut fit_t = Vec::new();
        let mut model = None;
        for _ in 0..repeats {
            let t0 = Instant::now();
            model = Some(params.fit(&x, &y)?);
            fit_t.push(t0.elapsed().as_secs_f64());
        }
        let model = model.expect("at least one fit");
        let mut pred_t = Vec::new();
        for _ in 0..repeats.max(3) {
            let t0 = Instant::now();
            std::hint::black_box(model.predict(&grid)?);
            pred_t.push(t0.elapsed().as_secs_f64());
        }
        let h = model.hyperparameters();
        let evals: u64 = model
            .diagnostics()
            .starts
            .iter()
            .map(|s| s.iterations)
            .sum();
        println!(
            "{mean:?}: fit_s(median of {repeats})={:.3} predict2500_s={:.4} lml_std={:.8} lml_orig={:.8} \
             sf2={:.4e} ls={:?} noise={:.4e} jitter={:.1e} lbfgs_iters_total={evals}",
            median(fit_t),
            median(pred_t),
            model.log_marginal_likelihood_standardized(),
            model.log_marginal_likelihood(),
            h.signal_variance,
            h.length_scales,
            h.noise_variance,
            model.diagnostics().jitter
        );
    }
    Ok(())
}
