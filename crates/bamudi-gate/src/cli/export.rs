//! `bamudi export-gate`: the gate as a finite-element deck with its import spec.
use super::{GateArgs, gate_source};
use anyhow::{Context, Result};
use bamudi_gate::output::check_file_destination;
use bamudi_gate::session::{GateSource, export_deck};
use std::path::PathBuf;

/// Arguments of `export-gate`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The deck to write (`.inp`: nodes, S4 shells per member, materials, node sets QUOIN,
    /// MITER, PINTLE, GUDGEON, gauge element sets, supports, a full-head load step).
    #[arg(long)]
    pub out: PathBuf,
    /// The import spec to write (TOML; default: beside `--out`, `<name>.spec.toml`).
    #[arg(long)]
    pub spec_out: Option<PathBuf>,
}

/// Runs `export-gate`.
pub fn run(a: &ExportArgs, gate: &GateArgs) -> Result<()> {
    let GateSource::Config(cfg) = gate_source(gate)? else {
        anyhow::bail!(
            "export-gate writes a gate configuration as a deck; --gate-inp is one already"
        )
    };
    let spec_out = a
        .spec_out
        .clone()
        .unwrap_or_else(|| a.out.with_extension("spec.toml"));
    check_file_destination("--out", &a.out)?;
    check_file_destination("--spec-out", &spec_out)?;
    let (deck, spec) = export_deck(&cfg).context("exporting the gate")?;
    bamudi::data::write_atomic(&a.out, deck.as_bytes())?;
    bamudi::data::write_atomic(&spec_out, spec.as_bytes())?;
    eprintln!(
        "wrote the deck {} and its import spec {} (use them with --gate-inp and --import-spec)",
        a.out.display(),
        spec_out.display()
    );
    Ok(())
}
