//! Changing the number of splats between steps: a new parameter store with the new rows and a
//! new Adam whose moments follow them (a kept or copied row keeps its source's moments, a new
//! one starts at zero), since a store's parameters never change shape.

use fogray_tape::optim::{Adam, AdamState};
use fogray_tape::Float;
use ndarray::{ArrayD, IxDyn};

use super::model::{SplatArraysOwned, SplatModel};
use crate::error::FitError;

/// The rows of a moment `[n, ...]` picked by `origin` (`None`: zeros).
fn gather<F: Float>(moment: &ArrayD<F>, origin: &[Option<usize>]) -> Result<ArrayD<F>, FitError> {
    let n = moment.shape().first().copied().unwrap_or(0);
    let width = moment.len().checked_div(n).unwrap_or(0);
    let flat = moment
        .as_slice()
        .map(<[F]>::to_vec)
        .unwrap_or_else(|| moment.iter().copied().collect());
    let mut out = Vec::with_capacity(origin.len() * width);
    for o in origin {
        match o {
            Some(i) if *i < n => out.extend_from_slice(&flat[i * width..(i + 1) * width]),
            Some(i) => return Err(FitError::Config(format!("splat row {i} of {n} does not exist"))),
            None => out.extend(std::iter::repeat_n(F::lit(0.0), width)),
        }
    }
    let mut shape = moment.shape().to_vec();
    shape[0] = origin.len();
    ArrayD::from_shape_vec(IxDyn(&shape), out).map_err(|e| FitError::Config(e.to_string()))
}

/// Replaces `model`'s splats with `arrays`, whose row `j` came from row `origin[j]` of the
/// old ones (`None`: a new splat), and `optimiser` with one of the same settings whose
/// moments follow the rows. Per-parameter rate scales are not kept: the rate policy sets them
/// before every step.
///
/// Errors: `origin` not one per row or naming a missing row, arrays that do not fit
/// ([`FitError::Config`]).
pub(crate) fn resize<F: Float>(
    model: &mut SplatModel<F>,
    optimiser: &mut Adam<F>,
    arrays: SplatArraysOwned<F>,
    origin: &[Option<usize>],
) -> Result<(), FitError> {
    if origin.len() != arrays.means.nrows() {
        return Err(FitError::Config(format!(
            "{} splats with {} origins",
            arrays.means.nrows(),
            origin.len()
        )));
    }
    let fresh = SplatModel::new(arrays, model.degree())?;
    let mut adam = Adam::new(optimiser.config())?;
    let (old, new) = (model.ids(), fresh.ids());
    let pairs = [
        (old.means, new.means),
        (old.log_scales, new.log_scales),
        (old.quats, new.quats),
        (old.opacity_logits, new.opacity_logits),
        (old.sh, new.sh),
    ];
    for (from, to) in pairs {
        if let Some(state) = optimiser.state(model.params(), from)? {
            let moved = AdamState {
                first_moment: gather(&state.first_moment, origin)?,
                second_moment: gather(&state.second_moment, origin)?,
                updates: state.updates,
            };
            adam.restore(fresh.params(), to, moved)?;
        }
    }
    *model = fresh;
    *optimiser = adam;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::arr2;

    #[test]
    fn moments_follow_their_rows() {
        let m = arr2(&[[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]).into_dyn();
        let g = gather::<f64>(&m, &[Some(2), None, Some(0), Some(2)]).unwrap();
        assert_eq!(g, arr2(&[[5.0, 6.0], [0.0, 0.0], [1.0, 2.0], [5.0, 6.0]]).into_dyn());
        assert!(gather::<f64>(&m, &[Some(3)]).is_err());
    }
}
