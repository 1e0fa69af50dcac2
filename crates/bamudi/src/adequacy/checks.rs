//! The statistics of the adequacy checks: each gauge predicted from the others, each
//! condition from the others, and per-gauge sensor-fault signatures fitted jointly with the
//! calibration (see [`super::residual`]). Every statistic comes with a p-value under the
//! calibrated model; the family correction is [`super::verdict`]'s.

use super::residual::ResidualModel;
use super::{ConditionCheck, FaultKind, GaugeCheck, SensorFault};
use crate::error::Result;
use nalgebra::{DMatrix, DVector};
use numerics::stats::{chi2_sf, ljung_box};

/// Lags of the Ljung-Box test on a gauge's whitened deletion residuals.
pub(crate) const LJUNG_BOX_LAGS: usize = 10;

/// Where a step may sit, as fractions of the record (every 0.05 from 0.1 to 0.9: a step
/// closer to either end than a tenth is indistinguishable from an offset of the rest).
pub(crate) fn step_positions() -> Vec<f64> {
    (0..17).map(|i| 0.1 + 0.05 * i as f64).collect()
}

/// The layout of the stacked observations: experiment-major, `n_o` outputs per experiment.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    pub n_e: usize,
    pub n_o: usize,
    /// Output names.
    pub names: Vec<String>,
    /// The fitted mean `ρ̄ a + b` at `θ̂`, stacked (output units): a gain error scales it.
    pub mean: DVector<f64>,
}

impl Layout {
    fn gauge_rows(&self, g: usize) -> Vec<usize> {
        (0..self.n_e).map(|i| i * self.n_o + g).collect()
    }

    /// Position of experiment `i` in the record, 0 to 1 (the data's row order is taken as
    /// time order).
    fn fraction(&self, i: usize) -> f64 {
        i as f64 / (self.n_e.max(2) - 1) as f64
    }

    /// One signature column on gauge `g`: `f(i)` at experiment `i`, zero on other gauges.
    fn column(&self, g: usize, f: impl Fn(usize) -> f64) -> DMatrix<f64> {
        let mut h = DMatrix::zeros(self.n_e * self.n_o, 1);
        for i in 0..self.n_e {
            h[(i * self.n_o + g, 0)] = f(i);
        }
        h
    }

    /// The signature of a fault of `kind` on gauge `g` (step at `at`).
    pub(crate) fn signature(&self, g: usize, kind: FaultKind, at: Option<f64>) -> DMatrix<f64> {
        match kind {
            FaultKind::Offset => self.column(g, |_| 1.0),
            FaultKind::Gain => self.column(g, |i| self.mean[i * self.n_o + g]),
            FaultKind::Drift => self.column(g, |i| self.fraction(i) - 0.5),
            FaultKind::Step => {
                let tau = at.unwrap_or(0.5);
                self.column(g, |i| f64::from(u8::from(self.fraction(i) >= tau)))
            }
        }
    }
}

/// Each gauge predicted from the others through the calibrated model.
pub(crate) fn leave_one_gauge_out(rm: &ResidualModel, lay: &Layout) -> Result<Vec<GaugeCheck>> {
    (0..lay.n_o)
        .map(|g| {
            let rows = lay.gauge_rows(g);
            let del = rm.delete_block(
                &rows,
                &format!("leave-one-gauge-out block of {}", lay.names[g]),
            )?;
            let n = rows.len() as f64;
            let outside = (0..rows.len())
                .filter(|&i| del.residual[i].abs() > 1.96 * del.sd[i])
                .count();
            let (_, lb_p) = ljung_box(&del.whitened, LJUNG_BOX_LAGS.min(rows.len() / 4).max(1));
            Ok(GaugeCheck {
                gauge: lay.names[g].clone(),
                chi2: del.chi2,
                dof: rows.len(),
                p_value: chi2_sf(del.chi2, n),
                mean_shift: del.residual.mean(),
                outside_band_fraction: outside as f64 / n,
                ljung_box_p: lb_p,
            })
        })
        .collect()
}

/// Each experiment (all its gauges) predicted from the others: the largest statistic, with
/// Šidák's correction over the experiments.
pub(crate) fn worst_condition(
    rm: &ResidualModel,
    lay: &Layout,
    x: &DMatrix<f64>,
) -> Result<ConditionCheck> {
    let mut worst = (0usize, f64::NEG_INFINITY);
    for i in 0..lay.n_e {
        let rows: Vec<usize> = (0..lay.n_o).map(|q| i * lay.n_o + q).collect();
        let d = rm.delete_block(&rows, &format!("condition block of experiment {}", i + 1))?;
        if d.chi2 > worst.1 {
            worst = (i, d.chi2);
        }
    }
    let p_one = chi2_sf(worst.1, lay.n_o as f64);
    Ok(ConditionCheck {
        experiment: worst.0 + 1,
        inputs: x.row(worst.0).iter().copied().collect(),
        max_chi2: worst.1,
        dof: lay.n_o,
        p_value: 1.0 - (1.0 - p_one).powf(lay.n_e as f64),
    })
}

/// Two-sided normal p-value of `z`.
pub(crate) fn normal_two_sided(z: f64) -> f64 {
    statrs::function::erf::erfc(z.abs() / std::f64::consts::SQRT_2)
}

/// Every fault signature on every gauge, each fitted alone with the calibration; the step's
/// position is the best of [`step_positions`] (Bonferroni over them).
pub(crate) fn sensor_faults(rm: &ResidualModel, lay: &Layout) -> Result<Vec<SensorFault>> {
    let mut out = Vec::new();
    for g in 0..lay.n_o {
        for kind in [FaultKind::Offset, FaultKind::Gain, FaultKind::Drift] {
            out.push(fit_one(rm, lay, g, kind, None, 1.0)?);
        }
        let taus = step_positions();
        let mut best: Option<SensorFault> = None;
        for &tau in &taus {
            let f = fit_one(rm, lay, g, FaultKind::Step, Some(tau), taus.len() as f64)?;
            if best.as_ref().is_none_or(|b| f.z.abs() > b.z.abs()) {
                best = Some(f);
            }
        }
        out.extend(best);
    }
    Ok(out)
}

fn fit_one(
    rm: &ResidualModel,
    lay: &Layout,
    g: usize,
    kind: FaultKind,
    at: Option<f64>,
    tests: f64,
) -> Result<SensorFault> {
    let h = lay.signature(g, kind, at);
    let what = format!("{} signature of {}", kind.name(), lay.names[g]);
    let (beta, cov) = rm.gls(&h, &what)?;
    let sd = cov[(0, 0)].max(0.0).sqrt();
    let z = beta[0] / sd;
    Ok(SensorFault {
        gauge: lay.names[g].clone(),
        kind,
        estimate: beta[0],
        sd,
        z,
        at_fraction: at,
        p_value: (normal_two_sided(z) * tests).min(1.0),
    })
}
