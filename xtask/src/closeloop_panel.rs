//! `cargo xtask closeloop-panel`: the close loop on records with effects nobody declared.
//!
//! Each record is a simulated 60-day field record of the FE gate (`mitergate::data::field`,
//! gap 90 in, 1 microstrain noise, no effect of the simulator switched on), into which ONE
//! undeclared effect is written after the fact, in a shape the loop's effect library does not
//! hold: the panel knows the truth, the loop does not. Kinds (sensor, structural, operational,
//! environmental), each on its own gauges, at three magnitudes (barely visible, moderate,
//! large) and three onsets (early = day 5, middle = day 30, late = day 50, in the test
//! window), `--seeds` seeds per cell, plus `--clean` records with no effect for the false
//! findings. Scored per record: the right cause named, the test-window RMSE after within 1.5x
//! the noise sd, the gap's 95 % interval holding the gap at the end of the record, a gap alarm
//! on a record whose only change is a sensor fault, the wall time, and, for a gain, an offset
//! step or a drift named by a sized sensor finding on the right gauge, whether the finding's
//! 95 % interval holds the size written.
//!
//! Each record is appended to `<json>.jsonl` as it finishes; a re-run with the same settings
//! skips the records already there, so the panel can be stopped and resumed in parts
//! (`--kinds`, `--magnitudes`, `--onsets`, `--seeds`). The table and the JSON are rewritten
//! (atomically) from every record of the plan at the end.
//!
//! Tuning and validation: the sensor pass's penalties are the event scan's modified BIC,
//! `3 ln n`, and `2 ln m` for choosing among `m` sensor hypotheses; `min_span_rows` 12 was set
//! before any record was run. Two settings of the noise scan were tuned here, on seeds 1 and 2
//! of the `noise` kind only (18 records): `noise_ratio` 1.5 (it was 2, the panel's small noise
//! increase) and the noise scan's load-motion test on the quiet rows (`sensor.rs`,
//! `moves_with_the_load`). Their validation is on the seeds from 1000 on, on the clean records
//! 2020-2039, and on the held-out shape `noise-rise` ([`HELDOUT_KINDS`]: a gradual rise on
//! another gauge to other ratios), which played no part in the tuning. Should another
//! threshold be tuned here, tune it on seeds 1 and 2 of the kinds `gain`, `offset-step`,
//! `exchange` (or `noise`) only and keep the other kinds (`stuck`, `dead`, `drift`, `gap-step`,
//! `gap-growth`, `lockage-lag`, `sun`, `wall-flexure`, `noise-rise`) and the validation seeds
//! (from 1000 on) for validation: the held-out part. Three cells of seed 1000 shaped the
//! design and are design cases, not held-out ones (docs/closeloop.md, "The panel"): a gain from
//! day 30 and from day 5, and a gauge stuck from day 5.
use anyhow::{Context, Result, bail};
use bamudi_closeloop::{CloseLoopConfig, CloseLoopReport, MeasuredRecord, SensorKind, close_loop};
use bamudi_gate::calibrator::GateCalibrator;
use bamudi_gate::gate;
use mitergate::ContactModel;
use mitergate::GateConfig;
use mitergate::data::field::FieldConfig;
use nalgebra::DMatrix;
use serde_json::json;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Every kind the panel can write into a record; the first seven are sensor faults.
pub const KINDS: [&str; 12] = [
    "gain",
    "offset-step",
    "drift",
    "exchange",
    "stuck",
    "dead",
    "noise",
    "gap-step",
    "gap-growth",
    "lockage-lag",
    "sun",
    "wall-flexure",
];

/// Kinds the panel writes only when asked by name (`--kinds`): shapes kept out of every
/// threshold tuned on the panel, for validating one. `noise-rise`: a gauge's noise sd growing
/// linearly over five days from the onset to `NOISE_RISE_RATIOS` (not a step), on SG2, at
/// ratios the `noise` kind does not write; the held-out shape of the noise scan's settings
/// (tuned on seeds 1-2 of `noise`).
pub const HELDOUT_KINDS: [&str; 1] = ["noise-rise"];

/// Whether a kind is a sensor fault (the first seven of [`KINDS`] and the held-out noise rise).
fn is_sensor(kind: &str) -> bool {
    KINDS[..7].contains(&kind) || kind == "noise-rise"
}

/// The noise sd ratios a `noise-rise` reaches, small / medium / large, and the days it takes.
const NOISE_RISE_RATIOS: [f64; 3] = [1.7, 2.5, 4.0];
const NOISE_RISE_DAYS: f64 = 5.0;

/// The noise sd ratio of a `noise-rise` record at day `d` after its onset.
fn noise_rise_ratio(level: usize, d: f64) -> f64 {
    1.0 + (NOISE_RISE_RATIOS[level] - 1.0) * (d / NOISE_RISE_DAYS).clamp(0.0, 1.0)
}

/// The sizes written by the kinds a sensor finding sizes, small / medium / large: a gain change
/// (fraction), an offset step (microstrain), a drift (microstrain per day).
const SIZES: [[f64; 3]; 3] = [[0.02, 0.05, 0.10], [3.0, 8.0, 20.0], [0.05, 0.15, 0.4]];

/// The noise sd ratios of a noise increase, small / medium / large.
const NOISE_RATIOS: [f64; 3] = [2.0, 3.0, 5.0];

#[derive(clap::Args)]
pub struct PanelArgs {
    /// Kinds, comma separated (default: all twelve).
    #[arg(long)]
    kinds: Option<String>,
    /// Magnitudes, comma separated: small, medium, large.
    #[arg(long, default_value = "small,medium,large")]
    magnitudes: String,
    /// Onsets, comma separated: early (day 5), middle (day 30), late (day 50).
    #[arg(long, default_value = "early,middle,late")]
    onsets: String,
    /// Seeds per cell (validation seeds `first_seed`, `first_seed + 1`, ...).
    #[arg(long, default_value_t = 5)]
    seeds: u64,
    /// First seed of each cell.
    #[arg(long, default_value_t = 1000)]
    first_seed: u64,
    /// Clean records (no effect) for the false-finding count.
    #[arg(long, default_value_t = 20)]
    clean: u64,
    /// Seed of the first clean record (the design's are 2000-2019; another range is a
    /// held-out set of clean records).
    #[arg(long, default_value_t = 2000)]
    first_clean_seed: u64,
    /// Mesh element size (in).
    #[arg(long, default_value_t = 24.0)]
    mesh: f64,
    /// Sampling step of the records (minutes).
    #[arg(long, default_value_t = 60.0)]
    step_minutes: f64,
    /// Propagation draws of the effects' parameters (the loop's `sensor.uncertainty_draws`).
    #[arg(long)]
    draws: Option<usize>,
    /// Markdown table.
    #[arg(long, default_value = "docs/results/closeloop-panel.md")]
    out: PathBuf,
    /// JSON of every record.
    #[arg(long, default_value = "docs/results/closeloop-panel.json")]
    json: PathBuf,
    /// Score the oracle of every record of the plan again (the records are simulated again,
    /// not run), as when its definition changed.
    #[arg(long)]
    rescore_oracle: bool,
    /// Also write each record's whole report (`results.json` of `bamudi close-loop`) into this
    /// folder as `<kind>-<magnitude>-<onset>-<seed>.json`, for reading one record in full.
    #[arg(long)]
    reports: Option<PathBuf>,
    /// The loop's settings: a close-loop configuration (TOML, the format `bamudi close-loop
    /// --config` reads; missing keys take their defaults), for comparing a setting on the
    /// same records. Its file name enters each record's key, so a panel run with it neither
    /// skips nor overwrites the records run without it.
    #[arg(long)]
    config: Option<PathBuf>,
}

/// One record's score.
struct Score {
    kind: String,
    magnitude: String,
    onset: String,
    seed: u64,
    cause: bool,
    rmse_ratio: f64,
    covered: bool,
    gap_alarm: bool,
    false_finding: bool,
    wall_s: f64,
    named: String,
    /// For a gain, offset step or drift named by a sized sensor finding on the right gauge:
    /// whether the finding's 95 % interval (size ± 1.96 sd) holds the size written.
    size_held: Option<bool>,
    /// Which corrections `rmse_ratio` was fitted with on the test rows too ([`test_rmse`]).
    in_sample: InSample,
    /// What an oracle could detect in the record ([`Oracle`]); `None` on a clean record.
    oracle: Option<Oracle>,
}

/// What an oracle that knows the written effect's shape, gauges and onset could detect in a
/// record: the best any method could do with these readings. `lambda` is the noncentrality of
/// its test of one size: the written change's sum of squares over the noise variance (for a
/// noise increase by `r` on `m` rows, twice the expected log likelihood ratio of the variance
/// change, `m (r² − 1 − ln r²)`, summed row by row for a noise rise); `power` is the test's power at the 1 % level (χ²₁ with
/// noncentrality `lambda` above its 99 % quantile). It is an upper bound: nothing of the effect
/// is absorbed by the calibration's discrepancy, and nothing is searched for (the loop chooses
/// among kinds, gauges and onsets and pays for it).
#[derive(Clone, Copy)]
struct Oracle {
    lambda: f64,
    power: f64,
}

/// The 99 % quantile of χ² with one degree of freedom: the oracle's test level.
const ORACLE_CHI2_99: f64 = 6.634_896_601;

/// Power at least this the oracle detects the record's effect reliably (the panel's summary).
const ORACLE_RELIABLE: f64 = 0.9;

impl Oracle {
    /// From the readings before (`y0`, noisy) and after (`y1`) the effect of `kind` at
    /// magnitude `level` was written from row `first`, and the noise sd. Where the written
    /// change carries the readings' noise (a stuck or dead gauge replaces a noisy reading, an
    /// exchange swaps two, a gain scales one), that noise's expected share of the sum of
    /// squares is taken out: `λ` is the change's own.
    fn new(
        kind: &str,
        level: usize,
        (first, onset): (usize, f64),
        time_h: &[f64],
        (y0, y1): (&DMatrix<f64>, &DMatrix<f64>),
        noise: f64,
    ) -> Self {
        let d = y1 - y0;
        let changed = d.iter().filter(|v| **v != 0.0).count() as f64;
        // the noise variance each changed cell's square carries, in noise variances
        let carried = match kind {
            "stuck" | "dead" => 1.0,
            "exchange" => 2.0,
            "gain" => SIZES[0][level].powi(2),
            _ => 0.0,
        };
        let lambda = match kind {
            "noise" => {
                let (m, r2) = ((y0.nrows() - first) as f64, NOISE_RATIOS[level].powi(2));
                m * (r2 - 1.0 - r2.ln())
            }
            "noise-rise" => time_h[first..]
                .iter()
                .map(|t| {
                    let r2 = noise_rise_ratio(level, t / 24.0 - onset).powi(2);
                    r2 - 1.0 - r2.ln()
                })
                .sum(),
            _ => (d.iter().map(|v| v * v).sum::<f64>() / (noise * noise) - carried * changed)
                .max(0.0),
        };
        // P(|Z + √λ| > √c), Z standard normal
        let (c, l) = (ORACLE_CHI2_99.sqrt(), lambda.sqrt());
        let phi = |z: f64| 0.5 * statrs::function::erf::erfc(-z / std::f64::consts::SQRT_2);
        Oracle {
            lambda,
            power: phi(-c - l) + 1.0 - phi(c - l),
        }
    }
}

/// What the scored test error was fitted on ([`test_rmse`]).
#[derive(Clone, Copy, PartialEq)]
enum InSample {
    /// Every correction fitted on rows before the test window.
    No,
    /// A sensor correction whose span reaches into the test window, fitted over the span.
    Sensor,
    /// The gap's change from the test window, fitted there.
    Gap,
    /// An effect from an onset after the calibration window, fitted on the rows from it.
    Onset,
}

pub fn run(args: &PanelArgs) -> Result<()> {
    // the loop's warnings (a failed re-calibration, ...) and, with RUST_LOG=info, its trace
    bamudi_gate::progress::init_logging(false);
    let kinds: Vec<String> = match &args.kinds {
        Some(k) => k.split(',').map(|s| s.trim().to_string()).collect(),
        None => KINDS.iter().map(|s| s.to_string()).collect(),
    };
    if let Some(k) = kinds
        .iter()
        .find(|k| !KINDS.contains(&k.as_str()) && !HELDOUT_KINDS.contains(&k.as_str()))
    {
        bail!(
            "unknown kind `{k}`; expected one of {} (or, by name only, {})",
            KINDS.join(", "),
            HELDOUT_KINDS.join(", ")
        );
    }
    let mut cfg = GateConfig::default();
    cfg.mesh.element_size = args.mesh;
    let (contact, _, _) = gate::build(&cfg)?;
    // written as it goes, one JSON line per record; a re-run skips the records already there
    let progress = args.json.with_extension("jsonl");
    let mut done = read_progress(&progress)?;
    let mut plan: Vec<(String, String, String, u64)> = (0..args.clean)
        .map(|c| {
            let seed = args.first_clean_seed + c;
            ("clean".into(), "none".into(), "none".into(), seed)
        })
        .collect();
    for kind in &kinds {
        for magnitude in args.magnitudes.split(',') {
            for onset in args.onsets.split(',') {
                for k in 0..args.seeds {
                    plan.push((
                        kind.clone(),
                        magnitude.into(),
                        onset.into(),
                        args.first_seed + k,
                    ));
                }
            }
        }
    }
    let mut scores = vec![];
    let mut records = vec![];
    for (kind, magnitude, onset, seed) in &plan {
        let key = record_key(kind, magnitude, onset, *seed, args);
        let j = match done.remove(&key) {
            // a record run before the oracle was scored: the record is simulated again (no
            // loop) for it, and the line appended again with it (the last line of a key wins)
            Some(mut j) if args.rescore_oracle || j.get("oracle").is_none() => {
                let p = prepare(args, &contact, kind, magnitude, onset, *seed)?;
                j["oracle"] = oracle_json(p.oracle);
                append_line(&progress, &j)?;
                j
            }
            Some(j) => j,
            None => {
                let (_, mut j) = one(args, &contact, kind, magnitude, onset, *seed)?;
                j["key"] = json!(key);
                append_line(&progress, &j)?;
                j
            }
        };
        scores.push(score_of(&j)?);
        records.push(j);
    }
    // the progress file rewritten with one line per record (a record scored again was appended
    // again): the records of other plans first, by key, then this plan's; read again first,
    // so that lines another run appended meanwhile are kept
    let mine: std::collections::HashSet<&str> =
        records.iter().filter_map(|j| j["key"].as_str()).collect();
    let mut others: Vec<serde_json::Value> = read_progress(&progress)?
        .into_iter()
        .filter(|(k, _)| !mine.contains(k.as_str()))
        .map(|(_, j)| j)
        .collect();
    others.sort_by(|a, b| a["key"].as_str().cmp(&b["key"].as_str()));
    let mut lines = String::new();
    for j in others.iter().chain(&records) {
        lines += &serde_json::to_string(j)?;
        lines.push('\n');
    }
    write_atomic(&progress, lines.as_bytes())?;
    let md = table(&scores, args);
    if let Some(p) = args.out.parent() {
        std::fs::create_dir_all(p)?;
    }
    write_atomic(&args.out, md.as_bytes())?;
    write_atomic(
        &args.json,
        serde_json::to_string_pretty(&records)?.as_bytes(),
    )?;
    println!("{md}");
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename.
fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("{}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("{}", path.display()))?;
    Ok(())
}

/// What identifies a record in the progress file: its cell, its seed and the settings that
/// change its outcome.
fn record_key(kind: &str, magnitude: &str, onset: &str, seed: u64, args: &PanelArgs) -> String {
    let key = format!(
        "{kind}/{magnitude}/{onset}/{seed}/mesh {}/step {}/draws {:?}",
        args.mesh, args.step_minutes, args.draws
    );
    match &args.config {
        Some(p) => format!(
            "{key}/config {}",
            p.file_name().unwrap_or(p.as_os_str()).to_string_lossy()
        ),
        None => key,
    }
}

/// The records already in the progress file, by key (none when it does not exist).
fn read_progress(
    path: &std::path::Path,
) -> Result<std::collections::HashMap<String, serde_json::Value>> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(Default::default());
    };
    let mut out = std::collections::HashMap::new();
    for (k, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let j: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("{} line {}: not a panel record", path.display(), k + 1))?;
        let key = j["key"]
            .as_str()
            .with_context(|| format!("{} line {}: no key", path.display(), k + 1))?
            .to_string();
        out.insert(key, j);
    }
    Ok(out)
}

/// Appends one record to the progress file and flushes it.
fn append_line(path: &std::path::Path, j: &serde_json::Value) -> Result<()> {
    use std::io::Write as _;
    if let Some(p) = path.parent() {
        std::fs::create_dir_all(p)?;
    }
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("{}", path.display()))?;
    writeln!(f, "{}", serde_json::to_string(j)?)?;
    f.sync_data()?;
    Ok(())
}

/// A record's score from its JSON line.
fn score_of(j: &serde_json::Value) -> Result<Score> {
    let s = |k: &str| {
        j[k].as_str()
            .map(str::to_string)
            .context(format!("record without {k}"))
    };
    let b = |k: &str| j[k].as_bool().context(format!("record without {k}"));
    let f = |k: &str| j[k].as_f64().context(format!("record without {k}"));
    Ok(Score {
        kind: s("kind")?,
        magnitude: s("magnitude")?,
        onset: s("onset")?,
        seed: j["seed"].as_u64().context("record without seed")?,
        cause: b("cause_named")?,
        rmse_ratio: j["rmse_ratio"].as_f64().unwrap_or(f64::NAN),
        covered: b("covered")?,
        gap_alarm: b("gap_alarm")?,
        false_finding: b("false_finding")?,
        wall_s: f("wall_time_s")?,
        named: s("named")?,
        size_held: size_held(j),
        oracle: j["oracle"]["lambda"]
            .as_f64()
            .zip(j["oracle"]["power_at_1_percent"].as_f64())
            .map(|(lambda, power)| Oracle { lambda, power }),
        in_sample: if j["parameter_correction"]["fitted_on_error_rows"].as_bool() == Some(true) {
            InSample::Gap
        } else if j["sensor"]["fitted_on_test_rows"].as_bool() == Some(true) {
            InSample::Sensor
        } else if j["onset_effects"]["added"]
            .as_array()
            .is_some_and(|a| !a.is_empty())
        {
            InSample::Onset
        } else {
            InSample::No
        },
    })
}

/// Whether the right sensor finding's 95 % interval holds the size written into the record
/// (`None` for the kinds without a size, or when no sized finding of the kind is on the right
/// gauge: the cause column says whether it was named otherwise).
fn size_held(j: &serde_json::Value) -> Option<bool> {
    let (kind, magnitude) = (j["kind"].as_str()?, j["magnitude"].as_str()?);
    let (row, kinds): (usize, &[&str]) = match kind {
        "gain" => (0, &["gain"]),
        "offset-step" => (1, &["step", "offset"]),
        "drift" => (2, &["drift"]),
        _ => return None,
    };
    let truth = SIZES[row][level(magnitude).ok()?];
    let gauges: Vec<String> = gauges_of(kind)
        .into_iter()
        .map(|g| format!("SG{}", g + 1))
        .collect();
    let f = j["sensor"]["findings"].as_array()?.iter().find(|f| {
        kinds.contains(&f["kind"].as_str().unwrap_or(""))
            && f["gauges"]
                .as_array()
                .is_some_and(|g| g.iter().all(|g| gauges.iter().any(|x| x == g)))
            && f["size"].is_number()
    })?;
    let (size, sd) = (f["size"].as_f64()?, f["size_sd"].as_f64()?);
    Some((size - truth).abs() <= 1.96 * sd)
}

/// Day of an onset name.
fn onset_day(onset: &str) -> Result<f64> {
    Ok(match onset {
        "early" => 5.0,
        "middle" => 30.0,
        "late" => 50.0,
        "none" => f64::INFINITY,
        o => bail!("unknown onset `{o}` (early, middle, late)"),
    })
}

/// Index 0, 1, 2 of a magnitude name.
fn level(m: &str) -> Result<usize> {
    Ok(match m {
        "small" => 0,
        "medium" => 1,
        "large" => 2,
        "none" => 0,
        o => bail!("unknown magnitude `{o}` (small, medium, large)"),
    })
}

/// The gauges each kind is written on (0-based), different per kind.
fn gauges_of(kind: &str) -> Vec<usize> {
    match kind {
        "gain" => vec![2],
        "offset-step" => vec![5],
        "drift" => vec![0],
        "exchange" => vec![1, 4],
        "stuck" => vec![3],
        "dead" => vec![6],
        "noise" => vec![4],
        "noise-rise" => vec![1],
        "lockage-lag" => vec![0, 3],
        "sun" => vec![1, 2, 5],
        "wall-flexure" => vec![2, 4, 6],
        _ => vec![],
    }
}

/// Writes the undeclared effect into the record; returns the gap at the end of the record.
fn inject(
    rec: &mut MeasuredRecord,
    contact: &ContactModel,
    kind: &str,
    magnitude: usize,
    onset: f64,
    seed: u64,
) -> Result<f64> {
    let n = rec.len();
    let day = |i: usize| rec.time_h[i] / 24.0;
    let after: Vec<bool> = (0..n).map(|i| day(i) >= onset).collect();
    let first = after.iter().position(|&a| a).unwrap_or(n);
    let gs = gauges_of(kind);
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut normal = move || {
        // a seeded Box-Muller pair from a 64-bit LCG (the panel's only randomness)
        let mut u = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (u(), u());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    };
    let col = |rec: &MeasuredRecord, name: &str| {
        rec.covariate_names.iter().position(|c| c == name).map(|j| {
            rec.covariates
                .column(j)
                .iter()
                .copied()
                .collect::<Vec<f64>>()
        })
    };
    let gap0 = 90.0;
    let mut gap_end = gap0;
    match kind {
        "gain" => {
            let k = SIZES[0][magnitude];
            for i in first..n {
                rec.y[(i, gs[0])] *= 1.0 + k;
            }
        }
        "offset-step" => {
            let s = SIZES[1][magnitude];
            for i in first..n {
                rec.y[(i, gs[0])] += s;
            }
        }
        "drift" => {
            let rate = SIZES[2][magnitude];
            for i in first..n {
                rec.y[(i, gs[0])] += rate * (day(i) - onset);
            }
        }
        "exchange" => {
            let (a, b) = (gs[0], gs[1]);
            for i in first..n {
                rec.y.swap((i, a), (i, b));
            }
        }
        "stuck" => {
            let v = rec.y[(first.saturating_sub(1), gs[0])];
            for i in first..n {
                rec.y[(i, gs[0])] = v;
            }
        }
        "dead" => {
            for i in first..n {
                rec.y[(i, gs[0])] = 0.0;
            }
        }
        "noise" => {
            let ratio = NOISE_RATIOS[magnitude];
            let extra = (ratio * ratio - 1.0).sqrt();
            for i in first..n {
                rec.y[(i, gs[0])] += extra * normal();
            }
        }
        "noise-rise" => {
            for i in first..n {
                let ratio = noise_rise_ratio(magnitude, day(i) - onset);
                rec.y[(i, gs[0])] += (ratio * ratio - 1.0).sqrt() * normal();
            }
        }
        "gap-step" | "gap-growth" => {
            let d = [3.0, 8.0, 20.0][magnitude];
            let end = day(n - 1);
            for i in first..n {
                let gap = match kind {
                    "gap-step" => gap0 + d,
                    _ => gap0 + d * (day(i) - onset) / (end - onset).max(1e-9),
                };
                let (hu, hd) = (rec.x[(i, 0)], rec.x[(i, 1)]);
                let s1 = strain(contact, hu, hd, gap)?;
                let s0 = strain(contact, hu, hd, gap0)?;
                for g in 0..rec.y.ncols() {
                    rec.y[(i, g)] += s1[g] - s0[g];
                }
                gap_end = gap;
            }
        }
        "lockage-lag" => {
            // a response that follows each fill start with a 2 h delay and a 6 h decay
            let amp = [1.0, 3.0, 8.0][magnitude];
            let phase = col(rec, "lockage_phase").context("the record has no lockage_phase")?;
            let starts: Vec<f64> = (1..n)
                .filter(|&i| phase[i] == 1.0 && phase[i - 1] != 1.0)
                .map(|i| rec.time_h[i])
                .collect();
            for i in first..n {
                let t = rec.time_h[i];
                let resp: f64 = starts
                    .iter()
                    .map(|&s| t - s - 2.0)
                    .filter(|&u| u >= 0.0)
                    .map(|u| (-u / 6.0).exp())
                    .sum();
                for (j, &g) in gs.iter().enumerate() {
                    rec.y[(i, g)] += amp * resp * if j == 0 { 1.0 } else { -0.6 };
                }
            }
        }
        "sun" => {
            // sun on the gauges: a half-wave daily cycle peaking at 13 h, random phase per seed
            let amp = [1.0, 3.0, 8.0][magnitude];
            let shift = (seed % 5) as f64 - 2.0;
            for i in first..n {
                let h = (rec.start_unix_s / 3600.0 + rec.time_h[i]).rem_euclid(24.0);
                let s = (std::f64::consts::PI * (h - 7.0 - shift) / 12.0)
                    .sin()
                    .max(0.0);
                for (j, &g) in gs.iter().enumerate() {
                    rec.y[(i, g)] += amp * s * [1.0, -0.7, 0.5][j];
                }
            }
        }
        "wall-flexure" => {
            let c = [0.1, 0.3, 0.8][magnitude];
            let up = col(rec, "upper_pool").context("the record has no upper_pool")?;
            let mean = up.iter().sum::<f64>() / n as f64;
            for i in first..n {
                for (j, &g) in gs.iter().enumerate() {
                    rec.y[(i, g)] += c * (up[i] - mean) * [1.0, -0.8, 0.6][j];
                }
            }
        }
        "none" | "clean" => {}
        k => bail!("unknown kind `{k}`"),
    }
    Ok(gap_end)
}

fn strain(contact: &ContactModel, hu: f64, hd: f64, gap: f64) -> Result<Vec<f64>> {
    let sol = contact.solve(hu, hd, gap)?;
    Ok(contact
        .gate()
        .strain(&sol.forces, hu, hd)
        .as_slice()
        .to_vec())
}

/// One record before the loop: simulated, its effect written in.
struct Prepared {
    rec: MeasuredRecord,
    calibrator: GateCalibrator,
    noise: f64,
    gap_end: f64,
    /// `None` on a clean record.
    oracle: Option<Oracle>,
}

/// Simulates a record and writes its effect in ([`inject`]).
fn prepare(
    args: &PanelArgs,
    contact: &ContactModel,
    kind: &str,
    magnitude: &str,
    onset: &str,
    seed: u64,
) -> Result<Prepared> {
    let fc = FieldConfig::default()
        .seed(seed)
        .duration(60.0, args.step_minutes);
    let field = gate::simulate_field(&fc, contact)?;
    let calibrator = GateCalibrator::new(contact.clone(), (60.0, 150.0))?;
    let mut rec = gate::as_measured(&field, calibrator.model(), "panel.csv")?;
    let y0 = rec.y.clone();
    let (level, onset) = (level(magnitude)?, onset_day(onset)?);
    let gap_end = inject(&mut rec, contact, kind, level, onset, seed)?;
    let noise = fc.noise_sd_microstrain;
    let first = rec.time_h.iter().position(|t| t / 24.0 >= onset);
    let oracle = first
        .filter(|_| kind != "clean")
        .map(|f| Oracle::new(kind, level, (f, onset), &rec.time_h, (&y0, &rec.y), noise));
    Ok(Prepared {
        rec,
        calibrator,
        noise,
        gap_end,
        oracle,
    })
}

/// One record: simulate, inject, run the loop, score.
fn one(
    args: &PanelArgs,
    contact: &ContactModel,
    kind: &str,
    magnitude: &str,
    onset: &str,
    seed: u64,
) -> Result<(Score, serde_json::Value)> {
    let Prepared {
        rec,
        calibrator,
        noise,
        gap_end,
        oracle,
    } = prepare(args, contact, kind, magnitude, onset, seed)?;
    let base = match &args.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("--config: reading {}", p.display()))?;
            bamudi_gate::session::close_loop_config_from_toml(&text)
                .with_context(|| format!("--config {}", p.display()))?
        }
        None => CloseLoopConfig::default(),
    };
    let mut cfg = gate::close_loop_config(base, &rec);
    if let Some(d) = args.draws {
        cfg.sensor.uncertainty_draws = d;
    }
    let t = Instant::now();
    let out = close_loop(&rec, &calibrator, &cfg)?;
    let wall_s = t.elapsed().as_secs_f64();
    let r = &out.report;
    if let Some(dir) = &args.reports {
        std::fs::create_dir_all(dir).with_context(|| format!("{}", dir.display()))?;
        let path = dir.join(format!("{kind}-{magnitude}-{onset}-{seed}.json"));
        write_atomic(&path, serde_json::to_string_pretty(r)?.as_bytes())?;
    }
    let score = score(r, kind, magnitude, onset, seed, gap_end, noise, wall_s);
    eprintln!(
        "{kind} {magnitude} {onset} seed {seed}: cause {} ({}), rmse/noise {:.2}, gap {:.2} ± {:.2} (truth {gap_end}), {wall_s:.0} s",
        score.cause, score.named, score.rmse_ratio, r.theta_after.mean, r.theta_after.sd
    );
    let j = json!({
        "kind": kind, "magnitude": magnitude, "onset": onset, "seed": seed,
        "gap_truth_end": gap_end, "cause_named": score.cause, "named": score.named,
        "rmse_ratio": score.rmse_ratio, "covered": score.covered, "gap_alarm": score.gap_alarm,
        "rmse_ratio_out_of_sample": r.heldout_rmse_total_after / noise,
        "false_finding": score.false_finding, "wall_time_s": wall_s,
        "theta_after": r.theta_after, "theta_before": r.theta_before,
        "effects": r.effects.iter().map(|e| (e.name.clone(), e.covariates.clone())).collect::<Vec<_>>(),
        "sensor": r.sensor, "alarms": r.alarms, "conclusion": r.conclusion,
        "parameter_correction": r.parameter_correction, "onset_effects": r.onset,
        "oracle": oracle_json(oracle),
    });
    Ok((score, j))
}

/// A record's oracle in its JSON line (`null` on a clean record).
fn oracle_json(o: Option<Oracle>) -> serde_json::Value {
    o.map_or(
        serde_json::Value::Null,
        |o| json!({"lambda": o.lambda, "power_at_1_percent": o.power}),
    )
}

/// What the loop named: its effects, sensor findings and alarms, in one line.
fn named(r: &CloseLoopReport) -> String {
    let mut v: Vec<String> = r
        .effects
        .iter()
        .map(|e| format!("{}({})", e.name, e.covariates.join(",")))
        .collect();
    if let Some(s) = &r.sensor {
        v.extend(
            s.findings
                .iter()
                .map(|f| format!("{}[{}]", f.kind.name(), f.gauges.join(","))),
        );
    }
    v.extend(r.alarms.iter().map(|a| format!("alarm[{}]", a.subject)));
    v.join(" ")
}

#[allow(clippy::too_many_arguments)]
fn score(
    r: &CloseLoopReport,
    kind: &str,
    magnitude: &str,
    onset: &str,
    seed: u64,
    gap_end: f64,
    noise: f64,
    wall_s: f64,
) -> Score {
    let gauge = |g: usize| format!("SG{}", g + 1);
    let gs: Vec<String> = gauges_of(kind).into_iter().map(gauge).collect();
    let finding = |k: &[SensorKind]| {
        r.sensor.as_ref().is_some_and(|s| {
            s.findings
                .iter()
                .any(|f| k.contains(&f.kind) && f.gauges.iter().all(|g| gs.contains(g)))
        })
    };
    let effect = |name: &str, cov: &[&str]| {
        r.effects.iter().any(|e| {
            e.name == name
                && (cov.is_empty()
                    || e.covariates
                        .iter()
                        .any(|c| cov.iter().any(|w| c.contains(w))))
        })
    };
    let gap_alarm = r.alarms.iter().any(|a| a.subject == "parameter");
    let gauge_alarm = r.alarms.iter().any(|a| gs.contains(&a.subject));
    let sensor_any = r.sensor.as_ref().is_some_and(|s| !s.findings.is_empty());
    let cause = match kind {
        "gain" => finding(&[SensorKind::Gain]),
        "offset-step" => {
            finding(&[SensorKind::Step, SensorKind::Offset])
                || effect("gauge_offset_jump", &[])
                || gauge_alarm
        }
        "drift" => finding(&[SensorKind::Drift]) || effect("gauge_drift", &[]),
        // on the right side of its day: exchanged from within a day of the onset to the end
        // (the other labelling, the readings before the day exchanged, is the wrong wiring)
        "exchange" => r.sensor.as_ref().is_some_and(|s| {
            s.findings.iter().any(|f| {
                f.kind == SensorKind::ChannelExchange
                    && f.gauges.iter().all(|g| gs.contains(g))
                    && f.from_row > 0
                    && onset_day(onset).is_ok_and(|d| (f.from_day - d).abs() <= 1.0)
            })
        }),
        "stuck" | "dead" => finding(&[SensorKind::Stuck]),
        "noise" | "noise-rise" => finding(&[SensorKind::NoiseIncrease]),
        "gap-step" | "gap-growth" => (gap_alarm || effect("time_varying_gap", &[])) && !sensor_any,
        "lockage-lag" => {
            effect("operational_event_response", &["lockage_phase"])
                || effect("generic_covariate_term", &["lockage"])
        }
        "sun" => {
            effect("thermal(air_temp_f)", &[])
                || effect("generic_covariate_term", &["daily", "air_temp"])
        }
        "wall-flexure" => effect("generic_covariate_term", &["upper_pool"]),
        _ => r.effects.is_empty() && !sensor_any && r.alarms.is_empty(),
    };
    let sensor_kind = is_sensor(kind);
    Score {
        kind: kind.into(),
        magnitude: magnitude.into(),
        onset: onset.into(),
        seed,
        cause,
        rmse_ratio: test_rmse(r) / noise,
        covered: r.theta_after.ci95.0 <= gap_end && gap_end <= r.theta_after.ci95.1,
        gap_alarm: gap_alarm && (sensor_kind || kind == "clean"),
        false_finding: kind == "clean" && !cause,
        wall_s,
        named: named(r),
        // read from the record's JSON line (`score_of`), like every score the table shows
        size_held: None,
        in_sample: InSample::No,
        oracle: None,
    }
}

/// The test window's RMSE over every gauge after the loop. A correction that starts in the
/// test window is fitted on its rows, so the out-of-sample figure leaves it out and an
/// exchanged or stuck gauge there, or a gap that changed there, would count as error; the
/// figure with every correction is taken instead (in-sample for that span; the report says so:
/// the sensor report's `fitted_on_test_rows`, the gap's `parameter_correction.
/// fitted_on_error_rows`, an effect from an onset's `onset.added`). The gap's correction is
/// applied on top of the sensor corrections and the effects from an onset, and the sensor's
/// figure on top of those effects, so each figure holds the ones before it. Gauges set aside on
/// every test row (no value) are left out.
fn test_rmse(r: &CloseLoopReport) -> f64 {
    let gap = r
        .parameter_correction
        .as_ref()
        .filter(|p| p.fitted_on_error_rows)
        .map(|p| &p.error_rmse);
    let sensor = r
        .sensor
        .as_ref()
        .filter(|s| s.fitted_on_test_rows)
        .and_then(|s| s.heldout_rmse_after_all_corrections.as_ref());
    let onset = r
        .onset
        .as_ref()
        .filter(|o| !o.added.is_empty())
        .and_then(|o| o.error_rmse_with.as_ref());
    match gap.or(sensor).or(onset) {
        Some(v) => bamudi_closeloop::rmse_over_gauges(v),
        None => r.heldout_rmse_total_after,
    }
}

/// Wilson 95 % interval of `k` of `n`.
fn wilson(k: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let (p, n, z) = (k as f64 / n as f64, n as f64, 1.96f64);
    let c = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let h = z * ((p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt()) / (1.0 + z * z / n);
    (c - h, c + h)
}

fn table(scores: &[Score], args: &PanelArgs) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Close-loop panel: {} records (mesh {} in, {} min step, 60 days, gap 90 in, noise 1 microstrain); `cargo xtask closeloop-panel{}`.\n",
        scores.len(),
        args.mesh,
        args.step_minutes,
        std::env::args()
            .skip(2)
            .map(|a| format!(" {a}"))
            .collect::<String>()
    );
    let _ = writeln!(
        s,
        "| kind | magnitude | onset | seed | cause named | what the loop named | fitted size's 95 % holds the size written | test RMSE / noise | gap 95 % holds the truth | gap alarm on a sensor fault | oracle's z = √λ | wall time (s) |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for x in scores {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {} | {} | {} | {:.0} |",
            x.kind,
            x.magnitude,
            x.onset,
            x.seed,
            yes(x.cause),
            x.named,
            x.size_held.map_or("–", yes),
            x.rmse_ratio,
            yes(x.covered),
            yes(x.gap_alarm),
            x.oracle
                .map_or("–".into(), |o| format!("{:.0}", o.lambda.sqrt())),
            x.wall_s
        );
    }
    let effect: Vec<&Score> = scores.iter().filter(|x| x.kind != "clean").collect();
    let n = effect.len();
    let count = |f: &dyn Fn(&Score) -> bool| effect.iter().filter(|x| f(x)).count();
    let line = |name: &str, k: usize| {
        let (lo, hi) = wilson(k, n);
        format!(
            "| {name} | {k} / {n} | {:.0} – {:.0} % |\n",
            100.0 * lo,
            100.0 * hi
        )
    };
    let _ = writeln!(
        s,
        "\n| criterion (records with an effect) | count | Wilson 95 % interval |\n|---|---|---|"
    );
    s += &line("right cause named", count(&|x| x.cause));
    s += &line("test RMSE ≤ 1.5x noise", count(&|x| x.rmse_ratio <= 1.5));
    s += &line("gap 95 % interval holds the truth", count(&|x| x.covered));
    s += &line(
        "all three",
        count(&|x| x.cause && x.rmse_ratio <= 1.5 && x.covered),
    );
    let passed: Vec<&&Score> = effect.iter().filter(|x| x.rmse_ratio <= 1.5).collect();
    let gap = passed
        .iter()
        .filter(|x| x.in_sample == InSample::Gap)
        .count();
    let sensor = passed
        .iter()
        .filter(|x| x.in_sample == InSample::Sensor)
        .count();
    let onset = passed
        .iter()
        .filter(|x| x.in_sample == InSample::Onset)
        .count();
    let _ = writeln!(
        s,
        "\nOf the {} records within 1.5x the noise, {} are scored on a figure whose corrections \
         were fitted on the test rows too: {sensor} with a sensor correction whose span reaches \
         into the test window (fitted over its whole span), {gap} with the gap's change from the \
         test window (fitted there: no fit on earlier rows can hold it), {onset} with an effect \
         from an onset after the calibration window (fitted on the rows from it). The JSON lines \
         keep each record's out-of-sample figure (`rmse_ratio_out_of_sample`) where it was \
         recorded.",
        passed.len(),
        sensor + gap + onset
    );
    let (seen, unseen): (Vec<&Score>, Vec<&Score>) = effect
        .iter()
        .partition(|x| x.oracle.is_some_and(|o| o.power >= ORACLE_RELIABLE));
    let named = |v: &[&Score]| v.iter().filter(|x| x.cause).count();
    let (lo, hi) = wilson(named(&seen), seen.len());
    let _ = writeln!(
        s,
        "\nAn oracle that knows each effect's shape, gauges and onset (the best any method could \
         do with these readings: nothing absorbed by the calibration, nothing searched for) \
         detects it at the 1 % level with power ≥ {ORACLE_RELIABLE} in {} of the {n} records. \
         The loop names the right cause in {} of those {} (Wilson 95 %: {:.0} – {:.0} %), and in \
         {} of the {} the oracle does not detect reliably. The table's `oracle's z` is the square \
         root of its noncentrality λ: the effect's size in noise sds, as an oracle reads it.",
        seen.len(),
        named(&seen),
        seen.len(),
        100.0 * lo,
        100.0 * hi,
        named(&unseen),
        unseen.len()
    );
    let sized: Vec<bool> = effect.iter().filter_map(|x| x.size_held).collect();
    let (k, m) = (sized.iter().filter(|b| **b).count(), sized.len());
    let (lo, hi) = wilson(k, m);
    let _ = writeln!(
        s,
        "\nA gain, offset step or drift named by a sized sensor finding on the right gauge: its 95 % interval holds the size written in {k} of {m} (Wilson 95 %: {:.0} – {:.0} %).",
        100.0 * lo,
        100.0 * hi
    );
    let clean: Vec<&Score> = scores.iter().filter(|x| x.kind == "clean").collect();
    let mut walls: Vec<f64> = scores.iter().map(|x| x.wall_s).collect();
    walls.sort_by(f64::total_cmp);
    let _ = writeln!(
        s,
        "\nGap alarms on records whose only change is a sensor fault: {}. False findings on clean records: {} of {}. Median wall time per record: {:.0} s.",
        scores.iter().filter(|x| x.gap_alarm).count(),
        clean.iter().filter(|x| x.false_finding).count(),
        clean.len(),
        walls.get(walls.len() / 2).copied().unwrap_or(f64::NAN)
    );
    s
}

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

#[derive(clap::Args)]
pub struct SummaryArgs {
    /// The panels' JSON files (`closeloop-panel --json`), comma separated: one column each.
    #[arg(long, value_delimiter = ',', required = true)]
    json: Vec<PathBuf>,
    /// Markdown summary.
    #[arg(long, default_value = "docs/results/closeloop-panel-summary.md")]
    out: PathBuf,
}

/// One panel's records, read back for the summary.
struct Panel {
    label: String,
    scores: Vec<Score>,
    /// Per record: the test error out of sample within 1.5x the noise, and its alarms.
    extra: Vec<(bool, usize)>,
}

/// `cargo xtask closeloop-panel-summary`: several panels (one seed each) side by side and
/// pooled, with Wilson 95 % intervals of the pooled proportions, and the pooled counts by kind
/// and by kind and magnitude.
pub fn summary(args: &SummaryArgs) -> Result<()> {
    let mut panels = vec![];
    for path in &args.json {
        let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
        let records: Vec<serde_json::Value> = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a panel's JSON", path.display()))?;
        let mut scores = vec![];
        let mut extra = vec![];
        for (k, j) in records.iter().enumerate() {
            scores.push(score_of(j).with_context(|| format!("{} record {k}", path.display()))?);
            let oos = j["rmse_ratio_out_of_sample"].as_f64().unwrap_or(f64::NAN) <= 1.5;
            extra.push((oos, j["alarms"].as_array().map_or(0, Vec::len)));
        }
        let seeds: std::collections::BTreeSet<u64> = scores
            .iter()
            .filter(|x| x.kind != "clean")
            .map(|x| x.seed)
            .collect();
        let label = match (seeds.first(), seeds.last()) {
            (Some(a), Some(b)) if a == b => format!("seed {a}"),
            (Some(a), Some(b)) => format!("seeds {a}-{b}"),
            _ => path.display().to_string(),
        };
        panels.push(Panel {
            label,
            scores,
            extra,
        });
    }
    let md = summary_table(&panels);
    if let Some(p) = args.out.parent() {
        std::fs::create_dir_all(p)?;
    }
    write_atomic(&args.out, md.as_bytes())?;
    println!("{md}");
    Ok(())
}

fn summary_table(panels: &[Panel]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Close-loop panels side by side and pooled; `cargo xtask closeloop-panel-summary{}`. Each \
         column is one panel (its records' seed); the last pools them, with the Wilson 95 % \
         interval of the proportion. Within a panel the base record is the same in every cell, \
         and for `exchange`, `stuck` and `dead` the three magnitudes are one record: the records \
         are not independent, and the intervals are narrower than the panel's information.\n",
        std::env::args()
            .skip(2)
            .map(|a| format!(" {a}"))
            .collect::<String>()
    );
    let head: Vec<&str> = panels.iter().map(|p| p.label.as_str()).collect();
    let _ = writeln!(
        s,
        "| criterion | {} | all |\n|---|{}---|",
        head.join(" | "),
        "---|".repeat(panels.len())
    );
    // a row: per panel the count among the panel's records `among`, pooled with its interval
    let row = |s: &mut String,
               name: &str,
               among: &dyn Fn(&Score) -> bool,
               hit: &dyn Fn(&Score, (bool, usize)) -> bool| {
        let (mut k_all, mut n_all) = (0, 0);
        let mut cells = vec![];
        for p in panels {
            let (mut k, mut n) = (0, 0);
            for (x, e) in p.scores.iter().zip(&p.extra) {
                if among(x) {
                    n += 1;
                    k += usize::from(hit(x, *e));
                }
            }
            cells.push(format!("{k} of {n}"));
            k_all += k;
            n_all += n;
        }
        let (lo, hi) = wilson(k_all, n_all);
        let _ = writeln!(
            s,
            "| {name} | {} | {k_all} of {n_all} ({:.0} – {:.0} %) |",
            cells.join(" | "),
            (100.0 * lo).max(0.0),
            100.0 * hi
        );
    };
    let effect = |x: &Score| x.kind != "clean";
    let sensor = |x: &Score| is_sensor(&x.kind);
    row(&mut s, "right cause named", &effect, &|x, _| x.cause);
    row(&mut s, "test RMSE ≤ 1.5x noise", &effect, &|x, _| {
        x.rmse_ratio <= 1.5
    });
    row(
        &mut s,
        "the same, out of sample (no correction fitted on the test rows)",
        &effect,
        &|_, e| e.0,
    );
    row(
        &mut s,
        "gap's 95 % interval holds the truth",
        &effect,
        &|x, _| x.covered,
    );
    row(&mut s, "all three", &effect, &|x, _| {
        x.cause && x.rmse_ratio <= 1.5 && x.covered
    });
    row(
        &mut s,
        "a sized finding's 95 % interval holds the size written",
        &|x| x.size_held.is_some(),
        &|x, _| x.size_held == Some(true),
    );
    row(
        &mut s,
        "an oracle detects the effect (power ≥ 0.9 at the 1 % level)",
        &|x| x.oracle.is_some(),
        &|x, _| x.oracle.is_some_and(|o| o.power >= ORACLE_RELIABLE),
    );
    row(
        &mut s,
        "gap alarm on a sensor-only record",
        &sensor,
        &|x, _| x.gap_alarm,
    );
    row(
        &mut s,
        "finding on a clean record",
        &|x| x.kind == "clean",
        &|x, _| x.false_finding,
    );
    let alarms: Vec<String> = panels
        .iter()
        .map(|p| p.extra.iter().map(|e| e.1).sum::<usize>().to_string())
        .collect();
    let total: usize = panels.iter().flat_map(|p| &p.extra).map(|e| e.1).sum();
    let _ = writeln!(
        s,
        "| alarms over the records | {} | {total} |",
        alarms.join(" | ")
    );
    let wall = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        format!(
            "{:.0} / {:.0} s",
            v.get(v.len() / 2).copied().unwrap_or(f64::NAN),
            v.last().copied().unwrap_or(f64::NAN)
        )
    };
    let walls: Vec<String> = panels
        .iter()
        .map(|p| wall(&mut p.scores.iter().map(|x| x.wall_s).collect()))
        .collect();
    let mut all: Vec<f64> = panels
        .iter()
        .flat_map(|p| p.scores.iter().map(|x| x.wall_s))
        .collect();
    let _ = writeln!(
        s,
        "| median / slowest wall time per record | {} | {} |",
        walls.join(" | "),
        wall(&mut all)
    );
    // pooled by kind, and the cause by kind and magnitude
    let _ = writeln!(
        s,
        "\nPooled by kind: records, right cause named, test RMSE ≤ 1.5x noise, gap's interval \
         holds the truth; and the cause named by magnitude.\n\n| kind | records | cause named | \
         error ≤ 1.5x | gap holds | cause: small | medium | large |\n|---|---|---|---|---|---|---|---|"
    );
    for kind in KINDS.iter().chain(&HELDOUT_KINDS) {
        let of: Vec<&Score> = panels
            .iter()
            .flat_map(|p| &p.scores)
            .filter(|x| x.kind == *kind)
            .collect();
        if of.is_empty() {
            continue;
        }
        let count = |f: &dyn Fn(&Score) -> bool| of.iter().filter(|x| f(x)).count();
        let by = |m: &str| {
            let n = count(&|x| x.magnitude == m);
            format!("{} of {n}", count(&|x| x.magnitude == m && x.cause))
        };
        let _ = writeln!(
            s,
            "| {kind} | {} | {} | {} | {} | {} | {} | {} |",
            of.len(),
            count(&|x| x.cause),
            count(&|x| x.rmse_ratio <= 1.5),
            count(&|x| x.covered),
            by("small"),
            by("medium"),
            by("large")
        );
    }
    s
}
