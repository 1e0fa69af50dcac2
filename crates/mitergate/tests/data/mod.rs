//! The data generators: the synthetic truth of Sec. 4.3.

mod truth;
