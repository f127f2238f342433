//! What a size will allocate, and whether the machine has it: the one place that knows the
//! bytes a grid node, a training ray, a rendered pixel and a loaded frame cost, so that a size
//! given by a flag or read from a file is refused in one line before anything is allocated,
//! instead of aborting on a failed allocation (or swapping) half way through.
//!
//! The figures count the arrays each piece of work holds at its peak (values, gradients,
//! optimiser moments, a step's recorded samples), not the allocator's overhead: they are a
//! floor on what the work needs, so that a refusal is certain and an acceptance likely. They
//! live here, in the lowest crate that every caller reaches (the fit's settings, the data
//! loader, the command line), because the ops are what allocates them: the grid fields, the
//! samplers' packed samples and the cameras' rays.
//!
//! ```
//! use fogray_ops::limits::{Bytes, GridShape};
//!
//! // A dense 64^3 grid of density and RGB in f32: 4 channels, 4 bytes each, five copies
//! // (values, two gradients, Adam's two moments).
//! let grid = GridShape { nodes: 64, channels: 4, float_bytes: 4 };
//! assert_eq!(grid.dense_bytes(), Bytes(64 * 64 * 64 * 4 * 4 * 5));
//! // Refused in one line that says what it would need and what there is.
//! let e = Bytes::check(grid.dense_bytes(), Bytes(1_000_000), "--grid 64", "the grid").unwrap_err();
//! assert_eq!(e.to_string(), "--grid 64 would need 21.0 MB for the grid; 1.00 MB available");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt;

use thiserror::Error;

use crate::rays::PinholeCamera;

pub mod headroom;

/// A number of bytes; displayed in decimal units to three significant digits (`12.3 TB`).
/// Arithmetic on it saturates: a size too large to count is `u64::MAX` bytes, refused like any
/// other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Bytes(pub u64);

/// Memory assumed available where the system does not say (not Linux, or `/proc/meminfo`
/// unreadable): a modest machine's, so that what passes the check has a fair chance.
pub const FALLBACK_AVAILABLE: Bytes = Bytes(8_000_000_000);

impl Bytes {
    /// `a * b * ...`, saturating at `u64::MAX`.
    pub fn product(factors: &[u64]) -> Bytes {
        Bytes(factors.iter().fold(1u64, |acc, &f| acc.saturating_mul(f)))
    }

    /// `self + other`, saturating.
    pub fn plus(self, other: Bytes) -> Bytes {
        Bytes(self.0.saturating_add(other.0))
    }

    /// `self * n`, saturating.
    pub fn times(self, n: u64) -> Bytes {
        Bytes(self.0.saturating_mul(n))
    }

    /// Ok if `need` fits in `available`; otherwise [`TooLarge`], whose message reads
    /// "`what` would need `need` for `needed_for`; `available` available".
    pub fn check(need: Bytes, available: Bytes, what: &str, needed_for: &str) -> Result<(), TooLarge> {
        if need <= available {
            return Ok(());
        }
        Err(TooLarge {
            what: what.to_string(),
            needed_for: needed_for.to_string(),
            need,
            available,
        })
    }
}

impl fmt::Display for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const UNITS: [&str; 6] = ["kB", "MB", "GB", "TB", "PB", "EB"];
        if self.0 < 1000 {
            return write!(f, "{} B", self.0);
        }
        let mut value = self.0 as f64;
        let mut unit = 0;
        value /= 1000.0;
        while value >= 999.5 && unit + 1 < UNITS.len() {
            value /= 1000.0;
            unit += 1;
        }
        let digits = if value >= 99.95 {
            0
        } else if value >= 9.995 {
            1
        } else {
            2
        };
        write!(f, "{value:.digits$} {}", UNITS[unit])
    }
}

/// A size refused: what asked for it, what for, how much it would need and how much the
/// machine has.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{what} would need {need} for {needed_for}; {available} available")]
pub struct TooLarge {
    /// The flag or file entry with its value (`--grid 100000`, `transforms.json: frames[0]`).
    pub what: String,
    /// What the bytes are for (`the grid`, `a step's rays`).
    pub needed_for: String,
    /// The bytes it would need.
    pub need: Bytes,
    /// The bytes available.
    pub available: Bytes,
}

/// The memory this process can still take without swapping or failing: the smallest of
/// Linux's `MemAvailable` (free memory plus the caches the kernel would drop, else
/// [`FALLBACK_AVAILABLE`]), its address-space limit less what it has mapped, and its control
/// groups' limits less what they hold ([`headroom::process_headroom`]).
pub fn available() -> Bytes {
    let machine = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_available(&text))
        .unwrap_or(FALLBACK_AVAILABLE);
    headroom::process_headroom().map_or(machine, |process| machine.min(process))
}

/// The `MemAvailable:` line of a `/proc/meminfo` text, in bytes (the file counts kibibytes).
pub fn mem_available(meminfo: &str) -> Option<Bytes> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(Bytes(kib.saturating_mul(1024)))
}

/// Copies of each parameter a fit holds: the values, the gradient of the lookup and that of
/// the prior (summed into one only after both exist), and Adam's two moments.
pub const PARAMETER_COPIES: u64 = 5;

/// Bytes per lattice node of a sparse grid besides its kept rows: its index (a `u32` row per
/// node) and the keep mask a growth builds (a `bool` per node).
pub const SPARSE_LATTICE_BYTES: u64 = 4 + 1;

/// Floats a training step records per sample, forward and backward: the position (3), `t`
/// and `delta` (2), the activated density and colour with their gradients (8), the
/// composite's weights and transmittance (2); the raw values and their gradient (2 per
/// channel) are added by [`GridShape::training_sample_bytes`].
pub const TRAINING_SAMPLE_FLOATS: u64 = 15;

/// Floats a view-dependent colour adds per sample: the view direction (3, and its copy on the
/// tape 3), the density slice and its gradient (4), the colour's value and gradient before the
/// composite (6); the coefficients' slice and its gradient (2 per channel) are added by
/// [`GridShape::training_sample_bytes`].
pub const VIEW_DEPENDENT_SAMPLE_FLOATS: u64 = 16;

/// Bytes of index per recorded sample: the ray it belongs to (`usize`).
pub const SAMPLE_INDEX_BYTES: u64 = 8;

/// Floats a training step holds per ray besides its samples: origin and direction (6), the
/// target colour and alpha (4), a random background and the colour over it (6), the target on
/// the tape (3), the composite's colour, opacity and end transmittance with their gradients
/// (10); plus [`SAMPLE_INDEX_BYTES`] for the ray's row in the table.
pub const TRAINING_RAY_FLOATS: u64 = 29;

/// Bytes a render holds per pixel of the frame being rendered: origin and direction in `f64`
/// (48), colour, opacity and depth in `f64` (40), the 8-bit PNG and GIF frame with its
/// palette indices (7).
pub const RENDER_PIXEL_BYTES: u64 = 48 + 40 + 7;

/// Bytes a render holds per frame of the list of views it will render: the camera, a copy
/// while the list is built, and the frame's name.
pub const RENDER_FRAME_BYTES: u64 = 2 * std::mem::size_of::<PinholeCamera>() as u64 + 64;

/// Bytes a splat render holds per (splat, tile) pair of its tiles' lists: the list entry
/// (`u32`, 4) and, in the backward, the pair's gradient row (9 `f64`: 2-D mean, conic,
/// opacity and colour).
pub const SPLAT_INTERSECTION_BYTES: u64 = 4 + 9 * 8;

/// Bytes a splat render holds per pixel: the colour, transmittance and count of the raster
/// (36), its per-tile copy before it is placed (36), and the tile offsets (8 per 256 pixels,
/// rounded up to 1).
pub const SPLAT_PIXEL_BYTES: u64 = 36 + 36 + 1;

/// Bytes a loaded frame keeps per pixel: colour (3) and alpha (1) in `f32`.
pub const FRAME_PIXEL_BYTES: u64 = 4 * 4;

/// Bytes per pixel while one frame is decoded: the file's decoded pixels (up to 16-bit RGBA,
/// 8), their RGBA copy in `f32` (16) and the colour and alpha kept (16).
pub const DECODE_PIXEL_BYTES: u64 = 8 + 16 + FRAME_PIXEL_BYTES;

/// A grid model's size: nodes per axis (of the final stage), channels per node (density and
/// colour), bytes per float.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GridShape {
    /// Nodes per axis.
    pub nodes: usize,
    /// Channels per node: 1 + 3 (degree + 1)^2 (see [`grid_channels`]).
    pub channels: usize,
    /// 4 for `f32`, 8 for `f64`.
    pub float_bytes: usize,
}

/// Channels per node of a grid with spherical harmonics of `sh_degree` (0: view-independent
/// RGB): the density and `3 (degree + 1)^2` colour coefficients.
pub fn grid_channels(sh_degree: usize) -> usize {
    1 + 3 * (sh_degree.saturating_add(1)).saturating_pow(2)
}

impl GridShape {
    fn lattice(&self) -> Bytes {
        let n = self.nodes as u64;
        Bytes::product(&[n, n, n])
    }

    fn node_parameter_bytes(&self) -> u64 {
        (self.channels as u64)
            .saturating_mul(self.float_bytes as u64)
            .saturating_mul(PARAMETER_COPIES)
    }

    /// A dense grid in training: every node's parameters, [`PARAMETER_COPIES`] times.
    pub fn dense_bytes(&self) -> Bytes {
        self.lattice().times(self.node_parameter_bytes())
    }

    /// A sparse grid in training at its worst, every node kept (as it is in the first stage,
    /// and at each growth where the scene fills the box): the dense grid's bytes plus
    /// [`SPARSE_LATTICE_BYTES`] a node.
    pub fn sparse_bytes(&self) -> Bytes {
        self.lattice()
            .times(self.node_parameter_bytes().saturating_add(SPARSE_LATTICE_BYTES))
    }

    /// Samples a ray through the grid's box takes at the grid's sample step (half the node
    /// spacing): those of a chord one box side long, `2 (N - 1)`, the chord through the middle
    /// that a camera looking at the box's centre sees (the diagonal has `sqrt 3` times more,
    /// a ray that grazes the box fewer).
    pub fn samples_per_ray(&self) -> u64 {
        2 * (self.nodes.max(2) as u64 - 1)
    }

    /// Bytes a training step records per sample (see [`TRAINING_SAMPLE_FLOATS`]).
    pub fn training_sample_bytes(&self) -> u64 {
        let c = self.channels as u64;
        let view_dependent = c > 4;
        let floats = TRAINING_SAMPLE_FLOATS
            + 2 * c
            + if view_dependent {
                VIEW_DEPENDENT_SAMPLE_FLOATS + 2 * c
            } else {
                0
            };
        floats.saturating_mul(self.float_bytes as u64) + SAMPLE_INDEX_BYTES
    }

    /// Bytes a training step holds per ray of its batch: [`TRAINING_RAY_FLOATS`] and its
    /// samples ([`GridShape::samples_per_ray`] of [`GridShape::training_sample_bytes`]).
    pub fn training_ray_bytes(&self) -> Bytes {
        let own = TRAINING_RAY_FLOATS * self.float_bytes as u64 + SAMPLE_INDEX_BYTES;
        Bytes(self.samples_per_ray())
            .times(self.training_sample_bytes())
            .plus(Bytes(own))
    }

    /// Bytes a chunk of `rays` rays holds while it is rendered without a tape's record: the
    /// samples' forward values only (about half a training sample's floats).
    pub fn render_chunk_bytes(&self, rays: usize) -> Bytes {
        let per_sample = self.training_sample_bytes() / 2 + SAMPLE_INDEX_BYTES;
        Bytes::product(&[rays as u64, self.samples_per_ray(), per_sample])
    }
}

/// Bytes a render of `frames` frames of `width x height` pixels holds at its peak: the list of
/// views ([`RENDER_FRAME_BYTES`] each) and one frame's pixels ([`RENDER_PIXEL_BYTES`] each);
/// the frames are rendered and written one at a time. The chunk the model renders at a time
/// ([`GridShape::render_chunk_bytes`]) comes on top.
pub fn render_bytes(frames: usize, width: usize, height: usize) -> Bytes {
    Bytes::product(&[frames as u64, RENDER_FRAME_BYTES]).plus(Bytes::product(&[
        width as u64,
        height as u64,
        RENDER_PIXEL_BYTES,
    ]))
}

/// Bytes a loaded `width x height` frame keeps ([`FRAME_PIXEL_BYTES`] a pixel).
pub fn frame_bytes(width: usize, height: usize) -> Bytes {
    Bytes::product(&[width as u64, height as u64, FRAME_PIXEL_BYTES])
}

/// Bytes the decoding of a `width x height` frame holds at its peak ([`DECODE_PIXEL_BYTES`]
/// a pixel).
pub fn decode_bytes(width: usize, height: usize) -> Bytes {
    Bytes::product(&[width as u64, height as u64, DECODE_PIXEL_BYTES])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_read_in_decimal_units_to_three_digits() {
        for (bytes, text) in [
            (0, "0 B"),
            (999, "999 B"),
            (1000, "1.00 kB"),
            (12_345, "12.3 kB"),
            (999_499, "999 kB"),
            (999_500, "1.00 MB"),
            (20_100_000_000, "20.1 GB"),
            (12_300_000_000_000, "12.3 TB"),
            (u64::MAX, "18.4 EB"),
        ] {
            assert_eq!(Bytes(bytes).to_string(), text, "{bytes}");
        }
    }

    #[test]
    fn products_saturate_instead_of_wrapping() {
        assert_eq!(
            Bytes::product(&[100_000, 100_000, 100_000, 100_000, 100_000]),
            Bytes(u64::MAX)
        );
        assert_eq!(Bytes(u64::MAX).plus(Bytes(1)), Bytes(u64::MAX));
        assert_eq!(Bytes::product(&[3, 5, 7]), Bytes(105));
    }

    #[test]
    fn mem_available_reads_kibibytes() {
        let text = "MemTotal:       24000000 kB\nMemFree:         1000 kB\nMemAvailable:   19629000 kB\n";
        assert_eq!(mem_available(text), Some(Bytes(19_629_000 * 1024)));
        assert_eq!(mem_available("MemTotal: 5 kB\n"), None);
        assert!(available() > Bytes(0));
    }

    #[test]
    fn channels_are_the_density_and_three_coefficients_per_harmonic() {
        // Degree d has (d + 1)^2 harmonics, each with an R, G and B coefficient.
        assert_eq!([0, 1, 2, 3].map(grid_channels), [4, 13, 28, 49]);
    }

    #[test]
    fn a_grid_costs_its_nodes_times_channels_floats_and_copies() {
        let dense = GridShape {
            nodes: 100_000,
            channels: 4,
            float_bytes: 4,
        };
        // 1e15 nodes, 4 channels of 4 bytes, 5 copies: 8e16 bytes.
        assert_eq!(dense.dense_bytes(), Bytes(80_000_000_000_000_000));
        assert_eq!(dense.sparse_bytes(), Bytes(85_000_000_000_000_000));
        let small = GridShape {
            nodes: 10,
            channels: 28,
            float_bytes: 8,
        };
        assert_eq!(small.dense_bytes(), Bytes(1000 * 28 * 8 * 5));
    }

    #[test]
    fn a_training_ray_costs_its_samples_and_its_own_values() {
        let grid = GridShape {
            nodes: 65,
            channels: 4,
            float_bytes: 4,
        };
        // 128 samples of (15 + 2 * 4) floats of 4 bytes and an 8-byte index, plus 29 floats
        // and an 8-byte row of the ray's own.
        assert_eq!(grid.samples_per_ray(), 128);
        assert_eq!(grid.training_ray_bytes(), Bytes(128 * (23 * 4 + 8) + 29 * 4 + 8));
        let view_dependent = GridShape { channels: 13, ..grid };
        // (15 + 26 + 16 + 26) floats a sample.
        assert_eq!(view_dependent.training_sample_bytes(), 83 * 4 + 8);
    }

    #[test]
    fn a_refusal_names_what_it_needs_and_what_there_is() {
        assert_eq!(Bytes::check(Bytes(5), Bytes(5), "x", "y"), Ok(()));
        let e = Bytes::check(
            Bytes(12_300_000_000_000),
            Bytes(20_100_000_000),
            "--grid 100000",
            "the grid",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "--grid 100000 would need 12.3 TB for the grid; 20.1 GB available"
        );
        assert_eq!(
            render_bytes(2, 10, 10),
            Bytes(2 * RENDER_FRAME_BYTES + 100 * RENDER_PIXEL_BYTES)
        );
        assert_eq!(frame_bytes(800, 800), Bytes(800 * 800 * 16));
    }
}
