//! The gate model: loads, equilibrium, supports, condensation, hydrostatic tables.
use mitergate::condense::CondensedGate;
use mitergate::fe::loads::load_transfer;
use mitergate::fe::{ShellModel, Support};
use mitergate::{GateConfig, GateError, GateModel};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use std::sync::OnceLock;

const GAMMA: f64 = 0.0361;

/// A coarse version of the default leaf (60 in elements) and its condensation (N_u = 41),
/// shared by the tests.
fn coarse() -> &'static (GateModel, CondensedGate) {
    static MODEL: OnceLock<(GateModel, CondensedGate)> = OnceLock::new();
    MODEL.get_or_init(|| {
        let mut cfg = GateConfig::default();
        cfg.mesh.element_size = 60.0;
        let model = GateModel::build(&cfg).unwrap();
        let cg = model.condense(41).unwrap();
        (model, cg)
    })
}

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    let den: f64 = b.iter().map(|y| y * y).sum::<f64>().sqrt();
    num / den
}

#[test]
fn water_load_resultants_are_exact() {
    let (model, _) = coarse();
    let l = model.config().geometry.leaf_length;
    for (hu, hd) in [(744.0, 24.0), (500.5, 123.4), (300.0, 300.0)] {
        let f = model.water_load(hu, hd).unwrap();
        let fy: f64 = f.iter().skip(1).step_by(6).sum();
        let exact = GAMMA * l * (hu * hu - hd * hd) / 2.0;
        // consistent loads integrate the linear pressure exactly: round-off only
        assert!(
            (fy - exact).abs() <= 1e-10 * exact.max(1.0),
            "{fy} vs {exact}"
        );
        // the moment about the sill is exact too (z is interpolated exactly by the shape functions)
        let mz: f64 = (0..model.mesh().shell.nodes.len())
            .map(|n| f[6 * n + 1] * model.mesh().shell.nodes[n][2])
            .sum();
        let exact_m = GAMMA * l * (hu.powi(3) - hd.powi(3)) / 6.0;
        // round-off relative to the full-head moment
        let scale = GAMMA * l * 744.0f64.powi(3) / 6.0;
        assert!((mz - exact_m).abs() <= 1e-10 * scale, "{mz} vs {exact_m}");
        assert!(f.iter().enumerate().all(|(i, v)| i % 6 == 1 || *v == 0.0));
    }
}

#[test]
fn water_levels_are_validated_by_name() {
    let (model, _) = coarse();
    for (hu, hd, name) in [
        (800.0, 24.0, "h_up"),
        (300.0, 10.0, "h_down"),
        (100.0, 200.0, "h_up"),
        (f64::NAN, 30.0, "h_up"),
    ] {
        match model.water_load(hu, hd) {
            Err(GateError::InvalidWaterLevel { parameter, .. }) => assert_eq!(parameter, name),
            other => panic!("expected InvalidWaterLevel for ({hu}, {hd}), got {other:?}"),
        }
    }
}

#[test]
fn reactions_balance_applied_loads() {
    let (model, cg) = coarse();
    let mut rng = StdRng::seed_from_u64(7);
    let nu = cg.n_points();
    let q: Vec<f64> = (0..2 * nu)
        .map(|_| rng.random_range(-2000.0..2000.0))
        .collect();
    let mut f = model.water_load(650.0, 80.0).unwrap();
    for (a, b) in f
        .iter_mut()
        .zip(model.quoin_line_load(&q, &cg.nu_points).unwrap())
    {
        *a += b;
    }
    let u = model.solve(&f).unwrap();
    let r = model.reactions(&u);
    let nodes = &model.mesh().shell.nodes;
    let mut sum_f = [0.0; 3];
    let mut sum_m = [0.0; 3];
    for (n, p) in nodes.iter().enumerate() {
        let fv = [f[6 * n], f[6 * n + 1], f[6 * n + 2]];
        for k in 0..3 {
            sum_f[k] += fv[k];
            sum_m[k] += f[6 * n + 3 + k];
        }
        sum_m[0] += p[1] * fv[2] - p[2] * fv[1];
        sum_m[1] += p[2] * fv[0] - p[0] * fv[2];
        sum_m[2] += p[0] * fv[1] - p[1] * fv[0];
    }
    let scale_f = sum_f.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let scale_m = scale_f * 1000.0;
    for k in 0..3 {
        // equilibrium holds to the solver's round-off (relative 1e-8 is generous)
        assert!(
            (sum_f[k] + r.total_force[k]).abs() < 1e-8 * scale_f,
            "force {k}"
        );
        assert!(
            (sum_m[k] + r.total_moment[k]).abs() < 1e-8 * scale_m,
            "moment {k}"
        );
    }
    // the miter bearing pushes only across the lock (along m) and carries no moments
    let m = model.config().miter_direction();
    for &(node, rv) in &r.nodal {
        if model.mesh().miter_nodes.contains(&node) {
            let along = rv[0] * m[0] + rv[1] * m[1];
            let perp = (rv[0] - along * m[0])
                .hypot(rv[1] - along * m[1])
                .hypot(rv[2]);
            assert!(perp < 1e-7 * scale_f, "node {node}: {rv:?}");
        }
    }
}

#[test]
fn condensed_strains_equal_full_solve() {
    let (model, cg) = coarse();
    let mut rng = StdRng::seed_from_u64(11);
    let nu = cg.n_points();
    for _ in 0..3 {
        let q: Vec<f64> = (0..2 * nu)
            .map(|_| rng.random_range(-5000.0..5000.0))
            .collect();
        let hu = rng.random_range(100.0..744.0);
        let hd = rng.random_range(24.0..hu);
        let mut f = model.water_load(hu, hd).unwrap();
        for (a, b) in f
            .iter_mut()
            .zip(model.quoin_line_load(&q, &cg.nu_points).unwrap())
        {
            *a += b;
        }
        let u = model.solve(&f).unwrap();
        let full = model.gauge_strains(&u);
        let condensed = cg.strain(&q, hu, hd);
        // adjoint and forward solves use the same factor: agreement to round-off (1e-9)
        let e = rel_err(condensed.as_slice(), &full);
        assert!(e < 1e-9, "relative error {e}");
        // and the quoin displacements: C P + u_w
        let p: Vec<f64> = {
            let t = &cg.load_transfer;
            let qn = nalgebra::DVector::from_column_slice(&q[..nu]);
            let qt = nalgebra::DVector::from_column_slice(&q[nu..]);
            (t * qn).iter().chain((t * qt).iter()).copied().collect()
        };
        let d = &cg.quoin_flexibility * nalgebra::DVector::from_vec(p)
            + cg.water_quoin_displacement.eval_levels(hu, hd);
        let e = rel_err(d.as_slice(), &model.quoin_displacements(&u));
        assert!(e < 1e-9, "quoin displacement relative error {e}");
    }
}

#[test]
fn quoin_flexibility_is_symmetric_positive_definite() {
    let (_, cg) = coarse();
    let c = &cg.quoin_flexibility;
    let asym = (c - c.transpose()).abs().max();
    // Maxwell–Betti reciprocity: symmetric up to solver round-off
    assert!(
        asym < 1e-9 * c.abs().max(),
        "asymmetry {asym} vs {}",
        c.abs().max()
    );
    assert!(((c + c.transpose()) * 0.5).cholesky().is_some());
}

#[test]
fn hydrostatic_tables_equal_full_water_solves() {
    let (model, cg) = coarse();
    let mut rng = StdRng::seed_from_u64(3);
    for _ in 0..4 {
        let hu: f64 = rng.random_range(30.0..744.0);
        let hd: f64 = rng.random_range(24.0..hu);
        assert!(!cg.water_strain.breakpoints().contains(&hu));
        let u = model.solve(&model.water_load(hu, hd).unwrap()).unwrap();
        // the tables are exact piecewise cubics: round-off only
        let e = rel_err(
            cg.water_strain.eval_levels(hu, hd).as_slice(),
            &model.gauge_strains(&u),
        );
        assert!(e < 1e-9, "strain table error {e}");
        let e = rel_err(
            cg.water_quoin_displacement.eval_levels(hu, hd).as_slice(),
            &model.quoin_displacements(&u),
        );
        assert!(e < 1e-9, "quoin table error {e}");
    }
}

#[test]
fn load_transfer_is_exact_for_linear_loads() {
    let nodes = [0.0, 10.0, 25.0, 31.0, 60.0, 100.0];
    let points: Vec<f64> = (0..7).map(|b| 100.0 * b as f64 / 6.0).collect();
    let t = load_transfer(&nodes, &points).unwrap();
    // q(z) = 2 + 0.5 z is represented exactly by the points; F_j = ∫ ψ_j q dz in closed form
    let q: Vec<f64> = points.iter().map(|z| 2.0 + 0.5 * z).collect();
    for j in 0..nodes.len() {
        let f: f64 = (0..points.len()).map(|b| t[(j, b)] * q[b]).sum();
        let (lo, hi) = (
            if j > 0 { nodes[j - 1] } else { nodes[j] },
            if j + 1 < nodes.len() {
                nodes[j + 1]
            } else {
                nodes[j]
            },
        );
        let zj = nodes[j];
        // ∫ hat * (2 + 0.5 z): left part (zj - lo)/2 * (2 + 0.5 (zj + 2 lo)/3 ...) via Simpson
        let side = |a: f64, b: f64, up: bool| {
            let g = |z: f64| {
                let s = if b > a { (z - a) / (b - a) } else { 0.0 };
                (if up { s } else { 1.0 - s }) * (2.0 + 0.5 * z)
            };
            (b - a) / 6.0 * (g(a) + 4.0 * g(0.5 * (a + b)) + g(b))
        };
        let exact = side(lo, zj, true) + side(zj, hi, false);
        // exact quadrature: round-off only
        assert!(
            (f - exact).abs() < 1e-10 * exact,
            "node {j}: {f} vs {exact}"
        );
    }
    assert!(load_transfer(&nodes, &[0.0, 50.0, 40.0]).is_err());
}

#[test]
fn rigid_quoin_reaction_is_plausible() {
    let (model, cg) = coarse();
    let r = model.rigid_quoin_response(cg, 744.0, 24.0).unwrap();
    let m = cg.n_quoin_nodes();
    let l = model.config().geometry.leaf_length;
    let w = GAMMA * l * (744.0f64.powi(2) - 24.0f64.powi(2)) / 2.0;
    let phi = model.config().geometry.miter_angle_deg.to_radians();
    let pn: f64 = r.nodal_forces[..m].iter().sum();
    let pt: f64 = r.nodal_forces[m..].iter().sum();
    // three-hinged-arch statics with the resultant at mid-length: P_n = W cos φ / (2 sin φ),
    // P_t = −W/2; the pintle and gudgeon take a few percent, hence 5 %
    assert!(
        (pn / (w / (2.0 * phi.tan())) - 1.0).abs() < 0.05,
        "P_n {pn}"
    );
    assert!((pt / (-0.5 * w) - 1.0).abs() < 0.05, "P_t {pt}");
    // the quoin is held: its displacements vanish up to round-off (scale: 1e-2 in)
    let dmax = r
        .quoin_displacements
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(dmax < 1e-9, "{dmax}");
    // the girder gauges are in compression of a few hundred microstrain
    for (k, e) in r.strains.iter().enumerate().take(5) {
        assert!(*e < -100.0 && *e > -1000.0, "gauge {k}: {e}");
    }
}

#[test]
fn supports_missing_a_rigid_mode_are_reported() {
    let mesh = crate::fe::common::plate_mesh(10.0, 10.0, 2, 2, 0.1);
    // pins on one edge only: rotation about that edge (x axis) is free
    let supports: Vec<Support> = [0, 1, 2]
        .iter()
        .flat_map(|&node| (0..3).map(move |dof| Support::Fixed { node, dof }))
        .collect();
    match ShellModel::build(mesh, crate::fe::common::STEEL, 1e-3, supports) {
        Err(GateError::UnrestrainedRigidMode { mode }) => assert!(mode.contains("rx"), "{mode}"),
        other => panic!("expected UnrestrainedRigidMode, got {other:?}"),
    }
}

#[test]
fn unconnected_node_is_reported() {
    let mut mesh = crate::fe::common::plate_mesh(10.0, 10.0, 1, 1, 0.1);
    mesh.nodes.push([50.0, 50.0, 0.0]);
    let supports: Vec<Support> = [0, 1, 2, 3]
        .iter()
        .flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof }))
        .collect();
    match ShellModel::build(mesh, crate::fe::common::STEEL, 1e-3, supports) {
        Err(GateError::UnconnectedDof { node, .. }) => assert_eq!(node, 4),
        other => panic!("expected UnconnectedDof, got {other:?}"),
    }
}

#[test]
fn gauge_off_the_mesh_is_an_error() {
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = 120.0;
    cfg.gauges[0].location = mitergate::gate::config::GaugeLocation::Point {
        point: [100.0, 7.0, 300.0],
        side: [0.0, 1.0, 0.0],
    };
    match GateModel::build(&cfg) {
        Err(GateError::GaugeNotOnMesh { name, .. }) => assert_eq!(name, "SG1"),
        other => panic!("expected GaugeNotOnMesh, got {other:?}"),
    }
}

#[test]
fn bad_input_lengths_are_errors() {
    let (model, cg) = coarse();
    assert!(matches!(
        model.solve(&[1.0, 2.0]),
        Err(GateError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        model.quoin_line_load(&[1.0; 3], &cg.nu_points),
        Err(GateError::DimensionMismatch { .. })
    ));
    assert!(model.condense(1).is_err());
}
