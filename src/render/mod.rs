//! The renderer (report §1.2, §4): scenes, the Whitted integrator and image
//! output.

pub mod integrator;
pub mod output;
pub mod scene;
pub mod shapes;
