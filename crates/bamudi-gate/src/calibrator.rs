//! BA-MUDI on the miter gate as the close loop's calibrator.
//!
//! * [`GateCalibrator::calibrate`](bamudi_closeloop::Calibrator::calibrate) runs Modules 2-3
//!   of the engine on the rows it is given (evenly thinned in time to at most
//!   [`GateCalibrator::max_experiments`] rows, see below) and returns a [`CalibratedGate`].
//! * [`CalibratedGate`] predicts through the engine's one Module-4 predictor: the mixture over
//!   the `θ` posterior of `ρ* A g(x, θ_j) + s_w(x) + B μ_α(x)`, whose variance (between-`θ`
//!   plus GP) is returned with `σ_ε²` added (a new measurement, not the noise-free strain).
//!   Rows with the gate open get no discrepancy (the model's
//!   [`response_vanishes`](mlmodel::UnobservableModel::response_vanishes)).
//!
//! # Speed
//!
//! One contact solve on the default gate takes about 0.45 ms (criterion, docs/benchmarks.md), and the loop
//! re-calibrates many times on the same rows with the same `θ` grid. Five documented choices
//! keep it usable; each can be changed:
//!
//! * the estimator of Eq. 29 is the exact linear-Gaussian conditional mean
//!   ([`EstimatorParams::ExactLinear`]): no training set, and for the gate (linear observable
//!   model) it is the estimator the learnt ones approximate ([`GateCalibrator::config`]);
//! * the model rows `A g` and `b` that Modules 3 and 4 read are memoised per exact
//!   `(h_up, h_down, θ)` ([`mlmodel::RowMemo`], 1,000,000 rows), and the contact forces
//!   themselves for the rest ([`mlmodel::Memo`], 150,000 solves);
//! * a calibration uses at most `max_experiments` rows (default 240), evenly spaced in time
//!   over the calibration window; rows with the gate open are left out (no quoin force, and
//!   Module 2's sampling rule is undefined where the nominal response is zero);
//! * predictions stand for the `θ` posterior by at most 16 equal-mass points
//!   ([`SupportPolicy`]): the loop predicts every row of a record after each calibration;
//! * the baseline without discrepancy is not fitted at its support points
//!   ([`CalibrationParams::no_discrepancy_fit`]): the loop never predicts it, and the fit
//!   was about a seventh of a loop's time (perf samples of an FE-gate record); its `θ`
//!   posterior is still computed.
//!
//! The exact estimator's output noise `σ_t` is the gauges' white-noise sd, estimated from the
//! rows of each calibration ([`estimated_gauge_noise_sd`]) unless set with
//! [`GateCalibrator::gauge_noise_sd`]; with `σ_t = 0` the estimator turns noise into huge
//! coefficients and the calibrated fit is worse than the noise. Module 3 integrates the
//! coefficients out ([`CoefficientMode::Marginal`], the engine's default): its `θ` intervals
//! are the ones the coverage study checks (`docs/results/coverage-quick.md`); with the paper's
//! prior-marginal coefficients a clean record is misfitted by several microstrain, which the
//! loop would then try to explain.

use crate::error::{GateAppError, Result};
use crate::tolerance::{
    ToleranceSpec, build_tolerances, check_tolerance_keys, check_tolerance_specs,
};
use bamudi::observe::Observer;
use bamudi::{
    BamudiError, Calibrate, Calibration, CalibrationConfig, CalibrationParams, CoefficientMode,
    EstimatorParams, Experiments, SupportPolicy,
};
use bamudi_closeloop::{CalibratedModel, Calibrator, CloseLoopError, ThetaSummary};
use mitergate::{ContactModel, GateConfig, GateMultiLevel, MultiLevelSpec};
use mlmodel::{ObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use std::sync::Arc;

/// Most `θ` support points in the close loop's predictions (16 equal-mass groups lose 2.2 %
/// of a Gaussian posterior's variance and keep its mean exactly; see [`SupportPolicy`]).
const LOOP_SUPPORT_NODES: usize = 16;

/// Most contact solves the close loop's model remembers (about 8 kB each at 509 points, 1.2
/// GB in all). Module 3's rows and Module 4's output moments read the solves through the
/// model-row memo ([`ROW_MEMO_CAPACITY`](crate::gate::ROW_MEMO_CAPACITY)); these are for the
/// rest (the exact estimator's prior nodes at each calibration row, the force predictions).
/// Measured on the wall-flexure record of docs/closeloop.md (24-in mesh, with the row memo,
/// 64-MB anchor cache): 400,000 solves 72.9 s and 3.50 GB peak, 150,000 72.4 s and 1.71 GB,
/// 50,000 75.6 s and 0.89 GB (command wall times).
const LOOP_CONTACT_MEMO: usize = 150_000;

/// BA-MUDI as the close loop's [`Calibrator`] of the miter gate. See the module docs.
pub struct GateCalibrator {
    model: Arc<GateMultiLevel>,
    config: CalibrationConfig,
    max_experiments: usize,
    gauge_noise_sd: Option<f64>,
    observer: Option<Arc<dyn Observer + Send + Sync>>,
}

impl GateCalibrator {
    /// A calibrator for the gate of `contact` with gap prior `Uniform(prior_in)` (in), the
    /// paper's 6 + 6 Legendre discrepancy terms (fewer when the gate has fewer representation
    /// points), the exact linear estimator, the marginal coefficient mode, 241 `θ` grid
    /// points, and at most 240 rows per calibration.
    pub fn new(contact: ContactModel, prior_in: (f64, f64)) -> Result<Self> {
        let spec = MultiLevelSpec {
            gap_prior_in: prior_in,
            discrepancy_terms: [6, 6],
            memo_capacity: LOOP_CONTACT_MEMO,
            row_memo_capacity: crate::gate::ROW_MEMO_CAPACITY,
        };
        let config = CalibrationParams::default()
            .estimator(EstimatorParams::ExactLinear)
            .coefficients(CoefficientMode::default())
            .theta_grid_points(241)
            .check()?;
        Ok(Self {
            model: Arc::new(mitergate::multilevel(contact, &spec)?),
            config,
            max_experiments: 240,
            gauge_noise_sd: None,
            observer: None,
        })
    }

    /// Replaces the calibration configuration (estimator, grid, `σ_ε`, seed, ...). Its
    /// `sampling.noise_sd` is replaced at each calibration by the gauge noise (see
    /// [`gauge_noise_sd`](Self::gauge_noise_sd)).
    pub fn config(mut self, config: CalibrationConfig) -> Self {
        self.config = config;
        self
    }

    /// Declares tolerances of the gate's build (`drawing`: the configuration the calibrator's
    /// contact model was built from): every calibration of the loop integrates them out and
    /// every prediction carries the deviation the data read (Module 4), so the loop's residuals
    /// do not show an as-built gate as a missing effect. Needs the marginal coefficient mode
    /// (the default; set the configuration first). Errors name `tolerances[i]` and its key or
    /// sd.
    pub fn tolerances(mut self, specs: &[ToleranceSpec], drawing: &GateConfig) -> Result<Self> {
        let label = "close-loop tolerances";
        check_tolerance_specs(specs, self.config.coefficients.kind(), label)?;
        check_tolerance_keys(specs, drawing, label)?;
        let built = build_tolerances(specs, Some(drawing), label)?;
        let model = Arc::try_unwrap(self.model).map_err(|_| {
            GateAppError::Invalid(format!(
                "{label}: declare them before the calibrator's model is shared"
            ))
        })?;
        let model = model
            .with_tolerances(built)
            .map_err(|e| GateAppError::Invalid(format!("{label}: {e}")))?;
        self.model = Arc::new(model);
        Ok(self)
    }

    /// Reports every calibration's stages to `observer` (e.g. progress bars).
    pub fn observer(mut self, observer: Arc<dyn Observer + Send + Sync>) -> Self {
        self.observer = Some(observer);
        self
    }

    /// Sets the maximum number of rows per calibration (at least 3; rows are thinned evenly).
    pub fn max_experiments(mut self, n: usize) -> Self {
        self.max_experiments = n.max(3);
        self
    }

    /// Sets the gauges' white-noise standard deviation (microstrain), the output noise `σ_t`
    /// the exact estimator assumes. Unset (the default), it is estimated from each
    /// calibration's rows ([`estimated_gauge_noise_sd`]).
    pub fn gauge_noise_sd(mut self, sd: f64) -> Result<Self> {
        if !(sd.is_finite() && sd > 0.0) {
            return Err(BamudiError::InvalidConfig {
                name: "gauge_noise_sd",
                reason: format!("must be a positive number of microstrain, got {sd}"),
            }
            .into());
        }
        self.gauge_noise_sd = Some(sd);
        Ok(self)
    }

    /// The configured gauge noise sd (microstrain), `None` when estimated per calibration.
    pub fn configured_gauge_noise_sd(&self) -> Option<f64> {
        self.gauge_noise_sd
    }

    /// The calibration configuration.
    pub fn calibration_config(&self) -> &CalibrationConfig {
        &self.config
    }

    /// Maximum rows per calibration.
    pub fn max_experiments_per_calibration(&self) -> usize {
        self.max_experiments
    }

    /// The gate's multi-level model (shared with every calibrated model).
    pub fn model(&self) -> &GateMultiLevel {
        &self.model
    }

    /// Runs the calibration and returns the concrete model (the trait method boxes it).
    pub fn calibrate_gate(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<CalibratedGate> {
        let (mut cal, exps, config) = self.run(x, y, Checks::Run)?;
        crate::physics::add_physics_checks(&mut cal, &self.model, &exps, &config)?;
        Ok(CalibratedGate {
            model: Arc::clone(&self.model),
            cal,
        })
    }

    /// The calibration (Modules 2-3, and the adequacy checks with [`Checks::Run`]) with its
    /// experiments and checked configuration.
    fn run(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        checks: Checks,
    ) -> Result<(Calibration, Experiments, CalibrationConfig)> {
        if x.nrows() != y.nrows() {
            return Err(BamudiError::dim("rows of x vs rows of y", x.nrows(), y.nrows()).into());
        }
        let exps = self.experiments(x, y)?;
        let noise_sd = self
            .gauge_noise_sd
            .unwrap_or_else(|| estimated_gauge_noise_sd(y));
        let mut params = self.config.clone().into_params();
        params.sampling = params.sampling.noise_sd(noise_sd);
        // the loop never predicts the baseline without discrepancy (its residuals, verdicts
        // and gap read the calibrated model): its fit at up to 400 support points is skipped
        params.no_discrepancy_fit = false;
        // the checks run after Module 3 and change none of its numbers
        params.adequacy.enabled &= checks == Checks::Run;
        let config = params.check()?;
        let mut run = Calibrate::new(&config);
        if let Some(o) = &self.observer {
            run = run.observer(o.as_ref());
        }
        let cal = run.run(self.model.as_ref(), &exps)?;
        Ok((cal, exps, config))
    }

    /// The loaded rows of `x`, `y`, evenly thinned to at most `max_experiments`.
    fn experiments(&self, x: &DMatrix<f64>, y: &DMatrix<f64>) -> Result<Experiments> {
        let unobservable = &self.model.unobservable;
        let loaded: Vec<usize> = (0..x.nrows())
            .filter(|&i| !unobservable.response_vanishes(&[x[(i, 0)], x[(i, 1)]]))
            .collect();
        let rows: Vec<usize> = thin_rows(loaded.len(), self.max_experiments)
            .into_iter()
            .map(|k| loaded[k])
            .collect();
        Ok(Experiments::new(
            unobservable.input_names(),
            self.model.observable.output_names(),
            x.select_rows(rows.iter()),
            y.select_rows(rows.iter()),
        )?)
    }
}

/// The gauges' white-noise standard deviation (microstrain) estimated from rows in time
/// order: per gauge the robust first-difference estimate
/// ([`numerics::robust::noise_sd_from_differences`]), then the median over gauges. Level
/// changes between rows make it err on the high side, which only regularises the exact
/// estimator more.
///
/// ```
/// use nalgebra::DMatrix;
/// let trend = DMatrix::from_fn(50, 3, |i, g| 0.1 * i as f64 + g as f64);
/// assert!(bamudi_gate::calibrator::estimated_gauge_noise_sd(&trend) < 1e-12);
/// ```
pub fn estimated_gauge_noise_sd(y: &DMatrix<f64>) -> f64 {
    let mut per_gauge: Vec<f64> = y
        .column_iter()
        .map(|c| numerics::robust::noise_sd_from_differences(c.as_slice()))
        .collect();
    numerics::robust::median(&mut per_gauge)
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

/// Whether a calibration runs its adequacy checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Checks {
    Run,
    Skip,
}

/// The gap's summary of a calibration's grid posterior.
fn theta_summary(cal: &Calibration) -> ThetaSummary {
    cal.module3().posterior.summary(0)
}

/// The close loop's error of an application error.
fn loop_error(e: GateAppError) -> CloseLoopError {
    match e {
        GateAppError::Engine(e) => e.into(),
        GateAppError::CloseLoop(e) => e,
        e => CloseLoopError::Calibration(e.to_string()),
    }
}

impl Calibrator for GateCalibrator {
    fn calibrate(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> bamudi_closeloop::Result<Box<dyn CalibratedModel>> {
        match self.calibrate_gate(x, y) {
            Ok(m) => Ok(Box::new(m)),
            Err(e) => Err(loop_error(e)),
        }
    }

    /// Modules 2-3 only: no adequacy or physics checks (they change no number of Module 3).
    fn calibrate_theta(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> bamudi_closeloop::Result<ThetaSummary> {
        let (cal, _, _) = self.run(x, y, Checks::Skip).map_err(loop_error)?;
        Ok(theta_summary(&cal))
    }
}

/// A BA-MUDI calibration of the gate, as a close-loop [`CalibratedModel`].
pub struct CalibratedGate {
    model: Arc<GateMultiLevel>,
    cal: Calibration,
}

impl std::fmt::Debug for GateCalibrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GateCalibrator")
            .field("config", &self.config)
            .field("max_experiments", &self.max_experiments)
            .field("gauge_noise_sd", &self.gauge_noise_sd)
            .finish_non_exhaustive()
    }
}

impl std::fmt::Debug for CalibratedGate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CalibratedGate")
            .field("rho_star", &self.cal.rho_star())
            .field("sigma_eps", &self.cal.sigma_eps())
            .finish_non_exhaustive()
    }
}

impl CalibratedGate {
    /// The underlying BA-MUDI calibration (ρ*, GPs, posteriors, timings).
    pub fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// The gate's multi-level model the calibration belongs to.
    pub fn model(&self) -> &GateMultiLevel {
        &self.model
    }

    fn predictor(
        &self,
    ) -> bamudi::Result<
        bamudi::Predictor<'_, mlmodel::Memo<mitergate::ContactForceModel>, mitergate::StrainModel>,
    > {
        let policy = SupportPolicy::default().max_nodes(LOOP_SUPPORT_NODES);
        self.cal
            .predictor(self.model.as_ref())?
            .support_policy(&policy)
    }
}

impl CalibratedModel for CalibratedGate {
    fn predict(&self, x: &DMatrix<f64>) -> bamudi_closeloop::Result<(DMatrix<f64>, DMatrix<f64>)> {
        let (mean, var) = self.predictor()?.output_moments(x)?;
        let noise = self.cal.sigma_eps().powi(2);
        Ok((mean, var.add_scalar(noise)))
    }

    fn predict_at_theta(
        &self,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> bamudi_closeloop::Result<DMatrix<f64>> {
        let thetas: Vec<Vec<f64>> = theta.iter().map(|t| vec![*t]).collect();
        Ok(self.predictor()?.outputs_at_theta(x, &thetas)?)
    }

    fn predict_at_thetas(
        &self,
        x: &DMatrix<f64>,
        thetas: &[f64],
    ) -> bamudi_closeloop::Result<Vec<DMatrix<f64>>> {
        let thetas: Vec<Vec<f64>> = thetas.iter().map(|t| vec![*t]).collect();
        Ok(self.predictor()?.outputs_at_thetas(x, &thetas)?)
    }

    fn theta_summary(&self) -> ThetaSummary {
        theta_summary(&self.cal)
    }

    fn theta_bounds(&self) -> (f64, f64) {
        self.model.prior.bounds()[0]
    }

    /// Module 3's grid posterior integrated, in the marginal mode (the default): its log
    /// density is the marginal likelihood with every constant, the discrepancy integrated out.
    /// The other modes fit the discrepancy to the same readings at each `θ` (a profile with no
    /// Occam penalty), which two data sets cannot be compared by: `None`.
    fn log_evidence(&self) -> Option<f64> {
        let m3 = self.cal.module3();
        m3.marginal().and(m3.posterior.log_evidence())
    }

    /// The discrepancy `δ(x)` (GPs over the load inputs) absorbs load-shaped residuals.
    fn absorbs_load_functions(&self) -> bool {
        true
    }

    fn adequacy(&self) -> Option<&bamudi::AdequacyReport> {
        self.cal.adequacy()
    }
}
