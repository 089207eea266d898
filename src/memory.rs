//! The memory this process may really use, for checks made before large
//! work: the least of the machine's `MemAvailable`, what its cgroup's limit
//! leaves (v2 `memory.max` less `memory.current`, v1
//! `memory.limit_in_bytes` less `memory.usage_in_bytes`, the process's
//! cgroup and every one above it), and what its address-space and data
//! limits leave (`RLIMIT_AS` less `VmSize`, `RLIMIT_DATA` less `VmData`),
//! as batch systems and containers set them. All read from `/proc` and
//! `/sys`, so a machine that says nothing is not checked.

use std::path::{Path, PathBuf};

/// One bound on the memory this process may use, and where it comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Bound {
    /// Bytes the process may still allocate under this bound.
    pub bytes: u64,
    /// What sets it, for messages (e.g. "the address-space limit").
    pub source: &'static str,
}

/// The memory this process may still allocate: the least of the bounds
/// this machine states, and which bound that is; `None` where it states
/// none.
#[must_use]
pub fn limit() -> Option<Bound> {
    bounds().into_iter().min_by_key(|b| b.bytes)
}

/// The bytes of [`limit`], if any bound is stated.
#[must_use]
pub fn available() -> Option<u64> {
    limit().map(|b| b.bytes)
}

/// Every bound this machine states (see the module's text).
#[must_use]
pub fn bounds() -> Vec<Bound> {
    let mut out = Vec::new();
    if let Some(b) = meminfo_available() {
        out.push(Bound {
            bytes: b,
            source: "the memory available",
        });
    }
    if let Some(b) = cgroup_left() {
        out.push(Bound {
            bytes: b,
            source: "the cgroup's memory limit",
        });
    }
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let limits = std::fs::read_to_string("/proc/self/limits").unwrap_or_default();
    for (limit_name, used_name, source) in [
        (
            "Max address space",
            "VmSize:",
            "the address-space limit (RLIMIT_AS)",
        ),
        (
            "Max data size",
            "VmData:",
            "the data-size limit (RLIMIT_DATA)",
        ),
    ] {
        if let Some(max) = soft_limit(&limits, limit_name) {
            let used = status_kb(&status, used_name).unwrap_or(0);
            out.push(Bound {
                bytes: max.saturating_sub(used),
                source,
            });
        }
    }
    out
}

/// Work that needs more memory than this process may still allocate:
/// what the work is, the bytes it needs, the bound it exceeds and, where the
/// caller knows one, a way around it. Displays as one line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TooLarge {
    /// The work (e.g. "reading the cloud").
    pub what: String,
    /// Bytes it needs, about.
    pub bytes: u64,
    /// The bound it exceeds.
    pub bound: Bound,
    /// A way around it, said after the rest (e.g. another output format).
    pub hint: Option<String>,
}

impl TooLarge {
    /// The same error with `hint` said after it.
    #[must_use]
    pub fn with_hint(self, hint: impl Into<String>) -> TooLarge {
        TooLarge {
            hint: Some(hint.into()),
            ..self
        }
    }
}

impl std::fmt::Display for TooLarge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} needs about {:.1} GB, more than the {:.1} GB {} leaves",
            self.what,
            self.bytes as f64 / 1e9,
            self.bound.bytes as f64 / 1e9,
            self.bound.source
        )?;
        match &self.hint {
            Some(h) => write!(f, ": {h}"),
            None => Ok(()),
        }
    }
}

impl std::error::Error for TooLarge {}

/// Fails when `bytes` is more than this process may still allocate
/// ([`limit`]; nothing is checked where the machine states no bound).
///
/// # Errors
/// [`TooLarge`]: what needs how much, against the tightest bound and its
/// name.
pub fn check(what: &str, bytes: u64) -> Result<(), TooLarge> {
    check_within(what, bytes, None)
}

/// [`check`] against the least of [`limit`] and `cap`, the bytes the user
/// allowed (`--max-memory`), named "the --max-memory limit" when it is the
/// tighter.
///
/// # Errors
/// As [`check`].
pub fn check_within(what: &str, bytes: u64, cap: Option<u64>) -> Result<(), TooLarge> {
    let user = cap.map(|b| Bound {
        bytes: b,
        source: "the --max-memory limit",
    });
    match limit().into_iter().chain(user).min_by_key(|b| b.bytes) {
        Some(b) if bytes > b.bytes => Err(TooLarge {
            what: what.to_string(),
            bytes,
            bound: b,
            hint: None,
        }),
        _ => Ok(()),
    }
}

/// `MemAvailable` of `/proc/meminfo`, in bytes.
fn meminfo_available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    status_kb(&text, "MemAvailable:")
}

/// A `NAME: N kB` line of `/proc/meminfo` or `/proc/self/status`, in bytes.
fn status_kb(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// The soft limit of a `/proc/self/limits` row, in bytes (`None` when
/// unlimited or absent).
fn soft_limit(limits: &str, name: &str) -> Option<u64> {
    let rest = limits.lines().find_map(|l| l.strip_prefix(name))?;
    rest.split_whitespace().next()?.parse().ok()
}

/// Limits at or above this are "no limit" (cgroup v1 writes 2^63 rounded
/// down to a page).
const NO_LIMIT: u64 = 1 << 62;

/// What the tightest memory cgroup over this process leaves: its own and
/// every ancestor's limit less its usage.
fn cgroup_left() -> Option<u64> {
    let own = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let mut best: Option<u64> = None;
    for line in own.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let (root, max_file, used_file) = if id == "0" && controllers.is_empty() {
            (
                PathBuf::from("/sys/fs/cgroup"),
                "memory.max",
                "memory.current",
            )
        } else if controllers.split(',').any(|c| c == "memory") {
            (
                PathBuf::from("/sys/fs/cgroup/memory"),
                "memory.limit_in_bytes",
                "memory.usage_in_bytes",
            )
        } else {
            continue;
        };
        let mut dir = Path::new(path.trim_start_matches('/'));
        loop {
            let here = root.join(dir);
            let read = |f: &str| -> Option<u64> {
                std::fs::read_to_string(here.join(f))
                    .ok()?
                    .trim()
                    .parse()
                    .ok()
            };
            if let (Some(max), Some(used)) = (read(max_file), read(used_file))
                && max < NO_LIMIT
            {
                let left = max.saturating_sub(used);
                best = Some(best.map_or(left, |b| b.min(left)));
            }
            match dir.parent() {
                Some(p) => dir = p,
                None => break,
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_rows_are_read_in_bytes() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
                      Max data size             unlimited            unlimited            bytes     \n\
                      Max address space         4000000000           unlimited            bytes     \n";
        assert_eq!(soft_limit(limits, "Max address space"), Some(4_000_000_000));
        assert_eq!(soft_limit(limits, "Max data size"), None);
        assert_eq!(
            status_kb("VmSize:\t    3896 kB\n", "VmSize:"),
            Some(3896 * 1024)
        );
    }

    #[test]
    fn this_machine_states_a_bound() {
        // Linux always has /proc/meminfo.
        let b = limit().expect("a bound");
        assert!(b.bytes > 0, "{b:?}");
        assert!(check("nothing", 0).is_ok());
        let err = check("everything", u64::MAX).unwrap_err().to_string();
        assert!(err.contains(b.source), "{err}");
    }
}
