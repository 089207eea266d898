//! Progress of long library work (splat generation while a scene loads,
//! rendering): the one mechanism by which the library says how far it is.
//! The library only calls the callback; showing it (the command line's
//! terminal line) is the caller's business.

/// A progress callback: called now and then with the name of the running
/// stage and the fraction of it done, in `[0, 1]`. It may be called from
/// several threads at once (rendering is parallel over rows), hence `Sync`.
/// Functions take an `Option<Progress>`; `None` reports nothing.
pub type Progress<'a> = &'a (dyn Fn(&str, f64) + Sync);

/// Calls `progress`, if there is one, with `stage` and `fraction`.
pub fn notify(progress: Option<Progress<'_>>, stage: &str, fraction: f64) {
    if let Some(p) = progress {
        p(stage, fraction);
    }
}
