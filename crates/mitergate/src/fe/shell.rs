//! Flat four-node shell element: membrane + drilling + plate bending, 6 DOFs per node.
//!
//! * **Membrane**: bilinear Q4 enriched with Wilson's incompatible modes `1 - ξ²`, `1 - η²`
//!   (QM6), with the Taylor–Beresford–Wilson (1976) correction (incompatible-mode derivatives
//!   taken with the centre Jacobian and scaled by `det J₀ / det J`) so that it passes the
//!   patch test on distorted meshes. The four internal modes are condensed statically per
//!   element; the strain recovery keeps them. QM6 represents in-plane bending of girder webs
//!   exactly on rectangles, where plain Q4 locks in shear.
//! * **Drilling**: a penalty `α G t ∫ (θ_z − ω)² dA`, `ω = ½(∂v/∂x − ∂u/∂y)` the in-plane
//!   rotation of the (compatible) membrane field and `θ_z` interpolated bilinearly, 2×2 Gauss
//!   points. This is the penalty form of Hughes & Brezzi (1989); a small factor `α` (default
//!   `1e-3`, as in the penalty drilling shells of Kanok-Nukulchai 1979) gives the rotation about
//!   the normal a stiffness without perturbing the membrane response. It is invariant under
//!   rigid in-plane rotation (`θ_z = ω`).
//! * **Bending**: Reissner–Mindlin plate, MITC4 (Bathe & Dvorkin 1985): bilinear `w`, `θ_x`,
//!   `θ_y`, curvatures from the rotations at 2×2 Gauss points, covariant transverse shear strains
//!   tied at the edge mid-points (no shear locking), shear correction 5/6.
//!
//! The element is flat: its plane is the mean plane of the four nodes (warped quadrilaterals are
//! projected, which is exact for the planar elements of the gate mesh). Local axes: `e1` along
//! the mean of the edges 1→2 and 4→3, `e3` along the cross product of the diagonals, `e2 = e3 ×
//! e1`. Rotations are right-handed about the axes; the through-thickness displacement field is
//! `u(ζ) = u₀ + ζ θ_y`, `v(ζ) = v₀ − ζ θ_x` with `ζ` along `e3`.

use crate::error::GateError;
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector2, Vector3};

/// 24×24 element matrix (4 nodes × 6 DOFs).
pub type Mat24 = SMatrix<f64, 24, 24>;
/// Element vector over the 24 DOFs.
pub type Vec24 = SVector<f64, 24>;

const GAUSS: f64 = 0.577_350_269_189_625_8; // 1/sqrt(3)
const XI: [f64; 4] = [-1.0, 1.0, 1.0, -1.0];
const ETA: [f64; 4] = [-1.0, -1.0, 1.0, 1.0];
/// Shear correction factor of Reissner–Mindlin plates.
pub const SHEAR_CORRECTION: f64 = 5.0 / 6.0;

/// Linear elastic isotropic material (psi).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellMaterial {
    /// Young's modulus (psi).
    pub youngs_modulus: f64,
    /// Poisson's ratio.
    pub poisson_ratio: f64,
}

impl ShellMaterial {
    /// Shear modulus `E / (2 (1 + ν))` (psi).
    ///
    /// ```
    /// let m = mitergate::fe::shell::ShellMaterial { youngs_modulus: 26.0, poisson_ratio: 0.3 };
    /// assert!((m.shear_modulus() - 10.0).abs() < 1e-12);
    /// ```
    pub fn shear_modulus(&self) -> f64 {
        self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))
    }

    fn plane_stress(&self) -> Matrix3<f64> {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
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
}

/// A flat shell quadrilateral with its local frame, ready to produce its stiffness and strain
/// operators in global coordinates.
#[derive(Debug, Clone)]
pub struct ShellQuad {
    /// Rows are the local axes `e1, e2, e3` in global coordinates.
    axes: Matrix3<f64>,
    centre: Vector3<f64>,
    local: [Vector2<f64>; 4],
    thickness: f64,
    material: ShellMaterial,
    drilling_penalty: f64,
}

struct Derivs {
    n: [f64; 4],
    dx: [f64; 4],
    dy: [f64; 4],
    det: f64,
}

impl ShellQuad {
    /// Builds the element from its 4 nodes (global, in, counter-clockwise about the normal),
    /// thickness (in), material and drilling penalty factor.
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[2.,0.,0.],[2.,1.,0.],[0.,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// assert!((q.area() - 2.0).abs() < 1e-12);
    /// ```
    pub fn new(
        coords: &[[f64; 3]; 4],
        thickness: f64,
        material: ShellMaterial,
        drilling_penalty: f64,
    ) -> Result<Self, GateError> {
        let p: Vec<Vector3<f64>> = coords.iter().map(|c| Vector3::from(*c)).collect();
        let centre = (p[0] + p[1] + p[2] + p[3]) * 0.25;
        let normal = (p[2] - p[0]).cross(&(p[3] - p[1]));
        let scale = (p[2] - p[0]).norm().max((p[3] - p[1]).norm());
        if !(normal.norm() > 1e-10 * scale * scale) || !(thickness > 0.0) {
            return Err(GateError::InvalidMesh(format!(
                "degenerate shell element {coords:?} (thickness {thickness})"
            )));
        }
        let e3 = normal.normalize();
        let a = (p[1] - p[0]) + (p[2] - p[3]);
        let e1 = (a - e3 * a.dot(&e3)).normalize();
        let e2 = e3.cross(&e1);
        let axes = Matrix3::from_rows(&[e1.transpose(), e2.transpose(), e3.transpose()]);
        let local = [0, 1, 2, 3].map(|i| {
            let d = p[i] - centre;
            Vector2::new(d.dot(&e1), d.dot(&e2))
        });
        let q = Self {
            axes,
            centre,
            local,
            thickness,
            material,
            drilling_penalty,
        };
        for (xi, eta) in [(-GAUSS, -GAUSS), (GAUSS, GAUSS), (-1.0, 1.0), (1.0, -1.0)] {
            if !(q.jacobian(xi, eta).determinant() > 0.0) {
                return Err(GateError::InvalidMesh(format!(
                    "shell element {coords:?} is inverted or not convex"
                )));
            }
        }
        Ok(q)
    }

    /// Element area (in²).
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[1.,0.,0.],[1.,0.,1.],[0.,0.,1.]], 1.0, m, 0.0).unwrap();
    /// assert!((q.area() - 1.0).abs() < 1e-12);
    /// ```
    pub fn area(&self) -> f64 {
        gauss_points()
            .map(|(xi, eta, w)| self.jacobian(xi, eta).determinant() * w)
            .sum()
    }

    /// Unit normal `e3` (global).
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]], 1.0, m, 0.0).unwrap();
    /// assert_eq!(q.normal(), [0.0, 0.0, 1.0]);
    /// ```
    pub fn normal(&self) -> [f64; 3] {
        let r = self.axes.row(2);
        [r[0], r[1], r[2]]
    }

    /// Thickness (in).
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[1.,0.,0.],[1.,1.,0.],[0.,1.,0.]], 0.5, m, 0.0).unwrap();
    /// assert_eq!(q.thickness(), 0.5);
    /// ```
    pub fn thickness(&self) -> f64 {
        self.thickness
    }

    fn jacobian(&self, xi: f64, eta: f64) -> Matrix2<f64> {
        let mut j = Matrix2::zeros();
        for i in 0..4 {
            let dxi = 0.25 * XI[i] * (1.0 + eta * ETA[i]);
            let deta = 0.25 * ETA[i] * (1.0 + xi * XI[i]);
            j[(0, 0)] += dxi * self.local[i].x;
            j[(0, 1)] += dxi * self.local[i].y;
            j[(1, 0)] += deta * self.local[i].x;
            j[(1, 1)] += deta * self.local[i].y;
        }
        j
    }

    fn derivs(&self, xi: f64, eta: f64) -> Derivs {
        let j = self.jacobian(xi, eta);
        let det = j.determinant();
        let jinv = j.try_inverse().unwrap_or_else(Matrix2::zeros);
        let mut d = Derivs {
            n: shape(xi, eta),
            dx: [0.0; 4],
            dy: [0.0; 4],
            det,
        };
        for i in 0..4 {
            let g = jinv
                * Vector2::new(
                    0.25 * XI[i] * (1.0 + eta * ETA[i]),
                    0.25 * ETA[i] * (1.0 + xi * XI[i]),
                );
            d.dx[i] = g.x;
            d.dy[i] = g.y;
        }
        d
    }

    /// Compatible membrane strain operator `[εxx, εyy, γxy]` over `[u_i, v_i]`.
    fn b_membrane(d: &Derivs) -> SMatrix<f64, 3, 8> {
        let mut b = SMatrix::<f64, 3, 8>::zeros();
        for i in 0..4 {
            b[(0, 2 * i)] = d.dx[i];
            b[(1, 2 * i + 1)] = d.dy[i];
            b[(2, 2 * i)] = d.dy[i];
            b[(2, 2 * i + 1)] = d.dx[i];
        }
        b
    }

    /// Incompatible-mode strain operator over `[a1 (u,1-ξ²), a2 (u,1-η²), a3 (v,1-ξ²), a4 (v,1-η²)]`
    /// with the Taylor correction.
    fn b_incompatible(&self, xi: f64, eta: f64, det: f64) -> SMatrix<f64, 3, 4> {
        let j0 = self.jacobian(0.0, 0.0);
        let j0inv = j0.try_inverse().unwrap_or_else(Matrix2::zeros);
        let scale = j0.determinant() / det;
        let p1 = j0inv * Vector2::new(-2.0 * xi, 0.0) * scale;
        let p2 = j0inv * Vector2::new(0.0, -2.0 * eta) * scale;
        SMatrix::<f64, 3, 4>::new(
            p1.x, p2.x, 0.0, 0.0, //
            0.0, 0.0, p1.y, p2.y, //
            p1.y, p2.y, p1.x, p2.x,
        )
    }

    /// Condensed membrane stiffness (8×8 over `[u_i, v_i]`) and the recovery `α = R u`.
    fn membrane(&self) -> (SMatrix<f64, 8, 8>, SMatrix<f64, 4, 8>) {
        let dm = self.material.plane_stress() * self.thickness;
        let mut kuu = SMatrix::<f64, 8, 8>::zeros();
        let mut kua = SMatrix::<f64, 8, 4>::zeros();
        let mut kaa = SMatrix::<f64, 4, 4>::zeros();
        for (xi, eta, w) in gauss_points() {
            let d = self.derivs(xi, eta);
            let b = Self::b_membrane(&d);
            let ba = self.b_incompatible(xi, eta, d.det);
            let f = w * d.det;
            kuu += b.transpose() * dm * b * f;
            kua += b.transpose() * dm * ba * f;
            kaa += ba.transpose() * dm * ba * f;
        }
        let kaa_inv = kaa
            .try_inverse()
            .unwrap_or_else(SMatrix::<f64, 4, 4>::zeros);
        let r = -(kaa_inv * kua.transpose());
        (kuu + kua * r, r)
    }

    /// Drilling penalty stiffness (12×12 over `[u_i, v_i, θz_i]`).
    fn drilling(&self) -> SMatrix<f64, 12, 12> {
        let gamma = self.drilling_penalty * self.material.shear_modulus() * self.thickness;
        let mut k = SMatrix::<f64, 12, 12>::zeros();
        for (xi, eta, w) in gauss_points() {
            let d = self.derivs(xi, eta);
            let mut g = SVector::<f64, 12>::zeros();
            for i in 0..4 {
                g[3 * i] = 0.5 * d.dy[i];
                g[3 * i + 1] = -0.5 * d.dx[i];
                g[3 * i + 2] = d.n[i];
            }
            k += g * g.transpose() * (gamma * w * d.det);
        }
        k
    }

    /// Curvature operator `[κxx, κyy, κxy]` over `[w_i, θx_i, θy_i]`.
    fn b_bending(d: &Derivs) -> SMatrix<f64, 3, 12> {
        let mut b = SMatrix::<f64, 3, 12>::zeros();
        for i in 0..4 {
            b[(0, 3 * i + 2)] = d.dx[i];
            b[(1, 3 * i + 1)] = -d.dy[i];
            b[(2, 3 * i + 1)] = -d.dx[i];
            b[(2, 3 * i + 2)] = d.dy[i];
        }
        b
    }

    /// Covariant transverse shear strain along `ξ` (`along_xi`) or `η` at a tying point.
    fn covariant_shear(&self, xi: f64, eta: f64, along_xi: bool) -> SVector<f64, 12> {
        let j = self.jacobian(xi, eta);
        let row = if along_xi { 0 } else { 1 };
        let (xd, yd) = (j[(row, 0)], j[(row, 1)]);
        let n = shape(xi, eta);
        let mut g = SVector::<f64, 12>::zeros();
        for i in 0..4 {
            let dn = if along_xi {
                0.25 * XI[i] * (1.0 + eta * ETA[i])
            } else {
                0.25 * ETA[i] * (1.0 + xi * XI[i])
            };
            g[3 * i] = dn;
            g[3 * i + 1] = -n[i] * yd;
            g[3 * i + 2] = n[i] * xd;
        }
        g
    }

    /// MITC4 transverse shear operator `[γxz, γyz]` over `[w_i, θx_i, θy_i]`.
    fn b_shear(&self, xi: f64, eta: f64) -> SMatrix<f64, 2, 12> {
        let a = self.covariant_shear(0.0, 1.0, true);
        let c = self.covariant_shear(0.0, -1.0, true);
        let b = self.covariant_shear(-1.0, 0.0, false);
        let d = self.covariant_shear(1.0, 0.0, false);
        let g_xi = a * (0.5 * (1.0 + eta)) + c * (0.5 * (1.0 - eta));
        let g_eta = d * (0.5 * (1.0 + xi)) + b * (0.5 * (1.0 - xi));
        let mut nat = SMatrix::<f64, 2, 12>::zeros();
        nat.set_row(0, &g_xi.transpose());
        nat.set_row(1, &g_eta.transpose());
        let jinv = self
            .jacobian(xi, eta)
            .try_inverse()
            .unwrap_or_else(Matrix2::zeros);
        jinv * nat
    }

    /// Plate bending + shear stiffness (12×12 over `[w_i, θx_i, θy_i]`).
    fn plate(&self) -> SMatrix<f64, 12, 12> {
        let t = self.thickness;
        let db = self.material.plane_stress() * (t * t * t / 12.0);
        let ds = SHEAR_CORRECTION * self.material.shear_modulus() * t;
        let mut k = SMatrix::<f64, 12, 12>::zeros();
        for (xi, eta, w) in gauss_points() {
            let d = self.derivs(xi, eta);
            let bb = Self::b_bending(&d);
            let bs = self.b_shear(xi, eta);
            k += (bb.transpose() * db * bb + bs.transpose() * bs * ds) * (w * d.det);
        }
        k
    }

    /// Local stiffness (24×24, DOFs per node `[u, v, w, θx, θy, θz]` in the local frame).
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[2.,0.,0.],[2.,1.,0.],[0.,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// let k = q.local_stiffness();
    /// assert!((k - k.transpose()).norm() < 1e-6 * k.norm());
    /// ```
    pub fn local_stiffness(&self) -> Mat24 {
        let (km, _) = self.membrane();
        let kd = self.drilling();
        let kp = self.plate();
        let mut k = Mat24::zeros();
        let mem = |a: usize| 6 * (a / 2) + a % 2;
        let dri = |a: usize| 6 * (a / 3) + [0, 1, 5][a % 3];
        let pla = |a: usize| 6 * (a / 3) + 2 + a % 3;
        for a in 0..8 {
            for b in 0..8 {
                k[(mem(a), mem(b))] += km[(a, b)];
            }
        }
        for a in 0..12 {
            for b in 0..12 {
                k[(dri(a), dri(b))] += kd[(a, b)];
                k[(pla(a), pla(b))] += kp[(a, b)];
            }
        }
        k
    }

    /// Transformation `T` (24×24) from global to local element DOFs.
    fn transformation(&self) -> Mat24 {
        block_rotation(&self.axes)
    }

    /// Global stiffness (24×24, DOFs per node `[ux, uy, uz, rx, ry, rz]`), `Tᵀ K_local T`.
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[2.,0.,0.],[2.,0.,1.],[0.,0.,1.]], 0.1, m, 1e-3).unwrap();
    /// let k = q.stiffness();
    /// // a rigid translation along y produces no forces
    /// let mut u = mitergate::fe::shell::Vec24::zeros();
    /// for i in 0..4 { u[6 * i + 1] = 1.0; }
    /// assert!((k * u).norm() < 1e-9 * k.norm());
    /// ```
    pub fn stiffness(&self) -> Mat24 {
        let t = self.transformation();
        t.transpose() * self.local_stiffness() * t
    }

    /// Local coordinates `(ξ, η)` and out-of-plane distance (in) of a global point, by Newton
    /// iteration on the bilinear map.
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad};
    /// let m = ShellMaterial { youngs_modulus: 1.0, poisson_ratio: 0.0 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[2.,0.,0.],[2.,1.,0.],[0.,1.,0.]], 1.0, m, 0.0).unwrap();
    /// let (xi, eta, dist) = q.natural_coordinates([1.5, 0.25, 0.0]);
    /// assert!((xi - 0.5).abs() < 1e-12 && (eta + 0.5).abs() < 1e-12 && dist.abs() < 1e-12);
    /// ```
    pub fn natural_coordinates(&self, point: [f64; 3]) -> (f64, f64, f64) {
        let d = Vector3::from(point) - self.centre;
        let target = Vector2::new(
            d.dot(&self.axes.row(0).transpose()),
            d.dot(&self.axes.row(1).transpose()),
        );
        let dist = d.dot(&self.axes.row(2).transpose());
        let (mut xi, mut eta) = (0.0, 0.0);
        for _ in 0..30 {
            let n = shape(xi, eta);
            let x: Vector2<f64> = (0..4).map(|i| self.local[i] * n[i]).sum();
            let r = target - x;
            if r.norm() < 1e-13 * (1.0 + target.norm()) {
                break;
            }
            let j = self.jacobian(xi, eta);
            let Some(step) = j.transpose().try_inverse().map(|m| m * r) else {
                break;
            };
            xi += step.x;
            eta += step.y;
        }
        (xi, eta, dist)
    }

    /// Strain operator (global, 24 entries, microstrain per unit DOF) of the normal strain along
    /// the in-plane direction `direction` at natural point `(ξ, η)` on the surface at distance
    /// `zeta` (in) from the mid-surface along `e3` (`±t/2` for the faces): membrane strain
    /// (with the incompatible modes) plus `zeta` times the curvature.
    ///
    /// ```
    /// use mitergate::fe::shell::{ShellMaterial, ShellQuad, Vec24};
    /// let m = ShellMaterial { youngs_modulus: 29e6, poisson_ratio: 0.3 };
    /// let q = ShellQuad::new(&[[0.,0.,0.],[2.,0.,0.],[2.,1.,0.],[0.,1.,0.]], 0.1, m, 1e-3).unwrap();
    /// let s = q.strain_operator(0.0, 0.0, 0.05, [1.0, 0.0, 0.0]);
    /// let mut u = Vec24::zeros();
    /// for i in [1, 2] { u[6 * i] = 2e-6; } // stretch of 1e-6 along x
    /// assert!((s.dot(&u) - 1.0).abs() < 1e-9);
    /// ```
    pub fn strain_operator(&self, xi: f64, eta: f64, zeta: f64, direction: [f64; 3]) -> Vec24 {
        let dir = Vector3::from(direction);
        let (dx, dy) = (
            dir.dot(&self.axes.row(0).transpose()),
            dir.dot(&self.axes.row(1).transpose()),
        );
        let nrm = (dx * dx + dy * dy).sqrt().max(f64::MIN_POSITIVE);
        let (dx, dy) = (dx / nrm, dy / nrm);
        let proj = SMatrix::<f64, 1, 3>::new(dx * dx, dy * dy, dx * dy);
        let (_, r) = self.membrane();
        let d = self.derivs(xi, eta);
        let bm = Self::b_membrane(&d) + self.b_incompatible(xi, eta, d.det) * r;
        let bb = Self::b_bending(&d) * zeta;
        let sm = proj * bm;
        let sb = proj * bb;
        let mut s = Vec24::zeros();
        for a in 0..8 {
            s[6 * (a / 2) + a % 2] += sm[a];
        }
        for a in 0..12 {
            s[6 * (a / 3) + 2 + a % 3] += sb[a];
        }
        self.transformation().transpose() * s * 1e6
    }
}

fn shape(xi: f64, eta: f64) -> [f64; 4] {
    [0, 1, 2, 3].map(|i| 0.25 * (1.0 + xi * XI[i]) * (1.0 + eta * ETA[i]))
}

fn gauss_points() -> impl Iterator<Item = (f64, f64, f64)> {
    [
        (-GAUSS, -GAUSS),
        (GAUSS, -GAUSS),
        (GAUSS, GAUSS),
        (-GAUSS, GAUSS),
    ]
    .into_iter()
    .map(|(a, b)| (a, b, 1.0))
}

/// The `N x N` (`N` a multiple of 3) block-diagonal matrix with the rotation `axes` (rows = local
/// axes in global coordinates) on every 3 x 3 diagonal block: global to local element DOFs.
pub(crate) fn block_rotation<const N: usize>(axes: &Matrix3<f64>) -> SMatrix<f64, N, N> {
    let mut t = SMatrix::<f64, N, N>::zeros();
    for blk in 0..N / 3 {
        t.fixed_view_mut::<3, 3>(3 * blk, 3 * blk).copy_from(axes);
    }
    t
}
