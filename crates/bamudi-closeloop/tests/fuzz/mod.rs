//! Parser fuzzing: arbitrary text (characters that matter to the formats, any Unicode, lossy
//! bytes) and mutated valid documents (characters replaced, inserted or deleted, lines
//! duplicated or deleted) fed to every text parser a user's file goes through, the engine's and
//! the close loop's (they live here, above both): CSV tables
//! ([`Table::parse`]), experiments ([`Experiments::from_table`]), measured records
//! ([`parse_csv`], both missing-value policies), the calibration TOML
//! ([`CalibrationConfig::from_toml_str`]) and the close-loop TOML (`toml::from_str` into
//! [`CloseLoopConfig`], then its `validate`, as `bamudi close-loop --config` reads it).
//!
//! The contract checked: `Ok` or `Err`, never a panic (a panic fails the property); on top of
//! that, the guarantees the CSV layer documents: every error names the file label, line
//! numbers increase, and the numbers a reader returns are finite (missing outputs dropped or
//! interpolated, never guessed). 256 cases per property on documents of a few hundred
//! characters: each property runs in well under a second.
//!
//! `fuzz_seeds_are_valid_documents` checks that the documents the mutations start from are
//! valid, so that the mutated cases start from the happy path.

use bamudi::data::{Empty, Table};
use bamudi::{CalibrationConfig, CalibrationParams, Experiments};
use bamudi_closeloop::{CloseLoopConfig, IngestConfig, MissingPolicy, parse_csv};
use proptest::prelude::*;
use proptest::sample::Index;

/// The file label of every parsed text.
const FILE: &str = "fuzz.csv";
const INPUTS: [&str; 2] = ["h_up", "h_down"];
const GAUGES: [&str; 3] = ["g1", "g2", "g3"];

const EXPERIMENTS: &str = "h_up,h_down,g1,g2,g3\n\
500,100,-12.5,3.25,1e-3\n\
620.5,80,-14,2.5,0.002\n\
410,190,-9.75,1.5,-0.001\n";

/// Timestamps of every accepted form (UTC `Z`, civil with a space and no seconds, an offset,
/// civil without seconds), a covariate, and a missing gauge value on line 3.
const RECORD_ISO: &str = "time,h_up,h_down,air_temp_f,g1,g2,g3\n\
2024-01-01T00:00:00Z,500,100,41.5,-12.5,3.25,0.1\n\
2024-01-01T01:00:00Z,520,110,42,,3.5,0.2\n\
2024-01-01 02:30,540,120,42.5,-13,3.75,0.3\n\
2024-01-01T04:00:00+01:00,560,130,43,-13.5,4,0.4\n\
2024-01-01T04:00,580,140,43.5,-14,4.25,0.5\n";

/// Time in hours.
const RECORD_HOURS: &str = "time,h_up,h_down,g1,g2,g3\n\
0,500,100,-12.5,3.25,0.1\n\
0.5,520,110,-12.75,3.5,0.2\n\
1,540,120,-13,3.75,0.3\n";

/// Every `CalibrationParams` key, as the docs write them.
const CALIBRATION_FULL: &str = "theta_grid_points = 201\n\
gp_restarts = 3\n\
seed = 2021\n\
training_size = 3000\n\
sigma_eps = 1.5\n\
threads = 2\n\
coefficients = \"marginal\"\n\
[estimator]\n\
kind = \"exact_linear\"\n\
[sampling]\n\
noise_sd = 1.0\n\
rho_range = [0.0, 1.2]\n\
alpha_scale = 0.5\n\
floor_fraction = 0.05\n\
draws_per_x = 10\n\
x_bounds = [[400.0, 700.0], [50.0, 200.0]]\n\
[marginalisation]\n\
method = \"quadrature\"\n\
order = 5\n\
[rho]\n\
lo = 0.0\n\
hi = 1.0\n\
points = 101\n\
refine = true\n\
[mcmc]\n\
chains = 4\n\
warmup = 2000\n\
samples = 5000\n\
[marginal]\n\
kernel = \"matern52\"\n\
scales = \"shared_per_component\"\n\
mask_outside_support = true\n";

const CALIBRATION_RIDGE: &str = "training_size = 1000\n\
coefficients = \"conditional_on_theta\"\n\
[estimator]\n\
kind = \"ridge\"\n\
lambda = 0.1\n\
[marginalisation]\n\
method = \"monte_carlo\"\n\
samples = 50\n";

/// Every `CloseLoopConfig` key (the CLI replaces `load` with the gate's head, but the file
/// may give it).
const CLOSE_LOOP_FULL: &str = "calibration_fraction = 0.6\n\
test_fraction = 0.2\n\
selection_origins = 3\n\
max_steps = 4\n\
min_relative_improvement = 0.05\n\
improvement_significance = 0.001\n\
min_significant_improvement = 0.01\n\
temperature_columns = [\"air_temp_f\", \"water_temp_f\"]\n\
parameter_name = \"gap\"\n\
output_unit = \"microstrain\"\n\
max_generic_features = 3\n\
generic_selection = \"stepwise_bic\"\n\
ljung_box_lags = 10\n\
significance = 0.01\n\
confirm_candidates = 3\n\
[column_units]\n\
air_temp_f = \"degF\"\n\
water_temp_f = \"degF\"\n\
[event_scan]\n\
enabled = true\n\
min_segment_rows = 8\n\
penalty_per_change_ln_n = 3.0\n\
level = 0.95\n\
[track]\n\
enabled = true\n\
window_hours = 24.0\n\
in_control_windows = 3650.0\n\
cusum_k = 0.5\n\
grid_nodes = 41\n\
[load]\n\
name = \"head\"\n\
weights = [1.0, -1.0]\n\
companion = 1\n\
active_above = 1.0\n";

fn calibration_seeds() -> Vec<String> {
    vec![
        toml::to_string(&CalibrationParams::default()).expect("default params serialise"),
        CALIBRATION_FULL.to_string(),
        CALIBRATION_RIDGE.to_string(),
    ]
}

fn close_loop_seeds() -> Vec<String> {
    vec![
        toml::to_string(&CloseLoopConfig::default()).expect("default loop config serialises"),
        CLOSE_LOOP_FULL.to_string(),
    ]
}

// ---------------------------------------------------------------------------------------------
// Strategies
// ---------------------------------------------------------------------------------------------

/// One edit of a document.
#[derive(Debug, Clone)]
enum Edit {
    Replace(Index, char),
    Insert(Index, char),
    Delete(Index),
    /// Copies a line to another position.
    DuplicateLine(Index, Index),
    DeleteLine(Index),
}

/// Characters that mean something to CSV, TOML or numbers, and now and then any character.
fn format_char() -> impl Strategy<Value = char> {
    prop_oneof![
        4 => prop::sample::select(vec![
            ',', ';', '"', '\'', '\n', '\r', '\t', ' ', '-', '+', '.', 'e', 'E', '0', '1', '9',
            '=', '[', ']', '{', '}', '#', ':', 'T', 'Z', '\\', 'n', 'a', 'i', 'f', '\u{feff}',
            '\u{0}', 'µ',
        ]),
        1 => any::<char>(),
    ]
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<Index>(), format_char()).prop_map(|(i, c)| Edit::Replace(i, c)),
        (any::<Index>(), format_char()).prop_map(|(i, c)| Edit::Insert(i, c)),
        any::<Index>().prop_map(Edit::Delete),
        (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Edit::DuplicateLine(a, b)),
        any::<Index>().prop_map(Edit::DeleteLine),
    ]
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    prop::collection::vec(edit(), 1..8)
}

/// Arbitrary text: format characters, any Unicode, or bytes read lossily as UTF-8.
fn text() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::collection::vec(format_char(), 0..200)
            .prop_map(|v| v.into_iter().collect::<String>()),
        any::<String>(),
        prop::collection::vec(any::<u8>(), 0..200)
            .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
    ]
}

/// `text` after the edits.
fn mutate(text: &str, edits: &[Edit]) -> String {
    let mut chars: Vec<char> = text.chars().collect();
    for e in edits {
        match e {
            Edit::Replace(i, c) if !chars.is_empty() => {
                let k = i.index(chars.len());
                chars[k] = *c;
            }
            Edit::Insert(i, c) => {
                let k = i.index(chars.len() + 1);
                chars.insert(k, *c);
            }
            Edit::Delete(i) if !chars.is_empty() => {
                let k = i.index(chars.len());
                chars.remove(k);
            }
            Edit::DuplicateLine(a, b) => {
                let s: String = chars.iter().collect();
                let mut lines: Vec<&str> = s.split_inclusive('\n').collect();
                if !lines.is_empty() {
                    let line = lines[a.index(lines.len())];
                    lines.insert(b.index(lines.len() + 1), line);
                }
                chars = lines.concat().chars().collect();
            }
            Edit::DeleteLine(a) => {
                let s: String = chars.iter().collect();
                let mut lines: Vec<&str> = s.split_inclusive('\n').collect();
                if !lines.is_empty() {
                    lines.remove(a.index(lines.len()));
                }
                chars = lines.concat().chars().collect();
            }
            _ => {}
        }
    }
    chars.into_iter().collect()
}

// ---------------------------------------------------------------------------------------------
// Checks
// ---------------------------------------------------------------------------------------------

/// The CSV error policy: every error names the file.
fn names_the_file(e: &dyn std::error::Error) -> Result<(), TestCaseError> {
    let msg = e.to_string();
    prop_assert!(
        msg.contains(FILE),
        "the error does not name the file: {msg}"
    );
    Ok(())
}

fn check_table(text: &str) -> Result<(), TestCaseError> {
    let t = match Table::parse(text, FILE) {
        Ok(t) => t,
        Err(e) => return names_the_file(&e),
    };
    // the header is line 1, rows follow in increasing lines, whatever the line ends (`\n`,
    // `\r\n`, classic-Mac `\r`: the table counts them itself)
    for i in 0..t.len() {
        prop_assert!(t.line(i) >= 2, "row {i} on line {}", t.line(i));
        if i > 0 {
            prop_assert!(
                t.line(i) > t.line(i - 1),
                "rows {} and {i} out of order",
                i - 1
            );
        }
    }
    for h in t.header() {
        for empty in [Empty::Refuse, Empty::Missing] {
            match t.numbers(&[h.as_str()], empty) {
                Ok(m) => {
                    prop_assert_eq!(m.nrows(), t.len());
                    if empty == Empty::Refuse {
                        prop_assert!(m.iter().all(|v| v.is_finite()), "column {h}: {m}");
                    }
                }
                Err(e) => names_the_file(&e)?,
            }
        }
    }
    Ok(())
}

fn check_experiments(text: &str) -> Result<(), TestCaseError> {
    let t = match Table::parse(text, FILE) {
        Ok(t) => t,
        Err(e) => return names_the_file(&e),
    };
    match Experiments::from_table(&t, &INPUTS, &GAUGES) {
        Ok(e) => {
            prop_assert_eq!(e.len(), t.len());
            prop_assert!(e.x.iter().chain(e.y.iter()).all(|v| v.is_finite()));
            Ok(())
        }
        Err(e) => names_the_file(&e),
    }
}

fn check_record(text: &str, missing: MissingPolicy) -> Result<(), TestCaseError> {
    let cfg = IngestConfig::new(&INPUTS, &GAUGES).missing(missing);
    match parse_csv(text, FILE, &cfg) {
        Ok(r) => {
            let n = r.len();
            prop_assert!(n >= 1);
            prop_assert_eq!(
                (
                    r.x.nrows(),
                    r.y.nrows(),
                    r.covariates.nrows(),
                    r.source_lines.len()
                ),
                (n, n, n, n)
            );
            prop_assert!(
                r.x.iter()
                    .chain(r.y.iter())
                    .chain(r.covariates.iter())
                    .all(|v| v.is_finite()),
                "a non-finite value in a parsed record"
            );
            // (line numbers: see `check_table`)
            prop_assert!(r.source_lines.windows(2).all(|w| w[0] < w[1]));
            Ok(())
        }
        Err(e) => names_the_file(&e),
    }
}

fn check_calibration_toml(text: &str) {
    // Ok or Err; a panic fails the property
    let _ = CalibrationConfig::from_toml_str(text);
}

fn check_close_loop_toml(text: &str) {
    if let Ok(cfg) = toml::from_str::<CloseLoopConfig>(text) {
        let _ = cfg.validate();
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn csv_tables_from_any_text(t in text()) {
        check_table(&t)?;
    }

    #[test]
    fn csv_tables_and_experiments_from_mutated_experiments(e in edits()) {
        let t = mutate(EXPERIMENTS, &e);
        check_table(&t)?;
        check_experiments(&t)?;
    }

    #[test]
    fn experiments_from_any_text(t in text()) {
        check_experiments(&t)?;
    }

    #[test]
    fn records_from_mutated_records(e in edits(), hours in any::<bool>(), impute in any::<bool>()) {
        let base = if hours { RECORD_HOURS } else { RECORD_ISO };
        let policy = if impute { MissingPolicy::Interpolate } else { MissingPolicy::Drop };
        check_record(&mutate(base, &e), policy)?;
    }

    #[test]
    fn records_from_any_text(t in text(), impute in any::<bool>()) {
        let policy = if impute { MissingPolicy::Interpolate } else { MissingPolicy::Drop };
        check_record(&t, policy)?;
    }

    #[test]
    fn calibration_toml_from_mutated_documents(e in edits(), seed in 0usize..3) {
        check_calibration_toml(&mutate(&calibration_seeds()[seed], &e));
    }

    #[test]
    fn calibration_toml_from_any_text(t in text()) {
        check_calibration_toml(&t);
    }

    #[test]
    fn close_loop_toml_from_mutated_documents(e in edits(), seed in 0usize..2) {
        check_close_loop_toml(&mutate(&close_loop_seeds()[seed], &e));
    }

    #[test]
    fn close_loop_toml_from_any_text(t in text()) {
        check_close_loop_toml(&t);
    }
}

#[test]
fn fuzz_seeds_are_valid_documents() {
    let t = Table::parse(EXPERIMENTS, FILE).unwrap();
    assert_eq!(
        Experiments::from_table(&t, &INPUTS, &GAUGES).unwrap().len(),
        3
    );
    let read = |text: &str, m: MissingPolicy| {
        parse_csv(text, FILE, &IngestConfig::new(&INPUTS, &GAUGES).missing(m)).unwrap()
    };
    // line 3 has no g1: dropped, or interpolated in time between 0 h (-12.5) and 2.5 h (-13)
    let dropped = read(RECORD_ISO, MissingPolicy::Drop);
    assert_eq!((dropped.len(), dropped.dropped_missing), (4, 1));
    assert_eq!(dropped.time_h, vec![0.0, 2.5, 3.0, 4.0]);
    let imputed = read(RECORD_ISO, MissingPolicy::Interpolate);
    assert_eq!((imputed.len(), imputed.imputed), (5, 1));
    // -12.5 + (1 / 2.5) (-0.5): a few operations on exact decimals, round-off only
    assert!(
        (imputed.y[(1, 0)] + 12.7).abs() < 1e-12,
        "{}",
        imputed.y[(1, 0)]
    );
    assert_eq!(
        read(RECORD_HOURS, MissingPolicy::Drop).time_h,
        vec![0.0, 0.5, 1.0]
    );
    for doc in calibration_seeds() {
        CalibrationConfig::from_toml_str(&doc).unwrap_or_else(|e| panic!("{e}\n{doc}"));
    }
    for doc in close_loop_seeds() {
        let cfg: CloseLoopConfig = toml::from_str(&doc).unwrap_or_else(|e| panic!("{e}\n{doc}"));
        cfg.validate().unwrap();
    }
}
