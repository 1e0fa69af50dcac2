//! What a bottom gap does to the quoin blocks' fatigue on the default gate: the contact
//! forces of the gate model (ρ = 1, no discrepancy) at a full upper pool for several gaps,
//! through the quoin-block prediction model (default blocks and S-N curve).
//!
//! `cargo run --release -p bamudi-gate --example gap_fatigue`
use mitergate::quoin_block::QUOIN_BLOCK_OUTPUTS;
use mitergate::{GateConfig, QuoinBlockModel, QuoinBlockParams};
use mlmodel::PredictionModel;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (contact, _) = mitergate::build_contact(&GateConfig::default())?;
    let z = contact.gate().nu_points.clone();
    let n = z.len();
    let block = QuoinBlockModel::new(QuoinBlockParams::default(), z.clone())?;
    let x = [738.0, 360.0];
    println!(
        "h_up = {} in, h_down = {} in (a full upper pool)",
        x[0], x[1]
    );
    println!(
        "gap (in) | hot spot z (in) | peak pressure (psi) | damage / 1,000 lockages | lockages to crack initiation"
    );
    for gap in [12.0, 45.0, 90.0, 120.0, 150.0] {
        let forces = contact.solve(x[0], x[1], gap)?.forces;
        let mut out = vec![0.0; QUOIN_BLOCK_OUTPUTS.len() * n];
        block.evaluate(&x, &[gap], &forces, &mut out)?;
        let damage = &out[3 * n..];
        let hot = (0..n)
            .max_by(|a, b| damage[*a].total_cmp(&damage[*b]))
            .unwrap_or(0);
        println!(
            "{gap:8.0} | {:15.0} | {:19.0} | {:23.3e} | {:.3e}",
            z[hot],
            out[hot],
            damage[hot],
            1000.0 / damage[hot]
        );
    }
    Ok(())
}
