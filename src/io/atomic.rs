//! The one atomic writer: every output file of the library and the command
//! line is written to a temporary name beside its target, flushed to disk
//! and renamed into place, so a failure never leaves a half-written file.

use super::{IoError, IoErrorKind};
use std::path::{Path, PathBuf};

/// The temporary name beside `path`: `.NAME.<pid>.partial` (hidden, and
/// distinct per process so two runs writing the same target do not share
/// it).
fn temp_path(path: &Path) -> Result<PathBuf, IoError> {
    let name = path
        .file_name()
        .ok_or_else(|| IoError::new(path, IoErrorKind::Header("not a file name".into())))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".{}.partial", std::process::id()));
    Ok(path.with_file_name(tmp_name))
}

/// Writes `path` atomically: `write` is handed a temporary path beside
/// `path` and writes the whole file there (with any writer, such as the
/// `image` crate's); the temporary file is then synced to disk and renamed
/// over `path`. On any failure the temporary file is removed and `path` is
/// left as it was.
///
/// # Errors
/// An [`IoError`] naming `path`: `write`'s error (as its one-line message)
/// or the operating system's.
pub fn write_atomic<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), IoError> {
    let tmp = temp_path(path)?;
    let result = write(&tmp)
        .map_err(|e| std::io::Error::other(e.to_string()))
        .and_then(|()| std::fs::File::open(&tmp)?.sync_all())
        .and_then(|()| std::fs::rename(&tmp, path));
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        IoError::new(path, IoErrorKind::Io(e))
    })
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
///
/// # Errors
/// An [`IoError`] when the file cannot be written.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("splatray-atomic-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn failure_leaves_the_target_alone_and_no_temporary() {
        let d = dir("fail");
        let target = d.join("out.txt");
        std::fs::write(&target, "old").unwrap();
        let e = write_atomic(&target, |tmp| {
            std::fs::write(tmp, "half").unwrap();
            Err("the writer failed")
        })
        .unwrap_err();
        assert!(e.to_string().contains("out.txt") && e.to_string().contains("the writer failed"));
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        write_bytes(&target, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(&d);
    }
}
