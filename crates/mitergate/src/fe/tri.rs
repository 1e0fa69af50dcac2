//! Flat three-node shell triangle (Abaqus `S3`), 6 DOFs per node, for imported decks.
//!
//! * **Membrane**: Allman's triangle with vertex drilling rotations (D. J. Allman, "A compatible
//!   triangular element including vertex rotations for plane elasticity analysis", Computers &
//!   Structures 19, 1984): the quadratic (LST) displacement field whose mid-side values are
//!   `½(u_i + u_j) + (l_ij/8)(θ_j − θ_i) n_ij` (`n_ij` the outward edge normal), so the vertex
//!   rotations `θ_z` bend the edges. It passes the constant-strain patch test and represents
//!   in-plane bending far better than the constant-strain triangle.
//! * **Drilling stabilisation**: Allman's field has one spurious zero-energy mode (equal vertex
//!   rotations, no displacement); the same Hughes–Brezzi penalty as the quadrilateral,
//!   `α G t ∫ (θ_z − ω)² dA` with `θ_z` linear and `ω` the rotation of the Allman field,
//!   removes it and vanishes for every exact constant-strain state (there `θ_z = ω`).
//! * **Bending**: the Discrete Kirchhoff Triangle (DKT) of Batoz, Bathe & Ho ("A study of
//!   three-node triangular plate bending elements", IJNME 15, 1980): quadratic normal rotations
//!   on the six vertex and mid-side nodes, with the Kirchhoff constraint imposed at the
//!   vertices and, along each edge, on the tangential rotation at the mid-side (cubic `w`
//!   along the edge) while the normal rotation varies linearly. Thin-plate (Kirchhoff)
//!   theory: no transverse shear flexibility.
//!
//! Local frame: `e1` along edge 1→2, `e3` along `(p2 − p1) × (p3 − p1)`, `e2 = e3 × e1`; the
//! through-thickness field and rotation conventions are those of [`super::shell`]
//! (`u(ζ) = u₀ + ζ θ_y`, `v(ζ) = v₀ − ζ θ_x`). All stiffness integrals are polynomial of
//! degree two and integrated exactly by the three mid-side points.

use super::shell::ShellMaterial;
use crate::error::GateError;
use nalgebra::{Matrix3, SMatrix, SVector, Vector2, Vector3};

/// 18×18 element matrix (3 nodes × 6 DOFs).
pub type Mat18 = SMatrix<f64, 18, 18>;
/// Element vector over the 18 DOFs.
pub type Vec18 = SVector<f64, 18>;

/// Edges `(i, j)` in counter-clockwise order, mid-side node `3 + k` on edge `k`.
const EDGES: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];

/// A flat shell triangle with its local frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ShellTriangle {
    /// Rows: local axes `e1, e2, e3` (global).
    axes: Matrix3<f64>,
    origin: Vector3<f64>,
    local: [Vector2<f64>; 3],
    area: f64,
    thickness: f64,
    material: ShellMaterial,
    drilling_penalty: f64,
}

impl ShellTriangle {
    /// Builds the triangle from its 3 nodes (global, in), thickness (in), material and
    /// drilling penalty factor (as for [`super::shell::ShellQuad`]).
    ///
    /// ```
    /// use mitergate::fe::shell::ShellMaterial;
    /// use mitergate::fe::tri::ShellTriangle;
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[2.,0.,0.],[0.,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// assert!((t.area() - 1.0).abs() < 1e-12);
    /// assert!(ShellTriangle::new(&[[0.,0.,0.],[1.,0.,0.],[2.,0.,0.]], 0.1, m, 1e-3).is_err());
    /// ```
    pub fn new(
        coords: &[[f64; 3]; 3],
        thickness: f64,
        material: ShellMaterial,
        drilling_penalty: f64,
    ) -> Result<Self, GateError> {
        let p = coords.map(Vector3::from);
        let normal = (p[1] - p[0]).cross(&(p[2] - p[0]));
        let scale = (p[1] - p[0]).norm().max((p[2] - p[0]).norm());
        if !(normal.norm() > 1e-10 * scale * scale) || !(thickness > 0.0) {
            return Err(GateError::InvalidMesh(format!(
                "degenerate shell triangle {coords:?} (thickness {thickness})"
            )));
        }
        let e3 = normal.normalize();
        let e1 = (p[1] - p[0]).normalize();
        let e2 = e3.cross(&e1);
        let local = [0, 1, 2].map(|i| {
            let d = p[i] - p[0];
            Vector2::new(d.dot(&e1), d.dot(&e2))
        });
        Ok(Self {
            axes: Matrix3::from_rows(&[e1.transpose(), e2.transpose(), e3.transpose()]),
            origin: p[0],
            local,
            area: 0.5 * normal.norm(),
            thickness,
            material,
            drilling_penalty,
        })
    }

    /// Area (in²).
    ///
    /// ```
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # use mitergate::fe::tri::ShellTriangle;
    /// # let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[0.,0.,3.],[0.,2.,0.]], 1.0, m, 0.0).unwrap();
    /// assert!((t.area() - 3.0).abs() < 1e-12);
    /// ```
    pub fn area(&self) -> f64 {
        self.area
    }

    /// Unit normal `e3` (global).
    ///
    /// ```
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # use mitergate::fe::tri::ShellTriangle;
    /// # let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[1.,0.,0.],[0.,1.,0.]], 1.0, m, 0.0).unwrap();
    /// assert_eq!(t.normal(), [0.0, 0.0, 1.0]);
    /// ```
    pub fn normal(&self) -> [f64; 3] {
        let r = self.axes.row(2);
        [r[0], r[1], r[2]]
    }

    /// Thickness (in).
    ///
    /// ```
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # use mitergate::fe::tri::ShellTriangle;
    /// # let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[1.,0.,0.],[0.,1.,0.]], 0.5, m, 0.0).unwrap();
    /// assert_eq!(t.thickness(), 0.5);
    /// ```
    pub fn thickness(&self) -> f64 {
        self.thickness
    }

    /// Cartesian derivatives `(∂L_i/∂x, ∂L_i/∂y)` of the area coordinates (constant).
    fn area_coordinate_gradients(&self) -> [Vector2<f64>; 3] {
        let x = &self.local;
        let two_a = 2.0 * self.area;
        [0, 1, 2].map(|i| {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            Vector2::new(x[j].y - x[k].y, x[k].x - x[j].x) / two_a
        })
    }

    /// Gradients of the six quadratic (LST) shape functions at area coordinates `l`.
    fn quadratic_gradients(&self, l: [f64; 3]) -> [Vector2<f64>; 6] {
        let g = self.area_coordinate_gradients();
        let mut out = [Vector2::zeros(); 6];
        for i in 0..3 {
            out[i] = g[i] * (4.0 * l[i] - 1.0);
        }
        for (k, &(i, j)) in EDGES.iter().enumerate() {
            out[3 + k] = (g[i] * l[j] + g[j] * l[i]) * 4.0;
        }
        out
    }

    /// Allman map from the vertex DOFs `[u_i, v_i, θz_i]` (9) to the LST nodal displacements
    /// `[u_1..u_6, v_1..v_6]` (12).
    fn allman_map(&self) -> SMatrix<f64, 12, 9> {
        let mut t = SMatrix::<f64, 12, 9>::zeros();
        for i in 0..3 {
            t[(i, 3 * i)] = 1.0;
            t[(6 + i, 3 * i + 1)] = 1.0;
        }
        for (k, &(i, j)) in EDGES.iter().enumerate() {
            let d = self.local[j] - self.local[i];
            let (m, mv) = (3 + k, 9 + k);
            for a in [i, j] {
                t[(m, 3 * a)] = 0.5;
                t[(mv, 3 * a + 1)] = 0.5;
            }
            // outward normal times length: (d_y, -d_x)
            t[(m, 3 * j + 2)] += d.y / 8.0;
            t[(m, 3 * i + 2)] -= d.y / 8.0;
            t[(mv, 3 * j + 2)] -= d.x / 8.0;
            t[(mv, 3 * i + 2)] += d.x / 8.0;
        }
        t
    }

    /// Membrane strain `[εxx, εyy, γxy]` and rotation `ω` operators over `[u_i, v_i, θz_i]`.
    fn membrane_operators(&self, l: [f64; 3]) -> (SMatrix<f64, 3, 9>, SMatrix<f64, 1, 9>) {
        let dn = self.quadratic_gradients(l);
        let mut b = SMatrix::<f64, 3, 12>::zeros();
        let mut w = SMatrix::<f64, 1, 12>::zeros();
        for a in 0..6 {
            b[(0, a)] = dn[a].x;
            b[(1, 6 + a)] = dn[a].y;
            b[(2, a)] = dn[a].y;
            b[(2, 6 + a)] = dn[a].x;
            w[(0, a)] = -0.5 * dn[a].y;
            w[(0, 6 + a)] = 0.5 * dn[a].x;
        }
        let t = self.allman_map();
        (b * t, w * t)
    }

    /// DKT map from the vertex DOFs `[w_i, θx_i, θy_i]` (9) to the six nodal normal rotations
    /// `[βx_1..βx_6, βy_1..βy_6]` (12), `βx = θy`, `βy = −θx` (`βx = −∂w/∂x` in the
    /// Kirchhoff limit).
    fn dkt_map(&self) -> SMatrix<f64, 12, 9> {
        let mut h = SMatrix::<f64, 12, 9>::zeros();
        for i in 0..3 {
            h[(i, 3 * i + 2)] = 1.0;
            h[(6 + i, 3 * i + 1)] = -1.0;
        }
        for (k, &(i, j)) in EDGES.iter().enumerate() {
            let d = self.local[j] - self.local[i];
            let len = d.norm();
            let s = d / len;
            let n = Vector2::new(s.y, -s.x);
            // β_s and β_n of the vertex rotations, as rows over the 9 DOFs
            let comp = |dir: Vector2<f64>, v: usize| {
                let mut r = SMatrix::<f64, 1, 9>::zeros();
                r[3 * v + 2] = dir.x;
                r[3 * v + 1] = -dir.y;
                r
            };
            let mut bs = -(comp(s, i) + comp(s, j)) * 0.25;
            bs[3 * j] -= 1.5 / len;
            bs[3 * i] += 1.5 / len;
            let bn = (comp(n, i) + comp(n, j)) * 0.5;
            let bx = bs * s.x + bn * n.x;
            let by = bs * s.y + bn * n.y;
            h.set_row(3 + k, &bx);
            h.set_row(9 + k, &by);
        }
        h
    }

    /// Curvature operator `[κxx, κyy, κxy]` over `[w_i, θx_i, θy_i]` at area coordinates `l`.
    fn curvature_operator(&self, l: [f64; 3]) -> SMatrix<f64, 3, 9> {
        let dn = self.quadratic_gradients(l);
        let mut b = SMatrix::<f64, 3, 12>::zeros();
        for a in 0..6 {
            b[(0, a)] = dn[a].x;
            b[(1, 6 + a)] = dn[a].y;
            b[(2, a)] = dn[a].y;
            b[(2, 6 + a)] = dn[a].x;
        }
        b * self.dkt_map()
    }

    /// The three mid-side points (area coordinates), each of weight `A/3`: exact for
    /// quadratics.
    fn points() -> [[f64; 3]; 3] {
        [[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]]
    }

    /// Local stiffness (18×18, DOFs per node `[u, v, w, θx, θy, θz]` in the local frame).
    ///
    /// ```
    /// use mitergate::fe::shell::ShellMaterial;
    /// use mitergate::fe::tri::ShellTriangle;
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[2.,0.,0.],[0.5,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// let k = t.local_stiffness();
    /// assert!((k - k.transpose()).norm() < 1e-9 * k.norm());
    /// ```
    pub fn local_stiffness(&self) -> Mat18 {
        let t = self.thickness;
        let d = plane_stress(self.material);
        let dm = d * t;
        let db = d * (t * t * t / 12.0);
        let gamma = self.drilling_penalty * self.material.shear_modulus() * t;
        let w = self.area / 3.0;
        let mut km = SMatrix::<f64, 9, 9>::zeros();
        let mut kb = SMatrix::<f64, 9, 9>::zeros();
        for l in Self::points() {
            let (bm, om) = self.membrane_operators(l);
            let mut drill = om * -1.0;
            for i in 0..3 {
                drill[3 * i + 2] += l[i];
            }
            km += (bm.transpose() * dm * bm + drill.transpose() * drill * gamma) * w;
            let bb = self.curvature_operator(l);
            kb += bb.transpose() * db * bb * w;
        }
        let mut k = Mat18::zeros();
        let mem = |a: usize| 6 * (a / 3) + [0, 1, 5][a % 3];
        let pla = |a: usize| 6 * (a / 3) + 2 + a % 3;
        for a in 0..9 {
            for b in 0..9 {
                k[(mem(a), mem(b))] += km[(a, b)];
                k[(pla(a), pla(b))] += kb[(a, b)];
            }
        }
        k
    }

    fn transformation(&self) -> Mat18 {
        super::shell::block_rotation(&self.axes)
    }

    /// Global stiffness (18×18, DOFs per node `[ux, uy, uz, rx, ry, rz]`).
    ///
    /// ```
    /// use mitergate::fe::shell::ShellMaterial;
    /// use mitergate::fe::tri::{ShellTriangle, Vec18};
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[2.,0.,1.],[0.,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// let mut u = Vec18::zeros();
    /// for i in 0..3 { u[6 * i + 2] = 1.0; } // rigid translation along z
    /// assert!((t.stiffness() * u).norm() < 1e-9 * t.stiffness().norm());
    /// ```
    pub fn stiffness(&self) -> Mat18 {
        let t = self.transformation();
        t.transpose() * self.local_stiffness() * t
    }

    /// Area coordinates `(L2, L3)` of the projection of a global point on the element plane
    /// (`L1 = 1 − L2 − L3`) and its distance (in) from the plane along `e3`.
    ///
    /// ```
    /// # use mitergate::fe::shell::ShellMaterial;
    /// # use mitergate::fe::tri::ShellTriangle;
    /// # let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[2.,0.,0.],[0.,2.,0.]], 1.0, m, 0.0).unwrap();
    /// let (l2, l3, dist) = t.natural_coordinates([0.5, 1.0, 0.25]);
    /// assert!((l2 - 0.25).abs() < 1e-12 && (l3 - 0.5).abs() < 1e-12 && (dist - 0.25).abs() < 1e-12);
    /// ```
    pub fn natural_coordinates(&self, point: [f64; 3]) -> (f64, f64, f64) {
        let d = Vector3::from(point) - self.origin;
        let p = Vector2::new(
            d.dot(&self.axes.row(0).transpose()),
            d.dot(&self.axes.row(1).transpose()),
        );
        let g = self.area_coordinate_gradients();
        // L_i is affine with gradient g_i; L2 and L3 vanish at vertex 1 (the origin)
        (
            g[1].dot(&p),
            g[2].dot(&p),
            d.dot(&self.axes.row(2).transpose()),
        )
    }

    /// Strain operator (global, 18 entries, microstrain per unit DOF) of the normal strain along
    /// the in-plane `direction` at area coordinates `(L2, L3)` on the surface at `zeta` (in)
    /// from the mid-surface along `e3`: Allman membrane strain plus `zeta` times the DKT
    /// curvature.
    ///
    /// ```
    /// use mitergate::fe::shell::ShellMaterial;
    /// use mitergate::fe::tri::{ShellTriangle, Vec18};
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let t = ShellTriangle::new(&[[0.,0.,0.],[2.,0.,0.],[0.,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// let s = t.strain_operator(0.3, 0.3, 0.05, [1.0, 0.0, 0.0]);
    /// let mut u = Vec18::zeros();
    /// u[6] = 2e-6; // node 2 at x = 2 moves 2e-6 along x: 1 microstrain
    /// assert!((s.dot(&u) - 1.0).abs() < 1e-9);
    /// ```
    pub fn strain_operator(&self, l2: f64, l3: f64, zeta: f64, direction: [f64; 3]) -> Vec18 {
        let dir = Vector3::from(direction);
        let (dx, dy) = (
            dir.dot(&self.axes.row(0).transpose()),
            dir.dot(&self.axes.row(1).transpose()),
        );
        let nrm = (dx * dx + dy * dy).sqrt().max(f64::MIN_POSITIVE);
        let (dx, dy) = (dx / nrm, dy / nrm);
        let proj = SMatrix::<f64, 1, 3>::new(dx * dx, dy * dy, dx * dy);
        let l = [1.0 - l2 - l3, l2, l3];
        let sm = proj * self.membrane_operators(l).0;
        let sb = proj * self.curvature_operator(l) * zeta;
        let mut s = Vec18::zeros();
        for a in 0..9 {
            s[6 * (a / 3) + [0, 1, 5][a % 3]] += sm[a];
            s[6 * (a / 3) + 2 + a % 3] += sb[a];
        }
        self.transformation().transpose() * s * 1e6
    }
}

fn plane_stress(m: ShellMaterial) -> Matrix3<f64> {
    let (e, nu) = (m.youngs_modulus, m.poisson_ratio);
    let c = e / (1.0 - nu * nu);
    Matrix3::new(
        c,
        c * nu,
        0.0,
        c * nu,
        c,
        0.0,
        0.0,
        0.0,
        c * 0.5 * (1.0 - nu),
    )
}
