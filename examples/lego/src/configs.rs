//! The configurations the report compares: what each adds to `fogray fit`'s defaults.

use serde::Serialize;

/// A run of `fogray fit` on lego.
#[derive(Debug, Clone, Serialize)]
pub struct Config {
    /// Short name (also its folder under runs/).
    pub name: &'static str,
    /// What it is, for the report.
    pub what: &'static str,
    /// Flags beyond `--data`, `--downscale`, `--seconds`, `--json` and `--out`.
    pub flags: &'static str,
    /// Training seconds.
    pub seconds: f64,
}

/// Every configuration, in the order of the report.
pub fn all() -> Vec<Config> {
    let c = |name, what, flags, seconds| Config {
        name,
        what,
        flags,
        seconds,
    };
    vec![
        c(
            "dense-64-sh0",
            "dense 64^3, view-independent colour, prior 1.5e-4 (fogray fit before the model issue)",
            "--model dense --grid 64 --sh-degree 0 --tv 1.5e-4",
            60.0,
        ),
        c(
            "dense-64-sh1",
            "dense 64^3, spherical harmonics degree 1",
            "--model dense --grid 64",
            60.0,
        ),
        c(
            "dense-128-sh1",
            "dense 128^3, spherical harmonics degree 1",
            "--model dense",
            60.0,
        ),
        c(
            "sparse-128-sh1-tv",
            "sparse 128^3, degree 1, prior 1.5e-4",
            "--tv 1.5e-4",
            60.0,
        ),
        c("sparse-128-sh1", "sparse 128^3, degree 1 (the defaults)", "", 60.0),
        c(
            "sparse-128-sh1-300s",
            "sparse 128^3, degree 1 (the defaults), 300 s",
            "",
            300.0,
        ),
        c(
            "sparse-256-sh1-300s",
            "sparse 256^3, degree 1, 300 s",
            "--grid 256",
            300.0,
        ),
    ]
}
