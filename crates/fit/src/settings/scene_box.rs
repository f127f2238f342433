//! [`SceneBox`]: the box a model covers, as a flag (`--box`) and in a checkpoint.

use serde::{Deserialize, Serialize};

use crate::error::FitError;

/// The farthest a box's corner may lie from the origin on any axis: a dataset's own scene box
/// is held to the same bound.
pub(crate) const MAX_BOX_COORDINATE: f64 = 1e6;

/// The box a model covers: `min` to `max` on each axis (world units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneBox {
    /// The lower corner.
    pub min: [f64; 3],
    /// The upper corner.
    pub max: [f64; 3],
}

impl SceneBox {
    /// `[-1, 1]^3`, the box of a model whose settings name none.
    pub const UNIT: SceneBox = SceneBox {
        min: [-1.0; 3],
        max: [1.0; 3],
    };

    /// The cube `[-half, half]^3`.
    pub(crate) fn cube(half: f64) -> SceneBox {
        SceneBox {
            min: [-half; 3],
            max: [half; 3],
        }
    }

    /// Half the spacing of a lattice of `nodes` per axis along the box's shortest side: the
    /// sample step that resolves a grid over the box (`1 / (nodes - 1)` for `[-1, 1]^3`).
    pub(crate) fn half_node_spacing(&self, nodes: usize) -> f64 {
        let side = (0..3).map(|a| self.max[a] - self.min[a]).fold(f64::INFINITY, f64::min);
        side / (2 * (nodes - 1)) as f64
    }

    /// Errors: [`FitError::BoxAxis`] for a bound that is not finite or an axis whose minimum is
    /// not below its maximum, [`FitError::BoxBeyondRange`] for a bound too far from the origin.
    pub(crate) fn check(&self) -> Result<(), FitError> {
        for a in 0..3 {
            let (lo, hi) = (self.min[a], self.max[a]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(FitError::BoxAxis {
                    axis: a,
                    min: lo,
                    max: hi,
                });
            }
            // A scene's coordinates lie within what a dataset may give (fogray-data's range):
            // beyond it steps and distances overflow in the samplers.
            if lo.abs().max(hi.abs()) > MAX_BOX_COORDINATE {
                return Err(FitError::BoxBeyondRange {
                    axis: a,
                    min: lo,
                    max: hi,
                    limit: MAX_BOX_COORDINATE,
                });
            }
        }
        Ok(())
    }
}

impl std::fmt::Display for SceneBox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [a, b, c] = self.min;
        let [d, e, g] = self.max;
        write!(f, "{a},{b},{c},{d},{e},{g}")
    }
}

impl std::str::FromStr for SceneBox {
    type Err = String;

    /// `H` for the cube `[-H, H]^3`, or `x0,y0,z0,x1,y1,z1` for the lower and upper corners.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let values = text
            .split(',')
            .map(|v| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        let scene_box = match values[..] {
            [h] => SceneBox::cube(h),
            [a, b, c, d, e, g] => SceneBox {
                min: [a, b, c],
                max: [d, e, g],
            },
            _ => return Err(format!("{text:?}: give H (the cube [-H, H]^3) or x0,y0,z0,x1,y1,z1")),
        };
        scene_box.check().map_err(|e| e.to_string())?;
        Ok(scene_box)
    }
}
