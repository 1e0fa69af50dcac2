//! `cargo xtask bench`: the workspace's criterion benchmarks and the Python peers of
//! `../shared/anchors` in one run, written as ratios into `docs/benchmarks.md` (issue 20).
//!
//! These machines are shared and noisy, so a figure means something only against a reference
//! measured in the same run: the task runs `cargo bench -p bamudi-benches`, reads every
//! criterion median from `target/criterion`, runs each anchor script whose Python packages are
//! installed (a missing package is reported in the table, not an error), and replaces the
//! section between [`BEGIN`] and [`END`] of the output document (appended when absent; the file
//! is written atomically). The anchors include one whole calibration run through a peer
//! ([`PEER_SCRIPT`]: SEPIA's ball drop through surmise and through our Python package, same
//! likelihood), whose posteriors are tabulated beside the wall times. With `--profile` it also records where `reproduce-paper --quick`
//! spends its time (`perf record`, inclusive share per function of our crates) when `perf` is
//! installed.

use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::SystemTime;

/// Start marker of the generated section.
pub const BEGIN: &str = "<!-- xtask-bench:begin -->";
/// End marker of the generated section.
pub const END: &str = "<!-- xtask-bench:end -->";

/// Arguments of `cargo xtask bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Only benchmarks whose id contains this text (criterion's filter).
    #[arg(long)]
    filter: Option<String>,
    /// Do not run the Python anchors.
    #[arg(long)]
    no_anchors: bool,
    /// Python interpreter for the anchors.
    #[arg(long, default_value = "python3")]
    python: String,
    /// Directory of the anchor scripts.
    #[arg(long, default_value = "../shared/anchors")]
    anchors: PathBuf,
    /// Also profile `reproduce-paper --quick` with `perf` (skipped, with a note, without it).
    #[arg(long)]
    profile: bool,
    /// Profile the paper-size `reproduce-paper` (the quick start's job, about 4 minutes on 2
    /// cores) instead of `--quick`; implies `--profile`.
    #[arg(long)]
    profile_paper: bool,
    /// Document whose generated section is replaced.
    #[arg(long, default_value = "docs/benchmarks.md")]
    out: PathBuf,
}

/// One anchor script's outcome: its `anchor` line's values, or why it did not run.
#[derive(Debug, Clone, PartialEq)]
pub enum Anchor {
    /// `key=value` pairs of the script's final `anchor` line (seconds, rates, likelihoods).
    Ran(BTreeMap<String, f64>),
    /// The script did not run or printed no `anchor` line.
    Skipped(String),
}

/// The whole-calibration comparison with a peer (run with `--python`, which needs the `bamudi`
/// package and surmise installed; skipped with the reason otherwise).
pub const PEER_SCRIPT: &str = "python/examples/benchmarks/peer_anchor.py";

/// Runs the task.
pub fn run(args: &BenchArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let run_began = std::time::SystemTime::now();
    run_criterion(args.filter.as_deref())?;
    let medians = criterion_medians(Path::new("target/criterion"), run_began)?;
    let anchors = match args.no_anchors {
        true => BTreeMap::new(),
        false => {
            let mut a = run_anchors(&args.python, &args.anchors);
            a.insert(
                PEER_SCRIPT.into(),
                run_anchor(&args.python, Path::new(PEER_SCRIPT)),
            );
            a
        }
    };
    let profile = match (args.profile, args.profile_paper) {
        (_, true) => Some(profile_reproduction(ProfiledRun::Paper)),
        (true, false) => Some(profile_reproduction(ProfiledRun::Quick)),
        (false, false) => None,
    };
    let section = render(&medians, &anchors, profile.as_deref(), started.elapsed());
    let doc = match std::fs::read_to_string(&args.out) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        read => read.with_context(|| format!("reading {}", args.out.display()))?,
    };
    bamudi::data::write_atomic(&args.out, replace_section(&doc, &section).as_bytes())?;
    eprintln!("bench: wrote {}", args.out.display());
    Ok(())
}

fn run_criterion(filter: Option<&str>) -> Result<()> {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.args([
        "bench",
        "-p",
        "bamudi-benches",
        "--bench",
        "workspace",
        "--",
    ]);
    if let Some(f) = filter {
        cmd.arg(f);
    }
    let status = cmd
        .status()
        .context("running cargo bench -p bamudi-benches")?;
    if !status.success() {
        bail!("cargo bench -p bamudi-benches failed ({status})");
    }
    Ok(())
}

/// Criterion's median (ns per iteration) of every benchmark under `root` whose estimates were
/// written at or after `since`, keyed `group/id`: results of earlier runs (benchmarks a
/// `--filter` left out) are not mixed into this run's ratios.
pub fn criterion_medians(root: &Path, since: SystemTime) -> Result<BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    let groups = std::fs::read_dir(root)
        .with_context(|| format!("reading criterion results in {}", root.display()))?;
    for group in groups.flatten().filter(|e| e.path().is_dir()) {
        for bench in std::fs::read_dir(group.path())?.flatten() {
            let file = bench.path().join("new").join("estimates.json");
            let written = std::fs::metadata(&file).and_then(|m| m.modified());
            if !written.is_ok_and(|t| t >= since) {
                continue; // criterion's own report directory, or not run this time
            }
            let text = std::fs::read_to_string(&file)
                .with_context(|| format!("reading {}", file.display()))?;
            let ns = median_ns(&text).with_context(|| format!("reading {}", file.display()))?;
            let key = format!(
                "{}/{}",
                group.file_name().to_string_lossy(),
                bench.file_name().to_string_lossy()
            );
            out.insert(key, ns);
        }
    }
    Ok(out)
}

/// The median point estimate (ns) of a criterion `estimates.json`.
pub fn median_ns(estimates_json: &str) -> Result<f64> {
    let v: serde_json::Value = serde_json::from_str(estimates_json)?;
    v["median"]["point_estimate"]
        .as_f64()
        .context("key median.point_estimate missing or not a number")
}

fn run_anchors(python: &str, dir: &Path) -> BTreeMap<String, Anchor> {
    ["gp_anchor.py", "chol_anchor.py", "lstm_anchor.py"]
        .iter()
        .map(|name| (name.to_string(), run_anchor(python, &dir.join(name))))
        .collect()
}

fn run_anchor(python: &str, script: &Path) -> Anchor {
    if !script.exists() {
        return Anchor::Skipped(format!("{} not found", script.display()));
    }
    eprintln!("bench: running {}", script.display());
    match Command::new(python).arg(script).output() {
        Err(e) => Anchor::Skipped(format!("{python} did not start: {e}")),
        Ok(o) => {
            let stdout = String::from_utf8_lossy(&o.stdout);
            match stdout.lines().rev().find_map(parse_anchor_line) {
                Some(values) if o.status.success() => Anchor::Ran(values),
                _ => Anchor::Skipped(last_error_line(&String::from_utf8_lossy(&o.stderr))),
            }
        }
    }
}

fn last_error_line(stderr: &str) -> String {
    let line = stderr.lines().rev().find(|l| !l.trim().is_empty());
    line.unwrap_or("no anchor line printed").trim().to_string()
}

/// The `key=value` pairs of a line beginning `anchor` (values that are not numbers are
/// dropped); `None` for any other line.
pub fn parse_anchor_line(line: &str) -> Option<BTreeMap<String, f64>> {
    let rest = line.trim().strip_prefix("anchor ")?;
    let pairs = rest.split_whitespace().filter_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        Some((k.to_string(), v.parse::<f64>().ok()?))
    });
    Some(pairs.collect())
}

/// One comparison against a peer: our benchmark, its scale to the peer's unit, the peer's key.
struct Pair {
    what: &'static str,
    ours: &'static [&'static str],
    script: &'static str,
    peer_key: &'static str,
    peer: &'static str,
}

/// The comparisons whose workloads match (see each anchor script's docstring and the bench
/// sources): our time is the sum of the listed medians.
const PAIRS: &[Pair] = &[
    Pair {
        what: "GP ML-II fit, 500 points in 2-D, 5 restarts",
        ours: &["gp/fit_n500_d2_5restarts"],
        script: "gp_anchor.py",
        peer_key: "gp_fit_s",
        peer: "scikit-learn GaussianProcessRegressor",
    },
    Pair {
        what: "GP predict mean and sd at 2,500 points",
        ours: &["gp/predict_mean_var_2500"],
        script: "gp_anchor.py",
        peer_key: "gp_predict2500_std_s",
        peer: "scikit-learn predict(return_std)",
    },
    Pair {
        what: "dense Cholesky of a 3500 x 3500 covariance",
        ours: &["bamudi/cholesky_V_3500"],
        script: "chol_anchor.py",
        peer_key: "np_chol3500_s",
        peer: "numpy.linalg.cholesky, 2 BLAS threads",
    },
    Pair {
        what: "Gaussian log-likelihood, 3500 (factor + log-det + solve)",
        ours: &["bamudi/cholesky_V_3500", "bamudi/loglik_one_theta_3500"],
        script: "chol_anchor.py",
        peer_key: "chol3500_s",
        peer: "SciPy cho_factor + cho_solve, 2 BLAS threads",
    },
];

/// The LSTM comparisons are throughputs (samples per second): our epoch of 5,120 samples
/// against the peer's samples per second.
const LSTM_PAIRS: &[(&str, &str, &str)] = &[
    (
        "LSTM training, 10 steps x 1 feature, f32, 2 threads",
        "seqnet/train_epoch_seq10x1_f32_2threads",
        "lstm_seq10_sps",
    ),
    (
        "LSTM training, 1 step x 10 features, f32, 1 thread (peer: 2 threads)",
        "seqnet/train_epoch_seq1x10_f32_1thread",
        "lstm_seq1_sps",
    ),
];

/// Samples per epoch in the `seqnet` training benchmarks (`benches/benches/workspace/seqnet.rs`).
const SEQNET_EPOCH_SAMPLES: f64 = 5_120.0;

/// Issue 20's speed targets that have a benchmark: (what, our ids summed, per-call divisor,
/// target in seconds).
const TARGETS: &[(&str, &str, f64, f64)] = &[
    (
        "contact solve g_BC (32 random inputs, per solve)",
        "contact/solve_32_random_inputs",
        32.0,
        100e-6,
    ),
    (
        "Module 3 log-likelihood per θ node at 3500 observations (one node alone)",
        "bamudi/loglik_one_theta_3500",
        1.0,
        1e-3,
    ),
    (
        "Module 3 dense log-likelihood per θ node at 3500 observations (30 nodes batched, as the grid evaluates them; paper and conditional modes)",
        "bamudi/loglik_30_theta_batched_3500",
        30.0,
        1e-3,
    ),
];

fn render(
    medians: &BTreeMap<String, f64>,
    anchors: &BTreeMap<String, Anchor>,
    profile: Option<&str>,
    elapsed: std::time::Duration,
) -> String {
    let mut s = format!(
        "## Generated by `cargo xtask bench`\n\nRun of {} s; every ratio below is taken within \
         that run (criterion medians; each anchor's own median). Regenerate with `cargo xtask \
         bench` (add `--profile` for the profile table of the quick reproduction, \
         `--profile-paper` for the paper-size one).\n\n",
        elapsed.as_secs()
    );
    s += &peer_table(medians, anchors);
    s += &whole_calibration_table(anchors);
    s += &target_table(medians);
    s += &all_medians_table(medians);
    if let Some(p) = profile {
        s += p;
    }
    s
}

fn peer_table(medians: &BTreeMap<String, f64>, anchors: &BTreeMap<String, Anchor>) -> String {
    let mut s = String::from(
        "### Against the Python peers\n\n| workload | ours | peer | peer time | peer / ours |\n|---|---|---|---|---|\n",
    );
    for p in PAIRS {
        let ours: Option<f64> = p
            .ours
            .iter()
            .map(|k| medians.get(*k).map(|ns| ns * 1e-9))
            .sum();
        let peer = anchor_value(anchors, p.script, p.peer_key);
        s += &format!(
            "| {} | {} | {} | {} | {} |\n",
            p.what,
            ours.map_or("not run".into(), seconds),
            p.peer,
            peer.clone().map_or_else(|e| e, seconds),
            ratio(peer.ok(), ours),
        );
    }
    for (what, id, key) in LSTM_PAIRS {
        let ours_sps = medians
            .get(*id)
            .map(|ns| SEQNET_EPOCH_SAMPLES / (ns * 1e-9));
        let peer = anchor_value(anchors, "lstm_anchor.py", key);
        // a throughput: ours / peer is the speed ratio
        let r = match (ours_sps, peer.as_ref().ok()) {
            (Some(o), Some(p)) if *p > 0.0 => format!("{:.2}x", o / p),
            _ => "—".into(),
        };
        s += &format!(
            "| {what} | {} | PyTorch nn.LSTM | {} | {r} (ours / peer, samples/s) |\n",
            ours_sps.map_or("not run".into(), |v| format!("{v:.0} samples/s")),
            peer.map_or_else(|e| e, |v| format!("{v:.0} samples/s")),
        );
    }
    s + "\n"
}

/// The whole calibration against a peer ([`PEER_SCRIPT`]): wall times and posteriors.
fn whole_calibration_table(anchors: &BTreeMap<String, Anchor>) -> String {
    let mut s = String::from(
        "### A whole calibration against a peer\n\nSEPIA's ball drop without discrepancy \
         (docs/results/peers.md): the same simulator, prior and known noise sd (0.01 s), i.e. the \
         same likelihood, through surmise 1.0's `directbayes` (Metropolis-Hastings, 2000 + 1000 \
         burn-in, the simulator passed through) and through our Python package (`bamudi.calibrate`, \
         the grid posterior without discrepancy); medians of the script's runs.\n\n\
         | calibration | C: mean ± sd | wall time |\n|---|---|---|\n",
    );
    let v = |k: &str| anchor_value(anchors, PEER_SCRIPT, k);
    let row = |who: &str, side: &str| -> String {
        match (
            v(&format!("{side}_mean")),
            v(&format!("{side}_sd")),
            v(&format!("{side}_s")),
        ) {
            (Ok(m), Ok(sd), Ok(t)) => format!("| {who} | {m:.4} ± {sd:.4} | {} |\n", seconds(t)),
            (Err(e), ..) | (_, Err(e), _) | (.., Err(e)) => format!("| {who} | {e} | — |\n"),
        }
    };
    s += &row("surmise 1.0 `directbayes`", "peer");
    s += &row("bamudi (Python package)", "ours");
    s += &format!(
        "| peer / ours | | {} |\n\n",
        ratio(v("peer_s").ok(), v("ours_s").ok())
    );
    s
}

fn anchor_value(
    anchors: &BTreeMap<String, Anchor>,
    script: &str,
    key: &str,
) -> std::result::Result<f64, String> {
    match anchors.get(script) {
        None => Err("not run (--no-anchors)".into()),
        Some(Anchor::Skipped(why)) => Err(format!("not run: {why}")),
        Some(Anchor::Ran(v)) => v.get(key).copied().ok_or(format!("{key} not printed")),
    }
}

fn target_table(medians: &BTreeMap<String, f64>) -> String {
    let mut s = String::from(
        "### Issue 20's targets\n\n| quantity | measured | target | measured / target |\n|---|---|---|---|\n",
    );
    for (what, id, per, target) in TARGETS {
        let t = medians.get(*id).map(|ns| ns * 1e-9 / per);
        s += &format!(
            "| {what} | {} | {} | {} |\n",
            t.map_or("not run".into(), seconds),
            seconds(*target),
            t.map_or("—".into(), |v| format!("{:.2}", v / target)),
        );
    }
    s + "\n"
}

fn all_medians_table(medians: &BTreeMap<String, f64>) -> String {
    let mut s = String::from("### Every criterion median\n\n| benchmark | median |\n|---|---|\n");
    for (k, ns) in medians {
        s += &format!("| `{k}` | {} |\n", seconds(ns * 1e-9));
    }
    s + "\n"
}

/// A time with a unit chosen for its size.
pub fn seconds(s: f64) -> String {
    match s {
        s if s >= 1.0 => format!("{s:.2} s"),
        s if s >= 1e-3 => format!("{:.2} ms", s * 1e3),
        s if s >= 1e-6 => format!("{:.1} µs", s * 1e6),
        s => format!("{:.0} ns", s * 1e9),
    }
}

fn ratio(peer: Option<f64>, ours: Option<f64>) -> String {
    match (peer, ours) {
        (Some(p), Some(o)) if o > 0.0 => format!("{:.2}x", p / o),
        _ => "—".into(),
    }
}

/// `doc` with the text between [`BEGIN`] and [`END`] replaced by `section` (the markers kept),
/// or with the markers and `section` appended when `doc` has none.
pub fn replace_section(doc: &str, section: &str) -> String {
    let block = format!("{BEGIN}\n{}\n{END}", section.trim_end());
    match (doc.find(BEGIN), doc.find(END)) {
        (Some(a), Some(b)) if a < b => format!("{}{block}{}", &doc[..a], &doc[b + END.len()..]),
        _ => format!("{}\n\n{block}\n", doc.trim_end()),
    }
}

/// Which reproduction the profile samples.
#[derive(Debug, Clone, Copy, PartialEq)]
enum ProfiledRun {
    /// `reproduce-paper --quick` (CI size, 49 samples per second).
    Quick,
    /// The paper-size run (20 samples per second: about 10,000 stacks over its minutes).
    Paper,
}

impl ProfiledRun {
    /// The title's command, the `reproduce-paper` arguments and the sampling frequency (Hz).
    fn setup(self) -> (&'static str, &'static [&'static str], &'static str) {
        match self {
            ProfiledRun::Quick => ("reproduce-paper --quick", &["--quick"], "49"),
            ProfiledRun::Paper => ("reproduce-paper", &[], "20"),
        }
    }
}

/// The profile section: `perf record` on the reproduction, as a table of inclusive shares; a
/// note instead when `perf` is missing or fails.
fn profile_reproduction(run: ProfiledRun) -> String {
    let head = format!("### Where `{}` spends its time\n\n", run.setup().0);
    match record_profile(run) {
        Ok(text) => format!("{head}{}\n", profile_table(&inclusive_shares(&text), 25)),
        Err(e) => format!("{head}Not profiled: {e:#}.\n\n"),
    }
}

fn record_profile(run: ProfiledRun) -> Result<String> {
    let (_, extra, hz) = run.setup();
    let exe = std::env::current_exe()?;
    let data = PathBuf::from("target/xtask-bench-perf.data");
    let status = Command::new("perf")
        .args(["record", "-F", hz, "--call-graph", "dwarf,16384", "-o"])
        .arg(&data)
        .arg("--")
        .arg(&exe)
        .arg("reproduce-paper")
        .args(extra)
        .args(["--out", "target/xtask-bench-reproduce"])
        .status()
        .context("perf did not start (is it installed?)")?;
    if !status.success() {
        bail!("perf record failed ({status})");
    }
    let out = Command::new("perf")
        .args(["script", "-i"])
        .arg(&data)
        .output()
        .context("perf script")?;
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Crates whose functions the profile table names.
const OUR_CRATES: &[&str] = &[
    "bamudi_gate::",
    "bamudi::",
    "mitergate::",
    "gp::",
    "seqnet::",
    "mlmodel::",
    "numerics::",
    "orthopoly::",
];

/// Share of samples (0-1) whose stack holds each function of our crates, from `perf script`
/// text (samples separated by blank lines, one frame per line: address then symbol).
pub fn inclusive_shares(perf_script: &str) -> Vec<(String, f64)> {
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut total = 0usize;
    for sample in perf_script.split("\n\n").filter(|s| !s.trim().is_empty()) {
        total += 1;
        let mut seen = std::collections::BTreeSet::new();
        for frame in sample.lines().skip(1) {
            if let Some(f) = our_function(frame)
                && seen.insert(f.clone())
            {
                *counts.entry(f).or_default() += 1;
            }
        }
    }
    let mut v: Vec<(String, f64)> = counts
        .into_iter()
        .map(|(k, c)| (k, c as f64 / total.max(1) as f64))
        .collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    v
}

/// The function of our crates in one `perf script` frame line (address, symbol, then
/// `(/path)`): the symbol's leading path when it is one of [`OUR_CRATES`], with the method
/// after a generic or trait-qualified type (`<Memo<U> as Trait>::evaluate` gives
/// `mlmodel::memo::Memo::evaluate`), closures folded into their function; `None` for other
/// code, including std and rayon frames that only carry our types as parameters.
fn our_function(frame: &str) -> Option<String> {
    let symbol = frame.trim().split_once(' ')?.1;
    let symbol = symbol.split(" (").next()?.split("+0x").next()?;
    let bare = symbol.trim_start_matches('<');
    if !OUR_CRATES.iter().any(|c| bare.starts_with(c)) {
        return None;
    }
    let is_ident = |c: &char| c.is_alphanumeric() || *c == '_';
    let head: String = bare
        .chars()
        .take_while(|c| is_ident(c) || *c == ':')
        .collect();
    let head = head.trim_end_matches(':').to_string();
    let rest = &bare[head.len()..];
    let method: String = match rest.starts_with('<') || symbol.starts_with('<') {
        true => rest
            .rfind(">::")
            .map(|i| rest[i + 3..].chars().take_while(is_ident).collect())
            .unwrap_or_default(),
        false => String::new(),
    };
    Some(match method.is_empty() {
        true => head,
        false => format!("{head}::{method}"),
    })
}

fn profile_table(shares: &[(String, f64)], rows: usize) -> String {
    let mut s = String::from("| function (inclusive) | share of samples |\n|---|---|\n");
    for (f, share) in shares.iter().take(rows) {
        s += &format!("| `{f}` | {:.1} % |\n", 100.0 * share);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_peer_table_shows_both_posteriors_and_the_ratio_or_why_not() {
        let line = "anchor peer_s=14.0 ours_s=0.5 peer_mean=0.1422 peer_sd=0.0005 ours_mean=0.1421 ours_sd=0.0006 runs=3";
        let ran = BTreeMap::from([(
            PEER_SCRIPT.to_string(),
            Anchor::Ran(parse_anchor_line(line).unwrap()),
        )]);
        let t = whole_calibration_table(&ran);
        assert!(
            t.contains("| surmise 1.0 `directbayes` | 0.1422 ± 0.0005 | 14.00 s |"),
            "{t}"
        );
        assert!(
            t.contains("| bamudi (Python package) | 0.1421 ± 0.0006 | 500.00 ms |"),
            "{t}"
        );
        assert!(t.contains("| peer / ours | | 28.00x |"), "{t}");
        let skipped = BTreeMap::from([(
            PEER_SCRIPT.to_string(),
            Anchor::Skipped("No module named 'surmise'".into()),
        )]);
        let t = whole_calibration_table(&skipped);
        assert!(t.contains("not run: No module named 'surmise'"), "{t}");
        assert!(t.contains("| peer / ours | | — |"), "{t}");
    }

    #[test]
    fn anchor_lines_are_parsed_and_other_lines_ignored() {
        let v = parse_anchor_line("anchor gp_fit_s=14.460 lml=623.5822 tag=abc").unwrap();
        assert_eq!(v.get("gp_fit_s"), Some(&14.46));
        assert_eq!(v.get("lml"), Some(&623.5822));
        assert!(
            !v.contains_key("tag"),
            "a value that is not a number is dropped"
        );
        assert!(parse_anchor_line("run 1: fit=1.0s").is_none());
    }

    #[test]
    fn criterion_median_is_read_and_a_bad_file_is_an_error() {
        let json = r#"{"mean":{"point_estimate":2.0},"median":{"point_estimate":1500.5}}"#;
        assert_eq!(median_ns(json).unwrap(), 1500.5);
        let err = median_ns(r#"{"mean":{"point_estimate":2.0}}"#).unwrap_err();
        assert!(err.to_string().contains("median.point_estimate"), "{err}");
    }

    #[test]
    fn only_medians_written_in_this_run_are_read() {
        let root = std::env::temp_dir().join(format!("xtask-bench-test-{}", std::process::id()));
        let json = r#"{"median":{"point_estimate":7.0}}"#;
        for id in ["old", "fresh"] {
            let dir = root.join("g").join(id).join("new");
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join("estimates.json"), json).unwrap();
        }
        let since = SystemTime::now() - std::time::Duration::from_secs(60);
        let old = std::fs::File::options()
            .write(true)
            .open(root.join("g/old/new/estimates.json"))
            .unwrap();
        old.set_modified(since - std::time::Duration::from_secs(3600))
            .unwrap();
        let medians = criterion_medians(&root, since).unwrap();
        std::fs::remove_dir_all(&root).unwrap();
        assert_eq!(medians.keys().collect::<Vec<_>>(), ["g/fresh"]);
        assert_eq!(medians["g/fresh"], 7.0);
    }

    #[test]
    fn the_generated_section_is_replaced_in_place_or_appended() {
        let doc = format!("# B\n\nhand text\n\n{BEGIN}\nold\n{END}\n\ntail\n");
        let new = replace_section(&doc, "fresh");
        assert_eq!(
            new,
            format!("# B\n\nhand text\n\n{BEGIN}\nfresh\n{END}\n\ntail\n")
        );
        let appended = replace_section("# B\n", "fresh");
        assert_eq!(appended, format!("# B\n\n{BEGIN}\nfresh\n{END}\n"));
        assert_eq!(replace_section(&new, "fresh"), new, "idempotent");
    }

    #[test]
    fn inclusive_shares_count_each_function_once_per_sample() {
        let script = "xtask 1 [000] 1.0: cycles:\n\
            \t 55 mitergate::contact::solve::h1234 (/x)\n\
            \t 66 bamudi::posterior::run (/x)\n\
            \t 77 bamudi::posterior::run (/x)\n\
            \n\
            xtask 1 [000] 2.0: cycles:\n\
            \t 88 libm_exp (/x)\n\
            \t 99 bamudi::posterior::run (/x)\n";
        let shares = inclusive_shares(script);
        assert_eq!(shares[0], ("bamudi::posterior::run".to_string(), 1.0));
        assert_eq!(
            shares[1],
            ("mitergate::contact::solve::h1234".to_string(), 0.5)
        );
        assert_eq!(shares.len(), 2);
    }

    #[test]
    fn missing_peers_are_named_not_fatal() {
        let mut anchors = BTreeMap::new();
        anchors.insert(
            "gp_anchor.py".to_string(),
            Anchor::Skipped("ModuleNotFoundError: No module named 'sklearn'".into()),
        );
        let mut medians = BTreeMap::new();
        medians.insert("gp/fit_n500_d2_5restarts".to_string(), 1.0e9);
        let t = peer_table(&medians, &anchors);
        assert!(t.contains("1.00 s"), "{t}");
        assert!(t.contains("No module named 'sklearn'"), "{t}");
    }
}
