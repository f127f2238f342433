//! Ctrl-C as a stop flag: a long fit checks it before each step, finishes the step under way
//! and returns what it has, so that the caller can save it. Commands with nothing to save
//! exit instead, leaving no temporary file behind ([`exit_on_ctrl_c`]).
//!
//! ```no_run
//! use fogray_fit::interrupt::StopFlag;
//!
//! let stop = StopFlag::on_ctrl_c()?;
//! // ... fit_from(&data, &settings, None, Some(stop.flag()), &mut |_| {}) ...
//! # Ok::<(), fogray_fit::FitError>(())
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::error::FitError;

/// The exit status of a command stopped by Ctrl-C: 128 + SIGINT, as a shell reports it.
pub const INTERRUPTED_STATUS: i32 = 130;

/// Has Ctrl-C (SIGINT) end the process at once with [`INTERRUPTED_STATUS`], after removing
/// every temporary file it is writing ([`fogray_data::remove_temporaries_and_exit`]): for
/// commands with nothing to save (a render, an export), which then leave whole files only.
///
/// Errors: [`FitError::CtrlC`] if the process's handler is already set (once a process).
pub fn exit_on_ctrl_c() -> Result<(), FitError> {
    ctrlc::set_handler(|| {
        fogray_data::remove_temporaries_and_exit(INTERRUPTED_STATUS);
    })
    .map_err(|e| FitError::CtrlC { reason: e.to_string() })
}

/// A flag raised by Ctrl-C (or by [`StopFlag::raise`]); `StopFlag::default()` is one that
/// nothing raises but [`StopFlag::raise`].
#[derive(Debug, Clone, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag that Ctrl-C raises (SIGINT; SIGTERM too on Unix where the `ctrlc` crate
    /// catches it).
    ///
    /// Errors: [`FitError::CtrlC`] if the process's handler is already set (once a process).
    pub fn on_ctrl_c() -> Result<Self, FitError> {
        let stop = StopFlag::default();
        let flag = Arc::clone(&stop.0);
        ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
            .map_err(|e| FitError::CtrlC { reason: e.to_string() })?;
        Ok(stop)
    }

    /// The flag, as [`fit_from`](crate::train::fit_from) takes it.
    pub(crate) fn flag(&self) -> &AtomicBool {
        &self.0
    }

    /// Raises the flag.
    pub fn raise(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether the flag is raised.
    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}
