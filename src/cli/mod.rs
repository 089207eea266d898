//! Subcommands of the `splatray` binary.

pub mod compare;
pub mod render;
