//! Subcommands of the `splatray` binary that are more than a few lines.

pub mod progress;
pub mod sample_cmd;
pub mod splat_cmd;
