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
    let mut batch = Batch::new();
    batch.stage(path, write)?;
    batch.commit()
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
///
/// # Errors
/// An [`IoError`] when the file cannot be written.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    write_atomic(path, |tmp| std::fs::write(tmp, bytes))
}

/// The outputs of one run, committed together: each is written to its
/// temporary name as it is produced ([`Batch::stage`]), and
/// [`Batch::commit`] renames them all into place at the end. A batch dropped
/// before its commit (a failure anywhere in the run) removes every
/// temporary, so a failed run leaves nothing behind and no target changed.
#[derive(Default)]
pub struct Batch {
    /// (temporary, target), in staging order.
    staged: Vec<(PathBuf, PathBuf)>,
}

impl Batch {
    /// An empty batch.
    #[must_use]
    pub fn new() -> Batch {
        Batch::default()
    }

    /// Writes the output `path` to its temporary name (as [`write_atomic`]
    /// does, synced to disk) without renaming it yet.
    ///
    /// # Errors
    /// An [`IoError`] naming `path`: it is a folder, or `write` or the
    /// operating system failed (the temporary is removed).
    pub fn stage<E: std::fmt::Display>(
        &mut self,
        path: &Path,
        write: impl FnOnce(&Path) -> Result<(), E>,
    ) -> Result<(), IoError> {
        if path.is_dir() {
            return Err(IoError::new(
                path,
                IoErrorKind::Io(std::io::Error::other("is a folder, not a file")),
            ));
        }
        let tmp = temp_path(path)?;
        let result = write(&tmp)
            .map_err(|e| std::io::Error::other(e.to_string()))
            .and_then(|()| std::fs::File::open(&tmp)?.sync_all());
        match result {
            Ok(()) => {
                self.staged.push((tmp, path.to_path_buf()));
                Ok(())
            }
            Err(e) => {
                let _ = std::fs::remove_file(&tmp);
                Err(IoError::new(path, IoErrorKind::Io(e)))
            }
        }
    }

    /// Renames every staged output into place, in staging order.
    ///
    /// # Errors
    /// An [`IoError`] naming the target that could not be renamed; the
    /// outputs not yet renamed are removed.
    pub fn commit(mut self) -> Result<(), IoError> {
        if let Some((_, path)) = self.staged.iter().find(|(_, p)| p.is_dir()) {
            return Err(IoError::new(
                path,
                IoErrorKind::Io(std::io::Error::other("is a folder, not a file")),
            ));
        }
        while !self.staged.is_empty() {
            let (tmp, path) = self.staged.remove(0);
            if let Err(e) = std::fs::rename(&tmp, &path) {
                let _ = std::fs::remove_file(&tmp);
                return Err(IoError::new(&path, IoErrorKind::Io(e)));
            }
        }
        Ok(())
    }
}

impl Drop for Batch {
    fn drop(&mut self) {
        for (tmp, _) in &self.staged {
            let _ = std::fs::remove_file(tmp);
        }
    }
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
    fn a_batch_commits_all_or_leaves_nothing() {
        let d = dir("batch");
        let (a, b) = (d.join("a.txt"), d.join("b.txt"));
        // The second output fails: neither target appears, no temporary.
        let mut batch = Batch::new();
        batch.stage(&a, |t| std::fs::write(t, "a")).unwrap();
        let e = batch.stage(&b, |_| Err::<(), _>("boom"));
        assert!(e.is_err());
        drop(batch);
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0);
        // A target that is a folder is refused before anything is written.
        std::fs::create_dir(&b).unwrap();
        let mut batch = Batch::new();
        batch.stage(&a, |t| std::fs::write(t, "a")).unwrap();
        assert!(batch.stage(&b, |t| std::fs::write(t, "b")).is_err());
        drop(batch);
        assert!(!a.exists());
        std::fs::remove_dir(&b).unwrap();
        // Both staged: both committed.
        let mut batch = Batch::new();
        batch.stage(&a, |t| std::fs::write(t, "a")).unwrap();
        batch.stage(&b, |t| std::fs::write(t, "b")).unwrap();
        assert!(!a.exists() && !b.exists());
        batch.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "a");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "b");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 2);
        let _ = std::fs::remove_dir_all(&d);
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
