//! Volume-rendering ops (not built yet).
