//! Prints the numbers recorded in docs/verification.md and docs/benchmarks.md for the default
//! gate: size, timings, rigid-quoin gauge strains under full head, observability of the quoin
//! normal force through the gauges.
//!
//! `cargo run --release -p mitergate --example gate_report -- [element sizes...]`
use mitergate::{GateConfig, GateModel};
use nalgebra::DMatrix;
use std::time::Instant;

fn main() {
    let sizes: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let sizes = if sizes.is_empty() { vec![12.0] } else { sizes };
    for size in sizes {
        let mut cfg = GateConfig::default();
        cfg.mesh.element_size = size;
        let t0 = Instant::now();
        let model = GateModel::build(&cfg).expect("build");
        let t_build = t0.elapsed();
        let t1 = Instant::now();
        let cg = model.condense(mitergate::DEFAULT_NU).expect("condense");
        let t_cond = t1.elapsed();
        println!(
            "element size {size} in: {} nodes, {} elements, {} DOFs ({} free), m = {} quoin nodes; \
             build (mesh+assemble+factor) {:.2} s, condense {:.2} s",
            model.mesh().shell.nodes.len(),
            model.mesh().shell.elements.len(),
            model.n_dofs(),
            model.shell_model().n_reduced(),
            cg.n_quoin_nodes(),
            t_build.as_secs_f64(),
            t_cond.as_secs_f64()
        );
        let water = cg.water_strain.eval_levels(744.0, 24.0);
        let rigid = model
            .rigid_quoin_response(&cg, 744.0, 24.0)
            .expect("rigid quoin");
        let m = cg.n_quoin_nodes();
        let pn: f64 = rigid.nodal_forces[..m].iter().sum();
        let pt: f64 = rigid.nodal_forces[m..].iter().sum();
        println!(
            "  rigid quoin, h_up 744, h_down 24: total normal {pn:.4e} lbf, tangential {pt:.4e} lbf"
        );
        for (k, name) in cg.gauge_names.iter().enumerate() {
            println!(
                "  {name}: water only {:10.2} ue, rigid quoin {:10.2} ue",
                water[k], rigid.strains[k]
            );
        }
        // observability: A_N L, L the first 6 Legendre polynomials on [0, H] at the N_u points
        let nu = cg.n_points();
        let l = DMatrix::from_fn(nu, 6, |b, k| {
            let x = 2.0 * cg.nu_points[b] / cg.quoin_height - 1.0;
            legendre(k, x)
        });
        let an = cg.a_matrix.columns(0, nu) * l;
        let sv = an.singular_values();
        println!(
            "  singular values of A_N L (ue per lbf/in): {:?}",
            sv.iter().map(|v| format!("{v:.3e}")).collect::<Vec<_>>()
        );
        println!("  condition number {:.3e}", sv.max() / sv.min());
    }
}

fn legendre(k: usize, x: f64) -> f64 {
    let (mut p0, mut p1) = (1.0, x);
    if k == 0 {
        return p0;
    }
    for n in 1..k {
        let p2 = ((2 * n + 1) as f64 * x * p1 - n as f64 * p0) / (n + 1) as f64;
        p0 = p1;
        p1 = p2;
    }
    p1
}
