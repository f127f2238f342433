//! The hard renderer: a ray shows the colour of the first sample whose density exceeds a
//! threshold, or the background if none does ("first hit", the limit the soft composite
//! reaches as densities grow). It has no useful derivative, so it is not a tape op.

use fogray_tape::{Float, Offsets};

use crate::error::CompositeError;

/// For each ray of the packing, the index (within the ray) of the first sample with
/// `sigma > threshold`, or `None`.
///
/// Errors if the offsets are not a valid packing of `sigma`, or a density is NaN.
pub fn first_hit<F: Float>(sigma: &[F], offsets: &[usize], threshold: F) -> Result<Vec<Option<usize>>, CompositeError> {
    let offsets = Offsets::new(offsets)?;
    if offsets.rows() != sigma.len() {
        return Err(CompositeError::Shape {
            what: "sigma",
            expected: format!("{} samples (the offsets' end)", offsets.rows()),
            got: format!("{}", sigma.len()),
        });
    }
    if let Some(i) = sigma.iter().position(|s| s.is_nan()) {
        let (ray, sample) = offsets.locate(i).unwrap_or((0, i));
        return Err(CompositeError::InvalidSample {
            ray,
            sample,
            what: "sigma".into(),
            value: f64::NAN,
            rule: "density must not be NaN",
        });
    }
    Ok(offsets
        .ranges()
        .map(|rows| sigma[rows].iter().position(|&s| s > threshold))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_sample_above_threshold_per_ray() {
        let sigma = [0.0, 2.0, 9.0, 0.5, 0.0, 7.0];
        let hits = first_hit(&sigma, &[0, 3, 3, 5, 6], 1.0).unwrap();
        assert_eq!(hits, vec![Some(1), None, None, Some(0)]);
        assert!(first_hit(&sigma, &[0, 3], 1.0).is_err());
        assert!(first_hit(&[f64::NAN], &[0, 1], 1.0).is_err());
    }
}
