mod beam_tri;
pub mod common;
mod config;
pub mod element;
mod gate;
mod inp;
