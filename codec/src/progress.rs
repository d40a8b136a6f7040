//! One progress type for every long operation: the bake, import, the
//! compressor's stages, the `pca` fit and the exact reference all report a
//! [`Step`] (which stage, how far of how much) through a [`Progress`].

use crate::raw::ResumeState;

/// What a long operation is doing when it reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Stage {
    /// Baking rows (rows done of all rows, resumed ones counted done);
    /// [`Step::work`] counts the shadow rays traced in this run.
    Bake {
        /// What the bake did with an existing `PATH.partial`.
        resume: ResumeState,
    },
    /// Importing a `.npy` array into a raw store (blocks done of all).
    Import,
    /// Row transform and transpose (rows done of P).
    Rows,
    /// Analysis (columns done of M).
    Analysis,
    /// Coding (columns done of M).
    Coding,
    /// The `pca` mode's randomized SVD (passes over the raw store done of
    /// all passes).
    Fit,
    /// The exact product `T·L` (rows done of P).
    Reference,
}

/// One report of a long operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Step {
    /// What is being done.
    pub stage: Stage,
    /// Units done.
    pub done: u64,
    /// Units in all.
    pub total: u64,
    /// A stage-specific amount of work done so far, for rates (the shadow
    /// rays of [`Stage::Bake`]); 0 where a stage has none.
    pub work: u64,
}

/// Where a long operation sends its [`Step`]s: a callback, or nothing.
/// Copy it into parallel work freely; the callback must be `Sync`.
#[derive(Clone, Copy, Default)]
pub struct Progress<'a> {
    sink: Option<&'a (dyn Fn(Step) + Sync)>,
}

impl<'a> Progress<'a> {
    /// Reports nowhere.
    pub const NONE: Progress<'static> = Progress { sink: None };

    /// Reports to `sink`.
    pub fn new(sink: &'a (dyn Fn(Step) + Sync)) -> Progress<'a> {
        Progress { sink: Some(sink) }
    }

    /// Reports `done` of `total` units of `stage`.
    pub fn report(&self, stage: Stage, done: u64, total: u64) {
        self.report_work(stage, done, total, 0);
    }

    /// Reports `done` of `total` units of `stage`, and `work` done so far.
    pub fn report_work(&self, stage: Stage, done: u64, total: u64, work: u64) {
        if let Some(sink) = self.sink {
            sink(Step {
                stage,
                done,
                total,
                work,
            });
        }
    }
}

impl std::fmt::Debug for Progress<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("reports", &self.sink.is_some())
            .finish()
    }
}

impl<'a, F: Fn(Step) + Sync> From<&'a F> for Progress<'a> {
    fn from(sink: &'a F) -> Progress<'a> {
        Progress::new(sink)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn steps_reach_the_sink_in_order_and_none_reports_nothing() {
        let seen = Mutex::new(Vec::new());
        let sink = |s: Step| seen.lock().unwrap().push(s);
        let p = Progress::from(&sink);
        p.report(Stage::Rows, 1, 4);
        p.report_work(Stage::Fit, 2, 4, 7);
        Progress::NONE.report(Stage::Coding, 3, 4);
        let seen = seen.into_inner().unwrap();
        assert_eq!(seen.len(), 2);
        assert_eq!(
            (seen[0].stage, seen[0].done, seen[0].total, seen[0].work),
            (Stage::Rows, 1, 4, 0)
        );
        assert_eq!((seen[1].stage, seen[1].work), (Stage::Fit, 7));
    }
}
