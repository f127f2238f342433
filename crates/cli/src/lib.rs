//! The code of the `fogray` command line (its contracts are in `docs/cli.md`; the binary is
//! `src/main.rs`), one module per command and what they share. A library so that the
//! criterion bench (`benches/composite.rs`) times the very steps `fogray bench` times, on the
//! same rays ([`bench`]); the command line, not this crate's API, is the contract.

pub mod animation;
pub mod bandwidth;
pub mod bench;
pub mod composite;
pub mod error;
pub mod evaluate;
pub mod export;
pub mod fit;
pub mod fit_report;
pub mod flag_error;
pub mod framing;
pub mod gradcheck;
pub mod grid_bench;
pub mod heap;
pub mod input;
pub mod load_bar;
pub mod markdown;
pub mod memory;
pub mod prepare;
pub mod reference;
pub mod render;
pub mod render_memory;
pub mod saved;
pub mod tape_cost;
pub mod view;
