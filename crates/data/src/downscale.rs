//! Downscaling by an integer factor `K`: each `K x K` block of pixels averaged into one, and the
//! intrinsics divided to match.
//!
//! Averaging after compositing keeps the result what a camera with `K`-times larger pixels
//! would have seen against the same background. An image whose width or height is not a
//! multiple of `K` loses its partial last columns or rows (the output is
//! `floor(W / K) x floor(H / K)`): the kept pixels then cover exactly the area of the
//! downscaled intrinsics (`fx, fy, cx, cy` divided by `K`), whose pixel `(a, b)` spans the
//! original pixels `[K a, K a + K) x [K b, K b + K)`.

use fogray_ops::Intrinsics;
use ndarray::{Array2, Array3};

use crate::picture::Picture;

/// The intrinsics of the same camera with pixels `k` times larger: focal lengths and principal
/// point divided by `k`, the size divided by `k` and rounded down. `k >= 1`.
pub fn downscale_intrinsics(k: &Intrinsics, factor: usize) -> Intrinsics {
    let f = factor as f64;
    Intrinsics {
        fx: k.fx / f,
        fy: k.fy / f,
        cx: k.cx / f,
        cy: k.cy / f,
        width: k.width / factor,
        height: k.height / factor,
    }
}

/// The picture with each `factor x factor` block averaged (colour and alpha alike); the
/// partial last rows and columns are dropped. `factor >= 1`; a factor of 1 returns a copy.
pub fn downscale_picture(picture: &Picture, factor: usize) -> Picture {
    if factor == 1 {
        return picture.clone();
    }
    let (h, w, _) = picture.color.dim();
    let (oh, ow) = (h / factor, w / factor);
    let norm = 1.0 / (factor * factor) as f32;
    let color = Array3::from_shape_fn((oh, ow, 3), |(a, b, c)| {
        let mut sum = 0.0f32;
        for i in a * factor..(a + 1) * factor {
            for j in b * factor..(b + 1) * factor {
                sum += picture.color[[i, j, c]];
            }
        }
        sum * norm
    });
    let alpha = picture.alpha.as_ref().map(|alpha| {
        Array2::from_shape_fn((oh, ow), |(a, b)| {
            let mut sum = 0.0f32;
            for i in a * factor..(a + 1) * factor {
                for j in b * factor..(b + 1) * factor {
                    sum += alpha[[i, j]];
                }
            }
            sum * norm
        })
    });
    Picture { color, alpha }
}
