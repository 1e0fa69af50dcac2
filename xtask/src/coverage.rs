//! `cargo xtask coverage`: the coverage study of `bamudi_gate::coverage`, its markdown, JSON
//! and two SVG plots (coverage against the nominal level; SBC rank histograms).

use crate::plots::{line_plot, series};
use anyhow::{Context, Result, bail};
use bamudi::ModeKind;
use bamudi::surrogate::LstmSettings;
use bamudi_gate::coverage::{self, CoverageOptions, CoverageReport, LEVELS, RANK_BINS};
use bamudi_gate::report::plot::CATEGORICAL;
use indicatif::{ProgressBar, ProgressStyle};
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

/// The command line's choices.
#[derive(clap::Args)]
pub struct CoverageArgs {
    /// CI-sized study (40 replicates, 120 experiments, 24-in mesh, exact estimator, marginal mode).
    #[arg(long)]
    quick: bool,
    /// Coefficient estimator: exact, lstm (reduced size, see `lstm_reduced`) or ridge.
    #[arg(long, default_value = "exact")]
    estimator: String,
    /// Replicates per scenario.
    #[arg(long)]
    replicates: Option<usize>,
    /// Index of the first replicate (the study runs `N .. N + replicates`): split a long study
    /// or resume a stopped one, then merge the parts with `--render A.json,B.json`. Exact
    /// estimator only.
    #[arg(long, default_value_t = 0)]
    first_replicate: usize,
    /// Experiments per replicate.
    #[arg(long)]
    experiments: Option<usize>,
    /// Module-2 training-set size (learnt estimators).
    #[arg(long)]
    training_size: Option<usize>,
    /// Mesh element size (in).
    #[arg(long)]
    mesh: Option<f64>,
    /// Coefficient modes, comma separated: marginal, conditional_on_theta, prior_marginal.
    #[arg(long, value_delimiter = ',')]
    modes: Option<Vec<String>>,
    /// Scenarios, comma separated (1, 2).
    #[arg(long, value_delimiter = ',')]
    scenarios: Option<Vec<u8>>,
    /// Shape of the true discrepancy.
    #[arg(long, value_enum, default_value = "paper")]
    discrepancy: coverage::DiscrepancyShape,
    /// Multiply the discrepancy shape by this factor (`--discrepancy paper --discrepancy-scale
    /// 2`: twice the paper's).
    #[arg(long, default_value_t = 1.0)]
    discrepancy_scale: f64,
    /// A true discrepancy of your own instead of a shape: a table (`.csv`, columns
    /// `h_up,h_down,d_u,normal,tangential` on a full grid spanning the levels 24-744 in and the
    /// quoin) or coefficients (`.toml`, Legendre series times a load; see
    /// `bamudi_gate::coverage::DeltaFile`).
    #[arg(long)]
    discrepancy_file: Option<PathBuf>,
    /// Simulation-based calibration: draw θ, ρ and the discrepancy per replicate from the
    /// calibration's isotropic prior with these hyper-parameters, `AMPLITUDE,LENGTH_FACTOR,
    /// LEVEL_VARIANCE,NOISE_SD`, and calibrate with `--sbc-hold` (holding them) or without
    /// (estimating them as the product does). Needs `--scales isotropic`.
    #[arg(long, value_delimiter = ',')]
    sbc: Option<Vec<f64>>,
    /// With `--sbc`: hold the generating hyper-parameters in the calibration.
    #[arg(long)]
    sbc_hold: bool,
    /// Marginal mode: the coefficients' prior scales, isotropic, shared_per_component or
    /// per_coefficient.
    #[arg(long, default_value = "isotropic")]
    scales: String,
    /// Marginal mode: the coefficients' kernel, module2 or matern52.
    #[arg(long, default_value = "matern52")]
    coefficient_kernel: String,
    /// Marginal mode: keep the discrepancy where the model's response vanishes (the gap).
    #[arg(long)]
    no_support_mask: bool,
    /// Marginal mode: prior variance of each coefficient function's unknown level, relative
    /// to the process variance (0: a zero-mean prior).
    #[arg(long, default_value_t = bamudi::params::DEFAULT_LEVEL_VARIANCE)]
    level_variance: f64,
    /// Marginal mode: assumed (the model with a discrepancy is the answer) or weighed (the
    /// models with and without one weighed by their evidence, the answer their mixture).
    #[arg(long, default_value = "weighed")]
    presence: String,
    /// Prior range of ρ, `LO,HI` (the sampling rule's `rho_range`; default `0,1.2`). A narrow
    /// range around the truth's 0.8 tells how much of the θ error comes through ρ.
    #[arg(long, value_delimiter = ',')]
    rho_range: Option<Vec<f64>>,
    /// Worker threads (0: all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Master seed.
    #[arg(long, default_value_t = 2021)]
    seed: u64,
    /// Also write the report as JSON here. While the study runs, each finished replicate is
    /// appended as one JSON line to `PATH.partial.jsonl` (scenario, then one result per mode),
    /// so a long study can be read, or its finished part kept, before it ends; the log is
    /// removed once the report is written.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Re-render the markdown and plots of a saved `--json` report (no calibration runs); the
    /// outputs are named by `--out` and the tag of the other flags, as for a fresh run. Several
    /// paths, comma separated, merge parts of one study (`--first-replicate` runs, or the
    /// `.partial.jsonl` log of a stopped one, read under the first report's options) into one
    /// report, written to `--json` if given.
    #[arg(long, value_delimiter = ',')]
    render: Option<Vec<PathBuf>>,
    /// Output directory of the markdown and the plots.
    #[arg(long, default_value = "docs/results")]
    out: PathBuf,
}

/// The LSTM at the reduced size of the coverage study: the paper's architecture (hidden 64,
/// one layer, 10 steps) trained on 10,000 samples for at most 30 epochs.
fn lstm_reduced() -> LstmSettings {
    LstmSettings {
        hidden: 64,
        layers: 1,
        steps: 10,
        epochs: 30,
        batch_size: 256,
        learning_rate: 1e-3,
        validation_fraction: 0.1,
        patience: 10,
        ..Default::default()
    }
}

fn options(a: &CoverageArgs) -> Result<CoverageOptions> {
    let mut o = if a.quick {
        CoverageOptions::quick()
    } else {
        CoverageOptions::paper_exact()
    };
    o.estimator = match a.estimator.as_str() {
        "exact" | "exact_linear" => bamudi::EstimatorParams::ExactLinear,
        "lstm" => {
            o.training_size = 10_000;
            bamudi::EstimatorParams::Lstm(lstm_reduced())
        }
        "ridge" => bamudi::EstimatorParams::Ridge(bamudi::RidgeParams { lambda: 1e-3 }),
        other => bail!("--estimator {other}: expected exact, lstm or ridge"),
    };
    if let Some(modes) = &a.modes {
        o.modes = modes.iter().map(|m| parse_mode(m)).collect::<Result<_>>()?;
    }
    o.n_replicates = a.replicates.unwrap_or(o.n_replicates);
    o.first_replicate = a.first_replicate;
    o.n_experiments = a.experiments.unwrap_or(o.n_experiments);
    o.training_size = a.training_size.unwrap_or(o.training_size);
    o.mesh_element_size = a.mesh.or(o.mesh_element_size);
    o.scenarios = a.scenarios.clone().unwrap_or(o.scenarios);
    (o.threads, o.seed, o.discrepancy) = (a.threads, a.seed, a.discrepancy);
    o.discrepancy_scale = a.discrepancy_scale;
    o.discrepancy_file = a.discrepancy_file.clone();
    o.sbc = match a.sbc.as_deref() {
        None if a.sbc_hold => bail!("--sbc-hold needs --sbc"),
        None => None,
        Some(&[amplitude, length_scale_factor, level_variance, noise_sd]) => {
            Some(coverage::SbcOptions {
                hyper: coverage::GeneratingHyper {
                    amplitude,
                    length_scale_factor,
                    level_variance,
                    noise_sd,
                },
                hold: a.sbc_hold,
            })
        }
        Some(other) => {
            bail!("--sbc: expected AMPLITUDE,LENGTH_FACTOR,LEVEL_VARIANCE,NOISE_SD, got {other:?}")
        }
    };
    o.rho_range = match a.rho_range.as_deref() {
        None => None,
        Some(&[lo, hi]) => Some((lo, hi)),
        Some(other) => bail!("--rho-range: expected LO,HI, got {other:?}"),
    };
    o.marginal = bamudi::MarginalPrior {
        scales: serde_json::from_value(serde_json::Value::String(a.scales.clone())).with_context(
            || {
                format!(
                    "--scales {}: expected isotropic, shared_per_component or per_coefficient",
                    a.scales
                )
            },
        )?,
        mask_outside_support: !a.no_support_mask,
        kernel: serde_json::from_value(serde_json::Value::String(a.coefficient_kernel.clone()))
            .with_context(|| {
                format!(
                    "--coefficient-kernel {}: expected module2 or matern52",
                    a.coefficient_kernel
                )
            })?,
        level_variance: a.level_variance,
        fixed: None,
        presence: serde_json::from_value(serde_json::Value::String(a.presence.clone()))
            .with_context(|| format!("--presence {}: expected assumed or weighed", a.presence))?,
    };
    Ok(o)
}

fn parse_mode(m: &str) -> Result<ModeKind> {
    serde_json::from_value(serde_json::Value::String(m.trim().into())).with_context(|| {
        format!("--modes {m}: expected marginal, conditional_on_theta or prior_marginal")
    })
}

/// The running log of a study whose report goes to `json`.
pub(crate) fn log_path(json: &Path) -> PathBuf {
    LogWriter::path_for(json)
}

/// Runs the study (or reads a saved one) and writes `coverage[-tag].md`, `coverage[-tag].svg`,
/// `sbc[-tag].svg`.
pub fn run(a: &CoverageArgs) -> Result<()> {
    let opts = options(a)?;
    let report = match &a.render {
        Some(paths) => {
            let report = read_parts(paths)?;
            if let (Some(path), true) = (&a.json, paths.len() > 1) {
                bamudi::data::write_atomic(path, report.to_json()?.as_bytes())?;
            }
            report
        }
        None => study(&opts, a.json.as_deref())?,
    };
    let tag = tag(a, &report.options);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let md = report.markdown();
    println!("{md}");
    let md_path = a.out.join(format!("coverage{tag}.md"));
    bamudi::data::write_atomic(&md_path, md.as_bytes())?;
    coverage_plot(&a.out.join(format!("coverage{tag}.svg")), &report)?;
    rank_plot(&a.out.join(format!("sbc{tag}.svg")), &report)?;
    if let (Some(path), None) = (&a.json, &a.render) {
        bamudi::data::write_atomic(path, report.to_json()?.as_bytes())?;
        // every finished replicate is in the report now: the running log has done its job
        let log = LogWriter::path_for(path);
        if let Err(e) = std::fs::remove_file(&log)
            && e.kind() != std::io::ErrorKind::NotFound
        {
            eprintln!("warning: could not remove {}: {e}", log.display());
        }
    }
    eprintln!("wrote {}", md_path.display());
    Ok(())
}

/// A saved report, or the merge of several parts of one study (reports and replicate logs).
fn read_parts(paths: &[PathBuf]) -> Result<CoverageReport> {
    let (mut reports, mut logs) = (Vec::new(), Vec::new());
    for path in paths {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        if path.extension().is_some_and(|e| e == "jsonl") {
            let log = coverage::ReplicateLog::parse(&text, &path.display().to_string())?;
            if log.truncated {
                eprintln!(
                    "warning: {}: the last line is cut off (a study stopped while writing it) \
                     and is left out",
                    path.display()
                );
            }
            logs.push(log);
        } else {
            reports.push(
                serde_json::from_str::<CoverageReport>(&text)
                    .with_context(|| format!("parsing {}", path.display()))?,
            );
        }
    }
    if paths.len() == 1 && logs.is_empty() {
        return reports.pop().context("no report read");
    }
    Ok(CoverageReport::merge(&reports, logs)?)
}

pub(crate) fn study(opts: &CoverageOptions, json: Option<&Path>) -> Result<CoverageReport> {
    bamudi_gate::progress::init_logging(false);
    let total = (opts.n_replicates * opts.scenarios.len()) as u64;
    let bar = if std::env::var_os("CI").is_none() {
        ProgressBar::new(total)
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("replicates [{bar:40}] {pos}/{len} ({eta})") {
        bar.set_style(style);
    }
    let log = json.map(|j| LogWriter::create(j, opts)).transpose()?;
    let report = coverage::run(opts, &|number, reps| {
        bar.inc(1);
        if let Some(log) = &log {
            log.append(number, reps);
        }
    })?;
    bar.finish_and_clear();
    Ok(report)
}

/// `PATH.partial.jsonl`: the study's options, then one line per finished replicate, flushed
/// as it comes ([`coverage::ReplicateLog`] reads it back).
struct LogWriter {
    path: PathBuf,
    file: std::sync::Mutex<std::fs::File>,
}

impl LogWriter {
    /// `PATH.partial.jsonl` for the report's `PATH`.
    fn path_for(json: &Path) -> PathBuf {
        let mut name = json.as_os_str().to_owned();
        name.push(".partial.jsonl");
        PathBuf::from(name)
    }

    /// Refuses to overwrite a log: it may be the only record of a stopped study.
    fn create(json: &Path, opts: &CoverageOptions) -> Result<Self> {
        use std::io::Write;
        let path = Self::path_for(json);
        let mut file = std::fs::File::create_new(&path).with_context(|| {
            format!(
                "creating the replicate log {} (an existing log may hold a stopped study's \
                 replicates: merge it with --render, then move it away)",
                path.display()
            )
        })?;
        let header = coverage::LogHeader {
            options: opts.clone(),
        };
        writeln!(file, "{}", serde_json::to_string(&header)?)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("finished replicates go to {}", path.display());
        Ok(Self {
            path,
            file: std::sync::Mutex::new(file),
        })
    }

    /// A failed write is reported once per replicate and does not stop the study: the log is
    /// a convenience, the final report is written at the end either way.
    fn append(&self, scenario: u8, reps: &[coverage::Replicate]) {
        use std::io::Write;
        let line = coverage::LoggedReplicate {
            scenario,
            modes: reps.to_vec(),
        };
        let line = match serde_json::to_string(&line) {
            Ok(l) => l,
            Err(e) => {
                eprintln!(
                    "warning: could not encode a replicate for {}: {e}",
                    self.path.display()
                );
                return;
            }
        };
        let mut file = match self.file.lock() {
            Ok(f) => f,
            Err(poisoned) => poisoned.into_inner(),
        };
        if let Err(e) = writeln!(file, "{line}").and_then(|()| file.flush()) {
            eprintln!("warning: could not append to {}: {e}", self.path.display());
        }
    }
}

/// `-quick`, `-<estimator>`, `-<shape>`, `-prior-variant`, `-rho-range` as they apply.
fn tag(a: &CoverageArgs, o: &CoverageOptions) -> String {
    let mut tag = if a.quick {
        "-quick".to_string()
    } else {
        String::new()
    };
    if !matches!(a.estimator.as_str(), "exact" | "exact_linear") {
        tag.push_str(&format!("-{}", a.estimator));
    }
    if let Ok(serde_json::Value::String(shape)) = serde_json::to_value(o.discrepancy)
        && o.discrepancy != coverage::DiscrepancyShape::Paper
    {
        tag.push_str(&format!("-{shape}"));
    }
    if o.discrepancy_scale != 1.0 {
        tag.push_str(&format!("-x{}", o.discrepancy_scale));
    }
    if let Some(stem) = o.discrepancy_file.as_ref().and_then(|p| p.file_stem()) {
        tag.push_str(&format!("-file-{}", stem.to_string_lossy()));
    }
    if let Some(sbc) = &o.sbc {
        tag.push_str(if sbc.hold {
            "-sbc-held"
        } else {
            "-sbc-estimated"
        });
    }
    if o.marginal != bamudi::MarginalPrior::default() {
        tag.push_str("-prior-variant");
    }
    if o.rho_range.is_some() {
        tag.push_str("-rho-range");
    }
    tag
}

fn label(s: &coverage::ScenarioCoverage) -> String {
    format!("{}, {}", s.name, coverage::mode_label(s.mode))
}

/// Empirical coverage against the nominal level, with the diagonal.
fn coverage_plot(path: &Path, r: &CoverageReport) -> Result<()> {
    let mut all = vec![series(
        "nominal",
        RGBColor(0, 0, 0),
        &[0.5, 0.95],
        &[0.5, 0.95],
        true,
    )];
    for (i, s) in r.scenarios.iter().enumerate() {
        let rates: Vec<f64> = s.theta_levels.iter().map(|l| l.rate).collect();
        all.push(series(
            &label(s),
            CATEGORICAL[i % CATEGORICAL.len()],
            &LEVELS,
            &rates,
            false,
        ));
    }
    line_plot(
        path,
        "Coverage of the central θ intervals",
        "nominal level",
        "empirical coverage",
        &all,
    )
}

/// The SBC rank histograms as step lines (replicates per bin of the posterior CDF at θ*).
fn rank_plot(path: &Path, r: &CoverageReport) -> Result<()> {
    let mut all = Vec::new();
    for (i, s) in r.scenarios.iter().enumerate() {
        let (mut xs, mut ys) = (Vec::new(), Vec::new());
        for (b, c) in s.sbc_histogram.iter().enumerate() {
            xs.extend([
                b as f64 / RANK_BINS as f64,
                (b + 1) as f64 / RANK_BINS as f64,
            ]);
            ys.extend([*c as f64, *c as f64]);
        }
        all.push(series(
            &label(s),
            CATEGORICAL[i % CATEGORICAL.len()],
            &xs,
            &ys,
            false,
        ));
    }
    if let Some(s) = r.scenarios.first() {
        let expected = s.n_replicates as f64 / RANK_BINS as f64;
        all.push(series(
            "uniform",
            RGBColor(0, 0, 0),
            &[0.0, 1.0],
            &[expected, expected],
            true,
        ));
    }
    line_plot(
        path,
        "SBC rank histograms",
        "posterior CDF at θ*",
        "replicates",
        &all,
    )
}
