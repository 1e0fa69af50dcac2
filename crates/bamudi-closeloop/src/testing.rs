//! Test doubles (feature `testing`): a small analytic gate-like model, an honest
//! grid-posterior calibrator, and a record generator, stand-ins for an application's model
//! and for BA-MUDI in the loop's tests and examples.
//!
//! [`ToyGate`]: the quoin is a line of height 762 in. Net hydrostatic line load
//! `p(z) = γ [(h_up − z)⁺ − (h_down − z)⁺]` (γ = 0.0361 lbf/in³ per inch of width). Above the
//! gap the quoin reacts the local load; the load on the gap zone `[0, θ)` is shed to the quoin
//! just above the gap with an exponential kernel of length 60 in. Gauge `g` reads
//! `Σ_z K_g(z) R(z) Δz + d_g p(z_g)` microstrain: a Gaussian influence line (width 120 in)
//! of the reaction plus local skin-plate bending. Strains reach ~100–200 microstrain at the
//! full 360 in lift, and they depend smoothly on the gap θ.

use super::{CalibratedModel, Calibrator, IngestConfig, LoadSpec, MeasuredRecord, ThetaSummary};
use crate::CloseLoopError;
use nalgebra::DMatrix;
use numerics::random::standard_normal;
use rand::{SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};

/// Analytic gate-like strain model; see the module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToyGate {
    /// Gauge heights (in).
    pub gauge_heights_in: Vec<f64>,
    /// Influence-line amplitude per gauge (microstrain per lbf/in² of reaction).
    pub influence: Vec<f64>,
    /// Local bending per gauge (microstrain per psi).
    pub local: Vec<f64>,
    /// Quoin height (in).
    pub height_in: f64,
    /// Number of integration cells along the quoin.
    pub cells: usize,
    /// Influence-line values `K_g(z_c)`, computed on first use (the fields above must not be
    /// changed after the first strain evaluation).
    #[serde(skip)]
    kernel: std::sync::OnceLock<Vec<f64>>,
}

impl Default for ToyGate {
    /// Seven gauges from 60 in to 680 in.
    fn default() -> Self {
        Self {
            gauge_heights_in: vec![60.0, 150.0, 250.0, 350.0, 450.0, 560.0, 680.0],
            influence: vec![0.05, -0.04, 0.045, 0.035, -0.03, 0.025, 0.02],
            local: vec![3.0, 2.0, -2.5, 2.0, 1.5, -1.0, 1.0],
            height_in: 762.0,
            cells: 96,
            kernel: std::sync::OnceLock::new(),
        }
    }
}

const GAMMA_WATER: f64 = 0.0361; // lbf/in³
const SHED_LENGTH_IN: f64 = 60.0;
const INFLUENCE_WIDTH_IN: f64 = 120.0;

impl ToyGate {
    /// Number of gauges.
    ///
    /// ```
    /// assert_eq!(bamudi_closeloop::testing::ToyGate::default().n_gauges(), 7);
    /// ```
    pub fn n_gauges(&self) -> usize {
        self.gauge_heights_in.len()
    }

    /// Gauge strains (microstrain) at levels `h_up >= h_down` (in) and gap `gap_in` (in).
    ///
    /// ```
    /// let g = bamudi_closeloop::testing::ToyGate::default();
    /// assert!(g.strain(200.0, 200.0, 90.0).iter().all(|e| e.abs() < 1e-12)); // zero head
    /// let (a, b) = (g.strain(540.0, 180.0, 90.0), g.strain(540.0, 180.0, 150.0));
    /// assert!((a[0] - b[0]).abs() > 1.0); // the bottom gauge feels the gap
    /// ```
    pub fn strain(&self, h_up: f64, h_down: f64, gap_in: f64) -> Vec<f64> {
        let p = |z: f64| GAMMA_WATER * ((h_up - z).max(0.0) - (h_down - z).max(0.0));
        let dz = self.height_in / self.cells as f64;
        let gap = gap_in.clamp(0.0, self.height_in - dz);
        let mut shed = 0.0;
        let mut react = vec![0.0; self.cells];
        let mut kern = vec![0.0; self.cells];
        let mut kern_sum = 0.0;
        for c in 0..self.cells {
            let (z0, z1) = (c as f64 * dz, (c + 1) as f64 * dz);
            let z = 0.5 * (z0 + z1);
            let below = ((gap - z0) / dz).clamp(0.0, 1.0); // fraction of the cell in the gap
            shed += p(z) * dz * below;
            react[c] = p(z) * (1.0 - below);
            let above = 1.0 - below;
            kern[c] = above * (-(z - gap).max(0.0) / SHED_LENGTH_IN).exp();
            kern_sum += kern[c] * dz;
        }
        let infl = self.kernel.get_or_init(|| {
            let mut k = Vec::with_capacity(self.n_gauges() * self.cells);
            for g in 0..self.n_gauges() {
                for c in 0..self.cells {
                    let z = (c as f64 + 0.5) * dz;
                    let u = (z - self.gauge_heights_in[g]) / INFLUENCE_WIDTH_IN;
                    k.push(self.influence[g] * (-u * u).exp() * dz);
                }
            }
            k
        });
        let r: Vec<f64> = (0..self.cells)
            .map(|c| react[c] + shed * kern[c] / kern_sum)
            .collect();
        (0..self.n_gauges())
            .map(|g| {
                let row = &infl[g * self.cells..(g + 1) * self.cells];
                self.local[g] * p(self.gauge_heights_in[g])
                    + row.iter().zip(&r).map(|(k, r)| k * r).sum::<f64>()
            })
            .collect()
    }

    fn strain_rows(&self, x: &DMatrix<f64>, theta: &[f64]) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows(), self.n_gauges());
        for i in 0..x.nrows() {
            for (j, e) in self
                .strain(x[(i, 0)], x[(i, 1)], theta[i])
                .into_iter()
                .enumerate()
            {
                out[(i, j)] = e;
            }
        }
        out
    }
}

/// Calibrates θ of a [`ToyGate`] under a uniform prior on `bounds`: the Gaussian likelihood
/// with per-gauge noise variance (plug-in, from the best fit) is evaluated on an 81-point grid,
/// then on a 41-point grid around the mode; predictions marginalise θ over that posterior.
#[derive(Debug, Clone)]
pub struct GridCalibrator {
    gate: ToyGate,
    bounds: (f64, f64),
}

impl GridCalibrator {
    /// Calibrator of `gate` with the gap prior `Uniform(bounds)` (in).
    ///
    /// ```
    /// use bamudi_closeloop::{Calibrator, testing::{GridCalibrator, ToyGate}};
    /// use nalgebra::DMatrix;
    /// let gate = ToyGate::default();
    /// let x = DMatrix::from_fn(40, 2, |i, j| if j == 0 { 200.0 + 8.0 * i as f64 } else { 180.0 });
    /// let y = DMatrix::from_fn(40, 7, |i, j| gate.strain(x[(i, 0)], 180.0, 120.0)[j] + 0.01 * ((i * 7 + j) % 5) as f64);
    /// let m = GridCalibrator::new(gate, (40.0, 200.0)).calibrate(&x, &y).unwrap();
    /// assert!((m.theta_summary().mean - 120.0).abs() < 2.0);
    /// ```
    pub fn new(gate: ToyGate, bounds: (f64, f64)) -> Self {
        Self { gate, bounds }
    }
}

/// The calibrated [`ToyGate`]: posterior nodes and weights of θ and per-gauge noise variance.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GridModel {
    gate: ToyGate,
    bounds: (f64, f64),
    nodes: Vec<f64>,
    weights: Vec<f64>,
    noise_var: Vec<f64>,
    /// The Gaussian log likelihood at the best coarse node, each gauge's noise variance at its
    /// estimate there.
    log_evidence: f64,
}

impl Calibrator for GridCalibrator {
    fn calibrate(
        &self,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
    ) -> Result<Box<dyn CalibratedModel>, CloseLoopError> {
        let (lo, hi) = self.bounds;
        if lo.is_nan()
            || hi.is_nan()
            || lo >= hi
            || x.ncols() != 2
            || y.ncols() != self.gate.n_gauges()
            || x.nrows() != y.nrows()
            || x.nrows() < 2
        {
            return Err(CloseLoopError::Calibration(format!(
                "grid calibrator needs bounds lo < hi ({lo}, {hi}), x n x 2 ({:?}), y n x {} ({:?})",
                x.shape(),
                self.gate.n_gauges(),
                y.shape()
            )));
        }
        let n = x.nrows() as f64;
        let sse = |th: f64| -> Vec<f64> {
            let p = self.gate.strain_rows(x, &vec![th; x.nrows()]);
            (0..y.ncols())
                .map(|j| (y.column(j) - p.column(j)).norm_squared())
                .collect()
        };
        let coarse: Vec<f64> = (0..=80).map(|k| lo + (hi - lo) * k as f64 / 80.0).collect();
        let coarse_sse: Vec<Vec<f64>> = coarse.iter().map(|&t| sse(t)).collect();
        let total = |s: &Vec<f64>| s.iter().sum::<f64>();
        let kbest = (0..coarse.len())
            .min_by(|&a, &b| total(&coarse_sse[a]).total_cmp(&total(&coarse_sse[b])))
            .unwrap_or(0);
        let noise_var: Vec<f64> = coarse_sse[kbest]
            .iter()
            .map(|s| (s / n).max(1e-12))
            .collect();
        let loglik =
            |s: &Vec<f64>| -0.5 * s.iter().zip(&noise_var).map(|(a, v)| a / v).sum::<f64>();
        let coarse_ll: Vec<f64> = coarse_sse.iter().map(loglik).collect();
        let step = (hi - lo) / 80.0;
        let mass_far = {
            let m = coarse_ll[kbest];
            let w: Vec<f64> = coarse_ll.iter().map(|l| (l - m).exp()).collect();
            let far: f64 = w
                .iter()
                .enumerate()
                .filter(|(k, _)| k.abs_diff(kbest) > 2)
                .map(|(_, v)| v)
                .sum();
            far / w.iter().sum::<f64>()
        };
        // refine around the mode when the posterior is concentrated there
        let (nodes, ll) = if mass_far < 1e-6 {
            let (a, b) = (
                (coarse[kbest] - 2.0 * step).max(lo),
                (coarse[kbest] + 2.0 * step).min(hi),
            );
            let nodes: Vec<f64> = (0..=40).map(|k| a + (b - a) * k as f64 / 40.0).collect();
            let ll = nodes.iter().map(|&t| loglik(&sse(t))).collect();
            (nodes, ll)
        } else {
            (coarse, coarse_ll)
        };
        let m = ll.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let w: Vec<f64> = ll.iter().map(|l| (l - m).exp()).collect();
        let s: f64 = w.iter().sum();
        Ok(Box::new(GridModel {
            gate: self.gate.clone(),
            bounds: self.bounds,
            nodes,
            weights: w.iter().map(|v| v / s).collect(),
            log_evidence: -0.5
                * n
                * noise_var
                    .iter()
                    .map(|v| (2.0 * std::f64::consts::PI * v).ln() + 1.0)
                    .sum::<f64>(),
            noise_var,
        }))
    }
}

impl CalibratedModel for GridModel {
    fn predict(&self, x: &DMatrix<f64>) -> Result<(DMatrix<f64>, DMatrix<f64>), CloseLoopError> {
        let g = self.gate.n_gauges();
        let mut mean = DMatrix::zeros(x.nrows(), g);
        let mut second = DMatrix::zeros(x.nrows(), g);
        for (t, w) in self.nodes.iter().zip(&self.weights) {
            if *w < 1e-10 {
                continue; // negligible posterior mass
            }
            let p = self.gate.strain_rows(x, &vec![*t; x.nrows()]);
            mean += &p * *w;
            second += p.component_mul(&p) * *w;
        }
        let wsum: f64 = self.weights.iter().filter(|w| **w >= 1e-10).sum();
        mean /= wsum;
        second /= wsum;
        let var = DMatrix::from_fn(x.nrows(), g, |i, j| {
            (second[(i, j)] - mean[(i, j)].powi(2)).max(0.0) + self.noise_var[j]
        });
        Ok((mean, var))
    }

    fn predict_at_theta(
        &self,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> Result<DMatrix<f64>, CloseLoopError> {
        if theta.len() != x.nrows() {
            return Err(CloseLoopError::Calibration(format!(
                "{} gap values for {} rows",
                theta.len(),
                x.nrows()
            )));
        }
        Ok(self.gate.strain_rows(x, theta))
    }

    fn theta_summary(&self) -> ThetaSummary {
        let mean: f64 = self
            .nodes
            .iter()
            .zip(&self.weights)
            .map(|(t, w)| t * w)
            .sum();
        let var: f64 = self
            .nodes
            .iter()
            .zip(&self.weights)
            .map(|(t, w)| w * (t - mean).powi(2))
            .sum();
        let quantile = |q: f64| {
            let mut acc = 0.0;
            for (k, w) in self.weights.iter().enumerate() {
                if acc + w >= q {
                    let frac = if *w > 0.0 { (q - acc) / w } else { 0.0 };
                    // spread each node's mass over its cell for a continuous CDF
                    let h = if self.nodes.len() > 1 {
                        self.nodes[1] - self.nodes[0]
                    } else {
                        0.0
                    };
                    return self.nodes[k] - 0.5 * h + frac * h;
                }
                acc += w;
            }
            *self.nodes.last().unwrap_or(&f64::NAN)
        };
        ThetaSummary {
            mean,
            sd: var.sqrt(),
            ci95: (quantile(0.025), quantile(0.975)),
        }
    }

    fn theta_bounds(&self) -> (f64, f64) {
        self.bounds
    }

    /// The profile likelihood at the best coarse grid node (each gauge's noise variance at its
    /// estimate there): θ has no prior density here to integrate.
    fn log_evidence(&self) -> Option<f64> {
        Some(self.log_evidence)
    }
}

/// A record of `n` hourly rows from `gate` at gap 90 in: the upper pool cycles through a
/// lockage every 8 hours over a lower pool that drifts over weeks, an air temperature follows a
/// daily and a weekly cycle, and every gauge carries N(0, 1) noise (seeded) plus
/// `effect(t_hours, gauge)`. Columns: `time` (hours), `h_up`, `h_down`, `air_temp_f`, `g1..g7`.
pub fn record_with(
    gate: &ToyGate,
    n: usize,
    seed: u64,
    effect: impl Fn(f64, usize) -> f64,
) -> crate::Result<MeasuredRecord> {
    let mut rng = StdRng::seed_from_u64(seed);
    let g = gate.n_gauges();
    let names: Vec<String> = (1..=g).map(|k| format!("g{k}")).collect();
    let mut csv = format!("time,h_up,h_down,air_temp_f,{}\n", names.join(","));
    for i in 0..n {
        let t = i as f64;
        let (h_up, h_down) = toy_levels(t);
        let temp = 50.0 + 10.0 * (t * std::f64::consts::TAU / 24.0).sin() + 5.0 * (t / 168.0).sin();
        let s = gate.strain(h_up, h_down, 90.0);
        let row: Vec<String> = (0..g)
            .map(|k| format!("{:?}", s[k] + standard_normal(&mut rng) + effect(t, k)))
            .collect();
        csv.push_str(&format!(
            "{t},{h_up:?},{h_down:?},{temp:?},{}\n",
            row.join(",")
        ));
    }
    let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let cfg = IngestConfig::new(&["h_up", "h_down"], &name_refs);
    super::parse_csv(&csv, "simulated", &cfg)
}

/// The water levels (in) of [`record_with`]'s row at hour `t`: `(h_up, h_down)`.
pub fn toy_levels(t: f64) -> (f64, f64) {
    let h_down = 150.0 + 30.0 * (t / 300.0).sin();
    let phase = (t % 8.0) / 8.0;
    let head = if phase < 0.5 {
        380.0 * (2.0 * phase)
    } else {
        380.0 * (2.0 - 2.0 * phase)
    };
    (h_down + head, h_down)
}

/// The gate-like model's load: the head `h_up − h_down`, paired with `h_down`, active above
/// 1 in.
pub fn toy_load() -> LoadSpec {
    LoadSpec::difference("head", 0, 1, 2, 1.0)
}
