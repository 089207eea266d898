//! A Python progress callback `f(stage: str, fraction: float)` as the
//! library's [`splatray::progress::Progress`]: called from whichever thread
//! reports (rendering reports from rayon's), with the GIL taken for the
//! call only, at most once per stage and percent. An exception raised by
//! the callback stops further calls and is raised when the work returns.

use pyo3::prelude::*;
use std::sync::Mutex;

/// The callback and what it was last told.
pub struct Callback {
    f: Option<Py<PyAny>>,
    state: Mutex<State>,
}

#[derive(Default)]
struct State {
    stage: String,
    percent: i64,
    error: Option<PyErr>,
}

impl Callback {
    /// `f` (`None`: nothing is reported).
    pub fn new(f: Option<Py<PyAny>>) -> Callback {
        Callback {
            f,
            state: Mutex::new(State {
                percent: -1,
                ..State::default()
            }),
        }
    }

    /// Reports `(stage, fraction)` when the stage or the percent changed.
    pub fn report(&self, stage: &str, fraction: f64) {
        let Some(f) = &self.f else { return };
        let Ok(mut s) = self.state.lock() else { return };
        let percent = (fraction.clamp(0.0, 1.0) * 100.0).floor() as i64;
        if s.error.is_some() || (s.stage == stage && s.percent == percent) {
            return;
        }
        s.stage.clear();
        s.stage.push_str(stage);
        s.percent = percent;
        // The lock is held over the call: the callback is called from one
        // thread at a time, in order.
        Python::attach(|py| {
            if let Err(e) = f.call1(py, (stage, fraction)) {
                s.error = Some(e);
            }
        });
    }

    /// The callback's exception, if it raised one.
    pub fn finish(self) -> PyResult<()> {
        match self.state.into_inner() {
            Ok(State { error: Some(e), .. }) => Err(e),
            _ => Ok(()),
        }
    }
}
