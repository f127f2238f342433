//! The framing a fit decided, as a picture: the training cameras and the inner region of a
//! contracted space seen from above (the world's x and y, looking down z), so that a user sees
//! what fogray took for the middle of the capture.

use std::path::Path;

use ndarray::Array3;

use crate::dataset::Dataset;
use crate::images::{write_png, ImageError};
use crate::space::Framing;

/// The picture's side in pixels.
const SIDE: usize = 480;
/// The length of a camera's viewing tick, as a fraction of the drawn span.
const TICK: f64 = 0.04;

impl Framing {
    /// Draws `data`'s training (blue) and held-out (orange) cameras from above, each a dot
    /// with a tick along its viewing direction, and the inner square (green) with its centre,
    /// to `path` as a PNG. The view spans the cameras and the square with a margin.
    ///
    /// Errors: a file that cannot be written.
    pub fn write_png(&self, path: &Path, data: &Dataset) -> Result<(), ImageError> {
        let cameras: Vec<([f64; 3], [f64; 3], bool)> = data
            .train
            .iter()
            .map(|v| (v, false))
            .chain(data.test.iter().map(|v| (v, true)))
            .map(|(v, held_out)| {
                let m = v.camera.camera_to_world();
                (v.camera.centre(), [m[0][2], m[1][2], m[2][2]], held_out)
            })
            .collect();
        let (c, r) = (self.centre, self.radius);
        let mut lo = [c[0] - r, c[1] - r];
        let mut hi = [c[0] + r, c[1] + r];
        for (p, _, _) in &cameras {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]) * 1.15;
        let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        let mut image = Array3::from_elem((SIDE, SIDE, 3), 1.0);
        // World x to the right, y up the picture.
        let pixel = |x: f64, y: f64| -> (f64, f64) {
            let u = ((x - mid[0]) / span + 0.5) * SIDE as f64;
            let v = (0.5 - (y - mid[1]) / span) * SIDE as f64;
            (u, v)
        };
        let dot = |u: f64, v: f64, radius: i64, colour: [f64; 3], image: &mut Array3<f64>| {
            for dv in -radius..=radius {
                for du in -radius..=radius {
                    let (x, y) = (u.round() as i64 + du, v.round() as i64 + dv);
                    if (0..SIDE as i64).contains(&x) && (0..SIDE as i64).contains(&y) {
                        for ch in 0..3 {
                            image[[y as usize, x as usize, ch]] = colour[ch];
                        }
                    }
                }
            }
        };
        let line = |a: (f64, f64), b: (f64, f64), colour: [f64; 3], image: &mut Array3<f64>| {
            let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).max(1);
            for k in 0..=n {
                let t = k as f64 / n as f64;
                dot(a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1), 0, colour, image);
            }
        };
        let green = [0.1, 0.6, 0.2];
        let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0)];
        for w in corners.windows(2) {
            let a = pixel(c[0] + w[0].0 * r, c[1] + w[0].1 * r);
            let b = pixel(c[0] + w[1].0 * r, c[1] + w[1].1 * r);
            line(a, b, green, &mut image);
        }
        let (cu, cv) = pixel(c[0], c[1]);
        line((cu - 6.0, cv), (cu + 6.0, cv), green, &mut image);
        line((cu, cv - 6.0), (cu, cv + 6.0), green, &mut image);
        for (p, forward, held_out) in &cameras {
            let colour = if *held_out { [0.9, 0.45, 0.1] } else { [0.15, 0.3, 0.8] };
            let planar = (forward[0].powi(2) + forward[1].powi(2)).sqrt().max(1e-12);
            let a = pixel(p[0], p[1]);
            let b = pixel(
                p[0] + forward[0] / planar * TICK * span,
                p[1] + forward[1] / planar * TICK * span,
            );
            line(a, b, colour, &mut image);
            dot(a.0, a.1, 2, colour, &mut image);
        }
        write_png(path, image.view())
    }
}
