//! The fitted model: prediction, joint posterior covariance (Eq. A3-A4), hyper-parameters.

use crate::likelihood::{Factor, NoiseModel};
use crate::linalg::small_forward_solve;
use crate::validate::check_points;
use crate::{GpError, Kernel, Mean};
use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{Accum, Mat, MatRef, Par};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Number of prediction points processed at once (bounds the `n × chunk` work matrices).
const PREDICT_CHUNK: usize = 1024;

/// Per-column input standardisation and output standardisation, stored in the model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Scaling {
    pub x_mean: Vec<f64>,
    pub x_scale: Vec<f64>,
    pub y_mean: f64,
    pub y_scale: f64,
}

/// Population standard deviation (ddof = 0, as scikit-learn's `normalize_y`); a constant
/// column gets scale 1 so it is centred but not blown up.
fn mean_and_scale(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = v.clone().count() as f64;
    let mean = v.clone().sum::<f64>() / n;
    let var = v.map(|a| (a - mean).powi(2)).sum::<f64>() / n;
    let sd = var.sqrt();
    (mean, if sd > 0.0 && sd.is_finite() { sd } else { 1.0 })
}

impl Scaling {
    pub fn from_data(x: &DMatrix<f64>, y: &[f64]) -> Self {
        let (x_mean, x_scale) = (0..x.ncols())
            .map(|c| mean_and_scale(x.column(c).iter().copied()))
            .unzip();
        let (y_mean, y_scale) = mean_and_scale(y.iter().copied());
        Self {
            x_mean,
            x_scale,
            y_mean,
            y_scale,
        }
    }

    pub fn standardize_x(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        DMatrix::from_fn(x.nrows(), x.ncols(), |r, c| {
            (x[(r, c)] - self.x_mean[c]) / self.x_scale[c]
        })
    }

    /// Row-major standardised copy.
    pub(crate) fn standardize_rows(
        &self,
        x: &DMatrix<f64>,
        rows: std::ops::Range<usize>,
    ) -> Vec<f64> {
        let d = x.ncols();
        let mut out = Vec::with_capacity(rows.len() * d);
        for r in rows {
            out.extend((0..d).map(|c| (x[(r, c)] - self.x_mean[c]) / self.x_scale[c]));
        }
        out
    }
}

/// Latent predictive mean and variance at a set of points (original output units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    /// Posterior mean `E[f(x) | y]` (Eq. A3).
    pub mean: DVector<f64>,
    /// Posterior variance of the latent `f(x)` (no observation noise), including the GLS term
    /// of Eq. (A4); clamped at 0 against round-off.
    pub variance: DVector<f64>,
}

/// Fitted hyper-parameters in original units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hyperparameters {
    /// Signal variance `σ_f²` (output units²).
    pub signal_variance: f64,
    /// One length scale per input column, in that column's units. An isotropic kernel has one
    /// length scale in standardised inputs, which maps to `ℓ · sd(column)` per column.
    pub length_scales: Vec<f64>,
    /// White-noise variance `σ_n²` (output units²), the fixed nugget if not estimated.
    pub noise_variance: f64,
    /// The optimised vector `[ln σ_f², ln ℓ…, (ln σ_n²)]` in standardised units.
    pub log_params_standardized: Vec<f64>,
}

/// What happened in one optimiser start.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartReport {
    /// Starting log parameters (standardised units).
    pub initial_log_params: Vec<f64>,
    /// Best log parameters found (`None` if the run failed).
    pub final_log_params: Option<Vec<f64>>,
    /// Best restricted LML reached, in standardised units (`None` if failed).
    pub lml: Option<f64>,
    /// L-BFGS iterations used.
    pub iterations: u64,
    /// argmin's termination status.
    pub termination: String,
    /// Error message if the run failed.
    pub error: Option<String>,
}

impl StartReport {
    pub(crate) fn failed(initial: Vec<f64>, error: String) -> Self {
        Self {
            initial_log_params: initial,
            final_log_params: None,
            lml: None,
            iterations: 0,
            termination: "failed".into(),
            error: Some(error),
        }
    }
}

/// Fit diagnostics: every start, which one won, and any jitter added to `K`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitDiagnostics {
    /// One report per start (the default start first).
    pub starts: Vec<StartReport>,
    /// Index into `starts` of the selected optimum.
    pub best_start: usize,
    /// Diagonal jitter added to the training covariance of the final model (output units²;
    /// 0 if `K` factorised as is). Jitter acts like extra noise; it is listed here, never hidden.
    pub jitter: f64,
}

/// A fitted GP regression model (ML-II hyper-parameters, GLS mean, Cholesky factor).
///
/// All public results are in original units; internally inputs and outputs are standardised.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GpModel {
    pub(crate) kernel: Kernel,
    pub(crate) mean: Mean,
    noise_estimated: bool,
    pub(crate) scaling: Scaling,
    pub(crate) n: usize,
    pub(crate) d: usize,
    pub(crate) p: usize,
    /// Row-major standardised training inputs.
    pub(crate) x_std: Vec<f64>,
    log_params: Vec<f64>,
    pub(crate) sf2: f64,
    pub(crate) inv_ls2: Vec<f64>,
    sn2: f64,
    /// Column-major lower Cholesky factor of `K + (σ_n² + jitter) I` (standardised units).
    chol: Vec<f64>,
    alpha: Vec<f64>,
    /// Column-major `L⁻¹ H`.
    pub(crate) linv_h: Vec<f64>,
    beta: Vec<f64>,
    pub(crate) a_chol: Vec<f64>,
    pub(crate) lml_std: f64,
    diagnostics: FitDiagnostics,
}

impl GpModel {
    pub(crate) fn from_parts(
        kernel: Kernel,
        mean: Mean,
        noise: NoiseModel,
        scaling: Scaling,
        xs: &DMatrix<f64>,
        f: Factor,
        diagnostics: FitDiagnostics,
    ) -> Self {
        let (n, d) = xs.shape();
        let p = mean.n_coefficients(d);
        let m = kernel.n_length_scales(d);
        let theta = &f.theta;
        let inv_ls2 = (0..d)
            .map(|i| (-2.0 * theta[1 + if m == 1 { 0 } else { i }]).exp())
            .collect();
        let sn2 = match noise {
            NoiseModel::Estimated => theta[1 + m].exp(),
            NoiseModel::Fixed(v) => v,
        };
        let mut x_std = Vec::with_capacity(n * d);
        for r in 0..n {
            x_std.extend(xs.row(r).iter());
        }
        let col_major = |m: &Mat<f64>| -> Vec<f64> {
            (0..m.ncols())
                .flat_map(|c| (0..m.nrows()).map(move |r| m[(r, c)]))
                .collect()
        };
        Self {
            kernel,
            mean,
            noise_estimated: matches!(noise, NoiseModel::Estimated),
            scaling,
            n,
            d,
            p,
            x_std,
            log_params: theta.clone(),
            sf2: theta[0].exp(),
            inv_ls2,
            sn2,
            chol: col_major(&f.l),
            alpha: f.alpha,
            linv_h: col_major(&f.linv_h),
            beta: f.beta,
            a_chol: f.a_chol,
            lml_std: f.lml,
            diagnostics,
        }
    }

    pub(crate) fn chol_ref(&self) -> MatRef<'_, f64> {
        MatRef::from_column_major_slice(&self.chol, self.n, self.n)
    }

    /// Standardised signal covariance between row-major point sets `a` (rows `na`) and the
    /// training set, as an `n × na` matrix.
    fn cross_cov(&self, a: &[f64]) -> Mat<f64> {
        let d = self.d;
        let na = a.len() / d;
        Mat::from_fn(self.n, na, |i, j| {
            let r2 = crate::kernel::scaled_sq_dist(
                &self.x_std[i * d..(i + 1) * d],
                &a[j * d..(j + 1) * d],
                &self.inv_ls2,
            );
            self.sf2 * self.kernel.correlation(r2)
        })
    }

    /// For standardised row-major points: latent mean (standardised), `V = L⁻¹ k*` and
    /// `U = L_A⁻¹ (h* − Hᵀ K⁻¹ k*)` (the Eq. A4 vectors), both column per point.
    pub(crate) fn latent_parts(&self, a: &[f64]) -> (Vec<f64>, Mat<f64>, Mat<f64>) {
        let (d, p) = (self.d, self.p);
        let na = a.len() / d;
        let mut v = self.cross_cov(a);
        let mut mean = vec![0.0; na];
        let mut h = vec![0.0; p];
        let mut u = Mat::<f64>::zeros(p, na);
        for j in 0..na {
            self.mean.basis_into(&a[j * d..(j + 1) * d], &mut h);
            let kstar_alpha: f64 = (0..self.n).map(|i| v[(i, j)] * self.alpha[i]).sum();
            mean[j] = kstar_alpha + h.iter().zip(&self.beta).map(|(a, b)| a * b).sum::<f64>();
            for k in 0..p {
                u[(k, j)] = h[k];
            }
        }
        solve_lower_triangular_in_place(self.chol_ref(), v.as_mut(), Par::Seq);
        if p > 0 {
            let linv_h = MatRef::from_column_major_slice(&self.linv_h, self.n, p);
            // u ← h* − (L⁻¹H)ᵀ (L⁻¹k*), then L_A⁻¹ u.
            faer::linalg::matmul::matmul(
                u.as_mut(),
                Accum::Add,
                linv_h.transpose(),
                v.as_ref(),
                -1.0,
                Par::Seq,
            );
            let mut col = vec![0.0; p];
            for j in 0..na {
                for k in 0..p {
                    col[k] = u[(k, j)];
                }
                small_forward_solve(&self.a_chol, p, &mut col);
                for k in 0..p {
                    u[(k, j)] = col[k];
                }
            }
        }
        (mean, v, u)
    }

    /// Posterior mean and latent variance (Eq. A3 and the diagonal of Eq. A4) at the rows of
    /// `x` (`m × d`), in original output units.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// let pred = model.predict(&DMatrix::from_column_slice(2, 1, &[2.5, 20.0]))?;
    /// assert!(pred.variance[1] > pred.variance[0]); // far from data → more uncertain
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn predict(&self, x: &DMatrix<f64>) -> Result<Prediction, GpError> {
        check_points(x, self.d, "x")?;
        let m = x.nrows();
        let (ym, ys2) = (self.scaling.y_mean, self.scaling.y_scale.powi(2));
        let mut mean = DVector::zeros(m);
        let mut variance = DVector::zeros(m);
        let mut start = 0;
        while start < m {
            let end = (start + PREDICT_CHUNK).min(m);
            let a = self.scaling.standardize_rows(x, start..end);
            let (mu, v, u) = self.latent_parts(&a);
            for j in 0..end - start {
                let vv: f64 = v.col(j).iter().map(|t| t * t).sum();
                let uu: f64 = u.col(j).iter().map(|t| t * t).sum();
                mean[start + j] = ym + self.scaling.y_scale * mu[j];
                variance[start + j] = ((self.sf2 - vv + uu) * ys2).max(0.0);
            }
            start = end;
        }
        Ok(Prediction { mean, variance })
    }

    /// Like [`predict`](Self::predict) but the variance is that of a new noisy observation
    /// (latent variance plus the white-noise variance of Eq. 35).
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// let xs = DMatrix::from_column_slice(1, 1, &[2.5]);
    /// let (f, obs) = (model.predict(&xs)?, model.predict_observation(&xs)?);
    /// assert!((obs.variance[0] - f.variance[0] - model.noise_variance()).abs() < 1e-12);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn predict_observation(&self, x: &DMatrix<f64>) -> Result<Prediction, GpError> {
        let mut p = self.predict(x)?;
        let nv = self.noise_variance();
        p.variance.iter_mut().for_each(|v| *v += nv);
        Ok(p)
    }

    /// Joint posterior covariance of the latent `f` between the rows of `x1` (`m1 × d`) and of
    /// `x2` (`m2 × d`), Eq. (A4) including the GLS term; `m1 × m2`, original output units².
    /// This is what Eq. (51) needs for the cross-experiment covariances.
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// let xs = DMatrix::from_column_slice(2, 1, &[2.5, 3.0]);
    /// let c = model.posterior_cov(&xs, &xs)?;
    /// let v = model.predict(&xs)?.variance;
    /// assert!((c[(0, 0)] - v[0]).abs() <= 1e-9 * (1.0 + v[0]));
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn posterior_cov(
        &self,
        x1: &DMatrix<f64>,
        x2: &DMatrix<f64>,
    ) -> Result<DMatrix<f64>, GpError> {
        check_points(x1, self.d, "x1")?;
        check_points(x2, self.d, "x2")?;
        let d = self.d;
        let a1 = self.scaling.standardize_rows(x1, 0..x1.nrows());
        let a2 = self.scaling.standardize_rows(x2, 0..x2.nrows());
        let (_, v1, u1) = self.latent_parts(&a1);
        let (_, v2, u2) = self.latent_parts(&a2);
        let mut c = Mat::<f64>::from_fn(x1.nrows(), x2.nrows(), |i, j| {
            let r2 = crate::kernel::scaled_sq_dist(
                &a1[i * d..(i + 1) * d],
                &a2[j * d..(j + 1) * d],
                &self.inv_ls2,
            );
            self.sf2 * self.kernel.correlation(r2)
        });
        faer::linalg::matmul::matmul(
            c.as_mut(),
            Accum::Add,
            v1.transpose(),
            v2.as_ref(),
            -1.0,
            Par::Seq,
        );
        if self.p > 0 {
            faer::linalg::matmul::matmul(
                c.as_mut(),
                Accum::Add,
                u1.transpose(),
                u2.as_ref(),
                1.0,
                Par::Seq,
            );
        }
        let ys2 = self.scaling.y_scale.powi(2);
        Ok(DMatrix::from_fn(x1.nrows(), x2.nrows(), |i, j| {
            c[(i, j)] * ys2
        }))
    }

    /// White-noise variance `σ_n²` of Eq. (35) in original output units² (the fixed nugget if
    /// the noise was not estimated; any jitter is reported separately in the diagnostics).
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// assert!(model.noise_variance() > 0.0);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn noise_variance(&self) -> f64 {
        self.sn2 * self.scaling.y_scale.powi(2)
    }

    /// Restricted log marginal likelihood at the optimum, for the data in ORIGINAL output units:
    /// the standardised value minus `(n − p) ln s_y` (the Jacobian of `y = ȳ + s_y y_std` on the
    /// `n − p` error contrasts). With `Mean::Zero` (`p = 0`) it is the ordinary log marginal
    /// likelihood of the mean-centred data, i.e. scikit-learn's
    /// `log_marginal_likelihood_value_` (normalize_y=True) minus `n ln s_y`.
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// assert!(model.log_marginal_likelihood().is_finite());
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.lml_std - (self.n - self.p) as f64 * self.scaling.y_scale.ln()
    }

    /// Restricted log marginal likelihood of the standardised outputs (the optimised value;
    /// comparable to scikit-learn's with `normalize_y=True` when `Mean::Zero`).
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| 3.0 * (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// assert!(model.log_marginal_likelihood_standardized() > model.log_marginal_likelihood());
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn log_marginal_likelihood_standardized(&self) -> f64 {
        self.lml_std
    }

    /// Fitted hyper-parameters in original units.
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 2, |i, j| (i * (j + 1)) as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// let h = model.hyperparameters();
    /// assert_eq!(h.length_scales.len(), 2);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn hyperparameters(&self) -> Hyperparameters {
        let ys2 = self.scaling.y_scale.powi(2);
        Hyperparameters {
            signal_variance: self.sf2 * ys2,
            length_scales: self
                .inv_ls2
                .iter()
                .zip(&self.scaling.x_scale)
                .map(|(w, s)| s / w.sqrt())
                .collect(),
            noise_variance: self.sn2 * ys2,
            log_params_standardized: self.log_params.clone(),
        }
    }

    /// GLS coefficients `β̂` of the prior mean in original units: `[]` for `Mean::Zero`,
    /// `[c]` for `Mean::Constant`, `[c, b_1, …, b_d]` (`c + Σ b_j x_j`) for `Mean::Linear`.
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(12, 1, |i, _| i as f64);
    /// let y: Vec<f64> = (0..12).map(|i| 2.0 + 0.5 * i as f64 + 0.1 * (i as f64).sin()).collect();
    /// let model = gp::GpParams::new().mean(gp::Mean::Linear).restarts(0).fit(&x, &y)?;
    /// assert_eq!(model.trend_coefficients().len(), 2);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn trend_coefficients(&self) -> Vec<f64> {
        let s = &self.scaling;
        match self.mean {
            Mean::Zero => Vec::new(),
            Mean::Constant => vec![s.y_mean + s.y_scale * self.beta[0]],
            Mean::Linear => {
                let slopes: Vec<f64> = (0..self.d)
                    .map(|j| s.y_scale * self.beta[1 + j] / s.x_scale[j])
                    .collect();
                let shift: f64 = (0..self.d).map(|j| slopes[j] * s.x_mean[j]).sum();
                let mut out = vec![s.y_mean + s.y_scale * self.beta[0] - shift];
                out.extend(slopes);
                out
            }
        }
    }

    /// Fit diagnostics (all starts, the chosen one, jitter).
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(2).fit(&x, &y)?;
    /// assert_eq!(model.diagnostics().starts.len(), 3);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn diagnostics(&self) -> &FitDiagnostics {
        &self.diagnostics
    }

    /// The kernel, the prior mean and whether the noise was estimated.
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// assert_eq!(model.spec(), (gp::Kernel::default(), gp::Mean::Constant, true));
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn spec(&self) -> (Kernel, Mean, bool) {
        (self.kernel, self.mean, self.noise_estimated)
    }

    /// Number of training points and input dimension.
    ///
    /// ```
    /// # use nalgebra::DMatrix;
    /// # let x = DMatrix::from_fn(10, 1, |i, _| i as f64);
    /// # let y: Vec<f64> = (0..10).map(|i| (i as f64 / 2.0).cos()).collect();
    /// let model = gp::GpParams::new().restarts(0).fit(&x, &y)?;
    /// assert_eq!(model.shape(), (10, 1));
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn shape(&self) -> (usize, usize) {
        (self.n, self.d)
    }
}
