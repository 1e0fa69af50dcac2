//! Consistent nodal loads of line loads and face pressures, for any mesh.
//!
//! * A line load `q(z)`, piecewise linear between representation points, becomes nodal forces
//!   `F_j = ∫ ψ_j(z) q(z) dz` on a line of nodes, `ψ_j` the piecewise-linear trace of the
//!   shell shape functions on that line; see [`load_transfer`] (and
//!   [`linear_load_transfer`], the same integral by Gauss points).
//! * Hydrostatic pressure `γ (h − z)₊` on a flat 3- or 4-node face, clipped exactly at the
//!   waterline (`face_pressure_integrals`, used by imported decks; the parametric gate uses
//!   the closed form of `crate::gate::skin_pressure_loads`).

use crate::error::GateError;
use nalgebra::DMatrix;

/// Consistent load transfer `T` (`m x N_u`): `T[j][b] = ∫ ψ_j φ_b dz`, the nodal force (lbf)
/// at quoin node `j` per unit line load (lbf/in) at representation point `b`, with `ψ_j` the
/// hat functions of the node heights and `φ_b` those of the points. Integrated exactly
/// (Simpson's rule on the merged breakpoints: the product of two linear functions is
/// quadratic). Loads outside the range of the points are zero.
///
/// ```
/// use mitergate::fe::loads::load_transfer;
/// let t = load_transfer(&[0.0, 1.0, 3.0], &[0.0, 1.5, 3.0]).unwrap();
/// // a uniform line load of 2 lbf/in over 3 in gives 6 lbf in total
/// let total: f64 = (0..3).map(|j| (0..3).map(|b| t[(j, b)] * 2.0).sum::<f64>()).sum();
/// assert!((total - 6.0).abs() < 1e-12);
/// ```
pub fn load_transfer(node_heights: &[f64], points: &[f64]) -> Result<DMatrix<f64>, GateError> {
    check_increasing("node_heights", node_heights)?;
    check_increasing("nu_points", points)?;
    let (m, nu) = (node_heights.len(), points.len());
    let mut t = DMatrix::zeros(m, nu);
    let lo = node_heights[0].max(points[0]);
    let hi = node_heights[m - 1].min(points[nu - 1]);
    if lo >= hi {
        return Ok(t);
    }
    let mut breaks: Vec<f64> = node_heights
        .iter()
        .chain(points)
        .copied()
        .filter(|&z| z > lo && z < hi)
        .collect();
    breaks.push(lo);
    breaks.push(hi);
    breaks.sort_by(f64::total_cmp);
    breaks.dedup();
    for w in breaks.windows(2) {
        let (a, b) = (w[0], w[1]);
        let mid = 0.5 * (a + b);
        let j = interval(node_heights, mid);
        let k = interval(points, mid);
        let hat = |grid: &[f64], i: usize, z: f64| {
            let s = (z - grid[i]) / (grid[i + 1] - grid[i]);
            [1.0 - s, s]
        };
        for (z, wgt) in [(a, 1.0), (mid, 4.0), (b, 1.0)] {
            let psi = hat(node_heights, j, z);
            let phi = hat(points, k, z);
            for p in 0..2 {
                for q in 0..2 {
                    t[(j + p, k + q)] += (b - a) / 6.0 * wgt * psi[p] * phi[q];
                }
            }
        }
    }
    Ok(t)
}

fn interval(grid: &[f64], z: f64) -> usize {
    (grid.partition_point(|&g| g <= z).max(1) - 1).min(grid.len() - 2)
}

fn check_increasing(what: &str, v: &[f64]) -> Result<(), GateError> {
    if v.len() < 2 {
        return Err(GateError::InvalidInput {
            what: what.into(),
            reason: format!("needs at least 2 entries, got {}", v.len()),
        });
    }
    if v.iter().any(|x| !x.is_finite()) || v.windows(2).any(|w| w[0] >= w[1]) {
        return Err(GateError::InvalidInput {
            what: what.into(),
            reason: "must be finite and strictly increasing".into(),
        });
    }
    Ok(())
}

/// The load transfer `T` (`m x N_u`, in) of the `CondensedGate` contract for linear nodal
/// shape functions `N_i` (hats on `node_heights`) and line loads interpolated linearly between
/// `points` (hats `φ_b`): `T_ib = ∫ N_i φ_b dz`, integrated exactly (two-point Gauss on every
/// interval between merged breakpoints, where the integrand is quadratic). Both grids must be
/// strictly increasing; the load is taken as zero outside `[points[0], points[last]]`.
///
/// ```
/// let t = mitergate::fe::loads::linear_load_transfer(&[0.0, 10.0], &[0.0, 5.0, 10.0]);
/// // a unit line load everywhere gives nodal forces 5 lbf + 5 lbf
/// let total: f64 = t.row(0).sum();
/// assert!((total - 5.0).abs() < 1e-12);
/// assert!((t[(0, 0)] - 5.0 * 5.0 / 12.0).abs() < 1e-12);
/// ```
pub fn linear_load_transfer(node_heights: &[f64], points: &[f64]) -> DMatrix<f64> {
    let m = node_heights.len();
    let n = points.len();
    let mut t = DMatrix::zeros(m, n);
    let mut cuts: Vec<f64> = node_heights.iter().chain(points).copied().collect();
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let g = 0.5 / 3f64.sqrt();
    for w in cuts.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b <= points[0] || a >= points[n - 1] {
            continue;
        }
        for z in [0.5 * (a + b) - g * (b - a), 0.5 * (a + b) + g * (b - a)] {
            let weight = 0.5 * (b - a);
            for (i, ni) in hat_values(node_heights, z) {
                for (k, pk) in hat_values(points, z) {
                    t[(i, k)] += weight * ni * pk;
                }
            }
        }
    }
    t
}

/// The (at most two) nonzero hat functions of grid `x` at `z`, as `(index, value)`.
fn hat_values(x: &[f64], z: f64) -> Vec<(usize, f64)> {
    let n = x.len();
    if z < x[0] || z > x[n - 1] {
        return Vec::new();
    }
    let k = (x.partition_point(|&v| v <= z).max(1) - 1).min(n - 2);
    let s = (z - x[k]) / (x[k + 1] - x[k]);
    vec![(k, 1.0 - s), (k + 1, s)]
}

/// Gauss–Legendre rule on `[-1, 1]` (nodes, weights).
fn gauss_rule(n: usize) -> (Vec<f64>, Vec<f64>) {
    orthopoly::gauss_legendre(n, -1.0, 1.0).expect("n >= 1")
}

/// Outer (across the level lines) and inner (along `η`) Gauss orders of
/// [`face_pressure_integrals`]: the inner integrand is a polynomial of degree <= 3 in `η`
/// (3 points are exact), the outer one is piecewise smooth between the split points and a
/// polynomial of degree <= 9 for flat parallelograms and triangles (8 points are exact).
const OUTER_POINTS: usize = 8;
const INNER_POINTS: usize = 3;

/// `∫ N_i p dA` (lbf) for every node `i` of a flat 3- or 4-node face with node heights `z`
/// (in above the sill) and coordinates `xyz` (in), under water at level `h`: `p = γ (h − z)₊`,
/// or with `derivative` its `h`-derivative `γ [z < h]`. Quadrilaterals use the bilinear
/// shapes on `[-1, 1]²`, triangles the linear ones on the unit triangle.
///
/// The wetted part `{z(ξ, η) < h}` is clipped exactly: for fixed `ξ` the height is linear in
/// `η`, so the wetted `η`-interval is known in closed form, and the outer integral is split
/// where that interval meets a side of the domain. On each piece the integrand is a
/// polynomial (flat parallelograms and triangles: exact) or a smooth rational function
/// (general quadrilaterals whose level lines are not parallel to a side: 8-point Gauss,
/// accurate to round-off for the gently tapered elements of a skin plate).
pub(crate) fn face_pressure_integrals(
    xyz: &[[f64; 3]],
    z: &[f64],
    gamma: f64,
    h: f64,
    derivative: bool,
) -> Vec<f64> {
    let mut out = vec![0.0; z.len()];
    if z.iter().all(|&zi| zi >= h) {
        return out;
    }
    let face = FaceHeights::new(z);
    let scale = z.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(h.abs());
    let pressure = Pressure {
        gamma,
        h,
        derivative,
    };
    let (go, wo) = gauss_rule(OUTER_POINTS);
    let (gi, wi) = gauss_rule(INNER_POINTS);
    for w in face.splits(h).windows(2) {
        let (xa, xb) = (w[0], w[1]);
        if xb - xa <= 1e-15 {
            continue;
        }
        for (&s, &ws) in go.iter().zip(&wo) {
            let xi = 0.5 * (xa + xb) + 0.5 * (xb - xa) * s;
            let wx = 0.5 * (xb - xa) * ws;
            let Some((ea, eb)) = face.wetted_eta(xi, h, scale) else {
                continue;
            };
            for (&t, &wt) in gi.iter().zip(&wi) {
                let eta = 0.5 * (ea + eb) + 0.5 * (eb - ea) * t;
                let weight = wx * 0.5 * (eb - ea) * wt;
                pressure.add_point(xyz, z, (xi, eta), weight, &mut out);
            }
        }
    }
    out
}

/// Water at level `h` (in) of unit weight `gamma` (lbf/in³), or its `h`-derivative.
struct Pressure {
    gamma: f64,
    h: f64,
    derivative: bool,
}

impl Pressure {
    /// Adds the integrand `N_i p |x_ξ × x_η|` at the natural point `(ξ, η)` of a face, times
    /// the quadrature `weight`, to `out`.
    fn add_point(
        &self,
        xyz: &[[f64; 3]],
        z: &[f64],
        (xi, eta): (f64, f64),
        weight: f64,
        out: &mut [f64],
    ) {
        let (shape, area) = face_shape(xyz, xi, eta);
        let zq: f64 = shape.iter().zip(z).map(|(n, zi)| n * zi).sum();
        let p = if self.derivative {
            self.gamma
        } else {
            self.gamma * (self.h - zq).max(0.0)
        };
        for (o, n) in out.iter_mut().zip(&shape) {
            *o += n * p * area * weight;
        }
    }
}

/// The height over a 3- or 4-node face in natural coordinates,
/// `z = c0 + c1 ξ + (d0 + d1 ξ) η`, on the domain `ξ ∈ xi_range`,
/// `η ∈ [lo0 + lo1 ξ, hi0 + hi1 ξ]`.
struct FaceHeights {
    xi_range: (f64, f64),
    c: (f64, f64),
    d: (f64, f64),
    lo: (f64, f64),
    hi: (f64, f64),
}

impl FaceHeights {
    /// Quadrilaterals on `[-1, 1]²`, triangles on the unit triangle.
    fn new(z: &[f64]) -> Self {
        if z.len() == 4 {
            let a0 = 0.25 * (z[0] + z[1] + z[2] + z[3]);
            let a1 = 0.25 * (-z[0] + z[1] + z[2] - z[3]);
            let a2 = 0.25 * (-z[0] - z[1] + z[2] + z[3]);
            let a3 = 0.25 * (z[0] - z[1] + z[2] - z[3]);
            Self {
                xi_range: (-1.0, 1.0),
                c: (a0, a1),
                d: (a2, a3),
                lo: (-1.0, 0.0),
                hi: (1.0, 0.0),
            }
        } else {
            Self {
                xi_range: (0.0, 1.0),
                c: (z[0], z[1] - z[0]),
                d: (z[2] - z[0], 0.0),
                lo: (0.0, 0.0),
                hi: (1.0, -1.0),
            }
        }
    }

    /// Sorted break points of the outer (`ξ`) integral: the ends of the range, where the
    /// waterline meets a side of the domain, and where the height stops depending on `η`.
    fn splits(&self, h: f64) -> Vec<f64> {
        let (c, d) = (self.c, self.d);
        let mut splits = vec![self.xi_range.0, self.xi_range.1];
        for b in [self.lo, self.hi] {
            // (c0 + c1 ξ) + (d0 + d1 ξ)(b0 + b1 ξ) = h
            let qa = d.1 * b.1;
            let qb = c.1 + d.0 * b.1 + d.1 * b.0;
            let qc = c.0 + d.0 * b.0 - h;
            splits.extend(quadratic_roots(qa, qb, qc));
        }
        if d.1 != 0.0 {
            splits.push(-d.0 / d.1);
        }
        splits.retain(|&s| s >= self.xi_range.0 && s <= self.xi_range.1);
        splits.sort_by(f64::total_cmp);
        splits.dedup();
        splits
    }

    /// The wetted `η`-interval (`z < h`) at `ξ`, `None` if empty; `scale` (in) sets when the
    /// height counts as independent of `η`.
    fn wetted_eta(&self, xi: f64, h: f64, scale: f64) -> Option<(f64, f64)> {
        let (lo, hi) = (self.lo, self.hi);
        let (lo_x, hi_x) = (lo.0 + lo.1 * xi, hi.0 + hi.1 * xi);
        let (cx, dx) = (self.c.0 + self.c.1 * xi, self.d.0 + self.d.1 * xi);
        let (ea, eb) = if dx.abs() <= 1e-14 * scale {
            if cx < h {
                (lo_x, hi_x)
            } else {
                return None;
            }
        } else {
            let cut = (h - cx) / dx;
            if dx > 0.0 {
                (lo_x, hi_x.min(cut))
            } else {
                (lo_x.max(cut), hi_x)
            }
        };
        if eb <= ea { None } else { Some((ea, eb)) }
    }
}

/// Real roots of `a x² + b x + c` (a linear equation when `a = 0`).
fn quadratic_roots(a: f64, b: f64, c: f64) -> Vec<f64> {
    if a == 0.0 {
        return if b != 0.0 { vec![-c / b] } else { vec![] };
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return vec![];
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let mut r = vec![q / a];
    if q != 0.0 {
        r.push(c / q);
    }
    r
}

/// Shape functions and area density `|x_ξ × x_η|` of a 3- or 4-node face at `(ξ, η)`.
fn face_shape(xyz: &[[f64; 3]], xi: f64, eta: f64) -> (Vec<f64>, f64) {
    let (n, dxi, deta): (Vec<f64>, Vec<f64>, Vec<f64>) = if xyz.len() == 4 {
        let s = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        (
            s.iter()
                .map(|(a, b)| 0.25 * (1.0 + a * xi) * (1.0 + b * eta))
                .collect(),
            s.iter().map(|(a, b)| 0.25 * a * (1.0 + b * eta)).collect(),
            s.iter().map(|(a, b)| 0.25 * b * (1.0 + a * xi)).collect(),
        )
    } else {
        (
            vec![1.0 - xi - eta, xi, eta],
            vec![-1.0, 1.0, 0.0],
            vec![-1.0, 0.0, 1.0],
        )
    };
    let mut gx = nalgebra::Vector3::zeros();
    let mut ge = nalgebra::Vector3::zeros();
    for (k, p) in xyz.iter().enumerate() {
        gx += nalgebra::Vector3::from(*p) * dxi[k];
        ge += nalgebra::Vector3::from(*p) * deta[k];
    }
    (n, gx.cross(&ge).norm())
}
