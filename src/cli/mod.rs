//! The `fogray` command line.

pub mod composite;
pub mod evaluate;
pub mod gradcheck;
pub mod input;
