//! The operational response: a data-driven term built from the record's own operational events
//! (a lock's fill and empty starts and ends, a gate closing, any change of an operating state),
//! for effects locked to the operating cycle that no formula in the library describes.
//!
//! An *event train* is the rows at which a state column enters (or leaves) one of its values.
//! Each train is passed through two response shapes at six time scales `τ` = 1, 2, 4, 8, 16,
//! 32 h: a first-order decay `Σ_events exp(−(t − s)/τ)` (a response that starts with the event
//! and fades) and a delayed one `Σ_events ((t − s)/τ) exp(1 − (t − s)/τ)` (a response that
//! builds up, peaks `τ` after the event, then fades). A train's twelve columns together are a
//! basis for its impulse response, in the manner of a Laguerre expansion: their sums shape
//! lagged and decaying responses (up to about a day and a half) that none of them is. Each
//! train starts at its steady state (the calibration rows' event rate times `τ`), not at zero,
//! so that the events before the record do not leave a ramp over its first days. One train is
//! chosen, whole, by BIC (each column costs one coefficient per gauge that takes it: a gauge takes
//! the train's columns only when they lower its own BIC, and keeps a constant alone otherwise, so
//! that a response seen on two gauges of seven is not made to pay on all seven); the loop then accepts
//! the term like every other effect, once: only when it lowers the rolling-origin
//! cross-validated error by its margin.

use super::generic::Candidate;
use super::linear::{Basis, LinearTerm};
use crate::effect::{Effect, EffectKind, FitContext, Fitted, param};
use crate::error::Result;
use crate::stats::ols;
use nalgebra::DMatrix;
use std::sync::Arc;

/// The time scales of the responses (hours): a factor of two apart, from a fill's duration to
/// more than a day.
pub const RESPONSE_SCALES_H: [f64; 6] = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0];
/// Most event trains in one term, and the term is not added twice: two trains of one column
/// can rebuild the column's levels (the long-scale decays after entering and after leaving a
/// state differ by about the state's indicator), and the levels of a lock's phase are a
/// function of the head, the load the calibrated model answers for: a term in them took over
/// part of a gap change on a design record.
const MAX_TRAINS: usize = 1;
/// Most distinct values a state column has (a lock's phase has four).
const MAX_STATES: usize = 8;
/// Fewest events of a train on the calibration rows: fewer cannot tell a response from noise.
const MIN_EVENTS: usize = 6;

/// The operational-event response term (see the module docs). State columns are the record's
/// covariates whose values are all whole numbers with between two and eight distinct values
/// (a phase or on/off code such as `lockage_phase`), beside the model's own inputs.
///
/// ```
/// use bamudi_closeloop::{Effect, effects::OperationalResponse};
/// let e = OperationalResponse;
/// assert_eq!(e.name(), "operational_event_response");
/// ```
#[derive(Debug, Clone)]
pub struct OperationalResponse;

impl Effect for OperationalResponse {
    fn name(&self) -> String {
        "operational_event_response".into()
    }
    fn meaning(&self) -> String {
        "response to the record's operational events (state changes), lagged and decaying at 1-32 h"
            .into()
    }
    fn kind(&self) -> EffectKind {
        EffectKind::DataDriven
    }
    fn repeatable(&self) -> bool {
        false
    }
    fn fit(self: Arc<Self>, ctx: &FitContext<'_>, r: &DMatrix<f64>) -> Result<Option<Fitted>> {
        let groups = groups(ctx);
        if groups.is_empty() {
            return Ok(None);
        }
        let chosen = select(ctx, r, &groups);
        if chosen.is_empty() {
            return Ok(None);
        }
        let cols: Vec<&Candidate> = chosen.iter().flat_map(|&g| &groups[g].1).collect();
        let n = ctx.feats.time_h.len();
        let mut basis = vec![vec![1.0; n]];
        basis.extend(
            cols.iter()
                .map(|c| (0..n).map(|i| c.z(i)).collect::<Vec<f64>>()),
        );
        let mut term = LinearTerm::fit(Basis::Columns(basis), ctx, r);
        // a gauge the columns do not help keeps its constant alone (the columns' coefficients
        // zero there, its constant the mean of its residual on the calibration rows)
        let helped = gauges_helped(ctx, r, &groups, &chosen);
        if helped.iter().any(|h| !h) {
            let n = ctx.cal.len() as f64;
            for (g, _) in helped.iter().enumerate().filter(|(_, h)| !**h) {
                term.coef.column_mut(g).fill(0.0);
                term.coef[(0, g)] = ctx.cal.iter().map(|&i| r[(i, g)]).sum::<f64>() / n;
            }
            let c = term.basis.matrix(ctx.feats) * &term.coef;
            term.sse = ctx
                .cal
                .iter()
                .map(|&i| (r.row(i) - c.row(i)).norm_squared())
                .sum();
        }
        let mut p = vec![term.parameter(0, "intercept", ctx.unit)];
        for (k, c) in cols.iter().enumerate() {
            let name = format!("per_sd_of_{} (sd = {:.4})", c.name, c.sd);
            p.push(param(
                &name,
                ctx.unit,
                term.coef.row(k + 1).iter().copied().collect(),
            ));
        }
        let names: Vec<String> = chosen.iter().map(|&g| groups[g].0.clone()).collect();
        // plotted against the state column of the first train chosen
        let plot = ctx.feats.names[cols[0].col].clone();
        Ok(Some(Fitted::new(self, Arc::new(term), names, p, &plot)))
    }
}

/// A group of candidate columns chosen together: its name (an event train) and its columns.
type Group = (String, Vec<Candidate>);

/// Each gauge's BIC of the least-squares fit of `r` on the calibration rows on a constant and
/// the columns of `chosen`: `n ln(SSE_g / n) + (1 + columns) ln n`.
fn gauge_bic(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    groups: &[Group],
    chosen: &[usize],
) -> Vec<f64> {
    let cols: Vec<&Candidate> = chosen.iter().flat_map(|&g| &groups[g].1).collect();
    let rows = ctx.cal;
    let x = DMatrix::from_fn(rows.len(), cols.len() + 1, |i, j| match j {
        0 => 1.0,
        _ => cols[j - 1].z(rows[i]),
    });
    let y = r.select_rows(rows.iter());
    let res = &y - &x * ols(&x, &y);
    let n = rows.len() as f64;
    (0..res.ncols())
        .map(|j| {
            n * (res.column(j).norm_squared() / n).max(1e-300).ln()
                + (cols.len() + 1) as f64 * n.ln()
        })
        .collect()
}

/// BIC of the fit of `r` on the columns of `chosen` where each gauge takes them only when they
/// lower its own BIC (a constant alone otherwise): the sum over the gauges of the lower of the
/// two. A response to the lock's cycle need not show on every gauge, and a term that made every
/// gauge pay for its columns would be chosen only when it is strong on most of them.
fn bic(ctx: &FitContext<'_>, r: &DMatrix<f64>, groups: &[Group], chosen: &[usize]) -> f64 {
    let without = gauge_bic(ctx, r, groups, &[]);
    if chosen.is_empty() {
        return without.iter().sum();
    }
    let with = gauge_bic(ctx, r, groups, chosen);
    with.iter().zip(&without).map(|(a, b)| a.min(*b)).sum()
}

/// The gauges whose own BIC the columns of `chosen` lower ([`bic`]).
fn gauges_helped(
    ctx: &FitContext<'_>,
    r: &DMatrix<f64>,
    groups: &[Group],
    chosen: &[usize],
) -> Vec<bool> {
    let without = gauge_bic(ctx, r, groups, &[]);
    let with = gauge_bic(ctx, r, groups, chosen);
    with.iter().zip(&without).map(|(a, b)| a < b).collect()
}

/// Forward selection of whole groups by BIC, at most [`MAX_TRAINS`].
fn select(ctx: &FitContext<'_>, r: &DMatrix<f64>, groups: &[Group]) -> Vec<usize> {
    let mut chosen: Vec<usize> = vec![];
    let mut best = bic(ctx, r, groups, &chosen);
    while chosen.len() < MAX_TRAINS {
        let step = (0..groups.len())
            .filter(|g| !chosen.contains(g))
            .map(|g| {
                let mut trial = chosen.clone();
                trial.push(g);
                (bic(ctx, r, groups, &trial), g)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        match step {
            Some((v, g)) if v < best => {
                best = v;
                chosen.push(g);
            }
            _ => break,
        }
    }
    chosen
}

/// Whether `values` are a state column's: whole numbers, two to [`MAX_STATES`] distinct values.
fn is_state_column(values: &[f64]) -> bool {
    if values
        .iter()
        .any(|v| !v.is_finite() || (v - v.round()).abs() > 1e-9)
    {
        return false;
    }
    let mut distinct: Vec<i64> = values.iter().map(|v| v.round() as i64).collect();
    distinct.sort_unstable();
    distinct.dedup();
    (2..=MAX_STATES).contains(&distinct.len())
}

/// The event trains of the state column `values` (named `name`): for each value `k`, the rows
/// where the column enters `k` and those where it leaves `k`, each train once (in a cycle the
/// end of one phase is the start of the next).
fn trains(values: &[f64], name: &str) -> Vec<(String, Vec<bool>)> {
    let mut states: Vec<i64> = values.iter().map(|v| v.round() as i64).collect();
    states.sort_unstable();
    states.dedup();
    let n = values.len();
    let mut out: Vec<(String, Vec<bool>)> = vec![];
    for &k in &states {
        let is = |i: usize| values[i].round() as i64 == k;
        let starts: Vec<bool> = (0..n).map(|i| i > 0 && is(i) && !is(i - 1)).collect();
        let ends: Vec<bool> = (0..n).map(|i| i > 0 && !is(i) && is(i - 1)).collect();
        for (label, train) in [("start", starts), ("end", ends)] {
            if !out.iter().any(|(_, t)| *t == train) {
                out.push((format!("{label} of {name}={k}"), train));
            }
        }
    }
    out
}

/// The decaying and the delayed response to the events of `train` at time scale `tau_h`:
/// `a_i = e^{−Δ/τ} a_{i−1} + [event at i]` and `b_i = e^{−Δ/τ} (b_{i−1} + (Δ/τ) a_{i−1})`,
/// the exact sampled values of `Σ e^{−u/τ}` and `Σ (u/τ) e^{−u/τ}` (`u` the time since each
/// event) on any row spacing, started at their steady state for events at `rate_per_h` before
/// the first row (both `rate · τ`); `b` is scaled by `e` to peak at one.
pub(crate) fn responses(
    t_h: &[f64],
    train: &[bool],
    tau_h: f64,
    rate_per_h: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = t_h.len();
    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
    let steady = rate_per_h * tau_h;
    for i in 0..n {
        let (a0, b0, decay, dt) = match i {
            0 => (steady, steady, 1.0, 0.0),
            _ => {
                let dt = t_h[i] - t_h[i - 1];
                (a[i - 1], b[i - 1], (-dt / tau_h).exp(), dt / tau_h)
            }
        };
        a[i] = decay * a0 + f64::from(u8::from(train[i]));
        b[i] = decay * (b0 + dt * a0);
    }
    b.iter_mut().for_each(|v| *v *= std::f64::consts::E);
    (a, b)
}

/// Events per hour of `train` over the calibration rows.
fn event_rate(ctx: &FitContext<'_>, train: &[bool]) -> f64 {
    let t = &ctx.feats.time_h;
    let (Some(&first), Some(&last)) = (ctx.cal.first(), ctx.cal.last()) else {
        return 0.0;
    };
    let count = ctx.cal.iter().filter(|&&i| train[i]).count() as f64;
    count / (t[last] - t[first]).max(1e-9)
}

/// Every group: per state column beside the model, the responses of each train with at least
/// [`MIN_EVENTS`] events on the calibration rows at every scale. The state's own levels are not
/// a group: on a lock they are a function of the head (gate open, full lift), the load the
/// calibrated model and its discrepancy already answer for, and a term in them takes over part
/// of a change of the gap (seen on a design record: the gap stayed 3 in off with them).
fn groups(ctx: &FitContext<'_>) -> Vec<Group> {
    let f = ctx.feats;
    let mut out = vec![];
    for &c in &f.lag_sources {
        if !super::generic::beside_model(ctx, c) || !is_state_column(&f.cols[c]) {
            continue;
        }
        let name = &f.names[c];
        for (label, train) in trains(&f.cols[c], name) {
            if ctx.cal.iter().filter(|&&i| train[i]).count() < MIN_EVENTS {
                continue;
            }
            let rate = event_rate(ctx, &train);
            let mut cols = vec![];
            for tau in RESPONSE_SCALES_H {
                let (a, b) = responses(&f.time_h, &train, tau, rate);
                cols.push(Candidate::from_values(
                    ctx,
                    c,
                    format!("decay{tau}h({label})"),
                    a,
                ));
                cols.push(Candidate::from_values(
                    ctx,
                    c,
                    format!("delay{tau}h({label})"),
                    b,
                ));
            }
            out.push((format!("response to {label}"), cols));
        }
    }
    for g in &mut out {
        g.1.retain(|c| c.sd > 1e-12);
    }
    out.retain(|g| !g.1.is_empty());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One event at 0 on an uneven grid: the recursions equal the closed forms.
    #[test]
    fn responses_are_the_closed_forms_on_any_spacing() {
        let t = [0.0, 0.5, 2.0, 2.25, 7.0, 30.0];
        let train = [true, false, false, false, false, false];
        let tau = 3.0;
        let (a, b) = responses(&t, &train, tau, 0.0);
        for (i, &ti) in t.iter().enumerate() {
            let u: f64 = ti / tau;
            // tolerance: a few roundings of an exp per step
            assert!((a[i] - (-u).exp()).abs() < 1e-12, "{i}");
            assert!((b[i] - u * (1.0 - u).exp()).abs() < 1e-12, "{i}");
        }
    }

    /// Events every 2 h from before the first row: started at the steady state, both responses
    /// repeat with the events' period from the first row on (no start-up ramp).
    #[test]
    fn a_regular_train_starts_at_its_steady_state() {
        let t: Vec<f64> = (0..200).map(|i| f64::from(i) * 0.5).collect();
        let train: Vec<bool> = (0..200).map(|i| i % 4 == 0).collect();
        for tau in RESPONSE_SCALES_H {
            let (a, b) = responses(&t, &train, tau, 0.5);
            // the mean over one period (4 rows) at the start and at the end. Tolerance: the
            // start is the continuous-time mean `rate · τ`, not the periodic train's value just
            // before an event; they differ by less than a third of the level, or of one event's
            // response when the level is below one (started at zero, τ = 32 h is 16x off)
            let mean = |v: &[f64], from: usize| v[from..from + 4].iter().sum::<f64>() / 4.0;
            let (a0, a_late) = (mean(&a, 0), mean(&a, 196));
            let (b0, b_late) = (mean(&b, 0), mean(&b, 196));
            assert!(
                (a0 - a_late).abs() < 0.35 * a_late.max(1.0),
                "τ {tau}: {a0} {a_late}"
            );
            assert!(
                (b0 - b_late).abs() < 0.35 * b_late.max(1.0),
                "τ {tau}: {b0} {b_late}"
            );
        }
    }

    #[test]
    fn a_cycle_gives_one_train_per_change() {
        let v = [0.0, 1.0, 2.0, 3.0, 0.0, 1.0, 2.0, 3.0, 0.0];
        assert!(is_state_column(&v));
        assert!(!is_state_column(&[0.5, 1.0]));
        assert!(!is_state_column(&[1.0; 5]));
        // entering k is leaving k−1: four trains, not eight
        assert_eq!(trains(&v, "p").len(), 4);
        // an on/off column: on and off are two trains
        assert_eq!(trains(&[0.0, 1.0, 1.0, 0.0, 1.0], "gate").len(), 2);
    }
}
