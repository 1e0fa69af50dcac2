//! Writes the mesh figure of the default gate used in docs/mitergate.md: an elevation (`x`–`z`,
//! seen from downstream) and a plan (`x`–`y`, `y` exaggerated), elements coloured by member
//! (skin grey, girders blue, diaphragms and end posts orange, bearing webs purple), gauges as
//! red dots, quoin bearing nodes blue, miter bearing nodes green, pintle and gudgeon black.
//!
//! `cargo run --release -p mitergate --example plot_gate -- docs/images/mitergate_mesh.svg [element size]`
use mitergate::gate::Member;
use mitergate::{GateConfig, GateModel};
use plotters::prelude::*;
use std::path::Path;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "mitergate_mesh.svg".into());
    let mut cfg = GateConfig::default();
    if let Some(size) = args.next().and_then(|s| s.parse().ok()) {
        cfg.mesh.element_size = size;
    }
    let model = GateModel::build(&cfg).expect("build the gate");
    if let Err(message) = draw(&model, Path::new(&path)) {
        eprintln!("plotting to {path} failed: {message}");
        std::process::exit(1);
    }
    println!("wrote {path}");
}

fn colour(m: Member) -> RGBColor {
    match m {
        Member::Skin => RGBColor(170, 170, 170),
        Member::GirderWeb(_) | Member::GirderFlange(_) => RGBColor(40, 90, 200),
        Member::Diaphragm(_) | Member::QuoinPlate | Member::MiterPlate => RGBColor(230, 130, 20),
        Member::QuoinBearingWeb | Member::MiterBearingWeb => RGBColor(140, 60, 170),
    }
}

/// One panel: drawing area, index of the vertical coordinate (2: `z`, 1: `y`), its range and
/// the title.
type View<'a, 'b> = (
    &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    usize,
    (f64, f64),
    &'static str,
);

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

fn draw(model: &GateModel, path: &Path) -> Result<(), String> {
    let g = &model.config().geometry;
    let (h, d) = (g.quoin_height, g.depth);
    let root = SVGBackend::new(path, (1100, 1200)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (top, bottom) = root.split_vertically(880);
    let views: [View; 2] = [
        (
            &top,
            2,
            (-0.05 * h, 1.05 * h),
            "Elevation (x-z) seen from downstream; z up from the sill (in)",
        ),
        (
            &bottom,
            1,
            (-0.2 * d, 1.2 * d),
            "Plan (x-y), y exaggerated; skin plate at y = 0, flanges at y = depth (in)",
        ),
    ];
    for view in views {
        draw_view(model, view)?;
    }
    root.present().map_err(err)
}

/// Elements (skin first, so that the framing draws on top), node marks and gauges of one
/// panel.
fn draw_view(model: &GateModel, (area, vert, yr, title): View) -> Result<(), String> {
    let l = model.config().geometry.leaf_length;
    let mesh = &model.mesh().shell;
    let members = &model.mesh().members;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(30)
        .y_label_area_size(45)
        .build_cartesian_2d(-0.05 * l..1.05 * l, yr.0..yr.1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x from the quoin (in)")
        .draw()
        .map_err(err)?;
    let mut order: Vec<usize> = (0..mesh.elements.len()).collect();
    order.sort_by_key(|&i| members[i] != Member::Skin);
    for i in order {
        let el = &mesh.elements[i];
        let mut pts: Vec<(f64, f64)> = el
            .nodes
            .iter()
            .map(|&n| (mesh.nodes[n][0], mesh.nodes[n][vert]))
            .collect();
        pts.push(pts[0]);
        chart
            .draw_series(std::iter::once(PathElement::new(
                pts,
                colour(members[i]).stroke_width(1),
            )))
            .map_err(err)?;
    }
    let marks = |nodes: &[usize]| {
        nodes
            .iter()
            .map(|&n| (mesh.nodes[n][0], mesh.nodes[n][vert]))
            .collect::<Vec<_>>()
    };
    let mm = model.mesh();
    for (pts, c, size) in [
        (marks(&mm.quoin_nodes), RGBColor(0, 60, 255), 3),
        (marks(&mm.miter_nodes), RGBColor(0, 160, 60), 3),
        (marks(&[mm.pintle_node, mm.gudgeon_node]), BLACK, 6),
    ] {
        chart
            .draw_series(pts.into_iter().map(|p| Circle::new(p, size, c.filled())))
            .map_err(err)?;
    }
    let (gauges, names) = (model.gauge_points(), model.gauge_names());
    chart
        .draw_series(gauges.iter().zip(&names).map(|(p, name)| {
            EmptyElement::at((p[0], p[vert]))
                + Circle::new((0, 0), 6, RED.filled())
                + Text::new(
                    name.clone(),
                    (8, -8),
                    ("sans-serif", 13).into_font().color(&RED),
                )
        }))
        .map_err(err)?;
    Ok(())
}
