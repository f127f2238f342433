//! Checks of a batch of packed rays on the host, before anything is uploaded (no device needed).

use crate::error::CudaError;

/// The number of colour channels the kernels composite.
pub const CHANNELS: usize = 3;

/// Samples per residual chunk: the forward keeps the exact optical depth before every
/// `CHUNK`-th sample of a ray (the kernel source's `CHUNK`; see `kernels/composite.cu`).
pub(crate) const CHUNK: usize = 8;

/// Rays per warp: the kernels' smallest block, and the rays of one partial sum of the
/// background gradient.
pub(crate) const WARP: usize = 32;

/// The most samples the rays of one warp (32 consecutive rays) may hold: the kernels index a
/// warp's colours (three values a sample) with 32-bit offsets from its first sample.
pub(crate) const WARP_SAMPLES: usize = (u32::MAX / 3) as usize;

/// The residual's length for `rays` rays over `samples` samples: ray `r` starting at sample
/// `s` keeps its chunk depths from index `s / CHUNK + r`, and has at most `len / CHUNK + 1`
/// chunks.
pub(crate) fn residual_len(rays: usize, samples: usize) -> usize {
    samples / CHUNK + rays + 1
}

/// Checks that `offsets` packs `samples` samples into rays (starts at 0, never decreases, ends
/// at `samples`) and that the per-sample and per-ray arrays have the lengths that packing
/// needs; returns the number of rays.
///
/// ```
/// use fogray_cuda::check_packing;
/// assert_eq!(check_packing(&[0, 2, 2, 5], 5, 15, 3).unwrap(), 3);
/// assert!(check_packing(&[0, 3, 2], 3, 9, 3).is_err());
/// ```
pub fn check_packing(
    offsets: &[usize],
    sigma_and_delta: usize,
    color: usize,
    background: usize,
) -> Result<usize, CudaError> {
    let Some((&first, _)) = offsets.split_first() else {
        return Err(CudaError::Offsets("empty: there must be at least the leading 0".into()));
    };
    if first != 0 {
        return Err(CudaError::Offsets(format!("must start at 0, starts at {first}")));
    }
    if let Some(r) = offsets.windows(2).position(|w| w[1] < w[0]) {
        return Err(CudaError::Offsets(format!(
            "ray {r} ends at {} before it starts at {}",
            offsets[r + 1],
            offsets[r]
        )));
    }
    let rays = offsets.len() - 1;
    let n = offsets[rays];
    if n != sigma_and_delta {
        return Err(CudaError::Shape {
            what: "sigma/delta (offsets end at the sample count)",
            expected: n,
            got: sigma_and_delta,
        });
    }
    if color != n * CHANNELS {
        return Err(CudaError::Shape {
            what: "color ([n, 3])",
            expected: n * CHANNELS,
            got: color,
        });
    }
    if background != CHANNELS {
        return Err(CudaError::Shape {
            what: "background ([3])",
            expected: CHANNELS,
            got: background,
        });
    }
    // Every block index of a launch must fit the grid's 2^31 - 1 blocks, at the smallest block.
    if rays.div_ceil(WARP) > i32::MAX as usize {
        return Err(CudaError::TooLarge(format!(
            "{rays} rays is more than one launch covers"
        )));
    }
    // Every warp's samples must be reachable with the kernels' 32-bit offsets.
    for w in (0..rays).step_by(WARP) {
        let held = offsets[(w + WARP).min(rays)] - offsets[w];
        if held > WARP_SAMPLES {
            return Err(CudaError::TooLarge(format!(
                "rays {w}..{} hold {held} samples; 32 consecutive rays may hold at most {WARP_SAMPLES}",
                (w + WARP).min(rays)
            )));
        }
    }
    Ok(rays)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packings_are_checked() {
        assert_eq!(check_packing(&[0], 0, 0, 3).unwrap(), 0);
        assert_eq!(check_packing(&[0, 0, 4], 4, 12, 3).unwrap(), 2);
        assert!(matches!(check_packing(&[], 0, 0, 3), Err(CudaError::Offsets(_))));
        assert!(matches!(check_packing(&[1, 2], 2, 6, 3), Err(CudaError::Offsets(_))));
        assert!(matches!(check_packing(&[0, 4, 3], 3, 9, 3), Err(CudaError::Offsets(_))));
        assert!(matches!(check_packing(&[0, 4], 5, 15, 3), Err(CudaError::Shape { .. })));
        assert!(matches!(check_packing(&[0, 4], 4, 8, 3), Err(CudaError::Shape { .. })));
        assert!(matches!(check_packing(&[0, 4], 4, 12, 1), Err(CudaError::Shape { .. })));
    }

    #[test]
    fn a_warp_may_hold_what_32_bit_offsets_reach() {
        // Lengths only: nothing of this size is allocated.
        let n = WARP_SAMPLES;
        assert_eq!(check_packing(&[0, n], n, 3 * n, 3).unwrap(), 1);
        assert!(matches!(
            check_packing(&[0, n + 1], n + 1, 3 * (n + 1), 3),
            Err(CudaError::TooLarge(_))
        ));
        // The same samples over rays in two warps fit: each warp holds half.
        let mut offsets: Vec<usize> = (0..=32).map(|r| r * (n / 32)).collect();
        offsets.push(offsets[32] + n / 2 + 1);
        let total = offsets[33];
        assert_eq!(check_packing(&offsets, total, 3 * total, 3).unwrap(), 33);
    }

    #[test]
    fn every_ray_has_room_for_its_chunks() {
        // Ray r's chunks [s/CHUNK + r, s/CHUNK + r + ceil(len/CHUNK)) never overlap the next
        // ray's and end inside the buffer.
        let lens = [0usize, 1, 7, 8, 9, 15, 16, 17, 0, 3, 64, 1, 0];
        let mut offsets = vec![0];
        for l in lens {
            offsets.push(offsets.last().unwrap() + l);
        }
        let n = *offsets.last().unwrap();
        let mut end = 0;
        for r in 0..lens.len() {
            let base = offsets[r] / CHUNK + r;
            assert!(base >= end, "ray {r}");
            end = base + lens[r].div_ceil(CHUNK);
        }
        assert!(end <= residual_len(lens.len(), n));
    }
}
