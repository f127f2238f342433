//! Input validation, flat views of the packed arrays, and the split into ray blocks that the
//! parallel loops run over.

use std::borrow::Cow;
use std::ops::Range;

use super::arrays::CompositeArrays;
use super::config::{Background, Composite};
use crate::error::{At, Op, OpsError};
use crate::prefetch::prefetch_span;
use fogray_tape::buffer::flat;
use fogray_tape::Float;

/// Rays per parallel work item: fixed, so results never depend on the thread count.
const RAYS_PER_BLOCK: usize = 64;

/// The composite's inputs as flat row-major slices, validated.
pub(crate) struct Flat<'a, F: Float> {
    pub sigma: Cow<'a, [F]>,
    pub delta: Cow<'a, [F]>,
    pub color: Cow<'a, [F]>,
    pub ch: usize,
    /// Empty (no background), `ch` values (shared) or `R * ch` (per ray).
    pub background: Cow<'a, [F]>,
    pub t: Option<Cow<'a, [F]>>,
}

impl<F: Float> Flat<'_, F> {
    /// Asks for the cache lines of `samples`' inputs at once, before the loops read them one
    /// array after another: the misses then overlap instead of following each other.
    #[inline(always)]
    pub(crate) fn request(&self, samples: Range<usize>) {
        let ch = self.ch;
        prefetch_span(&self.sigma, samples.clone());
        prefetch_span(&self.delta, samples.clone());
        prefetch_span(&self.color, samples.start * ch..samples.end * ch);
        if let Some(t) = &self.t {
            prefetch_span(t, samples);
        }
    }

    /// The background of ray `r` (empty when there is none).
    pub fn background_of(&self, r: usize) -> &[F] {
        match self.background.len() {
            0 => &[],
            n if n == self.ch => &self.background,
            _ => &self.background[r * self.ch..(r + 1) * self.ch],
        }
    }
}

fn shape_err(what: &'static str, expected: String, got: &[usize]) -> OpsError {
    OpsError::shape(Op::Composite, what, expected, format!("shape {got:?}"))
}

/// Checks shapes and values of the inputs and returns them flat.
pub(crate) fn validate<'a, F: Float>(
    op: &Composite,
    inputs: &'a CompositeArrays<'_, F>,
) -> Result<Flat<'a, F>, OpsError> {
    let flat = flatten(op, inputs)?;
    check_values(op, &flat)?;
    Ok(flat)
}

/// An optional argument `given` (or not) against the op's configuration.
pub(crate) fn mismatch(what: &'static str, given: bool) -> OpsError {
    OpsError::Mismatch {
        op: Op::Composite,
        what,
        problem: if given {
            "given, but the op is configured without it"
        } else {
            "required by the op's configuration, not given"
        },
    }
}

/// Checks the shapes only, and that the optional inputs are those the configuration needs
/// (the backward's inputs are the forward's, already checked).
pub(crate) fn flatten<'a, F: Float>(
    op: &Composite,
    inputs: &'a CompositeArrays<'_, F>,
) -> Result<Flat<'a, F>, OpsError> {
    let (n, rays) = (op.samples(), op.rays());
    for (what, x) in [("sigma", &inputs.sigma), ("delta", &inputs.delta)] {
        if x.shape() != [n] {
            return Err(shape_err(what, format!("[{n}] (the offsets end at {n})"), x.shape()));
        }
    }
    let color = &inputs.color;
    if color.ndim() != 2 || color.shape()[0] != n || color.shape()[1] == 0 {
        return Err(shape_err("color", format!("[{n}, ch] with ch >= 1"), color.shape()));
    }
    let ch = color.shape()[1];
    let background = match (op.background, &inputs.background) {
        (Background::None, None) => Cow::Borrowed(&[][..]),
        (Background::None, Some(_)) => return Err(mismatch("background", true)),
        (_, None) => return Err(mismatch("background", false)),
        (mode, Some(bg)) => {
            let want: &[usize] = if mode == Background::Shared { &[ch] } else { &[rays, ch] };
            if bg.shape() != want {
                return Err(shape_err("background", format!("{want:?}"), bg.shape()));
            }
            flat(bg)
        }
    };
    let t = match (op.depth, &inputs.t) {
        (false, None) => None,
        (false, Some(_)) => return Err(mismatch("t", true)),
        (true, None) => return Err(mismatch("t", false)),
        (true, Some(t)) => {
            if t.shape() != [n] {
                return Err(shape_err("t", format!("[{n}]"), t.shape()));
            }
            Some(flat(t))
        }
    };
    Ok(Flat {
        sigma: flat(&inputs.sigma),
        delta: flat(&inputs.delta),
        color: flat(color),
        ch,
        background,
        t,
    })
}

pub(crate) fn check_values<F: Float>(op: &Composite, f: &Flat<'_, F>) -> Result<(), OpsError> {
    let bad = |i: usize, what: String, value: F, rule: &'static str| {
        let (ray, sample) = op.offsets.locate(i).unwrap_or((0, i));
        OpsError::domain(Op::Composite, At::Sample { ray, sample }, what, value.as_f64(), rule)
    };
    let non_negative = |x: F| x.is_finite() && x >= F::zero();
    if let Some(i) = f.sigma.iter().position(|&x| !non_negative(x)) {
        return Err(bad(i, "sigma".into(), f.sigma[i], "density must be finite and >= 0"));
    }
    if let Some(i) = f.delta.iter().position(|&x| !non_negative(x)) {
        return Err(bad(i, "delta".into(), f.delta[i], "step must be finite and >= 0"));
    }
    if let Some(j) = f.color.iter().position(|x| !x.is_finite()) {
        return Err(bad(
            j / f.ch,
            format!("color[{}]", j % f.ch),
            f.color[j],
            "must be finite",
        ));
    }
    if let Some(t) = &f.t {
        if let Some(i) = t.iter().position(|x| !x.is_finite()) {
            return Err(bad(i, "t".into(), t[i], "must be finite"));
        }
    }
    check_background(f)
}

/// The background's values must be finite (checked before compositing: it is small).
pub(crate) fn check_background<F: Float>(f: &Flat<'_, F>) -> Result<(), OpsError> {
    if let Some(j) = f.background.iter().position(|x| !x.is_finite()) {
        let ray = if f.background.len() == f.ch { 0 } else { j / f.ch };
        return Err(OpsError::domain(
            Op::Composite,
            At::Ray(ray),
            format!("background[{}]", j % f.ch),
            f.background[j].as_f64(),
            "must be finite",
        ));
    }
    Ok(())
}

/// A run of consecutive rays and the samples they own.
#[derive(Debug, Clone)]
pub(crate) struct Block {
    pub rays: Range<usize>,
    pub samples: Range<usize>,
}

impl Block {
    /// The length of the block's longest ray.
    pub(crate) fn longest_ray(&self, offsets: &[usize]) -> usize {
        let ends = &offsets[self.rays.start..=self.rays.end];
        ends.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0)
    }

    /// Ray `r` (one of the block's) placed in the op and in the block.
    pub(crate) fn ray(&self, offsets: &[usize], r: usize) -> Ray {
        Ray {
            index: r,
            samples: offsets[r]..offsets[r + 1],
            local: offsets[r] - self.samples.start..offsets[r + 1] - self.samples.start,
            in_block: r - self.rays.start,
        }
    }
}

/// Where a ray sits: its index, its samples in the op and in its block, and its place among
/// its block's rays.
pub(crate) struct Ray {
    pub index: usize,
    pub samples: Range<usize>,
    pub local: Range<usize>,
    pub in_block: usize,
}

/// Cuts the rays into blocks of a fixed number of rays.
pub(crate) fn blocks(offsets: &[usize]) -> Vec<Block> {
    let rays = offsets.len() - 1;
    (0..rays)
        .step_by(RAYS_PER_BLOCK)
        .map(|r0| {
            let r1 = (r0 + RAYS_PER_BLOCK).min(rays);
            Block {
                rays: r0..r1,
                samples: offsets[r0]..offsets[r1],
            }
        })
        .collect()
}

/// Splits off the first `len` elements of `rest` (disjoint mutable pieces for parallel work).
pub(crate) fn take_front<'a, T>(rest: &mut &'a mut [T], len: usize) -> &'a mut [T] {
    let (head, tail) = std::mem::take(rest).split_at_mut(len);
    *rest = tail;
    head
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_every_ray_once() {
        let offsets: Vec<usize> = (0..=200).map(|r| r * 3).collect();
        let b = blocks(&offsets);
        assert_eq!(b.len(), 4);
        assert_eq!(b[3].rays, 192..200);
        assert_eq!(b[3].samples, 576..600);
    }
}
