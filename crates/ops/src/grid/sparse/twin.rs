//! The sparse lookup written with tape primitives: the packed values scattered into the full
//! lattice (`scatter_add` into zero rows, so an absent node reads 0), then the dense grid's
//! own twin. It costs the full lattice's memory: a reference for tests on small grids.

use fogray_tape::{Float, Tape, TapeError, Var};

use super::super::twin::lookup as dense_lookup;
use super::super::GridField;
use super::field::SparseGridField;

/// The twin of [`SparseGridField::apply`]: the same values and gradients, from primitives.
///
/// Errors: as the fused op's, and the tape's errors.
pub fn lookup<F: Float>(
    tape: &mut Tape<F>,
    field: &SparseGridField,
    data: Var,
    positions: Var,
) -> Result<Var, TapeError> {
    let [n0, n1, n2] = field.index().nodes();
    let ch = field.channels();
    let lattice = tape.scatter_add(data, &field.index().kept_nodes(), n0 * n1 * n2)?;
    let lattice = tape.reshape(lattice, &[n0, n1, n2, ch])?;
    let dense = GridField::new(*field.bbox(), &[n0, n1, n2, ch]).map_err(|e| TapeError::InvalidArgument {
        op: "sparse_grid_field_twin",
        reason: e.to_string(),
    })?;
    dense_lookup(tape, &dense, lattice, positions)
}
