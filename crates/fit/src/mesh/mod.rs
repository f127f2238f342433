//! A fitted model as a surface mesh, for tools that open meshes rather than radiance fields
//! (MeshLab, Blender, trimesh): the model's density sampled on a lattice over its box, the
//! surface where it crosses a level by marching cubes ([`extract`]), coloured by the model's
//! view-independent colour at each vertex ([`RadianceField::base_colors`]), and written as
//! binary PLY ([`Mesh::write_ply`]).
//!
//! The level is a density, or an opacity: the opacity `1 - exp(-sigma step)` of one sample
//! step of the model ([`RadianceField::sample_step`]), which needs no knowledge of the
//! density's scale. The default ([`Level::default`]) is a tenth of the light a step: a
//! fitted surface is a shell a few steps thick that absorbs the light together, and few of its
//! single steps absorb half of it, so a higher default loses parts of a fitted surface while a
//! lower one takes in the faint fog around it.
//!
//! ```
//! use fogray_fit::dense::DenseGrid;
//! use fogray_fit::mesh::{extract, Level, MeshOptions};
//! use fogray_fit::model::RadianceField;
//! use fogray_fit::settings::SceneBox;
//! use ndarray::Array4;
//!
//! // A dense 16^3 grid over [-1, 1]^3, dense (raw density 8) within 0.6 of the centre.
//! let mut model = DenseGrid::<f32>::new(SceneBox { min: [-1.0; 3], max: [1.0; 3] }, 16, 0.0, 0.0)?;
//! let raw = Array4::from_shape_fn((16, 16, 16, 4), |(i, j, k, c)| {
//!     let r2: f64 = [i, j, k].iter().map(|&x| (-1.0 + 2.0 * x as f64 / 15.0).powi(2)).sum();
//!     if c > 0 { 0.0 } else if r2 < 0.36 { 8.0 } else { -8.0 }
//! });
//! let id = model.grid_id();
//! model.params_mut().get_mut(id)?.assign(&raw);
//! let options = MeshOptions { level: Level::Density(4.0), resolution: None };
//! let extracted = extract(&model, &options)?;
//! assert!(extracted.mesh.triangles.len() > 100);
//! assert!(extracted.mesh.colors.iter().all(|&c| c == [128; 3])); // grey: sigmoid(0) = 0.5
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub(crate) mod lattice;
pub(crate) mod marching;
pub(crate) mod ply;
mod tables;

use fogray_tape::Float;
use ndarray::Array2;
use thiserror::Error;

use crate::error::FitError;
use crate::model::RadianceField;
use fogray_ops::space::InnerRegion;
pub(crate) use lattice::Lattice;
pub(crate) use marching::{march, Surface};

/// The opacity of one sample step at which [`Level::default`] puts the surface: a tenth of
/// the light absorbed (see the [module docs](self) for why).
pub(crate) const DEFAULT_OPACITY: f64 = 0.1;

/// Vertices whose colours are looked up at once.
const COLOR_CHUNK: usize = 1 << 16;

/// Why a mesh could not be made.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MeshError {
    /// A lattice of fewer than 2 nodes per axis (or more than memory can address).
    #[error("resolution {0}: a mesh needs a lattice of at least 2 nodes per axis (and one that fits in memory)")]
    Resolution(usize),
    /// An opacity outside `(0, 1)`.
    #[error("opacity {0}: must be in (0, 1)")]
    Opacity(f64),
    /// A level no surface crosses: not finite, not above 0, or outside the density's range
    /// on the lattice.
    #[error("{}", level_message(*.level, *.opacity, *.range))]
    Level {
        /// The density level.
        level: f64,
        /// The opacity of one step it came from, if it did.
        opacity: Option<f64>,
        /// The density's range on the lattice, when it is known.
        range: Option<(f64, f64)>,
    },
    /// Lattice values that are not one per node, or not finite.
    #[error("lattice: {0}")]
    Values(String),
    /// More vertices than a PLY file's indices reach.
    #[error("{vertices} vertices: more than a PLY file indexes (use a smaller resolution)")]
    TooLarge {
        /// Vertices made when the limit was passed.
        vertices: usize,
    },
}

fn level_message(level: f64, opacity: Option<f64>, range: Option<(f64, f64)>) -> String {
    let what = match opacity {
        Some(a) => format!("opacity {a} (density level {level})"),
        None => format!("density level {level}"),
    };
    match range {
        Some((lo, hi)) => format!(
            "{what} is outside the density's range [{}, {}] on the lattice",
            significant(lo),
            significant(hi)
        ),
        None => format!("{what}: a level must be finite and above 0"),
    }
}

/// `x` to 4 significant digits, in an exponent form when it is far from 1.
fn significant(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let e = x.abs().log10().floor();
    if (-4.0..6.0).contains(&e) {
        format!("{:.*}", (3.0 - e).max(0.0) as usize, x)
    } else {
        format!("{x:.3e}")
    }
}

/// Where the surface lies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Level {
    /// A density `sigma` (the model's units, per unit length).
    Density(f64),
    /// The opacity `1 - exp(-sigma step)` of one sample step of the model, in `(0, 1)`.
    Opacity(f64),
}

impl Default for Level {
    /// [`Level::Opacity`] of a tenth of the light a step (the [module docs](self) say why).
    fn default() -> Self {
        Level::Opacity(DEFAULT_OPACITY)
    }
}

impl Level {
    /// The density level for a model whose sample step is `step`: `-ln(1 - A) / step` for an
    /// opacity `A`.
    ///
    /// Errors: an opacity outside `(0, 1)` ([`MeshError::Opacity`]).
    pub(crate) fn density(self, step: f64) -> Result<f64, MeshError> {
        match self {
            Level::Density(sigma) => Ok(sigma),
            Level::Opacity(a) if a > 0.0 && a < 1.0 => Ok(-(-a).ln_1p() / step),
            Level::Opacity(a) => Err(MeshError::Opacity(a)),
        }
    }
}

/// What to extract.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MeshOptions {
    /// Where the surface lies.
    pub level: Level,
    /// Lattice nodes per axis; the model's own node count ([`RadianceField::nodes`]) if
    /// `None`.
    pub resolution: Option<usize>,
}

/// A coloured triangle mesh.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions, in the model's units.
    pub positions: Vec<[f32; 3]>,
    /// One 8-bit RGB colour a vertex.
    pub colors: Vec<[u8; 3]>,
    /// Triangles, three indices into `positions` each, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

/// A mesh and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Extraction {
    /// The mesh.
    pub mesh: Mesh,
    /// The density level of its surface.
    pub level: f64,
    /// Lattice nodes per axis.
    pub resolution: usize,
    /// The density's range on the lattice.
    pub range: (f64, f64),
}

/// The surface of `model` where its density crosses `options.level` on a lattice of
/// `options.resolution` nodes per axis over its box (over the inner region of a field of all
/// of space, in world units), each vertex coloured by the model's
/// view-independent colour there (rounded to 8 bits). Lattice and colours are looked up
/// without a tape. The surface encloses the region of at least the level's density and is
/// closed: where that region reaches the box, a cap just outside the box closes it.
///
/// Errors: a resolution below 2, an opacity outside `(0, 1)`, a level outside the density's
/// range on the lattice (the message gives the range), a mesh too large for a PLY file, the
/// model's (a NaN value).
pub fn extract<F: Float, M: RadianceField<F>>(model: &M, options: &MeshOptions) -> Result<Extraction, FitError> {
    let resolution = options.resolution.unwrap_or(model.nodes());
    if resolution < 2 {
        return Err(MeshError::Resolution(resolution).into());
    }
    let level = options.level.density(model.sample_step())?;
    let opacity = match options.level {
        Level::Opacity(a) => Some(a),
        Level::Density(_) => None,
    };
    let lattice = Lattice::sample(model, resolution)?;
    let range = lattice.range();
    if !(level >= range.0 && level <= range.1) {
        return Err(MeshError::Level {
            level,
            opacity,
            range: Some(range),
        }
        .into());
    }
    let Surface { positions, triangles } = march(&lattice, level).map_err(|e| match e {
        MeshError::Level { .. } => MeshError::Level {
            level,
            opacity,
            range: Some(range),
        },
        e => e,
    })?;
    let colors = vertex_colors(model, &positions)?;
    let positions = match model.space().contraction() {
        None => positions,
        // The inner region's contracted point u is the world point c + r u.
        Some(contraction) => {
            let InnerRegion { centre, radius } = contraction.region();
            positions
                .iter()
                .map(|p| std::array::from_fn(|a| (centre[a] + radius * f64::from(p[a])) as f32))
                .collect()
        }
    };
    Ok(Extraction {
        mesh: Mesh {
            positions,
            colors,
            triangles,
        },
        level,
        resolution,
        range,
    })
}

/// `model`'s view-independent colour at each of `positions`, rounded to 8 bits; a position
/// just outside the box (a cap's) takes the colour at the nearest point of the box.
///
/// Errors: the model's.
pub(crate) fn vertex_colors<F: Float, M: RadianceField<F>>(
    model: &M,
    positions: &[[f32; 3]],
) -> Result<Vec<[u8; 3]>, FitError> {
    let (lo, hi) = (model.bounds().min(), model.bounds().max());
    let mut colors = Vec::with_capacity(positions.len());
    for chunk in positions.chunks(COLOR_CHUNK) {
        let at = Array2::from_shape_fn((chunk.len(), 3), |(v, a)| {
            F::lit(f64::from(chunk[v][a]).clamp(lo[a], hi[a]))
        });
        let rgb = model.base_colors(at.view())?;
        colors.extend(
            rgb.rows()
                .into_iter()
                .map(|c| std::array::from_fn(|k| (c[k].as_f64().clamp(0.0, 1.0) * 255.0).round() as u8)),
        );
    }
    Ok(colors)
}

#[cfg(test)]
mod tests;
