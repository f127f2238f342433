//! A capture COLMAP can pose, made without fogray: a box on a floor, both covered in a
//! multi-scale noise texture (blobs at many sizes, which SIFT finds and matches), photographed
//! by a pinhole camera moving along an arc around it, each pixel the mean of 2x2 rays.

use std::path::Path;

/// How many photographs and their size.
pub const VIEWS: usize = 12;
const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;
/// The focal length in pixels (a horizontal field of view of about 56 degrees).
const FOCAL: f64 = 300.0;
/// The box: `[-HALF, HALF]^2 x [0, TALL]`.
const HALF: f64 = 0.6;
const TALL: f64 = 1.0;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn normalise(a: V3) -> V3 {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

/// A hash of a lattice point to `[0, 1)`.
fn lattice(ix: i64, iy: i64, seed: u64) -> f64 {
    let mut h = (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ seed.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Value noise: the lattice's values blended with a smoothstep between lattice points.
fn noise(u: f64, v: f64, seed: u64) -> f64 {
    let (fu, fv) = (u.floor(), v.floor());
    let (su, sv) = (u - fu, v - fv);
    let (wu, wv) = (su * su * (3.0 - 2.0 * su), sv * sv * (3.0 - 2.0 * sv));
    let (i, j) = (fu as i64, fv as i64);
    let top = lattice(i, j, seed) * (1.0 - wu) + lattice(i + 1, j, seed) * wu;
    let bottom = lattice(i, j + 1, seed) * (1.0 - wu) + lattice(i + 1, j + 1, seed) * wu;
    top * (1.0 - wv) + bottom * wv
}

/// The colour of a surface at `(u, v)` (world units): octaves of noise per channel.
fn texture(u: f64, v: f64, surface: u64) -> V3 {
    let mut colour = [0.0; 3];
    for (c, value) in colour.iter_mut().enumerate() {
        let mut sum = 0.0;
        for (octave, frequency) in [2.0, 5.0, 11.0].into_iter().enumerate() {
            sum += noise(
                u * frequency,
                v * frequency,
                surface * 16 + c as u64 * 4 + octave as u64,
            ) / 3.0;
        }
        // Stretch the mean-heavy sum to use the whole range.
        *value = ((sum - 0.5) * 2.5 + 0.5).clamp(0.0, 1.0);
    }
    colour
}

/// The colour seen along the ray `eye + t dir`.
fn shade(eye: V3, dir: V3) -> V3 {
    // The box by slabs: the entering face is the axis of the largest entry distance.
    let (lo, hi) = ([-HALF, -HALF, 0.0], [HALF, HALF, TALL]);
    let (mut enter, mut leave, mut axis) = (f64::NEG_INFINITY, f64::INFINITY, 0);
    for a in 0..3 {
        let (t0, t1) = ((lo[a] - eye[a]) / dir[a], (hi[a] - eye[a]) / dir[a]);
        let (near, far) = (t0.min(t1), t0.max(t1));
        if near > enter {
            enter = near;
            axis = a;
        }
        leave = leave.min(far);
    }
    let floor = if dir[2] < 0.0 { -eye[2] / dir[2] } else { f64::INFINITY };
    let (t, surface, light) = if enter <= leave && enter > 0.0 && enter < floor {
        (
            enter,
            1 + axis as u64 * 2 + u64::from(dir[axis] < 0.0),
            [0.95, 0.8, 0.65][axis],
        )
    } else if floor.is_finite() {
        (floor, 0, 1.0)
    } else {
        return [0.55, 0.7, 0.9];
    };
    let p = [eye[0] + t * dir[0], eye[1] + t * dir[1], eye[2] + t * dir[2]];
    let (u, v) = match (surface, axis) {
        (0, _) => (p[0], p[1]),
        (_, 0) => (p[1], p[2]),
        (_, 1) => (p[0], p[2]),
        _ => (p[0], p[1]),
    };
    texture(u, v, surface).map(|c| c * light)
}

/// Writes the photographs `view_00.png`... into `dir`: the camera 3.2 from the box's axis and
/// 1.8 above the floor, stepping 12 degrees along an arc, looking at the box's middle.
pub fn write_capture(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let target = [0.0, 0.0, 0.4];
    for view in 0..VIEWS {
        let angle = (view as f64 * 12.0).to_radians();
        let eye = [3.2 * angle.cos(), 3.2 * angle.sin(), 1.8];
        let forward = normalise(sub(target, eye));
        let right = normalise(cross(forward, [0.0, 0.0, 1.0]));
        let down = cross(forward, right);
        let mut image = image::RgbImage::new(WIDTH, HEIGHT);
        for (col, row, pixel) in image.enumerate_pixels_mut() {
            let mut sum = [0.0; 3];
            for (dx, dy) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                let x = (f64::from(col) + dx - f64::from(WIDTH) / 2.0) / FOCAL;
                let y = (f64::from(row) + dy - f64::from(HEIGHT) / 2.0) / FOCAL;
                let dir = normalise([0, 1, 2].map(|a| forward[a] + x * right[a] + y * down[a]));
                let colour = shade(eye, dir);
                for c in 0..3 {
                    sum[c] += colour[c] / 4.0;
                }
            }
            *pixel = image::Rgb(sum.map(|c| (c * 255.0).round() as u8));
        }
        image.save(dir.join(format!("view_{view:02}.png"))).unwrap();
    }
}
