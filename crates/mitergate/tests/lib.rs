//! Integration tests of `mitergate`, one module per layer of the crate: finite elements, the
//! gate model and its condensation, `.inp` decks, the quoin contact model, the data
//! generators and the multi-level model.

mod contact;
mod data;
mod fe;
mod fuzz;
mod gate;
mod inp;
mod multilevel;
