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
//!            "curve": [ { "rho": f, "objective": f, "sum_squares": f, "likelihood": f } ],
//!            "rho_projection": [mean, sd] | null },
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
//!   "timings_s": { "training_set_s": f, "estimator_s": f, "rho_s": f, "gp_s": f, "module3_s": f },
//!   "inputs": { "config": s, "data": s, "gate": s, "element_size_in": f or null (a deck), "gap_prior_in": [lo, hi],
//!               "seed": int, "version": s, "warnings": [s] }   // added, schema still 1
//!   "tolerances": [ { "name": s, "mean": f, "sd": f } ]  // declared tolerances only; added
//! }
//! ```

use super::plot::{
    AFTER, Axes, BEFORE, PRIOR, Series, TRUTH, draw_chart, draw_legend, line_plot, padded_range,
    svg_figure,
};
use crate::error::{GateAppError, Result};
use bamudi::posterior::FactorReport;
use bamudi::posterior::GridPosterior;
use bamudi::surrogate::CoefficientEstimator;
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

/// What a calibration was run on, stated in its reports (`results.json` key `inputs`, the
/// first section of `report.md`), with the warnings of its posterior.
#[derive(Debug, Clone, Serialize)]
pub struct ReportInputs {
    /// Configuration file (or a description of the configuration).
    pub config: String,
    /// Data file (or a description of the data).
    pub data: String,
    /// Gate configuration file, or `embedded default gate`.
    pub gate: String,
    /// Mesh element size (in); `None` for an imported deck (its own mesh).
    pub element_size_in: Option<f64>,
    /// Uniform prior of the gap (in).
    pub gap_prior_in: (f64, f64),
    /// Master seed.
    pub seed: u64,
    /// The true gap (in) when the data are synthetic and it is known (drawn in the plots).
    pub theta_true: Option<f64>,
    /// Warnings about the result (e.g. the posterior's, see
    /// [`bamudi::posterior::GridWarning`]).
    pub warnings: Vec<String>,
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
    inputs: serde_json::Value,
    /// The declared tolerances of the build with their posteriors, in their standard
    /// deviations (absent when none were declared).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    tolerances: Vec<bamudi::posterior::ToleranceEstimate>,
    /// The adequacy verdict and its checks (absent when disabled).
    #[serde(skip_serializing_if = "Option::is_none")]
    adequacy: Option<bamudi::AdequacyReport>,
}

impl Results {
    /// Builds the summary of a calibration.
    pub fn new(cal: &Calibration, prior_bounds: &[(f64, f64)], inputs: &ReportInputs) -> Self {
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
            rho: serde_json::json!({
                "rho_star": cal.rho_star(),
                "objective_at_star": m2.rho.objective_at_star,
                "curve": curve,
                "rho_projection": m3.marginal().map(|m| m.rho_projection),
            }),
            sigma_eps: serde_json::json!({ "value": m3.sigma_eps, "estimated": m3.sigma_eps_estimated }),
            theta: serde_json::json!({
                "prior_bounds": prior_bounds,
                "with_discrepancy": PosteriorSummary::new(&m3.posterior),
                "model_average": m3.averaged().map(|a| serde_json::json!({
                    "probability_without": a.probability_without,
                    "log_evidence_with": a.log_evidence_with,
                    "log_evidence_without": a.log_evidence_without,
                    "penalty": a.penalty,
                })),
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
            inputs: with_version(inputs),
            tolerances: m3
                .marginal()
                .map(|m| m.tolerances.clone())
                .unwrap_or_default(),
            adequacy: cal.adequacy().cloned(),
        }
    }
}

/// The inputs as JSON with the program version.
fn with_version(inputs: &ReportInputs) -> serde_json::Value {
    let mut v = serde_json::to_value(inputs).unwrap_or_default();
    if let Some(m) = v.as_object_mut() {
        m.insert("version".into(), env!("CARGO_PKG_VERSION").into());
    }
    v
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> GateAppError + '_ {
    move |source| GateAppError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Writes `results.json`, `report.md`, `rho_curve.svg`, `theta_posterior.svg` (grid posteriors
/// only) and `gp_coefficients.svg` into `dir` (created if needed).
pub fn write_report(
    cal: &Calibration,
    prior: &dyn mlmodel::Prior,
    inputs: &ReportInputs,
    dir: &Path,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let results = Results::new(cal, &prior.bounds(), inputs);
    let path = dir.join("results.json");
    let text = serde_json::to_string_pretty(&results).map_err(|e| GateAppError::Serde {
        context: path.display().to_string(),
        reason: e.to_string(),
    })?;
    bamudi::data::write_atomic(&path, text.as_bytes())?;
    plot_rho(cal, &dir.join("rho_curve.svg"))?;
    plot_theta(
        cal,
        prior,
        inputs.theta_true,
        &dir.join("theta_posterior.svg"),
    )?;
    plot_gp_coefficients(cal, &dir.join("gp_coefficients.svg"))?;
    let md = report_markdown(cal, inputs);
    Ok(bamudi::data::write_atomic(
        &dir.join("report.md"),
        md.as_bytes(),
    )?)
}

/// The force scale `ρ` (Fig. 13): in the marginal mode its posterior (a mixture over the `θ`
/// support of the Gaussians of `ρ` given `θ`), otherwise Module 2's normalised likelihood
/// (Eq. 30) zoomed to where it is above 1e-3 of its peak; Module 2's `ρ*` marked.
fn plot_rho(cal: &Calibration, path: &Path) -> Result<()> {
    let rho = &cal.module2().rho;
    let module2_star = rho.rho_star;
    let (title, pts) = match cal.module3().marginal() {
        Some(m) => (
            "Posterior of the force scale ρ (marginal mode)",
            rho_mixture(m),
        ),
        None => {
            let pts: Vec<(f64, f64)> = rho
                .grid
                .iter()
                .zip(&rho.likelihood)
                .map(|(p, l)| (p.rho, *l))
                .collect();
            (
                "Likelihood of the force scale ρ (Eq. 30, Fig. 13)",
                zoom_to_peak(pts),
            )
        }
    };
    let peak = pts.iter().fold(0.0f64, |m, p| m.max(p.1));
    let axes = Axes::new(
        title,
        "ρ (scale of the nominal contact force, dimensionless)",
        "density (1/ρ)",
    );
    let series = [
        Series::new("ρ", AFTER, pts),
        Series::new(
            &format!("Module 2 ρ* = {module2_star:.4} (Eq. 30)"),
            TRUTH,
            vec![(module2_star, 0.0), (module2_star, peak)],
        )
        .dashed(),
    ];
    line_plot(path, &axes, &series)
}

/// The points whose value is at least 1e-3 of the peak, with one neighbour on each side.
fn zoom_to_peak(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    let peak = pts.iter().fold(0.0f64, |m, p| m.max(p.1));
    let above: Vec<usize> = (0..pts.len())
        .filter(|&i| pts[i].1 >= 1e-3 * peak)
        .collect();
    match (above.first(), above.last()) {
        (Some(&lo), Some(&hi)) => pts[lo.saturating_sub(1)..(hi + 2).min(pts.len())].to_vec(),
        _ => pts,
    }
}

/// The marginal mode's `ρ` posterior with what its spread does not mean (`rho_curve.svg`
/// draws it): a `ρ` interval that the coverage study found to miss the simulator's `ρ` is not
/// offered as a claim.
fn rho_caveat(m: &bamudi::posterior::MarginalFit) -> String {
    let [p, p_sd] = m.rho_projection;
    format!(
        "* ρ⊥, the data's scale of the nominal force (the ρ that leaves the discrepancy's \
         strains orthogonal to the model's, fixed by the data): {p:.4} ± {p_sd:.4}. The split's \
         ρ in ρ g + δ (posterior mean {:.4}, `rho_curve.svg`) is not identified by the data — \
         a discrepancy along g is the same data as another ρ — and is not offered as an \
         interval. The gap's interval below is the checked claim \
         (docs/results/validation.md).\n",
        m.rho_mean
    )
}

/// The marginal mode's `ρ` posterior on 200 points over its mean ± 5 sd (within the prior).
fn rho_mixture(m: &bamudi::posterior::MarginalFit) -> Vec<(f64, f64)> {
    let lo = (m.rho_mean - 5.0 * m.rho_sd).max(m.rho_prior.0);
    let hi = (m.rho_mean + 5.0 * m.rho_sd).min(m.rho_prior.1);
    let total: f64 = m
        .nodes
        .iter()
        .map(|n| n.weight)
        .sum::<f64>()
        .max(f64::MIN_POSITIVE);
    (0..200)
        .map(|i| {
            let r = lo + (hi - lo) * i as f64 / 199.0;
            let d: f64 = m
                .nodes
                .iter()
                .map(|n| {
                    let v = n.rho_var.max(1e-300);
                    n.weight * (-(r - n.rho_mean).powi(2) / (2.0 * v)).exp()
                        / (std::f64::consts::TAU * v).sqrt()
                })
                .sum();
            (r, d / total)
        })
        .collect()
}

/// The `θ` quantile `p` of a grid posterior (first node whose CDF reaches `p`).
fn grid_quantile(g: &GridPosterior, p: f64) -> f64 {
    let i = g.cdf.partition_point(|c| *c < p).min(g.theta.len() - 1);
    g.theta[i]
}

/// The `θ` posteriors (Fig. 16; grid posteriors only), each in its own panel so that a
/// posterior piled at a prior bound (common without the discrepancy) does not flatten the
/// other; the x range spans both posteriors' 0.1-99.9 % quantiles (and the truth if known).
fn plot_theta(
    cal: &Calibration,
    prior: &dyn mlmodel::Prior,
    truth: Option<f64>,
    path: &Path,
) -> Result<()> {
    let m3 = cal.module3();
    let (ThetaPosterior::Grid(w), ThetaPosterior::Grid(wo)) =
        (&m3.posterior, &m3.posterior_no_discrepancy)
    else {
        return Ok(());
    };
    let ends = [w, wo].map(|g| [grid_quantile(g, 0.001), grid_quantile(g, 0.999)]);
    let x_range = padded_range(ends.into_iter().flatten().chain(truth));
    svg_figure(path, (960, 720), |root| {
        let (panels, legend) = root.split_horizontally(730);
        let (top, bottom) = panels.split_vertically(360);
        let panel = |g: &GridPosterior, title: &str, color| {
            let peak = g.density.iter().fold(0.0f64, |m, d| m.max(*d));
            let prior_pts: Vec<(f64, f64)> = g
                .theta
                .iter()
                .map(|t| (*t, prior.ln_pdf(&[*t]).exp()))
                .collect();
            let mut series = vec![
                Series::xy("posterior", color, &g.theta, &g.density),
                Series::new("prior", PRIOR, prior_pts).dashed(),
            ];
            if let Some(t) = truth {
                series.push(
                    Series::new("truth θ*", TRUTH, vec![(t, 0.0), (t, 1.05 * peak)]).dashed(),
                );
            }
            let mut axes = Axes::new(title, "gap θ (in)", "posterior density (1/in)");
            (axes.x_range, axes.y_range) = (Some(x_range), Some((0.0, 1.1 * peak)));
            (axes, series)
        };
        let (a, s_top) = panel(
            w,
            "θ posterior with the discrepancy (the calibration's answer)",
            AFTER,
        );
        draw_chart(&top, &a, &s_top)?;
        let (a, s_bottom) = panel(
            wo,
            "θ posterior without the discrepancy (δ = 0, for comparison)",
            BEFORE,
        );
        draw_chart(&bottom, &a, &s_bottom)?;
        let mut entries = vec![
            Series::new("with discrepancy", AFTER, vec![]),
            Series::new("without discrepancy", BEFORE, vec![]),
        ];
        entries.extend(s_top.into_iter().skip(1));
        draw_legend(&legend, &entries)
    })
}

/// One panel per discrepancy coefficient: the estimates `α̂_k` at the experiments (Eq. 32)
/// against the coefficient GP's mean there (Fig. 14 as a parity plot: points on the diagonal
/// are reproduced by the GP, spread off it is what the GP treats as noise).
fn plot_gp_coefficients(cal: &Calibration, path: &Path) -> Result<()> {
    let x = cal.x_experiments();
    let gps = cal.coefficient_gps();
    let (mu, _) = gps.predict(x)?;
    let k_total = gps.len();
    let cols = 4usize;
    let rows = k_total.div_ceil(cols).max(1);
    svg_figure(path, (1200, 280 * rows as u32 + 40), |root| {
        let (head, body) = root.split_vertically(40);
        head.draw(&Text::new(
        "Coefficient estimates α̂ (Eq. 32) against the coefficient GPs' means (Eq. 33-37, Fig. 14), lbf/in",
        (12, 12),
        ("sans-serif", 18),
    ))?;
        for (k, area) in body
            .split_evenly((rows, cols))
            .iter()
            .enumerate()
            .take(k_total)
        {
            let pts: Vec<(f64, f64)> = (0..x.nrows())
                .map(|i| (cal.alpha_hat()[(i, k)], mu[(i, k)]))
                .collect();
            let r = padded_range(pts.iter().flat_map(|p| [p.0, p.1]));
            let mut axes = Axes::new(
                &format!("coefficient {k}"),
                "α̂ (lbf/in)",
                "GP mean (lbf/in)",
            );
            (axes.x_range, axes.y_range) = (Some(r), Some(r));
            let series = [
                Series::new("", PRIOR, vec![(r.0, r.0), (r.1, r.1)]).dashed(),
                Series::scatter("", AFTER, pts),
            ];
            draw_chart(area, &axes, &series)?;
        }
        Ok(())
    })
}

/// The report's first section: what the calibration was run on, and its warnings.
pub(crate) fn inputs_markdown(i: &ReportInputs) -> String {
    let mut s = format!(
        "## Inputs\n\n* configuration: `{}`\n* data: `{}` (water levels in in, strains in microstrain)\n\
         * gate: {}, {}\n* gap prior: U({}, {}) in\n* seed: {}\n\
         * bamudi {}\n\n",
        i.config,
        i.data,
        i.gate,
        i.element_size_in
            .map_or("the deck's own mesh".into(), |h| format!(
                "mesh element size {h} in"
            )),
        i.gap_prior_in.0,
        i.gap_prior_in.1,
        i.seed,
        env!("CARGO_PKG_VERSION")
    );
    if !i.warnings.is_empty() {
        s += "## Warnings\n\n";
        for w in &i.warnings {
            s += &format!("* {w}\n");
        }
        s += "\n";
    }
    s + "## Results\n\n"
}

/// The declared tolerances of the build, integrated out, with their posteriors.
pub(super) fn tolerances_markdown(tols: &[bamudi::posterior::ToleranceEstimate]) -> String {
    tols.iter()
        .map(|t| {
            format!(
                "* declared tolerance `{}` integrated out: posterior {:+.2} ± {:.2} of its \
                 standard deviations (prior N(0, 1))\n",
                t.name, t.mean, t.sd
            )
        })
        .collect()
}

fn report_markdown(cal: &Calibration, inputs: &ReportInputs) -> String {
    let (m2, m3) = (cal.module2(), cal.module3());
    let mut s = String::from("# BA-MUDI calibration report\n\n");
    s += &super::adequacy::banner(cal.adequacy());
    s += &inputs_markdown(inputs);
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
    if let Some(m) = m3.marginal() {
        s += &rho_caveat(m);
        s += &tolerances_markdown(&m.tolerances);
    }
    s += &format!(
        "* sigma_eps = {:.4} microstrain ({})\n",
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
    s += "| posterior of the gap θ (in) | mean | sd | 95% interval |\n|---|---|---|---|\n";
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
    if let Some(a) = m3.averaged() {
        s += &format!(
            "\nIs there a discrepancy at all? The models with and without one weighed by their \
             evidence (ln Z {:.1} and {:.1} nats, {:.1} charged for the discrepancy's fitted \
             hyper-parameters): **P(no discrepancy) = {:.3}**. The force and strain predictions \
             mix the two models with these weights; the gap's interval above is the discrepancy \
             model's (a discrepancy below the gauges' resolution still moves the gap).\n",
            a.log_evidence_with, a.log_evidence_without, a.penalty, a.probability_without
        );
    }
    if let Some(a) = cal.adequacy() {
        s += "\n";
        s += &super::adequacy::section(a);
    }
    let t = cal.timings();
    s += &format!(
        "\n| step | seconds |\n|---|---|\n| training set (Eq. 27) | {:.2} |\n| estimator fit (Eq. 29) | {:.2} |\n| rho search (Eq. 30-32) | {:.2} |\n| GPs (Eq. 33-37) | {:.2} |\n| Module 3 | {:.2} |\n",
        t.training_set_s, t.estimator_s, t.rho_s, t.gp_s, t.module3_s
    );
    s += "\nPlots: `rho_curve.svg`, `theta_posterior.svg`, `gp_coefficients.svg`.\n";
    s
}
