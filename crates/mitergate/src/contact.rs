//! Quoin contact model `g_BC(x, θ)` with a bottom gap (paper Sec. 4.1, Eq. 45-46).
//!
//! The gate's quoin post bears on a rigid wall quoin block through linear contact springs.
//! Below the gap length `θ` (inches above the sill) there is no contact. Given the water levels
//! `x = (h_up, h_down)` (in) and `θ`, [`ContactModel::solve`] returns the normal and tangential
//! contact line loads `F_N`, `F_T` (lbf/in) at the `N_u` representation points of the
//! [`CondensedGate`], component blocked `[F_N; F_T]` (the layout of `mlmodel`; the paper's
//! Eq. 46 interleaves them, see `mlmodel::interleaved_index`).
//!
//! # Contact laws and units
//!
//! * **Normal** (Sec. 4.1, "force proportional to penetration"): `F_N = k_N max(0, p)` with `p`
//!   (in) the penetration of the gate into the wall and `k_N` (lbf/in per inch of penetration,
//!   i.e. lbf/in², psi) the normal stiffness per unit quoin length; default `k_N = 1e6` psi.
//!   No tension: `F_N ≥ 0`, and `F_N > 0` only where `p > 0` (complementarity).
//! * **Tangential** ("proportional to the product of the normal force and the tangential
//!   displacement"): `F_T = -k_T F_N u_T` with `u_T` (in) the tangential displacement of the
//!   gate and `k_T` in 1/in; default `k_T = 1e6` /in. The minus sign makes the force resist
//!   the motion. The law is a spring of stiffness `κ = k_T F_N` (psi) per unit length. With
//!   `k_T = 1e6`, a point carrying only `F_N = 1` lbf/in already has `κ = 1e6` psi (as stiff as the
//!   normal spring) and at the `F_N ~ 1e4` lbf/in that a loaded gate carries `κ ~ 1e10` psi: a
//!   tangential force of 100 lbf/in then lets the gate slide `100 / 1e10 = 1e-8` in. The
//!   tangential restraint is therefore effectively rigid wherever `F_N` is non-negligible, and
//!   vanishes smoothly where the contact opens. (The crate's tests check this by comparing the
//!   contact slip with the free tangential displacement.)
//!
//! # Discretisation
//!
//! Write `φ_b` for the hat function of representation point `d_b` and `N_i` for the linear
//! shape function of FE quoin node `i`. The contract of [`CondensedGate`] gives
//! `T_ib = ∫ N_i φ_b dz` (in): nodal force (lbf) per unit line load (lbf/in) at point `b`.
//!
//! * Line loads `q = [q_N; q_T]` (lbf/in) at the points give nodal forces `P = [T q_N; T q_T]`
//!   (lbf), and quoin-node displacements `u = C P + u_w(x)` (in).
//! * The displacement seen by the contact spring at point `b` is the work-conjugate average
//!   `ū_b = (Tᵀu)_b / w_b` with `w_b = Σ_i T_ib = ∫ φ_b dz` the tributary length (in). Where the
//!   FE displacement is linear across the hat of `φ_b` (everywhere except within one point
//!   spacing of an FE node) this equals the linearly interpolated displacement at `d_b`.
//!   Choosing the conjugate average makes the discrete problem symmetric (it is the stationarity
//!   condition of a convex energy, below).
//! * The penetration is `p_b = -ū_N,b` (the normal `n` points from the wall into the gate).
//! * Gap: point `b` carries the spring of its *lower cell* `[d_{b-1}, d_b]`; the fraction of that
//!   cell above `θ` is its coverage `c_b(θ) = clamp((d_b - θ) / (d_b - d_{b-1}), 0, 1)`. The
//!   spring stiffness of point `b` is `s_b = k_N c_b`, so `F_N = 0` exactly at every point with
//!   `d_b ≤ θ`, and all forces are continuous in `θ` (a point switches on gradually as the gap
//!   edge moves below it). The contact zone so represented starts, in the sense of the lumped
//!   spring length `Σ c_b w_b`, half a point spacing above `θ` (0.75 in for 509 points over
//!   762 in); this shift is common to the model and to all data generated with it.
//!
//! # Solution method
//!
//! For a fixed tangential stiffness `κ_b` the contact problem is the minimisation of the
//! strictly convex, piecewise quadratic energy (in the `2m` quoin-node displacements)
//!
//! `E(u) = ½ uᵀK u - uᵀK u_w + ½ Σ_b s_b w_b max(0, -ū_N,b)² + ½ Σ_b κ_b w_b ū_T,b²`
//!
//! with `K = C⁻¹` (computed once). Its stationarity condition is exactly `u = C T q + u_w` with
//! the contact laws above. This is the reduced, `2m`-sized form of the `2N_u`-sized linear
//! complementarity problem `q_N ≥ 0, w ⊙ (q_N / s - p) ≥ 0, q_Nᵀ(...) = 0`, whose matrix
//! `diag(w/s) + TᵀC T` is a diagonal plus a rank `≤ 2m` term: eliminating `q` through the
//! Woodbury identity gives the `2m x 2m` matrix `K + G(𝒜)` below.
//! It is solved by a primal-dual active-set (semismooth Newton) iteration, merged with a
//! fixed-point iteration on the bilinear tangential law (`κ_b = k_T F_N,b`):
//!
//! 1. Start from the stiff-contact limit: the rigid-quoin reaction `-K u_w`, spread to the
//!    points, gives the first active set `𝒜` (points with a spring and a compressive rigid
//!    reaction) and the first tangential springs `κ_b`.
//! 2. Solve `(K + G) u⁺ = K u_w` with `G = Σ_{b∈𝒜} (s_b/w_b) t_b t_bᵀ` (normal block)
//!    `+ Σ_b (κ_b/w_b) t_b t_bᵀ` (tangential block), `t_b` column `b` of `T` (2-3 nonzeros, so
//!    `G` is banded and cheap). `K + G` is symmetric positive definite and is factorised by
//!    Cholesky (`(2m)³/3` flops).
//! 3. Converged when the active set of `u⁺` equals `𝒜` (up to points whose penetration is
//!    zero to rounding), so that `u⁺` solves the piecewise linear problem exactly, **and** the
//!    tangential law `F_T = -k_T F_N ū_T` holds with the new `F_N` to the relative tolerance
//!    (default `1e-8` of `max|F|`; see [`ContactParams`] for why not tighter).
//! 4. Otherwise move towards `u⁺` (if the active set changed, halving the step until the
//!    energy decreases; this globalises the Newton iteration, and the full step is nearly always
//!    taken), take `𝒜` from the new `u`, set `κ_b = k_T F_N,b`, and repeat.
//!
//! The tangential update contracts fast (the restraint is nearly rigid, so the solution depends
//! weakly on `κ`: the law residual drops ~40x per iteration in the tests); most iterations go to
//! moving the edge of the contact zone. The fixture needs 5-16 iterations, 9 on average.
//! An iteration cap (default 100) returns [`GateError::ContactNotConverged`] naming the unmet
//! criterion, never a silent result.
//!
//! No FE re-factorisation happens per evaluation: one evaluation costs a handful of Cholesky
//! factorisations of size `2m` plus `O(N_u)` work.

use crate::GateError;
use crate::condensed::CondensedGate;
use nalgebra::{DMatrix, DVector};
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
    k_normal: f64,
    k_tangential: f64,
    tolerance: f64,
    max_iterations: usize,
}

impl Default for ContactParams {
    /// The paper's values `k_N = 1e6` psi and `k_T = 1e6` /in (Sec. 4.1), relative tolerance
    /// `1e-8` for the tangential law (relative to `max|F|`): the law is very stiff (`k_T F_N` is
    /// about 1e10 lbf/in² where the contact is loaded), and its residual can stall at a
    /// round-off floor near 5e-10 (seen at h_up = 542, h_down = 188, θ = 120 in on a 24 in
    /// mesh), so 1e-10 was not always reachable; at most 500 iterations (linear solves). The tangential
    /// law is iterated as a fixed point (springs `k_T F_N` from the previous iterate), which
    /// converges linearly: about 9 iterations on average over the paper's domain on the default
    /// gate, but up to ~170 near the top of a shrinking contact zone (e.g. h_up = 550,
    /// h_down = 318, θ = 164 in on a 24 in mesh), hence the generous cap.
    fn default() -> Self {
        Self {
            k_normal: 1e6,
            k_tangential: 1e6,
            tolerance: 1e-8,
            max_iterations: 500,
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
    /// Sets the cap on iterations (linear solves) of the contact solve, `≥ 1`.
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
    /// # let gate = mitergate::contact::doc_gate();
    /// let model = ContactParams::default().build(gate).unwrap();
    /// assert_eq!(model.gate().n_points(), 5);
    /// ```
    pub fn build(self, gate: CondensedGate) -> Result<ContactModel, GateError> {
        ContactModel::new(gate, self)
    }
}

/// Column `b` of the load transfer `T`, kept sparse: `(node, T_ib)` for the nonzero entries.
type SparseColumn = Vec<(usize, f64)>;

/// The quoin contact model `g_BC(x, θ)`, precomputed for one [`CondensedGate`].
/// See the module docs for the formulation.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ContactModel {
    gate: CondensedGate,
    params: ContactParams,
    /// `K = C⁻¹` (lbf/in), `2m x 2m`.
    stiffness: DMatrix<f64>,
    /// Tributary lengths `w_b = Σ_i T_ib` (in).
    weights: Vec<f64>,
    /// Lengths (in) of the lower cells `[d_{b-1}, d_b]` (the first point uses the first spacing).
    lower_cells: Vec<f64>,
    /// Sparse columns of `T`.
    columns: Vec<SparseColumn>,
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
    /// let sol = model.solve(600.0, 100.0, 0.0).unwrap();
    /// assert_eq!(sol.tangential().len(), 5);
    /// ```
    pub fn tangential(&self) -> &[f64] {
        &self.forces[self.forces.len() / 2..]
    }
}

/// Per-evaluation contact data: spring stiffnesses per point.
struct Springs<'a> {
    /// Normal spring stiffness `s_b = k_N c_b` (psi).
    normal: &'a [f64],
    /// Tangential spring stiffness `κ_b` (psi).
    tangential: &'a [f64],
}

impl ContactModel {
    /// Validates `gate` and `params` and precomputes `K = C⁻¹`, tributary lengths and the
    /// sparse load transfer. Errors name the offending field.
    ///
    /// ```
    /// use mitergate::contact::{ContactModel, ContactParams};
    /// let model = ContactModel::new(mitergate::contact::doc_gate(), ContactParams::default());
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
    /// assert_eq!(model.gate().quoin_height, 762.0);
    /// ```
    pub fn gate(&self) -> &CondensedGate {
        &self.gate
    }

    /// The contact parameters.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
    /// assert_eq!(model.params().k_normal(), 1e6);
    /// ```
    pub fn params(&self) -> &ContactParams {
        &self.params
    }

    /// Tributary lengths `w_b = ∫ φ_b dz` (in) of the representation points.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
    /// let sol = model.solve(700.0, 50.0, 100.0).unwrap();
    /// assert!(sol.n_active >= 1 && sol.tangential_residual < 1e-9);
    /// assert!(model.solve(700.0, 50.0, 800.0).is_err()); // gap longer than the quoin
    /// ```
    pub fn solve(&self, h_up: f64, h_down: f64, theta: f64) -> Result<ContactSolution, GateError> {
        self.check_inputs(h_up, h_down, theta)?;
        let uw = self.gate.water_quoin_displacement.eval_levels(h_up, h_down);
        let f = &self.stiffness * &uw;
        let normal: Vec<f64> = self
            .coverage(theta)
            .iter()
            .map(|c| c * self.params.k_normal)
            .collect();
        let n = self.gate.n_points();
        let k_t = self.params.k_tangential;

        // Start from the stiff-contact limit: the rigid-quoin normal reaction, spread to the
        // points, gives the first active set and the first tangential springs.
        let rigid = self.rigid_line_load(&f);
        let mut tangential: Vec<f64> = (0..n)
            .map(|b| k_t * normal[b] / self.params.k_normal * rigid[b].max(0.0))
            .collect();
        let mut u = uw.clone();
        let mut active = (0..n)
            .map(|b| normal[b] > 0.0 && rigid[b] > 0.0)
            .collect::<Vec<_>>();
        let (mut mismatches, mut residual) = (n, f64::INFINITY);
        for iter in 1..=self.params.max_iterations {
            let springs = Springs {
                normal: &normal,
                tangential: &tangential,
            };
            let u_new = self.newton_solve(&active, &springs, &f)?;
            let ubar = self.point_displacements(u_new.as_slice());
            let new_active = self.active_set(&ubar, &springs);
            // Penetrations within rounding of zero carry no force either way: ignore them.
            let zero = 1e-13 * ubar[..n].iter().fold(0.0f64, |a, v| a.max(v.abs()));
            mismatches = (0..n)
                .filter(|&b| new_active[b] != active[b] && ubar[b].abs() > zero)
                .count();
            let forces = self.forces_from(&ubar, &springs);
            residual = tangential_law_residual(&forces, &ubar, k_t);
            if mismatches == 0 && residual <= self.params.tolerance {
                return Ok(ContactSolution {
                    n_active: forces[..n].iter().filter(|&&v| v > 0.0).count(),
                    forces,
                    node_displacement: u_new.as_slice().to_vec(),
                    iterations: iter,
                    tangential_residual: residual,
                });
            }
            u = if mismatches == 0 {
                u_new
            } else {
                self.damped_step(u, u_new, &f, &springs)
            };
            let ubar = self.point_displacements(u.as_slice());
            active = self.active_set(&ubar, &springs);
            let forces = self.forces_from(&ubar, &springs);
            for b in 0..n {
                tangential[b] = k_t * forces[b];
            }
        }
        let stage = if mismatches > 0 {
            "normal contact active set"
        } else {
            "tangential law"
        };
        Err(GateError::ContactNotConverged {
            stage,
            iterations: self.params.max_iterations,
            residual: if mismatches > 0 {
                mismatches as f64
            } else {
                residual
            },
        })
    }

    /// Normal line load (lbf/in) at each point implied by the rigid-quoin reactions
    /// `-f = -K u_w`: each nodal reaction spread over its node's tributary length, then
    /// averaged over the point's hat with the weights `T_ib / w_b`.
    fn rigid_line_load(&self, f: &DVector<f64>) -> Vec<f64> {
        let m = self.gate.n_quoin_nodes();
        let mut node_length = vec![0.0; m];
        for col in &self.columns {
            for &(i, t) in col {
                node_length[i] += t;
            }
        }
        self.columns
            .iter()
            .zip(&self.weights)
            .map(|(col, w)| {
                col.iter()
                    .map(|&(i, t)| t / w * (-f[i] / node_length[i]))
                    .sum()
            })
            .collect()
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

    /// Contact line loads from point displacements and spring stiffnesses (no tension).
    fn forces_from(&self, ubar: &[f64], springs: &Springs) -> Vec<f64> {
        let n = self.gate.n_points();
        let mut q = vec![0.0; 2 * n];
        for b in 0..n {
            q[b] = springs.normal[b] * (-ubar[b]).max(0.0);
            q[n + b] = -springs.tangential[b] * ubar[n + b];
        }
        q
    }

    /// Active normal set: points with a spring and positive penetration.
    fn active_set(&self, ubar: &[f64], springs: &Springs) -> Vec<bool> {
        springs
            .normal
            .iter()
            .zip(ubar)
            .map(|(&s, &u)| s > 0.0 && u < 0.0)
            .collect()
    }

    /// Energy `E(u)` of the module docs (lbf·in) for fixed springs.
    fn energy(&self, u: &DVector<f64>, f: &DVector<f64>, springs: &Springs) -> f64 {
        let n = self.gate.n_points();
        let ubar = self.point_displacements(u.as_slice());
        let mut e = 0.5 * u.dot(&(&self.stiffness * u)) - u.dot(f);
        for b in 0..n {
            let pen = (-ubar[b]).max(0.0);
            e += 0.5 * self.weights[b] * (springs.normal[b] * pen * pen);
            e += 0.5 * self.weights[b] * springs.tangential[b] * ubar[n + b] * ubar[n + b];
        }
        e
    }

    /// Solves `(K + G(𝒜)) u = f` for the given active set.
    fn newton_solve(
        &self,
        active: &[bool],
        springs: &Springs,
        f: &DVector<f64>,
    ) -> Result<DVector<f64>, GateError> {
        let m = self.gate.n_quoin_nodes();
        let mut mat = self.stiffness.clone();
        for (b, col) in self.columns.iter().enumerate() {
            let gn = if active[b] {
                springs.normal[b] / self.weights[b]
            } else {
                0.0
            };
            let gt = springs.tangential[b] / self.weights[b];
            if gn == 0.0 && gt == 0.0 {
                continue;
            }
            for &(i, ti) in col {
                for &(j, tj) in col {
                    mat[(i, j)] += gn * ti * tj;
                    mat[(m + i, m + j)] += gt * ti * tj;
                }
            }
        }
        let chol = mat
            .cholesky()
            .ok_or(GateError::ContactNotPositiveDefinite {
                what: "K + G (contact Newton matrix)",
            })?;
        Ok(chol.solve(f))
    }

    /// Step from `u` towards the Newton point `u_new`, halving until the energy decreases.
    fn damped_step(
        &self,
        u: DVector<f64>,
        u_new: DVector<f64>,
        f: &DVector<f64>,
        springs: &Springs,
    ) -> DVector<f64> {
        let e0 = self.energy(&u, f, springs);
        let dir = &u_new - &u;
        let mut alpha = 1.0;
        for _ in 0..30 {
            let trial = &u + &dir * alpha;
            if self.energy(&trial, f, springs) <= e0 {
                return trial;
            }
            alpha *= 0.5;
        }
        // The Newton direction is a descent direction of the convex energy, so the loop above
        // returns unless rounding dominates; the full step is then as good as any.
        u_new
    }
}

/// `max_b |F_T,b + k_T F_N,b ū_T,b| / max|F|` (0 when all forces vanish).
fn tangential_law_residual(forces: &[f64], ubar: &[f64], k_t: f64) -> f64 {
    let n = forces.len() / 2;
    let scale = forces.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let worst = (0..n)
        .map(|b| (forces[n + b] + k_t * forces[b] * ubar[n + b]).abs())
        .fold(0.0f64, f64::max);
    if scale > 0.0 { worst / scale } else { 0.0 }
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

/// The load transfer `T` (`m x N_u`, in) of the [`CondensedGate`] contract for linear nodal
/// shape functions `N_i` (hats on `node_heights`) and line loads interpolated linearly between
/// `points` (hats `φ_b`): `T_ib = ∫ N_i φ_b dz`, integrated exactly (two-point Gauss on every
/// interval between merged breakpoints, where the integrand is quadratic). Both grids must be
/// strictly increasing; the load is taken as zero outside `[points[0], points[last]]`.
///
/// ```
/// let t = mitergate::contact::linear_load_transfer(&[0.0, 10.0], &[0.0, 5.0, 10.0]);
/// // a unit line load everywhere gives nodal forces 5 lbf + 5 lbf
/// let total: f64 = t.row(0).sum();
/// assert!((total - 5.0).abs() < 1e-12);
/// assert!((t[(0, 0)] - 5.0 * 5.0 / 12.0).abs() < 1e-12);
/// ```
pub fn linear_load_transfer(node_heights: &[f64], points: &[f64]) -> DMatrix<f64> {
    let m = node_heights.len();
    let n = points.len();
    let mut t = DMatrix::zeros(m, n);
    let mut cuts: Vec<f64> = node_heights.iter().chain(points).copied().collect();
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let g = 0.5 / 3f64.sqrt();
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b <= points[0] || a >= points[n - 1] {
            continue;
        }
        for z in [0.5 * (a + b) - g * (b - a), 0.5 * (a + b) + g * (b - a)] {
            let weight = 0.5 * (b - a);
            for (i, ni) in hat_values(node_heights, z) {
                for (k, pk) in hat_values(points, z) {
                    t[(i, k)] += weight * ni * pk;
                }
            }
        }
    }
    t
}

/// The (at most two) nonzero hat functions of grid `x` at `z`, as `(index, value)`.
fn hat_values(x: &[f64], z: f64) -> Vec<(usize, f64)> {
    let n = x.len();
    if z < x[0] || z > x[n - 1] {
        return Vec::new();
    }
    let k = (x.partition_point(|&v| v <= z).max(1) - 1).min(n - 2);
    let s = (z - x[k]) / (x[k + 1] - x[k]);
    vec![(k, 1.0 - s), (k + 1, s)]
}

/// A tiny hand-built [`CondensedGate`] for documentation examples: 3 quoin nodes at
/// 0, 381, 762 in, 5 representation points, 2 gauges. Not a physical gate; see the crate's
/// tests for a beam model.
///
/// ```
/// let g = mitergate::contact::doc_gate();
/// assert_eq!((g.n_quoin_nodes(), g.n_points(), g.n_gauges()), (3, 5, 2));
/// ```
pub fn doc_gate() -> CondensedGate {
    use crate::condensed::HydrostaticTable;
    let h = 762.0;
    let nodes = vec![0.0, 381.0, 762.0];
    let points: Vec<f64> = (0..5).map(|b| h * b as f64 / 4.0).collect();
    let t = linear_load_transfer(&nodes, &points);
    // Flexibility: a diagonal-dominant SPD matrix (in/lbf), weak normal-tangential coupling.
    let mut c = DMatrix::zeros(6, 6);
    for i in 0..6 {
        c[(i, i)] = 2e-6;
    }
    for i in 0..3 {
        c[(i, 3 + i)] = 2e-7;
        c[(3 + i, i)] = 2e-7;
    }
    c[(0, 1)] = 5e-7;
    c[(1, 0)] = 5e-7;
    c[(1, 2)] = 5e-7;
    c[(2, 1)] = 5e-7;
    // Water pushes the gate into the wall (-n) and downstream (+t): u_w(h) = r (h/762)^2 h.
    let dir = [-0.01, -0.02, -0.01, 0.004, 0.006, 0.004];
    let bp = vec![0.0, 381.0, 762.0];
    let val = |hh: f64| (hh / h).powi(2) * hh;
    let der = |hh: f64| 3.0 * (hh / h).powi(2);
    let values = DMatrix::from_fn(3, 6, |k, j| dir[j] * val(bp[k]));
    let slopes = DMatrix::from_fn(3, 6, |k, j| dir[j] * der(bp[k]));
    let uw = HydrostaticTable::new(bp.clone(), values, slopes).expect("valid table");
    let sv = DMatrix::from_fn(3, 2, |k, j| [1.0, -0.5][j] * val(bp[k]));
    let ss = DMatrix::from_fn(3, 2, |k, j| [1.0, -0.5][j] * der(bp[k]));
    let sw = HydrostaticTable::new(bp, sv, ss).expect("valid table");
    let a = DMatrix::from_fn(2, 10, |p, j| {
        1e-3 * ((p + 1) as f64) * ((j % 5) as f64 + 1.0)
    });
    CondensedGate {
        quoin_height: h,
        quoin_node_heights: nodes,
        quoin_flexibility: c,
        water_quoin_displacement: uw,
        gauge_names: vec!["G1".into(), "G2".into()],
        water_strain: sw,
        nu_points: points,
        load_transfer: t,
        a_matrix: a,
    }
}
