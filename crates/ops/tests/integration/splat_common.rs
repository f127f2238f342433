//! Scenes of splats for the splatting tests, and a renderer written out again here, plainly:
//! per pixel, every splat whose tile rectangle holds the pixel's tile, sorted by depth, in f64,
//! with no tile lists, no parallelism and no code of the crate but the camera.

use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::{Array1, Array2};
use rand::{Rng, SeedableRng};

/// A scene's parameters, as the fused op takes them.
#[derive(Debug, Clone)]
pub struct Scene {
    pub means: Array2<f64>,
    pub log_scales: Array2<f64>,
    pub quats: Array2<f64>,
    pub logits: Array1<f64>,
    pub colors: Array2<f64>,
}

/// A `width x height` camera 4 units from the origin, looking at it, slightly off axis.
pub fn camera(width: usize, height: usize) -> PinholeCamera {
    let f = 1.2 * width as f64;
    let k = Intrinsics {
        fx: f,
        fy: f * 1.05,
        cx: width as f64 / 2.0 + 0.3,
        cy: height as f64 / 2.0 - 0.2,
        width,
        height,
    };
    PinholeCamera::look_at(k, [0.4, -0.3, -4.0], [0.0; 3], [0.0, -1.0, 0.0]).unwrap()
}

/// `n` splats in the box `[-1, 1]^3` about the origin, of standard deviations 0.04 to 0.3,
/// random rotations, opacities sigmoid(-1.5..3) and colours in `[0, 1]`.
pub fn scene(seed: u64, n: usize) -> Scene {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    Scene {
        means: Array2::from_shape_fn((n, 3), |_| rng.gen_range(-1.0..1.0)),
        log_scales: Array2::from_shape_fn((n, 3), |_| rng.gen_range(0.04f64.ln()..0.3f64.ln())),
        quats: Array2::from_shape_fn((n, 4), |_| rng.gen_range(-1.0..1.0)),
        logits: Array1::from_shape_fn(n, |_| rng.gen_range(-1.5..3.0)),
        colors: Array2::from_shape_fn((n, 3), |_| rng.gen_range(0.0..1.0)),
    }
}

/// `a x = b` by Gaussian elimination with partial pivoting.
fn solve(mut a: [[f64; 3]; 3], mut b: [f64; 3]) -> [f64; 3] {
    for col in 0..3 {
        let p = (col..3)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap();
        a.swap(col, p);
        b.swap(col, p);
        for r in col + 1..3 {
            let f = a[r][col] / a[col][col];
            let pivot = a[col];
            for (x, p) in a[r].iter_mut().zip(pivot).skip(col) {
                *x -= f * p;
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 3];
    for r in (0..3).rev() {
        x[r] = (b[r] - (r + 1..3).map(|c| a[r][c] * x[c]).sum::<f64>()) / a[r][r];
    }
    x
}

/// A splat as the reference sees it: pixel mean, depth, conic, radius.
#[derive(Debug, Clone, Copy)]
pub struct RefSplat {
    pub mean: [f64; 2],
    pub depth: f64,
    pub conic: [f64; 3],
    pub radius: f64,
}

/// The projection of splat `i`, or `None` if culled.
pub fn ref_project(cam: &PinholeCamera, s: &Scene, i: usize) -> Option<RefSplat> {
    let m = cam.camera_to_world();
    let r = [0, 1, 2].map(|a| [0, 1, 2].map(|b| m[a][b]));
    let p = [0, 1, 2].map(|a| s.means[[i, a]] - m[a][3]);
    let pc = solve(r, p);
    let z = pc[2];
    if z < 0.01 {
        return None;
    }
    // W = R^-1, column by column.
    let wcols = [0, 1, 2].map(|c| solve(r, [0, 1, 2].map(|k| if k == c { 1.0 } else { 0.0 })));
    let w = [0, 1, 2].map(|a| [0, 1, 2].map(|b| wcols[b][a]));
    let qn = (0..4).map(|k| s.quats[[i, k]].powi(2)).sum::<f64>().sqrt();
    let [qw, qx, qy, qz] = [0, 1, 2, 3].map(|k| s.quats[[i, k]] / qn);
    let rot = [
        [
            1.0 - 2.0 * (qy * qy + qz * qz),
            2.0 * (qx * qy - qw * qz),
            2.0 * (qx * qz + qw * qy),
        ],
        [
            2.0 * (qx * qy + qw * qz),
            1.0 - 2.0 * (qx * qx + qz * qz),
            2.0 * (qy * qz - qw * qx),
        ],
        [
            2.0 * (qx * qz - qw * qy),
            2.0 * (qy * qz + qw * qx),
            1.0 - 2.0 * (qx * qx + qy * qy),
        ],
    ];
    let sc = [0, 1, 2].map(|k| s.log_scales[[i, k]].exp());
    // T = W R S, covariance in the camera frame = T T^T.
    let t = [0, 1, 2].map(|a| [0, 1, 2].map(|b| (0..3).map(|k| w[a][k] * rot[k][b]).sum::<f64>() * sc[b]));
    let v = [0, 1, 2].map(|a| [0, 1, 2].map(|b| (0..3).map(|k| t[a][k] * t[b][k]).sum::<f64>()));
    let k = cam.intrinsics();
    let (wd, ht) = (k.width as f64, k.height as f64);
    let lx = ((wd - k.cx) / k.fx + 0.15 * wd / k.fx, k.cx / k.fx + 0.15 * wd / k.fx);
    let ly = ((ht - k.cy) / k.fy + 0.15 * ht / k.fy, k.cy / k.fy + 0.15 * ht / k.fy);
    let tx = (pc[0] / z).max(-lx.1).min(lx.0);
    let ty = (pc[1] / z).max(-ly.1).min(ly.0);
    let j = [[k.fx / z, 0.0, -k.fx * tx / z], [0.0, k.fy / z, -k.fy * ty / z]];
    let c = |a: usize, b: usize| {
        (0..3)
            .map(|p| (0..3).map(|q| j[a][p] * v[p][q] * j[b][q]).sum::<f64>())
            .sum::<f64>()
    };
    let (c00, c01, c11) = (c(0, 0) + 0.3, c(0, 1), c(1, 1) + 0.3);
    let det = c00 * c11 - c01 * c01;
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    let mid = 0.5 * (c00 + c11);
    let major = mid + (mid * mid - det).max(0.1).sqrt();
    Some(RefSplat {
        mean: [k.fx * pc[0] / z + k.cx, k.fy * pc[1] / z + k.cy],
        depth: z,
        conic: [c11 / det, -c01 / det, c00 / det],
        radius: (3.0 * major.sqrt()).ceil(),
    })
}

fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        x.exp() / (1.0 + x.exp())
    }
}

/// The image `[h w][3]` of `s` over `bg`, pixel by pixel over every splat.
pub fn ref_render(cam: &PinholeCamera, s: &Scene, bg: [f64; 3]) -> Vec<[f64; 3]> {
    let k = cam.intrinsics();
    let (tw, th) = (k.width.div_ceil(16) as f64, k.height.div_ceil(16) as f64);
    let mut splats: Vec<(usize, RefSplat)> = (0..s.means.nrows())
        .filter_map(|i| ref_project(cam, s, i).map(|p| (i, p)))
        .collect();
    splats.sort_by(|a, b| a.1.depth.total_cmp(&b.1.depth).then(a.0.cmp(&b.0)));
    let mut image = Vec::with_capacity(k.pixels());
    for row in 0..k.height {
        for col in 0..k.width {
            let (tx, ty) = ((col / 16) as f64, (row / 16) as f64);
            let (px, py) = (col as f64 + 0.5, row as f64 + 0.5);
            let (mut t, mut c) = (1.0, [0.0; 3]);
            for &(i, p) in &splats {
                let x0 = ((p.mean[0] - p.radius) / 16.0).floor().clamp(0.0, tw);
                let x1 = ((p.mean[0] + p.radius) / 16.0).ceil().clamp(0.0, tw);
                let y0 = ((p.mean[1] - p.radius) / 16.0).floor().clamp(0.0, th);
                let y1 = ((p.mean[1] + p.radius) / 16.0).ceil().clamp(0.0, th);
                if !(tx >= x0 && tx < x1 && ty >= y0 && ty < y1) {
                    continue;
                }
                let (dx, dy) = (p.mean[0] - px, p.mean[1] - py);
                let power = -0.5 * (p.conic[0] * dx * dx + p.conic[2] * dy * dy) - p.conic[1] * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let alpha = (sigmoid(s.logits[i]) * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                if t * (1.0 - alpha) < 1e-4 {
                    break;
                }
                for (ch, c) in c.iter_mut().enumerate() {
                    *c += t * alpha * s.colors[[i, ch]];
                }
                t *= 1.0 - alpha;
            }
            image.push([0, 1, 2].map(|ch| c[ch] + t * bg[ch]));
        }
    }
    image
}
