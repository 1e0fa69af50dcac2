//! The miter gate as an `mlmodel` multi-level model (Sec. 4.1-4.2, Fig. 11), and the one
//! place where it is assembled.
//!
//! * [`ContactForceModel`] implements [`UnobservableModel`]: `g_BC(x, θ)`, inputs
//!   `x = [h_up, h_down]` (in), one parameter `θ` = bottom gap length (in), two components
//!   (normal, tangential line load, lbf/in) at the `N_u` representation points.
//! * [`StrainModel`] implements [`ObservableModel`] and [`LinearObservableModel`]: Eq. 47,
//!   strain (microstrain) `= A y_u + s_w(h_up, h_down)`.
//!
//! Both validate their inputs: levels in [`WATER_LEVEL_RANGE`] (`[24, 744]` in),
//! `h_up ≥ h_down`, `θ ∈ [0, H)`; a violation is an [`ModelError::OutOfDomain`] naming the
//! input.
//!
//! # Assembling the gate's multi-level model
//!
//! [`build_contact`] builds the FE leaf of a [`GateConfig`], condenses it to
//! [`DEFAULT_NU`] points and wraps it in the contact model with the paper's parameters;
//! [`multilevel`] turns that contact model and a [`MultiLevelSpec`] (gap prior, discrepancy
//! terms, memo size) into the [`GateMultiLevel`] the calibration consumes:
//!
//! ```
//! use mitergate::{MultiLevelSpec, multilevel, testing::doc_gate, ContactParams};
//! let contact = ContactParams::default().build(doc_gate()).unwrap();
//! let model = multilevel(contact, &MultiLevelSpec::default()).unwrap();
//! // the doc gate has 5 representation points: 6 + 6 terms are capped at 5 + 5
//! assert_eq!(model.basis.terms(), &[5, 5]);
//! ```

use crate::condense::{CondensedGate, DEFAULT_NU, HydrostaticTable};
use crate::contact::{AnchorCache, ContactModel, ContactParams};
use crate::error::GateError;
use crate::gate::{GateConfig, GateModel, WATER_LEVEL_RANGE};
use mlmodel::{
    DiscrepancyBasis, LinearObservableModel, Memo, ModelError, MultiLevelModel, ObservableModel,
    UniformPrior, UnobservableModel, check_len,
};
use nalgebra::{DMatrix, DVector};
use orthopoly::Family;
use serde::{Deserialize, Serialize};

/// Checks `x = [h_up, h_down]` (in) and `θ = [gap]` (in) against the gate's domain.
///
/// ```
/// use mitergate::multilevel::check_domain;
/// assert!(check_domain(&[500.0, 100.0], &[90.0], 762.0).is_ok());
/// assert!(check_domain(&[100.0, 500.0], &[90.0], 762.0).is_err()); // h_up < h_down
/// assert!(check_domain(&[500.0, 100.0], &[762.0], 762.0).is_err());
/// ```
pub fn check_domain(x: &[f64], theta: &[f64], quoin_height: f64) -> mlmodel::Result<()> {
    check_len("x", x, 2)?;
    check_len("theta", theta, 1)?;
    let (lo, hi) = WATER_LEVEL_RANGE;
    for (name, v) in [("h_up", x[0]), ("h_down", x[1])] {
        if !(lo..=hi).contains(&v) {
            return Err(out_of_domain(name, v, lo, hi));
        }
    }
    if x[0] < x[1] {
        return Err(out_of_domain("h_up - h_down", x[0] - x[1], 0.0, hi - lo));
    }
    let t = theta[0];
    if !(t >= 0.0 && t < quoin_height) {
        return Err(out_of_domain("theta", t, 0.0, quoin_height));
    }
    Ok(())
}

fn out_of_domain(name: &str, value: f64, lo: f64, hi: f64) -> ModelError {
    ModelError::OutOfDomain {
        name: name.to_string(),
        value,
        lo,
        hi,
    }
}

/// Smallest head `h_up - h_down` (in) at which the gate is loaded. Below it the gate is open:
/// no thrust, no quoin contact force (the contact force model's response vanishes, and a
/// calibration has nothing to learn from the row).
pub const MIN_HEAD_IN: f64 = 1.0;

/// Whether the levels `[h_up, h_down]` (in) leave the gate open: a head below
/// [`MIN_HEAD_IN`], hence no thrust and no quoin contact force. The discrepancy corrects the
/// contact force, so it is zero there too.
///
/// ```
/// use mitergate::multilevel::gate_open;
/// assert!(gate_open([300.0, 300.0]) && gate_open([300.5, 300.0]));
/// assert!(!gate_open([500.0, 100.0]));
/// ```
pub fn gate_open(x: [f64; 2]) -> bool {
    x[0] - x[1] < MIN_HEAD_IN
}

/// `g_BC(x, θ)` as an [`UnobservableModel`].
///
/// ```
/// use mitergate::multilevel::ContactForceModel;
/// use mlmodel::UnobservableModel;
/// let model = mitergate::contact::ContactParams::default()
///     .build(mitergate::testing::doc_gate()).unwrap();
/// let g = ContactForceModel::new(model);
/// let mut out = vec![0.0; g.response_len()];
/// g.evaluate(&[700.0, 100.0], &[90.0], &mut out).unwrap();
/// assert_eq!(out[0], 0.0); // in the gap
/// assert!(g.evaluate(&[800.0, 100.0], &[90.0], &mut out).is_err());
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ContactForceModel {
    contact: ContactModel,
    /// Anchored warm starts ([`AnchorCache`]): fewer iterations, the same function of
    /// `(x, θ)` under any evaluation order.
    #[serde(skip)]
    anchors: AnchorCache,
}

impl ContactForceModel {
    /// Wraps a contact model.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let g = mitergate::multilevel::ContactForceModel::new(model);
    /// assert_eq!(g.contact().gate().n_points(), 5);
    /// ```
    pub fn new(contact: ContactModel) -> Self {
        Self {
            contact,
            anchors: AnchorCache::default(),
        }
    }
    /// The wrapped contact model.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// # let g = mitergate::multilevel::ContactForceModel::new(model);
    /// assert_eq!(g.contact().params().k_normal(), 1e6);
    /// ```
    pub fn contact(&self) -> &ContactModel {
        &self.contact
    }
}

impl UnobservableModel for ContactForceModel {
    fn input_names(&self) -> Vec<String> {
        vec!["h_up".into(), "h_down".into()]
    }
    fn check_input(&self, x: &[f64]) -> mlmodel::Result<()> {
        check_domain(x, &[0.0], self.contact.gate().quoin_height)
    }
    fn param_dim(&self) -> usize {
        1
    }
    fn components(&self) -> usize {
        2
    }
    fn coordinates(&self) -> &[f64] {
        &self.contact.gate().nu_points
    }
    /// Gate open: less than [`MIN_HEAD_IN`] of head (see [`gate_open`]).
    fn response_vanishes(&self, x: &[f64]) -> bool {
        x.len() == 2 && gate_open([x[0], x[1]])
    }
    /// The contact coverage of each quoin point ([`ContactModel::coverage`]): a discrepancy
    /// of the contact force acts where there is contact, not in the gap below `θ`.
    fn discrepancy_support(&self, theta: &[f64]) -> Option<Vec<f64>> {
        theta.first().map(|t| self.contact.coverage(*t))
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        check_domain(x, theta, self.contact.gate().quoin_height)?;
        check_len("out", out, self.response_len())?;
        self.anchors
            .solve(&self.contact, x[0], x[1], theta[0])
            .map(|sol| out.copy_from_slice(&sol.forces))
            .map_err(|e| ModelError::Numerical {
                context: format!(
                    "contact g_BC at h_up = {}, h_down = {}, theta = {}",
                    x[0], x[1], theta[0]
                ),
                reason: e.to_string(),
            })
    }
}

/// The strain model of Eq. 47, `strain = A y_u + s_w(h_up, h_down)` (microstrain).
///
/// ```
/// use mitergate::multilevel::StrainModel;
/// use mlmodel::{LinearObservableModel, ObservableModel};
/// let gate = mitergate::testing::doc_gate();
/// let s = StrainModel::new(&gate);
/// let mut out = vec![0.0; 2];
/// s.evaluate(&[700.0, 100.0], &[90.0], &vec![0.0; 10], &mut out).unwrap();
/// let water = gate.water_strain.eval_levels(700.0, 100.0);
/// assert!((out[0] - water[0]).abs() < 1e-12);
/// assert_eq!(s.matrix().shape(), (2, 10));
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StrainModel {
    a_matrix: DMatrix<f64>,
    water_strain: HydrostaticTable,
    gauge_names: Vec<String>,
    quoin_height: f64,
}

impl StrainModel {
    /// Copies `A`, the water-strain table and the gauge names out of `gate`.
    ///
    /// ```
    /// let s = mitergate::multilevel::StrainModel::new(&mitergate::testing::doc_gate());
    /// assert_eq!(mlmodel::ObservableModel::output_dim(&s), 2);
    /// ```
    pub fn new(gate: &CondensedGate) -> Self {
        Self {
            a_matrix: gate.a_matrix.clone(),
            water_strain: gate.water_strain.clone(),
            gauge_names: gate.gauge_names.clone(),
            quoin_height: gate.quoin_height,
        }
    }
}

impl ObservableModel for StrainModel {
    fn output_names(&self) -> Vec<String> {
        self.gauge_names.clone()
    }
    fn evaluate(
        &self,
        x: &[f64],
        theta: &[f64],
        y_u: &[f64],
        out: &mut [f64],
    ) -> mlmodel::Result<()> {
        check_len("y_u", y_u, self.a_matrix.ncols())?;
        self.offset(x, theta, out)?;
        let strain = &self.a_matrix * DVector::from_column_slice(y_u);
        for (o, s) in out.iter_mut().zip(strain.iter()) {
            *o += s;
        }
        Ok(())
    }
}

impl LinearObservableModel for StrainModel {
    fn matrix(&self) -> &DMatrix<f64> {
        &self.a_matrix
    }
    fn offset(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        check_domain(x, theta, self.quoin_height)?;
        check_len("out", out, self.a_matrix.nrows())?;
        let water = self.water_strain.eval_levels(x[0], x[1]);
        out.copy_from_slice(water.as_slice());
        Ok(())
    }
}

/// The gate's multi-level model: memoised contact forces `g_BC` (unobservable), strains
/// (observable, Eq. 47), a uniform prior of the gap and a Legendre discrepancy basis. Built by
/// [`multilevel`].
pub type GateMultiLevel = MultiLevelModel<Memo<ContactForceModel>, StrainModel>;

/// What the gate's multi-level model needs beyond the contact model: the gap prior, the
/// discrepancy basis size and the memo. Validate with [`MultiLevelSpec::validate`] (done by
/// [`multilevel`]).
///
/// ```
/// use mitergate::MultiLevelSpec;
/// let spec = MultiLevelSpec::default().with_gap_prior((135.0, 165.0));
/// assert_eq!(spec.discrepancy_terms, [6, 6]);
/// assert!(spec.validate().is_ok());
/// let err = spec.with_discrepancy_terms([0, 6]).validate().unwrap_err();
/// assert!(err.to_string().contains("discrepancy_terms"));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MultiLevelSpec {
    /// Bounds `(lo, hi)` (in) of the uniform prior of the gap length `θ`:
    /// `0 <= lo < hi < H` (the quoin height, checked by [`multilevel`]).
    pub gap_prior_in: (f64, f64),
    /// Legendre discrepancy terms `[normal, tangential]` (degrees `0..k`), each `>= 1`;
    /// [`multilevel`] caps them at the number of representation points.
    pub discrepancy_terms: [usize; 2],
    /// Most remembered contact solves ([`mlmodel::Memo`], 8 bytes per force value: about 8
    /// kB per solve at 509 points); `0`: no memo.
    pub memo_capacity: usize,
    /// Most remembered model rows `A g` and `b` ([`mlmodel::RowMemo`], 14 values per row for
    /// the 7 gauges, about 260 bytes with the key): what Module 3's rows and Module 4's output
    /// moments read of the contact solves, at about a thirtieth of a solve's memory; `0`: no
    /// memo.
    #[serde(default)]
    pub row_memo_capacity: usize,
}

impl Default for MultiLevelSpec {
    /// The paper's scenario 1 (Table 1): gap prior `U(81, 105)` in, 6 + 6 Legendre terms;
    /// no memo.
    fn default() -> Self {
        Self {
            gap_prior_in: (81.0, 105.0),
            discrepancy_terms: [6, 6],
            memo_capacity: 0,
            row_memo_capacity: 0,
        }
    }
}

impl MultiLevelSpec {
    /// Sets the gap prior bounds (in).
    ///
    /// ```
    /// let s = mitergate::MultiLevelSpec::default().with_gap_prior((60.0, 150.0));
    /// assert_eq!(s.gap_prior_in, (60.0, 150.0));
    /// ```
    pub fn with_gap_prior(mut self, bounds_in: (f64, f64)) -> Self {
        self.gap_prior_in = bounds_in;
        self
    }

    /// Sets the discrepancy terms `[normal, tangential]`.
    ///
    /// ```
    /// let s = mitergate::MultiLevelSpec::default().with_discrepancy_terms([4, 2]);
    /// assert_eq!(s.discrepancy_terms, [4, 2]);
    /// ```
    pub fn with_discrepancy_terms(mut self, terms: [usize; 2]) -> Self {
        self.discrepancy_terms = terms;
        self
    }

    /// Sets the memo capacity (`0`: no memo).
    ///
    /// ```
    /// let s = mitergate::MultiLevelSpec::default().with_memo_capacity(400_000);
    /// assert_eq!(s.memo_capacity, 400_000);
    /// ```
    pub fn with_memo_capacity(mut self, capacity: usize) -> Self {
        self.memo_capacity = capacity;
        self
    }

    /// Sets the model-row memo capacity (`0`: no memo).
    ///
    /// ```
    /// let s = mitergate::MultiLevelSpec::default().with_row_memo_capacity(1_000_000);
    /// assert_eq!(s.row_memo_capacity, 1_000_000);
    /// ```
    pub fn with_row_memo_capacity(mut self, capacity: usize) -> Self {
        self.row_memo_capacity = capacity;
        self
    }

    /// Checks the fields that do not depend on the gate, naming the first invalid one
    /// ([`GateError::InvalidMultiLevelSpec`]).
    ///
    /// ```
    /// use mitergate::MultiLevelSpec;
    /// let err = MultiLevelSpec::default().with_gap_prior((105.0, 81.0)).validate().unwrap_err();
    /// assert!(err.to_string().contains("gap_prior_in"));
    /// ```
    pub fn validate(&self) -> Result<(), GateError> {
        let (lo, hi) = self.gap_prior_in;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi) {
            return Err(GateError::InvalidMultiLevelSpec {
                field: "gap_prior_in",
                reason: format!("need finite 0 <= lo < hi (in), got ({lo}, {hi})"),
            });
        }
        if self.discrepancy_terms.contains(&0) {
            return Err(GateError::InvalidMultiLevelSpec {
                field: "discrepancy_terms",
                reason: format!(
                    "each component needs at least one term, got {:?}",
                    self.discrepancy_terms
                ),
            });
        }
        Ok(())
    }
}

/// Size of a built gate, for reports.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GateSummary {
    /// Degrees of freedom of the FE model (6 per node).
    pub n_dofs: usize,
    /// FE quoin nodes `m`.
    pub n_quoin_nodes: usize,
    /// Target element size (in).
    pub element_size: f64,
}

/// Module 1 for a gate description: builds the FE leaf ([`GateModel::build`]), condenses it
/// to [`DEFAULT_NU`] representation points and wraps it in the contact model with the
/// paper's parameters ([`ContactParams::default`]). The FE model is dropped afterwards; the
/// summary keeps its size. Nothing is timed here: callers that report the time measure it.
///
/// ```
/// let mut cfg = mitergate::GateConfig::default();
/// cfg.mesh.element_size = 96.0;
/// let (contact, summary) = mitergate::build_contact(&cfg).unwrap();
/// assert_eq!(contact.gate().n_points(), mitergate::DEFAULT_NU);
/// assert_eq!((summary.n_quoin_nodes, summary.element_size), (contact.gate().n_quoin_nodes(), 96.0));
/// ```
pub fn build_contact(cfg: &GateConfig) -> Result<(ContactModel, GateSummary), GateError> {
    let model = GateModel::build(cfg)?;
    let condensed = model.condense(DEFAULT_NU)?;
    let summary = GateSummary {
        n_dofs: model.n_dofs(),
        n_quoin_nodes: condensed.n_quoin_nodes(),
        element_size: cfg.mesh.element_size,
    };
    let contact = ContactParams::default().build(condensed)?;
    log::debug!(
        "gate built: {} dofs, {} quoin nodes, element size {} in",
        summary.n_dofs,
        summary.n_quoin_nodes,
        summary.element_size
    );
    Ok((contact, summary))
}

/// The gate's multi-level model of `contact` and `spec`: [`ContactForceModel`] memoised with
/// `spec.memo_capacity` (and its model rows with `spec.row_memo_capacity`), [`StrainModel`],
/// the uniform gap prior `spec.gap_prior_in` and a Legendre discrepancy basis on `[0, H]` at
/// the gate's representation points.
///
/// The discrepancy terms are capped at the number of representation points `N_u`
/// (`spec.discrepancy_terms[c].min(N_u)`): a basis cannot have more independent polynomials
/// than points (the paper's 6 + 6 on 509 points are unchanged; a tiny test gate gets fewer).
/// Errors: an invalid `spec` or a prior reaching the quoin height
/// ([`GateError::InvalidMultiLevelSpec`] naming the field).
///
/// ```
/// use mitergate::{ContactParams, MultiLevelSpec, multilevel, testing::doc_gate};
/// use mlmodel::UnobservableModel;
/// let contact = ContactParams::default().build(doc_gate()).unwrap();
/// let spec = MultiLevelSpec::default().with_discrepancy_terms([3, 2]);
/// let m = multilevel(contact, &spec).unwrap();
/// assert_eq!((m.basis.terms(), m.unobservable.response_len()), (&[3, 2][..], 10));
/// assert_eq!(m.prior.bounds(), vec![(81.0, 105.0)]);
/// ```
pub fn multilevel(
    contact: ContactModel,
    spec: &MultiLevelSpec,
) -> Result<GateMultiLevel, GateError> {
    spec.validate()?;
    let gate = contact.gate();
    let (_, hi) = spec.gap_prior_in;
    if !(hi < gate.quoin_height) {
        return Err(GateError::InvalidMultiLevelSpec {
            field: "gap_prior_in",
            reason: format!(
                "the upper bound {hi} in must lie below the quoin height {} in",
                gate.quoin_height
            ),
        });
    }
    let n_points = gate.n_points();
    let terms = spec.discrepancy_terms.map(|k| k.min(n_points));
    if terms != spec.discrepancy_terms {
        log::debug!(
            "discrepancy terms {:?} capped at {n_points} representation points: {terms:?}",
            spec.discrepancy_terms
        );
    }
    let basis = DiscrepancyBasis::new(
        Family::Legendre,
        (0.0, gate.quoin_height),
        &gate.nu_points,
        &terms,
    )?;
    let strain = StrainModel::new(gate);
    let prior = UniformPrior::new(vec![spec.gap_prior_in])?;
    let forces = Memo::new(ContactForceModel::new(contact), spec.memo_capacity);
    Ok(
        MultiLevelModel::new(forces, strain, Box::new(prior), basis)?
            .with_row_memo(spec.row_memo_capacity),
    )
}
