//! Subcommands of the `splatray` binary (a module of the binary: the
//! library does not depend on it).

pub mod compare;
pub mod export;
pub mod plot;
pub mod progress;
pub mod render;
pub mod sample_cmd;
pub mod scan_check;
pub mod splat_cmd;
pub mod sweep;
pub mod view;
