//! Progress of long operations reported to a Python callable
//! `progress(stage, done, total)`, at most every 50 ms and at each stage's
//! end.

use ltm_codec::{Stage, Step};
use pyo3::prelude::*;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Least time between two calls of the callable within a stage.
const INTERVAL: Duration = Duration::from_millis(50);

/// The callable, and the first exception it raised (raised again when the
/// operation ends: the operation itself runs to its end).
pub struct Callback {
    f: Option<Py<PyAny>>,
    last: Mutex<Option<(Instant, &'static str)>>,
    error: Mutex<Option<PyErr>>,
}

/// The stage's name as the callable receives it.
fn name(stage: Stage) -> &'static str {
    match stage {
        Stage::Bake { .. } => "bake",
        Stage::Import => "import",
        Stage::Rows => "rows",
        Stage::Analysis => "analysis",
        Stage::Coding => "coding",
        Stage::Fit => "fit",
        Stage::Reference => "reference",
        _ => "work",
    }
}

impl Callback {
    /// `f`, or nothing to call when it is None.
    pub fn new(f: Option<Bound<'_, PyAny>>) -> Callback {
        Callback {
            f: f.map(Bound::unbind),
            last: Mutex::new(None),
            error: Mutex::new(None),
        }
    }

    /// Whether this step is due: the stage's first and last, or 50 ms
    /// after the last call.
    fn due(&self, stage: &'static str, step: &Step) -> bool {
        let Ok(mut last) = self.last.lock() else {
            return false;
        };
        let now = Instant::now();
        let due = match *last {
            Some((t, s)) => s != stage || step.done >= step.total || now - t >= INTERVAL,
            None => true,
        };
        if due {
            *last = Some((now, stage));
        }
        due
    }

    /// Calls the callable with the step (taking the interpreter).
    pub fn report(&self, step: Step) {
        let Some(f) = &self.f else {
            return;
        };
        let stage = name(step.stage);
        if !self.due(stage, &step) {
            return;
        }
        Python::attach(|py| {
            if let Err(e) = f.call1(py, (stage, step.done, step.total)) {
                if let Ok(mut first) = self.error.lock() {
                    first.get_or_insert(e);
                }
            }
        });
    }

    /// The callable's first exception, if it raised one.
    pub fn finish(self) -> PyResult<()> {
        match self.error.into_inner() {
            Ok(Some(e)) => Err(e),
            _ => Ok(()),
        }
    }
}
