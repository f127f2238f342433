//! What a capture knows of its scene besides the cameras: COLMAP's sparse points (a splat model
//! starts from them) and LLFF's depth bounds per view.

/// The points of a sparse reconstruction (COLMAP's `points3D`), in the cameras' world
/// ([`SceneData::world`](crate::SceneData::world) applied), in the file's order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// Positions.
    pub positions: Vec<[f64; 3]>,
    /// Colours as stored (8-bit sRGB), one per position.
    pub colors: Vec<[u8; 3]>,
}

impl PointCloud {
    /// How many points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// The nearest and farthest depth (along the viewing axis, in the cameras' world: the file's
/// values times [`WorldTransform::scale`](crate::WorldTransform::scale)) at which a view sees
/// the scene, as LLFF stores them; `0 <= near <= far`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthBounds {
    /// Nearest depth.
    pub near: f64,
    /// Farthest depth.
    pub far: f64,
}
