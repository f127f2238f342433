//! The exact photographs of a scene from a ring of cameras: each pixel the mean of
//! [`render_ray`] over a grid of rays through its area, in parallel over pixels.
//!
//! A camera's pixel gathers the light over its area, and so do the NeRF-synthetic renders (an
//! antialiased path tracer). One ray through each pixel's centre instead gives every view's
//! silhouettes a staircase of its own, which no field can match from the views between them:
//! the same fits scored lower on every scene's held-out views, most of the error at the
//! silhouettes (the figures are in `reports/grid/dark-scenes.md`).
//!
//! ```
//! use fogray_grid::photographs::photographs;
//! use fogray_grid::ring::Ring;
//! use fogray_grid::scene::Scene;
//!
//! let ring = Ring::new(2, 1, 8)?;
//! let images = photographs(&Scene::default(), &ring)?;
//! assert_eq!(images.len(), 3);
//! assert_eq!(images[0].shape(), &[8, 8, 3]); // [row][column][channel]
//! # Ok::<(), fogray_grid::ring::RingError>(())
//! ```

use fogray::ops::PinholeCamera;
use ndarray::Array3;
use rayon::prelude::*;

use crate::exact::{render_ray, Ray};
use crate::ring::{Ring, RingError};
use crate::scene::Scene;

/// Rays a pixel's side is divided into: a pixel is the mean over `RAYS_PER_SIDE^2` rays
/// through the centres of as many equal squares of it.
pub const RAYS_PER_SIDE: usize = 4;

/// The exact RGB photograph of a validated scene from `camera`, as `[row][column][channel]`
/// (rows top to bottom), each pixel the mean over its area ([`picture`]). Values are in
/// `[0, 1]`: convex combinations of colours and background.
pub fn photograph(scene: &Scene, camera: &PinholeCamera) -> Array3<f64> {
    picture(camera, |ray| render_ray(scene, ray).color)
}

/// The picture `[row][column][channel]` whose pixels are each the mean of `shade` over the
/// camera's rays through the centres of [`RAYS_PER_SIDE`] x [`RAYS_PER_SIDE`] equal squares of
/// the pixel, in parallel over pixels.
pub fn picture(camera: &PinholeCamera, shade: impl Fn(&Ray) -> [f64; 3] + Sync) -> Array3<f64> {
    let (w, h) = (camera.intrinsics().width, camera.intrinsics().height);
    let offsets: [f64; RAYS_PER_SIDE] = std::array::from_fn(|i| (i as f64 + 0.5) / RAYS_PER_SIDE as f64);
    let rays = (RAYS_PER_SIDE * RAYS_PER_SIDE) as f64;
    let origin = camera.centre();
    let pixels: Vec<f64> = (0..w * h)
        .into_par_iter()
        .flat_map_iter(|p| {
            let (row, col) = ((p / w) as f64, (p % w) as f64);
            let mut sum = [0.0; 3];
            for dy in &offsets {
                for dx in &offsets {
                    let ray = Ray {
                        origin,
                        direction: camera.direction_at(row + dy, col + dx),
                    };
                    let c = shade(&ray);
                    (0..3).for_each(|k| sum[k] += c[k]);
                }
            }
            sum.map(|v| v / rays)
        })
        .collect();
    // w * h * 3 values were produced for that shape.
    Array3::from_shape_vec((h, w, 3), pixels).unwrap_or_else(|_| unreachable!())
}

/// The exact photographs of every view of the ring, in view order (training and test views
/// alike; [`Ring::is_test`] tells them apart).
///
/// Errors: as [`Ring::camera`].
pub fn photographs(scene: &Scene, ring: &Ring) -> Result<Vec<Array3<f64>>, RingError> {
    (0..ring.len())
        .map(|i| Ok(photograph(scene, &ring.camera(i)?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactPixel;
    use crate::scene::{Cuboid, Primitive};
    use fogray::ops::Intrinsics;

    #[test]
    fn the_default_scene_photographs_lie_in_0_1_and_show_the_scene() {
        let ring = Ring::new(4, 2, 16).unwrap();
        let scene = Scene::default();
        let images = photographs(&scene, &ring).unwrap();
        for (i, image) in images.iter().enumerate() {
            assert!(image.iter().all(|v| (0.0..=1.0).contains(v)), "view {i}");
            // The red sphere of density 40 and radius 0.45 sits at the centre of every view:
            // through its middle T <= exp(-36), so the centre pixels are its colour (or the
            // colour of what lies in front of it), far from the white background.
            let c = image.slice(ndarray::s![8, 8, ..]);
            assert!(c.iter().any(|&v| v < 0.9), "view {i}: centre {c:?}");
            // The corners are background or the floor slab; their mean is bright.
            let corner = image.slice(ndarray::s![0, 0, ..]).sum() / 3.0;
            assert!(corner > 0.5, "view {i}: corner {corner}");
        }
    }

    /// A pixel half covered by an opaque box is half the box's colour and half the background,
    /// whatever lies under its centre: the camera looks along +z from (0, 0, -3), so the plane
    /// x = 0, the box's face, projects onto the middle column's centre line of a 5-pixel-wide
    /// image (it holds the camera and its axis). Density 1000 over a depth of 2 lets through
    /// exp(-2000), nothing in f64.
    #[test]
    fn a_pixel_is_the_mean_over_its_area() {
        let scene = Scene {
            background: [0.2, 0.4, 0.6],
            primitives: vec![Primitive::Box(Cuboid {
                min: [0.0, -1.0, -1.0],
                max: [1.0, 1.0, 1.0],
                density: 1000.0,
                color: [1.0, 0.0, 0.5],
            })],
        };
        let k = Intrinsics::from_vertical_fov(5, 5, 0.5).unwrap();
        let camera = PinholeCamera::look_at(k, [0.0, 0.0, -3.0], [0.0; 3], [0.0, 1.0, 0.0]).unwrap();
        let image = photograph(&scene, &camera);
        let half = [0.6, 0.2, 0.55];
        let middle = image.slice(ndarray::s![2, 2, ..]).to_vec();
        for c in 0..3 {
            assert!((middle[c] - half[c]).abs() < 1e-15, "{middle:?}");
        }
        // One ray through the centre sees the box or the background, not both.
        let centre = Ray {
            origin: camera.centre(),
            direction: camera.direction(2, 2),
        };
        let ExactPixel { color, .. } = render_ray(&scene, &centre);
        assert!(color.iter().zip(half).any(|(a, b)| (a - b).abs() > 0.1), "{color:?}");
        // The outer columns lie wholly on one side: the box's colour on one, the background's
        // on the other.
        let (left, right) = (
            image.slice(ndarray::s![2, 0, ..]).to_vec(),
            image.slice(ndarray::s![2, 4, ..]).to_vec(),
        );
        let (box_side, open_side) = if left[1] < 0.2 { (left, right) } else { (right, left) };
        for c in 0..3 {
            assert!((box_side[c] - [1.0, 0.0, 0.5][c]).abs() < 1e-15, "{box_side:?}");
            assert!((open_side[c] - scene.background[c]).abs() < 1e-15, "{open_side:?}");
        }
    }
}
