//! Figures of the contact model on the default gate for `docs/mitergate.md`: normal and
//! tangential quoin line loads along the quoin for gap lengths θ = 0, 90 and 150 in at two
//! water-level pairs, and the true discrepancy of both paper scenarios (Eq. 53-54).
//!
//! `cargo run --release -p mitergate --example contact_figures -- docs/images`
use mitergate::data::truth::{self, Scenario};
use mitergate::{ContactModel, GateConfig, build_contact};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

type Curve = (String, RGBColor, Vec<(f64, f64)>);

fn plot(
    path: &Path,
    title: &str,
    ylabel: &str,
    curves: &[Curve],
) -> Result<(), Box<dyn std::error::Error>> {
    let ys = curves.iter().flat_map(|c| c.2.iter().map(|p| p.1));
    let (lo, hi) = ys.fold((f64::MAX, f64::MIN), |(a, b), y| (a.min(y), b.max(y)));
    let pad = 0.05 * (hi - lo).abs().max(1.0);
    let root = SVGBackend::new(path, (900, 540)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(0f64..762f64, (lo - pad)..(hi + pad))?;
    chart
        .configure_mesh()
        .x_desc("height on the quoin d_u (in)")
        .y_desc(ylabel)
        .draw()?;
    for (label, color, pts) in curves {
        let c = *color;
        chart
            .draw_series(LineSeries::new(
                pts.clone(),
                ShapeStyle::from(&c).stroke_width(2),
            ))?
            .label(label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

const COLORS: [RGBColor; 3] = [
    RGBColor(30, 90, 200),
    RGBColor(200, 60, 40),
    RGBColor(20, 150, 60),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "docs/images".into()),
    );
    std::fs::create_dir_all(&dir)?;
    let (contact, _) = build_contact(&GateConfig::default())?;
    for x in [[744.0, 24.0], [426.0, 120.0]] {
        contact_plots(&dir, &contact, x)?;
    }
    for k in [1u8, 2] {
        discrepancy_plot(&dir, &contact.gate().nu_points, k)?;
    }
    println!("wrote figures to {}", dir.display());
    Ok(())
}

/// `F_N` and `F_T` along the quoin at levels `x` for θ = 0, 90 and 150 in.
fn contact_plots(
    dir: &Path,
    contact: &ContactModel,
    x: [f64; 2],
) -> Result<(), Box<dyn std::error::Error>> {
    let d = &contact.gate().nu_points;
    let mut normal = Vec::new();
    let mut tangential = Vec::new();
    for (theta, c) in [0.0, 90.0, 150.0].into_iter().zip(COLORS) {
        let sol = contact.solve(x[0], x[1], theta)?;
        let label = format!("θ = {theta} in");
        normal.push((
            label.clone(),
            c,
            d.iter()
                .copied()
                .zip(sol.normal().iter().copied())
                .collect(),
        ));
        tangential.push((
            label,
            c,
            d.iter()
                .copied()
                .zip(sol.tangential().iter().copied())
                .collect(),
        ));
    }
    let tag = format!("{}_{}", x[0], x[1]);
    plot(
        &dir.join(format!("contact_normal_{tag}.svg")),
        &format!(
            "Normal quoin force F_N, h_up = {} in, h_down = {} in",
            x[0], x[1]
        ),
        "F_N (lbf/in)",
        &normal,
    )?;
    plot(
        &dir.join(format!("contact_tangential_{tag}.svg")),
        &format!(
            "Tangential quoin force F_T, h_up = {} in, h_down = {} in",
            x[0], x[1]
        ),
        "F_T (lbf/in)",
        &tangential,
    )
}

/// The true discrepancy (Eq. 53-54) of paper scenario `k` at the points `d`.
fn discrepancy_plot(dir: &Path, d: &[f64], k: u8) -> Result<(), Box<dyn std::error::Error>> {
    let nu = d.len();
    let sc = Scenario::paper(k)?;
    let x = if k == 1 {
        [738.0, 360.0]
    } else {
        [426.0, 120.0]
    };
    let delta = truth::true_discrepancy(x, d, sc.theta_true, sc.discrepancy_scale);
    let curves = vec![
        (
            "δ_N (Eq. 53)".to_string(),
            COLORS[0],
            d.iter().copied().zip(delta[..nu].iter().copied()).collect(),
        ),
        (
            "δ_T (Eq. 54)".to_string(),
            COLORS[1],
            d.iter().copied().zip(delta[nu..].iter().copied()).collect(),
        ),
    ];
    plot(
        &dir.join(format!("true_discrepancy_scenario{k}.svg")),
        &format!(
            "True discrepancy, scenario {k} (θ* = {} in), h_up = {}, h_down = {}",
            sc.theta_true, x[0], x[1]
        ),
        "δ (lbf/in)",
        &curves,
    )
}
