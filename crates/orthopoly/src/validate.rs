//! Shared input checks.

use crate::OrthoError;

/// `n >= 1`.
pub(crate) fn check_order(name: &'static str, n: usize) -> Result<(), OrthoError> {
    if n == 0 {
        return Err(OrthoError::InvalidParameter {
            name,
            reason: "must be at least 1".into(),
        });
    }
    Ok(())
}

/// Finite `a < b`.
pub(crate) fn check_interval(a: f64, b: f64) -> Result<(), OrthoError> {
    for (name, v) in [("a", a), ("b", b)] {
        if !v.is_finite() {
            return Err(OrthoError::InvalidParameter {
                name,
                reason: format!("must be finite, got {v}"),
            });
        }
    }
    if a >= b {
        return Err(OrthoError::InvalidParameter {
            name: "b",
            reason: format!("interval must satisfy a < b, got a = {a}, b = {b}"),
        });
    }
    if !(b - a).is_finite() {
        return Err(OrthoError::InvalidParameter {
            name: "b",
            reason: format!("interval width b - a overflows (a = {a}, b = {b})"),
        });
    }
    Ok(())
}

/// Every element finite.
pub(crate) fn check_finite_slice(name: &'static str, xs: &[f64]) -> Result<(), OrthoError> {
    match xs.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(OrthoError::NonFinite {
            name,
            index,
            value: xs[index],
        }),
        None => Ok(()),
    }
}
