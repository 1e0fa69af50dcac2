pub mod common;
mod config;
mod element;
mod gate;
mod inp;
