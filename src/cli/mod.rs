//! Subcommands of the `splatray` binary.

pub mod render;
