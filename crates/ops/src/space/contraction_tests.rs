//! The contraction against its closed forms, its inverse, and f64 finite differences.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::{Contraction, InnerRegion};

const C: [f64; 3] = [0.5, -1.0, 2.0];
const R: f64 = 1.5;

fn space() -> Contraction {
    Contraction::new(InnerRegion::new(C, R).unwrap()).unwrap()
}

/// The world point of normalised point `u`: `c + r u`.
fn world(u: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|a| C[a] + R * u[a])
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
}

#[test]
fn inside_the_inner_region_the_map_is_the_identity_on_u() {
    let s = space();
    let mut rng = StdRng::seed_from_u64(1);
    for _ in 0..200 {
        let u: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..=1.0));
        assert!(close(s.contract(world(u)), u, 1e-15), "{u:?}");
    }
    // The inner region's corner is its own image.
    assert!(close(s.contract(world([1.0, -1.0, 1.0])), [1.0, -1.0, 1.0], 1e-15));
}

#[test]
fn face_edge_and_corner_points_by_hand() {
    let s = space();
    // Face: u = (3, 0.5, 0), m = 3, y = (2 - 1/3) u / 3 = (5/3, 5/18, 0).
    let y = s.contract(world([3.0, 0.5, 0.0]));
    assert!(close(y, [5.0 / 3.0, 5.0 / 18.0, 0.0], 1e-15), "{y:?}");
    // Edge (two axes tie): u = (3, -3, 1), y = (5/3) (1, -1, 1/3).
    let y = s.contract(world([3.0, -3.0, 1.0]));
    assert!(close(y, [5.0 / 3.0, -5.0 / 3.0, 5.0 / 9.0], 1e-15), "{y:?}");
    // Corner: u = (-4, 4, 4), m = 4, y = (7/4) (-1, 1, 1).
    let y = s.contract(world([-4.0, 4.0, 4.0]));
    assert!(close(y, [-1.75, 1.75, 1.75], 1e-15), "{y:?}");
    // Just outside a face: u = (1 + e, 0.2, 0): y_0 = 2 - 1/(1 + e) = 1 + e - e^2 + ..,
    // y_1 = 0.2 (2 - 1/(1 + e)) / (1 + e) = 0.2 (1 - e^2 + ..).
    let e = 1e-6;
    let y = s.contract(world([1.0 + e, 0.2, 0.0]));
    assert!((y[0] - (1.0 + e - e * e)).abs() < 1e-15 && (y[1] - 0.2 * (1.0 - e * e)).abs() < 1e-15);
}

#[test]
fn infinity_maps_onto_the_faces() {
    let s = space();
    // Along v, y -> 2 v / ||v||_inf, approached like 2 - 1/m.
    let v = [0.3, -0.6, 0.15];
    let limit = [1.0, -2.0, 0.5];
    for t in [1e3, 1e8, 1e15, 1e100, 1e300] {
        let x = std::array::from_fn(|a| C[a] + t * v[a]);
        let y = s.contract(x);
        // m = 0.6 t / r; |y - limit| = |v / ||v||_inf| / m at most.
        let m = 0.6 * t / R;
        assert!(close(y, limit, 1.0 / m + 1e-15), "{t}: {y:?}");
    }
    assert_eq!(s.contract([f64::INFINITY, 0.0, f64::NEG_INFINITY]), [2.0, 0.0, -2.0]);
    // The largest f32: on the face, the other coordinates (x_j - c_j) / x_0 of order 1e-38.
    let y = s.contract([f32::MAX, 0.0, 0.0]);
    assert!(y[0] == 2.0 && y[1].abs() < 1e-37 && y[2].abs() < 1e-37, "{y:?}");
    // -MAX - c overflows: the offset is halved, the image is still the face's centre.
    assert_eq!(s.contract([0.0, -f64::MAX, 0.0])[1], -2.0);
    assert!(s.contract([f64::NAN, 0.0, 0.0]).iter().all(|v| v.is_nan()));
}

#[test]
fn a_naive_form_fails_where_this_one_does_not() {
    // The naive u (2 m - 1) / m^2 squares m: beyond sqrt(f32::MAX) (about 1.8e19) m^2 is
    // infinite in f32 and the far point lands on the centre of the cube instead of a face.
    let naive = |u: [f32; 3]| {
        let m = u.iter().fold(0f32, |a, v| a.max(v.abs()));
        u.map(|v| (2.0 * m - 1.0) / (m * m) * v)
    };
    let u = [1e20f32, 5e19, 0.0];
    assert_eq!(naive(u), [0.0, 0.0, 0.0]);
    let s = Contraction::new(InnerRegion::new([0.0; 3], 1.0).unwrap()).unwrap();
    assert_eq!(s.contract(u), [2.0, 1.0, 0.0]);
    // And a branch-free form that evaluates (2 - 1/m) u / m everywhere (a `where` over both
    // branches) divides 0 by 0 at the centre: NaN, where this one gives the centre.
    let both_branches = |u: [f64; 3]| {
        let m = u.iter().fold(0f64, |a, v| a.max(v.abs()));
        let outer = u.map(|v| (2.0 - 1.0 / m) * v / m);
        let inner = u;
        (outer, inner)
    };
    let (outer, _) = both_branches([0.0; 3]);
    assert!(outer[0].is_nan());
    assert_eq!(s.contract([0.0f64; 3]), [0.0; 3]);
}

#[test]
fn the_inverse_undoes_the_map() {
    let s = space();
    let mut rng = StdRng::seed_from_u64(2);
    for _ in 0..2000 {
        // m up to 100: the inverse's error grows like eps m (see `inverse`).
        let m: f64 = 10f64.powf(rng.gen_range(-1.0..2.0));
        let u: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..=1.0));
        let n = u.iter().fold(0f64, |a, v| a.max(v.abs()));
        let u = u.map(|v| v / n * m);
        let x = world(u);
        let back = s.inverse(s.contract(x)).unwrap();
        let scale = (m * R).max(R);
        assert!(close(back, x, 1e-12 * scale), "{x:?} -> {back:?}");
    }
    assert_eq!(s.inverse([2.0, 0.0, 0.0f64]), None);
    assert_eq!(s.inverse([f64::NAN, 0.0, 0.0]), None);
    // The inverse of the closed-form face point above.
    let x = s.inverse([5.0 / 3.0, 5.0 / 18.0, 0.0]).unwrap();
    assert!(close(x, world([3.0, 0.5, 0.0]), 1e-14));
}

/// Central finite differences of the contraction at `x` in f64, along the unit axes.
fn numeric_jacobian(s: &Contraction, x: [f64; 3], h: f64) -> [[f64; 3]; 3] {
    let mut j = [[0.0; 3]; 3];
    for col in 0..3 {
        let mut p = x;
        let mut q = x;
        p[col] += h;
        q[col] -= h;
        let (yp, yq) = (s.contract(p), s.contract(q));
        for row in 0..3 {
            j[row][col] = (yp[row] - yq[row]) / (2.0 * h);
        }
    }
    j
}

fn max_diff(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> f64 {
    (0..9)
        .map(|k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs())
        .fold(0.0, f64::max)
}

#[test]
fn the_jacobian_matches_central_differences_in_every_region() {
    let s = space();
    let points = [
        [0.1, -0.3, 0.7],       // inner
        [1.0 - 1e-4, 0.2, 0.0], // inner, near a face
        [1.0 + 1e-4, 0.2, 0.0], // outer, near a face
        [1.0, 0.5, -0.5],       // on the face (J continuous: I / r from both sides)
        [1.0, 1.0, 1.0],        // on the inner region's corner (likewise)
        [3.0, 0.5, -1.0],       // +x region
        [0.5, -7.0, 2.0],       // -y region
        [0.2, 0.3, 40.0],       // far +z region
        [-2.5, 2.4, -2.45],     // -x region near the diagonals
    ];
    for u in points {
        let x = world(u);
        let m = u.iter().fold(0f64, |a, v| a.max(v.abs()));
        // A step well inside the point's region (away from the diagonals at 2.4 / 2.45 /
        // 2.5 and the face at m = 1 +- 1e-4); the map is smooth there except across m = 1,
        // where only its second derivative jumps (error O(h) / r).
        let h = 1e-7 * R * m.max(1.0);
        let j = s.jacobian(x);
        let fd = numeric_jacobian(&s, x, h);
        assert!(max_diff(j, fd) < 1e-7, "{u:?}: {j:?} vs {fd:?}");
    }
}

#[test]
fn on_a_diagonal_the_jacobian_is_the_lowest_axis_one_sided_one() {
    let s = space();
    // u = (3, -3, 1): axes 0 and 1 tie. The map is not differentiable there; `jacobian`
    // returns axis 0's side, the limit from where |u_0| > |u_1|.
    let u = [3.0, -3.0, 1.0];
    let j = s.jacobian(world(u));
    // One-sided differences into axis 0's side: move by +h along x (|u_0| grows) and by
    // +h along y (|u_1| shrinks), and for z either way (z never takes the max here).
    let h = 1e-7;
    let y0 = s.contract(world(u));
    for (col, dir) in [(0, 1.0), (1, 1.0), (2, 1.0)] {
        let mut p = world(u);
        p[col] += dir * h;
        let yp = s.contract(p);
        for row in 0..3 {
            let fd = (yp[row] - y0[row]) / (dir * h);
            assert!(
                (fd - j[row][col]).abs() < 1e-6,
                "row {row}, col {col}: {fd} vs {}",
                j[row][col]
            );
        }
    }
    // By hand: m = 3, w = 1/3, s = +1, e = (1, -1, 1/3):
    // J[0][0] = w^2 / r, J[1][1] = J[2][2] = w (2 - w) / r, J[1][0] = -2 e_1 w (1 - w) / r.
    let w = 1.0 / 3.0;
    assert!((j[0][0] - w * w / R).abs() < 1e-15);
    assert!((j[1][1] - w * (2.0 - w) / R).abs() < 1e-15);
    assert!((j[1][0] - 2.0 * w * (1.0 - w) / R).abs() < 1e-15);
    assert!((j[2][0] + 2.0 / 3.0 * w * (1.0 - w) / R).abs() < 1e-15);
    // From the other side (axis 1's) the derivative along y differs: d y_1 / d u_1 = w^2
    // there, not w (2 - w): the map has a kink across the diagonal plane.
    let mut p = world(u);
    p[1] -= h; // |u_1| grows
    let fd = (s.contract(p)[1] - y0[1]) / -h;
    assert!((fd - w * w / R).abs() < 1e-6, "{fd}");
}

#[test]
fn the_map_is_continuous_across_the_inner_faces() {
    let s = space();
    let mut rng = StdRng::seed_from_u64(3);
    for _ in 0..200 {
        let mut u: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..=1.0));
        let axis = rng.gen_range(0..3);
        u[axis] = if rng.gen::<bool>() { 1.0 } else { -1.0 };
        let e = 1e-9;
        let (inside, outside) = (world(u.map(|v| v * (1.0 - e))), world(u.map(|v| v * (1.0 + e))));
        // |y(outside) - y(inside)| <= |J| |dx| = 2 e (J = I / r on both sides, |dx| = 2 e r |u|).
        assert!(close(s.contract(inside), s.contract(outside), 2.0 * e + 1e-15));
        let dj = max_diff(s.jacobian(inside), s.jacobian(outside));
        assert!(dj < 1e-8, "{dj}");
    }
}

#[test]
fn f32_agrees_with_f64() {
    let s = space();
    let mut rng = StdRng::seed_from_u64(4);
    for _ in 0..500 {
        let x: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-30.0..30.0));
        let x32 = x.map(|v| v as f32);
        let y64 = s.contract(x32.map(f64::from));
        let y32 = s.contract(x32);
        assert!(close(y32.map(f64::from), y64, 1e-6), "{y32:?} {y64:?}");
        let j64 = s.jacobian(x32.map(f64::from));
        let j32 = s.jacobian(x32).map(|r| r.map(f64::from));
        assert!(max_diff(j32, j64) < 1e-6);
    }
}

#[test]
fn max_stretch_bounds_the_world_length_of_a_contracted_unit() {
    let s = space();
    // Inside: exactly r.
    assert_eq!(s.max_stretch(0.5), R);
    assert_eq!(s.max_stretch(1.0), R);
    assert_eq!(s.max_stretch(2.0), f64::INFINITY);
    // Continuous at the inner boundary and rising.
    assert!((s.max_stretch(1.0 + 1e-9) - R).abs() < 1e-7);
    let mut previous = R;
    for k in 1..1000 {
        let n = 1.0 + k as f64 / 1000.0;
        let g = s.max_stretch(n);
        assert!(g >= previous, "{n}");
        previous = g;
    }
    // 1 / |J v| for unit v, at random points and directions, never exceeds the bound at
    // the point's contracted norm; along a face axis it is r m^2 (J[i][i] = w^2 / r),
    // within sqrt(3) of the bound.
    let mut rng = StdRng::seed_from_u64(5);
    for _ in 0..5000 {
        let u: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-8.0..8.0));
        let x = world(u);
        let n = s.contract(x).iter().fold(0f64, |a, v| a.max(v.abs()));
        let j = s.jacobian(x);
        let v: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let len = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let jv: [f64; 3] = std::array::from_fn(|r| (0..3).map(|c| j[r][c] * v[c] / len).sum());
        let stretch = 1.0 / jv.iter().map(|a| a * a).sum::<f64>().sqrt();
        assert!(stretch <= s.max_stretch(n) * (1.0 + 1e-12), "{u:?}");
    }
    let m: f64 = 5.0;
    let radial = R * m * m;
    let bound = s.max_stretch(2.0 - 1.0 / m);
    assert!(bound >= radial && bound <= 3f64.sqrt() * radial, "{bound} vs {radial}");
}

#[test]
fn bad_regions_are_errors() {
    assert!(InnerRegion::new([0.0, f64::NAN, 0.0], 1.0).is_err());
    assert!(InnerRegion::new([0.0; 3], 0.0).is_err());
    assert!(InnerRegion::new([0.0; 3], f64::INFINITY).is_err());
    let bad = InnerRegion {
        centre: [0.0; 3],
        radius: -1.0,
    };
    let e = Contraction::new(bad).unwrap_err();
    assert!(e.to_string().starts_with("contraction: "), "{e}");
}
