//! The speed-against-error plot of the sweep workflow (`splatray sweep
//! --plot`): the report's resolution
//! scaling (§4.4, fig. 16), measured. Drawn with `plotters` and the DejaVu
//! Sans font the project ships (`assets/fonts/`), so it needs no system
//! fonts; written as PNG and as SVG beside it.

use crate::names::Named;
use crate::resolve::ShadingMode;
use crate::validate::compare::TruthErrors;
use crate::validate::sweep::{MODES, MeshRow, SweepResult, SweepRow};
use crate::{Error, Result};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// DejaVu Sans (Bitstream Vera licence, see `assets/fonts/README.md`).
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";
const SIZE: (u32, u32) = (1280, 560);

/// A drawing error, said as the plot's.
fn err(e: impl std::error::Error + Send + Sync + 'static) -> Error {
    Error::other(e).context("plot")
}

fn mode_color(i: usize) -> RGBColor {
    [
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(31, 119, 180),
    ][i % 3]
}

/// Line patterns by backend, in registry order: (dash, gap) in pixels, 0
/// for a solid line.
const DASHES: [(u32, u32); 4] = [(0, 0), (8, 4), (2, 4), (12, 4)];

fn short_count(n: usize) -> String {
    if n >= 10_000 {
        format!("{}k", (n as f64 / 1000.0).round())
    } else if n >= 1000 {
        format!("{:.1}k", n as f64 / 1000.0)
    } else {
        n.to_string()
    }
}

/// The chart of a panel: render seconds (log scale) across, `y` up.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, RangedCoordf64>>;

/// The axis ranges of a panel: the render seconds of every row and of the
/// mesh (log scale, padded by factors), and `y` of every row and of the
/// mesh's backends (padded by 8 %).
fn ranges(
    rows: &[SweepRow],
    mesh: Option<&MeshRow>,
    y: fn(&TruthErrors) -> Option<f64>,
) -> ((f64, f64), (f64, f64)) {
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for r in rows {
        xs.extend(r.backends.iter().map(|b| b.render_s));
        ys.extend(r.backends.iter().filter_map(|b| y(&b.errors)));
    }
    if let Some(m) = mesh {
        xs.extend(m.backends.iter().map(|b| b.render_s));
        ys.extend(m.backends.iter().filter_map(|b| y(&b.errors)));
    }
    let fin = |v: &Vec<f64>| {
        v.iter()
            .copied()
            .filter(|x| x.is_finite())
            .collect::<Vec<_>>()
    };
    let (xs, ys) = (fin(&xs), fin(&ys));
    let lo = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let x = if xs.is_empty() {
        (1e-3, 1.0)
    } else {
        (lo(&xs).max(1e-6) / 1.3, hi(&xs).max(1e-6) * 1.6)
    };
    let y = if ys.is_empty() {
        (0.0, 1.0)
    } else {
        let (a, b) = (lo(&ys), hi(&ys));
        let pad = ((b - a) * 0.08).max(1e-3);
        (a - pad, b + pad)
    };
    (x, y)
}

/// The panel's chart over `((x0, x1), (y0, y1))` with its axes, grid and
/// labels drawn.
fn axes<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    ((x0, x1), (y0, y1)): ((f64, f64), (f64, f64)),
    caption: &str,
    y_desc: &str,
) -> Result<Chart<'a, DB>>
where
    DB::ErrorType: 'static,
{
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FAMILY, 20))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(58)
        .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("render seconds (log scale)")
        .y_desc(y_desc)
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 15))
        .x_labels(20)
        .x_label_formatter(&|v| {
            let s = format!("{v:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        })
        .max_light_lines(1)
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// One curve: backend `k` in shading mode `mode`, its line (each backend
/// its own pattern) and its markers.
fn curve<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    rows: &[SweepRow],
    (mi, mode): (usize, ShadingMode),
    k: usize,
    y: fn(&TruthErrors) -> Option<f64>,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let color = mode_color(mi);
    let pts: Vec<(f64, f64, usize)> = rows
        .iter()
        .filter(|r| r.shading == mode)
        .filter_map(|r| {
            let b = &r.backends[k];
            y(&b.errors)
                .filter(|v| v.is_finite())
                .map(|v| (b.render_s, v, r.splats))
        })
        .collect();
    let name = format!(
        "{} {}",
        rows.first().map_or("", |r| r.backends[k].name),
        mode.name()
    );
    let xy: Vec<(f64, f64)> = pts.iter().map(|&(x, y, _)| (x, y)).collect();
    let stroke = color.stroke_width(2);
    let (dash, gap) = DASHES[k % DASHES.len()];
    let line = if dash == 0 {
        chart
            .draw_series(LineSeries::new(xy, stroke))
            .map_err(err)?
    } else {
        chart
            .draw_series(DashedLineSeries::new(xy, dash, gap, stroke))
            .map_err(err)?
    };
    line.label(name).legend(move |(x, y)| {
        // Three periods of the pattern within 22 pixels (a solid
        // line: three times the whole length).
        let (d, p) = if dash == 0 {
            (22, 0)
        } else {
            let d = i32::try_from(dash).unwrap_or(8);
            (d, d + i32::try_from(gap).unwrap_or(4))
        };
        let seg = |i: i32| PathElement::new(vec![(i * p, 0), ((i * p + d).min(22), 0)], stroke);
        EmptyElement::at((x, y)) + seg(0) + seg(1) + seg(2)
    });
    markers(chart, &pts, k, color)
}

/// Backend `k`'s markers at `pts` (dot, triangle, cross, square); the
/// reference (the first) labels its points with the splat counts.
fn markers<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    pts: &[(f64, f64, usize)],
    k: usize,
    color: RGBColor,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let stroke = color.stroke_width(2);
    let at = pts.iter().map(|&(x, y, _)| (x, y));
    match k % 4 {
        0 => chart.draw_series(at.map(|p| Circle::new(p, 4, color.filled()))),
        1 => chart.draw_series(at.map(|p| TriangleMarker::new(p, 5, stroke))),
        2 => chart.draw_series(at.map(|p| Cross::new(p, 4, stroke))),
        _ => chart.draw_series(
            at.map(|p| EmptyElement::at(p) + Rectangle::new([(-4, -4), (4, 4)], stroke)),
        ),
    }
    .map_err(err)?;
    if k == 0 {
        chart
            .draw_series(pts.iter().map(|&(x, y, n)| {
                EmptyElement::at((x, y))
                    + Text::new(short_count(n), (6, -14), (FAMILY, 12).into_font())
            }))
            .map_err(err)?;
    }
    Ok(())
}

/// The mesh row's points (issue 57): each backend's render seconds on the
/// triangles at its measured `y` (`None`: an infinite PSNR, drawn at the
/// top of `ys`), in black with the backend's marker, labelled with its
/// name; one legend entry.
fn mesh_points<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    mesh: &MeshRow,
    y: fn(&TruthErrors) -> Option<f64>,
    (y0, y1): (f64, f64),
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    for (k, b) in mesh.backends.iter().enumerate() {
        let at = y(&b.errors);
        let y = at.unwrap_or(y0 + 0.96 * (y1 - y0));
        let label = if at.is_some() { "" } else { ", inf dB" };
        let p = [(b.render_s, y, 0)];
        markers(chart, &p, k + 4, BLACK)?;
        let text = format!("mesh {}{label}", b.name);
        let placed = chart
            .draw_series(std::iter::once(
                EmptyElement::at((b.render_s, y))
                    + Text::new(
                        text,
                        (7, 4 + 14 * i32::from(k % 2 == 1)),
                        (FAMILY, 12).into_font(),
                    ),
            ))
            .map_err(err)?;
        if k == 0 {
            let name = format!("mesh, {} triangles (smooth-shaded)", mesh.triangles);
            placed.label(name).legend(|(x, y)| {
                EmptyElement::at((x + 11, y)) + Circle::new((0, 0), 4, BLACK.filled())
            });
        }
    }
    Ok(())
}

/// One panel: `y` of every row against render seconds, log-scaled seconds,
/// and the mesh's points (see [`mesh_points`]).
fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    result: &SweepResult,
    (caption, y_desc): (&str, &str),
    y: fn(&TruthErrors) -> Option<f64>,
    legend: bool,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let rows = &result.rows;
    let range = ranges(rows, result.mesh.as_ref(), y);
    let mut chart = axes(area, range, caption, y_desc)?;
    let count = rows.first().map_or(0, |r| r.backends.len());
    for mode in MODES.into_iter().enumerate() {
        for k in 0..count {
            curve(&mut chart, rows, mode, k, y)?;
        }
    }
    if let Some(m) = &result.mesh {
        mesh_points(&mut chart, m, y, range.1)?;
    }
    if legend {
        chart
            .configure_series_labels()
            .label_font((FAMILY, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, result: &SweepResult) -> Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled(
            "Render time against error over the splat budget (labels: splats; report fig. 16)",
            (FAMILY, 22),
        )
        .map_err(err)?;
    let (left, right) = root.split_horizontally(SIZE.0 / 2);
    panel(
        &left,
        result,
        (
            "mean normal error vs exact surface",
            "normal error, degrees (mean)",
        ),
        |e| Some(e.normal_deg_mean),
        true,
    )?;
    panel(
        &right,
        result,
        ("image PSNR vs exact surface", "PSNR, dB (higher is better)"),
        |e| e.image_psnr_db,
        false,
    )?;
    root.present().map_err(err)
}

/// Draws the sweep's rows (render seconds against mean normal error and
/// against image PSNR, one curve per backend and shading mode, points
/// labelled with splat counts; the mesh row's point per backend at its
/// measured error, in black) into `png` and into the SVG of the same stem. Both
/// files are written atomically; errors are one line.
pub fn plot_sweep(batch: &mut crate::io::Batch, result: &SweepResult, png: &Path) -> Result<()> {
    plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
        .map_err(|_| Error::invalid("plot: the embedded font is invalid"))?;
    let mut buf = vec![255u8; (SIZE.0 * SIZE.1 * 3) as usize];
    draw(
        BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area(),
        result,
    )?;
    let img = image::RgbImage::from_raw(SIZE.0, SIZE.1, buf)
        .ok_or_else(|| Error::invalid("plot: image buffer has the wrong size"))?;
    let mut svg = String::new();
    draw(
        SVGBackend::with_string(&mut svg, SIZE).into_drawing_area(),
        result,
    )?;
    crate::render::output::save_into(batch, &img, png, image::ImageFormat::Png)?;
    batch.stage(&png.with_extension("svg"), |t| std::fs::write(t, &svg))?;
    Ok(())
}
