//! The `bamudi` binary: clear errors for bad input, and a small simulate -> calibrate ->
//! predict round trip on a coarse gate (60 in elements, so it runs in seconds).
mod corpus;
mod deck;
mod docs;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bamudi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bamudi"))
        .args(args)
        .env("CI", "1") // no progress bars
        .output()
        .expect("the bamudi binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bamudi_cli_{}_{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn coarse_gate(d: &Path) -> String {
    let mut cfg = mitergate::GateConfig::default();
    cfg.mesh.element_size = 60.0;
    let p = d.join("coarse_gate.toml");
    std::fs::write(&p, cfg.to_toml_string().unwrap()).unwrap();
    p.to_str().unwrap().to_string()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs the command, expects failure, and checks that stderr names every piece.
fn fails_naming(args: &[&str], pieces: &[&str]) {
    let o = bamudi(args);
    let e = stderr(&o);
    assert!(!o.status.success(), "{args:?} succeeded: {e}");
    for p in pieces {
        assert!(e.contains(p), "{args:?}: stderr lacks `{p}`:\n{e}");
    }
}

#[test]
fn bad_arguments_and_files_are_clear_errors() {
    let d = dir("bad");
    let gate = coarse_gate(&d);
    // `--out` must not be a non-empty directory (that is its own error, tested in the corpus)
    let fresh = d.join("results");
    fails_naming(
        &["simulate", "field", "--effect", "rain", "--out", "x.csv"],
        &["unknown effect `rain`", "thermal"],
    );
    fails_naming(
        &[
            "simulate",
            "experiments",
            "--scenario",
            "3",
            "--out",
            "x.csv",
        ],
        &["--scenario", "scenarios 1 and 2"],
    );
    let missing = d.join("nope.toml");
    fails_naming(
        &[
            "calibrate",
            "--config",
            s(&missing),
            "--data",
            "x.csv",
            "--out",
            s(&fresh),
        ],
        &["nope.toml"],
    );
    let cfg = d.join("bad_prior.toml");
    std::fs::write(&cfg, "gap_prior = [105.0, 81.0]\n").unwrap();
    fails_naming(
        &[
            "calibrate",
            "--config",
            s(&cfg),
            "--data",
            "x.csv",
            "--out",
            s(&fresh),
        ],
        &["bad_prior.toml", "gap_prior"],
    );
    let cfg = d.join("typo.toml");
    std::fs::write(
        &cfg,
        "gap_prior = [81.0, 105.0]\n[calibration]\ntheta_grid = 5\n",
    )
    .unwrap();
    fails_naming(
        &[
            "calibrate",
            "--config",
            s(&cfg),
            "--data",
            "x.csv",
            "--out",
            s(&fresh),
        ],
        &["typo.toml", "theta_grid"],
    );
    let cfg = d.join("good.toml");
    std::fs::write(&cfg, "gap_prior = [81.0, 105.0]\n").unwrap();
    let csv = d.join("bad_row.csv");
    std::fs::write(
        &csv,
        "h_up,h_down,SG1,SG2,SG3,SG4,SG5,SG6,SG7\n500,100,1,2,3,4,5,6,7\n500,100,1,2,abc,4,5,6,7\n",
    )
    .unwrap();
    fails_naming(
        &[
            "calibrate",
            "--gate",
            &gate,
            "--config",
            s(&cfg),
            "--data",
            s(&csv),
            "--out",
            s(&fresh),
        ],
        &["bad_row.csv", "line 3", "`SG3`"],
    );
    let bad_gate = d.join("bad_gate.toml");
    std::fs::write(&bad_gate, "[mesh]\nelement_size = 60.0\n").unwrap();
    fails_naming(
        &[
            "simulate",
            "experiments",
            "--scenario",
            "1",
            "--gate",
            s(&bad_gate),
            "--out",
            "x.csv",
        ],
        &["bad_gate.toml"],
    );
    fails_naming(
        &[
            "predict",
            "--calibration",
            s(&d.join("none.json")),
            "--h-up",
            "500",
            "--h-down",
            "100",
        ],
        &["none.json"],
    );
    // the help shows `--gap-prior`'s default in the form the flag takes (`lo,hi`)
    let o = bamudi(&["close-loop", "--help"]);
    let help = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        help.contains("[default: 40,200]") && !help.contains("[default: 40 200]"),
        "{help}"
    );
}

#[test]
fn simulate_calibrate_predict_round_trip_on_a_coarse_gate() {
    let d = dir("round_trip");
    let gate = coarse_gate(&d);
    let exps = d.join("exps.csv");
    let o = bamudi(&[
        "--seed",
        "3",
        "simulate",
        "experiments",
        "--scenario",
        "1",
        "--n",
        "40",
        "--gate",
        &gate,
        "--out",
        s(&exps),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&exps).unwrap();
    assert_eq!(text.lines().count(), 41);
    assert!(text.starts_with("h_up,h_down,SG1"), "{text}");

    let cfg = d.join("cal.toml");
    std::fs::write(
        &cfg,
        "gap_prior = [81.0, 105.0]\n[calibration]\ntheta_grid_points = 49\ngp_restarts = 1\n[calibration.estimator]\nkind = \"exact_linear\"\n",
    )
    .unwrap();
    let out = d.join("results");
    let o = bamudi(&[
        "calibrate",
        "--gate",
        &gate,
        "--config",
        s(&cfg),
        "--data",
        s(&exps),
        "--out",
        s(&out),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}\n{stdout}", stderr(&o));
    for f in [
        "calibration.json",
        "model.json",
        "results.json",
        "report.md",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // the data come from the same coarse gate with θ* = 90 in. A single 95 % interval misses
    // the truth in 1 run of 20 even when everything is right (this seed gives [90.4, 96.4]),
    // so the check is 3 posterior sd (misses ~0.3 % of runs under a correct posterior) and a
    // posterior clearly narrower than the U(81, 105) prior (sd 6.9 in)
    let cal = bamudi::Calibration::load(&out.join("calibration.json")).unwrap();
    let post = &cal.module3().posterior;
    let (mean, sd) = (post.mean()[0], post.sd()[0]);
    assert!(
        (mean - 90.0).abs() < 3.0 * sd,
        "mean {mean}, sd {sd}\n{stdout}"
    );
    assert!(
        sd < 3.0,
        "posterior sd {sd} in: the data did not inform θ\n{stdout}"
    );

    // the report states its inputs (and what ρ's spread is not); a second run into the same
    // --out is refused, and with --force replaces it whole (no stale file of the first run
    // survives)
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    for piece in [
        "## Inputs",
        "exps.csv",
        "U(81, 105) in",
        "element size 60 in",
        // the identified ρ⊥ is reported; the split's ρ is said not to be identified, not
        // offered as an interval
        "ρ⊥, the data's scale of the nominal force",
        "is not identified by the data",
    ] {
        assert!(
            report.contains(piece),
            "report.md lacks `{piece}`:\n{report}"
        );
    }
    std::fs::write(out.join("stale.txt"), "from an earlier run").unwrap();
    let again = |force: bool| {
        let mut args = vec![
            "calibrate",
            "--gate",
            &gate,
            "--config",
            s(&cfg),
            "--data",
            s(&exps),
        ];
        args.extend(["--out", s(&out)]);
        if force {
            args.push("--force");
        }
        bamudi(&args)
    };
    let o = again(false);
    assert!(
        !o.status.success() && stderr(&o).contains("--force"),
        "{}",
        stderr(&o)
    );
    assert!(
        out.join("stale.txt").exists(),
        "a refused run must not touch the old result"
    );
    let o = again(true);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("stale.txt").exists() && out.join("calibration.json").exists());

    let forces = d.join("forces.csv");
    let o = bamudi(&[
        "predict",
        "--calibration",
        s(&out.join("calibration.json")),
        "--h-up",
        "600",
        "--h-down",
        "100",
        "--forces-out",
        s(&forces),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        stdout
            .lines()
            .filter(|l| l.trim_start().starts_with("SG"))
            .count(),
        7,
        "{stdout}"
    );
    let csv = std::fs::read_to_string(&forces).unwrap();
    assert!(csv.starts_with("z_in,normal_mean_lbf_per_in"), "{csv}");
    // one row per representation point along the 762 in quoin, plus the header
    assert!(csv.lines().count() > 10, "{csv}");
    // out-of-domain levels are an error that names the input
    let o = bamudi(&[
        "predict",
        "--calibration",
        s(&out.join("calibration.json")),
        "--h-up",
        "900",
        "--h-down",
        "100",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("h_up"), "{}", stderr(&o));

    // fatigue over a load history: a simulated field record, of which only the levels and
    // times are read; one row per quoin point, as in the forces CSV
    let field = d.join("field.csv");
    let o = bamudi(&[
        "--seed",
        "4",
        "simulate",
        "field",
        "--days",
        "3",
        "--gate",
        &gate,
        "--out",
        s(&field),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let fatigue = d.join("fatigue.csv");
    let predict_record = |record: &Path| {
        bamudi(&[
            "predict",
            "--calibration",
            s(&out.join("calibration.json")),
            "--record",
            s(record),
            "--record-out",
            s(&fatigue),
        ])
    };
    let o = predict_record(&field);
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout.contains("lockages counted"), "{stdout}");
    let table = std::fs::read_to_string(&fatigue).unwrap();
    assert!(table.starts_with("z_in,damage_per_1000_before"), "{table}");
    assert_eq!(table.lines().count(), csv.lines().count(), "{table}");
    // a history whose time runs backwards is an error naming the file and the row
    let text = std::fs::read_to_string(&field).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.swap(5, 6);
    let shuffled = d.join("shuffled.csv");
    std::fs::write(&shuffled, lines.join("\n")).unwrap();
    std::fs::remove_file(&fatigue).unwrap();
    let o = predict_record(&shuffled);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("shuffled.csv") && stderr(&o).contains("time"),
        "{}",
        stderr(&o)
    );
    assert!(
        !fatigue.exists(),
        "a failed run must not leave a fatigue table"
    );
    a_calibration_without_node_columns_is_a_clear_error(&d, &out.join("calibration.json"));
}

/// A calibration file in the format before the marginal nodes kept their columns `c` and `a`
/// (here: this run's file with them removed) is refused with the key and the remedy, not
/// with a panic or a prediction from empty columns.
fn a_calibration_without_node_columns_is_a_clear_error(d: &Path, saved: &Path) {
    let text = std::fs::read_to_string(saved).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let nodes = json["module3"]["marginal"]["nodes"]
        .as_array_mut()
        .expect("the default calibration is the marginal mode's, with nodes");
    for node in nodes {
        let node = node.as_object_mut().unwrap();
        node.remove("c");
        node.remove("a");
    }
    let old = d.join("old_format.json");
    std::fs::write(&old, json.to_string()).unwrap();
    fails_naming(
        &[
            "predict",
            "--calibration",
            s(&old),
            "--h-up",
            "600",
            "--h-down",
            "100",
        ],
        &[
            "old_format.json",
            "module3.marginal.nodes[0].c",
            "calibrate again",
        ],
    );
}

#[test]
fn close_loop_command_reads_a_record_and_writes_its_report() {
    let d = dir("close_loop");
    let gate = coarse_gate(&d);
    let csv = d.join("field.csv");
    let o = bamudi(&[
        "--seed",
        "21",
        "simulate",
        "field",
        "--days",
        "12",
        "--gate",
        &gate,
        "--out",
        s(&csv),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = d.join("loop");
    // the documented form of --gap-prior (lo,hi)
    let o = bamudi(&[
        "close-loop",
        "--gate",
        &gate,
        "--data",
        s(&csv),
        "--gap-prior",
        "60,150",
        "--max-experiments",
        "60",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("results.json").exists() && out.join("report.md").exists());
    // the prediction level over the record: report section, JSON key and plot
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("## Quoin-block fatigue over the record"),
        "{report}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let fatigue = &json["record_fatigue"];
    assert!(fatigue["lockages"].as_f64().unwrap() > 10.0, "{fatigue}");
    assert_eq!(
        fatigue["z_in"].as_array().unwrap().len(),
        fatigue["before"].as_array().unwrap().len()
    );
    assert!(out.join("fatigue_along_quoin.svg").exists());
    let bad = d.join("bad.toml");
    std::fs::write(&bad, "calibration_fraction = 1.5\n").unwrap();
    fails_naming(
        &[
            "close-loop",
            "--gate",
            &gate,
            "--data",
            s(&csv),
            "--config",
            s(&bad),
        ],
        &["calibration_fraction"],
    );
    fails_naming(
        &[
            "close-loop",
            "--gate",
            &gate,
            "--data",
            s(&csv),
            "--holdout-fraction",
            "1.2",
        ],
        &["--holdout-fraction"],
    );
    fails_naming(
        &[
            "close-loop",
            "--gate",
            &gate,
            "--data",
            s(&csv),
            "--gap-prior",
            "60",
        ],
        &["--gap-prior", "two numbers"],
    );
}

/// `simulate --reality`: a sensor error moves its gauge's column by exactly its formula and no
/// other; an as-built gate moves every gauge but not the levels (same seed); a bad
/// specification is an error naming the file and the key.
#[test]
fn simulate_with_a_reality_departs_from_the_gate_as_declared() {
    let d = dir("reality");
    let gate = coarse_gate(&d);
    let run = |name: &str, reality: Option<&str>| -> Vec<Vec<f64>> {
        let out = d.join(format!("{name}.csv"));
        let mut args = vec!["--seed", "5", "simulate", "experiments", "--scenario", "1"];
        args.extend(["--n", "30", "--gate", &gate, "--out", s(&out)]);
        let spec = d.join(format!("{name}.toml"));
        if let Some(text) = reality {
            std::fs::write(&spec, text).unwrap();
            args.extend(["--reality", s(&spec)]);
        }
        let o = bamudi(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = std::fs::read_to_string(&out).unwrap();
        text.lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let base = run("base", None);
    // SG2 is column 3 (after h_up, h_down)
    let sensor = run(
        "sensor",
        Some("[[sensors]]\ngauge = \"SG2\"\nscale = 1.5\noffset_microstrain = 5.0\n"),
    );
    for (b, r) in base.iter().zip(&sensor) {
        for c in 0..b.len() {
            let want = if c == 3 { 1.5 * b[c] + 5.0 } else { b[c] };
            // the CSV prints enough digits for 1e-9 relative
            assert!(
                (r[c] - want).abs() <= 1e-9 * want.abs().max(1.0),
                "column {c}: {} vs {want}",
                r[c]
            );
        }
    }
    let as_built = run("as_built", Some("[as_built.skin_plate]\nthickness = 0.6\n"));
    let moved = (2..base[0].len())
        .filter(|&c| {
            base.iter()
                .zip(&as_built)
                .any(|(b, r)| (b[c] - r[c]).abs() > 1e-6)
        })
        .count();
    assert_eq!(
        moved,
        base[0].len() - 2,
        "every gauge should see a thicker skin plate"
    );
    assert!(base.iter().zip(&as_built).all(|(b, r)| b[..2] == r[..2]));
    let bad = d.join("bad.toml");
    std::fs::write(&bad, "[as_built.skin_plate]\nthicknes = 0.6\n").unwrap();
    fails_naming(
        &[
            "simulate",
            "experiments",
            "--scenario",
            "1",
            "--n",
            "5",
            "--gate",
            &gate,
            "--reality",
            s(&bad),
            "--out",
            s(&d.join("x.csv")),
        ],
        &["bad.toml", "as_built.skin_plate.thicknes"],
    );
}
