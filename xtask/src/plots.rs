//! Plots of the reproduction, equivalent to the paper's Fig. 13-22.
//!
//! Per scenario directory: `results.json`, `report.md`, `rho_curve.svg` (Fig. 13),
//! `gp_coefficients.svg` (Fig. 14) and `theta_posterior.svg` (Fig. 16) from
//! `bamudi_gate::report::calibration::write_report`; here `discrepancy.svg` (Fig. 15), `forces.svg` (Fig. 17),
//! `normal_force_error.svg` (Fig. 18), `strain_errors.svg` (Fig. 19/20) and
//! `force_history.svg` (Fig. 21/22).

use anyhow::{Result, anyhow};
use bamudi::Calibration;
use bamudi_gate::paper::ScenarioResult;
use mitergate::GateMultiLevel;
use mitergate::data::truth::{self, Scenario};
use mlmodel::UnobservableModel;
use plotters::prelude::*;
use std::path::Path;

/// One labelled polyline.
pub(crate) struct Series {
    label: String,
    color: RGBColor,
    points: Vec<(f64, f64)>,
    dashed: bool,
}

pub(crate) fn series(label: &str, color: RGBColor, xs: &[f64], ys: &[f64], dashed: bool) -> Series {
    Series {
        label: label.into(),
        color,
        points: xs.iter().copied().zip(ys.iter().copied()).collect(),
        dashed,
    }
}

pub(crate) fn line_plot(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    all: &[Series],
) -> Result<()> {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for s in all {
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    let pad = 0.05 * (y1 - y0).abs().max(1e-9);
    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1.max(x0 + 1e-9), (y0 - pad)..(y1 + pad))
        .map_err(|e| anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
        .y_desc(ylabel)
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    for s in all {
        let style = ShapeStyle::from(&s.color).stroke_width(2);
        let color = s.color;
        if s.dashed {
            chart
                .draw_series(DashedLineSeries::new(s.points.clone(), 6, 4, style))
                .map_err(|e| anyhow!("{e}"))?
                .label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
        } else {
            chart
                .draw_series(LineSeries::new(s.points.clone(), style))
                .map_err(|e| anyhow!("{e}"))?
                .label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| anyhow!("{e}"))?;
    root.present().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

const TRUE_C: RGBColor = RGBColor(0, 0, 0);
const BEFORE_C: RGBColor = RGBColor(200, 60, 40);
const AFTER_C: RGBColor = RGBColor(30, 90, 200);
const BAND_C: RGBColor = RGBColor(120, 160, 230);

fn prior_mean(model: &GateMultiLevel, x: &[f64]) -> Result<Vec<f64>> {
    let rule = model.prior.quadrature(8)?;
    let n = model.unobservable.response_len();
    let (mut acc, mut g) = (vec![0.0; n], vec![0.0; n]);
    for (t, w) in rule.nodes.iter().zip(&rule.weights) {
        model.unobservable.evaluate(x, t, &mut g)?;
        acc.iter_mut().zip(&g).for_each(|(a, v)| *a += w * v);
    }
    Ok(acc)
}

/// Writes all plots of one scenario into `out/<scenario name>/`.
pub fn scenario_plots(
    out: &Path,
    res: &ScenarioResult,
    cal: &Calibration,
    model: &GateMultiLevel,
) -> Result<()> {
    let dir = out.join(res.name.replace(' ', "-"));
    bamudi_gate::report::calibration::write_report(cal, model.prior.as_ref(), &dir)?;
    let number = if res.theta_true < 120.0 { 1 } else { 2 };
    let scenario = Scenario::paper(number)?;
    let contact = model.unobservable.inner().contact();
    let d = contact.gate().nu_points.clone();
    let nu = d.len();
    // The paper's plotting conditions (Fig. 15, 17): (738, 360) for S1, (426, 120) for S2.
    let x = if number == 1 {
        [738.0, 360.0]
    } else {
        [426.0, 120.0]
    };
    let truth_f = truth::true_forces(&scenario, contact, x)?;
    let delta = truth::true_discrepancy(x, &d, scenario.theta_true, scenario.discrepancy_scale);
    let disc = cal.predictor(model)?.discrepancy(&x)?;
    let resp = cal.predictor(model)?.response(&x)?;
    let before = prior_mean(model, &x)?;
    for (c, name) in [(0usize, "normal"), (1, "tangential")] {
        let r = c * nu..(c + 1) * nu;
        line_plot(
            &dir.join(format!("discrepancy_{name}.svg")),
            &format!(
                "{}: {name} force discrepancy at h_up={}, h_down={} (Fig. 15)",
                res.name, x[0], x[1]
            ),
            "height on the quoin d_u (in)",
            "discrepancy (lbf/in)",
            &[
                series("true δ (Eq. 53-54)", TRUE_C, &d, &delta[r.clone()], false),
                series("BA-MUDI mean", AFTER_C, &d, &disc.mean[r.clone()], false),
                series("95% band", BAND_C, &d, &disc.lower[r.clone()], true),
                series("", BAND_C, &d, &disc.upper[r.clone()], true),
            ],
        )?;
        line_plot(
            &dir.join(format!("forces_{name}.svg")),
            &format!(
                "{}: total {name} force at h_up={}, h_down={} (Fig. 17)",
                res.name, x[0], x[1]
            ),
            "height on the quoin d_u (in)",
            "force (lbf/in)",
            &[
                series("truth ρ g + δ", TRUE_C, &d, &truth_f[r.clone()], false),
                series(
                    "before (prior mean, ρ=1, no δ)",
                    BEFORE_C,
                    &d,
                    &before[r.clone()],
                    true,
                ),
                series(
                    "after BA-MUDI (Eq. 52)",
                    AFTER_C,
                    &d,
                    &resp.mean[r.clone()],
                    false,
                ),
                series("95% band", BAND_C, &d, &resp.lower[r.clone()], true),
                series("", BAND_C, &d, &resp.upper[r.clone()], true),
            ],
        )?;
    }
    normal_force_error(&dir, res, cal, model, &scenario, number)?;
    force_history(&dir, res, cal, model, &scenario)?;
    Ok(())
}

/// Fig. 18: normal-force RMSE over the quoin, along one water level with the other fixed.
fn normal_force_error(
    dir: &Path,
    res: &ScenarioResult,
    cal: &Calibration,
    model: &GateMultiLevel,
    scenario: &Scenario,
    number: u8,
) -> Result<()> {
    let contact = model.unobservable.inner().contact();
    let nu = contact.gate().n_points();
    let (levels, xs): (Vec<f64>, Vec<[f64; 2]>) = if number == 1 {
        let l: Vec<f64> = (0..25).map(|i| 24.0 + 690.0 * i as f64 / 24.0).collect();
        (l.clone(), l.iter().map(|&h| [738.0, h]).collect())
    } else {
        let l: Vec<f64> = (0..25).map(|i| 130.0 + 610.0 * i as f64 / 24.0).collect();
        (l.clone(), l.iter().map(|&h| [h, 120.0]).collect())
    };
    let (mut eb, mut ea) = (vec![], vec![]);
    for x in &xs {
        let t = truth::true_forces(scenario, contact, *x)?;
        let b = prior_mean(model, x)?;
        let a = cal.predictor(model)?.response(x)?.mean;
        let r =
            |p: &[f64]| ((0..nu).map(|i| (p[i] - t[i]).powi(2)).sum::<f64>() / nu as f64).sqrt();
        eb.push(r(&b));
        ea.push(r(&a));
    }
    let xl = if number == 1 {
        "downstream level h_down (in), h_up = 738 in"
    } else {
        "upstream level h_up (in), h_down = 120 in"
    };
    line_plot(
        &dir.join("normal_force_error.svg"),
        &format!("{}: normal-force RMSE over the quoin (Fig. 18)", res.name),
        xl,
        "RMSE (lbf/in)",
        &[
            series("before BA-MUDI", BEFORE_C, &levels, &eb, true),
            series("after BA-MUDI", AFTER_C, &levels, &ea, false),
        ],
    )
}

/// Fig. 21/22: forces at location A (1/4 of the quoin height) over a week of lockages.
fn force_history(
    dir: &Path,
    res: &ScenarioResult,
    cal: &Calibration,
    model: &GateMultiLevel,
    scenario: &Scenario,
) -> Result<()> {
    let contact = model.unobservable.inner().contact();
    let d = &contact.gate().nu_points;
    let nu = d.len();
    let a_idx = d.partition_point(|&z| z < 0.25 * contact.gate().quoin_height);
    let hours: Vec<f64> = (0..=168).map(|h| h as f64).collect();
    let mut cols: [Vec<f64>; 6] = Default::default();
    for &h in &hours {
        let phase = (h / 8.0 * std::f64::consts::TAU).sin();
        let x = [
            560.0 + 150.0 * phase.max(-0.9),
            60.0 + 20.0 * (h / 24.0 * std::f64::consts::TAU).cos(),
        ];
        let t = truth::true_forces(scenario, contact, x)?;
        let b = prior_mean(model, &x)?;
        let a = cal.predictor(model)?.response(&x)?;
        for (c, off) in [(0usize, 0usize), (3, nu)] {
            cols[c].push(t[off + a_idx]);
            cols[c + 1].push(b[off + a_idx]);
            cols[c + 2].push(a.mean[off + a_idx]);
        }
    }
    for (c, name) in [(0usize, "normal"), (3, "tangential")] {
        line_plot(
            &dir.join(format!("history_{name}.svg")),
            &format!(
                "{}: {name} force at location A (d_u = {:.0} in) over a week (Fig. 22)",
                res.name, d[a_idx]
            ),
            "time (h)",
            "force (lbf/in)",
            &[
                series("truth", TRUE_C, &hours, &cols[c], false),
                series("before", BEFORE_C, &hours, &cols[c + 1], true),
                series("after BA-MUDI", AFTER_C, &hours, &cols[c + 2], false),
            ],
        )?;
    }
    Ok(())
}
