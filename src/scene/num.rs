//! Numbers checked where they enter the scene model: each field of the
//! scene file that must be finite, non-negative, positive, a fraction or a
//! bounded count is deserialized through one of these, so a bad value
//! fails at parse time with the TOML parser's line (and the key, added by
//! [`super::parse_scene_str`]), once, instead of at each use or never
//! (NaN pixels, an empty image, a hang).

use serde::de::{Deserialize, Deserializer, Error as _};

/// The deepest reflection and refraction recursion `render.max_depth`
/// takes. Each level is a stack frame of the render thread; between two
/// facing mirrors every level is used. Glass doubles the rays per level at
/// worst; that cost is bounded separately, by the render's ray estimate.
pub const MAX_DEPTH: u64 = 64;

/// The most shadow samples per shading point a sphere light takes (64 by
/// 64 strata).
pub const MAX_LIGHT_SAMPLES: u64 = 4096;

/// The most splats or points a procedural shape, a mesh sampling or a
/// synthetic scan makes: 50 million splats are about 4.2 GB before the
/// accelerators are built.
pub const MAX_GENERATED: u64 = 50_000_000;

/// Every number in a value: a scalar, an array of them, or an optional one.
pub trait Numbers {
    /// Calls `f` with each number, as f64 and as itself (for the message:
    /// `Debug` writes 1e-30, not thirty zeros).
    fn each(&self, f: &mut dyn FnMut(f64, &dyn std::fmt::Debug));
}

macro_rules! numbers {
    ($($t:ty),*) => {$(
        impl Numbers for $t {
            #[allow(clippy::cast_precision_loss, clippy::cast_lossless)]
            fn each(&self, f: &mut dyn FnMut(f64, &dyn std::fmt::Debug)) {
                f(*self as f64, self);
            }
        }
    )*};
}
numbers!(f32, f64, u32, u64, usize);

impl<T: Numbers, const N: usize> Numbers for [T; N] {
    fn each(&self, f: &mut dyn FnMut(f64, &dyn std::fmt::Debug)) {
        for x in self {
            x.each(f);
        }
    }
}

impl<T: Numbers> Numbers for Option<T> {
    fn each(&self, f: &mut dyn FnMut(f64, &dyn std::fmt::Debug)) {
        if let Some(x) = self {
            x.each(f);
        }
    }
}

/// Deserializes a `T` and rejects it unless every number in it passes
/// `ok`; the message says what was wanted and what came.
fn check<'de, D, T>(d: D, ok: impl Fn(f64) -> bool, want: &str) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de> + Numbers,
{
    let v = T::deserialize(d)?;
    let mut bad = None;
    v.each(&mut |x, shown| {
        if bad.is_none() && !ok(x) {
            bad = Some(format!("{shown:?}"));
        }
    });
    match bad {
        Some(x) => Err(D::Error::custom(format!("must be {want}, got {x}"))),
        None => Ok(v),
    }
}

/// Finite (not NaN, not infinite).
///
/// # Errors
/// A non-finite number.
pub fn finite<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    check(d, f64::is_finite, "finite")
}

/// Finite and at least 0.
///
/// # Errors
/// A negative or non-finite number.
pub fn non_negative<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    check(d, |x| x.is_finite() && x >= 0.0, "finite and >= 0")
}

/// Finite and above 0.
///
/// # Errors
/// A non-positive or non-finite number.
pub fn positive<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    check(d, |x| x.is_finite() && x > 0.0, "finite and > 0")
}

/// In `[0, 1]`.
///
/// # Errors
/// A number outside `[0, 1]` or NaN.
pub fn fraction<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    check(d, |x| (0.0..=1.0).contains(&x), "in [0, 1]")
}

/// A field of view in degrees: `[0.01, 179]` (a narrower one loses the
/// camera's precision, a wider one maps most pixels to a sliver).
///
/// # Errors
/// Out of range.
pub fn fov<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(d: D) -> Result<T, D::Error> {
    check(d, |x| (0.01..=179.0).contains(&x), "in [0.01, 179] degrees")
}

/// A count in `1..=max`; the message says why the bound is there.
fn count<'de, D, T>(d: D, max: u64, why: &str) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de> + Numbers,
{
    check(
        d,
        |x| (1.0..=max as f64).contains(&x),
        &format!("in 1..={max} ({why})"),
    )
}

/// `render.max_depth`: `1..=`[`MAX_DEPTH`].
///
/// # Errors
/// Out of range.
pub fn depth<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    count(
        d,
        MAX_DEPTH,
        "each level is a stack frame of the render thread",
    )
}

/// `light.samples`: `1..=`[`MAX_LIGHT_SAMPLES`].
///
/// # Errors
/// Out of range.
pub fn light_samples<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    count(d, MAX_LIGHT_SAMPLES, "shadow rays per shading point")
}

/// A count of generated splats, points or rays: `1..=`[`MAX_GENERATED`].
///
/// # Errors
/// Out of range.
pub fn generated<'de, D: Deserializer<'de>, T: Deserialize<'de> + Numbers>(
    d: D,
) -> Result<T, D::Error> {
    count(
        d,
        MAX_GENERATED,
        "about 84 bytes each before the accelerators",
    )
}

/// The most stations a synthetic scan takes (a cloud of several scans
/// indexes its scanners with 16 bits).
pub const MAX_STATIONS: usize = 1024;

/// A scanner's stations: one position `[x, y, z]` or a list of them
/// `[[x, y, z], ...]` (at least one, at most [`MAX_STATIONS`]), each
/// finite.
///
/// # Errors
/// Neither shape, an empty or too long list, or a non-finite coordinate.
pub fn stations<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<[f32; 3]>, D::Error> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum Stations {
        One([f32; 3]),
        Many(Vec<[f32; 3]>),
    }
    let list = match Stations::deserialize(d).map_err(|_| {
        D::Error::custom("must be a position [x, y, z] or a list of them [[x, y, z], ...]")
    })? {
        Stations::One(p) => vec![p],
        Stations::Many(list) => list,
    };
    if list.is_empty() || list.len() > MAX_STATIONS {
        return Err(D::Error::custom(format!(
            "must list 1..={MAX_STATIONS} stations, got {}",
            list.len()
        )));
    }
    if let Some(p) = list.iter().find(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(D::Error::custom(format!("must be finite, got {p:?}")));
    }
    Ok(list)
}
