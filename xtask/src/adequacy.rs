//! `cargo xtask adequacy`: the adequacy verdict over a matrix of realities (issue 16).
//!
//! Each run simulates experiments of a paper scenario with `bamudi simulate experiments
//! --reality` (an as-built gate, or one gauge's sensor fault, at three magnitudes — the
//! as-built gates at any factors with `--as-built-magnitudes`; or the drawing itself) and
//! calibrates them with the drawing through `bamudi calibrate` (exact estimator, the CLI's
//! default marginal mode) — exactly what a user runs. A run is a
//! **silent miss** when the gap's 95 % interval misses the truth and the verdict says
//! "adequate"; it found the **right cause** when the verdict is "inadequate" and, for sensor
//! cells, attributes every failure to a sensor with the verdict's sensor correction (the
//! faults still significant when fitted jointly) on the faulty gauge alone, or, for as-built
//! cells, blames no sensor. Clean runs
//! measure the false-alarm rate. Writes `adequacy.md` and, with `--json`, every run.

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The command line's choices.
#[derive(clap::Args)]
pub struct AdequacyArgs {
    /// Seeds per deviation cell and scenario.
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Seeds of the clean (drawing = truth) runs per scenario.
    #[arg(long, default_value_t = 30)]
    clean_seeds: u64,
    /// Scenarios, comma separated (1, 2).
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    scenarios: Vec<u8>,
    /// Experiments per run.
    #[arg(long, default_value_t = 150)]
    experiments: usize,
    /// Mesh element size (in) of the drawing and the truth.
    #[arg(long, default_value_t = 24.0)]
    mesh: f64,
    /// First seed: each cell and the clean runs use consecutive seeds from here, so the first
    /// clean runs are the deviation runs' paired twins (same seed, no deviation).
    #[arg(long, default_value_t = 3000)]
    seed: u64,
    /// Only the cells whose name contains this.
    #[arg(long)]
    only: Option<String>,
    /// Also write every run as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Output directory of `adequacy.md` and the runs' files (`target/adequacy` for the runs).
    #[arg(long, default_value = "docs/results")]
    out: PathBuf,
    /// Marginal mode: prior variance of each coefficient function's unknown level, relative
    /// to the process variance (written to every run's `cal.toml` as
    /// `[calibration.marginal] level_variance`; unset, the library's default, 0).
    #[arg(long)]
    level_variance: Option<f64>,
    /// Narrows `ρ`'s prior and the Module-2 sampling rule's `ρ` range to `LO,HI` (written to
    /// every run's `cal.toml` as `[calibration.sampling] rho_range`; unset, the library's
    /// default). A diagnostic, as `cargo xtask coverage --rho-range`: with `ρ` pinned near the
    /// simulator's 0.8 it measures how much of a miss comes through `ρ`.
    #[arg(long, value_delimiter = ',', value_name = "LO,HI")]
    rho_range: Option<Vec<f64>>,
    /// Factors on the drawing's value at which every as-built deviation is run, instead of
    /// the matrix's three (e.g. `0.95,0.97,1.03,1.05` between and around them; each finite and
    /// positive). The sensor cells keep theirs.
    #[arg(long, value_delimiter = ',', value_name = "F,...")]
    as_built_magnitudes: Option<Vec<f64>>,
    /// Declared tolerances of the drawing, integrated out by every run's calibration
    /// (`KEY=RELATIVE_SD`, e.g. `skin_plate.thickness=0.03`; written to `cal.toml` as
    /// `[[tolerances]]`).
    #[arg(long, value_delimiter = ',', value_name = "KEY=SD,...")]
    tolerances: Vec<String>,
}

/// One deviation of the matrix.
struct Cell {
    name: String,
    /// `as_built`, `sensor` or `clean`.
    kind: &'static str,
    gauge: Option<&'static str>,
    toml: String,
}

/// The matrix: three as-built deviations at three factors each (or at `as_built_magnitudes`),
/// four sensor faults at three magnitudes each. The drawing's values are those of
/// `GateConfig::default()` (checked by a test).
fn cells(as_built_magnitudes: Option<&[f64]>) -> Vec<Cell> {
    let mut out = Vec::new();
    let as_built: [(&str, &str, f64, [f64; 3]); 3] = [
        (
            "skin plate thickness",
            "[as_built.skin_plate]\nthickness",
            0.625,
            [1.03, 1.08, 1.15],
        ),
        (
            "steel modulus",
            "[as_built.material]\nyoungs_modulus",
            29.0e6,
            [0.98, 0.95, 0.90],
        ),
        (
            "girder web thickness",
            "[as_built.girders]\nweb_thickness",
            0.75,
            [0.97, 0.92, 0.85],
        ),
    ];
    for (name, key, base, mags) in as_built {
        for &m in as_built_magnitudes.unwrap_or(&mags) {
            out.push(Cell {
                name: format!("as-built {name} x{m}"),
                kind: "as_built",
                gauge: None,
                toml: format!("{key} = {}\n", base * m),
            });
        }
    }
    let sensors: [(&str, &str, &str, [f64; 3]); 4] = [
        (
            "SG2",
            "offset (µε)",
            "offset_microstrain = {}",
            [3.0, 10.0, 30.0],
        ),
        ("SG5", "gain", "scale = {}", [1.02, 1.05, 1.15]),
        (
            "SG7",
            "step at 0.5 (µε)",
            "step = { at_fraction = 0.5, size_microstrain = {} }",
            [5.0, 15.0, 40.0],
        ),
        (
            "SG4",
            "drift (µε)",
            "drift_microstrain = {}",
            [3.0, 10.0, 30.0],
        ),
    ];
    for (gauge, what, key, mags) in sensors {
        for m in mags {
            out.push(Cell {
                name: format!("{gauge} {what} {m}"),
                kind: "sensor",
                gauge: Some(gauge),
                toml: format!(
                    "[[sensors]]\ngauge = \"{gauge}\"\n{}\n",
                    key.replace("{}", &m.to_string())
                ),
            });
        }
    }
    out
}

fn scenario(s: u8) -> Result<(f64, (f64, f64))> {
    match s {
        1 => Ok((90.0, (81.0, 105.0))),
        2 => Ok((150.0, (135.0, 165.0))),
        _ => bail!("--scenarios: scenario {s} does not exist (1 or 2)"),
    }
}

/// Runs the matrix and writes the report.
pub fn run(a: &AdequacyArgs) -> Result<()> {
    rho_pair(a)?; // a bad range is the command's error, not every run's
    tolerance_pairs(a)?;
    if let Some(m) = a
        .as_built_magnitudes
        .iter()
        .flatten()
        .find(|m| !(m.is_finite() && **m > 0.0))
    {
        bail!("--as-built-magnitudes: {m} is not a finite positive factor");
    }
    let bin = build_cli()?;
    let work = PathBuf::from("target/adequacy");
    let mut runs = Vec::new();
    let clean = Cell {
        name: "clean (drawing = truth)".into(),
        kind: "clean",
        gauge: None,
        toml: String::new(),
    };
    let mut plan: Vec<(&Cell, u64)> = Vec::new();
    let all = cells(a.as_built_magnitudes.as_deref());
    for c in all
        .iter()
        .filter(|c| a.only.as_ref().is_none_or(|o| c.name.contains(o.as_str())))
    {
        plan.extend((0..a.seeds).map(|i| (c, a.seed + i)));
    }
    if a.only
        .as_ref()
        .is_none_or(|o| clean.name.contains(o.as_str()))
    {
        plan.extend((0..a.clean_seeds).map(|i| (&clean, a.seed + i)));
    }
    let total = plan.len() * a.scenarios.len();
    for &s in &a.scenarios {
        for (c, seed) in &plan {
            // a failed calibration is reported, not a silent answer: it stays in the table
            let r = one_run(&bin, &work, a, c, *seed, s).unwrap_or_else(|e| {
                json!({"cell": c.name, "kind": c.kind, "seed": seed, "scenario": s,
                       "covered": false, "verdict": "error", "right_cause": false,
                       "silent_miss": false, "error": format!("{e:#}")})
            });
            eprintln!("[{}/{total}] {}", runs.len() + 1, line(&r));
            runs.push(r);
        }
    }
    let md = markdown(a, &runs);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    bamudi::data::write_atomic(&a.out.join("adequacy.md"), md.as_bytes())?;
    if let Some(p) = &a.json {
        bamudi::data::write_atomic(p, serde_json::to_string_pretty(&runs)?.as_bytes())?;
    }
    println!("{md}");
    Ok(())
}

/// The runs' `bamudi calibrate --config` text: the gap prior `(lo, hi)` (in), the exact
/// estimator, and, when given, the marginal prior's level variance and `ρ`'s range.
fn calibration_toml(
    prior: (f64, f64),
    level_variance: Option<f64>,
    rho_range: Option<(f64, f64)>,
    tolerances: &[(String, f64)],
) -> String {
    let mut cfg = format!(
        "gap_prior = [{}, {}]\n[calibration.estimator]\nkind = \"exact_linear\"\n",
        prior.0, prior.1
    );
    if let Some(c) = level_variance {
        cfg.push_str(&format!("[calibration.marginal]\nlevel_variance = {c:e}\n"));
    }
    if let Some((lo, hi)) = rho_range {
        cfg.push_str(&format!(
            "[calibration.sampling]\nrho_range = [{lo:?}, {hi:?}]\n"
        ));
    }
    for (key, sd) in tolerances {
        cfg.push_str(&format!(
            "[[tolerances]]\nkey = \"{key}\"\nrelative_sd = {sd:?}\n"
        ));
    }
    cfg
}

/// `--tolerances` as (key, relative sd) pairs, checked: `KEY=SD` with `SD` a number.
fn tolerance_pairs(a: &AdequacyArgs) -> Result<Vec<(String, f64)>> {
    a.tolerances
        .iter()
        .map(|t| match t.split_once('=') {
            Some((k, v)) if !k.is_empty() => v
                .parse::<f64>()
                .map(|sd| (k.to_string(), sd))
                .with_context(|| format!("--tolerances {t}: `{v}` is not a number")),
            _ => bail!("--tolerances {t}: want KEY=RELATIVE_SD"),
        })
        .collect()
}

/// `--rho-range` as a pair, checked: two finite values, `0 <= LO < HI`.
fn rho_pair(a: &AdequacyArgs) -> Result<Option<(f64, f64)>> {
    match a.rho_range.as_deref() {
        None => Ok(None),
        Some(&[lo, hi]) if lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi => {
            Ok(Some((lo, hi)))
        }
        Some(v) => bail!("--rho-range: want LO,HI with 0 <= LO < HI, got {v:?}"),
    }
}

/// Builds the release CLI and returns its path.
fn build_cli() -> Result<PathBuf> {
    let st = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["build", "--release", "-p", "bamudi-gate", "--bin", "bamudi"])
        .status()
        .context("running cargo build for the bamudi CLI")?;
    if !st.success() {
        bail!("building the bamudi CLI failed");
    }
    Ok(PathBuf::from("target/release/bamudi"))
}

fn cli(bin: &Path, args: &[String]) -> Result<String> {
    let o = Command::new(bin)
        .args(args)
        .env("CI", "1")
        .output()
        .with_context(|| format!("running {}", bin.display()))?;
    if !o.status.success() {
        bail!(
            "bamudi {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&o.stdout).into_owned())
}

fn one_run(bin: &Path, work: &Path, a: &AdequacyArgs, c: &Cell, seed: u64, s: u8) -> Result<Value> {
    let (truth, prior) = scenario(s)?;
    let d = work.join(format!(
        "{}-s{s}-{seed}",
        c.name.replace([' ', '(', ')', '='], "_")
    ));
    std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    let p = |f: &str| d.join(f).display().to_string();
    let common = vec![
        "--seed".to_string(),
        seed.to_string(),
        "--element-size".into(),
        a.mesh.to_string(),
    ];
    let mut sim = common.clone();
    sim.extend(
        [
            "simulate",
            "experiments",
            "--scenario",
            &s.to_string(),
            "--n",
            &a.experiments.to_string(),
            "--out",
            &p("e.csv"),
        ]
        .map(String::from),
    );
    if !c.toml.is_empty() {
        std::fs::write(p("reality.toml"), &c.toml)?;
        sim.extend(["--reality".to_string(), p("reality.toml")]);
    }
    cli(bin, &sim)?;
    std::fs::write(
        p("cal.toml"),
        calibration_toml(prior, a.level_variance, rho_pair(a)?, &tolerance_pairs(a)?),
    )?;
    let mut cal = common;
    cal.extend(
        [
            "calibrate",
            "--config",
            &p("cal.toml"),
            "--data",
            &p("e.csv"),
            "--out",
            &p("res"),
            "--force",
        ]
        .map(String::from),
    );
    cli(bin, &cal)?;
    let text = std::fs::read_to_string(p("res/results.json"))?;
    let r: Value = serde_json::from_str(&text).with_context(|| p("res/results.json"))?;
    Ok(judge(c, seed, s, truth, &r))
}

/// The run's record: interval, verdict, failures, and whether it is a silent miss and found
/// the right cause.
fn judge(c: &Cell, seed: u64, s: u8, truth: f64, r: &Value) -> Value {
    let t = &r["theta"]["with_discrepancy"];
    let (lo, hi) = (
        t["ci95"][0][0].as_f64().unwrap_or(f64::NAN),
        t["ci95"][0][1].as_f64().unwrap_or(f64::NAN),
    );
    let covered = lo <= truth && truth <= hi;
    let ad = &r["adequacy"];
    let verdict = ad["verdict"].as_str().unwrap_or("absent").to_string();
    let failed: Vec<(Vec<String>, String, String)> = ad["failed"]
        .as_array()
        .map(|v| {
            v.iter()
                .map(|f| {
                    let g = f["gauges"]
                        .as_array()
                        .map(|g| {
                            g.iter()
                                .filter_map(|x| x.as_str().map(String::from))
                                .collect()
                        })
                        .unwrap_or_default();
                    (
                        g,
                        f["attribution"].as_str().unwrap_or("").to_string(),
                        f["check"].as_str().unwrap_or("").to_string(),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    let inadequate = verdict == "inadequate";
    let right = inadequate
        && match (c.kind, c.gauge) {
            ("sensor", Some(g)) => {
                failed.iter().all(|(_, att, _)| att == "sensor") && corrected_gauges(ad) == [g]
            }
            ("as_built", _) => failed.iter().all(|(_, att, _)| att != "sensor"),
            _ => false,
        };
    json!({
        "cell": c.name, "kind": c.kind, "seed": seed, "scenario": s, "theta_true": truth,
        "mean": t["mean"][0], "sd": t["sd"][0], "ci95": [lo, hi], "covered": covered,
        "verdict": verdict, "right_cause": right, "silent_miss": !covered && verdict == "adequate",
        "failed": failed.iter().map(|(g, a, c)| json!({"check": c, "gauges": g, "attribution": a})).collect::<Vec<_>>(),
        "tolerances": r["tolerances"].clone(),
    })
}

/// The gauges of the verdict's sensor correction (the faults significant when fitted jointly).
fn corrected_gauges(ad: &Value) -> Vec<String> {
    let mut g: Vec<String> = ad["sensor_correction"]["faults"]
        .as_array()
        .map(|v| {
            v.iter()
                .filter_map(|f| f["gauge"].as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    g.dedup();
    g
}

fn line(r: &Value) -> String {
    format!(
        "{} S{} seed {}: {:.2} ± {:.2}, covered {}, {}{}",
        r["cell"].as_str().unwrap_or(""),
        r["scenario"],
        r["seed"],
        r["mean"].as_f64().unwrap_or(f64::NAN),
        r["sd"].as_f64().unwrap_or(f64::NAN),
        r["covered"],
        r["verdict"].as_str().unwrap_or(""),
        if r["silent_miss"].as_bool() == Some(true) {
            " SILENT MISS"
        } else {
            ""
        }
    )
}

/// Upper end of the two-sided 95 % Clopper-Pearson interval of `k` successes in `n`.
fn clopper_pearson_upper(k: usize, n: usize) -> f64 {
    if k >= n {
        return 1.0;
    }
    let (a, b) = ((k + 1) as f64, (n - k) as f64);
    // bisection on the regularised incomplete beta: P(X ≤ k) = 0.025
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        let cdf = 1.0 - statrs::function::beta::beta_reg(a, b, mid);
        if cdf > 0.025 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// The optional flags of the run, as the report's command line echoes them.
fn optional_flags(a: &AdequacyArgs) -> String {
    let list = |v: &[f64]| v.iter().map(f64::to_string).collect::<Vec<_>>().join(",");
    let mut s = String::new();
    if let Some(o) = &a.only {
        s.push_str(&format!(" --only '{o}'"));
    }
    if let Some(c) = a.level_variance {
        s.push_str(&format!(" --level-variance {c:e}"));
    }
    if let Some(r) = &a.rho_range {
        s.push_str(&format!(" --rho-range {}", list(r)));
    }
    if let Some(m) = &a.as_built_magnitudes {
        s.push_str(&format!(" --as-built-magnitudes {}", list(m)));
    }
    if !a.tolerances.is_empty() {
        s.push_str(&format!(" --tolerances {}", a.tolerances.join(",")));
    }
    s
}

fn markdown(a: &AdequacyArgs, runs: &[Value]) -> String {
    let mut s = format!(
        "# The adequacy verdict on realities that differ from the model\n\n`cargo xtask adequacy --seeds {} --clean-seeds {} --scenarios {} --experiments {} --mesh {} --seed {}{}`: \
         each run simulates {} experiments with `bamudi simulate experiments --reality reality.toml` and calibrates them with the drawing \
         (`bamudi calibrate`, exact estimator, marginal mode, family-wise error 0.01). Silent miss: the gap's 95 % interval misses the \
         truth and the verdict is \"adequate\". Right cause: \"inadequate\", every failure attributed to a sensor and the sensor correction \
         (the faults significant when fitted jointly) on the faulty gauge alone (sensor cells), or blaming no sensor (as-built cells).\n\n| reality | scenario | runs | interval covers θ* | inadequate | right cause | silent misses |\n|---|---|---|---|---|---|---|\n",
        a.seeds,
        a.clean_seeds,
        a.scenarios
            .iter()
            .map(u8::to_string)
            .collect::<Vec<_>>()
            .join(","),
        a.experiments,
        a.mesh,
        a.seed,
        optional_flags(a),
        a.experiments
    );
    let mut keys: Vec<(String, u64)> = Vec::new();
    for r in runs {
        let k = (
            r["cell"].as_str().unwrap_or("").to_string(),
            r["scenario"].as_u64().unwrap_or(0),
        );
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    let count = |rs: &[&Value], key: &str, want: &str| {
        rs.iter()
            .filter(|r| r[key].to_string().trim_matches('"') == want)
            .count()
    };
    let (mut silent, mut total) = (0, 0);
    for (cell, sc) in &keys {
        let rs: Vec<&Value> = runs
            .iter()
            .filter(|r| r["cell"] == cell.as_str() && r["scenario"] == *sc)
            .collect();
        let n = rs.len();
        let clean = rs.first().is_some_and(|r| r["kind"] == "clean");
        let sm = count(&rs, "silent_miss", "true");
        silent += sm;
        total += n;
        let inad = count(&rs, "verdict", "inadequate");
        let errors = match count(&rs, "verdict", "error") {
            0 => String::new(),
            e => format!(" ({e} calibration(s) failed with an error)"),
        };
        let right = if clean {
            format!(
                "false alarms {inad}/{n} (95 % upper bound {:.1} %)",
                100.0 * clopper_pearson_upper(inad, n)
            )
        } else {
            format!("{}/{n}", count(&rs, "right_cause", "true"))
        };
        s += &format!(
            "| {cell} | {sc} | {n} | {}/{n} | {inad}/{n}{errors} | {right} | {sm} |\n",
            count(&rs, "covered", "true")
        );
    }
    s += &format!("\nSilent misses over all {total} runs: {silent}.\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use bamudi_gate::session::CalibrateSpec;

    /// The marginal prior's level variance of a run's calibration.
    fn level_variance(spec: &CalibrateSpec) -> f64 {
        let prior = spec.calibration.coefficients.marginal_prior();
        prior.expect("the marginal mode").level_variance
    }

    /// The runs' configuration is read by the CLI's own parser as meant: the level variance
    /// (written in exponent form) when given, the library's default when not.
    #[test]
    fn the_runs_configuration_carries_the_level_variance() {
        for (level, want) in [
            (Some(1e3), 1e3),
            (Some(0.0), 0.0),
            (None, bamudi::params::DEFAULT_LEVEL_VARIANCE),
        ] {
            let text = calibration_toml((81.0, 105.0), level, None, &[]);
            let spec = CalibrateSpec::from_toml_str(&text, "cal.toml").unwrap();
            assert_eq!(spec.prior(), (81.0, 105.0), "{text}");
            assert_eq!(level_variance(&spec), want, "{text}");
        }
    }

    /// The matrix's drawing values are the default gate's, and `--as-built-magnitudes` runs
    /// every as-built deviation at exactly the given factors of them (the reality read back by
    /// mitergate's own parser); the sensor cells do not change.
    #[test]
    fn as_built_magnitudes_scale_the_drawing_values() {
        let drawing = mitergate::GateConfig::default();
        let value = |g: &mitergate::GateConfig, c: &Cell| match c.name.as_str() {
            n if n.contains("skin plate") => g.skin_plate.thickness,
            n if n.contains("steel modulus") => g.material.youngs_modulus,
            n if n.contains("girder web") => g.girders.web_thickness,
            n => panic!("unknown as-built cell {n}"),
        };
        for (magnitudes, per_kind) in [(None, 3), (Some(&[0.95, 1.05][..]), 2)] {
            let all = cells(magnitudes);
            let as_built: Vec<&Cell> = all.iter().filter(|c| c.kind == "as_built").collect();
            assert_eq!(as_built.len(), 3 * per_kind);
            assert_eq!(all.iter().filter(|c| c.kind == "sensor").count(), 12);
            for c in as_built {
                let reality = mitergate::reality::Reality::from_toml_str(&c.toml).unwrap();
                let truth = reality.truth_gate(&drawing).unwrap();
                let factor = value(&truth, c) / value(&drawing, c);
                let named: f64 = c.name.rsplit('x').next().unwrap().parse().unwrap();
                // the factor is written as `base * m` in shortest round-trip form: equal to
                // the named factor up to one rounding of the product
                assert!(
                    (factor - named).abs() < 1e-12,
                    "{}: factor {factor}",
                    c.name
                );
                if let Some(m) = magnitudes {
                    assert!(m.contains(&named), "{}", c.name);
                }
            }
        }
    }

    /// A factor that is not finite and positive is the command's error, named, before any
    /// run (the check comes before the CLI is built).
    #[test]
    fn a_bad_as_built_magnitude_is_the_commands_error() {
        #[derive(clap::Parser)]
        struct Cmd {
            #[command(flatten)]
            a: AdequacyArgs,
        }
        for bad in ["0.95,-1", "0", "NaN"] {
            let cmd =
                <Cmd as clap::Parser>::try_parse_from(["adequacy", "--as-built-magnitudes", bad])
                    .unwrap();
            let err = run(&cmd.a).unwrap_err().to_string();
            assert!(err.contains("--as-built-magnitudes"), "{bad}: {err}");
        }
    }

    /// `--rho-range` reaches the sampling rule (and through it `ρ`'s prior) as written, next
    /// to the level variance; unset, the library's default range stays.
    #[test]
    fn the_runs_configuration_carries_the_rho_range() {
        for (range, want) in [
            (Some((0.799, 0.801)), (0.799, 0.801)),
            (None, bamudi::SamplingRule::default().rho_range),
        ] {
            let text = calibration_toml((81.0, 105.0), Some(1e3), range, &[]);
            let spec = CalibrateSpec::from_toml_str(&text, "cal.toml").unwrap();
            assert_eq!(spec.calibration.sampling.rho_range, want, "{text}");
            assert_eq!(level_variance(&spec), 1e3, "{text}");
        }
    }

    /// `--tolerances` reaches every run's configuration as `[[tolerances]]`, read back by the
    /// CLI's own parser; a malformed pair is the command's error, named.
    #[test]
    fn the_runs_configuration_carries_the_tolerances() {
        #[derive(clap::Parser)]
        struct Cmd {
            #[command(flatten)]
            a: AdequacyArgs,
        }
        let parse = |v: &str| {
            <Cmd as clap::Parser>::try_parse_from(["adequacy", "--tolerances", v])
                .unwrap()
                .a
        };
        let pairs = tolerance_pairs(&parse(
            "skin_plate.thickness=0.03,material.youngs_modulus=0.02",
        ))
        .unwrap();
        let text = calibration_toml((81.0, 105.0), None, None, &pairs);
        let spec = CalibrateSpec::from_toml_str(&text, "cal.toml").unwrap();
        let got: Vec<(&str, f64)> = spec
            .tolerances
            .iter()
            .map(|t| (t.key.as_str(), t.relative_sd))
            .collect();
        assert_eq!(
            got,
            [
                ("skin_plate.thickness", 0.03),
                ("material.youngs_modulus", 0.02)
            ],
            "{text}"
        );
        for bad in ["skin_plate.thickness", "=0.03", "skin_plate.thickness=thin"] {
            let err = run(&parse(bad)).unwrap_err().to_string();
            assert!(err.contains("--tolerances"), "{bad}: {err}");
        }
    }
}
