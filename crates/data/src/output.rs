//! Safe output: what fogray does to a user's files.
//!
//! - Every file is written whole or not at all ([`write_atomic`], [`AtomicFile`]): to a fresh,
//!   unguessable temporary in the target's folder, opened so that no existing file or link is
//!   ever followed, synced, then renamed over the target. An error, a drop without commit, and
//!   Ctrl-C where the application routes it to [`remove_temporaries_and_exit`] remove the
//!   temporary.
//! - Every output path is checked before the work starts ([`check_outputs`],
//!   [`plan_fit_outputs`]): not one of the command's inputs (a dataset's folder, transforms
//!   files and pictures included), not a folder where a file is expected, in a folder that
//!   takes a new file.
//!
//! ```
//! use fogray_data::{check_outputs, write_atomic, Inputs, Output};
//!
//! let dir = tempfile::tempdir()?;
//! let model = dir.path().join("model.safetensors");
//! std::fs::write(&model, b"weights")?;
//! let inputs = Inputs::new().file(&model);
//! // Writing over the command's own input is refused before any work...
//! let refused = check_outputs(&inputs, &[Output::File(&model)]).unwrap_err();
//! assert!(refused.to_string().contains("refused as an output: it is the input"));
//! // ... a file beside it is not, and is written whole.
//! let mesh = dir.path().join("mesh.ply");
//! check_outputs(&inputs, &[Output::File(&mesh)])?;
//! write_atomic(&mesh, |w| w.write_all(b"ply\n"))?;
//! assert_eq!(std::fs::read(&mesh)?, b"ply\n");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod atomic;
mod check;
mod registry;

pub use atomic::{write_atomic, AtomicFile};
pub use check::{check_outputs, plan_fit_outputs, resolved, Inputs, Output, OutputProblem};
pub use registry::{live_temporaries, remove_temporaries_and_exit};
