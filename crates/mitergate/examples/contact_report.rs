//! Contact model on the default gate: timing of one `g_BC` evaluation, force resultants, and the
//! visibility of the paper's discrepancy (Eq. 53-54) through the gauges.
//!
//! `cargo run --release -p mitergate --example contact_report`
use mitergate::data::truth::{self, Scenario};
use mitergate::{GateConfig, build_contact};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let t = Instant::now();
    let (contact, summary) = build_contact(&GateConfig::default())?;
    println!(
        "build + condense: {:.2} s, {} dofs, {} quoin nodes",
        t.elapsed().as_secs_f64(),
        summary.n_dofs,
        summary.n_quoin_nodes
    );
    let xs = truth::sample_levels(200, 7);
    for theta in [0.0, 90.0, 150.0] {
        let t = Instant::now();
        let mut iters = 0usize;
        for x in &xs {
            iters += contact.solve(x[0], x[1], theta)?.iterations;
        }
        let per = t.elapsed().as_secs_f64() / xs.len() as f64;
        println!(
            "theta = {theta:5.1} in: {:.3} ms per g_BC evaluation, {:.1} iterations on average",
            per * 1e3,
            iters as f64 / xs.len() as f64
        );
    }
    let sol = contact.solve(744.0, 24.0, 90.0)?;
    let dz = 762.0 / 508.0;
    let n: f64 = sol.normal().iter().sum::<f64>() * dz;
    let tt: f64 = sol.tangential().iter().sum::<f64>() * dz;
    println!("full head, theta = 90: normal resultant {n:.4e} lbf, tangential {tt:.4e} lbf");
    for k in [1u8, 2] {
        let sc = Scenario::paper(k)?;
        let vis = truth::discrepancy_visibility(&sc.n_experiments(200), &contact)?;
        println!(
            "scenario {k}: {vis:?}, signal/noise {:.2}",
            vis.signal_to_noise()
        );
    }
    Ok(())
}
