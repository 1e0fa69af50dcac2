//! `mlmodel` trait implementations and the constructor of the gate's multi-level model.

use crate::contact::model;
use mitergate::multilevel::{ContactForceModel, StrainModel};
use mitergate::{
    ContactParams, DEFAULT_NU, GateConfig, GateError, GateModel, GateSummary, MIN_HEAD_IN,
    MultiLevelSpec, build_contact, multilevel,
};
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

#[test]
fn the_constructor_builds_the_paper_model() {
    let gate = model().gate();
    let m = multilevel(model().clone(), &MultiLevelSpec::default()).unwrap();
    let (n, n_gauges) = (gate.n_points(), gate.n_gauges());
    assert_eq!(m.unobservable.input_names(), ["h_up", "h_down"]);
    assert_eq!(m.unobservable.param_dim(), 1);
    assert_eq!(m.unobservable.response_len(), 2 * n);
    assert_eq!(m.unobservable.coordinates(), gate.nu_points.as_slice());
    assert_eq!(m.unobservable.capacity(), 0);
    assert_eq!(m.observable.output_names(), gate.gauge_names);
    assert_eq!(m.observable.matrix(), &gate.a_matrix);
    assert_eq!(m.observable.matrix().shape(), (n_gauges, 2 * n));
    assert_eq!(m.prior.dim(), 1);
    assert_eq!(m.prior.bounds(), vec![(81.0, 105.0)]);
    assert_eq!(m.prior.ln_pdf(&[90.0]), -(24.0f64.ln()));
    assert_eq!(m.basis.family(), Family::Legendre);
    assert_eq!(m.basis.interval(), (0.0, gate.quoin_height));
    assert_eq!(m.basis.terms(), &[6, 6]);
    assert_eq!(m.basis.n_points(), n);
    let reference = DiscrepancyBasis::new(
        Family::Legendre,
        (0.0, gate.quoin_height),
        &gate.nu_points,
        &[6, 6],
    )
    .unwrap();
    assert_eq!(m.basis.block_matrix(), reference.block_matrix());
    let mut out = vec![0.0; 2 * n];
    m.unobservable
        .evaluate(&[700.0, 80.0], &[90.0], &mut out)
        .unwrap();
    assert_eq!(out, model().solve(700.0, 80.0, 90.0).unwrap().forces);
}

#[test]
fn the_memo_remembers_contact_solves() {
    let spec = MultiLevelSpec::default()
        .with_gap_prior((60.0, 150.0))
        .with_memo_capacity(10);
    let m = multilevel(model().clone(), &spec).unwrap();
    assert_eq!(m.unobservable.capacity(), 10);
    let n = m.unobservable.response_len();
    let (mut first, mut second) = (vec![0.0; n], vec![0.0; n]);
    m.unobservable
        .evaluate(&[600.0, 100.0], &[120.0], &mut first)
        .unwrap();
    m.unobservable
        .evaluate(&[600.0, 100.0], &[120.0], &mut second)
        .unwrap();
    assert_eq!((first == second, m.unobservable.len()), (true, 1));
    assert_eq!(m.prior.bounds(), vec![(60.0, 150.0)]);
}

#[test]
fn discrepancy_terms_are_capped_at_the_representation_points() {
    let contact = ContactParams::default()
        .build(mitergate::testing::doc_gate())
        .unwrap();
    assert_eq!(contact.gate().n_points(), 5);
    let spec = MultiLevelSpec::default().with_discrepancy_terms([6, 3]);
    let m = multilevel(contact, &spec).unwrap();
    assert_eq!(m.basis.terms(), &[5, 3]);
    assert_eq!(m.basis.n_coefficients(), 8);
}

#[test]
fn bad_specs_are_errors_naming_the_field() {
    let base = MultiLevelSpec::default();
    let cases = [
        (
            base.clone().with_gap_prior((f64::NAN, 105.0)),
            "gap_prior_in",
        ),
        (base.clone().with_gap_prior((105.0, 81.0)), "gap_prior_in"),
        (base.clone().with_gap_prior((90.0, 90.0)), "gap_prior_in"),
        (base.clone().with_gap_prior((-1.0, 10.0)), "gap_prior_in"),
        (
            base.clone().with_gap_prior((81.0, f64::INFINITY)),
            "gap_prior_in",
        ),
        // the gap must stay below the quoin height (762 in on the fixture)
        (base.clone().with_gap_prior((81.0, 762.0)), "gap_prior_in"),
        (
            base.clone().with_discrepancy_terms([0, 6]),
            "discrepancy_terms",
        ),
        (
            base.clone().with_discrepancy_terms([6, 0]),
            "discrepancy_terms",
        ),
    ];
    for (spec, field) in cases {
        match multilevel(model().clone(), &spec) {
            Err(GateError::InvalidMultiLevelSpec { field: f, .. }) => {
                assert_eq!(f, field, "{spec:?}")
            }
            Err(e) => panic!("{spec:?}: expected an invalid `{field}`, got {e}"),
            Ok(_) => panic!("{spec:?}: expected an invalid `{field}`"),
        }
    }
    assert!(base.validate().is_ok());
}

#[test]
fn the_response_vanishes_when_the_gate_is_open() {
    let g = ContactForceModel::new(model().clone());
    assert_eq!(MIN_HEAD_IN, 1.0);
    assert!(g.response_vanishes(&[300.0, 300.0]));
    assert!(g.response_vanishes(&[300.0 + 0.999, 300.0]));
    assert!(!g.response_vanishes(&[300.0 + MIN_HEAD_IN, 300.0]));
    assert!(!g.response_vanishes(&[700.0, 80.0]));
    assert!(!g.response_vanishes(&[700.0]));
    // the memoised model of the constructor says the same, and the force is indeed zero
    let m = multilevel(model().clone(), &MultiLevelSpec::default()).unwrap();
    assert!(m.unobservable.response_vanishes(&[300.0, 300.0]));
    let mut out = vec![0.0; m.unobservable.response_len()];
    m.unobservable
        .evaluate(&[300.0, 300.0], &[90.0], &mut out)
        .unwrap();
    assert!(out.iter().all(|&f| f == 0.0));
}

#[test]
fn build_contact_condenses_the_configured_gate() {
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = 96.0;
    let (contact, summary) = build_contact(&cfg).unwrap();
    let fe = GateModel::build(&cfg).unwrap();
    let condensed = fe.condense(DEFAULT_NU).unwrap();
    assert_eq!(
        summary,
        GateSummary {
            n_dofs: fe.n_dofs(),
            n_quoin_nodes: condensed.n_quoin_nodes(),
            element_size: 96.0,
        }
    );
    assert_eq!(contact.params(), &ContactParams::default());
    assert_eq!(contact.gate().a_matrix, condensed.a_matrix);
    assert_eq!(
        contact.gate().quoin_flexibility,
        condensed.quoin_flexibility
    );
    let mut bad = cfg.clone();
    bad.skin_plate.thickness = 0.0;
    assert!(matches!(
        build_contact(&bad),
        Err(GateError::InvalidConfig { ref parameter, .. }) if parameter == "skin_plate.thickness"
    ));
}
