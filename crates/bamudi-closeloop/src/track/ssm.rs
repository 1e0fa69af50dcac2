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

/// The smoothed states: means, covariances and the smoother gains `J_w` (`J` of the last
/// window unused, the identity).
pub(super) struct Smoothed {
    pub a: Vec<V2>,
    pub p: Vec<M2>,
    j: Vec<M2>,
}

impl Smoothed {
    /// The smoothed level's mean and variance at window `w`.
    pub fn level(&self, w: usize) -> (f64, f64) {
        (self.a[w][0], self.p[w][0][0].max(0.0))
    }

    /// `Cov(x_u, L_s | all data)` for every window `u`: the state at `u` with the level at
    /// `s`. With `M_{u,s} = J_u ⋯ J_{s−1}`, `Cov(x_u, x_s) = M_{u,s} P_s` for `u ≤ s` (the
    /// smoother's lag covariances), so going back from `s` each vector is the next one times
    /// `J_u`; going forward, `Cov(x_s, x_u) = M_{s,u} P_u`, whose level row follows
    /// `m_u = m_{u−1} J_{u−1}` from `m_s = e₀`.
    pub fn cov_with_level(&self, s: usize) -> Vec<V2> {
        let n = self.a.len();
        let mut out = vec![[0.0; 2]; n];
        out[s] = [self.p[s][0][0], self.p[s][1][0]];
        for u in (0..s).rev() {
            let (j, v) = (&self.j[u], out[u + 1]);
            out[u] = [
                j[0][0] * v[0] + j[0][1] * v[1],
                j[1][0] * v[0] + j[1][1] * v[1],
            ];
        }
        let mut m = [1.0, 0.0];
        for u in s + 1..n {
            let j = &self.j[u - 1];
            m = [
                m[0] * j[0][0] + m[1] * j[1][0],
                m[0] * j[0][1] + m[1] * j[1][1],
            ];
            let p = &self.p[u];
            out[u] = [
                m[0] * p[0][0] + m[1] * p[1][0],
                m[0] * p[0][1] + m[1] * p[1][1],
            ];
        }
        out
    }
}

/// Rauch-Tung-Striebel smoother.
pub(super) fn smooth(obs: &Obs<'_>, m: &Model, f: &Filtered) -> Smoothed {
    let n = f.a.len();
    let mut s = Smoothed {
        a: f.a.clone(),
        p: f.p.clone(),
        j: vec![[[1.0, 0.0], [0.0, 1.0]]; n],
    };
    for w in (0..n - 1).rev() {
        let (t, _) = transition(m, obs.days[w + 1] - obs.days[w]);
        let j = mul(&mul(&f.p[w], &transpose(&t)), &inverse(&f.p_pred[w + 1]));
        let (a_s, p_s) = (s.a[w + 1], s.p[w + 1]);
        let da = [a_s[0] - f.a_pred[w + 1][0], a_s[1] - f.a_pred[w + 1][1]];
        s.a[w] = [
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
        s.p[w] = [
            [f.p[w][0][0] + jdj[0][0], f.p[w][0][1] + jdj[0][1]],
            [f.p[w][1][0] + jdj[1][0], f.p[w][1][1] + jdj[1][1]],
        ];
        s.j[w] = j;
    }
    s
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
        for (mean, var) in (0..4).map(|w| s.level(w)) {
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
        for (w, d) in days.iter().enumerate() {
            let mean = s.level(w).0;
            assert!((mean - (90.0 + 0.7 * d)).abs() < 1e-3, "{d}: {mean}");
        }
    }
    /// The smoother's lag covariances against the dense posterior of a local level (a random
    /// walk observed with noise, one window without an estimate): the joint prior covariance
    /// `v0 + q min(t_u − t_0, t_v − t_0)`, the posterior `(Σ⁻¹ + R⁻¹)⁻¹` over the observed
    /// windows. Agreement to 1e-9 (relative): both are exact for this model.
    #[test]
    fn lag_covariances_match_the_dense_posterior() {
        let days = [0.5, 1.5, 2.5, 4.0, 5.5, 6.0];
        let est: Vec<Option<(f64, f64)>> =
            [Some(1.0), Some(2.0), None, Some(1.5), Some(3.0), Some(2.5)]
                .iter()
                .map(|e| e.map(|v| (v, 0.8)))
                .collect();
        let obs = Obs {
            est: &est,
            days: &days,
        };
        let (v0, q) = (4.0, 0.3);
        let m = Model {
            q_level: q,
            q_slope: 0.0,
            level0: (0.0, v0),
            slope0_var: 0.0,
        };
        let s = smooth(&obs, &m, &filter(&obs, &m));
        let n = days.len();
        let prior =
            nalgebra::DMatrix::from_fn(n, n, |u, v| v0 + q * (days[u].min(days[v]) - days[0]));
        let mut precision = prior
            .try_inverse()
            .expect("a random walk's prior is regular");
        for (w, e) in est.iter().enumerate() {
            if let Some((_, sd)) = e {
                precision[(w, w)] += 1.0 / (sd * sd);
            }
        }
        let post = precision.try_inverse().expect("regular");
        assert_level_covariances(&s, &post, n, 1e-9);
    }

    /// Every `Cov(L_u, L_t)` of the smoother against the dense posterior `post` (levels first),
    /// to `rel` relative.
    fn assert_level_covariances(s: &Smoothed, post: &nalgebra::DMatrix<f64>, n: usize, rel: f64) {
        for t in 0..n {
            let c = s.cov_with_level(t);
            for u in 0..n {
                let err = (c[u][0] - post[(u, t)]).abs() / post[(u, t)].abs();
                assert!(
                    err < rel,
                    "Cov(L_{u}, L_{t}): {} against {}",
                    c[u][0],
                    post[(u, t)]
                );
            }
        }
    }

    /// The same for the local linear trend, including the slope's covariance with the levels
    /// (which the level now uses): the dense prior of an integrated random walk started from a
    /// random level and slope, `Cov(L(a), L(b)) = v0 + s0 ab + q_l min(a, b) + q_s a²(3b − a)/6`
    /// and `Cov(L(a), S(b)) = s0 a + q_s (a²/2 if a ≤ b, else ab − b²/2)` (`a ≤ b`, times since
    /// the first window), conditioned on the observed windows.
    #[test]
    fn lag_covariances_of_the_trend_match_the_dense_posterior() {
        let days = [0.5, 1.5, 2.5, 4.0, 5.5, 6.0, 7.5];
        let est: Vec<Option<(f64, f64)>> = [
            Some(1.0),
            None,
            Some(2.0),
            Some(1.5),
            Some(3.0),
            Some(2.5),
            Some(3.5),
        ]
        .iter()
        .map(|e| e.map(|v| (v, 0.7)))
        .collect();
        let obs = Obs {
            est: &est,
            days: &days,
        };
        let (v0, s0, ql, qs) = (4.0, 0.5, 0.2, 0.05);
        let m = Model {
            q_level: ql,
            q_slope: qs,
            level0: (0.0, v0),
            slope0_var: s0,
        };
        let s = smooth(&obs, &m, &filter(&obs, &m));
        let n = days.len();
        let tau: Vec<f64> = days.iter().map(|d| d - days[0]).collect();
        let level_level = |a: f64, b: f64| {
            let (a, b) = (a.min(b), a.max(b));
            v0 + s0 * a * b + ql * a + qs * a * a * (3.0 * b - a) / 6.0
        };
        let level_slope = |a: f64, b: f64| {
            let walk = if a <= b {
                a * a / 2.0
            } else {
                a * b - b * b / 2.0
            };
            s0 * a + qs * walk
        };
        // Z = [L_0 .. L_{n-1}, S_{n-1}]
        let prior = nalgebra::DMatrix::from_fn(n + 1, n + 1, |i, j| match (i < n, j < n) {
            (true, true) => level_level(tau[i], tau[j]),
            (true, false) => level_slope(tau[i], tau[n - 1]),
            (false, true) => level_slope(tau[j], tau[n - 1]),
            (false, false) => s0 + qs * tau[n - 1],
        });
        let seen: Vec<usize> = (0..n).filter(|&w| est[w].is_some()).collect();
        let k = seen.len();
        let mut s_oo = nalgebra::DMatrix::from_fn(k, k, |a, b| prior[(seen[a], seen[b])]);
        for a in 0..k {
            s_oo[(a, a)] += 0.49;
        }
        let s_zo = nalgebra::DMatrix::from_fn(n + 1, k, |i, b| prior[(i, seen[b])]);
        let gain = s_oo.cholesky().expect("PD").solve(&s_zo.transpose());
        let post = &prior - &s_zo * gain;
        assert_level_covariances(&s, &post, n, 1e-8);
        for t in 0..n {
            let slope = s.cov_with_level(t)[n - 1][1];
            let rel = (slope - post[(n, t)]).abs() / post[(n, t)].abs();
            assert!(
                rel < 1e-8,
                "Cov(S_last, L_{t}): {slope} against {}",
                post[(n, t)]
            );
        }
    }
}
