//! The (restricted) log marginal likelihood and its analytic gradient, packaged as an argmin
//! problem.
//!
//! # Which likelihood
//! With a regression mean (`Mean::Constant`, `Mean::Linear`) the coefficients `β` are profiled
//! out by GLS *and* the likelihood is the **restricted** (REML) one,
//!
//! `ln L_R(θ) = −½ rᵀK⁻¹r − ½ ln|K| − ½ ln|HᵀK⁻¹H| + ½ ln|HᵀH| − ½ (n−p) ln 2π`,
//!
//! with `r = y − Hβ̂(θ)`. This is the marginal likelihood of `y` after integrating `β` out under a
//! flat prior — the same assumption that produces the extra variance term of Eq. (A4), so the
//! fit and the predictions are consistent. The constant `½ ln|HᵀH|` (Harville's form) makes the
//! value independent of how the basis is scaled. With `Mean::Zero` (`p = 0`) it is the ordinary
//! log marginal likelihood. Its gradient is
//! `∂ ln L_R / ∂θ_j = ½ tr[(ααᵀ − P) ∂K/∂θ_j]`, `α = K⁻¹ r`, `P = K⁻¹ − K⁻¹H (HᵀK⁻¹H)⁻¹ HᵀK⁻¹`.
//!
//! # Parameters
//! The optimiser works on natural logs of the (standardised-unit) hyper-parameters, in the
//! order `[ln σ_f², ln ℓ_1, …, ln ℓ_m, ln σ_n²]` (`m` = 1 or `d`; the noise entry only when it is
//! estimated). Bounds are imposed by [`BoundedLml`] (projection onto the box plus a quadratic
//! penalty outside it), so argmin's unconstrained L-BFGS can be used.

use crate::linalg::{
    cholesky_with_jitter, small_backward_solve, small_cholesky, small_forward_solve,
};
use crate::{GpError, Kernel, Mean};
use argmin::core::{CostFunction, Error as ArgminError, Gradient};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Mat, Par};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::sync::Mutex;

/// How the white-noise variance `σ_n²` of Eq. (35) is treated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum NoiseModel {
    /// `ln σ_n²` is the last optimised hyper-parameter.
    Estimated,
    /// A fixed nugget `σ_n²` (in the units of the outputs given to the problem).
    Fixed(f64),
}

/// Value of the log marginal likelihood at one parameter vector, plus what it took.
#[derive(Clone, Debug, PartialEq)]
pub struct LmlValue {
    /// Restricted log marginal likelihood (see module docs).
    pub lml: f64,
    /// Gradient with respect to the log parameters (empty if not requested).
    pub gradient: Vec<f64>,
    /// Diagonal jitter that had to be added to `K` (0 if none).
    pub jitter: f64,
}

/// Everything computed from one factorisation of `K` that prediction needs.
#[derive(Clone, Debug)]
pub(crate) struct Factor {
    pub theta: Vec<f64>,
    pub lml: f64,
    pub jitter: f64,
    /// Lower Cholesky factor of `K + (σ_n² + jitter) I`.
    pub l: Mat<f64>,
    /// `α = K⁻¹ (y − Hβ̂)`.
    pub alpha: Vec<f64>,
    /// `L⁻¹ H` (`n × p`).
    pub linv_h: Mat<f64>,
    /// GLS coefficients.
    pub beta: Vec<f64>,
    /// Column-major lower Cholesky factor of `HᵀK⁻¹H` (`p × p`).
    pub a_chol: Vec<f64>,
}

/// Reusable buffers so repeated evaluations (thousands per fit) do not allocate `n × n` matrices.
struct Workspace {
    kf: Mat<f64>,
    gfac: Mat<f64>,
    kinv: Mat<f64>,
    tmp_np: Mat<f64>,
    mem: MemBuffer,
    last: Option<Factor>,
    last_grad: Option<(Vec<f64>, Vec<f64>)>,
}

impl Workspace {
    /// Buffers for `n` points and `p` regression coefficients (`gfac` only for Matérn, whose
    /// length-scale derivative factor differs from the correlation).
    fn new(n: usize, p: usize, matern: bool) -> Self {
        let par = Par::Seq;
        let req = StackReq::any_of(&[
            numerics::cholesky::scratch(n, par),
            llt::inverse::inverse_scratch::<f64>(n, par),
        ]);
        Self {
            kf: Mat::zeros(n, n),
            gfac: Mat::zeros(if matern { n } else { 0 }, n),
            kinv: Mat::zeros(n, n),
            tmp_np: Mat::zeros(n, p),
            mem: MemBuffer::new(req),
            last: None,
            last_grad: None,
        }
    }
}

/// The log-marginal-likelihood problem for fixed training data: an argmin [`CostFunction`]
/// (negative LML) and [`Gradient`] over the log hyper-parameters (see module docs).
///
/// The data are used exactly as given (the model standardises them before building the
/// problem). The last factorisation is cached, so argmin's separate `cost` and `gradient`
/// calls at the same point factorise `K` once.
pub struct LmlProblem {
    kernel: Kernel,
    mean: Mean,
    noise: NoiseModel,
    n: usize,
    d: usize,
    p: usize,
    /// Row-major `n × d` inputs.
    x: Vec<f64>,
    y: Vec<f64>,
    /// `n × p` regression basis.
    h: Mat<f64>,
    /// `½ ln|HᵀH|`, the basis-scale normalisation of the REML value.
    half_logdet_hth: f64,
    ws: Mutex<Workspace>,
}

impl Clone for LmlProblem {
    /// The same problem with its own, empty workspace (buffers and factorisation cache): a
    /// clone can be evaluated on another thread. The cache never changes a value (it only
    /// skips refactorising at the same point), so a clone returns the same numbers.
    fn clone(&self) -> Self {
        Self {
            kernel: self.kernel,
            mean: self.mean,
            noise: self.noise,
            n: self.n,
            d: self.d,
            p: self.p,
            x: self.x.clone(),
            y: self.y.clone(),
            h: self.h.clone(),
            half_logdet_hth: self.half_logdet_hth,
            ws: Mutex::new(self.fresh_workspace()),
        }
    }
}

impl std::fmt::Debug for LmlProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LmlProblem")
            .field("kernel", &self.kernel)
            .field("mean", &self.mean)
            .field("noise", &self.noise)
            .field("n", &self.n)
            .field("d", &self.d)
            .finish_non_exhaustive()
    }
}

impl LmlProblem {
    /// Builds the problem for inputs `x` (`n × d`, rows are points) and outputs `y` (length `n`).
    ///
    /// Errors: empty data, shape mismatch, non-finite values, `n ≤ p`, a fixed noise that is
    /// negative or non-finite, or a rank-deficient regression basis.
    ///
    /// ```
    /// use gp::{Kernel, LmlProblem, Mean, NoiseModel};
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 3.0]);
    /// let p = LmlProblem::new(Kernel::default(), Mean::Zero, NoiseModel::Estimated, &x, &[0.0, 1.0, 0.5, 0.2])?;
    /// assert_eq!(p.n_params(), 3); // ln σ_f², ln ℓ, ln σ_n²
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn new(
        kernel: Kernel,
        mean: Mean,
        noise: NoiseModel,
        x: &DMatrix<f64>,
        y: &[f64],
    ) -> Result<Self, GpError> {
        crate::validate::check_training(x, y)?;
        let (n, d) = x.shape();
        let p = mean.n_coefficients(d);
        if n <= p {
            return Err(GpError::TooFewPoints { n, p });
        }
        if let NoiseModel::Fixed(v) = noise
            && !(v.is_finite() && v >= 0.0)
        {
            return Err(GpError::InvalidParameter {
                name: "fixed noise variance",
                reason: format!("must be finite and >= 0, got {v}"),
            });
        }
        let mut xr = Vec::with_capacity(n * d);
        for i in 0..n {
            xr.extend(x.row(i).iter());
        }
        let mut h = Mat::<f64>::zeros(n, p);
        let mut row = vec![0.0; p];
        for i in 0..n {
            mean.basis_into(&xr[i * d..(i + 1) * d], &mut row);
            for k in 0..p {
                h[(i, k)] = row[k];
            }
        }
        let half_logdet_hth = half_logdet_gram(&h)?;
        let ws = Workspace::new(n, p, matches!(kernel, Kernel::Matern52 { .. }));
        Ok(Self {
            kernel,
            mean,
            noise,
            n,
            d,
            p,
            x: xr,
            y: y.to_vec(),
            h,
            half_logdet_hth,
            ws: Mutex::new(ws),
        })
    }

    /// Empty buffers for this problem's size and kernel.
    fn fresh_workspace(&self) -> Workspace {
        Workspace::new(
            self.n,
            self.p,
            matches!(self.kernel, Kernel::Matern52 { .. }),
        )
    }

    /// Number of optimised log parameters: `1 + n_length_scales + (1 if noise estimated)`.
    ///
    /// ```
    /// use gp::{Kernel, LmlProblem, Mean, NoiseModel};
    /// let x = nalgebra::DMatrix::from_row_slice(3, 2, &[0.0, 0.0, 1.0, 0.5, 2.0, 0.1]);
    /// let p = LmlProblem::new(Kernel::Matern52 { ard: true }, Mean::Constant, NoiseModel::Fixed(1e-8), &x, &[1.0, 2.0, 0.0])?;
    /// assert_eq!(p.n_params(), 3);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn n_params(&self) -> usize {
        1 + self.kernel.n_length_scales(self.d)
            + usize::from(matches!(self.noise, NoiseModel::Estimated))
    }

    /// Number of training points.
    ///
    /// ```
    /// # use gp::{Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(3, 1, &[0.0, 1.0, 2.0]);
    /// let p = LmlProblem::new(Kernel::default(), Mean::Zero, NoiseModel::Estimated, &x, &[1.0, 2.0, 0.0])?;
    /// assert_eq!(p.n_points(), 3);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn n_points(&self) -> usize {
        self.n
    }

    /// Number of GLS regression coefficients `p` of the prior mean.
    ///
    /// ```
    /// # use gp::{Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(3, 1, &[0.0, 1.0, 2.0]);
    /// let p = LmlProblem::new(Kernel::default(), Mean::Linear, NoiseModel::Estimated, &x, &[1.0, 2.0, 0.0])?;
    /// assert_eq!(p.n_coefficients(), 2);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn n_coefficients(&self) -> usize {
        self.p
    }

    /// Restricted log marginal likelihood at `log_params` (no gradient).
    ///
    /// ```
    /// # use gp::{Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 3.0]);
    /// let p = LmlProblem::new(Kernel::default(), Mean::Zero, NoiseModel::Estimated, &x, &[0.0, 1.0, 0.5, 0.2])?;
    /// let v = p.log_marginal_likelihood(&[0.0, 0.0, -2.0])?;
    /// assert!(v.lml.is_finite() && v.gradient.is_empty());
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn log_marginal_likelihood(&self, log_params: &[f64]) -> Result<LmlValue, GpError> {
        let f = self.factor_cached(log_params)?;
        Ok(LmlValue {
            lml: f.0,
            gradient: Vec::new(),
            jitter: f.1,
        })
    }

    /// Restricted log marginal likelihood and its analytic gradient at `log_params`.
    ///
    /// ```
    /// # use gp::{Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 3.0]);
    /// let p = LmlProblem::new(Kernel::default(), Mean::Constant, NoiseModel::Estimated, &x, &[0.0, 1.0, 0.5, 0.2])?;
    /// let v = p.lml_and_gradient(&[0.0, 0.0, -2.0])?;
    /// assert_eq!(v.gradient.len(), 3);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn lml_and_gradient(&self, log_params: &[f64]) -> Result<LmlValue, GpError> {
        let (lml, jitter) = self.factor_cached(log_params)?;
        let mut ws = self.ws.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((t, g)) = &ws.last_grad
            && t.as_slice() == log_params
        {
            return Ok(LmlValue {
                lml,
                gradient: g.clone(),
                jitter,
            });
        }
        let gradient = self.gradient_from_cache(&mut ws);
        ws.last_grad = Some((log_params.to_vec(), gradient.clone()));
        Ok(LmlValue {
            lml,
            gradient,
            jitter,
        })
    }

    /// Splits a log-parameter vector into `(σ_f², inverse squared length scales expanded to d
    /// columns, σ_n²)`.
    fn unpack(&self, theta: &[f64]) -> Result<(f64, Vec<f64>, f64), GpError> {
        if theta.len() != self.n_params() {
            return Err(GpError::ShapeMismatch {
                name: "log_params",
                what: "entries",
                expected: self.n_params(),
                found: theta.len(),
            });
        }
        if let Some((i, v)) = theta.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(GpError::NonFinite {
                name: "log_params",
                row: i,
                col: 0,
                value: *v,
            });
        }
        let m = self.kernel.n_length_scales(self.d);
        let sf2 = theta[0].exp();
        let inv_ls2: Vec<f64> = (0..self.d)
            .map(|i| (-2.0 * theta[1 + if m == 1 { 0 } else { i }]).exp())
            .collect();
        let sn2 = match self.noise {
            NoiseModel::Estimated => theta[1 + m].exp(),
            NoiseModel::Fixed(v) => v,
        };
        Ok((sf2, inv_ls2, sn2))
    }

    /// Returns `(lml, jitter)` at `theta`, refactorising only if `theta` changed.
    fn factor_cached(&self, theta: &[f64]) -> Result<(f64, f64), GpError> {
        let mut guard = self.ws.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(f) = &guard.last
            && f.theta.as_slice() == theta
        {
            return Ok((f.lml, f.jitter));
        }
        let ws = &mut *guard;
        let f = self.factorize(theta, ws)?;
        let out = (f.lml, f.jitter);
        ws.last = Some(f);
        ws.last_grad = None;
        Ok(out)
    }

    /// Factorisation at `theta` for building a model (not cached).
    pub(crate) fn factor_owned(&self, theta: &[f64]) -> Result<Factor, GpError> {
        let mut guard = self.ws.lock().unwrap_or_else(|e| e.into_inner());
        let ws = &mut *guard;
        let f = self.factorize(theta, ws)?;
        Ok(f)
    }

    /// Fills the signal covariance (lower triangle) and, for Matérn, the length-scale factor.
    fn fill_kernel(&self, sf2: f64, inv_ls2: &[f64], ws: &mut Workspace) {
        let (n, d) = (self.n, self.d);
        let matern = matches!(self.kernel, Kernel::Matern52 { .. });
        for j in 0..n {
            let xj = &self.x[j * d..(j + 1) * d];
            for i in j..n {
                let xi = &self.x[i * d..(i + 1) * d];
                let r2 = crate::kernel::scaled_sq_dist(xi, xj, inv_ls2);
                if matern {
                    let (c, g) = self.kernel.correlation_and_factor(r2);
                    ws.kf[(i, j)] = sf2 * c;
                    ws.gfac[(i, j)] = sf2 * g;
                } else {
                    ws.kf[(i, j)] = sf2 * self.kernel.correlation(r2);
                }
            }
        }
    }

    fn factorize(&self, theta: &[f64], ws: &mut Workspace) -> Result<Factor, GpError> {
        let (n, p) = (self.n, self.p);
        let (sf2, inv_ls2, sn2) = self.unpack(theta)?;
        self.fill_kernel(sf2, &inv_ls2, ws);
        let mut l = ws
            .last
            .take()
            .map(|f| f.l)
            .unwrap_or_else(|| Mat::zeros(n, n));
        let jitter = cholesky_with_jitter(ws.kf.as_ref(), sn2, &mut l, &mut ws.mem)?;
        let logdet_k: f64 = 2.0 * (0..n).map(|i| l[(i, i)].ln()).sum::<f64>();

        // z = L⁻¹y, L⁻¹H
        let mut z = Mat::<f64>::from_fn(n, 1, |i, _| self.y[i]);
        solve_lower_triangular_in_place(l.as_ref(), z.as_mut(), Par::Seq);
        let mut linv_h = self.h.clone();
        solve_lower_triangular_in_place(l.as_ref(), linv_h.as_mut(), Par::Seq);

        // GLS: A = HᵀK⁻¹H, β = A⁻¹ HᵀK⁻¹y, z ← L⁻¹(y − Hβ)
        let mut a = vec![0.0; p * p];
        let mut beta = vec![0.0; p];
        for c in 0..p {
            for r in 0..p {
                a[r + c * p] = (0..n).map(|i| linv_h[(i, r)] * linv_h[(i, c)]).sum();
            }
            beta[c] = (0..n).map(|i| linv_h[(i, c)] * z[(i, 0)]).sum();
        }
        small_cholesky(&mut a, p).map_err(|index| GpError::NotPositiveDefinite {
            matrix: "H^T K^-1 H (GLS normal matrix)",
            index,
            max_jitter: 0.0,
        })?;
        small_forward_solve(&a, p, &mut beta);
        small_backward_solve(&a, p, &mut beta);
        for i in 0..n {
            let hb: f64 = (0..p).map(|c| linv_h[(i, c)] * beta[c]).sum();
            z[(i, 0)] -= hb;
        }
        let quad: f64 = (0..n).map(|i| z[(i, 0)] * z[(i, 0)]).sum();
        let logdet_a: f64 = 2.0 * (0..p).map(|i| a[i + i * p].ln()).sum::<f64>();
        solve_upper_triangular_in_place(l.as_ref().transpose(), z.as_mut(), Par::Seq);
        let alpha: Vec<f64> = (0..n).map(|i| z[(i, 0)]).collect();

        let lml = -0.5 * quad - 0.5 * logdet_k - 0.5 * logdet_a + self.half_logdet_hth
            - 0.5 * (n - p) as f64 * (2.0 * std::f64::consts::PI).ln();
        if !lml.is_finite() {
            return Err(GpError::NotPositiveDefinite {
                matrix: "K (training covariance; log-likelihood not finite)",
                index: 0,
                max_jitter: jitter,
            });
        }
        Ok(Factor {
            theta: theta.to_vec(),
            lml,
            jitter,
            l,
            alpha,
            linv_h,
            beta,
            a_chol: a,
        })
    }

    /// Gradient of the LML at the cached factorisation (see module docs for the formula).
    fn gradient_from_cache(&self, ws: &mut Workspace) -> Vec<f64> {
        let (n, d, p) = (self.n, self.d, self.p);
        let f = ws.last.as_ref().expect("factor_cached ran before");
        let (sf2, inv_ls2, sn2) = self.unpack(&f.theta).expect("validated when factorised");
        let _ = sf2;
        // K⁻¹ (lower triangle) from the Cholesky factor.
        llt::inverse::inverse(
            ws.kinv.as_mut(),
            f.l.as_ref(),
            Par::Seq,
            MemStack::new(&mut ws.mem),
        );
        // C = K⁻¹ H L_A⁻ᵀ so that P = K⁻¹ − C Cᵀ.
        ws.tmp_np.copy_from(&f.linv_h);
        solve_upper_triangular_in_place(f.l.as_ref().transpose(), ws.tmp_np.as_mut(), Par::Seq);
        let mut row = vec![0.0; p];
        for i in 0..n {
            for k in 0..p {
                row[k] = ws.tmp_np[(i, k)];
            }
            small_forward_solve(&f.a_chol, p, &mut row);
            for k in 0..p {
                ws.tmp_np[(i, k)] = row[k];
            }
        }
        let m = self.kernel.n_length_scales(d);
        let matern = matches!(self.kernel, Kernel::Matern52 { .. });
        let mut g_sf = 0.0;
        let mut g_ls = vec![0.0; d];
        let mut trace_w = 0.0;
        let alpha = &f.alpha;
        for j in 0..n {
            let xj = &self.x[j * d..(j + 1) * d];
            let aj = alpha[j];
            // Diagonal: ∂K/∂ln ℓ vanishes there (zero distance).
            let wjj = aj * aj - ws.kinv[(j, j)]
                + (0..p)
                    .map(|k| ws.tmp_np[(j, k)] * ws.tmp_np[(j, k)])
                    .sum::<f64>();
            g_sf += wjj * ws.kf[(j, j)];
            trace_w += wjj;
            for i in j + 1..n {
                let mut w = alpha[i] * aj - ws.kinv[(i, j)];
                for k in 0..p {
                    w += ws.tmp_np[(i, k)] * ws.tmp_np[(j, k)];
                }
                // Off-diagonal entries appear twice in the symmetric trace.
                let w2 = 2.0 * w;
                let kij = ws.kf[(i, j)];
                g_sf += w2 * kij;
                let gw = w2 * if matern { ws.gfac[(i, j)] } else { kij };
                let xi = &self.x[i * d..(i + 1) * d];
                for c in 0..d {
                    let dc = xi[c] - xj[c];
                    g_ls[c] += gw * dc * dc * inv_ls2[c];
                }
            }
        }
        let mut grad = Vec::with_capacity(self.n_params());
        grad.push(0.5 * g_sf);
        if m == 1 {
            grad.push(0.5 * g_ls.iter().sum::<f64>());
        } else {
            grad.extend(g_ls.iter().map(|g| 0.5 * g));
        }
        if matches!(self.noise, NoiseModel::Estimated) {
            grad.push(0.5 * sn2 * trace_w);
        }
        grad
    }
}

/// `½ ln|HᵀH|` (0 for an empty basis); errors if the basis is rank deficient.
fn half_logdet_gram(h: &Mat<f64>) -> Result<f64, GpError> {
    let (n, p) = (h.nrows(), h.ncols());
    let mut g = vec![0.0; p * p];
    for c in 0..p {
        for r in 0..p {
            g[r + c * p] = (0..n).map(|i| h[(i, r)] * h[(i, c)]).sum();
        }
    }
    small_cholesky(&mut g, p).map_err(|index| GpError::InvalidParameter {
        name: "mean",
        reason: format!(
            "the regression basis is rank deficient (column {index} is a combination of the others); \
             is an input column constant while using Mean::Linear?"
        ),
    })?;
    Ok((0..p).map(|i| g[i + i * p].ln()).sum())
}

impl CostFunction for LmlProblem {
    type Param = Vec<f64>;
    type Output = f64;

    /// Negative restricted log marginal likelihood.
    fn cost(&self, param: &Self::Param) -> Result<Self::Output, ArgminError> {
        Ok(-self.factor_cached(param)?.0)
    }
}

impl Gradient for LmlProblem {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    /// Gradient of the negative restricted log marginal likelihood.
    fn gradient(&self, param: &Self::Param) -> Result<Self::Gradient, ArgminError> {
        Ok(self
            .lml_and_gradient(param)?
            .gradient
            .iter()
            .map(|g| -g)
            .collect())
    }
}

/// [`LmlProblem`] with box bounds on the log parameters, for an unconstrained optimiser.
///
/// The optimiser variable `u` lives in the same log space as `θ`; the likelihood is evaluated
/// at the projection `θ = clamp(u, lo, hi)` and a quadratic penalty `n Σ_i dist(u_i, [lo_i, hi_i])²`
/// is added outside the box. Inside the box this is exactly the negative LML; outside, the
/// penalty gradient points back into the box, so a long first L-BFGS step that overshoots a
/// bound is rejected by the line search instead of stalling there (a smooth logistic
/// reparametrisation was tried first and rejected: its gradient vanishes at the bounds, which
/// trapped starts that overshot). Reported parameters are always the clamped `θ`.
#[derive(Debug)]
pub struct BoundedLml<'a> {
    problem: &'a LmlProblem,
    lower: Vec<f64>,
    upper: Vec<f64>,
}

impl<'a> BoundedLml<'a> {
    /// Wraps `problem` with lower/upper bounds on the log parameters (each `lo < hi`, finite).
    ///
    /// ```
    /// # use gp::{BoundedLml, Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 3.0]);
    /// let p = LmlProblem::new(Kernel::default(), Mean::Zero, NoiseModel::Estimated, &x, &[0.0, 1.0, 0.5, 0.2])?;
    /// let b = BoundedLml::new(&p, vec![-5.0; 3], vec![5.0; 3])?;
    /// assert_eq!(b.to_bounded(&[0.0, 9.0, -2.0]), vec![0.0, 5.0, -2.0]);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn new(problem: &'a LmlProblem, lower: Vec<f64>, upper: Vec<f64>) -> Result<Self, GpError> {
        let np = problem.n_params();
        for (name, v) in [("lower bounds", &lower), ("upper bounds", &upper)] {
            if v.len() != np {
                return Err(GpError::ShapeMismatch {
                    name,
                    what: "entries",
                    expected: np,
                    found: v.len(),
                });
            }
        }
        if let Some(i) = (0..np)
            .find(|&i| !(lower[i].is_finite() && upper[i].is_finite() && lower[i] < upper[i]))
        {
            return Err(GpError::InvalidParameter {
                name: "bounds",
                reason: format!(
                    "parameter {i}: need finite lo < hi, got [{}, {}]",
                    lower[i], upper[i]
                ),
            });
        }
        Ok(Self {
            problem,
            lower,
            upper,
        })
    }

    /// Projects optimiser variables onto the box: `θ = clamp(u, lo, hi)`.
    ///
    /// ```
    /// # use gp::{BoundedLml, Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 3.0]);
    /// # let p = LmlProblem::new(Kernel::default(), Mean::Zero, NoiseModel::Estimated, &x, &[0.0, 1.0, 0.5, 0.2])?;
    /// let b = BoundedLml::new(&p, vec![-1.0; 3], vec![1.0; 3])?;
    /// assert_eq!(b.to_bounded(&[-3.0, 0.5, 3.0]), vec![-1.0, 0.5, 1.0]);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn to_bounded(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .zip(self.lower.iter().zip(&self.upper))
            .map(|(&u, (&lo, &hi))| u.clamp(lo, hi))
            .collect()
    }

    /// Squared distance of `u` from the box, summed over coordinates.
    fn excess_sq(&self, u: &[f64]) -> f64 {
        u.iter()
            .zip(self.lower.iter().zip(&self.upper))
            .map(|(&u, (&lo, &hi))| (u - u.clamp(lo, hi)).powi(2))
            .sum()
    }

    /// Penalty weight: `n` nats per unit squared log-excess, so leaving the box by one e-fold
    /// costs as much as the whole likelihood typically varies.
    fn penalty_weight(&self) -> f64 {
        self.problem.n_points() as f64
    }

    /// The wrapped problem.
    ///
    /// ```
    /// # use gp::{BoundedLml, Kernel, LmlProblem, Mean, NoiseModel};
    /// # let x = nalgebra::DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 3.0]);
    /// # let p = LmlProblem::new(Kernel::default(), Mean::Zero, NoiseModel::Estimated, &x, &[0.0, 1.0, 0.5, 0.2])?;
    /// let b = BoundedLml::new(&p, vec![-1.0; 3], vec![1.0; 3])?;
    /// assert_eq!(b.problem().n_params(), 3);
    /// # Ok::<(), gp::GpError>(())
    /// ```
    pub fn problem(&self) -> &LmlProblem {
        self.problem
    }
}

impl CostFunction for BoundedLml<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    /// Negative restricted log marginal likelihood at `clamp(u)` plus the out-of-box penalty.
    fn cost(&self, u: &Self::Param) -> Result<Self::Output, ArgminError> {
        Ok(self.problem.cost(&self.to_bounded(u))? + self.penalty_weight() * self.excess_sq(u))
    }
}

impl Gradient for BoundedLml<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    /// Gradient of [`cost`](CostFunction::cost): the LML gradient for coordinates inside the
    /// box, the penalty gradient for coordinates outside (where the clamp is flat).
    fn gradient(&self, u: &Self::Param) -> Result<Self::Gradient, ArgminError> {
        let g = self.problem.gradient(&self.to_bounded(u))?;
        let w = 2.0 * self.penalty_weight();
        Ok(g.iter()
            .zip(u)
            .zip(self.lower.iter().zip(&self.upper))
            .map(|((&g, &u), (&lo, &hi))| {
                if u < lo {
                    w * (u - lo)
                } else if u > hi {
                    w * (u - hi)
                } else {
                    g
                }
            })
            .collect())
    }
}
