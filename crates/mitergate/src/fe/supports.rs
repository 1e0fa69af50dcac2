//! Supports imposed exactly by a linear change of variables `u = G ũ`: every full DOF is a
//! combination of the reduced DOFs `ũ`. A fixed DOF has an empty row of `G`; a roller node
//! (translation normal to a plane blocked, `u·m = 0`) keeps two translational unknowns along
//! an orthonormal basis of the plane. Supports that leave a rigid-body mode free are rejected
//! before any assembly, naming the mode.

use super::assembly::ShellMesh;
use crate::error::GateError;
use nalgebra::{Matrix6, SymmetricEigen, Vector3};

/// A support condition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Support {
    /// One DOF (0..6 = `ux, uy, uz, rx, ry, rz`) of a node fixed to zero.
    Fixed {
        /// Node index.
        node: usize,
        /// DOF index 0..6.
        dof: usize,
    },
    /// Translation of a node along the unit vector `normal` blocked (`u·normal = 0`).
    Roller {
        /// Node index.
        node: usize,
        /// Blocked direction.
        normal: [f64; 3],
    },
}

/// The support map `u = G ũ`, stored by full-DOF rows.
#[derive(Debug, Clone)]
pub(super) struct DofMap {
    offsets: Vec<usize>,
    terms: Vec<(usize, f64)>,
    /// Number of reduced unknowns `ũ`.
    pub(super) n_reduced: usize,
}

impl DofMap {
    /// Row `dof` of `G`: `(reduced unknown, coefficient)` pairs.
    pub(super) fn row(&self, dof: usize) -> &[(usize, f64)] {
        &self.terms[self.offsets[dof]..self.offsets[dof + 1]]
    }

    /// Appends one row per DOF: a new reduced unknown for each free DOF, an empty row for each
    /// fixed one.
    fn push_free(&mut self, fixed: &[bool]) {
        for &f in fixed {
            if !f {
                self.terms.push((self.n_reduced, 1.0));
                self.n_reduced += 1;
            }
            self.offsets.push(self.terms.len());
        }
    }

    /// Appends the three translation rows of a roller node with unit normal `m`: two new
    /// unknowns along an orthonormal basis `(a, b)` of the plane normal to `m`.
    fn push_roller(&mut self, m: Vector3<f64>) {
        let trial = if m.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let a = (trial - m * trial.dot(&m)).normalize();
        let b = m.cross(&a);
        let (ra, rb) = (self.n_reduced, self.n_reduced + 1);
        self.n_reduced += 2;
        for k in 0..3 {
            for (r, c) in [(ra, a[k]), (rb, b[k])] {
                if c.abs() > 1e-15 {
                    self.terms.push((r, c));
                }
            }
            self.offsets.push(self.terms.len());
        }
    }
}

/// Fixed DOFs (6 flags per node) and unit roller normals (per node) of a support list.
type SupportFlags = (Vec<bool>, Vec<Option<Vector3<f64>>>);

/// Reads the support list into [`SupportFlags`], rejecting out-of-range nodes and DOFs and
/// zero roller normals.
fn support_flags(n_nodes: usize, supports: &[Support]) -> Result<SupportFlags, GateError> {
    let mut fixed = vec![false; n_nodes * 6];
    let mut roller: Vec<Option<Vector3<f64>>> = vec![None; n_nodes];
    for s in supports {
        match *s {
            Support::Fixed { node, dof } => {
                if node >= n_nodes || dof >= 6 {
                    return Err(GateError::InvalidInput {
                        what: "support".into(),
                        reason: format!("fixed support node {node} dof {dof} out of range"),
                    });
                }
                fixed[6 * node + dof] = true;
            }
            Support::Roller { node, normal } => {
                let m = Vector3::from(normal);
                if node >= n_nodes || !(m.norm() > 0.0) {
                    return Err(GateError::InvalidInput {
                        what: "support".into(),
                        reason: format!("roller at node {node} with normal {normal:?} is invalid"),
                    });
                }
                roller[node] = Some(m.normalize());
            }
        }
    }
    Ok((fixed, roller))
}

/// The support map `G` of `supports` on `mesh` (reduced unknowns numbered node by node).
pub(super) fn support_map(mesh: &ShellMesh, supports: &[Support]) -> Result<DofMap, GateError> {
    let n_nodes = mesh.nodes.len();
    let (fixed, roller) = support_flags(n_nodes, supports)?;
    let mut map = DofMap {
        offsets: vec![0],
        terms: Vec::with_capacity(n_nodes * 6),
        n_reduced: 0,
    };
    for node in 0..n_nodes {
        let flags = &fixed[6 * node..6 * node + 6];
        match roller[node] {
            Some(_) if flags[..3].iter().any(|&f| f) => {
                return Err(GateError::InvalidInput {
                    what: "support".into(),
                    reason: format!("node {node} has both a roller and fixed translations"),
                });
            }
            Some(m) => map.push_roller(m),
            None => map.push_free(&flags[..3]),
        }
        map.push_free(&flags[3..]);
    }
    Ok(map)
}

/// Rejects supports that leave a rigid-body motion of the whole mesh free, naming the mode.
pub(super) fn check_rigid_modes(mesh: &ShellMesh, supports: &[Support]) -> Result<(), GateError> {
    let n = mesh.nodes.len().max(1) as f64;
    let c: Vector3<f64> = mesh
        .nodes
        .iter()
        .map(|p| Vector3::from(*p))
        .sum::<Vector3<f64>>()
        / n;
    let size = mesh
        .nodes
        .iter()
        .map(|p| (Vector3::from(*p) - c).norm())
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    // value of the 6 rigid modes (3 translations, 3 rotations about c scaled by size) at a DOF
    let mode_dof = |node: usize, dir: Vector3<f64>, rot: Vector3<f64>| -> [f64; 6] {
        let r = (Vector3::from(mesh.nodes[node]) - c) / size;
        std::array::from_fn(|k| {
            if k < 3 {
                dir[k]
            } else {
                let mut e = Vector3::zeros();
                e[k - 3] = 1.0;
                e.cross(&r).dot(&dir) + e.dot(&rot)
            }
        })
    };
    let mut gram = Matrix6::<f64>::zeros();
    for s in supports {
        let row = match *s {
            Support::Fixed { node, dof } if dof < 3 => {
                let mut d = Vector3::zeros();
                d[dof] = 1.0;
                mode_dof(node, d, Vector3::zeros())
            }
            Support::Fixed { node, dof } => {
                let mut d = Vector3::zeros();
                d[dof - 3] = 1.0;
                mode_dof(node, Vector3::zeros(), d)
            }
            Support::Roller { node, normal } => {
                mode_dof(node, Vector3::from(normal).normalize(), Vector3::zeros())
            }
        };
        let v = nalgebra::Vector6::from(row);
        gram += v * v.transpose();
    }
    let eig = SymmetricEigen::new(gram);
    let (imin, &lmin) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .expect("6 eigenvalues");
    let lmax = eig.eigenvalues.max();
    if lmin <= 1e-10 * lmax.max(1.0) {
        let v = eig.eigenvectors.column(imin);
        let names = ["tx", "ty", "tz", "rx", "ry", "rz"];
        let mode = names
            .iter()
            .zip(v.iter())
            .filter(|(_, c)| c.abs() > 1e-6)
            .map(|(n, c)| format!("{c:+.3} {n}"))
            .collect::<Vec<_>>()
            .join(" ");
        return Err(GateError::UnrestrainedRigidMode { mode });
    }
    Ok(())
}
