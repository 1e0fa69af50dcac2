//! Integration tests of `mitergate`: the shell element, the gate model and its condensation.

mod suite;

mod contact;
