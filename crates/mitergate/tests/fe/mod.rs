//! Finite elements and assembly: the shell quadrilateral, triangles, beams and the supported
//! shell model.

mod beam_tri;
pub mod common;
pub mod element;
