//! Subcommands of the `splatray` command line: a private module of the
//! library, run through `crate::run_cli` ([`app::run`]) by the binary
//! (src/main.rs) and by the Python package's `splatray` command, so both
//! are this one. It parses arguments and prints; the work is in
//! `crate::workflow`.

pub mod app;
pub mod common;
pub mod compare;
pub mod export;
pub mod progress;
pub mod render;
pub mod sample_cmd;
pub mod scan_check;
pub mod splat_cmd;
pub mod sweep;
pub mod view;
pub mod viewer;

use crate::io::Batch;
use crate::{Error, Result};
use std::path::Path;

/// `value` as pretty JSON (a report).
///
/// # Errors
/// [`Error::Other`] when `value` does not serialise.
pub fn json_text<T: serde::Serialize>(value: &T) -> Result<String> {
    serde_json::to_string_pretty(value).map_err(Error::other)
}

/// Stages `text` as the file `path`, one output of `batch`.
///
/// # Errors
/// The file cannot be written.
pub fn stage_text(batch: &mut Batch, path: &Path, text: &str) -> Result<()> {
    batch.stage(path, |t| std::fs::write(t, text))?;
    Ok(())
}
