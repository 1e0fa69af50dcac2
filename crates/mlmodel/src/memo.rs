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
    store: Store,
}

/// Values remembered by the exact bits of their inputs; cleared (logged at `info` with
/// `what`) when it holds `capacity` entries, and a pass-through at `capacity = 0`. The memos
/// of this crate share it.
#[derive(Debug)]
pub(crate) struct Store {
    map: RwLock<HashMap<Vec<u64>, Arc<[f64]>>>,
    capacity: usize,
    what: &'static str,
}

impl Store {
    pub(crate) fn new(capacity: usize, what: &'static str) -> Self {
        Self {
            map: RwLock::new(HashMap::new()),
            capacity,
            what,
        }
    }

    pub(crate) fn capacity(&self) -> usize {
        self.capacity
    }

    pub(crate) fn len(&self) -> usize {
        self.map.read().map_or(0, |m| m.len())
    }

    /// The key of `(x, θ)`: the exact bits of both.
    pub(crate) fn key(x: &[f64], theta: &[f64]) -> Vec<u64> {
        x.iter().chain(theta).map(|v| v.to_bits()).collect()
    }

    pub(crate) fn get(&self, key: &[u64]) -> Option<Arc<[f64]>> {
        self.map.read().ok().and_then(|m| m.get(key).cloned())
    }

    pub(crate) fn remember(&self, key: Vec<u64>, values: &[f64]) {
        if self.capacity == 0 {
            return;
        }
        if let Ok(mut m) = self.map.write() {
            if m.len() >= self.capacity {
                log::info!("{} full ({} entries): cleared", self.what, m.len());
                m.clear();
            }
            m.insert(key, Arc::from(values));
        }
    }
}

impl<U: UnobservableModel> Memo<U> {
    /// Wraps `inner`, remembering at most `capacity` evaluations (0: none).
    pub fn new(inner: U, capacity: usize) -> Self {
        Self {
            inner,
            store: Store::new(capacity, "model memo"),
        }
    }

    /// The wrapped model.
    pub fn inner(&self) -> &U {
        &self.inner
    }

    /// The largest number of remembered evaluations.
    pub fn capacity(&self) -> usize {
        self.store.capacity()
    }

    /// Number of remembered evaluations.
    pub fn len(&self) -> usize {
        self.store.len()
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
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
        if self.store.capacity() == 0 {
            return self.inner.evaluate(x, theta, out);
        }
        let key = Store::key(x, theta);
        if let Some(v) = self.store.get(&key)
            && v.len() == out.len()
        {
            out.copy_from_slice(&v);
            return Ok(());
        }
        self.inner.evaluate(x, theta, out)?;
        self.store.remember(key, out);
        Ok(())
    }
}

/// The rows `A g_u(x, θ)` and `b(x, θ)` of a multi-level model with a linear observable
/// model, remembered by the exact bits of `(x, θ)` (see
/// [`MultiLevelModel::model_row`](crate::MultiLevelModel::model_row)). A row holds `2 N_o`
/// values where the unobservable response it comes from holds `C N_u` (14 against 1018 for
/// the miter gate), so a calibration's repeated rows (the same experiments at the same `θ`
/// nodes in another coefficient mode, or predictions at support points met before) can be
/// kept for a few hundred bytes each. When it holds `capacity` rows it is cleared (logged at
/// `info`); `capacity = 0` (the default) remembers nothing.
///
/// The rows belong to the model they were computed with: a model whose `unobservable` or
/// `observable` field is replaced after rows were read must get a new memo
/// ([`with_row_memo`](crate::MultiLevelModel::with_row_memo)), or it would serve the old rows.
///
/// ```
/// use mlmodel::RowMemo;
/// let memo = RowMemo::new(1_000);
/// assert_eq!((memo.capacity(), memo.len(), memo.is_empty()), (1_000, 0, true));
/// // filled by `MultiLevelModel::model_row` (see its example)
/// ```
#[derive(Debug)]
pub struct RowMemo {
    store: Store,
}

impl Default for RowMemo {
    fn default() -> Self {
        Self::new(0)
    }
}

impl RowMemo {
    /// A memo of at most `capacity` rows (0: none).
    pub fn new(capacity: usize) -> Self {
        Self {
            store: Store::new(capacity, "model-row memo"),
        }
    }

    /// The largest number of remembered rows.
    pub fn capacity(&self) -> usize {
        self.store.capacity()
    }

    /// Number of remembered rows.
    pub fn len(&self) -> usize {
        self.store.len()
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The row `[A g; b]` at `(x, θ)`: remembered, or computed by `compute` (into a buffer
    /// of `len` values) and remembered.
    pub(crate) fn row(
        &self,
        x: &[f64],
        theta: &[f64],
        len: usize,
        compute: impl FnOnce(&mut [f64]) -> crate::Result<()>,
    ) -> crate::Result<Arc<[f64]>> {
        if self.capacity() == 0 {
            let mut out = vec![0.0; len];
            compute(&mut out)?;
            return Ok(Arc::from(out));
        }
        let key = Store::key(x, theta);
        if let Some(v) = self.store.get(&key)
            && v.len() == len
        {
            return Ok(v);
        }
        let mut out = vec![0.0; len];
        compute(&mut out)?;
        let row: Arc<[f64]> = Arc::from(out);
        self.store.remember(key, &row);
        Ok(row)
    }
}
