//! What the sampling benches share: the grid example's ring of cameras and a training batch.

use fogray_ops::rays::{CameraPixel, Intrinsics, PinholeCamera};
use rand::{Rng, SeedableRng};

/// Rays per training batch.
pub const RAYS: usize = 8192;

/// 32 eyes spread over the sphere of radius 3 (a Fibonacci lattice), as the grid example's ring.
pub fn cameras() -> Vec<PinholeCamera> {
    let k = Intrinsics::from_vertical_fov(64, 64, 40f64.to_radians()).unwrap();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..32)
        .map(|i| {
            let z = 1.0 - (i as f64 + 0.5) / 16.0;
            let rho = (1.0 - z * z).sqrt();
            let turn = golden * i as f64;
            let eye = [3.0 * rho * turn.cos(), 3.0 * rho * turn.sin(), 3.0 * z];
            let up = if z.abs() > 0.9 {
                [0.0, 1.0, 0.0]
            } else {
                [0.0, 0.0, 1.0]
            };
            PinholeCamera::look_at(k, eye, [0.0; 3], up).unwrap()
        })
        .collect()
}

/// `RAYS` random (camera, pixel) picks of `cams`' 64 x 64 pixels.
pub fn picks(cams: &[PinholeCamera], seed: u64) -> Vec<CameraPixel> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..RAYS)
        .map(|_| CameraPixel {
            camera: rng.gen_range(0..cams.len()),
            pixel: rng.gen_range(0..64 * 64),
        })
        .collect()
}
