//! The state-space model of the tracked parameter: a local linear trend (level and slope,
//! each a random walk in continuous time) observed through the window estimates, with its
//! Kalman filter, Rauch-Tung-Striebel smoother and maximum-likelihood noise variances. The
//! local level (no slope) and the constant are its special cases.

/// Window estimates `(mean, sd)` (`None`: no information) at window mid-times (days).
pub(super) struct Obs<'a> {
    pub est: &'a [Option<(f64, f64)>],
    pub days: &'a [f64],
}

/// Noise variances per day and the initial state.
#[derive(Debug, Clone, Copy)]
pub(super) struct Model {
    /// Level random-walk variance per day.
    pub q_level: f64,
    /// Slope random-walk variance per day (level units² / day³).
    pub q_slope: f64,
    /// Initial level mean and variance (the prior).
    pub level0: (f64, f64),
    /// Initial slope variance (mean 0); 0 = no slope.
    pub slope0_var: f64,
}

type V2 = [f64; 2];
type M2 = [[f64; 2]; 2];

/// Filtered and predicted states, innovations and the log-likelihood.
pub(super) struct Filtered {
    pub a: Vec<V2>,
    pub p: Vec<M2>,
    a_pred: Vec<V2>,
    p_pred: Vec<M2>,
    /// Innovation and its variance at informative windows.
    pub innovations: Vec<Option<(f64, f64)>>,
    pub loglik: f64,
}

/// Transition over `dt` days and its noise covariance (exact for the continuous-time model).
fn transition(m: &Model, dt: f64) -> (M2, M2) {
    let t = [[1.0, dt], [0.0, 1.0]];
    let qs = m.q_slope;
    let q = [
        [m.q_level * dt + qs * dt.powi(3) / 3.0, qs * dt * dt / 2.0],
        [qs * dt * dt / 2.0, qs * dt],
    ];
    (t, q)
}

fn mul(a: &M2, b: &M2) -> M2 {
    let mut c = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
        }
    }
    c
}

fn transpose(a: &M2) -> M2 {
    [[a[0][0], a[1][0]], [a[0][1], a[1][1]]]
}

/// Inverse of a symmetric positive semi-definite 2x2 matrix, regularised on its trace when
/// singular (a state without variance, e.g. the slope of a model without one).
fn inverse(a: &M2) -> M2 {
    let eps = 1e-12 * (a[0][0] + a[1][1]).abs().max(1e-300);
    let (p, q, r) = (a[0][0] + eps, a[0][1], a[1][1] + eps);
    let det = p * r - q * q;
    [[r / det, -q / det], [-q / det, p / det]]
}

/// The Kalman filter. The first informative windows, as many as the model has uncertain
/// initial states, only set those states: they are left out of the likelihood.
pub(super) fn filter(obs: &Obs<'_>, m: &Model) -> Filtered {
    let mut a: V2 = [m.level0.0, 0.0];
    let mut p: M2 = [[m.level0.1, 0.0], [0.0, m.slope0_var]];
    let diffuse = 1 + usize::from(m.slope0_var > 0.0);
    let mut seen = 0;
    let n = obs.est.len();
    let mut f = Filtered {
        a: Vec::with_capacity(n),
        p: Vec::with_capacity(n),
        a_pred: Vec::with_capacity(n),
        p_pred: Vec::with_capacity(n),
        innovations: Vec::with_capacity(n),
        loglik: 0.0,
    };
    for w in 0..n {
        if w > 0 {
            let (t, q) = transition(m, obs.days[w] - obs.days[w - 1]);
            a = [a[0] + t[0][1] * a[1], a[1]];
            let tp = mul(&mul(&t, &p), &transpose(&t));
            p = [
                [tp[0][0] + q[0][0], tp[0][1] + q[0][1]],
                [tp[1][0] + q[1][0], tp[1][1] + q[1][1]],
            ];
        }
        f.a_pred.push(a);
        f.p_pred.push(p);
        let mut innovation = None;
        if let Some((y, sd)) = obs.est[w] {
            let s = p[0][0] + sd * sd;
            let v = y - a[0];
            let k = [p[0][0] / s, p[1][0] / s];
            if seen >= diffuse {
                f.loglik -= 0.5 * ((2.0 * std::f64::consts::PI * s).ln() + v * v / s);
            }
            seen += 1;
            a = [a[0] + k[0] * v, a[1] + k[1] * v];
            p = [
                [p[0][0] - k[0] * p[0][0], p[0][1] - k[0] * p[0][1]],
                [p[1][0] - k[1] * p[0][0], p[1][1] - k[1] * p[0][1]],
            ];
            innovation = Some((v, s));
        }
        f.a.push(a);
        f.p.push(p);
        f.innovations.push(innovation);
    }
    f
}

/// Rauch-Tung-Striebel smoother: the level's mean and variance per window.
pub(super) fn smooth(obs: &Obs<'_>, m: &Model, f: &Filtered) -> Vec<(f64, f64)> {
    let n = f.a.len();
    let (mut a_s, mut p_s) = (f.a[n - 1], f.p[n - 1]);
    let mut out = vec![(a_s[0], p_s[0][0]); n];
    for w in (0..n - 1).rev() {
        let (t, _) = transition(m, obs.days[w + 1] - obs.days[w]);
        let j = mul(&mul(&f.p[w], &transpose(&t)), &inverse(&f.p_pred[w + 1]));
        let da = [a_s[0] - f.a_pred[w + 1][0], a_s[1] - f.a_pred[w + 1][1]];
        let a_new = [
            f.a[w][0] + j[0][0] * da[0] + j[0][1] * da[1],
            f.a[w][1] + j[1][0] * da[0] + j[1][1] * da[1],
        ];
        let dp = [
            [
                p_s[0][0] - f.p_pred[w + 1][0][0],
                p_s[0][1] - f.p_pred[w + 1][0][1],
            ],
            [
                p_s[1][0] - f.p_pred[w + 1][1][0],
                p_s[1][1] - f.p_pred[w + 1][1][1],
            ],
        ];
        let jdj = mul(&mul(&j, &dp), &transpose(&j));
        p_s = [
            [f.p[w][0][0] + jdj[0][0], f.p[w][0][1] + jdj[0][1]],
            [f.p[w][1][0] + jdj[1][0], f.p[w][1][1] + jdj[1][1]],
        ];
        a_s = a_new;
        out[w] = (a_s[0], p_s[0][0].max(0.0));
    }
    out
}

/// `ln q` values of a grid from `lo` to `hi` (both > 0), with 0 first.
fn q_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.max(lo * 10.0).ln());
    std::iter::once(0.0)
        .chain((0..n).map(|i| (a + (b - a) * i as f64 / (n - 1) as f64).exp()))
        .collect()
}

/// The most likely of `models`.
fn most_likely(obs: &Obs<'_>, models: impl Iterator<Item = Model>) -> Option<Model> {
    models
        .map(|m| (filter(obs, &m).loglik, m))
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, m)| m)
}

/// The local linear trend with both variances by maximum likelihood over a grid (25 values
/// each, log-spaced, and 0), the level's from 1e-8 to the prior variance per day, the slope's
/// from 1e-10 to the prior variance per day³ (of the record's span).
pub(super) fn fit_trend(
    obs: &Obs<'_>,
    level0: (f64, f64),
    slope0_var: f64,
    span_days: f64,
) -> Model {
    let levels = q_grid(1e-8, level0.1, 25);
    let slopes = q_grid(1e-10, level0.1 / span_days.powi(2), 25);
    let models = levels.iter().flat_map(|&q_level| {
        slopes.iter().map(move |&q_slope| Model {
            q_level,
            q_slope,
            level0,
            slope0_var,
        })
    });
    most_likely(obs, models).unwrap_or(Model {
        q_level: 0.0,
        q_slope: 0.0,
        level0,
        slope0_var,
    })
}

/// The local level (no slope) with its variance by maximum likelihood over a grid (60 values
/// from 1e-8 to the prior variance per day, and 0).
pub(super) fn fit_level(obs: &Obs<'_>, level0: (f64, f64)) -> Model {
    let level = |q_level| Model {
        q_level,
        q_slope: 0.0,
        level0,
        slope0_var: 0.0,
    };
    let grid = q_grid(1e-8, level0.1, 60);
    most_likely(obs, grid.into_iter().map(level)).unwrap_or(level(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With no noise in the state, a prior a million times wider than the data and no slope,
    /// the smoothed level is the plain mean of the estimates and its variance sd²/n.
    #[test]
    fn the_smoother_of_a_constant_is_the_weighted_mean() {
        let est: Vec<Option<(f64, f64)>> = [1.0, 3.0, 2.0, 2.5]
            .iter()
            .map(|&v| Some((v, 1.0)))
            .collect();
        let days = [0.5, 1.5, 2.5, 3.5];
        let obs = Obs {
            est: &est,
            days: &days,
        };
        let m = Model {
            q_level: 0.0,
            q_slope: 0.0,
            level0: (0.0, 1e12),
            slope0_var: 0.0,
        };
        let s = smooth(&obs, &m, &filter(&obs, &m));
        for (mean, var) in s {
            assert!(
                (mean - 2.125).abs() < 1e-6 && (var - 0.25).abs() < 1e-6,
                "{mean} {var}"
            );
        }
    }

    /// A noiseless straight line: the trend model's smoother recovers it exactly in the
    /// interior, with a slope prior wide enough to be uninformative.
    #[test]
    fn a_straight_line_is_recovered_by_the_trend_model() {
        let days: Vec<f64> = (0..20).map(|d| d as f64 + 0.5).collect();
        let est: Vec<Option<(f64, f64)>> =
            days.iter().map(|d| Some((90.0 + 0.7 * d, 1e-3))).collect();
        let obs = Obs {
            est: &est,
            days: &days,
        };
        let m = Model {
            q_level: 0.0,
            q_slope: 0.0,
            level0: (100.0, 1e6),
            slope0_var: 1e4,
        };
        let s = smooth(&obs, &m, &filter(&obs, &m));
        for (d, (mean, _)) in days.iter().zip(s) {
            assert!((mean - (90.0 + 0.7 * d)).abs() < 1e-3, "{d}: {mean}");
        }
    }
}
