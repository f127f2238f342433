//! The integration tests of the `fogray` binary, one module per topic, in one binary (add a
//! module here, not a file beside this one).

mod bad_files;
mod cli;
mod common;
mod disk_room;
mod export;
mod fit_render;
mod fit_view;
mod interrupt;
mod lego;
mod limits;
mod one_line;
mod orbit;
mod outputs;
mod prepare;
mod resume;
mod splats;
mod view;
