//! The one progress display: a line on stderr, shown only when stderr is a
//! terminal and the command has run for a while. It implements the
//! library's progress callback ([`crate::progress::Progress`]).

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Progress for long stages: redraws `splatray: <stage> <percent>` in place
/// at most ten times a second, and only after the first second, so short
/// runs and redirected stderr stay quiet. Shared by reference across
/// rayon's threads (the state is behind a mutex); hand
/// `&|stage, f| line.update(stage, f)` to the library.
pub struct ProgressLine {
    enabled: bool,
    start: Instant,
    state: Mutex<State>,
}

#[derive(Default)]
struct State {
    last: Option<Instant>,
    drawn: bool,
}

impl ProgressLine {
    /// A progress line, enabled when stderr is a terminal.
    #[must_use]
    pub fn new() -> ProgressLine {
        ProgressLine {
            enabled: std::io::stderr().is_terminal(),
            start: Instant::now(),
            state: Mutex::new(State::default()),
        }
    }

    /// Report that `stage` is `fraction` done.
    pub fn update(&self, stage: &str, fraction: f64) {
        if !self.enabled || self.start.elapsed() < Duration::from_secs(1) {
            return;
        }
        let Ok(mut st) = self.state.lock() else {
            return;
        };
        let now = Instant::now();
        if st
            .last
            .is_some_and(|t| now - t < Duration::from_millis(100))
        {
            return;
        }
        st.last = Some(now);
        st.drawn = true;
        let pct = (fraction.clamp(0.0, 1.0) * 100.0).round();
        let mut e = std::io::stderr().lock();
        let _ = write!(e, "\r\x1b[2Ksplatray: {stage} {pct:3.0}%");
        let _ = e.flush();
    }

    /// Clear the line, if anything was drawn (before printing other output,
    /// and when the work is done).
    pub fn finish(&self) {
        if let Ok(mut st) = self.state.lock()
            && st.drawn
        {
            let _ = write!(std::io::stderr().lock(), "\r\x1b[2K");
            st.drawn = false;
        }
    }
}

impl Default for ProgressLine {
    fn default() -> Self {
        ProgressLine::new()
    }
}

impl Drop for ProgressLine {
    fn drop(&mut self) {
        self.finish();
    }
}
