//! Hydrostatic water on the leaf: the admissible water levels and the consistent nodal loads
//! of water on the skin plate.
//!
//! Water at level `h` on the upstream face pushes the skin plate downstream (`+y`) with
//! pressure `γ (h − z)₊`. Nodal forces are the exact integrals `∫ N_i γ (h − z)₊ dA` over
//! each skin element, split at the waterline (two-point Gauss in `z` on the wetted part is
//! exact: bilinear shape function times linear pressure). The derivative with respect to `h`
//! is the same integral with the pressure replaced by `γ` on the wetted part (the integrand
//! vanishes at the waterline, so the moving limit adds nothing).

use crate::error::GateError;
use crate::fe::ShellMesh;

/// Lowest and highest admissible water levels (in), upstream and downstream (the paper's
/// range, Sec. 4.3): [`GateModel::water_load`](super::GateModel::water_load), the
/// `mlmodel` domain of the gate and the synthetic data all use it.
pub const WATER_LEVEL_RANGE: (f64, f64) = (24.0, 744.0);

const G2: f64 = 0.577_350_269_189_625_8;

/// Checks both levels against [`WATER_LEVEL_RANGE`] and `h_up >= h_down`.
pub(crate) fn check_levels(h_up: f64, h_down: f64) -> Result<(), GateError> {
    let (lo, hi) = WATER_LEVEL_RANGE;
    for (name, v) in [("h_up", h_up), ("h_down", h_down)] {
        if !(v.is_finite() && (lo..=hi).contains(&v)) {
            return Err(GateError::InvalidWaterLevel {
                parameter: name,
                value: v,
                reason: format!("must lie in [{lo}, {hi}] in"),
            });
        }
    }
    if h_up < h_down {
        return Err(GateError::InvalidWaterLevel {
            parameter: "h_up",
            value: h_up,
            reason: format!("must be >= h_down = {h_down} in (the gate holds upstream water)"),
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
/// use mitergate::gate::skin_pressure_loads;
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
