//! Consistent nodal loads: hydrostatic pressure on the skin plate and quoin line loads.
//!
//! * Water at level `h` on the upstream face pushes the skin plate downstream (`+y`) with
//!   pressure `γ (h − z)₊`. Nodal forces are the exact integrals `∫ N_i γ (h − z)₊ dA` over
//!   each skin element, split at the waterline (two-point Gauss in `z` on the wetted part is
//!   exact: bilinear shape function times linear pressure). The derivative with respect to `h`
//!   is the same integral with the pressure replaced by `γ` on the wetted part (the integrand
//!   vanishes at the waterline, so the moving limit adds nothing).
//! * A quoin line load `q(z)`, piecewise linear between representation points, becomes nodal
//!   forces `F_j = ∫ ψ_j(z) q(z) dz` with `ψ_j` the piecewise-linear trace of the shell shape
//!   functions on the bearing line; see [`load_transfer`].

use crate::GateError;
use crate::fe::ShellMesh;
use nalgebra::DMatrix;

const G2: f64 = 0.577_350_269_189_625_8;

/// Consistent load transfer `T` (`m x N_u`): `T[j][b] = ∫ ψ_j φ_b dz`, the nodal force (lbf)
/// at quoin node `j` per unit line load (lbf/in) at representation point `b`, with `ψ_j` the
/// hat functions of the node heights and `φ_b` those of the points. Integrated exactly
/// (Simpson's rule on the merged breakpoints: the product of two linear functions is
/// quadratic). Loads outside the range of the points are zero.
///
/// ```
/// use mitergate::loads::load_transfer;
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

/// Nodal forces along `+y` (lbf, as `(full dof, value)` pairs, one per loaded node and skin
/// element) of water at level `h` (in) on the upstream face of the skin elements `skin` with
/// unit weight `gamma` (lbf/in³); with `derivative` the derivative of those forces with
/// respect to `h` (lbf/in). The skin elements must be rectangles in the plane `y = 0` with
/// edges along `x` and `z` (as the gate mesher makes them).
///
/// ```
/// use mitergate::fe::{QuadElement, ShellMesh};
/// use mitergate::loads::skin_pressure_loads;
/// let mesh = ShellMesh {
///     nodes: vec![[0.,0.,0.],[2.,0.,0.],[2.,0.,3.],[0.,0.,3.]],
///     elements: vec![QuadElement { nodes: [0, 1, 2, 3], thickness: 0.5 }],
/// };
/// let f = skin_pressure_loads(&mesh, &[0], 0.0361, 1.5, false).unwrap();
/// let total: f64 = f.iter().map(|p| p.1).sum();
/// assert!((total - 0.0361 * 2.0 * 1.5 * 1.5 / 2.0).abs() < 1e-12); // γ L h² / 2
/// ```
pub fn skin_pressure_loads(
    mesh: &ShellMesh,
    skin: &[usize],
    gamma: f64,
    h: f64,
    derivative: bool,
) -> Result<Vec<(usize, f64)>, GateError> {
    let mut out = Vec::new();
    for &e in skin {
        let el = mesh
            .elements
            .get(e)
            .ok_or_else(|| GateError::InvalidMesh(format!("skin element {e} does not exist")))?;
        let p = el.nodes.map(|n| mesh.nodes[n]);
        let (x0, x1) = min_max(p.iter().map(|c| c[0]));
        let (z0, z1) = min_max(p.iter().map(|c| c[2]));
        let aligned = p.iter().all(|c| {
            c[1].abs() < 1e-9 * (1.0 + x1.abs())
                && (c[0] == x0 || c[0] == x1)
                && (c[2] == z0 || c[2] == z1)
        });
        if !aligned || x1 <= x0 || z1 <= z0 {
            return Err(GateError::InvalidMesh(format!(
                "skin element {e} is not an axis-aligned rectangle in the plane y = 0"
            )));
        }
        if h <= z0 {
            continue;
        }
        let zt = h.min(z1);
        let (c, r) = (0.5 * (z0 + zt), 0.5 * (zt - z0));
        for (k, &node) in el.nodes.iter().enumerate() {
            let top = p[k][2] == z1;
            let mut fz = 0.0;
            for g in [-G2, G2] {
                let z = c + r * g;
                let shape = if top {
                    (z - z0) / (z1 - z0)
                } else {
                    (z1 - z) / (z1 - z0)
                };
                let pressure = if derivative { gamma } else { gamma * (h - z) };
                fz += shape * pressure * r;
            }
            out.push((6 * node + 1, fz * 0.5 * (x1 - x0)));
        }
    }
    Ok(out)
}

fn min_max(it: impl Iterator<Item = f64>) -> (f64, f64) {
    it.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    })
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
    let nn = z.len();
    let mut out = vec![0.0; nn];
    if z.iter().all(|&zi| zi >= h) {
        return out;
    }
    // height z = c0 + c1 ξ + (d0 + d1 ξ) η; inner domain [lo0 + lo1 ξ, hi0 + hi1 ξ]
    let (xi_range, c, d, lo, hi) = if nn == 4 {
        let a0 = 0.25 * (z[0] + z[1] + z[2] + z[3]);
        let a1 = 0.25 * (-z[0] + z[1] + z[2] - z[3]);
        let a2 = 0.25 * (-z[0] - z[1] + z[2] + z[3]);
        let a3 = 0.25 * (z[0] - z[1] + z[2] - z[3]);
        ((-1.0, 1.0), (a0, a1), (a2, a3), (-1.0, 0.0), (1.0, 0.0))
    } else {
        (
            (0.0, 1.0),
            (z[0], z[1] - z[0]),
            (z[2] - z[0], 0.0),
            (0.0, 0.0),
            (1.0, -1.0),
        )
    };
    let scale = z.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(h.abs());
    let mut splits = vec![xi_range.0, xi_range.1];
    for b in [lo, hi] {
        // (c0 + c1 ξ) + (d0 + d1 ξ)(b0 + b1 ξ) = h
        let qa = d.1 * b.1;
        let qb = c.1 + d.0 * b.1 + d.1 * b.0;
        let qc = c.0 + d.0 * b.0 - h;
        splits.extend(quadratic_roots(qa, qb, qc));
    }
    if d.1 != 0.0 {
        splits.push(-d.0 / d.1);
    }
    splits.retain(|&s| s >= xi_range.0 && s <= xi_range.1);
    splits.sort_by(f64::total_cmp);
    splits.dedup();
    let (go, wo) = gauss_rule(OUTER_POINTS);
    let (gi, wi) = gauss_rule(INNER_POINTS);
    for w in splits.windows(2) {
        let (xa, xb) = (w[0], w[1]);
        if xb - xa <= 1e-15 {
            continue;
        }
        for (&s, &ws) in go.iter().zip(&wo) {
            let xi = 0.5 * (xa + xb) + 0.5 * (xb - xa) * s;
            let wx = 0.5 * (xb - xa) * ws;
            let (lo_x, hi_x) = (lo.0 + lo.1 * xi, hi.0 + hi.1 * xi);
            let (cx, dx) = (c.0 + c.1 * xi, d.0 + d.1 * xi);
            let (ea, eb) = if dx.abs() <= 1e-14 * scale {
                if cx < h { (lo_x, hi_x) } else { continue }
            } else {
                let cut = (h - cx) / dx;
                if dx > 0.0 {
                    (lo_x, hi_x.min(cut))
                } else {
                    (lo_x.max(cut), hi_x)
                }
            };
            if eb <= ea {
                continue;
            }
            for (&t, &wt) in gi.iter().zip(&wi) {
                let eta = 0.5 * (ea + eb) + 0.5 * (eb - ea) * t;
                let weight = wx * 0.5 * (eb - ea) * wt;
                let (shape, area) = face_shape(xyz, xi, eta);
                let zq: f64 = shape.iter().zip(z).map(|(n, zi)| n * zi).sum();
                let p = if derivative {
                    gamma
                } else {
                    gamma * (h - zq).max(0.0)
                };
                for (o, n) in out.iter_mut().zip(&shape) {
                    *o += n * p * area * weight;
                }
            }
        }
    }
    out
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
