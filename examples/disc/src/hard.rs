//! The hard renderer of lesson 7: a pixel shows the disc's colour iff its ray meets the disc
//! in front of the camera, by fogray's exact hit test [`fogray::ops::hard::ray_meets_ball`].

use fogray::ops::hard::ray_meets_ball;

use crate::scene::{Ray, Scene};

/// Whether `ray` meets the closed disc of `radius` centred at `(cx, 0)` in front of its origin.
///
/// Tangent rays count as hits, however their terms round (see [`ray_meets_ball`]): rays that
/// are tangent in exact arithmetic (two pairs are, at x = +-1.325 with the default scene) are
/// all hits, so ties are treated consistently.
pub fn hits(ray: &Ray, cx: f64, radius: f64) -> bool {
    ray_meets_ball(ray.origin, ray.dir, [cx, 0.0], radius)
}

/// The textbook test, `|w|^2 - (w.d)^2 <= radius^2`, with no care for ties: used only to show
/// how rounding splits the exact tangencies (it is how the lesson's count of 59 arises).
pub fn hits_plain(ray: &Ray, cx: f64, radius: f64) -> bool {
    let w = [cx - ray.origin[0], -ray.origin[1]];
    let along = w[0] * ray.dir[0] + w[1] * ray.dir[1];
    (w[0] * w[0] + w[1] * w[1]) - along * along <= radius * radius && along > 0.0
}

/// Pixel colours `[rays][ch]` of the disc at `(cx, 0)`.
pub fn render(scene: &Scene, rays: &[Ray], cx: f64, hit: fn(&Ray, f64, f64) -> bool) -> Vec<f64> {
    rays.iter()
        .flat_map(|r| {
            if hit(r, cx, scene.radius) {
                scene.disc_color.clone()
            } else {
                scene.background.clone()
            }
        })
        .collect()
}

/// Mean squared difference over pixels and channels.
pub fn loss(image: &[f64], photo: &[f64]) -> f64 {
    image.iter().zip(photo).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / image.len() as f64
}

/// Number of pixels whose hit/miss differs from the photograph's: the loss is this count
/// times `|disc - background|^2 / (pixels * channels)`, so distinct losses are distinct counts.
pub fn mismatches(rays: &[Ray], cx: f64, radius: f64, truth: &[bool], hit: fn(&Ray, f64, f64) -> bool) -> usize {
    rays.iter().zip(truth).filter(|(r, &t)| hit(r, cx, radius) != t).count()
}
