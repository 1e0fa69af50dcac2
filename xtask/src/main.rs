//! Developer tasks for the bamudi workspace (`cargo xtask <task>`, run in release mode).
//!
//! * `reproduce-paper [--quick] [--json PATH] [--out DIR] [--seed N] [--level-variance C]`:
//!   both scenarios of the paper's Table 1 on the embedded default gate; writes
//!   `docs/results/reproduce-paper.md` and plots.
//! * `coverage [--quick] [--estimator exact|lstm|ridge] [--replicates N] [--experiments N]
//!   [--mesh IN] [--modes LIST] [--threads N] [--seed N] [--json PATH] [--out DIR]`: the
//!   coverage study of the θ intervals and force bands; writes `docs/results/coverage*.md`.
//! * `adequacy [--seeds N] [--clean-seeds N] [--scenarios LIST] [--experiments N] [--mesh IN]
//!   [--seed N] [--only TEXT] [--level-variance C] [--json PATH] [--out DIR]`: the adequacy
//!   verdict over a matrix of as-built gates and sensor faults, and its false-alarm rate on
//!   clean data; writes `docs/results/adequacy.md`.
//! * `calculix-check [--element-size IN] [--dir DIR] [--ccx PATH] [--equation] [--report PATH]`:
//!   exports the default gate to CalculiX, runs `ccx` and compares gauge strains and
//!   displacements (needs `ccx` on PATH; see docs/verification.md).
//! * `bench [--filter TEXT] [--no-anchors] [--python PATH] [--anchors DIR] [--profile]
//!   [--profile-paper] [--out PATH]`: criterion benchmarks and the Python peers in one run, as
//!   ratios in `docs/benchmarks.md` (and a profile of the quick reproduction with `--profile`,
//!   of the paper-size one with `--profile-paper`).
//! * `closeloop-panel [--kinds LIST] [--magnitudes LIST] [--onsets LIST] [--seeds N]
//!   [--clean N] [--mesh IN] [--step-minutes M] [--draws N] [--out PATH] [--json PATH]`: the
//!   close loop on records with undeclared effects and on clean records; writes
//!   `docs/results/closeloop-panel.md` and `.json`.
//! * `closeloop-panel-summary --json A,B,... [--out PATH]`: several panels side by side and
//!   pooled (`docs/results/closeloop-panel-summary.md`).

mod adequacy;
mod bench;
mod calculix;
mod closeloop_panel;
mod coverage;
mod plots;
mod validation;

use anyhow::{Context, Result};
use bamudi_gate::paper::{self, ReproduceOptions};
use bamudi_gate::progress::Bars;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "xtask", about = "bamudi developer tasks")]
struct Cli {
    #[command(subcommand)]
    task: Task,
}

#[derive(Subcommand)]
enum Task {
    /// Reproduce the paper's case study (Sec. 4.3, Table 1, Fig. 13-22) end to end.
    ReproducePaper(ReproduceArgs),
    /// The coverage study: do the θ intervals and force bands hold the truth as often as they
    /// claim? (simulation-based calibration over replicate data sets)
    Coverage(coverage::CoverageArgs),
    /// The two-part validation protocol (SBC with the discrepancy drawn from the prior; a panel
    /// of fixed, wrong discrepancies), resumable part by part; writes
    /// docs/results/validation.md.
    Validation(validation::ValidationArgs),
    /// The adequacy verdict over realities that differ from the model (as-built gates, sensor
    /// faults) and its false-alarm rate on clean data.
    Adequacy(adequacy::AdequacyArgs),
    /// Benchmarks and the Python peers in one run, written as ratios to docs/benchmarks.md.
    Bench(bench::BenchArgs),
    /// The close loop on records with effects nobody declared (sensor, structural,
    /// operational, environmental), and on clean records; writes a markdown table and JSON.
    CloseloopPanel(closeloop_panel::PanelArgs),
    /// Several close-loop panels (one seed each) side by side and pooled, with Wilson
    /// intervals and counts by kind and magnitude.
    CloseloopPanelSummary(closeloop_panel::SummaryArgs),
    /// Cross-check the gate FE model against CalculiX (`ccx` must be installed).
    CalculixCheck {
        /// Mesh element size (in); the default 12 in mesh takes minutes in ccx.
        #[arg(long, default_value_t = 24.0)]
        element_size: f64,
        /// Working directory for the deck and the CalculiX results.
        #[arg(long, default_value = "target/calculix-check")]
        dir: PathBuf,
        /// CalculiX executable.
        #[arg(long, default_value = "ccx")]
        ccx: String,
        /// Write the miter roller as *EQUATION instead of *TRANSFORM.
        #[arg(long)]
        equation: bool,
        /// Also write the Markdown report to this file.
        #[arg(long)]
        report: Option<PathBuf>,
    },
}

/// The choices of `reproduce-paper`.
#[derive(clap::Args)]
struct ReproduceArgs {
    /// CI-sized run (coarser mesh, fewer experiments, exact linear estimator).
    #[arg(long)]
    quick: bool,
    /// Also write the numbers as JSON to this path.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Output directory for the report and plots.
    #[arg(long, default_value = "docs/results")]
    out: PathBuf,
    /// Master seed.
    #[arg(long, default_value_t = 2021)]
    seed: u64,
    /// Skip the sampling-rule sensitivity study.
    #[arg(long)]
    no_sensitivity: bool,
    /// Run the sensitivity study even with `--quick`.
    #[arg(long)]
    sensitivity: bool,
    /// The marginal mode's level variance of the discrepancy coefficient functions
    /// (`MarginalPrior::level_variance`; default the library's, 0).
    #[arg(long)]
    level_variance: Option<f64>,
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.task {
        Task::ReproducePaper(args) => reproduce(&args),
        Task::Coverage(args) => coverage::run(&args),
        Task::Validation(args) => validation::run(&args),
        Task::Adequacy(args) => adequacy::run(&args),
        Task::Bench(args) => bench::run(&args),
        Task::CloseloopPanel(args) => closeloop_panel::run(&args),
        Task::CloseloopPanelSummary(args) => closeloop_panel::summary(&args),
        Task::CalculixCheck {
            element_size,
            dir,
            ccx,
            equation,
            report,
        } => calculix::run(&calculix::CalculixCheck {
            element_size,
            work_dir: dir,
            ccx,
            equation,
            report,
        }),
    }
}

fn reproduce(a: &ReproduceArgs) -> Result<()> {
    let mut opts = if a.quick {
        ReproduceOptions::quick()
    } else {
        ReproduceOptions::paper()
    };
    opts.seed = a.seed;
    if let Some(c) = a.level_variance {
        opts.marginal_prior.level_variance = c;
    }
    opts.sensitivity = (opts.sensitivity || a.sensitivity) && !a.no_sensitivity;
    opts.progress = std::env::var_os("CI").is_none();
    let out = &a.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    bamudi_gate::progress::init_logging(false);
    let bars = if opts.progress {
        Bars::new()
    } else {
        Bars::hidden()
    };
    let report = paper::reproduce(&opts, &bars, |res, cal, model| {
        let (t, mode) = match &res.marginal {
            Some(m) => (&m.theta_posterior, "default mode"),
            None => (&res.theta_posterior, "paper's Module 3"),
        };
        eprintln!(
            "{} ({mode}): gap θ = {:.2} ± {:.2} in, 95 % [{:.2}, {:.2}] (truth {}){}",
            res.name,
            t.mean,
            t.sd,
            t.ci95.0,
            t.ci95.1,
            res.theta_true,
            res.marginal
                .as_ref()
                .and_then(|m| m.baselines)
                .map_or(String::new(), |b| format!(
                    "; normal force RMSE {:.1} lbf/in against {:.1} without a discrepancy",
                    b.calibrated.normal, b.no_discrepancy.normal
                ))
        );
        eprintln!(
            "{} (paper's Module 3, as published): θ = {:.2} ± {:.2} in, ρ* = {:.3}",
            res.name, res.theta_posterior.mean, res.theta_posterior.sd, res.rho_star
        );
        plots::scenario_plots(out, res, cal, model, &opts).map_err(|e| {
            bamudi_gate::GateAppError::Engine(bamudi::BamudiError::Calibration(format!(
                "plots: {e:#}"
            )))
        })
    })?;
    let md = report.markdown();
    println!("{md}");
    let md_path = out.join(if a.quick {
        "reproduce-paper-quick.md"
    } else {
        "reproduce-paper.md"
    });
    bamudi::data::write_atomic(&md_path, md.as_bytes())?;
    if let Some(path) = &a.json {
        bamudi::data::write_atomic(path, report.to_json()?.as_bytes())?;
    }
    eprintln!("wrote {}", md_path.display());
    Ok(())
}
