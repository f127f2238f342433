//! The settings' choices of kind: the model class, the float type, fused or taped ops, and
//! where samples go.

use serde::{Deserialize, Serialize};

/// Which implementation of the grid lookup, the activation and the composite a step records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Method {
    /// The fused ops (one record each, hand-written backwards).
    Fused,
    /// Their taped twins (built from tape primitives).
    Taped,
}

/// Where samples go along each ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Sampling {
    /// Every half voxel across the box.
    Uniform,
    /// Every half voxel, but only in the cells of an occupancy grid (one cell per voxel) that
    /// the current density marks as occupied, refreshed every few steps.
    Occupancy,
}

/// Which radiance field a fit trains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ModelKind {
    /// A dense grid, every node stored: small scenes.
    Dense,
    /// A sparse grid, only the nodes near what the occupancy grid finds, pruned at each
    /// growth: memory follows the scene.
    Sparse,
    /// 3-D Gaussian splats composited by projection onto the image, densified where the
    /// picture needs them.
    Splats,
}

impl ModelKind {
    /// `dense`, `sparse` or `splats`.
    pub(crate) fn name(self) -> &'static str {
        match self {
            ModelKind::Dense => "dense",
            ModelKind::Sparse => "sparse",
            ModelKind::Splats => "splats",
        }
    }
}

/// The floating-point type of a model and its render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Precision {
    /// 32-bit floats.
    F32,
    /// 64-bit floats.
    F64,
}

impl Precision {
    /// `f32` or `f64`.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }

    /// Bytes of one float of this precision (4 or 8): what a grid, a model file or a render
    /// holds per value.
    pub fn bytes(self) -> usize {
        match self {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }

    /// The precision of `F` (`f32` or `f64`, the two [`Float`](fogray_tape::Float) types).
    pub(crate) fn of<F: fogray_tape::Float>() -> Precision {
        if std::mem::size_of::<F>() == 4 {
            Precision::F32
        } else {
            Precision::F64
        }
    }
}

impl Method {
    /// `fused` or `taped`.
    pub fn name(self) -> &'static str {
        match self {
            Method::Fused => "fused",
            Method::Taped => "taped",
        }
    }
}

impl Sampling {
    /// `uniform` or `occupancy`.
    pub fn name(self) -> &'static str {
        match self {
            Sampling::Uniform => "uniform",
            Sampling::Occupancy => "occupancy",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Precision;

    #[test]
    fn a_precision_counts_the_bytes_of_its_float() {
        assert_eq!(Precision::F32.bytes(), std::mem::size_of::<f32>());
        assert_eq!(Precision::F64.bytes(), std::mem::size_of::<f64>());
        assert_eq!(Precision::of::<f32>().bytes(), 4);
        assert_eq!(Precision::of::<f64>().bytes(), 8);
    }
}
