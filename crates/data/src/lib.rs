//! # fogray-data
//!
//! Real datasets for fogray: transforms files and captures (COLMAP models, LLFF poses) read
//! into [`PinholeCamera`]s and their images into `f32` arrays, so that a fit can train on the
//! scenes other NeRF tools train on, and scenes written back in the transforms formats.
//!
//! - **Blender / NeRF-synthetic** ([`Format::Blender`]): a folder with
//!   `transforms_{train,val,test}.json` (train required). `camera_angle_x` gives
//!   `fx = fy = W / (2 tan(camera_angle_x / 2))`, `cx = W / 2`, `cy = H / 2` for the images'
//!   own size `W x H`; `file_path` has `.png` appended unless it has an extension. Scene box
//!   `[-1.5, 1.5]^3`. Test split: `transforms_test.json`, else `transforms_val.json`, else
//!   every eighth train frame (`i % 8 == 0`, then held out of train).
//! - **instant-ngp / nerfstudio** ([`Format::InstantNgp`]): one `transforms.json`, intrinsics
//!   `fl_x fl_y cx cy w h` global or per frame, OpenCV distortion `k1 k2 k3 k4 p1 p2`
//!   ([`LensDistortion`]), `camera_model` `OPENCV` or `PINHOLE` (others,
//!   such as `OPENCV_FISHEYE`, are refused). Test split: every eighth frame. Scene box: the
//!   cube instant-ngp marches for the file's `aabb_scale`, `scale` and `offset`, in the file's
//!   own world coordinates: axis by axis, with `a = aabb_scale` (default 1), `scale` (default
//!   0.33) and `offset` (default 0.5 per axis),
//!   `[(0.5 - a/2 - offset_i) / scale, (0.5 + a/2 - offset_i) / scale]` (see [`ngp_scene_box`];
//!   the default gives `[-1.515 a, 1.515 a]^3`).
//!
//! - **COLMAP** ([`Format::Colmap`]): a capture folder with a sparse model in `sparse/0`,
//!   `sparse` or `colmap/sparse/0` (binary or text; cameras SIMPLE_PINHOLE, PINHOLE,
//!   SIMPLE_RADIAL, RADIAL, OPENCV, others refused by name) and its photographs in `images/`
//!   (or `images_K/` for a downscale of `K`, see [`ImageSource`]); `points3D` kept as a
//!   [`PointCloud`]. Views in image-name order, every eighth held out.
//! - **LLFF** ([`Format::Llff`]): a capture folder with `poses_bounds.npy` (`(N, 17)` float64:
//!   `[R | c | hwf]` with `R`'s columns down, right, backward, then near and far bounds,
//!   kept as [`DepthBounds`]) and `images/` (or `images_K/`), row `i` with the `i`-th picture
//!   by file name. Every eighth view held out.
//!
//! A folder is recognised by what it holds, in this order: `transforms.json`,
//! `transforms_train.json`, a COLMAP model, `poses_bounds.npy` (see [`load`]). A capture's
//! world is its reconstruction's arbitrary one: its cameras are moved into a normalised world
//! (mean up to +Z, mean centre to the origin, camera centres within `[-1, 1]^3`, as nerfstudio
//! does; see [`world`]), and the transform applied is kept ([`SceneData::world`]) so that the
//! file's points map to it and back. Scene box of a capture: `[-1, 1]^3`
//! ([`CAPTURE_SCENE_BOX`]).
//!
//! Poses in the transforms formats are OpenGL camera-to-world matrices (camera looking down
//! -Z, +Y up), COLMAP's are world-to-camera in OpenCV axes, LLFF's its own (see the format
//! docs); all are checked to be rigid (a rotation to 1e-3 and a translation). Images (8- or 16-bit
//! PNG, JPEG; grey, grey + alpha, RGB, RGBA) are decoded in parallel, composited over
//! [`LoadOptions::background`] with straight alpha, kept as stored (sRGB values), and
//! optionally downscaled by an integer factor (block means; see [`downscale_picture`]).
//!
//! Every failure is a [`DataError`] whose one-line message names the file at fault, its
//! control characters escaped ([`escape_controls`]). Every file written is written whole or
//! not at all ([`write_atomic`]), and a command checks its outputs against its inputs before
//! any work ([`check_outputs`]).
//!
//! ```
//! use fogray_data::{load, write_blender, Format, LoadOptions};
//! use fogray_ops::{Intrinsics, PinholeCamera};
//! use ndarray::Array3;
//!
//! // Two 4x4 views of the origin from distance 3, written as a Blender dataset...
//! let dir = tempfile::tempdir()?;
//! let k = Intrinsics::from_vertical_fov(4, 4, 0.8)?;
//! let cams = [
//!     PinholeCamera::look_at(k, [0.0, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0])?,
//!     PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])?,
//! ];
//! let grey = Array3::from_elem((4, 4, 3), 0.5);
//! write_blender(dir.path(), &[("a", &cams[0], &grey), ("b", &cams[1], &grey)])?;
//!
//! // ... and read back: no test file, so frame 0 is held out for testing.
//! let scene = load(dir.path(), &LoadOptions::default())?;
//! assert_eq!(scene.format, Format::Blender);
//! assert_eq!((scene.train.len(), scene.test.len()), (1, 1));
//! assert_eq!(scene.test[0].name, "a");
//! let cam = &scene.train[0].camera;
//! assert!((cam.intrinsics().fx - k.fx).abs() < 1e-9);
//! assert!((cam.centre()[0] - 3.0).abs() < 1e-12);
//! // 0.5 is stored as 128 / 255.
//! assert!((scene.train[0].picture.color[[2, 1, 0]] - 128.0 / 255.0).abs() < 1e-6);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

mod blender;
mod capture;
mod colmap;
mod downscale;
mod error;
mod escape;
mod files;
mod jpeg;
mod json;
mod llff;
mod load;
mod ngp;
mod npy;
mod output;
mod picture;
mod pictures;
mod png;
mod pose;
mod ranges;
mod resolve;
mod spec;
mod split;
pub mod world;
mod write;

pub use blender::BLENDER_SCENE_BOX;
pub use capture::{DepthBounds, FullSizeReason, ImageSource, PointCloud, CAPTURE_SCENE_BOX};
pub use downscale::{downscale_intrinsics, downscale_picture};
pub use error::{DataError, MatrixProblem};
pub use escape::{escape_controls, shown, Shown};
pub use files::{dataset_files, DatasetFiles};
pub use load::{
    load, load_cameras, load_split_cameras, load_with_progress, Format, Frame, LoadOptions, NamedCamera, SceneData,
    Split,
};
pub use ngp::{ngp_scene_box, NGP_DEFAULT_OFFSET, NGP_DEFAULT_SCALE};
pub use output::{
    check_outputs, live_temporaries, plan_fit_outputs, remove_temporaries_and_exit, resolved, write_atomic, AtomicFile,
    Inputs, Output, OutputProblem,
};
pub use picture::Picture;
pub use pictures::LoadProgress;
pub use png::{write_png8, PngChannels};
pub use split::{holdout, HOLDOUT_EVERY};
pub use world::WorldTransform;
pub use write::{write_blender, write_instant_ngp, FrameToWrite};

/// Re-exported so that users name the camera types without depending on fogray-ops.
pub use fogray_ops::{Intrinsics, LensDistortion, PinholeCamera};
