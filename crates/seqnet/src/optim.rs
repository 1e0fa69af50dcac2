//! Optimisers, gradient clipping and learning-rate schedules.

use crate::float::Float;
use serde::{Deserialize, Serialize};

/// Parameter-update rule. The learning rate is set separately
/// ([`LstmSettings::learning_rate`](crate::LstmSettings::learning_rate)) so schedules apply to
/// both rules.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Optimizer {
    /// Adam (Kingma & Ba 2015) with bias correction, as `torch.optim.Adam`.
    Adam {
        /// Decay of the first-moment average (0.9 is standard).
        beta1: f64,
        /// Decay of the second-moment average (0.999 is standard).
        beta2: f64,
        /// Denominator guard (1e-8 is standard).
        eps: f64,
    },
    /// Stochastic gradient descent with optional heavy-ball momentum (`torch.optim.SGD`).
    Sgd {
        /// Momentum coefficient in `[0, 1)`; 0 gives plain SGD.
        momentum: f64,
    },
}

impl Default for Optimizer {
    fn default() -> Self {
        Self::adam()
    }
}

impl Optimizer {
    /// Adam with the usual defaults `beta1 = 0.9, beta2 = 0.999, eps = 1e-8`.
    ///
    /// ```
    /// assert!(matches!(seqnet::Optimizer::adam(), seqnet::Optimizer::Adam { .. }));
    /// ```
    pub fn adam() -> Self {
        Self::Adam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }

    /// SGD with the given momentum (0 for plain SGD).
    ///
    /// ```
    /// assert_eq!(seqnet::Optimizer::sgd(0.9), seqnet::Optimizer::Sgd { momentum: 0.9 });
    /// ```
    pub fn sgd(momentum: f64) -> Self {
        Self::Sgd { momentum }
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        let unit = |v: f64| (0.0..1.0).contains(&v);
        match *self {
            Self::Adam { beta1, beta2, eps }
                if unit(beta1) && unit(beta2) && eps > 0.0 && eps.is_finite() =>
            {
                Ok(())
            }
            Self::Adam { .. } => Err("Adam needs beta1, beta2 in [0, 1) and eps > 0".into()),
            Self::Sgd { momentum } if unit(momentum) => Ok(()),
            Self::Sgd { .. } => Err("SGD momentum must be in [0, 1)".into()),
        }
    }
}

/// Learning-rate schedule, applied per epoch to the base learning rate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub enum LrSchedule {
    /// The base rate throughout.
    #[default]
    Constant,
    /// Multiply by `factor` every `every` epochs.
    Step {
        /// Epochs between decays (at least 1).
        every: usize,
        /// Multiplier in `(0, 1]`.
        factor: f64,
    },
    /// Cosine decay from the base rate at epoch 0 to `min_factor * base` at the last epoch.
    Cosine {
        /// Final rate as a fraction of the base rate, in `[0, 1]`.
        min_factor: f64,
    },
    /// Multiply by `factor` whenever the monitored loss (validation if any, else training) has not
    /// improved for `patience` epochs, never going below `min_factor * base`.
    ReduceOnPlateau {
        /// Multiplier in `(0, 1)`.
        factor: f64,
        /// Epochs without improvement before a reduction (at least 1).
        patience: usize,
        /// Floor as a fraction of the base rate, in `[0, 1]`.
        min_factor: f64,
    },
}

impl LrSchedule {
    pub(crate) fn validate(&self) -> Result<(), String> {
        match *self {
            Self::Constant => Ok(()),
            Self::Step { every, factor } if every >= 1 && factor > 0.0 && factor <= 1.0 => Ok(()),
            Self::Step { .. } => Err("Step needs every >= 1 and factor in (0, 1]".into()),
            Self::Cosine { min_factor } if (0.0..=1.0).contains(&min_factor) => Ok(()),
            Self::Cosine { .. } => Err("Cosine needs min_factor in [0, 1]".into()),
            Self::ReduceOnPlateau {
                factor,
                patience,
                min_factor,
            } if factor > 0.0
                && factor < 1.0
                && patience >= 1
                && (0.0..=1.0).contains(&min_factor) =>
            {
                Ok(())
            }
            Self::ReduceOnPlateau { .. } => Err(
                "ReduceOnPlateau needs factor in (0, 1), patience >= 1, min_factor in [0, 1]"
                    .into(),
            ),
        }
    }
}

/// Tracks the current learning rate through a schedule.
#[derive(Debug, Clone)]
pub(crate) struct LrTracker {
    schedule: LrSchedule,
    base: f64,
    epochs: usize,
    plateau_lr: f64,
    best: f64,
    since_best: usize,
}

impl LrTracker {
    pub(crate) fn new(schedule: LrSchedule, base: f64, epochs: usize) -> Self {
        Self {
            schedule,
            base,
            epochs,
            plateau_lr: base,
            best: f64::INFINITY,
            since_best: 0,
        }
    }

    /// Learning rate for `epoch` (0-based).
    pub(crate) fn rate(&self, epoch: usize) -> f64 {
        match self.schedule {
            LrSchedule::Constant => self.base,
            LrSchedule::Step { every, factor } => self.base * factor.powi((epoch / every) as i32),
            LrSchedule::Cosine { min_factor } => {
                let frac = if self.epochs > 1 {
                    epoch as f64 / (self.epochs - 1) as f64
                } else {
                    0.0
                };
                let cos = 0.5 * (1.0 + (std::f64::consts::PI * frac).cos());
                self.base * (min_factor + (1.0 - min_factor) * cos)
            }
            LrSchedule::ReduceOnPlateau { .. } => self.plateau_lr,
        }
    }

    /// Reports the monitored loss at the end of an epoch (only the plateau rule uses it).
    pub(crate) fn observe(&mut self, loss: f64) {
        if let LrSchedule::ReduceOnPlateau {
            factor,
            patience,
            min_factor,
        } = self.schedule
        {
            if loss < self.best {
                self.best = loss;
                self.since_best = 0;
            } else {
                self.since_best += 1;
                if self.since_best >= patience {
                    self.plateau_lr = (self.plateau_lr * factor).max(self.base * min_factor);
                    self.since_best = 0;
                }
            }
        }
    }
}

/// Optimiser state (moments kept in f64 whatever the network precision).
#[derive(Debug, Clone)]
pub(crate) struct OptimizerState {
    rule: Optimizer,
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl OptimizerState {
    pub(crate) fn new(rule: Optimizer, n: usize) -> Self {
        let v = if matches!(rule, Optimizer::Adam { .. }) {
            vec![0.0; n]
        } else {
            Vec::new()
        };
        Self {
            rule,
            m: vec![0.0; n],
            v,
            t: 0,
        }
    }

    /// One update `params -= lr * step(grad)`, vectorised through pulp's runtime dispatch.
    pub(crate) fn step<T: Float>(&mut self, params: &mut [T], grad: &[T], lr: f64) {
        self.t += 1;
        let t = self.t;
        let (m, v) = (&mut self.m[..], &mut self.v[..]);
        pulp::Arch::new().dispatch(Update {
            rule: self.rule,
            t,
            params,
            grad,
            m,
            v,
            lr,
        });
    }
}

/// Arguments of one optimiser update, for pulp's SIMD dispatch.
struct Update<'a, T> {
    rule: Optimizer,
    t: i32,
    params: &'a mut [T],
    grad: &'a [T],
    m: &'a mut [f64],
    v: &'a mut [f64],
    lr: f64,
}

impl<T: Float> pulp::WithSimd for Update<'_, T> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let n = self.params.len();
        let (p, g, m) = (&mut self.params[..n], &self.grad[..n], &mut self.m[..n]);
        let lr = self.lr;
        match self.rule {
            Optimizer::Adam { beta1, beta2, eps } => {
                let v = &mut self.v[..n];
                // Bias corrections folded into the step size and epsilon (same maths as
                // m_hat / (sqrt(v_hat) + eps)).
                let c1 = 1.0 - beta1.powi(self.t);
                let c2 = 1.0 - beta2.powi(self.t);
                let step = lr / c1;
                let inv_sqrt_c2 = 1.0 / c2.sqrt();
                for k in 0..n {
                    let gk = g[k].f64();
                    m[k] = beta1 * m[k] + (1.0 - beta1) * gk;
                    v[k] = beta2 * v[k] + (1.0 - beta2) * gk * gk;
                    let upd = step * m[k] / (v[k].sqrt() * inv_sqrt_c2 + eps);
                    p[k] = T::of(p[k].f64() - upd);
                }
            }
            Optimizer::Sgd { momentum } => {
                for k in 0..n {
                    m[k] = momentum * m[k] + g[k].f64();
                    p[k] = T::of(p[k].f64() - lr * m[k]);
                }
            }
        }
    }
}

/// Euclidean norm of a gradient, accumulated in f64.
pub(crate) fn l2_norm<T: Float>(g: &[T]) -> f64 {
    g.iter().map(|v| v.f64() * v.f64()).sum::<f64>().sqrt()
}

/// Rescales `g` to norm `max_norm` if it is longer (global-norm clipping); returns the norm
/// before clipping.
pub(crate) fn clip_by_norm<T: Float>(g: &mut [T], max_norm: f64) -> f64 {
    let norm = l2_norm(g);
    if norm > max_norm {
        let s = T::of(max_norm / norm);
        for v in g {
            *v *= s;
        }
    }
    norm
}
