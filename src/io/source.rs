//! A cloud given to a command by name: a file, `-` for standard input, or
//! a pipe (`splat <(zcat pts.xyz.gz)`, a named pipe). A file is opened as
//! often as its reader needs (to sniff its first bytes, then to read it);
//! standard input or a pipe is read whole, once, when the source is
//! opened, and every later look at it reads those bytes: a second open of
//! a pipe would wait forever for a writer that has gone. The format is the
//! one named (`--format`), else the name's extension, else the first bytes.

use super::{
    Format, GaussianLayout, GaussianRead, IoError, IoErrorKind, PointCloud, parse_gaussians,
    parse_points, read_file, sniff_layout,
};
use std::borrow::Cow;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The name that stands for standard input.
pub const STDIN: &str = "-";

/// A cloud input: its name, the format named for it, and its bytes when it
/// is standard input or a pipe (read once, on [`Source::open`]).
#[derive(Debug)]
pub struct Source {
    path: PathBuf,
    format: Option<Format>,
    piped: Option<Vec<u8>>,
}

/// Whether `path` is standard input or something other than a regular
/// file or a folder (a pipe, a FIFO, a device): what is read once.
#[must_use]
pub fn is_piped(path: &Path) -> bool {
    path == Path::new(STDIN) || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

impl Source {
    /// The input `path` in `format` (`None`: by its extension, else its
    /// first bytes); standard input (`-`) or a pipe is read whole now.
    ///
    /// # Errors
    /// An [`IoError`] naming the input when a pipe cannot be read or is
    /// empty.
    pub fn open(path: &Path, format: Option<Format>) -> Result<Source, IoError> {
        let piped = if path == Path::new(STDIN) {
            let mut bytes = Vec::new();
            std::io::stdin()
                .lock()
                .read_to_end(&mut bytes)
                .map_err(|e| IoError::new(path, IoErrorKind::Io(e)))?;
            Some(bytes)
        } else if is_piped(path) {
            Some(std::fs::read(path).map_err(|e| IoError::new(path, IoErrorKind::Io(e)))?)
        } else {
            None
        };
        if piped.as_ref().is_some_and(Vec::is_empty) {
            return Err(IoError::new(path, IoErrorKind::Empty));
        }
        Ok(Source {
            path: path.to_path_buf(),
            format,
            piped,
        })
    }

    /// The name as given (`-` for standard input).
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the input was standard input or a pipe, held in memory.
    #[must_use]
    pub fn is_piped(&self) -> bool {
        self.piped.is_some()
    }

    /// The whole input: the bytes held, or the file read now (checked
    /// against the memory this process may use).
    ///
    /// # Errors
    /// As [`super::read_points`]'s reading.
    pub fn bytes(&self) -> Result<Cow<'_, [u8]>, IoError> {
        match &self.piped {
            Some(b) => Ok(Cow::Borrowed(b)),
            None => read_file(&self.path).map(Cow::Owned),
        }
    }

    /// The first 4 KiB (to sniff the format), or `None` when a file cannot
    /// be read.
    #[must_use]
    pub fn head(&self) -> Option<Cow<'_, [u8]>> {
        match &self.piped {
            Some(b) => Some(Cow::Borrowed(&b[..b.len().min(4096)])),
            None => super::file_head(&self.path).map(Cow::Owned),
        }
    }

    /// The format named, else by the extension, else by the first bytes.
    #[must_use]
    pub fn format(&self) -> Option<Format> {
        self.format
            .or_else(|| Format::from_extension(&self.path))
            .or_else(|| self.head().and_then(|h| Format::sniff(&h)))
    }

    /// The Gaussian splat layout of a PLY input, or `None`.
    #[must_use]
    pub fn gaussian_layout(&self) -> Option<GaussianLayout> {
        if self.format.is_some_and(|f| f != Format::Ply) {
            return None;
        }
        sniff_layout(&self.head()?)
    }

    /// The input as points ([`super::read_points`]; a folder as one cloud).
    ///
    /// # Errors
    /// An [`IoError`] naming the input: unreadable, an unknown format, or
    /// what the format's reader refuses.
    pub fn read_points(&self) -> Result<PointCloud, IoError> {
        if self.piped.is_none() && self.path.is_dir() {
            return super::read_folder(&self.path);
        }
        let at = |k| IoError::new(&self.path, k);
        let bytes = self.bytes()?;
        let format = self
            .format
            .or_else(|| Format::from_extension(&self.path))
            .or_else(|| Format::sniff(&bytes[..bytes.len().min(4096)]))
            .ok_or_else(|| at(IoErrorKind::UnknownFormat))?;
        parse_points(&bytes, format).map_err(at)
    }

    /// The input as a Gaussian splat file ([`super::read_gaussians`]).
    ///
    /// # Errors
    /// An [`IoError`] naming the input.
    pub fn read_gaussians(&self, min_opacity: f32) -> Result<GaussianRead, IoError> {
        let bytes = self.bytes()?;
        parse_gaussians(&bytes, min_opacity).map_err(|k| IoError::new(&self.path, k))
    }
}
