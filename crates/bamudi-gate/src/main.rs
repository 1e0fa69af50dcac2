//! The `bamudi` command-line interface on the miter gate (see `docs/cli.md`):
//!
//! * `simulate experiments` — the paper's synthetic experiments (Sec. 4.3, scenario 1 or 2);
//! * `simulate field` — a months-long field record (pools, lockages, temperatures, effects);
//! * `calibrate` — BA-MUDI Modules 2-3 from a TOML configuration and a CSV of experiments;
//! * `predict` — Module 4 (strains with 95 % bands, quoin forces CSV) from a saved calibration;
//! * `close-loop` — find the effects a calibration misses in a field record;
//! * `export-gate` — the gate as a finite-element deck (`.inp`) with its import spec.
//!
//! Every command works on the embedded default gate unless `--gate gate.toml` (or a deck:
//! `--gate-inp deck.inp --import-spec spec.toml`) is given.
mod cli;

use anyhow::{Context, Result};
use bamudi_gate::progress;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "bamudi",
    version,
    about = "BA-MUDI: Bayesian calibration of multi-level models with unobservable distributed response, on a miter gate"
)]
struct Cli {
    /// Master seed (overrides the config's `seed`; default 2021 for calibration, the scenario
    /// number for `simulate experiments`, 0 for `simulate field`).
    #[arg(long, global = true, allow_negative_numbers = true)]
    seed: Option<u64>,
    /// Worker threads of the rayon pool, in [1, 1024] (default: one per core).
    #[arg(long, global = true, allow_negative_numbers = true,
          value_parser = clap::value_parser!(u16).range(1..=1024))]
    threads: Option<u16>,
    /// Print the engine's diagnostics (log level `info`; `RUST_LOG` sets any level).
    #[arg(long, short, global = true)]
    verbose: bool,
    #[command(flatten)]
    gate: cli::GateArgs,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Generate synthetic data from the gate model.
    #[command(subcommand)]
    Simulate(cli::simulate::SimulateCmd),
    /// Calibrate: TOML configuration + CSV experiments -> results directory.
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Predict strains (95 % bands) and quoin forces from a saved calibration (Module 4).
    Predict(cli::predict::PredictArgs),
    /// Close the loop on a field record: find, add and report the missing effects.
    CloseLoop(cli::closeloop::CloseLoopCmd),
    /// Write the gate as a finite-element deck (.inp) with its import spec (for --gate-inp).
    ExportGate(cli::export::ExportArgs),
}

/// Prints an error as one line of its causes (`error: outer: inner: ...`, each piece once:
/// [`bamudi_gate::error::one_line`]), without the backtrace `RUST_BACKTRACE` would add, and
/// exits with status 1.
fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            let causes = e.chain().map(ToString::to_string);
            eprintln!("error: {}", bamudi_gate::error::one_line(causes));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    progress::init_logging(cli.verbose);
    match &cli.cmd {
        Cmd::Predict(_) => refuse_unused_flags(&cli, "predict", true)?,
        Cmd::ExportGate(_) => refuse_unused_flags(&cli, "export-gate", false)?,
        _ => {}
    }
    if let Some(t) = cli.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(usize::from(t))
            .build_global()
            .context("--threads: building the rayon pool")?;
    }
    match &cli.cmd {
        Cmd::Simulate(c) => cli::simulate::run(c, &cli.gate, cli.seed),
        Cmd::Calibrate(a) => cli::calibrate::run(a, &cli.gate, cli.seed),
        Cmd::Predict(a) => cli::predict::run(a),
        Cmd::CloseLoop(a) => cli::closeloop::run(a, &cli.gate, cli.seed),
        Cmd::ExportGate(a) => cli::export::run(a, &cli.gate),
    }
}

/// `predict` uses the gate and settings saved by `calibrate`, `export-gate` draws no random
/// number and solves nothing: a flag the command would ignore is an error, not a silent no-op.
fn refuse_unused_flags(cli: &Cli, command: &str, gate_flags_unused: bool) -> Result<()> {
    let g = &cli.gate;
    let unused = [
        ("--gate", gate_flags_unused && g.gate.is_some()),
        (
            "--element-size",
            gate_flags_unused && g.element_size.is_some(),
        ),
        ("--gate-inp", gate_flags_unused && g.gate_inp.is_some()),
        (
            "--import-spec",
            gate_flags_unused && g.import_spec.is_some(),
        ),
        ("--seed", cli.seed.is_some()),
        ("--threads", cli.threads.is_some()),
    ];
    for (flag, given) in unused {
        let why = if gate_flags_unused {
            "the gate and its settings come from the model.json written by `calibrate`"
        } else {
            "it only writes the gate as a deck"
        };
        anyhow::ensure!(
            !given,
            "{flag} is not used by `{command}`: {why}; remove {flag}"
        );
    }
    Ok(())
}
