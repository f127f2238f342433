//! The photographs put into `DIR/images/` under their own names: hard links where the file
//! system allows them (no copy of a phone's gigabytes, and the originals are never moved or
//! written: COLMAP only reads), else copies.

use std::ffi::OsString;
use std::path::Path;

use fogray_fit::interrupt::StopFlag;

use super::error::PrepareError;

/// How the photographs were placed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Placed {
    /// Hard-linked.
    pub linked: usize,
    /// Copied (another file system, or links refused).
    pub copied: usize,
}

/// Links or copies each of `names` from `from` into the new folder `to`; stops early, with
/// what it placed so far, when `stop` is raised.
///
/// Errors: [`PrepareError::File`] naming the folder or the photograph that failed.
pub fn place(from: &Path, names: &[OsString], to: &Path, stop: &StopFlag) -> Result<Placed, PrepareError> {
    std::fs::create_dir(to).map_err(PrepareError::file("create", to))?;
    let mut placed = Placed::default();
    for name in names {
        if stop.is_raised() {
            break;
        }
        let (source, target) = (from.join(name), to.join(name));
        if std::fs::hard_link(&source, &target).is_ok() {
            placed.linked += 1;
        } else {
            std::fs::copy(&source, &target).map_err(PrepareError::file("copy", &source))?;
            placed.copied += 1;
        }
    }
    Ok(placed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photographs_keep_their_names_and_bytes_and_the_originals_stay() {
        let dir = tempfile::tempdir().unwrap();
        let from = dir.path().join("photos");
        std::fs::create_dir(&from).unwrap();
        let names: Vec<OsString> = ["a.jpg", "B.PNG"].map(OsString::from).to_vec();
        for (i, name) in names.iter().enumerate() {
            std::fs::write(from.join(name), [i as u8; 3]).unwrap();
        }
        let to = dir.path().join("out").join("images");
        std::fs::create_dir(dir.path().join("out")).unwrap();
        let placed = place(&from, &names, &to, &StopFlag::default()).unwrap();
        assert_eq!(placed.linked + placed.copied, 2);
        for (i, name) in names.iter().enumerate() {
            assert_eq!(std::fs::read(to.join(name)).unwrap(), [i as u8; 3]);
            assert_eq!(std::fs::read(from.join(name)).unwrap(), [i as u8; 3]);
        }
        // A stop raised before the first photograph places none.
        let stop = StopFlag::default();
        stop.raise();
        let again = dir.path().join("again");
        assert_eq!(place(&from, &names, &again, &stop).unwrap(), Placed::default());
    }
}
