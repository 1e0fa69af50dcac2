//! Rainflow cycle counting (ASTM E1049-85, §5.4.4, the "rainflow counting" of a history that
//! starts at its first sample), online.
//!
//! A fatigue damage sum needs the load history as cycles with a range each. A clean
//! fill-empty sequence is one cycle per lockage; a measured history is not clean (pool
//! fluctuations, partial fills, two vessels in quick succession), and rainflow counting is the
//! standard way to pair its reversals into cycles: a small excursion inside a large one is a
//! cycle of its own, the large one keeps its full range.
//!
//! [`Rainflow`] takes the history one sample at a time, keeps only the reversals not yet paired
//! (a stack whose length is bounded by the number of distinct nested excursions, not by the
//! history's length), and reports each cycle as soon as it closes. [`Rainflow::finish`] reports
//! the residue as half cycles, as E1049 counts a history's unclosed ranges. No Rust crate on
//! crates.io implemented it when this was written; it is short and checked below against the
//! worked example of E1049 (Fig. 6) and by property tests.
//!
//! ```
//! use numerics::rainflow::Rainflow;
//! let mut rf = Rainflow::new();
//! let mut cycles = vec![];
//! for x in [-2.0, 1.0, -3.0, 5.0, -1.0, 3.0, -4.0, 4.0, -2.0] {
//!     rf.push(x, |range, count| cycles.push((range, count)));
//! }
//! rf.finish(|range, count| cycles.push((range, count)));
//! let total: f64 = cycles.iter().map(|c| c.1).sum();
//! assert_eq!(total, 4.0); // (9 reversals − 1) / 2
//! ```

use std::collections::VecDeque;

/// The direction of the excursion in progress.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Direction {
    Unknown,
    Rising,
    Falling,
}

/// An online rainflow counter (see the module docs). Cycles are reported through a callback
/// `sink(range, count)` with `count` 1 for a full cycle and 0.5 for a half cycle.
#[derive(Debug, Clone)]
pub struct Rainflow {
    /// Reversals not yet paired, oldest first.
    stack: VecDeque<f64>,
    /// The last reversal found (the stack's end may have been consumed by a cycle).
    last_reversal: Option<f64>,
    /// The extreme of the excursion in progress, a reversal candidate.
    candidate: f64,
    direction: Direction,
}

impl Default for Rainflow {
    fn default() -> Self {
        Self::new()
    }
}

impl Rainflow {
    /// An empty counter.
    pub fn new() -> Self {
        Self {
            stack: VecDeque::new(),
            last_reversal: None,
            candidate: 0.0,
            direction: Direction::Unknown,
        }
    }

    /// Adds the next sample; reports every cycle it closes. Non-finite samples are the
    /// caller's to reject: they would poison the ranges.
    pub fn push(&mut self, x: f64, mut sink: impl FnMut(f64, f64)) {
        let Some(last) = self.last_reversal else {
            // the history's first sample counts as a reversal (E1049 §5.4.4.1)
            self.reversal(x, &mut sink);
            return;
        };
        match self.direction {
            Direction::Unknown if x != last => {
                self.direction = if x > last {
                    Direction::Rising
                } else {
                    Direction::Falling
                };
                self.candidate = x;
            }
            Direction::Rising if x >= self.candidate => self.candidate = x,
            Direction::Falling if x <= self.candidate => self.candidate = x,
            Direction::Rising | Direction::Falling => {
                let peak = self.candidate;
                self.reversal(peak, &mut sink);
                self.direction = if self.direction == Direction::Rising {
                    Direction::Falling
                } else {
                    Direction::Rising
                };
                self.candidate = x;
            }
            Direction::Unknown => {}
        }
    }

    /// Ends the history: the excursion in progress becomes the last reversal, and the ranges
    /// still unpaired are reported as half cycles. The counter is empty afterwards.
    pub fn finish(&mut self, mut sink: impl FnMut(f64, f64)) {
        if self.direction != Direction::Unknown {
            let end = self.candidate;
            self.reversal(end, &mut sink);
        }
        while self.stack.len() > 1 {
            if let (Some(a), Some(b)) = (self.stack.pop_front(), self.stack.front()) {
                sink((a - b).abs(), 0.5);
            }
        }
        *self = Self::new();
    }

    /// A new reversal: the E1049 rule on the stack's last three reversals.
    fn reversal(&mut self, r: f64, sink: &mut impl FnMut(f64, f64)) {
        self.last_reversal = Some(r);
        self.stack.push_back(r);
        while self.stack.len() >= 3 {
            let n = self.stack.len();
            let x = (self.stack[n - 1] - self.stack[n - 2]).abs();
            let y = (self.stack[n - 2] - self.stack[n - 3]).abs();
            if x < y {
                break;
            }
            if n == 3 {
                // Y contains the history's start: a half cycle, and the start is dropped
                sink(y, 0.5);
                self.stack.pop_front();
            } else {
                sink(y, 1.0);
                self.stack.remove(n - 2);
                self.stack.remove(n - 3);
            }
        }
    }
}

/// All cycles of a whole history, `(range, count)` in the order they close.
pub fn cycles(history: &[f64]) -> Vec<(f64, f64)> {
    let mut rf = Rainflow::new();
    let mut out = Vec::new();
    for &x in history {
        rf.push(x, |r, c| out.push((r, c)));
    }
    rf.finish(|r, c| out.push((r, c)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Cycles as a histogram `range → count` (ranges are exact integers in these tests).
    fn histogram(c: &[(f64, f64)]) -> Vec<(f64, f64)> {
        let mut h: Vec<(f64, f64)> = vec![];
        for &(r, n) in c {
            match h.iter_mut().find(|(hr, _)| *hr == r) {
                Some(e) => e.1 += n,
                None => h.push((r, n)),
            }
        }
        h.sort_by(|a, b| a.0.total_cmp(&b.0));
        h
    }

    #[test]
    fn the_worked_example_of_astm_e1049_is_counted_as_published() {
        // E1049-85 (2017) Fig. 6 / Table 4: ranges 3 (0.5), 4 (1.5), 6 (0.5), 8 (1.0), 9 (0.5)
        let h = [-2.0, 1.0, -3.0, 5.0, -1.0, 3.0, -4.0, 4.0, -2.0];
        assert_eq!(
            histogram(&cycles(&h)),
            vec![(3.0, 0.5), (4.0, 1.5), (6.0, 0.5), (8.0, 1.0), (9.0, 0.5)]
        );
    }

    #[test]
    fn samples_between_reversals_and_plateaus_do_not_change_the_count() {
        let h = [-2.0, 1.0, -3.0, 5.0, -1.0, 3.0, -4.0, 4.0, -2.0];
        // the same history sampled densely, with repeated values at the reversals
        let mut dense = vec![];
        for w in h.windows(2) {
            for k in 0..5 {
                dense.push(w[0] + (w[1] - w[0]) * k as f64 / 5.0);
            }
            dense.push(w[1]);
        }
        dense.push(-2.0);
        assert_eq!(histogram(&cycles(&dense)), histogram(&cycles(&h)));
    }

    #[test]
    fn a_constant_amplitude_history_is_one_cycle_per_repetition() {
        // open gate (0) → loaded (a) → open, 50 times: 49 full cycles of range a and two
        // half cycles (the first rise, the last fall) = 50 cycles
        let a = 7.5;
        let mut h = vec![0.0];
        for _ in 0..50 {
            h.extend([a, 0.0]);
        }
        let c = cycles(&h);
        assert!(c.iter().all(|(r, _)| *r == a));
        assert_eq!(c.iter().map(|(_, n)| n).sum::<f64>(), 50.0);
    }

    #[test]
    fn a_constant_history_has_no_cycles() {
        assert!(cycles(&[3.0; 10]).is_empty());
        assert!(cycles(&[]).is_empty());
        assert!(cycles(&[1.0]).is_empty());
    }

    fn reversals(h: &[f64]) -> usize {
        let mut v: Vec<f64> = vec![];
        for &x in h {
            if v.last() == Some(&x) {
                continue;
            }
            if v.len() >= 2 {
                let (a, b) = (v[v.len() - 2], v[v.len() - 1]);
                if (b - a) * (x - b) > 0.0 {
                    v.pop();
                }
            }
            v.push(x);
        }
        v.len()
    }

    proptest! {
        /// Every range between successive reversals is counted once: the counts add up to
        /// (reversals − 1) / 2; the largest range is the history's full span; scaling and
        /// shifting the history scale the ranges and keep the counts.
        #[test]
        fn counts_are_conserved_and_the_span_is_the_largest_range(
            h in prop::collection::vec((-50i32..50).prop_map(f64::from), 0..200),
            scale in 0.5f64..4.0,
            shift in -100.0f64..100.0,
        ) {
            let c = cycles(&h);
            let total: f64 = c.iter().map(|(_, n)| n).sum();
            let n_rev = reversals(&h);
            prop_assert_eq!(total, n_rev.saturating_sub(1) as f64 / 2.0);
            let span = h.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - h.iter().copied().fold(f64::INFINITY, f64::min);
            let largest = c.iter().map(|(r, _)| *r).fold(0.0, f64::max);
            if n_rev > 1 {
                prop_assert_eq!(largest, span);
            }
            let moved: Vec<f64> = h.iter().map(|x| x * scale + shift).collect();
            let c2 = cycles(&moved);
            prop_assert_eq!(c.len(), c2.len());
            for ((r1, n1), (r2, n2)) in c.iter().zip(&c2) {
                prop_assert!((r1 * scale - r2).abs() <= 1e-9 * (1.0 + r2.abs()));
                prop_assert_eq!(n1, n2);
            }
        }
    }
}
