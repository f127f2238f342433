//! The parameter store and shared constants: lending without copies, the buffer pool, the
//! binding of gradients to parameters, and stale or foreign handles.

use std::sync::Arc;

use fogray_tape::params::{ParamError, Params};
use fogray_tape::{Tape, TapeError};
use ndarray::{arr0, arr1, arr2, Array1, ArrayD};

#[test]
fn a_lent_parameter_is_the_stores_array_not_a_copy() {
    let mut params = Params::<f64>::new();
    let w = params.add("w", arr1(&[1.0, -2.0, 3.0])).unwrap();
    let mut tape = Tape::new();
    let x = tape.param_from(&params, w).unwrap();
    assert_eq!(tape.value(x).unwrap().as_ptr(), params.get(w).unwrap().as_ptr());
    assert_eq!(tape.stats().shared_bytes, 3 * 8);
    assert_eq!(tape.stats().value_bytes, 3 * 8);
    // A second loan in the same step is the same value, so the gradient is one entry.
    assert_eq!(tape.param_from(&params, w).unwrap(), x);
    assert_eq!(tape.len(), 1);
    // d/dw sum(w^2) = 2w (by hand).
    let sq = tape.square(x).unwrap();
    let s = tape.sum(sq).unwrap();
    let grads = tape.backward(s).unwrap();
    assert_eq!(grads.param(w).unwrap(), arr1(&[2.0, -4.0, 6.0]).into_dyn());
    assert_eq!(grads.get(x).unwrap(), arr1(&[2.0, -4.0, 6.0]).into_dyn());
    // Handles lent before a clear go stale like any other.
    tape.clear();
    assert!(matches!(tape.value(x), Err(TapeError::StaleVar { .. })));
    assert!(!params.is_lent(w).unwrap());
}

#[test]
fn shared_arrays_never_enter_the_buffer_pool() {
    // 1 MiB each: well above the pool's size threshold, so an owned value would be kept.
    let n = 1 << 17;
    let mut params = Params::<f64>::new();
    let w = params.add("w", Array1::from_elem(n, 0.25)).unwrap();
    let target: Arc<ArrayD<f64>> = Arc::new(Array1::from_elem(n, 1.0).into_dyn());
    let mut tape = Tape::new();
    for _ in 0..3 {
        let x = tape.param_from(&params, w).unwrap();
        let t = tape.constant_shared(&target);
        assert_eq!(tape.value(t).unwrap().as_ptr(), target.as_ptr());
        assert_eq!(tape.stats().shared_bytes, 2 * n * 8);
        let _ = tape.sub(x, t).unwrap();
        tape.clear();
    }
    // Only the op outputs (one per step, reused) are pooled; the store and the caller own
    // their arrays again, untouched.
    assert_eq!(tape.stats().pooled_bytes, n * 8);
    assert_eq!(Arc::strong_count(&target), 1);
    assert!(!params.is_lent(w).unwrap());
    assert!(params.get(w).unwrap().iter().all(|&v| v == 0.25));
    assert!(target.iter().all(|&v| v == 1.0));
}

#[test]
fn a_lent_parameter_cannot_change_until_the_tape_gives_it_back() {
    let mut params = Params::<f32>::new();
    let b = params.add("bias", arr0(0.5f32)).unwrap();
    let mut tape = Tape::new();
    tape.param_from(&params, b).unwrap();
    assert_eq!(
        params.get_mut(b).unwrap_err(),
        ParamError::InUse { name: "bias".into() }
    );
    assert_eq!(params.get(b).unwrap()[[]], 0.5);
    drop(tape); // dropping the tape gives it back as well as clearing it
    params.get_mut(b).unwrap()[[]] = 2.0;
    assert_eq!(params.get(b).unwrap()[[]], 2.0);
}

#[test]
fn ids_of_another_store_are_rejected_and_leave_the_tape_unchanged() {
    let mut a = Params::<f64>::new();
    let mut b = Params::<f64>::new();
    let ia = a.add("w", arr1(&[1.0])).unwrap();
    let ib = b.add("w", arr1(&[2.0])).unwrap();
    assert_eq!(ia.index(), ib.index());
    let mut tape = Tape::new();
    let err = tape.param_from(&a, ib).unwrap_err();
    assert_eq!(err, TapeError::Param(ParamError::ForeignParam { index: 0 }));
    assert!(tape.is_empty());
    assert!(a.get(ib).is_err());
    assert!(a.get_mut(ib).is_err());
    assert!(a.name(ib).is_err());
    // Both stores can lend to one tape; the gradients tell their parameters apart.
    let xa = tape.param_from(&a, ia).unwrap();
    let xb = tape.param_from(&b, ib).unwrap();
    let y = tape.mul(xa, xb).unwrap();
    let s = tape.sum(y).unwrap();
    let grads = tape.backward(s).unwrap();
    assert_eq!(grads.param(ia).unwrap()[[0]], 2.0); // d(ab)/da = b
    assert_eq!(grads.param(ib).unwrap()[[0]], 1.0);
}

#[test]
fn names_are_unique_and_layouts_are_made_standard() {
    let mut params = Params::<f64>::new();
    let m = arr2(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    let t = params.add("t", m.clone().reversed_axes()).unwrap();
    assert_eq!(
        params.add("t", arr0(1.0)).unwrap_err(),
        ParamError::DuplicateName { name: "t".into() }
    );
    assert_eq!(params.len(), 1);
    assert_eq!(params.id("t"), Some(t));
    assert_eq!(params.id("u"), None);
    assert_eq!(params.name(t).unwrap(), "t");
    let got = params.get(t).unwrap();
    assert!(got.is_standard_layout());
    assert_eq!(got, m.t().into_dyn());
    assert_eq!(params.ids().collect::<Vec<_>>(), vec![t]);
    assert_eq!(params.bytes(), 6 * 8);
}
