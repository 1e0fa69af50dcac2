//! What a running calibration tells the outside world: progress, stage timings and epochs,
//! reported to an [`Observer`] (argmin's executor/observer split). The algorithms never print
//! and never read the clock; the executor in `calibration` times each [`Stage`] and
//! reports it. Diagnostics that are not progress (e.g. a GP refit that was discarded) go to the
//! `log` facade instead.
//!
//! ```
//! use bamudi::observe::{Event, Observer};
//! use std::sync::Mutex;
//! /// Collects the finished stages and their seconds.
//! #[derive(Default)]
//! struct Stages(Mutex<Vec<String>>);
//! impl Observer for Stages {
//!     fn observe(&self, e: &Event<'_>) {
//!         if let Event::Finished { stage, .. } = e {
//!             self.0.lock().unwrap().push(stage.label().to_string());
//!         }
//!     }
//! }
//! let o = Stages::default();
//! o.observe(&Event::Finished { stage: bamudi::observe::Stage::Rho, seconds: 0.1 });
//! assert_eq!(o.0.lock().unwrap()[0], "Module 2: rho*");
//! ```

/// The timed stages of a calibration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Module 2: the Eq.-27 training set.
    TrainingSet,
    /// Module 2: fitting the coefficient estimator (Eq. 29).
    Estimator,
    /// Module 2: `ρ*` (Eq. 30) and `α̂` at the experiments (Eq. 32).
    Rho,
    /// Module 2: the coefficient GPs (Eq. 33-37).
    CoefficientGps,
    /// Module 3: the coefficient strategy's own search (the conditional mode's `ρ` profile and
    /// GP refit).
    Coefficients,
    /// Module 3: the covariance and the `θ` posteriors.
    Module3,
    /// The adequacy checks ([`crate::adequacy`]).
    Adequacy,
}

impl Stage {
    /// A short human-readable label.
    pub fn label(self) -> &'static str {
        match self {
            Self::TrainingSet => "Module 2: training set",
            Self::Estimator => "Module 2: estimator",
            Self::Rho => "Module 2: rho*",
            Self::CoefficientGps => "Module 2: coefficient GPs",
            Self::Coefficients => "Module 3: coefficients",
            Self::Module3 => "Module 3: theta posterior",
            Self::Adequacy => "adequacy checks",
        }
    }
}

/// One report.
#[derive(Debug, Clone, PartialEq)]
pub enum Event<'a> {
    /// A stage begins; `work` units will be reported by [`Event::Advanced`] (0 = unknown).
    Started {
        /// The stage.
        stage: Stage,
        /// Units of work announced.
        work: u64,
    },
    /// `by` more units of the stage's work are done.
    Advanced {
        /// The stage.
        stage: Stage,
        /// Units just done.
        by: u64,
    },
    /// A stage ended after `seconds` of wall time.
    Finished {
        /// The stage.
        stage: Stage,
        /// Wall-clock seconds.
        seconds: f64,
    },
    /// The learnt estimator finished an epoch (losses in standardised units).
    Epoch {
        /// 1-based epoch.
        epoch: usize,
        /// Epoch budget.
        epochs: usize,
        /// Training loss.
        train_loss: f64,
        /// Validation loss, when a validation split is held out.
        val_loss: Option<f64>,
    },
    /// Something the user should read (not a diagnostic: those go to `log`).
    Notice {
        /// Where it happened.
        stage: Stage,
        /// The message.
        message: &'a str,
    },
}

/// Receives the [`Event`]s of a calibration; called from worker threads.
pub trait Observer: Sync {
    /// Handles one event.
    fn observe(&self, event: &Event<'_>);
}

/// An observer that ignores everything (the default).
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {
    fn observe(&self, _event: &Event<'_>) {}
}

/// Reports `Advanced { by: 1 }` for `stage` to `observer`; for progress inside parallel loops.
pub(crate) fn tick(observer: &dyn Observer, stage: Stage) {
    observer.observe(&Event::Advanced { stage, by: 1 });
}
