//! The code of the `fogray` command line (its contracts are in `docs/cli.md`; the binary is
//! `src/main.rs`), one module per command and what they share; the command line, not this
//! crate's API, is the contract. The measuring commands are `fogray-lab`'s (crates/lab).

pub mod animation;
pub mod composite;
pub mod created_dirs;
pub mod disk_room;
pub mod error;
pub mod evaluate;
pub mod export;
pub mod fit;
pub mod fit_report;
pub mod flag_error;
pub mod framing;
pub mod gradcheck;
pub mod input;
pub mod load_bar;
pub mod memory;
pub mod prepare;
pub mod render;
pub mod render_memory;
pub mod saved;
pub mod view;
