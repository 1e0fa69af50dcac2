//! `bamudi close-loop`: the close-the-loop workflow on a field record with the BA-MUDI
//! calibrator of the gate.
use super::{GateArgs, build_contact, gate_config};
use anyhow::{Context, Result};
use bamudi::CalibrationConfig;
use bamudi::closeloop::{CloseLoopConfig, CloseLoopReport, MissingPolicy, close_loop};
use bamudi_gate::calibrator::GateCalibrator;
use bamudi_gate::gate;
use std::path::PathBuf;

/// Arguments of `close-loop`.
#[derive(Debug, clap::Args)]
pub struct CloseLoopCmd {
    /// Measured CSV (`time`, `h_up`, `h_down`, gauge columns, covariates).
    #[arg(long)]
    data: PathBuf,
    /// Fraction of the record (the end, in time) held out for the checks; overrides
    /// `calibration_fraction` of the configuration (`1 - holdout_fraction`).
    #[arg(long)]
    holdout_fraction: Option<f64>,
    /// Optional TOML file with a close-loop configuration (missing keys take their defaults).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Impute missing gauge values by linear interpolation instead of dropping rows.
    #[arg(long)]
    impute: bool,
    /// Output directory.
    #[arg(long, default_value = "close-loop-out")]
    out: PathBuf,
    /// Uniform prior of the gap θ (in), `lo,hi`.
    #[arg(long, value_delimiter = ',', default_values_t = [40.0, 200.0])]
    gap_prior: Vec<f64>,
    /// Maximum rows per BA-MUDI calibration (evenly thinned in time; the checks use all rows).
    #[arg(long, default_value_t = 240)]
    max_experiments: usize,
    /// Gauge white-noise standard deviation (microstrain), used as the exact estimator's output
    /// noise; estimated from each calibration's rows (first differences) when not given.
    #[arg(long)]
    gauge_noise_sd: Option<f64>,
    /// Optional TOML calibration configuration (the keys of `[calibration]` in the
    /// `calibrate` file) for the BA-MUDI calibrations (default: exact linear estimator, 241 θ
    /// grid points, σ_ε estimated; its `sampling.noise_sd` is replaced by the gauge noise).
    #[arg(long)]
    calibration_config: Option<PathBuf>,
}

/// Runs `close-loop`.
pub fn run(c: &CloseLoopCmd, gate_args: &GateArgs, seed: Option<u64>) -> Result<()> {
    anyhow::ensure!(
        c.gap_prior.len() == 2,
        "--gap-prior must be two numbers lo,hi (in), got {} value(s)",
        c.gap_prior.len()
    );
    let (lo, hi) = (c.gap_prior[0], c.gap_prior[1]);
    anyhow::ensure!(
        lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi,
        "--gap-prior must be lo,hi with 0 <= lo < hi (in), got {lo},{hi}"
    );
    anyhow::ensure!(
        c.data.exists(),
        "--data {}: file does not exist",
        c.data.display()
    );
    let cfg = loop_config(c)?;
    let contact = build_contact(&gate_config(gate_args)?)?;
    let calibrator = calibrator(c, contact, (lo, hi), seed)?;
    let model = calibrator.model();
    let mut ingest = gate::ingest_config(model);
    if c.impute {
        ingest.missing = MissingPolicy::Interpolate;
    }
    let rec = gate::read_record(&c.data, model, &ingest)?;
    let out = close_loop(&rec, &calibrator, &cfg)?;
    for f in bamudi_gate::report::closeloop::write_report(&out, &c.out)? {
        eprintln!("wrote {}", f.display());
    }
    print_summary(&out.report);
    println!("report in {}", c.out.display());
    Ok(())
}

/// The loop's settings: the configuration file (or the defaults), the hold-out override and
/// the gate's load, parameter and unit.
fn loop_config(c: &CloseLoopCmd) -> Result<CloseLoopConfig> {
    let cfg: CloseLoopConfig = match &c.config {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            toml::from_str(&text).with_context(|| format!("parsing {}", p.display()))?
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
    Ok(gate::close_loop_config(cfg))
}

/// The gate calibrator with the command's settings.
fn calibrator(
    c: &CloseLoopCmd,
    contact: mitergate::ContactModel,
    prior: (f64, f64),
    seed: Option<u64>,
) -> Result<GateCalibrator> {
    let mut calibrator = GateCalibrator::new(contact, prior)?.max_experiments(c.max_experiments);
    if let Some(p) = &c.calibration_config {
        let text =
            std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
        let cfg = CalibrationConfig::from_toml_str(&text)
            .with_context(|| format!("in {}", p.display()))?;
        calibrator = calibrator.config(cfg);
    }
    if let Some(sd) = c.gauge_noise_sd {
        calibrator = calibrator.gauge_noise_sd(sd).context("--gauge-noise-sd")?;
    }
    if let Some(s) = seed {
        let params = calibrator
            .calibration_config()
            .clone()
            .into_params()
            .seed(s);
        calibrator = calibrator.config(params.check()?);
    }
    Ok(calibrator)
}

fn print_summary(report: &CloseLoopReport) {
    println!("{}", report.conclusion);
    println!(
        "held-out RMSE {:.3} -> {:.3} microstrain; gap {:.2} ± {:.2} -> {:.2} ± {:.2} in",
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
