//! What a fit's settings are checked against before anything is built (ranges, budgets that
//! end, the machine's memory), and how a resumed fit's settings take the flags given.

use fogray_ops::limits::{self, Bytes, GridShape};
use serde_json::{Map, Value};

use super::{Budget, FitSettings, ModelKind, MAX_EVALUATIONS, MAX_SECONDS, MAX_STEPS};
use crate::error::FitError;

impl FitSettings {
    /// Checks every setting's range, the budget against its caps (of seconds, and of steps:
    /// [`MAX_STEPS`]), the evaluations against theirs, and the grid and batch against the
    /// machine's memory.
    ///
    /// Errors: [`FitError::Setting`] naming the flag, [`FitError::BoxAxis`] or
    /// [`FitError::BoxBeyondRange`] for `--box`, [`FitError::TooLarge`] naming the flag and
    /// the bytes it would need.
    pub fn check(&self) -> Result<(), FitError> {
        let bad = |flag: &'static str, rule: &str| {
            Err(FitError::Setting {
                flag,
                value: None,
                rule: rule.into(),
            })
        };
        if self.grid < 2 {
            return bad("--grid", "must be at least 2");
        }
        if self.batch == 0 {
            return bad("--batch", "must be at least 1");
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("--lr", "must be finite and positive");
        }
        if !(self.lr_final.is_finite() && self.lr_final > 0.0) {
            return bad("--lr-final", "must be finite and positive");
        }
        if !(self.tv.is_finite() && self.tv >= 0.0) {
            return bad("--tv", "must be finite and non-negative");
        }
        if !self.shift.is_finite() {
            return bad("--shift", "must be finite");
        }
        if !(self.distortion.is_finite() && self.distortion >= 0.0) {
            return bad("--distortion", "must be finite and non-negative");
        }
        if self.sh_degree > 3 {
            return bad("--sh-degree", "must be 0, 1, 2 or 3");
        }
        if self.background_degree > 3 {
            return bad("--background-degree", "must be 0, 1, 2 or 3");
        }
        if let Some(b) = self.scene_box {
            b.check()?;
        }
        if self.evaluations > MAX_EVALUATIONS {
            return Err(FitError::Setting {
                flag: "--evaluations",
                value: Some(self.evaluations.to_string()),
                rule: format!("at most {MAX_EVALUATIONS} (each renders every held-out view)"),
            });
        }
        match self.budget() {
            Budget::Steps(0) => return bad("--steps", "must be at least 1"),
            Budget::Steps(n) if n > MAX_STEPS => {
                return Err(FitError::Setting {
                    flag: "--steps",
                    value: Some(n.to_string()),
                    rule: format!("at most {MAX_STEPS} (a budget that can end)"),
                })
            }
            Budget::Seconds(s) if !(s.is_finite() && s > 0.0) => {
                return bad("--seconds", "must be finite and positive")
            }
            Budget::Seconds(s) if s > MAX_SECONDS => {
                // Rust writes a large float in all its digits: 1e308 as 309 of them.
                let s = if s < 1e9 { s.to_string() } else { format!("{s:e}") };
                return Err(FitError::Setting {
                    flag: "--seconds",
                    value: Some(s),
                    rule: format!("at most {MAX_SECONDS} (one week; a budget that can end)"),
                });
            }
            _ => {}
        }
        self.check_memory(limits::available())
    }

    /// Checks that the grid (at its last stage, with the stage before it while it grows) and
    /// a step's batch fit in `available` bytes, as [`limits`] counts them: a sparse grid as if
    /// it kept every node, as it may.
    ///
    /// Errors: [`FitError::TooLarge`] naming the flag and the bytes it would need.
    pub(crate) fn check_memory(&self, available: Bytes) -> Result<(), FitError> {
        let shape = |nodes| GridShape {
            nodes,
            channels: limits::grid_channels(self.sh_degree),
            float_bytes: self.precision.bytes(),
        };
        let model_bytes = |nodes| match self.model {
            ModelKind::Dense => shape(nodes).dense_bytes(),
            ModelKind::Sparse => shape(nodes).sparse_bytes(),
            // No grid: splats are counted where they are made (`splats::check_count`).
            ModelKind::Splats => Bytes(0),
        };
        let stages = crate::schedule::growth_stages(self);
        // A growth builds the finer grid while the coarser one still exists.
        let grid = stages
            .iter()
            .rev()
            .take(2)
            .fold(Bytes(0), |sum, &(_, nodes)| sum.plus(model_bytes(nodes)));
        let kind = format!(
            "the {} grid ({}, {} channels a node)",
            self.model.name(),
            self.precision.name(),
            shape(self.grid).channels
        );
        Bytes::check(grid, available, &format!("--grid {}", self.grid), &kind)?;
        let batch = shape(self.grid).training_ray_bytes().times(self.batch as u64);
        let rays = format!("a step's rays at --grid {}", self.grid);
        Bytes::check(batch, available, &format!("--batch {}", self.batch), &rays)?;
        let what = format!("--grid {} with --batch {}", self.grid, self.batch);
        Bytes::check(grid.plus(batch), available, &what, "the grid and a step's rays")?;
        Ok(())
    }

    /// A resumed fit's settings: `saved`'s, except the fields `given` names (by field name, as
    /// clap's argument ids are), which are `self`'s. `steps` and `seconds` are one setting, the
    /// budget: giving either replaces both.
    ///
    /// Errors: [`FitError::Config`] if the settings cannot be merged (not expected for two
    /// values of this type).
    pub(crate) fn given_over(
        &self,
        saved: &FitSettings,
        given: &dyn Fn(&str) -> bool,
    ) -> Result<FitSettings, FitError> {
        let as_map = |s: &FitSettings| match serde_json::to_value(s) {
            Ok(Value::Object(map)) => Ok(map),
            other => Err(FitError::Config(format!("settings as JSON: {other:?}"))),
        };
        let (flags, mut merged): (Map<String, Value>, Map<String, Value>) = (as_map(self)?, as_map(saved)?);
        let budget_given = given("steps") || given("seconds");
        for (key, value) in flags {
            let budget = key == "steps" || key == "seconds";
            if (budget && budget_given) || (!budget && given(&key)) {
                merged.insert(key, value);
            }
        }
        serde_json::from_value(Value::Object(merged)).map_err(|e| FitError::Config(e.to_string()))
    }
}
