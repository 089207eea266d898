//! Clip lines of a splat at a sharp feature: [`Clip`] and [`ClipLine`],
//! defined with the primitive that tests them
//! ([`crate::primitive::ClippedDisc`], `docs/DESIGN.md`, "The primitive
//! contract") and re-exported here, where splats carry them.

pub use crate::primitive::clip::{Clip, ClipLine};
