//! The exact photograph of a ray: the emission-absorption integral of a scene of
//! constant-density primitives, with no quadrature error.
//!
//! Along a ray each primitive occupies one interval of depth (a sphere's chord, a box's slab
//! intersection), so the medium is piecewise constant between the sorted entry and exit
//! depths of all primitives. On a piece of length `L`, density `sigma` and colour `c` the
//! integral is exact in closed form: the piece emits `T (1 - e^(-sigma L)) c` and passes on
//! `T e^(-sigma L)`. Alpha compositing over the pieces is therefore the integral itself.
//! Opacities are `-expm1(-sigma L)` (exact for thin pieces, where `1 - exp` cancels) and the
//! transmittance is `exp` of the running optical depth (one rounding, however many pieces).
//!
//! ```
//! use fogray_grid::exact::{render_ray, Ray};
//! use fogray_grid::scene::{Primitive, Scene, Sphere};
//!
//! // Through the centre of a sphere of radius 0.5 and density 2: T = exp(-2 r s) = exp(-2).
//! let scene = Scene {
//!     background: [1.0, 1.0, 1.0],
//!     primitives: vec![Primitive::Sphere(Sphere { center: [0.0; 3], radius: 0.5, density: 2.0, color: [1.0, 0.0, 0.0] })],
//! };
//! let ray = Ray { origin: [0.0, 0.0, -3.0], direction: [0.0, 0.0, 1.0] };
//! let px = render_ray(&scene, &ray);
//! assert!((px.transmittance - (-2.0f64).exp()).abs() < 1e-15);
//! assert!((px.color[1] - (-2.0f64).exp()).abs() < 1e-15); // only the background has green
//! ```

use fogray::ops::Aabb;

use crate::scene::{Cuboid, Primitive, Scene, Sphere};

/// A ray `origin + t direction` for `t >= 0`. `direction` need not be unit, but then depths
/// are in units of its length and densities apply per unit of depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Where the ray starts.
    pub origin: [f64; 3],
    /// Where it goes (non-zero).
    pub direction: [f64; 3],
}

/// The depths where a ray enters and leaves a primitive, `enter <= exit`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Entry depth.
    pub enter: f64,
    /// Exit depth.
    pub exit: f64,
}

/// What a ray sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExactPixel {
    /// The composited colour, background included.
    pub color: [f64; 3],
    /// The fraction of light that gets through every primitive, `exp(-optical depth)`.
    pub transmittance: f64,
    /// The unnormalised expected depth `integral of t sigma(t) T(t) dt` (the composite's
    /// `depth` output; divide by `1 - transmittance` for the mean depth of what is seen).
    pub depth: f64,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The part of the ray (`t >= 0`) inside the sphere, or `None` if it misses or only grazes it.
///
/// The discriminant is computed as `r^2 - |oc - (oc.d / d.d) d|^2 (d.d)`: the squared distance
/// from the centre to the line, which stays accurate when the sphere is small and far away
/// (the textbook `b^2 - a c` subtracts two nearly equal large numbers there). The root nearer
/// zero comes from `c / q` rather than a difference, for the same reason.
pub fn sphere_span(s: &Sphere, ray: &Ray) -> Option<Span> {
    let d = ray.direction;
    let a = dot(d, d);
    if a == 0.0 {
        return None;
    }
    let oc = [
        ray.origin[0] - s.center[0],
        ray.origin[1] - s.center[1],
        ray.origin[2] - s.center[2],
    ];
    let b = dot(oc, d); // half the textbook b
    let closest = [oc[0] - b / a * d[0], oc[1] - b / a * d[1], oc[2] - b / a * d[2]];
    let disc = (s.radius * s.radius - dot(closest, closest)) * a;
    if disc.is_nan() || disc <= 0.0 {
        return None;
    }
    let c = dot(oc, oc) - s.radius * s.radius;
    // |q| = |b| + sqrt(disc) > 0 (signum(0) is 1), and the roots are q / a and c / q.
    let q = -(b + b.signum() * disc.sqrt());
    let (x, y) = (q / a, c / q);
    let (t0, t1) = (x.min(y), x.max(y));
    clip(t0, t1)
}

/// The part of the ray (`t >= 0`) inside the box, or `None` if it misses or only grazes it:
/// fogray-ops' ray/box clipping (the slab method), kept when it has a length. A box that is
/// flat on some axis holds no medium and has no span.
pub fn box_span(b: &Cuboid, ray: &Ray) -> Option<Span> {
    let (enter, exit) = Aabb::new(b.min, b.max).ok()?.clip_ray(ray.origin, ray.direction)?;
    (exit > enter).then_some(Span { enter, exit })
}

fn clip(enter: f64, exit: f64) -> Option<Span> {
    let enter = enter.max(0.0);
    (exit > enter).then_some(Span { enter, exit })
}

/// The span of any primitive along the ray (see [`sphere_span`] and [`box_span`]).
pub fn span(p: &Primitive, ray: &Ray) -> Option<Span> {
    match p {
        Primitive::Sphere(s) => sphere_span(s, ray),
        Primitive::Box(b) => box_span(b, ray),
    }
}

/// The exact colour and transmittance of one ray through the scene.
///
/// Cuts the ray at every entry and exit depth; on each piece the density is the sum of the
/// densities of the primitives whose span holds the piece's midpoint and the colour their
/// density-weighted mean; the pieces are composited front to back in closed form (see the
/// [module docs](self)) and the background is added behind. Expects a validated scene;
/// `O(P^2)` in the number of primitives `P`.
pub fn render_ray(scene: &Scene, ray: &Ray) -> ExactPixel {
    let spans: Vec<(Span, &Primitive)> = scene
        .primitives
        .iter()
        .filter_map(|p| span(p, ray).map(|s| (s, p)))
        .collect();
    let mut cuts: Vec<f64> = spans.iter().flat_map(|(s, _)| [s.enter, s.exit]).collect();
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut color = [0.0; 3];
    let (mut optical_depth, mut depth) = (0.0f64, 0.0);
    for w in cuts.windows(2) {
        let (t0, t1) = (w[0], w[1]);
        let mid = 0.5 * (t0 + t1);
        let (mut sigma, mut weighted) = (0.0, [0.0; 3]);
        for (s, p) in &spans {
            if s.enter <= mid && mid < s.exit {
                sigma += p.density();
                for (acc, c) in weighted.iter_mut().zip(p.color()) {
                    *acc += p.density() * c;
                }
            }
        }
        if sigma == 0.0 {
            continue;
        }
        let (length, tau) = (t1 - t0, sigma * (t1 - t0));
        let (through, alpha) = ((-optical_depth).exp(), -(-tau).exp_m1());
        // T alpha c with c = weighted / sigma.
        for (acc, w) in color.iter_mut().zip(weighted) {
            *acc += through * alpha / sigma * w;
        }
        // integral over s in [0, L] of (t0 + s) sigma e^(-sigma s) = t0 alpha + alpha / sigma - L e^(-tau).
        depth += through * (t0 * alpha + alpha / sigma - length * (1.0 - alpha));
        optical_depth += tau;
    }
    let transmittance = (-optical_depth).exp();
    for (acc, bg) in color.iter_mut().zip(scene.background) {
        *acc += transmittance * bg;
    }
    ExactPixel {
        color,
        transmittance,
        depth,
    }
}
