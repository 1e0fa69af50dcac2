//! Subcommand implementations of the `bamudi` binary and what they share: the gate (Module 1)
//! and the model file that lets `predict` rebuild exactly the calibrated model.
pub mod calibrate;
pub mod closeloop;
pub mod predict;
pub mod simulate;

use anyhow::{Context, Result};
use mitergate::contact::{ContactModel, ContactParams};
use mitergate::{GateConfig, GateModel};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

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

/// Builds, condenses (Module 1) and wraps the gate in its contact model; logs the time.
pub fn build_contact(cfg: &GateConfig) -> Result<ContactModel> {
    let t = Instant::now();
    let model = GateModel::build(cfg).context("building the gate finite-element model")?;
    let condensed = model
        .condense(mitergate::DEFAULT_NU)
        .context("condensing the gate to the quoin and the gauges")?;
    let contact = ContactParams::default()
        .build(condensed)
        .context("building the quoin contact model")?;
    eprintln!(
        "gate: {} dofs, element size {} in, built and condensed in {:.1} s",
        model.n_dofs(),
        cfg.mesh.element_size,
        t.elapsed().as_secs_f64()
    );
    Ok(contact)
}

/// The calibrated model's definition, saved as `model.json` beside `calibration.json` so that
/// `predict` uses exactly the same gate, prior and discrepancy basis without rebuilding.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SavedModel {
    /// The gate configuration the contact model was built from.
    pub gate: GateConfig,
    /// The condensed gate with its contact parameters.
    pub contact: ContactModel,
    /// Uniform prior of the gap θ (in).
    pub gap_prior: (f64, f64),
    /// Legendre terms of the discrepancy (normal, tangential).
    pub discrepancy_terms: [usize; 2],
}

impl SavedModel {
    /// Writes the JSON file.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self).context("serialising the model")?;
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
    }
    /// Reads the JSON file.
    pub fn load(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }
    /// The multi-level model (memoised contact forces, strains, prior, basis).
    pub fn multilevel(&self) -> Result<bamudi::closeloop::bamudi_calibrator::MemoGateModel> {
        Ok(bamudi::closeloop::bamudi_calibrator::gate_multilevel(
            self.contact.clone(),
            self.gap_prior,
            self.discrepancy_terms,
            50_000,
        )?)
    }
}

/// Creates an output directory (with its parents).
pub fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating directory {}", dir.display()))
}
