//! The scene contraction of mip-NeRF 360 in the L-infinity form of nerfacto and Zip-NeRF:
//! with `u = (x - c) / r` and `m = ||u||_inf`,
//! `contract(u) = u` for `m <= 1`, else `(2 - 1/m) u / m`,
//! which maps all of space onto the open cube `(-2, 2)^3`, infinity onto its faces.
//!
//! The L-infinity norm makes the contracted space a cube, so a cube of grid cells covers it
//! with no cell wasted outside a ball, and the inner region `|x - c|_inf <= r` is a box whose
//! cells are the world's cells scaled by `r`.

use fogray_tape::Float;

use crate::error::{At, Op, OpsError};
use crate::rays::Aabb;

/// Half the side of the contracted cube: every contracted point lies in
/// `[-CONTRACTED_HALF_WIDTH, CONTRACTED_HALF_WIDTH]^3`, and infinity on its faces.
pub const CONTRACTED_HALF_WIDTH: f64 = 2.0;

/// The inner region of a [`Contraction`]: the world box of centre `centre` and half-side
/// `radius` (world units), left as it is (only scaled by `1 / radius`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InnerRegion {
    /// The centre `c` (world units).
    pub centre: [f64; 3],
    /// The half-side `r` of the inner box (world units): finite and positive.
    pub radius: f64,
}

/// The contraction of all of space into `[-2, 2]^3` around an [`InnerRegion`] (see the
/// [module docs](self) for the map).
///
/// Every function is generic over [`Float`] and computed in that type, in a form that
/// neither overflows for huge points (no `m^2` is formed: `u / m` and `1 / m` are computed
/// from `x - c` and `r` directly) nor divides 0 by 0 at the centre (the inner branch divides
/// by `r` only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contraction {
    region: InnerRegion,
}

/// `max_a |v_a|` and the first axis attaining it (the lowest index on a tie).
fn norm_inf<F: Float>(v: [F; 3]) -> (F, usize) {
    let mut best = (v[0].abs(), 0);
    for (a, &x) in v.iter().enumerate().skip(1) {
        if x.abs() > best.0 {
            best = (x.abs(), a);
        }
    }
    best
}

impl InnerRegion {
    /// The region of centre `centre` and half-side `radius`.
    /// Errors: a centre coordinate not finite, a radius not finite and positive.
    pub fn new(centre: [f64; 3], radius: f64) -> Result<Self, OpsError> {
        if let Some(a) = (0..3).find(|&a| !centre[a].is_finite()) {
            return Err(OpsError::domain(
                Op::Contraction,
                At::Entry { row: 0, column: a },
                "inner region's centre",
                centre[a],
                "must be finite",
            ));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(OpsError::domain(
                Op::Contraction,
                At::Value,
                "inner region's radius",
                radius,
                "must be finite and positive",
            ));
        }
        Ok(InnerRegion { centre, radius })
    }
}

impl Contraction {
    /// The contraction around `region`. Errors: as [`InnerRegion::new`] (a region built by
    /// hand is checked again).
    pub fn new(region: InnerRegion) -> Result<Self, OpsError> {
        Ok(Contraction {
            region: InnerRegion::new(region.centre, region.radius)?,
        })
    }

    /// The inner region.
    pub fn region(&self) -> InnerRegion {
        self.region
    }

    /// The contracted cube `[-2, 2]^3`, the box of an occupancy grid or a grid field over
    /// contracted space.
    pub fn cube() -> Aabb {
        let h = CONTRACTED_HALF_WIDTH;
        Aabb::new([-h; 3], [h; 3]).expect("a finite cube with min < max")
    }

    /// `x - c` and the scale `r` to divide it by, halved together when `x - c` overflows (a
    /// point near the largest finite value, on the far side of the centre), so that the
    /// ratios the map needs stay exact.
    fn offset<F: Float>(&self, x: [F; 3]) -> ([F; 3], F) {
        let c = self.region.centre.map(F::lit);
        let r = F::lit(self.region.radius);
        let d: [F; 3] = std::array::from_fn(|a| x[a] - c[a]);
        if d.iter().all(|v| v.is_finite()) || x.iter().any(|v| !v.is_finite()) {
            return (d, r);
        }
        let half = F::lit(0.5);
        (std::array::from_fn(|a| x[a] * half - c[a] * half), r * half)
    }

    /// The contracted point of world point `x`, in `[-2, 2]^3` (on a face only where `x` is
    /// so far that `1/m` rounds below the type's resolution near 2). A NaN coordinate gives
    /// NaN.
    pub fn contract<F: Float>(&self, x: [F; 3]) -> [F; 3] {
        if x.iter().any(|v| v.is_nan()) {
            return [F::nan(); 3];
        }
        let (d, r) = self.offset(x);
        let (n, _) = norm_inf(d);
        if n <= r {
            return d.map(|v| v / r);
        }
        if n.is_infinite() {
            // A point at infinity: its direction's axes that are infinite reach the faces.
            let inf: [F; 3] = d.map(|v| if v.is_infinite() { v.signum() } else { F::zero() });
            return inf.map(|v| v * F::lit(CONTRACTED_HALF_WIDTH));
        }
        // (2 - 1/m) u / m with 1/m = r / n and u / m = d / n: both in [-1, 1], no m^2.
        let w = r / n;
        let scale = F::lit(2.0) - w;
        d.map(|v| scale * (v / n))
    }

    /// The world point whose contraction is `y`, or `None` where there is none: `y` not
    /// finite, `||y||_inf >= 2` (infinity), or a point beyond the type's range.
    ///
    /// Near the faces the world point is as precise as `2 - ||y||_inf` is: its relative error
    /// grows like the type's epsilon times `m = ||x - c||_inf / r`.
    pub fn inverse<F: Float>(&self, y: [F; 3]) -> Option<[F; 3]> {
        let (n, _) = norm_inf(y);
        if n.is_nan() || n >= F::lit(CONTRACTED_HALF_WIDTH) {
            return None;
        }
        let c = self.region.centre.map(F::lit);
        let r = F::lit(self.region.radius);
        let x: [F; 3] = if n <= F::one() {
            std::array::from_fn(|a| c[a] + r * y[a])
        } else {
            // m = 1 / (2 - n), u = m y / n.
            let w = F::lit(CONTRACTED_HALF_WIDTH) - n;
            let scale = r / w;
            std::array::from_fn(|a| c[a] + scale * (y[a] / n))
        };
        x.iter().all(|v| v.is_finite()).then_some(x)
    }

    /// The Jacobian `J[i][j] = d contract_i / d x_j` at world point `x`.
    ///
    /// Inside the inner region it is `I / r`. Outside, with `i` the axis where `||u||_inf`
    /// is attained, `s = sign(u_i)`, `w = 1/m` and `e = u / m`:
    /// `J[i][i] = w^2 / r`, `J[j][j] = w (2 - w) / r`, `J[j][i] = -2 s e_j w (1 - w) / r`
    /// (`j != i`), and 0 elsewhere. It is continuous across the inner region's faces, edges
    /// and corners (all three forms are `I / r` there).
    ///
    /// Where two or three axes attain `||u||_inf` outside the inner region (the diagonal
    /// planes the map is not differentiable across), the lowest such axis is taken: the
    /// result is the one-sided Jacobian from that axis's side, the limit of the Jacobian
    /// as the point is approached from where that axis alone is the largest.
    pub fn jacobian<F: Float>(&self, x: [F; 3]) -> [[F; 3]; 3] {
        let (d, r) = self.offset(x);
        let (n, i) = norm_inf(d);
        let mut j = [[F::zero(); 3]; 3];
        if n <= r {
            for (a, row) in j.iter_mut().enumerate() {
                row[a] = F::one() / r;
            }
            return j;
        }
        let w = r / n;
        let s = d[i].signum();
        let two = F::lit(2.0);
        // The region's own r, not the halved one of an overflowing offset.
        let r = F::lit(self.region.radius);
        j[i][i] = w * w / r;
        for a in (0..3).filter(|&a| a != i) {
            j[a][a] = w * (two - w) / r;
            j[a][i] = -two * s * (d[a] / n) * w * (F::one() - w) / r;
        }
        j
    }

    /// The most world length that one unit of contracted length can stand for, over every
    /// point whose contracted L-infinity norm is at most `norm` and every direction: the
    /// reciprocal of the Jacobian's smallest singular value, bounded over that set. It is
    /// `r` inside the inner region (`norm <= 1`), grows like `r m^2` with `m = 1 / (2 - norm)`
    /// outside, and is infinite at `norm >= 2`.
    ///
    /// Outside, `J^T J` keeps `f^2` (`f = w (2 - w)`) on the lateral direction orthogonal to
    /// the coupling `c = (J[j][i])_j`, and on the plane of axis `i` and `c` has the 2x2 form
    /// `[[w^4 + |c|^2, f |c|], [f |c|, f^2]]` whose smaller eigenvalue is the smallest of
    /// all; it falls as `|c|` grows, and `|c|^2 <= 2 (2 w (1 - w))^2` (each lateral
    /// `|e_j| <= 1`), so that bound gives the largest stretch at a given `m`; it rises with
    /// `m`, so the largest over `norm' <= norm` is at `norm`.
    pub fn max_stretch(&self, norm: f64) -> f64 {
        let r = self.region.radius;
        if norm <= 1.0 {
            return r;
        }
        if norm.is_nan() || norm >= CONTRACTED_HALF_WIDTH {
            return f64::INFINITY;
        }
        let w = CONTRACTED_HALF_WIDTH - norm;
        let a = w * w;
        let f = w * (2.0 - w);
        let c2 = 2.0 * (2.0 * w * (1.0 - w)).powi(2);
        let trace = a * a + c2 + f * f;
        let det = a * f;
        // The larger eigenvalue without cancellation; the smaller is det^2 / larger.
        let disc = (trace * trace - 4.0 * det * det).max(0.0).sqrt();
        let largest = 0.5 * (trace + disc);
        r * largest.sqrt() / det
    }
}
