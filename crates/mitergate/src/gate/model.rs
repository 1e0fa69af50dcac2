//! [`GateModel`]: the meshed leaf with its supports, factored stiffness, loads and gauges.

use super::config::{GateConfig, GaugeLocation};
use super::mesh::GateMesh;
use super::water::{check_levels, skin_pressure_loads};
use crate::error::GateError;
use crate::fe::loads::load_transfer;
use crate::fe::shell::ShellMaterial;
use crate::fe::{Reactions, ShellModel, Support, element_dofs};
use nalgebra::{DVector, Vector3};
use std::collections::BTreeMap;

/// A strain gauge as a linear functional of the full displacement vector.
#[derive(Debug, Clone)]
pub(crate) struct GaugeOperator {
    pub(crate) name: String,
    pub(crate) point: [f64; 3],
    /// `(full dof, microstrain per unit dof)`.
    pub(crate) terms: Vec<(usize, f64)>,
}

/// The finite-element miter gate leaf, assembled, supported and factored.
///
/// Supports (the leaf is stable without any quoin contact; contact forces enter as loads):
/// pintle at `(0, pivot_offset, 0)` fixes `ux, uy, uz`; gudgeon at `(0, pivot_offset, H)` fixes
/// `ux, uy`; every miter bearing-line node `(L, bearing_offset, z)` has the roller constraint
/// `u·m = 0`, `m = (cos φ, sin φ, 0)` the direction across the lock (the opposite leaf's
/// reaction by symmetry about the lock centre line).
///
/// ```
/// use mitergate::{GateConfig, GateModel};
/// let mut cfg = GateConfig::default();
/// cfg.mesh.element_size = 96.0;
/// let model = GateModel::build(&cfg).unwrap();
/// assert_eq!(model.n_dofs(), 6 * model.mesh().shell.nodes.len());
/// ```
#[derive(Debug)]
pub struct GateModel {
    config: GateConfig,
    mesh: GateMesh,
    fe: ShellModel,
    gauges: Vec<GaugeOperator>,
    quoin_n: [f64; 3],
    quoin_t: [f64; 3],
}

impl GateModel {
    /// Meshes the leaf, builds supports and gauges, assembles and factors the stiffness.
    ///
    /// ```
    /// use mitergate::{GateConfig, GateModel};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// assert!(GateModel::build(&cfg).is_ok());
    /// ```
    pub fn build(cfg: &GateConfig) -> Result<Self, GateError> {
        let mesh = GateMesh::build(cfg)?;
        let mut supports = vec![];
        for dof in 0..3 {
            supports.push(Support::Fixed {
                node: mesh.pintle_node,
                dof,
            });
        }
        for dof in 0..2 {
            supports.push(Support::Fixed {
                node: mesh.gudgeon_node,
                dof,
            });
        }
        let m = cfg.miter_direction();
        for &node in &mesh.miter_nodes {
            supports.push(Support::Roller { node, normal: m });
        }
        let material = ShellMaterial {
            youngs_modulus: cfg.material.youngs_modulus,
            poisson_ratio: cfg.material.poisson_ratio,
        };
        let fe = ShellModel::build(
            mesh.shell.clone(),
            material,
            cfg.mesh.drilling_penalty,
            supports,
        )?;
        let gauges = build_gauges(cfg, &fe)?;
        let (quoin_n, quoin_t) = cfg.quoin_directions();
        Ok(Self {
            config: cfg.clone(),
            mesh,
            fe,
            gauges,
            quoin_n,
            quoin_t,
        })
    }

    /// The configuration the model was built from.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert_eq!(model.config(), &cfg);
    /// ```
    pub fn config(&self) -> &GateConfig {
        &self.config
    }

    /// The mesh with its member tags and node sets.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert!(model.mesh().quoin_nodes.len() > 10);
    /// ```
    pub fn mesh(&self) -> &GateMesh {
        &self.mesh
    }

    /// The underlying assembled shell model.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert!(model.shell_model().n_reduced() < model.n_dofs());
    /// ```
    pub fn shell_model(&self) -> &ShellModel {
        &self.fe
    }

    /// Number of full DOFs (6 per node).
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert_eq!(model.n_dofs() % 6, 0);
    /// ```
    pub fn n_dofs(&self) -> usize {
        self.fe.n_dofs()
    }

    /// Gauge names, in output order.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert_eq!(model.gauge_names()[0], "SG1");
    /// ```
    pub fn gauge_names(&self) -> Vec<String> {
        self.gauges.iter().map(|g| g.name.clone()).collect()
    }

    /// Gauge points (in), in output order.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert_eq!(model.gauge_points()[0], [96.0, 30.0, 18.0]);
    /// ```
    pub fn gauge_points(&self) -> Vec<[f64; 3]> {
        self.gauges.iter().map(|g| g.point).collect()
    }

    /// Heights (in) of the quoin nodes.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// assert_eq!(model.quoin_heights()[0], 0.0);
    /// ```
    pub fn quoin_heights(&self) -> Vec<f64> {
        self.mesh.quoin_heights()
    }

    /// Solves `K u = f` for a full load vector (lbf, lbf·in); returns full displacements.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let u = model.solve(&model.water_load(700.0, 24.0).unwrap()).unwrap();
    /// assert_eq!(u.len(), model.n_dofs());
    /// ```
    pub fn solve(&self, f: &[f64]) -> Result<Vec<f64>, GateError> {
        self.fe.solve(f)
    }

    /// Consistent nodal loads (lbf) of upstream water at `h_up` and downstream water at
    /// `h_down` (in above the sill), both in [`WATER_LEVEL_RANGE`](super::WATER_LEVEL_RANGE)
    /// with `h_up >= h_down`.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let f = model.water_load(744.0, 24.0).unwrap();
    /// let fy: f64 = f.iter().skip(1).step_by(6).sum();
    /// let (g, l) = (0.0361, 696.0);
    /// assert!((fy - g * l * (744.0f64.powi(2) - 24.0f64.powi(2)) / 2.0).abs() < 1e-6 * fy);
    /// assert!(model.water_load(24.0, 744.0).is_err());
    /// ```
    pub fn water_load(&self, h_up: f64, h_down: f64) -> Result<Vec<f64>, GateError> {
        check_levels(h_up, h_down)?;
        let mut f = vec![0.0; self.n_dofs()];
        for (dof, v) in self.water_load_sparse(h_up, false)? {
            f[dof] += v;
        }
        for (dof, v) in self.water_load_sparse(h_down, false)? {
            f[dof] -= v;
        }
        Ok(f)
    }

    /// Upstream-face water at level `h` (or its derivative in `h`) as sparse nodal loads.
    pub(crate) fn water_load_sparse(
        &self,
        h: f64,
        derivative: bool,
    ) -> Result<Vec<(usize, f64)>, GateError> {
        skin_pressure_loads(
            &self.mesh.shell,
            &self.mesh.skin_elements(),
            self.config.water.unit_weight,
            h,
            derivative,
        )
    }

    /// Full nodal load vector (lbf) of quoin line loads `q` (lbf/in, length `2 N_u`, blocked
    /// `[normal; tangential]`) given at the increasing points `nu_points` (in), linear in
    /// between, through the consistent transfer of [`crate::fe::loads::load_transfer`].
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// // 100 lbf/in normal load over the full height
    /// let f = model.quoin_line_load(&[100.0, 100.0, 0.0, 0.0], &[0.0, 762.0]).unwrap();
    /// let fx: f64 = f.iter().step_by(6).sum();
    /// assert!((fx - 76_200.0).abs() < 1e-6);
    /// ```
    pub fn quoin_line_load(&self, q: &[f64], nu_points: &[f64]) -> Result<Vec<f64>, GateError> {
        let nu = nu_points.len();
        if q.len() != 2 * nu {
            return Err(GateError::DimensionMismatch {
                what: "quoin line loads q (2 N_u)".into(),
                expected: 2 * nu,
                got: q.len(),
            });
        }
        let t = load_transfer(&self.quoin_heights(), nu_points)?;
        let qn = DVector::from_column_slice(&q[..nu]);
        let qt = DVector::from_column_slice(&q[nu..]);
        let p: Vec<f64> = (&t * qn).iter().chain((&t * qt).iter()).copied().collect();
        self.quoin_nodal_load(&p)
    }

    /// Full nodal load vector of nodal quoin forces `p` (lbf, `2m`, blocked `[normal; tangential]`).
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let m = model.quoin_heights().len();
    /// let mut p = vec![0.0; 2 * m];
    /// p[m + 3] = 5.0; // 5 lbf tangential at quoin node 3
    /// let f = model.quoin_nodal_load(&p).unwrap();
    /// assert_eq!(f.iter().sum::<f64>(), 5.0);
    /// ```
    pub fn quoin_nodal_load(&self, p: &[f64]) -> Result<Vec<f64>, GateError> {
        let m = self.mesh.quoin_nodes.len();
        if p.len() != 2 * m {
            return Err(GateError::DimensionMismatch {
                what: "nodal quoin forces (2 m)".into(),
                expected: 2 * m,
                got: p.len(),
            });
        }
        let mut f = vec![0.0; self.n_dofs()];
        for (dof, v) in self
            .quoin_unit_loads()
            .iter()
            .zip(p)
            .flat_map(|(load, &s)| load.iter().map(move |&(d, c)| (d, c * s)))
        {
            f[dof] += v;
        }
        Ok(f)
    }

    /// Unit nodal loads along `n` (first `m`) and `t` (next `m`) at the quoin nodes.
    pub(crate) fn quoin_unit_loads(&self) -> Vec<Vec<(usize, f64)>> {
        let unit = |dir: [f64; 3]| {
            self.mesh.quoin_nodes.iter().map(move |&n| {
                (0..3)
                    .filter(|&k| dir[k] != 0.0)
                    .map(|k| (6 * n + k, dir[k]))
                    .collect::<Vec<_>>()
            })
        };
        unit(self.quoin_n).chain(unit(self.quoin_t)).collect()
    }

    /// Gauge strains (microstrain) of full displacements `u`.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let zero = model.gauge_strains(&vec![0.0; model.n_dofs()]);
    /// assert!(zero.iter().all(|&e| e == 0.0));
    /// ```
    pub fn gauge_strains(&self, u: &[f64]) -> Vec<f64> {
        self.gauges
            .iter()
            .map(|g| {
                g.terms
                    .iter()
                    .map(|&(d, c)| c * u.get(d).copied().unwrap_or(0.0))
                    .sum()
            })
            .collect()
    }

    /// Quoin-node displacements (in, `2m`, blocked `[along n; along t]`) of full displacements.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let d = model.quoin_displacements(&vec![0.0; model.n_dofs()]);
    /// assert_eq!(d.len(), 2 * model.quoin_heights().len());
    /// ```
    pub fn quoin_displacements(&self, u: &[f64]) -> Vec<f64> {
        self.quoin_unit_loads()
            .iter()
            .map(|load| {
                load.iter()
                    .map(|&(d, c)| c * u.get(d).copied().unwrap_or(0.0))
                    .sum()
            })
            .collect()
    }

    /// Support reactions (pintle, gudgeon, miter bearing) of displacements `u`: `K u` at the
    /// supported nodes (no load is ever applied at those nodes: they lie off the skin plate and
    /// off the quoin bearing line), with resultants for equilibrium checks.
    ///
    /// ```
    /// # use mitergate::{GateConfig, GateModel};
    /// # let mut cfg = GateConfig::default(); cfg.mesh.element_size = 96.0;
    /// let model = GateModel::build(&cfg).unwrap();
    /// let f = model.water_load(500.0, 100.0).unwrap();
    /// let r = model.reactions(&model.solve(&f).unwrap());
    /// let fy: f64 = f.iter().skip(1).step_by(6).sum();
    /// assert!((r.total_force[1] + fy).abs() < 1e-6 * fy);
    /// ```
    pub fn reactions(&self, u: &[f64]) -> Reactions {
        self.fe.reactions(u, &[])
    }

    pub(crate) fn gauges(&self) -> &[GaugeOperator] {
        &self.gauges
    }

    pub(crate) fn fe(&self) -> &ShellModel {
        &self.fe
    }
}

fn build_gauges(cfg: &GateConfig, fe: &ShellModel) -> Result<Vec<GaugeOperator>, GateError> {
    cfg.gauges
        .iter()
        .map(|spec| {
            let (point, side) = match &spec.location {
                GaugeLocation::GirderWeb { girder_web, x, y } => {
                    ([*x, *y, cfg.girders.heights[*girder_web]], [0.0, 0.0, 1.0])
                }
                GaugeLocation::GirderFlange { girder, x } => (
                    [*x, cfg.geometry.depth, cfg.girders.heights[*girder]],
                    [0.0, 1.0, 0.0],
                ),
                GaugeLocation::Point { point, side } => (*point, *side),
            };
            let terms = gauge_terms(fe, point, side, spec.direction).ok_or_else(|| {
                GateError::GaugeNotOnMesh {
                    name: spec.name.clone(),
                    point,
                    side,
                }
            })?;
            Ok(GaugeOperator {
                name: spec.name.clone(),
                point,
                terms,
            })
        })
        .collect()
}

/// Strain functional of a gauge: the average over every element whose plane contains the
/// point, whose normal is parallel to `side`, and which contains the point (a point on an
/// element edge gets the mean of the elements sharing it).
fn gauge_terms(
    fe: &ShellModel,
    point: [f64; 3],
    side: [f64; 3],
    dir: [f64; 3],
) -> Option<Vec<(usize, f64)>> {
    let s = Vector3::from(side).normalize();
    let d = Vector3::from(dir).normalize();
    let mut acc: BTreeMap<usize, f64> = BTreeMap::new();
    let mut count = 0usize;
    for (el, quad) in fe.mesh().elements.iter().zip(fe.quads()) {
        let nrm = Vector3::from(quad.normal());
        let along = nrm.dot(&s);
        if along.abs() < 0.99 || d.dot(&nrm).abs() > 1e-6 {
            continue;
        }
        let (xi, eta, dist) = quad.natural_coordinates(point);
        let size = quad.area().sqrt();
        if dist.abs() > 1e-6 * size || xi.abs() > 1.0 + 1e-9 || eta.abs() > 1.0 + 1e-9 {
            continue;
        }
        let zeta = 0.5 * quad.thickness() * along.signum();
        let op = quad.strain_operator(xi, eta, zeta, dir);
        for (a, &dof) in element_dofs(el).iter().enumerate() {
            *acc.entry(dof).or_insert(0.0) += op[a];
        }
        count += 1;
    }
    (count > 0).then(|| {
        acc.into_iter()
            .map(|(k, v)| (k, v / count as f64))
            .collect()
    })
}
