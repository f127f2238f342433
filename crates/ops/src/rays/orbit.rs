//! An orbit: pinhole cameras evenly spaced on a horizontal circle around a point, each looking
//! at it — the turntable of views a fitted scene is shown in.
//!
//! World `+z` is up, the convention of Blender / NeRF-synthetic scenes (their cameras stand
//! on the upper half of a sphere around the origin, `+z` up in every image). Frame `k` of `N`
//! sits at azimuth `a = 2 pi k / N` (from `+x` towards `+y`: counter-clockwise seen from
//! above) and elevation `e` above the horizontal plane through the centre:
//! `eye = centre + radius (cos e cos a, cos e sin a, sin e)`, rolled so that `+z` appears up.
//!
//! ```
//! use fogray_ops::rays::{Intrinsics, Orbit};
//!
//! let k = Intrinsics::from_vertical_fov(64, 48, 40f64.to_radians())?;
//! let orbit = Orbit { centre: [0.0, 0.0, 0.5], radius: 4.0, elevation: 30f64.to_radians(), frames: 8 };
//! let cameras = orbit.cameras(k)?;
//! assert_eq!(cameras.len(), 8);
//! // Every frame sees the centre at its principal point.
//! let [x, y] = cameras[3].project(orbit.centre).unwrap();
//! assert!((x - 32.0).abs() < 1e-9 && (y - 24.0).abs() < 1e-9);
//! # Ok::<(), fogray_ops::OpsError>(())
//! ```

use std::f64::consts::{FRAC_PI_2, TAU};

use super::camera::{Intrinsics, PinholeCamera};
use crate::error::{At, Op, OpsError};

/// World up for every orbit: `+z`.
pub const UP: [f64; 3] = [0.0, 0.0, 1.0];

/// Where an orbit's cameras stand (see the [module docs](self) for the formula).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    /// The point every camera looks at (finite).
    pub centre: [f64; 3],
    /// Every camera's distance from the centre (finite, positive).
    pub radius: f64,
    /// Angle of every camera above the horizontal plane through the centre, in radians, in
    /// `(-pi/2, pi/2)` (straight above or below, `+z` could not appear up).
    pub elevation: f64,
    /// Number of cameras (at least 1).
    pub frames: usize,
}

impl Orbit {
    /// Checks the domain of every field (see the field docs).
    pub fn check(&self) -> Result<(), OpsError> {
        let invalid = |what: &str, value: f64, rule| OpsError::Domain {
            op: Op::Rays,
            at: At::Value,
            what: format!("orbit {what}"),
            value,
            rule,
        };
        if self.frames == 0 {
            return Err(invalid("frames", 0.0, "at least one frame"));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(invalid("radius", self.radius, "must be finite and positive"));
        }
        if !(self.elevation > -FRAC_PI_2 && self.elevation < FRAC_PI_2) {
            return Err(invalid("elevation", self.elevation, "must be in (-pi/2, pi/2) radians"));
        }
        if let Some(&c) = self.centre.iter().find(|c| !c.is_finite()) {
            return Err(invalid("centre", c, "must be finite"));
        }
        Ok(())
    }

    /// Azimuth of frame `k`, `2 pi k / frames` radians.
    pub fn azimuth(&self, k: usize) -> f64 {
        TAU * k as f64 / self.frames as f64
    }

    /// Where frame `k` stands.
    pub fn eye(&self, k: usize) -> [f64; 3] {
        let (a, e) = (self.azimuth(k), self.elevation);
        let offset = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
        std::array::from_fn(|i| self.centre[i] + self.radius * offset[i])
    }

    /// The orbit's cameras, frame 0 first, each with `intrinsics`, looking at the centre with
    /// `+z` up in its image.
    ///
    /// Errors: a field outside its domain ([`Orbit::check`]), bad intrinsics.
    pub fn cameras(&self, intrinsics: Intrinsics) -> Result<Vec<PinholeCamera>, OpsError> {
        self.check()?;
        (0..self.frames)
            .map(|k| PinholeCamera::look_at(intrinsics, self.eye(k), self.centre, UP))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
    }

    fn orbit(frames: usize) -> Orbit {
        Orbit {
            centre: [0.3, -0.2, 0.5],
            radius: 3.7,
            elevation: 25f64.to_radians(),
            frames,
        }
    }

    /// Off-centre principal point and unequal focal lengths: a camera that looked anywhere
    /// but at the centre would project it elsewhere.
    fn intrinsics() -> Intrinsics {
        Intrinsics {
            fx: 90.0,
            fy: 95.0,
            cx: 41.3,
            cy: 27.8,
            width: 80,
            height: 60,
        }
    }

    #[test]
    fn every_camera_looks_at_the_centre_from_the_radius_and_elevation() {
        let o = orbit(7);
        let cameras = o.cameras(intrinsics()).unwrap();
        assert_eq!(cameras.len(), 7);
        for (k, cam) in cameras.iter().enumerate() {
            let [x, y] = cam.project(o.centre).unwrap();
            assert!(
                (x - 41.3).abs() < 1e-9 && (y - 27.8).abs() < 1e-9,
                "frame {k}: {x}, {y}"
            );
            let eye = cam.centre();
            assert!((distance(eye, o.centre) - 3.7).abs() < 1e-12, "frame {k}");
            // Height above the centre: radius sin(elevation).
            let height = eye[2] - o.centre[2];
            assert!((height - 3.7 * 25f64.to_radians().sin()).abs() < 1e-12, "frame {k}");
            // Azimuth 2 pi k / 7, from +x towards +y.
            let azimuth = (eye[1] - o.centre[1]).atan2(eye[0] - o.centre[0]).rem_euclid(TAU);
            let want = TAU * k as f64 / 7.0;
            let gap = (azimuth - want).abs();
            assert!(gap.min(TAU - gap) < 1e-12, "frame {k}: azimuth {azimuth}, want {want}");
        }
    }

    #[test]
    fn world_up_appears_up_in_every_image() {
        let o = orbit(5);
        for cam in o.cameras(intrinsics()).unwrap() {
            // A point straight above the centre projects on the principal point's column,
            // above it (smaller row).
            let [x, y] = cam.project([o.centre[0], o.centre[1], o.centre[2] + 0.4]).unwrap();
            assert!((x - 41.3).abs() < 1e-9, "{x}");
            assert!(y < 27.8 - 1.0, "{y}");
        }
    }

    #[test]
    fn frame_zero_lies_on_the_x_axis_and_one_frame_is_allowed() {
        let o = Orbit {
            centre: [0.0; 3],
            radius: 2.0,
            elevation: 0.0,
            frames: 1,
        };
        let cam = &o.cameras(intrinsics()).unwrap()[0];
        assert_eq!(cam.centre(), [2.0, 0.0, 0.0]);
        // Elevation -40 degrees: below the centre, looking up at it.
        let below = Orbit {
            elevation: -40f64.to_radians(),
            ..o
        };
        assert!(below.eye(0)[2] < 0.0);
        assert!(below.cameras(intrinsics()).is_ok());
    }

    #[test]
    fn bad_orbits_are_refused() {
        let o = orbit(4);
        let bad = [
            Orbit { frames: 0, ..o },
            Orbit { radius: 0.0, ..o },
            Orbit { radius: -1.0, ..o },
            Orbit { radius: f64::NAN, ..o },
            Orbit {
                elevation: FRAC_PI_2,
                ..o
            },
            Orbit {
                elevation: -FRAC_PI_2,
                ..o
            },
            Orbit {
                elevation: f64::NAN,
                ..o
            },
            Orbit {
                centre: [0.0, f64::INFINITY, 0.0],
                ..o
            },
        ];
        for b in bad {
            assert!(
                matches!(
                    b.cameras(intrinsics()),
                    Err(OpsError::Domain {
                        op: Op::Rays,
                        at: At::Value,
                        ..
                    })
                ),
                "{b:?}"
            );
        }
    }
}
