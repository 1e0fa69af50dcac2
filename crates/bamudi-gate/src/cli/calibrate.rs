//! `bamudi calibrate`: TOML configuration + CSV experiments -> results directory.
use super::{GateArgs, build_contact, gate_config};
use anyhow::{Context, Result};
use bamudi::data::Table;
use bamudi::module3::posterior::{GridWarning, ThetaPosterior};
use bamudi::{Calibrate, Calibration, CalibrationConfig, CalibrationParams, Experiments};
use bamudi_gate::gate::SavedModel;
use bamudi_gate::output::StagedDir;
use bamudi_gate::progress::Bars;
use bamudi_gate::report::calibration::ReportInputs;
use mitergate::GateMultiLevel;
use mlmodel::{ObservableModel, UnobservableModel};
use serde::Deserialize;
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

/// Most Legendre terms per discrepancy component: the gate has about 30 representation
/// points along the quoin, and the prior-scale fit of higher orders is not identifiable from
/// 7 gauges anyway.
pub const MAX_DISCREPANCY_TERMS: usize = 20;

/// Fewest experiments with distinct water levels: the coefficient GPs of Eq. 33-37 fit a
/// length scale per input, an amplitude and a noise level per coefficient; fewer distinct
/// conditions cannot identify them.
pub const MIN_DISTINCT_EXPERIMENTS: usize = 10;

/// The `calibrate` configuration file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrateFile {
    /// Uniform prior of the gap θ (in): exactly two numbers `[lo, hi]`.
    pub gap_prior: Vec<f64>,
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
    /// The gap prior `(lo, hi)` (in), checked by [`read`](Self::read).
    pub fn prior(&self) -> (f64, f64) {
        (self.gap_prior[0], self.gap_prior[1])
    }

    /// Reads and validates the file; errors name the file and the key.
    pub fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let f: Self =
            toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        let ok = match f.gap_prior[..] {
            [lo, hi] => lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi,
            _ => false,
        };
        anyhow::ensure!(
            ok,
            "{}: `gap_prior` must be two numbers [lo, hi] with 0 <= lo < hi (in), got {:?}",
            path.display(),
            f.gap_prior
        );
        anyhow::ensure!(
            f.discrepancy_terms
                .iter()
                .all(|t| (1..=MAX_DISCREPANCY_TERMS).contains(t)),
            "{}: `discrepancy_terms` must be in [1, {MAX_DISCREPANCY_TERMS}] each, got {:?}",
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

/// Runs `calibrate`: every input and the destination are checked before the gate is built.
pub fn run(a: &CalibrateArgs, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    let mut file = CalibrateFile::read(&a.config)?;
    if let Some(s) = seed {
        file.calibration.seed = s;
    }
    let config: CalibrationConfig = file.calibration.clone().check()?;
    let gate_cfg = gate_config(gate)?;
    let top = gate_cfg.geometry.quoin_height;
    anyhow::ensure!(
        file.prior().1 < top,
        "{}: `gap_prior` upper bound {} in must lie below the quoin height {top} in",
        a.config.display(),
        file.prior().1
    );
    let table = bamudi::data::Table::read(&a.data)
        .with_context(|| format!("--data {}", a.data.display()))?;
    let out = StagedDir::prepare("--out", &a.out, a.force)?;
    let contact = build_contact(&gate_cfg)?;
    let saved = SavedModel {
        gate: gate_cfg,
        contact,
        gap_prior: file.prior(),
        discrepancy_terms: file.discrepancy_terms,
    };
    let model = saved
        .multilevel(50_000)
        .with_context(|| format!("{}: `gap_prior` or `discrepancy_terms`", a.config.display()))?;
    let exps = read_experiments(&table, &model)?;
    eprintln!(
        "calibrating on {} experiments of {} ({} gauges), gap prior U({}, {}) in",
        exps.len(),
        a.data.display(),
        exps.y.ncols(),
        saved.gap_prior.0,
        saved.gap_prior.1
    );
    let bars = Bars::new();
    let mut cal = Calibrate::new(&config).observer(&bars).run(&model, &exps)?;
    bamudi_gate::physics::add_physics_checks(&mut cal, &model, &exps, &config)?;
    let warnings = posterior_warnings(&cal, saved.gap_prior);
    for w in &warnings {
        log::warn!("{w}");
    }
    cal.save(&out.path().join("calibration.json"))?;
    saved.save(&out.path().join("model.json"))?;
    let inputs = ReportInputs {
        config: a.config.display().to_string(),
        data: a.data.display().to_string(),
        gate: gate
            .gate
            .as_ref()
            .map_or("embedded default gate".into(), |g| g.display().to_string()),
        element_size_in: saved.gate.mesh.element_size,
        gap_prior_in: saved.gap_prior,
        seed: config.seed,
        theta_true: None,
        warnings: warnings.iter().map(ToString::to_string).collect(),
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

/// The experiments of the table in the gate's columns, each row checked against the model's
/// domain and the set checked for degeneracy; every error names the file (and the line).
/// Rows with the gate open (no head difference) carry no quoin force: they are left out with
/// a warning naming them, as the close loop's calibrator does.
fn read_experiments(table: &Table, model: &GateMultiLevel) -> Result<Experiments> {
    let names = model.observable.output_names();
    let outputs: Vec<&str> = names.iter().map(String::as_str).collect();
    let all = Experiments::from_table(table, &["h_up", "h_down"], &outputs)?;
    let col = table.column("h_up")?;
    let mut kept = vec![];
    let mut open = vec![];
    for i in 0..all.len() {
        let x = [all.x[(i, 0)], all.x[(i, 1)]];
        if let Err(e) = model.unobservable.check_input(&x) {
            return Err(table.error_at(i, col, e.to_string()).into());
        }
        match model.unobservable.response_vanishes(&x) {
            true => open.push(table.line(i)),
            false => kept.push(i),
        }
    }
    if !open.is_empty() {
        log::warn!(
            "{}: {} row(s) with the gate open (no head difference, no quoin force) left out, \
             lines {:?}{}",
            table.file(),
            open.len(),
            &open[..open.len().min(10)],
            if open.len() > 10 { " ..." } else { "" }
        );
    }
    let exps = Experiments::new(
        all.input_names.clone(),
        all.output_names.clone(),
        all.x.select_rows(kept.iter()),
        all.y.select_rows(kept.iter()),
    )?;
    check_informative(table, &exps, &outputs)?;
    Ok(exps)
}

/// Refuses data that would give a confident number from nothing: too few distinct
/// conditions, or a gauge that never changes (stuck or disconnected).
fn check_informative(table: &Table, exps: &Experiments, outputs: &[&str]) -> Result<()> {
    let mut conditions: Vec<(u64, u64)> = (0..exps.len())
        .map(|i| (exps.x[(i, 0)].to_bits(), exps.x[(i, 1)].to_bits()))
        .collect();
    conditions.sort_unstable();
    conditions.dedup();
    anyhow::ensure!(
        conditions.len() >= MIN_DISTINCT_EXPERIMENTS,
        "{}: {} experiment(s) with {} distinct water-level pair(s); calibrate needs at least \
         {MIN_DISTINCT_EXPERIMENTS} distinct conditions",
        table.file(),
        exps.len(),
        conditions.len()
    );
    for (j, name) in outputs.iter().enumerate() {
        let col = exps.y.column(j);
        let (lo, hi) = (col.min(), col.max());
        anyhow::ensure!(
            hi > lo,
            "{}: column `{name}` is constant ({lo} microstrain in every row): a stuck or \
             disconnected gauge carries no information; fix or drop it (and its gauge in the gate file)",
            table.file()
        );
    }
    Ok(())
}

/// The grid posterior's warnings (at a prior bound, under-resolved), for the terminal and the
/// report.
fn posterior_warnings(cal: &Calibration, prior: (f64, f64)) -> Vec<GridWarning> {
    match &cal.module3().posterior {
        ThetaPosterior::Grid(g) => g.warnings(prior),
        ThetaPosterior::Mcmc(_) => vec![],
    }
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
