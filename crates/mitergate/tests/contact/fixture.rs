//! A small analytical gate for the contact tests, until the FE model is available.
//!
//! The quoin post is an Euler-Bernoulli beam along `z ∈ [0, H]` (H = 762 in), bending in the
//! normal direction `n` (EI_n) and the tangential direction `t` (EI_t), with
//! * an elastic pintle at `z = 0` and an elastic gudgeon at `z = H` (both directions),
//! * an elastic "girder" foundation per unit height, coupling `n` and `t` (the leaf's in-plane
//!   compliance towards the miter, giving `C_NT ≠ 0`),
//! * hydrostatic water on the leaf (width 760 in), whose line load reaches the post as
//!   `-1.5 w` along `n` (thrust into the wall, ~1/(2 tan α) for an 18° miter angle) and
//!   `+0.5 w` along `t`, with `w = γ L (h - z)_+` (lbf/in), distributed to the nodes with linear
//!   hats (so the responses are exact piecewise cubics in `h`, as the contract requires),
//! * 7 gauges: bending strain `c κ(z)` (c = 24 in) at 4 heights of the `n` beam and 3 of the
//!   `t` beam, in microstrain.
//!
//! Everything in the [`CondensedGate`] is computed exactly from this model by static
//! condensation of the rotations and the non-quoin parts: `C = Bᵀ K⁻¹ B`,
//! `u_w = Bᵀ K⁻¹ F_w(h)`, `A = E K⁻¹ B blockdiag(T, T)`, `s_w = E K⁻¹ F_w(h)`.
//!
//! To run the tests on the real gate, make [`gate`] return
//! `mitergate::GateModel::build(&mitergate::GateConfig::default())?.condense(509)?`.

use mitergate::condense::{CondensedGate, HydrostaticTable};
use mitergate::fe::loads::linear_load_transfer;
use nalgebra::{DMatrix, DVector};

/// Quoin height (in).
pub const H: f64 = 762.0;
/// Unit weight of water (lbf/in³): 62.4 lbf/ft³.
const GAMMA: f64 = 62.4 / 1728.0;
/// Leaf width carrying water to the quoin (in).
const LEAF: f64 = 760.0;
/// Normal and tangential fractions of the water line load reaching the post.
const LOAD_DIR: [f64; 2] = [-1.5, 0.5];
/// Bending stiffness (lbf in²) in n and t.
const EI: [f64; 2] = [5e11, 2e11];
/// Pintle and gudgeon springs (lbf/in), same in both directions.
const PINTLE: f64 = 5e7;
const GUDGEON: f64 = 2e7;
/// Foundation per unit height (psi): [[nn, nt], [nt, tt]].
const FOUNDATION: [[f64; 2]; 2] = [[1e4, 3e3], [3e3, 5e3]];
/// Gauge heights (in) on the n beam and the t beam, and the section half-depth (in).
const GAUGES_N: [f64; 4] = [50.0, 200.0, 420.0, 640.0];
const GAUGES_T: [f64; 3] = [130.0, 330.0, 560.0];
const HALF_DEPTH: f64 = 24.0;

/// The full beam model behind the fixture.
pub struct BeamGate {
    /// Node heights (in), also the quoin nodes.
    pub z: Vec<f64>,
    /// Inverse of the full stiffness (4m dofs: per direction, per node `[v, rotation]`).
    pub k_inv: DMatrix<f64>,
    /// Strain operator (7 x 4m), microstrain per unit dof.
    pub strain_op: DMatrix<f64>,
    /// Representation points (in).
    pub points: Vec<f64>,
}

impl BeamGate {
    /// Number of nodes.
    pub fn m(&self) -> usize {
        self.z.len()
    }
    /// Dof index of the translation of node `i` in direction `dir` (0 = n, 1 = t).
    pub fn v(&self, dir: usize, i: usize) -> usize {
        2 * self.m() * dir + 2 * i
    }
    /// Full water load vector (4m) at level `h` (translations only).
    pub fn water_load(&self, h: f64) -> DVector<f64> {
        let m = self.m();
        let mut f = DVector::zeros(4 * m);
        for i in 0..m {
            let fi = hat_moment(&self.z, i, h) * GAMMA * LEAF;
            for dir in 0..2 {
                f[self.v(dir, i)] = LOAD_DIR[dir] * fi;
            }
        }
        f
    }
    /// d(water load)/dh (4m).
    fn water_load_slope(&self, h: f64) -> DVector<f64> {
        let m = self.m();
        let mut f = DVector::zeros(4 * m);
        for i in 0..m {
            let fi = hat_mass_below(&self.z, i, h) * GAMMA * LEAF;
            for dir in 0..2 {
                f[self.v(dir, i)] = LOAD_DIR[dir] * fi;
            }
        }
        f
    }
    /// Injection `B` (4m x 2m) of quoin nodal forces `[P_N; P_T]`.
    pub fn injection(&self) -> DMatrix<f64> {
        let m = self.m();
        let mut b = DMatrix::zeros(4 * m, 2 * m);
        for dir in 0..2 {
            for i in 0..m {
                b[(self.v(dir, i), dir * m + i)] = 1.0;
            }
        }
        b
    }
    /// Full displacement (4m) under quoin forces `p` (2m, lbf) and levels.
    pub fn displacement(&self, p: &[f64], h_up: f64, h_down: f64) -> DVector<f64> {
        let load = self.injection() * DVector::from_column_slice(p) + self.water_load(h_up)
            - self.water_load(h_down);
        &self.k_inv * load
    }
    /// Support reactions (lbf) on the post in directions n and t: pintle + gudgeon + foundation.
    pub fn support_reactions(&self, u: &DVector<f64>) -> [f64; 2] {
        let m = self.m();
        let trib = tributary(&self.z);
        let mut r = [0.0; 2];
        for dir in 0..2 {
            r[dir] -= PINTLE * u[self.v(dir, 0)] + GUDGEON * u[self.v(dir, m - 1)];
            for i in 0..m {
                for other in 0..2 {
                    r[dir] -= trib[i] * FOUNDATION[dir][other] * u[self.v(other, i)];
                }
            }
        }
        r
    }
    /// Total water force (lbf) on the post in n and t.
    pub fn water_resultant(&self, h_up: f64, h_down: f64) -> [f64; 2] {
        let f = self.water_load(h_up) - self.water_load(h_down);
        let m = self.m();
        [0, 1].map(|dir| (0..m).map(|i| f[self.v(dir, i)]).sum())
    }

    /// The condensed gate of this model.
    pub fn condensed(&self) -> CondensedGate {
        let m = self.m();
        let b = self.injection();
        let kb = &self.k_inv * &b;
        let c = b.transpose() * &kb;
        let c = (&c + c.transpose()) * 0.5;
        let t = linear_load_transfer(&self.z, &self.points);
        let n = self.points.len();
        let mut t2 = DMatrix::zeros(2 * m, 2 * n);
        t2.view_mut((0, 0), (m, n)).copy_from(&t);
        t2.view_mut((m, n), (m, n)).copy_from(&t);
        let a = &self.strain_op * &kb * &t2;
        let table = |op: &DMatrix<f64>| {
            let rows = op.nrows();
            let mut values = DMatrix::zeros(m, rows);
            let mut slopes = DMatrix::zeros(m, rows);
            for (k, &h) in self.z.iter().enumerate() {
                let v = op * (&self.k_inv * self.water_load(h));
                let s = op * (&self.k_inv * self.water_load_slope(h));
                values.row_mut(k).copy_from(&v.transpose());
                slopes.row_mut(k).copy_from(&s.transpose());
            }
            HydrostaticTable::new(self.z.clone(), values, slopes).unwrap()
        };
        let bt = b.transpose();
        CondensedGate {
            quoin_height: H,
            quoin_node_heights: self.z.clone(),
            quoin_flexibility: c,
            water_quoin_displacement: table(&bt),
            gauge_names: (1..=7).map(|g| format!("SG{g}")).collect(),
            water_strain: table(&self.strain_op),
            nu_points: self.points.clone(),
            load_transfer: t,
            a_matrix: a,
        }
    }
}

/// The beam model with `m` nodes and `n_u` representation points, both uniform on `[0, H]`.
pub fn beam_gate(m: usize, n_u: usize) -> BeamGate {
    let z: Vec<f64> = (0..m).map(|i| H * i as f64 / (m - 1) as f64).collect();
    let points: Vec<f64> = (0..n_u).map(|b| H * b as f64 / (n_u - 1) as f64).collect();
    let dofs = 4 * m;
    let mut k = DMatrix::zeros(dofs, dofs);
    let trib = tributary(&z);
    let idx = |dir: usize, i: usize| 2 * m * dir + 2 * i;
    for dir in 0..2 {
        for e in 0..m - 1 {
            let l = z[e + 1] - z[e];
            let ke = hermite_stiffness(EI[dir], l);
            let d = [
                idx(dir, e),
                idx(dir, e) + 1,
                idx(dir, e + 1),
                idx(dir, e + 1) + 1,
            ];
            for r in 0..4 {
                for c in 0..4 {
                    k[(d[r], d[c])] += ke[r][c];
                }
            }
        }
        k[(idx(dir, 0), idx(dir, 0))] += PINTLE;
        k[(idx(dir, m - 1), idx(dir, m - 1))] += GUDGEON;
        for i in 0..m {
            for other in 0..2 {
                k[(idx(dir, i), idx(other, i))] += trib[i] * FOUNDATION[dir][other];
            }
        }
    }
    let k_inv = k.cholesky().expect("beam stiffness is SPD").inverse();
    let mut strain_op = DMatrix::zeros(7, dofs);
    let gauges = GAUGES_N
        .iter()
        .map(|&g| (0, g))
        .chain(GAUGES_T.iter().map(|&g| (1, g)));
    for (row, (dir, zg)) in gauges.enumerate() {
        let e = (z.partition_point(|&v| v <= zg) - 1).min(m - 2);
        let l = z[e + 1] - z[e];
        let xi = (zg - z[e]) / l;
        let curv = [
            (-6.0 + 12.0 * xi) / (l * l),
            (-4.0 + 6.0 * xi) / l,
            (6.0 - 12.0 * xi) / (l * l),
            (-2.0 + 6.0 * xi) / l,
        ];
        let d = [
            idx(dir, e),
            idx(dir, e) + 1,
            idx(dir, e + 1),
            idx(dir, e + 1) + 1,
        ];
        for j in 0..4 {
            strain_op[(row, d[j])] = HALF_DEPTH * curv[j] * 1e6;
        }
    }
    BeamGate {
        z,
        k_inv,
        strain_op,
        points,
    }
}

/// The default fixture: 33 quoin nodes (23.8 in apart) and the paper's N_u = 509 points.
pub fn gate() -> CondensedGate {
    beam_gate(33, 509).condensed()
}

/// Hermite beam element stiffness for dofs `[v1, r1, v2, r2]`.
fn hermite_stiffness(ei: f64, l: f64) -> [[f64; 4]; 4] {
    let a = ei / (l * l * l);
    [
        [12.0 * a, 6.0 * l * a, -12.0 * a, 6.0 * l * a],
        [6.0 * l * a, 4.0 * l * l * a, -6.0 * l * a, 2.0 * l * l * a],
        [-12.0 * a, -6.0 * l * a, 12.0 * a, -6.0 * l * a],
        [6.0 * l * a, 2.0 * l * l * a, -6.0 * l * a, 4.0 * l * l * a],
    ]
}

/// Tributary length of each node (the integral of its hat).
fn tributary(z: &[f64]) -> Vec<f64> {
    let m = z.len();
    (0..m)
        .map(|i| {
            let lo = if i > 0 { z[i] - z[i - 1] } else { 0.0 };
            let hi = if i + 1 < m { z[i + 1] - z[i] } else { 0.0 };
            0.5 * (lo + hi)
        })
        .collect()
}

/// `∫_0^{min(h,H)} N_i(z) (h - z) dz` for the hat `N_i` of grid `z`, exact (two-point Gauss
/// on each piece, the integrand being quadratic).
fn hat_moment(z: &[f64], i: usize, h: f64) -> f64 {
    hat_integral(z, i, h, |zz| h - zz)
}

/// `∫_0^{min(h,H)} N_i(z) dz`.
fn hat_mass_below(z: &[f64], i: usize, h: f64) -> f64 {
    hat_integral(z, i, h, |_| 1.0)
}

fn hat_integral(z: &[f64], i: usize, h: f64, g: impl Fn(f64) -> f64) -> f64 {
    let m = z.len();
    let gp = 0.5 / 3f64.sqrt();
    let mut total = 0.0;
    for e in [i.wrapping_sub(1), i] {
        if e >= m - 1 {
            continue;
        }
        let (a, b) = (z[e], z[e + 1].min(h));
        if b <= a {
            continue;
        }
        for x in [0.5 * (a + b) - gp * (b - a), 0.5 * (a + b) + gp * (b - a)] {
            let s = (x - z[e]) / (z[e + 1] - z[e]);
            let ni = if e == i { 1.0 - s } else { s };
            total += 0.5 * (b - a) * ni * g(x);
        }
    }
    total
}
