//! The close loop's report on a gate record: `report.md`, `results.json` and SVG plots.

use super::calibration::{ReportInputs, inputs_markdown, tolerances_markdown};
use super::plot::{
    AFTER, ALARM, Axes, BAND, BEFORE, Series, draw_legend, line_plot, svg_figure, tick,
};
use crate::error::{GateAppError, Result};
use crate::record_fatigue::RecordFatigue;
use bamudi::posterior::ToleranceEstimate;
use bamudi_closeloop::{CloseLoopOutcome, CloseLoopReport};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Markdown summary of a report (the before/after table, the effects and every step).
///
pub fn markdown(r: &CloseLoopReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Close-the-loop report: {}\n", r.file);
    let origins: Vec<String> = r
        .selection_origin_days
        .iter()
        .map(|d| format!("{d:.1}"))
        .collect();
    let test = match r.test_start_day {
        Some(d) => format!("{} test rows from day {d:.1}", r.n_test),
        None => "no test window".into(),
    };
    let _ = writeln!(
        s,
        "{} rows: {} calibration, {} validation from day {:.1} (rolling origins at days {}), {test}; \
         the before/after error is on the {} window{}. {} rows dropped and {} cells imputed for missing gauge values; \
         white-noise sd from first differences {:.3} microstrain. Wall time of the loop: {:.1} s.\n",
        r.n_rows,
        r.n_calibration,
        r.n_validation,
        r.split_day,
        origins.join(", "),
        r.error_window,
        match r.error_window.as_str() {
            "test" => " (selection never used it)",
            _ => " (selection used it: no test window)",
        },
        r.dropped_missing,
        r.imputed,
        r.noise_sd_estimate,
        r.wall_time_s
    );
    let _ = writeln!(s, "**Conclusion:** {}\n", r.conclusion);
    for (when, a) in [
        ("first", &r.model_adequacy_before),
        ("final", &r.model_adequacy_after),
    ] {
        if let Some(a) = a {
            let _ = writeln!(
                s,
                "* the {when} calibration's adequacy verdict: {}",
                a.summary()
            );
        }
    }
    s.push('\n');
    rmse_table(&mut s, r);
    sensor_section(&mut s, r);
    onset_section(&mut s, r);
    alarms_section(&mut s, r);
    track_section(&mut s, r);
    effects_section(&mut s, r);
    steps_section(&mut s, r);
    checks_section(&mut s, r);
    s
}

/// RMSE per gauge on the error window before and after, and the gap before and after.
fn rmse_table(s: &mut String, r: &CloseLoopReport) {
    let _ = writeln!(
        s,
        "| gauge | RMSE before, error window (microstrain) | after (microstrain) |\n|---|---|---|"
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
    let t = |x: &bamudi_closeloop::ThetaSummary| {
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

/// The sensor findings' table and the gap with and without the corrections.
fn findings_table(s: &mut String, sr: &bamudi_closeloop::SensorReport) {
    let _ = writeln!(
        s,
        "| gauge(s) | kind | action | fitted size (± sd) | span (days) | found by | evidence |\n|---|---|---|---|---|---|---|"
    );
    for f in &sr.findings {
        let size = match (f.size, f.size_sd) {
            (Some(v), Some(sd)) => format!("{v:+.4} ± {sd:.4} {}", f.unit),
            (Some(v), None) => format!("{v:+.4} {}", f.unit),
            _ => "–".into(),
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {size} | {:.2} – {:.2} | {} | {} |",
            f.gauges.join(" <-> "),
            f.kind.name(),
            match f.action {
                bamudi_closeloop::SensorAction::Corrected => "corrected",
                bamudi_closeloop::SensorAction::SetAside => "set aside",
            },
            f.from_day,
            f.to_day,
            f.source,
            f.evidence
        );
    }
    let t = |x: &Option<bamudi_closeloop::ThetaSummary>| {
        x.map_or("–".into(), |x| {
            format!(
                "{:.2} ± {:.2} (95 %: {:.2} – {:.2})",
                x.mean, x.sd, x.ci95.0, x.ci95.1
            )
        })
    };
    let _ = writeln!(
        s,
        "\n| gap θ (in) | value |\n|---|---|\n| without the sensor corrections | {} |\n| with them | {} |\n\n{} cells set aside (left out of every error above).{}{}\n",
        t(&sr.theta_without_corrections),
        t(&sr.theta_with_corrections),
        sr.set_aside_cells,
        calibration_rows(sr.calibration_rows.as_ref()),
        if sr.fitted_on_test_rows {
            " A correction reaches into the test window and was dated and sized on every row, the test window's included: for its gauge and span the error after is not fully out of sample."
        } else {
            ""
        }
    );
}

/// What the calibrations with the corrections read of the calibration window.
fn calibration_rows(rows: Option<&bamudi_closeloop::CalibrationRows>) -> String {
    use bamudi_closeloop::CalibrationRows as R;
    match rows {
        Some(R::WithoutSetAside { complete_rows, .. }) => format!(
            " The calibrations with the corrections read the {complete_rows} rows of the calibration window where no gauge is set aside."
        ),
        Some(R::Filled { complete_rows }) => format!(
            " Only {complete_rows} rows of the calibration window are free of set-aside cells, too few to calibrate on: the set-aside cells there are filled with the model's prediction, which leans the gap towards the first calibration, made on the faulty readings."
        ),
        Some(R::Window) | None => String::new(),
    }
}

/// The changes seen on several gauges together after the calibration window, and each one's
/// scores: a change of the gap, one sensor, a level change on every gauge, or a library effect
/// from that day on (added when it scores lowest).
fn onset_section(s: &mut String, r: &CloseLoopReport) {
    let Some(o) = &r.onset else {
        return;
    };
    let _ = writeln!(
        s,
        "## Changes on several gauges after the calibration window

Each score is the residual sum of squares from the day on over the noise variances, plus its penalty; the lowest wins. An effect that wins is added from that day, fitted on the rows from it (the test window's included).

| from day | gauges | none | gap | one sensor | level change on every gauge | effect from the day | verdict |
|---|---|---|---|---|---|---|---|"
    );
    for t in &o.tests {
        let _ = writeln!(
            s,
            "| {:.2} | {} | {:.0} | {:.0} | {:.0} ({}) | {} | {} | {} |",
            t.from_day,
            t.gauges.join(", "),
            t.none,
            t.structure,
            t.sensor,
            t.sensor_hypothesis,
            t.steps.map_or("–".into(), |v| format!("{v:.0}")),
            match (t.effect, &t.effect_name) {
                (Some(v), Some(n)) => format!("{v:.0} ({n})"),
                _ => "–".into(),
            },
            t.verdict
        );
    }
    if let Some(v) = &o.error_rmse_with {
        let total = bamudi_closeloop::rmse_over_gauges(v);
        let _ = writeln!(
            s,
            "\nError window RMSE with the effects from an onset: {total:.3} microstrain (in-sample; the table of the error after, above, leaves them out)."
        );
    }
    s.push('\n');
}

/// The sensor findings: what was corrected or set aside, from when, with the fitted size, and
/// the gap with and without the corrections; then the structure-or-sensor tests.
fn sensor_section(s: &mut String, r: &CloseLoopReport) {
    let Some(sr) = &r.sensor else {
        return;
    };
    if let Some(sd) = r.theta_after_effect_sd {
        let _ = writeln!(
            s,
            "The gap after includes the uncertainty of the accepted effects' and corrections' parameters: {sd:.3} in of sd added (propagated by re-calibration over draws of them).\n"
        );
    }
    if sr.findings.is_empty() && sr.attribution_tests.is_empty() {
        return;
    }
    let _ = writeln!(s, "## Sensor findings\n");
    if !sr.findings.is_empty() {
        findings_table(s, sr);
    }
    if !sr.attribution_tests.is_empty() {
        let _ = writeln!(
            s,
            "Structure or sensor (residual sum of squares over the noise variance from the change on; the sensor side pays the penalty for choosing among its hypotheses):\n\n| change | from day | no change | parameter change | best sensor hypothesis | its score + penalty | verdict |\n|---|---|---|---|---|---|---|"
        );
        for t in &sr.attribution_tests {
            let _ = writeln!(
                s,
                "| {} | {:.2} | {:.0} | {:.0} | {} | {:.0} + {:.1} | {} |",
                t.subject,
                t.from_day,
                t.none,
                t.structure,
                t.sensor_hypothesis,
                t.sensor,
                t.penalty,
                t.verdict
            );
        }
        s.push('\n');
    }
    if !sr.coincident_findings.is_empty() {
        let what: Vec<String> = sr
            .coincident_findings
            .iter()
            .map(|f| f.describe())
            .collect();
        let _ = writeln!(
            s,
            "Not applied, because several gauges changed within a day of each other (a change of the structure, not of one sensor): {}.\n",
            what.join("; ")
        );
    }
    if let Some(w) = &sr.withheld_gap_alarm {
        let _ = writeln!(
            s,
            "**Gap alarm withheld:** the track's {} of {:.2} in from day {:.2} is not raised: {}.\n",
            w.alarm.direction, w.alarm.size, w.alarm.onset_day, w.reason
        );
    }
}

/// Every alarm in one table (the gauges' changes of level and the gap's change alarm), then
/// the event scan's details.
fn alarms_section(s: &mut String, r: &CloseLoopReport) {
    if r.events.is_none() && r.theta_track.is_none() {
        return;
    }
    let _ = writeln!(s, "## Alarms\n");
    if r.alarms.is_empty() {
        let _ = writeln!(
            s,
            "No alarm: no change of level in any gauge's residual and no change of the gap.\n"
        );
    } else {
        let _ = writeln!(
            s,
            "| what | change | onset (day) | onset 95 % (day) | size | raised (day) |\n|---|---|---|---|---|---|"
        );
        for a in &r.alarms {
            let (what, unit) = match a.subject.as_str() {
                "parameter" => ("gap".to_string(), "in"),
                g => (format!("gauge {g}"), a.unit.as_str()),
            };
            let _ = writeln!(
                s,
                "| {what} | {} | {:.2} | {:.2} – {:.2} | {:+.2} ± {:.2} {unit} | {} |",
                a.change,
                a.onset_day,
                a.onset_day_interval.0,
                a.onset_day_interval.1,
                a.size,
                a.size_sd,
                a.raised_day
                    .map_or("end of record".into(), |d| format!("{d:.2}"))
            );
        }
        s.push('\n');
    }
    gap_correction(s, r);
    scan_details(s, r);
}

/// The gap's change applied as a correction (when its alarm stands).
fn gap_correction(s: &mut String, r: &CloseLoopReport) {
    let Some(p) = &r.parameter_correction else {
        return;
    };
    let step = match (p.step_day, p.step_levels) {
        (Some(d), Some((b, a))) => {
            format!("its largest step on day {d:.2}, from {b:.2} to {a:.2} in")
        }
        _ => "no one-row step (the track's levels, interpolated)".into(),
    };
    let rms = bamudi_closeloop::rmse_over_gauges(&p.error_rmse);
    let _ = writeln!(
        s,
        "**The gap's change, applied:** every row predicted at the tracked gap, {step}. The \
         error window's RMSE with it is {rms:.2} microstrain (in-sample: the track reads every \
         row{}); the gauge alarms above are the scan with it ({} without it).\n",
        if p.fitted_on_error_rows {
            "; the change starts in that window, so no earlier fit can hold it"
        } else {
            ""
        },
        p.gauge_alarms_without
    );
}

/// The whole-record event scan: every change of level left in a gauge's residual.
fn scan_details(s: &mut String, r: &CloseLoopReport) {
    let Some(scan) = &r.events else {
        return;
    };
    let _ = writeln!(
        s,
        "Gauges: {} (levels held at least {} rows; intervals at {}).\n",
        scan.method, scan.config.min_segment_rows, scan.config.level
    );
    if scan.alarms.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "| gauge | onset (day) | onset interval (day) | time (UTC) | CSV line | size (microstrain) | window | with | reading |\n|---|---|---|---|---|---|---|---|---|"
    );
    for a in &scan.alarms {
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.2} – {:.2} | {} | {} | {:+.2} ± {:.2} | {:?} | {} | {} |",
            a.gauge,
            a.onset_day,
            a.onset_day_interval.0,
            a.onset_day_interval.1,
            a.onset_time.as_deref().unwrap_or("-"),
            a.onset_csv_line,
            a.size,
            0.5 * (a.size_interval.1 - a.size_interval.0),
            a.window,
            a.coincident_gauges.join(", "),
            a.reading
        );
    }
    s.push('\n');
}

/// The gap tracked through the record: now, the change alarm, and a weekly table.
fn track_section(s: &mut String, r: &CloseLoopReport) {
    let Some(t) = &r.theta_track else {
        return;
    };
    let _ = writeln!(
        s,
        "## Gap through the record\n\nGap now (filter at the last {:.0} h window): **{:.2} ± {:.2} in** (95 %: {:.2} – {:.2}); level random walk {:.3} in/√day, slope random walk {:.4} in/day/√day (constant gap against a random walk: p = {:.3}); window sds × {:.2} for over-dispersion; residual noise {:.3} microstrain. Plot: `theta_track.svg`.\n",
        t.config.window_hours,
        t.now.mean,
        t.now.sd,
        t.now.ci95.0,
        t.now.ci95.1,
        t.level_sd_per_day,
        t.slope_sd_per_day,
        t.constant_p_value,
        t.overdispersion,
        t.noise_sd
    );
    let _ = match &t.anchor {
        Some(a) => writeln!(
            s,
            "Levels anchored on the calibration's posterior, {:.2} ± {:.2} in: the misfit's own single gap over the calibration's rows lies {:+.2} in from it, and every smoothed level and the gap now are moved by that and carry the calibration's sd (the window estimates only their own). The gap moved by {:.2} in (weighted sd) over the calibration's {} windows.\n",
            a.calibration.mean, a.calibration.sd, a.offset, a.spread, a.windows
        ),
        None => writeln!(
            s,
            "Levels not anchored on the calibration (no window of its rows carries an estimate, the misfit over its rows has no minimum, its summary is not finite, or a result from before anchoring): they leave out the calibration's uncertainty.\n"
        ),
    };
    match &t.alarm {
        Some(a) => {
            let _ = writeln!(
                s,
                "**Change alarm:** the gap's {} was detected on day {:.2}; estimated onset day {:.2} (95 %: {:.2} – {:.2}; delay {:.2} days), size {:+.2} ± {:.2} in (CUSUM threshold {:.2} sd, one false alarm per {:.0} windows in control).\n",
                a.direction,
                a.day,
                a.onset_day,
                a.onset_day_interval.0,
                a.onset_day_interval.1,
                a.delay_days,
                a.size,
                a.size_sd,
                t.cusum_h,
                t.config.in_control_windows
            );
        }
        None => {
            let _ = writeln!(
                s,
                "No change alarm (CUSUM threshold {:.2} sd, one false alarm per {:.0} windows in control).\n",
                t.cusum_h, t.config.in_control_windows
            );
        }
    }
    let _ = writeln!(
        s,
        "| day | window estimate (in) | smoothed (in) | 95 % band (in) |\n|---|---|---|---|"
    );
    let mut next = 0.0;
    for p in &t.points {
        if p.day + 1e-9 < next {
            continue;
        }
        next = p.day + 7.0;
        let est = p
            .estimate
            .map_or("-".into(), |(m, sd)| format!("{m:.2} ± {sd:.2}"));
        let _ = writeln!(
            s,
            "| {:.1} | {est} | {:.2} ± {:.2} | {:.2} – {:.2} |",
            p.day, p.smoothed.0, p.smoothed.1, p.band95.0, p.band95.1
        );
    }
    s.push('\n');
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
            "### Step {} — {}\n\n| candidate | covariates | screened cross-validated MSE (microstrain²) | screened improvement | cross-validated MSE after re-calibration (microstrain²) | improvement after re-calibration | its t over the validation window's days |\n|---|---|---|---|---|---|---|",
            st.step, st.decision
        );
        for c in &st.candidates {
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} | {:.1} % | {} | {} | {} |",
                c.name,
                c.covariates.join(", "),
                c.heldout_mse,
                100.0 * c.relative_improvement,
                c.recalibrated_heldout_mse
                    .map_or("–".into(), |v| format!("{v:.4}")),
                c.recalibrated_relative_improvement
                    .map_or("–".into(), |v| format!("{:.1} %", 100.0 * v)),
                c.recalibrated_improvement_t
                    .map_or("–".into(), |(t, days)| format!("{t:.1} ({days} days)")),
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

/// Writes `report.md`, `results.json`, `rmse.svg`, `theta.svg`, `theta_track.svg` (when the
/// gap was tracked) and one `residual_vs_<covariate>.svg` per accepted effect into `dir`
/// (created if needed); with
/// `fatigue`, a section on the quoin block's fatigue over the record, its `results.json` key
/// `record_fatigue` and `fatigue_along_quoin.svg`. Returns the written paths.
///
pub fn write_report(
    out: &CloseLoopOutcome,
    inputs: Option<&ReportInputs>,
    fatigue: Option<&RecordFatigue>,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| GateAppError::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let mut files = vec![];
    let md = dir.join("report.md");
    let mut text = markdown(&out.report);
    if let Some(i) = inputs {
        // the inputs go right under the title line
        let at = text.find('\n').map_or(text.len(), |k| k + 1);
        text.insert_str(at, &format!("\n{}", inputs_markdown(i)));
    }
    if let Some(f) = fatigue {
        text.push_str(&fatigue_markdown(f));
    }
    let tolerances = final_tolerances(out);
    if !tolerances.is_empty() {
        text.push_str(
            "\n## Declared tolerances (the loop's final calibration)\n\nWhat the data read of the build's declared tolerances, integrated out by every calibration of the loop (`results.json` key `tolerances`):\n\n",
        );
        text.push_str(&tolerances_markdown(&tolerances));
    }
    bamudi::data::write_atomic(&md, text.as_bytes())?;
    files.push(md);
    let js = dir.join("results.json");
    let warnings = inputs.map_or(&[][..], |i| &i.warnings[..]);
    let json = results_json(out, fatigue, warnings, &js.display().to_string())?;
    bamudi::data::write_atomic(&js, json.as_bytes())?;
    files.push(js);
    if let Some(f) = fatigue {
        let p = dir.join("fatigue_along_quoin.svg");
        plot_fatigue(f, &p)?;
        files.push(p);
    }
    let p = dir.join("rmse.svg");
    plot_rmse(&out.report, &p)?;
    files.push(p);
    let p = dir.join("theta.svg");
    plot_theta(&out.report, &p)?;
    files.push(p);
    if let Some(t) = &out.report.theta_track {
        let p = dir.join("theta_track.svg");
        plot_track(t, &p)?;
        files.push(p);
    }
    let mut seen = vec![];
    for cov in &out.effect_plot_covariates {
        if seen.contains(cov) {
            continue;
        }
        seen.push(cov.clone());
        let p = dir.join(format!("residual_vs_{cov}.svg"));
        plot_residual_vs(out, cov, &p)?;
        files.push(p);
    }
    Ok(files)
}

/// The text of `results.json`: the loop's report, the declared tolerances the final
/// calibration read (`tolerances`, when declared), the record's fatigue (`record_fatigue`,
/// when given) and the front end's `warnings` (when any, e.g. the final posterior pressed
/// against a prior bound, [`close_loop_warnings`](crate::session::close_loop_warnings));
/// `context` names the output in an error.
pub fn results_json(
    out: &CloseLoopOutcome,
    fatigue: Option<&RecordFatigue>,
    warnings: &[String],
    context: &str,
) -> Result<String> {
    let serde = |e: serde_json::Error| GateAppError::Serde {
        context: context.to_string(),
        reason: e.to_string(),
    };
    let tolerances = final_tolerances(out);
    let mut value = serde_json::to_value(&out.report).map_err(serde)?;
    if let Some(map) = value.as_object_mut() {
        if let Some(f) = fatigue {
            let f = serde_json::to_value(f).map_err(serde)?;
            map.insert("record_fatigue".into(), f);
        }
        if !tolerances.is_empty() {
            let t = serde_json::to_value(tolerances).map_err(serde)?;
            map.insert("tolerances".into(), t);
        }
        if !warnings.is_empty() {
            map.insert("warnings".into(), serde_json::json!(warnings));
        }
    }
    serde_json::to_string_pretty(&value).map_err(serde)
}

/// The final calibration's posteriors of the build's declared tolerances (in their standard
/// deviations); empty without any, or when the loop's model is not a gate calibration.
fn final_tolerances(out: &CloseLoopOutcome) -> Vec<ToleranceEstimate> {
    let any: &dyn std::any::Any = out.model.as_ref();
    any.downcast_ref::<crate::calibrator::CalibratedGate>()
        .and_then(|g| g.calibration().module3().marginal())
        .map(|m| m.tolerances.clone())
        .unwrap_or_default()
}

/// The fatigue section of `report.md`.
fn fatigue_markdown(f: &RecordFatigue) -> String {
    let years = |v: Option<f64>| v.map_or("no initiation".to_string(), |y| format!("{y:.3e}"));
    let h = &f.hot_spot;
    format!(
        "\n## Quoin-block fatigue over the record\n\n\
         The loop's final calibration pushed through the quoin-block model along the whole \
         record (rainflow-counted cycles of the largest sub-surface shear, Miner's rule on the \
         EN 1993-1-9 shear curve, default blocks; `bamudi_gate::record_fatigue`): {:.1} days \
         sampled every {:.0} min, {:.1} lockages (fill-and-empty cycles) counted, {} joint draws. \
         The nominal model is the force averaged over the gap's prior, rho = 1, no \
         discrepancy.\n\n\
         | at the hot spot z = {:.1} in | nominal model | calibrated (95 % band) |\n|---|---|---|\n\
         | damage per 1,000 lockages | {:.3e} | {:.3e} [{:.3e}, {:.3e}] |\n\
         | years to crack initiation at this record's rate | {} | {} [{}, {}] |\n\n\
         Per point: `fatigue_along_quoin.svg`, `results.json` key `record_fatigue`.\n",
        f.duration_days,
        60.0 * f.sampling_step_h,
        f.lockages,
        f.n_draws,
        h.z_in,
        h.before,
        h.after_mean,
        h.after_lower,
        h.after_upper,
        years(h.years_before),
        years(h.years_after),
        years(h.years_after_lower),
        years(h.years_after_upper),
    )
}

/// Damage per 1,000 lockages along the quoin: nominal, calibrated mean and band.
fn plot_fatigue(f: &RecordFatigue, path: &Path) -> Result<()> {
    let z = &f.z_in;
    let series = [
        Series::xy("nominal model", BEFORE, z, &f.before),
        Series::xy("calibrated mean", AFTER, z, &f.after.mean),
        Series::xy("95 % band", BAND, z, &f.after.lower).dashed(),
        Series::xy("", BAND, z, &f.after.upper).dashed(),
    ];
    let axes = Axes::new(
        &format!(
            "quoin-block fatigue over the record ({:.1} days, {:.0} lockages)",
            f.duration_days, f.lockages
        ),
        "height above the sill (in)",
        "damage per 1,000 lockages",
    );
    line_plot(path, &axes, &series)
}

/// RMSE per gauge on the error window (the test window), before and after the loop: one
/// group of two bars per gauge, every gauge named under its group.
fn plot_rmse(r: &CloseLoopReport, path: &Path) -> Result<()> {
    svg_figure(path, (960, 460), |root| {
        let (plot, legend) = root.split_horizontally(760);
        let ng = r.gauge_names.len();
        let ymax = r
            .heldout_rmse_before
            .iter()
            .chain(&r.heldout_rmse_after)
            .fold(0.0f64, |a, b| a.max(*b))
            * 1.15
            + 1e-9;
        let mut ch = ChartBuilder::on(&plot)
            .caption(
                "RMSE per gauge on the error window, before and after the loop",
                ("sans-serif", 18),
            )
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(70)
            // plotters' integer ranges include their end: 0..ng-1 holds the ng gauges
            .build_cartesian_2d((0..ng.saturating_sub(1)).into_segmented(), 0.0..ymax)?;
        ch.configure_mesh()
            .disable_x_mesh()
            .x_labels(ng + 1)
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) => r.gauge_names.get(*i).cloned().unwrap_or_default(),
                _ => String::new(),
            })
            .x_desc("gauge")
            .y_desc("RMSE (microstrain)")
            .y_label_formatter(&tick)
            .draw()?;
        ch.draw_series(r.heldout_rmse_before.iter().enumerate().map(|(k, v)| {
            Rectangle::new(
                [
                    (SegmentValue::Exact(k), 0.0),
                    (SegmentValue::CenterOf(k), *v),
                ],
                BEFORE.filled(),
            )
        }))?;
        ch.draw_series(r.heldout_rmse_after.iter().enumerate().map(|(k, v)| {
            Rectangle::new(
                [
                    (SegmentValue::CenterOf(k), 0.0),
                    (SegmentValue::Exact(k + 1), *v),
                ],
                AFTER.filled(),
            )
        }))?;
        draw_legend(
            &legend,
            &[
                Series::new("before the loop", BEFORE, vec![]),
                Series::new("after the loop", AFTER, vec![]),
            ],
        )?;
        Ok(())
    })
}

/// The gap through the record: window estimates, the smoothed track and its 95 % band.
fn plot_track(t: &bamudi_closeloop::ThetaTrack, path: &Path) -> Result<()> {
    let pts = |f: &dyn Fn(&bamudi_closeloop::TrackPoint) -> f64| {
        t.points.iter().map(|p| (p.day, f(p))).collect::<Vec<_>>()
    };
    let estimates: Vec<(f64, f64)> = t
        .points
        .iter()
        .filter_map(|p| p.estimate.map(|(m, _)| (p.day, m)))
        .collect();
    let mut upper = Series::new("95 % band", BAND, pts(&|p| p.band95.1));
    upper.dashed = true;
    let mut lower = Series::new("", BAND, pts(&|p| p.band95.0));
    lower.dashed = true;
    let mut series = vec![
        Series::scatter("window estimate", BEFORE, estimates),
        Series::new("smoothed gap", AFTER, pts(&|p| p.smoothed.0)),
        upper,
        lower,
    ];
    series.extend(alarm_marks(t));
    let axes = Axes::new("Gap θ through the record", "time (days)", "gap θ (in)");
    line_plot(path, &axes, &series)
}

/// The change alarm as vertical lines over the band's range: the day it was raised (solid) and
/// its onset's 95 % interval (dashed); none without an alarm.
fn alarm_marks(t: &bamudi_closeloop::ThetaTrack) -> Vec<Series> {
    let Some(a) = &t.alarm else {
        return vec![];
    };
    let lo = t
        .points
        .iter()
        .map(|p| p.band95.0)
        .fold(f64::INFINITY, f64::min);
    let hi = t
        .points
        .iter()
        .map(|p| p.band95.1)
        .fold(f64::NEG_INFINITY, f64::max);
    let vertical = |d: f64| vec![(d, lo), (d, hi)];
    let raised = Series::new(
        &format!("change alarm (day {:.1})", a.day),
        ALARM,
        vertical(a.day),
    );
    let (o0, o1) = a.onset_day_interval;
    let mut first = Series::new("onset 95 % interval", ALARM, vertical(o0));
    first.dashed = true;
    let mut last = Series::new("", ALARM, vertical(o1));
    last.dashed = true;
    vec![raised, first, last]
}

/// The gap before and after the loop: mean and 95 % interval, one column each.
fn plot_theta(r: &CloseLoopReport, path: &Path) -> Result<()> {
    svg_figure(path, (560, 420), |root| {
        let (lo, hi) = (
            r.theta_before.ci95.0.min(r.theta_after.ci95.0),
            r.theta_before.ci95.1.max(r.theta_after.ci95.1),
        );
        let pad = 0.1 * (hi - lo).max(1.0);
        let mut ch = ChartBuilder::on(root)
            .caption("Gap θ: mean and 95 % interval", ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(70)
            // plotters' integer ranges include their end: 0..1 holds the two columns
            .build_cartesian_2d((0..1usize).into_segmented(), (lo - pad)..(hi + pad))?;
        ch.configure_mesh()
            .disable_x_mesh()
            .x_labels(3)
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(0) => "before the loop".into(),
                SegmentValue::CenterOf(1) => "after the loop".into(),
                _ => String::new(),
            })
            .y_desc("gap θ (in)")
            .y_label_formatter(&tick)
            .draw()?;
        for (k, t, c) in [(0, &r.theta_before, BEFORE), (1, &r.theta_after, AFTER)] {
            let x = SegmentValue::CenterOf(k);
            ch.draw_series([PathElement::new(
                vec![(x.clone(), t.ci95.0), (x.clone(), t.ci95.1)],
                c.stroke_width(3),
            )])?;
            ch.draw_series([Circle::new((x, t.mean), 6, c.filled())])?;
        }
        Ok(())
    })
}

fn plot_residual_vs(out: &CloseLoopOutcome, cov: &str, path: &Path) -> Result<()> {
    let Some((_, xs)) = out.features.iter().find(|(n, _)| n == cov) else {
        return Ok(());
    };
    let ho = &out.heldout_rows;
    // the gauge whose error-window RMSE improved most
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
    svg_figure(path, (720, 460), |root| {
        let mut ch = ChartBuilder::on(root)
            .caption(
                format!(
                    "Held-out residual of {} against {cov}: before (red) and after (blue) the loop",
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
            .y_desc(format!("residual of {} (microstrain)", r.gauge_names[g]))
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .draw()?;
        ch.draw_series(
            before
                .iter()
                .map(|p| Circle::new(*p, 2, BEFORE.mix(0.5).filled())),
        )?;
        ch.draw_series(
            after
                .iter()
                .map(|p| Circle::new(*p, 2, AFTER.mix(0.6).filled())),
        )?;
        Ok(())
    })
}
