//! `mlmodel` trait implementations.

use super::model;
use mitergate::gate_model::{ContactForceModel, StrainModel};
use mlmodel::{
    DiscrepancyBasis, LinearObservableModel, ModelError, MultiLevelModel, ObservableModel,
    UniformPrior, UnobservableModel,
};
use orthopoly::Family;

fn domain_name(r: mlmodel::Result<()>) -> String {
    match r {
        Err(ModelError::OutOfDomain { name, .. }) => name,
        other => panic!("expected an out-of-domain error, got {other:?}"),
    }
}

#[test]
fn contact_force_model_wraps_the_contact_solve() {
    let g = ContactForceModel::new(model().clone());
    assert_eq!(g.input_names(), ["h_up", "h_down"]);
    assert_eq!((g.param_dim(), g.components()), (1, 2));
    assert_eq!(g.coordinates(), model().gate().nu_points.as_slice());
    let mut out = vec![0.0; g.response_len()];
    g.evaluate(&[700.0, 80.0], &[95.0], &mut out).unwrap();
    assert_eq!(out, model().solve(700.0, 80.0, 95.0).unwrap().forces);
    assert_eq!(
        domain_name(g.evaluate(&[745.0, 80.0], &[95.0], &mut out)),
        "h_up"
    );
    assert_eq!(
        domain_name(g.evaluate(&[700.0, 23.0], &[95.0], &mut out)),
        "h_down"
    );
    assert_eq!(
        domain_name(g.evaluate(&[100.0, 200.0], &[95.0], &mut out)),
        "h_up - h_down"
    );
    assert_eq!(
        domain_name(g.evaluate(&[700.0, 80.0], &[762.0], &mut out)),
        "theta"
    );
    assert_eq!(
        domain_name(g.evaluate(&[700.0, 80.0], &[-0.5], &mut out)),
        "theta"
    );
    assert!(matches!(
        g.evaluate(&[700.0], &[95.0], &mut out),
        Err(ModelError::Dimension { what: "x", .. })
    ));
    assert!(matches!(
        g.evaluate(&[700.0, 80.0], &[95.0], &mut out[..5]),
        Err(ModelError::Dimension { what: "out", .. })
    ));
}

#[test]
fn strain_model_is_eq_47() {
    let gate = model().gate();
    let s = StrainModel::new(gate);
    assert_eq!(s.output_names(), gate.gauge_names);
    let forces = model().solve(650.0, 100.0, 120.0).unwrap().forces;
    let mut out = vec![0.0; 7];
    s.evaluate(&[650.0, 100.0], &[120.0], &forces, &mut out)
        .unwrap();
    let expected = gate.strain(&forces, 650.0, 100.0);
    let mut offset = vec![0.0; 7];
    s.offset(&[650.0, 100.0], &[120.0], &mut offset).unwrap();
    let linear = s.matrix() * nalgebra::DVector::from_column_slice(&forces);
    for p in 0..7 {
        // Same products in a different order: rounding only (strains ~1e3 microstrain).
        assert!((out[p] - expected[p]).abs() < 1e-9 * expected[p].abs().max(1.0));
        assert!((out[p] - (linear[p] + offset[p])).abs() < 1e-9 * out[p].abs().max(1.0));
    }
    assert_eq!(
        domain_name(s.offset(&[800.0, 100.0], &[120.0], &mut offset)),
        "h_up"
    );
    assert!(matches!(
        s.evaluate(&[650.0, 100.0], &[120.0], &forces[..10], &mut out),
        Err(ModelError::Dimension { what: "y_u", .. })
    ));
}

#[test]
fn the_gate_assembles_into_a_multi_level_model() {
    let gate = model().gate();
    let basis =
        DiscrepancyBasis::new(Family::Legendre, (0.0, 762.0), &gate.nu_points, &[6, 6]).unwrap();
    let prior = UniformPrior::new(vec![(81.0, 105.0)]).unwrap();
    let mlm = MultiLevelModel::new(
        ContactForceModel::new(model().clone()),
        StrainModel::new(gate),
        Box::new(prior),
        basis,
    )
    .unwrap();
    let mut out = vec![0.0; 2 * gate.n_points()];
    let alpha = vec![0.0; 12];
    mlm.corrected_response(&[700.0, 80.0], &[90.0], 0.8, &alpha, &mut out)
        .unwrap();
    let g = model().solve(700.0, 80.0, 90.0).unwrap().forces;
    assert!(
        out.iter()
            .zip(&g)
            .all(|(o, g)| (o - 0.8 * g).abs() <= 1e-12 * g.abs().max(1.0))
    );
}
