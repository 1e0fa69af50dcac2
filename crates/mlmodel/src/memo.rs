//! [`Memo`]: any [`UnobservableModel`] with its evaluations remembered.

use crate::{Result, UnobservableModel};
use std::collections::HashMap;
use std::sync::{Arc, RwLock};

/// An [`UnobservableModel`] that remembers its evaluations, keyed by the exact bits of
/// `(x, θ)`. A deterministic model gives identical outputs for identical inputs, so the memo
/// never changes a result; it only skips repeated solves (a calibration evaluates the same
/// experiment at the same θ nodes many times, and a close-the-loop run re-calibrates on the
/// same rows). When it holds `capacity` entries it is cleared (logged at `info` level through
/// the `log` facade). With `capacity = 0` nothing is stored: the wrapper is a pass-through.
///
/// Memory: each entry is `response_len()` values (8 bytes each) plus its key.
///
/// ```
/// use mlmodel::{Memo, UnobservableModel};
/// struct Square;
/// impl UnobservableModel for Square {
///     fn input_names(&self) -> Vec<String> { vec!["x".into()] }
///     fn param_dim(&self) -> usize { 1 }
///     fn components(&self) -> usize { 1 }
///     fn coordinates(&self) -> &[f64] { &[0.0] }
///     fn evaluate(&self, x: &[f64], t: &[f64], out: &mut [f64]) -> mlmodel::Result<()> {
///         out[0] = x[0] * x[0] * t[0];
///         Ok(())
///     }
/// }
/// let m = Memo::new(Square, 100);
/// let mut a = [0.0];
/// m.evaluate(&[3.0], &[2.0], &mut a).unwrap();
/// m.evaluate(&[3.0], &[2.0], &mut a).unwrap(); // from the memo
/// assert_eq!((a[0], m.len()), (18.0, 1));
/// ```
#[derive(Debug)]
pub struct Memo<U> {
    inner: U,
    memo: RwLock<HashMap<Vec<u64>, Arc<[f64]>>>,
    capacity: usize,
}

impl<U: UnobservableModel> Memo<U> {
    /// Wraps `inner`, remembering at most `capacity` evaluations (0: none).
    pub fn new(inner: U, capacity: usize) -> Self {
        Self {
            inner,
            memo: RwLock::new(HashMap::new()),
            capacity,
        }
    }

    /// The wrapped model.
    pub fn inner(&self) -> &U {
        &self.inner
    }

    /// The largest number of remembered evaluations.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Number of remembered evaluations.
    pub fn len(&self) -> usize {
        self.memo.read().map_or(0, |m| m.len())
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn key(x: &[f64], theta: &[f64]) -> Vec<u64> {
        x.iter().chain(theta).map(|v| v.to_bits()).collect()
    }

    fn remember(&self, key: Vec<u64>, out: &[f64]) {
        if let Ok(mut m) = self.memo.write() {
            if m.len() >= self.capacity {
                log::info!("model memo full ({} entries): cleared", m.len());
                m.clear();
            }
            m.insert(key, Arc::from(out));
        }
    }
}

impl<U: UnobservableModel> UnobservableModel for Memo<U> {
    fn input_names(&self) -> Vec<String> {
        self.inner.input_names()
    }
    fn param_dim(&self) -> usize {
        self.inner.param_dim()
    }
    fn components(&self) -> usize {
        self.inner.components()
    }
    fn coordinates(&self) -> &[f64] {
        self.inner.coordinates()
    }
    fn check_input(&self, x: &[f64]) -> Result<()> {
        self.inner.check_input(x)
    }
    fn response_vanishes(&self, x: &[f64]) -> bool {
        self.inner.response_vanishes(x)
    }
    fn discrepancy_support(&self, theta: &[f64]) -> Option<Vec<f64>> {
        self.inner.discrepancy_support(theta)
    }
    fn evaluate(&self, x: &[f64], theta: &[f64], out: &mut [f64]) -> Result<()> {
        if self.capacity == 0 {
            return self.inner.evaluate(x, theta, out);
        }
        let key = Self::key(x, theta);
        let hit = self.memo.read().ok().and_then(|m| m.get(&key).cloned());
        if let Some(v) = hit
            && v.len() == out.len()
        {
            out.copy_from_slice(&v);
            return Ok(());
        }
        self.inner.evaluate(x, theta, out)?;
        self.remember(key, out);
        Ok(())
    }
}
