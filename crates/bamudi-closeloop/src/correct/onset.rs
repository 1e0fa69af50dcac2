//! Effects that begin mid-record: the structure-or-sensor test's third answer.
//!
//! The loop selects effects by rolling-origin cross-validation and needs two folds to accept
//! one, so an effect that starts in the last fold or in the test window (sunlight on the gauges
//! from a day on, a response to the lock's cycle that a new operation brings, the wall flexing
//! with the pool once a joint opens) is left to the whole-record scan. Its change shows on
//! several gauges at once, and the structure-or-sensor test ([`sensor::attribute`]) had two
//! answers only: the gap changed, or one sensor did. Neither fits, so the sensor side won with
//! a step on one gauge, then another, and the effect was named as sensor faults.
//!
//! Here a change the scan sees on two or more gauges together after the calibration window,
//! which the structure-or-sensor test does not call the structure's (a change of the gap is
//! the track's to judge, with the model's own response), is offered a third answer: **an
//! effect of the library, present from that day on**. Every
//! additive library effect but the per-gauge sensor-like ones (offsets, drifts, jumps: a level
//! change on every gauge is the competitor `steps on every gauge` instead) is fitted on the
//! residual over the rows from the onset to the end, and its term is switched on from the
//! onset ([`FromOnset`]). The hypotheses are scored as the structure-or-sensor test scores them
//! (residual sum of squares over each gauge's noise variance from the rows before the change),
//! each fitted coefficient paying `ln` of the cells scored (BIC) and each side `2 ln` of the
//! number of hypotheses it chose among:
//!
//! | hypothesis | coefficients | choice |
//! |---|---|---|
//! | the gap changed (a step or a ramp of the parameter) | 1 | 2 |
//! | one sensor (a step, drift or gain on one gauge; an exchange) | 1 | the test's `m` |
//! | a level change on every gauge | gauges | 1 |
//! | a library effect from the onset | its fitted values (not those left at exactly zero on a gauge) | effects tried |
//!
//! The effect is added only when it wins. It is then one of the loop's effects (named as the
//! library names it, with `onset_day` among its parameters), so that the scans, the track and
//! the gap after read the residual without it. Its coefficients are fitted on the rows from the
//! onset, the test window's included: the report's out-of-sample error leaves it out, and
//! `onset.error_rmse_with` states the in-sample figure with it.

use crate::effect::{Effect, EffectKind, FitContext, Fitted, Term, param};
use crate::error::Result;
use crate::record::MeasuredRecord;
use crate::search::Loop;
use crate::sensor;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Most onsets tried in one record (the earliest changes seen on several gauges together).
const MAX_ONSETS: usize = 3;

/// One tested onset: the change the scan dated on several gauges, and each hypothesis's score
/// (residual sum of squares over the noise variances, plus its penalty).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OnsetTest {
    /// Day the tested rows start (the earliest of the coinciding alarms).
    pub from_day: f64,
    /// The gauges whose alarms coincide.
    pub gauges: Vec<String>,
    /// No change.
    pub none: f64,
    /// The best change of the parameter, with its penalty.
    pub structure: f64,
    /// The best one-sensor hypothesis, with its penalty, and its name.
    pub sensor: f64,
    /// That hypothesis, e.g. `SG3 step`.
    pub sensor_hypothesis: String,
    /// A level change on every gauge, with its penalty (`None` when the test called the change
    /// the structure's and nothing else was scored).
    pub steps: Option<f64>,
    /// The best library effect from the onset, with its penalty (`None`: none applied).
    pub effect: Option<f64>,
    /// Its name and covariates, e.g. `generic_covariate_term(daily_cos)`.
    pub effect_name: Option<String>,
    /// `effect` (added), `structure`, `sensor`, `steps` or `none`: the lowest score.
    pub verdict: String,
}

/// What the onset step did (the report's `onset`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OnsetReport {
    /// Every onset tested.
    pub tests: Vec<OnsetTest>,
    /// Effects added from an onset (their names as in `effects`).
    pub added: Vec<String>,
    /// The error window's RMSE per gauge with them (output units; in-sample: they are fitted
    /// on the rows from their onset, the error window's included). The report's
    /// `heldout_rmse_after` leaves them out.
    #[serde(default, deserialize_with = "crate::stats::nan_as_null::opt_vec")]
    pub error_rmse_with: Option<Vec<f64>>,
}

/// A library effect switched on from row `from_row`: fitted on the rows from it to the end,
/// zero before it.
#[derive(Debug)]
pub struct FromOnset {
    inner: Arc<dyn Effect>,
    from_row: usize,
    from_day: f64,
    n_rows: usize,
}

impl Effect for FromOnset {
    fn name(&self) -> String {
        self.inner.name()
    }
    fn meaning(&self) -> String {
        format!(
            "{}, from day {:.2} on (fitted on the rows from that day, the test window's included)",
            self.inner.meaning(),
            self.from_day
        )
    }
    fn kind(&self) -> EffectKind {
        self.inner.kind()
    }
    fn repeatable(&self) -> bool {
        false
    }
    /// Re-fitted on its own rows whatever rows the caller fits on: the back-fits after it
    /// fit on the selection's rows, which may not reach its onset.
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let rows: Vec<usize> = (self.from_row..self.n_rows).collect();
        let own = FitContext {
            feats: ctx.feats,
            x: ctx.x,
            cal: &rows,
            model: ctx.model,
            base_mean: ctx.base_mean,
            gauges: ctx.gauges,
            unit: ctx.unit,
        };
        let Some(f) = Arc::clone(&self.inner).fit(&own, r)? else {
            return Ok(None);
        };
        let term = Arc::new(Gated {
            inner: f.term,
            from_row: self.from_row,
        });
        let mut params = f.report.parameters;
        params.push(param("onset_day", "day", vec![self.from_day]));
        let plot = f.plot_covariate.clone();
        Ok(Some(Fitted::new(
            self,
            term,
            f.report.covariates,
            params,
            &plot,
        )))
    }
}

/// A term that is zero before `from_row`.
#[derive(Debug)]
struct Gated {
    inner: Arc<dyn Term>,
    from_row: usize,
}

impl Term for Gated {
    fn contribution(&self, ctx: &FitContext<'_>) -> Result<DMatrix<f64>> {
        let mut c = self.inner.contribution(ctx)?;
        let n = self.from_row.min(c.nrows());
        c.rows_mut(0, n).fill(0.0);
        Ok(c)
    }
}

/// Whether an effect is one of the per-gauge level terms a sensor fault looks like (the
/// competitor `steps on every gauge` stands for them) or moves the parameter itself.
fn offered(e: &dyn Effect) -> bool {
    !e.keeps_model_fixed() && !e.name().starts_with("gauge_")
}

/// The onsets to test: after the calibration window, the alarms of the scan that coincide with
/// an alarm on another gauge, the earliest of each group (groups a day apart), at most
/// [`MAX_ONSETS`]. Returns `(row, day, gauges)`.
///
/// Two alarms coincide when their onset intervals overlap (the scan's own mark) or when their
/// onsets lie within [`COINCIDENT_DAYS`](super::COINCIDENT_DAYS) of each other, the span within
/// which the one-gauge findings count as one change. The scan dates a change as a step, and
/// an effect that is not one (a response to the lock's cycle that begins on a day, weaker on
/// one gauge) is dated hours apart on its gauges with intervals that need not overlap.
fn onsets(
    rec: &MeasuredRecord,
    events: &crate::EventScan,
    first: usize,
) -> Vec<(usize, f64, Vec<String>)> {
    let row_of = |day: f64| rec.time_h.iter().position(|&t| t / 24.0 >= day);
    let after: Vec<_> = events
        .alarms
        .iter()
        .filter(|a| row_of(a.onset_day).is_some_and(|r| r >= first))
        .collect();
    let mut out: Vec<(usize, f64, Vec<String>)> = vec![];
    for a in &after {
        let Some(row) = row_of(a.onset_day) else {
            continue;
        };
        if out.iter().any(|o| (o.1 - a.onset_day).abs() <= 1.0) {
            continue;
        }
        let mut gauges = vec![a.gauge.clone()];
        gauges.extend(a.coincident_gauges.iter().cloned());
        gauges.extend(
            after
                .iter()
                .filter(|b| (b.onset_day - a.onset_day).abs() <= super::COINCIDENT_DAYS)
                .map(|b| b.gauge.clone()),
        );
        gauges.sort();
        gauges.dedup();
        if gauges.len() < 2 {
            continue;
        }
        out.push((row, a.onset_day, gauges));
        if out.len() == MAX_ONSETS {
            break;
        }
    }
    out
}

/// Tests each onset and adds the library effect that wins, from its onset, to `post.st`
/// (the residual, the scan and the track re-run after each). Returns the report (`None` when no
/// onset was tested).
pub(super) fn onset_effects(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    post: &mut super::PostPass,
    library: &[Arc<dyn Effect>],
) -> Result<Option<OnsetReport>> {
    let first = super::cal_end(lp);
    let Some(events) = post.events.as_ref() else {
        return Ok(None);
    };
    let tried = onsets(rec, events, first);
    if tried.is_empty() {
        return Ok(None);
    }
    let effects: Vec<&Arc<dyn Effect>> = library.iter().filter(|e| offered(e.as_ref())).collect();
    let sens = sensor::sensitivity(post.st.model.as_ref(), lp.x)?;
    let (mut tests, mut added) = (vec![], vec![]);
    for onset in tried {
        let (test, best) = test_onset(lp, rec, post, &sens, &effects, onset)?;
        if let (Some(f), "effect") = (best, test.verdict.as_str()) {
            post.st.effects.push(f);
            post.st.from_fold.push(lp.folds.len());
            let mut residual = lp.with_y(&post.y).residual(&post.st)?;
            super::zero_masked(&mut residual, &post.mask);
            post.residual = residual;
            let (events, track) =
                crate::whole_record(lp, rec, &post.st, &post.residual, &post.mask)?;
            post.events = events;
            post.track = track;
            added.extend(test.effect_name.clone());
        }
        tests.push(test);
    }
    Ok(Some(OnsetReport {
        tests,
        added,
        error_rmse_with: None,
    }))
}

/// One onset's test: every hypothesis scored on the rows from `from`, and the best effect's fit
/// (to be added when the verdict is `effect`).
fn test_onset(
    lp: &Loop<'_>,
    rec: &MeasuredRecord,
    post: &super::PostPass,
    sens: &DMatrix<f64>,
    effects: &[&Arc<dyn Effect>],
    (from, day, gauges): (usize, f64, Vec<String>),
) -> Result<(OnsetTest, Option<Fitted>)> {
    let fitted = post.fitted();
    let inp = post.scan_input(lp, rec, &fitted);
    let (test, _) = sensor::attribute("onset", &inp, sens, from);
    let ln = (((rec.len() - from) * rec.y.ncols()) as f64).ln();
    let structure = test.structure + ln + 2.0 * 2f64.ln();
    let sensor_score = test.sensor + ln + test.penalty + 2.0 * 2f64.ln();
    let mut out = OnsetTest {
        from_day: day,
        gauges,
        none: test.none,
        structure,
        sensor: sensor_score,
        sensor_hypothesis: test.sensor_hypothesis,
        steps: None,
        effect: None,
        effect_name: None,
        verdict: "structure".into(),
    };
    if test.verdict == "structure" {
        // the gap's own test: a change the parameter explains better than one sensor is the
        // track's and the gap alarm's to judge with the model itself (its response to a change
        // of inches is not the linear one scored here)
        return Ok((out, None));
    }
    let scores = sensor::SpanScores::new(&inp, from);
    let steps = scores.steps_all + rec.y.ncols() as f64 * ln;
    let best = best_effect(lp, post, effects, &scores, (from, day), ln)?;
    out.effect = best.as_ref().map(|(s, _)| *s);
    out.effect_name = best
        .as_ref()
        .map(|(_, f)| format!("{}({})", f.report.name, f.report.covariates.join(",")));
    let sides = [
        ("none", scores.none),
        ("structure", structure),
        ("sensor", sensor_score),
        ("steps", steps),
        ("effect", out.effect.unwrap_or(f64::INFINITY)),
    ];
    let verdict = sides
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or("none", |s| s.0);
    log::info!(
        "onset on day {day:.2} ({}): {verdict}",
        out.gauges.join(", ")
    );
    out.none = scores.none;
    out.steps = Some(steps);
    out.verdict = verdict.into();
    Ok((out, best.map(|(_, f)| f)))
}

/// Every offered effect fitted from the onset and scored with its coefficients (`ln` of the
/// cells each, `ln`) and the choice among the effects; the lowest score and its fit.
fn best_effect(
    lp: &Loop<'_>,
    post: &super::PostPass,
    effects: &[&Arc<dyn Effect>],
    scores: &sensor::SpanScores,
    (from, day): (usize, f64),
    ln: f64,
) -> Result<Option<(f64, Fitted)>> {
    let choice = 2.0 * (effects.len().max(1) as f64).ln();
    let mut best: Option<(f64, Fitted)> = None;
    for e in effects {
        let gated = Arc::new(FromOnset {
            inner: Arc::clone(e),
            from_row: from,
            from_day: day,
            n_rows: post.y.nrows(),
        });
        let ctx = lp.context_of(&post.st);
        let Some(f) = gated.fit(&ctx, &post.residual)? else {
            continue;
        };
        let mut c = f.term.contribution(&ctx)?;
        super::zero_masked(&mut c, &post.mask);
        // the fitted values, less the onset day itself; in a block of one coefficient per
        // gauge, a coefficient the term leaves out on a gauge (exactly zero there, as the
        // operational response's on gauges it does not help) is not one
        let gauges = post.y.ncols();
        let p: usize = f
            .report
            .parameters
            .iter()
            .map(|b| match b.values.len() == gauges {
                true => b.values.iter().filter(|v| **v != 0.0).count(),
                false => b.values.len(),
            })
            .sum::<usize>()
            - 1;
        let score = scores.with_removed(&c) + p as f64 * ln + choice;
        if best.as_ref().is_none_or(|(s, _)| score < *s) {
            best = Some((score, f));
        }
    }
    Ok(best)
}
