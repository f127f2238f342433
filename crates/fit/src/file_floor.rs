//! The fewest bytes the model file of a fit can take, known from its settings before it
//! trains: what a tool checks against the free space of the file's disk, so that a fit whose
//! model cannot be saved is refused before its budget is spent. It is a floor, never an
//! estimate: a fit refused for it could not have saved its model.
//!
//! - A dense grid's file holds its grid, `nodes^3 x channels` floats, and a grid only grows
//!   ([`growth_stages`]): the first stage's grid is a floor for any save, at the end or on
//!   Ctrl-C.
//! - A sparse grid's file holds the mask of the nodes it kept, a byte for each of the
//!   `nodes^3` (its kept rows may be few, the mask is not).
//! - Splats' PLY file holds its header (the splats may be pruned to few).
//!
//! Beside these, a safetensors file starts with the 8 bytes of its header's length; the
//! header's text, the optimiser's moments and the occupancy grid are not counted.

use fogray_ops::limits;

use crate::schedule::growth_stages;
use crate::settings::{FitSettings, ModelKind};

/// Bytes of a safetensors file before its header's text: the header's length, a `u64`.
const SAFETENSORS_PREFIX: u64 = 8;

impl FitSettings {
    /// The fewest bytes the model file of a fit with these settings can take when it is saved:
    /// what a tool checks against the free space of the file's disk before the fit trains. A
    /// floor, never an estimate: a dense grid counts the grid of its first growth stage, a
    /// sparse grid the mask of its nodes (a byte each), splats their PLY header; the header's
    /// text, the optimiser's moments and the occupancy grid are not counted.
    ///
    /// ```
    /// use fogray_fit::settings::{FitSettings, ModelKind};
    ///
    /// // A dense 32^3 grid that does not grow, density and RGB in f32: 32^3 nodes x 4 channels
    /// // x 4 bytes, after the 8 bytes of the header's length.
    /// let s = FitSettings { grid: 32, grow: false, model: ModelKind::Dense, sh_degree: 0, ..FitSettings::default() };
    /// assert_eq!(s.model_file_floor(), 8 + 32 * 32 * 32 * 4 * 4);
    /// ```
    pub fn model_file_floor(&self) -> u64 {
        let nodes = growth_stages(self).first().map_or(self.grid, |&(_, n)| n) as u64;
        let lattice = nodes.saturating_mul(nodes).saturating_mul(nodes);
        match self.model {
            ModelKind::Dense => {
                let float_bytes = self.precision.bytes() as u64;
                let channels = limits::grid_channels(self.sh_degree) as u64;
                lattice
                    .saturating_mul(channels)
                    .saturating_mul(float_bytes)
                    .saturating_add(SAFETENSORS_PREFIX)
            }
            ModelKind::Sparse => lattice.saturating_add(SAFETENSORS_PREFIX),
            ModelKind::Splats => crate::splats::ply::header(self.sh_degree, 0).len() as u64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::Precision;

    fn settings(model: ModelKind, grid: usize, grow: bool) -> FitSettings {
        FitSettings {
            model,
            grid,
            grow,
            sh_degree: 1,
            precision: Precision::F64,
            ..FitSettings::default()
        }
    }

    #[test]
    fn a_growing_dense_grid_counts_its_first_stage() {
        // Grid 64 grows from 16 (64 / 4); degree 1 has 1 + 3 * 4 = 13 channels; f64.
        assert_eq!(
            settings(ModelKind::Dense, 64, true).model_file_floor(),
            8 + 16 * 16 * 16 * 13 * 8
        );
        assert_eq!(
            settings(ModelKind::Dense, 64, false).model_file_floor(),
            8 + 64 * 64 * 64 * 13 * 8
        );
    }

    #[test]
    fn a_sparse_grid_counts_its_mask_and_splats_their_header() {
        // Grid 9 grows from 3 (9 / 4 rounded up): a mask of 27 bytes.
        assert_eq!(settings(ModelKind::Sparse, 9, true).model_file_floor(), 8 + 27);
        // ply, format, comment and element lines, 3 + 3 + 3 + 9 + 1 + 3 + 4 properties of
        // degree 1, end_header: counted line by line.
        let mut properties = 0;
        for name in ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] {
            properties += "property float ".len() + name.len() + 1;
        }
        for i in 0..9 {
            properties += "property float f_rest_".len() + format!("{i}").len() + 1;
        }
        for name in [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ] {
            properties += "property float ".len() + name.len() + 1;
        }
        let fixed = "ply\n".len()
            + "format binary_little_endian 1.0\n".len()
            + "comment fogray splats, colour degree 1\n".len()
            + "element vertex 0\n".len()
            + "end_header\n".len();
        assert_eq!(
            settings(ModelKind::Splats, 64, true).model_file_floor(),
            (fixed + properties) as u64
        );
    }

    #[test]
    fn a_lattice_too_large_to_count_saturates() {
        let huge = settings(ModelKind::Dense, usize::MAX, false);
        assert_eq!(huge.model_file_floor(), u64::MAX);
    }
}
