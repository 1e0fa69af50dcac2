//! Shared proptest strategies.

use proptest::prelude::*;
use seqnet::LstmShape;

/// Small network shapes: up to 3 features, 4 steps, 5 hidden units, 3 layers, 3 outputs.
pub fn small_shape() -> impl Strategy<Value = LstmShape> {
    (1usize..4, 1usize..5, 1usize..6, 1usize..4, 1usize..4)
        .prop_map(|(f, s, h, l, o)| LstmShape::new(f, s, h, l, o).expect("all sizes >= 1"))
}
