//! The words that name the values of the small enums the command line,
//! scene files and Python spell out (`--shading phong`, `--aov depth`,
//! `--pattern lines`): one table per enum, read both ways.

use crate::{Error, Result};

/// An enum whose values are spelled as one word each.
pub trait Named: Copy + PartialEq + 'static {
    /// What a value is, in an error ("shading mode").
    const WHAT: &'static str;
    /// Every value, in the order an error lists them.
    const ALL: &'static [Self];
    /// Their names: `NAMES[i]` names `ALL[i]`.
    const NAMES: &'static [&'static str];

    /// The value's name (as [`parse`] reads it).
    #[must_use]
    fn name(self) -> &'static str {
        let i = Self::ALL.iter().position(|&v| v == self);
        i.and_then(|i| Self::NAMES.get(i))
            .copied()
            .unwrap_or_default()
    }
}

/// The value named `s`; any other word is a one-line error listing the
/// names (`unknown AOV 'x' (expected depth, normal, splat or albedo)`).
///
/// # Errors
/// `s` names no value of `T`.
pub fn parse<T: Named>(s: &str) -> Result<T> {
    if let Some(i) = T::NAMES.iter().position(|&name| name == s) {
        return Ok(T::ALL[i]);
    }
    let expected = match T::NAMES.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => T::NAMES.concat(),
    };
    Err(Error::invalid(format!(
        "unknown {} '{s}' (expected {expected})",
        T::WHAT
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::output::Aov;
    use crate::resolve::ShadingMode;
    use crate::scanner::ScanPattern;

    /// Every value of `T` has a name of its own and reads back from it.
    fn round_trip<T: Named + std::fmt::Debug>() {
        assert_eq!(T::NAMES.len(), T::ALL.len(), "{}", T::WHAT);
        for (&v, &name) in T::ALL.iter().zip(T::NAMES) {
            assert_eq!(v.name(), name);
            assert_eq!(parse::<T>(name).unwrap(), v);
        }
        let mut names = T::NAMES.to_vec();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), T::ALL.len(), "{}: a name twice", T::WHAT);
    }

    #[test]
    fn names_read_back_and_unknown_ones_list_the_names() {
        round_trip::<ShadingMode>();
        round_trip::<ScanPattern>();
        round_trip::<Aov>();
        round_trip::<crate::terrain::ScanPattern>();
        let msg = |e: Error| e.to_string();
        assert_eq!(
            msg(parse::<ShadingMode>("gouraud").unwrap_err()),
            "unknown shading mode 'gouraud' (expected flat, blended or phong)"
        );
        assert_eq!(
            msg(parse::<ScanPattern>("spiral").unwrap_err()),
            "unknown scan pattern 'spiral' (expected raster or lines)"
        );
        assert_eq!(
            msg(parse::<Aov>("x").unwrap_err()),
            "unknown AOV 'x' (expected depth, normal, splat or albedo)"
        );
    }
}
