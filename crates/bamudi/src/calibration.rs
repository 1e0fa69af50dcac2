//! The executor of Modules 2-3 ([`Calibrate`], [`calibrate`]) and its result ([`Calibration`]).
//!
//! The executor runs the stages of [`crate::surrogate`] and [`crate::posterior`] in order, times
//! each one and reports it to the [`Observer`]; the stages themselves neither read the clock
//! nor print. A [`Calibration`] holds the checked configuration, what it needs to know of the
//! data and the model, the results of both modules and the timings; Module 4 is its
//! [`predictor`](Calibration::predictor).

use crate::adequacy::{self, AdequacyReport, Attribution, Check};
use crate::data::Experiments;
use crate::error::{BamudiError, Result};
use crate::observe::{Event, Observer, Silent, Stage};
use crate::params::{CalibrationConfig, CalibrationParams, ModeKind, ParamsFile};
use crate::posterior::{self, Method, Module3, marginal};
use crate::surrogate::artefact::ModelSignature;
use crate::surrogate::estimator::FittedEstimator;
use crate::surrogate::gps::CoefficientGps;
use crate::surrogate::training::LinearParts;
use crate::surrogate::{self, Module2, Problem, Surrogate};
use mlmodel::{LinearObservableModel, MultiLevelModel, UnobservableModel};
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Wall-clock seconds spent in each stage.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Timings {
    /// Module 2: training-set generation (Eq. 27).
    pub training_set_s: f64,
    /// Module 2: fitting the coefficient estimator (Eq. 29).
    pub estimator_s: f64,
    /// Module 2: `ρ*` search and `α̂` (Eq. 30-32).
    pub rho_s: f64,
    /// Module 2: coefficient GPs (Eq. 33-37).
    pub gp_s: f64,
    /// Module 3: the coefficient strategy's own search (the conditional mode's profile and
    /// GP refit; 0 in the paper's mode).
    #[serde(default)]
    pub coefficients_s: f64,
    /// Module 3: covariance factorisation and posterior of `θ` (both variants).
    pub module3_s: f64,
    /// The adequacy checks.
    #[serde(default)]
    pub adequacy_s: f64,
}

impl Timings {
    /// Seconds of Module 2 (training set, estimator, `ρ*`, GPs).
    pub fn module2_s(&self) -> f64 {
        self.training_set_s + self.estimator_s + self.rho_s + self.gp_s
    }
}

/// A saved calibration's configuration, checked again. The marginal mode's settings in a
/// calibration of another mode were never read; files written before such settings were
/// refused, or under other defaults, hold them, and they are dropped rather than refused.
fn saved_config<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<CalibrationConfig, D::Error> {
    let mut file = ParamsFile::deserialize(d)?;
    if file.coefficients != ModeKind::Marginal {
        file.marginal = None;
    }
    CalibrationParams::try_from(file)
        .and_then(CalibrationParams::check)
        .map_err(serde::de::Error::custom)
}

/// The result of a BA-MUDI calibration (serialisable: [`save`](Self::save) /
/// [`load`](Self::load)).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Calibration {
    #[serde(deserialize_with = "saved_config")]
    config: CalibrationConfig,
    signature: ModelSignature,
    x_experiments: DMatrix<f64>,
    parts: LinearParts,
    module2: Module2,
    module3: Module3,
    timings: Timings,
    /// The adequacy verdict ([`crate::adequacy`]; absent when disabled or in files saved
    /// before it existed).
    #[serde(default)]
    adequacy: Option<AdequacyReport>,
    /// The marginal mode's factorisation, rebuilt on first use by Module 4.
    #[serde(skip)]
    marginal_state: std::sync::OnceLock<std::sync::Arc<marginal::MarginalState>>,
    /// The conditional mode's coefficient shifts `x ↦ Σ_k(x, X) w_k`, reduced on first use
    /// by Module 4 (one reduction per coefficient instead of one per predicted input).
    #[serde(skip)]
    alpha_shifts: std::sync::OnceLock<Vec<gp::CovarianceContraction>>,
}

/// Runs Modules 2-3 of BA-MUDI for a linear observable model with the default (silent)
/// observer; see [`Calibrate`].
///
/// ```
/// # // a tiny two-level model: the response is θ at one point, the output reads it
/// # use bamudi::{CalibrationParams, EstimatorParams, Experiments};
/// # use mlmodel::*;
/// # use nalgebra::DMatrix;
/// # struct Lift;
/// # impl UnobservableModel for Lift {
/// #     fn input_names(&self) -> Vec<String> { vec!["x".into()] }
/// #     fn param_dim(&self) -> usize { 1 }
/// #     fn components(&self) -> usize { 1 }
/// #     fn coordinates(&self) -> &[f64] { &[0.0, 0.5, 1.0] }
/// #     fn evaluate(&self, x: &[f64], t: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
/// #         for (o, d) in out.iter_mut().zip([0.0, 0.5, 1.0]) { *o = x[0] * (t[0] + d); }
/// #         Ok(())
/// #     }
/// # }
/// # struct Read(DMatrix<f64>);
/// # impl ObservableModel for Read {
/// #     fn output_names(&self) -> Vec<String> { vec!["a".into(), "b".into()] }
/// #     fn evaluate(&self, x: &[f64], t: &[f64], y: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
/// #         self.offset(x, t, out)?;
/// #         for (o, v) in out.iter_mut().zip((&self.0 * nalgebra::DVector::from_column_slice(y)).iter()) { *o += v; }
/// #         Ok(())
/// #     }
/// # }
/// # impl LinearObservableModel for Read {
/// #     fn matrix(&self) -> &DMatrix<f64> { &self.0 }
/// #     fn offset(&self, _: &[f64], _: &[f64], out: &mut [f64]) -> mlmodel::Result<()> { out.fill(0.0); Ok(()) }
/// # }
/// let basis = DiscrepancyBasis::new(orthopoly::Family::Legendre, (0.0, 1.0), &[0.0, 0.5, 1.0], &[1]).unwrap();
/// let a = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.5, 0.0, 1.0, 0.5]);
/// let model = MultiLevelModel::new(Lift, Read(a), Box::new(UniformPrior::new(vec![(0.0, 4.0)]).unwrap()), basis).unwrap();
/// let x = DMatrix::from_fn(12, 1, |i, _| 1.0 + i as f64);
/// let y = DMatrix::from_fn(12, 2, |i, p| (1.0 + i as f64) * (2.0 + [0.5, 1.0][p]) + 0.01 * ((i * 7 + p) % 5) as f64);
/// let exps = Experiments::new(vec!["x".into()], vec!["a".into(), "b".into()], x, y).unwrap();
/// let cfg = CalibrationParams::default().estimator(EstimatorParams::ExactLinear).gp_restarts(0).check().unwrap();
/// let cal = bamudi::calibrate(&model, &exps, &cfg).unwrap();
/// assert!(cal.module3().posterior.mean()[0] > 0.0);
/// // Module 4: the corrected response at x = 3 (three points) with its 95 % band
/// let band = cal.predictor(&model).unwrap().response(&[3.0]).unwrap();
/// assert_eq!(band.mean.len(), 3);
/// assert!(band.lower.iter().zip(&band.upper).all(|(l, u)| l <= u));
///
/// // The same run through the executor, with an observer that counts the finished stages
/// // (an observer sees events, never the algorithm's state)
/// use bamudi::observe::{Event, Observer};
/// struct Stages(std::sync::atomic::AtomicUsize);
/// impl Observer for Stages {
///     fn observe(&self, e: &Event<'_>) {
///         if let Event::Finished { .. } = e {
///             self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
///         }
///     }
/// }
/// let stages = Stages(0.into());
/// let again = bamudi::Calibrate::new(&cfg).observer(&stages).run(&model, &exps).unwrap();
/// assert!(stages.0.into_inner() > 0);
/// assert_eq!(again.module3().posterior.mean(), cal.module3().posterior.mean());
/// ```
pub fn calibrate<U, O>(
    model: &MultiLevelModel<U, O>,
    exps: &Experiments,
    cfg: &CalibrationConfig,
) -> Result<Calibration>
where
    U: UnobservableModel,
    O: LinearObservableModel,
{
    Calibrate::new(cfg).run(model, exps)
}

/// The calibration executor: a checked configuration and an observer; [`run`](Self::run)
/// executes the stages, times them and reports them (an example with an observer, and the
/// [`Predictor`](crate::Predictor) made from its result: [`calibrate`]).
pub struct Calibrate<'a> {
    cfg: &'a CalibrationConfig,
    observer: &'a dyn Observer,
}

impl<'a> Calibrate<'a> {
    /// An executor with a silent observer.
    pub fn new(cfg: &'a CalibrationConfig) -> Self {
        Self {
            cfg,
            observer: &Silent,
        }
    }

    /// Reports progress and stage timings to `observer`.
    pub fn observer(mut self, observer: &'a dyn Observer) -> Self {
        self.observer = observer;
        self
    }

    /// Modules 2-3 from scratch.
    pub fn run<U, O>(
        &self,
        model: &MultiLevelModel<U, O>,
        exps: &Experiments,
    ) -> Result<Calibration>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let p = Problem::new(model, exps, self.cfg, self.observer)?;
        let mut t = Timings::default();
        let (m2, ctx) = self.fit_module2(&p, None, &mut t)?;
        self.conclude(p, m2, ctx, t)
    }

    /// Modules 2-3 with an estimator fitted before (e.g. by another calibration of the same
    /// data): the training set and the fit are skipped. `training_pool_size` is recorded as
    /// given.
    pub fn run_with_estimator<U, O>(
        &self,
        model: &MultiLevelModel<U, O>,
        exps: &Experiments,
        estimator: FittedEstimator,
        training_pool_size: usize,
    ) -> Result<Calibration>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let p = Problem::new(model, exps, self.cfg, self.observer)?;
        let mut t = Timings::default();
        let given = Some((estimator, training_pool_size));
        let (m2, ctx) = self.fit_module2(&p, given, &mut t)?;
        self.conclude(p, m2, ctx, t)
    }

    /// Module 2 alone — the training set, the estimator of Eq. 29, `ρ*` (Eq. 30), `α̂` and the
    /// coefficient GPs — as the [`Surrogate`] Module 3 runs on in any coefficient mode
    /// ([`run_with_surrogate`](Self::run_with_surrogate), which has an example).
    pub fn fit_surrogate<U, O>(
        &self,
        model: &MultiLevelModel<U, O>,
        exps: &Experiments,
    ) -> Result<Surrogate>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let p = Problem::new(model, exps, self.cfg, self.observer)?;
        let (m2, _) = self.fit_module2(&p, None, &mut Timings::default())?;
        Ok(Surrogate::fitted(&p, m2))
    }

    /// Module 3 (and the adequacy checks) in this configuration's coefficient mode on a
    /// [`Surrogate`] fitted before: from [`fit_surrogate`](Self::fit_surrogate), or the one a
    /// calibration of the same model and data ran on ([`Calibration::surrogate`]). Nothing of
    /// Module 2 is fitted again: on a surrogate from `fit_surrogate` or [`run`](Self::run) the
    /// result is the one `run` gives in this mode, bit for bit (on one from
    /// [`run_with_estimator`](Self::run_with_estimator), the one that gives). Errors, naming
    /// what differs, if the surrogate was fitted to another model (signature, `A`, basis) or
    /// other experiments (inputs or outputs), or under another `θ` quadrature rule or input
    /// box (another seed, prior or marginalisation), `ρ` search, sampling rule, GP setting,
    /// estimator or training-set size.
    ///
    /// ```
    /// # // a tiny two-level model: the response is θ at one point, the output reads it
    /// # use bamudi::{CalibrationParams, EstimatorParams, Experiments};
    /// # use mlmodel::*;
    /// # use nalgebra::DMatrix;
    /// # struct Lift;
    /// # impl UnobservableModel for Lift {
    /// #     fn input_names(&self) -> Vec<String> { vec!["x".into()] }
    /// #     fn param_dim(&self) -> usize { 1 }
    /// #     fn components(&self) -> usize { 1 }
    /// #     fn coordinates(&self) -> &[f64] { &[0.0, 0.5, 1.0] }
    /// #     fn evaluate(&self, x: &[f64], t: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
    /// #         for (o, d) in out.iter_mut().zip([0.0, 0.5, 1.0]) { *o = x[0] * (t[0] + d); }
    /// #         Ok(())
    /// #     }
    /// # }
    /// # struct Read(DMatrix<f64>);
    /// # impl ObservableModel for Read {
    /// #     fn output_names(&self) -> Vec<String> { vec!["a".into(), "b".into()] }
    /// #     fn evaluate(&self, x: &[f64], t: &[f64], y: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
    /// #         self.offset(x, t, out)?;
    /// #         for (o, v) in out.iter_mut().zip((&self.0 * nalgebra::DVector::from_column_slice(y)).iter()) { *o += v; }
    /// #         Ok(())
    /// #     }
    /// # }
    /// # impl LinearObservableModel for Read {
    /// #     fn matrix(&self) -> &DMatrix<f64> { &self.0 }
    /// #     fn offset(&self, _: &[f64], _: &[f64], out: &mut [f64]) -> mlmodel::Result<()> { out.fill(0.0); Ok(()) }
    /// # }
    /// # let basis = DiscrepancyBasis::new(orthopoly::Family::Legendre, (0.0, 1.0), &[0.0, 0.5, 1.0], &[1]).unwrap();
    /// # let a = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.5, 0.0, 1.0, 0.5]);
    /// # let model = MultiLevelModel::new(Lift, Read(a), Box::new(UniformPrior::new(vec![(0.0, 4.0)]).unwrap()), basis).unwrap();
    /// # let x = DMatrix::from_fn(12, 1, |i, _| 1.0 + i as f64);
    /// # let y = DMatrix::from_fn(12, 2, |i, p| (1.0 + i as f64) * (2.0 + [0.5, 1.0][p]) + 0.01 * ((i * 7 + p) % 5) as f64);
    /// # let exps = Experiments::new(vec!["x".into()], vec!["a".into(), "b".into()], x, y).unwrap();
    /// # use bamudi::{Calibrate, CoefficientMode};
    /// let paper = CalibrationParams::default()
    ///     .estimator(EstimatorParams::ExactLinear)
    ///     .gp_restarts(0)
    ///     .coefficients(CoefficientMode::PriorMarginal)
    ///     .check()
    ///     .unwrap();
    /// // Module 2 once, Module 3 in two modes on it
    /// let surrogate = Calibrate::new(&paper).fit_surrogate(&model, &exps).unwrap();
    /// let first = Calibrate::new(&paper).run_with_surrogate(&model, &exps, &surrogate).unwrap();
    /// let conditional = paper.clone().into_params()
    ///     .coefficients(CoefficientMode::ConditionalOnTheta)
    ///     .check()
    ///     .unwrap();
    /// let again = Calibrate::new(&conditional).run_with_surrogate(&model, &exps, &surrogate).unwrap();
    /// // each the answer of a calibration from scratch in its mode
    /// let full = Calibrate::new(&conditional).run(&model, &exps).unwrap();
    /// assert_eq!(again.module3().posterior.mean(), full.module3().posterior.mean());
    /// assert_eq!(first.module3().posterior.mean(), Calibrate::new(&paper).run(&model, &exps).unwrap().module3().posterior.mean());
    /// // a finished calibration hands on the surrogate it ran on
    /// let from_first = Calibrate::new(&conditional).run_with_surrogate(&model, &exps, &first.surrogate()).unwrap();
    /// assert_eq!(from_first.module3().posterior.mean(), full.module3().posterior.mean());
    /// // Module 2 under another seed is another Module 2
    /// let reseeded = conditional.into_params().seed(9).check().unwrap();
    /// let err = Calibrate::new(&reseeded).run_with_surrogate(&model, &exps, &surrogate).unwrap_err();
    /// assert!(err.to_string().contains("its seed differs"), "{err}");
    /// ```
    pub fn run_with_surrogate<U, O>(
        &self,
        model: &MultiLevelModel<U, O>,
        exps: &Experiments,
        surrogate: &Surrogate,
    ) -> Result<Calibration>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let p = Problem::new(model, exps, self.cfg, self.observer)?;
        surrogate.check_fits(&p)?;
        let mut t = Timings::default();
        let ctx = self.stage(Stage::Rho, &mut t.rho_s, || surrogate::contexts(&p))?;
        self.conclude(p, surrogate.module2().clone(), ctx, t)
    }

    /// Module 2 (the training set and the estimator unless `given`, then `ρ*`, `α̂` and the
    /// coefficient GPs), with the experiments' contexts Module 3 reads.
    fn fit_module2<U, O>(
        &self,
        p: &Problem<'_, U, O>,
        given: Option<(FittedEstimator, usize)>,
        t: &mut Timings,
    ) -> Result<(Module2, Vec<surrogate::training::XContext>)>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let (estimator, training_pool_size) = match given {
            Some(given) => given,
            None => {
                let training = self.stage(Stage::TrainingSet, &mut t.training_set_s, || {
                    surrogate::training_set(p)
                })?;
                let estimator = self.stage(Stage::Estimator, &mut t.estimator_s, || {
                    surrogate::fit_estimator(p, training.as_ref())
                })?;
                (estimator, training.as_ref().map_or(0, |s| s.pool_size))
            }
        };
        let (ctx, rho, alpha_hat) = self.stage(Stage::Rho, &mut t.rho_s, || {
            let ctx = surrogate::contexts(p)?;
            let (rho, alpha) = surrogate::rho_and_alpha(p, &estimator, &ctx)?;
            Ok((ctx, rho, alpha))
        })?;
        let gps = self.stage(Stage::CoefficientGps, &mut t.gp_s, || {
            surrogate::coefficient_gps(p, &alpha_hat)
        })?;
        let m2 = Module2 {
            x_bounds: p.x_bounds.clone(),
            theta_rule: p.theta_rule.clone(),
            training_pool_size,
            estimator,
            rho,
            alpha_hat,
            gps,
            outputs_digest: Some(surrogate::artefact::outputs_digest(&p.exps.y)),
        };
        Ok((m2, ctx))
    }

    /// Module 3 in the configured mode on Module 2's results, then the adequacy checks.
    fn conclude<U, O>(
        &self,
        p: Problem<'_, U, O>,
        m2: Module2,
        ctx: Vec<surrogate::training::XContext>,
        mut t: Timings,
    ) -> Result<Calibration>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let m3 = match posterior::method::<U, O>(&self.cfg.coefficients) {
            Method::Modular(strategy) => {
                let coefs = self.stage(Stage::Coefficients, &mut t.coefficients_s, || {
                    posterior::adapt_coefficients(&p, &m2, &ctx, strategy.as_ref())
                })?;
                self.stage(Stage::Module3, &mut t.module3_s, || {
                    posterior::posterior(&p, &m2, &ctx, strategy.as_ref(), coefs)
                })?
            }
            Method::Marginal(prior) => self.stage(Stage::Module3, &mut t.module3_s, || {
                let sigma0 = marginal::initial_sigma(&p, &m2, &ctx)?;
                marginal::posterior(&p, &m2, &ctx, sigma0, prior)
            })?,
        };
        let mut cal = Calibration {
            config: self.cfg.clone(),
            signature: ModelSignature::of(p.model),
            x_experiments: p.exps.x.clone(),
            parts: p.parts.clone(),
            module2: m2,
            module3: m3,
            timings: t,
            adequacy: None,
            marginal_state: std::sync::OnceLock::new(),
            alpha_shifts: std::sync::OnceLock::new(),
        };
        let mut timings = cal.timings.clone();
        cal.adequacy = self.adequacy(&p, &cal, &mut timings)?;
        cal.timings = timings;
        Ok(cal)
    }

    /// The adequacy checks; a numerical failure inside them is logged and reported as "not
    /// assessed" (the calibration itself stands).
    fn adequacy<U, O>(
        &self,
        p: &Problem<'_, U, O>,
        cal: &Calibration,
        t: &mut Timings,
    ) -> Result<Option<AdequacyReport>>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let params = &self.cfg.adequacy;
        if !params.enabled {
            return Ok(None);
        }
        let mut seconds = 0.0;
        let report = self.stage(Stage::Adequacy, &mut seconds, || {
            let state = || cal.marginal_state();
            let subject = adequacy::Subject {
                module3: cal.module3(),
                x: cal.x_experiments(),
                state: &state,
            };
            Ok(adequacy::assess(p, &subject, params).unwrap_or_else(|e| {
                log::warn!("adequacy checks failed to run: {e}");
                AdequacyReport::not_assessed(format!("the checks failed: {e}"), params.family_alpha)
            }))
        })?;
        t.adequacy_s = seconds;
        Ok(Some(report))
    }

    /// Runs one stage: reports its start and end, and adds its wall time to `seconds`.
    fn stage<T>(
        &self,
        stage: Stage,
        seconds: &mut f64,
        f: impl FnOnce() -> Result<T>,
    ) -> Result<T> {
        self.observer.observe(&Event::Started { stage, work: 0 });
        let start = Instant::now();
        let out = f()?;
        let elapsed = start.elapsed().as_secs_f64();
        *seconds += elapsed;
        self.observer.observe(&Event::Finished {
            stage,
            seconds: elapsed,
        });
        Ok(out)
    }
}

impl Calibration {
    /// The checked configuration used.
    pub fn config(&self) -> &CalibrationConfig {
        &self.config
    }
    /// Module 2's results.
    pub fn module2(&self) -> &Module2 {
        &self.module2
    }
    /// The [`Surrogate`] (Module 2) this calibration ran on, to run Module 3 on in another
    /// coefficient mode ([`Calibrate::run_with_surrogate`]).
    pub fn surrogate(&self) -> Surrogate {
        Surrogate::from_parts(
            self.module2.clone(),
            self.signature.clone(),
            self.parts.clone(),
            self.x_experiments.clone(),
            &self.config,
        )
    }
    /// Module 3's results.
    pub fn module3(&self) -> &Module3 {
        &self.module3
    }
    /// Seconds per stage.
    pub fn timings(&self) -> &Timings {
        &self.timings
    }
    /// The adequacy verdict and its checks (`None` when disabled).
    pub fn adequacy(&self) -> Option<&AdequacyReport> {
        self.adequacy.as_ref()
    }

    /// Adds an application's own checks (e.g. physical ones) to the verdict, each with the
    /// attribution the application gives it should it fail (a physical check that passes once
    /// the suspected sensor faults are removed, [`AdequacyReport::sensor_correction`], is a
    /// sensor's doing; otherwise the model's form). Each check's `passed` is taken as given
    /// (threshold checks; they do not enter the p-value family); a failed one makes the
    /// verdict inadequate and is listed. Nothing happens when the checks are disabled.
    pub fn add_adequacy_checks(&mut self, checks: Vec<(Check, Attribution)>) {
        if let Some(a) = self.adequacy.as_mut() {
            a.add_threshold_checks(checks);
        }
    }
    /// `A`, `L` and `B = A L` of the calibrated model.
    pub fn parts(&self) -> &LinearParts {
        &self.parts
    }
    /// Input names of the calibrated model.
    pub fn input_names(&self) -> &[String] {
        &self.signature.input_names
    }
    /// Output names of the calibrated model.
    pub fn output_names(&self) -> &[String] {
        &self.signature.output_names
    }
    /// The experiment inputs the coefficient GPs were fitted at (`N_e x d`).
    pub fn x_experiments(&self) -> &DMatrix<f64> {
        &self.x_experiments
    }
    /// `ρ*` used by Modules 3-4.
    pub fn rho_star(&self) -> f64 {
        self.module3.rho_star
    }
    /// `σ_ε` used by Module 3 (output units).
    pub fn sigma_eps(&self) -> f64 {
        self.module3.sigma_eps
    }
    /// The coefficient GPs Module 4 uses (the conditional mode's refit, or Module 2's).
    pub fn coefficient_gps(&self) -> &CoefficientGps {
        self.module3
            .conditional()
            .and_then(|c| c.refit_gps.as_ref())
            .unwrap_or(&self.module2.gps)
    }
    /// The coefficient estimates behind those GPs: the conditional mode's posterior-averaged
    /// `E_θ[α̂(θ)]`, or Module 2's `α̂` (Eq. 32), `N_e x K`.
    pub fn alpha_hat(&self) -> &DMatrix<f64> {
        self.module3
            .conditional()
            .map_or(&self.module2.alpha_hat, |c| &c.alpha_hat)
    }

    /// Means and latent variances of the discrepancy coefficients at the rows of `x` (two
    /// `N x K` matrices): the coefficient GPs, plus, in the conditional coefficient mode, the
    /// shift `Σ_k(x, X) w_k` of the posterior-averaged `α̂(θ)`.
    pub(crate) fn alpha_moments(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let gps = self.coefficient_gps();
        let (mut mean, var) = gps.predict(x)?;
        if let Some(w) = self.module3.conditional().map(|c| &c.alpha_correction) {
            for (k, shift) in self.alpha_shifts(gps, w)?.iter().enumerate() {
                let shift = shift
                    .apply(&gps.models[k], x)
                    .map_err(|e| BamudiError::Gp {
                        coefficient: k,
                        reason: e.to_string(),
                    })?;
                mean.column_mut(k)
                    .iter_mut()
                    .zip(shift.iter())
                    .for_each(|(m, s)| *m += s);
            }
        }
        Ok((mean, var))
    }

    /// The reduced shifts `x ↦ Σ_k(x, X) w_k` of [`Self::alpha_moments`] (built on first use,
    /// then shared): the GP mean moved by the conditional mode's correction of its targets.
    fn alpha_shifts(
        &self,
        gps: &CoefficientGps,
        w: &DMatrix<f64>,
    ) -> Result<&[gp::CovarianceContraction]> {
        if let Some(s) = self.alpha_shifts.get() {
            return Ok(s);
        }
        let shifts = gps
            .models
            .par_iter()
            .enumerate()
            .map(|(k, model)| {
                let wk: Vec<f64> = w.column(k).iter().copied().collect();
                model
                    .covariance_contraction(&self.x_experiments, &wk)
                    .map_err(|e| BamudiError::Gp {
                        coefficient: k,
                        reason: e.to_string(),
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(self.alpha_shifts.get_or_init(|| shifts))
    }

    /// The marginal mode's factorisation for Module 4 (built on first use, then shared).
    pub(crate) fn marginal_state(&self) -> Result<std::sync::Arc<marginal::MarginalState>> {
        if let Some(s) = self.marginal_state.get() {
            return Ok(s.clone());
        }
        let fit = self.module3.marginal().ok_or_else(|| {
            BamudiError::Calibration("no marginal-mode fit in this calibration".into())
        })?;
        let sigma2 = self.module3.sigma_eps.powi(2);
        let state = marginal::MarginalState::new(fit, &self.x_experiments, &self.parts, sigma2)?;
        Ok(self
            .marginal_state
            .get_or_init(|| std::sync::Arc::new(state))
            .clone())
    }

    /// Checks that `model` is the one this calibration was fitted to.
    pub(crate) fn check_model<U, O>(&self, model: &MultiLevelModel<U, O>) -> Result<()>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let got = ModelSignature::of(model);
        if got != self.signature {
            return Err(BamudiError::Calibration(format!(
                "the model differs from the calibrated one: calibrated {:?}, given {got:?}",
                self.signature
            )));
        }
        if model.observable.matrix() != &self.parts.a {
            return Err(BamudiError::Calibration(
                "the model's matrix A differs from the calibrated one".into(),
            ));
        }
        let declared: Vec<&str> = model.tolerances.iter().map(|t| t.name.as_str()).collect();
        let integrated: Vec<&str> = self
            .module3()
            .marginal()
            .iter()
            .flat_map(|m| m.tolerances.iter().map(|t| t.name.as_str()))
            .collect();
        if declared != integrated {
            return Err(BamudiError::Calibration(format!(
                "the model declares the build tolerances {declared:?}, the calibration \
                 integrated {integrated:?} (a model saved before models kept their tolerances \
                 has none: save the model again with the calibration's tolerances declared, \
                 e.g. by re-running the calibration)"
            )));
        }
        Ok(())
    }

    /// Saves the whole calibration (configuration, estimator, GPs, posteriors) as JSON,
    /// atomically, so that a later run can predict (Module 4) or report without
    /// re-calibrating.
    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| BamudiError::Serde {
            context: path.display().to_string(),
            reason: e.to_string(),
        })?;
        crate::data::write_atomic(path, text.as_bytes())
    }

    /// Loads a calibration saved by [`save`](Self::save); its configuration is checked again.
    ///
    /// ```
    /// let err = bamudi::Calibration::load(std::path::Path::new("/nonexistent.json")).unwrap_err();
    /// assert!(err.to_string().contains("/nonexistent.json"));
    /// ```
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| BamudiError::Io {
            path: path.display().to_string(),
            source: e,
        })?;
        Self::from_json_str(&text, &path.display().to_string())
    }

    /// The calibration of JSON text written by [`save`](Self::save) or
    /// [`to_json_string`](Self::to_json_string); `context` names it in errors; its
    /// configuration is checked again.
    pub fn from_json_str(text: &str, context: &str) -> Result<Self> {
        let cal: Self = serde_json::from_str(text).map_err(|e| BamudiError::Serde {
            context: context.to_string(),
            reason: e.to_string(),
        })?;
        cal.validate().map_err(|reason| BamudiError::Serde {
            context: context.to_string(),
            reason,
        })?;
        Ok(cal)
    }

    /// The JSON text [`save`](Self::save) writes.
    pub fn to_json_string(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| BamudiError::Serde {
            context: "calibration".into(),
            reason: e.to_string(),
        })
    }

    /// Consistency of a loaded calibration (sizes, a positive `σ_ε`).
    fn validate(&self) -> std::result::Result<(), String> {
        let (fitted, configured) = (self.module3.mode.kind(), self.config.coefficients.kind());
        if fitted != configured {
            return Err(format!(
                "config.coefficients is {configured:?}, but module3 holds the fit of the \
                 coefficient mode {fitted:?}"
            ));
        }
        let s = self.module3.sigma_eps;
        if !(s.is_finite() && s > 0.0) {
            return Err(format!("sigma_eps must be a positive number, got {s}"));
        }
        let k = self.signature.n_coefficients;
        let (n_e, d) = self.x_experiments.shape();
        if self.parts.b.ncols() != k || self.coefficient_gps().len() != k {
            return Err(format!(
                "{k} discrepancy coefficients, but B or the GPs disagree"
            ));
        }
        if d != self.signature.input_names.len() || self.alpha_hat().nrows() != n_e {
            return Err("experiment inputs and coefficient estimates disagree in size".into());
        }
        self.validate_marginal_nodes(n_e * self.parts.b.nrows())
    }

    /// Every marginal node's columns `c` and `a` have one entry per observation (`n_s`);
    /// a calibration saved before the nodes kept them has none.
    fn validate_marginal_nodes(&self, n_s: usize) -> std::result::Result<(), String> {
        let Some(fit) = self.module3.marginal() else {
            return Ok(());
        };
        for (j, node) in fit.nodes.iter().enumerate() {
            if let Some((what, len)) = node.column_mismatch(n_s) {
                return Err(format!(
                    "module3.marginal.nodes[{j}].{what} has {len} entries, expected {n_s} (one \
                     per observation; a calibration saved by an older bamudi lacks them: \
                     calibrate again)"
                ));
            }
        }
        Ok(())
    }
}
