//! The one error type of the readers and writers.

use std::fmt;
use std::path::{Path, PathBuf};

/// What went wrong with a file.
#[derive(Debug)]
#[non_exhaustive]
pub enum IoErrorKind {
    /// The operating system refused (missing file, permissions, disk full).
    Io(std::io::Error),
    /// The file has no bytes.
    Empty,
    /// Neither the extension nor the first bytes name a known format.
    UnknownFormat,
    /// The header is malformed or asks for something unsupported.
    Header(String),
    /// The body ends before the header's counts are met.
    Truncated(String),
    /// A value in the body could not be parsed or is out of range.
    Data(String),
    /// Nothing usable remains after reading.
    NoPoints(String),
    /// Reading it needs more memory than this process may still allocate.
    Memory(crate::memory::TooLarge),
    /// Its LZF-compressed body does not decompress.
    Lzf(super::LzfError),
}

/// A failure to read or write one file. `Display` is one line naming the
/// file and what is wrong with it.
#[derive(Debug)]
pub struct IoError {
    path: PathBuf,
    kind: IoErrorKind,
}

impl IoError {
    /// An error about `path`.
    #[must_use]
    pub fn new(path: &Path, kind: IoErrorKind) -> IoError {
        IoError {
            path: path.to_path_buf(),
            kind,
        }
    }

    /// Bad data refused before writing `path`: "`what`, nothing written".
    #[must_use]
    pub fn not_written(path: &Path, what: &str) -> IoError {
        IoError::new(path, IoErrorKind::Data(format!("{what}, nothing written")))
    }

    /// The file concerned.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What is wrong.
    #[must_use]
    pub fn kind(&self) -> &IoErrorKind {
        &self.kind
    }
}

/// Collapse any line breaks so a message stays on one line.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

impl fmt::Display for IoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match &self.kind {
            IoErrorKind::Io(e) => one_line(&e.to_string()),
            IoErrorKind::Empty => "the file is empty".to_string(),
            IoErrorKind::UnknownFormat => {
                "unknown format (expected .ply, .pcd, .xyz or .txt, or a PLY/PCD/XYZ header)"
                    .to_string()
            }
            IoErrorKind::Header(s) => format!("bad header: {}", one_line(s)),
            IoErrorKind::Truncated(s) => format!("truncated: {}", one_line(s)),
            IoErrorKind::Data(s) => format!("bad data: {}", one_line(s)),
            IoErrorKind::NoPoints(s) => one_line(s),
            IoErrorKind::Memory(e) => format!("bad data: {e}"),
            IoErrorKind::Lzf(e) => format!("bad data: {e}"),
        };
        write!(f, "{}: {what}", self.path.display())
    }
}

impl std::error::Error for IoError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match &self.kind {
            IoErrorKind::Io(e) => Some(e),
            IoErrorKind::Memory(e) => Some(e),
            IoErrorKind::Lzf(e) => Some(e),
            _ => None,
        }
    }
}
