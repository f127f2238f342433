//! Pictures through a lens resampled into the pinhole camera of the same intrinsics and
//! pose, for the splat op, which projects through a pinhole only: each output pixel's centre
//! is sent through the lens ([`LensDistortion::distort`]) and the picture is read there,
//! bilinearly (the colour and, where a picture has one, the alpha). A pixel whose lens point
//! falls outside the picture takes the nearest edge's value.
//!
//! [`LensDistortion::distort`]: fogray_ops::LensDistortion::distort

use fogray_ops::LensDistortion;
use ndarray::{Array2, Array3, ArrayView2};

use crate::dataset::{Dataset, View};
use crate::error::FitError;

/// `data` with every view through a lens resampled into its pinhole camera; `None` when no
/// view has a lens distortion.
///
/// Errors: a camera the pinhole cannot be made of.
pub(crate) fn undistorted(data: &Dataset) -> Result<Option<Dataset>, FitError> {
    let all = || data.train.iter().chain(&data.test);
    if all().all(|v| v.camera.distortion().is_none()) {
        return Ok(None);
    }
    let train = data.train.iter().map(undistorted_view).collect::<Result<_, _>>()?;
    let test = data.test.iter().map(undistorted_view).collect::<Result<_, _>>()?;
    Ok(Some(Dataset::new(train, test, data.background)?))
}

/// `view` resampled into the pinhole camera of its intrinsics and pose (see the
/// [module docs](self)); a view without distortion is copied.
///
/// Errors: a camera the pinhole cannot be made of.
pub(crate) fn undistorted_view(view: &View) -> Result<View, FitError> {
    let lens = *view.camera.distortion();
    let pinhole = view.camera.clone().with_distortion(LensDistortion::NONE)?;
    if lens.is_none() {
        return Ok(view.clone());
    }
    let k = *view.camera.intrinsics();
    let [h, w] = view.size();
    // Where each output pixel's centre lies in the picture through the lens, in the
    // picture's continuous pixel coordinates (centres at +0.5).
    let source: Vec<[f64; 2]> = (0..h * w)
        .map(|p| {
            let (r, c) = (p / w, p % w);
            let x = (c as f64 + 0.5 - k.cx) / k.fx;
            let y = (r as f64 + 0.5 - k.cy) / k.fy;
            let [xd, yd] = lens.distort([x, y]);
            [k.fx * xd + k.cx, k.fy * yd + k.cy]
        })
        .collect();
    let channels: Vec<Array2<f64>> = (0..3)
        .map(|c| resample(view.image.index_axis(ndarray::Axis(2), c), &source))
        .collect();
    let image = Array3::from_shape_fn((h, w, 3), |(r, col, c)| channels[c][[r, col]]);
    let mut out = View::new(view.name.clone(), &pinhole, image)?;
    out.alpha = view.alpha.as_ref().map(|a| resample(a.view(), &source));
    Ok(out)
}

/// `picture` read bilinearly at `source` (one point per pixel of a picture of its own size,
/// row-major), clamped to its edges.
fn resample(picture: ArrayView2<'_, f64>, source: &[[f64; 2]]) -> Array2<f64> {
    let (h, w) = picture.dim();
    let at = |r: isize, c: isize| picture[[r.clamp(0, h as isize - 1) as usize, c.clamp(0, w as isize - 1) as usize]];
    Array2::from_shape_fn((h, w), |(r, c)| {
        let [u, v] = source[r * w + c];
        // Continuous coordinates with pixel centres at integers.
        let (x, y) = (
            (u - 0.5).clamp(0.0, w as f64 - 1.0),
            (v - 0.5).clamp(0.0, h as f64 - 1.0),
        );
        let (c0, r0) = (x.floor() as isize, y.floor() as isize);
        let (fx, fy) = (x - c0 as f64, y - r0 as f64);
        let top = at(r0, c0) * (1.0 - fx) + at(r0, c0 + 1) * fx;
        let bottom = at(r0 + 1, c0) * (1.0 - fx) + at(r0 + 1, c0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fogray_ops::{Intrinsics, PinholeCamera};

    /// A smooth picture of the undistorted normalised point: what a pinhole would see.
    fn scene(p: [f64; 2]) -> f64 {
        0.5 + 0.4 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos()
    }

    #[test]
    fn a_lens_picture_resampled_is_the_pinhole_picture() {
        let k = Intrinsics {
            fx: 60.0,
            fy: 64.0,
            cx: 41.0,
            cy: 29.5,
            width: 80,
            height: 60,
        };
        let lens = LensDistortion {
            k1: -0.2,
            k2: 0.05,
            p1: 0.003,
            p2: -0.002,
            ..LensDistortion::NONE
        };
        let camera = PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])
            .unwrap()
            .with_distortion(lens)
            .unwrap();
        // Through the lens, pixel (r, c) shows the scene at the undistorted point of its
        // centre.
        let through_lens = Array3::from_shape_fn((60, 80, 3), |(r, c, _)| {
            let xd = (c as f64 + 0.5 - k.cx) / k.fx;
            let yd = (r as f64 + 0.5 - k.cy) / k.fy;
            scene(lens.undistort([xd, yd]).unwrap())
        });
        let view = View::new("v", &camera, through_lens).unwrap();
        let out = undistorted_view(&view).unwrap();
        assert!(out.camera.distortion().is_none());
        let mut worst = 0.0f64;
        let mut naive = 0.0f64;
        for r in 0..60 {
            for c in 0..80 {
                let x = (c as f64 + 0.5 - k.cx) / k.fx;
                let y = (r as f64 + 0.5 - k.cy) / k.fy;
                // Pixels whose lens point leaves the picture take its edge: not compared.
                let [xd, yd] = lens.distort([x, y]);
                let (u, v) = (k.fx * xd + k.cx, k.fy * yd + k.cy);
                if !(0.5..79.5).contains(&u) || !(0.5..59.5).contains(&v) {
                    continue;
                }
                worst = worst.max((out.image[[r, c, 0]] - scene([x, y])).abs());
                // The picture left as it is (a pinhole that ignored the lens).
                naive = naive.max((view.image[[r, c, 0]] - scene([x, y])).abs());
            }
        }
        // Bilinear reading of a smooth picture: second order in the pixel size.
        assert!(worst < 5e-3, "{worst}");
        assert!(naive > 0.05, "{naive}");
    }
}
