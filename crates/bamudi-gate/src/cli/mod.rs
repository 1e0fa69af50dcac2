//! Subcommand implementations of the `bamudi` binary and what they share: the gate (Module 1).
pub mod calibrate;
pub mod closeloop;
pub mod export;
pub mod predict;
pub mod simulate;

use anyhow::{Context, Result};
use bamudi_gate::session::{BuiltGate, GateSource};
use mitergate::GateConfig;
use std::path::PathBuf;

/// Gate selection, shared by every subcommand.
#[derive(Debug, Clone, clap::Args)]
pub struct GateArgs {
    /// Gate configuration TOML (every key of mitergate's `data/default_gate.toml`); default:
    /// the embedded Ohio-River-like leaf.
    #[arg(long, global = true)]
    pub gate: Option<PathBuf>,
    /// Override of the mesh element size (in) of the gate (coarser = faster, less accurate).
    #[arg(long, global = true, allow_negative_numbers = true,
          value_parser = number_in(0.0, mitergate::MAX_ELEMENT_SIZE_IN, Bound::Open, "in"))]
    pub element_size: Option<f64>,
    /// Your own gate as a finite-element deck (Abaqus / CalculiX `.inp`), with
    /// `--import-spec` (docs/mitergate.md, "Bring your own gate"); instead of `--gate`.
    #[arg(long, global = true, requires = "import_spec", conflicts_with_all = ["gate", "element_size"])]
    pub gate_inp: Option<PathBuf>,
    /// The import spec (TOML) of `--gate-inp`: where the deck's quoin, wetted skin and gauges
    /// are.
    #[arg(long, global = true, requires = "gate_inp")]
    pub import_spec: Option<PathBuf>,
}

impl GateArgs {
    /// How the gate is named in reports: the file(s) it came from.
    pub fn label(&self) -> String {
        match (&self.gate, &self.gate_inp, &self.import_spec) {
            (_, Some(inp), Some(spec)) => {
                format!("{} (import spec {})", inp.display(), spec.display())
            }
            (Some(g), _, _) => g.display().to_string(),
            _ => "embedded default gate".into(),
        }
    }
}

/// Whether the lower end of a [`number_in`] range is allowed.
#[derive(Debug, Clone, Copy)]
pub enum Bound {
    /// `lo` itself is allowed.
    Closed,
    /// Only values above `lo`.
    Open,
}

/// A clap value parser for a finite number in `[lo, hi]` (or `(lo, hi]`), in `unit`: the
/// message clap prints names the flag and the allowed range, so limits are checked before
/// any work and negative numbers reach it (with `allow_negative_numbers`).
pub fn number_in(
    lo: f64,
    hi: f64,
    lower: Bound,
    unit: &'static str,
) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone + Send + Sync + 'static {
    move |text: &str| {
        let v: f64 = text
            .trim()
            .parse()
            .map_err(|_| format!("`{text}` is not a number"))?;
        let above = match lower {
            Bound::Closed => v >= lo,
            Bound::Open => v > lo,
        };
        if v.is_finite() && above && v <= hi {
            return Ok(v);
        }
        let open = if matches!(lower, Bound::Open) {
            "("
        } else {
            "["
        };
        Err(format!("must be in {open}{lo}, {hi}] {unit}, got {text}"))
    }
}

/// Reads the gate configuration (file or embedded default) with the element-size override
/// ([`session::gate_config`](bamudi_gate::session::gate_config), as Python's `Gate`).
pub fn gate_config(args: &GateArgs) -> Result<GateConfig> {
    Ok(bamudi_gate::session::gate_config(
        args.gate.as_deref(),
        args.element_size,
        ("--gate", "--element-size"),
    )?)
}

/// The gate of the arguments: a deck with its import spec, or a configuration.
pub fn gate_source(args: &GateArgs) -> Result<GateSource> {
    match (&args.gate_inp, &args.import_spec) {
        (Some(inp), Some(spec)) => Ok(GateSource::Deck {
            inp: inp.clone(),
            spec: spec.clone(),
        }),
        _ => Ok(GateSource::Config(gate_config(args)?)),
    }
}

/// Builds and condenses the gate (Module 1) with its contact model; reports the time.
pub fn build_gate(source: &GateSource) -> Result<BuiltGate> {
    let built = source
        .build()
        .context("building the gate model (Module 1)")?;
    let mesh = built
        .element_size
        .map_or("the deck's own mesh".into(), |h| {
            format!("element size {h} in")
        });
    eprintln!(
        "gate: {} dofs, {mesh}, built and condensed in {:.1} s",
        built.n_dofs, built.seconds
    );
    Ok(built)
}
