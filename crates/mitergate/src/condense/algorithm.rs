//! Static condensation of a leaf to its quoin and gauges (Eq. 47) by adjoint solves.
//!
//! With `K` the supported stiffness, `b_g` the strain functional of gauge `g` and `Q` the unit
//! quoin loads (along `n` and `t` at the `m` quoin nodes):
//!
//! * `K X = Q` (`2m` solves) gives the quoin flexibility `C = Qᵀ X` (Maxwell–Betti: symmetric);
//! * `K Λ = B` (one adjoint solve per gauge) gives the nodal gauge sensitivities `Λᵀ Q` and the
//!   strain matrix `A = Λᵀ Q blockdiag(T, T)` (never `2 N_u` forward solves);
//! * the water terms are `Λᵀ f_w(h)` and `Xᵀ f_w(h)` tabulated with their `h`-derivatives at the
//!   skin-node heights (exact piecewise cubics, [`HydrostaticTable`]).
//!
//! The algorithm is written once, against [`CondensationSource`]: the parametric
//! [`GateModel`] and an imported deck (`crate::inp::ImportedModel::condense`) both feed it.

use super::condensed::{CondensedGate, HydrostaticTable};
use crate::error::GateError;
use crate::fe::ShellModel;
use crate::fe::loads::load_transfer;
use crate::gate::{GateModel, check_levels};
use faer::Mat;
use nalgebra::DMatrix;

/// Default number of quoin force representation points (paper Sec. 4.2).
pub const DEFAULT_NU: usize = 509;

/// Sparse full-DOF vector: `(full dof, value)` pairs (repeated dofs add up).
pub(crate) type SparseLoad = Vec<(usize, f64)>;

/// Everything the condensation needs from a supported, factored FE model of a leaf.
pub(crate) trait CondensationSource {
    /// The factored model (sparse solves and the support map).
    fn shell_model(&self) -> &ShellModel;
    /// Quoin height `H` (in): the representation points span `[0, H]`.
    fn quoin_height(&self) -> f64;
    /// Heights (in above the sill) of the `m` quoin nodes, strictly increasing.
    fn quoin_node_heights(&self) -> Vec<f64>;
    /// Unit nodal loads along `n` (first `m`) and `t` (next `m`) at the quoin nodes, in the
    /// order of [`Self::quoin_node_heights`].
    fn quoin_unit_loads(&self) -> Vec<SparseLoad>;
    /// `(name, strain functional in microstrain per unit full DOF)` of every gauge.
    fn gauge_functionals(&self) -> Vec<(String, SparseLoad)>;
    /// Breakpoints (in) of the hydrostatic tables: the heights where the water response
    /// changes polynomial piece (the skin-node heights), strictly increasing.
    fn water_breakpoints(&self) -> Vec<f64>;
    /// Nodal loads of water at level `h` (in) on the upstream face, or their `h`-derivative.
    fn upstream_water_load(&self, h: f64, derivative: bool) -> Result<SparseLoad, GateError>;
}

impl CondensationSource for GateModel {
    fn shell_model(&self) -> &ShellModel {
        self.fe()
    }
    fn quoin_height(&self) -> f64 {
        self.config().geometry.quoin_height
    }
    fn quoin_node_heights(&self) -> Vec<f64> {
        self.quoin_heights()
    }
    fn quoin_unit_loads(&self) -> Vec<SparseLoad> {
        GateModel::quoin_unit_loads(self)
    }
    fn gauge_functionals(&self) -> Vec<(String, SparseLoad)> {
        self.gauges()
            .iter()
            .map(|g| (g.name.clone(), g.terms.clone()))
            .collect()
    }
    fn water_breakpoints(&self) -> Vec<f64> {
        let shell = &self.mesh().shell;
        sorted_unique(
            self.mesh()
                .skin_elements()
                .iter()
                .flat_map(|&e| shell.elements[e].nodes.map(|n| shell.nodes[n][2]))
                .collect(),
        )
    }
    fn upstream_water_load(&self, h: f64, derivative: bool) -> Result<SparseLoad, GateError> {
        self.water_load_sparse(h, derivative)
    }
}

/// Sorted, exact duplicates removed.
pub(crate) fn sorted_unique(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// Response with the quoin held rigidly in `n` and `t` at every quoin node (a plausible quoin
/// reaction before the contact model exists): `P = −C⁻¹ u_w`.
#[derive(Debug, Clone)]
pub struct RigidQuoinResponse {
    /// Nodal quoin forces (lbf, `2m`, blocked `[normal; tangential]`).
    pub nodal_forces: Vec<f64>,
    /// Gauge strains (microstrain) under water plus those forces, from a full FE solve.
    pub strains: Vec<f64>,
    /// Quoin-node displacements (in, `2m`) of that solve (zero up to round-off).
    pub quoin_displacements: Vec<f64>,
}

impl GateModel {
    /// Condenses the gate to `nu` uniformly spaced quoin representation points over `[0, H]`
    /// (the paper uses `nu = 509`, [`DEFAULT_NU`]).
    ///
    /// ```
    /// use mitergate::{GateConfig, GateModel};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let cg = model.condense(51).unwrap();
    /// assert_eq!(cg.a_matrix.shape(), (7, 102));
    /// ```
    pub fn condense(&self, nu: usize) -> Result<CondensedGate, GateError> {
        condense(self, nu)
    }

    /// The response with the quoin held rigidly in `n` and `t` at all quoin nodes under water
    /// levels `(h_up, h_down)`: nodal forces `P = −C⁻¹ u_w` from the condensed gate, then a full
    /// FE solve under water plus `P` (which also checks the condensation: the quoin
    /// displacements of that solve vanish).
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let cg = model.condense(21).unwrap();
    /// let r = model.rigid_quoin_response(&cg, 744.0, 24.0).unwrap();
    /// let big = r.nodal_forces.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    /// assert!(big > 0.0);
    /// ```
    pub fn rigid_quoin_response(
        &self,
        cg: &CondensedGate,
        h_up: f64,
        h_down: f64,
    ) -> Result<RigidQuoinResponse, GateError> {
        check_levels(h_up, h_down)?;
        let uw = cg.water_quoin_displacement.eval_levels(h_up, h_down);
        let c = &cg.quoin_flexibility;
        let csym = (c + c.transpose()) * 0.5;
        let p = csym
            .clone()
            .cholesky()
            .map(|ch| ch.solve(&(-&uw)))
            .or_else(|| csym.lu().solve(&(-&uw)))
            .ok_or_else(|| GateError::DenseSolve("quoin flexibility C is singular".into()))?;
        let mut f = self.water_load(h_up, h_down)?;
        for (fi, qi) in f.iter_mut().zip(self.quoin_nodal_load(p.as_slice())?) {
            *fi += qi;
        }
        let u = self.solve(&f)?;
        Ok(RigidQuoinResponse {
            nodal_forces: p.iter().copied().collect(),
            strains: self.gauge_strains(&u),
            quoin_displacements: self.quoin_displacements(&u),
        })
    }
}

/// The condensation of any [`CondensationSource`] to `nu` uniformly spaced representation
/// points over `[0, H]`.
pub(crate) fn condense(
    src: &impl CondensationSource,
    nu: usize,
) -> Result<CondensedGate, GateError> {
    if nu < 2 {
        return Err(GateError::InvalidInput {
            what: "nu".into(),
            reason: format!("need at least 2 representation points, got {nu}"),
        });
    }
    let h = src.quoin_height();
    let nu_points: Vec<f64> = (0..nu).map(|b| h * b as f64 / (nu - 1) as f64).collect();
    let heights = src.quoin_node_heights();
    let m = heights.len();
    let gauges = src.gauge_functionals();
    let n_g = gauges.len();
    let fe = src.shell_model();
    // right-hand sides: 2m unit quoin loads, then one adjoint load per gauge
    let mut loads = src.quoin_unit_loads();
    if loads.len() != 2 * m {
        return Err(GateError::DimensionMismatch {
            what: "quoin unit loads (2 m)".into(),
            expected: 2 * m,
            got: loads.len(),
        });
    }
    let (gauge_names, gauge_terms): (Vec<String>, Vec<SparseLoad>) = gauges.into_iter().unzip();
    loads.extend(gauge_terms);
    let sol = fe.solve_sparse_loads(&loads);
    let reduced: Vec<SparseLoad> = loads.iter().map(|l| fe.reduce_sparse(l)).collect();
    let dot = |load: &[(usize, f64)], col: usize| {
        load.iter().map(|&(r, c)| c * sol[(r, col)]).sum::<f64>()
    };
    // C[i][j] = Q_iᵀ K⁻¹ Q_j
    let c = DMatrix::from_fn(2 * m, 2 * m, |i, j| dot(&reduced[i], j));
    // nodal gauge sensitivities G[g][j] = λ_gᵀ Q_j
    let g_nodal = DMatrix::from_fn(n_g, 2 * m, |g, j| dot(&reduced[j], 2 * m + g));
    let t = load_transfer(&heights, &nu_points)?;
    let mut a = DMatrix::zeros(n_g, 2 * nu);
    a.columns_mut(0, nu)
        .copy_from(&(g_nodal.columns(0, m) * &t));
    a.columns_mut(nu, nu)
        .copy_from(&(g_nodal.columns(m, m) * &t));
    let (water_strain, water_quoin) = water_tables(src, &sol, m, n_g)?;
    Ok(CondensedGate {
        quoin_height: h,
        quoin_node_heights: heights,
        quoin_flexibility: c,
        water_quoin_displacement: water_quoin,
        gauge_names,
        water_strain,
        nu_points,
        load_transfer: t,
        a_matrix: a,
    })
}

/// Hydrostatic tables of gauge strains (columns `2m..2m+n_g` of `sol`) and quoin
/// displacements (columns `0..2m`) at the water breakpoints.
fn water_tables(
    src: &impl CondensationSource,
    sol: &Mat<f64>,
    m: usize,
    n_g: usize,
) -> Result<(HydrostaticTable, HydrostaticTable), GateError> {
    let fe = src.shell_model();
    let bp = src.water_breakpoints();
    let nb = bp.len();
    let mut sv = DMatrix::zeros(nb, n_g);
    let mut ss = DMatrix::zeros(nb, n_g);
    let mut qv = DMatrix::zeros(nb, 2 * m);
    let mut qs = DMatrix::zeros(nb, 2 * m);
    for (k, &z) in bp.iter().enumerate() {
        for (deriv, strain, quoin) in [(false, &mut sv, &mut qv), (true, &mut ss, &mut qs)] {
            let f = fe.reduce_sparse(&src.upstream_water_load(z, deriv)?);
            let dot = |col: usize| f.iter().map(|&(r, c)| c * sol[(r, col)]).sum::<f64>();
            for g in 0..n_g {
                strain[(k, g)] = dot(2 * m + g);
            }
            for j in 0..2 * m {
                quoin[(k, j)] = dot(j);
            }
        }
    }
    Ok((
        HydrostaticTable::new(bp.clone(), sv, ss)?,
        HydrostaticTable::new(bp, qv, qs)?,
    ))
}
