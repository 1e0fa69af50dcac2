//! The built-in effects (each an [`Effect`](super::Effect)) and the default library.

mod basic;
mod generic;
mod lasso;
mod linear;
mod load_path;
mod operational;
mod stepwise;
mod thermal;
pub(crate) mod trend;

pub use crate::config::Selection;
pub use basic::{GaugeDrift, GaugeOffset, OffsetJump};
pub use generic::Generic;
pub use linear::{Basis, LinearTerm};
pub use load_path::LoadPathHysteresis;
pub use operational::{OperationalResponse, RESPONSE_SCALES_H};
pub use thermal::Thermal;
pub use trend::ParameterTrend;

use super::{CloseLoopConfig, Effect, MeasuredRecord};
use std::sync::Arc;

/// The library searched at every step when the caller gives none: gauge offset, drift and
/// offset jump; a thermal term for every temperature column (the configured ones, or every
/// column declared in a temperature unit, [`is_temperature_unit`](super::is_temperature_unit));
/// load-path hysteresis when a load is declared; the tracked parameter; then the two data-driven
/// terms: the response to the record's operational events and the sparse covariate term.
pub fn default_library(rec: &MeasuredRecord, cfg: &CloseLoopConfig) -> Vec<Arc<dyn Effect>> {
    let temp_cols: Vec<String> = match &cfg.temperature_columns {
        Some(c) => c.clone(),
        None => rec
            .covariate_names
            .iter()
            .filter(|c| {
                cfg.column_units
                    .get(*c)
                    .is_some_and(|u| super::is_temperature_unit(u))
            })
            .cloned()
            .collect(),
    };
    let mut library: Vec<Arc<dyn Effect>> = vec![
        Arc::new(GaugeOffset),
        Arc::new(GaugeDrift),
        Arc::new(OffsetJump),
    ];
    for column in &temp_cols {
        library.push(Arc::new(Thermal {
            column: column.clone(),
        }));
    }
    if let Some(load) = &cfg.load {
        library.push(Arc::new(LoadPathHysteresis {
            load: load.name.clone(),
        }));
    }
    library.push(Arc::new(ParameterTrend {
        parameter: cfg.parameter_name.clone(),
        track: cfg.track.clone(),
    }));
    library.push(Arc::new(OperationalResponse));
    library.push(Arc::new(Generic {
        max_features: cfg.max_generic_features,
        selection: cfg.generic_selection,
        lag_covered: temp_cols,
    }));
    library
}
