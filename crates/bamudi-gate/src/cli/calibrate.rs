//! `bamudi calibrate`: TOML configuration + CSV experiments -> results directory.
use super::{GateArgs, build_gate, gate_source};
use anyhow::{Context, Result};
use bamudi::{Calibration, CalibrationConfig};
use bamudi_gate::output::StagedDir;
use bamudi_gate::progress::Bars;
use bamudi_gate::report::calibration::ReportInputs;
use bamudi_gate::session::GateSource;
use bamudi_gate::session::{self, CalibrateSpec, experiments_from_table, posterior_warnings};
use std::path::{Path, PathBuf};

/// Arguments of `calibrate`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// TOML file: `gap_prior = [lo, hi]` (in), optional `discrepancy_terms = [6, 6]`, and a
    /// `[calibration]` table with any `CalibrationParams` keys (missing keys take defaults).
    #[arg(long)]
    pub config: PathBuf,
    /// CSV of experiments: `h_up`, `h_down` (in) and one column per gauge (microstrain),
    /// named like the gate's gauges.
    #[arg(long)]
    pub data: PathBuf,
    /// Results directory (created): `calibration.json`, `model.json`, `results.json`,
    /// `report.md` and SVG plots. Written under a temporary name and renamed when complete;
    /// an existing non-empty directory is refused unless `--force` is given.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing non-empty `--out` directory (only once the new results are
    /// complete: a failed run leaves the old one untouched).
    #[arg(long)]
    pub force: bool,
}

/// Reads and checks the `calibrate` configuration file; errors name the file and the key.
pub fn read_spec(path: &Path) -> Result<CalibrateSpec> {
    let text = session::read_input_text("--config", path)?;
    Ok(CalibrateSpec::from_toml_str(
        &text,
        &path.display().to_string(),
    )?)
}

/// Runs `calibrate`: every input and the destination are checked before the gate is built.
pub fn run(a: &CalibrateArgs, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    let spec = read_spec(&a.config)?;
    let config: CalibrationConfig = spec.config(seed)?;
    let source = gate_source(gate)?;
    let label = a.config.display().to_string();
    if let GateSource::Config(cfg) = &source {
        spec.check_quoin_height(&label, cfg.geometry.quoin_height)?;
        spec.check_tolerances(&label, cfg)?;
    } else if !spec.tolerances.is_empty() {
        anyhow::bail!("{label}: `tolerances` need a gate configuration, not an imported deck");
    }
    session::check_input_file("--data", &a.data)?;
    let table = bamudi::data::Table::read(&a.data)
        .with_context(|| format!("--data {}", a.data.display()))?;
    let out = StagedDir::prepare("--out", &a.out, a.force)?;
    let built = build_gate(&source)?;
    let saved = spec.saved_model(&label, built.config, built.contact)?;
    let model = spec
        .calibration_model(&saved, 50_000, &label)
        .with_context(|| format!("{label}: `gap_prior`, `discrepancy_terms` or `tolerances`"))?;
    let exps = experiments_from_table(&table, &model)?;
    eprintln!(
        "calibrating on {} experiments of {} ({} gauges), gap prior U({}, {}) in",
        exps.len(),
        a.data.display(),
        exps.y.ncols(),
        saved.gap_prior.0,
        saved.gap_prior.1
    );
    let bars = Bars::new();
    let cal = session::calibrate(&model, &exps, &config, &bars)?;
    let key = format!("{label}: `gap_prior`");
    let warnings = session::warning_lines(&posterior_warnings(&cal, saved.gap_prior), &key);
    for w in &warnings {
        log::warn!("{w}");
    }
    cal.save(&out.path().join("calibration.json"))?;
    saved.save(&out.path().join("model.json"))?;
    let inputs = ReportInputs {
        config: a.config.display().to_string(),
        data: a.data.display().to_string(),
        gate: gate.label(),
        element_size_in: built.element_size,
        gap_prior_in: saved.gap_prior,
        seed: config.seed,
        theta_true: None,
        warnings,
    };
    bamudi_gate::report::calibration::write_report(
        &cal,
        model.prior.as_ref(),
        &inputs,
        out.path(),
    )?;
    let dir = out.commit()?;
    print_summary(&cal, &dir);
    Ok(())
}

fn print_summary(cal: &Calibration, dir: &Path) {
    let p = &cal.module3().posterior;
    let ci = p.ci95()[0];
    println!(
        "gap θ: mean {:.2} in, sd {:.2} in, 95 % CI [{:.2}, {:.2}] in",
        p.mean()[0],
        p.sd()[0],
        ci.0,
        ci.1
    );
    if let Some(a) = cal.module3().averaged() {
        println!(
            "discrepancy: probability {:.3} that the gauges hold none the model lacks (evidence \
             with {:.1}, without {:.1} nats, {:.1} charged for its fitted hyper-parameters)",
            a.probability_without, a.log_evidence_with, a.log_evidence_without, a.penalty
        );
    }
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
    for t in cal
        .module3()
        .marginal()
        .into_iter()
        .flat_map(|m| &m.tolerances)
    {
        println!(
            "tolerance {}: {:+.2} ± {:.2} sd (prior N(0, 1), integrated out)",
            t.name, t.mean, t.sd
        );
    }
    if let Some(a) = cal.adequacy() {
        let written = match a.verdict {
            bamudi::Verdict::Inadequate => " (results written; see report.md)",
            _ => "",
        };
        println!("adequacy: {}{written}", a.summary());
    }
    let t = cal.timings();
    println!(
        "timings (s): training set {:.1}, estimator {:.1}, rho {:.1}, GPs {:.1}, coefficients {:.1}, Module 3 {:.1}, adequacy {:.1}",
        t.training_set_s,
        t.estimator_s,
        t.rho_s,
        t.gp_s,
        t.coefficients_s,
        t.module3_s,
        t.adequacy_s
    );
    println!("results in {}", dir.display());
}
