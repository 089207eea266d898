//! A one-line progress display on stderr, shown only when stderr is a
//! terminal and a stage has run for a while.

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

/// Progress for long stages: redraws `splatray: <stage> <percent>` in place
/// at most ten times a second, and only after the first second, so short
/// runs and redirected stderr stay quiet.
pub struct Progress {
    enabled: bool,
    start: Instant,
    last: Option<Instant>,
    drawn: bool,
}

impl Progress {
    /// A progress line, enabled when stderr is a terminal.
    #[must_use]
    pub fn new() -> Progress {
        Progress {
            enabled: std::io::stderr().is_terminal(),
            start: Instant::now(),
            last: None,
            drawn: false,
        }
    }

    /// Report that `stage` is `fraction` done.
    pub fn update(&mut self, stage: &str, fraction: f64) {
        if !self.enabled || self.start.elapsed() < Duration::from_secs(1) {
            return;
        }
        let now = Instant::now();
        if self
            .last
            .is_some_and(|t| now - t < Duration::from_millis(100))
        {
            return;
        }
        self.last = Some(now);
        self.drawn = true;
        let pct = (fraction.clamp(0.0, 1.0) * 100.0).round();
        let mut e = std::io::stderr().lock();
        let _ = write!(e, "\r\x1b[2Ksplatray: {stage} {pct:3.0}%");
        let _ = e.flush();
    }

    /// Clear the line, if anything was drawn.
    pub fn finish(&mut self) {
        if self.drawn {
            let _ = write!(std::io::stderr().lock(), "\r\x1b[2K");
            self.drawn = false;
        }
    }
}

impl Default for Progress {
    fn default() -> Self {
        Progress::new()
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}
