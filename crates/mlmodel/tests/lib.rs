//! Integration tests of the `mlmodel` traits on a second, non-gate application: a beam on an
//! elastic foundation with a lost-support end region (see `beam_app.rs`).

#[path = "apps/beam_app.rs"]
mod beam_app;

use beam_app::*;
use mlmodel::{LinearObservableModel, ObservableModel, UnobservableModel};
use proptest::prelude::*;

fn reaction(x: &[f64], gap: f64) -> Vec<f64> {
    let m = BeamReaction::new(41);
    let mut r = vec![0.0; 41];
    m.evaluate(x, &[gap], &mut r).unwrap();
    r
}

#[test]
fn reaction_balances_the_applied_load() {
    // A free-free beam on springs: the spring forces must carry the whole load P + q L.
    let m = BeamReaction::new(41);
    let x = [5000.0, 40.0];
    let r = reaction(&x, 12.0);
    let total: f64 = r
        .iter()
        .zip(m.tributary_lengths())
        .map(|(r, l)| r * l)
        .sum();
    let load = x[0] + x[1] * LENGTH_IN;
    // 1e-8 relative: only round-off of an 82-dof dense LU solve remains.
    assert!((total - load).abs() < 1e-8 * load, "{total} vs {load}");
}

#[test]
fn reaction_vanishes_in_the_gap_and_is_continuous_in_theta() {
    let m = BeamReaction::new(41);
    let r = reaction(&[5000.0, 40.0], 20.0);
    for (v, &d) in r.iter().zip(m.coordinates()) {
        if d < 20.0 - 1.5 {
            assert_eq!(*v, 0.0, "reaction at d = {d} inside the gap");
        }
    }
    // Springs are lumped on the supported part of each tributary length, so a tiny change of θ
    // gives a tiny change of the reaction (no jumps when θ crosses a node).
    let a = reaction(&[5000.0, 40.0], 19.5);
    let b = reaction(&[5000.0, 40.0], 19.5 + 1e-6);
    let diff = a
        .iter()
        .zip(&b)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    // bound: derivative (~ k w per inch of gap, < 1e3 lbf/in per in) times 1e-6 in
    assert!(diff < 1e-3, "jump of {diff} lbf/in");
}

#[test]
fn linear_observable_matches_its_matrix_form() {
    let m = BeamReaction::new(41);
    let s = BeamStrain::new(&m);
    let x = [3000.0, 70.0];
    let r = reaction(&x, 10.0);
    let mut direct = vec![0.0; 7];
    ObservableModel::evaluate(&s, &x, &[10.0], &r, &mut direct).unwrap();
    let mut b = vec![0.0; 7];
    s.offset(&x, &[10.0], &mut b).unwrap();
    let ar = s.matrix() * nalgebra::DVector::from_column_slice(&r);
    for p in 0..7 {
        // same arithmetic in a different order: round-off only
        assert!((direct[p] - (ar[p] + b[p])).abs() < 1e-9 * (1.0 + b[p].abs()));
    }
}

#[test]
fn strain_is_zero_past_the_free_end_by_equilibrium() {
    // Moment equilibrium of the whole beam: the moment at the right free end vanishes, so a
    // gauge at d = L would read ~0 (trapezoid lumping of the reaction is exact for the
    // resultant and first moment only up to the discretisation: allow 1% of the peak).
    let m = BeamReaction::new(41);
    let x = [6000.0, 50.0];
    let r = reaction(&x, 15.0);
    let lengths = m.tributary_lengths();
    let end = LENGTH_IN;
    let moment_loads = x[1] * end * end / 2.0 + x[0] * (end - LOAD_POSITION_IN);
    let moment_reac: f64 = (0..41)
        .map(|b| lengths[b] * r[b] * (end - m.coordinates()[b]))
        .sum();
    assert!((moment_loads - moment_reac).abs() < 0.01 * moment_loads);
}

#[test]
fn model_bundle_checks_dimensions() {
    let ml = beam_model((5.0, 25.0), 4);
    assert_eq!(ml.unobservable.response_len(), 41);
    assert_eq!(ml.observable.output_dim(), 7);
    assert_eq!(ml.basis.n_coefficients(), 4);
    let q = ml.prior.quadrature(5).unwrap();
    let s: f64 = q.weights.iter().sum();
    assert!((s - 1.0).abs() < 1e-12);
    // a basis built for another point count is rejected with an error, not a panic
    let other = mlmodel::DiscrepancyBasis::new(
        orthopoly::Family::Legendre,
        (0.0, LENGTH_IN),
        &[0.0, 60.0, 120.0],
        &[2],
    )
    .unwrap();
    let r = BeamReaction::new(41);
    let s = BeamStrain::new(&r);
    let prior = Box::new(mlmodel::UniformPrior::new(vec![(5.0, 25.0)]).unwrap());
    assert!(mlmodel::MultiLevelModel::new(r, s, prior, other).is_err());
}

#[test]
fn out_of_domain_theta_is_an_error() {
    let m = BeamReaction::new(41);
    let mut r = vec![0.0; 41];
    let err = m.evaluate(&[1000.0, 10.0], &[-1.0], &mut r).unwrap_err();
    assert!(err.to_string().contains("theta"));
    assert!(m.evaluate(&[1000.0], &[1.0], &mut r).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]
    /// g_u is linear in the loads (linear beam, linear springs): g(a x) = a g(x).
    #[test]
    fn reaction_is_linear_in_loads(p in 1000.0..10_000.0f64, q in 10.0..100.0f64,
                                   gap in 0.0..30.0f64, a in 0.1..3.0f64) {
        let r1 = reaction(&[p, q], gap);
        let r2 = reaction(&[a * p, a * q], gap);
        let scale = r1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (u, v) in r1.iter().zip(&r2) {
            // round-off relative to the largest reaction
            prop_assert!((a * u - v).abs() < 1e-8 * a * scale);
        }
    }

    /// The corrected response of Eq. 17 equals ρ g_u + L α for any ρ, α.
    #[test]
    fn corrected_response_is_rho_gu_plus_l_alpha(rho in 0.0..1.5f64, a0 in -5.0..5.0f64,
                                                 a1 in -5.0..5.0f64) {
        let ml = beam_model((5.0, 25.0), 2);
        let x = [4000.0, 30.0];
        let mut out = vec![0.0; 41];
        ml.corrected_response(&x, &[10.0], rho, &[a0, a1], &mut out).unwrap();
        let g = reaction(&x, 10.0);
        let l = ml.basis.block_matrix();
        for b in 0..41 {
            let expect = rho * g[b] + l[(b, 0)] * a0 + l[(b, 1)] * a1;
            prop_assert!((out[b] - expect).abs() < 1e-9 * (1.0 + expect.abs()));
        }
    }
}

proptest! {
    /// The row memo changes no number: with a memo so small that it is cleared over and over
    /// (3 rows) and with none, every `model_row` of a sequence that revisits inputs equals
    /// `[A g; b]` computed directly, bit for bit, and the memo never holds more than its
    /// capacity. A stale row returned for another `θ` or `x` would differ (the beam's response
    /// moves with both).
    #[test]
    fn row_memo_returns_the_rows_it_would_compute(
        picks in proptest::collection::vec(0usize..5, 1..40),
    ) {
        let inputs = [
            ([5000.0, 40.0], 12.0),
            ([5000.0, 40.0], 12.5),
            ([3000.0, 10.0], 12.0),
            ([3000.0, 10.0], 30.0),
            ([100.0, 80.0], 5.0),
        ];
        let plain = beam_model((0.0, 60.0), 4);
        let memo = beam_model((0.0, 60.0), 4).with_row_memo(3);
        for &k in &picks {
            let (x, theta) = inputs[k];
            let mut g = vec![0.0; plain.unobservable.response_len()];
            plain.unobservable.evaluate(&x, &[theta], &mut g).unwrap();
            let ag = plain.observable.matrix() * nalgebra::DVector::from_vec(g);
            let mut b = vec![0.0; ag.len()];
            plain.observable.offset(&x, &[theta], &mut b).unwrap();
            let direct: Vec<f64> = ag.iter().chain(&b).copied().collect();
            prop_assert_eq!(&plain.model_row(&x, &[theta]).unwrap()[..], &direct[..]);
            prop_assert_eq!(&memo.model_row(&x, &[theta]).unwrap()[..], &direct[..]);
            prop_assert!(memo.row_memo().len() <= 3);
        }
        prop_assert!(plain.row_memo().is_empty());
    }
}
