//! Quoin contact model `g_BC(x, θ)` with a bottom gap (paper Sec. 4.1, Eq. 45-46).
//!
//! The gate's quoin post bears on a rigid wall quoin block through linear contact springs.
//! Below the gap length `θ` (inches above the sill) there is no contact. Given the water levels
//! `x = (h_up, h_down)` (in) and `θ`, [`ContactModel::solve`] returns the normal and tangential
//! contact line loads `F_N`, `F_T` (lbf/in) at the `N_u` representation points of the
//! [`CondensedGate`](crate::condense::CondensedGate), component blocked `[F_N; F_T]` (the layout of `mlmodel`; the paper's
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
//! shape function of FE quoin node `i`. The contract of [`CondensedGate`](crate::condense::CondensedGate) gives
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
//! An iteration cap (default 1000) returns [`GateError::ContactNotConverged`](crate::error::GateError::ContactNotConverged) naming the unmet
//! criterion, never a silent result.
//!
//! **Recovery.** The bilinear tangential law can give the contact zone's upper edge a jump in `θ`:
//! at h_up = 520.37, h_down = 78.32 in on the 24 in mesh the zone ends six points higher at θ =
//! 86.729 than at 86.731 in. The jump moves the line loads near the edge by up to 7600 lbf/in but
//! the gauges' strains by 0.09 µε (a 0.0005 in step of `θ` elsewhere: 0.002 µε and 600 lbf/in),
//! well below the 1 µε noise. Exactly at such a fold the cold start lands on the ghost of the
//! branch that has just vanished (a relative law residual stuck at 3e-7 with a 2.4 lbf/in top
//! point) and creeps off it for hundreds of iterations — past the cap at θ = 86.72995 in, which
//! stopped a 200-replicate coverage study. A cold solve that hits the cap is therefore restarted
//! from the cold solutions at `θ + 0.01`, `θ − 0.01`, `θ + 0.1`, `θ − 0.1` in
//! (`RECOVERY_GAP_OFFSETS_IN`, first convergence wins; logged at `debug`): the same convergence
//! test, a start that depends only on `(x, θ)`, 12 iterations in that case.
//!
//! No FE re-factorisation happens per evaluation: one evaluation costs a handful of Cholesky
//! factorisations of size `2m` plus `O(N_u)` work.
//!
//! The model (parameters, set-up, forces API) is in `contact/model.rs`, the iteration above in
//! `contact/solver.rs`.

mod anchored;
mod model;
mod solver;

pub use anchored::{ANCHOR_SPACING_IN, AnchorCache, anchor_gap};
pub use model::{ContactModel, ContactParams, ContactSolution};
