//! Checking that posteriors are honest claims: the coverage of central credible intervals with
//! exact binomial intervals, the binomial acceptance region of a nominal level, and the
//! simulation-based-calibration (SBC) uniformity of the truth's posterior rank.
//!
//! Everything here works on the *probability integral transform* of each replicate,
//! `u = P(θ ≤ θ* | data)` ([`crate::ThetaPosterior::cdf`]): the limit of the SBC rank of `θ*`
//! among `L` posterior draws divided by `L` as `L` grows. When `θ*` is drawn from the prior and
//! the posterior is right, `u` is uniform on `[0, 1]`; the central `q` interval holds `θ*`
//! exactly when `|u − ½| ≤ q/2`.
//!
//! ```
//! use bamudi::validation::{Coverage, RankHistogram};
//! // twenty well-spread transforms: a calibrated posterior
//! let pits: Vec<f64> = (0..20).map(|i| (i as f64 + 0.5) / 20.0).collect();
//! let c = Coverage::from_pits(&pits, 0.9);
//! assert_eq!((c.hits, c.n), (18, 20));
//! let (lo, hi) = c.clopper_pearson(0.95).unwrap();
//! assert!(lo < 0.9 && 0.9 < hi);
//! let h = RankHistogram::new(&pits, 4).unwrap();
//! assert_eq!(h.counts, vec![5, 5, 5, 5]);
//! assert!(h.p_value > 0.99);
//! ```

use crate::error::{BamudiError, Result};
use serde::{Deserialize, Serialize};
use statrs::distribution::{Beta, Binomial, ChiSquared, ContinuousCDF, DiscreteCDF};

/// Whether the central credible interval of probability `level` holds the truth, given the
/// truth's probability integral transform `pit`.
pub fn central_interval_holds(pit: f64, level: f64) -> bool {
    (pit - 0.5).abs() <= 0.5 * level
}

/// How often central intervals of one nominal level held the truth.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Coverage {
    /// Nominal probability of the central interval.
    pub level: f64,
    /// Replicates whose interval held the truth.
    pub hits: usize,
    /// Replicates.
    pub n: usize,
}

impl Coverage {
    /// Counts the hits of the central `level` interval over replicates' transforms.
    pub fn from_pits(pits: &[f64], level: f64) -> Self {
        Self {
            level,
            hits: pits
                .iter()
                .filter(|u| central_interval_holds(**u, level))
                .count(),
            n: pits.len(),
        }
    }

    /// Empirical coverage `hits / n`.
    pub fn rate(&self) -> f64 {
        self.hits as f64 / self.n.max(1) as f64
    }

    /// The exact (Clopper-Pearson) interval of the true coverage with confidence `conf`.
    pub fn clopper_pearson(&self, conf: f64) -> Result<(f64, f64)> {
        let (k, n) = (self.hits as f64, self.n as f64);
        let tail = 0.5 * (1.0 - conf);
        let beta = |a: f64, b: f64| {
            Beta::new(a, b).map_err(|e| {
                BamudiError::config("coverage interval", format!("beta({a}, {b}): {e}"))
            })
        };
        let lo = match self.hits {
            0 => 0.0,
            _ => beta(k, n - k + 1.0)?.inverse_cdf(tail),
        };
        let hi = match self.hits == self.n {
            true => 1.0,
            false => beta(k + 1.0, n - k)?.inverse_cdf(1.0 - tail),
        };
        Ok((lo, hi))
    }

    /// Whether the hit count lies in the acceptance region of the nominal level
    /// ([`binomial_acceptance`] at significance `alpha`).
    pub fn accepts_nominal(&self, alpha: f64) -> Result<bool> {
        let (lo, hi) = binomial_acceptance(self.n, self.level, alpha)?;
        Ok((lo..=hi).contains(&self.hits))
    }
}

/// The two-sided acceptance region `[lo, hi]` of hit counts for `n` replicates whose true
/// coverage is `p`: `P(K < lo) ≤ α/2` and `P(K > hi) ≤ α/2` with `lo` largest and `hi`
/// smallest, `K ~ Binomial(n, p)`.
///
/// ```
/// // 40 replicates of a 95 % interval: 34 to 40 hits are consistent with it at 1 %
/// assert_eq!(bamudi::validation::binomial_acceptance(40, 0.95, 0.01).unwrap(), (34, 40));
/// ```
pub fn binomial_acceptance(n: usize, p: f64, alpha: f64) -> Result<(usize, usize)> {
    if !(0.0..=1.0).contains(&p) || !(0.0..1.0).contains(&alpha) {
        return Err(BamudiError::config(
            "binomial acceptance",
            format!("needs 0 <= p <= 1 and 0 <= alpha < 1, got p = {p}, alpha = {alpha}"),
        ));
    }
    let bin = Binomial::new(p, n as u64)
        .map_err(|e| BamudiError::config("binomial acceptance", e.to_string()))?;
    // P(K < lo) = cdf(lo − 1) ≤ α/2: the largest such lo
    let lo = (0..=n)
        .take_while(|&k| k == 0 || bin.cdf(k as u64 - 1) <= 0.5 * alpha)
        .last()
        .unwrap_or(0);
    // P(K > hi) = 1 − cdf(hi) ≤ α/2: the smallest such hi
    let hi = (0..=n)
        .find(|&k| bin.sf(k as u64) <= 0.5 * alpha)
        .unwrap_or(n);
    Ok((lo, hi))
}

/// The SBC rank histogram of replicates' transforms in equal bins, with Pearson's χ² test of
/// uniformity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RankHistogram {
    /// Replicates per bin, from `u = 0` to `u = 1`.
    pub counts: Vec<usize>,
    /// Pearson's statistic against equal expected counts.
    pub chi_square: f64,
    /// Its p-value (χ² with `bins − 1` degrees of freedom).
    pub p_value: f64,
}

impl RankHistogram {
    /// Bins `pits` (values in `[0, 1]`) into `bins ≥ 2` equal bins and tests uniformity.
    pub fn new(pits: &[f64], bins: usize) -> Result<Self> {
        if bins < 2 || pits.is_empty() {
            return Err(BamudiError::config(
                "rank histogram",
                format!(
                    "needs at least 2 bins and 1 replicate, got {bins} and {}",
                    pits.len()
                ),
            ));
        }
        if let Some(bad) = pits.iter().find(|u| !(0.0..=1.0).contains(*u)) {
            return Err(BamudiError::config(
                "rank histogram",
                format!("transform {bad} outside [0, 1]"),
            ));
        }
        let mut counts = vec![0usize; bins];
        for u in pits {
            counts[((u * bins as f64) as usize).min(bins - 1)] += 1;
        }
        let expected = pits.len() as f64 / bins as f64;
        let chi_square: f64 = counts
            .iter()
            .map(|c| (*c as f64 - expected).powi(2) / expected)
            .sum();
        let dist = ChiSquared::new((bins - 1) as f64)
            .map_err(|e| BamudiError::config("rank histogram", e.to_string()))?;
        Ok(Self {
            counts,
            chi_square,
            p_value: dist.sf(chi_square),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_acceptance_region_holds_its_probability_and_is_the_tightest() {
        for (n, p) in [(40, 0.95), (100, 0.5), (100, 0.95), (30, 0.8)] {
            let (lo, hi) = binomial_acceptance(n, p, 0.01).unwrap();
            let bin = Binomial::new(p, n as u64).unwrap();
            let below = if lo == 0 { 0.0 } else { bin.cdf(lo as u64 - 1) };
            assert!(below <= 0.005 && bin.sf(hi as u64) <= 0.005, "{n} {p}");
            // one step tighter on either side breaks the bound
            assert!(bin.cdf(lo as u64) > 0.005 || lo == n);
            assert!(hi == 0 || bin.sf(hi as u64 - 1) > 0.005);
        }
    }

    #[test]
    fn clopper_pearson_matches_known_values() {
        // 18/20 at 95 %: (0.6830, 0.9877) from the beta quantiles
        let (lo, hi) = Coverage {
            level: 0.9,
            hits: 18,
            n: 20,
        }
        .clopper_pearson(0.95)
        .unwrap();
        assert!(
            (lo - 0.6830).abs() < 1e-3 && (hi - 0.9877).abs() < 1e-3,
            "{lo} {hi}"
        );
        let all = Coverage {
            level: 0.9,
            hits: 20,
            n: 20,
        }
        .clopper_pearson(0.95)
        .unwrap();
        assert_eq!(all.1, 1.0);
    }

    #[test]
    fn a_skewed_rank_histogram_is_rejected() {
        // an over-confident posterior puts the truth in the outer bins
        let pits: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 0.01 } else { 0.99 })
            .collect();
        let h = RankHistogram::new(&pits, 10).unwrap();
        assert!(h.p_value < 1e-6);
        assert!(RankHistogram::new(&[1.5], 10).is_err());
    }
}
