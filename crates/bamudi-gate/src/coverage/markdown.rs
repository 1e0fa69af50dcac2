//! The coverage study as markdown.

use super::{ACCEPTANCE_ALPHA, CoverageReport, LevelCoverage, RANK_BINS, ScenarioCoverage};

/// The report's name of a coefficient mode.
pub fn mode_label(mode: bamudi::CoefficientMode) -> &'static str {
    match mode {
        bamudi::CoefficientMode::Marginal => "marginal (default)",
        bamudi::CoefficientMode::ConditionalOnTheta => "conditional",
        bamudi::CoefficientMode::PriorMarginal => "paper's Module 3",
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

impl CoverageReport {
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
             discrepancy shape `{}`; estimator {}; marginal-mode prior: kernel `{}`, scales `{}`, \
             support mask {}, level variance {:e}; {} new water-level pairs per replicate for the force bands; seed {}. \
             Wall time {:.0} s.\n\n",
            self.n_dofs,
            self.element_size,
            o.n_replicates,
            o.n_experiments,
            o.gauge_noise_sd,
            label(o.discrepancy),
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
