//! The `fogray` command line.

pub mod bandwidth;
pub mod bench;
pub mod composite;
pub mod error;
pub mod evaluate;
pub mod gradcheck;
pub mod grid_bench;
pub mod heap;
pub mod input;
pub mod markdown;
pub mod reference;
pub mod tape_cost;
