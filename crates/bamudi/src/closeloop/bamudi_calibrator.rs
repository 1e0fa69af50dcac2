//! The real close-the-loop calibrator: BA-MUDI Modules 2-4 ([`crate::calibrate()`]) on the miter
//! gate's multi-level model (quoin contact forces `g_BC(x, θ)` as the unobservable model,
//! gauge strains `A F + s_w` as the linear observable model).
//!
//! * [`BamudiCalibrator::calibrate`](super::Calibrator::calibrate) runs Modules 2-3 on the
//!   rows it is given (evenly thinned in time to at most
//!   [`BamudiCalibrator::max_experiments`] rows, see below) and returns a [`BamudiModel`].
//! * [`BamudiModel::predict`](super::CalibratedModel::predict) is the Module-4 output
//!   prediction (Eq. 50, covariance of Eq. 51): per row the mixture over the grid posterior of
//!   θ of `ρ* A g(x, θ_j) + s_w(x) + B μ_α(x)`; the variance is the between-θ variance + the
//!   GP variance `Σ_k B_pk² σ²_αk(x)` + `σ_ε²` (a new measurement, not the noise-free strain).
//!   Rows with the gate open ([`gate_open`]) get no discrepancy term (mean or variance).
//! * [`BamudiModel::predict_at_theta`](super::CalibratedModel::predict_at_theta) is Eq. 50 at
//!   a given gap per row: `ρ* A g(x, θ_i) + s_w(x) + B μ_α(x)`.
//! * [`BamudiModel::theta_summary`](super::CalibratedModel::theta_summary) is the mean, sd and
//!   95 % interval of the grid posterior of θ (Eq. 38-43 with the discrepancy).
//!
//! # Speed
//!
//! One contact solve on the default gate takes about 2 ms (release build), and the loop
//! re-calibrates many times on the same rows with the same θ grid. Three choices keep it
//! usable; all are documented defaults that can be changed:
//!
//! * the estimator of Eq. 29 is the exact linear-Gaussian conditional mean
//!   ([`EstimatorConfig::ExactLinear`]): it needs no training set, and for the gate (linear
//!   observable model, Gaussian discrepancy coefficients) it is the estimator the learnt ones
//!   approximate. Any [`CalibrationConfig`] can be set with [`BamudiCalibrator::config`];
//! * the contact forces are memoised per exact `(h_up, h_down, θ)` ([`MemoContactForces`]):
//!   re-calibrations and predictions on the same rows reuse every solve;
//! * a calibration uses at most `max_experiments` rows (default 240), evenly spaced in time
//!   over the calibration window. With hourly records the rows are strongly autocorrelated in
//!   their inputs (the pools move slowly), so thinning loses little about θ; the predictions
//!   and the loop's checks still use every row. Rows with less than [`MIN_HEAD_IN`] of head
//!   (gate open) are left out of calibrations: they carry no quoin force, and Module 2's
//!   sampling rule is undefined where the nominal response is identically zero.
//!
//! The exact estimator's output noise `σ_t` is the gauges' white-noise sd, estimated from the
//! rows of each calibration ([`estimated_gauge_noise_sd`]) unless set with
//! [`BamudiCalibrator::gauge_noise_sd`]; with `σ_t = 0` the estimator amplifies the noise into
//! huge coefficients and the calibrated fit is worse than the noise.
//!
//! Module 3 runs with the coefficients conditioned on θ
//! ([`CoefficientMode::ConditionalOnTheta`]): with the paper's prior-marginal coefficients the
//! gap posterior follows the prior window and a clean record is misfitted by several
//! microstrain (docs/closeloop.md), which the loop would then try to explain. `predict_at_theta`
//! uses the posterior-averaged coefficient shift at every θ (the shift's change over the narrow
//! posterior is not propagated).
//!
//! The θ mixture of `predict` keeps the grid nodes that carry all but `1e-6` of the posterior
//! mass (renormalised); the dropped tail changes a mean by at most `1e-6` times the spread of
//! the component means.

use super::stats::{median, noise_sd_from_differences};
use super::{CalibratedModel, Calibrator, ThetaSummary};
use crate::calibrate::{Calibration, ThetaPosterior, calibrate};
use crate::config::{CalibrationConfig, CoefficientMode, EstimatorConfig};
use crate::error::BamudiError;
use crate::experiments::Experiments;
use mitergate::contact::ContactModel;
use mitergate::gate_model::{ContactForceModel, StrainModel};
use mlmodel::{
    DiscrepancyBasis, LinearObservableModel, MultiLevelModel, ObservableModel, UniformPrior,
    UnobservableModel,
};
use nalgebra::{DMatrix, DVector};
use orthopoly::Family;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, RwLock};

/// The gate's multi-level model with memoised contact forces.
pub type MemoGateModel = MultiLevelModel<MemoContactForces, StrainModel>;

/// Rows with a smaller head `h_up - h_down` (in) are left out of a calibration.
pub const MIN_HEAD_IN: f64 = 1.0;

/// Posterior mass left out of the `predict` mixture.
const SUPPORT_TAIL: f64 = 1e-6;

/// Most θ nodes in the `predict` mixture. The zoomed grid posterior can hold 200 nodes within
/// its support, and every node costs one contact solve per row (the loop predicts every row
/// of a record after each calibration: 720 loaded rows x 200 nodes = 144,000 solves). Equal-
/// mass groups of neighbouring nodes, each at its mass-weighted mean θ, keep the posterior
/// mean of θ exactly and lose only the within-group variance: with 16 groups of a Gaussian
/// posterior that is 2.2 % of its variance (32 groups: 0.9 %). The strain is smooth in θ, and
/// the between-θ part is a small share of the predictive variance once the data identify θ.
const MAX_SUPPORT_NODES: usize = 16;

/// Merges `(θ, mass)` nodes (masses summing to 1) into at most `m` groups of neighbouring
/// nodes with about equal mass, each at its mass-weighted mean θ.
fn compress_support(mut nodes: Vec<(f64, f64)>, m: usize) -> Vec<(f64, f64)> {
    if nodes.len() <= m {
        return nodes;
    }
    nodes.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut groups = vec![(0.0, 0.0); m];
    let mut cum = 0.0;
    for (t, w) in nodes {
        let k = (((cum + 0.5 * w) * m as f64) as usize).min(m - 1);
        groups[k].0 += t * w;
        groups[k].1 += w;
        cum += w;
    }
    groups
        .into_iter()
        .filter(|g| g.1 > 0.0)
        .map(|(tw, w)| (tw / w, w))
        .collect()
}

/// [`ContactForceModel`] with a memo of every evaluation, keyed by the exact bits of
/// `(h_up, h_down, θ)`. Identical inputs give identical outputs (the contact solve is
/// deterministic), so the memo never changes a result, only skips repeated solves. When it
/// holds `capacity` entries it is cleared (logged to stderr once per clear).
#[derive(Debug)]
pub struct MemoContactForces {
    inner: ContactForceModel,
    memo: RwLock<HashMap<[u64; 3], Arc<[f64]>>>,
    capacity: usize,
}

impl MemoContactForces {
    /// Wraps a contact model; `capacity` is the number of stored force vectors (each
    /// `2 N_u` values; 200,000 entries of the default gate are about 250 MB).
    ///
    /// ```
    /// use mitergate::contact::{ContactParams, doc_gate};
    /// use mlmodel::UnobservableModel;
    /// let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let memo = bamudi::closeloop::bamudi_calibrator::MemoContactForces::new(contact, 1000);
    /// let mut a = vec![0.0; memo.response_len()];
    /// let mut b = a.clone();
    /// memo.evaluate(&[500.0, 100.0], &[90.0], &mut a).unwrap();
    /// memo.evaluate(&[500.0, 100.0], &[90.0], &mut b).unwrap(); // from the memo
    /// assert_eq!((a, memo.len()), (b, 1));
    /// ```
    pub fn new(contact: ContactModel, capacity: usize) -> Self {
        Self {
            inner: ContactForceModel::new(contact),
            memo: RwLock::new(HashMap::new()),
            capacity: capacity.max(1),
        }
    }

    /// Number of memoised evaluations.
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let memo = bamudi::closeloop::bamudi_calibrator::MemoContactForces::new(contact, 10);
    /// assert!(memo.is_empty() && memo.len() == 0);
    /// ```
    pub fn len(&self) -> usize {
        self.memo.read().map_or(0, |m| m.len())
    }

    /// Whether the memo is empty.
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// assert!(bamudi::closeloop::bamudi_calibrator::MemoContactForces::new(contact, 10).is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The wrapped contact model.
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let memo = bamudi::closeloop::bamudi_calibrator::MemoContactForces::new(contact, 10);
    /// assert_eq!(memo.contact().gate().n_gauges(), 2);
    /// ```
    pub fn contact(&self) -> &ContactModel {
        self.inner.contact()
    }
}

impl UnobservableModel for MemoContactForces {
    fn input_names(&self) -> Vec<String> {
        self.inner.input_names()
    }
    fn check_input(&self, x: &[f64]) -> mlmodel::Result<()> {
        self.inner.check_input(x)
    }
    fn param_dim(&self) -> usize {
        self.inner.param_dim()
    }
    fn components(&self) -> usize {
        self.inner.components()
    }
    fn coordinates(&self) -> &[f64] {
        self.inner.coordinates()
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        if x.len() != 2 || theta.len() != 1 {
            // let the wrapped model produce the dimension error
            return self.inner.evaluate(x, theta, out);
        }
        let key = [x[0].to_bits(), x[1].to_bits(), theta[0].to_bits()];
        if let Some(v) = self.memo.read().ok().and_then(|m| m.get(&key).cloned())
            && v.len() == out.len()
        {
            out.copy_from_slice(&v);
            return Ok(());
        }
        self.inner.evaluate(x, theta, out)?;
        if let Ok(mut m) = self.memo.write() {
            if m.len() >= self.capacity {
                eprintln!(
                    "bamudi: contact-force memo full ({} entries), clearing it",
                    m.len()
                );
                m.clear();
            }
            m.insert(key, Arc::from(&*out));
        }
        Ok(())
    }
}

/// Builds the gate's multi-level model: memoised contact forces, strains, a uniform prior of
/// the gap on `prior_in` (in) and a Legendre discrepancy basis with `orders` terms for the
/// normal and tangential components (the paper uses 6 + 6).
///
/// ```
/// use mitergate::contact::{ContactParams, doc_gate};
/// let contact = ContactParams::default().build(doc_gate()).unwrap();
/// let m = bamudi::closeloop::bamudi_calibrator::gate_multilevel(contact, (40.0, 200.0), [2, 2], 100).unwrap();
/// assert_eq!(m.basis.n_points(), 5);
/// ```
pub fn gate_multilevel(
    contact: ContactModel,
    prior_in: (f64, f64),
    orders: [usize; 2],
    memo_capacity: usize,
) -> Result<MemoGateModel, BamudiError> {
    let gate = contact.gate();
    let basis = DiscrepancyBasis::new(
        Family::Legendre,
        (0.0, gate.quoin_height),
        &gate.nu_points,
        &orders,
    )?;
    let strain = StrainModel::new(gate);
    let prior = UniformPrior::new(vec![prior_in])?;
    Ok(MultiLevelModel::new(
        MemoContactForces::new(contact, memo_capacity),
        strain,
        Box::new(prior),
        basis,
    )?)
}

/// BA-MUDI as the close-the-loop [`Calibrator`] of the miter gate. See the module docs.
pub struct BamudiCalibrator {
    model: Arc<MemoGateModel>,
    prior_in: (f64, f64),
    config: CalibrationConfig,
    max_experiments: usize,
    gauge_noise_sd: Option<f64>,
}

impl std::fmt::Debug for BamudiCalibrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BamudiCalibrator")
            .field("prior_in", &self.prior_in)
            .field("config", &self.config)
            .field("max_experiments", &self.max_experiments)
            .field("gauge_noise_sd", &self.gauge_noise_sd)
            .finish_non_exhaustive()
    }
}

impl BamudiCalibrator {
    /// A calibrator for the gate of `contact` with gap prior `Uniform(prior_in)` (in), the
    /// paper's 6 + 6 Legendre discrepancy terms (fewer when the gate has fewer representation
    /// points), the exact linear estimator, 241 θ grid points, progress bars off, and at most
    /// 240 rows per calibration.
    ///
    /// ```
    /// use mitergate::contact::{ContactParams, doc_gate};
    /// let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap();
    /// assert_eq!(c.prior(), (40.0, 200.0));
    /// ```
    pub fn new(contact: ContactModel, prior_in: (f64, f64)) -> Result<Self, BamudiError> {
        let n_points = contact.gate().nu_points.len();
        let order = 6.min(n_points);
        let model = gate_multilevel(contact, prior_in, [order, order], 400_000)?;
        Ok(Self {
            model: Arc::new(model),
            prior_in,
            config: CalibrationConfig::default()
                .estimator(EstimatorConfig::ExactLinear)
                .coefficients(CoefficientMode::ConditionalOnTheta)
                .theta_grid_points(241)
                .progress(false),
            max_experiments: 240,
            gauge_noise_sd: None,
        })
    }

    /// Replaces the calibration configuration (estimator, grid, `σ_ε`, seed, ...). Its
    /// `sampling.noise_sd` is replaced at each calibration by the gauge noise (see
    /// [`gauge_noise_sd`](Self::gauge_noise_sd)).
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let cfg = bamudi::CalibrationConfig::default().theta_grid_points(101).progress(false);
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap().config(cfg);
    /// assert_eq!(c.calibration_config().theta_grid_points, 101);
    /// ```
    pub fn config(mut self, config: CalibrationConfig) -> Self {
        self.config = config;
        self
    }

    /// Sets the maximum number of rows per calibration (at least 3; rows are thinned evenly).
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap().max_experiments(100);
    /// assert_eq!(c.max_experiments_per_calibration(), 100);
    /// ```
    pub fn max_experiments(mut self, n: usize) -> Self {
        self.max_experiments = n.max(3);
        self
    }

    /// Sets the gauges' white-noise standard deviation (microstrain), the output noise `σ_t` the
    /// exact estimator assumes (`SamplingRule::noise_sd`). Unset (the default), it is
    /// estimated from each calibration's rows (see [`estimated_gauge_noise_sd`]).
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap();
    /// assert_eq!(c.gauge_noise_sd(0.8).unwrap().configured_gauge_noise_sd(), Some(0.8));
    /// ```
    pub fn gauge_noise_sd(mut self, sd: f64) -> Result<Self, BamudiError> {
        if !(sd.is_finite() && sd > 0.0) {
            return Err(BamudiError::InvalidConfig {
                name: "gauge_noise_sd",
                reason: format!("must be a positive number of microstrain, got {sd}"),
            });
        }
        self.gauge_noise_sd = Some(sd);
        Ok(self)
    }

    /// The configured gauge noise sd (microstrain), `None` when it is estimated per calibration.
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap();
    /// assert_eq!(c.configured_gauge_noise_sd(), None);
    /// ```
    pub fn configured_gauge_noise_sd(&self) -> Option<f64> {
        self.gauge_noise_sd
    }

    /// The calibration configuration.
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap();
    /// assert_eq!(c.calibration_config().estimator, bamudi::EstimatorConfig::ExactLinear);
    /// ```
    pub fn calibration_config(&self) -> &CalibrationConfig {
        &self.config
    }

    /// Maximum rows per calibration.
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap();
    /// assert_eq!(c.max_experiments_per_calibration(), 240);
    /// ```
    pub fn max_experiments_per_calibration(&self) -> usize {
        self.max_experiments
    }

    /// Prior support of the gap (in).
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (60.0, 120.0)).unwrap();
    /// assert_eq!(c.prior(), (60.0, 120.0));
    /// ```
    pub fn prior(&self) -> (f64, f64) {
        self.prior_in
    }

    /// The multi-level model (shared with every calibrated model).
    ///
    /// ```
    /// # use mitergate::contact::{ContactParams, doc_gate};
    /// # let contact = ContactParams::default().build(doc_gate()).unwrap();
    /// let c = bamudi::closeloop::BamudiCalibrator::new(contact, (40.0, 200.0)).unwrap();
    /// assert_eq!(c.model().basis.n_coefficients(), 10);
    /// ```
    pub fn model(&self) -> &MemoGateModel {
        &self.model
    }

    /// Runs the calibration and returns the concrete model (the trait method boxes it).
    ///
    /// ```no_run
    /// # fn f(c: &bamudi::closeloop::BamudiCalibrator, x: &nalgebra::DMatrix<f64>, y: &nalgebra::DMatrix<f64>) {
    /// let m = c.calibrate_model(x, y).unwrap();
    /// println!("rho* = {}", m.calibration().rho.rho_star);
    /// # }
    /// ```
    pub fn calibrate_model(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> Result<BamudiModel, BamudiError> {
        if x.nrows() != y.nrows() {
            return Err(BamudiError::dim(
                "rows of x vs rows of y",
                x.nrows(),
                y.nrows(),
            ));
        }
        // rows with the gate open (no head) carry no quoin force, and Module 2's sampling
        // rule is undefined where the nominal response is identically zero
        let loaded: Vec<usize> = (0..x.nrows())
            .filter(|&i| !gate_open(&[x[(i, 0)], x[(i, 1)]]))
            .collect();
        let rows: Vec<usize> = thin_rows(loaded.len(), self.max_experiments)
            .into_iter()
            .map(|k| loaded[k])
            .collect();
        let pick =
            |m: &DMatrix<f64>| DMatrix::from_fn(rows.len(), m.ncols(), |i, j| m[(rows[i], j)]);
        let exps = Experiments::new(
            self.model.unobservable.input_names(),
            self.model.observable.output_names(),
            pick(x),
            pick(y),
        )?;
        let noise_sd = self
            .gauge_noise_sd
            .unwrap_or_else(|| estimated_gauge_noise_sd(y));
        let config = self
            .config
            .clone()
            .sampling(self.config.sampling.clone().noise_sd(noise_sd));
        let cal = calibrate(self.model.as_ref(), &exps, &config)?;
        Ok(BamudiModel {
            model: Arc::clone(&self.model),
            prior_in: self.prior_in,
            cal,
        })
    }
}

/// The gauges' white-noise standard deviation (microstrain) estimated from rows in time
/// order: per gauge the robust first-difference estimate (median absolute deviation of
/// `y[t+1] − y[t]` over `0.6745 √2`), then the median over gauges.
///
/// The exact estimator needs it as its output noise `σ_t`: with `σ_t = 0` it is the
/// pseudo-inverse of `B` (7 gauges, 12 coefficients on the default gate), which turns 1
/// microstrain of noise into coefficients of thousands of lbf/in; the coefficient GPs smooth
/// each coefficient differently, `B` no longer cancels them, and the fit becomes worse than no
/// discrepancy at all. Level changes between rows make the estimate err on the high side,
/// which only regularises the estimator more.
///
/// ```
/// use nalgebra::DMatrix;
/// // a steady trend is not noise; a zig-zag of ±0.5 microstrain is
/// let trend = DMatrix::from_fn(50, 3, |i, g| 0.1 * i as f64 + g as f64);
/// assert!(bamudi::closeloop::bamudi_calibrator::estimated_gauge_noise_sd(&trend) < 1e-12);
/// let zigzag = DMatrix::from_fn(51, 3, |i, _| if i % 2 == 0 { 0.5 } else { -0.5 });
/// let sd = bamudi::closeloop::bamudi_calibrator::estimated_gauge_noise_sd(&zigzag);
/// // 25 differences of +1 and 25 of −1: median 0, MAD 1
/// assert!((sd - 1.0 / (0.6745 * 2f64.sqrt())).abs() < 1e-12);
/// ```
pub fn estimated_gauge_noise_sd(y: &DMatrix<f64>) -> f64 {
    let mut per_gauge: Vec<f64> = y
        .column_iter()
        .map(|c| noise_sd_from_differences(c.as_slice()))
        .collect();
    median(&mut per_gauge)
}

/// Whether the row `[h_up, h_down]` (in) has less than [`MIN_HEAD_IN`] of head. Such rows are
/// left out of calibrations, and the discrepancy is taken as zero there: it corrects the quoin
/// contact force, and with no thrust there is no contact force to correct (a GP mean or
/// variance extrapolated from loaded rows would be a guess with no physical basis).
///
/// ```
/// use bamudi::closeloop::bamudi_calibrator::gate_open;
/// assert!(gate_open(&[300.0, 300.0]) && !gate_open(&[500.0, 100.0]));
/// ```
pub fn gate_open(x: &[f64; 2]) -> bool {
    x[0] - x[1] < MIN_HEAD_IN
}

/// `k` indices evenly spread over `0..n` (all of them when `n <= k`), first and last included.
fn thin_rows(n: usize, k: usize) -> Vec<usize> {
    if n <= k || k < 2 {
        return (0..n).collect();
    }
    (0..k)
        .map(|i| ((i as f64) * (n - 1) as f64 / (k - 1) as f64).round() as usize)
        .collect()
}

impl Calibrator for BamudiCalibrator {
    fn calibrate(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> Result<Box<dyn CalibratedModel>, BamudiError> {
        Ok(Box::new(self.calibrate_model(x, y)?))
    }
}

/// A BA-MUDI calibration of the gate, as a close-the-loop [`CalibratedModel`].
pub struct BamudiModel {
    model: Arc<MemoGateModel>,
    prior_in: (f64, f64),
    cal: Calibration,
}

impl std::fmt::Debug for BamudiModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BamudiModel")
            .field("prior_in", &self.prior_in)
            .field("rho_star", &self.cal.rho.rho_star)
            .field("sigma_eps", &self.cal.sigma_eps)
            .finish_non_exhaustive()
    }
}

impl BamudiModel {
    /// The underlying BA-MUDI calibration (ρ*, GPs, posteriors, timings).
    ///
    /// ```no_run
    /// # fn f(m: &bamudi::closeloop::BamudiModel) {
    /// println!("sigma_eps = {} microstrain", m.calibration().sigma_eps);
    /// # }
    /// ```
    pub fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// `ρ* A g(x, θ) + s_w(x)` (microstrain) for one row.
    fn model_strain(&self, x: &[f64], theta: f64) -> Result<DVector<f64>, BamudiError> {
        let mut g = vec![0.0; self.model.unobservable.response_len()];
        self.model.unobservable.evaluate(x, &[theta], &mut g)?;
        let mut off = vec![0.0; self.model.observable.output_dim()];
        self.model.observable.offset(x, &[theta], &mut off)?;
        let ag = self.model.observable.matrix() * DVector::from_vec(g);
        Ok(ag * self.cal.rho.rho_star + DVector::from_vec(off))
    }

    /// Grid nodes (or thinned MCMC draws) of the θ posterior with their weights, without the
    /// lightest `SUPPORT_TAIL` of the mass.
    fn support(&self) -> Vec<(f64, f64)> {
        match &self.cal.posterior {
            ThetaPosterior::Grid(g) => {
                let masses = g.masses();
                let mut idx: Vec<usize> = (0..masses.len()).collect();
                idx.sort_by(|a, b| masses[*b].total_cmp(&masses[*a]));
                let mut kept = Vec::new();
                let mut acc = 0.0;
                for i in idx {
                    if acc >= 1.0 - SUPPORT_TAIL {
                        break;
                    }
                    acc += masses[i];
                    kept.push((g.theta[i], masses[i]));
                }
                kept.iter_mut().for_each(|k| k.1 /= acc);
                compress_support(kept, MAX_SUPPORT_NODES)
            }
            post @ ThetaPosterior::Mcmc(_) => compress_support(
                post.support(200)
                    .into_iter()
                    .map(|(t, w)| (t[0], w))
                    .collect(),
                MAX_SUPPORT_NODES,
            ),
        }
    }

    /// `B μ_α(x_i)`, the discrepancy's strain; zero when the gate is open ([`gate_open`]).
    fn discrepancy_shift(&self, mu: &DMatrix<f64>, i: usize, open: bool) -> DVector<f64> {
        let b = &self.cal.parts.b;
        if open {
            DVector::zeros(b.nrows())
        } else {
            b * mu.row(i).transpose()
        }
    }

    fn check_x(&self, x: &DMatrix<f64>) -> Result<(), BamudiError> {
        if x.ncols() != 2 {
            return Err(BamudiError::dim(
                "prediction inputs [h_up, h_down]",
                2,
                x.ncols(),
            ));
        }
        Ok(())
    }
}

impl CalibratedModel for BamudiModel {
    fn predict(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>), BamudiError> {
        self.check_x(x)?;
        let (mu, var_alpha) = self.cal.alpha_moments(x)?;
        let b = &self.cal.parts.b;
        let support = self.support();
        let noise = self.cal.sigma_eps.powi(2);
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi = [x[(i, 0)], x[(i, 1)]];
                let open = gate_open(&xi);
                let shift = self.discrepancy_shift(&mu, i, open);
                let comps = support
                    .iter()
                    .map(|(t, _)| self.model_strain(&xi, *t))
                    .collect::<Result<Vec<_>, _>>()?;
                let n_o = b.nrows();
                let mut mean = DVector::zeros(n_o);
                for (c, (_, w)) in comps.iter().zip(&support) {
                    mean += c * *w;
                }
                let var = DVector::from_fn(n_o, |p, _| {
                    let between: f64 = comps
                        .iter()
                        .zip(&support)
                        .map(|(c, (_, w))| w * (c[p] - mean[p]).powi(2))
                        .sum();
                    let gp: f64 = if open {
                        0.0
                    } else {
                        (0..b.ncols())
                            .map(|k| b[(p, k)].powi(2) * var_alpha[(i, k)])
                            .sum()
                    };
                    between + gp + noise
                });
                Ok((mean + shift, var))
            })
            .collect::<Result<Vec<_>, BamudiError>>()?;
        let n_o = b.nrows();
        let mean = DMatrix::from_fn(x.nrows(), n_o, |i, p| rows[i].0[p]);
        let var = DMatrix::from_fn(x.nrows(), n_o, |i, p| rows[i].1[p]);
        Ok((mean, var))
    }

    fn predict_at_theta(
        &self,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> Result<DMatrix<f64>, BamudiError> {
        self.check_x(x)?;
        if theta.len() != x.nrows() {
            return Err(BamudiError::dim(
                "gap values vs rows",
                x.nrows(),
                theta.len(),
            ));
        }
        let (mu, _) = self.cal.alpha_moments(x)?;
        let b = &self.cal.parts.b;
        let rows = (0..x.nrows())
            .into_par_iter()
            .map(|i| {
                let xi = [x[(i, 0)], x[(i, 1)]];
                Ok(self.model_strain(&xi, theta[i])?
                    + self.discrepancy_shift(&mu, i, gate_open(&xi)))
            })
            .collect::<Result<Vec<_>, BamudiError>>()?;
        Ok(DMatrix::from_fn(x.nrows(), b.nrows(), |i, p| rows[i][p]))
    }

    fn theta_summary(&self) -> ThetaSummary {
        let p = &self.cal.posterior;
        ThetaSummary {
            mean: p.mean()[0],
            sd: p.sd()[0],
            ci95: p.ci95()[0],
        }
    }

    fn theta_bounds(&self) -> (f64, f64) {
        self.prior_in
    }

    /// The discrepancy `δ(x)` (GPs over the load inputs) absorbs load-shaped residuals.
    fn absorbs_load_functions(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compressed_support_keeps_the_mass_and_the_mean_and_most_of_the_variance() {
        // a Gaussian-shaped posterior of sd 0.05 in on 201 nodes 0.0025 in apart
        let raw: Vec<(f64, f64)> = (0..201)
            .map(|i| {
                let t = 89.75 + 0.0025 * i as f64;
                (t, (-0.5 * ((t - 90.0) / 0.05f64).powi(2)).exp())
            })
            .collect();
        let z: f64 = raw.iter().map(|n| n.1).sum();
        let raw: Vec<(f64, f64)> = raw.into_iter().map(|(t, w)| (t, w / z)).collect();
        let moments = |v: &[(f64, f64)]| {
            let m: f64 = v.iter().map(|(t, w)| t * w).sum();
            let var: f64 = v.iter().map(|(t, w)| w * (t - m).powi(2)).sum();
            (v.iter().map(|n| n.1).sum::<f64>(), m, var)
        };
        let c = compress_support(raw.clone(), MAX_SUPPORT_NODES);
        assert!(c.len() <= MAX_SUPPORT_NODES && c.len() >= MAX_SUPPORT_NODES - 2);
        let ((m0, mean0, var0), (m1, mean1, var1)) = (moments(&raw), moments(&c));
        // mass and mean are preserved up to rounding
        assert!((m0 - m1).abs() < 1e-12 && (mean0 - mean1).abs() < 1e-12);
        // the variance lost is the within-group part: 2.2 % for 16 groups of a Gaussian
        assert!(var1 < var0 && var1 > 0.975 * var0, "{var1} vs {var0}");
        // small supports are left alone
        assert_eq!(compress_support(raw[..10].to_vec(), 24), raw[..10].to_vec());
    }
}
