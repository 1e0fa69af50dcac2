//! Validated hyper-parameter settings and the ML-II fit (multi-start L-BFGS).

use crate::likelihood::{BoundedLml, LmlProblem, NoiseModel};
use crate::model::{FitDiagnostics, GpModel, Scaling, StartReport};
use crate::{GpError, Kernel, Mean};
use argmin::core::{Executor, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Box bounds on the hyper-parameters, in **standardised** units (inputs scaled to unit
/// standard deviation per column, outputs to unit standard deviation). Each pair is `(lo, hi)`
/// on the parameter itself (not its log).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// Signal variance `σ_f²` bounds (relative to the output variance).
    pub signal_variance: (f64, f64),
    /// Length-scale bounds (in input standard deviations).
    pub length_scale: (f64, f64),
    /// Noise variance `σ_n²` bounds (relative to the output variance); used when estimated.
    pub noise_variance: (f64, f64),
}

impl Default for Bounds {
    /// `σ_f² ∈ [1e-6, 1e4]`, `ℓ ∈ [1e-3, 1e3]`, `σ_n² ∈ [1e-10, 1e1]` (standardised units):
    /// wide enough to contain any sensible fit of standardised data, narrow enough that the
    /// logistic reparametrisation keeps useful curvature.
    fn default() -> Self {
        Self {
            signal_variance: (1e-6, 1e4),
            length_scale: (1e-3, 1e3),
            noise_variance: (1e-10, 1e1),
        }
    }
}

/// Hyper-parameters of a GP fit (linfa-style validated builder; `fit` returns a [`GpModel`]).
///
/// Defaults: squared-exponential ARD kernel, estimated white noise (Eq. 33-35), constant GLS
/// mean, 5 extra random starts, seed 0, [`Bounds::default`], a fixed nugget of 1e-10 (relative
/// to the output variance) when the noise is not estimated, at most 200 L-BFGS iterations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GpParams {
    kernel: Kernel,
    mean: Mean,
    estimate_noise: bool,
    restarts: usize,
    seed: u64,
    bounds: Bounds,
    nugget: f64,
    max_iters: u64,
}

impl Default for GpParams {
    fn default() -> Self {
        Self {
            kernel: Kernel::default(),
            mean: Mean::default(),
            estimate_noise: true,
            restarts: 5,
            seed: 0,
            bounds: Bounds::default(),
            nugget: 1e-10,
            max_iters: 200,
        }
    }
}

impl GpParams {
    /// Default settings (see the type docs).
    ///
    /// ```
    /// let p = gp::GpParams::new();
    /// assert_eq!(p, gp::GpParams::default());
    /// ```
    pub fn new() -> Self {
        Self::default()
    }

    /// Selects the signal kernel.
    ///
    /// ```
    /// let p = gp::GpParams::new().kernel(gp::Kernel::Matern52 { ard: false });
    /// ```
    pub fn kernel(mut self, k: Kernel) -> Self {
        self.kernel = k;
        self
    }

    /// Selects the prior mean (its coefficients are always estimated by GLS).
    ///
    /// ```
    /// let p = gp::GpParams::new().mean(gp::Mean::Linear);
    /// ```
    pub fn mean(mut self, m: Mean) -> Self {
        self.mean = m;
        self
    }

    /// `true` (default): estimate the white-noise variance of Eq. (35). `false`: use the fixed
    /// [`nugget`](Self::nugget) instead (near-interpolation).
    ///
    /// ```
    /// let p = gp::GpParams::new().estimate_noise(false);
    /// ```
    pub fn estimate_noise(mut self, yes: bool) -> Self {
        self.estimate_noise = yes;
        self
    }

    /// Number of extra random starts beyond the data-driven default start.
    ///
    /// ```
    /// let p = gp::GpParams::new().restarts(0); // only the default start
    /// ```
    pub fn restarts(mut self, n: usize) -> Self {
        self.restarts = n;
        self
    }

    /// Seed of the random starts (same seed, same data → same model).
    ///
    /// ```
    /// let p = gp::GpParams::new().seed(42);
    /// ```
    pub fn seed(mut self, s: u64) -> Self {
        self.seed = s;
        self
    }

    /// Box bounds on the hyper-parameters (standardised units).
    ///
    /// ```
    /// let b = gp::Bounds { length_scale: (1e-2, 1e2), ..Default::default() };
    /// let p = gp::GpParams::new().bounds(b);
    /// ```
    pub fn bounds(mut self, b: Bounds) -> Self {
        self.bounds = b;
        self
    }

    /// Fixed noise variance relative to the output variance, used when
    /// `estimate_noise(false)` (default 1e-10; diagonal jitter may be added on top if `K` is
    /// numerically singular, and is reported in the model diagnostics).
    ///
    /// ```
    /// let p = gp::GpParams::new().estimate_noise(false).nugget(1e-8);
    /// ```
    pub fn nugget(mut self, v: f64) -> Self {
        self.nugget = v;
        self
    }

    /// Maximum L-BFGS iterations per start.
    ///
    /// ```
    /// let p = gp::GpParams::new().max_iters(50);
    /// ```
    pub fn max_iters(mut self, n: u64) -> Self {
        self.max_iters = n;
        self
    }

    fn validate(&self) -> Result<(), GpError> {
        let b = &self.bounds;
        for (name, (lo, hi)) in [
            ("bounds.signal_variance", b.signal_variance),
            ("bounds.length_scale", b.length_scale),
            ("bounds.noise_variance", b.noise_variance),
        ] {
            if !(lo > 0.0 && hi.is_finite() && lo < hi) {
                return Err(GpError::InvalidParameter {
                    name,
                    reason: format!("need 0 < lo < hi < inf, got ({lo}, {hi})"),
                });
            }
        }
        if !(self.nugget.is_finite() && self.nugget >= 0.0) {
            return Err(GpError::InvalidParameter {
                name: "nugget",
                reason: format!("must be finite and >= 0, got {}", self.nugget),
            });
        }
        if self.max_iters == 0 {
            return Err(GpError::InvalidParameter {
                name: "max_iters",
                reason: "must be > 0".into(),
            });
        }
        Ok(())
    }

    /// Fits the GP by ML-II: standardises `x` (`n × d`, rows are points) and `y`, maximises the
    /// restricted log marginal likelihood (see [`LmlProblem`]) from the default start and
    /// `restarts` random starts with L-BFGS, and keeps the best. The starts run in parallel
    /// on rayon's current thread pool (`RAYON_NUM_THREADS`, or a pool you `install`); the
    /// result is the same for any number of threads.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(12, 1, |i, _| i as f64);
    /// let y: Vec<f64> = (0..12).map(|i| (i as f64 / 3.0).sin()).collect();
    /// let model = gp::GpParams::new().restarts(1).fit(&x, &y)?;
    /// assert!(model.noise_variance() >= 0.0);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn fit(&self, x: &DMatrix<f64>, y: &[f64]) -> Result<GpModel, GpError> {
        let (scaling, xs, problem, noise) = self.prepare(x, y)?;
        let (lower, upper) = self.log_bounds(x.ncols());
        let n = x.nrows() as f64;
        // Starts run in parallel, each on its own clone of the problem (its own buffers and
        // factorisation cache), so a start's result depends neither on the thread nor on
        // the order; `collect` keeps the starts' order, so the best start is the same too.
        let reports = self
            .starts(x.ncols(), &lower, &upper)
            .into_par_iter()
            .map(|theta0| {
                let own = problem.clone();
                let bounded = BoundedLml::new(&own, lower.clone(), upper.clone())?;
                Ok(self.run_start(&bounded, theta0, n))
            })
            .collect::<Result<Vec<StartReport>, GpError>>()?;
        let best = reports
            .iter()
            .enumerate()
            .filter_map(|(i, r)| r.lml.map(|l| (i, l)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i);
        let Some(best) = best else {
            return Err(GpError::OptimizationFailed {
                starts: reports.len(),
                last: reports
                    .last()
                    .and_then(|r| r.error.clone())
                    .unwrap_or_default(),
            });
        };
        let theta = reports[best]
            .final_log_params
            .clone()
            .expect("successful start has params");
        let factor = problem.factor_owned(&theta)?;
        let diagnostics = FitDiagnostics {
            starts: reports,
            best_start: best,
            jitter: factor.jitter * scaling.y_scale * scaling.y_scale,
        };
        Ok(GpModel::from_parts(
            self.kernel,
            self.mean,
            noise,
            scaling,
            &xs,
            factor,
            diagnostics,
        ))
    }

    /// Conditions the GP on `(x, y)` at given hyper-parameters, without optimising:
    /// `log_params = [ln σ_f², ln ℓ…, (ln σ_n² if estimate_noise)]` in standardised units
    /// (e.g. [`Hyperparameters::log_params_standardized`](crate::Hyperparameters) of an earlier
    /// fit on data with the same scaling). Bounds are not applied. The GLS mean is still
    /// estimated. `diagnostics().starts` is empty.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(8, 1, |i, _| i as f64);
    /// let y: Vec<f64> = (0..8).map(|i| (i as f64).sqrt()).collect();
    /// let m = gp::GpParams::new().fit_with_log_params(&x, &y, &[0.0, 0.0, (1e-3f64).ln()])?;
    /// assert!((m.hyperparameters().log_params_standardized[2] - (1e-3f64).ln()).abs() < 1e-15);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn fit_with_log_params(
        &self,
        x: &DMatrix<f64>,
        y: &[f64],
        log_params: &[f64],
    ) -> Result<GpModel, GpError> {
        let (scaling, xs, problem, noise) = self.prepare(x, y)?;
        let factor = problem.factor_owned(log_params)?;
        let diagnostics = FitDiagnostics {
            starts: Vec::new(),
            best_start: 0,
            jitter: factor.jitter * scaling.y_scale * scaling.y_scale,
        };
        Ok(GpModel::from_parts(
            self.kernel,
            self.mean,
            noise,
            scaling,
            &xs,
            factor,
            diagnostics,
        ))
    }

    /// Validates settings and data, standardises, and builds the likelihood problem.
    fn prepare(
        &self,
        x: &DMatrix<f64>,
        y: &[f64],
    ) -> Result<(Scaling, DMatrix<f64>, LmlProblem, NoiseModel), GpError> {
        self.validate()?;
        crate::validate::check_training(x, y)?;
        let scaling = Scaling::from_data(x, y);
        let xs = scaling.standardize_x(x);
        let ys: Vec<f64> = y
            .iter()
            .map(|v| (v - scaling.y_mean) / scaling.y_scale)
            .collect();
        let noise = if self.estimate_noise {
            NoiseModel::Estimated
        } else {
            NoiseModel::Fixed(self.nugget)
        };
        let problem = LmlProblem::new(self.kernel, self.mean, noise, &xs, &ys)?;
        Ok((scaling, xs, problem, noise))
    }

    /// Lower/upper bounds on the log parameters `[ln σ_f², ln ℓ…, (ln σ_n²)]`.
    fn log_bounds(&self, dim: usize) -> (Vec<f64>, Vec<f64>) {
        let m = self.kernel.n_length_scales(dim);
        let b = &self.bounds;
        let mut lo = vec![b.signal_variance.0.ln()];
        let mut hi = vec![b.signal_variance.1.ln()];
        lo.extend(std::iter::repeat_n(b.length_scale.0.ln(), m));
        hi.extend(std::iter::repeat_n(b.length_scale.1.ln(), m));
        if self.estimate_noise {
            lo.push(b.noise_variance.0.ln());
            hi.push(b.noise_variance.1.ln());
        }
        (lo, hi)
    }

    /// The default start (unit signal variance = the standardised output variance, unit
    /// length scales = one input standard deviation, noise 1 % of the output variance),
    /// followed by `restarts` log-uniform random starts in a plausible sub-box
    /// (`σ_f² ∈ [0.1, 10]`, `ℓ ∈ [0.1, 10]`, `σ_n² ∈ [1e-6, 0.5]`), all clamped into the bounds.
    fn starts(&self, dim: usize, lower: &[f64], upper: &[f64]) -> Vec<Vec<f64>> {
        let m = self.kernel.n_length_scales(dim);
        let clamp = |t: Vec<f64>| -> Vec<f64> {
            t.iter()
                .zip(lower.iter().zip(upper))
                .map(|(v, (l, h))| v.clamp(*l, *h))
                .collect()
        };
        let mut first = vec![0.0; 1 + m];
        if self.estimate_noise {
            first.push(1e-2f64.ln());
        }
        let mut out = vec![clamp(first)];
        let mut rng = StdRng::seed_from_u64(self.seed);
        let ln = f64::ln;
        for _ in 0..self.restarts {
            let mut t = vec![rng.random_range(ln(0.1)..ln(10.0))];
            for _ in 0..m {
                t.push(rng.random_range(ln(0.1)..ln(10.0)));
            }
            if self.estimate_noise {
                t.push(rng.random_range(ln(1e-6)..ln(0.5)));
            }
            out.push(clamp(t));
        }
        out
    }

    /// One L-BFGS run from `theta0`; failures are recorded, not propagated.
    fn run_start(&self, bounded: &BoundedLml<'_>, theta0: Vec<f64>, n: f64) -> StartReport {
        let u0 = theta0.clone();
        // Tolerances scale with n because the LML and its gradient are sums over n points:
        // a cost change below 1e-10·n (≈ 1e-12 per point) is round-off level.
        let solver = LBFGS::new(MoreThuenteLineSearch::new(), 10)
            .with_tolerance_grad(1e-7 * n)
            .and_then(|s| s.with_tolerance_cost(1e-10 * n));
        let result = solver.and_then(|solver| {
            Executor::new(BoundedRef(bounded), solver)
                .configure(|s| s.param(u0).max_iters(self.max_iters))
                .run()
        });
        match result {
            Ok(res) => {
                let state = res.state();
                let Some(u) = state.get_best_param() else {
                    return StartReport::failed(theta0, "optimiser returned no parameters".into());
                };
                let theta = bounded.to_bounded(u);
                StartReport {
                    initial_log_params: theta0,
                    final_log_params: Some(theta),
                    lml: Some(-state.get_best_cost()),
                    iterations: state.get_iter(),
                    termination: format!("{}", state.get_termination_status()),
                    error: None,
                }
            }
            Err(e) => StartReport::failed(theta0, e.to_string()),
        }
    }
}

/// Borrowing adaptor so one [`BoundedLml`] (and its factorisation cache) serves every
/// iteration of a start.
struct BoundedRef<'a, 'b>(&'a BoundedLml<'b>);

impl argmin::core::CostFunction for BoundedRef<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        self.0.cost(u)
    }
}

impl argmin::core::Gradient for BoundedRef<'_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, u: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        self.0.gradient(u)
    }
}
