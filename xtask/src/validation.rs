//! `cargo xtask validation`: the two-part validation protocol of the default calibration,
//! fixed before it was run (`docs/results/validation.md`):
//!
//! 1. **Self-consistency (SBC)**: `θ`, `ρ` and the discrepancy drawn per replicate from the
//!    calibration's stated prior; the calibration holds the generating hyper-parameters
//!    (`sbc-held`) or estimates them as the product does (`sbc-estimated`). Ranked: `θ`, `ρ`,
//!    the normal force at location A, the hot spot's damage.
//! 2. **Robustness to a fixed, wrong discrepancy**: a panel of shapes (the paper's at 0.5, 1,
//!    2 and 4 times its size, tapered, normal only, tangential only, none, and two shapes of
//!    files none of the library's shapes resembles), `θ*` from the prior, fresh noise and
//!    levels per replicate; the paper's shape and none also at the paper's size.
//!    Each panel part runs twice on the same replicates: with the default
//!    (`presence = "weighed"`: the predictions weigh the calibrations with and without a
//!    discrepancy by their evidence) and as `assumed-<part>` with the discrepancy assumed. The
//!    SBC parts calibrate with the discrepancy assumed: their data always hold one, drawn from
//!    the prior the calibration states.
//!
//! Every part is one coverage study (`bamudi_gate::coverage`) written to
//! `<out>/<part>.json` as it finishes (with the running log `<part>.json.partial.jsonl`
//! meanwhile): a stopped run resumes by skipping the parts already written, and a part stopped
//! midway is read from its log (marked so) until its log is moved away. `--render` (also
//! run after the parts) writes `<out>/../validation.md` from whatever parts exist.

use anyhow::{Context, Result, bail};
use bamudi::DiscrepancyPresence;
use bamudi_gate::coverage::{
    CorrectionSummary, CoverageOptions, CoverageReport, DiscrepancyShape, GeneratingHyper,
    SbcOptions, ScenarioCoverage,
};
use std::path::{Path, PathBuf};

/// The seeds of the validation, none used while choosing the prior (those were 2021, 7 and 11;
/// `docs/results/validation.md`).
pub const PANEL_SEED: u64 = 31_337;
/// The seed of the SBC parts.
pub const SBC_SEED: u64 = 4_242;
/// The seed of the paper-size parts.
pub const PAPER_SEED: u64 = 777;

/// The generating hyper-parameters of SBC: the amplitude and noise the calibration fits on the
/// paper's data at the quick size (medians over the tuning study's replicates: amplitude
/// 6.1e-6, σ 1.00 µε; fitted length factors 3-29), with a length factor of 5 so the draws vary
/// across the water levels, and no level (the default prior's).
pub const SBC_HYPER: GeneratingHyper = GeneratingHyper {
    amplitude: 6e-6,
    length_scale_factor: 5.0,
    level_variance: 0.0,
    noise_sd: 1.0,
};

/// The command line's choices.
#[derive(clap::Args)]
pub struct ValidationArgs {
    /// Parts to run, comma separated: `sbc-held`, `sbc-estimated`, `panel`, `paper-size`, or a
    /// single part's name (`panel-paper`, ...). Default: none (only `--render`).
    #[arg(long, value_delimiter = ',')]
    parts: Vec<String>,
    /// Replicates per scenario of the quick parts (SBC: 500, panel: 100 by default).
    #[arg(long)]
    replicates: Option<usize>,
    /// Replicates per scenario of the paper-size parts.
    #[arg(long, default_value_t = 30)]
    paper_replicates: usize,
    /// Worker threads (0: all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Where the parts' JSON go.
    #[arg(long, default_value = "docs/results/validation")]
    out: PathBuf,
    /// Write the markdown from the parts that exist.
    #[arg(long)]
    render: bool,
    /// Bring each requested part to its size: a part written or stopped with fewer replicates
    /// per scenario than asked runs the missing ones (as `<part>.extend-N.json`, each with its
    /// own running log, so a stopped extension resumes too) and the pieces are merged into
    /// `<part>.json`.
    #[arg(long)]
    extend: bool,
}

/// One part of the protocol.
struct Part {
    name: String,
    opts: CoverageOptions,
    group: &'static str,
}

fn parts(a: &ValidationArgs) -> Vec<Part> {
    let quick = |seed: u64, reps: usize| CoverageOptions {
        seed,
        n_replicates: reps,
        threads: a.threads,
        new_conditions: 4,
        ..CoverageOptions::quick()
    };
    let mut out = Vec::new();
    for hold in [true, false] {
        let mut o = quick(SBC_SEED, a.replicates.unwrap_or(500));
        o.sbc = Some(SbcOptions {
            hyper: SBC_HYPER,
            hold,
        });
        // what the study runs for SBC (`coverage` forces it), recorded so the parts of an
        // extension are parts of the same study
        o.marginal.presence = DiscrepancyPresence::Assumed;
        out.push(Part {
            name: format!("sbc-{}", if hold { "held" } else { "estimated" }),
            opts: o,
            group: "sbc",
        });
    }
    let shapes: [(&str, DiscrepancyShape, f64); 8] = [
        ("paper", DiscrepancyShape::Paper, 1.0),
        ("none", DiscrepancyShape::None, 1.0),
        ("paper-x0.5", DiscrepancyShape::Paper, 0.5),
        ("paper-x2", DiscrepancyShape::Paper, 2.0),
        ("paper-x4", DiscrepancyShape::Paper, 4.0),
        ("tapered", DiscrepancyShape::Tapered, 1.0),
        ("normal-only", DiscrepancyShape::PaperNormal, 1.0),
        ("tangential-only", DiscrepancyShape::PaperTangential, 1.0),
    ];
    // each panel part twice: the default (the discrepancy weighed by evidence) and with the
    // discrepancy assumed (the alternative, on the same seeds and replicates)
    let presences = [
        ("", DiscrepancyPresence::Weighed),
        ("assumed-", DiscrepancyPresence::Assumed),
    ];
    for (prefix, presence) in presences {
        let panel = if prefix.is_empty() {
            "panel"
        } else {
            "assumed-panel"
        };
        for (name, shape, scale) in shapes {
            let mut o = quick(PANEL_SEED, a.replicates.unwrap_or(100));
            (o.discrepancy, o.discrepancy_scale) = (shape, scale);
            o.marginal.presence = presence;
            out.push(Part {
                name: format!("{prefix}panel-{name}"),
                opts: o,
                group: panel,
            });
        }
        for file in ["bulge.csv", "tilt.toml"] {
            let mut o = quick(PANEL_SEED, a.replicates.unwrap_or(100));
            o.discrepancy_file = Some(a.out.join("shapes").join(file));
            o.marginal.presence = presence;
            out.push(Part {
                name: format!(
                    "{prefix}panel-file-{}",
                    file.split('.').next().unwrap_or(file)
                ),
                opts: o,
                group: panel,
            });
        }
        for (name, shape) in [
            ("paper", DiscrepancyShape::Paper),
            ("none", DiscrepancyShape::None),
        ] {
            let mut o = CoverageOptions {
                modes: vec![bamudi::ModeKind::Marginal],
                seed: PAPER_SEED,
                n_replicates: a.paper_replicates,
                threads: a.threads,
                discrepancy: shape,
                ..CoverageOptions::paper_exact()
            };
            o.marginal.presence = presence;
            out.push(Part {
                name: format!("{prefix}paper-size-{name}"),
                opts: o,
                group: if prefix.is_empty() {
                    "paper-size"
                } else {
                    "assumed-paper-size"
                },
            });
        }
    }
    out
}

/// Runs the requested parts (skipping those written) and renders the markdown.
pub fn run(a: &ValidationArgs) -> Result<()> {
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let all = parts(a);
    for want in &a.parts {
        if !all.iter().any(|p| &p.name == want || p.group == want) {
            bail!("--parts {want}: no such part or group");
        }
    }
    for part in all
        .iter()
        .filter(|p| a.parts.iter().any(|w| w == &p.name || w == p.group))
    {
        let json = a.out.join(format!("{}.json", part.name));
        if a.extend {
            extend(a, part)?;
            continue;
        }
        if json.exists() {
            eprintln!("{}: {} exists, skipped", part.name, json.display());
            continue;
        }
        let log = crate::coverage::log_path(&json);
        if log.exists() {
            eprintln!(
                "{}: {} holds a stopped run, skipped (the tables read it; move it away to run \
                 the part again)",
                part.name,
                log.display()
            );
            continue;
        }
        eprintln!("{}: running", part.name);
        let report = crate::coverage::study(&part.opts, Some(&json))?;
        bamudi::data::write_atomic(&json, report.to_json()?.as_bytes())?;
        let _ = std::fs::remove_file(crate::coverage::log_path(&json));
    }
    let md = render(&a.out, &all)?;
    let path = a
        .out
        .parent()
        .unwrap_or(Path::new("."))
        .join("validation.md");
    bamudi::data::write_atomic(&path, md.as_bytes())?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// The pieces of a part so far: `<part>.json` (or its stopped log) and the pieces of earlier
/// extensions (`<part>.extend-N.json` or their logs), each named by its report's path.
fn pieces(out: &Path, name: &str) -> Result<Vec<PathBuf>> {
    let mut found = vec![out.join(format!("{name}.json"))];
    for n in 1.. {
        let p = out.join(format!("{name}.extend-{n}.json"));
        if !p.exists() && !crate::coverage::log_path(&p).exists() {
            break;
        }
        found.push(p);
    }
    Ok(found)
}

/// The pieces merged. A replicate in more than one piece (a stopped run finishes replicates out
/// of order, and the extension after it runs every index from the first one missing) is kept
/// from the first piece: each replicate's data are drawn from its index, so the copies agree.
fn combined(pieces: &[PathBuf]) -> Result<Option<bamudi_gate::coverage::CoverageReport>> {
    let mut reports: Vec<CoverageReport> = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for p in pieces {
        let Some(mut r) = read(p)? else { continue };
        for s in &mut r.report.scenarios {
            s.replicates
                .retain(|x| !seen.contains(&(s.name.clone(), format!("{:?}", s.mode), x.index)));
        }
        for s in &r.report.scenarios {
            let mode = format!("{:?}", s.mode);
            seen.extend(
                s.replicates
                    .iter()
                    .map(|x| (s.name.clone(), mode.clone(), x.index)),
            );
        }
        r.report.scenarios.retain(|s| !s.replicates.is_empty());
        reports.push(r.report);
    }
    // a stopped run's log does not say its gate's size: it is the finished pieces' (the same
    // options build the same gate)
    let gate = reports
        .iter()
        .find(|r| r.n_dofs > 0)
        .map(|r| (r.n_dofs, r.element_size));
    if let Some((n_dofs, element_size)) = gate {
        for r in reports.iter_mut().filter(|r| r.n_dofs == 0) {
            (r.n_dofs, r.element_size) = (n_dofs, element_size);
        }
    }
    if reports.is_empty() {
        return Ok(None);
    }
    Ok(Some(CoverageReport::merge(&reports, vec![])?))
}

/// `--extend`: runs the replicates the part lacks, scenario by scenario, from the first index
/// missing to its size, then writes the merged `<part>.json` and removes the pieces.
fn extend(a: &ValidationArgs, part: &Part) -> Result<()> {
    let want = part.opts.n_replicates;
    for &number in &part.opts.scenarios {
        let pieces = pieces(&a.out, &part.name)?;
        let present: std::collections::BTreeSet<usize> = combined(&pieces)?
            .iter()
            .flat_map(|r| r.scenarios.iter())
            .filter(|s| s.name == format!("scenario {number}"))
            .flat_map(|s| s.replicates.iter().map(|x| x.index))
            .collect();
        let Some(first) = (0..want).find(|i| !present.contains(i)) else {
            continue;
        };
        let mut o = part.opts.clone();
        (o.scenarios, o.first_replicate, o.n_replicates) = (vec![number], first, want - first);
        let piece = a
            .out
            .join(format!("{}.extend-{}.json", part.name, pieces.len()));
        eprintln!(
            "{}: scenario {number}, replicates {first}..{want} into {}",
            part.name,
            piece.display()
        );
        let report = crate::coverage::study(&o, Some(&piece))?;
        bamudi::data::write_atomic(&piece, report.to_json()?.as_bytes())?;
        let _ = std::fs::remove_file(crate::coverage::log_path(&piece));
    }
    let pieces = pieces(&a.out, &part.name)?;
    let merged = combined(&pieces)?.context("no piece to merge")?;
    for s in &merged.scenarios {
        if s.replicates.len() < want {
            bail!(
                "{}: {} has {} of {want} replicates after the extension",
                part.name,
                s.name,
                s.replicates.len()
            );
        }
    }
    let json = &pieces[0];
    bamudi::data::write_atomic(json, merged.to_json()?.as_bytes())?;
    for p in &pieces[1..] {
        let _ = std::fs::remove_file(p);
    }
    for p in &pieces {
        let _ = std::fs::remove_file(crate::coverage::log_path(p));
    }
    eprintln!(
        "{}: {} written from {} pieces",
        part.name,
        json.display(),
        pieces.len()
    );
    Ok(())
}

/// A part's report, or, for a part stopped before it finished, the replicates its running
/// log holds (`stopped` set: the table says so, and its R column is what was run).
struct Read {
    report: CoverageReport,
    stopped: bool,
}

fn read(path: &Path) -> Result<Option<Read>> {
    if path.exists() {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let report =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        return Ok(Some(Read {
            report,
            stopped: false,
        }));
    }
    let log_path = crate::coverage::log_path(path);
    if !log_path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&log_path)
        .with_context(|| format!("reading {}", log_path.display()))?;
    let log = bamudi_gate::coverage::ReplicateLog::parse(&text, &log_path.display().to_string())?;
    let options = log
        .options
        .clone()
        .with_context(|| format!("{}: no options line", log_path.display()))?;
    // an empty report carries the log's options into the merge, which summarises the log
    let empty = CoverageReport {
        options,
        n_dofs: 0,
        element_size: 0.0,
        scenarios: vec![],
        total_s: 0.0,
        merged_from: 0,
    };
    Ok(Some(Read {
        report: CoverageReport::merge(&[empty], vec![log])?,
        stopped: true,
    }))
}

/// A part's name in a table, marked when its study was stopped before it finished.
fn label(name: &str, r: &Read) -> String {
    if r.stopped {
        format!("{name} (stopped: its log)")
    } else {
        name.to_string()
    }
}

/// The level cell: rate and whether it lies in its acceptance region.
fn level(s: &ScenarioCoverage, nominal: f64) -> String {
    s.theta_levels
        .iter()
        .find(|l| (l.level - nominal).abs() < 1e-9)
        .map_or("–".into(), |l| {
            let ok = (l.acceptance.0..=l.acceptance.1).contains(&l.hits);
            format!("{:.2}{}", l.rate, if ok { "" } else { " **miss**" })
        })
}

/// An SBC row against issue 57's bounds: χ² p ≥ 0.01; |mean z| ≤ 0.15 and sd in [0.9, 1.1]
/// with the hyper-parameters held, ≤ 0.25 and [0.8, 1.2] when they are estimated.
fn sbc_verdict(q: &bamudi_gate::coverage::RankSummary, held: bool) -> String {
    let (m_max, sd_lo, sd_hi) = if held {
        (0.15, 0.9, 1.1)
    } else {
        (0.25, 0.8, 1.2)
    };
    let mut fails = Vec::new();
    if q.uniformity_p < 0.01 {
        fails.push(format!("p {:.3} < 0.01", q.uniformity_p));
    }
    if let Some([m, sd]) = q.z_mean_sd {
        if m.abs() > m_max {
            fails.push(format!("|mean z| > {m_max}"));
        }
        if !(sd_lo..=sd_hi).contains(&sd) {
            fails.push(format!("z sd outside [{sd_lo}, {sd_hi}]"));
        }
    }
    if fails.is_empty() {
        "within".into()
    } else {
        format!("**outside**: {}", fails.join("; "))
    }
}

/// A panel row's θ against issue 57's bounds: every level's coverage in its acceptance
/// region, |mean z| ≤ 0.5, z sd in [0.75, 1.25]; an sd below says the interval is wider than
/// the fixed discrepancy needs (cautious), above that it is too narrow (overconfident).
fn panel_verdict(s: &ScenarioCoverage) -> String {
    let mut fails = Vec::new();
    for l in &s.theta_levels {
        if !(l.acceptance.0..=l.acceptance.1).contains(&l.hits) {
            let way = if l.rate > l.level { "wide" } else { "narrow" };
            fails.push(format!("{:.0} % {way}", 100.0 * l.level));
        }
    }
    let [m, sd] = s.z_mean_sd;
    if m.abs() > 0.5 {
        fails.push(format!("mean z {m:+.2}"));
    }
    if sd < 0.75 {
        fails.push(format!("z sd {sd:.2} (cautious)"));
    } else if sd > 1.25 {
        fails.push(format!("z sd {sd:.2} (overconfident)"));
    }
    if fails.is_empty() {
        "within".into()
    } else {
        format!("**outside**: {}", fails.join(", "))
    }
}

/// The median [smallest, largest] `P(M_0 | y)` over the replicates, `–` when not weighed.
fn probability_without(s: &ScenarioCoverage) -> String {
    let mut p: Vec<f64> = s
        .replicates
        .iter()
        .filter_map(|r| r.probability_without)
        .collect();
    if p.is_empty() {
        return "–".into();
    }
    p.sort_by(f64::total_cmp);
    // two decimals where they say something, else the order of magnitude
    let f = |v: f64| match v >= 0.01 {
        true => format!("{v:.2}"),
        false => format!("{v:.0e}"),
    };
    format!("{} [{}, {}]", f(p[p.len() / 2]), f(p[0]), f(p[p.len() - 1]))
}

fn nt(v: bamudi_gate::baselines::NormalTangential, p: usize) -> String {
    format!("{:.*} / {:.*}", p, v.normal, p, v.tangential)
}

fn render(out: &Path, all: &[Part]) -> Result<String> {
    let mut md = String::from(include_str!("validation_head.md"));
    md.push_str("\n## Part 1: self-consistency (SBC)\n\n");
    md.push_str(
        "| part | scenario | R | θ 50 / 90 / 95 % | quantity | χ² p | z mean / sd | against the bounds |\n|---|---|---|---|---|---|---|---|\n",
    );
    for part in all.iter().filter(|p| p.group == "sbc") {
        let Some(read) = read(&out.join(format!("{}.json", part.name)))? else {
            md.push_str(&format!("| {} | not run | | | | | | |\n", part.name));
            continue;
        };
        let name = label(&part.name, &read);
        let held = read.report.options.sbc.is_some_and(|o| o.hold);
        for s in &read.report.scenarios {
            for q in s.ranked.iter().flatten() {
                md.push_str(&format!(
                    "| {} | {} | {} | {} / {} / {} | {} | {:.3} | {} | {} |\n",
                    name,
                    s.name,
                    q.n,
                    level(s, 0.5),
                    level(s, 0.9),
                    level(s, 0.95),
                    q.quantity,
                    q.uniformity_p,
                    q.z_mean_sd
                        .map_or("–".into(), |[m, sd]| format!("{m:+.2} / {sd:.2}")),
                    sbc_verdict(q, held),
                ));
            }
        }
    }
    for (group, title) in [
        ("panel", "Part 2: a fixed, wrong discrepancy (quick size)"),
        (
            "paper-size",
            "Part 2 at the paper's size (500 experiments, 12-in mesh)",
        ),
        (
            "assumed-panel",
            "Part 2 with the discrepancy assumed (`presence = \"assumed\"`; quick size)",
        ),
        (
            "assumed-paper-size",
            "Part 2 with the discrepancy assumed, at the paper's size",
        ),
    ] {
        md.push_str(&format!("\n## {title}\n\n"));
        md.push_str("θ: coverage of the central intervals (**miss**: outside the 1 % binomial acceptance region), mean / sd of z = (posterior mean − θ*)/sd. Force (lbf/in, normal / tangential, medians over replicates): (b) the best calibration without a discrepancy, (c) the default's corrected force, (g) the floor for this θ posterior; δ̂ / δ the reconstructed discrepancy's RMSE over the true δ's RMS (its floor in brackets); bands: 95 % force band coverage and median half-width over the true δ's RMS; ρ⊥: the identified ρ's 95 % coverage; P(no δ): the median [smallest, largest] posterior probability of no discrepancy over the replicates (`–`: not weighed).\n\n");
        md.push_str("| shape | scenario | R | θ 50 / 90 / 95 % | θ z mean / sd | (b) | (c) | (g) | (c)/(b) | δ̂ / δ [floor] | band coverage | half-width / δ | ρ⊥ 95 % | P(no δ) | θ against the bounds |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for part in all.iter().filter(|p| p.group == group) {
            let Some(read) = read(&out.join(format!("{}.json", part.name)))? else {
                md.push_str(&format!(
                    "| {} | not run | | | | | | | | | | | | | |\n",
                    part.name
                ));
                continue;
            };
            let short = part
                .name
                .trim_start_matches("assumed-")
                .trim_start_matches("panel-")
                .trim_start_matches("paper-size-");
            let name = label(short, &read);
            for s in &read.report.scenarios {
                let c: Option<&CorrectionSummary> = s.correction.as_ref();
                let cell = |f: &dyn Fn(&CorrectionSummary) -> String| c.map_or("–".into(), f);
                md.push_str(&format!(
                    "| {} | {} | {} | {} / {} / {} | {:+.2} / {:.2} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    name,
                    s.name,
                    s.n_replicates,
                    level(s, 0.5),
                    level(s, 0.9),
                    level(s, 0.95),
                    s.z_mean_sd[0],
                    s.z_mean_sd[1],
                    cell(&|c| nt(c.baselines.no_discrepancy, 0)),
                    cell(&|c| nt(c.baselines.calibrated, 0)),
                    cell(&|c| nt(c.baselines.oracle_seen_posterior, 0)),
                    cell(&|c| nt(c.vs_no_discrepancy, 2)),
                    cell(&|c| format!(
                        "{} [{}]",
                        nt(c.delta_ratio, 2),
                        nt(c.delta_floor_ratio, 2)
                    )),
                    nt(bamudi_gate::baselines::NormalTangential {
                        normal: s.force_band_coverage_95.normal,
                        tangential: s.force_band_coverage_95.tangential,
                    }, 3),
                    cell(&|c| nt(c.halfwidth_over_delta, 1)),
                    cell(&|c| c
                        .rho_projection
                        .as_ref()
                        .map_or("–".into(), |r| format!("{:.2}", r.coverage_95.rate))),
                    probability_without(s),
                    panel_verdict(s),
                ));
            }
        }
    }
    md.push_str("\nEach part's full report: `cargo xtask coverage --render docs/results/validation/<part>.json`.\n");
    Ok(md)
}
