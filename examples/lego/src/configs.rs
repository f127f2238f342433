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
            "dense 64^3, view-independent colour, prior, fixed background (fogray fit before the model issue)",
            "--model dense --grid 64 --sh-degree 0 --tv 1.5e-4 --random-background false",
            60.0,
        ),
        c(
            "dense-64-sh1",
            "dense 64^3, spherical harmonics degree 1, prior, fixed background (the previous defaults)",
            "--model dense --grid 64 --tv 1.5e-4 --random-background false",
            60.0,
        ),
        c("dense-128-sh1", "dense 128^3, degree 1", "--model dense", 60.0),
        c(
            "sparse-128-fixed-background",
            "sparse 128^3, degree 1, fixed background",
            "--random-background false",
            60.0,
        ),
        c(
            "sparse-128-tv",
            "sparse 128^3, degree 1, prior 1.5e-4",
            "--tv 1.5e-4",
            60.0,
        ),
        c(
            "sparse-128-no-distortion",
            "sparse 128^3, degree 1, no distortion loss",
            "--distortion 0",
            60.0,
        ),
        c(
            "sparse-128",
            "sparse 128^3, degree 1, distortion loss 0.01 (the defaults)",
            "",
            60.0,
        ),
        c(
            "sparse-128-distortion-0.1",
            "sparse 128^3, degree 1, distortion loss 0.1",
            "--distortion 0.1",
            60.0,
        ),
        c(
            "sparse-128-300s",
            "sparse 128^3, degree 1, distortion 0.01, 300 s (the defaults of a short fit)",
            "--grid 128",
            300.0,
        ),
        c(
            "sparse-192-300s-no-distortion",
            "sparse 192^3, degree 1, no distortion loss, 300 s",
            "--distortion 0",
            300.0,
        ),
        c(
            "sparse-192-300s",
            "sparse 192^3, degree 1, distortion 0.01, 300 s (the defaults: a long fit grows to 192^3)",
            "",
            300.0,
        ),
        c(
            "sparse-256-300s",
            "sparse 256^3, degree 1, distortion 0.01, 300 s",
            "--grid 256",
            300.0,
        ),
    ]
}
