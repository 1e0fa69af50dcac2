//! Synthetic data: the paper's experiments and months-long field records, on a gate or on a
//! reality that departs from it (the same functions as `bamudi simulate`).

use crate::gate::Gate;
use crate::{invalid, to_py};
use mitergate::ContactModel;
use mitergate::data::field::{FieldConfig, FieldEffects, MissingValues};
use mitergate::data::truth::Scenario;
use mitergate::reality::Reality;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The CSV text `bamudi simulate experiments` writes for these experiments (the first two
/// columns are the inputs): the same function, so the same digits.
#[pyfunction]
pub fn experiments_csv(columns: Vec<String>, data: PyReadonlyArray2<'_, f64>) -> PyResult<String> {
    let a = data.as_array();
    if columns.len() != a.ncols() || columns.len() < 3 {
        return Err(invalid(format!(
            "experiments need h_up, h_down and at least one gauge column matching the array: \
             {} names for {} columns",
            columns.len(),
            a.ncols()
        )));
    }
    let x = nalgebra::DMatrix::from_fn(a.nrows(), 2, |i, j| a[(i, j)]);
    let y = nalgebra::DMatrix::from_fn(a.nrows(), a.ncols() - 2, |i, j| a[(i, j + 2)]);
    let exps = bamudi::Experiments::new(columns[..2].to_vec(), columns[2..].to_vec(), x, y)
        .map_err(to_py)?;
    Ok(exps.to_csv_string())
}

/// Most rows of a simulated field record (as `bamudi simulate field`).
const MAX_FIELD_ROWS: f64 = 200_000.0;

/// The truth's contact model: the gate's own, or the reality's (as built, mesh, support).
fn truth(
    py: Python<'_>,
    gate: &Gate,
    reality: Option<&PathBuf>,
) -> PyResult<(ContactModel, Reality)> {
    let Some(path) = reality else {
        return Ok((gate.contact.clone(), Reality::default()));
    };
    let context = |e: &dyn std::fmt::Display| invalid(format!("reality {}: {e}", path.display()));
    let drawing = gate.config().ok_or_else(|| {
        context(
            &"a reality declares deviations from a gate configuration; a gate imported \
                  from a deck has none",
        )
    })?;
    let r = Reality::from_file(path).map_err(|e| context(&e))?;
    let built = py.detach(|| bamudi_gate::gate::build_truth(&r, drawing));
    let contact = built.map_err(|e| context(&e))?;
    Ok((contact, r))
}

/// The paper's synthetic experiments (Sec. 4.3) of `scenario` (1: θ* = 90 in, 2: θ* = 150
/// in): returns `(columns, data)` with columns `h_up`, `h_down` (in) and one per gauge
/// (microstrain), `data` an `(n, 2 + gauges)` float64 array. `seed` defaults to the scenario
/// number, as on the command line.
#[pyfunction]
#[pyo3(signature = (gate, scenario, n=500, noise_sd=1.0, seed=None, reality=None))]
pub fn simulate_experiments<'py>(
    py: Python<'py>,
    gate: &Gate,
    scenario: u8,
    n: usize,
    noise_sd: f64,
    seed: Option<u64>,
    reality: Option<PathBuf>,
) -> PyResult<(Vec<String>, Bound<'py, PyArray2<f64>>)> {
    if !(1..=1_000_000).contains(&n) {
        return Err(invalid(format!("n must be in [1, 1000000], got {n}")));
    }
    if !(noise_sd.is_finite() && (0.0..=1000.0).contains(&noise_sd)) {
        return Err(invalid(format!(
            "noise_sd must be in [0, 1000] microstrain, got {noise_sd}"
        )));
    }
    let mut sc = Scenario::paper(scenario)
        .map_err(|e| invalid(format!("scenario: {e}")))?
        .n_experiments(n)
        .noise_sd(noise_sd);
    if let Some(s) = seed {
        sc = sc.seed(s);
    }
    sc.validate().map_err(to_py)?;
    let (contact, reality) = truth(py, gate, reality.as_ref())?;
    let exps = py
        .detach(|| bamudi_gate::session::simulate_experiments(&sc, &contact, &reality))
        .map_err(|e| invalid(format!("generating the experiments: {e}")))?;
    let mut columns = exps.input_names.clone();
    columns.extend(exps.output_names.iter().cloned());
    let (rows, k) = (exps.len(), columns.len());
    let data = ndarray::Array2::from_shape_fn((rows, k), |(i, j)| {
        if j < 2 {
            exps.x[(i, j)]
        } else {
            exps.y[(i, j - 2)]
        }
    });
    Ok((columns, data.into_pyarray(py)))
}

/// A months-long field record with the gate (or a reality) as the true strain function:
/// returns a dict with `csv` (the record as `bamudi simulate field` writes it), `columns` and
/// `data` (float64, `NaN` where a value is missing; the `time` column left out),
/// `time_unix_s` (int64) and the true gap `gap_in` per row.
#[pyfunction]
#[pyo3(signature = (gate, days=60.0, step_minutes=60.0, effects=vec!["none".to_string()],
                    gap=90.0, final_gap=None, noise_sd=1.0, missing=None, seed=None,
                    reality=None))]
#[allow(clippy::too_many_arguments)]
pub fn simulate_field<'py>(
    py: Python<'py>,
    gate: &Gate,
    days: f64,
    step_minutes: f64,
    effects: Vec<String>,
    gap: f64,
    final_gap: Option<f64>,
    noise_sd: f64,
    missing: Option<f64>,
    seed: Option<u64>,
    reality: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    check_range("days", days, 0.0, 3650.0, false)?;
    check_range("step_minutes", step_minutes, 1.0, 1440.0, true)?;
    check_range("noise_sd", noise_sd, 0.0, 1000.0, true)?;
    check_range("gap", gap, 0.0, 10_000.0, false)?;
    if let Some(g) = final_gap {
        check_range("final_gap", g, 0.0, 10_000.0, false)?;
    }
    let mut fx = FieldEffects::from_presets(&effects, final_gap).map_err(|e| match e {
        mitergate::GateError::InvalidInput { what, reason } if what == "final_gap" => {
            invalid(format!("final_gap: {reason}"))
        }
        mitergate::GateError::InvalidInput { reason, .. } => invalid(format!("effects: {reason}")),
        e => invalid(format!("effects: {e}")),
    })?;
    if let Some(p) = missing {
        check_range("missing", p, 0.0, 0.9, true)?;
        fx.missing = Some(MissingValues { probability: p });
    }
    let rows = days * 1440.0 / step_minutes;
    if rows > MAX_FIELD_ROWS {
        return Err(invalid(format!(
            "days {days} at step_minutes {step_minutes} gives {rows:.0} rows; at most \
             {MAX_FIELD_ROWS} (shorten the record or sample less often)"
        )));
    }
    let cfg = FieldConfig::default()
        .seed(seed.unwrap_or(0))
        .duration(days, step_minutes)
        .noise_sd(noise_sd)
        .gap(gap)
        .effects(fx);
    let (contact, reality) = truth(py, gate, reality.as_ref())?;
    let rec = py
        .detach(|| {
            let mut rec = bamudi_gate::gate::simulate_field(&cfg, &contact)?;
            reality.apply_to_field(&mut rec);
            Ok::<_, bamudi_gate::GateAppError>(rec)
        })
        .map_err(to_py)?;
    record_dict(py, &rec)
}

/// The record as a dict of numpy arrays beside its CSV text.
fn record_dict<'py>(
    py: Python<'py>,
    rec: &mitergate::data::field::FieldRecord,
) -> PyResult<Bound<'py, PyDict>> {
    let mut columns: Vec<String> = [
        "h_up",
        "h_down",
        "upper_pool",
        "chamber",
        "air_temp_f",
        "water_temp_f",
        "lockage_phase",
    ]
    .map(String::from)
    .to_vec();
    columns.extend(rec.gauge_names.iter().cloned());
    let data = ndarray::Array2::from_shape_fn((rec.len(), columns.len()), |(i, j)| match j {
        0 => rec.h_up[i],
        1 => rec.h_down[i],
        2 => rec.upper_pool[i],
        3 => rec.chamber[i],
        4 => rec.air_temp_f[i],
        5 => rec.water_temp_f[i],
        6 => f64::from(rec.lockage_phase[i]),
        _ => rec.strains[i][j - 7].unwrap_or(f64::NAN),
    });
    let d = PyDict::new(py);
    d.set_item("csv", rec.to_csv_string())?;
    d.set_item("columns", columns)?;
    d.set_item("data", data.into_pyarray(py))?;
    d.set_item(
        "time_unix_s",
        PyArray1::from_vec(py, rec.time_unix_s.clone()),
    )?;
    d.set_item("gap_in", PyArray1::from_vec(py, rec.gap_in.clone()))?;
    Ok(d)
}

/// `value` must be finite and in `[lo, hi]` (or `(lo, hi]` when `closed` is false).
pub(crate) fn check_range(name: &str, value: f64, lo: f64, hi: f64, closed: bool) -> PyResult<()> {
    let above = if closed { value >= lo } else { value > lo };
    if value.is_finite() && above && value <= hi {
        return Ok(());
    }
    let open = if closed { "[" } else { "(" };
    Err(invalid(format!(
        "{name} must be in {open}{lo}, {hi}], got {value}"
    )))
}
