//! Physical behaviour of the contact model on the beam fixture.

use super::strategies::{gap, levels};
use super::{beam, max_abs, model, resultants};
use mitergate::contact::ContactParams;
use nalgebra::DVector;
use proptest::prelude::*;

#[test]
fn zero_head_gives_exactly_zero_force() {
    for h in [24.0, 300.0, 744.0] {
        let sol = model().solve(h, h, 90.0).unwrap();
        assert!(sol.forces.iter().all(|&f| f == 0.0));
        assert_eq!(sol.n_active, 0);
    }
}

#[test]
fn contact_forces_close_equilibrium_with_water_and_supports() {
    let (m, b) = (model(), beam());
    for (x, theta) in [([744.0, 24.0], 90.0), ([500.0, 200.0], 150.0)] {
        let sol = m.solve(x[0], x[1], theta).unwrap();
        let p = m.nodal_forces(&sol.forces);
        let full = b.displacement(&p, x[0], x[1]);
        // The condensed displacement the contact law used is the full beam's quoin motion.
        let quoin = DVector::from_fn(p.len(), |k, _| {
            let (dir, i) = (k / b.m(), k % b.m());
            full[b.v(dir, i)]
        });
        let du = (&quoin - DVector::from_column_slice(&sol.node_displacement)).amax();
        // cond(C) ≈ 2e4: relative 1e-9 is rounding with margin.
        assert!(du < 1e-9 * quoin.amax(), "quoin displacement mismatch {du}");
        // Force balance in n and t: contact + water + pintle, gudgeon and girders = 0.
        let contact = resultants(m, &sol.forces);
        let water = b.water_resultant(x[0], x[1]);
        let supports = b.support_reactions(&full);
        for dir in 0..2 {
            let imbalance = contact[dir] + water[dir] + supports[dir];
            // The water resultant is ~1e7 lbf; the balance holds to rounding of sums of
            // ~500 terms of that size.
            assert!(
                imbalance.abs() < 1e-8 * water[dir].abs(),
                "direction {dir}: contact {} water {} supports {} imbalance {imbalance}",
                contact[dir],
                water[dir],
                supports[dir]
            );
        }
        // The wall carries most of the normal water thrust (the girders and pins the rest).
        assert!(contact[0] > 0.5 * -water[0]);
    }
}

#[test]
fn stiff_contact_tends_to_the_rigid_quoin_reactions() {
    // θ = 0 and the bonded quoin is compressed at every node for this load, so as k_N → ∞ the
    // contact must reproduce the reactions of a rigid quoin, with an error O(1/k_N).
    let gate = model().gate().clone();
    let mm = gate.n_quoin_nodes();
    let rigid = model().rigid_quoin_reactions(744.0, 24.0);
    assert!(rigid[..mm - 1].iter().all(|&r| r > 0.0));
    let error = |k: f64| {
        let stiff = ContactParams::default()
            .normal_stiffness(k)
            .build(gate.clone())
            .unwrap();
        let sol = stiff.solve(744.0, 24.0, 0.0).unwrap();
        let p = stiff.nodal_forces(&sol.forces);
        let total: f64 = p[..mm].iter().sum();
        let total_rigid: f64 = rigid[..mm].iter().sum();
        (total / total_rigid - 1.0).abs()
    };
    let (e8, e9, e10) = (error(1e8), error(1e9), error(1e10));
    // First-order convergence in 1/k_N: each decade divides the error by ~10.
    assert!(
        e9 < 0.2 * e8 && e10 < 0.2 * e9,
        "errors {e8:e} {e9:e} {e10:e}"
    );
    assert!(e10 < 1e-4, "resultant error at k_N = 1e10: {e10:e}");
}

#[test]
fn no_force_below_the_gap_and_no_tension() {
    let m = model();
    for theta in [0.0, 45.0, 90.0, 150.0, 300.0] {
        let sol = m.solve(700.0, 40.0, theta).unwrap();
        let n = m.gate().n_points();
        for (b, &d) in m.gate().nu_points.iter().enumerate() {
            if d <= theta {
                assert_eq!(sol.forces[b], 0.0);
                assert_eq!(sol.forces[n + b], 0.0);
            }
        }
        assert!(sol.normal().iter().all(|&f| f >= 0.0));
    }
}

/// Largest normal force within 30 in above the gap edge.
fn edge_peak(theta: f64) -> f64 {
    let m = model();
    let sol = m.solve(744.0, 24.0, theta).unwrap();
    m.gate()
        .nu_points
        .iter()
        .zip(sol.normal())
        .filter(|(d, _)| **d >= theta && **d <= theta + 30.0)
        .map(|(_, f)| *f)
        .fold(0.0, f64::max)
}

#[test]
fn force_concentrates_above_a_growing_gap() {
    // The water load on the unsupported bottom is carried up to the first contact points, so
    // the normal force just above the gap edge grows with the gap.
    let peaks: Vec<f64> = [30.0, 60.0, 90.0, 120.0, 150.0].map(edge_peak).to_vec();
    assert!(peaks.windows(2).all(|w| w[1] > w[0]), "peaks {peaks:?}");
    // ... and at a fixed height just above all these gaps.
    let m = model();
    let b = m.gate().nu_points.partition_point(|&d| d < 160.0);
    let at_160: Vec<f64> = [90.0, 120.0, 150.0]
        .map(|t| m.solve(744.0, 24.0, t).unwrap().normal()[b])
        .to_vec();
    assert!(
        at_160.windows(2).all(|w| w[1] > w[0]),
        "F_N at 160 in: {at_160:?}"
    );
    // Meanwhile the normal resultant changes little: the load is redistributed, not lost.
    let r0 = resultants(m, &m.solve(744.0, 24.0, 0.0).unwrap().forces)[0];
    let r150 = resultants(m, &m.solve(744.0, 24.0, 150.0).unwrap().forces)[0];
    assert!((r150 / r0 - 1.0).abs() < 0.2, "resultants {r0} {r150}");
}

/// Max-norm change of the forces between two evaluations.
fn change(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn forces_are_continuous_in_theta_including_across_points() {
    let m = model();
    // 90 in is exactly a representation point (index 60); 97.3 lies inside a cell.
    for theta in [90.0, 97.3] {
        let f0 = m.solve(600.0, 50.0, theta).unwrap().forces;
        for sign in [1.0, -1.0] {
            let d = |eps: f64| {
                change(
                    &m.solve(600.0, 50.0, theta + sign * eps).unwrap().forces,
                    &f0,
                )
            };
            let (big, small) = (d(1e-3), d(1e-4));
            // Lipschitz behaviour: a 10x smaller step gives a ~10x smaller change. A jump would
            // give a ratio near 1. The band [3, 30] allows for an active-set kink in between.
            assert!(
                (3.0..30.0).contains(&(big / small)),
                "θ = {theta} {sign:+}: changes {big:e} {small:e}"
            );
        }
    }
}

#[test]
fn forces_are_continuous_in_the_water_levels() {
    let m = model();
    let f0 = m.solve(600.0, 50.0, 120.0).unwrap().forces;
    let d = |eps: f64| {
        change(
            &m.solve(600.0 + eps, 50.0 - eps, 120.0).unwrap().forces,
            &f0,
        )
    };
    let (big, small) = (d(1e-3), d(1e-4));
    assert!(
        (3.0..30.0).contains(&(big / small)),
        "changes {big:e} {small:e}"
    );
}

#[test]
fn tangential_restraint_is_effectively_rigid_where_the_normal_force_is_not_small() {
    let m = model();
    let gate = m.gate();
    let n = gate.n_points();
    let (x, theta) = ([744.0, 24.0], 90.0);
    let sol = m.solve(x[0], x[1], theta).unwrap();
    let ubar = m.point_displacements(&sol.node_displacement);
    let free = m.point_displacements(
        gate.water_quoin_displacement
            .eval_levels(x[0], x[1])
            .as_slice(),
    );
    let free_scale = max_abs(&free[n..]);
    let fmax = max_abs(sol.normal());
    // Away from the FE element cut by the gap edge (one node spacing, 23.8 in, plus margin)
    // the contact slip is the tangential force over k_T F_N ~ 1e10 psi: ~1e-7 in against a free
    // motion of ~3 in. The bound 1e-5 x free leaves a factor ~100.
    let spacing = gate.quoin_node_heights[1] - gate.quoin_node_heights[0];
    let mut checked = 0;
    for b in 0..n {
        if gate.nu_points[b] > theta + 2.0 * spacing && sol.normal()[b] > 0.01 * fmax {
            assert!(
                ubar[n + b].abs() < 1e-5 * free_scale,
                "slip {} at {}",
                ubar[n + b],
                gate.nu_points[b]
            );
            checked += 1;
        }
    }
    assert!(checked > n / 2);
    // The stiffer limit k_T = 1e9 changes the tangential resultant by little.
    let rigid = ContactParams::default()
        .tangential_coefficient(1e9)
        .build(gate.clone())
        .unwrap();
    let r6 = resultants(m, &sol.forces)[1];
    let r9 = resultants(m, &rigid.solve(x[0], x[1], theta).unwrap().forces)[1];
    assert!(
        (r9 / r6 - 1.0).abs() < 1e-3,
        "tangential resultants {r6} {r9}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]

    #[test]
    fn random_loads_and_gaps_give_admissible_forces(x in levels(), theta in gap()) {
        let m = model();
        let n = m.gate().n_points();
        let sol = m.solve(x[0], x[1], theta).unwrap();
        for (b, &d) in m.gate().nu_points.iter().enumerate() {
            prop_assert!(sol.forces[b] >= 0.0);
            if d <= theta {
                prop_assert_eq!(sol.forces[b], 0.0);
                prop_assert_eq!(sol.forces[n + b], 0.0);
            }
        }
        // The solver's default tolerance on the tangential law.
        prop_assert!(sol.tangential_residual <= 1e-8);
        // The normal resultant pushes the gate away from the wall whenever there is head.
        if x[0] - x[1] > 1.0 {
            prop_assert!(resultants(m, &sol.forces)[0] > 0.0);
        }
    }
}
