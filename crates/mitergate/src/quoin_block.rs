//! The third level of the gate's multi-level model (paper Eq. 8, Fig. 2, Sec. 1 and 4): what
//! the quoin contact force does to the quoin blocks.
//!
//! The gate's quoin block (convex, radius `R_g`) bears on the wall's quoin block (concave,
//! radius `R_w > R_g`, or flat) along the height: a line contact per unit height, loaded by the
//! normal line load `F_N` (lbf/in) of the contact model. Per representation point:
//!
//! * **Hertz line contact** (Johnson, *Contact Mechanics*, 1985, §4.3, Eq. 4.43-4.45): effective
//!   radius `1/R = 1/R_g − 1/R_w`, effective modulus `1/E* = (1−ν²)/E + (1−ν²)/E` (same steel),
//!   half-width `b = √(4 F_N R / (π E*))` (in), peak pressure `p₀ = 2 F_N / (π b)` (psi);
//! * **the largest sub-surface shear** on the symmetry axis, `τ_max = 0.300 p₀` at depth
//!   `z = 0.786 b` (Johnson §4.3, Fig. 4.6) — where rolling-contact fatigue cracks start;
//! * **the surface tension of the tangential traction** (Smith and Liu, J. Appl. Mech. 20,
//!   1953): a sliding traction `Q = μ_eff F_N` adds `σ_x = 2 μ_eff p₀ = 4 |Q| / (π b)` at the
//!   trailing edge. The contact model's tangential line load is a penalty regularisation that
//!   can exceed the friction limit near the contact edge (docs/contact.md), which a real block
//!   cannot carry: `|Q|` is capped at `μ F_N` ([`QuoinBlockParams::friction`]);
//! * **fatigue**: one lockage is one cycle from the empty lock (no quoin load) to the loaded
//!   state, so the shear stress range is `Δτ = τ_max`; its life `N(Δτ)` is the stress-life curve
//!   of a steel detail in shear ([`ShearSnCurve`], EN 1993-1-9 Table 7.1 / Fig. 7.2: detail
//!   category `Δτ_C = 100 MPa` at `2·10⁶` cycles, slope `m = 5`, no damage below the cut-off
//!   `Δτ_L` at `10⁸` cycles); Miner's rule sums damage `Σ 1/N(Δτ_i)` over cycles.
//!
//! The block radii are a gate's own data (set them from its drawings); the defaults
//! (`R_g = 10 in`, `R_w = 10.5 in`, a nearly conforming pair) are illustrative, not from a
//! particular gate. The contact-stress and S-N formulas are the textbook closed forms cited;
//! a real block's life also depends on wear, misalignment and corrosion, which they ignore.

use crate::error::GateError;
use serde::{Deserialize, Serialize};

/// One MPa in psi.
pub const PSI_PER_MPA: f64 = 145.037_738;

/// A stress-life curve for shear stress ranges: `N = N_C (Δτ_C / Δτ)^m` above the cut-off
/// limit, infinite life below it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShearSnCurve {
    /// Reference stress range `Δτ_C` (psi) at [`reference_cycles`](Self::reference_cycles).
    pub reference_range_psi: f64,
    /// Cycles `N_C` at the reference range.
    pub reference_cycles: f64,
    /// Inverse slope `m`.
    pub slope: f64,
    /// Cycles at the cut-off limit (no damage from smaller ranges).
    pub cutoff_cycles: f64,
}

impl Default for ShearSnCurve {
    /// EN 1993-1-9, shear detail category 100: `Δτ_C = 100 MPa` at `2·10⁶`, `m = 5`, cut-off at
    /// `10⁸` cycles (`Δτ_L = 45.7 MPa`).
    fn default() -> Self {
        Self {
            reference_range_psi: 100.0 * PSI_PER_MPA,
            reference_cycles: 2.0e6,
            slope: 5.0,
            cutoff_cycles: 1.0e8,
        }
    }
}

impl ShearSnCurve {
    /// The cut-off stress range `Δτ_L` (psi).
    pub fn cutoff_range_psi(&self) -> f64 {
        self.reference_range_psi
            * (self.reference_cycles / self.cutoff_cycles).powf(1.0 / self.slope)
    }

    /// Cycles to crack initiation at the stress range `range_psi` (infinite below the cut-off).
    pub fn cycles_to_failure(&self, range_psi: f64) -> f64 {
        if range_psi <= self.cutoff_range_psi() {
            return f64::INFINITY;
        }
        self.reference_cycles * (self.reference_range_psi / range_psi).powf(self.slope)
    }

    /// Miner's damage sum of the stress ranges (psi), one cycle each.
    pub fn miner_damage(&self, ranges_psi: &[f64]) -> f64 {
        ranges_psi
            .iter()
            .map(|r| 1.0 / self.cycles_to_failure(*r))
            .sum()
    }
}

/// The quoin blocks' geometry, steel and fatigue curve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuoinBlockParams {
    /// Radius of the gate's convex quoin block (in).
    pub gate_block_radius_in: f64,
    /// Radius of the wall's concave quoin block (in); `f64::INFINITY` or 0 for a flat block.
    pub wall_block_radius_in: f64,
    /// Young's modulus of the block steel (psi).
    pub youngs_modulus_psi: f64,
    /// Poisson's ratio of the block steel.
    pub poisson_ratio: f64,
    /// Friction coefficient: the largest tangential line load the contact carries is
    /// `friction × F_N`.
    pub friction: f64,
    /// Stress-life curve of the detail in shear.
    pub sn_curve: ShearSnCurve,
}

impl Default for QuoinBlockParams {
    /// Illustrative nearly conforming blocks (10 in in 10.5 in), structural steel
    /// (`E = 29·10⁶` psi, `ν = 0.3`), steel-on-steel friction 0.3, EN 1993-1-9 shear curve.
    fn default() -> Self {
        Self {
            gate_block_radius_in: 10.0,
            wall_block_radius_in: 10.5,
            youngs_modulus_psi: 29.0e6,
            poisson_ratio: 0.3,
            friction: 0.3,
            sn_curve: ShearSnCurve::default(),
        }
    }
}

/// The Hertz line contact at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HertzLine {
    /// Contact half-width `b` (in).
    pub half_width_in: f64,
    /// Peak pressure `p₀` (psi).
    pub peak_pressure_psi: f64,
    /// Largest sub-surface shear stress `τ_max = 0.300 p₀` (psi).
    pub max_shear_psi: f64,
    /// Its depth `0.786 b` (in).
    pub max_shear_depth_in: f64,
}

impl QuoinBlockParams {
    /// Checks every field; errors name it.
    pub fn validate(&self) -> Result<(), GateError> {
        let bad = |parameter: &str, reason: String| {
            Err(GateError::InvalidConfig {
                parameter: parameter.into(),
                reason,
            })
        };
        let (rg, rw) = (self.gate_block_radius_in, self.wall_block_radius_in);
        if !(rg.is_finite() && rg > 0.0) {
            return bad("gate_block_radius_in", format!("must be > 0, got {rg}"));
        }
        if !(rw == 0.0 || rw.is_infinite() || rw > rg) {
            return bad(
                "wall_block_radius_in",
                format!("must exceed the gate block's {rg} in (or be 0/inf for flat), got {rw}"),
            );
        }
        let e = self.youngs_modulus_psi;
        if !(e.is_finite() && e > 0.0) {
            return bad("youngs_modulus_psi", format!("must be > 0, got {e}"));
        }
        if !(self.poisson_ratio > -1.0 && self.poisson_ratio < 0.5) {
            return bad(
                "poisson_ratio",
                format!("must be in (-1, 0.5), got {}", self.poisson_ratio),
            );
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return bad("friction", format!("must be >= 0, got {}", self.friction));
        }
        let sn = &self.sn_curve;
        let positive = [
            sn.reference_range_psi,
            sn.reference_cycles,
            sn.slope,
            sn.cutoff_cycles,
        ];
        if !positive.iter().all(|v| v.is_finite() && *v > 0.0) {
            return bad("sn_curve", "every field must be a positive number".into());
        }
        Ok(())
    }

    /// Effective radius `R` (in) of the pair.
    pub fn effective_radius_in(&self) -> f64 {
        let rw = self.wall_block_radius_in;
        let curvature_wall = if rw == 0.0 || rw.is_infinite() {
            0.0
        } else {
            1.0 / rw
        };
        1.0 / (1.0 / self.gate_block_radius_in - curvature_wall)
    }

    /// Effective (plane-strain) modulus `E*` (psi) of two blocks of the same steel.
    pub fn effective_modulus_psi(&self) -> f64 {
        self.youngs_modulus_psi / (2.0 * (1.0 - self.poisson_ratio.powi(2)))
    }

    /// The Hertz line contact under the normal line load `normal_lbf_per_in` (compression
    /// positive; no load, no contact).
    pub fn hertz(&self, normal_lbf_per_in: f64) -> HertzLine {
        let q = normal_lbf_per_in.max(0.0);
        let b = (4.0 * q * self.effective_radius_in()
            / (std::f64::consts::PI * self.effective_modulus_psi()))
        .sqrt();
        let p0 = if b > 0.0 {
            2.0 * q / (std::f64::consts::PI * b)
        } else {
            0.0
        };
        HertzLine {
            half_width_in: b,
            peak_pressure_psi: p0,
            max_shear_psi: 0.300 * p0,
            max_shear_depth_in: 0.786 * b,
        }
    }

    /// The surface tensile stress (psi) of the tangential traction at the trailing edge,
    /// `4 |Q| / (π b)` with `|Q| ≤ friction × F_N` (zero without contact).
    pub fn traction_stress_psi(&self, normal_lbf_per_in: f64, tangential_lbf_per_in: f64) -> f64 {
        let h = self.hertz(normal_lbf_per_in);
        if h.half_width_in <= 0.0 {
            return 0.0;
        }
        let q = tangential_lbf_per_in
            .abs()
            .min(self.friction * normal_lbf_per_in.max(0.0));
        4.0 * q / (std::f64::consts::PI * h.half_width_in)
    }
}

/// Outputs per quoin point of [`QuoinBlockModel`], in this order (blocks of `N_u`).
pub const QUOIN_BLOCK_OUTPUTS: [&str; 4] = [
    "peak_pressure_psi",
    "max_shear_psi",
    "traction_stress_psi",
    "damage_per_1000_lockages",
];

/// The quoin blocks as the gate's prediction model (`mlmodel::PredictionModel`, Eq. 8): from
/// the quoin line loads (normal then tangential, lbf/in, at the `N_u` points) to, per point,
/// the Hertz peak pressure, the largest sub-surface shear, the traction's surface stress (psi)
/// and the fatigue damage of 1,000 lockages to this load (Miner, one cycle of range `τ_max`
/// per lockage). Output blocks in the order of [`QUOIN_BLOCK_OUTPUTS`].
///
/// ```
/// use mitergate::{QuoinBlockModel, QuoinBlockParams};
/// use mlmodel::PredictionModel;
/// // two quoin points: one unloaded, one at 40,000 lbf/in normal and 2,000 lbf/in tangential
/// let model = QuoinBlockModel::new(QuoinBlockParams::default(), vec![10.0, 20.0]).unwrap();
/// let forces = [0.0, 40_000.0, 0.0, 2_000.0];
/// let mut out = [0.0; 8];
/// model.evaluate(&[600.0, 100.0], &[90.0], &forces, &mut out).unwrap();
/// // by hand: 1/R = 1/10 − 1/10.5 → R = 210 in; E* = E / (2 (1 − ν²)) = 15.93e6 psi;
/// // b = √(4 · 40,000 · 210 / (π · 15.93e6)) = 0.8193 in; p₀ = 2 · 40,000 / (π b) = 31,082 psi
/// assert_eq!(out[0], 0.0);
/// assert!((out[1] - 31_082.0).abs() < 1.0, "peak pressure {}", out[1]);
/// assert!((out[3] - 0.300 * out[1]).abs() < 1e-9); // τ_max = 0.300 p₀
/// // damage of 1,000 lockages: τ_max = 9,325 psi = 64.29 MPa > the 45.7 MPa cut-off;
/// // N = 2e6 · (100 / 64.29)^5 = 1.821e7 cycles
/// assert!((out[7] - 1000.0 / 1.821e7).abs() < 1e-3 * out[7], "damage {}", out[7]);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct QuoinBlockModel {
    params: QuoinBlockParams,
    coordinates_in: Vec<f64>,
}

impl QuoinBlockModel {
    /// The model at the quoin points `coordinates_in` (height above the sill, in).
    pub fn new(params: QuoinBlockParams, coordinates_in: Vec<f64>) -> Result<Self, GateError> {
        params.validate()?;
        Ok(Self {
            params,
            coordinates_in,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &QuoinBlockParams {
        &self.params
    }

    /// The quoin points (in).
    pub fn coordinates_in(&self) -> &[f64] {
        &self.coordinates_in
    }
}

impl mlmodel::PredictionModel for QuoinBlockModel {
    fn output_names(&self) -> Vec<String> {
        QUOIN_BLOCK_OUTPUTS
            .iter()
            .flat_map(|q| {
                self.coordinates_in
                    .iter()
                    .map(move |z| format!("{q}@z={z:.1}in"))
            })
            .collect()
    }

    fn evaluate(
        &self,
        _x: &[f64],
        _theta: &[f64],
        y_u: &[f64],
        out: &mut [f64],
    ) -> mlmodel::Result<()> {
        let n = self.coordinates_in.len();
        if y_u.len() != 2 * n || out.len() != 4 * n {
            return Err(mlmodel::ModelError::Dimension {
                what: "quoin block model: forces (2 N_u) / outputs (4 N_u)",
                expected: 2 * n,
                got: y_u.len(),
            });
        }
        for b in 0..n {
            let (normal, tangential) = (y_u[b], y_u[n + b]);
            let h = self.params.hertz(normal);
            out[b] = h.peak_pressure_psi;
            out[n + b] = h.max_shear_psi;
            out[2 * n + b] = self.params.traction_stress_psi(normal, tangential);
            out[3 * n + b] = 1000.0 / self.params.sn_curve.cycles_to_failure(h.max_shear_psi);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Stresses on the symmetry axis under the Hertz pressure (Johnson Eq. 4.49, from
    /// McEwen 1949): `σ_x = −p₀ [(1 + 2 s²)/√(1 + s²) − 2 s]`, `σ_z = −p₀ / √(1 + s²)`,
    /// `s = z / b`; the largest in-plane shear is `(σ_x − σ_z) / 2`.
    fn axis_shear(p0: f64, s: f64) -> f64 {
        let sx = -p0 * ((1.0 + 2.0 * s * s) / (1.0 + s * s).sqrt() - 2.0 * s);
        let sz = -p0 / (1.0 + s * s).sqrt();
        0.5 * (sx - sz).abs()
    }

    #[test]
    fn hertz_line_contact_matches_its_closed_forms() {
        let p = QuoinBlockParams::default();
        let q = 40_000.0; // lbf/in, a loaded gate's normal line load
        let h = p.hertz(q);
        // equilibrium: the elliptical pressure p0 √(1 − x²/b²) integrates to the line load
        let n = 20_000;
        let integral: f64 = (0..n)
            .map(|i| {
                let x = -h.half_width_in + (i as f64 + 0.5) * 2.0 * h.half_width_in / n as f64;
                h.peak_pressure_psi * (1.0 - (x / h.half_width_in).powi(2)).sqrt()
            })
            .sum::<f64>()
            * 2.0
            * h.half_width_in
            / n as f64;
        // midpoint rule on a square-root edge: relative error ~1e-5 at 20,000 cells
        assert!((integral - q).abs() < 1e-4 * q, "{integral} vs {q}");
        // b from Johnson Eq. 4.45 by hand: R = 1/(1/10 − 1/10.5) = 210 in,
        // E* = 29e6 / (2 · 0.91) = 15.934e6 psi, b = √(4 · 40000 · 210 / (π · 15.934e6))
        let b = (4.0 * 40_000.0 * 210.0 / (PI * 15.934_066e6)).sqrt();
        // (E* rounded to 8 digits by hand: agreement to 1e-7)
        assert!((h.half_width_in - b).abs() < 1e-7 * b);
        assert!((p.effective_radius_in() - 210.0).abs() < 1e-9);
        // the largest axis shear of McEwen's field: 0.300 p0 at 0.786 b (3 digits, as cited)
        let (s_best, t_best) = (0..20_000)
            .map(|i| {
                let s = i as f64 * 2e-4;
                (s, axis_shear(h.peak_pressure_psi, s))
            })
            .fold((0.0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        assert!(
            (t_best / h.max_shear_psi - 1.0).abs() < 2e-3,
            "{t_best} vs {}",
            h.max_shear_psi
        );
        assert!((s_best * h.half_width_in - h.max_shear_depth_in).abs() < 2e-3 * h.half_width_in);
    }

    #[test]
    fn miner_sum_matches_a_hand_calculation() {
        let sn = ShearSnCurve::default();
        let c = sn.reference_range_psi;
        // two cycles at Δτ_C (N = 2e6 each), one at 2 Δτ_C (N = 2e6 / 2⁵ = 62,500), and one
        // below the cut-off (Δτ_L = 0.457 Δτ_C): 2 / 2e6 + 1 / 62,500 + 0 = 1.7e-5
        let d = sn.miner_damage(&[c, c, 2.0 * c, 0.4 * c]);
        assert!((d - 1.7e-5).abs() < 1e-12, "{d}");
        assert!((sn.cutoff_range_psi() / c - 0.457_305).abs() < 1e-5);
    }

    #[test]
    fn traction_is_capped_at_friction_and_absent_without_contact() {
        let p = QuoinBlockParams::default();
        let h = p.hertz(10_000.0);
        let capped = p.traction_stress_psi(10_000.0, -2.6e6);
        // at the cap Q = μ F_N the closed form is 2 μ p0
        assert!((capped - 2.0 * 0.3 * h.peak_pressure_psi).abs() < 1e-9 * capped);
        assert_eq!(p.traction_stress_psi(0.0, 500.0), 0.0);
        assert_eq!(p.hertz(-5.0).peak_pressure_psi, 0.0);
    }

    #[test]
    fn bad_parameters_are_named() {
        let p = QuoinBlockParams {
            wall_block_radius_in: 9.0,
            ..QuoinBlockParams::default()
        };
        assert!(
            p.validate()
                .unwrap_err()
                .to_string()
                .contains("wall_block_radius_in")
        );
    }
}
