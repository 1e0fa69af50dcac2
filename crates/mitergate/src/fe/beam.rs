//! Two-node 3-D beam (Abaqus `B31`) with 6 DOFs per node, compatible with the shell nodes.
//!
//! **Formulation**: the exact two-node Timoshenko beam stiffness of Przemieniecki (*Theory of
//! Matrix Structural Analysis*, 1968, Sec. 5.6): cubic bending interpolation with the shear
//! parameter `Φ = 12 E I / (G A_s L²)` in each bending plane, linear axial and Saint-Venant
//! torsion. It reproduces the Timoshenko beam solution exactly at the nodes for end loads
//! (one element gives the exact cantilever tip deflection `P L³/(3EI) + P L/(G A_s)`); with
//! no shear area (`A_s = ∞`, `Φ = 0`) it is the Euler–Bernoulli (Hermite) beam. Abaqus's `B31`
//! is also shear-flexible (Timoshenko), with linear interpolation and one integration point,
//! so it converges to the same beam theory under mesh refinement.
//!
//! **Section axes (Abaqus convention)**: `t` along the beam from its first to its second node;
//! the first section axis `n1` is the direction given on the second data line of
//! `*BEAM SECTION` made normal to `t` (`n2 = t × n1_approx / |…|`, `n1 = n2 × t`); when that
//! line is absent, `n1_approx = (0, 0, −1)`, Abaqus's default. `(t, n1, n2)` is right-handed.
//! Section coordinates `(x1, x2)` run along `(n1, n2)`; `I11 = ∫ x2² dA` (bending about `n1`),
//! `I22 = ∫ x1² dA` (about `n2`), `I12 = ∫ x1 x2 dA`; a non-zero `I12` is handled by rotating
//! to the principal axes of the bending stiffness `E [[I11, −I12], [−I12, I22]]`.
//!
//! Not modelled: offsets of the beam axis from the nodes (the beam axis runs through its
//! nodes), warping torsion, shear centre eccentricity.

use crate::error::GateError;
use nalgebra::{Matrix2, Matrix3, SMatrix, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

/// 12×12 beam matrix (2 nodes × 6 DOFs).
pub type Mat12 = SMatrix<f64, 12, 12>;

/// Abaqus's default approximate first section axis `n1` of a beam in space.
pub const DEFAULT_N1: [f64; 3] = [0.0, 0.0, -1.0];

/// Shear correction factor of a solid rectangle (Timoshenko), used for `RECT` sections.
pub const RECT_SHEAR_CORRECTION: f64 = 5.0 / 6.0;

/// Section properties of a beam (in², in⁴).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BeamSectionProperties {
    /// Area `A` (in²).
    pub area: f64,
    /// `I11 = ∫ x2² dA` (in⁴): bending about the first section axis `n1`.
    pub i11: f64,
    /// `I12 = ∫ x1 x2 dA` (in⁴).
    pub i12: f64,
    /// `I22 = ∫ x1² dA` (in⁴): bending about the second section axis `n2`.
    pub i22: f64,
    /// Saint-Venant torsion constant `J` (in⁴).
    pub torsion_constant: f64,
    /// Transverse shear area `A_s` (in², the same in both directions); `None`: shear-rigid
    /// (Euler–Bernoulli).
    pub shear_area: Option<f64>,
}

impl BeamSectionProperties {
    /// A solid rectangle `a` (along `n1`) by `b` (along `n2`), in: `A = ab`, `I11 = a b³/12`,
    /// `I22 = b a³/12`, `J` from Roark's series (`L s³ [1/3 − 0.21 (s/L)(1 − s⁴/(12 L⁴))]`,
    /// `L`/`s` the long/short side, within 0.5 % of the exact series), shear area
    /// `5/6 A`.
    ///
    /// ```
    /// let s = mitergate::fe::beam::BeamSectionProperties::rectangle(2.0, 4.0).unwrap();
    /// assert_eq!((s.area, s.i11, s.i22), (8.0, 2.0 * 64.0 / 12.0, 4.0 * 8.0 / 12.0));
    /// ```
    pub fn rectangle(a: f64, b: f64) -> Result<Self, GateError> {
        if !(a > 0.0 && b > 0.0 && a.is_finite() && b.is_finite()) {
            return Err(GateError::InvalidInput {
                what: "rectangular beam section (a, b)".into(),
                reason: format!("sides {a}, {b} must be finite and > 0"),
            });
        }
        let (l, s) = (a.max(b), a.min(b));
        let j =
            l * s.powi(3) * (1.0 / 3.0 - 0.21 * (s / l) * (1.0 - s.powi(4) / (12.0 * l.powi(4))));
        Ok(Self {
            area: a * b,
            i11: a * b.powi(3) / 12.0,
            i12: 0.0,
            i22: b * a.powi(3) / 12.0,
            torsion_constant: j,
            shear_area: Some(RECT_SHEAR_CORRECTION * a * b),
        })
    }

    /// A general section from `A, I11, I12, I22, J` (Abaqus `*BEAM GENERAL SECTION`), shear
    /// rigid.
    ///
    /// ```
    /// let s = mitergate::fe::beam::BeamSectionProperties::general(3.0, 2.0, 0.5, 1.0, 0.4).unwrap();
    /// assert!(s.shear_area.is_none());
    /// assert!(mitergate::fe::beam::BeamSectionProperties::general(3.0, 1.0, 2.0, 1.0, 0.4).is_err());
    /// ```
    pub fn general(area: f64, i11: f64, i12: f64, i22: f64, j: f64) -> Result<Self, GateError> {
        let s = Self {
            area,
            i11,
            i12,
            i22,
            torsion_constant: j,
            shear_area: None,
        };
        s.validate()?;
        Ok(s)
    }

    fn validate(&self) -> Result<(), GateError> {
        let ok = [self.area, self.i11, self.i22, self.torsion_constant]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0)
            && self.i12.is_finite()
            && self.i11 * self.i22 > self.i12 * self.i12
            && self.shear_area.is_none_or(|a| a > 0.0 && a.is_finite());
        if ok {
            Ok(())
        } else {
            Err(GateError::InvalidInput {
                what: "beam section".into(),
                reason: format!(
                    "need A, I11, I22, J > 0, I11 I22 > I12² and a positive shear area: {self:?}"
                ),
            })
        }
    }
}

/// Elastic moduli of a beam (psi).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BeamMaterial {
    /// Young's modulus `E` (psi).
    pub youngs_modulus: f64,
    /// Shear modulus `G` (psi).
    pub shear_modulus: f64,
}

impl BeamMaterial {
    /// From `E` and Poisson's ratio: `G = E / (2 (1 + ν))`.
    ///
    /// ```
    /// let m = mitergate::fe::beam::BeamMaterial::isotropic(26.0, 0.3);
    /// assert!((m.shear_modulus - 10.0).abs() < 1e-12);
    /// ```
    pub fn isotropic(youngs_modulus: f64, poisson_ratio: f64) -> Self {
        Self {
            youngs_modulus,
            shear_modulus: youngs_modulus / (2.0 * (1.0 + poisson_ratio)),
        }
    }
}

/// A two-node beam with its section frame, ready to give its stiffness.
#[derive(Debug, Clone, PartialEq)]
pub struct Beam {
    /// Rows: `t`, principal axis `p1`, `p2 = t × p1` (global).
    axes: Matrix3<f64>,
    /// Section axes `(t, n1, n2)` as rows.
    section_axes: Matrix3<f64>,
    length: f64,
    /// Bending inertias about `p1` and `p2` (in⁴).
    principal: [f64; 2],
    section: BeamSectionProperties,
    material: BeamMaterial,
}

impl Beam {
    /// Builds the beam from its end points (in), the approximate first section axis
    /// (`None`: [`DEFAULT_N1`]), the section and the material.
    ///
    /// ```
    /// use mitergate::fe::beam::{Beam, BeamMaterial, BeamSectionProperties};
    /// let s = BeamSectionProperties::rectangle(1.0, 2.0).unwrap();
    /// let b = Beam::new([0.; 3], [10., 0., 0.], None, s, BeamMaterial::isotropic(29e6, 0.3)).unwrap();
    /// assert_eq!(b.section_axes()[1], [0.0, 0.0, -1.0]);
    /// assert!(Beam::new([0.; 3], [0., 0., 5.], None, s, BeamMaterial::isotropic(29e6, 0.3)).is_err());
    /// ```
    pub fn new(
        p1: [f64; 3],
        p2: [f64; 3],
        n1_approx: Option<[f64; 3]>,
        section: BeamSectionProperties,
        material: BeamMaterial,
    ) -> Result<Self, GateError> {
        section.validate()?;
        if !(material.youngs_modulus > 0.0 && material.shear_modulus > 0.0) {
            return Err(GateError::InvalidInput {
                what: "beam material".into(),
                reason: format!("E and G must be > 0: {material:?}"),
            });
        }
        let d = Vector3::from(p2) - Vector3::from(p1);
        let length = d.norm();
        if !(length > 0.0 && length.is_finite()) {
            return Err(GateError::InvalidMesh(format!(
                "beam from {p1:?} to {p2:?} has zero length"
            )));
        }
        let t = d / length;
        let n1a = Vector3::from(n1_approx.unwrap_or(DEFAULT_N1));
        let n2 = t.cross(&n1a);
        if !(n2.norm() > 1e-6 * n1a.norm()) {
            return Err(GateError::InvalidMesh(format!(
                "beam from {p1:?} to {p2:?}: its first section axis {:?} is parallel to the \
                 beam (give a direction on the second data line of *BEAM SECTION)",
                n1a.as_slice()
            )));
        }
        let n2 = n2.normalize();
        let n1 = n2.cross(&t);
        // principal axes of E [[I11, -I12], [-I12, I22]] in the (n1, n2) rotation components
        let s = Matrix2::new(section.i11, -section.i12, -section.i12, section.i22);
        let eig = SymmetricEigen::new(s);
        let v = eig.eigenvectors.column(0);
        let q1 = n1 * v[0] + n2 * v[1];
        let q2 = t.cross(&q1);
        Ok(Self {
            axes: Matrix3::from_rows(&[t.transpose(), q1.transpose(), q2.transpose()]),
            section_axes: Matrix3::from_rows(&[t.transpose(), n1.transpose(), n2.transpose()]),
            length,
            principal: [eig.eigenvalues[0], eig.eigenvalues[1]],
            section,
            material,
        })
    }

    /// Section axes `[t, n1, n2]` (global unit vectors).
    ///
    /// ```
    /// use mitergate::fe::beam::{Beam, BeamMaterial, BeamSectionProperties};
    /// let s = BeamSectionProperties::rectangle(1.0, 2.0).unwrap();
    /// let b = Beam::new([0.; 3], [0., 3., 0.], Some([1., 0., 0.]), s, BeamMaterial::isotropic(1.0, 0.0)).unwrap();
    /// assert_eq!(b.section_axes(), [[0., 1., 0.], [1., 0., 0.], [0., 0., -1.]]);
    /// ```
    pub fn section_axes(&self) -> [[f64; 3]; 3] {
        let r = |i: usize| {
            let row = self.section_axes.row(i);
            [row[0], row[1], row[2]]
        };
        [r(0), r(1), r(2)]
    }

    /// Length (in).
    ///
    /// ```
    /// use mitergate::fe::beam::{Beam, BeamMaterial, BeamSectionProperties};
    /// let s = BeamSectionProperties::rectangle(1.0, 2.0).unwrap();
    /// let b = Beam::new([0.; 3], [3., 4., 0.], None, s, BeamMaterial::isotropic(1.0, 0.0)).unwrap();
    /// assert_eq!(b.length(), 5.0);
    /// ```
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Stiffness in the principal frame `(t, p1, p2)`, DOFs per node `[u, v, w, θt, θ1, θ2]`.
    fn local_stiffness(&self) -> Mat12 {
        let (e, g, l) = (
            self.material.youngs_modulus,
            self.material.shear_modulus,
            self.length,
        );
        let mut k = Mat12::zeros();
        let mut put = |dofs: [usize; 2], v: f64| {
            let [a, b] = dofs;
            k[(a, a)] += v;
            k[(b, b)] += v;
            k[(a, b)] -= v;
            k[(b, a)] -= v;
        };
        put([0, 6], e * self.section.area / l);
        put([3, 9], g * self.section.torsion_constant / l);
        let phi = |i: f64| match self.section.shear_area {
            Some(a_s) => 12.0 * e * i / (g * a_s * l * l),
            None => 0.0,
        };
        // bending with displacement along p1 (index 1) and rotation about p2 (index 5):
        // inertia about p2; displacement along p2 (2) with rotation about p1 (4): about p1
        for (disp, rot, inertia, sign) in [
            (1, 5, self.principal[1], 1.0),
            (2, 4, self.principal[0], -1.0),
        ] {
            let ph = phi(inertia);
            let c = e * inertia / ((1.0 + ph) * l.powi(3));
            let idx = [disp, rot, disp + 6, rot + 6];
            let s6 = sign * 6.0 * l;
            let block = [
                [12.0, s6, -12.0, s6],
                [s6, (4.0 + ph) * l * l, -s6, (2.0 - ph) * l * l],
                [-12.0, -s6, 12.0, -s6],
                [s6, (2.0 - ph) * l * l, -s6, (4.0 + ph) * l * l],
            ];
            for a in 0..4 {
                for b in 0..4 {
                    k[(idx[a], idx[b])] += c * block[a][b];
                }
            }
        }
        k
    }

    /// Global stiffness (12×12, DOFs per node `[ux, uy, uz, rx, ry, rz]`).
    ///
    /// ```
    /// use mitergate::fe::beam::{Beam, BeamMaterial, BeamSectionProperties};
    /// let s = BeamSectionProperties::rectangle(1.0, 2.0).unwrap();
    /// let b = Beam::new([0.; 3], [10., 0., 0.], None, s, BeamMaterial::isotropic(29e6, 0.3)).unwrap();
    /// let k = b.stiffness();
    /// assert!((k[(0, 0)] - 29e6 * 2.0 / 10.0).abs() < 1e-6); // EA / L
    /// ```
    pub fn stiffness(&self) -> Mat12 {
        let mut t = Mat12::zeros();
        for blk in 0..4 {
            t.fixed_view_mut::<3, 3>(3 * blk, 3 * blk)
                .copy_from(&self.axes);
        }
        t.transpose() * self.local_stiffness() * t
    }
}
