//! Writes the mesh figure of the default gate used in docs/mitergate.md.
//!
//! `cargo run --release -p mitergate --example plot_gate -- docs/mitergate_mesh.svg [element size]`
use mitergate::{GateConfig, GateModel, plot_mesh};

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "mitergate_mesh.svg".into());
    let mut cfg = GateConfig::default();
    if let Some(size) = args.next().and_then(|s| s.parse().ok()) {
        cfg.mesh.element_size = size;
    }
    let model = GateModel::build(&cfg).expect("build the gate");
    plot_mesh(&model, std::path::Path::new(&path)).expect("plot");
    println!("wrote {path}");
}
