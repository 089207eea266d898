//! The `export` workflow: splats (or a Gaussian file in the other layout)
//! written as a Gaussian splat file other splat renderers and trainers read.
//! The front end parses and prints.

use crate::io::{
    GaussianLayout, SplatSet, encode_gaussians, file_layout, read_gaussians, read_splats,
    write_bytes,
};
use crate::{Error, Result};
use std::path::Path;

/// What [`export`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Exported {
    /// Splats read and Gaussians written (one each).
    pub splats: usize,
    /// Splats with a normal field (eq. 4) the layout cannot hold, written
    /// flat.
    pub curved: usize,
    /// Splats with clip lines the layout cannot hold, written whole.
    pub clipped: usize,
    /// Bytes written.
    pub bytes: usize,
    /// Warnings of reading a Gaussian input, one line each.
    pub warnings: Vec<String>,
}

/// Reads `input` (a splat file, or a Gaussian file whose Gaussians less
/// opaque than `min_opacity` are left out) and writes it to `output` in
/// `layout` with colour of spherical-harmonic degree `sh_degree`.
///
/// # Errors
/// `min_opacity` outside [0, 1], an unreadable input, an unwritable
/// output; each one line.
pub fn export(
    input: &Path,
    output: &Path,
    layout: GaussianLayout,
    sh_degree: u32,
    min_opacity: f32,
) -> Result<Exported> {
    if !(0.0..=1.0).contains(&min_opacity) {
        return Err(Error::invalid(format!(
            "--min-opacity {min_opacity} must be in [0, 1]"
        )));
    }
    let (set, warnings): (SplatSet, Vec<String>) = if file_layout(input).is_some() {
        let read = read_gaussians(input, min_opacity)?;
        let warnings = read.warnings();
        (read.set, warnings)
    } else {
        (read_splats(input)?, Vec::new())
    };
    let bytes = encode_gaussians(output, &set.splats, set.origin, layout, sh_degree)?;
    write_bytes(output, &bytes)?;
    let flat = crate::splat::NormalField::FLAT;
    Ok(Exported {
        splats: set.splats.len(),
        curved: set.splats.iter().filter(|s| s.field != flat).count(),
        clipped: set.splats.iter().filter(|s| s.is_clipped()).count(),
        bytes: bytes.len(),
        warnings,
    })
}
