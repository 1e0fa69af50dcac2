use super::*;
use mitergate::data::field::*;

/// Noise sd of every simulated record (microstrain), the FieldConfig default.
const NOISE: f64 = 1.0;

/// The loop names `expected` first, reaches the noise level on held-out data and does not
/// move the gap away from `true_gap`.
fn check_found(name: &str, out: &CloseLoopOutcome, expected: &str, true_gap: f64) {
    summary(name, out);
    let r = &out.report;
    assert!(!r.effects.is_empty(), "{name}: no effect found");
    assert_eq!(
        r.effects[0].name, expected,
        "{name}: wrong effect named first"
    );
    // the brief's acceptance bar: held-out RMSE within 1.5x the noise level
    assert!(
        r.heldout_rmse_total_after <= 1.5 * NOISE,
        "{name}: rmse after {}",
        r.heldout_rmse_total_after
    );
    assert!(r.heldout_rmse_total_after < r.heldout_rmse_total_before);
    // toward the truth; 0.5 in slack is ~5 posterior sds of an unbiased estimate, for records
    // where the effect hardly biased the gap in the first place
    let (before, after) = (
        (r.theta_before.mean - true_gap).abs(),
        (r.theta_after.mean - true_gap).abs(),
    );
    assert!(
        after <= before + 0.5,
        "{name}: gap error {before:.2} -> {after:.2} in"
    );
}

/// Thermal strain, 0.6-2 microstrain/°F on a 6 h lag of the air temperature, zeroed at 60 °F.
fn thermal() -> FieldEffects {
    FieldEffects {
        thermal: Some(ThermalEffect {
            coefficients: vec![1.5, -1.0, 2.0, 0.8, -1.2, 1.0, 0.6],
            lag_hours: 6.0,
            source: TemperatureSource::Air,
            reference_f: 60.0,
        }),
        ..Default::default()
    }
}

/// Gauge drift of 0.1-0.3 microstrain/day.
fn drift() -> FieldEffects {
    FieldEffects {
        drift: Some(DriftEffect {
            rates_per_day: vec![0.3, -0.2, 0.25, 0.1, -0.3, 0.2, 0.15],
        }),
        ..Default::default()
    }
}

/// A 20 microstrain step in g3 on day 15.
fn jump() -> FieldEffects {
    FieldEffects {
        offset_jump: Some(OffsetJump {
            gauge: 2,
            at_day: 15.0,
            size_microstrain: 20.0,
        }),
        ..Default::default()
    }
}

/// Filling/emptying hysteresis of 4-8 microstrain peak.
fn hysteresis() -> FieldEffects {
    FieldEffects {
        hysteresis: Some(LoadPathHysteresis {
            amplitude: vec![8.0, -6.0, 7.0, 5.0, -6.0, 4.0, 4.0],
        }),
        ..Default::default()
    }
}

/// The gap grows from 90 in to 130 in over the record.
fn gap_growth() -> FieldEffects {
    FieldEffects {
        gap_growth: Some(GapGrowth {
            final_gap_in: 130.0,
        }),
        ..Default::default()
    }
}

/// Lock-wall flexure, 0.3-0.6 microstrain per inch of upper pool (not in the library).
fn wall_flexure() -> FieldEffects {
    FieldEffects {
        wall_flexure: Some(WallFlexure {
            coefficients: vec![0.6, -0.4, 0.5, 0.3, -0.5, 0.4, 0.3],
        }),
        ..Default::default()
    }
}

#[test]
fn thermal_strain_is_named_and_removes_the_gap_bias() {
    let out = run(&record(base(2, thermal())));
    check_found("thermal", &out, "thermal(air_temp_f)", 90.0);
    // the fitted lag is near the true 6 h (daily cycle makes it well identified)
    let lag = &out.report.effects[0].parameters[3].values[0];
    // the daily cycle pins the lag: a 1.5 h error would shift the daily thermal wave by ~20 min,
    // a misfit of several microstrain that the held-out RMSE bar would not tolerate anyway
    assert!((lag - 6.0).abs() < 1.5, "lag {lag}");
    let truth = [1.5, -1.0, 2.0, 0.8, -1.2, 1.0, 0.6];
    let coef = &out.report.effects[0].parameters[0].values;
    let zero_t = &out.report.effects[0].parameters[2].values;
    for g in 0..7 {
        // ~850 hourly rows, temperature sd ~8 °F, unit noise: coefficient se ~0.005 microstrain/°F;
        // 0.05 leaves room for the small lag misfit
        assert!((coef[g] - truth[g]).abs() < 0.05, "coefficients {coef:?}");
        // the gauges were zeroed at 60 °F; 1 °F is ~10 se of -intercept/coefficient
        assert!(
            (zero_t[g] - 60.0).abs() < 1.0,
            "zero-strain temperatures {zero_t:?}"
        );
    }
}

#[test]
fn gauge_drift_is_named() {
    let fx = FieldEffects {
        drift: Some(DriftEffect {
            rates_per_day: vec![0.3, -0.2, 0.25, 0.1, -0.3, 0.2, 0.15],
        }),
        ..Default::default()
    };
    check_found("drift", &run(&record(base(3, fx))), "gauge_drift", 90.0);
}

#[test]
fn offset_jump_is_named_with_its_gauge_and_day() {
    let fx = FieldEffects {
        offset_jump: Some(OffsetJump {
            gauge: 2,
            at_day: 15.0,
            size_microstrain: 20.0,
        }),
        ..Default::default()
    };
    let out = run(&record(base(4, fx)));
    check_found("jump", &out, "gauge_offset_jump", 90.0);
    let days = &out.report.effects[0].parameters[1].values;
    // hourly samples: the step is located to within a few hours
    assert!((days[2] - 15.0).abs() < 0.2, "{days:?}");
}

#[test]
fn load_path_hysteresis_is_named() {
    let fx = FieldEffects {
        hysteresis: Some(LoadPathHysteresis {
            amplitude: vec![8.0, -6.0, 7.0, 5.0, -6.0, 4.0, 4.0],
        }),
        ..Default::default()
    };
    // 15 minute sampling so that fills and emptyings (30 min) are seen
    let out = run(&record(base(5, fx).duration(30.0, 15.0)));
    check_found("hysteresis", &out, "load_path_hysteresis", 90.0);
}

#[test]
fn growing_gap_is_named_and_tracked() {
    let fx = FieldEffects {
        gap_growth: Some(GapGrowth {
            final_gap_in: 130.0,
        }),
        ..Default::default()
    };
    let out = run(&record(base(6, fx)));
    // the truth that matters is the gap now, at the end of the record
    check_found("gap growth", &out, "time_varying_gap", 130.0);
    let t = out.report.theta_after;
    assert!(t.ci95.0 <= 130.0 && 130.0 <= t.ci95.1, "{t:?}");
}

#[test]
fn undeclared_effect_is_traced_to_its_covariate() {
    let fx = FieldEffects {
        wall_flexure: Some(WallFlexure {
            coefficients: vec![0.6, -0.4, 0.5, 0.3, -0.5, 0.4, 0.3],
        }),
        ..Default::default()
    };
    let out = run(&record(base(7, fx)));
    check_found("wall flexure", &out, "generic_covariate_term", 90.0);
    assert!(
        out.report.effects[0]
            .covariates
            .contains(&"upper_pool".to_string()),
        "{:?}",
        out.report.effects[0].covariates
    );
}

#[test]
fn clean_records_get_no_effect() {
    // false positives over 5 seeds; the count is stated in docs/closeloop.md
    let mut false_positives = 0;
    for seed in 10..15 {
        let out = run(&record(base(seed, FieldEffects::default())));
        summary(&format!("clean seed {seed}"), &out);
        false_positives += usize::from(!out.report.effects.is_empty());
        assert!(out.report.conclusion.starts_with("no missing effect found"));
    }
    assert_eq!(false_positives, 0);
}

#[test]
fn report_files_are_written() {
    let fx = FieldEffects {
        missing: Some(MissingValues { probability: 0.002 }),
        ..thermal()
    };
    let out = run(&record(base(2, fx)));
    let dir = std::env::temp_dir().join("bamudi_closeloop_demo");
    let files = bamudi_gate::report::closeloop::write_report(&out, None, None, &dir).unwrap();
    for f in &files {
        assert!(std::fs::metadata(f).unwrap().len() > 100, "{}", f.display());
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    for key in [
        "effects",
        "heldout_rmse_before",
        "heldout_rmse_after",
        "theta_before",
        "theta_after",
        "error_window",
        "events",
        "theta_track",
        "alarms",
        "wall_time_s",
    ] {
        assert!(json.get(key).is_some(), "{key}");
    }
    assert!(json["wall_time_s"].as_f64().unwrap() > 0.0);
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    for section in [
        "## Alarms",
        "## Gap through the record",
        "Wall time of the loop",
    ] {
        assert!(md.contains(section), "report.md lacks {section}");
    }
    assert!(out.report.dropped_missing > 0);
}

/// Generates the scenario table of docs/closeloop.md (slow: ~2 min). Run with
/// `cargo test -p bamudi-gate --test lib scenario_table -- --ignored --nocapture`.
#[test]
#[ignore = "documentation generator, not a check"]
fn scenario_table() {
    let both = FieldEffects {
        thermal: thermal().thermal,
        offset_jump: jump().offset_jump,
        ..Default::default()
    };
    let cases: Vec<(&str, FieldConfig, f64)> = vec![
        ("thermal", base(2, thermal()), 90.0),
        ("drift", base(3, drift()), 90.0),
        ("offset jump", base(4, jump()), 90.0),
        (
            "hysteresis (15 min, 30 d)",
            base(5, hysteresis()).duration(30.0, 15.0),
            90.0,
        ),
        ("gap 90 -> 130 in", base(6, gap_growth()), 130.0),
        ("wall flexure (undeclared)", base(7, wall_flexure()), 90.0),
        ("thermal + offset jump", base(8, both), 90.0),
    ];
    println!(
        "| simulated effect | effects found (covariates) | held-out RMSE before -> after (microstrain) | gap before -> after (in, truth) |"
    );
    println!("|---|---|---|---|");
    for (name, cfg, truth) in cases {
        let r = run(&record(cfg)).report;
        let fx: Vec<String> = r
            .effects
            .iter()
            .map(|e| format!("{} ({})", e.name, e.covariates.join(", ")))
            .collect();
        println!(
            "| {name} | {} | {:.2} -> {:.2} | {:.1} ± {:.1} -> {:.1} ± {:.1} ({truth}) |",
            fx.join("; "),
            r.heldout_rmse_total_before,
            r.heldout_rmse_total_after,
            r.theta_before.mean,
            r.theta_before.sd,
            r.theta_after.mean,
            r.theta_after.sd
        );
    }
    let (mut fail_checks, mut accepted) = (0, 0);
    let seeds = 100..140;
    for seed in seeds.clone() {
        let r = run(&record(base(seed, FieldEffects::default()))).report;
        fail_checks += usize::from(r.checks_before.iter().any(|c| !c.passed()));
        accepted += usize::from(!r.effects.is_empty());
    }
    println!(
        "\nclean records, seeds {seeds:?}: {fail_checks} failed an adequacy check, {accepted} got an effect"
    );
}
