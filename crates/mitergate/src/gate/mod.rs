//! The parametric miter gate leaf: its description ([`GateConfig`], TOML), the structured
//! shell mesh of the leaf ([`GateMesh`]), the assembled, supported and factored finite-element
//! model ([`GateModel`]) and the water loads on it.
//!
//! Coordinates (the leaf frame): `x` along the leaf from the quoin (`x = 0`) to the miter end
//! (`x = L`); `y` normal to the skin plate, positive downstream (the skin plate is the plane
//! `y = 0`, framing at `y > 0`); `z` up from the sill (`z = 0`) to the top of the quoin
//! (`z = H`).

pub mod config;
pub mod mesh;
mod model;
mod water;

pub use config::{
    DEFAULT_GATE_TOML, GateConfig, GaugeLocation, GaugeSpec, MAX_ELEMENT_SIZE_IN,
    MAX_GAUGE_READING_MICROSTRAIN,
};
pub use mesh::{GateMesh, Member};
pub use model::GateModel;
pub(crate) use water::check_levels;
pub use water::{WATER_LEVEL_RANGE, skin_pressure_loads};
