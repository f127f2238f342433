//! The free space of each output's disk, checked before a command does its work: a fit
//! whose model or report cannot be written is refused in one line before it trains, instead
//! of failing once its budget is spent.
//!
//! Each output says the fewest bytes it can take (a floor: its model file's first-stage grid,
//! the report's fixed files at the least their formats allow), and the outputs on one
//! filesystem are summed against that filesystem's free space (`statvfs` through rustix: the
//! blocks free to this process, the reserved ones included for root). Only a floor is checked,
//! so that the check never refuses a command that would have fitted; a disk that fills while
//! the command runs is still found when the file is written (whole or not at all).

use std::path::{Path, PathBuf};

use fogray_ops::limits::Bytes;

use crate::error::CliError;

/// An output a command will write, and the fewest bytes it will take.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Output {
    /// The file or folder written (the folder's files are counted together).
    pub path: PathBuf,
    /// What it is, for the error (`the model file`, `the report`).
    pub what: &'static str,
    /// The fewest bytes it takes.
    pub floor: u64,
}

/// The filesystem an output lands on: its device, and the bytes this process may still write
/// there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Room {
    /// The device number of the filesystem.
    pub device: u64,
    /// Bytes free to this process.
    pub free: u64,
}

/// The room of the filesystem that `path` will be written on: that of its nearest existing
/// ancestor (the working directory for a bare name); `None` where the system does not say.
#[cfg(unix)]
pub fn room(path: &Path) -> Option<Room> {
    use std::os::unix::fs::MetadataExt;
    let existing = path
        .ancestors()
        .map(|a| if a.as_os_str().is_empty() { Path::new(".") } else { a })
        .find(|a| a.exists())?;
    let device = std::fs::metadata(existing).ok()?.dev();
    let stats = rustix::fs::statvfs(existing).ok()?;
    // Root may write into the blocks an ext filesystem reserves; others may not.
    let blocks = if rustix::process::geteuid().is_root() {
        stats.f_bfree
    } else {
        stats.f_bavail
    };
    let block = if stats.f_frsize > 0 {
        stats.f_frsize
    } else {
        stats.f_bsize
    };
    Some(Room {
        device,
        free: blocks.saturating_mul(block),
    })
}

/// The room of `path`'s filesystem: not known off Unix (nothing is refused).
#[cfg(not(unix))]
pub fn room(_path: &Path) -> Option<Room> {
    None
}

/// Refuses `outputs` that cannot fit on their filesystems, as `room` finds them: an output
/// whose own floor exceeds its filesystem's free bytes, then outputs sharing a filesystem
/// whose floors together do. Outputs whose room is unknown pass.
///
/// Errors: [`CliError::NoRoom`] naming the output (or the outputs sharing the disk), the bytes
/// it needs and the bytes free.
pub fn check(outputs: &[Output], room: impl Fn(&Path) -> Option<Room>) -> Result<(), CliError> {
    let placed: Vec<(&Output, Room)> = outputs.iter().filter_map(|o| Some((o, room(&o.path)?))).collect();
    for (output, room) in &placed {
        if output.floor > room.free {
            return Err(no_room(&[output], output.floor, room.free));
        }
    }
    for (i, (_, first)) in placed.iter().enumerate() {
        if placed[..i].iter().any(|(_, r)| r.device == first.device) {
            continue;
        }
        let sharing: Vec<&Output> = placed[i..]
            .iter()
            .filter(|(_, r)| r.device == first.device)
            .map(|(o, _)| *o)
            .collect();
        let need = sharing.iter().fold(0u64, |sum, o| sum.saturating_add(o.floor));
        if need > first.free {
            return Err(no_room(&sharing, need, first.free));
        }
    }
    Ok(())
}

fn no_room(outputs: &[&Output], need: u64, free: u64) -> CliError {
    let names: Vec<String> = outputs
        .iter()
        .map(|o| format!("{} ({})", fogray_data::shown(&o.path), o.what))
        .collect();
    CliError::NoRoom {
        outputs: names,
        need: Bytes(need),
        free: Bytes(free),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn output(path: &str, floor: u64) -> Output {
        Output {
            path: PathBuf::from(path),
            what: "the model file",
            floor,
        }
    }

    /// Two filesystems: `a/` (device 1, 1000 bytes free) and `b/` (device 2, 10 free).
    fn rooms(path: &Path) -> Option<Room> {
        match path.components().next()?.as_os_str().to_str()? {
            "a" => Some(Room { device: 1, free: 1000 }),
            "b" => Some(Room { device: 2, free: 10 }),
            _ => None,
        }
    }

    #[test]
    fn an_output_larger_than_its_disk_s_free_space_is_refused_by_name() {
        assert!(check(&[output("a/m", 1000), output("b/m", 10)], rooms).is_ok());
        let e = check(&[output("a/m", 1000), output("b/m", 11)], rooms).unwrap_err();
        assert_eq!(
            e.to_string(),
            "b/m (the model file) needs at least 11 B; its disk has 10 B free"
        );
        // Unknown room: not refused.
        assert!(check(&[output("c/m", u64::MAX)], rooms).is_ok());
    }

    #[test]
    fn outputs_on_one_disk_are_summed() {
        // 600 + 401 > 1000 on device 1; the one on device 2 is apart.
        let outputs = [output("a/m", 600), output("b/x", 5), output("a/r", 401)];
        let e = check(&outputs, rooms).unwrap_err();
        assert_eq!(
            e.to_string(),
            "a/m (the model file) and a/r (the model file) need at least 1.00 kB; their disk has 1.00 kB free"
        );
        assert!(check(&[output("a/m", 600), output("a/r", 400)], rooms).is_ok());
    }

    #[test]
    fn the_room_of_a_path_not_made_yet_is_its_nearest_folder_s() {
        let dir = tempfile::tempdir().unwrap();
        let deep = dir.path().join("not/made/yet/m.safetensors");
        let here = room(dir.path()).expect("a temporary folder's filesystem says its free space");
        assert_eq!(room(&deep).map(|r| r.device), Some(here.device));
    }
}
