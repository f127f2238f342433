//! The scene: constant-density primitives (spheres and axis-aligned boxes) in front of a
//! background colour, read from JSON and validated.
//!
//! Where primitives overlap their densities add, and the colour there is the density-weighted
//! mean of their colours (see [`crate::exact`]). The fit models the box `[-1, 1]^3` only, so a
//! scene meant to be fitted keeps its primitives inside it.
//!
//! ```
//! use fogray_grid::scene::{Primitive, Scene};
//!
//! let scene = Scene::from_json(
//!     r#"{"background": [1, 1, 1], "primitives": [
//!         {"kind": "sphere", "center": [0, 0, 0], "radius": 0.5, "density": 10, "color": [1, 0, 0]},
//!         {"kind": "box", "min": [-1, -1, -1], "max": [1, 1, -0.8], "density": 30, "color": [0.5, 0.5, 0.5]}
//!     ]}"#,
//! )?;
//! assert!(matches!(scene.primitives[0], Primitive::Sphere(ref s) if s.radius == 0.5));
//! // Bad input is a typed error, never a panic.
//! assert!(Scene::from_json(r#"{"background": [1, 1, 2], "primitives": []}"#).is_err());
//! assert_eq!(Scene::default().primitives.len(), 4);
//! # Ok::<(), fogray_grid::scene::SceneError>(())
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a scene was rejected.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SceneError {
    /// The scene file could not be read.
    #[error("cannot read scene file {path}: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        message: String,
    },
    /// The text is not JSON of the scene's shape (a missing or unknown field, a wrong type).
    #[error("scene JSON: {0}")]
    Json(String),
    /// A primitive whose `kind` is neither `sphere` nor `box`.
    #[error("primitive {index}: unknown kind {kind} (expected \"sphere\" or \"box\")")]
    UnknownKind {
        /// Index of the primitive in `primitives`.
        index: usize,
        /// The kind given, as JSON.
        kind: String,
    },
    /// A number outside its domain.
    #[error("{what} is {value} ({rule})")]
    InvalidValue {
        /// Which number, e.g. `primitive 1 (sphere) radius` or `background[2]`.
        what: String,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// A box with `min[axis] > max[axis]`.
    #[error("primitive {index} (box): min[{axis}] = {min} > max[{axis}] = {max}")]
    MinAboveMax {
        /// Index of the primitive in `primitives`.
        index: usize,
        /// The axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// `min[axis]`.
        min: f64,
        /// `max[axis]`.
        max: f64,
    },
}

/// A ball of constant density and colour.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sphere {
    /// Centre (finite).
    pub center: [f64; 3],
    /// Radius (finite, `>= 0`).
    pub radius: f64,
    /// Density, the extinction per unit length (finite, `>= 0`).
    pub density: f64,
    /// Colour, RGB in `[0, 1]`.
    pub color: [f64; 3],
}

/// An axis-aligned box of constant density and colour (kind `"box"` in JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cuboid {
    /// The corner of smallest coordinates (finite, `min <= max` on every axis).
    pub min: [f64; 3],
    /// The corner of largest coordinates (finite).
    pub max: [f64; 3],
    /// Density, the extinction per unit length (finite, `>= 0`).
    pub density: f64,
    /// Colour, RGB in `[0, 1]`.
    pub color: [f64; 3],
}

/// One primitive of the scene, tagged by `kind` in JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Primitive {
    /// `{"kind": "sphere", "center", "radius", "density", "color"}`.
    Sphere(Sphere),
    /// `{"kind": "box", "min", "max", "density", "color"}`.
    Box(Cuboid),
}

impl Primitive {
    /// The primitive's density.
    pub fn density(&self) -> f64 {
        match self {
            Primitive::Sphere(s) => s.density,
            Primitive::Box(b) => b.density,
        }
    }

    /// The primitive's colour.
    pub fn color(&self) -> [f64; 3] {
        match self {
            Primitive::Sphere(s) => s.color,
            Primitive::Box(b) => b.color,
        }
    }

    fn kind(&self) -> &'static str {
        match self {
            Primitive::Sphere(_) => "sphere",
            Primitive::Box(_) => "box",
        }
    }
}

/// A background colour and the primitives in front of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// What a ray that gets through shows, RGB in `[0, 1]`.
    pub background: [f64; 3],
    /// The primitives, in any order (compositing does not depend on it).
    pub primitives: Vec<Primitive>,
}

impl Default for Scene {
    /// The built-in scene: a red sphere, a smaller blue one, a green box and a grey floor slab,
    /// on white.
    fn default() -> Self {
        let sphere = |center, radius, density, color| {
            Primitive::Sphere(Sphere {
                center,
                radius,
                density,
                color,
            })
        };
        let cuboid = |min, max, density, color| {
            Primitive::Box(Cuboid {
                min,
                max,
                density,
                color,
            })
        };
        Scene {
            background: [1.0, 1.0, 1.0],
            primitives: vec![
                sphere([0.0, 0.0, 0.1], 0.45, 40.0, [0.85, 0.3, 0.2]),
                sphere([0.45, 0.35, -0.2], 0.25, 15.0, [0.2, 0.55, 0.9]),
                cuboid([-0.8, -0.7, -0.5], [-0.35, -0.1, 0.45], 25.0, [0.3, 0.8, 0.35]),
                cuboid([-0.9, -0.9, -0.75], [0.9, 0.9, -0.6], 60.0, [0.75, 0.75, 0.7]),
            ],
        }
    }
}

impl Scene {
    /// The density at point `p`: the sum of the densities of the primitives holding it (the
    /// boundary included), 0 outside them all.
    pub fn density_at(&self, p: [f64; 3]) -> f64 {
        let inside = |prim: &Primitive| match prim {
            Primitive::Sphere(s) => (0..3).map(|a| (p[a] - s.center[a]).powi(2)).sum::<f64>() <= s.radius * s.radius,
            Primitive::Box(b) => (0..3).all(|a| b.min[a] <= p[a] && p[a] <= b.max[a]),
        };
        self.primitives
            .iter()
            .filter(|prim| inside(prim))
            .map(Primitive::density)
            .sum()
    }

    /// Parses and validates a scene from JSON text.
    ///
    /// Errors: [`SceneError::Json`] for text that is not a scene, [`SceneError::UnknownKind`],
    /// and the errors of [`Scene::validate`].
    pub fn from_json(text: &str) -> Result<Scene, SceneError> {
        let value: serde_json::Value = serde_json::from_str(text).map_err(|e| SceneError::Json(e.to_string()))?;
        // Named before serde's own message, which would only say "unknown variant".
        if let Some(primitives) = value.get("primitives").and_then(|p| p.as_array()) {
            for (index, p) in primitives.iter().enumerate() {
                match p.get("kind") {
                    Some(serde_json::Value::String(k)) if k == "sphere" || k == "box" => {}
                    Some(k) => {
                        return Err(SceneError::UnknownKind {
                            index,
                            kind: k.to_string(),
                        })
                    }
                    None => return Err(SceneError::Json(format!("primitive {index}: missing field `kind`"))),
                }
            }
        }
        let scene: Scene = serde_json::from_value(value).map_err(|e| SceneError::Json(e.to_string()))?;
        scene.validate()?;
        Ok(scene)
    }

    /// Reads, parses and validates a scene file ([`SceneError::Read`] if it cannot be read).
    pub fn read(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|e| SceneError::Read {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Scene::from_json(&text)
    }

    /// The scene as indented JSON, which [`Scene::from_json`] reads back unchanged.
    pub fn to_json_pretty(&self) -> String {
        // A scene holds plain numbers, arrays and strings: serialising it cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks every number: colours in `[0, 1]`, densities and radii finite and `>= 0`,
    /// centres and corners finite, `min <= max` on every axis of a box.
    pub fn validate(&self) -> Result<(), SceneError> {
        check_color("background", &self.background)?;
        for (index, p) in self.primitives.iter().enumerate() {
            let what = |field: &str| format!("primitive {index} ({}) {field}", p.kind());
            check_non_negative(&what("density"), p.density())?;
            check_color(&what("color"), &p.color())?;
            match p {
                Primitive::Sphere(s) => {
                    check_finite(&what("center"), &s.center)?;
                    check_non_negative(&what("radius"), s.radius)?;
                }
                Primitive::Box(b) => {
                    check_finite(&what("min"), &b.min)?;
                    check_finite(&what("max"), &b.max)?;
                    if let Some(axis) = (0..3).find(|&a| b.min[a] > b.max[a]) {
                        return Err(SceneError::MinAboveMax {
                            index,
                            axis,
                            min: b.min[axis],
                            max: b.max[axis],
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

fn invalid(what: String, value: f64, rule: &'static str) -> SceneError {
    SceneError::InvalidValue { what, value, rule }
}

fn check_color(what: &str, c: &[f64; 3]) -> Result<(), SceneError> {
    match c.iter().position(|v| !(0.0..=1.0).contains(v)) {
        Some(k) => Err(invalid(format!("{what}[{k}]"), c[k], "must be in [0, 1]")),
        None => Ok(()),
    }
}

fn check_finite(what: &str, p: &[f64; 3]) -> Result<(), SceneError> {
    match p.iter().position(|v| !v.is_finite()) {
        Some(k) => Err(invalid(format!("{what}[{k}]"), p[k], "must be finite")),
        None => Ok(()),
    }
}

fn check_non_negative(what: &str, v: f64) -> Result<(), SceneError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(what.to_string(), v, "must be finite and >= 0"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(primitive: &str) -> Result<Scene, SceneError> {
        Scene::from_json(&format!(r#"{{"background": [1, 1, 1], "primitives": [{primitive}]}}"#))
    }

    const SPHERE: &str = r#"{"kind": "sphere", "center": [0, 0, 0], "radius": 0.5, "density": 2, "color": [1, 0, 0]}"#;

    #[test]
    fn the_default_scene_round_trips_through_json() {
        let scene = Scene::default();
        assert_eq!(Scene::from_json(&scene.to_json_pretty()), Ok(scene.clone()));
        // The JSON carries the kinds the issue names.
        let v: serde_json::Value = serde_json::from_str(&scene.to_json_pretty()).unwrap();
        assert_eq!(v["primitives"][0]["kind"], "sphere");
        assert_eq!(v["primitives"][3]["kind"], "box");
        assert_eq!(v["primitives"][3]["max"][2], -0.6);
    }

    #[test]
    fn a_valid_sphere_parses() {
        let s = parse(SPHERE).unwrap();
        assert_eq!(
            s.primitives,
            vec![Primitive::Sphere(Sphere {
                center: [0.0; 3],
                radius: 0.5,
                density: 2.0,
                color: [1.0, 0.0, 0.0]
            })]
        );
    }

    #[test]
    fn bad_scenes_are_named_errors() {
        let cone = r#"{"kind": "cone", "center": [0, 0, 0]}"#;
        assert_eq!(
            parse(cone),
            Err(SceneError::UnknownKind {
                index: 0,
                kind: "\"cone\"".into()
            })
        );
        let neg_density = SPHERE.replace(r#""density": 2"#, r#""density": -1"#);
        assert!(
            matches!(parse(&neg_density), Err(SceneError::InvalidValue { ref what, value, .. }) if what == "primitive 0 (sphere) density" && value == -1.0)
        );
        let neg_radius = SPHERE.replace(r#""radius": 0.5"#, r#""radius": -0.5"#);
        assert!(
            matches!(parse(&neg_radius), Err(SceneError::InvalidValue { ref what, .. }) if what.ends_with("radius"))
        );
        let bright = SPHERE.replace("[1, 0, 0]", "[1, 0, 1.5]");
        assert!(
            matches!(parse(&bright), Err(SceneError::InvalidValue { ref what, value, .. }) if what.ends_with("color[2]") && value == 1.5)
        );
        let inverted = r#"{"kind": "box", "min": [0, 0, 0], "max": [1, -1, 1], "density": 1, "color": [0, 0, 0]}"#;
        assert_eq!(
            parse(inverted),
            Err(SceneError::MinAboveMax {
                index: 0,
                axis: 1,
                min: 0.0,
                max: -1.0
            })
        );
        let typo = SPHERE.replace("radius", "radios");
        assert!(matches!(parse(&typo), Err(SceneError::Json(_))));
        assert!(matches!(Scene::from_json("not json"), Err(SceneError::Json(_))));
        let dark_background = r#"{"background": [-0.1, 0, 0], "primitives": []}"#;
        assert!(
            matches!(Scene::from_json(dark_background), Err(SceneError::InvalidValue { ref what, .. }) if what == "background[0]")
        );
        assert!(matches!(
            Scene::read(Path::new("/nonexistent/scene.json")),
            Err(SceneError::Read { .. })
        ));
    }

    #[test]
    fn non_finite_numbers_built_in_code_are_rejected() {
        // JSON cannot spell NaN, but a scene built in code can hold one.
        let mut scene = Scene::default();
        if let Primitive::Sphere(s) = &mut scene.primitives[0] {
            s.center[1] = f64::NAN;
        }
        assert!(
            matches!(scene.validate(), Err(SceneError::InvalidValue { ref what, .. }) if what.ends_with("center[1]"))
        );
        let mut scene = Scene::default();
        if let Primitive::Box(b) = &mut scene.primitives[2] {
            b.density = f64::INFINITY;
        }
        assert!(
            matches!(scene.validate(), Err(SceneError::InvalidValue { ref what, .. }) if what.ends_with("density"))
        );
    }

    #[test]
    fn the_scene_density_adds_where_primitives_overlap() {
        let scene = Scene::default();
        assert_eq!(scene.density_at([0.0, 0.0, 0.1]), 40.0); // red sphere's centre
        assert_eq!(scene.density_at([0.0, 0.0, -0.7]), 60.0); // floor slab
        assert_eq!(scene.density_at([0.95, 0.95, 0.95]), 0.0); // empty corner

        // The blue sphere (centre (0.45, 0.35, -0.2), radius 0.25) reaches into the red one
        // (centre (0, 0, 0.1), radius 0.45) at (0.3, 0.2, -0.1): 0.3^2 + 0.2^2 + 0.2^2 = 0.17 <
        // 0.2025, and 0.15^2 + 0.15^2 + 0.1^2 = 0.055 < 0.0625.
        assert_eq!(scene.density_at([0.3, 0.2, -0.1]), 55.0);
    }
}
