//! Shared data generators and proptest strategies.

use gp::{Kernel, Mean};
use nalgebra::DMatrix;
use proptest::prelude::*;
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// Any of the four kernels.
pub fn kernel() -> impl Strategy<Value = Kernel> {
    prop_oneof![
        Just(Kernel::SquaredExponential { ard: true }),
        Just(Kernel::SquaredExponential { ard: false }),
        Just(Kernel::Matern52 { ard: true }),
        Just(Kernel::Matern52 { ard: false }),
    ]
}

/// Any of the three prior means.
pub fn mean() -> impl Strategy<Value = Mean> {
    prop_oneof![Just(Mean::Zero), Just(Mean::Constant), Just(Mean::Linear)]
}

/// `n × d` inputs uniform in `[0, 10]` and a smooth-plus-noise response, from a seed.
pub fn smooth_data(n: usize, d: usize, noise_sd: f64, seed: u64) -> (DMatrix<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let x = DMatrix::from_fn(n, d, |_, _| 10.0 * rng.random::<f64>());
    let y = (0..n)
        .map(|i| {
            let s: f64 = (0..d)
                .map(|j| (x[(i, j)] * (0.3 + 0.2 * j as f64)).sin())
                .sum();
            s + noise_sd * standard_normal(&mut rng)
        })
        .collect();
    (x, y)
}

/// Box-Muller standard normal draw.
pub fn standard_normal(rng: &mut StdRng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}
