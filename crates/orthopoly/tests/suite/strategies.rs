//! Shared proptest strategies.
use orthopoly::{Family, Normalization};
use proptest::prelude::*;

/// Any of the three families.
pub fn family() -> impl Strategy<Value = Family> {
    prop_oneof![
        Just(Family::Legendre),
        Just(Family::Chebyshev),
        Just(Family::Hermite)
    ]
}

/// Either normalisation.
pub fn normalization() -> impl Strategy<Value = Normalization> {
    prop_oneof![
        Just(Normalization::Orthonormal),
        Just(Normalization::Classical)
    ]
}

/// A physical interval `(a, b)` with `a < b`: widths 1e-2 .. 1e3 (the quoin is [0, 762] in)
/// and a lower end within ±5 widths of the origin, so [`map_condition`] stays below ~11.
pub fn interval() -> impl Strategy<Value = (f64, f64)> {
    (-2.0..3.0f64, -5.0..5.0f64).prop_map(|(log_w, offset)| {
        let w = 10f64.powf(log_w);
        (offset * w, offset * w + w)
    })
}

/// Relative condition number `(|a| + |b|) / (b - a)` of the map `t -> z`: a physical point
/// stored with relative round-off `eps` has reference coordinate `z` perturbed by up to
/// `~2 eps · map_condition`. Tolerances of tests that go through physical coordinates scale
/// with it.
pub fn map_condition(a: f64, b: f64) -> f64 {
    (a.abs() + b.abs()) / (b - a)
}
