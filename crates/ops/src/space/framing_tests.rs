//! Framing from cameras: exact on a ring looking at a point, the fallback for parallel and
//! diverging axes, errors for what cannot be framed.

use super::{axes_meeting_point, framing_from_cameras, RADIUS_PER_MEDIAN_CAMERA_DISTANCE};
use crate::error::OpsError;

/// `n` cameras on a circle of radius `rho` around `target`, tilted by `lift` out of its
/// plane, all looking at `target`.
fn ring(n: usize, target: [f64; 3], rho: f64, lift: f64) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let mut centres = Vec::new();
    let mut axes = Vec::new();
    for k in 0..n {
        let a = k as f64 * std::f64::consts::TAU / n as f64 + 0.3;
        let c = [
            target[0] + rho * a.cos(),
            target[1] + rho * a.sin(),
            target[2] + lift * (2.0 * a).sin(),
        ];
        // Any positive scale of the axis: it is normalised.
        axes.push(std::array::from_fn(|i| 2.5 * (target[i] - c[i])));
        centres.push(c);
    }
    (centres, axes)
}

#[test]
fn cameras_on_a_ring_frame_the_point_they_look_at() {
    let target = [1.0, 2.0, -0.5];
    let (centres, axes) = ring(8, target, 3.0, 0.7);
    let region = framing_from_cameras(&centres, &axes).unwrap();
    for (&got, &want) in region.centre.iter().zip(&target) {
        assert!((got - want).abs() < 1e-12, "{:?}", region.centre);
    }
    // Every camera is at distance sqrt(9 + (0.7 sin 2a)^2) from the target; the median of
    // the eight (sin 2a takes each of its four magnitudes twice).
    let mut d: Vec<f64> = (0..8)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 8.0 + 0.3;
            (9.0 + (0.7 * (2.0 * a).sin()).powi(2)).sqrt()
        })
        .collect();
    d.sort_by(f64::total_cmp);
    let median = 0.5 * (d[3] + d[4]);
    assert!((region.radius - RADIUS_PER_MEDIAN_CAMERA_DISTANCE * median).abs() < 1e-12);
    // Two cameras suffice when their axes cross.
    let two = framing_from_cameras(
        &[[0.0, -2.0, 0.0], [2.0, 0.0, 0.0]],
        &[[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]],
    )
    .unwrap();
    assert!(two.centre.iter().all(|v| v.abs() < 1e-15) && (two.radius - 2.0).abs() < 1e-15);
}

#[test]
fn parallel_axes_fall_back_to_the_mean_of_the_centres() {
    // A forward-facing grid of cameras (LLFF) all looking along +z.
    let mut centres = Vec::new();
    for i in 0..4 {
        for j in 0..3 {
            centres.push([i as f64 * 0.2, j as f64 * 0.1 + 1.0, 0.5]);
        }
    }
    let axes = vec![[0.0, 0.0, 1.0]; centres.len()];
    assert_eq!(axes_meeting_point(&centres, &axes).unwrap(), None);
    let region = framing_from_cameras(&centres, &axes).unwrap();
    let mean = [0.3, 1.1, 0.5];
    assert!(
        (0..3).all(|a| (region.centre[a] - mean[a]).abs() < 1e-14),
        "{:?}",
        region.centre
    );
    // Nearly parallel: each axis tilted by at most 1e-3 rad (reciprocal condition about
    // 1e-6), still the mean.
    let tilted: Vec<[f64; 3]> = (0..centres.len())
        .map(|k| [1e-3 * (k as f64 * 0.7).sin(), 1e-3 * (k as f64 * 1.3).cos(), 1.0])
        .collect();
    assert_eq!(axes_meeting_point(&centres, &tilted).unwrap(), None);
    // A drone flying a line, looking down.
    let line: Vec<[f64; 3]> = (0..10).map(|k| [k as f64, 0.0, 30.0]).collect();
    let down = vec![[0.0, 0.0, -1.0]; 10];
    let region = framing_from_cameras(&line, &down).unwrap();
    assert!((region.centre[0] - 4.5).abs() < 1e-14 && region.centre[2] == 30.0);
    // Distances 0.5, 0.5, 1.5, 1.5, ..., 4.5, 4.5: the median is 2.5.
    assert!((region.radius - 2.5 * RADIUS_PER_MEDIAN_CAMERA_DISTANCE).abs() < 1e-14);
}

#[test]
fn axes_meeting_behind_the_cameras_fall_back() {
    // A ring looking outward: the axes meet at the ring's centre, behind every camera.
    let (centres, inward) = ring(6, [0.0; 3], 2.0, 0.0);
    let outward: Vec<[f64; 3]> = inward.iter().map(|d| d.map(|v| -v)).collect();
    assert_eq!(axes_meeting_point(&centres, &outward).unwrap(), None);
    // The mean of the centres is the ring's centre anyway.
    let region = framing_from_cameras(&centres, &outward).unwrap();
    assert!(region.centre.iter().all(|v| v.abs() < 1e-14));
}

#[test]
fn what_cannot_be_framed_is_an_error() {
    let one = framing_from_cameras(&[[0.0; 3]], &[[0.0, 0.0, 1.0]]).unwrap_err();
    assert!(matches!(one, OpsError::Frame { .. }), "{one}");
    let nan = framing_from_cameras(&[[0.0; 3], [1.0, f64::NAN, 0.0]], &[[0.0, 0.0, 1.0]; 2]).unwrap_err();
    assert!(nan.to_string().contains("row 1, column 1"), "{nan}");
    let inf_axis = framing_from_cameras(
        &[[0.0; 3], [1.0, 0.0, 0.0]],
        &[[0.0, 0.0, 1.0], [f64::INFINITY, 0.0, 0.0]],
    );
    assert!(inf_axis.is_err());
    let zero_axis = framing_from_cameras(&[[0.0; 3], [1.0, 0.0, 0.0]], &[[0.0, 0.0, 1.0], [0.0; 3]]);
    assert!(zero_axis.unwrap_err().to_string().contains("camera 1"));
    let counts = framing_from_cameras(&[[0.0; 3], [1.0, 0.0, 0.0]], &[[0.0, 0.0, 1.0]]);
    assert!(matches!(counts, Err(OpsError::Shape { .. })));
    // Two cameras at one spot looking different ways: their axes meet there, and nothing
    // sizes the region.
    let spot = framing_from_cameras(&[[1.0; 3], [1.0; 3]], &[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]);
    assert!(spot.unwrap_err().to_string().contains("no spread"));
}
