//! SVG figure of the gate mesh (elevation and plan), with gauges, quoin and supports marked.

use crate::GateError;
use crate::mesh::Member;
use crate::model::GateModel;
use plotters::prelude::*;
use std::path::Path;

/// Draws the mesh of `model` to an SVG file: an elevation (`x`–`z`, seen from downstream) and a
/// plan (`x`–`y`, `y` exaggerated), elements coloured by member (skin grey, girders blue,
/// diaphragms and end posts orange, bearing webs purple), gauges as red dots, quoin bearing
/// nodes blue, miter bearing nodes green, pintle and gudgeon black.
///
/// ```no_run
/// use mitergate::{GateConfig, GateModel, plot_mesh};
/// let model = GateModel::build(&GateConfig::default()).unwrap();
/// plot_mesh(&model, std::path::Path::new("gate_mesh.svg")).unwrap();
/// ```
pub fn plot_mesh(model: &GateModel, path: &Path) -> Result<(), GateError> {
    draw(model, path).map_err(|message| GateError::Plot {
        path: path.to_path_buf(),
        message,
    })
}

fn colour(m: Member) -> RGBColor {
    match m {
        Member::Skin => RGBColor(170, 170, 170),
        Member::GirderWeb(_) | Member::GirderFlange(_) => RGBColor(40, 90, 200),
        Member::Diaphragm(_) | Member::QuoinPlate | Member::MiterPlate => RGBColor(230, 130, 20),
        Member::QuoinBearingWeb | Member::MiterBearingWeb => RGBColor(140, 60, 170),
    }
}

type View<'a, 'b> = (
    &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    usize,
    (f64, f64),
    &'static str,
);

fn draw(model: &GateModel, path: &Path) -> Result<(), String> {
    let e = |err: &dyn std::fmt::Display| err.to_string();
    let g = &model.config().geometry;
    let (l, h, d) = (g.leaf_length, g.quoin_height, g.depth);
    let root = SVGBackend::new(path, (1100, 1200)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let (top, bottom) = root.split_vertically(880);
    let mesh = &model.mesh().shell;
    let members = &model.mesh().members;
    let gauges = model.gauge_points();
    let names = model.gauge_names();
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
    for (area, vert, yr, title) in views {
        let mut chart = ChartBuilder::on(area)
            .caption(title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(-0.05 * l..1.05 * l, yr.0..yr.1)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x from the quoin (in)")
            .draw()
            .map_err(|x| e(&x))?;
        // skin first so that framing draws on top
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
                .map_err(|x| e(&x))?;
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
                .map_err(|x| e(&x))?;
        }
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
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}
