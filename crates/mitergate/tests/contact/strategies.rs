//! Shared proptest strategies.

use proptest::prelude::*;

/// Water levels `[h_up, h_down]` (in) on the paper's triangle `24 <= h_down <= h_up <= 744`.
pub fn levels() -> impl Strategy<Value = [f64; 2]> {
    (24.0..744.0f64, 24.0..744.0f64).prop_map(|(a, b)| if a >= b { [a, b] } else { [b, a] })
}

/// Gap lengths (in) from none to a third of the quoin.
pub fn gap() -> impl Strategy<Value = f64> {
    0.0..250.0f64
}
