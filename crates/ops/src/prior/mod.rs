//! Priors on a grid's values: terms added to a fit's loss that say what a scene is likely to
//! look like where the photographs say little.
//!
//! [`TotalVariation`]: the mean squared difference of neighbouring nodes, which pulls a grid
//! that the rays constrain only in places (few views, many unknowns) towards a smooth field
//! instead of leaving speckle where no ray disagreed with it.

mod sparse_total_variation;
mod total_variation;

pub use sparse_total_variation::SparseTotalVariation;
pub use total_variation::TotalVariation;
