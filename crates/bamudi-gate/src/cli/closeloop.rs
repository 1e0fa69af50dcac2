//! `bamudi close-loop`: the close-the-loop workflow on a field record with the BA-MUDI
//! calibrator of the gate.
use super::{GateArgs, build_gate, gate_source};
use anyhow::{Context, Result};
use bamudi::observe::Observer;
use bamudi::{CalibrationConfig, ModeKind};
use bamudi_closeloop::{
    CloseLoopConfig, CloseLoopOutcome, CloseLoopReport, MeasuredRecord, MissingPolicy, close_loop,
};
use bamudi_gate::calibrator::{CalibratedGate, GateCalibrator};
use bamudi_gate::gate;
use bamudi_gate::output::StagedDir;
use bamudi_gate::progress::Bars;
use bamudi_gate::record_fatigue::{self, RecordFatigue, RecordFatigueOptions, record_fatigue};
use bamudi_gate::report::calibration::ReportInputs;
use bamudi_gate::session::{self, GateSource};
use bamudi_gate::tolerance::{ToleranceSpec, check_tolerance_keys, check_tolerance_specs};
use mitergate::{QuoinBlockModel, QuoinBlockParams};
use mlmodel::UnobservableModel;
use std::path::PathBuf;
use std::sync::Arc;

/// Arguments of `close-loop`.
#[derive(Debug, clap::Args)]
pub struct CloseLoopCmd {
    /// Measured CSV (`time`, `h_up`, `h_down`, gauge columns, covariates).
    #[arg(long)]
    data: PathBuf,
    /// Fraction of the record (the end, in time) after the calibration window: the
    /// validation window (rolling-origin selection) and the final test window; overrides
    /// `calibration_fraction` of the configuration (`1 - holdout_fraction`).
    #[arg(long, allow_negative_numbers = true)]
    holdout_fraction: Option<f64>,
    /// Fraction of the record at its end that selection never sees, where the before/after
    /// error is reported; overrides `test_fraction` of the configuration (default 0.2).
    #[arg(long, allow_negative_numbers = true)]
    test_fraction: Option<f64>,
    /// Optional TOML file with a close-loop configuration (missing keys take their defaults).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Impute missing gauge values by linear interpolation instead of dropping rows.
    #[arg(long)]
    impute: bool,
    /// Output directory (written under a temporary name and renamed when complete; an
    /// existing non-empty directory is refused unless `--force` is given).
    #[arg(long, default_value = "close-loop-out")]
    out: PathBuf,
    /// Replace an existing non-empty `--out` directory once the new report is complete.
    #[arg(long)]
    force: bool,
    /// Uniform prior of the gap θ (in), one value `lo,hi` (e.g. `--gap-prior 60,120`).
    // Two values are taken in so that the old form `--gap-prior 60 120` is refused by
    // `check_args` with the flag and the `lo,hi` form named, not by clap as a stray argument.
    #[arg(long, num_args = 1..=2, allow_negative_numbers = true, value_name = "LO,HI",
          default_value = "40,200")]
    gap_prior: Vec<String>,
    /// Maximum rows per BA-MUDI calibration (evenly thinned in time; the checks use all rows),
    /// at least 10.
    #[arg(long, default_value_t = 240, allow_negative_numbers = true,
          value_parser = clap::value_parser!(u32).range(10..=100_000))]
    max_experiments: u32,
    /// Gauge white-noise standard deviation (microstrain), used as the exact estimator's output
    /// noise; estimated from each calibration's rows (first differences) when not given.
    #[arg(long, allow_negative_numbers = true)]
    gauge_noise_sd: Option<f64>,
    /// Optional TOML calibration configuration (the keys of `[calibration]` in the
    /// `calibrate` file) for the BA-MUDI calibrations (default: exact linear estimator, 241 θ
    /// grid points, σ_ε estimated; its `sampling.noise_sd` is replaced by the gauge noise).
    #[arg(long)]
    calibration_config: Option<PathBuf>,
    /// Optional TOML file of declared build tolerances (`[[tolerances]]` with `key` and
    /// `relative_sd`, as in the `calibrate` configuration): every calibration of the loop
    /// integrates them out and its predictions carry the deviation the data read, so an
    /// as-built gate is not reported as a missing effect (marginal mode; a configured gate).
    #[arg(long)]
    tolerances: Option<PathBuf>,
}

/// The `--tolerances` file.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ToleranceFile {
    tolerances: Vec<ToleranceSpec>,
}

/// Checks the command's own arguments; returns the gap prior `(lo, hi)` (in).
fn check_args(c: &CloseLoopCmd) -> Result<(f64, f64)> {
    let (lo, hi) = gap_prior(&c.gap_prior)?;
    session::check_input_file("--data", &c.data)?;
    if let Some(sd) = c.gauge_noise_sd {
        anyhow::ensure!(
            sd.is_finite() && sd > 0.0,
            "--gauge-noise-sd must be a positive number of microstrain, got {sd}"
        );
    }
    Ok((lo, hi))
}

/// The `--gap-prior` value `lo,hi` (in), with 0 <= lo < hi; the message names the flag, the
/// form and what it got.
fn gap_prior(values: &[String]) -> Result<(f64, f64)> {
    let [value] = values else {
        anyhow::bail!(
            "--gap-prior takes one value `lo,hi` (comma-separated, no space: \
             `--gap-prior {}`), got {} values `{}`",
            values.join(","),
            values.len(),
            values.join(" ")
        )
    };
    let numbers = value
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .map_err(|_| anyhow::anyhow!("--gap-prior {value}: `{t}` is not a number"))
        })
        .collect::<Result<Vec<f64>>>()?;
    let [lo, hi] = numbers[..] else {
        anyhow::bail!(
            "--gap-prior must be two numbers `lo,hi` (in), got {} in `{value}`",
            numbers.len()
        )
    };
    anyhow::ensure!(
        lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi,
        "--gap-prior must be lo,hi with 0 <= lo < hi (in), got {lo},{hi}"
    );
    Ok((lo, hi))
}

/// Runs `close-loop`.
pub fn run(c: &CloseLoopCmd, gate_args: &GateArgs, seed: Option<u64>) -> Result<()> {
    let (lo, hi) = check_args(c)?;
    let cfg = loop_config(c)?;
    let cal_cfg = calibration_config(c)?;
    let source = gate_source(gate_args)?;
    let tolerances = read_tolerances(c, &source, cal_cfg.as_ref())?;
    if let GateSource::Config(cfg) = &source {
        check_prior_below(lo, hi, cfg.geometry.quoin_height)?;
    }
    let staged = StagedDir::prepare("--out", &c.out, c.force)?;
    let built = build_gate(&source)?;
    let contact = built.contact;
    check_prior_below(lo, hi, contact.gate().quoin_height)?;
    let bars: Arc<dyn Observer + Send + Sync> = Arc::new(Bars::new());
    let mut calibrator = calibrator(c, cal_cfg, contact, (lo, hi), seed)?;
    if let (Some(drawing), Some(file), false) = (
        built.config.as_ref(),
        c.tolerances.as_ref(),
        tolerances.is_empty(),
    ) {
        calibrator = calibrator
            .tolerances(&tolerances, drawing)
            .with_context(|| format!("--tolerances {}", file.display()))?;
    }
    let calibrator = calibrator.observer(bars);
    let model = calibrator.model();
    let mut ingest = gate::ingest_config(model);
    if c.impute {
        ingest.missing = MissingPolicy::Interpolate;
    }
    let rec = session::read_record(&c.data, model, &ingest)?;
    let cfg = gate::close_loop_config(cfg, &rec);
    let out = close_loop(&rec, &calibrator, &cfg)?;
    let warnings = session::close_loop_warnings(&out, &format!("--gap-prior {lo},{hi}"));
    for w in &warnings {
        log::warn!("{w}");
    }
    let inputs = ReportInputs {
        config: c
            .config
            .as_ref()
            .map_or("close-loop defaults".into(), |p| p.display().to_string()),
        data: c.data.display().to_string(),
        gate: gate_args.label(),
        element_size_in: built.element_size,
        gap_prior_in: (lo, hi),
        seed: calibrator.calibration_config().seed,
        theta_true: None,
        warnings,
    };
    let fatigue = loop_fatigue(&out, &rec, calibrator.calibration_config().seed)?;
    let files = bamudi_gate::report::closeloop::write_report(
        &out,
        Some(&inputs),
        Some(&fatigue),
        staged.path(),
    )?;
    let dir = staged.commit()?;
    for f in files {
        if let Some(name) = f.file_name() {
            eprintln!("wrote {}", dir.join(name).display());
        }
    }
    print_summary(&out.report);
    println!("{}", record_fatigue::summary(&fatigue));
    println!("report in {}", dir.display());
    Ok(())
}

/// The gap prior's upper bound must lie below the quoin height `top` (in).
fn check_prior_below(lo: f64, hi: f64, top: f64) -> Result<()> {
    anyhow::ensure!(
        hi < top,
        "--gap-prior {lo},{hi}: the upper bound must lie below the quoin height {top} in"
    );
    Ok(())
}

/// The quoin block's fatigue over the whole record with the loop's final calibration.
fn loop_fatigue(out: &CloseLoopOutcome, rec: &MeasuredRecord, seed: u64) -> Result<RecordFatigue> {
    let any: &dyn std::any::Any = out.model.as_ref();
    let gate = any
        .downcast_ref::<CalibratedGate>()
        .context("the close loop's final model is not a gate calibration")?;
    let model = gate.model();
    let block = QuoinBlockModel::new(
        QuoinBlockParams::default(),
        model.unobservable.coordinates().to_vec(),
    )?;
    let history = record_fatigue::load_history(rec)?;
    let opts = RecordFatigueOptions {
        seed,
        ..RecordFatigueOptions::default()
    };
    record_fatigue(model, gate.calibration(), &block, &history, None, opts)
        .context("the quoin block's fatigue over the record")
}

/// The loop's settings: the configuration file (or the defaults) and the hold-out override
/// (the gate's load, parameter, units and the record's column units are added once the record
/// is read).
fn loop_config(c: &CloseLoopCmd) -> Result<CloseLoopConfig> {
    let cfg: CloseLoopConfig = match &c.config {
        Some(p) => {
            let text = session::read_input_text("--config", p)?;
            let cfg: CloseLoopConfig = toml::from_str(&text)
                .with_context(|| format!("--config: parsing {}", p.display()))?;
            cfg.validate()
                .with_context(|| format!("--config {}", p.display()))?;
            cfg
        }
        None => CloseLoopConfig::default(),
    };
    let cfg = match c.holdout_fraction {
        Some(h) => {
            anyhow::ensure!(
                h.is_finite() && h > 0.0 && h < 1.0,
                "--holdout-fraction must be in (0, 1), got {h}"
            );
            cfg.calibration_fraction(1.0 - h)
        }
        None => cfg,
    };
    let cfg = match c.test_fraction {
        Some(t) => cfg.test_fraction(t),
        None => cfg,
    };
    cfg.validate()?;
    Ok(cfg)
}

/// The `--calibration-config` file, read and checked.
fn calibration_config(c: &CloseLoopCmd) -> Result<Option<CalibrationConfig>> {
    let Some(p) = &c.calibration_config else {
        return Ok(None);
    };
    let text = session::read_input_text("--calibration-config", p)?;
    let cfg = CalibrationConfig::from_toml_str(&text)
        .with_context(|| format!("--calibration-config {}", p.display()))?;
    Ok(Some(cfg))
}

/// The `--tolerances` file, read and checked before the gate is built: the relative sds,
/// no key twice, the marginal mode of `cal_cfg` (the loop's default), and each key against a
/// configured gate (`source`; an imported deck has nothing to vary).
fn read_tolerances(
    c: &CloseLoopCmd,
    source: &GateSource,
    cal_cfg: Option<&CalibrationConfig>,
) -> Result<Vec<ToleranceSpec>> {
    let Some(p) = &c.tolerances else {
        return Ok(Vec::new());
    };
    let label = format!("--tolerances {}", p.display());
    let text = session::read_input_text("--tolerances", p)?;
    let file: ToleranceFile = toml::from_str(&text).with_context(|| label.clone())?;
    let mode = cal_cfg.map_or(ModeKind::Marginal, |c| c.coefficients.kind());
    check_tolerance_specs(&file.tolerances, mode, &label)?;
    match source {
        GateSource::Config(gate) => check_tolerance_keys(&file.tolerances, gate, &label)?,
        GateSource::Deck { .. } if !file.tolerances.is_empty() => anyhow::bail!(
            "{label}: tolerances need a gate configuration, not an imported deck (--gate-inp)"
        ),
        GateSource::Deck { .. } => {}
    }
    Ok(file.tolerances)
}

/// The gate calibrator with the command's settings.
fn calibrator(
    c: &CloseLoopCmd,
    config: Option<CalibrationConfig>,
    contact: mitergate::ContactModel,
    prior: (f64, f64),
    seed: Option<u64>,
) -> Result<GateCalibrator> {
    let (max, sd) = (c.max_experiments as usize, c.gauge_noise_sd);
    bamudi_gate::session::gate_calibrator(contact, prior, max, sd, config, seed)
        .context("setting up the close loop's calibrator")
}

fn print_summary(report: &CloseLoopReport) {
    println!("{}", report.conclusion);
    println!(
        "RMSE on the {} window {:.3} -> {:.3} microstrain; gap {:.2} ± {:.2} -> {:.2} ± {:.2} in",
        report.error_window,
        report.heldout_rmse_total_before,
        report.heldout_rmse_total_after,
        report.theta_before.mean,
        report.theta_before.sd,
        report.theta_after.mean,
        report.theta_after.sd
    );
    for e in &report.effects {
        println!("effect: {} ({})", e.name, e.covariates.join(", "));
    }
}
