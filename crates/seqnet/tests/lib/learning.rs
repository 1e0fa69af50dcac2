//! The trainer actually learns: a nonlinear multi-output map and a task needing memory.

use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use seqnet::{LrSchedule, LstmParams, Optimizer, Precision, SearchSpace, select_hyperparameters};

fn uniform(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    DMatrix::from_fn(rows, cols, |_, _| rng.random_range(-1.0..1.0))
}

/// Mean over outputs of MSE / Var(y): 1.0 = predicting the mean, 0.0 = perfect.
fn relative_mse(pred: &DMatrix<f64>, y: &DMatrix<f64>) -> f64 {
    let mut total = 0.0;
    for c in 0..y.ncols() {
        let col = y.column(c);
        let mean = col.mean();
        let var = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / col.len() as f64;
        let mse = (0..y.nrows())
            .map(|r| (pred[(r, c)] - y[(r, c)]).powi(2))
            .sum::<f64>()
            / y.nrows() as f64;
        total += mse / var;
    }
    total / y.ncols() as f64
}

fn nonlinear_map(x: &DMatrix<f64>) -> DMatrix<f64> {
    DMatrix::from_fn(x.nrows(), 3, |r, c| {
        let (a, b, d) = (x[(r, 0)], x[(r, 1)], x[(r, 2)]);
        match c {
            0 => (2.0 * a).sin() * b,
            1 => a * a - d,
            _ => (a + b + d).tanh(),
        }
    })
}

#[test]
fn fits_a_nonlinear_multi_output_map() {
    let (x, x_test) = (uniform(2000, 3, 1), uniform(500, 3, 2));
    let (y, y_test) = (nonlinear_map(&x), nonlinear_map(&x_test));
    for precision in [Precision::F32, Precision::F64] {
        let m = LstmParams::new(3, 3)
            .hidden(24)
            .epochs(40)
            .batch_size(64)
            .learning_rate(1e-2)
            .schedule(LrSchedule::Cosine { min_factor: 0.05 })
            .precision(precision)
            .fit(&x, &y)
            .unwrap();
        let err = relative_mse(&m.predict(&x_test).unwrap(), &y_test);
        // Noise-free smooth targets: a well-trained net explains >98 % of the variance on held-out
        // data; an untrained or broken one sits near 1.0.
        assert!(err < 0.02, "{precision:?}: relative test MSE {err}");
    }
}

#[test]
fn remembers_the_first_step_of_a_sequence() {
    // Output = first element of a 6-step scalar sequence: only memory carried through 5
    // recurrent steps can solve it; the last step alone explains nothing.
    let (x, x_test) = (uniform(3000, 6, 3), uniform(500, 6, 4));
    let first = |m: &DMatrix<f64>| DMatrix::from_fn(m.nrows(), 1, |r, _| m[(r, 0)]);
    let m = LstmParams::new(6, 1)
        .steps(6)
        .hidden(16)
        .epochs(40)
        .batch_size(64)
        .learning_rate(1e-2)
        .clip_norm(1.0)
        .fit(&x, &first(&x))
        .unwrap();
    let err = relative_mse(&m.predict(&x_test).unwrap(), &first(&x_test));
    // Predicting the mean gives 1.0; recall through 5 steps to ~3 % accuracy (std) gives ~1e-3.
    assert!(err < 0.01, "relative test MSE {err}");
}

#[test]
fn learns_a_running_sum_with_two_layers_and_sgd() {
    let (x, x_test) = (uniform(3000, 5, 5), uniform(500, 5, 6));
    let sum = |m: &DMatrix<f64>| DMatrix::from_fn(m.nrows(), 1, |r, _| m.row(r).sum());
    let m = LstmParams::new(5, 1)
        .steps(5)
        .hidden(12)
        .layers(2)
        .epochs(40)
        .batch_size(32)
        .learning_rate(0.05)
        .optimizer(Optimizer::sgd(0.9))
        .clip_norm(1.0)
        .fit(&x, &sum(&x))
        .unwrap();
    let err = relative_mse(&m.predict(&x_test).unwrap(), &sum(&x_test));
    // A linear-in-inputs target; 2 % of the variance left is a loose bound for 40 SGD epochs.
    assert!(err < 0.02, "relative test MSE {err}");
}

#[test]
fn early_stopping_restores_the_best_epoch() {
    let x = uniform(300, 3, 7);
    let y = nonlinear_map(&x);
    let m = LstmParams::new(3, 3)
        .hidden(8)
        .epochs(200)
        .batch_size(16)
        .learning_rate(3e-2)
        .patience(3)
        .validation_fraction(0.3)
        .fit(&x, &y)
        .unwrap();
    let h = m.history();
    assert!(
        h.stopped_early,
        "should stop before 200 epochs: ran {}",
        h.train_loss.len()
    );
    assert_eq!(h.train_loss.len(), h.best_epoch + 1 + 3);
    let best = h.val_loss.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(h.best_loss, best);
}

#[test]
fn search_picks_a_candidate_and_is_deterministic() {
    let x = uniform(600, 3, 8);
    let y = nonlinear_map(&x);
    let space = SearchSpace {
        hidden: vec![2, 16],
        layers: vec![1, 2],
        max_candidates: 3,
        max_epochs: 15,
        test_fraction: 0.25,
    };
    let base = LstmParams::new(3, 3).batch_size(32).learning_rate(1e-2);
    let a = select_hyperparameters(&base, &space, &x, &y).unwrap();
    let b = select_hyperparameters(&base, &space, &x, &y).unwrap();
    assert_eq!(a.table.len(), 3); // budget honoured: (1,2), (1,16), (2,2)
    assert_eq!(
        a.table.iter().map(|c| c.test_score).collect::<Vec<_>>(),
        b.table.iter().map(|c| c.test_score).collect::<Vec<_>>()
    );
    let best = a
        .table
        .iter()
        .min_by(|p, q| p.test_score.total_cmp(&q.test_score))
        .unwrap();
    assert_eq!(
        (a.best.settings().hidden, a.best.settings().layers),
        (best.hidden, best.layers)
    );
    // Two hidden units cannot represent three nonlinear outputs as well as sixteen.
    assert_eq!(a.best.settings().hidden, 16);
}
