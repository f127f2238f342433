//! # fogray
//!
//! Differentiable volume rendering in Rust: this facade re-exports the reverse-mode tape
//! ([`tape`], the `fogray-tape` crate), the volume-rendering ops ([`ops`], `fogray-ops`) and
//! the pipeline around a training step ([`fit`], `fogray-fit`), and holds nothing of its own.

pub use fogray_fit as fit;
pub use fogray_ops as ops;
pub use fogray_tape as tape;

/// The README's examples, compiled and run as doctests so that the front page stays true.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// docs/your-own-renderer.md's examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../docs/your-own-renderer.md")]
pub struct YourOwnRendererDoctests;
