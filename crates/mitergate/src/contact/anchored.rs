//! Anchored warm starts: the contact solve at `(x, θ)` started from the solution at the
//! nearest point of a fixed `θ` lattice, so that a calibration's many gap values per water
//! level cost fewer active-set iterations, while each result stays a pure function of
//! `(x, θ)` (deterministic under any thread schedule and any memo state).
//!
//! A warm start from a neighbouring gap cuts the iterations of a solve roughly in half, but
//! starting from *whichever* solution was computed last would make a result depend on the
//! order of evaluation. Starting from a canonical anchor, itself a cold solve, keeps
//! `g_BC(x, θ)` a function: the same `(x, θ)` always meets the same start. The answer meets the
//! solver's convergence test either way, so it agrees with [`ContactModel::solve`] to the
//! solver tolerance (largest relative force difference measured on the default gate, 24-in
//! mesh, 1446 solves over six water levels and 241 gaps in 60-150 in: 8e-9), not bit for bit.
//!
//! Measured on that sweep (release build, one thread): cold solves 8.1 iterations and 254 µs
//! each; anchored at 5 in spacing, 4.2 iterations plus one cold anchor per 13 solves, 1.8x
//! faster over all. The criterion pair `contact/theta_sweep_241_cold` and
//! `contact/theta_sweep_241_anchored` (`cargo bench -p bamudi-benches -- theta_sweep`) measures
//! the ratio on the default 12-in gate.

use super::model::{ContactModel, ContactSolution};
use crate::error::GateError;
use std::collections::HashMap;
use std::sync::{Arc, RwLock};

/// Spacing of the anchor lattice (in of gap). Finer anchors give closer starts but more cold
/// anchor solves: on the sweep above, 1 in spacing took 1.35x the time of 5 in; 10 in 1.08x.
pub const ANCHOR_SPACING_IN: f64 = 5.0;

/// Memory budget of the anchor cache (bytes of stored forces); when full it is cleared, which
/// changes no result (anchors are recomputed identically). A close loop's record of 1440
/// hourly water levels under a 60-150 in gap prior meets about 27,000 anchors of about 9 kB
/// (24-in mesh); at the former 64 MB budget (7424 anchors) its loop cleared the cache 15
/// times and took 47.8 s instead of 41.5 s (thermal record of docs/closeloop.md, results
/// identical, peak memory 1.62 -> 1.81 GB).
const ANCHOR_CACHE_BYTES: usize = 512 << 20;

/// Cold solutions at anchor gaps, keyed by the exact bits of `(h_up, h_down, θ_anchor)`.
///
/// ```
/// use mitergate::contact::{AnchorCache, ContactParams};
/// let model = ContactParams::default().build(mitergate::testing::doc_gate()).unwrap();
/// let cache = AnchorCache::default();
/// let warm = cache.solve(&model, 700.0, 50.0, 101.3).unwrap(); // starts from θ = 100
/// let cold = model.solve(700.0, 50.0, 101.3).unwrap();
/// let peak = cold.forces.iter().fold(0.0f64, |m, v| m.max(v.abs()));
/// assert!(warm.forces.iter().zip(&cold.forces).all(|(w, c)| (w - c).abs() <= 1e-6 * peak));
/// assert_eq!(cache.len(), 1); // the anchor at 100 in is kept for the next gap near it
/// ```
#[derive(Debug, Default)]
pub struct AnchorCache {
    anchors: RwLock<HashMap<[u64; 3], Arc<ContactSolution>>>,
}

impl Clone for AnchorCache {
    /// A clone starts empty: the cache holds no state that changes a result.
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl AnchorCache {
    /// Number of anchor solutions held.
    pub fn len(&self) -> usize {
        self.anchors.read().map_or(0, |m| m.len())
    }

    /// Whether no anchor is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The contact solution at `(h_up, h_down, θ)`, warm-started from the cold solution at the
    /// anchor gap [`anchor_gap`] (at an anchor gap, that cold solution itself). If the warm
    /// solve fails to converge, the cold solve at `θ` is the documented recovery (logged at
    /// `debug`); its error, if any, is returned.
    pub fn solve(
        &self,
        model: &ContactModel,
        h_up: f64,
        h_down: f64,
        theta: f64,
    ) -> Result<ContactSolution, GateError> {
        let anchor = anchor_gap(theta, model.gate().quoin_height);
        let start = match self.anchor(model, h_up, h_down, anchor) {
            Ok(s) => s,
            Err(e) => {
                log::debug!("contact anchor at theta = {anchor} in failed ({e}); cold solve");
                return model.solve(h_up, h_down, theta);
            }
        };
        if anchor == theta {
            return Ok((*start).clone()); // an anchor gap is its own cold solve
        }
        model.solve_from(h_up, h_down, theta, &start).or_else(|e| {
            log::debug!(
                "warm contact solve at h_up = {h_up}, h_down = {h_down}, theta = {theta} \
                     failed ({e}); cold solve"
            );
            model.solve(h_up, h_down, theta)
        })
    }

    /// The cold solution at an anchor gap, from the cache or solved and remembered.
    fn anchor(
        &self,
        model: &ContactModel,
        h_up: f64,
        h_down: f64,
        anchor: f64,
    ) -> Result<Arc<ContactSolution>, GateError> {
        let key = [h_up.to_bits(), h_down.to_bits(), anchor.to_bits()];
        if let Some(s) = self.anchors.read().ok().and_then(|m| m.get(&key).cloned()) {
            return Ok(s);
        }
        let solution = Arc::new(model.solve(h_up, h_down, anchor)?);
        if let Ok(mut m) = self.anchors.write() {
            let per_entry = 8 * solution.forces.len().max(1) + 8 * solution.node_displacement.len();
            if m.len() * per_entry >= ANCHOR_CACHE_BYTES {
                log::debug!("contact anchor cache full ({} anchors): cleared", m.len());
                m.clear();
            }
            m.insert(key, Arc::clone(&solution));
        }
        Ok(solution)
    }
}

/// The anchor of gap `theta` (in): the nearest multiple of [`ANCHOR_SPACING_IN`], moved one
/// spacing down when that would reach the quoin height `height` (gaps live in `[0, height)`).
///
/// ```
/// use mitergate::contact::anchor_gap;
/// assert_eq!(anchor_gap(91.0, 762.0), 90.0);
/// assert_eq!(anchor_gap(93.0, 762.0), 95.0);
/// assert_eq!(anchor_gap(761.0, 762.0), 760.0);
/// assert_eq!(anchor_gap(759.0, 759.5), 755.0); // 760 would reach the quoin height
/// ```
pub fn anchor_gap(theta: f64, height: f64) -> f64 {
    let a = (theta / ANCHOR_SPACING_IN).round() * ANCHOR_SPACING_IN;
    if a >= height {
        (a - ANCHOR_SPACING_IN).max(0.0)
    } else {
        a.max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::ContactParams;

    /// The anchored solve is a function of its inputs: the same value whatever was solved
    /// before, and within the solver tolerance of the cold solve.
    #[test]
    fn anchored_solves_are_pure_and_agree_with_cold_solves() {
        let model = ContactParams::default()
            .build(crate::testing::doc_gate())
            .unwrap();
        let cache = AnchorCache::default();
        let first = cache.solve(&model, 700.0, 50.0, 101.3).unwrap();
        for theta in [97.0, 104.0, 100.0] {
            cache.solve(&model, 700.0, 50.0, theta).unwrap();
        }
        let again = cache.solve(&model, 700.0, 50.0, 101.3).unwrap();
        let fresh = AnchorCache::default()
            .solve(&model, 700.0, 50.0, 101.3)
            .unwrap();
        assert_eq!(first.forces, again.forces);
        assert_eq!(first.forces, fresh.forces);
        let cold = model.solve(700.0, 50.0, 101.3).unwrap();
        let scale = cold.forces.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (a, c) in first.forces.iter().zip(&cold.forces) {
            // 1e-6 of the peak line load: the solver's convergence test is relative, 1e-9 by
            // default on the tangential law; the normal loads agree to rounding once the
            // active sets match
            assert!((a - c).abs() <= 1e-6 * scale, "{a} vs {c}");
        }
    }
}
