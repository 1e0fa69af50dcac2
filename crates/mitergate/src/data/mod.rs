//! Data generators around the gate model: the paper's synthetic truth and experiments
//! ([`truth`], Sec. 4.3) and months of simulated field records with environmental and
//! instrument effects ([`field`], for the close-the-loop workflow of `bamudi`).

pub mod field;
pub mod truth;
