//! Output buffers for ops: zeroed vectors that the kernel may back with transparent huge
//! pages, and element-wise maps that write into them; inside a tape, all of them come from the
//! tape's pool of buffers kept from earlier steps (see [`Tape::clear`](crate::Tape::clear)).
//!
//! An op that returns a fresh array touches every page of it once; with 4 KiB pages the page
//! faults (and the kernel's page clearing) are a large share of a fast op's time. Linux
//! backs a range with 2 MiB pages where asked to, under its default `madvise` policy. A reused
//! buffer costs no fault at all. Custom ops with large outputs can use the same helpers.

use std::borrow::Cow;

use ndarray::{ArrayD, ArrayViewD, Zip};
use rayon::prelude::*;

use crate::float::Float;
use crate::pool;

/// Below this many bytes a buffer is not worth a system call.
const WORTH_ADVISING: usize = 4 << 20;

/// The elements of `x` in row-major order: borrowed when `x` is already contiguous in that
/// order (the usual case for tape values), copied otherwise.
pub fn flat<'a, F: Float>(x: &'a ArrayViewD<'_, F>) -> Cow<'a, [F]> {
    match x.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(x.iter().copied().collect()),
    }
}

/// `len` zeros: a buffer from the pool of the tape running this op, or a fresh one whose
/// pages, if it is large, are advised to be huge before anything touches them.
pub fn zeroed<F: Float>(len: usize) -> Vec<F> {
    match pool::take(len) {
        Some(mut v) => {
            v.clear();
            v.resize(len, F::zero());
            v
        }
        None => {
            let v = vec![F::zero(); len];
            advise_huge_pages(&v);
            v
        }
    }
}

/// `len` values for an op that overwrites every one of them before anyone reads it: a pooled
/// buffer keeps what an earlier step left in it (finite or not, but never uninitialised memory),
/// which saves [`zeroed`]'s pass of zeros; a fresh one is zeros.
pub fn scratch<F: Float>(len: usize) -> Vec<F> {
    match pool::take(len) {
        Some(mut v) => {
            // Shrinks without writing when it held at least `len` values.
            v.resize(len, F::zero());
            v
        }
        None => zeroed(len),
    }
}

/// `f` of every element of `x`, into a [`scratch`] buffer (pooled or fresh); a contiguous `x`
/// in one loop, in pieces on rayon's threads when large (`f` is shared by them, hence `Sync`).
pub fn map1<F: Float>(x: &ArrayViewD<'_, F>, f: impl Fn(F) -> F + Sync) -> ArrayD<F> {
    if let Some(xs) = x.as_slice() {
        let mut out = scratch(xs.len());
        pieces(&mut out, PIECE, |start, out| {
            for (o, &v) in out.iter_mut().zip(&xs[start..]) {
                *o = f(v);
            }
        });
        if let Ok(y) = ArrayD::from_shape_vec(x.raw_dim(), out) {
            return y;
        }
    }
    match overwritten(x.raw_dim()) {
        Some(mut out) => {
            Zip::from(&mut out).and(x).for_each(|o, &v| *o = f(v));
            out
        }
        None => x.mapv(f),
    }
}

/// `f` element by element over two views of one shape, into a [`scratch`] buffer: loops over
/// flat memory when both are contiguous or one is a column, scalar or row broadcast of a
/// contiguous array and the other contiguous (in pieces on rayon's threads when large),
/// otherwise `Zip` (2-D views with static dimensions, which give `Zip` a fast inner loop;
/// `IxDyn` indexes every element). `f` is shared by the threads, hence `Sync`.
pub fn map2<F: Float>(a: &ArrayViewD<'_, F>, b: &ArrayViewD<'_, F>, f: impl Fn(F, F) -> F + Sync) -> ArrayD<F> {
    if a.shape() == b.shape() {
        if let Some(out) = map2_flat(a, b, &f) {
            if let Ok(z) = ArrayD::from_shape_vec(a.raw_dim(), out) {
                return z;
            }
        }
    }
    if let (Ok(x), Ok(y)) = (
        a.view().into_dimensionality::<ndarray::Ix2>(),
        b.view().into_dimensionality::<ndarray::Ix2>(),
    ) {
        if let Some(mut out) = overwritten(x.raw_dim()) {
            Zip::from(&mut out).and(&x).and(&y).for_each(|o, &x, &y| *o = f(x, y));
            return out.into_dyn();
        }
    }
    match overwritten(a.raw_dim()) {
        Some(mut out) => {
            Zip::from(&mut out).and(a).and(b).for_each(|o, &x, &y| *o = f(x, y));
            out
        }
        None => Zip::from(a).and(b).map_collect(|&x, &y| f(x, y)),
    }
}

/// Element-wise maps of at least this many elements are cut into pieces run on rayon's
/// threads; below it, handing work over costs more than it saves.
const PARALLEL: usize = 1 << 15;

/// Elements per piece (about 64 KiB of f32 output): many pieces per thread, for balance.
pub(crate) const PIECE: usize = 1 << 14;

/// Runs `body(start, out[start..start + piece])` over `out` cut into pieces of `piece`
/// elements (the last one shorter), on rayon's threads when `out` is large; each element is
/// written by one call, so the values do not depend on the threads.
pub(crate) fn pieces<F: Float>(out: &mut [F], piece: usize, body: impl Fn(usize, &mut [F]) + Sync) {
    if out.len() < PARALLEL {
        body(0, out);
        return;
    }
    out.par_chunks_mut(piece)
        .enumerate()
        .for_each(|(k, out)| body(k * piece, out));
}

/// How a view reads row-major memory, element `i` (row-major) of it being:
enum Flat<'a, F> {
    /// `values[i]`: a contiguous array.
    Each(&'a [F]),
    /// `values[i / inner]`: an array broadcast along its trailing axes (a column `[n, 1]` or a
    /// scalar stretched over `[n, c]`).
    Repeat(&'a [F], usize),
    /// `values[i % values.len()]`: an array broadcast along its leading axes (a row `[c]`
    /// stretched over `[n, c]`).
    Tile(&'a [F]),
}

impl<'a, F> Flat<'a, F> {
    /// `v`'s pattern, if it is one of the three; `None` for other layouts and empty views.
    fn of(v: &ArrayViewD<'a, F>) -> Option<Self> {
        if let Some(values) = v.to_slice() {
            return Some(Flat::Each(values));
        }
        if v.is_empty() {
            return None;
        }
        // Axes that read nothing new: stride 0 (broadcast) or length 1.
        let idle = |k: usize| v.strides()[k] == 0 || v.shape()[k] == 1;
        let n = v.ndim();
        let trailing = (0..n).rev().take_while(|&k| idle(k)).count();
        if trailing > 0 {
            let mut base = v.clone();
            for k in (n - trailing..n).rev() {
                base = base.index_axis_move(ndarray::Axis(k), 0);
            }
            if let Some(values) = base.to_slice() {
                return Some(Flat::Repeat(values, v.shape()[n - trailing..].iter().product()));
            }
        }
        let leading = (0..n).take_while(|&k| idle(k)).count();
        if leading > 0 {
            let mut base = v.clone();
            for _ in 0..leading {
                base = base.index_axis_move(ndarray::Axis(0), 0);
            }
            return base.to_slice().map(Flat::Tile);
        }
        None
    }
}

/// `f` over two views of one shape as loops over flat memory, when each is contiguous or one
/// of them is a [`Flat`] broadcast of a contiguous array and the other contiguous (the common
/// cases, which `Zip` walks index by index); `None` otherwise. A broadcast first operand is
/// handled as a broadcast second one with the arguments of `f` swapped back.
fn map2_flat<F: Float>(
    a: &ArrayViewD<'_, F>,
    b: &ArrayViewD<'_, F>,
    f: &(impl Fn(F, F) -> F + Sync),
) -> Option<Vec<F>> {
    let (x, y) = (Flat::of(a)?, Flat::of(b)?);
    if !matches!((&x, &y), (Flat::Each(_), _) | (_, Flat::Each(_))) {
        return None;
    }
    let mut out = scratch(a.len());
    let flipped = |y: F, x: F| f(x, y);
    match (x, y) {
        (Flat::Each(xs), Flat::Each(ys)) => pieces(&mut out, PIECE, |start, out| {
            for ((o, &x), &y) in out.iter_mut().zip(&xs[start..]).zip(&ys[start..]) {
                *o = f(x, y);
            }
        }),
        (Flat::Each(xs), Flat::Repeat(ys, inner)) => with_repeated(&mut out, xs, ys, inner, f),
        (Flat::Repeat(xs, inner), Flat::Each(ys)) => with_repeated(&mut out, ys, xs, inner, &flipped),
        (Flat::Each(xs), Flat::Tile(ys)) => with_tiled(&mut out, xs, ys, f),
        (Flat::Tile(xs), Flat::Each(ys)) => with_tiled(&mut out, ys, xs, &flipped),
        // Two broadcasts: excluded above.
        _ => return None,
    }
    Some(out)
}

/// Elements per piece of whole runs (or tiles, or table rows) of `run` elements, so that each
/// piece starts at a run's first element.
pub(crate) fn whole_runs(run: usize) -> usize {
    (PIECE / run).max(1) * run
}

/// `out[i] = f(xs[i], ys[i / inner])`.
fn with_repeated<F: Float>(out: &mut [F], xs: &[F], ys: &[F], inner: usize, f: &(impl Fn(F, F) -> F + Sync)) {
    pieces(out, whole_runs(inner), |start, out| {
        let runs = out.chunks_exact_mut(inner).zip(xs[start..].chunks_exact(inner));
        for ((o, x), &y) in runs.zip(&ys[start / inner..]) {
            for (o, &x) in o.iter_mut().zip(x) {
                *o = f(x, y);
            }
        }
    });
}

/// `out[i] = f(xs[i], ys[i % ys.len()])`.
fn with_tiled<F: Float>(out: &mut [F], xs: &[F], ys: &[F], f: &(impl Fn(F, F) -> F + Sync)) {
    pieces(out, whole_runs(ys.len()), |start, out| {
        for (o, x) in out.chunks_exact_mut(ys.len()).zip(xs[start..].chunks_exact(ys.len())) {
            for ((o, &x), &y) in o.iter_mut().zip(x).zip(ys) {
                *o = f(x, y);
            }
        }
    });
}

/// An array of `dim` in standard layout over a [`scratch`] buffer, for a caller that writes
/// every element (`None` only if `dim` overflows, which no view's shape does).
fn overwritten<F: Float, D: ndarray::Dimension>(dim: D) -> Option<ndarray::Array<F, D>> {
    let len = dim.size_checked()?;
    ndarray::Array::from_shape_vec(dim, scratch(len)).ok()
}

/// `f` element by element over three views of one shape (see [`map2`]).
pub fn map3<F: Float>(
    a: &ArrayViewD<'_, F>,
    b: &ArrayViewD<'_, F>,
    c: &ArrayViewD<'_, F>,
    f: impl Fn(F, F, F) -> F + Sync,
) -> ArrayD<F> {
    if let (Some(xs), Some(ys), Some(zs)) = (a.as_slice(), b.as_slice(), c.as_slice()) {
        if a.shape() == b.shape() && a.shape() == c.shape() {
            let mut out = scratch(xs.len());
            pieces(&mut out, PIECE, |start, out| {
                let inputs = xs[start..].iter().zip(&ys[start..]).zip(&zs[start..]);
                for (o, ((&x, &y), &z)) in out.iter_mut().zip(inputs) {
                    *o = f(x, y, z);
                }
            });
            if let Ok(w) = ArrayD::from_shape_vec(a.raw_dim(), out) {
                return w;
            }
        }
    }
    match overwritten(a.raw_dim()) {
        Some(mut out) => {
            Zip::from(&mut out)
                .and(a)
                .and(b)
                .and(c)
                .for_each(|o, &x, &y, &z| *o = f(x, y, z));
            out
        }
        None => Zip::from(a).and(b).and(c).map_collect(|&x, &y, &z| f(x, y, z)),
    }
}

#[cfg(target_os = "linux")]
fn advise_huge_pages<T>(v: &Vec<T>) {
    const HUGE: usize = 2 << 20;
    let bytes = v.capacity() * std::mem::size_of::<T>();
    if bytes < WORTH_ADVISING {
        return;
    }
    let start = v.as_ptr() as usize;
    let (lo, hi) = (start.next_multiple_of(HUGE), (start + bytes) / HUGE * HUGE);
    if hi > lo {
        // SAFETY: [lo, hi) lies inside the live allocation behind `v` (its capacity), which
        // we own.
        // MADV_HUGEPAGE is advice: it changes neither the contents nor the validity of any
        // byte, and a refusal (huge pages disabled) leaves everything as it was, so the
        // result is ignored.
        unsafe {
            libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages<T>(_: &Vec<T>) {}

#[cfg(test)]
mod tests {
    use super::*;

    use ndarray::{arr2, ArrayD, Dimension, IxDyn, ShapeBuilder};

    #[test]
    fn maps_agree_with_ndarray_for_contiguous_broadcast_and_strided_views() {
        let a = arr2(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]).into_dyn();
        let b = arr2(&[[0.5, 0.25, 2.0], [1.0, -1.0, 0.0]]).into_dyn();
        let want = &a * &b;
        assert_eq!(map2(&a.view(), &b.view(), |x, y| x * y), want);
        // A transposed (strided) pair and a broadcast column take the Zip paths.
        let (at, bt) = (a.t(), b.t());
        assert_eq!(map2(&at, &bt, |x, y| x * y), want.t());
        let col = ArrayD::from_shape_vec(IxDyn(&[2, 1]), vec![10.0, 100.0]).unwrap();
        let col = col.broadcast(IxDyn(&[2, 3])).unwrap();
        assert_eq!(map2(&a.view(), &col, |x, y| x + y), &a + &col);
        assert_eq!(map1(&a.view(), |x| -x), -&a);
        assert_eq!(map1(&at, |x| -x), -&a.t());
        assert_eq!(map3(&a.view(), &b.view(), &a.view(), |x, y, z| x * y + z), &a * &b + &a);
        assert_eq!(map3(&at, &bt, &at, |x, y, z| x * y + z), (&a * &b + &a).t());
    }

    #[test]
    fn large_maps_cut_into_pieces_match_zip_on_any_number_of_threads() {
        // Past the parallel threshold, with lengths that are not multiples of a piece, runs
        // (a column of 3) and tiles (a row of 7) that do not divide it either.
        let n = 3 * PARALLEL + 1234;
        let full = ArrayD::from_shape_fn(IxDyn(&[n, 3, 7]), |ix| (ix[0] * 21 + ix[1] * 7 + ix[2]) as f64);
        let column = ArrayD::from_shape_fn(IxDyn(&[n, 1, 1]), |ix| 0.5 * ix[0] as f64);
        let row = ArrayD::from_shape_fn(IxDyn(&[3, 7]), |ix| (ix[0] * 7 + ix[1]) as f64 + 0.25);
        let f = |x: f64, y: f64| x - 2.0 * y;
        let g = |x: f64, y: f64, z: f64| x * 0.5 - y + z;
        let shape = IxDyn(&[n, 3, 7]);
        let (col, row) = (column.broadcast(shape.clone()).unwrap(), row.broadcast(shape).unwrap());
        let want = [
            Zip::from(&full).and(&col).map_collect(|&x, &y| f(x, y)),
            Zip::from(&col).and(&full).map_collect(|&x, &y| f(x, y)),
            Zip::from(&full).and(&row).map_collect(|&x, &y| f(x, y)),
            Zip::from(&row).and(&full).map_collect(|&x, &y| f(x, y)),
            Zip::from(&full).and(&full).map_collect(|&x, &y| f(x, y)),
        ];
        let want1 = full.mapv(|x| -x);
        let want3 = Zip::from(&full)
            .and(&full)
            .and(&full)
            .map_collect(|&x, &y, &z| g(x, y, z));
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let got = [
                    map2(&full.view(), &col, f),
                    map2(&col, &full.view(), f),
                    map2(&full.view(), &row, f),
                    map2(&row, &full.view(), f),
                    map2(&full.view(), &full.view(), f),
                ];
                for (k, (got, want)) in got.iter().zip(&want).enumerate() {
                    assert_eq!(got, want, "case {k} on {threads} threads");
                }
                assert_eq!(map1(&full.view(), |x| -x), want1);
                assert_eq!(map3(&full.view(), &full.view(), &full.view(), g), want3);
            });
        }
    }

    proptest::proptest! {
        // map2 against ndarray's Zip for an operand of the full shape (row- or column-major)
        // against another that is the same, a broadcast of its trailing axes (a column, a
        // scalar), of its leading axes (a row), or the full array reversed along every axis:
        // every flat loop and the general paths, both argument orders, with a function that
        // tells them apart.
        #[test]
        fn map2_matches_zip_for_every_broadcast_pattern(
            shape in proptest::collection::vec(0usize..4, 1..4),
            kind in 0usize..6,
            split_pick in 0usize..4,
        ) {
            let split = split_pick % (shape.len() + 1);
            let full = ArrayD::from_shape_fn(IxDyn(&shape), |ix| {
                (0..ix.ndim()).fold(1.0, |acc, k| acc * 3.0 + ix[k] as f64)
            });
            let mut column_major = ArrayD::<f64>::zeros(IxDyn(&shape).f());
            column_major.assign(&full);
            // The operand before broadcasting: axes from `split` on (trailing) or before it
            // (leading) set to 1.
            let partial = |trailing: bool| {
                let s: Vec<usize> = shape.iter().enumerate()
                    .map(|(k, &d)| if (k >= split) == trailing { 1 } else { d }).collect();
                ArrayD::from_shape_fn(IxDyn(&s), |ix| 0.5 + (0..ix.ndim()).fold(0.0, |acc, k| acc * 2.0 + ix[k] as f64))
            };
            let other = match kind {
                0 => full.mapv(|v| v * 0.25),
                1 => column_major.clone(),
                2 => partial(true),
                3 => partial(false),
                4 => ArrayD::from_elem(IxDyn(&[]), 7.0),
                _ => full.slice_each_axis(|_| ndarray::Slice::new(0, None, -1)).to_owned(),
            };
            let f = |x: f64, y: f64| x - 2.0 * y;
            let b = other.broadcast(IxDyn(&shape)).unwrap();
            for a in [full.view(), column_major.view()] {
                let want = Zip::from(&a).and(&b).map_collect(|&x, &y| f(x, y));
                proptest::prop_assert_eq!(&map2(&a, &b, f), &want);
                let want = Zip::from(&b).and(&a).map_collect(|&x, &y| f(x, y));
                proptest::prop_assert_eq!(&map2(&b, &a, f), &want);
            }
        }
    }

    #[test]
    fn buffers_are_zero_whatever_their_size() {
        for len in [0, 1, 1000, (WORTH_ADVISING / 4) + 12345, 3 << 20] {
            let v = zeroed::<f32>(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0));
        }
        assert!(zeroed::<f64>(1 << 20).iter().all(|&x| x == 0.0));
    }

    #[test]
    fn pooled_buffers_have_the_asked_length_and_zeroed_ones_are_zero() {
        use crate::pool::{install, Home};
        let big = crate::pool::WORTH_POOLING; // elements: above the threshold for f32
        let home: Home<f32> = std::cell::RefCell::new(Some(Box::default()));
        let _on = install(&home);
        for len in [big, big + 1000, big - 1000] {
            crate::pool::give(vec![7.0f32; big]);
            let v = zeroed::<f32>(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0), "stale values left in a zeroed buffer");
            crate::pool::give(v);
            let w = scratch::<f32>(len);
            assert_eq!(w.len(), len);
            crate::pool::give(w);
        }
    }
}
