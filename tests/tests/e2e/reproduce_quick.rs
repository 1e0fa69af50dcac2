//! The CI-sized reproduction of the paper's case study (`cargo xtask reproduce-paper --quick`)
//! as a test: the whole chain from water levels through the FE gate (24 in mesh), the contact
//! model and the synthetic truth (120 experiments per scenario) to Modules 2-4 (exact linear
//! estimator), scored against the truth.
//!
//! What is asserted is what the method delivers on our gate. Three of issue 7's acceptance
//! criteria are NOT met and are therefore not asserted (see docs/results/reproduce-paper.md):
//! ρ is not identified by Eq. 30 (ρ* runs to the search bound, because 12 discrepancy
//! coefficients can absorb `(0.8 − ρ) g` through only 7 gauges), and as a consequence the θ
//! interval is over-confident and the force field is not corrected. This test prints those
//! numbers so a change that fixes or worsens them is visible.

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
        assert!(s.rho_star >= 0.0 && s.rho_star <= 1.0);
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
    }
}
