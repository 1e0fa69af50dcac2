//! Structured shell mesh of the gate leaf.
//!
//! All plates of the leaf lie in coordinate planes of the leaf frame, so the mesh is built on
//! one global grid: the `x`, `y` and `z` grid lines contain every structural line (leaf ends,
//! diaphragms, bearing-web edges; skin plate, bearing line, pivot axis, flanges; girder webs
//! and flange edges, sill and top), and every interval between them is divided into
//! `ceil(length / element_size)` equal parts. Plates sharing a grid line share its nodes, so the
//! mesh is conforming without any merging tolerance.

use super::config::GateConfig;
use crate::error::GateError;
use crate::fe::{QuadElement, ShellMesh};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The structural member an element belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Member {
    /// Upstream skin plate (`y = 0`).
    Skin,
    /// Web of girder `i` (plane `z = z_i`).
    GirderWeb(usize),
    /// Downstream flange of girder `i` (plane `y = depth`).
    GirderFlange(usize),
    /// Interior diaphragm `j` (plane `x = x_j`).
    Diaphragm(usize),
    /// Quoin end plate (`x = 0`).
    QuoinPlate,
    /// Miter end plate (`x = L`).
    MiterPlate,
    /// Quoin bearing web (`y = bearing_offset`, `0 <= x <= w`).
    QuoinBearingWeb,
    /// Miter bearing web (`y = bearing_offset`, `L - w <= x <= L`).
    MiterBearingWeb,
}

/// The meshed leaf: shell mesh, member tags and the node sets the model needs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GateMesh {
    /// Nodes and elements.
    pub shell: ShellMesh,
    /// Member of each element.
    pub members: Vec<Member>,
    /// Quoin bearing-line nodes (`x = 0`, `y = bearing_offset`), sorted by height.
    pub quoin_nodes: Vec<usize>,
    /// Miter bearing-line nodes (`x = L`, `y = bearing_offset`), sorted by height.
    pub miter_nodes: Vec<usize>,
    /// Pintle node (`x = 0`, `y = pivot_offset`, `z = 0`).
    pub pintle_node: usize,
    /// Gudgeon node (`x = 0`, `y = pivot_offset`, `z = H`).
    pub gudgeon_node: usize,
    /// Grid lines along `x` (in).
    pub x_lines: Vec<f64>,
    /// Grid lines along `y` (in).
    pub y_lines: Vec<f64>,
    /// Grid lines along `z` (in).
    pub z_lines: Vec<f64>,
}

impl GateMesh {
    /// Meshes the leaf described by `cfg` (validated first).
    ///
    /// ```
    /// use mitergate::{GateConfig, gate::GateMesh};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let m = GateMesh::build(&cfg).unwrap();
    /// assert_eq!(m.quoin_nodes.len(), m.z_lines.len());
    /// ```
    pub fn build(cfg: &GateConfig) -> Result<Self, GateError> {
        cfg.validate()?;
        let [x_lines, y_lines, z_lines] = grid(cfg);
        let mut b = Builder {
            x: &x_lines,
            y: &y_lines,
            z: &z_lines,
            ids: HashMap::new(),
            mesh: ShellMesh::default(),
            members: Vec::new(),
        };
        b.skin_and_girders(cfg);
        b.diaphragms_and_end_posts(cfg);
        let g = &cfg.geometry;
        let (nx, nz) = (x_lines.len() - 1, z_lines.len() - 1);
        let jb = index_of(&y_lines, g.bearing_offset);
        let quoin_nodes = (0..=nz).map(|k| b.ids[&(0, jb, k)]).collect();
        let miter_nodes = (0..=nz).map(|k| b.ids[&(nx, jb, k)]).collect();
        let jp = index_of(&y_lines, g.pivot_offset);
        let pintle_node = b.ids[&(0, jp, 0)];
        let gudgeon_node = b.ids[&(0, jp, nz)];
        let Builder { mesh, members, .. } = b;
        Ok(Self {
            shell: mesh,
            members,
            quoin_nodes,
            miter_nodes,
            pintle_node,
            gudgeon_node,
            x_lines,
            y_lines,
            z_lines,
        })
    }

    /// Heights (in) of the quoin nodes, increasing.
    ///
    /// ```
    /// use mitergate::{GateConfig, gate::GateMesh};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let m = GateMesh::build(&cfg).unwrap();
    /// let z = m.quoin_heights();
    /// assert_eq!((z[0], *z.last().unwrap()), (0.0, 762.0));
    /// ```
    pub fn quoin_heights(&self) -> Vec<f64> {
        self.quoin_nodes
            .iter()
            .map(|&n| self.shell.nodes[n][2])
            .collect()
    }

    /// Indices of the skin-plate elements.
    ///
    /// ```
    /// use mitergate::{GateConfig, gate::GateMesh};
    /// let mut cfg = GateConfig::default();
    /// cfg.mesh.element_size = 96.0;
    /// let m = GateMesh::build(&cfg).unwrap();
    /// assert_eq!(m.skin_elements().len(), (m.x_lines.len() - 1) * (m.z_lines.len() - 1));
    /// ```
    pub fn skin_elements(&self) -> Vec<usize> {
        (0..self.members.len())
            .filter(|&e| self.members[e] == Member::Skin)
            .collect()
    }
}

#[derive(Clone, Copy)]
enum Plane {
    X(usize),
    Y(usize),
    Z(usize),
}

struct Builder<'a> {
    x: &'a [f64],
    y: &'a [f64],
    z: &'a [f64],
    ids: HashMap<(usize, usize, usize), usize>,
    mesh: ShellMesh,
    members: Vec<Member>,
}

impl Builder<'_> {
    fn node(&mut self, key: (usize, usize, usize)) -> usize {
        if let Some(&n) = self.ids.get(&key) {
            return n;
        }
        let n = self.mesh.nodes.len();
        self.mesh
            .nodes
            .push([self.x[key.0], self.y[key.1], self.z[key.2]]);
        self.ids.insert(key, n);
        n
    }

    /// Number of grid cells along `x`, `y` and `z`.
    fn cells(&self) -> (usize, usize, usize) {
        (self.x.len() - 1, self.y.len() - 1, self.z.len() - 1)
    }

    /// The skin plate (`y = 0`), then each girder's web and downstream flange, bottom up.
    fn skin_and_girders(&mut self, cfg: &GateConfig) {
        let (nx, ny, nz) = self.cells();
        let half = 0.5 * cfg.girders.flange_width;
        self.plate(
            Plane::Y(0),
            (0, nx),
            (0, nz),
            cfg.skin_plate.thickness,
            Member::Skin,
        );
        let jd = index_of(self.y, cfg.geometry.depth);
        for (i, &z) in cfg.girders.heights.iter().enumerate() {
            let (kz, k_lo, k_hi) = (
                index_of(self.z, z),
                index_of(self.z, z - half),
                index_of(self.z, z + half),
            );
            self.plate(
                Plane::Z(kz),
                (0, nx),
                (0, ny),
                cfg.girders.web_thickness,
                Member::GirderWeb(i),
            );
            self.plate(
                Plane::Y(jd),
                (0, nx),
                (k_lo, k_hi),
                cfg.girders.flange_thickness,
                Member::GirderFlange(i),
            );
        }
    }

    /// The diaphragms, the quoin and miter end plates and the two bearing webs.
    fn diaphragms_and_end_posts(&mut self, cfg: &GateConfig) {
        let (nx, ny, nz) = self.cells();
        for (j, &x) in cfg.diaphragms.positions.iter().enumerate() {
            let i = index_of(self.x, x);
            self.plate(
                Plane::X(i),
                (0, ny),
                (0, nz),
                cfg.diaphragms.thickness,
                Member::Diaphragm(j),
            );
        }
        let e = &cfg.end_posts;
        self.plate(
            Plane::X(0),
            (0, ny),
            (0, nz),
            e.quoin_plate_thickness,
            Member::QuoinPlate,
        );
        self.plate(
            Plane::X(nx),
            (0, ny),
            (0, nz),
            e.miter_plate_thickness,
            Member::MiterPlate,
        );
        let (l, w) = (cfg.geometry.leaf_length, e.bearing_web_width);
        let jb = index_of(self.y, cfg.geometry.bearing_offset);
        let (iw, il) = (index_of(self.x, w), index_of(self.x, l - w));
        self.plate(
            Plane::Y(jb),
            (0, iw),
            (0, nz),
            e.bearing_web_thickness,
            Member::QuoinBearingWeb,
        );
        self.plate(
            Plane::Y(jb),
            (il, nx),
            (0, nz),
            e.bearing_web_thickness,
            Member::MiterBearingWeb,
        );
    }

    /// Meshes the rectangle of grid cells `a` x `b` in a coordinate plane; `(a, b)` are the two
    /// in-plane grid directions in cyclic order (`X`: y, z; `Y`: x, z; `Z`: x, y).
    fn plate(
        &mut self,
        plane: Plane,
        a: (usize, usize),
        b: (usize, usize),
        t: f64,
        member: Member,
    ) {
        for i in a.0..a.1 {
            for j in b.0..b.1 {
                let corners = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
                let nodes = corners.map(|(p, q)| {
                    let key = match plane {
                        Plane::X(k) => (k, p, q),
                        Plane::Y(k) => (p, k, q),
                        Plane::Z(k) => (p, q, k),
                    };
                    self.node(key)
                });
                self.mesh.elements.push(QuadElement {
                    nodes,
                    thickness: t,
                });
                self.members.push(member);
            }
        }
    }
}

/// The `x`, `y` and `z` grid lines of the leaf: every structural line (leaf ends, bearing-web
/// edges, diaphragms; skin, flanges, bearing line, pivot axis; sill, top, girder webs and
/// flange edges), each interval divided by [`grid_lines`].
fn grid(cfg: &GateConfig) -> [Vec<f64>; 3] {
    let g = &cfg.geometry;
    let (l, h, d) = (g.leaf_length, g.quoin_height, g.depth);
    let h_el = cfg.mesh.element_size;
    let w = cfg.end_posts.bearing_web_width;
    let mut xk = vec![0.0, l, w, l - w];
    xk.extend(&cfg.diaphragms.positions);
    let yk = vec![0.0, d, g.bearing_offset, g.pivot_offset];
    let half = 0.5 * cfg.girders.flange_width;
    let mut zk = vec![0.0, h];
    for &z in &cfg.girders.heights {
        zk.extend([z - half, z, z + half]);
    }
    [
        grid_lines(xk, h_el),
        grid_lines(yk, h_el),
        grid_lines(zk, h_el),
    ]
}

/// Sorted unique key coordinates, each interval divided into `ceil(len / h)` equal parts.
fn grid_lines(mut keys: Vec<f64>, h: f64) -> Vec<f64> {
    keys.sort_by(f64::total_cmp);
    let span = keys.last().copied().unwrap_or(0.0) - keys[0];
    let tol = 1e-9 * span.max(1.0);
    keys.dedup_by(|a, b| (*a - *b).abs() <= tol);
    let mut lines = vec![keys[0]];
    for w in keys.windows(2) {
        let n = ((w[1] - w[0]) / h - 1e-9).ceil().max(1.0) as usize;
        for k in 1..=n {
            lines.push(if k == n {
                w[1]
            } else {
                w[0] + (w[1] - w[0]) * k as f64 / n as f64
            });
        }
    }
    lines
}

fn index_of(lines: &[f64], v: f64) -> usize {
    lines
        .iter()
        .enumerate()
        .min_by(|a, b| (a.1 - v).abs().total_cmp(&(b.1 - v).abs()))
        .map(|(i, _)| i)
        .unwrap_or(0)
}
