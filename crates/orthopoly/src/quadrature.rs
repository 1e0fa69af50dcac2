//! Gauss quadrature rules (Eq. 25/27: marginalising θ over its prior).
//!
//! Nodes come from Newton iteration on the three-term recurrence, started from asymptotic
//! initial guesses, so any order works in `O(n²)` time and nodes are accurate to round-off.

use std::f64::consts::PI;

use crate::OrthoError;
use crate::family::{Family, Normalization, recurrence};
use crate::validate::{check_interval, check_order};

/// Newton stops refining once a step is below this relative size; it then takes
/// [`POLISH_STEPS`] more steps, which (quadratic convergence) reach round-off.
const NEWTON_TOL: f64 = 1e-9;
/// Extra Newton steps after [`NEWTON_TOL`] is met.
const POLISH_STEPS: usize = 2;
/// Cap on Newton iterations per node before reporting [`OrthoError::NoConvergence`].
const MAX_NEWTON: usize = 100;
/// Cap on safeguarded Newton/bisection iterations per Gauss-Hermite node (bisection alone
/// needs ~60 halvings to shrink a bracket of width 2 sqrt(n) to round-off).
const MAX_BRACKETED: usize = 300;

/// `n`-point Gauss-Legendre rule on `[a, b]`: `(nodes, weights)`, nodes ascending, weights
/// summing to `b - a`; `Σ w_i f(t_i) = ∫_a^b f(t) dt` exactly for polynomials of degree
/// `<= 2n - 1`.
///
/// Nodes are found by Newton iteration in the angle `θ` (`z = cos θ`) from Tricomi's initial
/// guesses, which avoids cancellation in `1 - z²` near the ends; weights use
/// `w = 2 / (dP_n/dθ)²` on `[-1, 1]`. The rule is exactly symmetric. Cost `O(n²)`.
///
/// Errors: `n == 0`, non-finite `a`/`b`, `a >= b`.
///
/// ```
/// use orthopoly::gauss_legendre;
/// let (t, w) = gauss_legendre(3, 0.0, 762.0).unwrap();
/// let integral: f64 = t.iter().zip(&w).map(|(t, w)| w * t * t).sum();
/// assert!((integral - 762f64.powi(3) / 3.0).abs() < 1e-6 * 762f64.powi(3));
/// ```
pub fn gauss_legendre(n: usize, a: f64, b: f64) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
    check_order("n", n)?;
    check_interval(a, b)?;
    let (z, w) = legendre_reference(n)?;
    let (center, half) = (0.5 * (a + b), 0.5 * (b - a));
    let nodes = z.iter().map(|&z| center + half * z).collect();
    let weights = w.iter().map(|&w| half * w).collect();
    Ok((nodes, weights))
}

/// `n`-point probabilists' Gauss-Hermite rule: `(nodes, weights)` for the weight
/// `exp(-x²/2)` on the real line, nodes ascending, weights summing to `sqrt(2π)`; exact for
/// polynomials of degree `<= 2n - 1`. Divide the weights by `sqrt(2π)` for expectations
/// under `N(0, 1)`, and map `x -> μ + σ x` for `N(μ, σ²)`.
///
/// Nodes are found by Newton iteration on the orthonormal Hermite recurrence (rescaled on the
/// fly so that large orders do not overflow) from asymptotic initial guesses, safeguarded by a
/// Sturm-count bracket so that every node is provably the intended root. Far-tail weights
/// of very large orders underflow to 0, as they must in double precision. Cost `O(n²)`.
///
/// Errors: `n == 0`.
///
/// ```
/// use orthopoly::gauss_hermite_prob;
/// let (x, w) = gauss_hermite_prob(4).unwrap();
/// let total: f64 = w.iter().sum();
/// let fourth: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(4)).sum::<f64>() / total;
/// assert!((fourth - 3.0).abs() < 1e-13); // E[Z⁴] = 3
/// ```
pub fn gauss_hermite_prob(n: usize) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
    check_order("n", n)?;
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    let mut roots: Vec<f64> = Vec::with_capacity(n.div_ceil(2));
    let rec = Recurrence::new(Family::Hermite, Normalization::Orthonormal, n);
    // All roots are below 2 sqrt(n) (the largest zero of He_n is < sqrt(4n - 2)).
    let mut upper = 2.0 * (n as f64).sqrt() + 1.0;
    for k in 0..n.div_ceil(2) {
        let x = if n % 2 == 1 && k == n / 2 {
            0.0 // exact by symmetry
        } else {
            let guess = hermite_initial_guess(n, k, roots.last().copied().unwrap_or(0.0), &roots);
            hermite_root(&rec, k, guess, upper).ok_or(OrthoError::NoConvergence {
                rule: "Gauss-Hermite",
                n,
                node: k,
            })?
        };
        roots.push(x);
        upper = x;
        let weight = hermite_eval(&rec, x).weight;
        nodes[n - 1 - k] = x;
        nodes[k] = -x;
        weights[n - 1 - k] = weight;
        weights[k] = weight;
    }
    Ok((nodes, weights))
}

/// `n`-point Gauss-Chebyshev (first kind) rule on `[a, b]`: `Σ w_i f(t_i) =
/// ∫_a^b f(t) / sqrt((t - a)(b - t)) dt` exactly for polynomials of degree `<= 2n - 1`.
/// Nodes ascending, all weights `π/n` (they sum to `π`).
///
/// ```
/// use orthopoly::gauss_chebyshev;
/// let (t, w) = gauss_chebyshev(5, -1.0, 1.0).unwrap();
/// // ∫ z² / sqrt(1 - z²) dz = π/2
/// let m2: f64 = t.iter().zip(&w).map(|(t, w)| w * t * t).sum();
/// assert!((m2 - std::f64::consts::FRAC_PI_2).abs() < 1e-14);
/// ```
pub fn gauss_chebyshev(n: usize, a: f64, b: f64) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
    check_order("n", n)?;
    check_interval(a, b)?;
    let (center, half) = (0.5 * (a + b), 0.5 * (b - a));
    let nodes = (0..n)
        .map(|k| {
            // Ascending: angle runs from π down to 0; sin form keeps the middle node exactly 0.
            let z = -((n as f64 - 1.0 - 2.0 * k as f64) * PI / (2.0 * n as f64)).sin();
            center + half * z
        })
        .collect();
    Ok((nodes, vec![PI / n as f64; n]))
}

/// Gauss-Legendre on `[-1, 1]`, nodes ascending.
fn legendre_reference(n: usize) -> Result<(Vec<f64>, Vec<f64>), OrthoError> {
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    let nf = n as f64;
    let rec = Recurrence::new(Family::Legendre, Normalization::Classical, n);
    for k in 0..n.div_ceil(2) {
        // k-th largest root; Tricomi's asymptotic guess.
        let middle = n % 2 == 1 && k == n / 2;
        let theta = if middle {
            PI / 2.0
        } else {
            let guess = (1.0 - 1.0 / (8.0 * nf * nf) + 1.0 / (8.0 * nf * nf * nf))
                * (PI * (4 * k + 3) as f64 / (4.0 * nf + 2.0)).cos();
            newton(|th| legendre_theta_step(&rec, th).0, guess.acos(), 1.0).ok_or(
                OrthoError::NoConvergence {
                    rule: "Gauss-Legendre",
                    n,
                    node: k,
                },
            )?
        };
        let dp_dtheta = legendre_theta_step(&rec, theta).1;
        let z = if middle { 0.0 } else { theta.cos() };
        let w = 2.0 / (dp_dtheta * dp_dtheta);
        nodes[n - 1 - k] = z;
        nodes[k] = -z;
        weights[n - 1 - k] = w;
        weights[k] = w;
    }
    Ok((nodes, weights))
}

/// Newton step `P_n(cos θ) / (dP_n/dθ)` and `dP_n/dθ` at angle `θ`.
///
/// Uses `dP_n/dθ = -n (P_{n-1} - z P_n) / sin θ`, with `sin θ` computed from `θ` directly, so
/// nodes near `z = ±1` keep full relative accuracy in `1 - z² = sin² θ`.
fn legendre_theta_step(rec: &Recurrence, theta: f64) -> (f64, f64) {
    let (z, s) = (theta.cos(), theta.sin());
    let (p, p_prev) = rec.eval_pair(z); // P_n, P_{n-1}
    let dp_dtheta = -(rec.n() as f64) * (p_prev - z * p) / s;
    (p / dp_dtheta, dp_dtheta)
}

/// Initial guess for the `k`-th largest probabilists' Hermite root (asymptotic formulas for
/// the first two, extrapolation from the roots already found for the rest; after Numerical
/// Recipes' `gauher`, converted from the physicists' variable `y = x/sqrt(2)`).
fn hermite_initial_guess(n: usize, k: usize, previous: f64, roots: &[f64]) -> f64 {
    let m = (2 * n + 1) as f64;
    match k {
        0 => std::f64::consts::SQRT_2 * (m.sqrt() - 1.85575 * m.powf(-1.0 / 6.0)),
        1 => previous - 2.0 * 1.14 * (n as f64).powf(0.426) / previous,
        2 => 1.86 * previous - 0.86 * roots[0],
        3 => 1.91 * previous - 0.91 * roots[1],
        _ => 2.0 * previous - roots[k - 2],
    }
}

/// The `k`-th largest (`k < n/2`, so positive) root of `He_n`, below `upper`.
///
/// Safeguarded Newton: the sign changes of the orthonormal sequence `h_0(x), ..., h_n(x)`
/// count the roots above `x` (Sturm property of three-term recurrences), which keeps a bracket
/// `(lo, hi)` around exactly the wanted root. A Newton step leaving the bracket is replaced by
/// bisection, so a poor asymptotic guess (large `n`) can never converge to a neighbouring root.
fn hermite_root(rec: &Recurrence, k: usize, guess: f64, upper: f64) -> Option<f64> {
    let (mut lo, mut hi) = (0.0, upper);
    let mut x = if lo < guess && guess < hi {
        guess
    } else {
        0.5 * (lo + hi)
    };
    for _ in 0..MAX_BRACKETED {
        let eval = hermite_eval(rec, x);
        if eval.roots_above > k {
            lo = x;
        } else {
            hi = x;
        }
        if eval.step.abs() <= NEWTON_TOL * x.abs().max(1.0) {
            let root = newton(|x| hermite_eval(rec, x).step, x, 1.0)?;
            if is_kth_hermite_root(rec, k, root) {
                return Some(root);
            }
            // Converged to a neighbouring root: fall back on bisection of the bracket.
            x = 0.5 * (lo + hi);
            continue;
        }
        let newton_x = x - eval.step;
        x = if lo < newton_x && newton_x < hi {
            newton_x
        } else {
            0.5 * (lo + hi)
        };
    }
    None
}

/// Whether `r` is (to round-off) the `k`-th largest root: exactly `k + 1` roots lie above a
/// point just below `r` and exactly `k` above a point just above it. The offset `1e-8·|r|`
/// is far above the root's round-off and far below the root spacing (`> n^{-1/2}` in the
/// bulk, `> n^{-1/6}` at the edge) for any practical `n`.
fn is_kth_hermite_root(rec: &Recurrence, k: usize, r: f64) -> bool {
    let d = 1e-8 * r.abs().max(1.0);
    hermite_eval(rec, r - d).roots_above == k + 1 && hermite_eval(rec, r + d).roots_above == k
}

/// Tabulated coefficients of `p_{j+1} = a_j z p_j - c_j p_{j-1}`, `j < n`.
///
/// Nodes cost ~10 recurrence passes each, and a pass is latency-bound on its loop-carried
/// chain; tabulating turns the per-step division (and square roots) into multiplications.
struct Recurrence {
    a: Vec<f64>,
    c: Vec<f64>,
}

impl Recurrence {
    fn new(family: Family, normalization: Normalization, n: usize) -> Self {
        let (a, c) = (0..n).map(|j| recurrence(family, normalization, j)).unzip();
        Self { a, c }
    }
    /// The polynomial degree `n`.
    fn n(&self) -> usize {
        self.a.len()
    }
    /// `(p_n(z), p_{n-1}(z))`.
    fn eval_pair(&self, z: f64) -> (f64, f64) {
        let (mut p_prev, mut p) = (0.0, 1.0);
        for (a, c) in self.a.iter().zip(&self.c) {
            (p_prev, p) = (p, a * z * p - c * p_prev);
        }
        (p, p_prev)
    }
}

/// Result of one pass of the orthonormal probabilists' Hermite recurrence at `x`.
struct HermiteEval {
    /// Newton step `h_n(x) / h_n'(x)`.
    step: f64,
    /// Gauss weight `sqrt(2π) / (n h_{n-1}(x)²)` (meaningful at a root).
    weight: f64,
    /// Number of roots of `He_n` above `x` (sign changes of `h_0, ..., h_n`).
    roots_above: usize,
}

/// Evaluates the orthonormal recurrence `h_j = He_j / sqrt(j!)` up to `j = n` at `x`.
///
/// Values are rescaled whenever they pass 1e150, with the scale kept in log form, so large `x`
/// and `n` neither overflow nor change the (scale-free) Newton step and sign pattern.
fn hermite_eval(rec: &Recurrence, x: f64) -> HermiteEval {
    let n = rec.n();
    const BIG: f64 = 1e150;
    let (mut h_prev, mut h) = (0.0, 1.0); // h_{-1}, h_0
    let mut log_scale = 0.0;
    let mut roots_above = 0;
    for j in 0..n {
        let h_next = rec.a[j] * x * h - rec.c[j] * h_prev;
        // Branch-free sign-change count (signs alternate unpredictably; a branch here
        // mispredicts about every other step). An exact zero counts as positive, which can
        // only shift a bracket end, never the final `is_kth_hermite_root` check.
        roots_above += ((h_next.to_bits() ^ h.to_bits()) >> 63) as usize;
        (h_prev, h) = (h, h_next);
        if h.abs() > BIG {
            h /= BIG;
            h_prev /= BIG;
            log_scale += BIG.ln();
        }
    }
    let nf = n as f64;
    // h_n' = sqrt(n) h_{n-1}
    let step = h / (nf.sqrt() * h_prev);
    let ln_weight = 0.5 * (2.0 * PI).ln() - nf.ln() - 2.0 * (h_prev.abs().ln() + log_scale);
    HermiteEval {
        step,
        weight: ln_weight.exp(),
        roots_above,
    }
}

/// Newton iteration `x <- x - step(x)` until the step is below `NEWTON_TOL · max(|x|, scale)`,
/// then [`POLISH_STEPS`] more. `None` on non-finite values or too many iterations.
fn newton(step: impl Fn(f64) -> f64, mut x: f64, scale: f64) -> Option<f64> {
    let mut polish = 0;
    for _ in 0..MAX_NEWTON {
        let dx = step(x);
        x -= dx;
        if !x.is_finite() {
            return None;
        }
        if polish > 0 || dx.abs() <= NEWTON_TOL * x.abs().max(scale) {
            polish += 1;
            if polish > POLISH_STEPS {
                return Some(x);
            }
        }
    }
    None
}
