//! The close loop's report on a gate record: `report.md`, `results.json` and SVG plots.

use crate::error::{GateAppError, Result};
use bamudi::closeloop::{CloseLoopOutcome, CloseLoopReport};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn plot_err(path: &Path, e: impl std::fmt::Display) -> GateAppError {
    GateAppError::plot(path, e)
}

/// Markdown summary of a report (the before/after table, the effects and every step).
///
pub fn markdown(r: &CloseLoopReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Close-the-loop report: {}\n", r.file);
    let _ = writeln!(
        s,
        "{} rows ({} calibration, {} held-out from day {:.1}); {} rows dropped and {} cells imputed for missing gauge values; \
         white-noise sd from first differences {:.3} microstrain.\n",
        r.n_rows,
        r.n_calibration,
        r.n_heldout,
        r.split_day,
        r.dropped_missing,
        r.imputed,
        r.noise_sd_estimate
    );
    let _ = writeln!(s, "**Conclusion:** {}\n", r.conclusion);
    rmse_table(&mut s, r);
    effects_section(&mut s, r);
    steps_section(&mut s, r);
    checks_section(&mut s, r);
    s
}

/// Held-out RMSE per gauge before and after, and the gap before and after.
fn rmse_table(s: &mut String, r: &CloseLoopReport) {
    let _ = writeln!(
        s,
        "| gauge | held-out RMSE before (microstrain) | after (microstrain) |\n|---|---|---|"
    );
    for (k, g) in r.gauge_names.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {g} | {:.3} | {:.3} |",
            r.heldout_rmse_before[k], r.heldout_rmse_after[k]
        );
    }
    let _ = writeln!(
        s,
        "| **all** | **{:.3}** | **{:.3}** |\n",
        r.heldout_rmse_total_before, r.heldout_rmse_total_after
    );
    let t = |x: &bamudi::closeloop::ThetaSummary| {
        format!(
            "{:.2} ± {:.2} (95 %: {:.2} – {:.2})",
            x.mean, x.sd, x.ci95.0, x.ci95.1
        )
    };
    let _ = writeln!(
        s,
        "| gap θ (in) | value |\n|---|---|\n| before | {} |\n| after | {} ({}) |\n",
        t(&r.theta_before),
        t(&r.theta_after),
        r.theta_after_basis
    );
}

/// One section per accepted effect with its parameters.
fn effects_section(s: &mut String, r: &CloseLoopReport) {
    if r.effects.is_empty() {
        let _ = writeln!(s, "No effect was added.\n");
    }
    for e in &r.effects {
        let covariates = match e.covariates.is_empty() {
            true => "none".to_string(),
            false => e.covariates.join(", "),
        };
        let _ = writeln!(
            s,
            "## Effect `{}`\n\n{} — covariates: {covariates}\n",
            e.name, e.meaning
        );
        let _ = writeln!(s, "| parameter | unit | values |\n|---|---|---|");
        for p in &e.parameters {
            let v: Vec<String> = p.values.iter().map(|v| format!("{v:.4}")).collect();
            let _ = writeln!(s, "| {} | {} | {} |", p.name, p.unit, v.join(", "));
        }
        s.push('\n');
    }
}

/// Every step's candidates, screened and re-calibrated.
fn steps_section(s: &mut String, r: &CloseLoopReport) {
    let _ = writeln!(s, "## Steps\n");
    for st in &r.steps {
        let _ = writeln!(
            s,
            "### Step {} — {}\n\n| candidate | covariates | screened held-out MSE (microstrain²) | screened improvement | held-out MSE after re-calibration (microstrain²) | improvement after re-calibration |\n|---|---|---|---|---|---|",
            st.step, st.decision
        );
        for c in &st.candidates {
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} | {:.1} % | {} | {} |",
                c.name,
                c.covariates.join(", "),
                c.heldout_mse,
                100.0 * c.relative_improvement,
                c.recalibrated_heldout_mse
                    .map_or("–".into(), |v| format!("{v:.4}")),
                c.recalibrated_relative_improvement
                    .map_or("–".into(), |v| format!("{:.1} %", 100.0 * v)),
            );
        }
        s.push('\n');
    }
}

/// The adequacy checks before and after, with the first failure of each window.
fn checks_section(s: &mut String, r: &CloseLoopReport) {
    let _ = writeln!(s, "## Adequacy checks\n");
    for (label, checks) in [("before", &r.checks_before), ("after", &r.checks_after)] {
        for c in checks {
            let _ = writeln!(
                s,
                "- {label}, {} window: {} failed check(s){}",
                c.window,
                c.failures.len(),
                c.failures
                    .first()
                    .map_or(String::new(), |f| format!(", e.g. {f}"))
            );
        }
    }
}

/// Writes `report.md`, `results.json`, `rmse.svg`, `theta.svg` and one
/// `residual_vs_<covariate>.svg` per accepted effect into `dir` (created if needed); returns the
/// written paths.
///
pub fn write_report(out: &CloseLoopOutcome, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| GateAppError::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let mut files = vec![];
    let md = dir.join("report.md");
    bamudi::data::write_atomic(&md, markdown(&out.report).as_bytes())?;
    files.push(md);
    let js = dir.join("results.json");
    let text = serde_json::to_string_pretty(&out.report).map_err(|e| GateAppError::Serde {
        context: js.display().to_string(),
        reason: e.to_string(),
    })?;
    bamudi::data::write_atomic(&js, text.as_bytes())?;
    files.push(js);
    let p = dir.join("rmse.svg");
    plot_rmse(&out.report, &p).map_err(|e| plot_err(&p, e))?;
    files.push(p);
    let p = dir.join("theta.svg");
    plot_theta(&out.report, &p).map_err(|e| plot_err(&p, e))?;
    files.push(p);
    let mut seen = vec![];
    for cov in &out.effect_plot_covariates {
        if seen.contains(cov) {
            continue;
        }
        seen.push(cov.clone());
        let p = dir.join(format!("residual_vs_{cov}.svg"));
        plot_residual_vs(out, cov, &p).map_err(|e| plot_err(&p, e))?;
        files.push(p);
    }
    Ok(files)
}

type PlotResult = std::result::Result<(), Box<dyn std::error::Error>>;

fn plot_rmse(r: &CloseLoopReport, path: &Path) -> PlotResult {
    let root = SVGBackend::new(path, (720, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let ng = r.gauge_names.len();
    let ymax = r
        .heldout_rmse_before
        .iter()
        .chain(&r.heldout_rmse_after)
        .fold(0.0f64, |a, b| a.max(*b))
        * 1.15
        + 1e-9;
    let mut ch = ChartBuilder::on(&root)
        .caption(
            "Held-out RMSE per gauge (microstrain): before (red) / after (blue)",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..ng as f64, 0.0..ymax)?;
    ch.configure_mesh()
        .x_labels(ng)
        .x_label_formatter(&|v| {
            r.gauge_names
                .get(v.floor() as usize)
                .cloned()
                .unwrap_or_default()
        })
        .y_desc("RMSE (microstrain)")
        .draw()?;
    for (k, (b, a)) in r
        .heldout_rmse_before
        .iter()
        .zip(&r.heldout_rmse_after)
        .enumerate()
    {
        let x = k as f64;
        ch.draw_series([
            Rectangle::new([(x + 0.1, 0.0), (x + 0.45, *b)], RED.filled()),
            Rectangle::new([(x + 0.55, 0.0), (x + 0.9, *a)], BLUE.filled()),
        ])?;
    }
    root.present()?;
    Ok(())
}

fn plot_theta(r: &CloseLoopReport, path: &Path) -> PlotResult {
    let root = SVGBackend::new(path, (520, 400)).into_drawing_area();
    root.fill(&WHITE)?;
    let (lo, hi) = (
        r.theta_before.ci95.0.min(r.theta_after.ci95.0),
        r.theta_before.ci95.1.max(r.theta_after.ci95.1),
    );
    let pad = 0.1 * (hi - lo).max(1.0);
    let mut ch = ChartBuilder::on(&root)
        .caption(
            "Gap θ (in): mean and 95 % interval, before / after",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..2.0, (lo - pad)..(hi + pad))?;
    ch.configure_mesh()
        .x_labels(2)
        .x_label_formatter(&|v| {
            if *v < 1.0 {
                "before".into()
            } else {
                "after".into()
            }
        })
        .y_desc("gap (in)")
        .draw()?;
    for (k, t, c) in [(0.5, &r.theta_before, RED), (1.5, &r.theta_after, BLUE)] {
        ch.draw_series([PathElement::new(
            vec![(k, t.ci95.0), (k, t.ci95.1)],
            c.stroke_width(3),
        )])?;
        ch.draw_series([Circle::new((k, t.mean), 6, c.filled())])?;
    }
    root.present()?;
    Ok(())
}

fn plot_residual_vs(out: &CloseLoopOutcome, cov: &str, path: &Path) -> PlotResult {
    let Some((_, xs)) = out.features.iter().find(|(n, _)| n == cov) else {
        return Ok(());
    };
    let ho = &out.heldout_rows;
    // the gauge whose held-out RMSE improved most
    let r = &out.report;
    let g = (0..r.gauge_names.len())
        .max_by(|&a, &b| {
            (r.heldout_rmse_before[a] - r.heldout_rmse_after[a])
                .total_cmp(&(r.heldout_rmse_before[b] - r.heldout_rmse_after[b]))
        })
        .unwrap_or(0);
    let pts = |m: &nalgebra::DMatrix<f64>| -> Vec<(f64, f64)> {
        ho.iter().map(|&i| (xs[i], m[(i, g)])).collect()
    };
    let (before, after) = (pts(&out.residual_before), pts(&out.residual_after));
    let (xmin, xmax) = before
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
            (a.0.min(p.0), a.1.max(p.0))
        });
    let ymax = before
        .iter()
        .chain(&after)
        .fold(0.0f64, |a, p| a.max(p.1.abs()))
        * 1.1
        + 1e-9;
    let root = SVGBackend::new(path, (720, 460)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut ch = ChartBuilder::on(&root)
        .caption(
            format!(
                "Held-out residual of {} vs {cov}: before (red), after (blue)",
                r.gauge_names[g]
            ),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(xmin..(xmax + 1e-9), -ymax..ymax)?;
    ch.configure_mesh()
        .x_desc(cov)
        .y_desc("residual (microstrain)")
        .draw()?;
    ch.draw_series(
        before
            .iter()
            .map(|p| Circle::new(*p, 2, RED.mix(0.5).filled())),
    )?;
    ch.draw_series(
        after
            .iter()
            .map(|p| Circle::new(*p, 2, BLUE.mix(0.6).filled())),
    )?;
    root.present()?;
    Ok(())
}
