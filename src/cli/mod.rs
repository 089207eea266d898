//! Subcommands of the `splatray` binary.

pub mod compare;
pub mod plot;
pub mod progress;
pub mod render;
pub mod sample_cmd;
pub mod splat_cmd;
pub mod sweep;
