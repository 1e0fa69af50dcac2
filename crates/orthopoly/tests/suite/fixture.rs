//! Agreement with numpy.polynomial (fixture written by scripts/orthopoly_fixture.py).
use orthopoly::{Basis, Family, Normalization, gauss_hermite_prob, gauss_legendre};
use serde_json::Value;

fn fixture() -> Value {
    let text = include_str!("../data/numpy_fixture.json");
    serde_json::from_str(text).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn table(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().unwrap().iter().map(floats).collect()
}

/// Classical values on [-1, 1] (so `t = z`) for degrees 0..=max_degree at each point.
fn classical_rows(family: Family, points: &[f64], n_terms: usize, a: f64, b: f64) -> Vec<Vec<f64>> {
    let basis = Basis::with_normalization(family, a, b, n_terms, Normalization::Classical).unwrap();
    points
        .iter()
        .map(|&t| basis.eval(basis.from_reference(t)).unwrap())
        .collect()
}

/// Majorant `M_n(|x|)` of the probabilists' Hermite recurrence with every sign made positive:
/// `M_{n+1} = |x| M_n + n M_{n-1}`. Round-off in either recurrence (ours or numpy's
/// Clenshaw) is bounded by a modest multiple of `n · eps · M_n(|x|)`, which can exceed
/// `|He_n(x)|` by many orders of magnitude near a root.
fn hermite_majorant(n: usize, x: f64) -> f64 {
    let (mut m_prev, mut m) = (0.0, 1.0);
    for j in 0..n {
        (m_prev, m) = (m, x.abs() * m + j as f64 * m_prev);
    }
    m
}

#[test]
fn legendre_and_chebyshev_values_match_numpy() {
    let fx = fixture();
    let points = floats(&fx["unit_points"]);
    let n_terms = fx["max_degree"].as_u64().unwrap() as usize + 1;
    for (family, key) in [
        (Family::Legendre, "legendre"),
        (Family::Chebyshev, "chebyshev"),
    ] {
        let expected = table(&fx[key]);
        let ours = classical_rows(family, &points, n_terms, -1.0, 1.0);
        for (j, row) in ours.iter().enumerate() {
            for (n, v) in row.iter().enumerate() {
                // |P_n|, |T_n| <= 1 on [-1, 1] and both sides are stable recurrences, so an
                // absolute 1e-12 is ~50x the round-off (n·eps ≈ 4e-15 for n = 20).
                let e = expected[n][j];
                assert!(
                    (v - e).abs() < 1e-12,
                    "{key} n={n} z={}: {v} vs {e}",
                    points[j]
                );
            }
        }
    }
}

#[test]
fn hermite_values_match_numpy() {
    let fx = fixture();
    let n_terms = fx["max_degree"].as_u64().unwrap() as usize + 1;
    for (pkey, vkey) in [
        ("unit_points", "hermite_e_unit"),
        ("wide_points", "hermite_e_wide"),
    ] {
        let points = floats(&fx[pkey]);
        let expected = table(&fx[vkey]);
        // A Hermite basis on [-1, 1] has z = t, and any real t is admissible.
        let ours = classical_rows(Family::Hermite, &points, n_terms, -1.0, 1.0);
        for (j, row) in ours.iter().enumerate() {
            for (n, v) in row.iter().enumerate() {
                let e = expected[n][j];
                // Relative to the recurrence majorant (see `hermite_majorant`), since values
                // reach ~1e13 at |x| = 6 and cancel near roots.
                let tol = 1e-12 * hermite_majorant(n, points[j]);
                assert!(
                    (v - e).abs() <= tol,
                    "{vkey} n={n} x={}: {v} vs {e}",
                    points[j]
                );
            }
        }
    }
}

/// Checks one rule against the fixture: tightly against the 40-digit mpmath reference, and
/// against numpy within numpy's own recorded error.
fn check_rule(family: &str, rule: &Value, x: &[f64], w: &[f64]) {
    let n = rule["n"].as_u64().unwrap() as usize;
    let (np_x, np_w) = (floats(&rule["nodes"]), floats(&rule["weights"]));
    let (mp_x, mp_w) = (floats(&rule["mp_nodes"]), floats(&rule["mp_weights"]));
    let numpy_weight_error = rule["numpy_max_weight_rel_error"].as_f64().unwrap();
    assert_eq!((x.len(), w.len(), mp_x.len()), (n, n, n));
    for i in 0..n {
        // Nodes: Newton-polished to round-off; 4 ulps of max(1, |x|) (Hermite nodes reach
        // |x| ≈ 19 at n = 100).
        let node_tol = 4.0 * f64::EPSILON * mp_x[i].abs().max(1.0);
        assert!(
            (x[i] - mp_x[i]).abs() <= node_tol,
            "{family} n={n} node {i}: {} vs {}",
            x[i],
            mp_x[i]
        );
        // Weights: the brief asks for 1e-12 relative; ours are ~1e-14 (a weight is a smooth
        // function of its node, evaluated by an O(n) stable recurrence).
        assert!(
            (w[i] - mp_w[i]).abs() <= 1e-12 * mp_w[i],
            "{family} n={n} weight {i}: {} vs {}",
            w[i],
            mp_w[i]
        );
        // numpy itself: nodes agree to the same round-off; numpy's weights are only as good as
        // the error the script recorded against mpmath (up to 2.1e-12 for leggauss(100)), so
        // allow that plus our 1e-12.
        assert!(
            (x[i] - np_x[i]).abs() <= 2.0 * node_tol + 4e-15,
            "{family} numpy n={n} node {i}"
        );
        let tol = (numpy_weight_error + 1e-12) * mp_w[i];
        assert!(
            (w[i] - np_w[i]).abs() <= tol,
            "{family} numpy n={n} weight {i}"
        );
    }
}

#[test]
fn gauss_legendre_matches_reference_rules() {
    let fx = fixture();
    for rule in fx["leggauss"].as_array().unwrap() {
        let n = rule["n"].as_u64().unwrap() as usize;
        let (x, w) = gauss_legendre(n, -1.0, 1.0).unwrap();
        check_rule("leggauss", rule, &x, &w);
    }
}

#[test]
fn gauss_hermite_matches_reference_rules() {
    let fx = fixture();
    for rule in fx["hermegauss"].as_array().unwrap() {
        let n = rule["n"].as_u64().unwrap() as usize;
        let (x, w) = gauss_hermite_prob(n).unwrap();
        check_rule("hermegauss", rule, &x, &w);
    }
}
