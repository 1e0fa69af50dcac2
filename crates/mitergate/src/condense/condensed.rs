//! [`CondensedGate`] and its exact hydrostatic tables ([`HydrostaticTable`]); see the
//! [module docs](super) for units and signs.

use crate::error::GateError;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Exact piecewise-cubic table of a linear response to hydrostatic water at level `h` on the
/// upstream face of the skin plate. Below the first breakpoint the response is zero; above the
/// last it continues linearly with the last slope (the water covers the whole face, and raising
/// it adds a uniform pressure increment).
///
/// ```
/// use mitergate::condense::HydrostaticTable;
/// use nalgebra::DMatrix;
/// // response r(h) = h^3 on [0, 2], tabulated at 0, 1, 2 (exact for cubics)
/// let t = HydrostaticTable::new(
///     vec![0.0, 1.0, 2.0],
///     DMatrix::from_row_slice(3, 1, &[0.0, 1.0, 8.0]),
///     DMatrix::from_row_slice(3, 1, &[0.0, 3.0, 12.0]),
/// ).unwrap();
/// assert!((t.eval(1.5)[0] - 3.375).abs() < 1e-12);
/// assert!((t.eval(3.0)[0] - 20.0).abs() < 1e-12); // linear beyond the top
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HydrostaticTable {
    breakpoints: Vec<f64>,
    values: DMatrix<f64>,
    slopes: DMatrix<f64>,
}

impl HydrostaticTable {
    /// `breakpoints` strictly increasing (in); `values` and `slopes` have one row per breakpoint
    /// and one column per response component.
    pub fn new(
        breakpoints: Vec<f64>,
        values: DMatrix<f64>,
        slopes: DMatrix<f64>,
    ) -> Result<Self, GateError> {
        let n = breakpoints.len();
        let ok_order = breakpoints.windows(2).all(|w| w[0] < w[1]);
        if n < 2 || !ok_order || values.nrows() != n || slopes.shape() != values.shape() {
            return Err(GateError::InvalidTable(format!(
                "need >= 2 strictly increasing breakpoints and values/slopes of {n} rows \
                 with equal shapes (got values {:?}, slopes {:?})",
                values.shape(),
                slopes.shape()
            )));
        }
        Ok(Self {
            breakpoints,
            values,
            slopes,
        })
    }

    /// Number of response components.
    pub fn n_responses(&self) -> usize {
        self.values.ncols()
    }

    /// Breakpoint heights (in).
    pub fn breakpoints(&self) -> &[f64] {
        &self.breakpoints
    }

    /// Response to water at level `h` (in) on the upstream face.
    pub fn eval(&self, h: f64) -> DVector<f64> {
        let bp = &self.breakpoints;
        let last = bp.len() - 1;
        if h <= bp[0] {
            return DVector::zeros(self.n_responses());
        }
        if h >= bp[last] {
            let dh = h - bp[last];
            return (self.values.row(last) + self.slopes.row(last) * dh).transpose();
        }
        let k = bp.partition_point(|&b| b <= h) - 1;
        let (h0, h1) = (bp[k], bp[k + 1]);
        let dx = h1 - h0;
        let s = (h - h0) / dx;
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        (self.values.row(k) * h00
            + self.slopes.row(k) * (h10 * dx)
            + self.values.row(k + 1) * h01
            + self.slopes.row(k + 1) * (h11 * dx))
            .transpose()
    }

    /// Response to upstream level `h_up` and downstream level `h_down`: `R(h_up) - R(h_down)`.
    pub fn eval_levels(&self, h_up: f64, h_down: f64) -> DVector<f64> {
        self.eval(h_up) - self.eval(h_down)
    }
}

/// The gate condensed to its quoin and gauges. See the [module docs](super) for units and signs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CondensedGate {
    /// Quoin height (in); the quoin spans `[0, quoin_height]`.
    pub quoin_height: f64,
    /// Heights (in) of the `m` FE quoin nodes, strictly increasing.
    pub quoin_node_heights: Vec<f64>,
    /// Quoin-node flexibility `C` (in/lbf), `2m x 2m`, blocked `[normal; tangential]`.
    pub quoin_flexibility: DMatrix<f64>,
    /// Quoin-node displacements (in, `2m` responses) under water alone, no quoin contact.
    pub water_quoin_displacement: HydrostaticTable,
    /// Gauge names, one per strain output.
    pub gauge_names: Vec<String>,
    /// Gauge strains (microstrain, `N_o` responses) under water alone, no quoin contact.
    pub water_strain: HydrostaticTable,
    /// The `N_u` quoin force representation points (in), strictly increasing in `[0, H]`.
    pub nu_points: Vec<f64>,
    /// Consistent load transfer `T` (`m x N_u`): nodal force (lbf) at each quoin node per unit
    /// line load (lbf/in) at each representation point, the load between points interpolated
    /// linearly. The same `T` serves both directions.
    pub load_transfer: DMatrix<f64>,
    /// Strain matrix `A` (`N_o x 2 N_u`, microstrain per lbf/in), columns `[normal; tangential]`.
    pub a_matrix: DMatrix<f64>,
}

impl CondensedGate {
    /// Number of FE quoin nodes `m`.
    pub fn n_quoin_nodes(&self) -> usize {
        self.quoin_node_heights.len()
    }
    /// Number of gauges `N_o`.
    pub fn n_gauges(&self) -> usize {
        self.gauge_names.len()
    }
    /// Number of representation points `N_u`.
    pub fn n_points(&self) -> usize {
        self.nu_points.len()
    }
    /// Strain (microstrain) for quoin line loads `q` (lbf/in, length `2 N_u`) and water levels.
    pub fn strain(&self, q: &[f64], h_up: f64, h_down: f64) -> DVector<f64> {
        &self.a_matrix * DVector::from_column_slice(q) + self.water_strain.eval_levels(h_up, h_down)
    }
}
