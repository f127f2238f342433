//! # fogray
//!
//! Differentiable volume rendering in Rust: this facade re-exports the reverse-mode tape
//! ([`tape`], the `fogray-tape` crate) and the volume-rendering ops ([`ops`], `fogray-ops`),
//! and holds what the command line (the `fogray-cli` crate) and the examples share
//! ([`machine`]: the memory bandwidth they measure; [`stamp`]: the provenance written at the
//! top of every generated report).

pub use fogray_fit as fit;
pub use fogray_ops as ops;
pub use fogray_tape as tape;

pub mod machine;
pub mod stamp;

/// The README's examples, compiled and run as doctests so that the front page stays true.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// docs/your-own-renderer.md's examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../docs/your-own-renderer.md")]
pub struct YourOwnRendererDoctests;
