//! The pairs of a sweep's runs that differ in one setting, compared on their curves: fused
//! against taped for every sampling and precision that has both, occupancy against uniform
//! sampling for every method and precision that has both, and every run against an anchor.
//! Each pair is named by [`shared_name`].

use crate::curves::{
    against_anchor, fused_vs_taped, occupancy_vs_uniform, AgainstAnchor, Anchor, CurveError, FusedVsTaped,
    OccupancyVsUniform,
};

use super::config::shared_name;
use super::run::ConfigRun;

/// Fused against taped for every sampling and precision that has both, named by the pair's
/// shared part (`"uniform"`, `"occupancy-f64"`).
///
/// Errors: [`CurveError::Log`] for a log that is not a curve.
pub fn fused_vs_taped_rows(runs: &[ConfigRun]) -> Result<Vec<(String, FusedVsTaped)>, CurveError> {
    let mut rows = Vec::new();
    for f in runs.iter().filter(|r| r.method == "fused") {
        if let Some(t) = runs
            .iter()
            .find(|t| t.method == "taped" && t.sampling == f.sampling && t.precision == f.precision)
        {
            rows.push((shared_name(f.sampling, f.precision), fused_vs_taped(&f.log, &t.log)?));
        }
    }
    Ok(rows)
}

/// Occupancy against uniform for every method and precision that has both, `batch` rays per
/// step.
///
/// Errors: [`CurveError::Log`] for a log that is not a curve, or a `batch` of 0.
pub fn occupancy_vs_uniform_rows(
    runs: &[ConfigRun],
    batch: usize,
) -> Result<Vec<(String, OccupancyVsUniform)>, CurveError> {
    let mut rows = Vec::new();
    for o in runs.iter().filter(|r| r.sampling == "occupancy") {
        if let Some(u) = runs
            .iter()
            .find(|u| u.sampling == "uniform" && u.method == o.method && u.precision == o.precision)
        {
            rows.push((
                shared_name(o.method, o.precision),
                occupancy_vs_uniform(&o.log, &u.log, batch)?,
            ));
        }
    }
    Ok(rows)
}

/// Every configuration against the anchor, at the anchor's final test PSNR. Errors:
/// [`CurveError::Log`] for a log that is not a curve.
pub fn anchor_rows(runs: &[ConfigRun], anchor: &Anchor) -> Result<Vec<(String, AgainstAnchor)>, CurveError> {
    let entries = anchor.entries();
    runs.iter()
        .map(|r| Ok((r.name.clone(), against_anchor(&r.log, &entries)?)))
        .collect()
}
