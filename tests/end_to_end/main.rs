//! The end-to-end tests of fogray, through the facade a user depends on (`fogray::tape`,
//! `fogray::ops`, `fogray::fit`) and nothing else, one module per topic in one binary (each
//! test file would be a crate of its own that compiles the generic kernels again: add a module
//! here, not a file beside this one). Each crate's own tests stay in its `tests/`.
//!
//! - [`lesson_tables`]: the lesson's worked tables, reproduced by the fused composite and its
//!   taped twin;
//! - [`fused_vs_taped`]: the fused composite against its taped twin, finite differences and
//!   itself across precisions, thread counts and packings;
//! - [`fit_a_ball`]: a whole fit of a known scene, scored on held-out views.
//!
//! The README's examples (and docs/your-own-renderer.md's) are not here: they run as doctests
//! of the facade (`ReadmeDoctests` in src/lib.rs), `cargo test -p fogray --doc`.

mod composite_common;
mod fit_a_ball;
mod fused_vs_taped;
mod lesson_tables;
