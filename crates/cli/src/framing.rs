//! The orbit `fogray render --orbit` flies: its flags checked, and what they leave open taken
//! from the model's dataset, so that an orbit looks like the views the model was fitted on.
//!
//! The checkpoint names its dataset (`data`, as `fogray fit` was given it: a relative path is
//! read from the working directory) and its `downscale`. Where that dataset's transforms can
//! be read (no image is decoded), its first camera gives the image size and the vertical field
//! of view, and its cameras' mean distance from the centre of the scene box gives the radius.
//! Otherwise: 200x200 pixels, 40 degrees, and the radius at which the sphere around the scene
//! box just fits in the narrower field of view.

use std::path::Path;
use std::str::FromStr;

use fogray_data::load_cameras;
use fogray_fit::checkpoint::ModelInfo;
use fogray_ops::{Intrinsics, Orbit, PinholeCamera};

use crate::error::CliError;
use crate::render::RenderArgs;

/// Image size without a flag or a readable dataset.
pub const FALLBACK_SIZE: ImageSize = ImageSize {
    width: 200,
    height: 200,
};

/// Vertical field of view (degrees) without a flag or a readable dataset: about that of the
/// NeRF-synthetic scenes (39.6 degrees).
pub const FALLBACK_FOV_DEGREES: f64 = 40.0;

/// The orbit's elevation (degrees) without a flag: high enough to see the top of an object
/// standing on the horizontal plane and its sides.
pub const DEFAULT_ELEVATION_DEGREES: f64 = 30.0;

/// An image size, `WxH` on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageSize {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl FromStr for ImageSize {
    type Err = String;

    /// `WxH`, two whole numbers (0 is parsed, and refused with the other flags' values).
    fn from_str(text: &str) -> Result<Self, String> {
        let parse = |s: &str| s.trim().parse::<usize>().map_err(|e| format!("{s:?}: {e}"));
        match text.split_once(['x', 'X']) {
            Some((w, h)) => Ok(ImageSize {
                width: parse(w)?,
                height: parse(h)?,
            }),
            None => Err(format!("{text:?} is not WxH (such as 200x200)")),
        }
    }
}

/// What the model's dataset says about its views: their size, field of view and distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DatasetViews {
    /// The first camera's image size.
    pub size: ImageSize,
    /// The first camera's vertical field of view, radians.
    pub fov_y: f64,
    /// The cameras' mean distance from the scene box's centre.
    pub radius: f64,
}

/// The views of the dataset the model at `model` was fitted on, `None` where its checkpoint
/// names none or it cannot be read (the reason then goes to stderr: the defaults are another
/// framing, which the user should know).
pub fn dataset_views(model: &Path, info: &ModelInfo, centre: [f64; 3]) -> Option<DatasetViews> {
    let data = info.extra.get("data")?;
    let downscale = info.extra.get("downscale").and_then(|d| d.parse().ok()).unwrap_or(1);
    let cameras = match load_cameras(Path::new(data), downscale) {
        Ok(c) => c,
        Err(e) => {
            eprintln!(
                "fogray render: note: {}'s dataset cannot be read ({e}); the orbit's defaults frame the scene box",
                model.display()
            );
            return None;
        }
    };
    let first: &PinholeCamera = &cameras.first()?.camera;
    let k = first.intrinsics();
    let distance = |c: &PinholeCamera| {
        let e = c.centre();
        (0..3).map(|i| (e[i] - centre[i]).powi(2)).sum::<f64>().sqrt()
    };
    let radius = cameras.iter().map(|c| distance(&c.camera)).sum::<f64>() / cameras.len() as f64;
    Some(DatasetViews {
        size: ImageSize {
            width: k.width,
            height: k.height,
        },
        fov_y: 2.0 * (k.height as f64 / (2.0 * k.fy.abs())).atan(),
        radius,
    })
}

/// Checks the orbit's flags, before any file is read: one line naming the flag.
///
/// Errors: zero frames, an elevation outside (-90, 90) degrees, a radius that is not positive,
/// a size of 0, a field of view outside (0, 180) degrees.
pub fn check_flags(args: &RenderArgs) -> Result<(), CliError> {
    let refuse = |flag, value: &dyn std::fmt::Display, rule: &str| {
        Err(CliError::Flag {
            flag,
            value: Some(value.to_string()),
            rule: rule.into(),
        })
    };
    if args.orbit == Some(0) {
        return refuse("--orbit", &0, "zero frames (at least one is needed)");
    }
    if let Some(e) = args.elevation.filter(|e| !(*e > -90.0 && *e < 90.0)) {
        return refuse("--elevation", &e, "must be in (-90, 90) degrees");
    }
    if let Some(r) = args.radius.filter(|r| !(r.is_finite() && *r > 0.0)) {
        return refuse("--radius", &r, "must be finite and positive");
    }
    if let Some(f) = args.fov.filter(|f| !(*f > 0.0 && *f < 180.0)) {
        return refuse("--fov", &f, "must be in (0, 180) degrees");
    }
    let zero = match (args.size, args.width, args.height) {
        (Some(s), _, _) if s.width == 0 || s.height == 0 => Some(("--size", format!("{}x{}", s.width, s.height))),
        (_, Some(0), _) => Some(("--width", "0".into())),
        (_, _, Some(0)) => Some(("--height", "0".into())),
        _ => None,
    };
    if let Some((flag, value)) = zero {
        return refuse(flag, &value, "an image needs at least one pixel each way");
    }
    Ok(())
}

/// The orbit and the intrinsics of its frames: the flags, else `dataset`'s views, else the
/// fallbacks (see the [module docs](self)), around `centre` of a scene box whose half diagonal
/// is `half_diagonal`. `args.orbit` must be set.
///
/// Errors: as [`check_flags`], and intrinsics or an orbit the camera module refuses.
pub fn orbit_of(
    args: &RenderArgs,
    dataset: Option<&DatasetViews>,
    centre: [f64; 3],
    half_diagonal: f64,
) -> Result<(Orbit, Intrinsics), CliError> {
    check_flags(args)?;
    let frames = args.orbit.ok_or(CliError::MissingFlag { give: "--orbit N" })?;
    let base = dataset.map_or(FALLBACK_SIZE, |d| d.size);
    let size = args.size.unwrap_or(ImageSize {
        width: args.width.unwrap_or(base.width),
        height: args.height.unwrap_or(base.height),
    });
    let fov_y = match (args.fov, dataset) {
        (Some(degrees), _) => degrees.to_radians(),
        (None, Some(d)) => d.fov_y,
        (None, None) => FALLBACK_FOV_DEGREES.to_radians(),
    };
    let k = Intrinsics::from_vertical_fov(size.width, size.height, fov_y)
        .map_err(|source| CliError::FlagOp { flag: "--fov", source })?;
    let radius = match (args.radius, dataset) {
        (Some(r), _) => r,
        (None, Some(d)) => d.radius,
        (None, None) => {
            // The narrower of the two fields of view holds the box's bounding sphere.
            let fov_x = 2.0 * (k.width as f64 / (2.0 * k.fx)).atan();
            half_diagonal / (fov_y.min(fov_x) / 2.0).sin()
        }
    };
    let orbit = Orbit {
        centre,
        radius,
        elevation: args.elevation.unwrap_or(DEFAULT_ELEVATION_DEGREES).to_radians(),
        frames,
    };
    orbit.check().map_err(|source| CliError::FlagOp {
        flag: "--orbit",
        source,
    })?;
    Ok((orbit, k))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_as_width_by_height() {
        assert_eq!(
            "320x240".parse::<ImageSize>(),
            Ok(ImageSize {
                width: 320,
                height: 240
            })
        );
        assert_eq!("0X5".parse::<ImageSize>().map(|s| (s.width, s.height)), Ok((0, 5)));
        for bad in ["320", "x240", "320x", "-1x5", "axb"] {
            assert!(bad.parse::<ImageSize>().is_err(), "{bad}");
        }
    }
}
