//! The library of physically named effects and the generic data-driven term. Each effect is
//! a parametric term added to the observable model; its parameters are estimated on the
//! calibration window only.

use super::stats::{correlation, ols, select_rows};
use super::{CalibratedModel, Features};
use crate::BamudiError;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Which effect (with its non-estimated structure, e.g. the temperature column).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum EffectSpec {
    /// Constant zero offset per gauge.
    GaugeOffset,
    /// Zero offset + linear drift in time per gauge.
    GaugeDrift,
    /// Zero offset + a step at a gauge-specific time.
    OffsetJump,
    /// Thermal strain driven by a lagged temperature column.
    Thermal {
        /// Feature (column) name of the temperature.
        column: String,
    },
    /// Different strain while the head rises (filling) and falls (emptying).
    LoadPath,
    /// A bottom gap changing linearly in time.
    GapTrend,
    /// Sparse linear model in the covariates (forward stepwise, BIC).
    Generic,
}

impl EffectSpec {
    /// Short machine name.
    pub fn name(&self) -> String {
        match self {
            Self::GaugeOffset => "gauge_offset".into(),
            Self::GaugeDrift => "gauge_drift".into(),
            Self::OffsetJump => "gauge_offset_jump".into(),
            Self::Thermal { column } => format!("thermal({column})"),
            Self::LoadPath => "load_path_hysteresis".into(),
            Self::GapTrend => "time_varying_gap".into(),
            Self::Generic => "generic_covariate_term".into(),
        }
    }
    /// Physical meaning, for the report.
    pub fn meaning(&self) -> &'static str {
        match self {
            Self::GaugeOffset => "constant gauge zero error (microstrain)",
            Self::GaugeDrift => {
                "gauge zero drifting linearly in time (adhesive creep, moisture; microstrain/day)"
            }
            Self::OffsetJump => {
                "step in a gauge zero (logger reset, re-bonded gauge, electrical transient)"
            }
            Self::Thermal { .. } => {
                "apparent/thermal strain proportional to a first-order-lagged temperature (microstrain/°F)"
            }
            Self::LoadPath => {
                "load-path hysteresis: friction at quoin/miter contacts, different strain while filling vs emptying"
            }
            Self::GapTrend => {
                "bottom gap changing during the record (progressive loss of quoin contact)"
            }
            Self::Generic => "effect outside the library: linear in the named covariates",
        }
    }
}

/// One named parameter block (one value per gauge, or a single value).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EffectParameter {
    /// Parameter name.
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Values (per gauge, in gauge order, unless the name says otherwise).
    pub values: Vec<f64>,
}

/// A fitted effect as reported in `results.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EffectReport {
    /// Effect name (see [`EffectSpec::name`]).
    pub name: String,
    /// Physical meaning.
    pub meaning: String,
    /// Covariates the term uses.
    pub covariates: Vec<String>,
    /// Fitted parameters.
    pub parameters: Vec<EffectParameter>,
}

/// How a fitted effect is evaluated.
#[derive(Debug, Clone)]
pub(crate) enum Term {
    /// `basis (n x p) * coef (p x g)`.
    Linear { basis: Basis, coef: DMatrix<f64> },
    /// Per gauge: offset + step at `times[g]` (hours) if any.
    Jump {
        times: Vec<Option<f64>>,
        level: Vec<f64>,
        step: Vec<f64>,
    },
    /// `g(x, a + b t) − g(x, θ̂)`, `t` in hours.
    Gap {
        a: f64,
        b_per_h: f64,
        bounds: (f64, f64),
    },
}

#[derive(Debug, Clone)]
pub(crate) enum Basis {
    Offset,
    Drift,
    Thermal {
        col: usize,
        tau_h: f64,
    },
    LoadPath,
    Generic {
        cols: Vec<usize>,
        mean: Vec<f64>,
        sd: Vec<f64>,
    },
}

/// A fitted effect.
#[derive(Debug, Clone)]
pub(crate) struct Fitted {
    pub spec: EffectSpec,
    pub term: Term,
    pub report: EffectReport,
    /// Main covariate for plots.
    pub plot_covariate: String,
    /// For the gap trend: (gap at end of record, its standard error) in inches.
    pub gap_end: Option<(f64, f64, f64)>,
}

/// Context shared by all fits.
pub(crate) struct FitContext<'a> {
    pub feats: &'a Features,
    pub x: &'a DMatrix<f64>,
    pub cal: &'a [usize],
    pub model: &'a dyn CalibratedModel,
    pub base_mean: &'a DMatrix<f64>,
    pub gauges: &'a [String],
    pub gap_segments: usize,
    pub max_generic_features: usize,
}

fn first_order_lag(t_h: &[f64], v: &[f64], tau_h: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(v.len());
    let mut s = v[0];
    for i in 0..v.len() {
        if i > 0 {
            let a = if tau_h <= 0.0 {
                0.0
            } else {
                (-(t_h[i] - t_h[i - 1]) / tau_h).exp()
            };
            s = a * s + (1.0 - a) * v[i];
        }
        out.push(s);
    }
    out
}

fn basis_matrix(b: &Basis, f: &Features) -> DMatrix<f64> {
    let n = f.time_h.len();
    match b {
        Basis::Offset => DMatrix::from_element(n, 1, 1.0),
        Basis::Drift => {
            DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { f.time_h[i] / 24.0 })
        }
        Basis::Thermal { col, tau_h } => {
            let lag = first_order_lag(&f.time_h, &f.cols[*col], *tau_h);
            DMatrix::from_fn(n, 2, |i, j| if j == 0 { 1.0 } else { lag[i] })
        }
        Basis::LoadPath => DMatrix::from_fn(n, 4, |i, j| {
            let h = f.head[i] / 100.0;
            let rate = f.head_rate[i];
            let ind = if j < 2 { rate > 1e-9 } else { rate < -1e-9 };
            if !ind {
                0.0
            } else if j % 2 == 0 {
                h
            } else {
                h * h
            }
        }),
        Basis::Generic { cols, mean, sd } => DMatrix::from_fn(n, cols.len() + 1, |i, j| {
            if j == 0 {
                1.0
            } else {
                (f.cols[cols[j - 1]][i] - mean[j - 1]) / sd[j - 1]
            }
        }),
    }
}

/// Contribution (n x g, microstrain) of a fitted effect to every row.
pub(crate) fn contribution(fit: &Fitted, ctx: &FitContext) -> Result<DMatrix<f64>, BamudiError> {
    let f = ctx.feats;
    let g = ctx.gauges.len();
    let n = f.time_h.len();
    Ok(match &fit.term {
        Term::Linear { basis, coef } => basis_matrix(basis, f) * coef,
        Term::Jump { times, level, step } => DMatrix::from_fn(n, g, |i, j| {
            level[j] + times[j].map_or(0.0, |tj| if f.time_h[i] >= tj { step[j] } else { 0.0 })
        }),
        Term::Gap { a, b_per_h, bounds } => {
            let theta: Vec<f64> = f
                .time_h
                .iter()
                .map(|t| (a + b_per_h * t).clamp(bounds.0, bounds.1))
                .collect();
            ctx.model.predict_at_theta(ctx.x, &theta)? - ctx.base_mean
        }
    })
}

fn sse_cal(r: &DMatrix<f64>, c: &DMatrix<f64>, cal: &[usize]) -> f64 {
    cal.iter()
        .map(|&i| (r.row(i) - c.row(i)).norm_squared())
        .sum()
}

fn fit_linear(basis: Basis, ctx: &FitContext, r: &DMatrix<f64>) -> (DMatrix<f64>, f64, Basis) {
    let bm = basis_matrix(&basis, ctx.feats);
    let coef = ols(&select_rows(&bm, ctx.cal), &select_rows(r, ctx.cal));
    let c = &bm * &coef;
    (coef, sse_cal(r, &c, ctx.cal), basis)
}

fn per_gauge(coef: &DMatrix<f64>, row: usize) -> Vec<f64> {
    coef.row(row).iter().copied().collect()
}

fn param(name: &str, unit: &str, values: Vec<f64>) -> EffectParameter {
    EffectParameter {
        name: name.into(),
        unit: unit.into(),
        values,
    }
}

/// Fits `spec` to the residual `r` (n x g) on the calibration rows. `None` when the effect
/// does not apply (e.g. no jump found, too few segments).
pub(crate) fn fit(
    spec: &EffectSpec,
    ctx: &FitContext,
    r: &DMatrix<f64>,
) -> Result<Option<Fitted>, BamudiError> {
    let mk = |term: Term, covariates: Vec<String>, parameters: Vec<EffectParameter>, plot: &str| {
        Fitted {
            spec: spec.clone(),
            term,
            report: EffectReport {
                name: spec.name(),
                meaning: spec.meaning().into(),
                covariates,
                parameters,
            },
            plot_covariate: plot.into(),
            gap_end: None,
        }
    };
    Ok(Some(match spec {
        EffectSpec::GaugeOffset => {
            let (coef, _, basis) = fit_linear(Basis::Offset, ctx, r);
            let p = vec![param("offset", "microstrain", per_gauge(&coef, 0))];
            mk(Term::Linear { basis, coef }, vec![], p, "time_days")
        }
        EffectSpec::GaugeDrift => {
            let (coef, _, basis) = fit_linear(Basis::Drift, ctx, r);
            let p = vec![
                param("offset_at_start", "microstrain", per_gauge(&coef, 0)),
                param("drift_rate", "microstrain/day", per_gauge(&coef, 1)),
            ];
            mk(
                Term::Linear { basis, coef },
                vec!["time_days".into()],
                p,
                "time_days",
            )
        }
        EffectSpec::OffsetJump => match fit_jump(ctx, r) {
            None => return Ok(None),
            Some((times, level, step)) => {
                let p = vec![
                    param("level_before", "microstrain", level.clone()),
                    param(
                        "jump_day (NaN = none)",
                        "day",
                        times
                            .iter()
                            .map(|t| t.map_or(f64::NAN, |t| t / 24.0))
                            .collect(),
                    ),
                    param("jump_size", "microstrain", step.clone()),
                ];
                mk(
                    Term::Jump { times, level, step },
                    vec!["time_days".into()],
                    p,
                    "time_days",
                )
            }
        },
        EffectSpec::Thermal { column } => {
            let Some(col) = ctx.feats.names.iter().position(|n| n == column) else {
                return Ok(None);
            };
            let (coef, tau_h) = fit_thermal(ctx, r, col);
            let basis = Basis::Thermal { col, tau_h };
            // temperature at which the thermal term vanishes (the gauges' zeroing temperature
            // when nothing else offsets them)
            let zero_temp = (0..coef.ncols())
                .map(|g| -coef[(0, g)] / coef[(1, g)])
                .collect();
            let p = vec![
                param("coefficient", "microstrain/°F", per_gauge(&coef, 1)),
                param("intercept", "microstrain", per_gauge(&coef, 0)),
                param("zero_strain_temperature", "°F", zero_temp),
                param("lag_time_constant (all gauges)", "hours", vec![tau_h]),
            ];
            mk(
                Term::Linear { basis, coef },
                vec![column.clone()],
                p,
                column,
            )
        }
        EffectSpec::LoadPath => {
            if !ctx.cal.iter().any(|&i| ctx.feats.head_rate[i].abs() > 1e-9) {
                return Ok(None);
            }
            let (coef, _, basis) = fit_linear(Basis::LoadPath, ctx, r);
            let p = vec![
                param("filling_per_100in_head", "microstrain", per_gauge(&coef, 0)),
                param(
                    "filling_per_100in_head_sq",
                    "microstrain",
                    per_gauge(&coef, 1),
                ),
                param(
                    "emptying_per_100in_head",
                    "microstrain",
                    per_gauge(&coef, 2),
                ),
                param(
                    "emptying_per_100in_head_sq",
                    "microstrain",
                    per_gauge(&coef, 3),
                ),
            ];
            mk(
                Term::Linear { basis, coef },
                vec!["head".into(), "d_head_per_h".into()],
                p,
                "d_head_per_h",
            )
        }
        EffectSpec::GapTrend => match fit_gap_trend(ctx, r)? {
            None => return Ok(None),
            Some((a, b, bounds, end)) => {
                let p = vec![
                    param("gap_at_start", "in", vec![a]),
                    param("gap_rate", "in/day", vec![b * 24.0]),
                    param("gap_at_end", "in", vec![end.0]),
                ];
                let mut f = mk(
                    Term::Gap {
                        a,
                        b_per_h: b,
                        bounds,
                    },
                    vec!["time_days".into()],
                    p,
                    "time_days",
                );
                f.gap_end = Some(end);
                f
            }
        },
        EffectSpec::Generic => match fit_generic(ctx, r) {
            None => return Ok(None),
            Some((cols, mean, sd, coef)) => {
                let names: Vec<String> = cols.iter().map(|&c| ctx.feats.names[c].clone()).collect();
                let mut p = vec![param("intercept", "microstrain", per_gauge(&coef, 0))];
                for (k, nm) in names.iter().enumerate() {
                    p.push(param(
                        &format!("per_sd_of_{nm} (sd = {:.4})", sd[k]),
                        "microstrain",
                        per_gauge(&coef, k + 1),
                    ));
                }
                let plot = names[0].clone();
                mk(
                    Term::Linear {
                        basis: Basis::Generic { cols, mean, sd },
                        coef,
                    },
                    names,
                    p,
                    &plot,
                )
            }
        },
    }))
}

/// Per gauge, the best single step (by cumulative sums over the calibration rows); kept only
/// where BIC favours it (`n ln(SSE0/SSE1) > 3 ln n`: level, size and time are 3 parameters).
#[allow(clippy::type_complexity)]
fn fit_jump(ctx: &FitContext, r: &DMatrix<f64>) -> Option<(Vec<Option<f64>>, Vec<f64>, Vec<f64>)> {
    let cal = ctx.cal;
    let n = cal.len();
    if n < 20 {
        return None;
    }
    let (mut times, mut level, mut step) = (vec![], vec![], vec![]);
    for j in 0..r.ncols() {
        let v: Vec<f64> = cal.iter().map(|&i| r[(i, j)]).collect();
        let (tot, tot2) = (v.iter().sum::<f64>(), v.iter().map(|x| x * x).sum::<f64>());
        let sse0 = tot2 - tot * tot / n as f64;
        let mut best = (sse0, 0usize);
        let (mut s, mut s2) = (0.0, 0.0);
        let min_seg = (n / 20).max(5);
        for k in 0..n - min_seg {
            s += v[k];
            s2 += v[k] * v[k];
            let m = k + 1;
            if m < min_seg {
                continue;
            }
            let sse = (s2 - s * s / m as f64) + ((tot2 - s2) - (tot - s).powi(2) / (n - m) as f64);
            if sse < best.0 {
                best = (sse, m);
            }
        }
        let m = best.1;
        let keep = m > 0 && best.0 > 0.0 && n as f64 * (sse0 / best.0).ln() > 3.0 * (n as f64).ln();
        if keep {
            let before = v[..m].iter().sum::<f64>() / m as f64;
            let after = v[m..].iter().sum::<f64>() / (n - m) as f64;
            times.push(Some(
                0.5 * (ctx.feats.time_h[cal[m - 1]] + ctx.feats.time_h[cal[m]]),
            ));
            level.push(before);
            step.push(after - before);
        } else {
            times.push(None);
            level.push(tot / n as f64);
            step.push(0.0);
        }
    }
    times
        .iter()
        .any(Option::is_some)
        .then_some((times, level, step))
}

/// Thermal term: lag time constant by a grid over 0-128 h refined by golden section on ln τ.
fn fit_thermal(ctx: &FitContext, r: &DMatrix<f64>, col: usize) -> (DMatrix<f64>, f64) {
    let sse = |tau: f64| fit_linear(Basis::Thermal { col, tau_h: tau }, ctx, r).1;
    let grid = [0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0];
    let vals: Vec<f64> = grid.iter().map(|&t| sse(t)).collect();
    let k = (0..grid.len())
        .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    let mut tau = grid[k];
    if k > 0 && k + 1 < grid.len() {
        // golden section on ln τ between the grid neighbours
        let (mut lo, mut hi) = (grid[k - 1].max(0.25).ln(), grid[k + 1].ln());
        let gr = 0.618_033_988_75;
        for _ in 0..25 {
            let (a, b) = (hi - gr * (hi - lo), lo + gr * (hi - lo));
            if sse(a.exp()) < sse(b.exp()) {
                hi = b
            } else {
                lo = a
            }
        }
        let t = (0.5 * (lo + hi)).exp();
        if sse(t) < vals[k] {
            tau = t;
        }
    }
    let (coef, _, _) = fit_linear(Basis::Thermal { col, tau_h: tau }, ctx, r);
    (coef, tau)
}

/// Gap trend: the calibration window cut into segments, the gap of each found by a grid
/// search of the model conditional on θ, then a straight line through the segment gaps.
/// Returns (gap at t = 0, rate per hour, prior bounds, (gap at end, sd, half-width of 95 %)).
#[allow(clippy::type_complexity)]
fn fit_gap_trend(
    ctx: &FitContext,
    r: &DMatrix<f64>,
) -> Result<Option<(f64, f64, (f64, f64), (f64, f64, f64))>, BamudiError> {
    let k = ctx.gap_segments;
    let n = ctx.cal.len();
    if k < 3 || n < 10 * k {
        return Ok(None);
    }
    let bounds = ctx.model.theta_bounds();
    let grid: Vec<f64> = (0..=40)
        .map(|i| bounds.0 + (bounds.1 - bounds.0) * i as f64 / 40.0)
        .collect();
    let (mut tk, mut thk) = (vec![], vec![]);
    for s in 0..k {
        let rows: Vec<usize> = ctx.cal[s * n / k..(s + 1) * n / k].to_vec();
        let xs = select_rows(ctx.x, &rows);
        // target = data minus the other effects = residual + current model mean
        let target = select_rows(r, &rows) + select_rows(ctx.base_mean, &rows);
        let mut sse = Vec::with_capacity(grid.len());
        for &th in &grid {
            let p = ctx.model.predict_at_theta(&xs, &vec![th; rows.len()])?;
            sse.push((&target - p).norm_squared());
        }
        let b = (0..grid.len())
            .min_by(|&a, &c| sse[a].total_cmp(&sse[c]))
            .unwrap_or(0);
        let mut th = grid[b];
        if b > 0 && b + 1 < grid.len() {
            // vertex of the parabola through the three grid points around the minimum
            let (y0, y1, y2) = (sse[b - 1], sse[b], sse[b + 1]);
            let den = y0 - 2.0 * y1 + y2;
            if den > 0.0 {
                th += 0.5 * (y0 - y2) / den * (grid[1] - grid[0]);
            }
        }
        tk.push(rows.iter().map(|&i| ctx.feats.time_h[i]).sum::<f64>() / rows.len() as f64);
        thk.push(th);
    }
    let kf = k as f64;
    let (tm, ym) = (tk.iter().sum::<f64>() / kf, thk.iter().sum::<f64>() / kf);
    let sxx: f64 = tk.iter().map(|t| (t - tm).powi(2)).sum();
    let b = tk
        .iter()
        .zip(&thk)
        .map(|(t, y)| (t - tm) * (y - ym))
        .sum::<f64>()
        / sxx;
    let a = ym - b * tm;
    let s2 = tk
        .iter()
        .zip(&thk)
        .map(|(t, y)| (y - a - b * t).powi(2))
        .sum::<f64>()
        / (kf - 2.0);
    let t_end = *ctx.feats.time_h.last().unwrap_or(&0.0);
    let end = (a + b * t_end).clamp(bounds.0, bounds.1);
    let sd = (s2 * (1.0 / kf + (t_end - tm).powi(2) / sxx)).sqrt();
    Ok(Some((a, b, bounds, (end, sd, student_t975(k - 2) * sd))))
}

/// 97.5 % quantile of Student's t with `dof` degrees of freedom (table; normal beyond 30).
fn student_t975(dof: usize) -> f64 {
    const T: [f64; 10] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    ];
    match dof {
        0 => f64::INFINITY,
        1..=10 => T[dof - 1],
        11..=30 => 2.228 - (dof as f64 - 10.0) * (2.228 - 2.042) / 20.0,
        _ => 1.96,
    }
}

/// Forward stepwise selection over all features but the model inputs (standardised on the calibration rows), one
/// shared feature set with per-gauge coefficients, stopped by BIC. Returns the chosen feature
/// columns, their means and sds, and the coefficients (`1 + k` x g).
#[allow(clippy::type_complexity)]
fn fit_generic(
    ctx: &FitContext,
    r: &DMatrix<f64>,
) -> Option<(Vec<usize>, Vec<f64>, Vec<f64>, DMatrix<f64>)> {
    let f = ctx.feats;
    let cal = ctx.cal;
    let n = cal.len() as f64;
    let g = r.ncols() as f64;
    let stats: Vec<(f64, f64)> = f
        .cols
        .iter()
        .map(|c| {
            let m = cal.iter().map(|&i| c[i]).sum::<f64>() / n;
            let sd = (cal.iter().map(|&i| (c[i] - m).powi(2)).sum::<f64>() / n).sqrt();
            (m, sd)
        })
        .collect();
    let rc = select_rows(r, cal);
    let cal_values = |c: usize| -> Vec<f64> { cal.iter().map(|&i| f.cols[c][i]).collect() };
    let bic = |cols: &[usize]| -> (f64, DMatrix<f64>) {
        let x = DMatrix::from_fn(cal.len(), cols.len() + 1, |i, j| {
            if j == 0 {
                1.0
            } else {
                (f.cols[cols[j - 1]][cal[i]] - stats[cols[j - 1]].0) / stats[cols[j - 1]].1
            }
        });
        let coef = ols(&x, &rc);
        let res = &rc - &x * &coef;
        let mut crit = 0.0;
        for j in 0..res.ncols() {
            crit += n * (res.column(j).norm_squared() / n).max(1e-300).ln();
        }
        (crit + (cols.len() + 1) as f64 * g * n.ln(), coef)
    };
    let mut chosen: Vec<usize> = vec![];
    let mut best = bic(&chosen).0;
    while chosen.len() < ctx.max_generic_features {
        let mut step: Option<(f64, usize)> = None;
        for c in 0..f.cols.len() {
            // the model inputs themselves belong to the calibrated model (its discrepancy is a
            // function of them), so the generic term only looks beyond them
            // (a covariate that duplicates one, e.g. `chamber` = `h_up`, counts as one)
            let model_input = matches!(f.names[c].as_str(), "h_up" | "h_down" | "head")
                || (1..=3).any(|m| correlation(&cal_values(c), &cal_values(m)).abs() > 0.999);
            if model_input || chosen.contains(&c) || stats[c].1 <= 1e-12 {
                continue;
            }
            let mut trial = chosen.clone();
            trial.push(c);
            let v = bic(&trial).0;
            if step.is_none_or(|s| v < s.0) {
                step = Some((v, c));
            }
        }
        match step {
            Some((v, c)) if v < best => {
                best = v;
                chosen.push(c);
            }
            _ => break,
        }
    }
    if chosen.is_empty() {
        return None;
    }
    let coef = bic(&chosen).1;
    let mean = chosen.iter().map(|&c| stats[c].0).collect();
    let sd = chosen.iter().map(|&c| stats[c].1).collect();
    Some((chosen, mean, sd, coef))
}
