//! The CI-sized reproduction of the paper's case study (`cargo xtask reproduce-paper --quick`)
//! as a test: the whole chain from water levels through the FE gate (24 in mesh), the contact
//! model and the synthetic truth (120 experiments per scenario) to Modules 2-4 (exact linear
//! estimator), scored against the truth.
//!
//! What is asserted is what the method delivers on our gate, in a form the prior would fail:
//! the default (marginal) mode must learn θ (posterior sd under 1/20 of the prior's) and land
//! within four of its own sd of θ*, learn ρ (its interval of ±4 sd holds 0.8 and excludes the
//! prior mean), and correct the force field (normal-force RMSE after at most 1/5 of before).
//! The reconstructed discrepancy is printed, not asserted (only `ρ g + δ` is identified). The paper's
//! Module 3 is only required to explain the strains: its ρ* is not identified by Eq. 30 (it
//! runs to the search bound, because 12 coefficients absorb `(0.8 − ρ) g` through 7 gauges),
//! so its θ interval misses θ* and the force field is not corrected (see
//! docs/results/reproduce-paper.md). Whether intervals hold θ* at their nominal rate is the
//! coverage study's question (one data set cannot answer it).

use bamudi::observe::Silent;
use bamudi_gate::paper::{ReproduceOptions, reproduce};

#[test]
fn quick_reproduction_explains_the_strains_and_moves_theta_towards_the_truth() {
    let report = reproduce(&ReproduceOptions::quick(), &Silent, |_, _, _| Ok(())).unwrap();
    assert_eq!(report.scenarios.len(), 2);
    for s in &report.scenarios {
        let t = &s.theta_posterior;
        let t0 = &s.theta_posterior_no_discrepancy;
        eprintln!(
            "{}: rho* {:.3}, theta {:.2} ± {:.2} [{:.2}, {:.2}] (truth {}), without δ {:.2} ± {:.2}; \
             normal RMSE {:.1} -> {:.1}; strain RMSE {:.2} vs {:.2}; σ_ε {:.3}",
            s.name,
            s.rho_star,
            t.mean,
            t.sd,
            t.ci95.0,
            t.ci95.1,
            s.theta_true,
            t0.mean,
            t0.sd,
            s.force_rmse.normal_before,
            s.force_rmse.normal_after,
            s.strain_rmse.with_discrepancy,
            s.strain_rmse.without_discrepancy,
            s.sigma_eps
        );
    }
    for s in &report.scenarios {
        // Strains at 20 new conditions: the calibrated prediction error must be smaller than
        // the strain effect of the true discrepancy itself (RMS of A δ), i.e. modelling δ must
        // remove more error than it adds.
        assert!(
            s.strain_rmse.with_discrepancy < s.discrepancy_strain_rms,
            "{}: strain RMSE {} vs discrepancy effect {}",
            s.name,
            s.strain_rmse.with_discrepancy,
            s.discrepancy_strain_rms
        );
        // ... and be far better than the calibration that ignores the discrepancy (Fig. 19-20).
        assert!(s.strain_rmse.with_discrepancy < 0.2 * s.strain_rmse.without_discrepancy);
        // Modelling the discrepancy must pull θ towards the truth (Fig. 16).
        let (t, t0) = (&s.theta_posterior, &s.theta_posterior_no_discrepancy);
        assert!(
            (t.mean - s.theta_true).abs() < (t0.mean - s.theta_true).abs(),
            "{}: with δ {} is not closer to θ* than without {}",
            s.name,
            t.mean,
            t0.mean
        );
        // Issue criterion for the paper size is 3 in; with a quarter of the experiments and
        // the ρ bias above, 6 in (a quarter of the prior width) is the quick-size bound.
        assert!(
            (t.mean - s.theta_true).abs() <= 6.0,
            "{}: θ mean {}",
            s.name,
            t.mean
        );
        // The conditional-coefficient variant (not in the paper): θ judged by what a smooth
        // discrepancy cannot explain at that θ. Issue 7's paper-size criterion, 3 in, applies.
        let c = s
            .conditional
            .as_ref()
            .expect("quick options run the variant");
        eprintln!(
            "{} conditional: rho* {:.3}, theta {:.2} ± {:.2} [{:.2}, {:.2}]; normal RMSE {:.1} -> {:.1}; strain RMSE {:.2}; σ_ε {:.3}",
            s.name,
            c.rho_star,
            c.theta_posterior.mean,
            c.theta_posterior.sd,
            c.theta_posterior.ci95.0,
            c.theta_posterior.ci95.1,
            c.force_rmse.normal_before,
            c.force_rmse.normal_after,
            c.strain_rmse.with_discrepancy,
            c.sigma_eps
        );
        assert!(
            (c.theta_posterior.mean - s.theta_true).abs() <= 3.0,
            "{}: conditional θ mean {}",
            s.name,
            c.theta_posterior.mean
        );
        assert!(
            (c.theta_posterior.mean - s.theta_true).abs() < (t.mean - s.theta_true).abs(),
            "{}: conditional θ {} is not closer to θ* than the paper's Module 3 {}",
            s.name,
            c.theta_posterior.mean,
            t.mean
        );
        assert!(c.strain_rmse.with_discrepancy < s.discrepancy_strain_rms);
        check_marginal(s);
        check_stage_timings(s);
    }
}

/// The report's profile of a scenario: every stage that ran is listed once, and the stages
/// account for the scenario's wall time. Only building the result struct runs between the last
/// stage and the total, so 10 ms is ample (a missing stage of this run takes far longer).
fn check_stage_timings(s: &bamudi_gate::paper::ScenarioResult) {
    let t = &s.timings_s;
    let names: Vec<&str> = t.stages.iter().map(|x| x.stage.as_str()).collect();
    for expected in [
        "synthetic truth",
        "conditional mode",
        "marginal mode",
        "fatigue",
    ] {
        let hits = names.iter().filter(|n| n.contains(expected)).count();
        assert_eq!(hits, 1, "{}: stage {expected:?} in {names:?}", s.name);
    }
    let sum: f64 = t.stages.iter().map(|x| x.seconds).sum();
    assert!(
        t.stages.iter().all(|x| x.seconds >= 0.0) && sum <= t.total && t.total - sum < 0.01,
        "{}: stages {sum} s vs total {} s",
        s.name,
        t.total
    );
}

/// The default mode: θ and ρ learnt and near the truth, the force corrected, δ reconstructed.
fn check_marginal(s: &bamudi_gate::paper::ScenarioResult) {
    let m = s
        .marginal
        .as_ref()
        .expect("quick options run the default mode");
    let t = &m.theta_posterior;
    let d = &m.discrepancy;
    eprintln!(
        "{} marginal: rho {:.3} ± {:.3}, theta {:.2} ± {:.2} [{:.2}, {:.2}]; normal RMSE {:.1} -> {:.1}; \
         δ̂ RMSE {:.1} (true δ RMS {:.1}), band {:.2}/{:.2}",
        s.name,
        m.rho_star,
        m.rho_sd.unwrap_or(f64::NAN),
        t.mean,
        t.sd,
        t.ci95.0,
        t.ci95.1,
        m.force_rmse.normal_before,
        m.force_rmse.normal_after,
        d.normal_rmse,
        d.normal_true_rms,
        d.normal_band_coverage,
        d.tangential_band_coverage
    );
    // Both scenarios' priors are 60 in wide uniform windows (sd 17.3 in): a posterior that
    // did not learn from the data keeps that sd.
    let prior_sd = 60.0 / 12f64.sqrt();
    assert!(t.sd < prior_sd / 20.0, "{}: θ sd {}", s.name, t.sd);
    // Four posterior sd: the coverage study measures z rms 1.1-1.5 for this mode, so a
    // correct posterior exceeds 4 sd with negligible probability; a bias of the paper's
    // Module 3 size (15-17 sd) fails.
    assert!(
        (t.mean - s.theta_true).abs() < 4.0 * t.sd,
        "{}: θ {} ± {} vs θ* {}",
        s.name,
        t.mean,
        t.sd,
        s.theta_true
    );
    // ρ: truth 0.8; the ρ prior is uniform on the sampling rule's range, whose mean is not 0.8.
    let rho_sd = m.rho_sd.expect("the marginal mode reports ρ's sd");
    assert!(
        (m.rho_star - 0.8).abs() < 4.0 * rho_sd,
        "{}: ρ {} ± {}",
        s.name,
        m.rho_star,
        rho_sd
    );
    assert!(m.force_rmse.normal_after <= 0.2 * m.force_rmse.normal_before);
    // δ̂ itself is reported, not asserted: the paper's δ is nearly proportional to g, so only
    // ρ g + δ is identified and δ̂ moves with ρ's posterior (see the module docs).
}
