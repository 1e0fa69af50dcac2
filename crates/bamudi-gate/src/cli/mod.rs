//! Subcommand implementations of the `bamudi` binary and what they share: the gate (Module 1).
pub mod calibrate;
pub mod closeloop;
pub mod predict;
pub mod simulate;

use anyhow::{Context, Result};
use mitergate::{ContactModel, GateConfig};
use std::path::{Path, PathBuf};

/// Gate selection, shared by every subcommand.
#[derive(Debug, Clone, clap::Args)]
pub struct GateArgs {
    /// Gate configuration TOML (every key of mitergate's `data/default_gate.toml`); default:
    /// the embedded Ohio-River-like leaf.
    #[arg(long, global = true)]
    pub gate: Option<PathBuf>,
    /// Override of the mesh element size (in) of the gate (coarser = faster, less accurate).
    #[arg(long, global = true)]
    pub element_size: Option<f64>,
}

/// Reads the gate configuration (file or embedded default) with the element-size override.
pub fn gate_config(args: &GateArgs) -> Result<GateConfig> {
    let mut cfg = match &args.gate {
        Some(p) => GateConfig::from_file(p).with_context(|| format!("--gate {}", p.display()))?,
        None => GateConfig::default(),
    };
    if let Some(h) = args.element_size {
        anyhow::ensure!(
            h.is_finite() && h > 0.0,
            "--element-size must be a positive length in inches, got {h}"
        );
        cfg.mesh.element_size = h;
        cfg.validate().context("--element-size")?;
    }
    Ok(cfg)
}

/// Builds and condenses the gate (Module 1) with its contact model; reports the time.
pub fn build_contact(cfg: &GateConfig) -> Result<ContactModel> {
    let (contact, s, seconds) =
        bamudi_gate::gate::build(cfg).context("building the gate model (Module 1)")?;
    eprintln!(
        "gate: {} dofs, element size {} in, built and condensed in {seconds:.1} s",
        s.n_dofs, s.element_size
    );
    Ok(contact)
}

/// Creates an output directory (with its parents).
pub fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating directory {}", dir.display()))
}
