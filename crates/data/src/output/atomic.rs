//! A file written whole or not at all: the bytes go to a fresh temporary in the target's
//! folder, which is synced and renamed over the target only once everything is written.
//!
//! The temporary's name, `.fogray-<16 random hex digits>.tmp`, cannot be guessed in advance,
//! and it is opened with `O_CREAT | O_EXCL` (`create_new`), which refuses any existing name,
//! a symbolic link included: a link planted in the folder is never followed, and no file but
//! the temporary is ever opened for writing. The rename replaces the target's directory entry
//! (a link at the target's name is replaced, not written through). On any error, on drop
//! without [`AtomicFile::commit`], and on Ctrl-C where the application asked for it
//! ([`remove_temporaries_and_exit`](super::remove_temporaries_and_exit)), the temporary is
//! removed.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use super::registry;
use crate::error::DataError;

/// How many fresh names to try before giving up (each collision is a 2^-64 event unless
/// someone fills the folder with guesses).
const ATTEMPTS: usize = 16;

/// A file being written to a temporary beside its target.
#[derive(Debug)]
pub struct AtomicFile {
    file: Option<File>,
    temporary: PathBuf,
    target: PathBuf,
}

impl AtomicFile {
    /// Creates a fresh temporary in `target`'s folder (which must exist).
    ///
    /// Errors: [`DataError::Io`] naming `target` when the folder cannot be written (or does
    /// not exist).
    pub fn create(target: &Path) -> Result<Self, DataError> {
        let (file, temporary) = create_temporary(folder_of(target)).map_err(|e| DataError::io(target, e))?;
        Ok(AtomicFile {
            file: Some(file),
            temporary,
            target: target.to_path_buf(),
        })
    }

    /// The file it will become.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// The temporary being written.
    pub fn temporary(&self) -> &Path {
        &self.temporary
    }

    /// Syncs the temporary to disk and renames it over the target (then syncs the folder, so
    /// that the rename survives a power cut where the system allows it).
    ///
    /// Errors: [`DataError::Io`] naming the target; the temporary is then removed.
    pub fn commit(mut self) -> Result<(), DataError> {
        let Some(file) = self.file.take() else {
            return Err(DataError::io(&self.target, "already committed"));
        };
        let synced = file.sync_all();
        drop(file);
        let renamed = registry::finish(&self.temporary, || {
            let renamed = synced.and_then(|()| std::fs::rename(&self.temporary, &self.target));
            if renamed.is_err() {
                std::fs::remove_file(&self.temporary).ok();
            }
            renamed
        });
        renamed.map_err(|e| DataError::io(&self.target, e))?;
        // Best effort: not every system can open a folder to sync it.
        if let Ok(folder) = File::open(folder_of(&self.target)) {
            folder.sync_all().ok();
        }
        Ok(())
    }

    fn file(&mut self) -> io::Result<&mut File> {
        self.file
            .as_mut()
            .ok_or_else(|| io::Error::other("the file is already committed"))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file()?.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file()?.flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            // An error in the middle of writing is the one to report; a temporary that cannot be
            // removed either is left to the user's cleaning.
            registry::finish(&self.temporary, || std::fs::remove_file(&self.temporary)).ok();
        }
    }
}

/// Writes `target` whole through `write` (given a buffered writer into the temporary), then
/// renames it into place (see [`AtomicFile`]).
///
/// Errors: [`DataError::Io`] naming `target` for a folder that cannot be written, an error of
/// `write`, a failed flush, sync or rename; `target` is then as it was and no temporary is left.
pub fn write_atomic(target: &Path, write: impl FnOnce(&mut dyn Write) -> io::Result<()>) -> Result<(), DataError> {
    let mut file = AtomicFile::create(target)?;
    let mut buffered = BufWriter::with_capacity(1 << 16, &mut file);
    write(&mut buffered)
        .and_then(|()| buffered.flush())
        .map_err(|e| DataError::io(target, e))?;
    drop(buffered);
    file.commit()
}

/// A fresh temporary in `folder`, created with `create_new` and recorded in the registry.
fn create_temporary(folder: &Path) -> io::Result<(File, PathBuf)> {
    let mut last = None;
    for _ in 0..ATTEMPTS {
        let temporary = folder.join(format!(".fogray-{:016x}.tmp", rand::random::<u64>()));
        let opened = registry::create(&temporary, |t| OpenOptions::new().write(true).create_new(true).open(t));
        match opened {
            Ok(file) => return Ok((file, temporary)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(last.unwrap_or_else(|| io::Error::other("no fresh temporary name")))
}

/// Whether a file can be created in `folder`: a temporary is created there and removed.
pub(super) fn probe(folder: &Path) -> io::Result<()> {
    let (file, temporary) = create_temporary(folder)?;
    drop(file);
    registry::finish(&temporary, || std::fs::remove_file(&temporary))
}

/// The folder a file `path` lies in (`.` for a bare name).
pub(super) fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_committed_file_replaces_its_target_and_leaves_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.txt");
        std::fs::write(&target, "old").unwrap();
        write_atomic(&target, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(names(dir.path()), ["a.txt"]);
    }

    #[test]
    fn an_error_or_a_drop_leaves_the_target_as_it_was_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.txt");
        std::fs::write(&target, "old").unwrap();
        let err = write_atomic(&target, |w| {
            w.write_all(b"half")?;
            Err(io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(
            err.to_string().contains("a.txt") && err.to_string().contains("disk full"),
            "{err}"
        );
        let mut file = AtomicFile::create(&target).unwrap();
        file.write_all(b"dropped").unwrap();
        let temporary = file.temporary().to_path_buf();
        assert!(live_contains(&temporary));
        drop(file);
        assert!(!live_contains(&temporary));
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(names(dir.path()), ["a.txt"]);
    }

    fn live_contains(path: &Path) -> bool {
        registry::live_temporaries().iter().any(|p| p == path)
    }

    #[test]
    fn two_temporaries_of_one_target_have_different_names() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.txt");
        let (a, b) = (
            AtomicFile::create(&target).unwrap(),
            AtomicFile::create(&target).unwrap(),
        );
        assert_ne!(a.temporary(), b.temporary());
        assert_eq!(a.temporary().parent(), Some(dir.path()));
    }

    #[cfg(unix)]
    #[test]
    fn a_symlink_in_the_folder_is_never_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let elsewhere = dir.path().join("elsewhere.txt");
        std::fs::write(&elsewhere, "keep").unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir(&out).unwrap();
        // A link at the target's own name is replaced by the file, not written through.
        std::os::unix::fs::symlink(&elsewhere, out.join("a.txt")).unwrap();
        write_atomic(&out.join("a.txt"), |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&elsewhere).unwrap(), b"keep");
        assert!(!std::fs::symlink_metadata(out.join("a.txt")).unwrap().is_symlink());
        assert_eq!(std::fs::read(out.join("a.txt")).unwrap(), b"new");
    }

    #[test]
    fn a_missing_folder_is_an_error_naming_the_target() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("no/such/a.txt");
        let err = write_atomic(&target, |w| w.write_all(b"x")).unwrap_err();
        assert!(err.to_string().contains("no/such/a.txt"), "{err}");
    }
}
