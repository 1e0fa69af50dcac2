//! The synthetic truth of Sec. 4.3.

use crate::contact::model;
use mitergate::data::truth::{
    Scenario, discrepancy_visibility, generate, sample_levels, true_discrepancy, true_forces,
};

#[test]
fn discrepancy_follows_eq_53_54_and_vanishes_below_the_gap() {
    let d: Vec<f64> = (0..=762).step_by(6).map(f64::from).collect();
    let n = d.len();
    let x = [600.0, 150.0];
    let delta = true_discrepancy(x, &d, 150.0, 2.0);
    for (b, &z) in d.iter().enumerate() {
        if z < 150.0 {
            assert_eq!((delta[b], delta[n + b]), (0.0, 0.0));
        } else {
            let dn = 2.0 * 3.0 * 450.0 * ((762.0 - z) / 1200.0).powi(3);
            let dt = 2.0 * 4.5f64.powi(2) * (z / 240.0).sin();
            // Same formula evaluated in a different order: rounding only.
            assert!((delta[b] - dn).abs() <= 1e-12 * dn.abs().max(1.0));
            assert!((delta[n + b] - dt).abs() <= 1e-12 * dt.abs().max(1.0));
        }
    }
    // Zero head, zero discrepancy.
    assert!(
        true_discrepancy([300.0, 300.0], &d, 0.0, 1.0)
            .iter()
            .all(|&v| v == 0.0)
    );
}

#[test]
fn levels_are_uniform_on_the_triangle() {
    let x = sample_levels(20_000, 11);
    assert!(
        x.iter()
            .all(|l| 24.0 <= l[1] && l[1] <= l[0] && l[0] < 744.0)
    );
    let n = x.len() as f64;
    let mean_up = x.iter().map(|l| l[0]).sum::<f64>() / n;
    let mean_down = x.iter().map(|l| l[1]).sum::<f64>() / n;
    // Uniform on the triangle: h_up is the max and h_down the min of two uniforms on
    // [24, 744]: means 24 + 2/3 * 720 = 504 and 24 + 1/3 * 720 = 264, standard deviation
    // 720/sqrt(18) = 170 each, so the standard error is 1.2 in; 6 in is 5 standard errors.
    assert!((mean_up - 504.0).abs() < 6.0, "mean h_up {mean_up}");
    assert!((mean_down - 264.0).abs() < 6.0, "mean h_down {mean_down}");
    // P(head > 360) = (1 - 360/720)^2 = 1/4; standard error sqrt(3/16 / n) = 0.003.
    let big = x.iter().filter(|l| l[0] - l[1] > 360.0).count() as f64 / n;
    assert!((big - 0.25).abs() < 0.015, "P(head > 360) = {big}");
}

#[test]
fn generated_data_follow_eq_47_48() {
    let m = model();
    let gate = m.gate();
    let s = Scenario::paper(1).unwrap().n_experiments(60);
    let e = generate(&s, m).unwrap();
    assert_eq!(e, generate(&s, m).unwrap(), "same seed, same data");
    assert_ne!(e.strains, generate(&s.clone().seed(99), m).unwrap().strains);
    assert_eq!(e.x, sample_levels(60, s.seed));
    let mut noise = Vec::new();
    for k in 0..e.x.len() {
        let x = e.x[k];
        let forces = true_forces(&s, m, x).unwrap();
        assert_eq!(forces, e.true_forces[k]);
        let g = m.solve(x[0], x[1], s.theta_true).unwrap().forces;
        let delta = true_discrepancy(x, &gate.nu_points, s.theta_true, 1.0);
        for b in 0..forces.len() {
            // ρ g + δ computed twice the same way: identical up to rounding.
            assert!((forces[b] - (0.8 * g[b] + delta[b])).abs() <= 1e-9 * (1.0 + g[b].abs()));
            if b < gate.n_points() && gate.nu_points[b] < s.theta_true {
                assert_eq!(forces[b], 0.0);
            }
        }
        let clean = gate.strain(&forces, x[0], x[1]);
        for (p, c) in clean.iter().enumerate() {
            assert!((e.noise_free_strains[k][p] - c).abs() <= 1e-9 * c.abs().max(1.0));
            noise.push(e.strains[k][p] - c);
        }
    }
    let n = noise.len() as f64;
    let mean = noise.iter().sum::<f64>() / n;
    let sd = (noise.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    // 420 draws of N(0, 1): standard errors 0.049 (mean) and 0.035 (sd); bounds are 4 of them.
    assert!(mean.abs() < 0.2, "noise mean {mean}");
    assert!((sd - 1.0).abs() < 0.14, "noise sd {sd}");
}

#[test]
fn discrepancy_is_visible_above_the_noise_on_the_fixture() {
    let m = model();
    for number in [1, 2] {
        let s = Scenario::paper(number).unwrap().n_experiments(100);
        let v = discrepancy_visibility(&s, m).unwrap();
        eprintln!("scenario {number}: {v:?}");
        // The literal Eq. 53-54 must move the gauges by more than the noise for the
        // calibration to see it (fixture: ~4-5 microstrain RMS against σ = 1).
        assert!(v.signal_to_noise() > 2.0, "{v:?}");
        // The tangential part is near the noise level, as the paper reports (Sec. 4.3).
        assert!(v.rms_literal_tangential_strain < v.rms_literal_normal_strain);
        // The contact forces themselves dominate the strains.
        assert!(v.rms_contact_strain > 50.0 * v.rms_literal_discrepancy_strain);
        let scaled = discrepancy_visibility(&s.clone().discrepancy_scale(3.0), m).unwrap();
        assert!((scaled.rms_discrepancy_strain - 3.0 * v.rms_discrepancy_strain).abs() < 1e-9);
    }
}

#[test]
fn scenarios_are_validated() {
    assert!(Scenario::paper(0).is_err());
    let s = Scenario::paper(1).unwrap();
    assert!(s.validate().is_ok());
    let mut bad = s.clone();
    bad.theta_true = 200.0;
    assert!(bad.validate().is_err());
    assert!(s.clone().n_experiments(0).validate().is_err());
    assert!(s.clone().discrepancy_scale(f64::NAN).validate().is_err());
    assert!(generate(&s.noise_sd(f64::INFINITY), model()).is_err());
}
