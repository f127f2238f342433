//! Every op's error names its op, alone and through the tape, and reads the same both ways.

use fogray_ops::prior::{SparseTotalVariation, TotalVariation};
use fogray_ops::sample::{OccupancyConfig, Spacing, Uniform};
use fogray_ops::{
    hard, Aabb, Composite, CompositeInputs, DensityColor, DistortionLoss, GridBox, GridField, NodeIndex, Op, OpsError,
    ShColor, SparseGridField,
};
use fogray_tape::{Tape, TapeError};
use ndarray::{arr1, arr2, Array2, ArrayD, IxDyn};

/// The error of a call outside the tape names `op`, and its message begins with the op's name.
fn names_alone<T: std::fmt::Debug>(op: Op, r: Result<T, OpsError>) {
    let e = r.unwrap_err();
    assert_eq!(e.op(), op, "{e}");
    assert!(e.to_string().starts_with(&format!("{}: ", op.name())), "{e}");
}

/// Through the tape: the same error whole under the op's name, its message written once.
fn names_through_the_tape<T: std::fmt::Debug>(op: Op, r: Result<T, TapeError>) {
    let e = r.unwrap_err();
    assert!(
        matches!(e, TapeError::Op { op: name, .. } if name == op.name()),
        "{e:?}"
    );
    let typed = e.downcast_ref::<OpsError>().unwrap_or_else(|| panic!("{e:?}"));
    assert_eq!(typed.op(), op, "{e}");
    assert_eq!(e.to_string(), typed.to_string());
    let prefix = format!("{}: ", op.name());
    assert!(e.to_string().starts_with(&prefix), "{e}");
    assert!(!e.to_string()[prefix.len()..].starts_with(&prefix), "{e}");
}

#[test]
fn the_ops_outside_the_tape_name_themselves() {
    names_alone(Op::Composite, Composite::new(&[1, 2]));
    names_alone(Op::FirstHit, hard::first_hit(&[f64::NAN], &[0, 1], 0.5));
    names_alone(Op::DistortionLoss, DistortionLoss::new(&[0, 2, 1]));
    names_alone(Op::GridField, GridBox::new(&[0.0; 3], &[1.0, -1.0, 1.0]));
    names_alone(Op::SparseGridField, NodeIndex::full([1, 4, 4]));
    names_alone(Op::DensityColor, DensityColor::new(f64::NAN));
    names_alone(Op::ShColor, ShColor::new(4));
    names_alone(Op::TotalVariation, TotalVariation::new(-1.0));
    names_alone(Op::Rays, Aabb::new([0.0; 3], [1.0, 1.0, f64::NAN]));
    names_alone(Op::Sample, Uniform::new(Spacing::Count(0)));
    names_alone(Op::Occupancy, OccupancyConfig::density(-1.0));
}

#[test]
fn the_ops_on_the_tape_name_themselves() {
    let mut tape = Tape::<f64>::new();

    let composite = Composite::new(&[0, 1]).unwrap();
    let inputs = CompositeInputs {
        sigma: tape.param(arr1(&[f64::NAN])),
        delta: tape.constant(arr1(&[0.5])),
        color: tape.constant(arr2(&[[0.5]])),
        background: Some(tape.constant(arr1(&[0.0]))),
        t: None,
    };
    names_through_the_tape(Op::Composite, composite.apply(&mut tape, &inputs));
    let target = tape.constant(arr2(&[[0.5]]));
    names_through_the_tape(Op::CompositeMse, composite.apply_mse(&mut tape, &inputs, target));

    let distortion = DistortionLoss::new(&[0, 2]).unwrap();
    let sigma = tape.param(arr1(&[-1.0, 1.0]));
    let delta = tape.constant(arr1(&[0.5, 0.5]));
    let t = tape.constant(arr1(&[0.25, 0.75]));
    names_through_the_tape(Op::DistortionLoss, distortion.apply(&mut tape, sigma, delta, t));

    let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
    let nan_position = tape.constant(arr2(&[[f64::NAN, 0.5, 0.5]]));
    let field = GridField::new(bbox, &[2, 2, 2, 1]).unwrap();
    let grid = tape.param(ArrayD::zeros(IxDyn(&[2, 2, 2, 1])));
    names_through_the_tape(Op::GridField, field.apply(&mut tape, grid, nan_position));
    let sparse = SparseGridField::new(bbox, NodeIndex::full([2, 2, 2]).unwrap(), 1).unwrap();
    let data = tape.param(Array2::zeros((8, 1)));
    names_through_the_tape(Op::SparseGridField, sparse.apply(&mut tape, data, nan_position));

    let raw = tape.param(arr2(&[[f64::NAN, 0.0]]));
    names_through_the_tape(Op::DensityColor, DensityColor::new(0.0).unwrap().apply(&mut tape, raw));

    let coeffs = tape.param(arr2(&[[0.0, 0.0, 0.0]]));
    let long = tape.constant(arr2(&[[2.0, 0.0, 0.0]]));
    names_through_the_tape(Op::ShColor, ShColor::new(0).unwrap().apply(&mut tape, coeffs, long));

    let tv = TotalVariation::new(1.0).unwrap();
    let flat = tape.param(arr1(&[0.0, 1.0, 2.0]));
    names_through_the_tape(Op::TotalVariation, tv.apply(&mut tape, flat));
    let sparse_tv = SparseTotalVariation::new(tv, &sparse);
    names_through_the_tape(Op::SparseTotalVariation, sparse_tv.apply(&mut tape, flat));
}
