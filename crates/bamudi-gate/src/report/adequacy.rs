//! The adequacy verdict in `report.md` ([`bamudi::adequacy`]).

use bamudi::adequacy::{AdequacyReport, Attribution, Verdict};

/// The banner under the report's title when the model does not explain the data.
pub fn banner(a: Option<&AdequacyReport>) -> String {
    match a.map(|a| a.verdict) {
        Some(Verdict::Inadequate) => {
            "**INADEQUATE: the results below are of a model that does not explain \
             the data; see \"Adequacy\".**\n\n"
                .into()
        }
        _ => String::new(),
    }
}

fn attribution(a: Attribution) -> &'static str {
    match a {
        Attribution::Sensor => "sensor",
        Attribution::ModelForm => "model form",
        Attribution::Unexplained => "unexplained",
    }
}

/// The "Adequacy" section: verdict, failures, each gauge from the others, the sensor-fault
/// fits that matter, identifiability.
pub fn section(a: &AdequacyReport) -> String {
    let mut s = format!("## Adequacy\n\nverdict: **{}**\n\n", a.summary());
    if !a.failed.is_empty() {
        s += "| failed check | gauges | attribution | detail |\n|---|---|---|---|\n";
        for f in &a.failed {
            s += &format!(
                "| {} | {} | {} | {} |\n",
                f.check,
                f.gauges.join(", "),
                attribution(f.attribution),
                f.detail
            );
        }
        s += "\n";
    }
    if let Some(c) = &a.sensor_correction {
        s += &format!(
            "The failures are explained by sensor faults, fitted jointly with the calibration: \
             {} (output units; gain per unit, drift per record length). Correct or exclude \
             these gauges before trusting the gap.\n\n",
            c.describe()
        );
    }
    if !a.gauges.is_empty() {
        s += &format!(
            "Each gauge predicted from the others (chi-square over the experiments; one family \
             of {} tests, Holm, family-wise error {}):\n\n| gauge | chi-square / dof | p | mean \
             shift (µε) | outside 95 % band | Ljung-Box p |\n|---|---|---|---|---|---|\n",
            a.family_size(),
            a.family_alpha
        );
        for g in &a.gauges {
            s += &format!(
                "| {} | {:.2} | {:.2e} | {:+.2} | {:.1} % | {:.2e} |\n",
                g.gauge,
                g.chi2 / g.dof as f64,
                g.p_value,
                g.mean_shift,
                100.0 * g.outside_band_fraction,
                g.ljung_box_p
            );
        }
        s += "\n";
    }
    s += &faults_table(a);
    s += &identifiability(a);
    s
}

/// The sensor-fault fits with |z| ≥ 3 (all of them are in `results.json`).
fn faults_table(a: &AdequacyReport) -> String {
    let big: Vec<_> = a
        .sensor_faults
        .iter()
        .filter(|f| f.z.abs() >= 3.0)
        .collect();
    if big.is_empty() {
        return "No sensor-fault signature reaches |z| = 3.\n\n".into();
    }
    let mut s = String::from(
        "Sensor-fault signatures fitted jointly with the calibration, |z| ≥ 3 (offset, drift and \
         step in µε; gain as scale − 1):\n\n| gauge | kind | estimate ± sd | z | p (alone) |\n|---|---|---|---|---|\n",
    );
    for f in big {
        let at = f
            .at_fraction
            .map_or(String::new(), |t| format!(" at {t:.2}"));
        s += &format!(
            "| {} | {}{at} | {:+.3} ± {:.3} | {:.1} | {:.1e} |\n",
            f.gauge,
            f.kind.name(),
            f.estimate,
            f.sd,
            f.z,
            f.p_value
        );
    }
    s + "\n"
}

fn identifiability(a: &AdequacyReport) -> String {
    let Some(i) = &a.identifiability else {
        return String::new();
    };
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        "Identifiability at experiment {}: singular values of B D_a (µε per prior sd) {}; \
         posterior-to-prior variance along those directions {}; {} coefficient directions the \
         gauges cannot see; corr(ρ, θ) = {}; discrepancy amplitude s = {}.\n\n",
        i.experiment,
        fmt(&i.singular_values),
        fmt(&i.posterior_to_prior_variance),
        i.unseen_directions,
        i.rho_theta_correlation
            .map_or("n/a".into(), |c| format!("{c:.3}")),
        a.discrepancy_amplitude
            .map_or("n/a".into(), |s| format!("{s:.3}")),
    )
}
