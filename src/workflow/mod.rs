//! The workflows a front end runs (the command line, the Python package):
//! each a function with plain options and a typed, serialisable report,
//! doing the reading, the work and the committing of outputs; the front
//! end only parses, calls, prints and writes what it is asked to.

pub mod compare;
pub mod export;
pub mod plot;
pub mod render;
pub mod sample;
pub mod scan_check;
pub mod splat;
pub mod sweep;
