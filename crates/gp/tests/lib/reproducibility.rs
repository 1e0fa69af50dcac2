//! Bit-for-bit reproducibility: fixed fits give exactly the numbers recorded in
//! `tests/data/repro_fixture.txt` before the training-covariance Cholesky moved to
//! `numerics::cholesky` (fitted log parameters, likelihoods, jitter, GLS trend, predictive
//! means and variances, a block of the joint posterior covariance).

use gp::{GpModel, GpParams, Kernel, Mean};
use nalgebra::DMatrix;
use std::collections::HashMap;

/// Deterministic inputs on `[0, 10]^d` and a smooth response with a small fixed ripple.
fn data(n: usize, d: usize, salt: usize) -> (DMatrix<f64>, Vec<f64>) {
    let x = DMatrix::from_fn(n, d, |i, j| {
        10.0 * (((i + salt) * (7 + 5 * j) + 3 * j) % 37) as f64 / 37.0
    });
    let y = (0..n)
        .map(|i| {
            (0..d)
                .map(|j| (x[(i, j)] * (0.3 + 0.2 * j as f64)).sin())
                .sum::<f64>()
                + 0.05 * ((i * 13 % 7) as f64 - 3.0)
        })
        .collect();
    (x, y)
}

/// The fixture: case name -> key -> values.
fn fixture() -> HashMap<String, HashMap<String, Vec<f64>>> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/repro_fixture.txt");
    let text = std::fs::read_to_string(path).unwrap();
    let mut cases = HashMap::new();
    let mut current = String::new();
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            current = name.to_string();
            continue;
        }
        let mut words = line.split_whitespace();
        let key = words.next().unwrap().to_string();
        let values = words.map(|w| w.parse::<f64>().unwrap()).collect();
        cases
            .entry(current.clone())
            .or_insert_with(HashMap::new)
            .insert(key, values);
    }
    cases
}

/// Asserts every recorded quantity of `case` equals the model's, bit for bit.
fn assert_same(case: &HashMap<String, Vec<f64>>, m: &GpModel, xs: &DMatrix<f64>, name: &str) {
    let p = m.predict(xs).unwrap();
    let cov = m.posterior_cov(xs, &xs.rows(0, 5).into_owned()).unwrap();
    let now: [(&str, Vec<f64>); 7] = [
        ("log_params", m.hyperparameters().log_params_standardized),
        (
            "lml",
            vec![
                m.log_marginal_likelihood(),
                m.log_marginal_likelihood_standardized(),
            ],
        ),
        ("jitter", vec![m.diagnostics().jitter]),
        ("trend", m.trend_coefficients()),
        ("mean", p.mean.as_slice().to_vec()),
        ("variance", p.variance.as_slice().to_vec()),
        ("cov", cov.as_slice().to_vec()),
    ];
    for (key, values) in now {
        let bits = |v: &[f64]| v.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&values), bits(&case[key]), "{name}: {key} changed");
    }
}

#[test]
fn fixed_fits_reproduce_the_recorded_numbers_bit_for_bit() {
    let fx = fixture();
    let (x, y) = data(40, 2, 0);
    let (xs, _) = data(12, 2, 5);
    let m = GpParams::new()
        .kernel(Kernel::SquaredExponential { ard: true })
        .mean(Mean::Constant)
        .restarts(2)
        .seed(7)
        .fit(&x, &y)
        .unwrap();
    assert_same(&fx["se_ard_constant"], &m, &xs, "se_ard_constant");
    let m = GpParams::new()
        .kernel(Kernel::Matern52 { ard: false })
        .mean(Mean::Linear)
        .restarts(1)
        .seed(3)
        .fit(&x, &y)
        .unwrap();
    assert_same(&fx["matern_iso_linear"], &m, &xs, "matern_iso_linear");
}

#[test]
fn the_jitter_ladder_gives_the_recorded_jitter_and_numbers() {
    // Duplicated points, no noise and a huge length scale: K is numerically rank one and the
    // factorisation needs a rung of the ladder.
    let fx = fixture();
    let x = DMatrix::from_row_slice(6, 1, &[0.0, 1.0, 1.0, 2.0, 3.0, 4.0]);
    let y = [0.0, 1.0, 1.0, 0.5, 0.2, 0.1];
    let m = GpParams::new()
        .estimate_noise(false)
        .nugget(0.0)
        .fit_with_log_params(&x, &y, &[0.0, 9.2])
        .unwrap();
    assert!(m.diagnostics().jitter > 0.0);
    let xs = DMatrix::from_row_slice(6, 1, &[0.5, 1.0, 1.5, 2.5, 3.5, 5.0]);
    assert_same(&fx["jitter_ladder"], &m, &xs, "jitter_ladder");
}

#[test]
fn parallel_restarts_give_the_same_fit_on_one_thread_and_on_four() {
    // The restarts run on rayon's pool, each on its own copy of the likelihood problem: the
    // fit must not depend on how many threads run them or in which order they finish.
    let (x, y) = data(40, 2, 1);
    let fit_on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| GpParams::new().restarts(5).seed(11).fit(&x, &y).unwrap())
    };
    let (one, four) = (fit_on(1), fit_on(4));
    let bits = |m: &GpModel| {
        let d = m.diagnostics();
        let mut v: Vec<u64> = d
            .starts
            .iter()
            .flat_map(|s| s.final_log_params.clone().unwrap_or_default())
            .chain(d.starts.iter().filter_map(|s| s.lml))
            .map(f64::to_bits)
            .collect();
        v.push(d.best_start as u64);
        v.push(m.log_marginal_likelihood().to_bits());
        v
    };
    assert_eq!(one.diagnostics().starts.len(), 6);
    assert_eq!(bits(&one), bits(&four));
}
