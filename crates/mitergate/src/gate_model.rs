//! The miter gate as an `mlmodel` multi-level model (Sec. 4.1-4.2, Fig. 11).
//!
//! * [`ContactForceModel`] implements [`UnobservableModel`]: `g_BC(x, θ)`, inputs
//!   `x = [h_up, h_down]` (in), one parameter `θ` = bottom gap length (in), two components
//!   (normal, tangential line load, lbf/in) at the `N_u` representation points.
//! * [`StrainModel`] implements [`ObservableModel`] and [`LinearObservableModel`]: Eq. 47,
//!   strain (microstrain) `= A y_u + s_w(h_up, h_down)`.
//!
//! Both validate their inputs: levels in `[24, 744]` in, `h_up ≥ h_down`, `θ ∈ [0, H)`; a
//! violation is an [`ModelError::OutOfDomain`] naming the input.

use crate::condensed::{CondensedGate, HydrostaticTable};
use crate::contact::ContactModel;
use crate::truth::LEVEL_RANGE;
use mlmodel::{LinearObservableModel, ModelError, ObservableModel, UnobservableModel, check_len};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Checks `x = [h_up, h_down]` (in) and `θ = [gap]` (in) against the gate's domain.
///
/// ```
/// use mitergate::gate_model::check_domain;
/// assert!(check_domain(&[500.0, 100.0], &[90.0], 762.0).is_ok());
/// assert!(check_domain(&[100.0, 500.0], &[90.0], 762.0).is_err()); // h_up < h_down
/// assert!(check_domain(&[500.0, 100.0], &[762.0], 762.0).is_err());
/// ```
pub fn check_domain(x: &[f64], theta: &[f64], quoin_height: f64) -> mlmodel::Result<()> {
    check_len("x", x, 2)?;
    check_len("theta", theta, 1)?;
    let (lo, hi) = LEVEL_RANGE;
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

/// `g_BC(x, θ)` as an [`UnobservableModel`].
///
/// ```
/// use mitergate::gate_model::ContactForceModel;
/// use mlmodel::UnobservableModel;
/// let model = mitergate::contact::ContactParams::default()
///     .build(mitergate::contact::doc_gate()).unwrap();
/// let g = ContactForceModel::new(model);
/// let mut out = vec![0.0; g.response_len()];
/// g.evaluate(&[700.0, 100.0], &[90.0], &mut out).unwrap();
/// assert_eq!(out[0], 0.0); // in the gap
/// assert!(g.evaluate(&[800.0, 100.0], &[90.0], &mut out).is_err());
/// ```
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ContactForceModel {
    contact: ContactModel,
}

impl ContactForceModel {
    /// Wraps a contact model.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
    /// let g = mitergate::gate_model::ContactForceModel::new(model);
    /// assert_eq!(g.contact().gate().n_points(), 5);
    /// ```
    pub fn new(contact: ContactModel) -> Self {
        Self { contact }
    }
    /// The wrapped contact model.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
    /// # let g = mitergate::gate_model::ContactForceModel::new(model);
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
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        check_domain(x, theta, self.contact.gate().quoin_height)?;
        check_len("out", out, self.response_len())?;
        self.contact
            .forces_into(x[0], x[1], theta[0], out)
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
/// use mitergate::gate_model::StrainModel;
/// use mlmodel::{LinearObservableModel, ObservableModel};
/// let gate = mitergate::contact::doc_gate();
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
    /// let s = mitergate::gate_model::StrainModel::new(&mitergate::contact::doc_gate());
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
