//! The calibration settings: [`CalibrationParams`] as written (TOML or setters), checked once
//! into an immutable [`CalibrationConfig`].

use crate::error::{BamudiError, Result};
use serde::{Deserialize, Serialize};

/// How the discrepancy coefficients `α` and the regression coefficient `ρ` of the Module-2
/// training set (Eq. 27) are drawn. It is fixed in advance from the model alone, never tuned
/// against a known truth:
///
/// * `ρ ~ U(rho_range)`; the default `[0, 1.2]` covers the Eq.-30 search range `[0, 1]` with a
///   margin, so that the estimator is not extrapolating at the edges of the search.
/// * `x ~ U(x_bounds)` (per input; default: the bounding box of the experiment inputs, which are
///   controlled, known quantities).
/// * `α_k ~ U(-c s_k(x), c s_k(x))` independently, where `s_k(x)` is the magnitude of the
///   `k`-th coefficient of the least-squares projection (onto the discrepancy basis) of the
///   nominal response `g_u(x, θ̄)` at the prior mean `θ̄`, plus a floor
///   `floor_fraction * max_j |coef_j|` over the coefficients `j` of the same component, so that
///   coefficients the nominal shape happens not to excite still get a range. `c` is
///   [`alpha_scale`](Self::alpha_scale).
/// * `draws_per_x` `(ρ, α)` draws share one `x`, so each `g_u(x, θ_j)` evaluation (at every
///   quadrature node `θ_j`) is reused `draws_per_x` times: a training set of `N_t` samples needs
///   `N_t / draws_per_x` distinct `x` values ("the pool") and `pool * n_nodes` `g_u` calls.
/// * `noise_sd`: standard deviation of Gaussian noise added to the training outputs `μ_o`
///   (Eq. 27 has none; default 0). Set it to the gauges' noise when calibrating on measured
///   data: the estimator then learns (or, for the exact one, is) the noise-aware conditional
///   mean. With 0 and fewer gauges than coefficients, 1 microstrain of measurement noise becomes
///   coefficients of thousands of lbf/in, and the GP-smoothed fit can be worse than no
///   discrepancy (docs/closeloop.md, "The real gate"). `reproduce-paper` and the close-loop
///   calibrator set it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SamplingRule {
    /// Range of `ρ`.
    pub rho_range: (f64, f64),
    /// The constant `c` of the `α` range.
    pub alpha_scale: f64,
    /// Floor of `s_k(x)` as a fraction of the component's largest nominal coefficient.
    pub floor_fraction: f64,
    /// `(ρ, α)` draws per distinct `x`.
    pub draws_per_x: usize,
    /// Explicit input bounds (default: the experiments' bounding box).
    pub x_bounds: Option<Vec<(f64, f64)>>,
    /// Noise added to the training outputs (output units, e.g. microstrain).
    pub noise_sd: f64,
}

impl Default for SamplingRule {
    fn default() -> Self {
        Self {
            rho_range: (0.0, 1.2),
            alpha_scale: 0.5,
            floor_fraction: 0.05,
            draws_per_x: 10,
            x_bounds: None,
            noise_sd: 0.0,
        }
    }
}

impl SamplingRule {
    /// Sets the range of `ρ`.
    ///
    /// ```
    /// let r = bamudi::SamplingRule::default().rho_range(0.0, 1.5);
    /// assert_eq!(r.rho_range, (0.0, 1.5));
    /// ```
    pub fn rho_range(mut self, lo: f64, hi: f64) -> Self {
        self.rho_range = (lo, hi);
        self
    }
    /// Sets `c`.
    ///
    /// ```
    /// assert_eq!(bamudi::SamplingRule::default().alpha_scale(1.0).alpha_scale, 1.0);
    /// ```
    pub fn alpha_scale(mut self, c: f64) -> Self {
        self.alpha_scale = c;
        self
    }
    /// Sets the floor fraction.
    ///
    /// ```
    /// assert_eq!(bamudi::SamplingRule::default().floor_fraction(0.1).floor_fraction, 0.1);
    /// ```
    pub fn floor_fraction(mut self, f: f64) -> Self {
        self.floor_fraction = f;
        self
    }
    /// Sets the number of draws per distinct `x`.
    ///
    /// ```
    /// assert_eq!(bamudi::SamplingRule::default().draws_per_x(5).draws_per_x, 5);
    /// ```
    pub fn draws_per_x(mut self, n: usize) -> Self {
        self.draws_per_x = n;
        self
    }
    /// Sets explicit input bounds.
    ///
    /// ```
    /// let r = bamudi::SamplingRule::default().x_bounds(vec![(0.0, 1.0)]);
    /// assert!(r.x_bounds.is_some());
    /// ```
    pub fn x_bounds(mut self, b: Vec<(f64, f64)>) -> Self {
        self.x_bounds = Some(b);
        self
    }
    /// Sets the training-output noise.
    ///
    /// ```
    /// assert_eq!(bamudi::SamplingRule::default().noise_sd(0.5).noise_sd, 0.5);
    /// ```
    pub fn noise_sd(mut self, s: f64) -> Self {
        self.noise_sd = s;
        self
    }

    /// Checks the values ([`CalibrationParams::check`] calls it).
    ///
    /// ```
    /// use bamudi::{CalibrationParams, SamplingRule};
    /// assert!(CalibrationParams::default().sampling(SamplingRule::default()).check().is_ok());
    /// let bad = SamplingRule::default().alpha_scale(-1.0);
    /// assert!(CalibrationParams::default().sampling(bad).check().is_err());
    /// ```
    pub(crate) fn validate(&self) -> Result<()> {
        let (lo, hi) = self.rho_range;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(BamudiError::config(
                "sampling.rho_range",
                format!("need lo < hi, got [{lo}, {hi}]"),
            ));
        }
        if !(self.alpha_scale.is_finite() && self.alpha_scale > 0.0) {
            return Err(BamudiError::config("sampling.alpha_scale", "must be > 0"));
        }
        if !(self.floor_fraction.is_finite() && self.floor_fraction >= 0.0) {
            return Err(BamudiError::config(
                "sampling.floor_fraction",
                "must be >= 0",
            ));
        }
        if self.draws_per_x == 0 {
            return Err(BamudiError::config("sampling.draws_per_x", "must be >= 1"));
        }
        if !(self.noise_sd.is_finite() && self.noise_sd >= 0.0) {
            return Err(BamudiError::config("sampling.noise_sd", "must be >= 0"));
        }
        if let Some(b) = &self.x_bounds
            && b.iter()
                .any(|&(lo, hi)| !(lo.is_finite() && hi.is_finite() && lo < hi))
        {
            return Err(BamudiError::config(
                "sampling.x_bounds",
                "each interval needs lo < hi",
            ));
        }
        Ok(())
    }
}

/// How `θ` is marginalised over its prior in Eq. 25/27.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "snake_case", deny_unknown_fields)]
pub enum Marginalisation {
    /// Gauss quadrature of the prior ([`mlmodel::Prior::quadrature`]) with `order` nodes per dimension.
    Quadrature {
        /// Nodes per dimension.
        order: usize,
    },
    /// Monte Carlo over `samples` prior draws (the paper's choice).
    MonteCarlo {
        /// Number of prior draws.
        samples: usize,
    },
}

impl Default for Marginalisation {
    fn default() -> Self {
        Self::Quadrature { order: 5 }
    }
}

/// The estimator `α = f_ML(ρ, x, y)` of Eq. 29 (unfitted; see `estimator`).
///
/// In TOML: `[estimator]` with `kind = "lstm" | "ridge" | "exact_linear"` and the kind's own
/// keys (for the LSTM every [`seqnet::LstmSettings`] field, missing ones at their defaults).
///
/// ```
/// let p: bamudi::EstimatorParams = toml::from_str("kind = \"lstm\"\nhidden = 32\nsteps = 10").unwrap();
/// let bamudi::EstimatorParams::Lstm(s) = p else { panic!() };
/// assert_eq!((s.hidden, s.steps), (32, 10));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum EstimatorParams {
    /// The paper's LSTM (`seqnet`); the inputs `[ρ, x, y]` (standardised) are fed as a sequence
    /// of `steps` steps. The hyper-parameters are `seqnet`'s own settings.
    Lstm(seqnet::LstmSettings),
    /// A `smartcore` ridge regression on quadratic features of the standardised `[ρ, x, y]`
    /// (one model per coefficient).
    Ridge(RidgeParams),
    /// The exact linear-Gaussian conditional mean (needs a linear `g_o`).
    ExactLinear,
}

/// Settings of the ridge estimator.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RidgeParams {
    /// Ridge penalty on the standardised features.
    pub lambda: f64,
}

impl Default for EstimatorParams {
    /// The exact linear-Gaussian conditional mean ([`EstimatorParams::ExactLinear`]): the
    /// engine's observable level is linear in the response
    /// ([`mlmodel::LinearObservableModel`]), so the estimator of Eq. 29 has a closed form that
    /// the learnt estimators approximate, and it needs no training set. The default
    /// (marginal) mode's Module 3 reads the estimator's coefficients only to start its noise
    /// search, when neither `sigma_eps` nor `sampling.noise_sd` is given; the paper's LSTM
    /// ([`EstimatorParams::lstm`]) is for the paper's and the conditional modes as published
    /// (`cargo xtask reproduce-paper` sets it).
    ///
    /// ```
    /// assert_eq!(bamudi::EstimatorParams::default(), bamudi::EstimatorParams::ExactLinear);
    /// ```
    fn default() -> Self {
        Self::ExactLinear
    }
}

impl EstimatorParams {
    /// The LSTM with 64 hidden units in one layer, 10 scalar steps, at most 200 epochs of
    /// batches of 256 with Adam at 1e-3, early stopping after 20 epochs without improvement
    /// on a 10 % validation split: the paper's architecture with a generous training budget.
    ///
    /// ```
    /// let bamudi::EstimatorParams::Lstm(s) = bamudi::EstimatorParams::lstm() else { panic!() };
    /// assert_eq!((s.hidden, s.layers, s.steps, s.epochs, s.patience), (64, 1, 10, 200, 20));
    /// ```
    pub fn lstm() -> Self {
        Self::Lstm(seqnet::LstmSettings {
            hidden: 64,
            layers: 1,
            steps: 10,
            epochs: 200,
            batch_size: 256,
            learning_rate: 1e-3,
            validation_fraction: 0.1,
            patience: 20,
            ..seqnet::LstmSettings::default()
        })
    }

    /// Short name for reports (`lstm`, `ridge`, `exact_linear`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Lstm(_) => "lstm",
            Self::Ridge(_) => "ridge",
            Self::ExactLinear => "exact_linear",
        }
    }

    fn validate(&self) -> Result<()> {
        match self {
            // seqnet checks its own settings; the input count is only known at fit time, so any
            // multiple of `steps` stands in for it here
            Self::Lstm(s) => seqnet::LstmParams::new(s.steps.max(1), 1)
                .settings(s.clone())
                .check()
                .map(|_| ())
                .map_err(|e| BamudiError::config("estimator", e.to_string())),
            Self::Ridge(RidgeParams { lambda }) if !(lambda.is_finite() && *lambda >= 0.0) => Err(
                BamudiError::config("estimator.lambda", format!("must be >= 0, got {lambda}")),
            ),
            Self::Ridge(_) | Self::ExactLinear => Ok(()),
        }
    }
}

/// The `ρ` search of Eq. 30: a grid over `[lo, hi]` refined by Brent's method.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RhoSearch {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    /// Grid points.
    pub points: usize,
    /// Refine the best grid point with Brent's method.
    pub refine: bool,
}

impl Default for RhoSearch {
    fn default() -> Self {
        Self {
            lo: 0.0,
            hi: 1.0,
            points: 101,
            refine: true,
        }
    }
}

/// Settings of the adaptive random-walk Metropolis sampler (used when `dim θ > 1`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct McmcConfig {
    /// Independent chains.
    pub chains: usize,
    /// Warm-up (adaptation) iterations per chain, discarded.
    pub warmup: usize,
    /// Kept iterations per chain.
    pub samples: usize,
}

impl Default for McmcConfig {
    fn default() -> Self {
        Self {
            chains: 4,
            warmup: 2000,
            samples: 5000,
        }
    }
}

/// How Module 3 (Eq. 50) sets the discrepancy coefficients at a candidate `θ`; a mode carries
/// its own settings (only the marginal mode has any: its prior). In TOML the mode is named by
/// `coefficients` and the marginal mode's prior is the `[marginal]` section, which another mode
/// refuses.
///
/// ```
/// use bamudi::{CalibrationConfig, CoefficientMode, ModeKind};
/// let cfg = CalibrationConfig::from_toml_str("coefficients = \"conditional_on_theta\"").unwrap();
/// assert_eq!(cfg.coefficients, CoefficientMode::ConditionalOnTheta);
/// let cfg = CalibrationConfig::from_toml_str("[marginal]\nlevel_variance = 1e4").unwrap();
/// assert_eq!(cfg.coefficients.kind(), ModeKind::Marginal);
/// assert_eq!(cfg.coefficients.marginal_prior().unwrap().level_variance, 1e4);
/// // the marginal mode's section beside another mode is refused, even at its defaults
/// let text = "coefficients = \"prior_marginal\"\n[marginal]\nlevel_variance = 0";
/// let e = CalibrationConfig::from_toml_str(text).unwrap_err();
/// assert!(e.to_string().contains("`marginal`"), "{e}");
/// // each mode, written and read again, is itself with its settings
/// let prior = bamudi::MarginalPrior { level_variance: 10.0, ..Default::default() };
/// for mode in [
///     CoefficientMode::PriorMarginal,
///     CoefficientMode::ConditionalOnTheta,
///     CoefficientMode::Marginal(prior),
/// ] {
///     let cfg = bamudi::CalibrationParams::default().coefficients(mode.clone()).check().unwrap();
///     let text = toml::to_string(cfg.params()).unwrap();
///     assert_eq!(text.contains("[marginal]"), mode.kind() == ModeKind::Marginal, "{text}");
///     assert_eq!(CalibrationConfig::from_toml_str(&text).unwrap().coefficients, mode);
/// }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub enum CoefficientMode {
    /// The paper: `μ_α(x)` of Module 2, estimated with `θ` marginalised over its prior
    /// (Eq. 25/27), is the same at every `θ`. The coefficients then absorb the difference
    /// between the prior-averaged response and the response at the true `θ`, which pulls the
    /// posterior towards the `θ` whose response equals the prior average (see
    /// `docs/equations.md`, "Module 3 coefficient modes").
    PriorMarginal,
    /// Not in the paper: at each `θ` the estimator of Eq. 29 is re-applied to the observations
    /// shifted to what the prior-averaged model would have produced,
    /// `y − ρ*(A g(x, θ) − A ḡ(x)) − (b(x, θ) − b̄(x))`, and the coefficient GPs are re-conditioned
    /// on these `α̂(θ)` with their hyper-parameters held (a linear smoother). `θ` is then judged
    /// by what a smooth discrepancy cannot explain at that `θ`.
    ConditionalOnTheta,
    /// Not in the paper: the coefficient functions integrated out under a Gaussian-process
    /// prior with Module 2's kernels (the Kennedy-O'Hagan treatment), `ρ` integrated over its
    /// uniform prior, `σ_ε` and the prior's amplitude by type-II maximum likelihood; Module 4
    /// carries `θ`, `ρ` and every coefficient direction (see `marginal`).
    /// The default (with the default prior): its intervals are the ones the coverage study
    /// checks.
    Marginal(MarginalPrior),
}

impl Default for CoefficientMode {
    /// The marginal mode with the default prior.
    fn default() -> Self {
        Self::Marginal(MarginalPrior::default())
    }
}

impl CoefficientMode {
    /// The mode without its settings.
    pub fn kind(&self) -> ModeKind {
        match self {
            Self::PriorMarginal => ModeKind::PriorMarginal,
            Self::ConditionalOnTheta => ModeKind::ConditionalOnTheta,
            Self::Marginal(_) => ModeKind::Marginal,
        }
    }

    /// The marginal mode's prior; `None` in the other modes.
    pub fn marginal_prior(&self) -> Option<&MarginalPrior> {
        match self {
            Self::Marginal(prior) => Some(prior),
            _ => None,
        }
    }
}

/// A coefficient mode's name, without its settings: the TOML key `coefficients`, and what a
/// result or a study records of the mode it ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeKind {
    /// [`CoefficientMode::PriorMarginal`] (`"prior_marginal"`).
    PriorMarginal,
    /// [`CoefficientMode::ConditionalOnTheta`] (`"conditional_on_theta"`).
    ConditionalOnTheta,
    /// [`CoefficientMode::Marginal`] (`"marginal"`; the default).
    #[default]
    Marginal,
}

impl From<ModeKind> for CoefficientMode {
    /// The mode with its default settings.
    fn from(kind: ModeKind) -> Self {
        match kind {
            ModeKind::PriorMarginal => Self::PriorMarginal,
            ModeKind::ConditionalOnTheta => Self::ConditionalOnTheta,
            ModeKind::Marginal => Self::default(),
        }
    }
}

impl ModeKind {
    /// The name a configuration file uses (`prior_marginal`, `conditional_on_theta`,
    /// `marginal`).
    pub fn name(self) -> &'static str {
        match self {
            Self::PriorMarginal => "prior_marginal",
            Self::ConditionalOnTheta => "conditional_on_theta",
            Self::Marginal => "marginal",
        }
    }
}

/// The prior of the discrepancy coefficients in the marginal mode
/// ([`CoefficientMode::Marginal`]; TOML section `[marginal]`, given only with that mode).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MarginalPrior {
    /// How each coefficient function's prior scale follows from the sampling rule's ranges.
    pub scales: CoefficientScales,
    /// Zero the discrepancy where the unobservable model says the response vanishes at `θ`
    /// ([`mlmodel::UnobservableModel::discrepancy_support`]; for the gate, in the gap).
    pub mask_outside_support: bool,
    /// The correlation family of the coefficient functions over the inputs.
    pub kernel: CoefficientKernel,
    /// Prior variance of each coefficient function's unknown level, relative to the process
    /// variance (dimensionless, ≥ 0): `α_k(x) = √s a_k(x) (z_k(x) + β_k)`, `β_k ~ N(0, c)`.
    /// `0` (the default, [`DEFAULT_LEVEL_VARIANCE`]) is a zero-mean prior; `1e4` is vague,
    /// near an unknown flat-prior level (ordinary kriging); see `marginal`.
    ///
    /// ```
    /// let cfg = bamudi::CalibrationConfig::from_toml_str("[marginal]\nlevel_variance = 1e4").unwrap();
    /// assert_eq!(cfg.coefficients.marginal_prior().unwrap().level_variance, 1e4);
    /// let default = bamudi::CalibrationConfig::from_toml_str("").unwrap();
    /// let prior = default.coefficients.marginal_prior().unwrap();
    /// assert_eq!(prior.level_variance, bamudi::params::DEFAULT_LEVEL_VARIANCE);
    /// assert!(bamudi::CalibrationConfig::from_toml_str("[marginal]\nlevel_variance = -1").is_err());
    /// ```
    pub level_variance: f64,
    /// Hold the amplitude `s` and the length-scale factor at these values instead of fitting
    /// them by type-II maximum likelihood (`None`, the default, fits them). Needs `sigma_eps`
    /// too, so that nothing is estimated: the setting of simulation-based calibration, where
    /// the data are drawn from this very prior.
    ///
    /// ```
    /// let text = "sigma_eps = 1.0\n[marginal.fixed]\namplitude = 1e-5\nlength_scale_factor = 1.0";
    /// assert!(bamudi::CalibrationConfig::from_toml_str(text).is_ok());
    /// // without sigma_eps something would still be fitted: refused, naming the key
    /// let e = bamudi::CalibrationConfig::from_toml_str(&text[16..]).unwrap_err();
    /// assert!(e.to_string().contains("marginal.fixed"), "{e}");
    /// ```
    pub fixed: Option<FixedHyper>,
    /// Whether the data may say there is no discrepancy at all
    /// (`average`): [`DiscrepancyPresence::Weighed`] (the default) weighs the
    /// model with the discrepancy against the calibration without one by their evidence and
    /// predicts with the two models' mixture; [`DiscrepancyPresence::Assumed`] keeps the model
    /// with it.
    ///
    /// ```
    /// use bamudi::params::DiscrepancyPresence;
    /// let cfg = bamudi::CalibrationConfig::from_toml_str("[marginal]\npresence = \"assumed\"").unwrap();
    /// assert_eq!(cfg.coefficients.marginal_prior().unwrap().presence, DiscrepancyPresence::Assumed);
    /// let default = bamudi::CalibrationConfig::from_toml_str("").unwrap();
    /// assert_eq!(default.coefficients.marginal_prior().unwrap().presence, DiscrepancyPresence::Weighed);
    /// ```
    pub presence: DiscrepancyPresence,
}

impl MarginalPrior {
    /// Checks the prior's values (errors name the TOML key); `sigma_eps` is the calibration's.
    fn check(&self, sigma_eps: Option<f64>) -> Result<()> {
        let c = self.level_variance;
        if !(c.is_finite() && (0.0..=MAX_LEVEL_VARIANCE).contains(&c)) {
            return Err(BamudiError::config(
                "marginal.level_variance",
                format!("must be in [0, {MAX_LEVEL_VARIANCE:e}], got {c}"),
            ));
        }
        if let Some(f) = &self.fixed {
            let ok = |v: f64| v.is_finite() && v > 0.0;
            if !(ok(f.amplitude) && ok(f.length_scale_factor)) {
                return Err(BamudiError::config(
                    "marginal.fixed",
                    format!(
                        "amplitude and length_scale_factor must be finite and > 0, got {} and {}",
                        f.amplitude, f.length_scale_factor
                    ),
                ));
            }
            if sigma_eps.is_none() {
                return Err(BamudiError::config(
                    "marginal.fixed",
                    "holding the amplitude and length scales needs sigma_eps too",
                ));
            }
        }
        Ok(())
    }
}

/// Whether Module 4's predictions assume a discrepancy ([`MarginalPrior::presence`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DiscrepancyPresence {
    /// The model with the discrepancy is the answer. Simulation-based calibration, whose data
    /// always hold a discrepancy drawn from its prior, checks this posterior.
    Assumed,
    /// The models with and without a discrepancy weighed by their evidence, the answer their
    /// mixture (`average`). Needs the no-discrepancy fit
    /// ([`CalibrationParams::no_discrepancy_fit`]), a one-dimensional `θ` (a grid posterior
    /// carries its evidence) and no declared build tolerances (the fit without a discrepancy
    /// does not integrate them, so the evidences would not compare the discrepancy alone);
    /// otherwise the model with the discrepancy is the answer.
    /// The default: on truths without a discrepancy, or with one below the gauges' resolution,
    /// the discrepancy model's `θ` posterior is several times wider than the data need and,
    /// near the gap's edge, its corrected force 2.6-9.6x worse than the fit without one
    /// (`docs/results/validation.md` has both panels side by side). The weighing enters the
    /// predictions; the gap's posterior stays the discrepancy model's.
    #[default]
    Weighed,
}

/// Hyper-parameters of the marginal mode held at given values ([`MarginalPrior::fixed`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedHyper {
    /// The amplitude `s` (dimensionless: the coefficients' variance relative to their
    /// scales' squares).
    pub amplitude: f64,
    /// The factor on the coefficients' length scales.
    pub length_scale_factor: f64,
}

/// The largest accepted [`MarginalPrior::level_variance`]: beyond it the level directions'
/// eigenvalues would swamp the process's in double precision.
pub const MAX_LEVEL_VARIANCE: f64 = 1e8;

/// The default [`MarginalPrior::level_variance`]: `0`, a zero-mean prior, with the default
/// [`CoefficientScales::Isotropic`] scales. A level per coefficient function (`1e3`) made `θ`
/// confounded with the discrepancy's load-proportional part: on the tuning study (quick size,
/// 20 replicates per scenario, seed 2021, the paper's δ) the `θ` posterior sd doubled (0.17 →
/// 0.36 in) and, as the contact force at the gap's edge follows `θ`, the corrected normal force
/// was 2.5x less accurate (RMSE 110 → 276 lbf/in, scenario 1); with `0` the `θ` intervals held
/// their levels on that study as well (`docs/results/validation.md` has the design table and
/// the validation on other seeds). Under the per-component scales used before, `0` had failed
/// the coverage study and `1e3` was the default.
pub const DEFAULT_LEVEL_VARIANCE: f64 = 0.0;

/// The correlation family of the marginal mode's coefficient functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoefficientKernel {
    /// Module 2's kernel (the squared exponential unless configured otherwise).
    Module2,
    /// Matérn ν = 5/2 with Module 2's length scales (then scaled by the fitted factor): the
    /// default, because a discrepancy's shape across conditions is not known to be infinitely
    /// smooth, and the squared exponential's certainty about it made `θ` over-confident in the
    /// coverage study (the alternative the paper names after Eq. 34).
    #[default]
    Matern52,
}

impl Default for MarginalPrior {
    fn default() -> Self {
        Self {
            scales: CoefficientScales::Isotropic,
            mask_outside_support: true,
            kernel: CoefficientKernel::Matern52,
            level_variance: DEFAULT_LEVEL_VARIANCE,
            fixed: None,
            presence: DiscrepancyPresence::default(),
        }
    }
}

/// The prior scale of each discrepancy coefficient function in the marginal mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoefficientScales {
    /// Each coefficient its own sampling-rule range `h_k(x)/√3`: the shape of the nominal
    /// response decides which polynomial orders the discrepancy may use.
    PerCoefficient,
    /// Every coefficient of a response component the largest range of that component at `x`:
    /// no polynomial order is presumed smaller than another (the discrepancy's shape is
    /// unknown), while the size still follows the nominal response. The default before the
    /// isotropic scales: the tangential coefficients' ranges follow the tangential response's
    /// size, so a normal-force discrepancy was partly explained by tangential coefficients
    /// (reconstructed δ 2-11x worse than leaving it out).
    SharedPerComponent,
    /// One force-unit scale for every coefficient of every component: the root mean square
    /// `r(x)` of the nominal response `g_u(x, θ̄)` over all its points. The supported basis is
    /// orthonormalised in the response's own metric (a unit coefficient is a correction of unit
    /// root mean square over the points of its component) and every coefficient function
    /// shares one correlation function, so the prior of the correction `L α(x)` is the same in
    /// every direction of the basis's span: no direction of the response is cheaper than
    /// another, and the posterior mean corrects only what the observations see (the posterior
    /// mean of `α(x)` lies in the row space of `B` at every input). The default.
    #[default]
    Isotropic,
}

/// Everything a calibration needs besides the model and the data, as a user writes it (TOML
/// or setters). Its values are checked when [`check`](Self::check) turns it into a
/// [`CalibrationConfig`], which cannot change afterwards (linfa's params → checked params);
/// reading a file already refuses what cannot be represented, such as a `[marginal]` section
/// beside another coefficient mode.
///
/// ```
/// use bamudi::{CalibrationParams, EstimatorParams};
/// let cfg = CalibrationParams::default()
///     .estimator(EstimatorParams::ExactLinear)
///     .training_size(3000)
///     .sigma_eps(Some(1.0))
///     .seed(7)
///     .check()
///     .unwrap();
/// assert_eq!(cfg.training_size, 3000); // read through the checked value
/// let text = toml::to_string(cfg.params()).unwrap();
/// let back = bamudi::CalibrationConfig::from_toml_str(&text).unwrap();
/// assert_eq!(back, cfg);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ParamsFile", into = "ParamsFile")]
pub struct CalibrationParams {
    /// The coefficient estimator of Eq. 29.
    pub estimator: EstimatorParams,
    /// The training-set sampling rule.
    pub sampling: SamplingRule,
    /// Training-set size `N_t` (paper: 50,000).
    pub training_size: usize,
    /// Marginalisation of `θ` in Eq. 25/27/31.
    pub marginalisation: Marginalisation,
    /// The `ρ` search.
    pub rho: RhoSearch,
    /// Grid points for the one-dimensional `θ` posterior.
    pub theta_grid_points: usize,
    /// Random restarts of each GP hyper-parameter fit.
    pub gp_restarts: usize,
    /// Measurement-noise standard deviation `σ_ε` (output units); `None`: estimated.
    pub sigma_eps: Option<f64>,
    /// MCMC settings (for `dim θ > 1`).
    pub mcmc: McmcConfig,
    /// How Module 3 sets the discrepancy coefficients at each `θ`, with the mode's settings
    /// (default: the marginal mode with the default prior; TOML `coefficients` and
    /// `[marginal]`).
    pub coefficients: CoefficientMode,
    /// The adequacy checks run after Module 3.
    pub adequacy: AdequacyParams,
    /// Fit the strongest calibration without a discrepancy at its `θ` posterior's support
    /// points ([`crate::posterior::no_discrepancy::NoDiscrepancyFit`], "baseline (b)"), which
    /// [`crate::Predictor::no_discrepancy_response`] predicts from (default `true`). It costs
    /// the model at every support point of that posterior (up to 400 `θ`s, each at every
    /// experiment); a caller that never predicts the baseline, such as a close loop, turns it
    /// off. The posterior without discrepancy itself (Fig. 16) is computed either way.
    pub no_discrepancy_fit: bool,
    /// Master seed; every random step derives its seed from it.
    pub seed: u64,
    /// Worker threads (`None`: rayon's default). The engine does not start threads of its own;
    /// a binary applies this to its global pool.
    pub threads: Option<usize>,
}

impl Default for CalibrationParams {
    fn default() -> Self {
        Self {
            estimator: EstimatorParams::default(),
            sampling: SamplingRule::default(),
            training_size: 50_000,
            marginalisation: Marginalisation::default(),
            rho: RhoSearch::default(),
            theta_grid_points: 201,
            gp_restarts: 3,
            sigma_eps: None,
            mcmc: McmcConfig::default(),
            coefficients: CoefficientMode::default(),
            adequacy: AdequacyParams::default(),
            no_discrepancy_fit: true,
            seed: 2021,
            threads: None,
        }
    }
}

macro_rules! setter {
    ($(#[$doc:meta])* $name:ident : $ty:ty, $example:expr) => {
        $(#[$doc])*
        ///
        /// ```
        #[doc = concat!("let cfg = bamudi::CalibrationParams::default().", stringify!($name), "(", $example, ");")]
        /// assert!(cfg.check().is_ok());
        /// ```
        pub fn $name(mut self, v: $ty) -> Self {
            self.$name = v;
            self
        }
    };
}

/// Largest accepted values of the sizes a user sets, so that a typo is an error instead of a
/// calibration that runs for days or exhausts memory. Each is far above what the paper or the
/// case study needs (in brackets).
pub mod limits {
    /// Training-set size [50,000].
    pub const TRAINING_SIZE: usize = 5_000_000;
    /// `θ` grid points [121-241].
    pub const THETA_GRID_POINTS: usize = 100_000;
    /// GP restarts [3].
    pub const GP_RESTARTS: usize = 1_000;
    /// `ρ` grid points [101].
    pub const RHO_POINTS: usize = 100_000;
    /// Quadrature order or Monte-Carlo samples for `θ` [5].
    pub const MARGINALISATION_NODES: usize = 100_000;
    /// MCMC chains [4] and kept or warm-up iterations per chain [5,000].
    pub const MCMC_CHAINS: usize = 256;
    /// See [`MCMC_CHAINS`].
    pub const MCMC_ITERATIONS: usize = 10_000_000;
    /// Worker threads.
    pub const THREADS: usize = 1_024;
}

impl CalibrationParams {
    setter!(/// Sets the estimator.
        estimator: EstimatorParams, "bamudi::EstimatorParams::ExactLinear");
    setter!(/// Sets the sampling rule.
        sampling: SamplingRule, "bamudi::SamplingRule::default()");
    setter!(/// Sets the training-set size.
        training_size: usize, "3000");
    setter!(/// Sets the marginalisation method.
        marginalisation: Marginalisation, "bamudi::Marginalisation::MonteCarlo { samples: 100 }");
    setter!(/// Sets the `ρ` search.
        rho: RhoSearch, "bamudi::RhoSearch::default()");
    setter!(/// Sets the number of `θ` grid points.
        theta_grid_points: usize, "101");
    setter!(/// Sets GP restarts.
        gp_restarts: usize, "2");
    setter!(/// Sets (or clears) `σ_ε`.
        sigma_eps: Option<f64>, "Some(1.0)");
    setter!(/// Sets the MCMC settings.
        mcmc: McmcConfig, "bamudi::McmcConfig::default()");
    setter!(/// Sets how Module 3 treats the discrepancy coefficients at each `θ`, with the
        /// mode's settings (the marginal mode's prior).
        coefficients: CoefficientMode, "bamudi::CoefficientMode::Marginal(bamudi::MarginalPrior { scales: bamudi::CoefficientScales::PerCoefficient, ..Default::default() })");
    setter!(/// Sets whether the baseline without discrepancy is fitted at its support points.
        no_discrepancy_fit: bool, "false");
    setter!(/// Sets the master seed.
        seed: u64, "42");
    setter!(/// Sets the thread count.
        threads: Option<usize>, "Some(2)");

    /// Checks every field (errors name the TOML key and say what is allowed) and returns the
    /// checked, immutable configuration.
    ///
    /// ```
    /// assert!(bamudi::CalibrationParams::default().check().is_ok());
    /// let e = bamudi::CalibrationParams::default().sigma_eps(Some(-1.0)).check().unwrap_err();
    /// assert!(e.to_string().contains("sigma_eps"));
    /// // the marginal mode's prior is checked with it
    /// let prior = bamudi::MarginalPrior { level_variance: -1.0, ..Default::default() };
    /// let mode = bamudi::CoefficientMode::Marginal(prior);
    /// let e = bamudi::CalibrationParams::default().coefficients(mode).check().unwrap_err();
    /// assert!(e.to_string().contains("marginal.level_variance"), "{e}");
    /// ```
    pub fn check(self) -> Result<CalibrationConfig> {
        self.sampling.validate()?;
        self.estimator.validate()?;
        self.check_sizes()?;
        let r = &self.rho;
        if !(r.lo.is_finite() && r.hi.is_finite() && r.lo < r.hi) {
            return Err(BamudiError::config(
                "rho",
                format!("need finite lo < hi, got [{}, {}]", r.lo, r.hi),
            ));
        }
        let alpha = self.adequacy.family_alpha;
        if !(alpha > 0.0 && alpha < 0.5) {
            return Err(BamudiError::config(
                "adequacy.family_alpha",
                format!("must be in (0, 0.5), got {alpha}"),
            ));
        }
        if let Some(s) = self.sigma_eps
            && !(s.is_finite() && s > 0.0)
        {
            return Err(BamudiError::config(
                "sigma_eps",
                format!("must be > 0, got {s}"),
            ));
        }
        if let CoefficientMode::Marginal(prior) = &self.coefficients {
            prior.check(self.sigma_eps)?;
        }
        Ok(CalibrationConfig(self))
    }

    fn check_sizes(&self) -> Result<()> {
        let marg = match self.marginalisation {
            Marginalisation::Quadrature { order } => ("marginalisation.order", order),
            Marginalisation::MonteCarlo { samples } => ("marginalisation.samples", samples),
        };
        let (chains, warm, kept) = (self.mcmc.chains, self.mcmc.warmup, self.mcmc.samples);
        let threads = self.threads.unwrap_or(1);
        for (key, value, lo, hi) in [
            (
                "training_size",
                self.training_size,
                10,
                limits::TRAINING_SIZE,
            ),
            (
                "theta_grid_points",
                self.theta_grid_points,
                3,
                limits::THETA_GRID_POINTS,
            ),
            ("gp_restarts", self.gp_restarts, 0, limits::GP_RESTARTS),
            ("rho.points", self.rho.points, 3, limits::RHO_POINTS),
            (marg.0, marg.1, 1, limits::MARGINALISATION_NODES),
            ("mcmc.chains", chains, 2, limits::MCMC_CHAINS),
            ("mcmc.warmup", warm, 0, limits::MCMC_ITERATIONS),
            ("mcmc.samples", kept, 10, limits::MCMC_ITERATIONS),
            ("threads", threads, 1, limits::THREADS),
        ] {
            if !(lo..=hi).contains(&value) {
                return Err(BamudiError::config(
                    key,
                    format!("must be in [{lo}, {hi}], got {value}"),
                ));
            }
        }
        Ok(())
    }
}

/// A checked [`CalibrationParams`]: produced only by [`CalibrationParams::check`] (also when
/// read from TOML or JSON), read-only afterwards (it dereferences to the params). To change a
/// setting, take the params back with [`into_params`](Self::into_params), change them and
/// check again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "CalibrationParams", into = "CalibrationParams")]
pub struct CalibrationConfig(CalibrationParams);

impl TryFrom<CalibrationParams> for CalibrationConfig {
    type Error = BamudiError;
    fn try_from(p: CalibrationParams) -> Result<Self> {
        p.check()
    }
}

impl From<CalibrationConfig> for CalibrationParams {
    fn from(c: CalibrationConfig) -> Self {
        c.0
    }
}

impl std::ops::Deref for CalibrationConfig {
    type Target = CalibrationParams;
    fn deref(&self) -> &CalibrationParams {
        &self.0
    }
}

impl Default for CalibrationConfig {
    /// The checked defaults of [`CalibrationParams`].
    fn default() -> Self {
        Self(CalibrationParams::default())
    }
}

impl CalibrationConfig {
    /// The checked params (read-only).
    pub fn params(&self) -> &CalibrationParams {
        &self.0
    }

    /// The params, to change and check again.
    pub fn into_params(self) -> CalibrationParams {
        self.0
    }

    /// Parses and checks a TOML configuration (missing keys take their defaults).
    ///
    /// ```
    /// let cfg = bamudi::CalibrationConfig::from_toml_str("training_size = 1000\n[estimator]\nkind = \"exact_linear\"\n").unwrap();
    /// assert_eq!(cfg.training_size, 1000);
    /// assert!(bamudi::CalibrationConfig::from_toml_str("training_size = 0").is_err());
    /// ```
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let params: CalibrationParams = toml::from_str(text).map_err(|e| BamudiError::Serde {
            context: "calibration config (TOML)".into(),
            reason: e.to_string(),
        })?;
        params.check()
    }
}

/// [`CalibrationParams`] as a file holds it: the coefficient mode by name (`coefficients`)
/// and the marginal mode's prior as its own section (`marginal`), which is refused beside
/// another mode. Missing keys take their defaults.
#[derive(Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub(crate) struct ParamsFile {
    estimator: EstimatorParams,
    sampling: SamplingRule,
    training_size: usize,
    marginalisation: Marginalisation,
    rho: RhoSearch,
    theta_grid_points: usize,
    gp_restarts: usize,
    sigma_eps: Option<f64>,
    mcmc: McmcConfig,
    pub(crate) coefficients: ModeKind,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) marginal: Option<MarginalPrior>,
    adequacy: AdequacyParams,
    no_discrepancy_fit: bool,
    seed: u64,
    threads: Option<usize>,
}

impl Default for ParamsFile {
    /// The defaults of [`CalibrationParams`], the marginal section absent (a file that names
    /// the marginal mode without it gets the default prior).
    fn default() -> Self {
        let mut file = Self::from(CalibrationParams::default());
        file.marginal = None;
        file
    }
}

impl From<CalibrationParams> for ParamsFile {
    fn from(p: CalibrationParams) -> Self {
        Self {
            coefficients: p.coefficients.kind(),
            marginal: p.coefficients.marginal_prior().cloned(),
            estimator: p.estimator,
            sampling: p.sampling,
            training_size: p.training_size,
            marginalisation: p.marginalisation,
            rho: p.rho,
            theta_grid_points: p.theta_grid_points,
            gp_restarts: p.gp_restarts,
            sigma_eps: p.sigma_eps,
            mcmc: p.mcmc,
            adequacy: p.adequacy,
            no_discrepancy_fit: p.no_discrepancy_fit,
            seed: p.seed,
            threads: p.threads,
        }
    }
}

impl TryFrom<ParamsFile> for CalibrationParams {
    type Error = BamudiError;
    fn try_from(f: ParamsFile) -> Result<Self> {
        let coefficients = match (f.coefficients, f.marginal) {
            (ModeKind::Marginal, prior) => CoefficientMode::Marginal(prior.unwrap_or_default()),
            (kind, None) => kind.into(),
            (kind, Some(_)) => {
                return Err(BamudiError::config(
                    "marginal",
                    format!(
                        "the [marginal] settings belong to coefficients = \"marginal\", but \
                         the coefficients are \"{}\": remove them, or choose the marginal mode",
                        kind.name()
                    ),
                ));
            }
        };
        Ok(Self {
            coefficients,
            estimator: f.estimator,
            sampling: f.sampling,
            training_size: f.training_size,
            marginalisation: f.marginalisation,
            rho: f.rho,
            theta_grid_points: f.theta_grid_points,
            gp_restarts: f.gp_restarts,
            sigma_eps: f.sigma_eps,
            mcmc: f.mcmc,
            adequacy: f.adequacy,
            no_discrepancy_fit: f.no_discrepancy_fit,
            seed: f.seed,
            threads: f.threads,
        })
    }
}

/// Settings of the adequacy checks (TOML section `[adequacy]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdequacyParams {
    /// Run the checks after Module 3.
    pub enabled: bool,
    /// Family-wise error rate of the p-value checks (Holm). 0.01 rather than 0.05: the
    /// hyper-parameters are plug-ins, and a false alarm sends an engineer to a gate.
    pub family_alpha: f64,
}

impl Default for AdequacyParams {
    fn default() -> Self {
        Self {
            enabled: true,
            family_alpha: 0.01,
        }
    }
}
