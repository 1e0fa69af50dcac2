//! `bamudi close-loop`: the close-the-loop workflow on a field record with the BA-MUDI
//! calibrator of the gate.
use super::{GateArgs, build_contact, gate_config};
use anyhow::{Context, Result};
use bamudi::CalibrationConfig;
use bamudi::closeloop::BamudiCalibrator;
use bamudi::closeloop::report::{CloseLoopArgs, run_close_loop_command};
use std::path::PathBuf;

/// Arguments of `close-loop`.
#[derive(Debug, clap::Args)]
pub struct CloseLoopCmd {
    #[command(flatten)]
    args: CloseLoopArgs,
    /// Uniform prior of the gap θ (in), `lo,hi`.
    #[arg(long, value_delimiter = ',', num_args = 2, default_values_t = [40.0, 200.0])]
    gap_prior: Vec<f64>,
    /// Maximum rows per BA-MUDI calibration (evenly thinned in time; the checks use all rows).
    #[arg(long, default_value_t = 240)]
    max_experiments: usize,
    /// Gauge white-noise standard deviation (microstrain), used as the exact estimator's output
    /// noise; estimated from each calibration's rows (first differences) when not given.
    #[arg(long)]
    gauge_noise_sd: Option<f64>,
    /// Optional TOML `CalibrationConfig` for the BA-MUDI calibrations (default: exact linear
    /// estimator, 241 θ grid points, σ_ε estimated; its `sampling.noise_sd` is replaced by the
    /// gauge noise).
    #[arg(long)]
    calibration_config: Option<PathBuf>,
}

/// Runs `close-loop`.
pub fn run(c: &CloseLoopCmd, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    let (lo, hi) = (c.gap_prior[0], c.gap_prior[1]);
    anyhow::ensure!(
        lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi,
        "--gap-prior must be lo,hi with 0 <= lo < hi (in), got {lo},{hi}"
    );
    anyhow::ensure!(
        c.args.data.exists(),
        "--data {}: file does not exist",
        c.args.data.display()
    );
    let contact = build_contact(&gate_config(gate)?)?;
    let mut args = c.args.clone();
    if args.gauges.is_empty() {
        args.gauges = contact.gate().gauge_names.clone();
    }
    let mut calibrator =
        BamudiCalibrator::new(contact, (lo, hi))?.max_experiments(c.max_experiments);
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
        let cfg = calibrator.calibration_config().clone().seed(s);
        calibrator = calibrator.config(cfg);
    }
    let report = run_close_loop_command(&args, &calibrator)?;
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
    println!("report in {}", args.out.display());
    Ok(())
}
