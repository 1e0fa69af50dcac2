//! The paper's synthetic truth for the miter gate (Sec. 4.3, Eq. 45-48, 53-54, Table 1).
//!
//! The "true" quoin forces are `F_true(x) = ρ g_BC(x, θ*) + δ(x)` (Eq. 45-46), with `g_BC` the
//! [`ContactModel`] and the discrepancy `δ = [δ_N; δ_T]` of Eq. 53-54, both zero below the true
//! gap length `θ*`. Measured strains are `y = A F_true + s_w(x) + ε` (Eq. 47-48), with `ε`
//! independent `N(0, σ²)` per gauge and experiment (`σ = 1` microstrain).
//!
//! # Units given to Eq. 53-54
//! The paper states no units. Here `h_up`, `h_down`, `d_u` are in inches and `δ_N`, `δ_T` in
//! lbf/in (line loads, like `g_BC`):
//!
//! * `δ_N(x, d) = 3 (h_up - h_down) ((762 - d) / 1200)³` lbf/in (at most ≈ 380 lbf/in at the
//!   full 720 in head and `d = 90` in),
//! * `δ_T(x, d) = ((h_up - h_down) / 100)² sin(d / 240)` lbf/in (at most ≈ 52 lbf/in),
//!
//! for `d ≥ θ*`, zero below. Contact line loads of a loaded gate are of order `1e4` lbf/in, so
//! the literal discrepancy is a few percent of the force. Whether that is visible through the
//! 7 gauges above the 1 microstrain noise depends on the gate's `A`;
//! [`discrepancy_visibility`] measures it, and [`Scenario::discrepancy_scale`] multiplies
//! `δ` when the literal magnitudes are too small to matter (1 = the paper's literal values).
//!
//! # Input domain
//! Water levels are drawn uniformly on the triangle `24 ≤ h_down < h_up ≤ 744` in (upstream
//! above downstream, both within the paper's range `[24, 744]` in,
//! [`WATER_LEVEL_RANGE`]): draw both uniformly on the
//! square and swap them if `h_down > h_up`, which maps the square two-to-one onto the triangle
//! and keeps the density uniform.

use crate::contact::ContactModel;
use crate::error::GateError;
use crate::gate::WATER_LEVEL_RANGE;
use nalgebra::DVector;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// Quoin height used by Eq. 53 (in).
const EQ53_HEIGHT: f64 = 762.0;

/// One synthetic-data scenario of Table 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scenario {
    /// Human-readable name.
    pub name: String,
    /// True gap length `θ*` (in).
    pub theta_true: f64,
    /// Uniform prior bounds of `θ` (in).
    pub prior: (f64, f64),
    /// True regression coefficient `ρ` of Eq. 45 (0.8 in the paper).
    pub rho: f64,
    /// Number of experiments `N_e` (500 in the paper).
    pub n_experiments: usize,
    /// Measurement noise standard deviation `σ` (microstrain; 1 in the paper).
    pub noise_sd: f64,
    /// Multiplier of the literal Eq. 53-54 discrepancy (1 = the paper's values).
    pub discrepancy_scale: f64,
    /// Seed of the water levels and the noise.
    pub seed: u64,
}

impl Scenario {
    /// Scenario 1 (`θ* = 90` in, prior `U(81, 105)`) or 2 (`θ* = 150` in, prior `U(135, 165)`)
    /// of Table 1, with `ρ = 0.8`, `N_e = 500`, `σ = 1`, literal discrepancy, seed = number.
    ///
    /// ```
    /// let s = mitergate::data::truth::Scenario::paper(2).unwrap();
    /// assert_eq!((s.theta_true, s.prior), (150.0, (135.0, 165.0)));
    /// assert!(mitergate::data::truth::Scenario::paper(3).is_err());
    /// ```
    pub fn paper(number: u8) -> Result<Self, GateError> {
        let (theta_true, prior) = match number {
            1 => (90.0, (81.0, 105.0)),
            2 => (150.0, (135.0, 165.0)),
            _ => {
                return Err(GateError::InvalidScenario {
                    name: "number",
                    reason: format!("the paper has scenarios 1 and 2, got {number}"),
                });
            }
        };
        Ok(Self {
            name: format!("paper scenario {number}"),
            theta_true,
            prior,
            rho: 0.8,
            n_experiments: 500,
            noise_sd: 1.0,
            discrepancy_scale: 1.0,
            seed: u64::from(number),
        })
    }

    /// Sets the seed.
    ///
    /// ```
    /// let s = mitergate::data::truth::Scenario::paper(1).unwrap().seed(7);
    /// assert_eq!(s.seed, 7);
    /// ```
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// Sets the discrepancy multiplier.
    ///
    /// ```
    /// let s = mitergate::data::truth::Scenario::paper(1).unwrap().discrepancy_scale(10.0);
    /// assert_eq!(s.discrepancy_scale, 10.0);
    /// ```
    pub fn discrepancy_scale(mut self, scale: f64) -> Self {
        self.discrepancy_scale = scale;
        self
    }
    /// Sets the number of experiments.
    ///
    /// ```
    /// let s = mitergate::data::truth::Scenario::paper(1).unwrap().n_experiments(20);
    /// assert_eq!(s.n_experiments, 20);
    /// ```
    pub fn n_experiments(mut self, n: usize) -> Self {
        self.n_experiments = n;
        self
    }
    /// Sets the noise standard deviation (microstrain).
    ///
    /// ```
    /// let s = mitergate::data::truth::Scenario::paper(1).unwrap().noise_sd(0.0);
    /// assert!(s.validate().is_ok());
    /// ```
    pub fn noise_sd(mut self, sd: f64) -> Self {
        self.noise_sd = sd;
        self
    }

    /// Checks every field, naming the first invalid one.
    ///
    /// ```
    /// let s = mitergate::data::truth::Scenario::paper(1).unwrap().noise_sd(-1.0);
    /// assert!(s.validate().is_err());
    /// ```
    pub fn validate(&self) -> Result<(), GateError> {
        let bad =
            |name: &'static str, reason: String| Err(GateError::InvalidScenario { name, reason });
        let (lo, hi) = self.prior;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi) {
            return bad(
                "prior",
                format!("need finite 0 <= lo < hi, got ({lo}, {hi})"),
            );
        }
        if !(lo..=hi).contains(&self.theta_true) {
            return bad(
                "theta_true",
                format!("{} in lies outside the prior [{lo}, {hi}]", self.theta_true),
            );
        }
        if !self.rho.is_finite() {
            return bad("rho", format!("must be finite, got {}", self.rho));
        }
        if self.n_experiments == 0 {
            return bad("n_experiments", "must be >= 1".into());
        }
        if !(self.noise_sd.is_finite() && self.noise_sd >= 0.0) {
            return bad(
                "noise_sd",
                format!("must be finite and >= 0, got {}", self.noise_sd),
            );
        }
        if !self.discrepancy_scale.is_finite() {
            return bad(
                "discrepancy_scale",
                format!("must be finite, got {}", self.discrepancy_scale),
            );
        }
        Ok(())
    }
}

/// The true discrepancy `δ = scale · [δ_N; δ_T]` of Eq. 53-54 (lbf/in, component blocked,
/// length `2 d_u.len()`) for levels `x = [h_up, h_down]` (in), points `d_u` (in) and true gap
/// length `theta_star` (in): zero at points below `θ*`.
///
/// ```
/// let d = [0.0, 100.0, 762.0];
/// let delta = mitergate::data::truth::true_discrepancy([744.0, 24.0], &d, 90.0, 1.0);
/// assert_eq!(delta[0], 0.0); // below the gap
/// let dn = 3.0 * 720.0 * ((762.0f64 - 100.0) / 1200.0).powi(3);
/// assert!((delta[1] - dn).abs() < 1e-12);
/// assert_eq!(delta[2], 0.0); // (762 - d)^3 vanishes at the top
/// assert!((delta[4] - 7.2f64.powi(2) * (100.0f64 / 240.0).sin()).abs() < 1e-12);
/// ```
pub fn true_discrepancy(x: [f64; 2], d_u: &[f64], theta_star: f64, scale: f64) -> Vec<f64> {
    let head = x[0] - x[1];
    let n = d_u.len();
    let mut delta = vec![0.0; 2 * n];
    for (b, &d) in d_u.iter().enumerate() {
        if d >= theta_star {
            delta[b] = scale * 3.0 * head * ((EQ53_HEIGHT - d) / 1200.0).powi(3);
            delta[n + b] = scale * (head / 100.0).powi(2) * (d / 240.0).sin();
        }
    }
    delta
}

/// `n` water-level pairs `[h_up, h_down]` (in), uniform on the triangle
/// `24 ≤ h_down < h_up ≤ 744` (see the module docs), reproducible from `seed`.
///
/// ```
/// let x = mitergate::data::truth::sample_levels(100, 3);
/// assert!(x.iter().all(|l| 24.0 <= l[1] && l[1] <= l[0] && l[0] <= 744.0));
/// assert_eq!(x, mitergate::data::truth::sample_levels(100, 3));
/// ```
pub fn sample_levels(n: usize, seed: u64) -> Vec<[f64; 2]> {
    let mut rng = StdRng::seed_from_u64(seed);
    draw_levels(n, &mut rng)
}

fn draw_levels(n: usize, rng: &mut StdRng) -> Vec<[f64; 2]> {
    let (lo, hi) = WATER_LEVEL_RANGE;
    (0..n)
        .map(|_| {
            let a = rng.random_range(lo..hi);
            let b = rng.random_range(lo..hi);
            if a >= b { [a, b] } else { [b, a] }
        })
        .collect()
}

/// Synthetic experiments of one scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Experiments {
    /// Water levels `[h_up, h_down]` (in), one pair per experiment.
    pub x: Vec<[f64; 2]>,
    /// Measured strains (microstrain, `N_o` per experiment), noise included.
    pub strains: Vec<Vec<f64>>,
    /// Noise-free strains `A F_true + s_w` (microstrain).
    pub noise_free_strains: Vec<Vec<f64>>,
    /// True forces `ρ g_BC(x, θ*) + δ(x)` (lbf/in, `2 N_u`, blocked) per experiment.
    pub true_forces: Vec<Vec<f64>>,
}

/// True quoin forces `ρ g_BC(x, θ*) + δ(x)` (lbf/in, blocked) of `scenario` at levels `x`.
///
/// ```
/// # let model = mitergate::contact::ContactParams::default()
/// #     .build(mitergate::testing::doc_gate()).unwrap();
/// let s = mitergate::data::truth::Scenario::paper(1).unwrap();
/// let f = mitergate::data::truth::true_forces(&s, &model, [700.0, 100.0]).unwrap();
/// assert_eq!(f[0], 0.0); // z = 0 lies in the gap
/// ```
pub fn true_forces(
    scenario: &Scenario,
    model: &ContactModel,
    x: [f64; 2],
) -> Result<Vec<f64>, GateError> {
    let mut forces = model.solve(x[0], x[1], scenario.theta_true)?.forces;
    let delta = true_discrepancy(
        x,
        &model.gate().nu_points,
        scenario.theta_true,
        scenario.discrepancy_scale,
    );
    for (f, d) in forces.iter_mut().zip(&delta) {
        *f = scenario.rho * *f + d;
    }
    Ok(forces)
}

/// Generates the scenario's `N_e` experiments (Eq. 48) on the gate of `model`. The levels
/// come first from the seeded generator, then the noise, experiment by experiment.
///
/// ```
/// # let model = mitergate::contact::ContactParams::default()
/// #     .build(mitergate::testing::doc_gate()).unwrap();
/// let s = mitergate::data::truth::Scenario::paper(1).unwrap().n_experiments(3);
/// let e = mitergate::data::truth::generate(&s, &model).unwrap();
/// assert_eq!((e.x.len(), e.strains[0].len()), (3, 2));
/// assert_eq!(e, mitergate::data::truth::generate(&s, &model).unwrap()); // seeded
/// ```
pub fn generate(scenario: &Scenario, model: &ContactModel) -> Result<Experiments, GateError> {
    scenario.validate()?;
    let gate = model.gate();
    let mut rng = StdRng::seed_from_u64(scenario.seed);
    let x = draw_levels(scenario.n_experiments, &mut rng);
    let noise = Normal::new(0.0, scenario.noise_sd).map_err(|e| GateError::InvalidScenario {
        name: "noise_sd",
        reason: e.to_string(),
    })?;
    let mut out = Experiments {
        x: x.clone(),
        strains: Vec::with_capacity(x.len()),
        noise_free_strains: Vec::with_capacity(x.len()),
        true_forces: Vec::with_capacity(x.len()),
    };
    for &xe in &x {
        let forces = true_forces(scenario, model, xe)?;
        let clean = gate.strain(&forces, xe[0], xe[1]);
        let measured: Vec<f64> = clean.iter().map(|c| c + noise.sample(&mut rng)).collect();
        out.strains.push(measured);
        out.noise_free_strains.push(clean.as_slice().to_vec());
        out.true_forces.push(forces);
    }
    Ok(out)
}

/// How visible the discrepancy is through the gauges, over the scenario's experiments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiscrepancyVisibility {
    /// RMS over experiments and gauges of `A δ` at the scenario's `discrepancy_scale`
    /// (microstrain).
    pub rms_discrepancy_strain: f64,
    /// The same for the literal Eq. 53-54 (`scale = 1`).
    pub rms_literal_discrepancy_strain: f64,
    /// RMS of the strain of the normal part `A [δ_N; 0]`, literal scale.
    pub rms_literal_normal_strain: f64,
    /// RMS of the strain of the tangential part `A [0; δ_T]`, literal scale.
    pub rms_literal_tangential_strain: f64,
    /// RMS of the contact-force strain `A ρ g_BC(x, θ*)` (microstrain), for comparison.
    pub rms_contact_strain: f64,
    /// The measurement noise standard deviation `σ` (microstrain).
    pub noise_sd: f64,
}

impl DiscrepancyVisibility {
    /// Signal-to-noise ratio `rms(A δ) / σ` at the scenario's scale (∞ if `σ = 0`).
    ///
    /// ```
    /// let v = mitergate::data::truth::DiscrepancyVisibility {
    ///     rms_discrepancy_strain: 5.0, rms_literal_discrepancy_strain: 5.0,
    ///     rms_literal_normal_strain: 4.0, rms_literal_tangential_strain: 3.0,
    ///     rms_contact_strain: 100.0, noise_sd: 1.0,
    /// };
    /// assert_eq!(v.signal_to_noise(), 5.0);
    /// ```
    pub fn signal_to_noise(&self) -> f64 {
        self.rms_discrepancy_strain / self.noise_sd
    }
}

/// Measures the gauge strain of the discrepancy against the noise over the scenario's
/// water levels (the same levels as [`generate`]).
///
/// ```
/// # let model = mitergate::contact::ContactParams::default()
/// #     .build(mitergate::testing::doc_gate()).unwrap();
/// let s = mitergate::data::truth::Scenario::paper(1).unwrap().n_experiments(5);
/// let v = mitergate::data::truth::discrepancy_visibility(&s, &model).unwrap();
/// assert!(v.rms_literal_discrepancy_strain > 0.0);
/// ```
pub fn discrepancy_visibility(
    scenario: &Scenario,
    model: &ContactModel,
) -> Result<DiscrepancyVisibility, GateError> {
    scenario.validate()?;
    let gate = model.gate();
    let n = gate.n_points();
    let x = sample_levels(scenario.n_experiments, scenario.seed);
    let (mut ss_lit, mut ss_n, mut ss_t, mut ss_g) = (0.0, 0.0, 0.0, 0.0);
    for &xe in &x {
        let delta = DVector::from_vec(true_discrepancy(
            xe,
            &gate.nu_points,
            scenario.theta_true,
            1.0,
        ));
        let mut normal = delta.clone();
        normal.rows_mut(n, n).fill(0.0);
        let tangential = &delta - &normal;
        ss_lit += (&gate.a_matrix * &delta).norm_squared();
        ss_n += (&gate.a_matrix * normal).norm_squared();
        ss_t += (&gate.a_matrix * tangential).norm_squared();
        let g = DVector::from_vec(model.solve(xe[0], xe[1], scenario.theta_true)?.forces);
        ss_g += (&gate.a_matrix * g * scenario.rho).norm_squared();
    }
    let count = (x.len() * gate.n_gauges()) as f64;
    let rms = |ss: f64| (ss / count).sqrt();
    Ok(DiscrepancyVisibility {
        rms_discrepancy_strain: scenario.discrepancy_scale.abs() * rms(ss_lit),
        rms_literal_discrepancy_strain: rms(ss_lit),
        rms_literal_normal_strain: rms(ss_n),
        rms_literal_tangential_strain: rms(ss_t),
        rms_contact_strain: rms(ss_g),
        noise_sd: scenario.noise_sd,
    })
}
