//! `bamudi simulate experiments|field`.
use super::{Bound, GateArgs, build_gate, gate_source, number_in};
use anyhow::{Context, Result};
use bamudi_gate::output::check_file_destination;
use bamudi_gate::session::GateSource;
use mitergate::data::field::{FieldConfig, FieldEffects, MissingValues};
use mitergate::data::truth::Scenario;
use mitergate::reality::Reality;
use std::path::PathBuf;

/// What to simulate.
#[derive(Debug, clap::Subcommand)]
pub enum SimulateCmd {
    /// The paper's synthetic experiments (Sec. 4.3, Eq. 48, 53-54): strains of the true forces
    /// `ρ g_BC(x, θ*) + δ(x)` plus Gaussian noise at random water levels.
    Experiments(ExperimentsArgs),
    /// A field record: months of lockages with the gate model as the true strain function and
    /// optional effects the calibration model lacks.
    Field(FieldArgs),
}

/// Arguments of `simulate experiments`.
#[derive(Debug, clap::Args)]
pub struct ExperimentsArgs {
    /// Paper scenario: 1 (θ* = 90 in, prior U(81, 105)) or 2 (θ* = 150 in, prior U(135, 165)).
    #[arg(long, allow_negative_numbers = true)]
    pub scenario: u8,
    /// Number of experiments, in [1, 1000000].
    #[arg(long, default_value_t = 500, allow_negative_numbers = true,
          value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub n: u32,
    /// Noise standard deviation (microstrain), in [0, 1000].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true,
          value_parser = number_in(0.0, 1000.0, Bound::Closed, "microstrain"))]
    pub noise_sd: f64,
    /// A reality (TOML, docs/reality.md): the truth departs from the gate by declared
    /// deviations (as built, mesh, support, sensors).
    #[arg(long)]
    pub reality: Option<PathBuf>,
    /// Output CSV (`h_up`, `h_down` in inches, one column per gauge in microstrain).
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `simulate field`.
#[derive(Debug, clap::Args)]
pub struct FieldArgs {
    /// Record length (days), in (0, 3650]; at most 200,000 rows in all.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true,
          value_parser = number_in(0.0, 3650.0, Bound::Open, "days"))]
    pub days: f64,
    /// Sampling interval (minutes), in [1, 1440].
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true,
          value_parser = number_in(1.0, 1440.0, Bound::Closed, "minutes"))]
    pub step_minutes: f64,
    /// Effects to switch on (repeat or comma-separate): thermal, drift, offset-jump,
    /// gap-growth, hysteresis, wall-flexure, none.
    #[arg(long, value_delimiter = ',', default_value = "none")]
    pub effect: Vec<String>,
    /// True bottom gap length (in) at the start of the record (the gate's own limits apply).
    #[arg(long, default_value_t = 90.0, allow_negative_numbers = true,
          value_parser = number_in(0.0, 10_000.0, Bound::Open, "in"))]
    pub gap: f64,
    /// Gap at the end of the record (in) for the `gap-growth` effect (default 130; refused
    /// without it).
    #[arg(long, allow_negative_numbers = true,
          value_parser = number_in(0.0, 10_000.0, Bound::Open, "in"))]
    pub final_gap: Option<f64>,
    /// White gauge noise (microstrain), in [0, 1000].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true,
          value_parser = number_in(0.0, 1000.0, Bound::Closed, "microstrain"))]
    pub noise_sd: f64,
    /// Probability that a gauge value is missing (telemetry drop-out), in [0, 0.9].
    #[arg(long, allow_negative_numbers = true,
          value_parser = number_in(0.0, 0.9, Bound::Closed, "(a probability)"))]
    pub missing: Option<f64>,
    /// A reality (TOML, docs/reality.md): the truth departs from the gate by declared
    /// deviations (as built, mesh, support, sensors).
    #[arg(long)]
    pub reality: Option<PathBuf>,
    /// Output CSV (see docs/closeloop.md for the columns).
    #[arg(long)]
    pub out: PathBuf,
}

/// The truth's contact model: the gate of `gate`, or its reality (as built, mesh, support)
/// when `--reality` is given; and the reality (the identity without one). A reality departs
/// from a gate configuration: it is refused with an imported deck.
fn truth_contact(
    gate: &GateArgs,
    reality: Option<&std::path::Path>,
) -> Result<(mitergate::ContactModel, Reality)> {
    let source = gate_source(gate)?;
    let Some(path) = reality else {
        return Ok((build_gate(&source)?.contact, Reality::default()));
    };
    let GateSource::Config(drawing) = source else {
        anyhow::bail!(
            "--reality {}: a reality declares deviations from a gate configuration (--gate or \
             the embedded default); it cannot be combined with --gate-inp",
            path.display()
        )
    };
    let r = Reality::from_file(path).with_context(|| format!("--reality {}", path.display()))?;
    let contact = bamudi_gate::gate::build_truth(&r, &drawing)
        .with_context(|| format!("--reality {}", path.display()))?;
    eprintln!("truth: the reality of {}", path.display());
    Ok((contact, r))
}

/// Most rows of a simulated field record (a year at 3-minute steps): every row is a contact
/// solve (about 0.45 ms on the default gate, plus the strains).
const MAX_FIELD_ROWS: f64 = 200_000.0;

/// Runs `simulate`.
pub fn run(cmd: &SimulateCmd, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    match cmd {
        SimulateCmd::Experiments(a) => experiments(a, gate, seed),
        SimulateCmd::Field(a) => field(a, gate, seed),
    }
}

fn experiments(a: &ExperimentsArgs, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    let mut sc = Scenario::paper(a.scenario)
        .context("--scenario")?
        .n_experiments(a.n as usize)
        .noise_sd(a.noise_sd);
    if let Some(s) = seed {
        sc = sc.seed(s);
    }
    sc.validate().context("invalid --n or --noise-sd")?;
    check_file_destination("--out", &a.out)?;
    let (contact, reality) = truth_contact(gate, a.reality.as_deref())?;
    let exps = bamudi_gate::session::simulate_experiments(&sc, &contact, &reality)
        .context("generating the experiments")?;
    exps.write_csv(&a.out)?;
    eprintln!(
        "wrote {} experiments of {} (true gap {} in, prior U({}, {}) in, seed {}) to {}",
        exps.len(),
        sc.name,
        sc.theta_true,
        sc.prior.0,
        sc.prior.1,
        sc.seed,
        a.out.display()
    );
    Ok(())
}

fn field(a: &FieldArgs, gate: &GateArgs, seed: Option<u64>) -> Result<()> {
    let mut effects = FieldEffects::from_presets(&a.effect, a.final_gap).map_err(|e| match e {
        mitergate::GateError::InvalidInput { what, reason } if what == "final_gap" => {
            anyhow::anyhow!("--final-gap: {reason}")
        }
        mitergate::GateError::InvalidInput { reason, .. } => {
            anyhow::anyhow!("--effect {}: {reason}", a.effect.join(","))
        }
        e => anyhow::anyhow!("--effect: {e}"),
    })?;
    if let Some(p) = a.missing {
        effects.missing = Some(MissingValues { probability: p });
    }
    let cfg = FieldConfig::default()
        .seed(seed.unwrap_or(0))
        .duration(a.days, a.step_minutes)
        .noise_sd(a.noise_sd)
        .gap(a.gap)
        .effects(effects);
    let rows = a.days * 1440.0 / a.step_minutes;
    anyhow::ensure!(
        rows <= MAX_FIELD_ROWS,
        "--days {} at --step-minutes {} gives {rows:.0} rows; at most {MAX_FIELD_ROWS} \
         (shorten the record or sample less often)",
        a.days,
        a.step_minutes
    );
    check_file_destination("--out", &a.out)?;
    let (contact, reality) = truth_contact(gate, a.reality.as_deref())?;
    let mut rec = bamudi_gate::gate::simulate_field(&cfg, &contact)?;
    reality.apply_to_field(&mut rec);
    rec.write_csv(&a.out)
        .with_context(|| format!("writing {}", a.out.display()))?;
    eprintln!(
        "wrote {} rows ({} days every {} min, effects: {}) to {}",
        rec.len(),
        a.days,
        a.step_minutes,
        a.effect.join(", "),
        a.out.display()
    );
    Ok(())
}
