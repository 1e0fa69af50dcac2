//! `bamudi predict`: Module 4 from a saved calibration.
use anyhow::{Context, Result};
use bamudi::{Band, Calibration};
use bamudi_gate::gate::SavedModel;
use bamudi_gate::record_fatigue::{self, LoadHistory, RecordFatigueOptions, record_fatigue};
use mitergate::quoin_block::QUOIN_BLOCK_OUTPUTS;
use mitergate::{GateMultiLevel, QuoinBlockModel, QuoinBlockParams};
use mlmodel::{ObservableModel, UnobservableModel};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `predict`.
#[derive(Debug, clap::Args)]
pub struct PredictArgs {
    /// `calibration.json` written by `calibrate`.
    #[arg(long)]
    pub calibration: PathBuf,
    /// `model.json` written by `calibrate` (default: beside the calibration file).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Upstream water level above the sill (in); with `--h-down`, the condition to predict at
    /// (needed unless `--record` is given).
    #[arg(
        long,
        allow_negative_numbers = true,
        required_unless_present = "record",
        requires = "h_down"
    )]
    pub h_up: Option<f64>,
    /// Downstream water level above the sill (in).
    #[arg(
        long,
        allow_negative_numbers = true,
        required_unless_present = "record",
        requires = "h_up"
    )]
    pub h_down: Option<f64>,
    /// A load history (a field record or a lockage schedule: CSV with `time`, `h_up`, `h_down`;
    /// other columns are ignored): the quoin block's fatigue over it — rainflow-counted stress
    /// cycles, damage per 1,000 lockages and years to crack initiation along the quoin, nominal
    /// model beside the calibrated one with 95 % bands.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// CSV of the fatigue over `--record` (default: `record_fatigue.csv` beside the
    /// calibration file).
    #[arg(long, requires = "record")]
    pub record_out: Option<PathBuf>,
    /// CSV of the predicted quoin forces (default: `forces_<h_up>_<h_down>.csv` beside the
    /// calibration file).
    #[arg(long)]
    pub forces_out: Option<PathBuf>,
    /// CSV of the quoin-block prediction level (contact stresses and fatigue damage per 1,000
    /// lockages with 95 % bands; default: `quoin_block_<h_up>_<h_down>.csv` beside the
    /// calibration file).
    #[arg(long)]
    pub quoin_block_out: Option<PathBuf>,
}

/// Joint draws of the calibrated force behind the quoin-block bands.
const BLOCK_DRAWS: usize = 2_000;

/// Runs `predict`.
pub fn run(a: &PredictArgs) -> Result<()> {
    let cal = Calibration::load(&a.calibration)?;
    let dir = a
        .calibration
        .parent()
        .map(PathBuf::from)
        .unwrap_or_default();
    let model_path = a.model.clone().unwrap_or_else(|| dir.join("model.json"));
    let saved = SavedModel::load(&model_path).with_context(|| {
        format!(
            "the model file written by `calibrate` (give it with --model if it is not beside {})",
            a.calibration.display()
        )
    })?;
    let model = saved
        .multilevel(0)
        .with_context(|| format!("the model in {}", model_path.display()))?;
    if let (Some(h_up), Some(h_down)) = (a.h_up, a.h_down) {
        let x = [h_up, h_down];
        let files = ConditionFiles::of(a, &dir, x)?;
        let what = format!("{} and {}", a.calibration.display(), model_path.display());
        at_condition(&cal, &model, &what, x, &files)?;
    }
    if let Some(record) = &a.record {
        let out = a
            .record_out
            .clone()
            .unwrap_or_else(|| dir.join("record_fatigue.csv"));
        over_record(&cal, &model, record, &out)?;
    }
    Ok(())
}

/// The output files of the prediction at one condition, checked before any work.
struct ConditionFiles {
    forces: PathBuf,
    block: PathBuf,
}

impl ConditionFiles {
    fn of(a: &PredictArgs, dir: &std::path::Path, x: [f64; 2]) -> Result<Self> {
        for (name, v) in [("--h-up", x[0]), ("--h-down", x[1])] {
            anyhow::ensure!(
                v.is_finite(),
                "{name} must be a finite level in inches, got {v}"
            );
        }
        let forces = a
            .forces_out
            .clone()
            .unwrap_or_else(|| dir.join(format!("forces_{}_{}.csv", x[0], x[1])));
        bamudi_gate::output::check_file_destination("--forces-out", &forces)?;
        let block = a
            .quoin_block_out
            .clone()
            .unwrap_or_else(|| dir.join(format!("quoin_block_{}_{}.csv", x[0], x[1])));
        bamudi_gate::output::check_file_destination("--quoin-block-out", &block)?;
        Ok(Self { forces, block })
    }
}

/// Module 4 at one condition: strains, forces and the quoin-block prediction level.
fn at_condition(
    cal: &Calibration,
    model: &GateMultiLevel,
    what: &str,
    x: [f64; 2],
    files: &ConditionFiles,
) -> Result<()> {
    model
        .unobservable
        .check_input(&x)
        .context("--h-up / --h-down")?;
    let predictor = cal.predictor(model).context(what.to_string())?;
    let strains = predictor.outputs(&x).with_context(|| {
        format!(
            "predicting strains at h_up = {} in, h_down = {} in",
            x[0], x[1]
        )
    })?;
    let forces = predictor
        .response(&x)
        .context("predicting the quoin forces")?;
    print_strains(
        x,
        &model.observable.output_names(),
        &strains,
        cal.sigma_eps(),
    );
    let z = model.unobservable.coordinates();
    bamudi::data::write_atomic(&files.forces, forces_csv(z, &forces).as_bytes())?;
    println!(
        "quoin forces (95 % bands, {} points along the quoin) written to {}",
        z.len(),
        files.forces.display()
    );
    let block = QuoinBlockModel::new(QuoinBlockParams::default(), z.to_vec())?;
    let levels = predictor
        .predict_through(&block, &x, BLOCK_DRAWS, cal.config().seed)
        .context("the quoin-block prediction level")?;
    bamudi::data::write_atomic(&files.block, block_csv(z, &levels).as_bytes())?;
    print_hot_spot(z, &levels);
    println!(
        "quoin-block stresses and fatigue (95 % bands) written to {}",
        files.block.display()
    );
    Ok(())
}

/// The quoin block's fatigue over a load history.
fn over_record(
    cal: &Calibration,
    model: &GateMultiLevel,
    record: &std::path::Path,
    out: &std::path::Path,
) -> Result<()> {
    bamudi_gate::output::check_file_destination("--record-out", out)?;
    let history = load_history(record, model)?;
    let block = QuoinBlockModel::new(
        QuoinBlockParams::default(),
        model.unobservable.coordinates().to_vec(),
    )?;
    let opts = RecordFatigueOptions {
        seed: cal.config().seed,
        ..RecordFatigueOptions::default()
    };
    let r = record_fatigue(model, cal, &block, &history, None, opts)
        .with_context(|| format!("the quoin block's fatigue over {}", record.display()))?;
    bamudi::data::write_atomic(out, record_fatigue::to_csv(&r).as_bytes())?;
    println!("{}", record_fatigue::summary(&r));
    println!(
        "fatigue along the quoin over the record written to {}",
        out.display()
    );
    Ok(())
}

/// The record's levels and times (no gauge column needed; each row checked against the
/// gate's input domain, naming the file and line).
fn load_history(record: &std::path::Path, model: &GateMultiLevel) -> Result<LoadHistory> {
    let ingest = bamudi_closeloop::IngestConfig::new(&["h_up", "h_down"], &[]);
    let rec = bamudi_gate::session::read_record(record, model, &ingest)
        .with_context(|| format!("--record {}", record.display()))?;
    bamudi_gate::record_fatigue::load_history(&rec)
        .with_context(|| format!("--record {}", record.display()))
}

/// The hot spot: the quoin point of the largest mean damage rate.
fn print_hot_spot(z: &[f64], b: &Band) {
    let n = z.len();
    let hot = (0..n)
        .max_by(|p, q| b.mean[3 * n + p].total_cmp(&b.mean[3 * n + q]))
        .unwrap_or(0);
    println!(
        "quoin-block hot spot at z = {:.0} in: peak contact pressure {:.0} psi [{:.0}, {:.0}], \
         fatigue damage per 1,000 lockages {:.3e} [{:.3e}, {:.3e}] (Miner, default blocks; \
         docs/cli.md)",
        z[hot],
        b.mean[hot],
        b.lower[hot],
        b.upper[hot],
        b.mean[3 * n + hot],
        b.lower[3 * n + hot],
        b.upper[3 * n + hot]
    );
}

/// The quoin-block outputs with their bands, one row per point along the quoin (in).
fn block_csv(z: &[f64], b: &Band) -> String {
    let n = z.len();
    let mut csv = String::from("z_in");
    for q in QUOIN_BLOCK_OUTPUTS {
        let _ = write!(csv, ",{q}_mean,{q}_lower,{q}_upper");
    }
    csv.push('\n');
    for p in 0..n {
        let _ = write!(csv, "{}", z[p]);
        for k in 0..QUOIN_BLOCK_OUTPUTS.len() {
            let i = k * n + p;
            let _ = write!(csv, ",{},{},{}", b.mean[i], b.lower[i], b.upper[i]);
        }
        csv.push('\n');
    }
    csv
}

/// The strain table: mean, model band and measurement band (adds `σ_ε`) per gauge.
fn print_strains(x: [f64; 2], names: &[String], strains: &Band, sigma_eps: f64) {
    println!(
        "strains at h_up = {} in, h_down = {} in (microstrain; model band = noise-free strain, \
         measurement band adds sigma_eps = {sigma_eps:.3}):",
        x[0], x[1]
    );
    println!(
        "{:>8} {:>12} {:>12} {:>12} {:>14} {:>14}",
        "gauge", "mean", "2.5%", "97.5%", "meas. 2.5%", "meas. 97.5%"
    );
    for (p, name) in names.iter().enumerate() {
        let half = 1.959_964 * (strains.sd[p].powi(2) + sigma_eps.powi(2)).sqrt();
        println!(
            "{:>8} {:>12.3} {:>12.3} {:>12.3} {:>14.3} {:>14.3}",
            name,
            strains.mean[p],
            strains.lower[p],
            strains.upper[p],
            strains.mean[p] - half,
            strains.mean[p] + half
        );
    }
}

/// The quoin forces (lbf/in) with their bands, one row per point along the quoin (in).
fn forces_csv(z: &[f64], forces: &Band) -> String {
    let n = z.len();
    let mut csv = String::from(
        "z_in,normal_mean_lbf_per_in,normal_lower_lbf_per_in,normal_upper_lbf_per_in,\
         tangential_mean_lbf_per_in,tangential_lower_lbf_per_in,tangential_upper_lbf_per_in\n",
    );
    for b in 0..n {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{}",
            z[b],
            forces.mean[b],
            forces.lower[b],
            forces.upper[b],
            forces.mean[n + b],
            forces.lower[n + b],
            forces.upper[n + b]
        );
    }
    csv
}
