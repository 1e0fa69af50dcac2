//! The CI-sized reproduction of the paper's case study (`cargo xtask reproduce-paper --quick`)
//! as a test: the whole chain from water levels through the FE gate (24 in mesh), the contact
//! model and the synthetic truth (120 experiments per scenario) to Modules 2-4 (exact linear
//! estimator), scored against the truth.
//!
//! What is asserted is what the method delivers on our gate, in a form the prior would fail:
//! the default (marginal) mode must learn θ (posterior sd under 1/20 of the prior's) and land
//! within four of its own sd of θ*, estimate the identified ρ⊥ within four of its sd of the
//! truth's, fit the strains better than the best calibration without a discrepancy (ρ and θ
//! fitted), and give a corrected force within 10 % of the floor for its θ posterior (the model
//! at that posterior with ρ* known, corrected by everything the gauges see of the remaining
//! error). The reconstructed discrepancy is printed, not asserted. The paper's Module 3 is only
//! required to explain the strains better than the discrepancy's own strain effect: its ρ* is
//! not identified by Eq. 30, so its θ interval misses θ* (see docs/results/reproduce-paper.md).
//!
//! Against the weaker baseline it used to be compared with (ρ = 1 and the discrepancy model's
//! σ_ε), the paper's Module 3 pulled θ towards the truth and its strains beat the baseline's
//! fivefold; the best fit without a discrepancy (ρ fitted, σ_ε profiled) is closer to θ* than
//! the paper's Module 3 in both scenarios (90.22 and 150.08 against 92.27 and 152.48 in when
//! this was written), so those two assertions were replaced, not loosened: they compared
//! against a baseline no user would choose. Whether intervals hold θ* at their nominal rate is
//! the coverage study's question (one data set cannot answer it).

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
        // Strains at 20 new conditions: the paper's Module 3 must predict them better than the
        // strain effect of the true discrepancy itself (RMS of A δ), i.e. modelling δ must
        // remove more error than it adds.
        assert!(
            s.strain_rmse.with_discrepancy < s.discrepancy_strain_rms,
            "{}: strain RMSE {} vs discrepancy effect {}",
            s.name,
            s.strain_rmse.with_discrepancy,
            s.discrepancy_strain_rms
        );
        let t = &s.theta_posterior;
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
        "{} marginal: rho (split) {:.3} ± {:.3}, theta {:.2} ± {:.2} [{:.2}, {:.2}]; normal RMSE {:.1} -> {:.1}; \
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
    // ρ⊥, the data's own scale of g, against the truth's at the experiments. Its sd is the
    // gauges' noise and θ's spread (1e-4 here), so 4 sd is tight; the split's ρ, which the data
    // cannot tell from a discrepancy along g, is no longer asserted against 0.8.
    let [rho, rho_sd] = m.rho_projection.expect("the marginal mode reports ρ⊥");
    let rho_true = s.rho_projection_true.expect("the truth's ρ⊥");
    assert!(
        (rho - rho_true).abs() < 4.0 * rho_sd,
        "{}: ρ⊥ {rho} ± {rho_sd} vs the truth's {rho_true}",
        s.name
    );
    // The strains: better than the best calibration without a discrepancy.
    assert!(
        m.strain_rmse.with_discrepancy < m.strain_rmse.without_discrepancy,
        "{}: strain RMSE {} with δ vs {} without",
        s.name,
        m.strain_rmse.with_discrepancy,
        m.strain_rmse.without_discrepancy
    );
    // The force: within 10 % of the floor for this θ posterior (measured 0.98-1.02 when
    // written: the correction's own error is small beside θ's spread at the gap's edge), and
    // corrected at least fivefold against the prior-mean model.
    let b = m.baselines.expect("the reproduction scores the baselines");
    assert!(
        b.calibrated.normal <= 1.1 * b.oracle_seen_posterior.normal,
        "{}: normal force RMSE {} vs the floor {}",
        s.name,
        b.calibrated.normal,
        b.oracle_seen_posterior.normal
    );
    assert!(m.force_rmse.normal_after <= 0.2 * m.force_rmse.normal_before);
}
