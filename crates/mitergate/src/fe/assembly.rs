//! The assembled shell model: element operators, sparse stiffness `Gᵀ K G` (the supports of
//! [`super::supports`] imposed), the supernodal Cholesky factorisation of `faer`, solves and
//! reactions.
//!
//! The reduced stiffness is symmetric positive definite for a properly supported structure and
//! is factored once with a fill-reducing (AMD) ordering; every later solve reuses the factor.

use super::DOF_NAMES;
use super::shell::{Mat24, ShellMaterial, ShellQuad, Vec24};
use super::supports::{DofMap, Support, check_rigid_modes, support_map};
use crate::error::GateError;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, MatMut, Par, Side};
use nalgebra::Vector3;

/// A four-node shell element of a [`ShellMesh`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct QuadElement {
    /// Node indices, counter-clockwise about the element normal.
    pub nodes: [usize; 4],
    /// Thickness (in).
    pub thickness: f64,
}

/// Nodes (in) and shell elements.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShellMesh {
    /// Node coordinates (in).
    pub nodes: Vec<[f64; 3]>,
    /// Elements.
    pub elements: Vec<QuadElement>,
}

/// An element given directly by its global stiffness (6 DOFs per node `[ux, uy, uz, rx, ry,
/// rz]`, node by node), assembled into a [`ShellModel`] next to the shell quadrilaterals: the
/// beams ([`super::beam`]) and shell triangles ([`super::tri`]) of imported decks.
///
/// ```
/// use mitergate::fe::GeneralElement;
/// use nalgebra::DMatrix;
/// // an axial spring of 10 lbf/in along x between nodes 0 and 1
/// let mut k = DMatrix::zeros(12, 12);
/// k[(0, 0)] = 10.0; k[(6, 6)] = 10.0; k[(0, 6)] = -10.0; k[(6, 0)] = -10.0;
/// let e = GeneralElement::new(vec![0, 1], k).unwrap();
/// assert_eq!(e.nodes(), &[0, 1]);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct GeneralElement {
    nodes: Vec<usize>,
    stiffness: nalgebra::DMatrix<f64>,
}

impl GeneralElement {
    /// `stiffness` must be square of size `6 * nodes.len()`, finite and symmetric (to 1e-9
    /// of its largest entry).
    ///
    /// ```
    /// use mitergate::fe::GeneralElement;
    /// assert!(GeneralElement::new(vec![0, 1], nalgebra::DMatrix::zeros(6, 6)).is_err());
    /// ```
    pub fn new(nodes: Vec<usize>, stiffness: nalgebra::DMatrix<f64>) -> Result<Self, GateError> {
        let n = 6 * nodes.len();
        if stiffness.shape() != (n, n) {
            return Err(GateError::DimensionMismatch {
                what: "general element stiffness (6 x nodes per side)".into(),
                expected: n,
                got: stiffness.nrows(),
            });
        }
        let scale = stiffness.amax();
        let asym = (&stiffness - stiffness.transpose()).amax();
        if !(scale.is_finite() && asym <= 1e-9 * scale) {
            return Err(GateError::InvalidMesh(format!(
                "general element on nodes {nodes:?}: stiffness is not finite and symmetric \
                 (max |K - Kᵀ| = {asym:e}, max |K| = {scale:e})"
            )));
        }
        Ok(Self { nodes, stiffness })
    }

    /// Node indices.
    ///
    /// ```
    /// # use mitergate::fe::GeneralElement;
    /// let e = GeneralElement::new(vec![3], nalgebra::DMatrix::zeros(6, 6)).unwrap();
    /// assert_eq!(e.nodes(), &[3]);
    /// ```
    pub fn nodes(&self) -> &[usize] {
        &self.nodes
    }

    /// Global stiffness (`6n x 6n`).
    ///
    /// ```
    /// # use mitergate::fe::GeneralElement;
    /// let e = GeneralElement::new(vec![3], nalgebra::DMatrix::identity(6, 6)).unwrap();
    /// assert_eq!(e.stiffness()[(5, 5)], 1.0);
    /// ```
    pub fn stiffness(&self) -> &nalgebra::DMatrix<f64> {
        &self.stiffness
    }

    fn dofs(&self) -> impl Iterator<Item = usize> + '_ {
        self.nodes
            .iter()
            .flat_map(|&n| (0..6).map(move |k| 6 * n + k))
    }
}

/// Support reactions (forces the supports exert on the structure): per supported node the
/// six generalised forces (lbf, lbf·in), and the totals.
#[derive(Debug, Clone, PartialEq)]
pub struct Reactions {
    /// `(node, [Fx, Fy, Fz, Mx, My, Mz])` for every supported node.
    pub nodal: Vec<(usize, [f64; 6])>,
    /// Sum of the reaction forces (lbf).
    pub total_force: [f64; 3],
    /// Sum of the reaction moments about the origin (lbf·in), including `r × F`.
    pub total_moment: [f64; 3],
}

/// Assembled, supported and factored shell model.
#[derive(Debug)]
pub struct ShellModel {
    mesh: ShellMesh,
    quads: Vec<ShellQuad>,
    general: Vec<GeneralElement>,
    supports: Vec<Support>,
    map: DofMap,
    symbolic: SymbolicCholesky<usize>,
    factor: Vec<f64>,
    /// Reduced-DOF `(node, dof)` for error messages.
    reduced_owner: Vec<(usize, usize)>,
}

impl ShellModel {
    /// Builds element operators, the support map, assembles `Gᵀ K G` and factors it.
    ///
    /// ```
    /// use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// use mitergate::fe::shell::ShellMaterial;
    /// // one square plate element clamped along the edge x = 0
    /// let mesh = ShellMesh {
    ///     nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    ///     elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }],
    /// };
    /// let supports: Vec<Support> = [0, 3].iter()
    ///     .flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, supports).unwrap();
    /// assert_eq!(model.n_dofs(), 24);
    /// ```
    pub fn build(
        mesh: ShellMesh,
        material: ShellMaterial,
        drilling_penalty: f64,
        supports: Vec<Support>,
    ) -> Result<Self, GateError> {
        Self::build_with_elements(mesh, material, drilling_penalty, supports, Vec::new())
    }

    /// As [`ShellModel::build`], with further elements given by their global stiffness
    /// (beams, triangles) assembled into the same sparse system.
    ///
    /// ```
    /// use mitergate::fe::{GeneralElement, ShellMesh, ShellModel, Support};
    /// use mitergate::fe::shell::ShellMaterial;
    /// // two nodes joined only by a general element (a 6-DOF spring of 1e3 per DOF)
    /// let mesh = ShellMesh { nodes: vec![[0., 0., 0.], [1., 0., 0.]], elements: vec![] };
    /// let mut k = nalgebra::DMatrix::zeros(12, 12);
    /// for i in 0..6 {
    ///     k[(i, i)] = 1e3; k[(i + 6, i + 6)] = 1e3; k[(i, i + 6)] = -1e3; k[(i + 6, i)] = -1e3;
    /// }
    /// let spring = GeneralElement::new(vec![0, 1], k).unwrap();
    /// let fixed = (0..6).map(|dof| Support::Fixed { node: 0, dof }).collect();
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build_with_elements(mesh, m, 1e-3, fixed, vec![spring]).unwrap();
    /// let mut f = vec![0.0; 12];
    /// f[8] = 2.0;
    /// assert!((model.solve(&f).unwrap()[8] - 2e-3).abs() < 1e-15);
    /// ```
    pub fn build_with_elements(
        mesh: ShellMesh,
        material: ShellMaterial,
        drilling_penalty: f64,
        supports: Vec<Support>,
        general: Vec<GeneralElement>,
    ) -> Result<Self, GateError> {
        let quads = element_operators(&mesh, material, drilling_penalty)?;
        for (i, g) in general.iter().enumerate() {
            if let Some(&n) = g.nodes.iter().find(|&&n| n >= mesh.nodes.len()) {
                return Err(GateError::InvalidMesh(format!(
                    "general element {i} refers to node {n} but the mesh has {} nodes",
                    mesh.nodes.len()
                )));
            }
        }
        let map = support_map(&mesh, &supports)?;
        check_rigid_modes(&mesh, &supports)?;
        let mut reduced_owner = vec![(0, 0); map.n_reduced];
        for dof in 0..mesh.nodes.len() * 6 {
            for &(r, _) in map.row(dof) {
                reduced_owner[r] = (dof / 6, dof % 6);
            }
        }
        let k = assemble_reduced(&mesh, &quads, &general, &map)?;
        check_diagonal(&k, &reduced_owner, &mesh)?;
        let symbolic = factorize_symbolic_cholesky(
            k.symbolic(),
            Side::Upper,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .map_err(|e| GateError::Sparse(format!("symbolic Cholesky: {e:?}")))?;
        let factor = factor_numeric(&symbolic, &k, &reduced_owner, &mesh)?;
        Ok(Self {
            mesh,
            quads,
            general,
            supports,
            map,
            symbolic,
            factor,
            reduced_owner,
        })
    }

    /// Number of full DOFs (6 per node).
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// assert_eq!(model.n_dofs(), 24);
    /// assert_eq!(model.n_reduced(), 12);
    /// ```
    pub fn n_dofs(&self) -> usize {
        self.mesh.nodes.len() * 6
    }

    /// Number of unknowns after the supports are imposed.
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// assert_eq!(model.n_reduced(), 12);
    /// ```
    pub fn n_reduced(&self) -> usize {
        self.map.n_reduced
    }

    /// The mesh.
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// assert_eq!(model.mesh().elements.len(), 1);
    /// ```
    pub fn mesh(&self) -> &ShellMesh {
        &self.mesh
    }

    /// Element operators (frames, stiffness, strain recovery), one per mesh element.
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// assert!((model.quads()[0].area() - 1.0).abs() < 1e-12);
    /// ```
    pub fn quads(&self) -> &[ShellQuad] {
        &self.quads
    }

    /// The supports the model was built with.
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// assert_eq!(model.supports().len(), 12);
    /// ```
    pub fn supports(&self) -> &[Support] {
        &self.supports
    }

    /// The elements given by their global stiffness (see [`ShellModel::build_with_elements`]).
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// assert!(model.general_elements().is_empty());
    /// ```
    pub fn general_elements(&self) -> &[GeneralElement] {
        &self.general
    }

    /// Maps a full load vector to the reduced unknowns: `Gᵀ f`.
    fn reduce(&self, f: &[f64], out: &mut [f64]) {
        out.iter_mut().for_each(|v| *v = 0.0);
        for (dof, &fv) in f.iter().enumerate() {
            if fv != 0.0 {
                for &(r, c) in self.map.row(dof) {
                    out[r] += c * fv;
                }
            }
        }
    }

    /// Maps reduced unknowns to full DOFs: `G ũ`.
    fn expand(&self, u_red: &[f64]) -> Vec<f64> {
        (0..self.n_dofs())
            .map(|dof| self.map.row(dof).iter().map(|&(r, c)| c * u_red[r]).sum())
            .collect()
    }

    /// Solves `K u = f` (full DOFs; loads on supported DOFs go to the supports).
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// let mut f = vec![0.0; 24];
    /// f[6 * 1 + 2] = 1.0; // tip loads along z
    /// f[6 * 2 + 2] = 1.0;
    /// let u = model.solve(&f).unwrap();
    /// assert!(u[6 * 1 + 2] > 0.0);
    /// ```
    pub fn solve(&self, f: &[f64]) -> Result<Vec<f64>, GateError> {
        if f.len() != self.n_dofs() {
            return Err(GateError::DimensionMismatch {
                what: "load vector f".into(),
                expected: self.n_dofs(),
                got: f.len(),
            });
        }
        if let Some(i) = f.iter().position(|v| !v.is_finite()) {
            return Err(GateError::InvalidInput {
                what: format!("load vector f[{i}]"),
                reason: "not finite".into(),
            });
        }
        let mut rhs = Mat::<f64>::zeros(self.n_reduced(), 1);
        let mut col = vec![0.0; self.n_reduced()];
        self.reduce(f, &mut col);
        for (i, v) in col.iter().enumerate() {
            rhs[(i, 0)] = *v;
        }
        self.solve_reduced_in_place(rhs.as_mut());
        let u_red: Vec<f64> = (0..self.n_reduced()).map(|i| rhs[(i, 0)]).collect();
        Ok(self.expand(&u_red))
    }

    /// Solves `(Gᵀ K G) X = B` in place for several right-hand sides (reduced unknowns).
    pub(crate) fn solve_reduced_in_place(&self, rhs: MatMut<'_, f64>) {
        let par = Par::Seq;
        let ncols = rhs.ncols();
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, par));
        LltRef::<'_, usize, f64>::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            rhs,
            par,
            MemStack::new(&mut mem),
        );
    }

    /// Solves for many full load vectors given sparsely, returning the reduced solutions as
    /// columns. `loads[j]` lists `(full dof, value)` pairs.
    pub(crate) fn solve_sparse_loads(&self, loads: &[Vec<(usize, f64)>]) -> Mat<f64> {
        let mut rhs = Mat::<f64>::zeros(self.n_reduced(), loads.len());
        for (j, load) in loads.iter().enumerate() {
            for &(dof, v) in load {
                for &(r, c) in self.map.row(dof) {
                    rhs[(r, j)] += c * v;
                }
            }
        }
        self.solve_reduced_in_place(rhs.as_mut());
        rhs
    }

    /// `Gᵀ` applied to a sparse full vector, as a sparse reduced vector.
    pub(crate) fn reduce_sparse(&self, load: &[(usize, f64)]) -> Vec<(usize, f64)> {
        let mut out = Vec::with_capacity(load.len());
        for &(dof, v) in load {
            for &(r, c) in self.map.row(dof) {
                out.push((r, c * v));
            }
        }
        out
    }

    /// `K u` with the unsupported stiffness (full DOFs).
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// let u = vec![1.0; 24].iter().enumerate().map(|(i, _)| if i % 6 == 0 { 1.0 } else { 0.0 }).collect::<Vec<_>>();
    /// let ku = model.apply_stiffness(&u); // rigid translation: no forces
    /// assert!(ku.iter().all(|v| v.abs() < 1e-6));
    /// ```
    pub fn apply_stiffness(&self, u: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_dofs()];
        for (el, quad) in self.mesh.elements.iter().zip(&self.quads) {
            let k: Mat24 = quad.stiffness();
            let dofs = element_dofs(el);
            let ue = Vec24::from_iterator(dofs.iter().map(|&d| u[d]));
            let fe = k * ue;
            for (a, &d) in dofs.iter().enumerate() {
                out[d] += fe[a];
            }
        }
        for g in &self.general {
            let dofs: Vec<usize> = g.dofs().collect();
            for (a, &da) in dofs.iter().enumerate() {
                out[da] += dofs
                    .iter()
                    .enumerate()
                    .map(|(b, &db)| g.stiffness[(a, b)] * u[db])
                    .sum::<f64>();
            }
        }
        out
    }

    /// Support reactions `K u − f` at the supported nodes and their resultants.
    ///
    /// ```
    /// # use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # let mesh = ShellMesh { nodes: vec![[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]],
    /// #   elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.1 }] };
    /// # let s: Vec<Support> = [0, 3].iter().flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof })).collect();
    /// # let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let model = ShellModel::build(mesh, m, 1e-3, s).unwrap();
    /// let mut f = vec![0.0; 24];
    /// f[6 + 2] = 3.0;
    /// let u = model.solve(&f).unwrap();
    /// let r = model.reactions(&u, &f);
    /// assert!((r.total_force[2] + 3.0).abs() < 1e-8);
    /// ```
    pub fn reactions(&self, u: &[f64], f: &[f64]) -> Reactions {
        let ku = self.apply_stiffness(u);
        let mut nodes: Vec<usize> = self
            .supports
            .iter()
            .map(|s| match *s {
                Support::Fixed { node, .. } | Support::Roller { node, .. } => node,
            })
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        let mut total_force = Vector3::zeros();
        let mut total_moment = Vector3::zeros();
        let nodal = nodes
            .into_iter()
            .map(|n| {
                let r: [f64; 6] = std::array::from_fn(|k| {
                    ku[6 * n + k] - f.get(6 * n + k).copied().unwrap_or(0.0)
                });
                let force = Vector3::new(r[0], r[1], r[2]);
                total_force += force;
                total_moment += Vector3::from(self.mesh.nodes[n]).cross(&force)
                    + Vector3::new(r[3], r[4], r[5]);
                (n, r)
            })
            .collect();
        Reactions {
            nodal,
            total_force: total_force.into(),
            total_moment: total_moment.into(),
        }
    }

    /// Describes reduced DOF `r` as `(node, dof name, position)`.
    #[allow(dead_code)]
    pub(crate) fn describe_reduced(&self, r: usize) -> (usize, &'static str, [f64; 3]) {
        let (n, d) = self.reduced_owner[r];
        (n, DOF_NAMES[d], self.mesh.nodes[n])
    }
}

/// Full DOF indices of an element, node by node.
pub(crate) fn element_dofs(el: &QuadElement) -> [usize; 24] {
    std::array::from_fn(|a| 6 * el.nodes[a / 6] + a % 6)
}

fn element_operators(
    mesh: &ShellMesh,
    material: ShellMaterial,
    drilling_penalty: f64,
) -> Result<Vec<ShellQuad>, GateError> {
    mesh.elements
        .iter()
        .enumerate()
        .map(|(i, el)| {
            if let Some(&n) = el.nodes.iter().find(|&&n| n >= mesh.nodes.len()) {
                return Err(GateError::InvalidMesh(format!(
                    "element {i} refers to node {n} but the mesh has {} nodes",
                    mesh.nodes.len()
                )));
            }
            let coords = el.nodes.map(|n| mesh.nodes[n]);
            ShellQuad::new(&coords, el.thickness, material, drilling_penalty)
                .map_err(|e| GateError::InvalidMesh(format!("element {i}: {e}")))
        })
        .collect()
}

fn assemble_reduced(
    mesh: &ShellMesh,
    quads: &[ShellQuad],
    general: &[GeneralElement],
    map: &DofMap,
) -> Result<SparseColMat<usize, f64>, GateError> {
    let mut trip: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(mesh.elements.len() * 300);
    for (el, quad) in mesh.elements.iter().zip(quads) {
        let k = quad.stiffness();
        let dofs = element_dofs(el);
        for a in 0..24 {
            for &(ra, ca) in map.row(dofs[a]) {
                for b in 0..24 {
                    for &(rb, cb) in map.row(dofs[b]) {
                        if ra <= rb {
                            trip.push(Triplet::new(ra, rb, ca * cb * k[(a, b)]));
                        }
                    }
                }
            }
        }
    }
    for g in general {
        let dofs: Vec<usize> = g.dofs().collect();
        for (a, &da) in dofs.iter().enumerate() {
            for &(ra, ca) in map.row(da) {
                for (b, &db) in dofs.iter().enumerate() {
                    for &(rb, cb) in map.row(db) {
                        if ra <= rb {
                            trip.push(Triplet::new(ra, rb, ca * cb * g.stiffness[(a, b)]));
                        }
                    }
                }
            }
        }
    }
    SparseColMat::try_new_from_triplets(map.n_reduced, map.n_reduced, &trip)
        .map_err(|e| GateError::Sparse(format!("assembly: {e:?}")))
}

fn check_diagonal(
    k: &SparseColMat<usize, f64>,
    owner: &[(usize, usize)],
    mesh: &ShellMesh,
) -> Result<(), GateError> {
    let kr = k.as_ref();
    let mut scale = 0.0f64;
    let mut diag = vec![0.0; k.ncols()];
    for j in 0..k.ncols() {
        for (i, v) in kr.row_idx_of_col(j).zip(kr.val_of_col(j)) {
            if i == j {
                diag[j] = *v;
                scale = scale.max(v.abs());
            }
        }
    }
    for (j, &d) in diag.iter().enumerate() {
        if !(d > 1e-14 * scale) {
            let (node, dof) = owner[j];
            return Err(GateError::UnconnectedDof {
                node,
                dof: DOF_NAMES[dof],
                position: mesh.nodes[node],
            });
        }
    }
    Ok(())
}

fn factor_numeric(
    symbolic: &SymbolicCholesky<usize>,
    k: &SparseColMat<usize, f64>,
    owner: &[(usize, usize)],
    mesh: &ShellMesh,
) -> Result<Vec<f64>, GateError> {
    let par = Par::Seq;
    let mut values = vec![0.0; symbolic.len_val()];
    let mut mem =
        MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
    let res = symbolic.factorize_numeric_llt::<f64>(
        &mut values,
        k.as_ref(),
        Side::Upper,
        LltRegularization::default(),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    );
    match res {
        Ok(_) => Ok(values),
        Err(LltError::NonPositivePivot { index }) => {
            let original = symbolic
                .perm()
                .map(|p| p.arrays().0[index])
                .unwrap_or(index);
            let (node, dof) = owner[original];
            Err(GateError::NotPositiveDefinite {
                node,
                dof: DOF_NAMES[dof],
                position: mesh.nodes[node],
            })
        }
    }
}
