//! A tape reused across steps hands the buffers of one step to the ops of the next: the
//! results must be bitwise those of a fresh tape, and the pool must stay about one step large.

use fogray_tape::{Gradients, Tape, Var};
use ndarray::{Array1, Array2, ArrayD};

const RAYS: usize = 32_768;
const SAMPLES: usize = 4;
const N: usize = RAYS * SAMPLES; // 512 KiB per f32 value: every large value is pooled

struct Step {
    x: Var,
    w: Var,
    loss: Var,
}

/// Inputs that change with the step, so that a pooled buffer always holds stale numbers.
fn inputs(step: usize) -> (Array1<f32>, Array2<f32>) {
    let x = Array1::from_shape_fn(N, |i| ((i * 7 + step * 13) % 101) as f32 / 50.0);
    let w = Array2::from_shape_fn((N, 3), |(i, c)| ((i * 3 + c + step) % 17) as f32 / 8.0 - 1.0);
    (x, w)
}

/// Exercises the ops that accumulate into zeroed buffers (segment sums, the reduction of a
/// broadcast in backward), the ones that overwrite theirs (element-wise maps, reshape) and
/// a strided broadcast (`[N, 1] * [N, 3]`).
fn build(t: &mut Tape<f32>, step: usize) -> Step {
    let offsets: Vec<usize> = (0..=RAYS).map(|r| r * SAMPLES).collect();
    let (xv, wv) = inputs(step);
    let x = t.param(xv);
    let w = t.param(wv);
    let sq = t.mul(x, x).unwrap();
    let before = t.segment_exclusive_cumsum(sq, &offsets).unwrap();
    let minus = t.neg(before).unwrap();
    let e = t.exp(minus).unwrap();
    let col = t.reshape(e, &[N, 1]).unwrap();
    let wc = t.mul(col, w).unwrap();
    let per_ray = t.segment_sum(wc, &offsets).unwrap();
    let sq_ray = t.mul(per_ray, per_ray).unwrap();
    let loss = t.sum(sq_ray).unwrap();
    Step { x, w, loss }
}

fn values(t: &Tape<f32>, g: &Gradients<f32>, s: &Step) -> (Vec<f32>, ArrayD<f32>, ArrayD<f32>) {
    (
        t.value(s.loss).unwrap().iter().copied().collect(),
        g.get(s.x).unwrap().to_owned(),
        g.get(s.w).unwrap().to_owned(),
    )
}

#[test]
fn a_reused_tape_gives_bitwise_what_a_fresh_tape_gives() {
    let mut reused = Tape::<f32>::new();
    for step in 0..4 {
        reused.clear();
        let s = build(&mut reused, step);
        let g = reused.backward(s.loss).unwrap();
        let got = values(&reused, &g, &s);
        reused.recycle(g);

        let mut fresh = Tape::<f32>::new();
        let sf = build(&mut fresh, step);
        let gf = fresh.backward(sf.loss).unwrap();
        let want = values(&fresh, &gf, &sf);
        assert_eq!(got.0, want.0, "loss, step {step}");
        assert!(got.1 == want.1, "d loss/dx, step {step}");
        assert!(got.2 == want.2, "d loss/dw, step {step}");
    }
}

#[test]
fn the_next_step_draws_on_the_pool_and_the_pool_stays_one_step_large() {
    let mut t = Tape::<f32>::new();
    let mut after_clear = Vec::new();
    for step in 0..6 {
        t.clear();
        after_clear.push(t.stats().pooled_bytes);
        let s = build(&mut t, step);
        if step > 0 {
            assert!(
                t.stats().pooled_bytes < after_clear[step],
                "the forward of step {step} took no pooled buffer"
            );
        }
        let g = t.backward(s.loss).unwrap();
        t.recycle(g);
    }
    assert_eq!(after_clear[0], 0);
    // The values of one step: x, x^2, cumsum, -cumsum, exp, reshape (N each); w, w*col (3N).
    let one_step = (6 + 2 * 3) * N * 4;
    assert!(after_clear[1] >= one_step, "{after_clear:?}");
    // Steady: the same program takes the same buffers every step, and nothing piles up.
    assert_eq!(after_clear[5], after_clear[3], "{after_clear:?}");
    assert!(after_clear[5] <= 2 * after_clear[1], "{after_clear:?}");
    t.release_buffers();
    assert_eq!(t.stats().pooled_bytes, 0);
}

#[test]
fn a_tape_that_is_never_cleared_keeps_no_buffer() {
    let mut once = Tape::<f32>::new();
    let s = build(&mut once, 0);
    let g = once.backward(s.loss).unwrap();
    assert!(g.get(s.x).is_some());
    assert_eq!(
        once.stats().pooled_bytes,
        0,
        "a one-shot backward kept its spent gradients"
    );
    // Once reused, the backward keeps what it spent for the next step.
    once.clear();
    let s = build(&mut once, 1);
    let before = once.stats().pooled_bytes;
    once.backward(s.loss).unwrap();
    assert!(once.stats().pooled_bytes > before);
}
