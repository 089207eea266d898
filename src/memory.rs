//! The machine's available memory, for checks made before large work.

/// The memory this machine has available now (`MemAvailable` of
/// `/proc/meminfo`), if it says.
#[must_use]
pub fn available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// Fails when `bytes` is more than the memory available (nothing is
/// checked where the machine does not say).
///
/// # Errors
/// One line: what needs how much, against what is available.
pub fn check(what: &str, bytes: u64) -> Result<(), String> {
    match available() {
        Some(a) if bytes > a => Err(format!(
            "{what} needs about {:.1} GB, more than the {:.1} GB available",
            bytes as f64 / 1e9,
            a as f64 / 1e9
        )),
        _ => Ok(()),
    }
}
