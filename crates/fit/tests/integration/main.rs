//! fogray-fit's integration tests, one module per topic, in one binary (every test file would
//! be a crate of its own that compiles the generic kernels again: add a module here, not a file
//! beside this one). They use the crate as a user does, through its public paths only; the
//! tests that reach internals are unit tests beside the module they test (the fits of small
//! synthetic datasets share `crate::testing`); the fits of a real scene are the examples' tests.

mod depth;
