//! Test doubles for documentation examples and tests (feature `testing`, not part of the
//! public API): enable it in a dev-dependency,
//! `mitergate = { workspace = true, features = ["testing"] }`.

use crate::condense::{CondensedGate, HydrostaticTable};
use crate::fe::loads::linear_load_transfer;
use nalgebra::DMatrix;

/// A tiny hand-built [`CondensedGate`] for documentation examples and tests: 3 quoin nodes at
/// 0, 381, 762 in, 5 representation points, 2 gauges. Not a physical gate; see the crate's
/// tests for a beam model.
///
/// ```
/// let g = mitergate::testing::doc_gate();
/// assert_eq!((g.n_quoin_nodes(), g.n_points(), g.n_gauges()), (3, 5, 2));
/// ```
pub fn doc_gate() -> CondensedGate {
    let h = 762.0;
    let nodes = vec![0.0, 381.0, 762.0];
    let points: Vec<f64> = (0..5).map(|b| h * b as f64 / 4.0).collect();
    let t = linear_load_transfer(&nodes, &points);
    // Flexibility: a diagonal-dominant SPD matrix (in/lbf), weak normal-tangential coupling.
    let mut c = DMatrix::zeros(6, 6);
    for i in 0..6 {
        c[(i, i)] = 2e-6;
    }
    for i in 0..3 {
        c[(i, 3 + i)] = 2e-7;
        c[(3 + i, i)] = 2e-7;
    }
    c[(0, 1)] = 5e-7;
    c[(1, 0)] = 5e-7;
    c[(1, 2)] = 5e-7;
    c[(2, 1)] = 5e-7;
    // Water pushes the gate into the wall (-n) and downstream (+t): u_w(h) = r (h/762)^2 h.
    let dir = [-0.01, -0.02, -0.01, 0.004, 0.006, 0.004];
    let bp = vec![0.0, 381.0, 762.0];
    let val = |hh: f64| (hh / h).powi(2) * hh;
    let der = |hh: f64| 3.0 * (hh / h).powi(2);
    let values = DMatrix::from_fn(3, 6, |k, j| dir[j] * val(bp[k]));
    let slopes = DMatrix::from_fn(3, 6, |k, j| dir[j] * der(bp[k]));
    let uw = HydrostaticTable::new(bp.clone(), values, slopes).expect("valid table");
    let sv = DMatrix::from_fn(3, 2, |k, j| [1.0, -0.5][j] * val(bp[k]));
    let ss = DMatrix::from_fn(3, 2, |k, j| [1.0, -0.5][j] * der(bp[k]));
    let sw = HydrostaticTable::new(bp, sv, ss).expect("valid table");
    let a = DMatrix::from_fn(2, 10, |p, j| {
        1e-3 * ((p + 1) as f64) * ((j % 5) as f64 + 1.0)
    });
    CondensedGate {
        quoin_height: h,
        quoin_node_heights: nodes,
        quoin_flexibility: c,
        water_quoin_displacement: uw,
        gauge_names: vec!["G1".into(), "G2".into()],
        water_strain: sw,
        nu_points: points,
        load_transfer: t,
        a_matrix: a,
    }
}
