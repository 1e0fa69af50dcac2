//! Progress reporting without printing: the trainer hands one [`EpochReport`] per epoch to a
//! [`TrainObserver`] chosen by the caller (a progress bar, a log line, an event forwarded to an
//! application's own observer, or nothing).

/// What the trainer knows at the end of one epoch. Losses are mean squared errors in
/// standardised output units (1.0 is the error of predicting the training mean), exactly the
/// values then stored in the [`TrainingHistory`](crate::TrainingHistory).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct EpochReport {
    /// The epoch just finished (0-based).
    pub epoch: usize,
    /// The epoch budget (early stopping may end training sooner).
    pub epochs: usize,
    /// Mean training loss over the epoch's mini-batches.
    pub train_loss: f64,
    /// Validation loss after the epoch (`None` without a validation split).
    pub val_loss: Option<f64>,
    /// Learning rate used in this epoch.
    pub learning_rate: f64,
    /// Epoch (0-based) with the lowest monitored loss so far (validation, else training),
    /// including this one; its weights are the ones the model will keep.
    pub best_epoch: usize,
    /// The monitored loss at `best_epoch`.
    pub best_loss: f64,
    /// Wall-clock seconds of this epoch (training pass plus validation).
    pub seconds: f64,
}

/// Receives training progress, one call per finished epoch (in order, on the calling thread).
/// Observing never changes the numbers: a fit with any observer gives the same model as
/// without.
///
/// Closures `FnMut(&EpochReport)` are observers:
///
/// ```
/// use nalgebra::DMatrix;
/// let x = DMatrix::from_fn(32, 2, |r, c| ((r * 5 + c) % 7) as f64);
/// let y = DMatrix::from_fn(32, 1, |r, _| x[(r, 0)] - x[(r, 1)]);
/// let mut seen = Vec::new();
/// let params = seqnet::LstmParams::new(2, 1).hidden(3).epochs(2).patience(0).check().unwrap();
/// params.fit_observed(&x, &y, &mut |r: &seqnet::EpochReport| seen.push(r.epoch)).unwrap();
/// assert_eq!(seen, vec![0, 1]);
/// ```
pub trait TrainObserver {
    /// Called after each epoch with that epoch's numbers.
    fn epoch(&mut self, report: &EpochReport);
}

/// The observer that ignores every report (what [`CheckedLstmParams::fit`] uses).
///
/// [`CheckedLstmParams::fit`]: crate::CheckedLstmParams::fit
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoObserver;

impl TrainObserver for NoObserver {
    fn epoch(&mut self, _report: &EpochReport) {}
}

impl<F: FnMut(&EpochReport)> TrainObserver for F {
    fn epoch(&mut self, report: &EpochReport) {
        self(report)
    }
}
