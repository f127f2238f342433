//! Branch-free scalar kernels shared by the ops, written so that a loop over a slice
//! vectorises: `exp(-x)` and `-expm1(-x)` ([`exp`]), and the logistic family built on them,
//! `softplus`, `sigmoid` and the sigmoid's slope ([`logistic`]).
//!
//! Every kernel computes in f64 and has two tiers chosen at compile time: the double tier,
//! within a few ulp of the C library, and the `SINGLE` tier for f32 data, with shorter
//! polynomials whose error is far below an f32 rounding.

pub(crate) mod exp;
pub(crate) mod logistic;
