//! Module 2 as an artefact: its fitted parts with what they were fitted to, so that Module 3
//! runs on them in any coefficient mode without fitting them again ([`Surrogate`]).

use super::training::LinearParts;
use super::{Module2, Problem};
use crate::error::{BamudiError, Result};
use crate::params::{CalibrationParams, EstimatorParams, RhoSearch, SamplingRule};
use mlmodel::{LinearObservableModel, MultiLevelModel, UnobservableModel};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// What a fit remembers of the model it was fitted to, so that a different one is refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct ModelSignature {
    pub(crate) input_names: Vec<String>,
    pub(crate) output_names: Vec<String>,
    pub(crate) response_len: usize,
    pub(crate) n_coefficients: usize,
}

impl ModelSignature {
    pub(crate) fn of<U, O>(model: &MultiLevelModel<U, O>) -> Self
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        Self {
            input_names: model.unobservable.input_names(),
            output_names: model.observable.output_names(),
            response_len: model.unobservable.response_len(),
            n_coefficients: model.basis.n_coefficients(),
        }
    }
}

/// Module 2 fitted — the estimator of Eq. 29, `ρ*` (Eq. 30), `α̂` at the experiments
/// (Eq. 32) and the coefficient GPs (Eq. 33-37) — with what it was fitted to: the model, the
/// experiments (inputs and outputs) and the settings Module 2 reads. It is the paper's
/// surrogate of the discrepancy coefficients, learnt from the measured outputs, not an
/// emulator of the simulator alone: other data need another one. None of it depends on the
/// coefficient mode, so Module 3 can run on it in any mode, with any settings Module 3 alone
/// reads (`coefficients`, `theta_grid_points`, `sigma_eps`, `mcmc`, `adequacy`,
/// `no_discrepancy_fit`, `threads`).
///
/// [`Calibrate::fit_surrogate`](crate::Calibrate::fit_surrogate) fits one,
/// [`Calibration::surrogate`](crate::Calibration::surrogate) takes the one a calibration ran
/// on, and [`Calibrate::run_with_surrogate`](crate::Calibrate::run_with_surrogate) runs
/// Module 3 on it; it refuses a surrogate of another model, other experiments or other
/// Module-2 settings, naming what differs (an example there). It is kept in memory; saved, it
/// is part of a [`Calibration`](crate::Calibration).
#[derive(Debug, Clone)]
pub struct Surrogate {
    module2: Module2,
    model: ModelSignature,
    parts: LinearParts,
    x_experiments: DMatrix<f64>,
    settings: Module2Settings,
}

/// A digest of the experiment outputs (their shape and every value's bits; 64-bit FNV-1a,
/// the same on every platform and toolchain), so that a Module 2 refuses data it was not
/// fitted to.
pub(crate) fn outputs_digest(y: &DMatrix<f64>) -> u64 {
    let words = [y.nrows() as u64, y.ncols() as u64]
        .into_iter()
        .chain(y.iter().map(|v| v.to_bits()));
    words.fold(0xcbf2_9ce4_8422_2325, |h, w| {
        w.to_le_bytes()
            .iter()
            .fold(h, |h, b| (h ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3))
    })
}

/// The settings Module 2 reads (the `θ` rule and the input box are in [`Module2`] itself).
#[derive(Debug, Clone, PartialEq)]
struct Module2Settings {
    seed: u64,
    rho: RhoSearch,
    sampling: SamplingRule,
    gp_restarts: usize,
    estimator: EstimatorParams,
    training_size: usize,
}

impl Module2Settings {
    fn of(p: &CalibrationParams) -> Self {
        Self {
            seed: p.seed,
            rho: p.rho.clone(),
            sampling: p.sampling.clone(),
            gp_restarts: p.gp_restarts,
            estimator: p.estimator.clone(),
            training_size: p.training_size,
        }
    }

    /// The first setting that differs from `other`'s, by name.
    fn differs(&self, other: &Self) -> Option<&'static str> {
        [
            ("seed", self.seed != other.seed),
            ("ρ search", self.rho != other.rho),
            ("sampling rule", self.sampling != other.sampling),
            ("GP restarts", self.gp_restarts != other.gp_restarts),
            ("estimator", self.estimator != other.estimator),
            (
                "training-set size",
                self.training_size != other.training_size,
            ),
        ]
        .into_iter()
        .find_map(|(what, differs)| differs.then_some(what))
    }
}

impl Surrogate {
    /// Module 2 fitted to `p`.
    pub(crate) fn fitted<U, O>(p: &Problem<'_, U, O>, module2: Module2) -> Self
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        Self::from_parts(
            module2,
            ModelSignature::of(p.model),
            p.parts.clone(),
            p.exps.x.clone(),
            p.cfg,
        )
    }

    /// Module 2 of a calibration fitted to a model of signature `model` and matrices `parts`,
    /// at `x_experiments`, under `cfg`.
    pub(crate) fn from_parts(
        module2: Module2,
        model: ModelSignature,
        parts: LinearParts,
        x_experiments: DMatrix<f64>,
        cfg: &CalibrationParams,
    ) -> Self {
        Self {
            module2,
            model,
            parts,
            x_experiments,
            settings: Module2Settings::of(cfg),
        }
    }

    /// Module 2's results.
    pub fn module2(&self) -> &Module2 {
        &self.module2
    }

    /// Checks that this surrogate is Module 2 of `p`: the same model (signature, `A` and the
    /// discrepancy basis `L`), experiment inputs and outputs, `θ` quadrature rule (the prior
    /// and the marginalisation), input box and the settings Module 2 reads. The model's
    /// declared tolerances are not compared: Module 2 does not read them.
    pub(crate) fn check_fits<U, O>(&self, p: &Problem<'_, U, O>) -> Result<()>
    where
        U: UnobservableModel,
        O: LinearObservableModel,
    {
        let model = ModelSignature::of(p.model);
        if self.model != model {
            return Err(BamudiError::Calibration(format!(
                "the surrogate (Module 2) was fitted to another model: fitted to {:?}, given {model:?}",
                self.model
            )));
        }
        let outputs = match self.module2.outputs_digest {
            Some(d) => d != outputs_digest(&p.exps.y),
            None => {
                return Err(BamudiError::Calibration(
                    "the surrogate (Module 2) was saved before the outputs it was fitted to \
                     were recorded: fit it again"
                        .into(),
                ));
            }
        };
        let differs = [
            ("model's matrix A", self.parts.a != p.parts.a),
            ("discrepancy basis L", self.parts.l != p.parts.l),
            ("experiment inputs", self.x_experiments != p.exps.x),
            ("experiment outputs", outputs),
            ("θ quadrature rule", self.module2.theta_rule != p.theta_rule),
            ("input box", self.module2.x_bounds != p.x_bounds),
        ]
        .into_iter()
        .find_map(|(what, differs)| differs.then_some(what))
        .or_else(|| self.settings.differs(&Module2Settings::of(p.cfg)));
        match differs {
            Some(what) => Err(BamudiError::Calibration(format!(
                "the surrogate (Module 2) was fitted to something else: its {what} differs"
            ))),
            None => Ok(()),
        }
    }
}
