//! The budget loop, once for every trainer: [`run_budget`] steps a [`Stepper`] (the grid's
//! [`Trainer`](super::Trainer), the splats' [`SplatTrainer`](crate::splats::SplatTrainer))
//! until its budget is spent or a stop flag is raised, evaluating the held-out views
//! `evaluations` times on the way (off the training clock) and once at the end with depth.

use std::sync::atomic::{AtomicBool, Ordering};

use super::{Evaluation, StepReport};
use crate::error::FitError;
use crate::train::{LogEntry, Progress};

/// What the budget loop needs of a trainer, whatever its model and however it renders.
pub(crate) trait Stepper {
    /// One training step.
    ///
    /// Errors: the trainer's; it should then be dropped.
    fn step(&mut self) -> Result<StepReport, FitError>;
    /// The held-out views rendered and scored (with depth if `depth` and the model has one).
    ///
    /// Errors: the trainer's.
    fn evaluate(&self, depth: bool) -> Result<Evaluation, FitError>;
    /// The fraction of the budget spent.
    fn fraction(&self) -> f64;
    /// Steps done (a resumed fit's earlier steps included).
    fn steps(&self) -> usize;
    /// Whether the budget is spent.
    fn is_done(&self) -> bool {
        self.fraction() >= 1.0
    }
}

/// What [`run_budget`] returns.
#[derive(Debug, Clone)]
pub(crate) struct BudgetRun {
    /// The evaluations, in order (the one before the first step included).
    pub log: Vec<LogEntry>,
    /// The final evaluation, with depth, of the model as the loop left it; `None` when the
    /// stop flag ended the loop (a stopped fit is saved, not scored).
    pub last: Option<Evaluation>,
    /// Whether the stop flag ended the loop before the budget was spent.
    pub interrupted: bool,
}

/// Steps `trainer` to the end of its budget or until `stop` is raised (checked before each
/// step, so the step under way is finished), with an evaluation before the first step, one
/// each time another `1 / evaluations` of the budget is spent, and a final one with depth
/// (the last in-loop one when it was that already) unless `stop` ended it. Calls `progress` after every step with
/// the trainer as the step left it.
///
/// Errors: the trainer's.
pub(crate) fn run_budget<T: Stepper>(
    trainer: &mut T,
    evaluations: usize,
    stop: Option<&AtomicBool>,
    progress: &mut dyn FnMut(Progress, &T),
) -> Result<BudgetRun, FitError> {
    let evaluations = evaluations as f64;
    let mut log = vec![trainer.evaluate(false)?.entry];
    let mut next_eval = (trainer.fraction() * evaluations).floor() as usize + 1;
    let mut interrupted = false;
    // The last in-loop evaluation, and whether it was a final one (made with depth).
    let mut last: Option<(Evaluation, bool)> = None;
    while !trainer.is_done() {
        if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
            interrupted = true;
            break;
        }
        let report = trainer.step()?;
        progress(
            Progress {
                step: report.step,
                fraction: report.fraction,
            },
            trainer,
        );
        if trainer.is_done() || trainer.fraction() * evaluations >= next_eval as f64 {
            let depth = trainer.is_done();
            let evaluation = trainer.evaluate(depth)?;
            log.push(evaluation.entry);
            last = Some((evaluation, depth));
            next_eval = (trainer.fraction() * evaluations).floor() as usize + 1;
        }
    }
    let last = match last.filter(|(e, depth)| *depth && e.entry.step == trainer.steps()) {
        Some((e, _)) => Some(e),
        None if interrupted => None,
        None => Some(trainer.evaluate(true)?),
    };
    Ok(BudgetRun { log, last, interrupted })
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;

    /// A trainer of ten steps that counts its evaluations and raises `stop` after `stop_after`.
    struct Counted<'a> {
        step: usize,
        evaluations: Cell<usize>,
        stop_after: usize,
        stop: &'a AtomicBool,
    }

    impl Stepper for Counted<'_> {
        fn step(&mut self) -> Result<StepReport, FitError> {
            self.step += 1;
            if self.step == self.stop_after {
                self.stop.store(true, Ordering::Relaxed);
            }
            Ok(StepReport {
                step: self.step,
                loss: 0.0,
                samples: 0,
                fraction: self.fraction(),
            })
        }
        fn evaluate(&self, _depth: bool) -> Result<Evaluation, FitError> {
            self.evaluations.set(self.evaluations.get() + 1);
            let entry = LogEntry {
                step: self.step,
                seconds: 0.0,
                train_loss: 0.0,
                test_psnr: 0.0,
                test_ssim: 0.0,
                samples: 0,
            };
            Ok(Evaluation { entry, views: vec![] })
        }
        fn fraction(&self) -> f64 {
            self.step as f64 / 10.0
        }
        fn steps(&self) -> usize {
            self.step
        }
    }

    fn run(stop_after: usize) -> (BudgetRun, usize, Vec<usize>) {
        let stop = AtomicBool::new(false);
        let mut trainer = Counted {
            step: 0,
            evaluations: Cell::new(0),
            stop_after,
            stop: &stop,
        };
        let mut seen = vec![];
        let run = run_budget(&mut trainer, 3, Some(&stop), &mut |p, t| {
            assert_eq!(p.step, t.steps());
            seen.push(p.step)
        })
        .unwrap();
        (run, trainer.evaluations.get(), seen)
    }

    #[test]
    fn three_evaluations_of_ten_steps_fall_where_each_third_is_passed_and_the_last_is_final() {
        let (run, evaluations, seen) = run(usize::MAX);
        // Thirds of 10 steps are passed at steps 4 (0.4), 7 (0.7) and 10.
        let steps: Vec<usize> = run.log.iter().map(|e| e.step).collect();
        assert_eq!(steps, [0, 4, 7, 10]);
        assert_eq!(run.last.map(|e| e.entry.step), Some(10));
        // The evaluation at step 10 is the final one: not made twice.
        assert_eq!(evaluations, 4);
        assert_eq!(seen, (1..=10).collect::<Vec<_>>());
        assert!(!run.interrupted);
    }

    #[test]
    fn a_stop_raised_during_step_five_ends_the_loop_after_it_without_a_final_evaluation() {
        let (run, evaluations, seen) = run(5);
        let steps: Vec<usize> = run.log.iter().map(|e| e.step).collect();
        assert_eq!(steps, [0, 4]);
        assert!(run.interrupted);
        assert!(run.last.is_none());
        assert_eq!(evaluations, 2);
        assert_eq!(seen, [1, 2, 3, 4, 5]);
    }
}
