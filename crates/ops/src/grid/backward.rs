//! The backward into the positions: `dL/dp_a = (du_a/dp_a) sum_c g_c sum_k (dw_k/dt_a) v_kc`,
//! with `v_kc` channel `c` of corner `k`, `dw_k/dt_a` the weight with axis `a`'s factor
//! replaced by +1 or -1, and `du_a/dp_a = (n_a - 1) / (max_a - min_a)`. One row per
//! position, in parallel over fixed chunks, summed in f64.
//!
//! The interpolant is continuous but its derivative jumps across cell faces: on a face the
//! gradient is that of the cell the position belongs to (the cell above it, or the last cell
//! on the max face). Outside the box it is zero.

use fogray_tape::Float;
use rayon::prelude::*;

use super::forward::{position, CHUNK};
use super::geometry::{weight_derivatives, Layout};

/// Writes `dL/dpositions` (`[n, D]`, flat, every value) for upstream gradients `upstream`
/// (`[n, ch]`, flat).
pub(crate) fn position_gradient<F: Float, const D: usize>(
    layout: &Layout<D>,
    grid: &[F],
    positions: &[F],
    upstream: &[F],
    ch: usize,
    out: &mut [F],
) {
    out.par_chunks_mut(CHUNK * D)
        .zip(positions.par_chunks(CHUNK * D))
        .zip(upstream.par_chunks(CHUNK * ch))
        .for_each(|((o, p), g)| {
            for (s, (o, g)) in o.chunks_exact_mut(D).zip(g.chunks_exact(ch)).enumerate() {
                o.fill(F::zero());
                if g.iter().all(|&v| v == F::zero()) {
                    continue;
                }
                let Some(cell) = layout.locate(position::<F, D>(p, s)) else {
                    continue;
                };
                // g . v_k for each corner, then each axis's derivative weights.
                let mut gv = [0.0f64; 8];
                for (gv, &corner) in gv.iter_mut().zip(&layout.corners[..1 << D]) {
                    let row = &grid[(cell.node + corner) * ch..][..ch];
                    *gv = row.iter().zip(g).map(|(&v, &g)| v.as_f64() * g.as_f64()).sum();
                }
                for (a, o) in o.iter_mut().enumerate() {
                    let dw = weight_derivatives(cell.t, a);
                    let d: f64 = dw.iter().zip(&gv).map(|(w, v)| w * v).sum();
                    *o = F::lit(d * layout.axes[a].scale);
                }
            }
        });
}
