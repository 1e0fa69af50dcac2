//! [`ContactParams`], [`ContactModel`] and [`ContactSolution`]: the contact model's set-up,
//! its inputs and outputs, and the forces API (`g_BC`). The iteration that solves it lives in
//! `super::solver`; the formulation is in the [module docs](super).

use crate::condense::CondensedGate;
use crate::error::GateError;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Validated hyper-parameters of the contact model, with chained setters.
///
/// ```
/// use mitergate::contact::ContactParams;
/// let p = ContactParams::default().normal_stiffness(2e6).tangential_coefficient(1e5);
/// assert_eq!(p.k_normal(), 2e6);
/// assert!(p.validate().is_ok());
/// assert!(ContactParams::default().normal_stiffness(-1.0).validate().is_err());
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    pub(super) k_normal: f64,
    pub(super) k_tangential: f64,
    pub(super) tolerance: f64,
    pub(super) max_iterations: usize,
}

impl Default for ContactParams {
    /// The paper's values `k_N = 1e6` psi and `k_T = 1e6` /in (Sec. 4.1), relative tolerance
    /// `1e-8` for the tangential law (relative to `max|F|`): the law is very stiff (`k_T F_N` is
    /// about 1e10 lbf/in² where the contact is loaded), and its residual can stall at a
    /// round-off floor near 5e-10 (seen at h_up = 542, h_down = 188, θ = 120 in on a 24 in
    /// mesh), so 1e-10 was not always reachable; at most 1000 iterations (linear solves): the
    /// typical solve needs 8-9 and the hardest input found (a contact edge creeping up the
    /// quoin, module docs) 322.
    fn default() -> Self {
        Self {
            k_normal: 1e6,
            k_tangential: 1e6,
            tolerance: 1e-8,
            max_iterations: 1000,
        }
    }
}

impl ContactParams {
    /// Sets the normal stiffness `k_N` (psi = lbf/in per inch of penetration), `> 0`.
    ///
    /// ```
    /// let p = mitergate::contact::ContactParams::default().normal_stiffness(5e5);
    /// assert_eq!(p.k_normal(), 5e5);
    /// ```
    pub fn normal_stiffness(mut self, k_normal: f64) -> Self {
        self.k_normal = k_normal;
        self
    }
    /// Sets the tangential coefficient `k_T` (1/in), `≥ 0` (`0` = frictionless).
    ///
    /// ```
    /// let p = mitergate::contact::ContactParams::default().tangential_coefficient(0.0);
    /// assert_eq!(p.k_tangential(), 0.0);
    /// ```
    pub fn tangential_coefficient(mut self, k_tangential: f64) -> Self {
        self.k_tangential = k_tangential;
        self
    }
    /// Sets the relative tolerance of the tangential fixed point, in `(0, 1e-3]`.
    ///
    /// ```
    /// let p = mitergate::contact::ContactParams::default().tolerance(1e-8);
    /// assert_eq!(p.tol(), 1e-8);
    /// ```
    pub fn tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = tolerance;
        self
    }
    /// Sets the cap on iterations (linear solves) of the contact solve, `≥ 1`. The cap holds
    /// per attempt: a cold solve that reaches it is restarted from neighbouring gaps ("Recovery"
    /// in the [module docs](super)), each restart with the same cap, so a failing evaluation
    /// costs at most nine capped attempts.
    ///
    /// ```
    /// let p = mitergate::contact::ContactParams::default().max_iterations(0);
    /// assert!(p.validate().is_err());
    /// ```
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.max_iterations = n;
        self
    }
    /// Normal stiffness `k_N` (psi).
    ///
    /// ```
    /// assert_eq!(mitergate::contact::ContactParams::default().k_normal(), 1e6);
    /// ```
    pub fn k_normal(&self) -> f64 {
        self.k_normal
    }
    /// Tangential coefficient `k_T` (1/in).
    ///
    /// ```
    /// assert_eq!(mitergate::contact::ContactParams::default().k_tangential(), 1e6);
    /// ```
    pub fn k_tangential(&self) -> f64 {
        self.k_tangential
    }
    /// Relative tolerance of the tangential fixed point.
    ///
    /// ```
    /// assert_eq!(mitergate::contact::ContactParams::default().tol(), 1e-8);
    /// ```
    pub fn tol(&self) -> f64 {
        self.tolerance
    }

    /// Checks every parameter, naming the first invalid one.
    ///
    /// ```
    /// use mitergate::contact::ContactParams;
    /// assert!(ContactParams::default().tolerance(0.0).validate().is_err());
    /// ```
    pub fn validate(&self) -> Result<(), GateError> {
        let bad = |name: &'static str, value: f64, reason: &str| {
            Err(GateError::InvalidContactParameter {
                name,
                value,
                reason: reason.to_string(),
            })
        };
        if !(self.k_normal.is_finite() && self.k_normal > 0.0) {
            return bad("k_normal", self.k_normal, "must be finite and > 0 (psi)");
        }
        if !(self.k_tangential.is_finite() && self.k_tangential >= 0.0) {
            return bad(
                "k_tangential",
                self.k_tangential,
                "must be finite and >= 0 (1/in)",
            );
        }
        if !(self.tolerance > 0.0 && self.tolerance <= 1e-3) {
            return bad("tolerance", self.tolerance, "must lie in (0, 1e-3]");
        }
        if self.max_iterations == 0 {
            return bad("max_iterations", 0.0, "must be >= 1");
        }
        Ok(())
    }

    /// Validates the parameters and precomputes the contact model for `gate` (the "fit").
    ///
    /// ```
    /// # use mitergate::contact::ContactParams;
    /// # let gate = mitergate::testing::doc_gate();
    /// let model = ContactParams::default().build(gate).unwrap();
    /// assert_eq!(model.gate().n_points(), 5);
    /// ```
    pub fn build(self, gate: CondensedGate) -> Result<ContactModel, GateError> {
        ContactModel::new(gate, self)
    }
}

/// Column `b` of the load transfer `T`, kept sparse: `(node, T_ib)` for the nonzero entries.
pub(super) type SparseColumn = Vec<(usize, f64)>;

/// The quoin contact model `g_BC(x, θ)`, precomputed for one [`CondensedGate`].
/// See the module docs for the formulation.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ContactModel {
    pub(super) gate: CondensedGate,
    pub(super) params: ContactParams,
    /// `K = C⁻¹` (lbf/in), `2m x 2m`.
    pub(super) stiffness: DMatrix<f64>,
    /// Tributary lengths `w_b = Σ_i T_ib` (in).
    pub(super) weights: Vec<f64>,
    /// Lengths (in) of the lower cells `[d_{b-1}, d_b]` (the first point uses the first spacing).
    pub(super) lower_cells: Vec<f64>,
    /// Sparse columns of `T`.
    pub(super) columns: Vec<SparseColumn>,
}

/// Result of one contact solve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactSolution {
    /// Contact line loads (lbf/in) at the representation points, blocked `[F_N; F_T]`.
    pub forces: Vec<f64>,
    /// Quoin-node displacements (in), blocked `[normal; tangential]`, `u = C T q + u_w`.
    pub node_displacement: Vec<f64>,
    /// Number of points in normal contact.
    pub n_active: usize,
    /// Iterations (linear solves of size `2m`) used.
    pub iterations: usize,
    /// Final relative residual of the tangential law `max|F_T + k_T F_N ū_T| / max|F|`.
    pub tangential_residual: f64,
}

impl ContactSolution {
    /// Normal line loads `F_N` (lbf/in), one per representation point.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let sol = model.solve(600.0, 100.0, 0.0).unwrap();
    /// assert!(sol.normal().iter().all(|&f| f >= 0.0));
    /// ```
    pub fn normal(&self) -> &[f64] {
        &self.forces[..self.forces.len() / 2]
    }
    /// Tangential line loads `F_T` (lbf/in), one per representation point.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let sol = model.solve(600.0, 100.0, 0.0).unwrap();
    /// assert_eq!(sol.tangential().len(), 5);
    /// ```
    pub fn tangential(&self) -> &[f64] {
        &self.forces[self.forces.len() / 2..]
    }
}

impl ContactModel {
    /// Validates `gate` and `params` and precomputes `K = C⁻¹`, tributary lengths and the
    /// sparse load transfer. Errors name the offending field.
    ///
    /// ```
    /// use mitergate::contact::{ContactModel, ContactParams};
    /// let model = ContactModel::new(mitergate::testing::doc_gate(), ContactParams::default());
    /// assert!(model.is_ok());
    /// ```
    pub fn new(gate: CondensedGate, params: ContactParams) -> Result<Self, GateError> {
        params.validate()?;
        validate_gate(&gate)?;
        let stiffness = invert_spd(&gate.quoin_flexibility)?;
        let columns = sparse_columns(&gate.load_transfer);
        let weights: Vec<f64> = columns
            .iter()
            .map(|c| c.iter().map(|&(_, t)| t).sum())
            .collect();
        if let Some(b) = weights.iter().position(|&w| w.is_nan() || w <= 0.0) {
            return Err(GateError::InvalidCondensedGate(format!(
                "load_transfer column {b} (point at {} in) sums to {}; tributary lengths must be > 0",
                gate.nu_points[b], weights[b]
            )));
        }
        let d = &gate.nu_points;
        let lower_cells = (0..d.len())
            .map(|b| if b == 0 { d[1] - d[0] } else { d[b] - d[b - 1] })
            .collect();
        Ok(Self {
            gate,
            params,
            stiffness,
            weights,
            lower_cells,
            columns,
        })
    }

    /// The condensed gate the model was built on.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// assert_eq!(model.gate().quoin_height, 762.0);
    /// ```
    pub fn gate(&self) -> &CondensedGate {
        &self.gate
    }

    /// The contact parameters.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// assert_eq!(model.params().k_normal(), 1e6);
    /// ```
    pub fn params(&self) -> &ContactParams {
        &self.params
    }

    /// Tributary lengths `w_b = ∫ φ_b dz` (in) of the representation points.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let total: f64 = model.tributary_lengths().iter().sum();
    /// assert!((total - 762.0).abs() < 1e-9); // the hats partition the quoin
    /// ```
    pub fn tributary_lengths(&self) -> &[f64] {
        &self.weights
    }

    /// Contact coverage `c_b(θ) ∈ [0, 1]` of each point for gap length `theta` (in): the
    /// fraction of the point's lower cell `[d_{b-1}, d_b]` lying above the gap.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// // points at 0, 190.5, 381, 571.5, 762 in
    /// let c = model.coverage(95.25);
    /// assert_eq!(c, vec![0.0, 0.5, 1.0, 1.0, 1.0]);
    /// ```
    pub fn coverage(&self, theta: f64) -> Vec<f64> {
        self.gate
            .nu_points
            .iter()
            .zip(&self.lower_cells)
            .map(|(&d, &l)| ((d - theta) / l).clamp(0.0, 1.0))
            .collect()
    }

    /// Nodal quoin forces `P = [T q_N; T q_T]` (lbf) of line loads `q` (lbf/in, `2 N_u`).
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let q = vec![1.0; 10]; // 1 lbf/in normal and tangential everywhere
    /// let p = model.nodal_forces(&q);
    /// let total: f64 = p[..3].iter().sum();
    /// assert!((total - 762.0).abs() < 1e-9);
    /// ```
    pub fn nodal_forces(&self, q: &[f64]) -> Vec<f64> {
        let m = self.gate.n_quoin_nodes();
        let n = self.gate.n_points();
        let mut p = vec![0.0; 2 * m];
        for (b, col) in self.columns.iter().enumerate() {
            for &(i, t) in col {
                p[i] += t * q[b];
                p[m + i] += t * q[n + b];
            }
        }
        p
    }

    /// Conjugate point displacements `ū = [Tᵀu_N / w; Tᵀu_T / w]` (in) of quoin-node
    /// displacements `u` (in, `2m`).
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let u = vec![0.5, 0.5, 0.5, -1.0, -1.0, -1.0]; // uniform translation
    /// let ubar = model.point_displacements(&u);
    /// assert!(ubar[..5].iter().all(|v| (v - 0.5).abs() < 1e-12));
    /// assert!(ubar[5..].iter().all(|v| (v + 1.0).abs() < 1e-12));
    /// ```
    pub fn point_displacements(&self, u: &[f64]) -> Vec<f64> {
        let m = self.gate.n_quoin_nodes();
        let n = self.gate.n_points();
        let mut ubar = vec![0.0; 2 * n];
        for (b, col) in self.columns.iter().enumerate() {
            let (mut un, mut ut) = (0.0, 0.0);
            for &(i, t) in col {
                un += t * u[i];
                ut += t * u[m + i];
            }
            ubar[b] = un / self.weights[b];
            ubar[n + b] = ut / self.weights[b];
        }
        ubar
    }

    /// Nodal quoin reactions (lbf, `2m`, blocked) of a rigid, fully bonded quoin
    /// (`u = 0` at every quoin node): `P = -K u_w(h_up, h_down)`. The contact solution tends to
    /// this as `k_N → ∞` when `θ = 0` and the bonded quoin is in compression everywhere.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let p = model.rigid_quoin_reactions(600.0, 100.0);
    /// assert!(p[..3].iter().sum::<f64>() > 0.0); // the wall pushes the gate along +n
    /// ```
    pub fn rigid_quoin_reactions(&self, h_up: f64, h_down: f64) -> Vec<f64> {
        let uw = self.gate.water_quoin_displacement.eval_levels(h_up, h_down);
        (-(&self.stiffness * uw)).as_slice().to_vec()
    }

    /// Contact line loads `g_BC(x, θ)` (lbf/in, `2 N_u`, blocked `[F_N; F_T]`) for water levels
    /// `h_up`, `h_down` (in) and gap length `theta` (in), written into `out`.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let mut f = vec![0.0; 10];
    /// model.forces_into(700.0, 50.0, 100.0, &mut f).unwrap();
    /// assert_eq!(f[0], 0.0); // below the gap
    /// assert!(f[2] > 0.0);
    /// ```
    pub fn forces_into(
        &self,
        h_up: f64,
        h_down: f64,
        theta: f64,
        out: &mut [f64],
    ) -> Result<(), GateError> {
        let expected = 2 * self.gate.n_points();
        if out.len() != expected {
            return Err(GateError::ContactDimension {
                what: "out",
                expected,
                got: out.len(),
            });
        }
        let sol = self.solve(h_up, h_down, theta)?;
        out.copy_from_slice(&sol.forces);
        Ok(())
    }

    /// Solves the contact problem for water levels `h_up`, `h_down` (in, finite) and gap length
    /// `theta ∈ [0, H)` (in). See the module docs for the method.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let sol = model.solve(700.0, 50.0, 100.0).unwrap();
    /// assert!(sol.n_active >= 1 && sol.tangential_residual < 1e-9);
    /// assert!(model.solve(700.0, 50.0, 800.0).is_err()); // gap longer than the quoin
    /// ```
    pub fn solve(&self, h_up: f64, h_down: f64, theta: f64) -> Result<ContactSolution, GateError> {
        self.check_inputs(h_up, h_down, theta)?;
        self.solve_cold(h_up, h_down, theta)
            .or_else(|e| self.recover_from_neighbours(h_up, h_down, theta, e))
    }

    /// Solves like [`ContactModel::solve`], starting from a previous solution (e.g. at a
    /// neighbouring `θ` or water level) instead of the rigid-quoin guess: its contact zone
    /// and normal forces give the first active set and tangential springs. The result meets
    /// the same convergence test, so it agrees with [`ContactModel::solve`] to the solver
    /// tolerance (not bit for bit); it usually needs fewer iterations along a sweep.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::testing::doc_gate()).unwrap();
    /// let cold = model.solve(700.0, 50.0, 100.0).unwrap();
    /// let warm = model.solve_from(700.0, 50.0, 101.0, &cold).unwrap();
    /// assert!(warm.iterations <= model.solve(700.0, 50.0, 101.0).unwrap().iterations);
    /// assert!(model.solve_from(700.0, 50.0, 101.0, &cold).is_ok());
    /// ```
    pub fn solve_from(
        &self,
        h_up: f64,
        h_down: f64,
        theta: f64,
        previous: &ContactSolution,
    ) -> Result<ContactSolution, GateError> {
        self.check_inputs(h_up, h_down, theta)?;
        let n = self.gate.n_points();
        if previous.forces.len() != 2 * n {
            return Err(GateError::ContactDimension {
                what: "previous.forces",
                expected: 2 * n,
                got: previous.forces.len(),
            });
        }
        self.solve_warm(h_up, h_down, theta, &previous.forces)
    }

    /// Rejects non-finite levels and gap lengths outside `[0, H)`.
    fn check_inputs(&self, h_up: f64, h_down: f64, theta: f64) -> Result<(), GateError> {
        let height = self.gate.quoin_height;
        for (name, v) in [("h_up", h_up), ("h_down", h_down)] {
            if !v.is_finite() {
                return Err(GateError::ContactDomain {
                    name,
                    value: v,
                    lo: f64::NEG_INFINITY,
                    hi: f64::INFINITY,
                });
            }
        }
        if !(theta >= 0.0 && theta < height) {
            return Err(GateError::ContactDomain {
                name: "theta",
                value: theta,
                lo: 0.0,
                hi: height,
            });
        }
        Ok(())
    }
}

/// Checks the shapes and orderings the contact model relies on.
fn validate_gate(g: &CondensedGate) -> Result<(), GateError> {
    let m = g.n_quoin_nodes();
    let n = g.n_points();
    let bad = |s: String| Err(GateError::InvalidCondensedGate(s));
    if !(g.quoin_height.is_finite() && g.quoin_height > 0.0) {
        return bad(format!("quoin_height = {} must be > 0", g.quoin_height));
    }
    if m < 2 || n < 2 {
        return bad(format!(
            "need >= 2 quoin nodes and >= 2 nu_points (got {m} and {n})"
        ));
    }
    if g.quoin_flexibility.shape() != (2 * m, 2 * m) {
        return bad(format!(
            "quoin_flexibility is {:?}, expected ({}, {})",
            g.quoin_flexibility.shape(),
            2 * m,
            2 * m
        ));
    }
    if g.load_transfer.shape() != (m, n) {
        return bad(format!(
            "load_transfer is {:?}, expected ({m}, {n})",
            g.load_transfer.shape()
        ));
    }
    if g.water_quoin_displacement.n_responses() != 2 * m {
        return bad(format!(
            "water_quoin_displacement has {} responses, expected {}",
            g.water_quoin_displacement.n_responses(),
            2 * m
        ));
    }
    let d = &g.nu_points;
    let ordered = d.windows(2).all(|w| w[0] < w[1]);
    if !ordered || d[0] < 0.0 || d[n - 1] > g.quoin_height {
        return bad(format!(
            "nu_points must increase strictly within [0, {}]",
            g.quoin_height
        ));
    }
    let c = &g.quoin_flexibility;
    let scale = c.amax();
    let asym = (c - c.transpose()).amax();
    if !(scale.is_finite() && asym <= 1e-9 * scale) {
        return bad(format!(
            "quoin_flexibility must be finite and symmetric (max |C - Cᵀ| = {asym:e}, max |C| = {scale:e})"
        ));
    }
    Ok(())
}

/// `C⁻¹` of a symmetric positive definite `C`, symmetrised.
fn invert_spd(c: &DMatrix<f64>) -> Result<DMatrix<f64>, GateError> {
    let chol = c
        .clone()
        .cholesky()
        .ok_or(GateError::ContactNotPositiveDefinite {
            what: "quoin_flexibility C",
        })?;
    let k = chol.inverse();
    Ok((&k + k.transpose()) * 0.5)
}

/// Nonzero entries of each column of `T`.
fn sparse_columns(t: &DMatrix<f64>) -> Vec<SparseColumn> {
    (0..t.ncols())
        .map(|b| {
            (0..t.nrows())
                .filter(|&i| t[(i, b)] != 0.0)
                .map(|i| (i, t[(i, b)]))
                .collect()
        })
        .collect()
}
