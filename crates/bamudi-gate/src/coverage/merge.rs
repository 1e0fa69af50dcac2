//! Parts of one study, run separately (`first_replicate`) or stopped before the end (its
//! replicate log), merged into one report whose summaries are recomputed from every replicate.

use super::{CoverageOptions, CoverageReport, Replicate, summarise};
use crate::error::{GateAppError, Result};
use std::collections::BTreeMap;

/// One finished replicate of a study's log (`PATH.partial.jsonl`): its scenario and its result
/// per mode, in the study's mode order.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LoggedReplicate {
    /// Scenario number (1, 2).
    pub scenario: u8,
    /// One result per coefficient mode.
    pub modes: Vec<Replicate>,
}

/// The first line of a replicate log: the study's options.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LogHeader {
    /// The options of the study that wrote the log.
    pub options: CoverageOptions,
}

/// A study's replicate log as read back: its options (absent in logs written before they were
/// recorded) and its finished replicates.
#[derive(Debug, Clone)]
pub struct ReplicateLog {
    /// Where it was read from (for error messages).
    pub source: String,
    /// The study's options, from the log's first line.
    pub options: Option<CoverageOptions>,
    /// Finished replicates in the order they were written.
    pub replicates: Vec<LoggedReplicate>,
    /// Whether a last line that does not parse was left out: a study killed while writing.
    pub truncated: bool,
}

impl ReplicateLog {
    /// Parses a log's text; `source` names it in errors. A last line that does not parse is
    /// left out (and `truncated` set); any other bad line is an error naming its number.
    pub fn parse(text: &str, source: &str) -> Result<Self> {
        let lines: Vec<(usize, &str)> = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
            .collect();
        let mut log = Self {
            source: source.to_string(),
            options: None,
            replicates: Vec::new(),
            truncated: false,
        };
        for (k, &(i, line)) in lines.iter().enumerate() {
            if k == 0
                && let Ok(h) = serde_json::from_str::<LogHeader>(line)
            {
                log.options = Some(h.options);
                continue;
            }
            match serde_json::from_str::<LoggedReplicate>(line) {
                Ok(r) => log.replicates.push(r),
                Err(_) if k + 1 == lines.len() => log.truncated = true,
                Err(e) => {
                    return Err(GateAppError::Invalid(format!(
                        "{source} line {}: not a logged replicate ({e})",
                        i + 1
                    )));
                }
            }
        }
        Ok(log)
    }
}

/// Replicates per scenario, then per index, one slot per mode with the part it came from.
type Slots = BTreeMap<u8, BTreeMap<usize, Vec<Option<(Replicate, String)>>>>;

impl CoverageReport {
    /// Merges parts of one study: reports and replicate logs whose options equal the first
    /// report's but for the scenarios, the replicate range and the threads (a log without
    /// recorded options is read under the first report's). Every scenario and mode is
    /// summarised again from all its replicates, in index order; the wall time is the reports'
    /// sum. A replicate present twice, or missing a mode, is an error naming it and its parts.
    ///
    /// ```
    /// use bamudi_gate::coverage::{CoverageReport, LoggedReplicate, ReplicateLog};
    /// let report: CoverageReport = serde_json::from_str(&std::fs::read_to_string(
    ///     concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/results/coverage-quick.json"),
    /// ).unwrap()).unwrap();
    /// // a study split in two: its first 10 replicates' log, and the rest as a report
    /// let s = &report.scenarios[0];
    /// let replicates: Vec<LoggedReplicate> = s.replicates[..10]
    ///     .iter()
    ///     .map(|r| LoggedReplicate { scenario: 1, modes: vec![r.clone()] })
    ///     .collect();
    /// let log = ReplicateLog {
    ///     source: "head.partial.jsonl".into(),
    ///     options: Some(report.options.clone()),
    ///     replicates,
    ///     truncated: false,
    /// };
    /// let mut rest = report.clone();
    /// rest.scenarios.retain(|c| c.name == s.name && c.mode == s.mode);
    /// rest.scenarios[0].replicates.drain(..10);
    /// let merged = CoverageReport::merge(&[rest], vec![log]).unwrap();
    /// assert_eq!(merged.scenarios[0].n_replicates, s.n_replicates);
    /// assert_eq!(merged.scenarios[0].theta_coverage, s.theta_coverage);
    /// ```
    pub fn merge(parts: &[CoverageReport], logs: Vec<ReplicateLog>) -> Result<Self> {
        let first = parts.first().ok_or_else(|| {
            GateAppError::Option("coverage merge: at least one report (for the options)".into())
        })?;
        let modes = &first.options.modes;
        let n_parts = parts.len() + logs.len();
        let mut slots = Slots::new();
        for (p, part) in parts.iter().enumerate() {
            let source = format!("report {}", p + 1);
            same_study(&first.options, &part.options, &source)?;
            if (first.n_dofs, first.element_size) != (part.n_dofs, part.element_size) {
                return Err(not_a_part(&source, "its gate differs"));
            }
            for s in &part.scenarios {
                let number = scenario_number(&s.name)?;
                let m = modes
                    .iter()
                    .position(|&m| m == s.mode)
                    .ok_or_else(|| not_a_part(&source, &format!("it ran mode {:?}", s.mode)))?;
                for r in &s.replicates {
                    place(
                        &mut slots,
                        number,
                        (r.clone(), source.clone()),
                        m,
                        modes.len(),
                    )?;
                }
            }
        }
        for log in logs {
            if let Some(o) = &log.options {
                same_study(&first.options, o, &log.source)?;
            }
            for line in log.replicates {
                if line.modes.len() != modes.len() {
                    let what = format!("a replicate with {} modes", line.modes.len());
                    return Err(not_a_part(&log.source, &what));
                }
                for (m, r) in line.modes.into_iter().enumerate() {
                    let src = log.source.clone();
                    place(&mut slots, line.scenario, (r, src), m, modes.len())?;
                }
            }
        }
        first.resummarised(slots, parts.iter().map(|p| p.total_s).sum(), n_parts)
    }

    /// The merged report: the first part's options, every scenario summarised again.
    fn resummarised(&self, slots: Slots, total_s: f64, n_parts: usize) -> Result<Self> {
        let mut options = self.options.clone();
        options.scenarios = slots.keys().copied().collect();
        options.first_replicate = slots
            .values()
            .flat_map(|s| s.keys())
            .min()
            .copied()
            .unwrap_or(0);
        options.n_replicates = slots.values().map(BTreeMap::len).max().unwrap_or(0);
        let mut scenarios = Vec::new();
        for (&number, reps) in &slots {
            for (m, &mode) in self.options.modes.iter().enumerate() {
                let of_mode = reps
                    .iter()
                    .map(|(&index, per_mode)| {
                        per_mode[m].as_ref().map(|(r, _)| r.clone()).ok_or_else(|| {
                            GateAppError::Option(format!(
                                "coverage merge: scenario {number} replicate {index} lacks mode \
                                 {mode:?}"
                            ))
                        })
                    })
                    .collect::<Result<Vec<_>>>()?;
                scenarios.push(summarise(number, mode, &options, of_mode)?);
            }
        }
        Ok(Self {
            options,
            n_dofs: self.n_dofs,
            element_size: self.element_size,
            scenarios,
            total_s,
            merged_from: n_parts,
        })
    }
}

/// Puts a replicate of `scenario` in mode slot `m`; a second copy is an error naming both
/// parts.
fn place(
    slots: &mut Slots,
    scenario: u8,
    (r, source): (Replicate, String),
    m: usize,
    n_modes: usize,
) -> Result<()> {
    let index = r.index;
    let per_mode = slots
        .entry(scenario)
        .or_default()
        .entry(index)
        .or_insert_with(|| vec![None; n_modes]);
    if let Some((_, before)) = &per_mode[m] {
        return Err(GateAppError::Option(format!(
            "coverage merge: scenario {scenario} replicate {index} (mode {}) is in {before} \
             and again in {source}",
            m + 1
        )));
    }
    per_mode[m] = Some((r, source));
    Ok(())
}

/// `options` must be those of `first`'s study: equal but for the scenarios, the replicate
/// range and the threads.
fn same_study(first: &CoverageOptions, options: &CoverageOptions, source: &str) -> Result<()> {
    let key = |o: &CoverageOptions| {
        let mut o = o.clone();
        (o.scenarios, o.n_replicates, o.first_replicate, o.threads) = (vec![], 0, 0, 0);
        serde_json::to_value(o).map_err(|e| GateAppError::Serde {
            context: "coverage options".into(),
            reason: e.to_string(),
        })
    };
    if key(first)? != key(options)? {
        return Err(not_a_part(
            source,
            "its options differ beyond the scenarios, the replicate range and the threads",
        ));
    }
    Ok(())
}

fn not_a_part(source: &str, why: &str) -> GateAppError {
    GateAppError::Option(format!(
        "coverage merge: {source} is not a part of the first report's study: {why}"
    ))
}

/// `"scenario 2"` → 2.
fn scenario_number(name: &str) -> Result<u8> {
    name.strip_prefix("scenario ")
        .and_then(|n| n.parse().ok())
        .ok_or_else(|| {
            GateAppError::Option(format!(
                "coverage merge: a summary is named {name:?}, expected \"scenario N\""
            ))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A saved study (written before some summaries existed), its summaries recomputed from
    /// its replicates as the current version computes them.
    fn report() -> CoverageReport {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../docs/results/coverage.json"
        );
        let saved: CoverageReport =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let mut current = CoverageReport::merge(std::slice::from_ref(&saved), vec![]).unwrap();
        current.merged_from = saved.merged_from;
        current
    }

    /// The log text a study writes: its options, then one line per replicate.
    fn log_text(whole: &CoverageReport, reps: &[Replicate]) -> String {
        let mut text = serde_json::to_string(&LogHeader {
            options: whole.options.clone(),
        })
        .unwrap();
        for r in reps {
            let line = LoggedReplicate {
                scenario: 1,
                modes: vec![r.clone()],
            };
            text.push('\n');
            text.push_str(&serde_json::to_string(&line).unwrap());
        }
        text
    }

    /// A study split at an arbitrary replicate into a report and a log merges back into the
    /// study's own summaries, every number identical (the summaries are recomputed, so a
    /// merge that dropped, duplicated or re-ordered replicates would change them); a log cut
    /// in the middle of its last line loses that line only.
    #[test]
    fn a_split_study_merges_back_into_itself() {
        let whole = report();
        let s = &whole.scenarios[0];
        let cut = 37;
        let mut text = log_text(&whole, &s.replicates[cut..]);
        text.push_str("\n{\"scenario\":1,\"modes\":[{\"ind");
        let log = ReplicateLog::parse(&text, "tail.partial.jsonl").unwrap();
        assert!(log.truncated && log.options.is_some());
        let mut head = whole.clone();
        head.scenarios[0].replicates.truncate(cut);
        let merged = CoverageReport::merge(&[head], vec![log]).unwrap();
        let json = |c: &super::super::ScenarioCoverage| serde_json::to_value(c).unwrap();
        assert_eq!(json(&merged.scenarios[0]), json(s));
        assert_eq!(merged.options.n_replicates, s.n_replicates);
        assert_eq!(merged.merged_from, 2);
    }

    #[test]
    fn a_replicate_twice_a_foreign_study_or_a_bad_line_is_an_error() {
        let whole = report();
        let twice = CoverageReport::merge(&[whole.clone(), whole.clone()], vec![]);
        let msg = twice.unwrap_err().to_string();
        assert!(
            msg.contains("replicate 0") && msg.contains("report 1 and again in report 2"),
            "{msg}"
        );
        let mut other = whole.clone();
        other.options.n_experiments += 1;
        other.scenarios.clear();
        let msg = CoverageReport::merge(&[whole.clone(), other.clone()], vec![])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("report 2 is not a part"), "{msg}");
        // a log of another study is refused by its recorded options
        let text = log_text(&other, &whole.scenarios[0].replicates[..1]);
        let log = ReplicateLog::parse(&text, "other.partial.jsonl").unwrap();
        let mut head = whole.clone();
        head.scenarios[0].replicates.drain(..1);
        let msg = CoverageReport::merge(&[head], vec![log])
            .unwrap_err()
            .to_string();
        assert!(msg.contains("other.partial.jsonl is not a part"), "{msg}");
        // a bad line before the last is the parse's error, with its line number
        let text = format!("{}\nnot json\n{}", log_text(&whole, &[]), "{}");
        let msg = ReplicateLog::parse(&text, "x.jsonl")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("x.jsonl line 2"), "{msg}");
    }
}
