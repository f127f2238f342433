//! The sealed float trait that makes the tape generic over `f32` and `f64`.

use std::fmt::{Debug, Display};
use std::iter::Sum;
use std::ops::{AddAssign, MulAssign, SubAssign};

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// The element type of every tape value: implemented for `f32` and `f64` only.
///
/// The trait is sealed so that kernels may rely on IEEE binary32/binary64 semantics
/// (rounding, `expm1`, subnormals) without caring about exotic user types.
pub trait Float:
    num_traits::Float
    + ndarray::ScalarOperand
    + ndarray::LinalgScalar
    + AddAssign
    + SubAssign
    + MulAssign
    + Sum
    + Default
    + Debug
    + Display
    + Send
    + Sync
    + 'static
    + sealed::Sealed
{
    /// `"f32"` or `"f64"`, for messages and reports.
    const NAME: &'static str;

    /// Converts an `f64` literal, rounding to nearest (so kernels need no `F::from(x).unwrap()`).
    fn lit(x: f64) -> Self;

    /// Widens (or keeps) the value as an `f64`; exact for both types.
    fn as_f64(self) -> f64;
}

impl Float for f32 {
    const NAME: &'static str = "f32";
    #[inline]
    fn lit(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn as_f64(self) -> f64 {
        f64::from(self)
    }
}

impl Float for f64 {
    const NAME: &'static str = "f64";
    #[inline]
    fn lit(x: f64) -> Self {
        x
    }
    #[inline]
    fn as_f64(self) -> f64 {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::Float;

    #[test]
    fn lit_rounds_to_nearest_and_widening_is_exact() {
        // 0.1 is not representable; f32 rounds it to 13421773 * 2^-27.
        assert_eq!(f32::lit(0.1).as_f64(), 13_421_773.0 * 2f64.powi(-27));
        assert_eq!(f64::lit(0.1), 0.1);
        assert_eq!(<f32 as Float>::NAME, "f32");
    }
}
