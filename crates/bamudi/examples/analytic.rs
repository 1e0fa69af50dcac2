//! Calibrates a small analytic two-level model with the engine (the example of the crate
//! README): `cargo run --release -p bamudi --example analytic`.
use bamudi::{CalibrationParams, CoefficientMode, EstimatorParams, Experiments, SamplingRule};
use mlmodel::{
    DiscrepancyBasis, LinearObservableModel, MultiLevelModel, ObservableModel, UniformPrior,
    UnobservableModel,
};
use nalgebra::{DMatrix, DVector};

/// Points along the strip where the load is represented (m).
const POINTS: [f64; 21] = [
    0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8,
    0.85, 0.9, 0.95, 1.0,
];

/// Unobservable: the contact load along a strip (kN/m), `q(d) = x₀ exp(−θ d)`, with the
/// applied load `x₀` (kN/m) and an unknown decay rate `θ` (1/m).
struct StripLoad;

impl UnobservableModel for StripLoad {
    fn input_names(&self) -> Vec<String> {
        vec!["load_kn_per_m".into()]
    }
    fn param_dim(&self) -> usize {
        1
    }
    fn components(&self) -> usize {
        1
    }
    fn coordinates(&self) -> &[f64] {
        &POINTS
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        for (o, d) in out.iter_mut().zip(POINTS) {
            *o = x[0] * (-theta[0] * d).exp();
        }
        Ok(())
    }
}

/// Observable: six sensors, each a Gaussian-weighted average of the load (kN/m), linear in
/// the load: `y = A q`.
struct Sensors(DMatrix<f64>);

impl Sensors {
    fn new() -> Self {
        let centres = [0.05, 0.25, 0.45, 0.65, 0.85, 1.0];
        Self(DMatrix::from_fn(6, POINTS.len(), |s, b| {
            0.05 * (-((POINTS[b] - centres[s]) / 0.2).powi(2)).exp()
        }))
    }
}

impl ObservableModel for Sensors {
    fn output_names(&self) -> Vec<String> {
        (1..=6).map(|s| format!("sensor_{s}")).collect()
    }
    fn evaluate(&self, x: &[f64], t: &[f64], q: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        self.offset(x, t, out)?;
        let y = &self.0 * DVector::from_column_slice(q);
        out.iter_mut().zip(y.iter()).for_each(|(o, v)| *o += v);
        Ok(())
    }
}

impl LinearObservableModel for Sensors {
    fn matrix(&self) -> &DMatrix<f64> {
        &self.0
    }
    fn offset(&self, _: &[f64], _: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        out.fill(0.0);
        Ok(())
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // the multi-level model: prior θ ~ U(0.5, 3), a linear Legendre discrepancy
    let basis = DiscrepancyBasis::new(orthopoly::Family::Legendre, (0.0, 1.0), &POINTS, &[2])?;
    let prior = Box::new(UniformPrior::new(vec![(0.5, 3.0)])?);
    let model = MultiLevelModel::new(StripLoad, Sensors::new(), prior, basis)?;

    // synthetic measurements from a reality the model lacks: 90 % of the model's load plus a
    // smooth extra load, θ* = 1.6, sensor noise 0.002 kN/m (deterministic pseudo-noise)
    let (theta_true, n) = (1.6, 40);
    let x = DMatrix::from_fn(n, 1, |i, _| 1.0 + 9.0 * i as f64 / (n - 1) as f64);
    let a = model.observable.matrix().clone();
    let y = DMatrix::from_fn(n, 6, |i, s| {
        let q = DVector::from_fn(POINTS.len(), |b, _| {
            let d = POINTS[b];
            0.9 * x[(i, 0)] * (-theta_true * d).exp() + 0.04 * x[(i, 0)] * (1.0 - d)
        });
        (a.row(s) * q)[(0, 0)] + 0.002 * (((i * 7 + s * 3) % 11) as f64 / 5.0 - 1.0)
    });
    let names = model.observable.output_names();
    let exps = Experiments::new(vec!["load_kn_per_m".into()], names, x, y)?;

    // params -> checked config -> calibrate (Modules 2-3)
    let cfg = CalibrationParams::default()
        .estimator(EstimatorParams::ExactLinear)
        .coefficients(CoefficientMode::ConditionalOnTheta)
        .sampling(SamplingRule::default().noise_sd(0.002))
        .theta_grid_points(121)
        .check()?;
    let cal = bamudi::calibrate(&model, &exps, &cfg)?;
    let theta = cal.module3().posterior.summary(0);
    println!(
        "theta = {:.3} ± {:.3} (95 % [{:.3}, {:.3}]; truth {theta_true}), rho* = {:.3}",
        theta.mean,
        theta.sd,
        theta.ci95.0,
        theta.ci95.1,
        cal.rho_star()
    );

    // Module 4: the calibrated load along the strip at a new input, with its band
    let band = cal.predictor(&model)?.response(&[5.0])?;
    println!(
        "load at d = 0.5 m for x = 5 kN/m: {:.3} kN/m [{:.3}, {:.3}]",
        band.mean[10], band.lower[10], band.upper[10]
    );

    // the third level (Eq. 8): a prediction model fed by the calibrated load, here its peak
    // and its resultant; the band comes from joint draws of the load, not point by point
    let prediction = cal
        .predictor(&model)?
        .predict_through(&PeakAndResultant, &[5.0], 2000, 7)?;
    println!(
        "resultant for x = 5 kN/m: {:.4} kN [{:.4}, {:.4}]",
        prediction.mean[1], prediction.lower[1], prediction.upper[1]
    );
    // `--json`: the same numbers at full precision and the calibration's seconds (the Python
    // package's test and benchmark of the same model as numpy callables compare with them)
    if std::env::args().any(|a| a == "--json") {
        let (lo, hi) = theta.ci95;
        let t = cal.timings();
        let seconds = t.module2_s() + t.coefficients_s + t.module3_s + t.adequacy_s;
        println!(
            "{{\"theta\": [{:?}, {:?}, {lo:?}, {hi:?}], \"rho_star\": {:?}, \"sigma_eps\": {:?}, \"load_mean\": {:?}, \"load_band\": [{:?}, {:?}], \"resultant\": [{:?}, {:?}, {:?}], \"calibration_s\": {seconds:?}}}",
            theta.mean,
            theta.sd,
            cal.rho_star(),
            cal.sigma_eps(),
            band.mean,
            band.lower[10],
            band.upper[10],
            prediction.mean[1],
            prediction.lower[1],
            prediction.upper[1]
        );
    }
    Ok(())
}

/// A prediction model (`g_p` of Eq. 8): the peak load (kN/m) and the resultant (kN, trapezoid
/// rule over the strip) of a load along the strip.
struct PeakAndResultant;

impl mlmodel::PredictionModel for PeakAndResultant {
    fn output_names(&self) -> Vec<String> {
        vec!["peak_kn_per_m".into(), "resultant_kn".into()]
    }
    fn evaluate(&self, _: &[f64], _: &[f64], q: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
        out[0] = q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        out[1] = q.windows(2).map(|w| 0.05 * 0.5 * (w[0] + w[1])).sum();
        Ok(())
    }
}
