//! Plots of the reproduction, equivalent to the paper's Fig. 13-22.
//!
//! Per scenario directory, for the headline calibration (the default marginal mode; its
//! name is in every title): `results.json`, `report.md`, `rho_curve.svg` (Fig. 13),
//! `gp_coefficients.svg` (Fig. 14) and `theta_posterior.svg` (Fig. 16) from
//! `bamudi_gate::report::calibration::write_report`; here `discrepancy_{normal,tangential}.svg`
//! (Fig. 15), `forces_{normal,tangential}.svg` (Fig. 17), `normal_force_error.svg` (Fig. 18)
//! and `history_{normal,tangential}.svg` (Fig. 21/22); `fatigue_damage.svg`, the prediction
//! level (quoin-block fatigue damage along the quoin, truth / before / after with its band). The strain errors of Fig. 19/20 are
//! tables in `reproduce-paper.md`, not a plot.

use anyhow::Result;
use bamudi::Calibration;
use bamudi_gate::paper::{ScenarioResult, prior_mean_response};
use mitergate::GateMultiLevel;
use mitergate::data::truth::{self, Scenario};
use plotters::prelude::*;
use rayon::prelude::*;
use std::path::Path;

pub(crate) use bamudi_gate::report::plot::Series;
use bamudi_gate::report::plot::{AFTER, Axes, BAND, BEFORE, NO_DELTA, TRUTH};

/// A labelled polyline in the shared style (an empty label stays out of the legend).
pub(crate) fn series(label: &str, color: RGBColor, xs: &[f64], ys: &[f64], dashed: bool) -> Series {
    let s = Series::xy(label, color, xs, ys);
    if dashed { s.dashed() } else { s }
}

/// The shared line plot (legend in its own strip, units in the labels).
pub(crate) fn line_plot(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    all: &[Series],
) -> Result<()> {
    bamudi_gate::report::plot::line_plot(path, &Axes::new(title, xlabel, ylabel), all)?;
    Ok(())
}

/// The 1-99 % quantile range of `values`, padded 10 %.
fn quantile_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.01), at(0.99));
    let pad = 0.1 * (hi - lo).max(1.0);
    (lo - pad, hi + pad)
}

/// Writes all plots of one scenario into `out/<scenario name>/`.
pub fn scenario_plots(
    out: &Path,
    res: &ScenarioResult,
    cal: &Calibration,
    model: &GateMultiLevel,
    opts: &bamudi_gate::paper::ReproduceOptions,
) -> Result<()> {
    let dir = out.join(res.name.replace(' ', "-"));
    let inputs = bamudi_gate::report::calibration::ReportInputs {
        config: "cargo xtask reproduce-paper (the paper's Table 1 settings)".into(),
        data: format!(
            "{} synthetic experiments of {} (Eq. 48, 53-54), truth θ* = {} in",
            opts.n_experiments, res.name, res.theta_true
        ),
        gate: "embedded default gate".into(),
        element_size_in: Some(
            opts.mesh_element_size
                .unwrap_or(mitergate::GateConfig::default().mesh.element_size),
        ),
        gap_prior_in: model.prior.bounds()[0],
        seed: opts.seed,
        theta_true: Some(res.theta_true),
        warnings: vec![],
    };
    bamudi_gate::report::calibration::write_report(cal, model.prior.as_ref(), &inputs, &dir)?;
    let number = if res.theta_true < 120.0 { 1 } else { 2 };
    let scenario = Scenario::paper(number)?;
    let contact = model.unobservable.inner().contact();
    let d = contact.gate().nu_points.clone();
    let nu = d.len();
    // The paper's plotting conditions (Fig. 15, 17): (738, 360) for S1, (426, 120) for S2.
    let x = bamudi_gate::paper::figures::condition(number);
    let truth_f = truth::true_forces(&scenario, contact, x)?;
    let curve =
        bamudi_gate::paper::figures::discrepancy_curve(model, cal, &scenario, contact, number)?;
    let (delta, disc) = (&curve.truth, &curve.band);
    let predictor = cal.predictor(model)?;
    let resp = predictor.response(&x)?;
    let before = prior_mean_response(model, &x)?;
    let mode = bamudi_gate::coverage::mode_label(cal.config().coefficients.kind());
    for (c, name) in [(0usize, "normal"), (1, "tangential")] {
        let r = c * nu..(c + 1) * nu;
        line_plot(
            &dir.join(format!("discrepancy_{name}.svg")),
            &format!(
                "{}, {mode}: {name} force discrepancy at h_up = {} in, h_down = {} in (Fig. 15)",
                res.name, x[0], x[1]
            ),
            "height on the quoin d_u (in)",
            "discrepancy (lbf/in)",
            &[
                series("true δ (Eq. 53-54)", TRUTH, &d, &delta[r.clone()], false),
                series("BA-MUDI mean", AFTER, &d, &disc.mean[r.clone()], false),
                series("95 % band", BAND, &d, &disc.lower[r.clone()], true),
                series("", BAND, &d, &disc.upper[r.clone()], true),
            ],
        )?;
        let all = [
            series("truth ρ g + δ", TRUTH, &d, &truth_f[r.clone()], false),
            series(
                "before (prior mean, ρ = 1, no δ)",
                BEFORE,
                &d,
                &before[r.clone()],
                true,
            ),
            series(
                "after BA-MUDI (Eq. 52)",
                AFTER,
                &d,
                &resp.mean[r.clone()],
                false,
            ),
            series("95 % band", BAND, &d, &resp.lower[r.clone()], true),
            series("", BAND, &d, &resp.upper[r.clone()], true),
        ];
        let mut axes = Axes::new(
            &format!(
                "{}, {mode}: total {name} force at h_up = {} in, h_down = {} in (Fig. 17)",
                res.name, x[0], x[1]
            ),
            "height on the quoin d_u (in)",
            "force (lbf/in)",
        );
        // the tangential force has a narrow peak at the contact edge (up to 1e6 lbf/in) that
        // would flatten the rest: the y range is the 1-99 % quantiles of the plotted values
        if c == 1 {
            axes.y_range = Some(quantile_range(
                all.iter().flat_map(|s| s.points.iter().map(|p| p.1)),
            ));
            axes.title.push_str(", peak clipped");
        }
        bamudi_gate::report::plot::line_plot(&dir.join(format!("forces_{name}.svg")), &axes, &all)?;
    }
    let plots = ScenarioPlots {
        dir,
        res,
        cal,
        model,
        scenario,
        number,
    };
    normal_force_error(&plots)?;
    force_history(&plots)?;
    fatigue_plot(&plots)
}

/// What the per-scenario plots below share.
struct ScenarioPlots<'a> {
    dir: std::path::PathBuf,
    res: &'a ScenarioResult,
    cal: &'a Calibration,
    model: &'a GateMultiLevel,
    scenario: Scenario,
    number: u8,
}

/// The prediction level: damage per 1,000 lockages along the quoin, truth, before and after
/// (with the band of the joint force draws).
fn fatigue_plot(p: &ScenarioPlots<'_>) -> Result<()> {
    use bamudi_gate::paper::fatigue;
    let contact = p.model.unobservable.inner().contact();
    let x = fatigue::condition(p.number);
    let seed = 700 + p.number as u64;
    let d = fatigue::damage_along_quoin(p.model, p.cal, &p.scenario, contact, x, seed)?;
    let mode = bamudi_gate::coverage::mode_label(p.cal.config().coefficients.kind());
    line_plot(
        &p.dir.join("fatigue_damage.svg"),
        &format!(
            "{}, {mode}: quoin-block fatigue damage of 1,000 lockages at h_up = {} in, h_down = {} in",
            p.res.name, x[0], x[1]
        ),
        "height on the quoin d_u (in)",
        "Miner damage per 1,000 lockages",
        &[
            series("truth", TRUTH, &d.z_in, &d.truth, false),
            series("before (nominal model)", BEFORE, &d.z_in, &d.before, true),
            series("after BA-MUDI", AFTER, &d.z_in, &d.after.mean, false),
            series("95 % band", BAND, &d.z_in, &d.after.lower, true),
            series("", BAND, &d.z_in, &d.after.upper, true),
        ],
    )
}

/// Fig. 18: normal-force RMSE over the quoin, along one water level with the other fixed.
fn normal_force_error(p: &ScenarioPlots<'_>) -> Result<()> {
    let (dir, res, cal, model) = (&p.dir, p.res, p.cal, p.model);
    let (scenario, number) = (&p.scenario, p.number);
    let contact = model.unobservable.inner().contact();
    let nu = contact.gate().n_points();
    let (levels, xs): (Vec<f64>, Vec<[f64; 2]>) = if number == 1 {
        let l: Vec<f64> = (0..25).map(|i| 24.0 + 690.0 * i as f64 / 24.0).collect();
        (l.clone(), l.iter().map(|&h| [738.0, h]).collect())
    } else {
        let l: Vec<f64> = (0..25).map(|i| 130.0 + 610.0 * i as f64 / 24.0).collect();
        (l.clone(), l.iter().map(|&h| [h, 120.0]).collect())
    };
    let predictor = cal.predictor(model)?;
    let errors: Vec<(f64, f64)> = xs
        .par_iter()
        .map(|x| -> Result<(f64, f64)> {
            let t = truth::true_forces(scenario, contact, *x)?;
            let b = prior_mean_response(model, x)?;
            let (a, _) = predictor.response_moments(x)?;
            let r = |p: &[f64]| {
                ((0..nu).map(|i| (p[i] - t[i]).powi(2)).sum::<f64>() / nu as f64).sqrt()
            };
            Ok((r(&b), r(&a)))
        })
        .collect::<Vec<_>>() // every row first: an error is then the first in their order
        .into_iter()
        .collect::<Result<_>>()?;
    let (eb, ea): (Vec<f64>, Vec<f64>) = errors.into_iter().unzip();
    let xl = if number == 1 {
        "downstream level h_down (in), h_up = 738 in"
    } else {
        "upstream level h_up (in), h_down = 120 in"
    };
    line_plot(
        &dir.join("normal_force_error.svg"),
        &format!(
            "{}, {}: normal-force RMSE over the quoin (Fig. 18)",
            res.name,
            bamudi_gate::coverage::mode_label(cal.config().coefficients.kind())
        ),
        xl,
        "RMSE (lbf/in)",
        &[
            series("before BA-MUDI", BEFORE, &levels, &eb, true),
            series("after BA-MUDI", AFTER, &levels, &ea, false),
        ],
    )
}

/// Fig. 22: forces at location A (a quarter of the quoin height) over a week of lockages,
/// with the corrected force's band and the best fit without a discrepancy
/// ([`bamudi_gate::paper::figures::force_history`], whose numbers the report tabulates).
fn force_history(p: &ScenarioPlots<'_>) -> Result<()> {
    let (dir, res, cal, model, scenario) = (&p.dir, p.res, p.cal, p.model, &p.scenario);
    let contact = model.unobservable.inner().contact();
    let h = bamudi_gate::paper::figures::force_history(model, cal, scenario, contact)?;
    let col = |k: usize, c: usize| -> Vec<f64> { h.rows.iter().map(|r| r[k][c]).collect() };
    let mode = bamudi_gate::coverage::mode_label(cal.config().coefficients.kind());
    for (c, name) in [(0usize, "normal"), (1, "tangential")] {
        line_plot(
            &dir.join(format!("history_{name}.svg")),
            &format!(
                "{}, {mode}: {name} force at location A (d_u = {:.0} in) over a week (Fig. 22)",
                res.name, h.location.1
            ),
            "time (h)",
            "force (lbf/in)",
            &[
                series("truth", TRUTH, &h.hours, &col(0, c), false),
                series("before", BEFORE, &h.hours, &col(1, c), true),
                series(
                    "without discrepancy (ρ, θ fitted)",
                    NO_DELTA,
                    &h.hours,
                    &col(2, c),
                    true,
                ),
                series("after BA-MUDI", AFTER, &h.hours, &col(3, c), false),
                series("95 % band", BAND, &h.hours, &col(4, c), true),
                series("", BAND, &h.hours, &col(5, c), true),
            ],
        )?;
    }
    Ok(())
}
