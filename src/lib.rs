//! splatray: ray tracing point clouds as surface splats, after Linsen et al.
//! 2007 and Botsch et al. 2004 (the report in `docs/`, cited by section and
//! equation number), with two interchangeable acceleration backends — an
//! octree and Embree 4 user-geometry discs — feeding one shading path.

pub mod accel;
pub mod config;
pub mod data;
pub mod embree;
pub mod error;
pub mod freespace;
pub mod geometry;
pub mod io;
pub mod memory;
pub mod names;
pub mod pipeline;
pub mod primitive;
pub mod progress;
pub mod render;
pub mod resolve;
pub mod rng;
pub mod scanner;
pub mod scene;
pub mod simd;
pub mod splat;
pub mod terrain;
pub mod tiled;
pub mod validate;
pub mod viewer;
pub mod workflow;

pub use error::{Error, Result};
