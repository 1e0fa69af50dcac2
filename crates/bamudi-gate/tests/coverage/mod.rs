//! Quick coverage studies as tests, on the 24-in mesh with the exact estimator, calibrated in
//! the default (marginal) mode with 60 experiments per data set (half of `cargo xtask coverage
//! --quick`), on seed 8080, which played no part in choosing the default prior (that was seed
//! 2021 with the paper's discrepancy, `docs/results/validation.md`). Both are scored on `θ` and
//! the force bands only (`coverage::Scoring::ForceBands`, what they assert; the baselines,
//! fatigue bands and ranks they would otherwise compute took a quarter of their time, and the
//! unit test `force_band_scoring_is_the_full_scoring_without_the_extras` runs the full scoring
//! and shows that the lighter one changes no bit of the rest).
//!
//! 1. **A fixed, wrong discrepancy** (the paper's Eq. 53-54, a shape the calibration's basis
//!    does not contain), `θ*` drawn from the prior: the number of replicates whose 95 % `θ`
//!    interval holds `θ*` must lie in the 1 % binomial acceptance region of p = 0.95 for
//!    n = 40 (34..=40 hits), and the intervals must resolve the gap (median posterior sd
//!    ≤ 0.5 in, against prior sds of 7 and 9 in: a prior-wide interval cannot pass). The
//!    power against over-confidence (intervals half as wide must fail the same check) is
//!    asserted in the SBC test, not here: with a fixed discrepancy the default's intervals are
//!    cautious (z rms 0.52 on this seed, 40/40 half-width intervals holding θ*), as the
//!    validation's panel measures on other seeds (z sd 0.58-0.85); this check asserted it
//!    until the default became the isotropic zero-mean prior, and failed then (issue 57: the
//!    bound moved to where it is well posed, said here and in the closing note). The rank
//!    histogram is not tested here either: with one discrepancy shared by every
//!    replicate, the posterior's width carries the uncertainty of which discrepancy it is while
//!    the replicates differ only in `θ*`, levels and noise, so the ranks bunch in the middle
//!    (a well-calibrated method fails uniformity; the previous version of this test asserted it
//!    and the issue called that bound ill-posed).
//! 2. **Simulation-based calibration** (the well-posed rank test): `θ`, `ρ` and the
//!    discrepancy drawn per replicate from the calibration's own prior, which the calibration
//!    holds; the ranks of `θ*` must not reject uniformity at 1 %, the 95 % intervals must
//!    hold their level, and intervals half as wide must not (the power to see over-confidence
//!    of that size).

use bamudi::validation::{Coverage, binomial_acceptance};
use bamudi_gate::coverage::{self, CoverageOptions, ScenarioCoverage};

/// Significance of the acceptance regions (a correct method fails the check 1 % of the time
/// per scenario; the seed is fixed, so the outcome is deterministic).
const ALPHA: f64 = 0.01;

/// The central level of a Gaussian interval half as wide as the 95 % one: 2Φ(1.96/2) − 1.
const HALF_WIDTH_LEVEL: f64 = 0.6729;

/// The 95 % intervals' hit count lies in the acceptance region.
fn assert_in_region(s: &ScenarioCoverage, c95: &Coverage, region: (usize, usize)) {
    assert!(
        (region.0..=region.1).contains(&c95.hits),
        "{}: 95 % intervals hold θ* {}/{} times, outside the acceptance region {:?}",
        s.name,
        c95.hits,
        c95.n,
        region
    );
}

fn hits(s: &ScenarioCoverage, level: f64) -> Coverage {
    let pits: Vec<f64> = s.replicates.iter().map(|r| r.pit).collect();
    Coverage::from_pits(&pits, level)
}

#[test]
fn quick_coverage_of_the_default_mode_holds_its_nominal_level() {
    let opts = CoverageOptions {
        n_experiments: 60,
        seed: SEED,
        scoring: coverage::Scoring::ForceBands,
        ..CoverageOptions::quick()
    };
    let report = coverage::run(&opts, &|_, _| {}).unwrap();
    let region = binomial_acceptance(opts.n_replicates, 0.95, ALPHA).unwrap();
    assert_eq!(
        region,
        (34, 40),
        "the acceptance region stated in the module docs"
    );
    for s in &report.scenarios {
        let c95 = hits(s, 0.95);
        let half = hits(s, HALF_WIDTH_LEVEL);
        eprintln!(
            "{}: 95 % {}/{}, half-width intervals {}/{}, 50 % {:.2}, SBC p {:.3}, z rms {:.2}, \
             bands {:.3}/{:.3}, RMSE ratio {:.3}/{:.3}",
            s.name,
            c95.hits,
            c95.n,
            half.hits,
            half.n,
            s.theta_coverage["0.5"],
            s.sbc_uniformity_p,
            s.z_rms,
            s.force_band_coverage_95.normal,
            s.force_band_coverage_95.tangential,
            s.force_rmse_ratio_median.normal,
            s.force_rmse_ratio_median.tangential,
        );
        // The intervals resolve the gap: the scenarios' priors are 24 and 30 in wide (sd 7, 9 in);
        // the default's median sd on the paper's data is 0.17 in (tuning seed 2021), so 0.5 in
        // leaves room for this seed and none for an interval that learnt nothing.
        assert!(
            s.theta_sd_median <= 0.5,
            "{}: median θ sd {} in: the intervals do not resolve the gap",
            s.name,
            s.theta_sd_median
        );
        assert_in_region(s, &c95, region);
        // The force bands: at least 0.90 of the condition × point pairs (the bound) in
        // the normal force.
        assert!(
            s.force_band_coverage_95.normal >= 0.90,
            "{}: normal-force band coverage {}",
            s.name,
            s.force_band_coverage_95.normal
        );
        // Calibration must correct the force: normal-force RMSE after at most 1/5 of before.
        assert!(s.force_rmse_ratio_median.normal <= 0.2);
    }
}

/// The seed of both studies (not used while choosing the default prior).
const SEED: u64 = 8080;

/// Simulation-based calibration at the test's size: the discrepancy, `θ` and `ρ` drawn from
/// the calibration's prior with `bamudi`'s validation hyper-parameters, held by the calibration
/// (the exact-inference check of `cargo xtask validation`, part `sbc-held`, on 40 replicates).
#[test]
fn sbc_with_the_discrepancy_drawn_from_the_prior_has_uniform_ranks() {
    let opts = CoverageOptions {
        n_experiments: 60,
        seed: SEED,
        scoring: coverage::Scoring::ForceBands,
        sbc: Some(coverage::SbcOptions {
            hyper: coverage::GeneratingHyper {
                amplitude: 6e-6,
                length_scale_factor: 5.0,
                level_variance: 0.0,
                noise_sd: 1.0,
            },
            hold: true,
        }),
        ..CoverageOptions::quick()
    };
    let report = coverage::run(&opts, &|_, _| {}).unwrap();
    let region = binomial_acceptance(opts.n_replicates, 0.95, ALPHA).unwrap();
    for s in &report.scenarios {
        let c95 = hits(s, 0.95);
        eprintln!(
            "{} (SBC): 95 % {}/{}, 50 % {:.2}, rank p {:.3}, z mean / sd {:+.2} / {:.2}",
            s.name,
            c95.hits,
            c95.n,
            s.theta_coverage["0.5"],
            s.sbc_uniformity_p,
            s.z_mean_sd[0],
            s.z_mean_sd[1]
        );
        assert_in_region(s, &c95, region);
        assert!(
            s.sbc_uniformity_p >= ALPHA,
            "{}: SBC rank histogram rejects uniformity (p {:.4})",
            s.name,
            s.sbc_uniformity_p
        );
        // Power: intervals half as wide must be rejected by the same check.
        let half = hits(s, HALF_WIDTH_LEVEL);
        assert!(
            !(region.0..=region.1).contains(&half.hits),
            "{}: half-width intervals pass ({}/{}): the check cannot see over-confidence",
            s.name,
            half.hits,
            half.n
        );
    }
}

/// Module 4's force bands on a gate built unlike its drawing, with the deviation's field
/// declared as a build tolerance. The reality: the skin plate 5 % thinner than drawn (declared
/// sd 3 %, so the truth sits −1.67 sd off), `ρ = 0.8` and the paper's discrepancy (Eq. 53-54),
/// 60 experiments with 1 microstrain of noise, `θ*` at three places in scenario 1's prior. The
/// skin changes the contact force itself, not only the strains (`R ≠ 0`: the predictions must
/// carry the deviation into the unobservable response, which the beam test with `R = 0` does
/// not exercise). The truth's force at 10 new water-level pairs is the as-built gate's
/// `0.8 g(x, θ*) + δ(x)`.
///
/// Asserted (bounds set before the first run): the 95 % normal-force bands hold the true force
/// at ≥ 0.90 of the condition x point pairs over the three data sets (issue 15's bound for the
/// force bands), and the 95 % gap interval holds `θ*` in at least 2 of 3 (at the nominal 0.95,
/// 1 or fewer has probability 0.007).
///
/// What this test can and cannot see. It checks the declared calibration's claims (its bands
/// and its gap interval hold the as-built truth); it has no demonstrated power against a
/// calibration, or a Module 4, that left the skin out. Measured with the ignored test below
/// (12 data sets, `θ*` = 82-104 in, other seeds): declared, the bands hold 0.991 of the pairs
/// and bands half as wide 0.942; undeclared, 0.911 and 0.549, and the gap's interval holds
/// `θ*` 12 of 12 times against 8 of 12. The bands are conservative over most of the quoin, so
/// the pair bound passes the undeclared calibration and half-width bands, and at 8 of 12 the
/// undeclared one would meet "2 of 3" with probability 0.74: the contrast is a measurement,
/// not an assertion.
///
/// Measured when written (`cargo test -p bamudi-gate --test lib force_bands -- --nocapture`,
/// about 12 s): bands hold 14605 of 15270 pairs (0.956; per data set 0.948, 0.954, 0.967, at
/// the low end of the 12-set measurement's 0.954-1.000), gaps 85.50 ± 0.26 (1.9 sd from `θ*`,
/// near the interval's edge; the grid's step is 0.2 in), 93.30 ± 0.22, 101.10 ± 0.17 in
/// (3 of 3). History, so that no seed looks chosen: the first version (same bounds, seeds
/// 910 + r, 920 + r, 930 + r, 940 + r) held 0.951 of the pairs and `θ*` 2 of 3; moving the
/// set-up into [`AsBuiltSkin`] changed the seed scheme to the one below, and the numbers above
/// are its. On the first seeds one data set (`θ*` = 93, gap 93.52 ± 0.21 in, missed) held
/// 0.854: misses from the gap's edge to the top, the worst at the top point, where 7 gauges do
/// not constrain the discrepancy's Legendre terms and the mean extrapolates (6700 ± 3350 lbf/in
/// against a true 0); and at a condition with a 0.8 in head, bands (scaled, like the
/// discrepancy's prior, to the model's nearly vanishing force) narrower than the truth's
/// discrepancy of under 1 lbf/in. A first version also asserted that half-width bands fail the
/// bound; they did on its seeds (0.866) but not over the 12 data sets (0.942), so that
/// assertion was removed rather than kept on a lucky seed.
#[test]
fn force_bands_carry_a_declared_tolerance_on_an_as_built_gate() {
    let setup = AsBuiltSkin::new();
    let mut declared = SkinTally::default();
    for (r, theta) in [85.0, 93.0, 101.0].into_iter().enumerate() {
        let [d, _] = setup.replicate(theta, 910 + 10 * r as u64, false);
        declared.add(&d);
    }
    let (rate, _) = declared.rates();
    assert!(rate >= 0.90, "declared: normal bands hold {declared:?}");
    assert!(
        declared.covered >= 2,
        "declared: θ* covered in {} of 3",
        declared.covered
    );
}

/// The measurement behind the test above on more data sets (`θ*` at 12 places spread over
/// the prior, other seeds), with and without the declaration: `cargo test -p bamudi-gate --test lib
/// as_built_skin_force_bands_over_twelve -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement for the documentation, not a check"]
fn as_built_skin_force_bands_over_twelve_gaps() {
    let setup = AsBuiltSkin::new();
    let (mut declared, mut undeclared) = (SkinTally::default(), SkinTally::default());
    for r in 0..12 {
        let theta = 82.0 + 2.0 * r as f64;
        let [d, u] = setup.replicate(theta, 7000 + 10 * r as u64, true);
        declared.add(&d);
        undeclared.add(&u);
    }
    eprintln!(
        "declared over 12 gaps: {declared:?}, rates {:?}",
        declared.rates()
    );
    eprintln!("undeclared: {undeclared:?}, rates {:?}", undeclared.rates());
}

/// Hits of one calibration (or a sum of them) against its as-built truth.
#[derive(Debug, Default, Clone, Copy)]
struct SkinTally {
    /// Condition x point pairs whose true normal force lies in the 95 % band.
    inside: usize,
    /// The same for bands half as wide (each side of the mixture's mean halved).
    inside_half: usize,
    /// Condition x point pairs scored.
    pairs: usize,
    /// Data sets whose 95 % gap interval holds `θ*`.
    covered: usize,
}

impl SkinTally {
    fn add(&mut self, o: &SkinTally) {
        self.inside += o.inside;
        self.inside_half += o.inside_half;
        self.pairs += o.pairs;
        self.covered += o.covered;
    }

    /// Fractions of pairs inside the 95 % bands and inside the half-width bands.
    fn rates(&self) -> (f64, f64) {
        let n = self.pairs.max(1) as f64;
        (self.inside as f64 / n, self.inside_half as f64 / n)
    }
}

/// The drawing (24-in mesh) calibrated with and without the skin plate declared to 3 %, and
/// the as-built gate whose skin is 5 % thinner.
struct AsBuiltSkin {
    truth_contact: mitergate::ContactModel,
    declared: mitergate::GateMultiLevel,
    undeclared: mitergate::GateMultiLevel,
}

impl AsBuiltSkin {
    fn new() -> Self {
        use bamudi_gate::tolerance::{ToleranceSpec, build_tolerances};
        use mitergate::{GateConfig, MultiLevelSpec, reality::Reality};
        let mut drawing = GateConfig::default();
        drawing.mesh.element_size = 24.0;
        let thin = Reality::scaled_field(&drawing, "skin_plate.thickness", 0.95).unwrap();
        let (contact, _, _) = bamudi_gate::gate::build(&drawing).unwrap();
        let (truth_contact, _, _) = bamudi_gate::gate::build(&thin).unwrap();
        let spec = MultiLevelSpec {
            gap_prior_in: (81.0, 105.0),
            discrepancy_terms: [6, 6],
            memo_capacity: 100_000,
            row_memo_capacity: 0,
        };
        let undeclared = mitergate::multilevel(contact.clone(), &spec).unwrap();
        let tolerance = ToleranceSpec {
            key: "skin_plate.thickness".into(),
            relative_sd: 0.03,
        };
        let built = build_tolerances(&[tolerance], Some(&drawing), "test").unwrap();
        let declared = mitergate::multilevel(contact, &spec)
            .unwrap()
            .with_tolerances(built)
            .unwrap();
        Self {
            truth_contact,
            declared,
            undeclared,
        }
    }

    /// One data set (60 experiments, `ρ` = 0.8, the paper's discrepancy, 1 microstrain of
    /// noise) at `theta`, calibrated with the declaration (and without, when `both`), scored
    /// at 10 new conditions; seeds from `seed`.
    fn replicate(&self, theta: f64, seed: u64, both: bool) -> [SkinTally; 2] {
        use bamudi::{Calibrate, CalibrationParams, CoefficientMode, EstimatorParams};
        use bamudi_gate::coverage::{DiscrepancyShape, Truth};
        use mitergate::data::truth::sample_levels;
        let truth = Truth::new(theta, 0.8, DiscrepancyShape::Paper);
        let levels = sample_levels(60, seed);
        let y = truth
            .strains(&self.truth_contact, &levels, 1.0, seed + 1)
            .unwrap();
        let x = nalgebra::DMatrix::from_fn(levels.len(), 2, |i, j| levels[i][j]);
        let gauges = (1..=y.ncols()).map(|g| format!("g{g}")).collect();
        let exps =
            bamudi::Experiments::new(vec!["h_up".into(), "h_down".into()], gauges, x, y).unwrap();
        let cfg = CalibrationParams::default()
            .estimator(EstimatorParams::ExactLinear)
            .coefficients(CoefficientMode::default())
            .theta_grid_points(121)
            .sampling(bamudi::SamplingRule::default().noise_sd(1.0))
            .seed(seed + 2)
            .check()
            .unwrap();
        let new_x = sample_levels(10, seed + 3);
        let true_forces: Vec<Vec<f64>> = new_x
            .iter()
            .map(|xn| truth.forces(&self.truth_contact, *xn).unwrap())
            .collect();
        let mut out = [SkinTally::default(); 2];
        let models = if both { 2 } else { 1 };
        for (k, model) in [&self.declared, &self.undeclared][..models]
            .iter()
            .enumerate()
        {
            let cal = Calibrate::new(&cfg).run(*model, &exps).unwrap();
            let s = cal.module3().posterior.summary(0);
            let t = &mut out[k];
            t.covered = usize::from((s.ci95.0..=s.ci95.1).contains(&theta));
            let predictor = cal.predictor(*model).unwrap();
            for (xn, f) in new_x.iter().zip(&true_forces) {
                let band = predictor.response(xn).unwrap();
                for p in 0..self.truth_contact.gate().n_points() {
                    let (m, lo, hi) = (band.mean[p], band.lower[p], band.upper[p]);
                    t.inside += usize::from(lo <= f[p] && f[p] <= hi);
                    let (lo, hi) = (m - 0.5 * (m - lo), m + 0.5 * (hi - m));
                    t.inside_half += usize::from(lo <= f[p] && f[p] <= hi);
                    t.pairs += 1;
                }
            }
            eprintln!(
                "skin x 0.95, θ* {theta}, {}: gap {:.2} ± {:.2} in, {t:?}",
                ["declared", "undeclared"][k],
                s.mean,
                s.sd
            );
        }
        out
    }
}
