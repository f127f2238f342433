//! The built-in ops, one family per file. Each is a [`CustomOp`](crate::CustomOp) like any
//! user's op, plus a `Tape` method that applies it.

pub mod activation;
pub mod binary;
pub mod index;
pub mod matmul;
pub mod reduce;
pub mod segment;
pub mod select;
pub mod shape;
pub mod unary;

use crate::float::Float;

/// `g * d` with the strong-zero convention: a zero upstream gradient contributes exactly zero,
/// even where the local derivative `d` is infinite or NaN (a masked `sqrt(0)`, say).
#[inline]
pub(crate) fn strong_mul<F: Float>(g: F, d: F) -> F {
    if g == F::zero() {
        F::zero()
    } else {
        g * d
    }
}

#[cfg(test)]
pub(crate) mod test_util;
