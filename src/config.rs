//! The process's configuration from its environment, read once at the top:
//! [`SIMD_VAR`] (the octree's SIMD path, `crate::simd`), [`PACKETS_VAR`]
//! (the integrator's batches) and [`EMBREE_VAR`] (the configuration string
//! Embree devices are made with). The command line reads it with
//! [`Config::from_env`] before any work, refusing an unusable value in one
//! line, and puts it in force with [`Config::install`]; another front end
//! (the Python package) does the same. The modules below ask
//! [`current`] and read no variable themselves; where nothing was
//! installed (the library used on its own, its tests), [`current`] reads
//! the environment once, an unusable value meaning unset.
//!
//! This module sits just above `simd` and below everything that asks it:
//! its error is its own ([`ConfigError`]), which `crate::Error` wraps.

use crate::simd::{Isa, available, default_path};
use std::fmt;
use std::sync::OnceLock;

pub use crate::simd::SIMD_VAR;

/// The environment variable that forces the integrator's batches on
/// (`on`) or off (`off`) whatever the backend prefers
/// (`crate::accel::Backend::prefers_packets`); unset: the backend's
/// preference.
pub const PACKETS_VAR: &str = "SPLATRAY_PACKETS";

/// The environment variable whose value, when set, is the configuration
/// `crate::embree::Device::new` hands to `rtcNewDevice`: e.g.
/// `isa=sse4.2`, `isa=avx2`, `isa=avx512` to force the kernels Embree runs
/// (it otherwise picks the widest the CPU has, so float results of its
/// native primitives differ in the last bits from machine to machine), or
/// `threads=2`.
pub const EMBREE_VAR: &str = "SPLATRAY_EMBREE_CONFIG";

/// An unusable value of one of the variables: one line naming it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigError(pub String);

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ConfigError {}

/// What the process runs with.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Config {
    /// The octree's SIMD path ([`SIMD_VAR`]; unset: [`default_path`]).
    pub simd: Isa,
    /// The integrator's batches forced on or off ([`PACKETS_VAR`]); `None`:
    /// each backend's preference.
    pub packets: Option<bool>,
    /// Embree's device configuration ([`EMBREE_VAR`]); empty: Embree's
    /// defaults.
    pub embree: String,
}

impl Default for Config {
    /// Every variable unset.
    fn default() -> Config {
        Config {
            simd: default_path(),
            packets: None,
            embree: String::new(),
        }
    }
}

impl Config {
    /// The three variables of this process's environment, each checked:
    /// a one-line error for a SIMD path that is not one or that this CPU
    /// does not run, or a batch setting other than `on` / `off`.
    pub fn from_env() -> Result<Config, ConfigError> {
        Config::from_vars(|name| std::env::var(name).ok())
    }

    /// As [`Config::from_env`], with `get` answering for the environment
    /// (`None`: unset).
    pub fn from_vars(get: impl Fn(&str) -> Option<String>) -> Result<Config, ConfigError> {
        Ok(Config {
            simd: get(SIMD_VAR).map_or(Ok(default_path()), |v| simd_path(&v))?,
            packets: get(PACKETS_VAR).map_or(Ok(None), |v| packets(&v))?,
            embree: get(EMBREE_VAR).unwrap_or_default(),
        })
    }

    /// [`Config::from_vars`] where an unusable value means unset (what the
    /// library runs with when no front end installed a configuration).
    fn lenient(get: impl Fn(&str) -> Option<String>) -> Config {
        Config {
            simd: get(SIMD_VAR)
                .and_then(|v| simd_path(&v).ok())
                .unwrap_or_else(default_path),
            packets: get(PACKETS_VAR).and_then(|v| packets(&v).ok().flatten()),
            embree: get(EMBREE_VAR).unwrap_or_default(),
        }
    }

    /// Puts this configuration in force for the rest of the process (what
    /// [`current`] answers). An error when another one is in force already
    /// (installed before, or read by a [`current`] that came first).
    pub fn install(self) -> Result<(), ConfigError> {
        let mut mine = Some(self);
        let now = IN_FORCE.get_or_init(|| mine.take().expect("taken once"));
        match mine {
            Some(other) if other != *now => Err(ConfigError(format!(
                "a configuration is in force already ({now:?}); it is set once per process"
            ))),
            _ => Ok(()),
        }
    }
}

static IN_FORCE: OnceLock<Config> = OnceLock::new();

/// The configuration in force: the one installed ([`Config::install`]),
/// or else this process's environment read once, an unusable value
/// meaning unset.
#[must_use]
pub fn current() -> &'static Config {
    IN_FORCE.get_or_init(|| Config::lenient(|name| std::env::var(name).ok()))
}

/// The SIMD path named `v`, checked against this CPU.
fn simd_path(v: &str) -> Result<Isa, ConfigError> {
    let names = || {
        available()
            .iter()
            .map(|i| i.name())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match Isa::parse(v.trim()) {
        Some(i) if i.supported() => Ok(i),
        Some(i) => Err(ConfigError(format!(
            "{SIMD_VAR}={v}: this CPU does not run {i} (it runs: {})",
            names()
        ))),
        None => Err(ConfigError(format!(
            "{SIMD_VAR}={v}: not a SIMD path (expected one of: {})",
            names()
        ))),
    }
}

/// The batch setting `v`: `on`, `off`.
fn packets(v: &str) -> Result<Option<bool>, ConfigError> {
    match v.trim() {
        "on" => Ok(Some(true)),
        "off" => Ok(Some(false)),
        _ => Err(ConfigError(format!(
            "{PACKETS_VAR}={v}: expected on or off"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars<'a>(pairs: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| {
            pairs
                .iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| (*v).to_string())
        }
    }

    /// Unset is the default; each variable is read into its field.
    #[test]
    fn reads_each_variable() {
        assert_eq!(Config::from_vars(vars(&[])).unwrap(), Config::default());
        let c = Config::from_vars(vars(&[
            (SIMD_VAR, "portable"),
            (PACKETS_VAR, " off "),
            (EMBREE_VAR, "threads=2"),
        ]))
        .unwrap();
        assert_eq!(c.simd, Isa::Portable);
        assert_eq!(c.packets, Some(false));
        assert_eq!(c.embree, "threads=2");
    }

    /// An unusable value is one line naming the variable; leniently read
    /// it means unset.
    #[test]
    fn refuses_unusable_values() {
        let bad = [(SIMD_VAR, "sse9"), (PACKETS_VAR, "maybe")];
        let e = Config::from_vars(vars(&bad[..1])).unwrap_err().to_string();
        assert!(e.starts_with("SPLATRAY_SIMD=sse9: not a SIMD path"), "{e}");
        let e = Config::from_vars(vars(&bad[1..])).unwrap_err().to_string();
        assert_eq!(e, "SPLATRAY_PACKETS=maybe: expected on or off");
        assert_eq!(Config::lenient(vars(&bad)), Config::default());
    }
}
