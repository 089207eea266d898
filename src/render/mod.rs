//! The renderer (report §1.2, §4): the Whitted integrator and image output
//! (scenes are in [`crate::scene`]).

pub mod budget;
pub mod cast;
pub mod integrator;
pub mod nearest;
pub mod output;
