//! The operations the `bamudi` command line and the Python package (`python/`) share, so that
//! both give the same numbers for the same inputs and seed and the same messages for the same
//! mistakes: the calibration specification (`gap_prior`, `discrepancy_terms`,
//! `[calibration]`), the experiments read from a table and checked, the calibration with the
//! gate's physics checks, and the paper's synthetic experiments on a gate or a reality.

use crate::calibrator::GateCalibrator;
use crate::error::{GateAppError, Result};
use crate::gate::SavedModel;
use crate::tolerance::{ToleranceSpec, check_tolerance_keys, check_tolerance_specs};
use bamudi::data::Table;
use bamudi::observe::Observer;
use bamudi::posterior::{GridWarning, ThetaPosterior};
use bamudi::{Calibrate, Calibration, CalibrationConfig, CalibrationParams, Experiments};
use bamudi_closeloop::{IngestConfig, MeasuredRecord};
use mitergate::contact::ContactParams;
use mitergate::data::truth::{self, Scenario};
use mitergate::inp::{ImportSpec, InpModel};
use mitergate::reality::Reality;
use mitergate::{ContactModel, GateConfig, GateMultiLevel, MAX_GAUGE_READING_MICROSTRAIN};
use mlmodel::{ObservableModel, UnobservableModel};
use nalgebra::DMatrix;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Where a gate comes from: a configuration (the embedded default or a gate TOML) or a
/// finite-element deck (`.inp`, Abaqus / CalculiX) with its import spec (TOML; see
/// `docs/mitergate.md`, "Bring your own gate").
#[derive(Debug, Clone)]
pub enum GateSource {
    /// A gate configuration, built by the crate's own mesher.
    Config(GateConfig),
    /// An imported deck and the spec that tells where its quoin, skin and gauges are.
    Deck {
        /// The `.inp` file.
        inp: PathBuf,
        /// The import spec (TOML).
        spec: PathBuf,
    },
}

/// A built and condensed gate (Module 1) with what the reports state about it.
#[derive(Debug, Clone)]
pub struct BuiltGate {
    /// The contact model on the condensed gate.
    pub contact: ContactModel,
    /// The configuration, when the gate was built from one (not for a deck).
    pub config: Option<GateConfig>,
    /// Degrees of freedom of the finite-element model.
    pub n_dofs: usize,
    /// Mesh element size (in) of a configured gate (a deck has its own mesh).
    pub element_size: Option<f64>,
    /// Wall seconds of the build and condensation.
    pub seconds: f64,
}

impl GateSource {
    /// Builds and condenses the gate with the default contact parameters; a deck's errors
    /// name the file (and the line or key).
    pub fn build(&self) -> Result<BuiltGate> {
        match self {
            Self::Config(cfg) => {
                let (contact, summary, seconds) = crate::gate::build(cfg)?;
                Ok(BuiltGate {
                    contact,
                    config: Some(cfg.clone()),
                    n_dofs: summary.n_dofs,
                    element_size: Some(cfg.mesh.element_size),
                    seconds,
                })
            }
            Self::Deck { inp, spec } => build_deck(inp, spec),
        }
    }
}

/// Builds the gate of a deck and its import spec.
fn build_deck(inp: &Path, spec: &Path) -> Result<BuiltGate> {
    let start = std::time::Instant::now();
    // the spec first, as it is read first
    check_input_file("import spec", spec)?;
    check_input_file("deck", inp)?;
    let named =
        |what: String, e: mitergate::GateError| GateAppError::Invalid(format!("{what}: {e}"));
    let import = ImportSpec::from_file(spec).map_err(|e| named(spec.display().to_string(), e))?;
    let deck = InpModel::from_file(inp).map_err(|e| named(inp.display().to_string(), e))?;
    let n_dofs = 6 * deck.nodes.len();
    // a failure here may lie in the deck or in what the spec says about it: name both
    let both = format!("{} with import spec {}", inp.display(), spec.display());
    let condensed = deck
        .build(import.drilling_penalty)
        .and_then(|m| m.condense(&import, mitergate::DEFAULT_NU))
        .map_err(|e| named(both, e))?;
    let contact = ContactParams::default().build(condensed)?;
    Ok(BuiltGate {
        contact,
        config: None,
        n_dofs,
        element_size: None,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Most Legendre terms per discrepancy component: the gate has about 30 representation
/// points along the quoin, and the prior-scale fit of higher orders is not identifiable from
/// 7 gauges anyway.
pub const MAX_DISCREPANCY_TERMS: usize = 20;

/// Fewest experiments with distinct water levels: the coefficient GPs of Eq. 33-37 fit a
/// length scale per input, an amplitude and a noise level per coefficient; fewer distinct
/// conditions cannot identify them.
pub const MIN_DISTINCT_EXPERIMENTS: usize = 10;

/// What a calibration of the gate needs besides the data: the `calibrate` configuration file
/// (TOML) or the Python package's dict (JSON), with the same keys.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrateSpec {
    /// Uniform prior of the gap θ (in): exactly two numbers `[lo, hi]`.
    pub gap_prior: Vec<f64>,
    /// Legendre terms of the discrepancy (normal, tangential); the paper's 6 + 6 by default.
    #[serde(default = "default_terms")]
    pub discrepancy_terms: [usize; 2],
    /// BA-MUDI settings (missing keys take their defaults).
    #[serde(default)]
    pub calibration: CalibrationParams,
    /// Declared tolerances of the gate's build (`[[tolerances]]`), integrated out by the
    /// marginal mode; none by default.
    #[serde(default)]
    pub tolerances: Vec<ToleranceSpec>,
}

fn default_terms() -> [usize; 2] {
    [6, 6]
}

impl CalibrateSpec {
    /// Parses TOML text and checks it; `label` (the file) starts every message.
    pub fn from_toml_str(text: &str, label: &str) -> Result<Self> {
        let spec: Self = toml::from_str(text).map_err(|e| GateAppError::Serde {
            context: format!("parsing {label}"),
            reason: e.to_string(),
        })?;
        spec.checked(label)
    }

    /// Parses JSON text (the Python package's dict) and checks it; `label` starts every message.
    pub fn from_json_str(text: &str, label: &str) -> Result<Self> {
        let spec: Self = serde_json::from_str(text).map_err(|e| GateAppError::Serde {
            context: format!("parsing {label}"),
            reason: e.to_string(),
        })?;
        spec.checked(label)
    }

    /// The gap prior `(lo, hi)` (in), checked by the constructors.
    pub fn prior(&self) -> (f64, f64) {
        (self.gap_prior[0], self.gap_prior[1])
    }

    /// The checked calibration configuration, with the seed replaced when `seed` is given.
    pub fn config(&self, seed: Option<u64>) -> Result<CalibrationConfig> {
        let mut params = self.calibration.clone();
        if let Some(s) = seed {
            params.seed = s;
        }
        Ok(params.check()?)
    }

    fn checked(self, label: &str) -> Result<Self> {
        let ok = match self.gap_prior[..] {
            [lo, hi] => lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo < hi,
            _ => false,
        };
        if !ok {
            return Err(GateAppError::Invalid(format!(
                "{label}: `gap_prior` must be two numbers [lo, hi] with 0 <= lo < hi (in), got {:?}",
                self.gap_prior
            )));
        }
        if !self
            .discrepancy_terms
            .iter()
            .all(|t| (1..=MAX_DISCREPANCY_TERMS).contains(t))
        {
            return Err(GateAppError::Invalid(format!(
                "{label}: `discrepancy_terms` must be in [1, {MAX_DISCREPANCY_TERMS}] each, got {:?}",
                self.discrepancy_terms
            )));
        }
        check_tolerance_specs(
            &self.tolerances,
            self.calibration.coefficients.kind(),
            label,
        )?;
        if let Err(e) = self.calibration.clone().check() {
            return Err(GateAppError::Invalid(format!(
                "{label}: in table [calibration]: {e}"
            )));
        }
        Ok(self)
    }

    /// Checks the spec against the gate's quoin height `top` (in): the prior's upper bound
    /// must lie below it (for a configured gate, checked before the gate is built).
    pub fn check_quoin_height(&self, label: &str, top: f64) -> Result<()> {
        if self.prior().1 >= top {
            return Err(GateAppError::Invalid(format!(
                "{label}: `gap_prior` upper bound {} in must lie below the quoin height {top} in",
                self.prior().1
            )));
        }
        Ok(())
    }

    /// Checks every declared tolerance against the drawing `gate` (the key names a numeric
    /// field, and the gate stays valid one standard deviation either side) before anything is
    /// built.
    pub fn check_tolerances(&self, label: &str, gate: &GateConfig) -> Result<()> {
        check_tolerance_keys(&self.tolerances, gate, label)
    }

    /// The gate's multi-level model of `saved` (contact forces memoised, `memo_capacity`
    /// entries) with this spec's declared tolerances ([`build_tolerances`]); errors name
    /// `label`.
    pub fn calibration_model(
        &self,
        saved: &SavedModel,
        memo_capacity: usize,
        label: &str,
    ) -> Result<GateMultiLevel> {
        saved.multilevel_with(memo_capacity, &self.tolerances, label)
    }

    /// The saved model of a calibration of `contact` (built from `gate`, `None` for a deck)
    /// with this spec, checked by [`check_quoin_height`](Self::check_quoin_height).
    pub fn saved_model(
        &self,
        label: &str,
        gate: Option<GateConfig>,
        contact: ContactModel,
    ) -> Result<SavedModel> {
        self.check_quoin_height(label, contact.gate().quoin_height)?;
        Ok(SavedModel {
            gate,
            contact,
            gap_prior: self.prior(),
            discrepancy_terms: self.discrepancy_terms,
            tolerances: self.tolerances.clone(),
        })
    }
}

/// The experiments of the table in the gate's columns, each row checked against the model's
/// domain and the set checked for degeneracy; every error names the file (and the line).
/// Rows with the gate open (no head difference) carry no quoin force: they are left out with
/// a warning naming them, as the close loop's calibrator does.
pub fn experiments_from_table(table: &Table, model: &GateMultiLevel) -> Result<Experiments> {
    let names = model.observable.output_names();
    let outputs: Vec<&str> = names.iter().map(String::as_str).collect();
    let all = Experiments::from_table(table, &["h_up", "h_down"], &outputs)?;
    check_gauge_readings(table, &outputs)?;
    let col = table.column("h_up")?;
    let mut kept = vec![];
    let mut open = vec![];
    for i in 0..all.len() {
        let x = [all.x[(i, 0)], all.x[(i, 1)]];
        if let Err(e) = model.unobservable.check_input(&x) {
            return Err(table.error_at(i, col, e.to_string()).into());
        }
        match model.unobservable.response_vanishes(&x) {
            true => open.push(table.line(i)),
            false => kept.push(i),
        }
    }
    if !open.is_empty() {
        log::warn!(
            "{}: {} row(s) with the gate open (no head difference, no quoin force) left out, \
             lines {:?}{}",
            table.file(),
            open.len(),
            &open[..open.len().min(10)],
            if open.len() > 10 { " ..." } else { "" }
        );
    }
    let exps = Experiments::new(
        all.input_names.clone(),
        all.output_names.clone(),
        all.x.select_rows(kept.iter()),
        all.y.select_rows(kept.iter()),
    )?;
    check_informative(table.file(), &exps.x, &exps.y, &outputs, all.len())?;
    Ok(exps)
}

/// Refuses a gauge value beyond ±[`MAX_GAUGE_READING_MICROSTRAIN`] (10 % strain, more than
/// any strain gauge reports) in the columns `gauges`, naming the file, line and column.
pub fn check_gauge_readings(table: &Table, gauges: &[&str]) -> Result<()> {
    Ok(table.check_magnitude(
        gauges,
        MAX_GAUGE_READING_MICROSTRAIN,
        "microstrain",
        "no strain gauge reports more than 10 % strain (a unit mix-up, an overflow or a \
         placeholder?)",
    )?)
}

/// Refuses data that would give a confident number from nothing, before any calibration:
/// too few distinct loaded conditions (every row with the gate open, or the same levels
/// repeated), or a gauge that never changes (stuck or disconnected). `x` and `y` are the
/// loaded rows (the gate closed) of the `rows` read from `file`.
fn check_informative(
    file: &str,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    outputs: &[&str],
    rows: usize,
) -> Result<()> {
    let mut conditions: Vec<(u64, u64)> = (0..x.nrows())
        .map(|i| (x[(i, 0)].to_bits(), x[(i, 1)].to_bits()))
        .collect();
    conditions.sort_unstable();
    conditions.dedup();
    if conditions.len() < MIN_DISTINCT_EXPERIMENTS {
        let open = match rows - x.nrows() {
            0 => String::new(),
            n if n == rows => format!(
                " (every row has the gate open: columns `h_up` - `h_down` below \
                 {} in, no quoin force)",
                mitergate::MIN_HEAD_IN
            ),
            n => format!(" ({n} of the {rows} rows have the gate open and are left out)"),
        };
        return Err(GateAppError::Invalid(format!(
            "{file}: {} loaded row(s) with {} distinct water-level pair(s){open}; a calibration \
             needs at least {MIN_DISTINCT_EXPERIMENTS} distinct conditions with the gate closed",
            x.nrows(),
            conditions.len()
        )));
    }
    for (j, name) in outputs.iter().enumerate() {
        let col = y.column(j);
        let (lo, hi) = (col.min(), col.max());
        if hi <= lo {
            return Err(GateAppError::Invalid(format!(
                "{file}: column `{name}` is constant ({lo} microstrain in every loaded row): a \
                 stuck or disconnected gauge carries no information; fix or drop it (and its \
                 gauge in the gate file)"
            )));
        }
    }
    Ok(())
}

/// Reads a gate's field record (`path`, labelled by its path in messages) with the checks of
/// [`record_from_table`].
pub fn read_record(
    path: &Path,
    model: &GateMultiLevel,
    ingest: &IngestConfig,
) -> Result<MeasuredRecord> {
    record_from_table(&Table::read(path)?, model, ingest)
}

/// A gate's field record from CSV text (`label` names it in messages) with the checks of
/// [`record_from_table`].
pub fn parse_record(
    text: &str,
    label: &str,
    model: &GateMultiLevel,
    ingest: &IngestConfig,
) -> Result<MeasuredRecord> {
    record_from_table(&Table::parse(text, label)?, model, ingest)
}

/// The record of a gate's table with every check a calibration of the gate applies to its
/// experiments ([`experiments_from_table`]), so that the close loop refuses what `calibrate`
/// refuses, before any calibration, with the file, line and column: gauge readings beyond
/// ±[`MAX_GAUGE_READING_MICROSTRAIN`], levels outside the gate's domain, too few distinct
/// loaded conditions (every row with the gate open), a gauge that never changes (the last two
/// only for a record with gauges, not for a load history).
pub fn record_from_table(
    table: &Table,
    model: &GateMultiLevel,
    ingest: &IngestConfig,
) -> Result<MeasuredRecord> {
    let gauges: Vec<&str> = ingest.gauge_columns.iter().map(String::as_str).collect();
    let rec = bamudi_closeloop::from_table(table, ingest)?;
    check_gauge_readings(table, &gauges)?;
    crate::gate::check_record(&rec, model)?;
    if gauges.is_empty() {
        return Ok(rec); // a load history (levels only), e.g. `predict --record`
    }
    let loaded: Vec<usize> = (0..rec.len())
        .filter(|&i| {
            !model
                .unobservable
                .response_vanishes(&[rec.x[(i, 0)], rec.x[(i, 1)]])
        })
        .collect();
    check_informative(
        &rec.file,
        &rec.x.select_rows(loaded.iter()),
        &rec.y.select_rows(loaded.iter()),
        &gauges,
        rec.len(),
    )?;
    Ok(rec)
}

/// Checks that the input file `path` of `label` (a flag or argument name) can be read before
/// any work: it exists (a broken symbolic link is named as one), is not a directory, and its
/// metadata can be read (a symbolic-link loop or a permission error is reported as such).
pub fn check_input_file(label: &str, path: &Path) -> Result<()> {
    let shown = path.display();
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => Err(GateAppError::Invalid(format!(
            "{label} {shown}: is a directory, not a file"
        ))),
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let why = match std::fs::read_link(path) {
                Ok(target) => format!(
                    "is a symbolic link to `{}`, which does not exist",
                    target.display()
                ),
                Err(_) => "file does not exist".into(),
            };
            Err(GateAppError::Invalid(format!("{label} {shown}: {why}")))
        }
        Err(e) => Err(GateAppError::Invalid(format!(
            "{label} {shown}: cannot be read: {e}"
        ))),
    }
}

/// The text of the input file `path` of `label` ([`check_input_file`], then
/// [`bamudi::data::read_text`]: a byte that is not UTF-8 is named with its line).
pub fn read_input_text(label: &str, path: &Path) -> Result<String> {
    check_input_file(label, path)?;
    bamudi::data::read_text(path).map_err(|e| {
        let (message, shown) = (e.to_string(), path.display().to_string());
        GateAppError::Invalid(match message.starts_with(&shown) {
            true => format!("{label} {message}"),
            false => format!("{label} {shown}: {message}"),
        })
    })
}

/// The gate configuration of `path` (a gate TOML) or the embedded default, with the mesh
/// `element_size` (in) when given: what `--gate` / `--element-size` and Python's `Gate(path,
/// element_size)` read. A deck (`.inp`) given as a configuration is refused with the way to
/// import it; `labels` name the file and the size in messages (the flags, or the argument
/// names).
pub fn gate_config(
    path: Option<&Path>,
    element_size: Option<f64>,
    labels: (&str, &str),
) -> Result<GateConfig> {
    let (file_label, size_label) = labels;
    let mut cfg = match path {
        Some(p) => {
            let text = read_input_text(file_label, p)?;
            if let Some(line) = deck_keyword_line(p, &text) {
                return Err(GateAppError::Invalid(format!(
                    "{file_label} {}: a finite-element deck (`*` keyword on line {line}), not a \
                     gate configuration (TOML); import a deck with its spec: `--gate-inp {} \
                     --import-spec spec.toml` (Python: `Gate.from_inp`)",
                    p.display(),
                    p.display()
                )));
            }
            gate_config_of_text(&text, p)
                .map_err(|e| GateAppError::Invalid(format!("{file_label} {}: {e}", p.display())))?
        }
        None => GateConfig::default(),
    };
    if let Some(h) = element_size {
        if !(h.is_finite() && h > 0.0 && h <= mitergate::MAX_ELEMENT_SIZE_IN) {
            return Err(GateAppError::Invalid(format!(
                "{size_label} must be in (0, {}] in, got {h}",
                mitergate::MAX_ELEMENT_SIZE_IN
            )));
        }
        cfg.mesh.element_size = h;
        cfg.validate()
            .map_err(|e| GateAppError::Invalid(format!("{size_label} {h}: {e}")))?;
    }
    Ok(cfg)
}

/// A gate configuration parsed from the text of `path` and validated.
fn gate_config_of_text(
    text: &str,
    path: &Path,
) -> std::result::Result<GateConfig, mitergate::GateError> {
    let cfg: GateConfig = toml::from_str(text).map_err(|e| mitergate::GateError::ConfigParse {
        path: Some(path.to_path_buf()),
        message: e.to_string(),
    })?;
    cfg.validate()?;
    Ok(cfg)
}

/// The line of an Abaqus / CalculiX keyword (`*HEADING`, `*NODE`, ...) that starts a
/// finite-element deck, when `text` (of `path`) is one: a `.inp` file, or a first
/// significant line starting with `*`.
fn deck_keyword_line(path: &Path, text: &str) -> Option<usize> {
    let first = text
        .lines()
        .enumerate()
        .find(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))?;
    let inp = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("inp"));
    (inp || first.1.trim_start().starts_with('*')).then_some(first.0 + 1)
}

/// The grid posterior's warnings (mass at a prior bound, an under-resolved interval), which
/// the command line prints and writes into the report, and the Python package logs and keeps.
pub fn posterior_warnings(cal: &Calibration, prior: (f64, f64)) -> Vec<GridWarning> {
    match &cal.module3().posterior {
        ThetaPosterior::Grid(g) => g.warnings(prior),
        ThetaPosterior::Mcmc(_) => vec![],
    }
}

/// The posterior's warnings as lines: a bound warning starts with `key`, the prior's key or
/// flag in the front end (`cal.toml: gap_prior`, `--gap-prior 10,20`, `gap_prior`), so the
/// line names what to widen and which way.
pub fn warning_lines(warnings: &[GridWarning], key: &str) -> Vec<String> {
    warnings
        .iter()
        .map(|w| match w {
            GridWarning::AtPriorBound { .. } => format!("{key}: {w}"),
            GridWarning::UnderResolved { .. } => w.to_string(),
        })
        .collect()
}

/// The warnings of the close loop's final calibration of the gate (the θ posterior against
/// its prior, as [`posterior_warnings`] for `calibrate`), as lines starting with `key`
/// ([`warning_lines`]; none when the loop's model is not a gate calibration), then one per
/// gauge set aside on most of the calibration window ([`set_aside_warnings`]).
pub fn close_loop_warnings(out: &bamudi_closeloop::CloseLoopOutcome, key: &str) -> Vec<String> {
    let set_aside = set_aside_warnings(&out.report);
    let any: &dyn std::any::Any = out.model.as_ref();
    let Some(gate) = any.downcast_ref::<crate::calibrator::CalibratedGate>() else {
        return set_aside;
    };
    let prior = out.model.theta_bounds();
    let key = format!("{key}: the loop's final calibration");
    let lines = warning_lines(&posterior_warnings(gate.calibration(), prior), &key);
    lines
        .into_iter()
        .map(|l| match l.starts_with(&key) {
            true => l,
            false => format!("the loop's final calibration: {l}"),
        })
        .chain(set_aside)
        .collect()
}

/// Gauges set aside so early that fewer than 30 of the calibration window's rows are free of
/// set-aside cells ([`bamudi_closeloop::CalibrationRows::Filled`]): the calibrations then
/// cannot leave those cells out, and fill
/// them with the model's own prediction, from a first calibration that was fitted to the faulty
/// readings, so the fill keeps their imprint and the gap can be confidently wrong (before
/// the loop calibrated on the rows free of set-aside cells, a gauge stuck from day 5 of 60 on
/// the FE gate gave 66 ± 5 in for a gap of 90, filled). A gauge set aside later is left out of the
/// calibration, which reads the rows before it, and is not warned about.
fn set_aside_warnings(r: &bamudi_closeloop::CloseLoopReport) -> Vec<String> {
    let Some(s) = &r.sensor else {
        return vec![];
    };
    let Some(bamudi_closeloop::CalibrationRows::Filled { complete_rows }) = s.calibration_rows
    else {
        return vec![];
    };
    s.findings
        .iter()
        .filter(|f| {
            f.action == bamudi_closeloop::SensorAction::SetAside && f.from_row < r.n_calibration
        })
        .map(|f| {
            let rows = r.n_calibration.min(f.to_row).saturating_sub(f.from_row);
            format!(
                "{} is set aside from day {:.2} ({}), on {:.0} % of the calibration window, and only {complete_rows} rows of the window are free of set-aside cells, too few to calibrate on: its cells are filled with the model's prediction from a calibration the faulty readings shaped, and the gap after ({:.2} ± {:.2}) rests on the other gauges and that fill: treat it as unverified",
                f.gauges.join(", "),
                f.from_day,
                f.kind.name(),
                100.0 * rows as f64 / r.n_calibration.max(1) as f64,
                r.theta_after.mean,
                r.theta_after.sd
            )
        })
        .collect()
}

/// BA-MUDI Modules 2-3 on the gate with the adequacy verdict and the gate's physics checks
/// (what `bamudi calibrate` computes before it writes its results).
pub fn calibrate(
    model: &GateMultiLevel,
    exps: &Experiments,
    config: &CalibrationConfig,
    observer: &dyn Observer,
) -> Result<Calibration> {
    let mut cal = Calibrate::new(config).observer(observer).run(model, exps)?;
    crate::physics::add_physics_checks(&mut cal, model, exps, config)?;
    Ok(cal)
}

/// The paper's synthetic experiments of `scenario` (Sec. 4.3) with `truth` as the true
/// contact model and the reality's sensor behaviour applied; columns `h_up`, `h_down` (in)
/// and one per gauge (microstrain).
pub fn simulate_experiments(
    scenario: &Scenario,
    truth_contact: &ContactModel,
    reality: &Reality,
) -> Result<Experiments> {
    let e = truth::generate(scenario, truth_contact)?;
    let names = truth_contact.gate().gauge_names.clone();
    let n = e.x.len();
    let mut y = DMatrix::from_fn(n, names.len(), |i, j| e.strains[i][j]);
    for i in 0..n {
        let mut row: Vec<Option<f64>> = y.row(i).iter().map(|v| Some(*v)).collect();
        reality.apply_sensors(&names, i as f64 / (n - 1).max(1) as f64, &mut row);
        for (j, v) in row.into_iter().enumerate() {
            y[(i, j)] = v.unwrap_or(f64::NAN);
        }
    }
    let x = DMatrix::from_fn(n, 2, |i, j| e.x[i][j]);
    Ok(Experiments::new(
        vec!["h_up".into(), "h_down".into()],
        names,
        x,
        y,
    )?)
}

/// The close loop's gate calibrator with the command line's settings: at most
/// `max_experiments` rows per calibration, the gauge noise (microstrain) when known, the
/// calibration configuration when given (else the calibrator's default), the seed when given.
pub fn gate_calibrator(
    contact: ContactModel,
    prior: (f64, f64),
    max_experiments: usize,
    gauge_noise_sd: Option<f64>,
    config: Option<CalibrationConfig>,
    seed: Option<u64>,
) -> Result<GateCalibrator> {
    let mut calibrator = GateCalibrator::new(contact, prior)?.max_experiments(max_experiments);
    if let Some(cfg) = config {
        calibrator = calibrator.config(cfg);
    }
    if let Some(sd) = gauge_noise_sd {
        calibrator = calibrator.gauge_noise_sd(sd)?;
    }
    if let Some(s) = seed {
        let params = calibrator
            .calibration_config()
            .clone()
            .into_params()
            .seed(s);
        calibrator = calibrator.config(params.check()?);
    }
    Ok(calibrator)
}

/// A close-loop configuration from TOML text (missing keys take their defaults), checked.
pub fn close_loop_config_from_toml(text: &str) -> Result<bamudi_closeloop::CloseLoopConfig> {
    let cfg: bamudi_closeloop::CloseLoopConfig =
        toml::from_str(text).map_err(|e| GateAppError::Serde {
            context: "close-loop configuration (TOML)".into(),
            reason: e.to_string(),
        })?;
    cfg.validate()?;
    Ok(cfg)
}

/// The finite-element deck (`.inp`, Abaqus / CalculiX) of a configured gate and its import
/// spec (TOML): what `--gate-inp` / `--import-spec` and the Python `Gate.from_inp` read back
/// (a starting point for a deck of your own gate; re-imported, it condenses to the same
/// model to round-off, docs/verification.md). The deck's load step is the full head.
pub fn export_deck(cfg: &GateConfig) -> Result<(String, String)> {
    let gate = mitergate::GateModel::build(cfg)?;
    let deck = mitergate::inp::export_gate(&gate, &mitergate::inp::ExportOptions::default())?;
    let spec = toml::to_string(&ImportSpec::for_exported_gate(&gate)).map_err(|e| {
        GateAppError::Serde {
            context: "the import spec (TOML)".into(),
            reason: e.to_string(),
        }
    })?;
    Ok((deck, spec))
}

#[cfg(test)]
mod tests {
    use super::*;
    use bamudi_closeloop::testing::{GridCalibrator, ToyGate, record_with, toy_load};
    use bamudi_closeloop::{CloseLoopConfig, close_loop};

    /// A gauge stuck from hour 20 of a 45-day toy record leaves 20 rows of the 648-row
    /// calibration window free of set-aside cells, too few to calibrate on: its cells are filled
    /// and the warning names it. Stuck from hour 48 (48 rows free) or 600, the calibrations
    /// leave it out instead and nothing is warned.
    #[test]
    fn a_gauge_set_aside_too_early_to_leave_out_is_warned_about() {
        let cfg = CloseLoopConfig::default()
            .load(toy_load())
            .parameter_name("gap")
            .column_unit("air_temp_f", "degF");
        for (at, warned) in [(20usize, true), (48, false), (600, false)] {
            let mut rec = record_with(&ToyGate::default(), 1080, 41, |_, _| 0.0).unwrap();
            let v = rec.y[(at - 1, 3)];
            for i in at..rec.len() {
                rec.y[(i, 3)] = v;
            }
            let cal = GridCalibrator::new(ToyGate::default(), (40.0, 200.0));
            let out = close_loop(&rec, &cal, &cfg).unwrap();
            let w = set_aside_warnings(&out.report);
            assert_eq!(!w.is_empty(), warned, "stuck from row {at}: {w:?}");
            if warned {
                assert!(w[0].starts_with("g4 is set aside"), "{w:?}");
                assert!(w[0].contains("treat it as unverified"), "{w:?}");
            }
        }
    }
}
