//! Module 2, the coefficient estimator `α = f_ML(ρ, x, y)` of Eq. 29, with three
//! implementations:
//!
//! * [`ExactLinearEstimator`]: the linear-Gaussian conditional mean, available when `g_o` is
//!   linear. A network trained by mean-squared error on the Eq.-27 training set approximates
//!   the conditional mean `E[α | ρ, x, μ_o]` under the training distribution. Given `(ρ, x)`,
//!   `μ_o = ρ A ḡ(x) + b̄(x) + B α (+ ε_t)` is affine in `α`, so when `α` is Gaussian with the
//!   training moments `(m(x), Σ_α(x))` the conditional mean is exactly
//!   `α̂ = m + Σ_α Bᵀ (B Σ_α Bᵀ + σ_t² I)⁺ (y − ρ A ḡ(x) − b̄(x) − B m)` (`σ_t` = training-output
//!   noise, `⁺` = pseudo-inverse, which is the limit `σ_t → 0` and reduces to least squares
//!   when `B` has full column rank). For the uniform `α` of the [`SamplingRule`] it is the best
//!   *linear* estimator (linear MMSE), which is what the network converges to when the
//!   relation is linear. No training is needed: it is the reference the learnt estimators
//!   are measured against.
//! * [`RidgeEstimator`]: a `smartcore` ridge regression on quadratic features of the
//!   standardised `[ρ, x, y]` (so products `ρ x_j` are representable), one model per coefficient.
//! * [`LstmEstimator`]: the paper's LSTM (Eq. 28, `seqnet`, hand-written backpropagation through
//!   time), fed `[ρ, x, y]` as a sequence (by default 10 scalar steps), trained by mean-squared
//!   error with Adam and early stopping; `seqnet` standardises inputs and outputs itself.
//!
//! [`SamplingRule`]: crate::SamplingRule

use crate::error::{BamudiError, Result};
use crate::training::{LinearParts, TrainingSet, XContext};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use smartcore::linalg::basic::arrays::Array;
use smartcore::linalg::basic::matrix::DenseMatrix;
use smartcore::linear::ridge_regression::{RidgeRegression, RidgeRegressionParameters};

/// `α = f_ML(ρ, x, y)` (Eq. 29), evaluated for many experiments at one `ρ`.
pub trait CoefficientEstimator: Send + Sync {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// Predicts `α̂` (`N x K`) for the rows of `x` (`N x d`) and `y` (`N x N_o`) at `ρ`.
    /// `ctx` holds the prior-averaged quantities at each row's `x` (used by the exact
    /// estimator; learnt estimators ignore it).
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        ctx: &[XContext],
    ) -> Result<DMatrix<f64>>;
}

/// The exact linear-Gaussian conditional-mean estimator (see the module docs).
///
/// ```
/// use bamudi::estimator::{CoefficientEstimator, ExactLinearEstimator};
/// use bamudi::training::XContext;
/// use nalgebra::DMatrix;
/// // one output, one coefficient, B = [2]: y = 2 α  =>  α̂ = y / 2 when noise-free
/// let est = ExactLinearEstimator::new(DMatrix::from_element(1, 1, 2.0), 0.0).unwrap();
/// let ctx = vec![XContext { mean_ag: vec![0.0], mean_offset: vec![0.0], alpha_half_width: vec![1.0] }];
/// let a = est.predict(1.0, &DMatrix::zeros(1, 1), &DMatrix::from_element(1, 1, 1.0), &ctx).unwrap();
/// assert!((a[(0, 0)] - 0.5).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ExactLinearEstimator {
    b: DMatrix<f64>,
    noise_var: f64,
}

impl ExactLinearEstimator {
    /// From `B = A L` and the training-output noise standard deviation `σ_t`.
    pub fn new(b: DMatrix<f64>, noise_sd: f64) -> Result<Self> {
        if !(noise_sd.is_finite() && noise_sd >= 0.0) {
            return Err(BamudiError::config("sampling.noise_sd", "must be >= 0"));
        }
        Ok(Self {
            b,
            noise_var: noise_sd * noise_sd,
        })
    }

    /// From the linear parts of a model.
    pub fn from_parts(parts: &LinearParts, noise_sd: f64) -> Result<Self> {
        Self::new(parts.b.clone(), noise_sd)
    }

    /// The conditional mean for a general Gaussian prior `α ~ N(m, Σ_α)` and residual
    /// `r = y − ρ A ḡ − b̄` (the formula of the module docs).
    ///
    /// ```
    /// use bamudi::estimator::ExactLinearEstimator;
    /// use nalgebra::{DMatrix, DVector};
    /// let est = ExactLinearEstimator::new(DMatrix::identity(2, 2), 1.0).unwrap();
    /// // prior variance 1, noise variance 1: posterior mean = half the residual
    /// let a = est.conditional_mean(&DVector::zeros(2), &DMatrix::identity(2, 2), &DVector::from_vec(vec![2.0, -4.0])).unwrap();
    /// assert!((a[0] - 1.0).abs() < 1e-12 && (a[1] + 2.0).abs() < 1e-12);
    /// ```
    pub fn conditional_mean(
        &self,
        m: &DVector<f64>,
        cov: &DMatrix<f64>,
        resid: &DVector<f64>,
    ) -> Result<DVector<f64>> {
        // With Σ_α = L Lᵀ and G = B L = U S Vᵀ (thin SVD):
        // Σ_α Bᵀ (B Σ_α Bᵀ + σ² I)⁺ = L V diag(s / (s² + σ²)) Uᵀ,
        // which avoids squaring the condition number of B; singular values below
        // 1e-12 s_max are treated as zero (the pseudo-inverse).
        let l = cov
            .clone()
            .cholesky()
            .ok_or_else(|| BamudiError::NotPositiveDefinite {
                what: "training covariance of alpha".into(),
            })?
            .l();
        let g = &self.b * &l;
        let svd = g.svd(true, true);
        let (u, vt) = match (svd.u, svd.v_t) {
            (Some(u), Some(vt)) => (u, vt),
            _ => {
                return Err(BamudiError::Numerical {
                    context: "exact estimator".into(),
                    reason: "SVD failed".into(),
                });
            }
        };
        let s = svd.singular_values;
        let tol = 1e-12 * s.max();
        let innovation = resid - &self.b * m;
        let mut ut_r = u.transpose() * innovation;
        for (i, v) in ut_r.iter_mut().enumerate() {
            let si = s[i];
            *v *= if si > tol {
                si / (si * si + self.noise_var)
            } else {
                0.0
            };
        }
        Ok(m + l * (vt.transpose() * ut_r))
    }
}

impl CoefficientEstimator for ExactLinearEstimator {
    fn name(&self) -> &'static str {
        "exact_linear"
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        if ctx.len() != y.nrows() || x.nrows() != y.nrows() {
            return Err(BamudiError::dim(
                "exact estimator: contexts/x vs y rows",
                y.nrows(),
                ctx.len(),
            ));
        }
        let k = self.b.ncols();
        let mut out = DMatrix::zeros(y.nrows(), k);
        for (i, c) in ctx.iter().enumerate() {
            // uniform α_k on ±h_k: mean 0, variance h_k² / 3
            let cov = DMatrix::from_diagonal(&DVector::from_iterator(
                k,
                c.alpha_half_width.iter().map(|h| h * h / 3.0),
            ));
            let resid = DVector::from_fn(y.ncols(), |p, _| {
                y[(i, p)] - rho * c.mean_ag[p] - c.mean_offset[p]
            });
            let a = self.conditional_mean(&DVector::zeros(k), &cov, &resid)?;
            out.row_mut(i).copy_from(&a.transpose());
        }
        Ok(out)
    }
}

/// Per-column affine standardisation `z = (v − mean) / sd` (sd floored to avoid division by 0).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardizer {
    /// Column means.
    pub mean: Vec<f64>,
    /// Column standard deviations.
    pub sd: Vec<f64>,
}

impl Standardizer {
    /// Fits to the columns of `m`.
    ///
    /// ```
    /// use bamudi::estimator::Standardizer;
    /// let s = Standardizer::fit(&nalgebra::DMatrix::from_row_slice(2, 1, &[1.0, 3.0]));
    /// assert_eq!(s.mean, vec![2.0]);
    /// assert!((s.apply(&nalgebra::DMatrix::from_element(1, 1, 3.0))[(0, 0)] - 1.0).abs() < 1e-12);
    /// ```
    pub fn fit(m: &DMatrix<f64>) -> Self {
        let n = m.nrows().max(1) as f64;
        let mean: Vec<f64> = (0..m.ncols()).map(|j| m.column(j).sum() / n).collect();
        let sd = (0..m.ncols())
            .map(|j| {
                let v = m
                    .column(j)
                    .iter()
                    .map(|x| (x - mean[j]).powi(2))
                    .sum::<f64>()
                    / n;
                // constant columns: keep them as offsets instead of dividing by zero
                if v.sqrt() > 1e-300 { v.sqrt() } else { 1.0 }
            })
            .collect();
        Self { mean, sd }
    }
    /// Applies the transform.
    ///
    /// ```
    /// use bamudi::estimator::Standardizer;
    /// let s = Standardizer { mean: vec![1.0], sd: vec![2.0] };
    /// assert_eq!(s.apply(&nalgebra::DMatrix::from_element(1, 1, 5.0))[(0, 0)], 2.0);
    /// ```
    pub fn apply(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| {
            (m[(i, j)] - self.mean[j]) / self.sd[j]
        })
    }
    /// Inverts the transform.
    ///
    /// ```
    /// use bamudi::estimator::Standardizer;
    /// let s = Standardizer { mean: vec![1.0], sd: vec![2.0] };
    /// assert_eq!(s.invert(&nalgebra::DMatrix::from_element(1, 1, 2.0))[(0, 0)], 5.0);
    /// ```
    pub fn invert(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| {
            m[(i, j)] * self.sd[j] + self.mean[j]
        })
    }
}

/// Stacks `[ρ, x, y]` row-wise into the learnt estimators' raw input matrix.
pub fn stack_inputs(rho: &[f64], x: &DMatrix<f64>, y: &DMatrix<f64>) -> DMatrix<f64> {
    let d = x.ncols();
    DMatrix::from_fn(x.nrows(), 1 + d + y.ncols(), |i, j| match j {
        0 => rho[i],
        j if j <= d => x[(i, j - 1)],
        j => y[(i, j - 1 - d)],
    })
}

/// Quadratic features `[1, z_i, z_i z_j (i <= j)]` of standardised inputs (the constant column
/// is the intercept: `smartcore`'s ridge without normalisation fits none).
fn quadratic_features(z: &DMatrix<f64>) -> DMatrix<f64> {
    let p = z.ncols();
    let n_feat = 1 + p + p * (p + 1) / 2;
    let mut f = DMatrix::zeros(z.nrows(), n_feat);
    for r in 0..z.nrows() {
        f[(r, 0)] = 1.0;
        let mut c = 1;
        for i in 0..p {
            f[(r, c)] = z[(r, i)];
            c += 1;
        }
        for i in 0..p {
            for j in i..p {
                f[(r, c)] = z[(r, i)] * z[(r, j)];
                c += 1;
            }
        }
    }
    f
}

/// Ridge regression (`smartcore`) on quadratic features; coefficients are copied out of the
/// fitted `smartcore` models so the estimator is serialisable.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RidgeEstimator {
    input_scaler: Standardizer,
    output_scaler: Standardizer,
    /// One row of feature weights per coefficient.
    weights: DMatrix<f64>,
    intercepts: Vec<f64>,
}

impl RidgeEstimator {
    /// Fits one ridge model per coefficient on the training set.
    pub fn fit(train: &TrainingSet, lambda: f64) -> Result<Self> {
        let raw = stack_inputs(&train.rho, &train.x, &train.mu_o);
        let input_scaler = Standardizer::fit(&raw);
        let output_scaler = Standardizer::fit(&train.alpha);
        let feats = quadratic_features(&input_scaler.apply(&raw));
        let targets = output_scaler.apply(&train.alpha);
        let err = |reason: String| BamudiError::Estimator {
            estimator: "ridge",
            reason,
        };
        let rows: Vec<Vec<f64>> = (0..feats.nrows())
            .map(|i| feats.row(i).iter().copied().collect())
            .collect();
        let xm = DenseMatrix::from_2d_vec(&rows).map_err(|e| err(e.to_string()))?;
        let mut weights = DMatrix::zeros(targets.ncols(), feats.ncols());
        let mut intercepts = Vec::with_capacity(targets.ncols());
        for k in 0..targets.ncols() {
            let yk: Vec<f64> = targets.column(k).iter().copied().collect();
            let params = RidgeRegressionParameters::default()
                .with_alpha(lambda)
                .with_normalize(false);
            let model: RidgeRegression<f64, f64, DenseMatrix<f64>, Vec<f64>> =
                RidgeRegression::fit(&xm, &yk, params).map_err(|e| err(e.to_string()))?;
            let coef = model.coefficients();
            for j in 0..feats.ncols() {
                weights[(k, j)] = *coef.get((j, 0));
            }
            intercepts.push(*model.intercept());
        }
        Ok(Self {
            input_scaler,
            output_scaler,
            weights,
            intercepts,
        })
    }
}

impl CoefficientEstimator for RidgeEstimator {
    fn name(&self) -> &'static str {
        "ridge"
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        _ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        let raw = stack_inputs(&vec![rho; x.nrows()], x, y);
        if raw.ncols() != self.input_scaler.mean.len() {
            return Err(BamudiError::dim(
                "ridge estimator inputs",
                self.input_scaler.mean.len(),
                raw.ncols(),
            ));
        }
        let feats = quadratic_features(&self.input_scaler.apply(&raw));
        let mut z = feats * self.weights.transpose();
        for mut row in z.row_iter_mut() {
            for (v, c) in row.iter_mut().zip(&self.intercepts) {
                *v += c;
            }
        }
        Ok(self.output_scaler.invert(&z))
    }
}

/// A fitted estimator of any kind (serialisable, so a re-run can skip training).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FittedEstimator {
    /// See [`ExactLinearEstimator`].
    ExactLinear(ExactLinearEstimator),
    /// See [`RidgeEstimator`].
    Ridge(RidgeEstimator),
    /// See [`LstmEstimator`] (boxed: the network is much larger than the other variants).
    Lstm(Box<LstmEstimator>),
}

impl CoefficientEstimator for FittedEstimator {
    fn name(&self) -> &'static str {
        match self {
            Self::ExactLinear(e) => e.name(),
            Self::Ridge(e) => e.name(),
            Self::Lstm(e) => e.name(),
        }
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        match self {
            Self::ExactLinear(e) => e.predict(rho, x, y, ctx),
            Self::Ridge(e) => e.predict(rho, x, y, ctx),
            Self::Lstm(e) => e.predict(rho, x, y, ctx),
        }
    }
}

/// Hyper-parameters of the paper's LSTM estimator (the fields of
/// [`EstimatorConfig::Lstm`](crate::EstimatorConfig::Lstm)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LstmSettings {
    /// Hidden units.
    pub hidden: usize,
    /// Stacked layers.
    pub layers: usize,
    /// Sequence length (`n_inputs` must be divisible by it).
    pub steps: usize,
    /// Maximum epochs.
    pub epochs: usize,
    /// Mini-batch size.
    pub batch_size: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Validation fraction for early stopping.
    pub validation_fraction: f64,
    /// Early-stopping patience (epochs).
    pub patience: usize,
}

/// The paper's LSTM estimator `α = f_ML(ρ, x, y)` (Sec. 3.3.2, Eq. 28-29).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LstmEstimator {
    net: seqnet::LstmRegressor,
}

impl LstmEstimator {
    /// Trains the network on the Eq.-27 training set (inputs `[ρ, x, μ_o]`, outputs `α`).
    pub fn fit(train: &TrainingSet, s: &LstmSettings, seed: u64, progress: bool) -> Result<Self> {
        let inputs = stack_inputs(&train.rho, &train.x, &train.mu_o);
        let net = seqnet::LstmParams::new(inputs.ncols(), train.alpha.ncols())
            .hidden(s.hidden)
            .layers(s.layers)
            .steps(s.steps)
            .epochs(s.epochs)
            .batch_size(s.batch_size)
            .learning_rate(s.learning_rate)
            .validation_fraction(s.validation_fraction)
            .patience(s.patience)
            .seed(seed)
            .progress(progress)
            .fit(&inputs, &train.alpha)
            .map_err(|e| BamudiError::Estimator {
                estimator: "lstm",
                reason: e.to_string(),
            })?;
        Ok(Self { net })
    }

    /// The trained network (for its training history, or to save it).
    pub fn network(&self) -> &seqnet::LstmRegressor {
        &self.net
    }
}

impl CoefficientEstimator for LstmEstimator {
    fn name(&self) -> &'static str {
        "lstm"
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        _ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        let inputs = stack_inputs(&vec![rho; x.nrows()], x, y);
        self.net
            .predict(&inputs)
            .map_err(|e| BamudiError::Estimator {
                estimator: "lstm",
                reason: e.to_string(),
            })
    }
}
