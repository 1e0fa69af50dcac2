//! The contact solve: a primal-dual active-set (semismooth Newton) iteration merged with a
//! fixed point on the bilinear tangential law, with coupled Newton steps where that fixed
//! point contracts slowly (see "Solution method" in the [module docs](super)). The dense
//! `2m`-sized systems are factored in place by single-threaded faer Cholesky / LU in a
//! per-thread workspace.

use super::model::{ContactModel, ContactSolution};
use crate::error::GateError;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::linalg::lu::partial_pivoting::{factor as lu_factor, solve as lu_solve};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Mat, MatMut, Par};
use nalgebra::{DMatrix, DVector};

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

/// Gap offsets (in) of the neighbouring cold solves that a cold solve which did not converge
/// restarts from, nearest first and the longer gap first (see "Recovery" in the
/// [module docs](super)).
const RECOVERY_GAP_OFFSETS_IN: [f64; 4] = [0.01, -0.01, 0.1, -0.1];

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

/// The state carried from one iteration to the next.
struct Iteration {
    /// Current iterate (quoin-node displacements, in).
    u: DVector<f64>,
    /// Active normal set of `u`.
    active: Vec<bool>,
    /// Tangential springs `κ_b` (psi).
    tangential: Vec<f64>,
    /// Active-set changes of the last spring solve (rounding-level penetrations ignored).
    mismatches: usize,
    /// Tangential-law residual of the last spring solve.
    residual: f64,
    /// Newton iterates rejected so far.
    newton_rejections: usize,
}

impl Iteration {
    /// The error of a solve that hit the iteration cap, naming the unmet criterion.
    fn not_converged(&self, iterations: usize) -> GateError {
        let (stage, residual) = if self.mismatches > 0 {
            ("normal contact active set", self.mismatches as f64)
        } else {
            ("tangential law", self.residual)
        };
        GateError::ContactNotConverged {
            stage,
            iterations,
            residual,
        }
    }
}

impl ContactModel {
    /// Solves from the stiff-contact limit: the rigid-quoin normal reaction, spread to the
    /// points, gives the first active set and the first tangential springs (inputs checked
    /// by the caller).
    pub(super) fn solve_cold(
        &self,
        h_up: f64,
        h_down: f64,
        theta: f64,
    ) -> Result<ContactSolution, GateError> {
        let problem = self.problem(h_up, h_down, theta);
        let rigid = self.rigid_line_load(&problem.load);
        let start = self.start_from_normal_forces(&problem, |b| rigid[b].max(0.0));
        self.iterate(&problem, start)
    }

    /// The documented recovery of a cold solve that did not converge: the solve at `θ` is
    /// restarted from the cold solution at each gap `θ + d` of [`RECOVERY_GAP_OFFSETS_IN`]
    /// in turn (inside `[0, H)`), and the first that converges is returned (logged at
    /// `debug`). The restart meets the same convergence test, and it depends on `(x, θ)` only,
    /// so `g_BC` stays a function. Any other error, or no converging restart, returns `error`.
    pub(super) fn recover_from_neighbours(
        &self,
        h_up: f64,
        h_down: f64,
        theta: f64,
        error: GateError,
    ) -> Result<ContactSolution, GateError> {
        if !matches!(error, GateError::ContactNotConverged { .. }) {
            return Err(error);
        }
        let height = self.gate.quoin_height;
        for d in RECOVERY_GAP_OFFSETS_IN {
            let near = theta + d;
            if !(0.0..height).contains(&near) {
                continue;
            }
            let Ok(start) = self.solve_cold(h_up, h_down, near) else {
                continue;
            };
            if let Ok(sol) = self.solve_warm(h_up, h_down, theta, &start.forces) {
                log::debug!(
                    "contact at h_up {h_up}, h_down {h_down}, θ {theta}: cold solve failed \
                     ({error}); converged in {} iterations from the solution at θ {near}",
                    sol.iterations
                );
                return Ok(sol);
            }
        }
        Err(error)
    }

    /// Solves from the normal line loads of a previous solution (`previous_forces`, blocked,
    /// length checked by the caller).
    pub(super) fn solve_warm(
        &self,
        h_up: f64,
        h_down: f64,
        theta: f64,
        previous_forces: &[f64],
    ) -> Result<ContactSolution, GateError> {
        let problem = self.problem(h_up, h_down, theta);
        let start = self.start_from_normal_forces(&problem, |b| previous_forces[b].max(0.0));
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
        let mut state = Iteration {
            u: problem.uw.clone(),
            active: start.active,
            tangential: start.tangential,
            mismatches: self.gate.n_points(),
            residual: f64::INFINITY,
            newton_rejections: 0,
        };
        for iter in 1..=self.params.max_iterations {
            if let Some(solution) = self.iteration(problem, &mut state, iter)? {
                return Ok(solution);
            }
        }
        Err(state.not_converged(self.params.max_iterations))
    }

    /// One iteration (the module docs' steps 2-5): the spring solve `u⁺` for the current
    /// active set and tangential springs, the convergence test (returns the solution), else
    /// the next iterate, active set and springs.
    fn iteration(
        &self,
        problem: &Problem,
        state: &mut Iteration,
        iter: usize,
    ) -> Result<Option<ContactSolution>, GateError> {
        let n = self.gate.n_points();
        let springs = Springs {
            normal: &problem.normal,
            tangential: &state.tangential,
        };
        let u_new = self.spring_solve(problem, &state.active, &springs)?;
        let ubar = self.point_displacements(u_new.as_slice());
        let new_active = self.active_set(&ubar, &springs);
        // Penetrations within rounding of zero carry no force either way: ignore them.
        let zero = PENETRATION_ROUNDING * ubar[..n].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let previous = (state.mismatches, state.residual);
        state.mismatches = (0..n)
            .filter(|&b| new_active[b] != state.active[b] && ubar[b].abs() > zero)
            .count();
        let forces = self.forces_from(&ubar, &springs);
        state.residual = tangential_law_residual(&forces, &ubar, self.params.k_tangential);
        if state.mismatches == 0 && state.residual <= self.params.tolerance {
            return Ok(Some(ContactSolution {
                n_active: forces[..n].iter().filter(|&&v| v > 0.0).count(),
                forces,
                node_displacement: u_new.as_slice().to_vec(),
                iterations: iter,
                tangential_residual: state.residual,
            }));
        }
        let slow_tail = state.mismatches == 0
            && previous.0 == 0
            && state.residual > SLOW_CONTRACTION * previous.1
            && state.newton_rejections < MAX_NEWTON_REJECTIONS;
        let u = std::mem::replace(&mut state.u, DVector::zeros(0));
        let next = if slow_tail {
            match self.coupled_newton_step(problem, &u_new, &new_active) {
                Some(next) if self.merit(&next, problem) < self.merit(&u_new, problem) => {
                    Next::Other(next)
                }
                _ => {
                    state.newton_rejections += 1;
                    Next::SpringSolve(u_new)
                }
            }
        } else if state.mismatches == 0 {
            Next::SpringSolve(u_new)
        } else {
            Next::Other(self.damped_step(u, u_new, &problem.load, &springs))
        };
        match next {
            Next::SpringSolve(u_new) => {
                state.u = u_new;
                self.set_springs(state, new_active, &forces);
            }
            Next::Other(next) => {
                state.u = next;
                self.update_springs(problem, state);
            }
        }
        Ok(None)
    }

    /// The active set and tangential springs `κ_b = k_T F_N,b` of the iterate `state.u`
    /// (forces evaluated with the springs of the step just taken).
    fn update_springs(&self, problem: &Problem, state: &mut Iteration) {
        let ubar = self.point_displacements(state.u.as_slice());
        let springs = Springs {
            normal: &problem.normal,
            tangential: &state.tangential,
        };
        let active = self.active_set(&ubar, &springs);
        let forces = self.forces_from(&ubar, &springs);
        self.set_springs(state, active, &forces);
    }

    /// Takes `active` and `κ_b = k_T F_N,b` from `forces` (those of `state.u`).
    fn set_springs(&self, state: &mut Iteration, active: Vec<bool>, forces: &[f64]) {
        state.active = active;
        let k_t = self.params.k_tangential;
        for b in 0..self.gate.n_points() {
            state.tangential[b] = k_t * forces[b];
        }
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
            self.for_each_spring_entry(&coeffs, Entries::Lower, |i, j, v| mat[(i, j)] += v);
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
            self.for_each_spring_entry(&coupling_only, Entries::All, |i, j, v| b[i] += v * u[j]);
            self.for_each_spring_entry(&coeffs, Entries::All, |i, j, v| mat[(i, j)] += v);
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
    /// columns), or with [`Entries::Lower`] for those of `G` on and below the diagonal.
    /// Each matrix entry receives its values in the same order either way.
    fn for_each_spring_entry(
        &self,
        coeffs: &SpringCoefficients,
        entries: Entries,
        mut add: impl FnMut(usize, usize, f64),
    ) {
        let m = self.gate.n_quoin_nodes();
        debug_assert!(entries == Entries::All || coeffs.coupling.iter().all(|&e| e == 0.0));
        for (b, col) in self.columns.iter().enumerate() {
            let (gn, gt, e) = (coeffs.normal[b], coeffs.tangential[b], coeffs.coupling[b]);
            for &(i, ti) in col {
                for &(j, tj) in col {
                    if entries == Entries::Lower && j > i {
                        continue;
                    }
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
                llt::factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, llt_params().into()),
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
            llt_params().into(),
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

/// Below this size faer's Cholesky factors a diagonal block without splitting it further.
/// faer's default, 64, leaves the contact matrix (`2m = 156` on the default gate) two
/// unblocked 64-column leaves; 16 makes more of its work matrix products. Measured on a
/// 156 x 156 SPD matrix (release, one thread, 20,000 factorisations each): 30.5 µs with the
/// default, 25.3-26.0 µs with 16 (block size 32, 64 or 128 alike); the factors differ in
/// rounding only.
const LLT_RECURSION_THRESHOLD: usize = 16;

/// faer's Cholesky parameters with [`LLT_RECURSION_THRESHOLD`].
fn llt_params() -> llt::factor::LltParams {
    let mut params: llt::factor::LltParams = faer::Auto::<f64>::auto();
    params.recursion_threshold = LLT_RECURSION_THRESHOLD;
    params
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

/// The next iterate of the contact iteration.
enum Next {
    /// The spring solve's own: its active set and forces (with the springs of the step just
    /// taken) are those the iteration has computed, and are reused.
    SpringSolve(DVector<f64>),
    /// A Newton or damped step: its active set and forces are computed anew.
    Other(DVector<f64>),
}

/// Which entries `ContactModel::for_each_spring_entry` visits.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Entries {
    /// Every entry of `G + E`.
    All,
    /// The entries of `G` with row ≥ column (what the Cholesky factorisation reads); `E` must
    /// be zero.
    Lower,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::ContactParams;
    use crate::testing::doc_gate;

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
