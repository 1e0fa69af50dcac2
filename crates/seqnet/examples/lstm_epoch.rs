//! Times full training epochs on the anchor's data recipe (/work/shared/anchors/lstm_anchor.py):
//! 50,000 training + 10,000 test samples, 10 inputs -> 12 outputs, `Y = X A + tanh(X B) + noise`,
//! LSTM(64) + dense head, Adam 1e-3, batch 256, no validation split (as the anchor).
//!
//! `cargo run --release -p seqnet --example lstm_epoch -- [steps] [threads] [f32|f64] [epochs]`
use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use seqnet::{LstmParams, Precision};

fn gaussian(rng: &mut StdRng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let threads: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let precision = match args.get(3).map(String::as_str) {
        Some("f64") => Precision::F64,
        _ => Precision::F32,
    };
    let epochs: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(3);
    let (n, n_test, d_in, d_out) = (50_000, 10_000, 10, 12);
    let mut rng = StdRng::seed_from_u64(0);
    let a = DMatrix::from_fn(d_in, d_out, |_, _| 0.3 * gaussian(&mut rng));
    let b = DMatrix::from_fn(d_in, d_out, |_, _| 0.5 * gaussian(&mut rng));
    let x = DMatrix::from_fn(n + n_test, d_in, |_, _| gaussian(&mut rng));
    let xb = &x * &b;
    let y = &x * &a
        + xb.map(f64::tanh)
        + DMatrix::from_fn(n + n_test, d_out, |_, _| 0.1 * gaussian(&mut rng));
    let (x_tr, y_tr) = (x.rows(0, n).into_owned(), y.rows(0, n).into_owned());
    let (x_te, y_te) = (
        x.rows(n, n_test).into_owned(),
        y.rows(n, n_test).into_owned(),
    );
    let model = LstmParams::new(d_in, d_out)
        .hidden(64)
        .steps(steps)
        .epochs(epochs)
        .batch_size(256)
        .learning_rate(1e-3)
        .validation_fraction(0.0)
        .patience(0)
        .precision(precision)
        .threads(threads)
        .seed(0)
        .fit(&x_tr, &y_tr)
        .expect("training succeeds");
    let h = model.history();
    let mut t = h.epoch_seconds.clone();
    t.sort_by(f64::total_cmp);
    let med = t[t.len() / 2];
    // Test MSE in standardised output units, comparable with the anchor's.
    let pred = model.predict(&x_te).expect("shape is right");
    let sd: Vec<f64> = (0..d_out)
        .map(|c| {
            let col = y_tr.column(c);
            let m = col.mean();
            (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt()
        })
        .collect();
    let te = (0..n_test)
        .flat_map(|r| (0..d_out).map(move |c| (r, c)))
        .map(|(r, c)| ((pred[(r, c)] - y_te[(r, c)]) / sd[c]).powi(2))
        .sum::<f64>()
        / (n_test * d_out) as f64;
    println!(
        "seqnet seq{steps}x{} {precision:?} threads={threads}: epoch_s median={med:.3} min={:.3} max={:.3} \
         samples_per_s={:.0} epochs={} train_mse_last_epoch={:.4} test_mse={te:.4}",
        d_in / steps,
        t[0],
        t[t.len() - 1],
        n as f64 / med,
        h.train_loss.len(),
        h.train_loss.last().copied().unwrap_or(f64::NAN),
    );
}
