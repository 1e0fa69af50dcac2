//! Criterion benchmarks for `seqnet`: the Module-2 LSTM of Sec. 3.3.2 on the paper's shape
//! (10 inputs -> 12 outputs, hidden 64, batch 256), data recipe of
//! `/work/shared/anchors/lstm_anchor.py`.
//!
//! * `seqnet/train_epoch_*`: one `fit` epoch on 5,120 samples (20 mini-batches; the full 50,000
//!   would make criterion's repetitions take minutes). Throughput is reported in samples/second;
//!   a full 50,000-sample epoch takes `50_000 / throughput` seconds. Full epochs side by side with
//!   PyTorch: `scripts/lstm_bench.sh`.
//! * `seqnet/batch_grad_*`: one forward + BPTT backward of a 256-sample batch, with faer's GEMM
//!   sequential or on 2 rayon threads, to choose the GEMM parallelism.
use criterion::{Criterion, Throughput};
use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use seqnet::{LstmParams, LstmShape, Network, Precision, Workspace};
use std::hint::black_box;

fn gaussian(rng: &mut StdRng) -> f64 {
    numerics::random::standard_normal(rng)
}

/// The anchor recipe: `Y = X A + tanh(X B) + 0.1 noise`, X standard normal.
fn anchor_data(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut rng = StdRng::seed_from_u64(0);
    let a = DMatrix::from_fn(10, 12, |_, _| 0.3 * gaussian(&mut rng));
    let b = DMatrix::from_fn(10, 12, |_, _| 0.5 * gaussian(&mut rng));
    let x = DMatrix::from_fn(n, 10, |_, _| gaussian(&mut rng));
    let y = &x * &a
        + (&x * &b).map(f64::tanh)
        + DMatrix::from_fn(n, 12, |_, _| 0.1 * gaussian(&mut rng));
    (x, y)
}

fn params(steps: usize, precision: Precision, threads: usize) -> LstmParams {
    LstmParams::new(10, 12)
        .hidden(64)
        .steps(steps)
        .epochs(1)
        .batch_size(256)
        .validation_fraction(0.0)
        .patience(0)
        .precision(precision)
        .threads(threads)
}

/// Registers the `seqnet` benchmarks.
pub fn benches(c: &mut Criterion) {
    const N: usize = 5_120;
    let (x, y) = anchor_data(N);
    let mut group = c.benchmark_group("seqnet");
    group.sample_size(10);
    group.throughput(Throughput::Elements(N as u64));
    for (name, steps, precision, threads) in [
        ("train_epoch_seq10x1_f32_1thread", 10, Precision::F32, 1),
        ("train_epoch_seq10x1_f32_2threads", 10, Precision::F32, 2),
        ("train_epoch_seq1x10_f32_1thread", 1, Precision::F32, 1),
        ("train_epoch_seq10x1_f64_1thread", 10, Precision::F64, 1),
    ] {
        let p = params(steps, precision, threads);
        group.bench_function(name, |b| {
            b.iter(|| p.fit(black_box(&x), black_box(&y)).unwrap())
        });
    }
    group.throughput(Throughput::Elements(256));
    let shape = LstmShape::new(1, 10, 64, 1, 12).expect("valid shape");
    let net = Network::<f32>::init(shape, 0);
    let mut rng = StdRng::seed_from_u64(1);
    let xb: Vec<f32> = (0..256 * 10).map(|_| rng.random_range(-1.0..1.0)).collect();
    let yb: Vec<f32> = (0..256 * 12).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut grad = vec![0.0f32; shape.n_params()];
    for (name, threads) in [
        ("batch_grad_seq10x1_f32_gemm_seq", 1),
        ("batch_grad_seq10x1_f32_gemm_rayon2", 2),
    ] {
        let mut ws = Workspace::with_gemm_threads(threads);
        group.bench_function(name, |b| {
            b.iter(|| {
                net.loss_and_gradient(black_box(&xb), black_box(&yb), 256, &mut grad, &mut ws)
                    .unwrap()
            })
        });
    }
    group.finish();
}
