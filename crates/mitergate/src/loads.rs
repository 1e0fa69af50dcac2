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
