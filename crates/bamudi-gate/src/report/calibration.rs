//! Report writer: `results.json`, `report.md` and SVG plots.
//!
//! # `results.json` schema (version 1)
//!
//! ```text
//! {
//!   "schema_version": 1,
//!   "estimator": "exact_linear" | "ridge" | "lstm",
//!   "training_pool_size": int,                 // distinct x in the Eq.-27 training set
//!   "rho": { "rho_star": f, "objective_at_star": f,
//!            "curve": [ { "rho": f, "objective": f, "sum_squares": f, "likelihood": f } ] },
//!   "sigma_eps": { "value": f, "estimated": bool },   // output units (e.g. microstrain)
//!   "theta": {
//!     "prior_bounds": [[lo, hi], ...],
//!     "with_discrepancy":    { "method": "grid" | "mcmc", "mean": [f], "sd": [f], "ci95": [[lo, hi]],
//!                              "rhat": [f] | null, "ess": [f] | null },
//!     "without_discrepancy": { same fields }
//!   },
//!   "alpha_hat": [[f; K]; N_e],                  // Eq. 32, rows = experiments
//!   "gp": [ { "coefficient": k, "noise_variance": f, "log_marginal_likelihood": f } ],
//!   "covariance": { "size": N_s, "log_det": f, "jitter": f },
//!   "timings_s": { "training_set_s": f, "estimator_s": f, "rho_s": f, "gp_s": f, "module3_s": f }
//! }
//! ```

use crate::error::{GateAppError, Result};
use bamudi::module2::estimator::CoefficientEstimator;
use bamudi::module3::likelihood::FactorReport;
use bamudi::{Calibration, ThetaPosterior, Timings};
use plotters::prelude::*;
use serde::Serialize;
use std::path::Path;

/// One posterior in `results.json`.
#[derive(Debug, Clone, Serialize)]
pub struct PosteriorSummary {
    /// `grid` or `mcmc`.
    pub method: &'static str,
    /// Mean per dimension.
    pub mean: Vec<f64>,
    /// Standard deviation per dimension.
    pub sd: Vec<f64>,
    /// 95% intervals.
    pub ci95: Vec<(f64, f64)>,
    /// Split-R̂ (MCMC only).
    pub rhat: Option<Vec<f64>>,
    /// Effective sample sizes (MCMC only).
    pub ess: Option<Vec<f64>>,
}

impl PosteriorSummary {
    fn new(p: &ThetaPosterior) -> Self {
        let (method, rhat, ess) = match p {
            ThetaPosterior::Grid(_) => ("grid", None, None),
            ThetaPosterior::Mcmc(m) => ("mcmc", Some(m.rhat.clone()), Some(m.ess.clone())),
        };
        Self {
            method,
            mean: p.mean(),
            sd: p.sd(),
            ci95: p.ci95(),
            rhat,
            ess,
        }
    }
}

/// The `results.json` document (see the module docs for the schema).
#[derive(Debug, Clone, Serialize)]
pub struct Results {
    schema_version: u32,
    estimator: &'static str,
    training_pool_size: usize,
    rho: serde_json::Value,
    sigma_eps: serde_json::Value,
    theta: serde_json::Value,
    alpha_hat: Vec<Vec<f64>>,
    gp: Vec<serde_json::Value>,
    covariance: FactorReport,
    timings_s: Timings,
}

impl Results {
    /// Builds the summary of a calibration.
    pub fn new(cal: &Calibration, prior_bounds: &[(f64, f64)]) -> Self {
        let (m2, m3) = (cal.module2(), cal.module3());
        let curve: Vec<serde_json::Value> = m2
            .rho
            .grid
            .iter()
            .zip(&m2.rho.likelihood)
            .map(|(p, l)| serde_json::json!({ "rho": p.rho, "objective": p.objective, "sum_squares": p.sum_squares, "likelihood": l }))
            .collect();
        Self {
            schema_version: 1,
            estimator: m2.estimator.name(),
            training_pool_size: m2.training_pool_size,
            rho: serde_json::json!({ "rho_star": cal.rho_star(), "objective_at_star": m2.rho.objective_at_star, "curve": curve }),
            sigma_eps: serde_json::json!({ "value": m3.sigma_eps, "estimated": m3.sigma_eps_estimated }),
            theta: serde_json::json!({
                "prior_bounds": prior_bounds,
                "with_discrepancy": PosteriorSummary::new(&m3.posterior),
                "without_discrepancy": PosteriorSummary::new(&m3.posterior_no_discrepancy),
            }),
            alpha_hat: cal.alpha_hat().row_iter().map(|r| r.iter().copied().collect()).collect(),
            gp: cal
                .coefficient_gps()
                .models
                .iter()
                .enumerate()
                .map(|(k, m)| serde_json::json!({ "coefficient": k, "noise_variance": m.noise_variance(), "log_marginal_likelihood": m.log_marginal_likelihood() }))
                .collect(),
            covariance: m3.covariance,
            timings_s: cal.timings().clone(),
        }
    }
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> GateAppError + '_ {
    move |source| GateAppError::Io {
        path: path.display().to_string(),
        source,
    }
}

fn plot_err(file: &Path) -> impl Fn(String) -> GateAppError + '_ {
    move |reason| GateAppError::plot(file, reason)
}

fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = vals
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = 0.05 * (hi - lo).max(1e-12 * (1.0 + hi.abs()));
    (lo - pad, hi + pad)
}

/// A line plot of several named series on one chart.
pub fn line_plot(
    file: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(&str, Vec<(f64, f64)>)],
) -> Result<()> {
    let perr = plot_err(file);
    let root = SVGBackend::new(file, (800, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| perr(e.to_string()))?;
    let xr = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.0)));
    let yr = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
        .map_err(|e| perr(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()
        .map_err(|e| perr(e.to_string()))?;
    let colors = [BLUE, RED, BLACK, GREEN, MAGENTA, CYAN];
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = colors[i % colors.len()];
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(|e| perr(e.to_string()))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| perr(e.to_string()))?;
    root.present().map_err(|e| perr(e.to_string()))
}

/// Discrepancy (or response) reconstruction at one `x`: mean, 95% band, optional truth.
pub fn band_plot(
    file: &Path,
    title: &str,
    coords: &[f64],
    band: &bamudi::Band,
    truth: Option<&[f64]>,
) -> Result<()> {
    let n = coords.len();
    let comps = band.mean.len() / n.max(1);
    let mut series = Vec::new();
    let names: Vec<String> = (0..comps)
        .flat_map(|c| {
            [
                format!("mean c{c}"),
                format!("2.5% c{c}"),
                format!("97.5% c{c}"),
                format!("truth c{c}"),
            ]
        })
        .collect();
    for c in 0..comps {
        let pick =
            |v: &[f64]| -> Vec<(f64, f64)> { (0..n).map(|b| (coords[b], v[c * n + b])).collect() };
        series.push((names[4 * c].as_str(), pick(&band.mean)));
        series.push((names[4 * c + 1].as_str(), pick(&band.lower)));
        series.push((names[4 * c + 2].as_str(), pick(&band.upper)));
        if let Some(t) = truth {
            series.push((names[4 * c + 3].as_str(), pick(t)));
        }
    }
    line_plot(file, title, "coordinate d_u", "value", &series)
}

/// Writes `results.json`, `report.md`, `rho_curve.svg`, `theta_posterior.svg` (grid posteriors
/// only) and `gp_coefficients.svg` into `dir` (created if needed).
pub fn write_report(cal: &Calibration, prior: &dyn mlmodel::Prior, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let results = Results::new(cal, &prior.bounds());
    let path = dir.join("results.json");
    let text = serde_json::to_string_pretty(&results).map_err(|e| GateAppError::Serde {
        context: path.display().to_string(),
        reason: e.to_string(),
    })?;
    bamudi::data::write_atomic(&path, text.as_bytes())?;
    plot_rho(cal, &dir.join("rho_curve.svg"))?;
    plot_theta(cal, prior, &dir.join("theta_posterior.svg"))?;
    plot_gp_coefficients(cal, &dir.join("gp_coefficients.svg"))?;
    let md = report_markdown(cal, &results);
    Ok(bamudi::data::write_atomic(
        &dir.join("report.md"),
        md.as_bytes(),
    )?)
}

/// The normalised likelihood of `ρ` (Eq. 30, Fig. 13).
fn plot_rho(cal: &Calibration, path: &Path) -> Result<()> {
    let rho = &cal.module2().rho;
    let pts: Vec<(f64, f64)> = rho
        .grid
        .iter()
        .zip(&rho.likelihood)
        .map(|(p, l)| (p.rho, *l))
        .collect();
    line_plot(
        path,
        "Normalised likelihood of rho (Eq. 30)",
        "rho",
        "density",
        &[("L(rho)", pts)],
    )
}

/// The `θ` posteriors with and without the discrepancy and the prior (Fig. 16; grid
/// posteriors only).
fn plot_theta(cal: &Calibration, prior: &dyn mlmodel::Prior, path: &Path) -> Result<()> {
    let m3 = cal.module3();
    let (ThetaPosterior::Grid(w), ThetaPosterior::Grid(wo)) =
        (&m3.posterior, &m3.posterior_no_discrepancy)
    else {
        return Ok(());
    };
    let prior_pts: Vec<(f64, f64)> = w
        .theta
        .iter()
        .map(|t| (*t, prior.ln_pdf(&[*t]).exp()))
        .collect();
    let curve = |g: &bamudi::module3::posterior::GridPosterior| -> Vec<(f64, f64)> {
        g.theta
            .iter()
            .copied()
            .zip(g.density.iter().copied())
            .collect()
    };
    line_plot(
        path,
        "Posterior of theta (Fig. 16)",
        "theta",
        "density",
        &[
            ("with discrepancy", curve(w)),
            ("without discrepancy", curve(wo)),
            ("prior", prior_pts),
        ],
    )
}

/// Coefficient estimates and GP means along the first input, at the experiments (Fig. 14).
fn plot_gp_coefficients(cal: &Calibration, path: &Path) -> Result<()> {
    let x = cal.x_experiments();
    let gps = cal.coefficient_gps();
    let (mu, _) = gps.predict(x)?;
    let mut order: Vec<usize> = (0..x.nrows()).collect();
    order.sort_by(|a, b| x[(*a, 0)].total_cmp(&x[(*b, 0)]));
    let names: Vec<String> = (0..gps.len())
        .flat_map(|k| [format!("alpha_hat {k}"), format!("GP mean {k}")])
        .collect();
    let mut series = Vec::new();
    for k in 0..gps.len() {
        let along = |v: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
            order.iter().map(|&i| (x[(i, 0)], v(i))).collect()
        };
        series.push((names[2 * k].as_str(), along(&|i| cal.alpha_hat()[(i, k)])));
        series.push((names[2 * k + 1].as_str(), along(&|i| mu[(i, k)])));
    }
    line_plot(
        path,
        "Coefficient estimates and GP means (Fig. 14)",
        &cal.input_names()[0],
        "alpha",
        &series,
    )
}

fn report_markdown(cal: &Calibration, _r: &Results) -> String {
    let (m2, m3) = (cal.module2(), cal.module3());
    let mut s = String::from("# BA-MUDI calibration report\n\n");
    s += &format!(
        "* estimator: `{}` (training pool: {} distinct x)\n",
        m2.estimator.name(),
        m2.training_pool_size
    );
    s += &format!(
        "* rho* = {:.4} (Eq. 30 objective {:.4})\n",
        cal.rho_star(),
        m2.rho.objective_at_star
    );
    s += &format!(
        "* sigma_eps = {:.4} ({})\n",
        m3.sigma_eps,
        if m3.sigma_eps_estimated {
            "estimated from Module-2 residuals"
        } else {
            "configured"
        }
    );
    s += &format!(
        "* covariance V: {} x {}, ln|V| = {:.3}, jitter = {:e}\n\n",
        m3.covariance.size, m3.covariance.size, m3.covariance.log_det, m3.covariance.jitter
    );
    s += "| posterior of theta | mean | sd | 95% interval |\n|---|---|---|---|\n";
    for (name, p) in [
        ("with discrepancy", &m3.posterior),
        ("without discrepancy", &m3.posterior_no_discrepancy),
    ] {
        for j in 0..p.mean().len() {
            let ci = p.ci95()[j];
            s += &format!(
                "| {name} [{j}] | {:.4} | {:.4} | [{:.4}, {:.4}] |\n",
                p.mean()[j],
                p.sd()[j],
                ci.0,
                ci.1
            );
        }
    }
    let t = cal.timings();
    s += &format!(
        "\n| step | seconds |\n|---|---|\n| training set (Eq. 27) | {:.2} |\n| estimator fit (Eq. 29) | {:.2} |\n| rho search (Eq. 30-32) | {:.2} |\n| GPs (Eq. 33-37) | {:.2} |\n| Module 3 | {:.2} |\n",
        t.training_set_s, t.estimator_s, t.rho_s, t.gp_s, t.module3_s
    );
    s += "\nPlots: `rho_curve.svg`, `theta_posterior.svg`, `gp_coefficients.svg`.\n";
    s
}
