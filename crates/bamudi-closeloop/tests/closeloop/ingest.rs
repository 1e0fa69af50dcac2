use bamudi_closeloop::CloseLoopError;
use bamudi_closeloop::{IngestConfig, MissingPolicy, parse_csv};

fn cfg() -> IngestConfig {
    IngestConfig::new(&["h_up", "h_down"], &["g1", "g2"])
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
        Err(CloseLoopError::Csv { ref column, ref reason, row: 1, .. })
            if column == "h_down" && reason.starts_with("missing column")
    ));
    let e = parse_csv("time,h_up,h_down,g1,g1,g2\n", "f.csv", &cfg()).unwrap_err();
    assert!(
        matches!(e, CloseLoopError::Csv { ref reason, .. } if reason.starts_with("duplicate column")),
        "{e}"
    );
    let e = err("2024-01-01T00:00:00Z,300,100,40,1,2\n2024-01-01T01:00:00Z,300,100,NaN,1,2\n");
    assert!(e.contains("f.csv: line 3, column `air_temp_f`"), "{e}");
    let e = err("2024-01-01T00:00:00Z,300,100,40,abc,2\n");
    assert!(
        e.contains("line 2, column `g1`: `abc` is not a number"),
        "{e}"
    );
    let e = err("2024-01-01T01:00:00Z,300,100,40,1,2\n2024-01-01T00:00:00Z,300,100,40,1,2\n");
    assert!(
        e.contains("line 3, column `time`: time does not increase"),
        "{e}"
    );
    let e = err("2024-01-01T00:00:00Z,300,100,40,1,2\nyesterday,300,100,40,1,2\n");
    assert!(
        e.contains("line 3, column `time`") && e.contains("ISO 8601"),
        "{e}"
    );
    let e = err("2024-01-01T00:00:00Z,300,100,40,1\n");
    assert!(
        e.contains("line 2") && e.contains("5 fields, the header has 6"),
        "{e}"
    );
}

#[test]
fn input_checks_name_the_line_of_the_refused_row() {
    let rec = parse_csv(
        &format!("{HEAD}0,300,100,40,1,2\n1,100,300,40,1,2\n"),
        "f.csv",
        &cfg(),
    )
    .unwrap();
    let e = rec
        .check_inputs(|x| match x[0] >= x[1] {
            true => Ok(()),
            false => Err(format!("h_up {} < h_down {}", x[0], x[1])),
        })
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("f.csv: line 3") && e.contains("h_up 100 < h_down 300"),
        "{e}"
    );
}

#[test]
fn missing_gauge_values_are_dropped_or_interpolated_and_counted() {
    let body = "2024-01-01T00:00:00Z,300,100,40,1,2\n2024-01-01T01:00:00Z,300,100,40,,4\n2024-01-01T02:00:00Z,300,100,40,3,6\n";
    let text = format!("{HEAD}{body}");
    let dropped = parse_csv(&text, "f.csv", &cfg()).unwrap();
    assert_eq!((dropped.len(), dropped.dropped_missing), (2, 1));
    let c = cfg().missing(MissingPolicy::Interpolate);
    let imputed = parse_csv(&text, "f.csv", &c).unwrap();
    assert_eq!((imputed.len(), imputed.imputed), (3, 1));
    assert_eq!(imputed.y[(1, 0)], 2.0); // halfway between 1 and 3
}
