//! `bamudi calibrate`: TOML configuration + CSV experiments -> results directory.
use super::{GateArgs, build_contact, create_dir, gate_config};
use anyhow::{Context, Result};
use bamudi::{Calibrate, CalibrationConfig, CalibrationParams, Experiments};
use bamudi_gate::gate::SavedModel;
use bamudi_gate::progress::Bars;
use mlmodel::ObservableModel;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Arguments of `calibrate`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// TOML file: `gap_prior = [lo, hi]` (in), optional `discrepancy_terms = [6, 6]`, and a
    /// `[calibration]` table with any `CalibrationConfig` keys (missing keys take defaults).
    #[arg(long)]
    pub config: PathBuf,
    /// CSV of experiments: `h_up`, `h_down` (in) and one column per gauge (microstrain),
    /// named like the gate's gauges.
    #[arg(long)]
    pub data: PathBuf,
    /// Results directory (created): `calibration.json`, `model.json`, `results.json`,
    /// `report.md` and SVG plots.
    #[arg(long)]
    pub out: PathBuf,
}

/// The `calibrate` configuration file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrateFile {
    /// Uniform prior of the gap θ (in).
    pub gap_prior: [f64; 2],
    /// Legendre terms of the discrepancy (normal, tangential); the paper's 6 + 6 by default.
    #[serde(default = "default_terms")]
    pub discrepancy_terms: [usize; 2],
    /// BA-MUDI settings.
    #[serde(default)]
    pub calibration: CalibrationParams,
}

fn default_terms() -> [usize; 2] {
    [6, 6]
}

impl CalibrateFile {
    /// Reads and validates the file; errors name the file and the key.
    pub fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let f: Self =
            toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        let [lo, hi] = f.gap_prior;
        anyhow::ensure!(
            lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi,
            "{}: `gap_prior` must be [lo, hi] with 0 <= lo < hi (in), got [{lo}, {hi}]",
            path.display()
        );
        anyhow::ensure!(
            f.discrepancy_terms.iter().all(|&t| t >= 1),
            "{}: `discrepancy_terms` must be at least 1 each, got {:?}",
            path.display(),
            f.discrepancy_terms
        );
        f.calibration
            .clone()
            .check()
            .with_context(|| format!("{}: in table [calibration]", path.display()))?;
        Ok(f)
    }
}

/// Runs `calibrate`.
pub fn run(a: &CalibrateArgs, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    let mut file = CalibrateFile::read(&a.config)?;
    if let Some(s) = seed {
        file.calibration.seed = s;
    }
    let config: CalibrationConfig = file.calibration.clone().check()?;
    let gate_cfg = gate_config(gate)?;
    anyhow::ensure!(
        a.data.exists(),
        "--data {}: file does not exist",
        a.data.display()
    );
    let contact = build_contact(&gate_cfg)?;
    let saved = SavedModel {
        gate: gate_cfg,
        contact,
        gap_prior: (file.gap_prior[0], file.gap_prior[1]),
        discrepancy_terms: file.discrepancy_terms,
    };
    let model = saved.multilevel(50_000)?;
    let outputs = model.observable.output_names();
    let outputs: Vec<&str> = outputs.iter().map(String::as_str).collect();
    let exps = Experiments::read_csv(&a.data, &["h_up", "h_down"], &outputs)?;
    eprintln!(
        "calibrating on {} experiments ({} gauges), gap prior U({}, {}) in",
        exps.len(),
        outputs.len(),
        saved.gap_prior.0,
        saved.gap_prior.1
    );
    let bars = Bars::new();
    let cal = Calibrate::new(&config).observer(&bars).run(&model, &exps)?;
    create_dir(&a.out)?;
    cal.save(&a.out.join("calibration.json"))?;
    saved.save(&a.out.join("model.json"))?;
    bamudi_gate::report::calibration::write_report(&cal, model.prior.as_ref(), &a.out)?;
    let p = &cal.module3().posterior;
    let ci = p.ci95()[0];
    println!(
        "gap θ: mean {:.2} in, sd {:.2} in, 95 % CI [{:.2}, {:.2}] in",
        p.mean()[0],
        p.sd()[0],
        ci.0,
        ci.1
    );
    println!(
        "rho* = {:.4}, sigma_eps = {:.3} microstrain ({})",
        cal.rho_star(),
        cal.sigma_eps(),
        if cal.module3().sigma_eps_estimated {
            "estimated"
        } else {
            "configured"
        }
    );
    let t = cal.timings();
    println!(
        "timings (s): training set {:.1}, estimator {:.1}, rho {:.1}, GPs {:.1}, coefficients {:.1}, Module 3 {:.1}",
        t.training_set_s, t.estimator_s, t.rho_s, t.gp_s, t.coefficients_s, t.module3_s
    );
    println!("results in {}", a.out.display());
    Ok(())
}
