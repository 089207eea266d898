//! The library's one error type. Every variant displays as one line; the
//! command line prints it after `splatray: ` and exits non-zero. The error
//! it wraps stays reachable through [`std::error::Error::source`].

use crate::embree::EmbreeError;
use crate::io::IoError;
use crate::memory::TooLarge;
use crate::splat::GenerateError;
use std::fmt;

/// Anything that can go wrong in the library.
#[derive(Debug)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file (the file is named in the message).
    Io(IoError),
    /// Embree reported an error.
    Embree(EmbreeError),
    /// No splats could be made from a point cloud.
    Generate(GenerateError),
    /// Work that needs more memory than this process may still allocate.
    Memory(TooLarge),
    /// Invalid input or options: a scene, a parameter, a request the data
    /// cannot satisfy. The message says what and where.
    Invalid(String),
    /// An error of another library (an image codec, the plot, JSON), with
    /// its own message.
    Other(Box<dyn std::error::Error + Send + Sync>),
    /// Another error and where it happened (a file, a model): displays as
    /// `what: source`.
    Context {
        /// Where: a file, a model.
        what: String,
        /// What went wrong there.
        source: Box<Error>,
    },
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An [`Error::Invalid`] with this message.
    #[must_use]
    pub fn invalid(msg: impl Into<String>) -> Error {
        Error::Invalid(msg.into())
    }

    /// An [`Error::Other`] wrapping another library's error.
    #[must_use]
    pub fn other(e: impl std::error::Error + Send + Sync + 'static) -> Error {
        Error::Other(Box::new(e))
    }

    /// The same error with `what: ` in front of its message (a file, a
    /// model), so the line says where it happened; the error itself stays
    /// the [`std::error::Error::source`].
    #[must_use]
    pub fn context(self, what: impl fmt::Display) -> Error {
        Error::Context {
            what: what.to_string(),
            source: Box::new(self),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io(e) => e.fmt(f),
            Error::Embree(e) => e.fmt(f),
            Error::Generate(e) => e.fmt(f),
            Error::Memory(e) => e.fmt(f),
            Error::Invalid(s) => f.write_str(s),
            Error::Other(e) => e.fmt(f),
            Error::Context { what, source } => write!(f, "{what}: {source}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io(e) => Some(e),
            Error::Embree(e) => Some(e),
            Error::Generate(e) => Some(e),
            Error::Memory(e) => Some(e),
            Error::Invalid(_) => None,
            Error::Other(e) => Some(e.as_ref()),
            Error::Context { source, .. } => Some(source.as_ref()),
        }
    }
}

/// `From` for each wrapped error type.
macro_rules! wrap {
    ($($ty:ty => $variant:ident),* $(,)?) => {$(
        impl From<$ty> for Error {
            fn from(e: $ty) -> Error {
                Error::$variant(e)
            }
        }
    )*};
}

wrap!(IoError => Io, EmbreeError => Embree, GenerateError => Generate, TooLarge => Memory);

/// An unusable environment variable is invalid input, its line unchanged.
impl From<crate::config::ConfigError> for Error {
    fn from(e: crate::config::ConfigError) -> Error {
        Error::Invalid(e.0)
    }
}

impl From<String> for Error {
    fn from(s: String) -> Error {
        Error::Invalid(s)
    }
}

impl From<&str> for Error {
    fn from(s: &str) -> Error {
        Error::Invalid(s.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `context` says where in front and keeps the error itself as the
    /// source, its variant intact.
    #[test]
    fn context_keeps_the_source() {
        let io = IoError::new(std::path::Path::new("a.ply"), crate::io::IoErrorKind::Empty);
        let e = Error::from(io).context("model 2").context("s.toml");
        assert_eq!(e.to_string(), "s.toml: model 2: a.ply: the file is empty");
        let inner = std::error::Error::source(&e).unwrap();
        assert_eq!(inner.to_string(), "model 2: a.ply: the file is empty");
        let inner = inner.downcast_ref::<Error>().unwrap();
        let Error::Context { source, .. } = inner else {
            panic!("{inner:?}")
        };
        assert!(matches!(**source, Error::Io(_)), "{source:?}");
    }
}
