//! The paper's LSTM estimator (`seqnet`).

use super::{CoefficientEstimator, EstimatorData, FittedEstimator, stack_inputs};
use crate::error::{BamudiError, Result};
use crate::observe::{Event, Observer};
use crate::surrogate::training::{TrainingSet, XContext};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// The paper's LSTM estimator `α = f_ML(ρ, x, y)` (Sec. 3.3.2, Eq. 28-29).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LstmEstimator {
    net: seqnet::LstmRegressor,
}

impl LstmEstimator {
    /// Trains the network on the Eq.-27 training set (inputs `[ρ, x, μ_o]`, outputs `α`),
    /// reporting each epoch to `observer`.
    pub fn fit(
        train: &TrainingSet,
        settings: &seqnet::LstmSettings,
        seed: u64,
        observer: &dyn Observer,
    ) -> Result<Self> {
        let inputs = stack_inputs(&train.rho, &train.x, &train.mu_o);
        let err = |e: seqnet::SeqError| BamudiError::Estimator {
            estimator: "lstm",
            reason: e.to_string(),
        };
        let net = seqnet::LstmParams::new(inputs.ncols(), train.alpha.ncols())
            .settings(settings.clone())
            .seed(seed)
            .check()
            .map_err(err)?
            .fit_observed(&inputs, &train.alpha, &mut EpochForwarder(observer))
            .map_err(err)?;
        Ok(Self { net })
    }

    /// The trained network (for its training history, or to save it).
    pub fn network(&self) -> &seqnet::LstmRegressor {
        &self.net
    }
}

impl CoefficientEstimator for LstmEstimator {
    fn name(&self) -> &'static str {
        "lstm"
    }
    fn predict(
        &self,
        rho: f64,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        _ctx: &[XContext],
    ) -> Result<DMatrix<f64>> {
        let inputs = stack_inputs(&vec![rho; x.nrows()], x, y);
        self.net
            .predict(&inputs)
            .map_err(|e| BamudiError::Estimator {
                estimator: "lstm",
                reason: e.to_string(),
            })
    }
}

/// Fits the LSTM on the Eq.-27 training set, reporting each epoch to the observer.
pub(super) fn fit(s: &seqnet::LstmSettings, data: &EstimatorData<'_>) -> Result<FittedEstimator> {
    let train = data.training("lstm")?;
    let net = LstmEstimator::fit(train, s, data.seed, data.observer)?;
    Ok(FittedEstimator::Lstm(Box::new(net)))
}

/// Forwards `seqnet`'s epoch reports to the calibration's observer.
struct EpochForwarder<'a>(&'a dyn Observer);

impl seqnet::TrainObserver for EpochForwarder<'_> {
    fn epoch(&mut self, r: &seqnet::EpochReport) {
        self.0.observe(&Event::Epoch {
            epoch: r.epoch,
            epochs: r.epochs,
            train_loss: r.train_loss,
            val_loss: r.val_loss,
        });
    }
}
