//! Which fits a sweep runs: a method, a sampling and a precision, named
//! `METHOD-SAMPLING[-PRECISION]` (`fused-uniform`, `taped-occupancy`, `fused-uniform-f64`).

use std::fmt;
use std::str::FromStr;

use fogray_fit::settings::{Method, Precision, Sampling};

use super::SweepError;

/// One configuration of a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunConfig {
    /// Fused ops or taped twins.
    pub method: Method,
    /// Uniform or occupancy sampling.
    pub sampling: Sampling,
    /// The model's and the render's float type.
    pub precision: Precision,
}

/// The default configurations of a sweep: fused and taped, uniform and occupancy, all in f32.
pub const DEFAULT_CONFIGS: [RunConfig; 4] = [
    RunConfig::f32(Method::Fused, Sampling::Uniform),
    RunConfig::f32(Method::Taped, Sampling::Uniform),
    RunConfig::f32(Method::Fused, Sampling::Occupancy),
    RunConfig::f32(Method::Taped, Sampling::Occupancy),
];

impl RunConfig {
    /// An f32 configuration.
    pub const fn f32(method: Method, sampling: Sampling) -> Self {
        RunConfig {
            method,
            sampling,
            precision: Precision::F32,
        }
    }
}

impl fmt::Display for RunConfig {
    /// The name that [`RunConfig::from_str`] reads back (`-f32` left out).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}-{}", self.method.name(), self.sampling.name())?;
        match self.precision {
            Precision::F32 => Ok(()),
            Precision::F64 => write!(f, "-f64"),
        }
    }
}

impl FromStr for RunConfig {
    type Err = SweepError;

    /// Reads `METHOD-SAMPLING[-PRECISION]`: `fused|taped`, `uniform|occupancy`, `f32|f64`
    /// (f32 if absent). Error: [`SweepError::Config`] naming what is wrong.
    fn from_str(name: &str) -> Result<Self, SweepError> {
        let bad = |what: &str| {
            SweepError::Config(format!(
                "configuration {name:?}: {what} (expected METHOD-SAMPLING[-PRECISION], e.g. fused-uniform or taped-occupancy-f64)"
            ))
        };
        let parts: Vec<&str> = name.split('-').collect();
        if !(2..=3).contains(&parts.len()) {
            return Err(bad("two or three parts"));
        }
        let method = match parts[0] {
            "fused" => Method::Fused,
            "taped" => Method::Taped,
            _ => return Err(bad("the method is fused or taped")),
        };
        let sampling = match parts[1] {
            "uniform" => Sampling::Uniform,
            "occupancy" => Sampling::Occupancy,
            _ => return Err(bad("the sampling is uniform or occupancy")),
        };
        let precision = match parts.get(2) {
            None | Some(&"f32") => Precision::F32,
            Some(&"f64") => Precision::F64,
            Some(_) => return Err(bad("the precision is f32 or f64")),
        };
        Ok(RunConfig {
            method,
            sampling,
            precision,
        })
    }
}

/// The name of a pair of configurations that differ in one setting: the setting they share
/// (`part`, such as `"uniform"` for fused against taped) and the precision they share, left out
/// for `"f32"` (`"uniform"`, `"occupancy-f64"`).
pub fn shared_name(part: &str, precision: &str) -> String {
    if precision == "f32" {
        part.to_string()
    } else {
        format!("{part}-{precision}")
    }
}
