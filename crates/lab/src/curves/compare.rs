//! Two runs' curves set against each other at a test PSNR both reach: how much sooner the
//! fused ops reach what the taped twins reach, how many samples per ray occupancy sampling
//! spends against uniform sampling for the same test PSNR, and how much sooner a run reaches
//! what an outside pipeline (an [`Anchor`](super::Anchor)) ends at.

use serde::Serialize;

use fogray_fit::train::LogEntry;

use super::reach::{final_psnr, reach, Reach};
use super::CurveError;

/// Fused against taped at the taped run's final test PSNR, or at the fused run's if that is
/// lower (on the same steps the two differ only by rounding, and either may end a hair above).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FusedVsTaped {
    /// min(taped final PSNR, fused final PSNR) (dB).
    pub target_psnr: f64,
    /// Where the fused run first reached it.
    pub fused: Reach,
    /// Where the taped run first reached it.
    pub taped: Reach,
    /// Taped seconds over fused seconds to the target; `None` if the fused run was there at
    /// 0 s.
    pub speedup: Option<f64>,
}

/// Occupancy against uniform sampling at the lower of their two final test PSNRs (both runs
/// reach it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OccupancyVsUniform {
    /// min(final PSNR of each) (dB).
    pub target_psnr: f64,
    /// Where the occupancy run first reached it.
    pub occupancy: Reach,
    /// Where the uniform run first reached it.
    pub uniform: Reach,
    /// Mean samples per training ray of the occupancy run up to the target (`None` if reached
    /// at step 0).
    pub occupancy_samples_per_ray: Option<f64>,
    /// The same for the uniform run.
    pub uniform_samples_per_ray: Option<f64>,
    /// Occupancy samples per ray over uniform samples per ray.
    pub samples_per_ray_ratio: Option<f64>,
    /// Uniform seconds over occupancy seconds to the target (`None` if the occupancy run was
    /// there at 0 s).
    pub speedup: Option<f64>,
}

fn ratio(num: f64, den: f64) -> Option<f64> {
    (den > 0.0 && num.is_finite() && den.is_finite()).then(|| num / den)
}

/// How much sooner `fused` reached the final test PSNR of `taped` (see [`FusedVsTaped`]).
///
/// Errors: [`CurveError::Log`] for a log that is empty, not in time order, or has a NaN PSNR.
pub fn fused_vs_taped(fused: &[LogEntry], taped: &[LogEntry]) -> Result<FusedVsTaped, CurveError> {
    let target = final_psnr(taped)?.min(final_psnr(fused)?);
    let missing = || CurveError::Log("a run misses its own final PSNR".into());
    let t = reach(taped, target)?.ok_or_else(missing)?;
    let f = reach(fused, target)?.ok_or_else(missing)?;
    Ok(FusedVsTaped {
        target_psnr: target,
        fused: f,
        taped: t,
        speedup: ratio(t.seconds, f.seconds),
    })
}

/// Samples per ray and seconds of `occupancy` and `uniform` (both with `batch` rays per step)
/// to the lower of their final test PSNRs.
///
/// Errors: [`CurveError::Log`] as for [`fused_vs_taped`], or a `batch` of 0.
pub fn occupancy_vs_uniform(
    occupancy: &[LogEntry],
    uniform: &[LogEntry],
    batch: usize,
) -> Result<OccupancyVsUniform, CurveError> {
    if batch == 0 {
        return Err(CurveError::Log("the batch must be at least 1 ray".into()));
    }
    let target = final_psnr(occupancy)?.min(final_psnr(uniform)?);
    let missing = || CurveError::Log("a run misses its own final PSNR".into());
    let o = reach(occupancy, target)?.ok_or_else(missing)?;
    let u = reach(uniform, target)?.ok_or_else(missing)?;
    let (os, us) = (o.samples_per_ray(batch), u.samples_per_ray(batch));
    Ok(OccupancyVsUniform {
        target_psnr: target,
        occupancy: o,
        uniform: u,
        occupancy_samples_per_ray: os,
        uniform_samples_per_ray: us,
        samples_per_ray_ratio: os.zip(us).and_then(|(o, u)| ratio(o, u)),
        speedup: ratio(u.seconds, o.seconds),
    })
}

/// A configuration against an outside pipeline (an [`Anchor`](super::Anchor)) at the
/// test PSNR the anchor ends at.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AgainstAnchor {
    /// The anchor's final test PSNR (dB).
    pub target_psnr: f64,
    /// Where the anchor first reached it.
    pub anchor: Reach,
    /// Where the configuration first reached it; `None` if it never did.
    pub run: Option<Reach>,
    /// Anchor seconds over the configuration's seconds to the target; `None` if the
    /// configuration never reached it or was there at 0 s.
    pub speedup: Option<f64>,
}

/// How much sooner `run` reached the final test PSNR of `anchor` (see [`AgainstAnchor`]).
///
/// Errors: [`CurveError::Log`] for a log that is empty, not in time order, or has a NaN PSNR.
pub fn against_anchor(run: &[LogEntry], anchor: &[LogEntry]) -> Result<AgainstAnchor, CurveError> {
    let target = final_psnr(anchor)?;
    let a = reach(anchor, target)?.ok_or_else(|| CurveError::Log("the anchor misses its own final PSNR".into()))?;
    let r = reach(run, target)?;
    Ok(AgainstAnchor {
        target_psnr: target,
        anchor: a,
        run: r,
        speedup: r.and_then(|r| ratio(a.seconds, r.seconds)),
    })
}
