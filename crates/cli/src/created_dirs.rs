//! Folders a command creates for its outputs, removed again if the command fails before it
//! has put anything in them: a refused or failed command leaves no empty folder behind.

use std::path::{Path, PathBuf};

use crate::error::CliError;

/// The folders created so far (outermost first); removed, innermost first and only while
/// empty, when dropped before [`CreatedDirs::keep`].
#[derive(Debug, Default)]
pub struct CreatedDirs {
    created: Vec<PathBuf>,
    kept: bool,
}

impl CreatedDirs {
    /// Nothing created yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Creates `dir` and its missing parents, remembering those it created.
    ///
    /// Errors: a folder that cannot be created, named.
    pub fn create(&mut self, dir: &Path) -> Result<(), CliError> {
        let missing: Vec<PathBuf> = dir
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .map(Path::to_path_buf)
            .collect();
        std::fs::create_dir_all(dir).map_err(CliError::file("create", dir))?;
        self.created.extend(missing.into_iter().rev());
        Ok(())
    }

    /// The command succeeded: its folders stay.
    pub fn keep(mut self) {
        self.kept = true;
    }
}

impl Drop for CreatedDirs {
    fn drop(&mut self) {
        if self.kept {
            return;
        }
        // `remove_dir` removes only an empty folder: whatever the command wrote stays.
        for dir in self.created.iter().rev() {
            let _ = std::fs::remove_dir(dir);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_left_empty_by_a_failure_are_removed_and_kept_ones_stay() {
        let root = tempfile::tempdir().unwrap();
        let deep = root.path().join("a/b/c");
        {
            let mut dirs = CreatedDirs::new();
            dirs.create(&deep).unwrap();
            assert!(deep.is_dir());
        }
        assert!(!root.path().join("a").exists());
        // A file written inside keeps its folder (and the folders above it).
        {
            let mut dirs = CreatedDirs::new();
            dirs.create(&deep).unwrap();
            std::fs::write(root.path().join("a/b/file"), b"x").unwrap();
        }
        assert!(root.path().join("a/b/file").exists() && !deep.exists());
        // Kept: all stay.
        let mut dirs = CreatedDirs::new();
        dirs.create(&deep).unwrap();
        dirs.keep();
        assert!(deep.is_dir());
    }
}
