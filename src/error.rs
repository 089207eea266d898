//! The library's one error type. Every variant displays as one line; the
//! command line prints it after `splatray: ` and exits non-zero.

use crate::embree::EmbreeError;
use crate::io::IoError;
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
    /// Invalid input or options: a scene, a parameter, a request the data
    /// cannot satisfy. The message says what and where.
    Invalid(String),
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An [`Error::Invalid`] with this message.
    #[must_use]
    pub fn invalid(msg: impl Into<String>) -> Error {
        Error::Invalid(msg.into())
    }

    /// The same error with `what: ` in front of its message (a file, a
    /// model), so the line says where it happened.
    #[must_use]
    pub fn context(self, what: impl fmt::Display) -> Error {
        Error::Invalid(format!("{what}: {self}"))
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io(e) => e.fmt(f),
            Error::Embree(e) => e.fmt(f),
            Error::Generate(e) => e.fmt(f),
            Error::Invalid(s) => f.write_str(s),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io(e) => Some(e),
            Error::Embree(e) => Some(e),
            Error::Generate(e) => Some(e),
            Error::Invalid(_) => None,
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

wrap!(IoError => Io, EmbreeError => Embree, GenerateError => Generate);

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

/// For callers whose errors are still one-line strings: `?` turns an
/// [`Error`] into its message.
impl From<Error> for String {
    fn from(e: Error) -> String {
        e.to_string()
    }
}
