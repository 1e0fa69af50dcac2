//! The coverage study as markdown.

use super::{ACCEPTANCE_ALPHA, CoverageReport, LevelCoverage, RANK_BINS, ScenarioCoverage};

/// The report's name of a coefficient mode.
pub fn mode_label(mode: bamudi::ModeKind) -> &'static str {
    match mode {
        bamudi::ModeKind::Marginal => "marginal (default)",
        bamudi::ModeKind::ConditionalOnTheta => "conditional",
        bamudi::ModeKind::PriorMarginal => "paper's Module 3",
    }
}

/// The serialised name of a unit enum variant.
fn label(v: impl serde::Serialize) -> String {
    serde_json::to_value(v)
        .ok()
        .and_then(|v| v.as_str().map(String::from))
        .unwrap_or_default()
}

fn level_cell(l: &LevelCoverage) -> String {
    let ok = (l.acceptance.0..=l.acceptance.1).contains(&l.hits);
    format!(
        "{:.2} [{:.2}, {:.2}] {}",
        l.rate,
        l.interval.0,
        l.interval.1,
        if ok { "ok" } else { "**miss**" }
    )
}

fn coverage_row(s: &ScenarioCoverage) -> String {
    let cells: Vec<String> = s.theta_levels.iter().map(level_cell).collect();
    format!(
        "| {} | {} | {} | {} | {} | {:.3} | {:.2} | {:.3} |\n",
        s.name,
        mode_label(s.mode),
        s.estimator,
        s.n_replicates,
        cells.join(" | "),
        s.sbc_uniformity_p,
        s.z_rms,
        s.theta_sd_median,
    )
}

fn prediction_row(s: &ScenarioCoverage) -> String {
    format!(
        "| {} | {} | {:.3} | {:.3} | {} | {} | {:.3} ± {:.3} [{:.3}, {:.3}] | {:.3} | {:.3} | {:.1} |\n",
        s.name,
        mode_label(s.mode),
        s.force_band_coverage_95.normal,
        s.force_band_coverage_95.tangential,
        s.fatigue_band_coverage_95
            .map_or("not measured".to_string(), |v| format!("{v:.3}")),
        s.force_band_halfwidth_ratio_median
            .map_or("not measured".to_string(), |h| format!(
                "{:.3} / {:.3}",
                h.normal, h.tangential
            )),
        s.rho[0],
        s.rho[1],
        s.rho[2],
        s.rho[3],
        s.force_rmse_ratio_median.normal,
        s.force_rmse_ratio_median.tangential,
        s.seconds / s.n_replicates.max(1) as f64,
    )
}

/// The check of `ρ`'s posterior against the truth's `ρ` (modes that report its sd).
fn rho_section(scenarios: &[ScenarioCoverage]) -> String {
    let rows: Vec<String> = scenarios
        .iter()
        .filter_map(|s| {
            s.rho_check.as_ref().map(|c| {
                format!(
                    "| {} | {} | {} | {:+.2} | {:.2} | {:.4} |\n",
                    s.name,
                    mode_label(s.mode),
                    level_cell(&c.coverage_95),
                    c.z_mean,
                    c.z_rms,
                    c.sd_median,
                )
            })
        })
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\nρ's reported posterior against the truth's ρ: coverage of mean ± 1.96 sd (a Gaussian \
         approximation of the mixture over θ), mean and rms of (posterior mean − ρ)/sd, median \
         sd. The truth's ρ is the scale of g in the simulator's split ρ g + δ; a δ partly along \
         g makes other splits of the same data equally true, so a miss says the ρ interval is \
         not one for that split's ρ (the θ table above is the claim users act on).\n\n\
         | scenario | mode | ρ 95 % | z mean | z rms | median sd |\n|---|---|---|---|---|---|\n",
    );
    rows.iter().for_each(|r| out.push_str(r));
    out
}

/// The corrected force beside the baselines and oracles, and `ρ⊥` against the truth's.
fn correction_section(scenarios: &[ScenarioCoverage]) -> String {
    let rows: Vec<String> = scenarios
        .iter()
        .filter_map(|s| {
            let c = s.correction.as_ref()?;
            let b = &c.baselines;
            let nt = |v: crate::baselines::NormalTangential, p: usize| {
                format!("{:.*} / {:.*}", p, v.normal, p, v.tangential)
            };
            let rho = c.rho_projection.as_ref().map_or("–".into(), |r| {
                format!("{} z {:+.2} (rms {:.2})", level_cell(&r.coverage_95), r.z_mean, r.z_rms)
            });
            let delta = format!(
                "{:.2} / {:.2} (floor {:.2} / {:.2})",
                c.delta_ratio.normal,
                c.delta_ratio.tangential,
                c.delta_floor_ratio.normal,
                c.delta_floor_ratio.tangential
            );
            Some(format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:+.2} / {:.2} | {} |\n",
                s.name,
                mode_label(s.mode),
                nt(b.prior_mean, 0),
                nt(b.no_discrepancy, 1),
                nt(b.calibrated, 1),
                nt(b.oracle_split, 1),
                nt(b.oracle_seen, 1),
                nt(b.theta_spread, 1),
                nt(b.oracle_seen_posterior, 1),
                nt(c.vs_no_discrepancy, 2),
                nt(c.vs_oracle_seen, 2),
                delta,
                nt(c.halfwidth_over_delta, 2),
                s.z_mean_sd[0],
                s.z_mean_sd[1],
                rho,
            ))
        })
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut out = String::from(
        "\nThe corrected force against the baselines (medians over replicates of the RMSE over \
         conditions and quoin points, lbf/in, normal / tangential): (a) the prior-mean model \
         with ρ = 1; (b) the best calibration without a discrepancy (ρ and θ fitted); (c) this \
         calibration; (d) the truth's own split ρ* g(θ*), whose error is the true δ; (e) (d) \
         plus the part of δ the gauges see (the floor for a method that knew θ*); (f) the truth \
         with θ* replaced by this calibration's θ posterior (what θ's spread alone costs); (g) \
         the model at this θ posterior with ρ* known, corrected by exactly what the gauges see \
         (the floor for this θ posterior). Ratios are medians of per-replicate \
         ratios; δ̂ / δ is the reconstructed discrepancy's RMSE over the true δ's RMS (truth's \
         split), with the floor (g)'s reconstruction leaves; half-width / δ the median (over conditions and points) 95 % force band half-width over the true δ's RMS; \
         θ z: mean / sd of (posterior mean − θ*)/sd; ρ⊥: the identified ρ against the truth's \
         (95 % coverage, z mean and rms).\n\n\
         | scenario | mode | (a) | (b) | (c) | (d) | (e) | (f) | (g) | (c)/(b) | (c)/(e) | δ̂ / δ | half-width / δ | θ z mean / sd | ρ⊥ 95 % |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    rows.iter().for_each(|r| out.push_str(r));
    out
}

/// Every ranked quantity's uniformity test and z.
fn ranks_section(scenarios: &[ScenarioCoverage]) -> String {
    let mut rows = String::new();
    for s in scenarios {
        for r in s.ranked.iter().flatten() {
            let z = r
                .z_mean_sd
                .map_or("–".to_string(), |[m, sd]| format!("{m:+.2} / {sd:.2}"));
            rows.push_str(&format!(
                "| {} | {} | {} | {} | {:.3} | {} | {:?} |\n",
                s.name,
                mode_label(s.mode),
                r.quantity,
                r.n,
                r.uniformity_p,
                z,
                r.histogram
            ));
        }
    }
    if rows.is_empty() {
        return String::new();
    }
    format!(
        "\nRanks of the truth in each posterior (simulation-based calibration: uniform when the \
         calibration is exact): the χ² p of the {RANK_BINS}-bin histogram, and the mean / sd of \
         (posterior mean − truth)/posterior sd (0 / 1 when calibrated). ρ is the split's ρ \
         (the data's own ρ only when δ is drawn from the prior); the force is the normal force \
         at location A (a quarter of the quoin height) at the first new condition, ranked \
         among 1,000 joint posterior draws; the damage is the quoin block's largest along the \
         quoin there (each draw's hot spot against the truth's).\n\n\
         | scenario | mode | quantity | R | p | z mean / sd | histogram |\n|---|---|---|---|---|---|---|\n{rows}"
    )
}

impl CoverageReport {
    /// The true discrepancy as the options name it.
    fn truth_label(&self) -> String {
        let o = &self.options;
        if let Some(sbc) = &o.sbc {
            let h = sbc.hyper;
            return format!(
                "drawn per replicate with θ and ρ from the calibration's prior (amplitude {:e}, \
                 length factor {}, level variance {}; the calibration {} them)",
                h.amplitude,
                h.length_scale_factor,
                h.level_variance,
                if sbc.hold { "holds" } else { "estimates" }
            );
        }
        if let Some(f) = &o.discrepancy_file {
            return format!("file {}", f.display());
        }
        match o.discrepancy_scale == 1.0 {
            true => label(o.discrepancy),
            false => format!("{} x{}", label(o.discrepancy), o.discrepancy_scale),
        }
    }

    /// Which replicates the report holds, when that is not simply `0 .. n` of one run.
    fn provenance(&self) -> String {
        let mut out = String::new();
        if self.merged_from > 0 {
            out.push_str(&format!(
                "Merged from {} parts (reports and replicate logs of one study, \
                 `cargo xtask coverage --render`); the wall time is the merged reports' sum, the \
                 logs' replicates count only in the seconds per replicate.\n\n",
                self.merged_from
            ));
        }
        let o = &self.options;
        let whole = |s: &ScenarioCoverage| {
            s.replicates
                .iter()
                .enumerate()
                .all(|(k, r)| r.index == o.first_replicate + k)
                && s.n_replicates == o.n_replicates
        };
        if o.first_replicate > 0 || !self.scenarios.iter().all(whole) {
            out.push_str("Replicate indices: ");
            let ranges: Vec<String> = self
                .scenarios
                .iter()
                .map(|s| format!("{} {}", s.name, index_ranges(&s.replicates)))
                .collect();
            out.push_str(&ranges.join("; "));
            out.push_str(".\n\n");
        }
        out
    }

    /// The markdown report: coverage table, prediction table, rank histograms.
    pub fn markdown(&self) -> String {
        let o = &self.options;
        let mut s = String::from("# Coverage of the θ posterior and of the force bands\n\n");
        s.push_str(&format!(
            "Gate: {} DOF ({} in elements). Per scenario {} replicates, each with θ* drawn from \
             the prior, {} experiments with fresh water levels and noise (σ = {} µε) and the \
             true discrepancy `{}`; estimator {}; marginal-mode prior: kernel `{}`, scales `{}`, \
             support mask {}, level variance {:e}; {} new water-level pairs per replicate for the force bands; seed {}. \
             Wall time {:.0} s.\n\n",
            self.n_dofs,
            self.element_size,
            o.n_replicates,
            o.n_experiments,
            o.sbc.map_or(o.gauge_noise_sd, |s| s.hyper.noise_sd),
            self.truth_label(),
            super::estimator_kind(&o.estimator),
            label(o.marginal.kernel),
            label(o.marginal.scales),
            if o.marginal.mask_outside_support {
                "on"
            } else {
                "off"
            },
            o.marginal.level_variance,
            o.new_conditions,
            o.seed,
            self.total_s,
        ));
        s.push_str(&self.provenance());
        if let Some((lo, hi)) = o.rho_range {
            let (d_lo, d_hi) = bamudi::SamplingRule::default().rho_range;
            s.push_str(&format!(
                "ρ's prior (and the Module-2 sampling rule's ρ range) narrowed to U({lo}, {hi}); \
                 the default is U({d_lo}, {d_hi}).\n\n"
            ));
        }
        s.push_str(&format!(
            "Coverage of the central θ intervals: empirical rate, Clopper-Pearson 95 % interval, \
             and whether the hit count lies in the {:.0} % binomial acceptance region of the \
             nominal level. SBC p: χ² test of the {RANK_BINS}-bin rank histogram. z rms: root \
             mean square of (posterior mean − θ*)/sd (1 when calibrated).\n\n",
            100.0 * ACCEPTANCE_ALPHA
        ));
        s.push_str("| scenario | mode | estimator | R | 50 % | 80 % | 90 % | 95 % | SBC p | z rms | median sd (in) |\n");
        s.push_str("|---|---|---|---|---|---|---|---|---|---|---|\n");
        self.scenarios
            .iter()
            .for_each(|r| s.push_str(&coverage_row(r)));
        s.push_str(
            "\nModule-4 predictions: mean fraction of condition × quoin-point pairs inside the 95 % \
             force bands, and inside the 95 % band of the quoin-block fatigue damage rate (the \
             prediction level, points with damage only); the bands' median half-width over \
             the force RMSE before calibration (normal / tangential: how wide a band is against \
             the error it corrects); ρ over replicates (mean ± sd [min, max]; the posterior mean in the \
             marginal mode, ρ* otherwise); median force RMSE after / before; seconds per replicate.\n\n",
        );
        s.push_str("| scenario | mode | band normal | band tangential | band fatigue | half-width / RMSE before | ρ | RMSE ratio normal | RMSE ratio tangential | s / replicate |\n");
        s.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
        self.scenarios
            .iter()
            .for_each(|r| s.push_str(&prediction_row(r)));
        s.push_str(&correction_section(&self.scenarios));
        s.push_str(&ranks_section(&self.scenarios));
        s.push_str(&rho_section(&self.scenarios));
        s.push_str("\nSBC rank histograms (replicates per tenth of the posterior CDF at θ*):\n\n");
        for r in &self.scenarios {
            s.push_str(&format!(
                "- {}, {}: {:?}\n",
                r.name,
                mode_label(r.mode),
                r.sbc_histogram
            ));
        }
        s
    }
}

/// `0-21, 50-66` for the replicates' indices (sorted).
fn index_ranges(reps: &[super::Replicate]) -> String {
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for r in reps {
        match ranges.last_mut() {
            Some((_, hi)) if r.index == *hi + 1 => *hi = r.index,
            _ => ranges.push((r.index, r.index)),
        }
    }
    ranges
        .iter()
        .map(|&(lo, hi)| {
            if lo == hi {
                lo.to_string()
            } else {
                format!("{lo}-{hi}")
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}
