use bamudi::BamudiError;
use bamudi::closeloop::{IngestConfig, MissingPolicy, parse_csv};

fn cfg() -> IngestConfig {
    IngestConfig::new(vec!["g1".into(), "g2".into()])
}

const HEAD: &str = "time,h_up,h_down,air_temp_f,g1,g2\n";

fn err(body: &str) -> String {
    parse_csv(&format!("{HEAD}{body}"), "f.csv", &cfg())
        .unwrap_err()
        .to_string()
}

#[test]
fn good_file_reads_covariates_and_hours() {
    let rec = parse_csv(
        &format!(
            "{HEAD}2024-01-01T00:00:00Z,300,100,40,1,2\n2024-01-01T01:30:00Z,100,100,41,0,0\n"
        ),
        "f.csv",
        &cfg(),
    )
    .unwrap();
    assert_eq!(rec.covariate_names, vec!["air_temp_f"]);
    assert_eq!(rec.time_h, vec![0.0, 1.5]);
    assert_eq!(rec.y[(0, 1)], 2.0);
}

#[test]
fn errors_name_file_line_and_column() {
    assert!(matches!(
        parse_csv("time,h_up,g1,g2\n", "f.csv", &cfg()),
        Err(BamudiError::Csv { ref column, ref reason, row: 1, .. })
            if column == "h_down" && reason == "missing column"
    ));
    let e = parse_csv("time,h_up,h_down,g1,g1,g2\n", "f.csv", &cfg()).unwrap_err();
    assert!(
        matches!(e, BamudiError::Csv { ref reason, .. } if reason == "duplicate column"),
        "{e}"
    );
    let e = err("2024-01-01T00:00:00Z,300,100,40,1,2\n2024-01-01T01:00:00Z,300,100,NaN,1,2\n");
    assert!(e.contains("f.csv: row 3, column `air_temp_f`"), "{e}");
    let e = err("2024-01-01T00:00:00Z,300,100,40,abc,2\n");
    assert!(e.contains("row 2, column `g1`: not a number"), "{e}");
    let e = err("2024-01-01T01:00:00Z,300,100,40,1,2\n2024-01-01T00:00:00Z,300,100,40,1,2\n");
    assert!(
        e.contains("row 3, column `time`: time does not increase"),
        "{e}"
    );
    let e = err("2024-01-01T00:00:00Z,800,100,40,1,2\n");
    assert!(
        e.contains("column `h_up`") && e.contains("outside the model domain"),
        "{e}"
    );
    let e = err("2024-01-01T00:00:00Z,100,300,40,1,2\n");
    assert!(e.contains("h_up 100 < h_down 300"), "{e}");
}

#[test]
fn missing_gauge_values_are_dropped_or_interpolated_and_counted() {
    let body = "2024-01-01T00:00:00Z,300,100,40,1,2\n2024-01-01T01:00:00Z,300,100,40,,4\n2024-01-01T02:00:00Z,300,100,40,3,6\n";
    let text = format!("{HEAD}{body}");
    let dropped = parse_csv(&text, "f.csv", &cfg()).unwrap();
    assert_eq!((dropped.len(), dropped.dropped_missing), (2, 1));
    let mut c = cfg();
    c.missing = MissingPolicy::Interpolate;
    let imputed = parse_csv(&text, "f.csv", &c).unwrap();
    assert_eq!((imputed.len(), imputed.imputed), (3, 1));
    assert_eq!(imputed.y[(1, 0)], 2.0); // halfway between 1 and 3
}

mod cli {
    use super::super::{base, record};
    use bamudi::closeloop::reference::{GridCalibrator, ToyGate};
    use bamudi::closeloop::report::{CloseLoopArgs, run_close_loop_command};
    use clap::Parser;
    use mitergate::field::FieldEffects;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: CloseLoopArgs,
    }

    fn calibrator() -> GridCalibrator {
        GridCalibrator::new(ToyGate::default(), super::super::GAP_BOUNDS)
    }

    #[test]
    fn command_reads_file_and_writes_report() {
        let dir = std::env::temp_dir().join("bamudi_closeloop_cli");
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("clean.csv");
        record(base(21, FieldEffects::default()).duration(12.0, 60.0))
            .write_csv(&csv)
            .unwrap();
        let out = dir.join("out");
        let cli = Cli::parse_from([
            "x",
            "--gauges",
            "g1,g2,g3,g4,g5,g6,g7",
            "--data",
            csv.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let report = run_close_loop_command(&cli.args, &calibrator()).unwrap();
        assert!(report.effects.is_empty());
        assert!(out.join("results.json").exists() && out.join("report.md").exists());
    }

    #[test]
    fn bad_config_is_a_clear_error() {
        let dir = std::env::temp_dir().join("bamudi_closeloop_cli_bad");
        std::fs::create_dir_all(&dir).unwrap();
        let csv = dir.join("clean.csv");
        record(base(22, FieldEffects::default()).duration(3.0, 60.0))
            .write_csv(&csv)
            .unwrap();
        let cfg = dir.join("cfg.toml");
        std::fs::write(&cfg, "calibration_fraction = 1.5\n").unwrap();
        let cli = Cli::parse_from([
            "x",
            "--gauges",
            "g1,g2,g3,g4,g5,g6,g7",
            "--data",
            csv.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
        ]);
        let err = run_close_loop_command(&cli.args, &calibrator())
            .unwrap_err()
            .to_string();
        assert!(err.contains("calibration_fraction"), "{err}");
        let cli = Cli::parse_from([
            "x",
            "--gauges",
            "g1,g2,g3,g4,g5,g6,g7",
            "--data",
            csv.to_str().unwrap(),
            "--holdout-fraction",
            "1.2",
        ]);
        let err = run_close_loop_command(&cli.args, &calibrator())
            .unwrap_err()
            .to_string();
        assert!(err.contains("--holdout-fraction"), "{err}");
    }
}
