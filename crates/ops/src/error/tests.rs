use fogray_tape::{Tape, TapeError};
use ndarray::{arr1, arr2};

use super::{At, Op, OpsError};
use crate::{Composite, CompositeInputs};

/// A pipeline mixing composite construction, tape ops and the composite's forward.
fn pipeline(offsets: &[usize], sigma0: f64) -> Result<f64, TapeError> {
    let op = Composite::new(offsets)?;
    let mut tape = Tape::<f64>::new();
    let raw = tape.param(arr1(&[sigma0, 1.0]));
    let sigma = tape.mul_scalar(raw, 2.0)?;
    let delta = tape.constant(arr1(&[0.5, 0.5]));
    let color = tape.constant(arr2(&[[1.0], [0.0]]));
    let background = Some(tape.constant(arr1(&[0.0])));
    let out = op.apply(
        &mut tape,
        &CompositeInputs {
            sigma,
            delta,
            color,
            background,
            t: None,
        },
    )?;
    Ok(tape.value(out.color)?[[0, 0]])
}

#[test]
fn question_mark_carries_the_ops_error_whole_through_a_pipeline() {
    // 1 - exp(-2 * 0.5 * 1) of the front sample's colour 1.
    let c = pipeline(&[0, 2], 1.0).unwrap();
    assert!((c - (1.0 - (-1.0f64).exp())).abs() < 1e-15);
    let bad_offsets = pipeline(&[0, 3, 2], 1.0).unwrap_err();
    assert!(matches!(
        bad_offsets.downcast_ref::<OpsError>(),
        Some(OpsError::Offsets { op: Op::Composite, .. })
    ));
    let bad_value = pipeline(&[0, 1, 2], -1.0).unwrap_err();
    match bad_value.downcast_ref::<OpsError>() {
        Some(OpsError::Domain {
            op: Op::Composite,
            at: At::Sample { ray, sample },
            what,
            value,
            ..
        }) => {
            assert_eq!((*ray, *sample), (0, 0));
            assert_eq!((what.as_str(), *value), ("sigma", -2.0));
        }
        other => panic!("{other:?}"),
    }
    // The op's name once, alone and through the tape alike.
    let alone = bad_value.downcast_ref::<OpsError>().unwrap().to_string();
    assert!(alone.starts_with("composite: ray 0, sample 0: sigma is -2"), "{alone}");
    assert_eq!(bad_value.to_string(), alone);
}

#[test]
fn the_tape_error_carries_the_op_name_and_the_same_message() {
    let e = OpsError::config(Op::ShColor, "degree", 4.0, "must be 0, 1, 2 or 3");
    let tape: TapeError = e.clone().into();
    assert!(matches!(tape, TapeError::Op { op: "sh_color", .. }));
    assert_eq!(tape.to_string(), "sh_color: degree is 4 (must be 0, 1, 2 or 3)");
    assert_eq!(tape.downcast_ref::<OpsError>(), Some(&e));
    assert_eq!(e.op(), Op::ShColor);
    assert_eq!(e.clone().in_op(Op::Sample).op(), Op::Sample);
}

#[test]
fn sites_write_where_the_value_sits() {
    let at = |at| OpsError::domain(Op::Sample, at, "t", f64::NAN, "must be finite").to_string();
    assert_eq!(at(At::Value), "sample: t is NaN (must be finite)");
    assert_eq!(at(At::Ray(2)), "sample: ray 2: t is NaN (must be finite)");
    assert_eq!(
        at(At::Sample { ray: 2, sample: 1 }),
        "sample: ray 2, sample 1: t is NaN (must be finite)"
    );
    assert_eq!(at(At::Cell(5)), "sample: cell 5: t is NaN (must be finite)");
    assert_eq!(
        at(At::Entry { row: 3, column: 0 }),
        "sample: row 3, column 0: t is NaN (must be finite)"
    );
}
