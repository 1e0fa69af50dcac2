//! The engine's observer events as calls of a Python callback
//! `progress(stage: str, done: int, total: int)` (`total` 0 when unknown).

use bamudi::observe::{Event, Observer, Stage};
use pyo3::prelude::*;
use std::collections::HashMap;
use std::sync::Mutex;

/// Forwards stage starts, advances and ends to `callback`, counting the work done per
/// stage. An exception raised by the callback is reported as unraisable (it cannot stop a
/// computation running without the GIL) and later calls still happen.
pub struct Callback {
    callback: Option<Py<PyAny>>,
    counts: Mutex<HashMap<Stage, (u64, u64)>>,
}

impl Callback {
    /// An observer calling `callback` (none: ignores everything).
    pub fn new(callback: Option<Py<PyAny>>) -> Self {
        Self {
            callback,
            counts: Mutex::new(HashMap::new()),
        }
    }

    fn call(&self, stage: Stage, done: u64, total: u64) {
        let Some(cb) = &self.callback else { return };
        Python::attach(|py| {
            if let Err(e) = cb.call1(py, (stage.label(), done, total)) {
                e.write_unraisable(py, None);
            }
        });
    }
}

impl Observer for Callback {
    fn observe(&self, event: &Event<'_>) {
        let Ok(mut counts) = self.counts.lock() else {
            return;
        };
        let (stage, done, total) = match *event {
            Event::Started { stage, work } => {
                counts.insert(stage, (0, work));
                (stage, 0, work)
            }
            Event::Advanced { stage, by } => {
                let c = counts.entry(stage).or_insert((0, 0));
                c.0 += by;
                (stage, c.0, c.1)
            }
            Event::Finished { stage, .. } => {
                let c = counts.entry(stage).or_insert((0, 0));
                let total = c.1.max(c.0);
                (stage, total, total)
            }
            _ => return,
        };
        drop(counts);
        self.call(stage, done, total);
    }
}
