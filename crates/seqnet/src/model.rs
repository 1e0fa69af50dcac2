//! The trained regressor: prediction in data units, training history, versioned save/load.

use crate::data::{check_matrix, to_row_major};
use crate::error::SeqError;
use crate::float::{Float, Precision};
use crate::net::{LstmShape, Network, Workspace};
use crate::params::CheckedLstmParams;
use nalgebra::DMatrix;
use numerics::Standardizer;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Version of the JSON file format written by [`LstmRegressor::save`]; bumped on any
/// incompatible change.
///
/// * 2 (current): the scalers' standard deviations are named `sd` (the shared
///   [`numerics::Standardizer`]), and the hyper-parameters have no `progress` flag.
/// * 1: scalers with `std`, hyper-parameters with `progress`. Still read by
///   [`LstmRegressor::load`] (the same numbers, bit for bit); never written.
///
/// Files of any other version are refused with [`SeqError::Format`].
pub const FORMAT_VERSION: u32 = 2;

/// Every version [`LstmRegressor::load`] reads (see [`FORMAT_VERSION`]).
const READABLE_VERSIONS: [u32; 2] = [1, FORMAT_VERSION];

/// The in-memory value is always in the current format, whatever version it was read from.
fn current_format_version() -> u32 {
    FORMAT_VERSION
}

/// Per-epoch record of a training run. Losses are mean squared errors in standardised output
/// units (so 1.0 is the error of predicting the training mean).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingHistory {
    /// Mean training loss over each epoch's mini-batches (weights changing during the epoch).
    pub train_loss: Vec<f64>,
    /// Validation loss after each epoch (empty without a validation split).
    pub val_loss: Vec<f64>,
    /// Learning rate used in each epoch.
    pub learning_rate: Vec<f64>,
    /// Wall-clock seconds of each epoch (training pass plus validation).
    pub epoch_seconds: Vec<f64>,
    /// Epoch (0-based) whose weights were kept: lowest validation (else training) loss.
    pub best_epoch: usize,
    /// The monitored loss at `best_epoch`.
    pub best_loss: f64,
    /// Whether early stopping ended training before the epoch budget.
    pub stopped_early: bool,
    /// Samples in the training split.
    pub train_samples: usize,
    /// Samples in the validation split.
    pub validation_samples: usize,
    /// Total wall-clock seconds of `fit`'s training phase.
    pub wall_seconds: f64,
}

/// Network weights in the precision they were trained in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) enum Weights {
    F32(Network<f32>),
    F64(Network<f64>),
}

impl Weights {
    fn shape(&self) -> &LstmShape {
        match self {
            Self::F32(n) => n.shape(),
            Self::F64(n) => n.shape(),
        }
    }
    fn n_params(&self) -> usize {
        match self {
            Self::F32(n) => n.params().len(),
            Self::F64(n) => n.params().len(),
        }
    }
}

/// A trained LSTM regressor (Sec. 3.3.2's `alpha = f_ML(rho, x, mu_o)`): standardisation,
/// network and training history in one serialisable value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LstmRegressor {
    #[serde(skip_deserializing, default = "current_format_version")]
    format_version: u32,
    shape: LstmShape,
    params: CheckedLstmParams,
    weights: Weights,
    x_scaler: Standardizer,
    y_scaler: Standardizer,
    history: TrainingHistory,
}

/// Rows per forward chunk in `predict` (bounds workspace memory for large inputs).
const PREDICT_CHUNK: usize = 1024;

impl LstmRegressor {
    pub(crate) fn from_parts(
        params: CheckedLstmParams,
        weights: Weights,
        x_scaler: Standardizer,
        y_scaler: Standardizer,
        history: TrainingHistory,
    ) -> Self {
        Self {
            format_version: FORMAT_VERSION,
            shape: *weights.shape(),
            params,
            weights,
            x_scaler,
            y_scaler,
            history,
        }
    }

    /// Predicts outputs (data units) for each row of `x` (`n_inputs` columns).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(32, 2, |r, c| (r + c) as f64);
    /// let y = DMatrix::from_fn(32, 1, |r, _| r as f64);
    /// let m = seqnet::LstmParams::new(2, 1).hidden(4).epochs(1).fit(&x, &y).unwrap();
    /// assert_eq!(m.predict(&x).unwrap().shape(), (32, 1));
    /// assert!(m.predict(&DMatrix::zeros(3, 5)).is_err()); // wrong column count
    /// ```
    pub fn predict(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>, SeqError> {
        check_matrix("x", x, None, self.shape.n_inputs())?;
        match &self.weights {
            Weights::F32(net) => Ok(self.predict_typed(net, x)),
            Weights::F64(net) => Ok(self.predict_typed(net, x)),
        }
    }

    fn predict_typed<T: Float>(&self, net: &Network<T>, x: &DMatrix<f64>) -> DMatrix<f64> {
        let xs: Vec<T> = to_row_major(&self.x_scaler, x);
        let (n_in, n_out) = (self.shape.n_inputs(), self.shape.n_outputs);
        let mut out = DMatrix::zeros(x.nrows(), n_out);
        let mut ws = Workspace::new();
        for start in (0..x.nrows()).step_by(PREDICT_CHUNK) {
            let b = PREDICT_CHUNK.min(x.nrows() - start);
            let yhat = net
                .forward(&xs[start * n_in..(start + b) * n_in], b, &mut ws)
                .expect("input buffer is built with the network's shape");
            for r in 0..b {
                for c in 0..n_out {
                    out[(start + r, c)] = self.y_scaler.invert_value(c, yhat[r * n_out + c].f64());
                }
            }
        }
        out
    }

    /// Per-epoch losses, learning rates and timings of the training run.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(32, 2, |r, c| (r * c) as f64);
    /// let y = DMatrix::from_fn(32, 1, |r, _| r as f64);
    /// let m = seqnet::LstmParams::new(2, 1).hidden(4).epochs(3).patience(0).fit(&x, &y).unwrap();
    /// assert_eq!(m.history().val_loss.len(), 3);
    /// ```
    pub fn history(&self) -> &TrainingHistory {
        &self.history
    }

    /// The network shape.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(16, 2, |r, c| (r + 2 * c) as f64);
    /// let y = DMatrix::from_fn(16, 3, |r, c| (r * c) as f64);
    /// let m = seqnet::LstmParams::new(2, 3).hidden(4).steps(2).epochs(1).fit(&x, &y).unwrap();
    /// assert_eq!((m.shape().steps, m.shape().n_outputs), (2, 3));
    /// ```
    pub fn shape(&self) -> &LstmShape {
        &self.shape
    }

    /// The (checked) parameters the model was trained with: data shape, hyper-parameters,
    /// seed.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(16, 2, |r, c| (r + 2 * c) as f64);
    /// let y = DMatrix::from_fn(16, 1, |r, _| r as f64);
    /// let p = seqnet::LstmParams::new(2, 1).hidden(4).epochs(1).check().unwrap();
    /// assert_eq!(p.fit(&x, &y).unwrap().params(), &p);
    /// ```
    pub fn params(&self) -> &CheckedLstmParams {
        &self.params
    }

    /// Precision of the stored weights.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(16, 2, |r, c| (r + 2 * c) as f64);
    /// let y = DMatrix::from_fn(16, 1, |r, _| r as f64);
    /// let m = seqnet::LstmParams::new(2, 1).hidden(4).epochs(1)
    ///     .precision(seqnet::Precision::F64).fit(&x, &y).unwrap();
    /// assert_eq!(m.precision(), seqnet::Precision::F64);
    /// ```
    pub fn precision(&self) -> Precision {
        match self.weights {
            Weights::F32(_) => Precision::F32,
            Weights::F64(_) => Precision::F64,
        }
    }

    /// Writes the model as JSON (`format_version`, shape, hyper-parameters, weights, scalers,
    /// history). Floats are written in shortest round-trip form, so `load` restores every weight
    /// bit for bit.
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(16, 2, |r, c| (r + 2 * c) as f64);
    /// let y = DMatrix::from_fn(16, 1, |r, _| r as f64);
    /// let m = seqnet::LstmParams::new(2, 1).hidden(4).epochs(1).fit(&x, &y).unwrap();
    /// let path = std::env::temp_dir().join("seqnet_doc_save.json");
    /// m.save(&path).unwrap();
    /// assert_eq!(seqnet::LstmRegressor::load(&path).unwrap(), m);
    /// ```
    pub fn save(&self, path: &Path) -> Result<(), SeqError> {
        let json = serde_json::to_string(self).map_err(|source| SeqError::Json {
            path: path.to_path_buf(),
            source,
        })?;
        std::fs::write(path, json).map_err(|source| SeqError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads a model written by [`LstmRegressor::save`] (this version or version 1, see
    /// [`FORMAT_VERSION`]); another `format_version` or an internally inconsistent file
    /// (weights not matching the stated shape, scalers of the wrong length) is a
    /// [`SeqError::Format`], and invalid hyper-parameters a [`SeqError::Json`].
    ///
    /// ```
    /// let path = std::env::temp_dir().join("seqnet_doc_bad_version.json");
    /// std::fs::write(&path, r#"{"format_version": 99}"#).unwrap();
    /// assert!(matches!(seqnet::LstmRegressor::load(&path), Err(seqnet::SeqError::Format { .. })));
    /// ```
    pub fn load(path: &Path) -> Result<Self, SeqError> {
        let text = std::fs::read_to_string(path).map_err(|source| SeqError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let json_err = |source| SeqError::Json {
            path: path.to_path_buf(),
            source,
        };
        let value: serde_json::Value = serde_json::from_str(&text).map_err(json_err)?;
        let found = value.get("format_version").and_then(|v| v.as_u64());
        if !found.is_some_and(|v| READABLE_VERSIONS.iter().any(|&r| u64::from(r) == v)) {
            return Err(SeqError::Format {
                path: path.to_path_buf(),
                expected: format!("format_version {FORMAT_VERSION} (or 1)"),
                found: found.map_or("no format_version field".into(), |v| {
                    format!("format_version {v}")
                }),
            });
        }
        let model: Self = serde_json::from_value(value).map_err(json_err)?;
        model.check_consistency(path)?;
        Ok(model)
    }

    /// Like [`LstmRegressor::load`], and additionally requires the stored network to have
    /// `expected` shape (e.g. the 10-input, 12-output Module-2 network).
    ///
    /// ```
    /// use nalgebra::DMatrix;
    /// let x = DMatrix::from_fn(16, 2, |r, c| (r + 2 * c) as f64);
    /// let y = DMatrix::from_fn(16, 1, |r, _| r as f64);
    /// let m = seqnet::LstmParams::new(2, 1).hidden(4).epochs(1).fit(&x, &y).unwrap();
    /// let path = std::env::temp_dir().join("seqnet_doc_shape.json");
    /// m.save(&path).unwrap();
    /// let other = seqnet::LstmShape::new(2, 1, 8, 1, 1).unwrap();
    /// assert!(seqnet::LstmRegressor::load_with_shape(&path, &other).is_err());
    /// ```
    pub fn load_with_shape(path: &Path, expected: &LstmShape) -> Result<Self, SeqError> {
        let model = Self::load(path)?;
        if model.shape != *expected {
            return Err(SeqError::Format {
                path: path.to_path_buf(),
                expected: format!("{expected:?}"),
                found: format!("{:?}", model.shape),
            });
        }
        Ok(model)
    }

    fn check_consistency(&self, path: &Path) -> Result<(), SeqError> {
        let fail = |expected: String, found: String| {
            Err(SeqError::Format {
                path: path.to_path_buf(),
                expected,
                found,
            })
        };
        let sh = self.shape;
        if let Err(e) = LstmShape::new(sh.n_features, sh.steps, sh.hidden, sh.layers, sh.n_outputs)
        {
            return fail("a shape with all sizes >= 1".into(), e.to_string());
        }
        if self.params.shape() != self.shape {
            return fail(
                format!("hyper-parameters describing shape {:?}", self.shape),
                format!("{:?}", self.params.shape()),
            );
        }
        if self.weights.shape() != &self.shape {
            return fail(
                format!("weights of shape {:?}", self.shape),
                format!("{:?}", self.weights.shape()),
            );
        }
        if self.weights.n_params() != self.shape.n_params() {
            return fail(
                format!("{} weights", self.shape.n_params()),
                format!("{} weights", self.weights.n_params()),
            );
        }
        let scalers = [
            ("x", &self.x_scaler, self.shape.n_inputs()),
            ("y", &self.y_scaler, self.shape.n_outputs),
        ];
        for (name, s, n) in scalers {
            if s.mean.len() != n || s.sd.len() != n {
                return fail(
                    format!("{name} scaler of length {n}"),
                    format!("lengths {} / {}", s.mean.len(), s.sd.len()),
                );
            }
        }
        Ok(())
    }
}
