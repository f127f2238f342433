//! Element-wise loops over a parameter, its gradient and per-element state, split into chunks
//! that rayon spreads over threads for large arrays. Each element is updated by itself, so the
//! result does not depend on the number of threads.

use rayon::prelude::*;

use crate::float::Float;

/// Elements per task: 16 Ki (64 KiB of `f32`) is large enough that the splitting costs
/// nothing beside the arithmetic, small enough that a grid spreads over every thread.
pub(crate) const CHUNK: usize = 1 << 14;

/// `f(x[i], g[i])` for every `i`; `x` and `g` have the same length.
pub(crate) fn zip2<F: Float>(x: &mut [F], g: &[F], f: impl Fn(&mut F, F) + Sync) {
    let run = |x: &mut [F], g: &[F]| x.iter_mut().zip(g).for_each(|(x, &g)| f(x, g));
    if x.len() <= CHUNK {
        run(x, g);
    } else {
        x.par_chunks_mut(CHUNK)
            .zip(g.par_chunks(CHUNK))
            .for_each(|(x, g)| run(x, g));
    }
}

/// `f(x[i], g[i], s[i])` for every `i`; the three have the same length.
pub(crate) fn zip3<F: Float>(x: &mut [F], g: &[F], s: &mut [F], f: impl Fn(&mut F, F, &mut F) + Sync) {
    let run = |x: &mut [F], g: &[F], s: &mut [F]| {
        x.iter_mut()
            .zip(g)
            .zip(s.iter_mut())
            .for_each(|((x, &g), s)| f(x, g, s));
    };
    if x.len() <= CHUNK {
        run(x, g, s);
    } else {
        x.par_chunks_mut(CHUNK)
            .zip(g.par_chunks(CHUNK))
            .zip(s.par_chunks_mut(CHUNK))
            .for_each(|((x, g), s)| run(x, g, s));
    }
}

/// `f(x[i], g[i], m[i], v[i])` for every `i`; the four have the same length.
pub(crate) fn zip4<F: Float>(
    x: &mut [F],
    g: &[F],
    m: &mut [F],
    v: &mut [F],
    f: impl Fn(&mut F, F, &mut F, &mut F) + Sync,
) {
    let run = |x: &mut [F], g: &[F], m: &mut [F], v: &mut [F]| {
        x.iter_mut()
            .zip(g)
            .zip(m.iter_mut().zip(v.iter_mut()))
            .for_each(|((x, &g), (m, v))| f(x, g, m, v));
    };
    if x.len() <= CHUNK {
        run(x, g, m, v);
    } else {
        x.par_chunks_mut(CHUNK)
            .zip(g.par_chunks(CHUNK))
            .zip(m.par_chunks_mut(CHUNK).zip(v.par_chunks_mut(CHUNK)))
            .for_each(|((x, g), (m, v))| run(x, g, m, v));
    }
}

/// The position of the first NaN or infinity in `g`, if any.
pub(crate) fn first_non_finite<F: Float>(g: &[F]) -> Option<usize> {
    // Whole chunks are scanned without an early exit, which vectorises; only the chunk with a
    // bad element is searched element by element. Rayon's per-element `position_first` costs
    // more than the optimiser's update it guards.
    let any_bad = |c: &[F]| c.iter().fold(false, |bad, x| bad | !x.is_finite());
    let chunk = if g.len() <= CHUNK {
        usize::from(!any_bad(g)) // 0 if bad, past the end if not
    } else {
        g.par_chunks(CHUNK).position_first(any_bad)?
    };
    let start = chunk * CHUNK;
    g.get(start..)?
        .iter()
        .take(CHUNK)
        .position(|x| !x.is_finite())
        .map(|i| start + i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunked_loops_visit_every_element_once_in_place() {
        // Three chunks and a remainder: every x[i] becomes x[i] + g[i] + s[i] exactly.
        let n = 3 * CHUNK + 17;
        let mut x: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let g: Vec<f64> = (0..n).map(|i| (2 * i) as f64).collect();
        let mut s = vec![1.0; n];
        zip3(&mut x, &g, &mut s, |x, g, s| {
            *x += g + *s;
            *s = 0.0;
        });
        assert!(x.iter().enumerate().all(|(i, &v)| v == (3 * i + 1) as f64));
        assert!(s.iter().all(|&v| v == 0.0));
        let mut m = vec![0.0; n];
        let mut v = vec![0.0; n];
        zip4(&mut x, &g, &mut m, &mut v, |_, g, m, v| {
            *m = g;
            *v = -g;
        });
        assert_eq!(m, g);
        assert!(v.iter().zip(&g).all(|(v, g)| *v == -g));
        zip2(&mut x, &g, |x, g| *x -= g);
        assert!(x.iter().enumerate().all(|(i, &v)| v == (i + 1) as f64));
    }

    #[test]
    fn the_first_non_finite_element_is_found_in_any_chunk() {
        let n = 4 * CHUNK;
        let mut g = vec![0.5f32; n];
        assert_eq!(first_non_finite(&g), None);
        g[3 * CHUNK + 5] = f32::INFINITY;
        g[2 * CHUNK + 1] = f32::NAN;
        assert_eq!(first_non_finite(&g), Some(2 * CHUNK + 1));
        assert_eq!(first_non_finite(&[1.0f64, f64::NEG_INFINITY]), Some(1));
        assert_eq!(first_non_finite(&[1.0f64, 2.0]), None);
        assert_eq!(first_non_finite::<f64>(&[]), None);
        // The first bad element of the first bad chunk, at a chunk's first and last element.
        let mut h = vec![1.0f64; 3 * CHUNK + 3];
        assert_eq!(first_non_finite(&h), None);
        h[3 * CHUNK + 2] = f64::NAN;
        assert_eq!(first_non_finite(&h), Some(3 * CHUNK + 2));
        h[CHUNK] = f64::INFINITY;
        h[2 * CHUNK - 1] = f64::NAN;
        assert_eq!(first_non_finite(&h), Some(CHUNK));
        h[CHUNK] = 0.0;
        assert_eq!(first_non_finite(&h), Some(2 * CHUNK - 1));
    }
}
