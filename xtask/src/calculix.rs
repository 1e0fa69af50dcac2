//! `cargo xtask calculix-check`: the gate against CalculiX (see `mitergate::calculix`).

use anyhow::{Context, Result, bail};
use mitergate::GateConfig;
use mitergate::calculix::{CrossCheckOptions, ccx_available, cross_check};
use mitergate::inp::MiterConstraint;
use std::path::PathBuf;

/// Options of the `calculix-check` task.
pub struct CalculixCheck {
    /// Mesh element size (in).
    pub element_size: f64,
    /// Working directory for the deck and the CalculiX results.
    pub work_dir: PathBuf,
    /// CalculiX executable.
    pub ccx: String,
    /// Write the miter roller as `*EQUATION`s instead of a `*TRANSFORM`.
    pub equation: bool,
    /// Also write the Markdown report to this file.
    pub report: Option<PathBuf>,
}

/// Exports the default gate at `element_size`, runs `ccx` and prints the comparison.
pub fn run(opts: &CalculixCheck) -> Result<()> {
    if !ccx_available(&opts.ccx) {
        bail!(
            "`{}` (CalculiX) not found; install it, e.g. `apt-get install calculix-ccx`",
            opts.ccx
        );
    }
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = opts.element_size;
    let miter = if opts.equation {
        MiterConstraint::Equation
    } else {
        MiterConstraint::Transform
    };
    let check = CrossCheckOptions::new(&opts.work_dir)
        .with_ccx(&opts.ccx)
        .with_miter(miter);
    let report = cross_check(&cfg, &check)?;
    let md = report.to_markdown();
    println!("{md}");
    if let Some(path) = &opts.report {
        std::fs::write(path, &md).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
