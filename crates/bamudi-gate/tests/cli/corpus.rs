//! The bad-input corpus of the `bamudi` binary: a table of cases, each a set of input files,
//! a command line and the words its error must contain, run against the real binary.
//!
//! Every case must end as a clean, named refusal:
//!
//! * a non-zero exit status (not a signal), within [`CASE_TIMEOUT`];
//! * no panic: stderr contains neither `panicked` nor `RUST_BACKTRACE`;
//! * no clap refusal of a well-formed argument (`unexpected argument`, `a value is required`):
//!   negative numbers must reach the validators;
//! * stderr names every culprit of the case (the flag, the TOML key, the file, `line N`, the
//!   column);
//! * cases marked [`Stage::BeforeGate`] run on the embedded default gate and must fail before
//!   any gate is built (stderr must not report a gate build, [`GATE_BUILT`]);
//! * nothing left behind and nothing changed: each case runs in its own fresh directory (the
//!   working directory, and every path of the case is relative to it); afterwards the
//!   directory holds exactly the entries the case created (a partial output, an empty
//!   results directory or a staging directory is a failure) and every input file is
//!   byte-identical (so a previous good result in `--out` survives a failed run).
//!
//! * the error line prints each cause once (no `(os error N)` twice, no piece repeated as in
//!   `--data X: X:`).
//!
//! A few inputs are right to accept with a named warning (a gap prior that excludes the
//! data): those cases ([`Expect::Warn`]) must exit 0, name their culprits on stderr, and
//! create nothing but their `--out` directory.
//!
//! All cases run (two at a time) before the single assertion, which lists every failing case
//! with its command line, what went wrong and an excerpt of stderr.
//!
//! Before the cases, one control run: `calibrate` on the uncorrupted base inputs (20
//! experiments computed in-process from the 60 in gate, the configuration [`CAL_TOML`]) must
//! succeed and report its gate build. That proves that the corrupted variants fail because of
//! their corruption (several data cases can only demand the file name), that the
//! before-the-gate check can see a gate build, and it provides the `calibration.json` and
//! `model.json` the `predict` cases corrupt.
use std::collections::BTreeSet;
use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use Stage::{BeforeGate, NeedsGate};

const BIN: &str = env!("CARGO_BIN_EXE_bamudi");

/// Bound on one case. A refused input fails at validation: before any gate build in
/// milliseconds, or, for the cases that need the gate, after building the 60 in gate (about a
/// second, a few seconds in a test build on a loaded machine) and reading a small file. 60 s
/// is more than ten times the slowest legitimate refusal, while a missed check shows up either
/// as a success (exit 0, outputs written) or as work on the 12 in default gate (a calibration
/// of minutes, a simulation of 500 experiments or months of field data) that runs into this
/// bound and is reported as a hang. The "huge" values of the corpus are chosen just past their
/// limits (`--n 1000001`, `--days 3651`, `--threads 1025`), not at 1e9, so that a missed check
/// costs time, never the memory of the machine.
const CASE_TIMEOUT: Duration = Duration::from_secs(60);

/// Bound on the control calibration (20 experiments, 49 grid points, 60 in gate: seconds to a
/// minute in a test build).
const FIXTURE_TIMEOUT: Duration = Duration::from_secs(900);

/// How often a running case is polled.
const POLL: Duration = Duration::from_millis(20);

/// Cases run concurrently (the binary itself uses every core when it computes).
const WORKERS: usize = 2;

/// The corpus must keep at least this many cases.
const MIN_CASES: usize = 110;

/// What `bamudi` prints on stderr when it has built the gate (`cli::build_contact`). The
/// control run checks that it is still printed; otherwise the before-the-gate check would be
/// blind.
const GATE_BUILT: &str = "built and condensed";

/// The global flags of a case that needs the gate: the coarse gate builds in about a second.
const COARSE: [&str; 2] = ["--element-size", "60"];

/// clap's words when it refuses an argument before any validator sees it. Every argument of
/// the corpus is well formed (negative numbers included), so these must never appear.
const CLAP_REFUSALS: [&str; 2] = ["unexpected argument", "a value is required"];

/// The gate's gauges (the default gate), in output order.
const GAUGES: [&str; 7] = ["SG1", "SG2", "SG3", "SG4", "SG5", "SG6", "SG7"];

/// Gap (in) of the base data.
const TRUE_GAP_IN: f64 = 90.0;

/// Rows of the base experiments and of the base field record.
const EXPERIMENT_ROWS: usize = 20;
const RECORD_ROWS: usize = 48;

/// Rows of the long base record (a week hourly): the fewest the close loop runs on (its
/// calibration, validation and test windows need 30 rows each at the default fractions), for
/// the cases that must run the loop to its end.
const LONG_RECORD_ROWS: usize = 168;

/// A valid `calibrate` configuration (the round trip's: exact linear estimator, 49 grid points).
const CAL_TOML: &str = "gap_prior = [81.0, 105.0]\n[calibration]\ntheta_grid_points = 49\n\
                        gp_restarts = 1\n[calibration.estimator]\nkind = \"exact_linear\"\n";

/// The valid first line of the `calibrate` configurations of the corpus.
const PRIOR: &str = "gap_prior = [81.0, 105.0]\n";

/// Stand-ins for the results of an earlier good run, placed in `--out` before a failing run.
const PREVIOUS_CALIBRATION: &str = "{\"previous\": \"calibration.json of an earlier good run\"}\n";
const PREVIOUS_MODEL: &str = "{\"previous\": \"model.json of an earlier good run\"}\n";
const PREVIOUS_REPORT: &str = "# close-loop report of an earlier good run\n";

/// Where a case must fail.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// At argument, option or file validation, before any gate is built: the case runs on the
    /// embedded default gate and stderr must not report a gate build.
    BeforeGate,
    /// Only once the gate exists (data against the gate's gauges and domain, destinations
    /// checked after the build): the case runs with `--element-size 60`.
    NeedsGate,
}

/// How a case must end.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    /// A refusal: non-zero exit, nothing left behind.
    Refuse,
    /// Accepted with a named warning: exit 0; only `out` (a directory of the case) is created.
    Warn {
        /// The output directory the run may create.
        out: &'static str,
    },
}

/// One bad input.
struct Case {
    /// Unique; says what is wrong (the case's directory is numbered, so that the name cannot
    /// leak into stderr through a path and satisfy a culprit).
    name: String,
    stage: Stage,
    /// Inputs, by path relative to the case directory; a path ending in `/` is an empty
    /// directory.
    files: Vec<(String, Vec<u8>)>,
    /// Arguments after `bamudi` (before [`COARSE`] is added for [`Stage::NeedsGate`]).
    args: Vec<String>,
    /// Substrings stderr must contain.
    culprits: Vec<String>,
    /// Symbolic links to create: `(path, target)`, both relative to the case directory.
    links: Vec<(String, String)>,
    expect: Expect,
}

impl Case {
    fn new(name: &str, stage: Stage, args: &[&str], culprits: &[&str]) -> Self {
        Self {
            name: name.to_string(),
            stage,
            files: Vec::new(),
            args: args.iter().map(|s| s.to_string()).collect(),
            culprits: culprits.iter().map(|s| s.to_string()).collect(),
            links: Vec::new(),
            expect: Expect::Refuse,
        }
    }

    /// A symbolic link `path` -> `target` (a case on a platform without them is skipped).
    fn link(mut self, path: &str, target: &str) -> Self {
        self.links.push((path.to_string(), target.to_string()));
        self
    }

    /// The input is right to accept with a warning; the run writes `out`.
    fn warns(mut self, out: &'static str) -> Self {
        self.expect = Expect::Warn { out };
        self
    }

    fn file(mut self, path: &str, contents: impl AsRef<[u8]>) -> Self {
        self.files
            .push((path.to_string(), contents.as_ref().to_vec()));
        self
    }

    fn dir(mut self, path: &str) -> Self {
        self.files
            .push((format!("{}/", path.trim_end_matches('/')), Vec::new()));
        self
    }

    /// The full argument list.
    fn command_line(&self) -> Vec<String> {
        let prefix: &[&str] = match self.stage {
            BeforeGate => &[],
            NeedsGate => &COARSE,
        };
        prefix
            .iter()
            .map(|s| s.to_string())
            .chain(self.args.iter().cloned())
            .collect()
    }
}

/// `a` followed by `b`.
fn cat<'a>(a: &[&'a str], b: &[&'a str]) -> Vec<&'a str> {
    a.iter().chain(b).copied().collect()
}

// ---------------------------------------------------------------------------------------------
// Base inputs: valid documents the cases corrupt
// ---------------------------------------------------------------------------------------------

/// The valid base inputs.
struct Base {
    /// 20 experiments: `h_up` in [400, 700] in, `h_down` in [50, 200] in, 20 distinct pairs,
    /// the strains of the 60 in gate at a 90 in gap plus a deterministic ±1 microstrain.
    exps: String,
    /// 48 hourly rows: `time` (ISO 8601), `h_up`, `h_down`, `air_temp_f`, the gauges.
    record: String,
    /// The same layout over [`LONG_RECORD_ROWS`] hourly rows.
    long_record: String,
    /// The default gate TOML with 60 in elements.
    gate_toml: String,
}

/// A deterministic stand-in for gauge noise, in [-1, 1) microstrain.
fn jitter(i: usize, k: usize) -> f64 {
    let h = (i as u64 * 2_654_435_761 + k as u64 * 40_503 + 12_345) % 2_000;
    h as f64 / 1_000.0 - 1.0
}

impl Base {
    fn generate() -> Self {
        let mut cfg = mitergate::GateConfig::default();
        cfg.mesh.element_size = 60.0;
        let (contact, _) = mitergate::build_contact(&cfg).expect("the 60 in default gate builds");
        assert!(
            contact
                .gate()
                .gauge_names
                .iter()
                .map(String::as_str)
                .eq(GAUGES),
            "the corpus assumes the default gate's gauges {GAUGES:?}, got {:?}",
            contact.gate().gauge_names
        );
        let strains = |h_up: f64, h_down: f64, salt: usize| -> Vec<f64> {
            let sol = contact
                .solve(h_up, h_down, TRUE_GAP_IN)
                .unwrap_or_else(|e| panic!("contact solve at {h_up}, {h_down}: {e}"));
            let eps = contact.gate().strain(&sol.forces, h_up, h_down);
            eps.iter()
                .enumerate()
                .map(|(k, s)| s + jitter(salt, k))
                .collect()
        };
        let cells = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.4}"))
                .collect::<Vec<_>>()
                .join(",")
        };

        let mut exps = format!("h_up,h_down,{}\n", GAUGES.join(","));
        for i in 0..EXPERIMENT_ROWS {
            // 7 and 13 are coprime with 20: both levels run through 20 distinct values
            let h_up = 400.0 + 300.0 * ((7 * i) % 20) as f64 / 19.0;
            let h_down = 50.0 + 150.0 * ((13 * i) % 20) as f64 / 19.0;
            exps += &format!(
                "{},{}\n",
                cells(&[h_up, h_down]),
                cells(&strains(h_up, h_down, i))
            );
        }

        let record_of = |rows: usize| {
            let mut record = format!("time,h_up,h_down,air_temp_f,{}\n", GAUGES.join(","));
            for i in 0..rows {
                let t = i as f64;
                let h_up = 600.0 + 100.0 * (0.4 * t).sin();
                let h_down = 120.0 + 60.0 * (0.3 * t).cos();
                let air = 50.0 + 10.0 * (2.0 * std::f64::consts::PI * t / 24.0).sin();
                record += &format!(
                    "2024-01-{:02}T{:02}:00:00Z,{},{}\n",
                    1 + i / 24,
                    i % 24,
                    cells(&[h_up, h_down, air]),
                    cells(&strains(h_up, h_down, 100 + i))
                );
            }
            record
        };
        let record = record_of(RECORD_ROWS);
        let long_record = record_of(LONG_RECORD_ROWS);

        // the base documents are what the cases assume they are
        let table = bamudi::data::Table::parse(&exps, "exps.csv").expect("base experiments");
        let e = bamudi::Experiments::from_table(&table, &["h_up", "h_down"], &GAUGES)
            .expect("base experiments");
        assert_eq!(e.len(), EXPERIMENT_ROWS);
        let ingest = bamudi_closeloop::IngestConfig::new(&["h_up", "h_down"], &GAUGES);
        let rec = bamudi_closeloop::parse_csv(&record, "record.csv", &ingest).expect("base record");
        assert_eq!(rec.len(), RECORD_ROWS);
        Self {
            exps,
            record,
            long_record,
            gate_toml: replace_once(
                mitergate::gate::DEFAULT_GATE_TOML,
                "element_size = 12.0",
                "element_size = 60.0",
            ),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Text surgery (the base CSVs have no quotes; `line` is the file line, the header is line 1)
// ---------------------------------------------------------------------------------------------

/// `text` with its single occurrence of `from` replaced: a base document that changed under
/// the corpus stops the test instead of silently making a case valid.
fn replace_once(text: &str, from: &str, to: &str) -> String {
    assert_eq!(
        text.matches(from).count(),
        1,
        "corpus construction: `{from}` must occur exactly once in the base document"
    );
    text.replacen(from, to, 1)
}

fn column_index(csv: &str, column: &str) -> usize {
    let header = csv.lines().next().unwrap_or("");
    header
        .split(',')
        .position(|h| h == column)
        .unwrap_or_else(|| panic!("corpus construction: no column `{column}` in `{header}`"))
}

fn join_lines(lines: &[String]) -> String {
    let mut s = lines.join("\n");
    s.push('\n');
    s
}

/// `csv` with file line `line` replaced by `f(line text)`.
fn map_line(csv: &str, line: usize, f: impl FnOnce(&str) -> String) -> String {
    let mut lines: Vec<String> = csv.lines().map(str::to_string).collect();
    assert!(
        (1..=lines.len()).contains(&line),
        "corpus construction: no line {line}"
    );
    let new = f(&lines[line - 1]);
    lines[line - 1] = new;
    join_lines(&lines)
}

/// `csv` with the cell of `column` on file line `line` set to `value`.
fn set_cell(csv: &str, line: usize, column: &str, value: &str) -> String {
    let c = column_index(csv, column);
    map_line(csv, line, |l| {
        let mut cells: Vec<&str> = l.split(',').collect();
        cells[c] = value;
        cells.join(",")
    })
}

/// `csv` with `column` set to `value` in every data row.
fn set_column(csv: &str, column: &str, value: &str) -> String {
    let c = column_index(csv, column);
    let lines: Vec<String> = csv
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return l.to_string();
            }
            let mut cells: Vec<&str> = l.split(',').collect();
            cells[c] = value;
            cells.join(",")
        })
        .collect();
    join_lines(&lines)
}

/// `csv` without `column`.
fn drop_column(csv: &str, column: &str) -> String {
    let c = column_index(csv, column);
    let lines: Vec<String> = csv
        .lines()
        .map(|l| {
            let mut cells: Vec<&str> = l.split(',').collect();
            cells.remove(c);
            cells.join(",")
        })
        .collect();
    join_lines(&lines)
}

/// The header and the first `rows` data rows.
fn head(csv: &str, rows: usize) -> String {
    let lines: Vec<String> = csv.lines().take(rows + 1).map(str::to_string).collect();
    join_lines(&lines)
}

/// The header and the first data row repeated `rows` times.
fn repeated_first_row(csv: &str, rows: usize) -> String {
    let mut lines = csv.lines();
    let header = lines.next().unwrap_or("").to_string();
    let first = lines.next().unwrap_or("").to_string();
    let mut all = vec![header];
    all.extend(std::iter::repeat_n(first, rows));
    join_lines(&all)
}

/// Every gauge cell set to its value in the first data row (the levels still vary).
fn constant_gauges(csv: &str) -> String {
    let first: Vec<String> = csv
        .lines()
        .nth(1)
        .unwrap_or("")
        .split(',')
        .map(str::to_string)
        .collect();
    let mut out = csv.to_string();
    for g in GAUGES {
        out = set_column(&out, g, &first[column_index(csv, g)]);
    }
    out
}

/// `csv` with CRLF line ends (a file saved on Windows).
fn crlf(csv: &str) -> String {
    csv.lines().map(|l| format!("{l}\r\n")).collect()
}

/// `csv` with the gate open in every row (`h_down` set to `h_up`: no head, no quoin force).
fn gate_open_everywhere(csv: &str) -> String {
    let (up, down) = (column_index(csv, "h_up"), column_index(csv, "h_down"));
    let lines: Vec<String> = csv
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let mut cells: Vec<String> = l.split(',').map(str::to_string).collect();
            if i > 0 {
                cells[down] = cells[up].clone();
            }
            cells.join(",")
        })
        .collect();
    join_lines(&lines)
}

/// The first two cells of file line `line` with their commas (`a,b,`): an anchor for
/// [`with_latin1_byte`] that puts the byte at the start of the line's third cell.
fn two_cells(csv: &str, line: usize) -> String {
    let l = csv
        .lines()
        .nth(line - 1)
        .expect("corpus construction: a line");
    let cells: Vec<&str> = l.splitn(3, ',').collect();
    format!("{},{},", cells[0], cells[1])
}

/// UTF-16 little endian with its byte-order mark (what spreadsheets call "Unicode text").
fn utf16le(text: &str) -> Vec<u8> {
    let mut bytes = vec![0xFF, 0xFE];
    for unit in text.encode_utf16() {
        bytes.extend_from_slice(&unit.to_le_bytes());
    }
    bytes
}

/// `text` with the byte 0xB5 (Latin-1 `µ`, invalid UTF-8) after the first `after`.
fn with_latin1_byte(text: &str, after: &str) -> Vec<u8> {
    let at = text.find(after).expect("corpus construction: anchor") + after.len();
    let mut bytes = text.as_bytes().to_vec();
    bytes.insert(at, 0xB5);
    bytes
}

/// The first half of `bytes` (a file cut off mid-write).
fn truncated(bytes: &[u8]) -> Vec<u8> {
    bytes[..bytes.len() / 2].to_vec()
}

/// A JSON document with the value at `path` replaced.
fn json_with(bytes: &[u8], path: &[&str], value: serde_json::Value) -> Vec<u8> {
    let mut doc: serde_json::Value =
        serde_json::from_slice(bytes).expect("the control run's JSON parses");
    let mut at = &mut doc;
    for key in path {
        at = at.get_mut(*key).unwrap_or_else(|| {
            panic!(
                "the control run's JSON has no `{}`: update the corpus",
                path.join(".")
            )
        });
    }
    *at = value;
    serde_json::to_vec(&doc).expect("JSON serialises")
}

// ---------------------------------------------------------------------------------------------
// The corpus, grouped by input kind
// ---------------------------------------------------------------------------------------------

fn corpus(base: &Base, fixture: Option<&Fixture>) -> Vec<Case> {
    let mut cases = Vec::new();
    cases.extend(global_flags(base));
    cases.extend(simulate_experiments_flags());
    cases.extend(simulate_field_flags());
    cases.extend(calibrate_config_files(base));
    cases.extend(calibrate_data_files(base));
    cases.extend(gate_files(base));
    cases.extend(close_loop_flags(base));
    cases.extend(close_loop_config_files(base));
    cases.extend(close_loop_tolerance_files(base));
    cases.extend(close_loop_records(base));
    cases.extend(reality_files());
    cases.extend(prior_excludes_the_data(base));
    cases.extend(output_paths(base));
    if let Some(fx) = fixture {
        cases.extend(predict_inputs(base, fx));
    }
    cases
}

/// Global flags (`--threads`, `--element-size`, `--seed`), on the cheapest command.
fn global_flags(base: &Base) -> Vec<Case> {
    const SIM: [&str; 8] = [
        "simulate",
        "experiments",
        "--scenario",
        "1",
        "--n",
        "5",
        "--out",
        "x.csv",
    ];
    let sim = |name: &str, flag: &str, value: &str, culprits: &[&str]| {
        Case::new(
            &format!("global_{name}"),
            BeforeGate,
            &cat(&SIM, &[flag, value]),
            culprits,
        )
    };
    vec![
        sim("threads_zero", "--threads", "0", &["--threads", "1024"]),
        sim(
            "threads_above_limit",
            "--threads",
            "1025",
            &["--threads", "1024"],
        ),
        sim("threads_negative", "--threads", "-1", &["--threads"]),
        sim("threads_text", "--threads", "two", &["--threads"]),
        sim(
            "element_size_zero",
            "--element-size",
            "0",
            &["--element-size"],
        ),
        sim(
            "element_size_negative",
            "--element-size",
            "-12",
            &["--element-size"],
        ),
        sim(
            "element_size_nan",
            "--element-size",
            "NaN",
            &["--element-size"],
        ),
        sim(
            "element_size_inf",
            "--element-size",
            "inf",
            &["--element-size"],
        ),
        // positive and finite, but below the gate's own minimum (quoin height / 2000)
        sim(
            "element_size_below_gate_minimum",
            "--element-size",
            "0.1",
            &["--element-size"],
        ),
        sim("seed_negative", "--seed", "-1", &["--seed"]),
        sim(
            "seed_overflow",
            "--seed",
            "18446744073709551616",
            &["--seed"],
        ),
        Case::new(
            "global_element_size_zero_calibrate",
            BeforeGate,
            &[
                "calibrate",
                "--config",
                "cal.toml",
                "--data",
                "exps.csv",
                "--out",
                "out",
                "--element-size",
                "0",
            ],
            &["--element-size"],
        )
        .file("cal.toml", CAL_TOML)
        .file("exps.csv", &base.exps),
        Case::new(
            "global_threads_zero_calibrate",
            BeforeGate,
            &[
                "--threads",
                "0",
                "calibrate",
                "--config",
                "cal.toml",
                "--data",
                "exps.csv",
                "--out",
                "out",
            ],
            &["--threads"],
        )
        .file("cal.toml", CAL_TOML)
        .file("exps.csv", &base.exps),
        Case::new(
            "global_element_size_nan_close_loop",
            BeforeGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--out",
                "loop",
                "--element-size",
                "NaN",
            ],
            &["--element-size"],
        )
        .file("record.csv", &base.record),
    ]
}

/// `simulate experiments`: `--n` in [1, 1000000], `--noise-sd` finite >= 0, `--scenario` 1|2.
fn simulate_experiments_flags() -> Vec<Case> {
    let sim = |name: &str, args: &[&str], culprits: &[&str]| {
        Case::new(
            &format!("simulate_experiments_{name}"),
            BeforeGate,
            &cat(&["simulate", "experiments", "--out", "x.csv"], args),
            culprits,
        )
    };
    vec![
        sim(
            "n_zero",
            &["--scenario", "1", "--n", "0"],
            &["--n", "1000000"],
        ),
        sim(
            "n_above_limit",
            &["--scenario", "1", "--n", "1000001"],
            &["--n", "1000000"],
        ),
        sim("n_negative", &["--scenario", "1", "--n", "-1"], &["--n"]),
        sim(
            "n_overflow",
            &["--scenario", "1", "--n", "18446744073709551616"],
            &["--n"],
        ),
        sim(
            "noise_sd_negative",
            &["--scenario", "1", "--n", "5", "--noise-sd", "-1"],
            &["--noise-sd"],
        ),
        sim(
            "noise_sd_nan",
            &["--scenario", "1", "--n", "5", "--noise-sd", "NaN"],
            &["--noise-sd"],
        ),
        sim(
            "noise_sd_inf",
            &["--scenario", "1", "--n", "5", "--noise-sd", "inf"],
            &["--noise-sd"],
        ),
        sim(
            "scenario_zero",
            &["--scenario", "0", "--n", "5"],
            &["--scenario"],
        ),
        sim(
            "scenario_three",
            &["--scenario", "3", "--n", "5"],
            &["--scenario"],
        ),
        sim(
            "scenario_negative",
            &["--scenario", "-1", "--n", "5"],
            &["--scenario"],
        ),
        sim(
            "scenario_overflow",
            &["--scenario", "256", "--n", "5"],
            &["--scenario"],
        ),
    ]
}

/// `simulate field`: `--days` in (0, 3650], `--step-minutes` in [1, 1440], `--missing` in
/// [0, 1), `--gap` / `--final-gap` finite > 0, `--noise-sd` finite >= 0, known effects.
fn simulate_field_flags() -> Vec<Case> {
    let field = |name: &str, args: &[&str], culprits: &[&str]| {
        Case::new(
            &format!("simulate_field_{name}"),
            BeforeGate,
            &cat(&["simulate", "field", "--out", "record.csv"], args),
            culprits,
        )
    };
    let days = &["--days", "2"];
    vec![
        field("days_zero", &["--days", "0"], &["--days", "3650"]),
        field("days_negative", &["--days", "-1"], &["--days", "3650"]),
        field("days_nan", &["--days", "NaN"], &["--days"]),
        field("days_inf", &["--days", "inf"], &["--days"]),
        field("days_above_limit", &["--days", "3651"], &["--days", "3650"]),
        field(
            "step_zero",
            &cat(days, &["--step-minutes", "0"]),
            &["--step-minutes", "1440"],
        ),
        field(
            "step_below_one_minute",
            &cat(days, &["--step-minutes", "0.5"]),
            &["--step-minutes", "1440"],
        ),
        field(
            "step_above_limit",
            &cat(days, &["--step-minutes", "1441"]),
            &["--step-minutes", "1440"],
        ),
        field(
            "step_negative",
            &cat(days, &["--step-minutes", "-5"]),
            &["--step-minutes", "1440"],
        ),
        field(
            "step_nan",
            &cat(days, &["--step-minutes", "NaN"]),
            &["--step-minutes"],
        ),
        // each flag within its limits, together ten years of minutes (5.3 million rows)
        field(
            "too_many_rows",
            &["--days", "3650", "--step-minutes", "1"],
            &["--days", "--step-minutes"],
        ),
        field(
            "missing_one",
            &cat(days, &["--missing", "1"]),
            &["--missing"],
        ),
        field(
            "missing_above_one",
            &cat(days, &["--missing", "1.5"]),
            &["--missing"],
        ),
        field(
            "missing_negative",
            &cat(days, &["--missing", "-0.1"]),
            &["--missing"],
        ),
        field(
            "missing_nan",
            &cat(days, &["--missing", "NaN"]),
            &["--missing"],
        ),
        field("gap_zero", &cat(days, &["--gap", "0"]), &["--gap"]),
        field("gap_negative", &cat(days, &["--gap", "-10"]), &["--gap"]),
        field("gap_nan", &cat(days, &["--gap", "NaN"]), &["--gap"]),
        field("gap_inf", &cat(days, &["--gap", "inf"]), &["--gap"]),
        field(
            "final_gap_zero",
            &cat(days, &["--effect", "gap-growth", "--final-gap", "0"]),
            &["--final-gap"],
        ),
        field(
            "final_gap_negative",
            &cat(days, &["--effect", "gap-growth", "--final-gap", "-1"]),
            &["--final-gap"],
        ),
        field(
            "final_gap_nan",
            &cat(days, &["--effect", "gap-growth", "--final-gap", "NaN"]),
            &["--final-gap"],
        ),
        field(
            "final_gap_inf",
            &cat(days, &["--effect", "gap-growth", "--final-gap", "inf"]),
            &["--final-gap"],
        ),
        field(
            "noise_sd_negative",
            &cat(days, &["--noise-sd", "-1"]),
            &["--noise-sd"],
        ),
        field(
            "noise_sd_nan",
            &cat(days, &["--noise-sd", "NaN"]),
            &["--noise-sd"],
        ),
        field(
            "effect_unknown",
            &cat(days, &["--effect", "rain"]),
            &["rain", "thermal"],
        ),
        // contradictions: `none` with an effect, an effect twice, a final gap nothing uses
        field(
            "effect_none_with_another",
            &cat(days, &["--effect", "none,thermal"]),
            &["--effect", "`none`"],
        ),
        field(
            "effect_named_twice",
            &cat(days, &["--effect", "thermal,drift,thermal"]),
            &["--effect", "`thermal`", "twice"],
        ),
        field(
            "effect_empty_name",
            &cat(days, &["--effect", "thermal,"]),
            &["--effect", "empty"],
        ),
        field(
            "final_gap_without_gap_growth",
            &cat(days, &["--effect", "thermal", "--final-gap", "120"]),
            &["--final-gap", "gap-growth"],
        ),
    ]
}

/// The `calibrate --config` file: syntax, types, unknown keys, `gap_prior`,
/// `discrepancy_terms`, and every checked `[calibration]` key with its limits
/// (`bamudi::params::limits`). The file is `config.toml` in every case (a neutral name, so
/// that it cannot satisfy a key culprit); the data are the valid base experiments.
fn calibrate_config_files(base: &Base) -> Vec<Case> {
    let args = [
        "calibrate",
        "--config",
        "config.toml",
        "--data",
        "exps.csv",
        "--out",
        "out",
    ];
    let cfg = |name: &str, toml: &str, culprits: &[&str]| {
        Case::new(
            &format!("calibrate_config_{name}"),
            BeforeGate,
            &args,
            &cat(&["config.toml"], culprits),
        )
        .file("config.toml", toml)
        .file("exps.csv", &base.exps)
    };
    let cal = |name: &str, table: &str, culprits: &[&str]| {
        cfg(name, &format!("{PRIOR}[calibration]\n{table}"), culprits)
    };
    vec![
        // gap_prior
        cfg(
            "prior_reversed",
            "gap_prior = [105.0, 81.0]\n",
            &["gap_prior"],
        ),
        cfg("prior_equal", "gap_prior = [90.0, 90.0]\n", &["gap_prior"]),
        cfg(
            "prior_three_numbers",
            "gap_prior = [81.0, 90.0, 105.0]\n",
            &["gap_prior"],
        ),
        cfg("prior_one_number", "gap_prior = [81.0]\n", &["gap_prior"]),
        cfg(
            "prior_missing",
            "[calibration]\ntheta_grid_points = 49\n",
            &["gap_prior"],
        ),
        cfg(
            "prior_strings",
            "gap_prior = [\"81\", \"105\"]\n",
            &["gap_prior"],
        ),
        cfg("prior_scalar", "gap_prior = 90.0\n", &["gap_prior"]),
        cfg(
            "prior_negative",
            "gap_prior = [-10.0, 50.0]\n",
            &["gap_prior"],
        ),
        cfg("prior_nan", "gap_prior = [nan, 105.0]\n", &["gap_prior"]),
        cfg("prior_inf", "gap_prior = [81.0, inf]\n", &["gap_prior"]),
        cfg(
            "prior_duplicate_key",
            "gap_prior = [81.0, 105.0]\ngap_prior = [81.0, 105.0]\n",
            &["gap_prior"],
        ),
        // [[tolerances]]: a relative sd in (0, 0.5], a numeric gate field, the marginal mode
        cfg(
            "tolerance_sd_zero",
            &format!("{PRIOR}[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.0\n"),
            &["tolerances[0].relative_sd"],
        ),
        cfg(
            "tolerance_sd_above_half",
            &format!("{PRIOR}[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.9\n"),
            &["tolerances[0].relative_sd", "(0, 0.5]"],
        ),
        cfg(
            "tolerance_unknown_key",
            &format!("{PRIOR}[[tolerances]]\nkey = \"skin_plate.colour\"\nrelative_sd = 0.03\n"),
            &["tolerances[0].key", "skin_plate.colour"],
        ),
        cfg(
            "tolerance_key_not_a_number",
            &format!("{PRIOR}[[tolerances]]\nkey = \"gauges\"\nrelative_sd = 0.03\n"),
            &["tolerances[0].key", "not a number"],
        ),
        cfg(
            "tolerance_declared_twice",
            &format!(
                "{PRIOR}[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.03\n[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.02\n"
            ),
            &["tolerances[1].key", "twice"],
        ),
        cfg(
            "tolerance_unknown_field",
            &format!(
                "{PRIOR}[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.03\nunit = \"in\"\n"
            ),
            &["unit"],
        ),
        cfg(
            "tolerance_outside_the_marginal_mode",
            &format!(
                "{PRIOR}[calibration]\ncoefficients = \"conditional_on_theta\"\n[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.03\n"
            ),
            &["tolerances", "marginal"],
        ),
        // the marginal mode's own section beside another mode, even at its defaults
        cfg(
            "marginal_section_outside_the_marginal_mode",
            &format!(
                "{PRIOR}[calibration]\ncoefficients = \"prior_marginal\"\n[calibration.marginal]\nlevel_variance = 0\n"
            ),
            &["marginal", "prior_marginal"],
        ),
        // discrepancy_terms, each in [1, 20]
        cfg(
            "terms_zero",
            &format!("{PRIOR}discrepancy_terms = [0, 6]\n"),
            &["discrepancy_terms", "[1, 20]"],
        ),
        cfg(
            "terms_above_limit",
            &format!("{PRIOR}discrepancy_terms = [6, 21]\n"),
            &["discrepancy_terms", "[1, 20]"],
        ),
        cfg(
            "terms_one_number",
            &format!("{PRIOR}discrepancy_terms = [6]\n"),
            &["discrepancy_terms"],
        ),
        cfg(
            "terms_negative",
            &format!("{PRIOR}discrepancy_terms = [-1, 6]\n"),
            &["discrepancy_terms"],
        ),
        cfg(
            "terms_fractional",
            &format!("{PRIOR}discrepancy_terms = [6.5, 6]\n"),
            &["discrepancy_terms"],
        ),
        // unknown keys (typos that are not substrings of a valid key, so that the list of
        // expected keys in the message cannot satisfy the culprit)
        cfg(
            "unknown_top_level_key",
            &format!("{PRIOR}colour = 3\n"),
            &["colour"],
        ),
        cal(
            "unknown_calibration_key",
            "theta_gird_points = 49\n",
            &["theta_gird_points"],
        ),
        cfg(
            "unknown_table",
            &format!("{PRIOR}[calibraton]\ntheta_grid_points = 49\n"),
            &["calibraton"],
        ),
        // [calibration] sizes: limits of bamudi::params::limits, named with their range
        cal(
            "theta_grid_points_zero",
            "theta_grid_points = 0\n",
            &["theta_grid_points", "[3, 100000]"],
        ),
        cal(
            "theta_grid_points_above_limit",
            "theta_grid_points = 100001\n",
            &["theta_grid_points", "[3, 100000]"],
        ),
        cal(
            "theta_grid_points_negative",
            "theta_grid_points = -5\n",
            &["theta_grid_points"],
        ),
        cal(
            "theta_grid_points_string",
            "theta_grid_points = \"many\"\n",
            &["theta_grid_points"],
        ),
        cal(
            "theta_grid_points_fractional",
            "theta_grid_points = 49.5\n",
            &["theta_grid_points"],
        ),
        cal(
            "gp_restarts_above_limit",
            "gp_restarts = 1001\n",
            &["gp_restarts", "[0, 1000]"],
        ),
        cal(
            "training_size_below_limit",
            "training_size = 5\n",
            &["training_size", "[10, 5000000]"],
        ),
        cal(
            "training_size_above_limit",
            "training_size = 5000001\n",
            &["training_size", "[10, 5000000]"],
        ),
        cal("threads_zero", "threads = 0\n", &["threads", "[1, 1024]"]),
        cal(
            "threads_above_limit",
            "threads = 1025\n",
            &["threads", "[1, 1024]"],
        ),
        cal(
            "rho_points_one",
            "[calibration.rho]\npoints = 1\n",
            &["rho.points", "[3, 100000]"],
        ),
        cal(
            "rho_reversed",
            "[calibration.rho]\nlo = 1.0\nhi = 0.5\n",
            &["rho"],
        ),
        cal(
            "marginalisation_order_zero",
            "[calibration.marginalisation]\nmethod = \"quadrature\"\norder = 0\n",
            &["marginalisation.order", "[1, 100000]"],
        ),
        cal(
            "marginalisation_unknown_method",
            "[calibration.marginalisation]\nmethod = \"simpson\"\norder = 5\n",
            &["simpson"],
        ),
        cal(
            "mcmc_one_chain",
            "[calibration.mcmc]\nchains = 1\n",
            &["mcmc.chains", "[2, 256]"],
        ),
        cal(
            "mcmc_too_few_samples",
            "[calibration.mcmc]\nsamples = 5\n",
            &["mcmc.samples", "[10, 10000000]"],
        ),
        // sigma_eps > 0
        cal("sigma_eps_negative", "sigma_eps = -1.0\n", &["sigma_eps"]),
        cal("sigma_eps_zero", "sigma_eps = 0.0\n", &["sigma_eps"]),
        cal("sigma_eps_nan", "sigma_eps = nan\n", &["sigma_eps"]),
        cal("sigma_eps_inf", "sigma_eps = inf\n", &["sigma_eps"]),
        cal("seed_negative", "seed = -1\n", &["seed"]),
        cal(
            "coefficients_unknown",
            "coefficients = \"bogus\"\n",
            &["bogus"],
        ),
        // the estimator
        cal(
            "estimator_unknown_kind",
            "[calibration.estimator]\nkind = \"svm\"\n",
            &["svm"],
        ),
        cal(
            "estimator_ridge_negative_lambda",
            "[calibration.estimator]\nkind = \"ridge\"\nlambda = -1.0\n",
            &["estimator.lambda"],
        ),
        cal(
            "estimator_lstm_no_hidden_units",
            "[calibration.estimator]\nkind = \"lstm\"\nhidden = 0\n",
            &["estimator"],
        ),
        // the sampling rule
        cal(
            "sampling_rho_range_reversed",
            "[calibration.sampling]\nrho_range = [1.0, 0.0]\n",
            &["sampling.rho_range"],
        ),
        cal(
            "sampling_alpha_scale_zero",
            "[calibration.sampling]\nalpha_scale = 0.0\n",
            &["sampling.alpha_scale"],
        ),
        cal(
            "sampling_draws_per_x_zero",
            "[calibration.sampling]\ndraws_per_x = 0\n",
            &["sampling.draws_per_x"],
        ),
        cal(
            "sampling_noise_sd_negative",
            "[calibration.sampling]\nnoise_sd = -1.0\n",
            &["sampling.noise_sd"],
        ),
        cal(
            "sampling_x_bounds_reversed",
            "[calibration.sampling]\nx_bounds = [[700.0, 400.0], [50.0, 200.0]]\n",
            &["sampling.x_bounds"],
        ),
        // the file itself
        cfg(
            "syntax_unterminated_array",
            "gap_prior = [81.0, 105.0\n",
            &[],
        ),
        cfg("syntax_missing_value", "gap_prior =\n", &[]),
        cfg("empty_file", "", &["gap_prior"]),
        Case::new(
            "calibrate_config_invalid_utf8",
            BeforeGate,
            &args,
            &["config.toml"],
        )
        .file(
            "config.toml",
            with_latin1_byte(&format!("{PRIOR}# gauges in µstrain\n"), "# gauges in "),
        )
        .file("exps.csv", &base.exps),
        Case::new(
            "calibrate_config_missing",
            BeforeGate,
            &[
                "calibrate",
                "--config",
                "nope.toml",
                "--data",
                "exps.csv",
                "--out",
                "out",
            ],
            &["nope.toml"],
        )
        .file("exps.csv", &base.exps),
        Case::new(
            "calibrate_config_is_a_directory",
            BeforeGate,
            &[
                "calibrate",
                "--config",
                "confdir",
                "--data",
                "exps.csv",
                "--out",
                "out",
            ],
            &["confdir"],
        )
        .dir("confdir")
        .file("exps.csv", &base.exps),
        // within the file's syntax, outside the model: the gap must be below the quoin
        // height (762 in), which the gate knows
        Case::new(
            "calibrate_config_prior_outside_the_gate",
            NeedsGate,
            &args,
            &["gap_prior"],
        )
        .file("config.toml", "gap_prior = [81.0, 800.0]\n")
        .file("exps.csv", &base.exps),
    ]
}

/// The `calibrate --data` CSV: the file (encoding, delimiter, shape, header), its cells, the
/// rows against the gate's domain, and data that cannot inform a calibration. The file is
/// `data.csv` in every case; the configuration is [`CAL_TOML`].
fn calibrate_data_files(base: &Base) -> Vec<Case> {
    let data = |name: &str, csv: &dyn AsRef<[u8]>, culprits: &[&str]| {
        Case::new(
            &format!("calibrate_data_{name}"),
            NeedsGate,
            &[
                "calibrate",
                "--config",
                "cal.toml",
                "--data",
                "data.csv",
                "--out",
                "out",
            ],
            &cat(&["data.csv"], culprits),
        )
        .file("cal.toml", CAL_TOML)
        .file("data.csv", AsRef::<[u8]>::as_ref(csv))
    };
    let e = base.exps.as_str();
    vec![
        // the file
        data("empty_file", &"", &[]),
        data("header_only", &head(e, 0), &[]),
        data("utf16", &utf16le(e), &[]),
        data(
            "invalid_utf8",
            &with_latin1_byte(e, "SG1"),
            &["line 1", "UTF-8"],
        ),
        data(
            "invalid_utf8_in_a_row",
            &with_latin1_byte(e, &two_cells(e, 5)),
            &["line 5", "`SG1`", "UTF-8"],
        ),
        // Windows line ends: the lines named are still the file's
        data(
            "crlf_text_cell",
            &crlf(&set_cell(e, 4, "SG2", "abc")),
            &["line 4", "`SG2`"],
        ),
        data("semicolon_delimiter", &e.replace(',', ";"), &["`h_up`"]),
        data("tab_delimiter", &e.replace(',', "\t"), &["`h_up`"]),
        data(
            "short_row",
            &map_line(e, 4, |l| l.rsplit_once(',').map_or(l, |p| p.0).to_string()),
            &["line 4"],
        ),
        data(
            "long_row",
            &map_line(e, 4, |l| format!("{l},1.0")),
            &["line 4"],
        ),
        data(
            "unterminated_quote",
            &set_cell(e, 4, "SG1", "\"12.5"),
            &["line 4"],
        ),
        // the header
        data(
            "duplicate_column",
            &set_cell(e, 1, "SG4", "SG3"),
            &["line 1", "`SG3`"],
        ),
        data("missing_gauge_column", &drop_column(e, "SG5"), &["`SG5`"]),
        data(
            "missing_level_column",
            &drop_column(e, "h_down"),
            &["`h_down`"],
        ),
        data("unnamed_column", &set_cell(e, 1, "SG7", ""), &["line 1"]),
        // one cell
        data(
            "text_cell",
            &set_cell(e, 3, "SG3", "abc"),
            &["line 3", "`SG3`"],
        ),
        data(
            "empty_cell",
            &set_cell(e, 5, "SG1", ""),
            &["line 5", "`SG1`"],
        ),
        data(
            "infinite_cell",
            &set_cell(e, 4, "SG3", "inf"),
            &["line 4", "`SG3`"],
        ),
        data(
            "negative_infinite_cell",
            &set_cell(e, 6, "SG2", "-inf"),
            &["line 6", "`SG2`"],
        ),
        data(
            "nan_level",
            &set_cell(e, 3, "h_up", "NaN"),
            &["line 3", "`h_up`"],
        ),
        data(
            "overflowing_cell",
            &set_cell(e, 6, "SG7", "1e400"),
            &["line 6", "`SG7`"],
        ),
        // finite, but more than any strain gauge reports (10 % strain)
        data(
            "absurd_gauge_reading",
            &set_cell(e, 6, "SG3", "1e300"),
            &["line 6", "`SG3`", "100000"],
        ),
        data(
            "absurd_negative_gauge_reading",
            &set_cell(e, 9, "SG5", "-250000"),
            &["line 9", "`SG5`", "100000"],
        ),
        // rows outside the gate's domain (24 <= h_down <= h_up <= 744 in)
        data(
            "h_down_above_h_up",
            &set_cell(&set_cell(e, 5, "h_up", "100"), 5, "h_down", "200"),
            &["line 5"],
        ),
        data(
            "h_up_above_domain",
            &set_cell(e, 7, "h_up", "800"),
            &["line 7"],
        ),
        data(
            "h_down_below_domain",
            &set_cell(e, 8, "h_down", "10"),
            &["line 8"],
        ),
        data(
            "negative_level",
            &set_cell(e, 9, "h_down", "-50"),
            &["line 9"],
        ),
        data(
            "zero_heads",
            &set_cell(&set_cell(e, 2, "h_up", "0"), 2, "h_down", "0"),
            &["line 2"],
        ),
        // data that cannot inform a calibration
        data("one_row", &head(e, 1), &[]),
        data(
            "duplicate_rows_only",
            &repeated_first_row(e, EXPERIMENT_ROWS),
            &[],
        ),
        data("constant_gauges", &constant_gauges(e), &["constant"]),
        // the file is not there, or is a directory
        Case::new(
            "calibrate_data_missing",
            BeforeGate,
            &[
                "calibrate",
                "--config",
                "cal.toml",
                "--data",
                "nope.csv",
                "--out",
                "out",
            ],
            &["nope.csv"],
        )
        .file("cal.toml", CAL_TOML),
        Case::new(
            "calibrate_data_is_a_directory",
            NeedsGate,
            &[
                "calibrate",
                "--config",
                "cal.toml",
                "--data",
                "datadir",
                "--out",
                "out",
            ],
            &["datadir"],
        )
        .file("cal.toml", CAL_TOML)
        .dir("datadir"),
    ]
}

/// Gate TOML (`--gate`): syntax, missing and unknown keys, wrong types, every kind of bad
/// value, duplicate gauge names. The file is `gate.toml` (the default gate with 60 in
/// elements, then corrupted), on `simulate experiments` unless said otherwise.
fn gate_files(base: &Base) -> Vec<Case> {
    let sim = [
        "simulate",
        "experiments",
        "--scenario",
        "1",
        "--n",
        "5",
        "--gate",
        "gate.toml",
        "--out",
        "x.csv",
    ];
    let gate = |name: &str, toml: &str, culprits: &[&str]| {
        Case::new(
            &format!("gate_{name}"),
            BeforeGate,
            &sim,
            &cat(&["gate.toml"], culprits),
        )
        .file("gate.toml", toml)
    };
    let g = base.gate_toml.as_str();
    let edit = |from: &str, to: &str| replace_once(g, from, to);
    vec![
        gate("syntax_error", &format!("{g}\n[geometry\n"), &[]),
        gate("empty_file", "", &[]),
        gate(
            "only_one_section",
            "[mesh]\nelement_size = 60.0\ndrilling_penalty = 1.0e-3\n",
            &["geometry"],
        ),
        gate(
            "unknown_key",
            &edit("[skin_plate]\n", "[skin_plate]\ncolour = 3\n"),
            &["colour"],
        ),
        gate(
            "wrong_type",
            &edit("thickness = 0.625", "thickness = \"thick\""),
            &["thickness"],
        ),
        gate(
            "negative_thickness",
            &edit("thickness = 0.625", "thickness = -0.625"),
            &["skin_plate.thickness"],
        ),
        // the command line's limit of --element-size holds in the file too
        gate(
            "element_size_above_limit",
            &edit("element_size = 60.0", "element_size = 1e6"),
            &["mesh.element_size", "240"],
        ),
        gate(
            "zero_element_size",
            &edit("element_size = 60.0", "element_size = 0.0"),
            &["mesh.element_size"],
        ),
        gate(
            "negative_element_size",
            &edit("element_size = 60.0", "element_size = -60.0"),
            &["mesh.element_size"],
        ),
        gate(
            "element_size_below_minimum",
            &edit("element_size = 60.0", "element_size = 0.1"),
            &["mesh.element_size"],
        ),
        gate(
            "negative_leaf_length",
            &edit("leaf_length = 696.0", "leaf_length = -696.0"),
            &["geometry.leaf_length"],
        ),
        gate(
            "infinite_quoin_height",
            &edit("quoin_height = 762.0", "quoin_height = inf"),
            &["geometry.quoin_height"],
        ),
        gate(
            "negative_miter_angle",
            &edit("miter_angle_deg = 18.43", "miter_angle_deg = -18.43"),
            &["geometry.miter_angle_deg"],
        ),
        gate(
            "pivot_on_bearing_line",
            &edit("pivot_offset = 45.0", "pivot_offset = 30.0"),
            &["geometry.pivot_offset"],
        ),
        gate(
            "nan_modulus",
            &edit("youngs_modulus = 29.0e6", "youngs_modulus = nan"),
            &["material.youngs_modulus"],
        ),
        gate(
            "poisson_ratio_half",
            &edit("poisson_ratio = 0.3", "poisson_ratio = 0.5"),
            &["material.poisson_ratio"],
        ),
        gate(
            "zero_water_weight",
            &edit("unit_weight = 0.0361", "unit_weight = 0.0"),
            &["water.unit_weight"],
        ),
        gate(
            "girder_above_the_quoin",
            &edit("624.0, 744.0]", "624.0, 900.0]"),
            &["girders.heights"],
        ),
        gate(
            "no_girders",
            &edit(
                "heights = [18.0, 52.6, 89.0, 127.4, 168.4, 212.4, 260.2, 313.1, 384.0, 504.0, \
                 624.0, 744.0]",
                "heights = []",
            ),
            &["girders.heights"],
        ),
        gate(
            "diaphragm_outside_the_leaf",
            &edit(
                "positions = [174.0, 348.0, 522.0]",
                "positions = [174.0, 348.0, 900.0]",
            ),
            &["diaphragms.positions"],
        ),
        gate(
            "gauge_on_missing_girder",
            &edit("girder_web = 10,", "girder_web = 20,"),
            &["girder_web"],
        ),
        gate(
            "duplicate_gauge_names",
            &edit("name = \"SG4\"", "name = \"SG3\""),
            &["SG3"],
        ),
        gate(
            "empty_gauge_name",
            &edit("name = \"SG1\"", "name = \"\""),
            &["gauges[0].name"],
        ),
        gate(
            "zero_gauge_direction",
            &edit(
                "name = \"SG2\"",
                "name = \"SG2\"\ndirection = [0.0, 0.0, 0.0]",
            ),
            &["direction"],
        ),
        // a deck given where a gate TOML goes: the way to import it is named
        Case::new(
            "gate_deck_given_as_toml",
            BeforeGate,
            &cat(&sim[..6], &["--gate", "deck.inp", "--out", "x.csv"]),
            &["--gate", "deck.inp", "--gate-inp"],
        )
        .file(
            "deck.inp",
            "*HEADING\nexported gate\n*NODE\n1, 0.0, 0.0, 0.0\n",
        ),
        Case::new(
            "gate_missing",
            BeforeGate,
            &[
                "simulate",
                "experiments",
                "--scenario",
                "1",
                "--n",
                "5",
                "--gate",
                "nope_gate.toml",
                "--out",
                "x.csv",
            ],
            &["nope_gate.toml"],
        ),
        // the same checks on the other commands that read a gate
        Case::new(
            "gate_duplicate_gauge_names_calibrate",
            BeforeGate,
            &[
                "calibrate",
                "--gate",
                "gate.toml",
                "--config",
                "cal.toml",
                "--data",
                "exps.csv",
                "--out",
                "out",
            ],
            &["gate.toml", "SG3"],
        )
        .file("gate.toml", edit("name = \"SG4\"", "name = \"SG3\""))
        .file("cal.toml", CAL_TOML)
        .file("exps.csv", &base.exps),
        Case::new(
            "gate_negative_thickness_close_loop",
            BeforeGate,
            &[
                "close-loop",
                "--gate",
                "gate.toml",
                "--data",
                "record.csv",
                "--out",
                "loop",
            ],
            &["gate.toml", "skin_plate.thickness"],
        )
        .file("gate.toml", edit("thickness = 0.625", "thickness = -0.625"))
        .file("record.csv", &base.record),
    ]
}

/// `close-loop` flags: `--gap-prior` (two finite numbers, 0 <= lo < hi, inside the gate's
/// domain), `--holdout-fraction` in (0, 1), `--max-experiments` >= 10, `--gauge-noise-sd` > 0,
/// `--data`. The record is the valid base record.
fn close_loop_flags(base: &Base) -> Vec<Case> {
    let cl = |name: &str, flags: &[&str], culprits: &[&str]| {
        Case::new(
            &format!("close_loop_{name}"),
            BeforeGate,
            &cat(
                &["close-loop", "--data", "record.csv", "--out", "loop"],
                flags,
            ),
            culprits,
        )
        .file("record.csv", &base.record)
    };
    vec![
        cl(
            "gap_prior_one_number",
            &["--gap-prior", "60"],
            &["--gap-prior"],
        ),
        cl(
            "gap_prior_three_numbers",
            &["--gap-prior", "60,100,150"],
            &["--gap-prior"],
        ),
        cl(
            "gap_prior_reversed",
            &["--gap-prior", "150,60"],
            &["--gap-prior"],
        ),
        cl(
            "gap_prior_equal",
            &["--gap-prior", "60,60"],
            &["--gap-prior"],
        ),
        // `=` form: a list that starts with a minus sign is no plain negative number to clap
        cl(
            "gap_prior_negative",
            &["--gap-prior=-10,60"],
            &["--gap-prior"],
        ),
        cl(
            "gap_prior_nan",
            &["--gap-prior", "nan,60"],
            &["--gap-prior"],
        ),
        cl(
            "gap_prior_inf",
            &["--gap-prior", "60,inf"],
            &["--gap-prior"],
        ),
        cl("gap_prior_text", &["--gap-prior", "a,b"], &["--gap-prior"]),
        // the old two-value form: the flag and the `lo,hi` form are named, not a stray `50`
        cl(
            "gap_prior_two_values",
            &["--gap-prior", "100", "50"],
            &["--gap-prior", "lo,hi"],
        ),
        cl(
            "holdout_zero",
            &["--holdout-fraction", "0"],
            &["--holdout-fraction", "(0, 1)"],
        ),
        cl(
            "holdout_one",
            &["--holdout-fraction", "1"],
            &["--holdout-fraction", "(0, 1)"],
        ),
        cl(
            "holdout_above_one",
            &["--holdout-fraction", "1.2"],
            &["--holdout-fraction", "(0, 1)"],
        ),
        cl(
            "holdout_negative",
            &["--holdout-fraction", "-0.5"],
            &["--holdout-fraction", "(0, 1)"],
        ),
        cl(
            "holdout_nan",
            &["--holdout-fraction", "NaN"],
            &["--holdout-fraction"],
        ),
        cl(
            "max_experiments_zero",
            &["--max-experiments", "0"],
            &["--max-experiments", "10"],
        ),
        cl(
            "max_experiments_nine",
            &["--max-experiments", "9"],
            &["--max-experiments", "10"],
        ),
        cl(
            "max_experiments_negative",
            &["--max-experiments", "-5"],
            &["--max-experiments"],
        ),
        cl(
            "gauge_noise_zero",
            &["--gauge-noise-sd", "0"],
            &["--gauge-noise-sd"],
        ),
        cl(
            "gauge_noise_negative",
            &["--gauge-noise-sd", "-1"],
            &["--gauge-noise-sd"],
        ),
        cl(
            "gauge_noise_nan",
            &["--gauge-noise-sd", "NaN"],
            &["--gauge-noise-sd"],
        ),
        cl(
            "gauge_noise_inf",
            &["--gauge-noise-sd", "inf"],
            &["--gauge-noise-sd"],
        ),
        Case::new(
            "close_loop_data_missing",
            BeforeGate,
            &["close-loop", "--data", "nope.csv", "--out", "loop"],
            &["nope.csv"],
        ),
        // a symbolic-link loop and a broken link are named as such, not as a missing file
        Case::new(
            "close_loop_data_symlink_loop",
            BeforeGate,
            &["close-loop", "--data", "a.csv", "--out", "loop"],
            &["--data a.csv", "symbolic links"],
        )
        .link("a.csv", "b.csv")
        .link("b.csv", "a.csv"),
        Case::new(
            "close_loop_data_broken_symlink",
            BeforeGate,
            &["close-loop", "--data", "rec.csv", "--out", "loop"],
            &["--data rec.csv", "symbolic link", "gone.csv"],
        )
        .link("rec.csv", "gone.csv"),
        // a valid pair, but the gap must stay below the quoin (762 in), which the gate knows
        Case::new(
            "close_loop_gap_prior_outside_the_gate",
            NeedsGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--out",
                "loop",
                "--gap-prior",
                "60,800",
            ],
            &["--gap-prior"],
        )
        .file("record.csv", &base.record),
    ]
}

/// `close-loop --tolerances` (the declared build tolerances, `tol.toml`), checked before the
/// gate is built.
fn close_loop_tolerance_files(base: &Base) -> Vec<Case> {
    let tc = |name: &str, toml: &str, culprits: &[&str]| {
        Case::new(
            &format!("close_loop_tolerances_{name}"),
            BeforeGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--tolerances",
                "tol.toml",
                "--out",
                "loop",
            ],
            &cat(&["tol.toml"], culprits),
        )
        .file("tol.toml", toml)
        .file("record.csv", &base.record)
    };
    vec![
        tc(
            "unknown_key",
            "[[tolerances]]\nkey = \"skin_plate.colour\"\nrelative_sd = 0.03\n",
            &["tolerances[0].key", "skin_plate.colour"],
        ),
        tc(
            "sd_above_half",
            "[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.9\n",
            &["tolerances[0].relative_sd", "(0, 0.5]"],
        ),
        tc(
            "declared_twice",
            "[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.03\n\
             [[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.02\n",
            &["tolerances[1].key", "twice"],
        ),
        tc(
            "unknown_field",
            "[[tolerances]]\nkey = \"skin_plate.thickness\"\nrelative_sd = 0.03\nunit = \"in\"\n",
            &["unit"],
        ),
    ]
}

/// `close-loop --config` (the loop's settings, `loop.toml`) and `--calibration-config` (the
/// `[calibration]` keys, `settings.toml`).
fn close_loop_config_files(base: &Base) -> Vec<Case> {
    let lc = |name: &str, toml: &str, culprits: &[&str]| {
        Case::new(
            &format!("close_loop_config_{name}"),
            BeforeGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--config",
                "loop.toml",
                "--out",
                "loop",
            ],
            &cat(&["loop.toml"], culprits),
        )
        .file("loop.toml", toml)
        .file("record.csv", &base.record)
    };
    let cc = |name: &str, toml: &str, culprits: &[&str]| {
        Case::new(
            &format!("close_loop_calibration_config_{name}"),
            BeforeGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--calibration-config",
                "settings.toml",
                "--out",
                "loop",
            ],
            &cat(&["settings.toml"], culprits),
        )
        .file("settings.toml", toml)
        .file("record.csv", &base.record)
    };
    vec![
        lc(
            "fraction_above_one",
            "calibration_fraction = 1.5\n",
            &["calibration_fraction"],
        ),
        lc(
            "fraction_zero",
            "calibration_fraction = 0.0\n",
            &["calibration_fraction"],
        ),
        lc(
            "fraction_nan",
            "calibration_fraction = nan\n",
            &["calibration_fraction"],
        ),
        lc(
            "no_validation_window",
            "test_fraction = 0.45\n",
            &["test_fraction"],
        ),
        lc(
            "test_fraction_negative",
            "test_fraction = -0.1\n",
            &["test_fraction"],
        ),
        lc(
            "no_selection_origin",
            "selection_origins = 0\n",
            &["selection_origins"],
        ),
        lc(
            "significance_zero",
            "significance = 0.0\n",
            &["significance"],
        ),
        lc(
            "significance_one",
            "significance = 1.0\n",
            &["significance"],
        ),
        lc(
            "no_confirmation_candidates",
            "confirm_candidates = 0\n",
            &["confirm_candidates"],
        ),
        lc(
            "no_ljung_box_lags",
            "ljung_box_lags = 0\n",
            &["ljung_box_lags"],
        ),
        lc(
            "negative_improvement",
            "min_relative_improvement = -0.1\n",
            &["min_relative_improvement"],
        ),
        lc(
            "nan_improvement",
            "min_relative_improvement = nan\n",
            &["min_relative_improvement"],
        ),
        lc(
            "significance_level_too_loose",
            "improvement_significance = 0.2\n",
            &["improvement_significance", "0.05"],
        ),
        lc(
            "nan_significance_level",
            "improvement_significance = nan\n",
            &["improvement_significance"],
        ),
        lc(
            "negative_significant_improvement",
            "min_significant_improvement = -0.01\n",
            &["min_significant_improvement"],
        ),
        lc("negative_max_steps", "max_steps = -1\n", &["max_steps"]),
        lc("max_steps_string", "max_steps = \"four\"\n", &["max_steps"]),
        lc(
            "unknown_key",
            "calibration_fracton = 0.5\n",
            &["calibration_fracton"],
        ),
        lc("syntax_error", "calibration_fraction = \n", &[]),
        Case::new(
            "close_loop_config_missing",
            BeforeGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--config",
                "nope_loop.toml",
                "--out",
                "loop",
            ],
            &["nope_loop.toml"],
        )
        .file("record.csv", &base.record),
        cc(
            "training_size_zero",
            "training_size = 0\n",
            &["training_size", "[10, 5000000]"],
        ),
        cc(
            "unknown_key",
            "theta_gird_points = 49\n",
            &["theta_gird_points"],
        ),
        cc("syntax_error", "training_size = \n", &[]),
        cc("sigma_eps_negative", "sigma_eps = -1.0\n", &["sigma_eps"]),
        cc("threads_zero", "threads = 0\n", &["threads", "[1, 1024]"]),
        Case::new(
            "close_loop_calibration_config_missing",
            BeforeGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--calibration-config",
                "nope_settings.toml",
                "--out",
                "loop",
            ],
            &["nope_settings.toml"],
        )
        .file("record.csv", &base.record),
    ]
}

/// The `close-loop --data` record: `time` (present, parseable, strictly increasing), gauge
/// and level cells, covariates, the gate's domain, all values missing. The file is
/// `record.csv`.
fn close_loop_records(base: &Base) -> Vec<Case> {
    let rec = |name: &str, csv: &dyn AsRef<[u8]>, flags: &[&str], culprits: &[&str]| {
        Case::new(
            &format!("record_{name}"),
            NeedsGate,
            &cat(
                &["close-loop", "--data", "record.csv", "--out", "loop"],
                flags,
            ),
            &cat(&["record.csv"], culprits),
        )
        .file("record.csv", AsRef::<[u8]>::as_ref(csv))
    };
    let r = base.record.as_str();
    // the time of data row 4 (file line 5), to repeat on line 6
    let line5_time = r
        .lines()
        .nth(4)
        .and_then(|l| l.split(',').next())
        .unwrap_or("")
        .to_string();
    vec![
        rec("empty_file", &"", &[], &[]),
        rec("header_only", &head(r, 0), &[], &[]),
        rec("utf16", &utf16le(r), &[], &[]),
        rec("no_time_column", &drop_column(r, "time"), &[], &["`time`"]),
        rec(
            "time_repeated",
            &set_cell(r, 6, "time", &line5_time),
            &[],
            &["line 6", "`time`"],
        ),
        rec(
            "time_goes_back",
            &set_cell(r, 10, "time", "2024-01-01T01:00:00Z"),
            &[],
            &["line 10", "`time`"],
        ),
        rec(
            "time_not_a_time",
            &set_cell(r, 3, "time", "yesterday"),
            &[],
            &["line 3", "`time`"],
        ),
        rec(
            "gauge_text",
            &set_cell(r, 4, "SG2", "abc"),
            &[],
            &["line 4", "`SG2`"],
        ),
        rec(
            "gauge_infinite",
            &set_cell(r, 7, "SG5", "inf"),
            &[],
            &["line 7", "`SG5`"],
        ),
        rec(
            "level_nan",
            &set_cell(r, 3, "h_down", "NaN"),
            &[],
            &["line 3", "`h_down`"],
        ),
        // finite, but no gauge reads it, no thermometer shows it
        rec(
            "gauge_absurd_reading",
            &set_cell(r, 12, "SG4", "-2e5"),
            &[],
            &["line 12", "`SG4`", "100000"],
        ),
        rec(
            "gauge_1e300",
            &set_cell(r, 30, "SG2", "1e300"),
            &[],
            &["line 30", "`SG2`", "100000"],
        ),
        rec(
            "temperature_fault_code",
            &set_cell(r, 9, "air_temp_f", "-999"),
            &[],
            &["line 9", "`air_temp_f`", "degF"],
        ),
        // data that cannot inform a calibration, refused before the loop
        rec(
            "constant_gauges",
            &constant_gauges(r),
            &[],
            &["`SG1`", "constant"],
        ),
        rec(
            "gate_open_in_every_row",
            &gate_open_everywhere(r),
            &[],
            &["gate open", "`h_up`"],
        ),
        // encodings and line ends
        rec(
            "invalid_utf8",
            &with_latin1_byte(r, &two_cells(r, 5)),
            &[],
            &["line 5", "`h_down`", "UTF-8"],
        ),
        rec(
            "crlf_gauge_text",
            &crlf(&set_cell(r, 4, "SG2", "abc")),
            &[],
            &["line 4", "`SG2`"],
        ),
        rec(
            "covariate_text",
            &set_cell(r, 4, "air_temp_f", "warm"),
            &[],
            &["line 4", "`air_temp_f`"],
        ),
        rec(
            "h_down_above_h_up",
            &set_cell(&set_cell(r, 8, "h_up", "100"), 8, "h_down", "200"),
            &[],
            &["line 8"],
        ),
        rec(
            "h_up_above_domain",
            &set_cell(r, 9, "h_up", "800"),
            &[],
            &["line 9"],
        ),
        rec(
            "missing_gauge_column",
            &drop_column(r, "SG6"),
            &[],
            &["`SG6`"],
        ),
        rec(
            "short_row",
            &map_line(r, 5, |l| l.rsplit_once(',').map_or(l, |p| p.0).to_string()),
            &[],
            &["line 5"],
        ),
        rec(
            "duplicate_column",
            &set_cell(r, 1, "SG3", "SG2"),
            &[],
            &["line 1", "`SG2`"],
        ),
        // with the default policy every row is dropped; with --impute there is nothing to
        // interpolate from
        rec(
            "gauge_never_measured",
            &set_column(r, "SG1", ""),
            &[],
            &["`SG1`"],
        ),
        rec(
            "gauge_never_measured_impute",
            &set_column(r, "SG1", ""),
            &["--impute"],
            &["`SG1`"],
        ),
        Case::new(
            "record_is_a_directory",
            NeedsGate,
            &["close-loop", "--data", "recdir", "--out", "loop"],
            &["recdir"],
        )
        .dir("recdir"),
    ]
}

/// `simulate --reality` files (`reality.toml`): the limits of gauge readings and of the mesh
/// hold for what a reality declares, checked before any gate is built.
fn reality_files() -> Vec<Case> {
    let reality = |name: &str, toml: &str, culprits: &[&str]| {
        Case::new(
            &format!("reality_{name}"),
            BeforeGate,
            &[
                "simulate",
                "experiments",
                "--scenario",
                "1",
                "--n",
                "5",
                "--reality",
                "reality.toml",
                "--out",
                "x.csv",
            ],
            &cat(&["reality.toml"], culprits),
        )
        .file("reality.toml", toml)
    };
    vec![
        reality(
            "sensor_offset_absurd",
            "[[sensors]]\ngauge = \"SG2\"\noffset_microstrain = 1e300\n",
            &["offset_microstrain", "100000"],
        ),
        reality(
            "sensor_step_absurd",
            "[[sensors]]\ngauge = \"SG2\"\nstep = { at_fraction = 0.5, size_microstrain = -1e6 }\n",
            &["step.size_microstrain", "100000"],
        ),
        reality(
            "mesh_above_limit",
            "mesh_element_size_in = 1e6\n",
            &["mesh_element_size_in", "240"],
        ),
    ]
}

/// A gap prior that excludes the data (the base data's gap is 90 in): accepted, with the
/// warning that the posterior is pressed against the prior's upper bound and which way to
/// widen it, in `calibrate` and in `close-loop` (the loop's final calibration).
fn prior_excludes_the_data(base: &Base) -> Vec<Case> {
    let narrow = CAL_TOML.replace("gap_prior = [81.0, 105.0]", "gap_prior = [60.0, 80.0]");
    vec![
        Case::new(
            "calibrate_gap_prior_excludes_the_data",
            NeedsGate,
            &[
                "calibrate",
                "--config",
                "cal.toml",
                "--data",
                "data.csv",
                "--out",
                "out",
            ],
            &[
                "cal.toml",
                "`gap_prior`",
                "upper bound",
                "raise the upper bound above 80",
            ],
        )
        .file("cal.toml", narrow)
        .file("data.csv", &base.exps)
        .warns("out"),
        Case::new(
            "close_loop_gap_prior_excludes_the_data",
            NeedsGate,
            &[
                "close-loop",
                "--data",
                "record.csv",
                "--gap-prior",
                "60,80",
                "--max-experiments",
                "30",
                "--out",
                "loop",
            ],
            &[
                "--gap-prior 60,80",
                "upper bound",
                "raise the upper bound above 80",
            ],
        )
        .file("record.csv", &base.long_record)
        .warns("loop"),
    ]
}

/// Output destinations: an existing file, a non-empty directory without `--force`, a path
/// below a regular file; and previous good results that a failed run (with `--force`) must
/// leave byte-identical (the check is on every input of every case; these cases put a result
/// there).
fn output_paths(base: &Base) -> Vec<Case> {
    let calibrate = |data: &str, out: &str, force: bool| -> Vec<String> {
        let mut a: Vec<String> = [
            "calibrate",
            "--config",
            "cal.toml",
            "--data",
            data,
            "--out",
            out,
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        if force {
            a.push("--force".into());
        }
        a
    };
    let with_args = |name: &str, stage: Stage, args: Vec<String>, culprits: &[&str]| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        Case::new(name, stage, &refs, culprits)
    };
    let bad_record = set_cell(&base.record, 4, "SG2", "abc");
    vec![
        with_args(
            "output_calibrate_out_is_a_file",
            NeedsGate,
            calibrate("exps.csv", "results.txt", false),
            &["--out", "results.txt"],
        )
        .file("cal.toml", CAL_TOML)
        .file("exps.csv", &base.exps)
        .file("results.txt", "notes of an earlier run\n"),
        with_args(
            "output_calibrate_out_not_empty_without_force",
            BeforeGate,
            calibrate("exps.csv", "results", false),
            &["--out", "--force"],
        )
        .file("cal.toml", CAL_TOML)
        .file("exps.csv", &base.exps)
        .file("results/calibration.json", PREVIOUS_CALIBRATION)
        .file("results/model.json", PREVIOUS_MODEL),
        with_args(
            "output_calibrate_force_keeps_the_previous_result_on_bad_data",
            NeedsGate,
            calibrate("data.csv", "results", true),
            &["data.csv", "line 3", "`SG3`"],
        )
        .file("cal.toml", CAL_TOML)
        .file("data.csv", set_cell(&base.exps, 3, "SG3", "abc"))
        .file("results/calibration.json", PREVIOUS_CALIBRATION)
        .file("results/model.json", PREVIOUS_MODEL),
        with_args(
            "output_calibrate_force_keeps_the_previous_result_on_bad_domain",
            NeedsGate,
            calibrate("data.csv", "results", true),
            &["data.csv", "line 7"],
        )
        .file("cal.toml", CAL_TOML)
        .file("data.csv", set_cell(&base.exps, 7, "h_up", "800"))
        .file("results/calibration.json", PREVIOUS_CALIBRATION)
        .file("results/model.json", PREVIOUS_MODEL),
        Case::new(
            "output_calibrate_force_keeps_the_previous_result_on_bad_config",
            BeforeGate,
            &[
                "calibrate",
                "--config",
                "config.toml",
                "--data",
                "exps.csv",
                "--out",
                "results",
                "--force",
            ],
            &["config.toml", "gap_prior"],
        )
        .file("config.toml", "gap_prior = [105.0, 81.0]\n")
        .file("exps.csv", &base.exps)
        .file("results/calibration.json", PREVIOUS_CALIBRATION),
        with_args(
            "output_calibrate_out_below_a_file",
            NeedsGate,
            calibrate("exps.csv", "f.txt/results", false),
            &["--out"],
        )
        .file("cal.toml", CAL_TOML)
        .file("exps.csv", &base.exps)
        .file("f.txt", "a file, not a directory\n"),
        Case::new(
            "output_close_loop_out_is_a_file",
            NeedsGate,
            &["close-loop", "--data", "record.csv", "--out", "report.txt"],
            &["--out", "report.txt"],
        )
        .file("record.csv", &base.record)
        .file("report.txt", "notes of an earlier run\n"),
        Case::new(
            "output_close_loop_out_not_empty_without_force",
            BeforeGate,
            &["close-loop", "--data", "record.csv", "--out", "loop"],
            &["--out", "--force"],
        )
        .file("record.csv", &base.record)
        .file("loop/report.md", PREVIOUS_REPORT),
        Case::new(
            "output_close_loop_force_keeps_the_previous_report_on_bad_record",
            NeedsGate,
            &[
                "close-loop",
                "--data",
                "bad.csv",
                "--out",
                "loop",
                "--force",
            ],
            &["bad.csv", "line 4", "`SG2`"],
        )
        .file("bad.csv", &bad_record)
        .file("loop/report.md", PREVIOUS_REPORT),
        Case::new(
            "output_close_loop_out_below_a_file",
            NeedsGate,
            &["close-loop", "--data", "record.csv", "--out", "f.txt/loop"],
            &["--out"],
        )
        .file("record.csv", &base.record)
        .file("f.txt", "a file, not a directory\n"),
        Case::new(
            "output_simulate_experiments_out_below_a_file",
            NeedsGate,
            &[
                "simulate",
                "experiments",
                "--scenario",
                "1",
                "--n",
                "5",
                "--out",
                "f.txt/x.csv",
            ],
            &["--out"],
        )
        .file("f.txt", "a file, not a directory\n"),
        Case::new(
            "output_simulate_experiments_out_is_a_directory",
            NeedsGate,
            &[
                "simulate",
                "experiments",
                "--scenario",
                "1",
                "--n",
                "5",
                "--out",
                "x.csv",
            ],
            &["--out"],
        )
        .dir("x.csv"),
        Case::new(
            "output_simulate_field_out_below_a_file",
            NeedsGate,
            &[
                "simulate",
                "field",
                "--days",
                "2",
                "--out",
                "f.txt/record.csv",
            ],
            &["--out"],
        )
        .file("f.txt", "a file, not a directory\n"),
    ]
}

/// `predict`: the calibration file (missing, empty, garbage, truncated, wrong types, a
/// negative `sigma_eps`, an invalid stored configuration), the model file (missing, empty,
/// garbage, wrong types, a different model, an invalid prior), the levels (non-finite, outside
/// the gate's domain), flags it would ignore, and the forces destination. The good files come
/// from the control run and sit in `cal/`.
fn predict_inputs(base: &Base, fx: &Fixture) -> Vec<Case> {
    let levels = ["--h-up", "600", "--h-down", "100"];
    let call = |extra: &[&str]| -> Vec<String> {
        ["predict", "--calibration", "cal/calibration.json"]
            .iter()
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    let pc = |name: &str,
              calibration: &[u8],
              model: Option<&[u8]>,
              args: Vec<String>,
              culprits: &[&str]| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let mut case = Case::new(&format!("predict_{name}"), BeforeGate, &refs, culprits)
            .file("cal/calibration.json", calibration);
        if let Some(m) = model {
            case = case.file("cal/model.json", m);
        }
        case
    };
    let good_cal = fx.calibration.as_slice();
    let good_model = Some(fx.model.as_slice());
    let cal_with = |path: &[&str], v: serde_json::Value| json_with(good_cal, path, v);
    let model_with = |path: &[&str], v: serde_json::Value| json_with(&fx.model, path, v);
    let h = |up: &str, down: &str| call(&["--h-up", up, "--h-down", down]);
    let lv = call(&levels);
    vec![
        // the calibration file
        Case::new(
            "predict_calibration_missing",
            BeforeGate,
            &cat(&["predict", "--calibration", "none.json"], &levels),
            &["none.json"],
        ),
        pc(
            "calibration_empty",
            b"",
            good_model,
            lv.clone(),
            &["calibration.json"],
        ),
        pc(
            "calibration_garbage",
            b"this is not JSON\n",
            good_model,
            lv.clone(),
            &["calibration.json"],
        ),
        pc(
            "calibration_truncated",
            &truncated(good_cal),
            good_model,
            lv.clone(),
            &["calibration.json"],
        ),
        pc(
            "calibration_json_array",
            b"[]",
            good_model,
            lv.clone(),
            &["calibration.json"],
        ),
        pc(
            "calibration_utf16",
            &utf16le("{}"),
            good_model,
            lv.clone(),
            &["calibration.json"],
        ),
        pc(
            "calibration_negative_sigma_eps",
            &cal_with(&["module3", "sigma_eps"], serde_json::json!(-1.0)),
            good_model,
            lv.clone(),
            &["calibration.json", "sigma_eps"],
        ),
        pc(
            "calibration_zero_sigma_eps",
            &cal_with(&["module3", "sigma_eps"], serde_json::json!(0.0)),
            good_model,
            lv.clone(),
            &["calibration.json", "sigma_eps"],
        ),
        pc(
            "calibration_sigma_eps_string",
            &cal_with(&["module3", "sigma_eps"], serde_json::json!("one")),
            good_model,
            lv.clone(),
            &["calibration.json"],
        ),
        pc(
            "calibration_invalid_stored_config",
            &cal_with(&["config", "theta_grid_points"], serde_json::json!(0)),
            good_model,
            lv.clone(),
            &["calibration.json", "theta_grid_points"],
        ),
        Case::new(
            "predict_calibration_is_a_directory",
            BeforeGate,
            &cat(&["predict", "--calibration", "resultsdir"], &levels),
            &["resultsdir"],
        )
        .file("resultsdir/model.json", &fx.model),
        // the model file
        pc("model_missing", good_cal, None, lv.clone(), &["model.json"]),
        pc(
            "model_empty",
            good_cal,
            Some(b"".as_slice()),
            lv.clone(),
            &["model.json"],
        ),
        pc(
            "model_garbage",
            good_cal,
            Some(b"{ not json".as_slice()),
            lv.clone(),
            &["model.json"],
        ),
        pc(
            "model_truncated",
            good_cal,
            Some(truncated(&fx.model).as_slice()),
            lv.clone(),
            &["model.json"],
        ),
        pc(
            "model_wrong_type",
            good_cal,
            Some(model_with(&["discrepancy_terms"], serde_json::json!("six")).as_slice()),
            lv.clone(),
            &["model.json"],
        ),
        pc(
            "model_invalid_prior",
            good_cal,
            Some(model_with(&["gap_prior"], serde_json::json!([-5.0, 100.0])).as_slice()),
            lv.clone(),
            &["model.json", "gap_prior"],
        ),
        // a valid model, but not the calibrated one (4 + 4 discrepancy terms instead of 6 + 6)
        pc(
            "model_of_another_calibration",
            good_cal,
            good_model,
            call(&cat(&["--model", "other.json"], &levels)),
            &["other.json"],
        )
        .file(
            "other.json",
            model_with(&["discrepancy_terms"], serde_json::json!([4, 4])),
        ),
        // the levels: finite, 24 <= h_down <= h_up <= 744 in
        pc(
            "h_up_nan",
            good_cal,
            good_model,
            h("NaN", "100"),
            &["--h-up"],
        ),
        pc(
            "h_up_inf",
            good_cal,
            good_model,
            h("inf", "100"),
            &["--h-up"],
        ),
        pc(
            "h_up_negative_inf",
            good_cal,
            good_model,
            call(&["--h-up=-inf", "--h-down", "100"]),
            &["--h-up"],
        ),
        pc(
            "h_up_negative",
            good_cal,
            good_model,
            h("-1", "100"),
            &["--h-up"],
        ),
        pc(
            "h_up_above_domain",
            good_cal,
            good_model,
            h("900", "100"),
            &["--h-up"],
        ),
        pc(
            "h_down_nan",
            good_cal,
            good_model,
            h("600", "NaN"),
            &["--h-down"],
        ),
        pc(
            "h_down_negative",
            good_cal,
            good_model,
            h("600", "-5"),
            &["--h-down"],
        ),
        pc(
            "h_down_below_domain",
            good_cal,
            good_model,
            h("600", "10"),
            &["--h-down"],
        ),
        // flags predict would ignore (the gate and its settings come from model.json)
        pc(
            "refuses_gate",
            good_cal,
            good_model,
            call(&cat(&levels, &["--gate", "gate.toml"])),
            &["--gate"],
        )
        .file("gate.toml", &base.gate_toml),
        pc(
            "refuses_element_size",
            good_cal,
            good_model,
            call(&cat(&levels, &["--element-size", "60"])),
            &["--element-size"],
        ),
        pc(
            "refuses_seed",
            good_cal,
            good_model,
            call(&cat(&levels, &["--seed", "3"])),
            &["--seed"],
        ),
        pc(
            "refuses_threads",
            good_cal,
            good_model,
            call(&cat(&levels, &["--threads", "2"])),
            &["--threads"],
        ),
        // the forces CSV cannot be written
        pc(
            "forces_out_below_a_file",
            good_cal,
            good_model,
            call(&cat(&levels, &["--forces-out", "f.txt/forces.csv"])),
            &["f.txt/forces.csv"],
        )
        .file("f.txt", "a file, not a directory\n"),
        // the load history of --record (fatigue over a record)
        pc(
            "record_missing",
            good_cal,
            good_model,
            call(&["--record", "none.csv"]),
            &["none.csv"],
        ),
        pc(
            "record_without_h_down",
            good_cal,
            good_model,
            call(&["--record", "r.csv"]),
            &["r.csv", "h_down"],
        )
        .file("r.csv", "time,h_up\n0,600\n1,120\n"),
        pc(
            "record_time_backwards",
            good_cal,
            good_model,
            call(&["--record", "r.csv"]),
            &["r.csv", "line 3", "time"],
        )
        .file("r.csv", "time,h_up,h_down\n1,600,100\n0,120,120\n"),
        pc(
            "record_level_outside_domain",
            good_cal,
            good_model,
            call(&["--record", "r.csv"]),
            &["r.csv", "line 3"],
        )
        .file("r.csv", "time,h_up,h_down\n0,600,100\n1,900,100\n"),
        pc(
            "record_single_row",
            good_cal,
            good_model,
            call(&["--record", "r.csv"]),
            &["r.csv", "two samples"],
        )
        .file("r.csv", "time,h_up,h_down\n0,600,100\n"),
        pc(
            "record_out_below_a_file",
            good_cal,
            good_model,
            call(&["--record", "r.csv", "--record-out", "f.txt/fatigue.csv"]),
            &["f.txt/fatigue.csv"],
        )
        .file("r.csv", "time,h_up,h_down\n0,600,100\n1,120,120\n")
        .file("f.txt", "a file, not a directory\n"),
    ]
}

// ---------------------------------------------------------------------------------------------
// Running
// ---------------------------------------------------------------------------------------------

/// The outcome of one run of the binary.
struct Run {
    /// Exit status (`None`: ended by a signal, or killed at the time limit).
    code: Option<i32>,
    timed_out: bool,
    stderr: String,
    seconds: f64,
}

/// Runs `bamudi args` in `cwd`, killing it after `limit`. stdout and stderr are drained by
/// threads, so a talkative run cannot block on a full pipe and look like a hang.
fn run(args: &[String], cwd: &Path, limit: Duration) -> Run {
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .env("CI", "1") // no progress bars
        .env_remove("RUST_BACKTRACE") // a panic must show its "run with RUST_BACKTRACE" note
        .env_remove("RUST_LIB_BACKTRACE")
        .env_remove("RUST_LOG")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the bamudi binary starts");
    let drain = |mut pipe: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            let _ = pipe.read_to_end(&mut bytes);
            bytes
        })
    };
    let out = drain(Box::new(child.stdout.take().expect("piped stdout")));
    let err = drain(Box::new(child.stderr.take().expect("piped stderr")));
    let start = Instant::now();
    let (status, timed_out) = loop {
        if let Some(status) = child.try_wait().expect("polling bamudi") {
            break (status, false);
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            break (child.wait().expect("reaping the killed bamudi"), true);
        }
        std::thread::sleep(POLL);
    };
    let seconds = start.elapsed().as_secs_f64();
    let _ = out.join();
    let stderr = String::from_utf8_lossy(&err.join().unwrap_or_default()).into_owned();
    Run {
        code: if timed_out { None } else { status.code() },
        timed_out,
        stderr,
        seconds,
    }
}

/// Creates the case's symbolic links under `dir`; `false` where the platform has none.
fn write_links(dir: &Path, links: &[(String, String)]) -> bool {
    #[cfg(unix)]
    {
        for (path, target) in links {
            std::os::unix::fs::symlink(target, dir.join(path)).expect("creating a symbolic link");
        }
        true
    }
    #[cfg(not(unix))]
    {
        links.is_empty()
    }
}

/// Creates the case's inputs under `dir`.
fn write_inputs(dir: &Path, files: &[(String, Vec<u8>)]) {
    std::fs::create_dir_all(dir).expect("creating a case directory");
    for (rel, bytes) in files {
        let path = dir.join(rel.trim_end_matches('/'));
        if rel.ends_with('/') {
            std::fs::create_dir_all(&path).expect("creating an input directory");
        } else {
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).expect("creating an input's directory");
            }
            std::fs::write(&path, bytes).expect("writing an input file");
        }
    }
}

/// Every entry below `dir`, relative, directories with a trailing `/`.
fn listing(dir: &Path) -> BTreeSet<String> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeSet<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let rel = path
                .strip_prefix(root)
                .map(|p| p.to_string_lossy().replace('\\', "/"))
                .unwrap_or_else(|_| path.display().to_string());
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                out.insert(format!("{rel}/"));
                walk(root, &path, out);
            } else {
                out.insert(rel);
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(dir, dir, &mut out);
    out
}

/// A readable excerpt of stderr: the beginning (clap and anyhow put the error first) and the
/// end.
fn excerpt(text: &str) -> String {
    let text = text.trim();
    let chars: Vec<char> = text.chars().collect();
    let shown = if chars.len() <= 1200 {
        text.to_string()
    } else {
        let head: String = chars[..800].iter().collect();
        let tail: String = chars[chars.len() - 300..].iter().collect();
        format!(
            "{head}\n[... {} characters ...]\n{tail}",
            chars.len() - 1100
        )
    };
    if shown.is_empty() {
        "(empty)".into()
    } else {
        shown.replace('\n', "\n      | ")
    }
}

/// Runs one case in `dir`; `None` when it is a clean, named refusal.
fn check_case(case: &Case, dir: &Path) -> Option<String> {
    write_inputs(dir, &case.files);
    if !write_links(dir, &case.links) {
        return None; // no symbolic links on this platform
    }
    let before = listing(dir);
    let r = run(&case.command_line(), dir, CASE_TIMEOUT);
    let mut problems = Vec::new();
    if r.timed_out {
        problems.push(format!(
            "still running after {} s, killed: the input was not refused by a validator",
            CASE_TIMEOUT.as_secs()
        ));
    }
    match (r.code, case.expect) {
        (Some(0), Expect::Refuse) => {
            problems.push("exit status 0: the bad input was accepted".into())
        }
        (Some(c), Expect::Warn { .. }) if c != 0 => problems.push(format!(
            "exit status {c}: the input must be accepted with a warning"
        )),
        (None, _) if !r.timed_out => problems.push("ended by a signal (a crash)".into()),
        _ => {}
    }
    if let Some(p) = repeated_cause(&r.stderr) {
        problems.push(p);
    }
    for word in ["panicked", "RUST_BACKTRACE"] {
        if r.stderr.contains(word) {
            problems.push(format!("stderr contains `{word}`: a panic, not an error"));
        }
    }
    for word in CLAP_REFUSALS {
        if r.stderr.contains(word) {
            problems.push(format!(
                "stderr contains `{word}`: clap refused a well-formed argument before any \
                 validator saw it"
            ));
        }
    }
    for c in &case.culprits {
        if !r.stderr.contains(c.as_str()) {
            problems.push(format!("stderr does not name `{c}`"));
        }
    }
    if case.stage == BeforeGate && r.stderr.contains(GATE_BUILT) {
        problems.push("the gate was built before the refusal (validate first)".into());
    }
    let after = listing(dir);
    let written = |entry: &str| match case.expect {
        Expect::Warn { out } => entry.starts_with(&format!("{out}/")),
        Expect::Refuse => false,
    };
    for extra in after.difference(&before).filter(|e| !written(e)) {
        problems.push(format!("left behind: {extra}"));
    }
    for gone in before.difference(&after) {
        problems.push(format!("input removed: {gone}"));
    }
    for (rel, bytes) in case.files.iter().filter(|(rel, _)| !rel.ends_with('/')) {
        if let Ok(now) = std::fs::read(dir.join(rel))
            && now != *bytes
        {
            problems.push(format!("input changed: {rel}"));
        }
    }
    if problems.is_empty() {
        return None;
    }
    let mut text = format!(
        "{} ({:?}, {:.1} s, in {})\n    $ bamudi {}\n",
        case.name,
        case.stage,
        r.seconds,
        dir.display(),
        case.command_line().join(" ")
    );
    for p in problems {
        text += &format!("    - {p}\n");
    }
    text += &format!("    stderr:\n      | {}\n", excerpt(&r.stderr));
    Some(text)
}

/// What is wrong with the `error: ` line of `stderr` when it prints a cause twice: an
/// `(os error N)` more than once, or the same piece twice in a row (`--data X: X: ...`).
fn repeated_cause(stderr: &str) -> Option<String> {
    let line = stderr.lines().find(|l| l.starts_with("error: "))?;
    if line.matches("(os error").count() > 1 {
        return Some(format!("the error line prints the OS error twice: {line}"));
    }
    let pieces: Vec<&str> = line.split(": ").collect();
    pieces
        .windows(2)
        .find(|w| w[0].trim() == w[1].trim() || w[0].ends_with(&format!(" {}", w[1].trim())))
        .map(|w| format!("the error line repeats `{}`: {line}", w[1]))
}

/// Runs every case, [`WORKERS`] at a time, each in `root/case_NNN`; the failures in corpus
/// order.
fn run_all(cases: &[Case], root: &Path) -> Vec<String> {
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..WORKERS {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(case) = cases.get(i) else { break };
                    let dir = root.join(format!("case_{i:03}"));
                    if let Some(f) = check_case(case, &dir) {
                        failures.lock().unwrap().push((i, f));
                    }
                }
            });
        }
    });
    let mut failures = failures.into_inner().unwrap();
    failures.sort_by_key(|(i, _)| *i);
    failures.into_iter().map(|(_, f)| f).collect()
}

/// The control run's results: a good calibration of the base experiments.
struct Fixture {
    calibration: Vec<u8>,
    model: Vec<u8>,
}

impl Fixture {
    /// Calibrates the uncorrupted base inputs on the 60 in gate; `None` (with the reason in
    /// `failures`) when that fails.
    fn make(dir: &Path, base: &Base, failures: &mut Vec<String>) -> Option<Self> {
        write_inputs(
            dir,
            &[
                ("cal.toml".into(), CAL_TOML.as_bytes().to_vec()),
                ("exps.csv".into(), base.exps.as_bytes().to_vec()),
            ],
        );
        let args: Vec<String> = [
            "--element-size",
            "60",
            "calibrate",
            "--config",
            "cal.toml",
            "--data",
            "exps.csv",
            "--out",
            "good",
        ]
        .map(String::from)
        .to_vec();
        let r = run(&args, dir, FIXTURE_TIMEOUT);
        if r.timed_out || r.code != Some(0) {
            failures.push(format!(
                "control: `bamudi {}` on the uncorrupted base inputs (in {}) must succeed: the \
                 data cases corrupt exactly these inputs, and the predict cases need its \
                 results (not run). Exit {:?}, {:.1} s{}\n    stderr:\n      | {}\n",
                args.join(" "),
                dir.display(),
                r.code,
                r.seconds,
                if r.timed_out { " (killed)" } else { "" },
                excerpt(&r.stderr)
            ));
            return None;
        }
        if !r.stderr.contains(GATE_BUILT) {
            failures.push(format!(
                "control: a run that builds the gate no longer prints `{GATE_BUILT}` on stderr, \
                 so the before-the-gate check of the corpus cannot see a gate build: update \
                 GATE_BUILT\n    stderr:\n      | {}\n",
                excerpt(&r.stderr)
            ));
        }
        let read = |f: &str| std::fs::read(dir.join("good").join(f));
        match (read("calibration.json"), read("model.json")) {
            (Ok(calibration), Ok(model)) => Some(Self { calibration, model }),
            _ => {
                failures.push(format!(
                    "control: calibrate succeeded but {} has no calibration.json and model.json \
                     (the predict cases were not run)\n",
                    dir.join("good").display()
                ));
                None
            }
        }
    }
}

#[test]
fn every_bad_input_is_a_clean_refusal_that_names_its_culprit() {
    let root = std::env::temp_dir().join(format!("bamudi_corpus_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let base = Base::generate();
    let mut failures = Vec::new();
    let fixture = Fixture::make(&root.join("control"), &base, &mut failures);
    let cases = corpus(&base, fixture.as_ref());
    let names: BTreeSet<&str> = cases.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names.len(), cases.len(), "case names must be unique");
    if cases.len() < MIN_CASES {
        failures.push(format!(
            "the corpus has {} cases, fewer than {MIN_CASES}\n",
            cases.len()
        ));
    }
    failures.extend(run_all(&cases, &root.join("cases")));
    if failures.is_empty() {
        let _ = std::fs::remove_dir_all(&root);
    }
    assert!(
        failures.is_empty(),
        "{} problem(s) in the bad-input corpus of {} cases (inputs and anything left behind \
         are kept under {}):\n\n{}",
        failures.len(),
        cases.len(),
        root.display(),
        failures.join("\n")
    );
}
