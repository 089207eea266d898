//! Image output: sRGB PNG for looking at, linear EXR for the radiance and
//! the AOVs. Every file is written through [`crate::io::write_atomic`]
//! (a temporary name beside the target, renamed into place), so a failure
//! never leaves a half-written file.

use super::integrator::Frame;
use crate::io::Batch;
use crate::names::Named;
use crate::{Error, Result};
use glam::Vec3;
use image::{ImageBuffer, ImageFormat, Rgb};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

use crate::io::linear_to_srgb8 as srgb;

/// The frame's radiance as an 8-bit sRGB image.
#[must_use]
pub fn to_srgb8(frame: &Frame) -> ImageBuffer<Rgb<u8>, Vec<u8>> {
    let data = frame
        .rgb
        .par_iter()
        .flat_map_iter(|c| [srgb(c.x), srgb(c.y), srgb(c.z)])
        .collect();
    ImageBuffer::from_raw(frame.width, frame.height, data).unwrap_or_default()
}

fn format_of(path: &Path) -> Result<ImageFormat> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => Ok(ImageFormat::Png),
        Some("exr") => Ok(ImageFormat::OpenExr),
        _ => Err(Error::invalid(format!(
            "{}: output must end in .png or .exr",
            path.display()
        ))),
    }
}

/// Checks an output path before any work is done: known extension, and an
/// existing folder.
pub fn check_output_path(path: &Path) -> Result<()> {
    format_of(path)?;
    check_writable(path)
}

/// Checks that `path` ends in one of `allowed` (lower case, no dot), then
/// that it can be written ([`check_writable`]): `-o out.png` for a splat
/// file is a mistake, not a PLY to write under that name.
///
/// # Errors
/// Another extension, or an unwritable path.
pub fn check_extension(path: &Path, allowed: &[&str]) -> Result<()> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if !ext.as_deref().is_some_and(|e| allowed.contains(&e)) {
        let list: Vec<String> = allowed.iter().map(|e| format!(".{e}")).collect();
        return Err(Error::invalid(format!(
            "{}: the output must end in {}",
            path.display(),
            list.join(" or ")
        )));
    }
    check_writable(path)
}

/// Checks a path a run will write before any work is done: not a folder, in
/// a folder that exists (any extension).
pub fn check_writable(path: &Path) -> Result<()> {
    if path.is_dir() {
        return Err(Error::invalid(format!(
            "{}: is a folder, not a file",
            path.display()
        )));
    }
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty());
    if let Some(d) = dir
        && !d.is_dir()
    {
        return Err(Error::invalid(format!(
            "{}: folder does not exist",
            d.display()
        )));
    }
    Ok(())
}

/// Saves `img` in `format` to `path` atomically; errors are one line naming
/// the file.
pub fn save<P, C>(img: &ImageBuffer<P, C>, path: &Path, format: ImageFormat) -> Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    crate::io::write_atomic(path, |tmp| img.save_with_format(tmp, format)).map_err(Error::from)
}

/// [`save`] as one output of a run, committed with the others
/// ([`Batch::commit`]).
pub fn save_into<P, C>(
    batch: &mut Batch,
    img: &ImageBuffer<P, C>,
    path: &Path,
    format: ImageFormat,
) -> Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    batch
        .stage(path, |tmp| img.save_with_format(tmp, format))
        .map_err(Error::from)
}

fn write_rgb32f(
    batch: &mut Batch,
    path: &Path,
    w: u32,
    h: u32,
    px: impl Iterator<Item = Vec3>,
) -> Result<()> {
    let data: Vec<f32> = px.flat_map(|c| c.to_array()).collect();
    let img: ImageBuffer<Rgb<f32>, Vec<f32>> =
        ImageBuffer::from_raw(w, h, data).ok_or_else(|| Error::invalid("image size mismatch"))?;
    save_into(batch, &img, path, ImageFormat::OpenExr)
}

/// The frame's radiance as the bytes of the PNG file [`write_image`]
/// writes (the same encoder and settings), for a frame that is sent
/// rather than saved (`splatray view`).
///
/// # Errors
/// The encoder fails.
pub fn png_bytes(frame: &Frame) -> Result<Vec<u8>> {
    rgb8_png(&to_srgb8(frame))
}

/// An 8-bit RGB image as PNG bytes, with [`save`]'s encoder and settings.
///
/// # Errors
/// The encoder fails.
pub fn rgb8_png(img: &ImageBuffer<Rgb<u8>, Vec<u8>>) -> Result<Vec<u8>> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png)
        .map_err(Error::other)?;
    Ok(out.into_inner())
}

/// Writes the frame: PNG (sRGB, 8 bit) or EXR (linear float) by extension.
pub fn write_image(frame: &Frame, path: &Path) -> Result<()> {
    let mut batch = Batch::new();
    write_image_into(&mut batch, frame, path)?;
    batch.commit().map_err(Error::from)
}

/// [`write_image`] as one output of a run ([`Batch`]).
pub fn write_image_into(batch: &mut Batch, frame: &Frame, path: &Path) -> Result<()> {
    match format_of(path)? {
        ImageFormat::OpenExr => write_rgb32f(
            batch,
            path,
            frame.width,
            frame.height,
            frame.rgb.iter().copied(),
        ),
        _ => save_into(batch, &to_srgb8(frame), path, ImageFormat::Png),
    }
}

/// The AOVs a render can write beside its image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aov {
    /// Primary hit distance (miss: +inf).
    Depth,
    /// Resolved shading normal.
    Normal,
    /// Resolved splat id (miss: -1).
    Splat,
    /// Unlit colour, linear (miss: 0).
    Albedo,
}

impl Named for Aov {
    const WHAT: &'static str = "AOV";
    const ALL: &'static [Self] = &[Self::Depth, Self::Normal, Self::Splat, Self::Albedo];
    const NAMES: &'static [&'static str] = &["depth", "normal", "splat", "albedo"];
}

/// Where an AOV of `image` goes: `out.png` → `out.depth.exr`.
#[must_use]
pub fn aov_path(image: &Path, aov: Aov) -> PathBuf {
    let stem = image
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    image.with_file_name(format!("{stem}.{}.exr", aov.name()))
}

/// Writes one AOV as a linear EXR (the value in all three channels for
/// depth and splat id).
pub fn write_aov(frame: &Frame, aov: Aov, path: &Path) -> Result<()> {
    let mut batch = Batch::new();
    write_aov_into(&mut batch, frame, aov, path)?;
    batch.commit().map_err(Error::from)
}

/// [`write_aov`] as one output of a run ([`Batch`]).
pub fn write_aov_into(batch: &mut Batch, frame: &Frame, aov: Aov, path: &Path) -> Result<()> {
    let (w, h) = (frame.width, frame.height);
    match aov {
        Aov::Depth => write_rgb32f(
            batch,
            path,
            w,
            h,
            frame.depth.iter().map(|&d| Vec3::splat(d)),
        ),
        Aov::Normal => write_rgb32f(batch, path, w, h, frame.normal.iter().copied()),
        Aov::Albedo => write_rgb32f(batch, path, w, h, frame.albedo.iter().copied()),
        Aov::Splat => write_rgb32f(
            batch,
            path,
            w,
            h,
            frame
                .splat
                .iter()
                .map(|&id| Vec3::splat(if id == u32::MAX { -1.0 } else { id as f32 })),
        ),
    }
}

/// Stacks images of one width top to bottom into `out`: the bands of one
/// image that renders with `--band I/N` made apart (8-bit RGB PNG, or
/// linear float RGB EXR, as [`write_image`] writes them). The result is
/// the bytes a whole render writes.
///
/// # Errors
/// One line naming the part when a part cannot be read, is of another
/// kind or width than the first, or `out`'s format differs from the parts'.
pub fn stitch(parts: &[PathBuf], out: &Path) -> Result<(u32, u32)> {
    let format = format_of(out)?;
    let mut width = None;
    let mut height = 0u32;
    let mut bytes8: Vec<u8> = Vec::new();
    let mut floats: Vec<f32> = Vec::new();
    for p in parts {
        let img = image::open(p).map_err(|e| Error::other(e).context(p.display()))?;
        let (w, h) = (img.width(), img.height());
        if *width.get_or_insert(w) != w {
            return Err(Error::invalid(format!(
                "{}: {w} pixels wide, the first part {}",
                p.display(),
                width.unwrap_or(0)
            )));
        }
        match (format, img) {
            (ImageFormat::Png, image::DynamicImage::ImageRgb8(b)) => {
                bytes8.extend_from_slice(b.as_raw());
            }
            (ImageFormat::OpenExr, image::DynamicImage::ImageRgb32F(b)) => {
                floats.extend_from_slice(b.as_raw());
            }
            (_, other) => {
                return Err(Error::invalid(format!(
                    "{}: {:?} pixels, not what a render writes to {}",
                    p.display(),
                    other.color(),
                    out.display()
                )));
            }
        }
        height += h;
    }
    let width = width.ok_or_else(|| Error::invalid("no parts to stitch"))?;
    if format == ImageFormat::OpenExr {
        let img: ImageBuffer<Rgb<f32>, Vec<f32>> = ImageBuffer::from_raw(width, height, floats)
            .ok_or_else(|| Error::invalid("image size mismatch"))?;
        save(&img, out, ImageFormat::OpenExr)?;
    } else {
        let img: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_raw(width, height, bytes8)
            .ok_or_else(|| Error::invalid("image size mismatch"))?;
        save(&img, out, ImageFormat::Png)?;
    }
    Ok((width, height))
}
