//! What a calibration and a close-loop run leave on disk: `results.json`, `report.md` and SVG
//! plots.

pub mod adequacy;
pub mod calibration;
pub mod closeloop;
pub mod plot;
