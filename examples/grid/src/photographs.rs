//! The exact photographs of a scene from a ring of cameras, one [`render_ray`] per pixel,
//! in parallel over pixels.
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

/// The exact RGB photograph of a validated scene from `camera`, as `[row][column][channel]`
/// (rows top to bottom). Values are in `[0, 1]`: convex combinations of colours and
/// background.
pub fn photograph(scene: &Scene, camera: &PinholeCamera) -> Array3<f64> {
    picture(camera, |ray| render_ray(scene, ray).color)
}

/// The picture `[row][column][channel]` whose pixels are `shade` of the camera's ray through
/// each, in parallel over pixels.
pub fn picture(camera: &PinholeCamera, shade: impl Fn(&Ray) -> [f64; 3] + Sync) -> Array3<f64> {
    let (w, h) = (camera.intrinsics().width, camera.intrinsics().height);
    let pixels: Vec<f64> = (0..w * h)
        .into_par_iter()
        .flat_map_iter(|p| {
            let ray = Ray {
                origin: camera.centre(),
                direction: camera.direction(p / w, p % w),
            };
            shade(&ray)
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
        // Pixel (row, column) is render_ray of that pixel's ray.
        let ray = ring.rays(3).unwrap()[5 * 16 + 11];
        let ExactPixel { color, .. } = render_ray(&scene, &ray);
        assert_eq!(images[3].slice(ndarray::s![5, 11, ..]).to_vec(), color.to_vec());
    }
}
