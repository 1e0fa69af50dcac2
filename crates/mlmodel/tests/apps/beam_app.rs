//! A second application of the `mlmodel` traits: an Euler-Bernoulli beam on a Winkler
//! (elastic) foundation whose support has been lost over an end region `[0, θ)`.
//!
//! * Inputs `x = [P, q]`: a point load `P` (lbf, downward) at `d = 72 in` and a uniform load
//!   `q` (lbf/in, downward) over the whole beam.
//! * Unknown parameter `θ` (inches): length of the unsupported region at the left end, like the
//!   miter gate's bottom gap.
//! * Unobservable response `g_u(x, θ)`: the distributed support reaction (lbf/in, upward) at
//!   `N_u = 41` equally spaced points along the 120 in beam, from a Hermite-cubic finite-element
//!   model with Winkler springs lumped on each node's supported tributary length (so `g_u` is
//!   continuous in `θ`).
//! * Observable response `g_o`: bending strain (microstrain) at 7 gauges on the bottom fibre,
//!   computed by statics from the loads and the reaction resultants left of each gauge. It is
//!   exactly linear in the reaction: `ε = A r + b(x)` (a [`LinearObservableModel`]).
//! * "Truth": `r_true = ρ g_u(x, θ*) + δ(x, d)` with a smooth `δ` that vanishes on the
//!   unsupported region (as the gate's Eq. 53-54 do).
//!
//! The file depends only on `mlmodel` and `nalgebra` so that other test binaries can include it
//! with `#[path = ...] mod beam_app;`.
#![allow(dead_code)]

use mlmodel::{
    DiscrepancyBasis, LinearObservableModel, ModelError, MultiLevelModel, ObservableModel,
    UniformPrior, UnobservableModel, check_len,
};
use nalgebra::{DMatrix, DVector};

/// Beam length (in).
pub const LENGTH_IN: f64 = 120.0;
/// Flexural rigidity `E I` (lbf in²): steel, `I = 100 in⁴`.
pub const EI_LBF_IN2: f64 = 29.0e6 * 100.0;
/// Winkler foundation modulus (lbf/in per inch of deflection, per inch of length).
pub const K_FOUNDATION: f64 = 15_000.0;
/// Distance from the neutral axis to the gauged fibre (in).
pub const FIBRE_IN: f64 = 6.0;
/// Position of the point load (in).
pub const LOAD_POSITION_IN: f64 = 72.0;
/// Gauge positions along the beam (in).
pub const GAUGES_IN: [f64; 7] = [10.0, 25.0, 40.0, 55.0, 70.0, 85.0, 100.0];
/// Range of the point load `P` (lbf).
pub const P_RANGE_LBF: (f64, f64) = (1000.0, 10_000.0);
/// Range of the uniform load `q` (lbf/in).
pub const Q_RANGE_LBF_PER_IN: (f64, f64) = (10.0, 100.0);

/// The unobservable model: support reaction intensity (lbf/in) at `n_points` nodes.
#[derive(Debug, Clone)]
pub struct BeamReaction {
    nodes: Vec<f64>,
}

impl BeamReaction {
    /// A beam discretised with `n_points` equally spaced nodes (`n_points >= 3`).
    pub fn new(n_points: usize) -> Self {
        assert!(n_points >= 3, "need at least two elements");
        let h = LENGTH_IN / (n_points - 1) as f64;
        Self {
            nodes: (0..n_points).map(|i| i as f64 * h).collect(),
        }
    }

    fn spacing(&self) -> f64 {
        self.nodes[1] - self.nodes[0]
    }

    /// Tributary interval of node `b`.
    fn tributary(&self, b: usize) -> (f64, f64) {
        let h = self.spacing();
        let lo = (self.nodes[b] - 0.5 * h).max(0.0);
        let hi = (self.nodes[b] + 0.5 * h).min(LENGTH_IN);
        (lo, hi)
    }

    /// Tributary lengths (in) of each node: trapezoid-rule weights for the reaction resultant.
    pub fn tributary_lengths(&self) -> Vec<f64> {
        (0..self.nodes.len())
            .map(|b| {
                let (lo, hi) = self.tributary(b);
                hi - lo
            })
            .collect()
    }

    /// Supported fraction of node `b`'s tributary length when `[0, gap)` has no support.
    fn supported_fraction(&self, b: usize, gap: f64) -> f64 {
        let (lo, hi) = self.tributary(b);
        ((hi - gap.max(lo)).max(0.0)) / (hi - lo)
    }
}

impl UnobservableModel for BeamReaction {
    fn input_names(&self) -> Vec<String> {
        vec!["point_load_lbf".into(), "uniform_load_lbf_per_in".into()]
    }
    fn param_dim(&self) -> usize {
        1
    }
    fn components(&self) -> usize {
        1
    }
    fn coordinates(&self) -> &[f64] {
        &self.nodes
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        check_len("x", x, 2)?;
        check_len("theta", theta, 1)?;
        check_len("out", out, self.nodes.len())?;
        let gap = theta[0];
        if !(0.0..=0.5 * LENGTH_IN).contains(&gap) {
            return Err(ModelError::OutOfDomain {
                name: "theta[0] (gap length, in)".into(),
                value: gap,
                lo: 0.0,
                hi: 0.5 * LENGTH_IN,
            });
        }
        let n = self.nodes.len();
        let h = self.spacing();
        let ndof = 2 * n;
        let mut k = DMatrix::<f64>::zeros(ndof, ndof);
        let c = EI_LBF_IN2 / h.powi(3);
        let ke = [
            [12.0, 6.0 * h, -12.0, 6.0 * h],
            [6.0 * h, 4.0 * h * h, -6.0 * h, 2.0 * h * h],
            [-12.0, -6.0 * h, 12.0, -6.0 * h],
            [6.0 * h, 2.0 * h * h, -6.0 * h, 4.0 * h * h],
        ];
        for e in 0..n - 1 {
            for a in 0..4 {
                for b in 0..4 {
                    k[(2 * e + a, 2 * e + b)] += c * ke[a][b];
                }
            }
        }
        let lengths = self.tributary_lengths();
        let springs: Vec<f64> = (0..n)
            .map(|b| K_FOUNDATION * lengths[b] * self.supported_fraction(b, gap))
            .collect();
        for (b, s) in springs.iter().enumerate() {
            k[(2 * b, 2 * b)] += s;
        }
        let (p, q) = (x[0], x[1]);
        let mut f = DVector::<f64>::zeros(ndof);
        for e in 0..n - 1 {
            // consistent nodal loads of a uniform load on a Hermite element
            f[2 * e] += q * h / 2.0;
            f[2 * e + 1] += q * h * h / 12.0;
            f[2 * e + 2] += q * h / 2.0;
            f[2 * e + 3] -= q * h * h / 12.0;
        }
        let load_node = (LOAD_POSITION_IN / h).round() as usize;
        f[2 * load_node] += p;
        let w = k.lu().solve(&f).ok_or_else(|| ModelError::Numerical {
            context: "BeamReaction::evaluate".into(),
            reason: "singular beam stiffness (too little support)".into(),
        })?;
        for b in 0..n {
            // intensity averaged over the tributary length: spring force / tributary length
            out[b] = springs[b] * w[2 * b] / lengths[b];
        }
        Ok(())
    }
}

/// The observable model: bending strain (microstrain) at [`GAUGES_IN`], linear in the reaction.
#[derive(Debug, Clone)]
pub struct BeamStrain {
    a: DMatrix<f64>,
    /// The beam's flexural rigidity relative to [`EI_LBF_IN2`] (1: the drawing).
    stiffness: f64,
}

/// Microstrain per lbf·in of bending moment on the gauged fibre.
fn microstrain_per_moment() -> f64 {
    1e6 * FIBRE_IN / EI_LBF_IN2
}

impl BeamStrain {
    /// Builds `A` for the reaction nodes of `reaction`.
    pub fn new(reaction: &BeamReaction) -> Self {
        Self::with_stiffness(reaction, 1.0)
    }

    /// As built: the flexural rigidity `stiffness x EI_LBF_IN2` (strains scale with its
    /// inverse, the reaction's share `A` and the loads' `b` alike).
    pub fn with_stiffness(reaction: &BeamReaction, stiffness: f64) -> Self {
        let nodes = reaction.coordinates();
        let lengths = reaction.tributary_lengths();
        let s = microstrain_per_moment() / stiffness;
        let a = DMatrix::from_fn(GAUGES_IN.len(), nodes.len(), |p, b| {
            // an upward reaction resultant left of the gauge gives a hogging (negative) moment
            -s * lengths[b] * (GAUGES_IN[p] - nodes[b]).max(0.0)
        });
        Self { a, stiffness }
    }
}

impl ObservableModel for BeamStrain {
    fn output_names(&self) -> Vec<String> {
        (0..GAUGES_IN.len())
            .map(|p| format!("gauge_{}", p + 1))
            .collect()
    }
    fn evaluate(
        &self,
        x: &[f64],
        theta: &[f64],
        y_u: &[f64],
        out: &mut [f64],
    ) -> mlmodel::Result<()> {
        check_len("y_u", y_u, self.a.ncols())?;
        self.offset(x, theta, out)?;
        for (p, o) in out.iter_mut().enumerate() {
            *o += (0..y_u.len()).map(|b| self.a[(p, b)] * y_u[b]).sum::<f64>();
        }
        Ok(())
    }
}

impl LinearObservableModel for BeamStrain {
    fn matrix(&self) -> &DMatrix<f64> {
        &self.a
    }
    fn offset(&self, x: &[f64], _theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        check_len("x", x, 2)?;
        check_len("out", out, GAUGES_IN.len())?;
        let s = microstrain_per_moment() / self.stiffness;
        for (o, &g) in out.iter_mut().zip(&GAUGES_IN) {
            let moment = x[1] * g * g / 2.0 + x[0] * (g - LOAD_POSITION_IN).max(0.0);
            *o = s * moment;
        }
        Ok(())
    }
}

/// The assumed true discrepancy of the reaction (lbf/in) at `d`: smooth, and fading in
/// smoothly (value and slope zero) from the edge of the unsupported region `[0, gap)`, where the
/// true reaction must vanish.
pub fn true_discrepancy(x: &[f64], d: f64, gap: f64) -> f64 {
    if d < gap {
        return 0.0;
    }
    let u = d / LENGTH_IN;
    let taper = 1.0 - (-((d - gap) / 10.0).powi(2)).exp();
    taper * (0.3 * x[1] * (std::f64::consts::PI * u).cos() + 0.2 * (x[0] / LENGTH_IN) * u * u)
}

/// The true reaction `ρ g_u(x, θ*) + δ(x, d)` at all nodes.
pub fn true_reaction(model: &BeamReaction, x: &[f64], gap: f64, rho: f64) -> Vec<f64> {
    let mut r = vec![0.0; model.coordinates().len()];
    model.evaluate(x, &[gap], &mut r).unwrap();
    for (v, &d) in r.iter_mut().zip(model.coordinates()) {
        *v = rho * *v + true_discrepancy(x, d, gap);
    }
    r
}

/// Deterministic SplitMix64 + Box-Muller normal generator (keeps this file free of `rand`).
pub struct Normal64 {
    state: u64,
}

impl Normal64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }
    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// `n_e` synthetic experiments: loads uniform over their ranges, strains from the true reaction
/// plus `N(0, sigma²)` noise. Returns `(x: n_e x 2, y: n_e x 7)`.
pub fn simulate(
    n_e: usize,
    gap: f64,
    rho: f64,
    sigma_microstrain: f64,
    seed: u64,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let reaction = BeamReaction::new(41);
    let strain = BeamStrain::new(&reaction);
    let mut g = Normal64::new(seed);
    let mut x = DMatrix::zeros(n_e, 2);
    let mut y = DMatrix::zeros(n_e, GAUGES_IN.len());
    for i in 0..n_e {
        let p = P_RANGE_LBF.0 + (P_RANGE_LBF.1 - P_RANGE_LBF.0) * g.uniform();
        let q = Q_RANGE_LBF_PER_IN.0 + (Q_RANGE_LBF_PER_IN.1 - Q_RANGE_LBF_PER_IN.0) * g.uniform();
        x[(i, 0)] = p;
        x[(i, 1)] = q;
        let r = true_reaction(&reaction, &[p, q], gap, rho);
        let mut out = vec![0.0; GAUGES_IN.len()];
        ObservableModel::evaluate(&strain, &[p, q], &[gap], &r, &mut out).unwrap();
        for (j, o) in out.iter().enumerate() {
            y[(i, j)] = o + sigma_microstrain * g.normal();
        }
    }
    (x, y)
}

/// The complete multi-level model: 41-node beam, prior `θ ~ U(prior)`, `terms` Legendre terms.
pub fn beam_model(prior: (f64, f64), terms: usize) -> MultiLevelModel<BeamReaction, BeamStrain> {
    let reaction = BeamReaction::new(41);
    let strain = BeamStrain::new(&reaction);
    let basis = DiscrepancyBasis::new(
        orthopoly::Family::Legendre,
        (0.0, LENGTH_IN),
        reaction.coordinates(),
        &[terms],
    )
    .unwrap();
    let prior = Box::new(UniformPrior::new(vec![prior]).unwrap());
    MultiLevelModel::new(reaction, strain, prior, basis).unwrap()
}
