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
//!    `G` is banded and cheap to add). `K + G` is symmetric positive definite and is factorised
//!    by an in-place, single-threaded faer Cholesky (`(2m)³/3` flops) in a per-thread
//!    workspace, so an iteration allocates no large matrix.
//! 3. Converged when the active set of `u⁺` equals `𝒜` (up to points whose penetration is
//!    zero to rounding), so that `u⁺` solves the piecewise linear problem exactly, **and** the
//!    tangential law `F_T = -k_T F_N ū_T` holds with the new `F_N` to the relative tolerance
//!    (default `1e-8` of `max|F|`; see [`ContactParams`] for why not tighter). The returned
//!    forces are those of `u⁺`, in exact equilibrium with it.
//! 4. Otherwise move towards `u⁺` (if the active set changed, halving the step until the
//!    energy decreases; this globalises the Newton iteration, and the full step is nearly always
//!    taken), take `𝒜` from the new `u`, set `κ_b = k_T F_N,b`, and repeat.
//! 5. Once the active set has settled, the fixed point on `κ` usually contracts 100-1000x per
//!    iteration. Where it does not (ratio of successive law residuals above
//!    `SLOW_CONTRACTION` = 0.05, typically near the top of a shrinking contact zone where
//!    `F_N` is small and `κ` sensitive), the next iterate comes instead from a Newton step on
//!    the coupled laws: `κ_b = k_T s_b p_b` is differentiated with respect to the penetration
//!    too, which adds a non-symmetric block `E` (tangential rows, normal columns) and is
//!    solved by LU. Step 3's test is unchanged, so this only changes how fast it is met.
//!
//! The Newton iterate is kept only if its residual of the exact laws (`merit`: equilibrium
//! with `F_N`, `F_T` evaluated at the iterate itself) is below that of the fixed-point
//! iterate; after `MAX_NEWTON_REJECTIONS` = 5 rejections the solve stays with the fixed point.
//! Accepting every Newton iterate cycled near a moving contact edge. The hardest inputs are
//! edges that creep: at the top of the zone a point with `F_N` of a few lbf/in carries
//! `|F_T|` ~ 1000 `F_N` (the bilinear law), the fixed point is nearly neutral there and the
//! edge point switches off only after hundreds of iterations (322 at h_up = 544.26,
//! h_down = 182.96, θ = 119.99 in on the 24 in mesh; the cap is 1000).
//!
//! Measured on the default gate (12 in mesh, `m` = 78 quoin nodes, `N_u` = 509) over 6,000
//! random water levels and gaps (θ from 0 to 200 in): 8.6 iterations on average, at most 17;
//! on a 24 in mesh over 18,000 inputs 7.7 on average and at most 20 (the plain fixed point:
//! up to 86), and over a dense grid of 9,600 inputs around the creeping-edge case at most
//! 248; no failure. Timing: `cargo run --release -p mitergate --example
//! contact_report` and the `contact/` criterion group. Most iterations go to
//! moving the upper edge of the contact zone: the active set shrinks from the rigid-quoin
//! guess by about half of its excess per iteration. [`ContactModel::solve_from`] starts from
//! a neighbouring solution instead (a `θ` or water-level sweep) and needs fewer.
//! An iteration cap (default 1000) returns [`GateError::ContactNotConverged`] naming the unmet
//! criterion, never a silent result.
//!
//! No FE re-factorisation happens per evaluation: one evaluation costs a handful of Cholesky
//! factorisations of size `2m` plus `O(N_u)` work.

use crate::GateError;
use crate::condensed::CondensedGate;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Mat, MatMut, Par};
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

/// Below this ratio of successive tangential-law residuals (with an unchanged active set) the
/// fixed-point iteration is deemed fast (it usually contracts 100-1000x per step); above it,
/// the next iterate comes from a Newton step on the coupled laws instead.
const SLOW_CONTRACTION: f64 = 0.05;

/// After this many rejected Newton steps (not better than the fixed-point iterate by the
/// [`ContactModel::merit`] residual, or failed) the iteration stays with the fixed point.
/// Accepting Newton iterates unconditionally cycled near a moving contact edge (h_up = 542.33,
/// h_down = 185.01, θ = 119.47 in on a 24 in mesh).
const MAX_NEWTON_REJECTIONS: usize = 5;

/// What one evaluation keeps fixed: the free water displacement `u_w` (in), the load `K u_w`
/// (lbf) and the normal springs `s_b` (psi).
struct Problem {
    uw: DVector<f64>,
    load: DVector<f64>,
    normal: Vec<f64>,
}

/// First active set and tangential springs (psi) of an iteration.
struct Start {
    active: Vec<bool>,
    tangential: Vec<f64>,
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
        let problem = self.problem(h_up, h_down, theta);
        // Start from the stiff-contact limit: the rigid-quoin normal reaction, spread to the
        // points, gives the first active set and the first tangential springs.
        let rigid = self.rigid_line_load(&problem.load);
        let start = self.start_from_normal_forces(&problem, |b| rigid[b].max(0.0));
        self.iterate(&problem, start)
    }

    /// Solves like [`ContactModel::solve`], starting from a previous solution (e.g. at a
    /// neighbouring `θ` or water level) instead of the rigid-quoin guess: its contact zone
    /// and normal forces give the first active set and tangential springs. The result meets
    /// the same convergence test, so it agrees with [`ContactModel::solve`] to the solver
    /// tolerance (not bit for bit); it usually needs fewer iterations along a sweep.
    ///
    /// ```
    /// # let model = mitergate::contact::ContactParams::default()
    /// #     .build(mitergate::contact::doc_gate()).unwrap();
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
        let problem = self.problem(h_up, h_down, theta);
        let start = self.start_from_normal_forces(&problem, |b| previous.forces[b].max(0.0));
        self.iterate(&problem, start)
    }

    /// The data of one evaluation that do not change during the iteration.
    fn problem(&self, h_up: f64, h_down: f64, theta: f64) -> Problem {
        let uw = self.gate.water_quoin_displacement.eval_levels(h_up, h_down);
        let load = &self.stiffness * &uw;
        let normal = self
            .coverage(theta)
            .iter()
            .map(|c| c * self.params.k_normal)
            .collect();
        Problem { uw, load, normal }
    }

    /// First active set and tangential springs from a guess of the normal line loads
    /// (lbf/in): points with a spring and a positive guess are active, `κ_b = k_T c_b F_N,b`.
    fn start_from_normal_forces(&self, problem: &Problem, guess: impl Fn(usize) -> f64) -> Start {
        let n = self.gate.n_points();
        let k_n = self.params.k_normal;
        let k_t = self.params.k_tangential;
        let mut start = Start {
            active: vec![false; n],
            tangential: vec![0.0; n],
        };
        for b in 0..n {
            let fb = guess(b);
            start.active[b] = problem.normal[b] > 0.0 && fb > 0.0;
            start.tangential[b] = k_t * problem.normal[b] / k_n * fb;
        }
        start
    }

    /// The iteration of the module docs from a first active set and tangential springs.
    fn iterate(&self, problem: &Problem, start: Start) -> Result<ContactSolution, GateError> {
        let n = self.gate.n_points();
        let k_t = self.params.k_tangential;
        let f = &problem.load;
        let normal = &problem.normal;
        let Start {
            mut active,
            mut tangential,
        } = start;
        let mut u = problem.uw.clone();
        let (mut mismatches, mut residual) = (n, f64::INFINITY);
        let mut newton_rejections = 0;
        for iter in 1..=self.params.max_iterations {
            let springs = Springs {
                normal,
                tangential: &tangential,
            };
            let u_new = self.spring_solve(problem, &active, &springs)?;
            let ubar = self.point_displacements(u_new.as_slice());
            let new_active = self.active_set(&ubar, &springs);
            // Penetrations within rounding of zero carry no force either way: ignore them.
            let zero = PENETRATION_ROUNDING * ubar[..n].iter().fold(0.0f64, |a, v| a.max(v.abs()));
            let previous = (mismatches, residual);
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
            let slow_tail = mismatches == 0
                && previous.0 == 0
                && residual > SLOW_CONTRACTION * previous.1
                && newton_rejections < MAX_NEWTON_REJECTIONS;
            u = if slow_tail {
                match self.coupled_newton_step(problem, &u_new, &new_active) {
                    Some(next) if self.merit(&next, problem) < self.merit(&u_new, problem) => next,
                    _ => {
                        newton_rejections += 1;
                        u_new
                    }
                }
            } else if mismatches == 0 {
                u_new
            } else {
                self.damped_step(u, u_new, f, &springs)
            };
            let ubar = self.point_displacements(u.as_slice());
            let springs = Springs {
                normal,
                tangential: &tangential,
            };
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

    /// Relative equilibrium residual of the exact contact laws at `u`:
    /// `max|K (u − u_w) − P(u)| / max|P(u)|`, with `P(u)` the nodal forces of
    /// `F_N = s max(0, −ū_N)` and `F_T = −k_T F_N ū_T` evaluated at `u` itself.
    fn merit(&self, u: &DVector<f64>, problem: &Problem) -> f64 {
        let n = self.gate.n_points();
        let ubar = self.point_displacements(u.as_slice());
        let mut q = vec![0.0; 2 * n];
        for b in 0..n {
            q[b] = problem.normal[b] * (-ubar[b]).max(0.0);
            q[n + b] = -self.params.k_tangential * q[b] * ubar[n + b];
        }
        let p = DVector::from_vec(self.nodal_forces(&q));
        let r = &self.stiffness * u - &problem.load - &p;
        r.amax() / p.amax().max(f64::MIN_POSITIVE)
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

    /// Solves `(K + G(𝒜, κ)) u = K u_w` (the module docs' step 2) by an in-place,
    /// single-threaded faer Cholesky factorisation in this thread's workspace.
    fn spring_solve(
        &self,
        problem: &Problem,
        active: &[bool],
        springs: &Springs,
    ) -> Result<DVector<f64>, GateError> {
        let coeffs = self.spring_coefficients(active, springs, None);
        let dim = problem.load.len();
        let solution = with_workspace(dim, |mut mat, mut rhs, ws| {
            copy_lower(&self.stiffness, mat.rb_mut());
            self.for_each_spring_entry(&coeffs, |i, j, v| {
                if i >= j {
                    mat[(i, j)] += v;
                }
            });
            column_slice(rhs.rb_mut(), 0).copy_from_slice(problem.load.as_slice());
            ws.cholesky_solve(mat, rhs.rb_mut())
                .map(|()| column_slice(rhs, 0).to_vec())
        });
        solution
            .map(DVector::from_vec)
            .map_err(|_| GateError::ContactNotPositiveDefinite {
                what: "K + G (contact Newton matrix)",
            })
    }

    /// One Newton step on the coupled normal-tangential equations at `u` for the active set
    /// `active`: the tangential springs `κ_b = k_T s_b p_b` are differentiated with respect to
    /// the penetration too (the fixed-point iteration holds them constant), which adds the
    /// non-symmetric coupling `E` of [`ContactModel::spring_coefficients`]; the step solves
    /// `(K + G + E) u⁺ = K u_w + E u` by LU with partial pivoting. Used only when the fixed
    /// point contracts slowly (see [`SLOW_CONTRACTION`]); returns `None` if the step is not
    /// finite, and the iteration then continues with the fixed-point iterate (the
    /// convergence test is the same either way).
    fn coupled_newton_step(
        &self,
        problem: &Problem,
        u: &DVector<f64>,
        active: &[bool],
    ) -> Option<DVector<f64>> {
        let n = self.gate.n_points();
        let k_t = self.params.k_tangential;
        let ubar = self.point_displacements(u.as_slice());
        let kappa: Vec<f64> = (0..n)
            .map(|b| {
                if active[b] {
                    k_t * problem.normal[b] * (-ubar[b]).max(0.0)
                } else {
                    0.0
                }
            })
            .collect();
        let springs = Springs {
            normal: &problem.normal,
            tangential: &kappa,
        };
        let coeffs = self.spring_coefficients(active, &springs, Some(u));
        let dim = problem.load.len();
        let next = with_workspace(dim, |mut mat, mut rhs, ws| {
            for j in 0..dim {
                column_slice(mat.rb_mut(), j).copy_from_slice(self.stiffness.column(j).as_slice());
            }
            let b = column_slice(rhs.rb_mut(), 0);
            b.copy_from_slice(problem.load.as_slice());
            let coupling_only = SpringCoefficients {
                normal: vec![0.0; n],
                tangential: vec![0.0; n],
                coupling: coeffs.coupling.clone(),
            };
            self.for_each_spring_entry(&coupling_only, |i, j, v| b[i] += v * u[j]);
            self.for_each_spring_entry(&coeffs, |i, j, v| mat[(i, j)] += v);
            ws.lu_solve(mat, rhs.rb_mut());
            column_slice(rhs, 0).to_vec()
        });
        next.iter()
            .all(|v| v.is_finite())
            .then(|| DVector::from_vec(next))
    }

    /// Per-point coefficients (psi/in) of the spring matrix `G(𝒜, κ)` (normal `s_b / w_b` on
    /// active points, tangential `κ_b / w_b`) and, when `coupling = Some(u_lin)`, of the Newton
    /// coupling `E`: `-k_T s_b ū_T,b / w_b` on active points, the derivative of the tangential
    /// spring force `κ_b ū_T,b` (`κ_b = k_T s_b p_b`) with respect to the normal displacements
    /// at `u_lin`.
    fn spring_coefficients(
        &self,
        active: &[bool],
        springs: &Springs,
        coupling: Option<&DVector<f64>>,
    ) -> SpringCoefficients {
        let n = self.gate.n_points();
        let k_t = self.params.k_tangential;
        let ubar = coupling.map(|u| self.point_displacements(u.as_slice()));
        let mut out = SpringCoefficients {
            normal: vec![0.0; n],
            tangential: vec![0.0; n],
            coupling: vec![0.0; n],
        };
        for b in 0..n {
            let w = self.weights[b];
            if active[b] {
                out.normal[b] = springs.normal[b] / w;
                if let Some(ubar) = &ubar {
                    out.coupling[b] = -k_t * springs.normal[b] * ubar[n + b] / w;
                }
            }
            out.tangential[b] = springs.tangential[b] / w;
        }
        out
    }

    /// Calls `add(row, col, value)` for every entry of `G + E` (displacement-component
    /// indices, blocked `[normal; tangential]`; `E` sits in the tangential rows and normal
    /// columns).
    fn for_each_spring_entry(
        &self,
        coeffs: &SpringCoefficients,
        mut add: impl FnMut(usize, usize, f64),
    ) {
        let m = self.gate.n_quoin_nodes();
        for (b, col) in self.columns.iter().enumerate() {
            let (gn, gt, e) = (coeffs.normal[b], coeffs.tangential[b], coeffs.coupling[b]);
            for &(i, ti) in col {
                for &(j, tj) in col {
                    if gn != 0.0 {
                        add(i, j, gn * ti * tj);
                    }
                    if gt != 0.0 {
                        add(m + i, m + j, gt * ti * tj);
                    }
                    if e != 0.0 {
                        add(m + i, j, e * ti * tj);
                    }
                }
            }
        }
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

/// Scratch of the dense solves of one thread: a `d x d` matrix, a right-hand side, and the
/// factorisation buffers, grown on demand. It carries no state between calls (every entry
/// used is overwritten first); it only avoids allocating (and having the kernel zero) a fresh
/// matrix of ~200 kB for every iteration.
struct Workspace {
    mat: Mat<f64>,
    rhs: Mat<f64>,
    factor: Factorisations,
}

/// Pivot arrays and scratch memory of the sequential Cholesky and LU factorisations. They
/// run single-threaded: the systems are small (`2m`) and evaluations already run in parallel
/// at a higher level, so faer's global (multi-threaded) default would only add
/// synchronisation.
#[derive(Default)]
struct Factorisations {
    fwd: Vec<usize>,
    bwd: Vec<usize>,
    buf: Option<MemBuffer>,
    capacity: usize,
}

impl Factorisations {
    /// Scratch memory for systems of size `n`.
    fn stack(&mut self, n: usize) -> &mut MemBuffer {
        if self.capacity < n || self.buf.is_none() {
            let req = StackReq::any_of(&[
                lu_factor::lu_in_place_scratch::<usize, f64>(n, n, Par::Seq, Default::default()),
                lu_solve::solve_in_place_scratch::<usize, f64>(n, 1, Par::Seq),
                llt::factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default()),
                llt::solve::solve_in_place_scratch::<f64>(n, 1, Par::Seq),
            ]);
            self.buf = Some(MemBuffer::new(req));
            self.capacity = n;
        }
        self.buf.as_mut().expect("allocated above")
    }

    /// Solves `mat x = rhs` in place for symmetric positive definite `mat` (lower triangle
    /// read); `Err(index)` names the first non-positive pivot.
    fn cholesky_solve(
        &mut self,
        mut mat: MatMut<'_, f64>,
        mut rhs: MatMut<'_, f64>,
    ) -> Result<(), usize> {
        let buf = self.stack(mat.nrows());
        llt::factor::cholesky_in_place(
            mat.rb_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(buf),
            Default::default(),
        )
        .map_err(|e| match e {
            llt::factor::LltError::NonPositivePivot { index } => index,
        })?;
        llt::solve::solve_in_place(mat.rb(), rhs.rb_mut(), Par::Seq, MemStack::new(buf));
        Ok(())
    }

    /// Solves `mat x = rhs` in place by LU with partial pivoting.
    fn lu_solve(&mut self, mut mat: MatMut<'_, f64>, mut rhs: MatMut<'_, f64>) {
        let n = mat.nrows();
        self.fwd.resize(n, 0);
        self.bwd.resize(n, 0);
        let Self { fwd, bwd, .. } = self;
        let (fwd, bwd) = (&mut fwd[..n], &mut bwd[..n]);
        let buf = match &mut self.buf {
            Some(buf) if self.capacity >= n => buf,
            _ => unreachable!(),
        };
        let (_, perm) = lu_factor::lu_in_place(
            mat.rb_mut(),
            fwd,
            bwd,
            Par::Seq,
            MemStack::new(buf),
            Default::default(),
        );
        lu_solve::solve_in_place(
            mat.rb(),
            mat.rb(),
            perm,
            rhs.rb_mut(),
            Par::Seq,
            MemStack::new(buf),
        );
    }
}

thread_local! {
    static WORKSPACE: std::cell::RefCell<Workspace> = std::cell::RefCell::new(Workspace {
        mat: Mat::zeros(0, 0),
        rhs: Mat::zeros(0, 1),
        factor: Factorisations::default(),
    });
}

/// Runs `work` on this thread's scratch matrix (`d x d`), right-hand side (`d x 1`) and
/// factorisation buffers.
fn with_workspace<R>(
    d: usize,
    work: impl FnOnce(MatMut<'_, f64>, MatMut<'_, f64>, &mut Factorisations) -> R,
) -> R {
    WORKSPACE.with(|cell| {
        let mut ws = cell.borrow_mut();
        if ws.mat.nrows() < d {
            ws.mat = Mat::zeros(d, d);
            ws.rhs = Mat::zeros(d, 1);
        }
        let Workspace { mat, rhs, factor } = &mut *ws;
        factor.stack(d);
        work(
            mat.as_mut().submatrix_mut(0, 0, d, d),
            rhs.as_mut().subrows_mut(0, d),
            factor,
        )
    })
}

/// Copies the lower triangle of `k` into `out` (the Cholesky factorisation reads only that).
fn copy_lower(k: &DMatrix<f64>, mut out: MatMut<'_, f64>) {
    for j in 0..k.ncols() {
        let column = k.column(j);
        column_slice(out.rb_mut(), j)[j..].copy_from_slice(&column.as_slice()[j..]);
    }
}

/// Per-point spring coefficients (see `ContactModel::spring_coefficients`), psi/in.
struct SpringCoefficients {
    normal: Vec<f64>,
    tangential: Vec<f64>,
    coupling: Vec<f64>,
}

/// Column `j` of a column-major faer matrix view as a mutable slice.
fn column_slice(m: MatMut<'_, f64>, j: usize) -> &mut [f64] {
    m.col_mut(j)
        .try_as_col_major_mut()
        .expect("workspace matrices are column major")
        .as_slice_mut()
}

/// Penetrations below `1e-13 · max|ū_N|` are rounding: the active-set tests ignore them.
const PENETRATION_ROUNDING: f64 = 1e-13;

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

#[cfg(test)]
mod tests {
    use super::*;

    /// The coupled Newton step linearises the tangential law correctly: from a point near the
    /// solution its error is of the order of the squared initial error, while the fixed-point
    /// step (springs frozen at the perturbed point) only reduces it linearly.
    #[test]
    fn coupled_newton_step_converges_quadratically() {
        // k_T such that the tangential springs κ w = k_T F_N w are comparable to the gate's
        // stiffness (~5e5 lbf/in): there the coupling matters (at the paper's k_T = 1e6 the
        // restraint is rigid and any linearisation looks quadratic).
        for k_t in [1e-4, 1e-3, 1e-2] {
            newton_is_quadratic(k_t);
        }
    }

    fn newton_is_quadratic(k_t: f64) {
        // A tight tolerance: the reference solution must be far more accurate than the
        // errors compared below.
        let model = ContactParams::default()
            .tangential_coefficient(k_t)
            .tolerance(1e-14)
            .build(doc_gate())
            .unwrap();
        let (h_up, h_down, theta) = (700.0, 50.0, 100.0);
        let exact = model.solve(h_up, h_down, theta).unwrap();
        let u_star = DVector::from_vec(exact.node_displacement.clone());
        let problem = model.problem(h_up, h_down, theta);
        let ubar = model.point_displacements(u_star.as_slice());
        let active = model.active_set(
            &ubar,
            &Springs {
                normal: &problem.normal,
                tangential: &vec![0.0; ubar.len() / 2],
            },
        );
        let scale = u_star.amax();
        let direction = DVector::from_fn(u_star.len(), |i, _| ((i * 7 + 3) % 5) as f64 - 2.0);
        let mut errors = Vec::new();
        for eps in [1e-3, 1e-4] {
            let u0 = &u_star + &direction * (eps * scale);
            let u1 = model.coupled_newton_step(&problem, &u0, &active).unwrap();
            errors.push(((&u1 - &u_star).amax() / scale, eps));
        }
        // Quadratic: shrinking the start error 10x shrinks the step's error ~100x (allow 30x
        // for the rounding floor and higher-order terms).
        let (e3, e4) = (errors[0].0, errors[1].0);
        assert!(
            e3 < 1e-3 * 1e-1,
            "k_T = {k_t}: Newton error {e3:e} from a 1e-3 start"
        );
        assert!(
            e4 <= e3 / 30.0 || e4 < 1e-12,
            "k_T = {k_t}: errors {errors:?}"
        );
    }
}
