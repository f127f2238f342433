//! Helpers: COLMAP models (binary and text) and LLFF `poses_bounds.npy` files written by hand
//! from known cameras, byte by byte as COLMAP's and NumPy's documentation lay them out.

use std::path::Path;

use fogray_data::PinholeCamera;

/// COLMAP's model ids by name (its `CameraModelId`).
pub fn model_id(name: &str) -> i32 {
    let names = [
        "SIMPLE_PINHOLE",
        "PINHOLE",
        "SIMPLE_RADIAL",
        "RADIAL",
        "OPENCV",
        "OPENCV_FISHEYE",
        "FULL_OPENCV",
    ];
    names.iter().position(|n| *n == name).expect("a model in the list") as i32
}

/// A camera as COLMAP stores it.
#[derive(Clone, Debug)]
pub struct ColmapCamera {
    pub id: i32,
    pub model: &'static str,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

/// A registered image as COLMAP stores it (world-to-camera quaternion `w x y z` and
/// translation).
#[derive(Clone, Debug)]
pub struct ColmapImage {
    pub id: i32,
    pub q: [f64; 4],
    pub t: [f64; 3],
    pub camera: i32,
    pub name: String,
}

/// A sparse point.
#[derive(Clone, Debug)]
pub struct ColmapPoint {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
}

/// The COLMAP camera of `camera` in `model`, whose parameters it must be able to hold
/// (SIMPLE_* and RADIAL need fx = fy).
pub fn colmap_camera(id: i32, model: &'static str, camera: &PinholeCamera) -> ColmapCamera {
    let k = camera.intrinsics();
    let d = camera.distortion();
    let params = match model {
        "SIMPLE_PINHOLE" => vec![k.fx, k.cx, k.cy],
        "PINHOLE" => vec![k.fx, k.fy, k.cx, k.cy],
        "SIMPLE_RADIAL" => vec![k.fx, k.cx, k.cy, d.k1],
        "RADIAL" => vec![k.fx, k.cx, k.cy, d.k1, d.k2],
        "OPENCV" => vec![k.fx, k.fy, k.cx, k.cy, d.k1, d.k2, d.p1, d.p2],
        other => panic!("no writer for {other}"),
    };
    ColmapCamera {
        id,
        model,
        width: k.width as u64,
        height: k.height as u64,
        params,
    }
}

/// The COLMAP image of `camera`: world-to-camera `R = Mᵀ` for the camera-to-world rotation
/// `M` (OpenCV axes, as COLMAP's) and `t = -R c` for the centre `c`.
pub fn colmap_image(id: i32, camera_id: i32, name: &str, camera: &PinholeCamera) -> ColmapImage {
    let m = camera.camera_to_world();
    let r: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]));
    let c = camera.centre();
    let t = std::array::from_fn(|i| -(r[i][0] * c[0] + r[i][1] * c[1] + r[i][2] * c[2]));
    ColmapImage {
        id,
        q: quaternion(r),
        t,
        camera: camera_id,
        name: name.to_string(),
    }
}

/// The unit quaternion `w x y z` of the rotation `r` (Shepperd's method: the largest of the
/// four squared components is taken from the trace, the rest from off-diagonal sums).
pub fn quaternion(r: [[f64; 3]; 3]) -> [f64; 4] {
    let trace = r[0][0] + r[1][1] + r[2][2];
    let candidates = [trace, r[0][0], r[1][1], r[2][2]];
    let largest = (0..4).max_by(|&a, &b| candidates[a].total_cmp(&candidates[b])).unwrap();
    match largest {
        0 => {
            let s = 2.0 * (1.0 + trace).sqrt();
            [
                s / 4.0,
                (r[2][1] - r[1][2]) / s,
                (r[0][2] - r[2][0]) / s,
                (r[1][0] - r[0][1]) / s,
            ]
        }
        1 => {
            let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
            [
                (r[2][1] - r[1][2]) / s,
                s / 4.0,
                (r[0][1] + r[1][0]) / s,
                (r[0][2] + r[2][0]) / s,
            ]
        }
        2 => {
            let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
            [
                (r[0][2] - r[2][0]) / s,
                (r[0][1] + r[1][0]) / s,
                s / 4.0,
                (r[1][2] + r[2][1]) / s,
            ]
        }
        _ => {
            let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
            [
                (r[1][0] - r[0][1]) / s,
                (r[0][2] + r[2][0]) / s,
                (r[1][2] + r[2][1]) / s,
                s / 4.0,
            ]
        }
    }
}

/// `cameras.bin` bytes.
pub fn cameras_bin(cameras: &[ColmapCamera]) -> Vec<u8> {
    let mut b = (cameras.len() as u64).to_le_bytes().to_vec();
    for c in cameras {
        b.extend(c.id.to_le_bytes());
        b.extend(model_id(c.model).to_le_bytes());
        b.extend(c.width.to_le_bytes());
        b.extend(c.height.to_le_bytes());
        c.params.iter().for_each(|p| b.extend(p.to_le_bytes()));
    }
    b
}

/// `images.bin` bytes; each image gets one 2-D point (skipped by the reader).
pub fn images_bin(images: &[ColmapImage]) -> Vec<u8> {
    let mut b = (images.len() as u64).to_le_bytes().to_vec();
    for i in images {
        b.extend(i.id.to_le_bytes());
        i.q.iter().chain(&i.t).for_each(|v| b.extend(v.to_le_bytes()));
        b.extend(i.camera.to_le_bytes());
        b.extend(i.name.as_bytes());
        b.push(0);
        b.extend(1u64.to_le_bytes());
        b.extend(1.5f64.to_le_bytes());
        b.extend(2.5f64.to_le_bytes());
        b.extend((-1i64).to_le_bytes());
    }
    b
}

/// `points3D.bin` bytes; each point gets a track of two elements (skipped by the reader).
pub fn points_bin(points: &[ColmapPoint]) -> Vec<u8> {
    let mut b = (points.len() as u64).to_le_bytes().to_vec();
    for p in points {
        b.extend(p.id.to_le_bytes());
        p.xyz.iter().for_each(|v| b.extend(v.to_le_bytes()));
        b.extend(p.rgb);
        b.extend(0.25f64.to_le_bytes());
        b.extend(2u64.to_le_bytes());
        for (image, point2d) in [(1i32, 0i32), (2, 0)] {
            b.extend(image.to_le_bytes());
            b.extend(point2d.to_le_bytes());
        }
    }
    b
}

/// `cameras.txt` text.
pub fn cameras_txt(cameras: &[ColmapCamera]) -> String {
    let mut s = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    for c in cameras {
        let params: Vec<String> = c.params.iter().map(|p| p.to_string()).collect();
        s += &format!("{} {} {} {} {}\n", c.id, c.model, c.width, c.height, params.join(" "));
    }
    s
}

/// `images.txt` text: each image's pose line, then its 2-D points line (one point for the
/// first image, empty for the others, as COLMAP writes images without points).
pub fn images_txt(images: &[ColmapImage]) -> String {
    let mut s = String::from("# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    for (n, i) in images.iter().enumerate() {
        let v: Vec<String> = i.q.iter().chain(&i.t).map(|v| v.to_string()).collect();
        s += &format!("{} {} {} {}\n", i.id, v.join(" "), i.camera, i.name);
        s += if n == 0 { "1.5 2.5 -1\n" } else { "\n" };
    }
    s
}

/// `points3D.txt` text.
pub fn points_txt(points: &[ColmapPoint]) -> String {
    let mut s = String::from("# 3D point list with one line of data per point:\n");
    for p in points {
        s += &format!(
            "{} {} {} {} {} {} {} 0.25 1 0 2 0\n",
            p.id, p.xyz[0], p.xyz[1], p.xyz[2], p.rgb[0], p.rgb[1], p.rgb[2]
        );
    }
    s
}

/// Writes a model in `folder` (created), binary or text.
pub fn write_model(
    folder: &Path,
    binary: bool,
    cameras: &[ColmapCamera],
    images: &[ColmapImage],
    points: &[ColmapPoint],
) {
    std::fs::create_dir_all(folder).unwrap();
    if binary {
        std::fs::write(folder.join("cameras.bin"), cameras_bin(cameras)).unwrap();
        std::fs::write(folder.join("images.bin"), images_bin(images)).unwrap();
        std::fs::write(folder.join("points3D.bin"), points_bin(points)).unwrap();
    } else {
        std::fs::write(folder.join("cameras.txt"), cameras_txt(cameras)).unwrap();
        std::fs::write(folder.join("images.txt"), images_txt(images)).unwrap();
        std::fs::write(folder.join("points3D.txt"), points_txt(points)).unwrap();
    }
}

/// An `.npy` file's bytes: version 1.0, the header `{'descr': DESCR, 'fortran_order': ORDER,
/// 'shape': SHAPE, }` padded with spaces to a multiple of 64 bytes with its newline, as
/// NumPy writes it, then `data`.
pub fn npy(descr: &str, fortran: bool, shape: &str, data: &[u8]) -> Vec<u8> {
    let order = if fortran { "True" } else { "False" };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend((header.len() as u16).to_le_bytes());
    b.extend(header.as_bytes());
    b.extend(data);
    b
}

/// The LLFF row of `camera` (square pixels, centred principal point): `[R | c | hwf]` with
/// `R`'s columns the camera's down, right and backward axes, then `near`, `far`.
pub fn llff_row(camera: &PinholeCamera, near: f64, far: f64) -> [f64; 17] {
    let m = camera.camera_to_world();
    let k = camera.intrinsics();
    let hwf = [k.height as f64, k.width as f64, k.fx];
    let mut row = [0.0; 17];
    for r in 0..3 {
        // OpenCV columns: x right, y down, z forward.
        let cols = [m[r][1], m[r][0], -m[r][2], m[r][3], hwf[r]];
        row[r * 5..r * 5 + 5].copy_from_slice(&cols);
    }
    row[15] = near;
    row[16] = far;
    row
}

/// `poses_bounds.npy` bytes for `rows`.
pub fn poses_bounds(rows: &[[f64; 17]]) -> Vec<u8> {
    let data: Vec<u8> = rows.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    npy("<f8", false, &format!("({}, 17)", rows.len()), &data)
}

#[test]
fn the_quaternion_writer_gives_back_each_rotation() {
    // The rotation of a quaternion (Hamilton, w first), written out independently of the
    // crate, for rotations whose largest component is each of the four in turn.
    let rot = |[w, x, y, z]: [f64; 4]| {
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    };
    for q in [
        [0.9, 0.1, -0.3, 0.2],
        [0.1, 0.9, 0.3, -0.2],
        [0.2, -0.1, 0.9, 0.3],
        [0.1, 0.3, -0.2, -0.9],
    ] {
        let n = q.iter().map(|v: &f64| v * v).sum::<f64>().sqrt();
        let q = q.map(|v| v / n);
        let back = rot(quaternion(rot(q)));
        let r = rot(q);
        assert!(back
            .iter()
            .flatten()
            .zip(r.iter().flatten())
            .all(|(a, b)| (a - b).abs() < 1e-14));
    }
}
