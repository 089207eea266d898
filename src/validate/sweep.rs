//! Speed against error over the splat budget: the measured counterpart of the
//! report's resolution scaling (§4.4, fig. 16), where the same model is shown
//! with 350k, 110k and 35k splats, flat (Gaussian blending) against Phong
//! splats (normal fields of eq. 4, blended by eq. 5).
//!
//! Each budget step regenerates the splats of every model made from points
//! or a mesh with another error threshold `ϵ` (§2.1); shapes and splat files
//! stay as they are. Every rendering backend of the registry is built once
//! per step and renders the scene in every shading mode; each render is compared with the exact
//! surface of `compare --truth`, which does not depend on the budget and is
//! rendered once.

use crate::accel::registry::renderers;
use crate::error::{Error, Result};
use crate::names::Named;
use crate::progress::Progress;
use crate::render::integrator::{Frame, render};
use crate::resolve::ShadingMode;
use crate::scene::{ModelSpec, Scene, SceneFile, build_scene};
use crate::validate::compare::{TruthErrors, render_truth, truth_errors};
use crate::validate::truth::Truth;
use std::path::Path;

/// The shading modes of a sweep, in CSV and plot order.
pub const MODES: [ShadingMode; 3] = [ShadingMode::Flat, ShadingMode::Blended, ShadingMode::Phong];

/// What a sweep varies and how it renders.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepPlan {
    /// The error thresholds `ϵ` (§2.1, fraction of each model's bounding-box
    /// diagonal), one per budget step, coarse first.
    pub epsilons_rel: Vec<f32>,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl SweepPlan {
    /// `steps` thresholds spaced geometrically from `coarse` down to `fine`
    /// (both included). Errors, in one line, unless `steps >= 2` and
    /// `coarse > fine > 0` are finite.
    pub fn geometric(
        coarse: f32,
        fine: f32,
        steps: usize,
        width: u32,
        height: u32,
    ) -> Result<SweepPlan> {
        if !(fine > 0.0 && coarse > fine && coarse.is_finite()) {
            return Err(Error::invalid(format!(
                "epsilon range {coarse}..{fine} must be finite with coarse > fine > 0"
            )));
        }
        if steps < 2 {
            return Err(Error::invalid(format!("steps {steps} must be at least 2")));
        }
        let ratio = f64::from(fine) / f64::from(coarse);
        let epsilons = (0..steps)
            .map(|i| (f64::from(coarse) * ratio.powf(i as f64 / (steps - 1) as f64)) as f32)
            .collect();
        Ok(SweepPlan {
            epsilons_rel: epsilons,
            width,
            height,
        })
    }
}

/// One backend's figures in one row of the sweep.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BackendFigures {
    /// The backend's registry name.
    pub name: &'static str,
    /// Build seconds (once per step).
    pub build_s: f64,
    /// Render seconds in this row's mode.
    pub render_s: f64,
    /// Millions of rays (all kinds) per second of that render.
    pub mrays_per_s: f64,
    /// Bytes the backend's structure holds (its build statistics).
    pub memory_bytes: usize,
    /// Its render against the exact surface.
    pub errors: TruthErrors,
}

impl BackendFigures {
    /// `frame` rendered by `backend` (named `name`), measured against
    /// `truth`.
    fn measure(
        name: &'static str,
        backend: &dyn crate::accel::Backend,
        frame: Frame,
        truth: (&Frame, &crate::scene::Camera, f32),
    ) -> BackendFigures {
        let stats = backend.stats();
        BackendFigures {
            name,
            build_s: stats.build_seconds,
            render_s: frame.seconds,
            mrays_per_s: frame.rays.total() as f64 / frame.seconds.max(1e-9) / 1e6,
            memory_bytes: stats.memory_bytes,
            errors: truth_errors(frame, truth.0, truth.1, truth.2),
        }
    }
}

/// The sweep's mesh row (issue 57): the varied models' meshes rendered as
/// their triangles ([`SceneFile::meshes_as_triangles`]; shapes and splat
/// files stay as they are), once, on every rendering backend, in Phong
/// mode at the sweep's resolution, shaded as the exact surface is
/// (area-weighted vertex normals where the file has none,
/// [`SceneFile::meshes_as_triangles`] with `smooth`). The mesh is the
/// exact surface every row is measured against, so its row is the point
/// of (near) zero error beside each backend's front; its errors are what
/// its render measures against the exact surface's (the backends' own
/// triangle test against Embree's, shapes still splats), written and
/// plotted as measured.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MeshRow {
    /// Triangles of the meshes.
    pub triangles: usize,
    /// Splats left in that scene (shapes and splat files).
    pub scene_splats: usize,
    /// Every rendering backend on the triangles, the reference first, each
    /// with its errors against the exact surface.
    pub backends: Vec<BackendFigures>,
    /// True when every backend's render of the triangles is the
    /// reference's bit for bit (image, depths and hit ids).
    pub backends_identical: bool,
}

/// What a sweep measures: its rows, and the mesh row when the varied
/// models have meshes.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SweepResult {
    /// One row per budget step and shading mode.
    pub rows: Vec<SweepRow>,
    /// The meshes as triangles.
    pub mesh: Option<MeshRow>,
}

/// One row of the sweep: one budget step in one shading mode, every figure
/// measured in this run.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SweepRow {
    /// Budget step, 0 = coarsest.
    pub step: usize,
    /// `ϵ` of the step (§2.1), fraction of the bounding-box diagonal.
    pub epsilon_rel: f32,
    /// Shading mode (§4: flat, blended by eq. 5, Phong fields of eq. 4),
    /// serialised by its name (`Named::name`).
    #[serde(serialize_with = "serialize_mode")]
    pub shading: ShadingMode,
    /// Splats of the varied models (points and meshes).
    pub splats: usize,
    /// Splats of the whole scene (with shapes and splat files).
    pub scene_splats: usize,
    /// Seconds `build_scene` spent reading, sampling and generating splats.
    pub splat_seconds: f64,
    /// Every rendering backend of the registry, the reference first.
    pub backends: Vec<BackendFigures>,
    /// True when every backend's errors equal the reference's bit for bit
    /// (the backend contract of `docs/DESIGN.md` says they should).
    pub backends_identical: bool,
}

impl SweepRow {
    /// The reference backend's figures (the first).
    #[must_use]
    pub fn reference(&self) -> &BackendFigures {
        &self.backends[0]
    }
}

/// A shading mode as its name, for a serialised [`SweepRow`].
fn serialize_mode<S: serde::Serializer>(mode: &ShadingMode, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(mode.name())
}

fn psnr(p: Option<f64>) -> String {
    p.map_or("inf".to_string(), |p| p.to_string())
}

/// The CSV header for backends `names` (reference first), matching
/// [`csv_line`]: per backend `NAME_build_s`, `NAME_render_s`,
/// `NAME_mrays_per_s` and `NAME_memory_bytes`; the reference's truth errors
/// unprefixed; then per other backend its key errors as `NAME_coverage`,
/// `NAME_normal_deg_mean`, `NAME_psnr_db`.
#[must_use]
pub fn csv_header(names: &[&str]) -> String {
    let mut h = vec![
        "step".to_string(),
        "epsilon".into(),
        "shading".into(),
        "splats".into(),
        "scene_splats".into(),
        "triangles".into(),
        "splat_seconds".into(),
    ];
    for k in ["build_s", "render_s", "mrays_per_s", "memory_bytes"] {
        h.extend(names.iter().map(|n| format!("{n}_{k}")));
    }
    h.extend(
        [
            "coverage",
            "false_hits",
            "depth_rel_p50",
            "depth_rel_p99",
            "normal_deg_mean",
            "normal_deg_p99",
            "psnr_db",
            "backends_identical",
        ]
        .map(String::from),
    );
    for n in names.iter().skip(1) {
        h.extend(["coverage", "normal_deg_mean", "psnr_db"].map(|k| format!("{n}_{k}")));
    }
    h.join(",")
}

/// The cells of [`csv_header`] from `triangles` on, for `backends` (their
/// figures) with errors `errors` (each backend's, reference first).
fn csv_figures(
    triangles: usize,
    splat_seconds: f64,
    backends: &[BackendFigures],
    errors: &[&TruthErrors],
    identical: bool,
) -> Vec<String> {
    let mut c = vec![triangles.to_string(), splat_seconds.to_string()];
    c.extend(backends.iter().map(|b| b.build_s.to_string()));
    c.extend(backends.iter().map(|b| b.render_s.to_string()));
    c.extend(backends.iter().map(|b| b.mrays_per_s.to_string()));
    c.extend(backends.iter().map(|b| b.memory_bytes.to_string()));
    let o = errors[0];
    c.extend([
        o.coverage.to_string(),
        o.false_hits.to_string(),
        o.depth_rel_p50.to_string(),
        o.depth_rel_p99.to_string(),
        o.normal_deg_mean.to_string(),
        o.normal_deg_p99.to_string(),
        psnr(o.image_psnr_db),
        identical.to_string(),
    ]);
    for e in errors.iter().skip(1) {
        c.extend([
            e.coverage.to_string(),
            e.normal_deg_mean.to_string(),
            psnr(e.image_psnr_db),
        ]);
    }
    c
}

/// One CSV line (no newline) for `r`, in the columns of [`csv_header`]. An
/// infinite PSNR (identical images) is written `inf`.
#[must_use]
pub fn csv_line(r: &SweepRow) -> String {
    let mut c = vec![
        r.step.to_string(),
        r.epsilon_rel.to_string(),
        r.shading.name().to_string(),
        r.splats.to_string(),
        r.scene_splats.to_string(),
    ];
    let errors: Vec<&TruthErrors> = r.backends.iter().map(|b| &b.errors).collect();
    c.extend(csv_figures(
        0,
        r.splat_seconds,
        &r.backends,
        &errors,
        r.backends_identical,
    ));
    c.join(",")
}

/// The mesh row's CSV line: step and epsilon 0, shading `mesh`, no varied
/// splats, its triangles, its speeds and its measured errors.
#[must_use]
pub fn csv_mesh_line(m: &MeshRow) -> String {
    let mut c = vec![
        "0".to_string(),
        "0".into(),
        "mesh".into(),
        "0".into(),
        m.scene_splats.to_string(),
    ];
    let errors: Vec<&TruthErrors> = m.backends.iter().map(|b| &b.errors).collect();
    c.extend(csv_figures(
        m.triangles,
        0.0,
        &m.backends,
        &errors,
        m.backends_identical,
    ));
    c.join(",")
}

/// The whole CSV text, header first, one line per row, the mesh row last.
#[must_use]
pub fn csv_text(result: &SweepResult) -> String {
    let names: Vec<&str> = result
        .rows
        .first()
        .map(|r| r.backends.iter().map(|b| b.name).collect())
        .unwrap_or_default();
    let mut s = csv_header(&names);
    s.push('\n');
    for r in &result.rows {
        s.push_str(&csv_line(r));
        s.push('\n');
    }
    if let Some(m) = &result.mesh {
        s.push_str(&csv_mesh_line(m));
        s.push('\n');
    }
    s
}

fn is_generated(m: &ModelSpec) -> bool {
    m.points.is_some() || m.mesh.is_some()
}

/// Sets the camera resolution (keeping the vertical field of view) and the
/// shading mode of every material.
fn set_view(scene: &mut Scene, plan: &SweepPlan, mode: ShadingMode) -> Result<()> {
    scene.set_view(Some(plan.width), Some(plan.height), Some(1), Some(mode))
}

/// Moves a step's scene into the coordinates of the reference (first) step,
/// so that the one render of the exact surface serves every step: the
/// re-centring offset of a scene depends on its splats' bounding box, hence
/// slightly on the budget. Camera, lights and the scene-relative
/// `eps_self` are the reference's too; the blending windows stay the
/// step's own, measured on its splats.
fn reframe(step: &mut Scene, reference: &Scene) {
    let shift = step.offset - reference.offset;
    for s in &mut step.splats {
        s.center += shift;
    }
    step.offset = reference.offset;
    step.camera = reference.camera;
    step.lights.clone_from(&reference.lights);
    let xi = step.options.scale.xi;
    step.options = reference.options;
    step.options.scale.xi = xi;
    step.shading_of.clone_from(&reference.shading_of);
}

/// Runs a sweep over `plan` for the scene `file` (relative paths against
/// `base`): per budget step the splats are generated once, every rendering backend
/// built once, and each shading mode of [`MODES`] rendered by both and
/// compared with the exact surface. Splat generation reports to `progress`
/// (renders do not); `log` receives one line per measurement as it is
/// made.
///
/// Errors (one line) when no model is made from points or a mesh, when a
/// model has no exact surface (point files), or when loading fails.
pub fn run_sweep(
    file: &SceneFile,
    base: &Path,
    plan: &SweepPlan,
    progress: Option<Progress<'_>>,
    log: &mut dyn FnMut(&str),
) -> Result<SweepResult> {
    if !file.models.iter().any(is_generated) {
        return Err(Error::invalid(
            "the scene has no model made from points or a mesh: nothing to vary",
        ));
    }
    let generated: Vec<u16> = (0..file.models.len())
        .filter(|&i| is_generated(&file.models[i]))
        .map(|i| i as u16)
        .collect();
    let mut reference: Option<(Scene, Frame)> = None;
    let mut rows = Vec::new();
    for (step, &eps) in plan.epsilons_rel.iter().enumerate() {
        let mut f = file.clone();
        for m in f.models.iter_mut().filter(|m| is_generated(m)) {
            m.splat.epsilon_rel = Some(eps);
        }
        let mut scene = build_scene(&f, base, progress)?;
        set_view(&mut scene, plan, ShadingMode::Phong)?;
        // Each step holds every backend's accelerator, the truth's frame
        // and the one being measured.
        let holds = crate::render::budget::Holds {
            frames: 2,
            accelerators: u32::try_from(crate::accel::registry::renderers().len())
                .unwrap_or(u32::MAX),
        };
        crate::render::budget::check(&scene, holds, &crate::render::budget::Limits::default())?;
        if reference.is_none() {
            let truth = Truth::new(&scene)?;
            let tf = render_truth(&scene, &truth, None);
            log(&format!(
                "exact surface: rendered once in {:.3} s ({}x{})",
                tf.seconds, plan.width, plan.height
            ));
            reference = Some((scene.clone(), tf));
        }
        let Some((ref_scene, truth_frame)) = &reference else {
            unreachable!("set above")
        };
        reframe(&mut scene, ref_scene);
        let splats = scene
            .material_of
            .iter()
            .filter(|m| generated.contains(m))
            .count();
        let mut built = Vec::new();
        for info in renderers() {
            let b = info.build_scene(&scene)?;
            built.push((info.name, b));
        }
        let builds: Vec<String> = built
            .iter()
            .map(|(n, b)| format!("{n} {:.3} s", b.stats().build_seconds))
            .collect();
        log(&format!(
            "step {step}: epsilon {eps:.5}, {splats} splats ({} in the scene) generated in {:.2} s; build {}",
            scene.splats.len(),
            scene.load.splat_seconds,
            builds.join(", ")
        ));
        let diagonal = scene.options.scale.diagonal;
        for mode in MODES {
            set_view(&mut scene, plan, mode)?;
            let backends: Vec<BackendFigures> = built
                .iter()
                .map(|(name, b)| {
                    let fr = render(&scene, b.as_ref(), None);
                    let truth = (truth_frame, &scene.camera, diagonal);
                    BackendFigures::measure(name, b.as_ref(), fr, truth)
                })
                .collect();
            let reference = &backends[0];
            let differ: Vec<&BackendFigures> = backends
                .iter()
                .filter(|b| b.errors != reference.errors)
                .collect();
            let renders: Vec<String> = backends
                .iter()
                .map(|b| format!("{} {:.3} s", b.name, b.render_s))
                .collect();
            let o = &reference.errors;
            let fmt_psnr = |p: Option<f64>| p.map_or("inf".to_string(), |p| format!("{p:.2} dB"));
            let differences: String = if differ.is_empty() {
                ", backends identical".to_string()
            } else {
                differ
                    .iter()
                    .map(|b| {
                        format!(
                            "; {} differs: normal deg mean {:.3}, PSNR {}",
                            b.name,
                            b.errors.normal_deg_mean,
                            fmt_psnr(b.errors.image_psnr_db)
                        )
                    })
                    .collect()
            };
            log(&format!(
                "  {:<7} render {}; coverage {:.5}, false hits {:.5}, depth/diag p50 {:.2e} p99 {:.2e}, normal deg mean {:.3} p99 {:.3}, PSNR {}{differences}",
                mode.name(),
                renders.join(", "),
                o.coverage,
                o.false_hits,
                o.depth_rel_p50,
                o.depth_rel_p99,
                o.normal_deg_mean,
                o.normal_deg_p99,
                fmt_psnr(o.image_psnr_db),
            ));
            let row = SweepRow {
                step,
                epsilon_rel: eps,
                shading: mode,
                splats,
                scene_splats: scene.splats.len(),
                splat_seconds: scene.load.splat_seconds,
                backends_identical: differ.is_empty(),
                backends,
            };
            rows.push(row);
        }
    }
    let mesh = match &reference {
        Some((ref_scene, truth_frame)) => {
            mesh_row(file, base, plan, (ref_scene, truth_frame), progress, log)?
        }
        None => None,
    };
    Ok(SweepResult { rows, mesh })
}

/// The sweep's [`MeshRow`]: `file`'s meshes as triangles, built and
/// rendered once on every rendering backend at `plan`'s resolution in
/// Phong mode, each render timed and measured against the exact
/// surface's frame of `reference`; `None` when no model has a mesh.
fn mesh_row(
    file: &SceneFile,
    base: &Path,
    plan: &SweepPlan,
    reference: (&Scene, &Frame),
    progress: Option<Progress<'_>>,
    log: &mut dyn FnMut(&str),
) -> Result<Option<MeshRow>> {
    let (tris, n) = file.meshes_as_triangles(true);
    if n == 0 {
        return Ok(None);
    }
    let mut scene = build_scene(&tris, base, progress)?;
    set_view(&mut scene, plan, ShadingMode::Phong)?;
    let holds = crate::render::budget::Holds {
        frames: 2,
        accelerators: 1,
    };
    crate::render::budget::check(&scene, holds, &crate::render::budget::Limits::default())?;
    let (ref_scene, truth_frame) = reference;
    let truth = (truth_frame, &ref_scene.camera, ref_scene.options.scale.diagonal);
    let mut backends = Vec::new();
    let mut first: Option<Frame> = None;
    let mut identical = true;
    for info in renderers() {
        let b = info.build_scene(&scene)?;
        let fr = render(&scene, b.as_ref(), None);
        match &first {
            None => first = Some(fr.clone()),
            Some(f) => identical &= same_frame(f, &fr),
        }
        backends.push(BackendFigures::measure(info.name, b.as_ref(), fr, truth));
    }
    let figures: Vec<String> = backends
        .iter()
        .map(|b| {
            format!(
                "{} build {:.3} s, render {:.3} s ({:.2} Mrays/s), {:.1} MB",
                b.name,
                b.build_s,
                b.render_s,
                b.mrays_per_s,
                b.memory_bytes as f64 / 1e6
            )
        })
        .collect();
    let o = &backends[0].errors;
    log(&format!(
        "mesh as triangles: {} triangles ({} splats beside them); {}; backends {}; \
         against the exact surface's render: normal deg mean {:.4}, PSNR {}",
        scene.triangles.tris.len(),
        scene.splats.len(),
        figures.join("; "),
        if identical { "identical" } else { "differ" },
        o.normal_deg_mean,
        o.image_psnr_db
            .map_or("inf".to_string(), |p| format!("{p:.2} dB")),
    ));
    Ok(Some(MeshRow {
        triangles: scene.triangles.tris.len(),
        scene_splats: scene.splats.len(),
        backends,
        backends_identical: identical,
    }))
}

/// True when two renders give the same image, depths and hit ids, bit for
/// bit.
fn same_frame(a: &Frame, b: &Frame) -> bool {
    let bits = |x: &f32| x.to_bits();
    let rgb = |c: &glam::Vec3| c.to_array().map(f32::to_bits);
    a.rgb.iter().map(rgb).eq(b.rgb.iter().map(rgb))
        && a.depth.iter().map(bits).eq(b.depth.iter().map(bits))
        && a.splat == b.splat
}

/// One configuration on a Pareto front of render time against image error.
#[derive(Clone, Debug, PartialEq)]
pub struct ParetoPoint {
    /// The row's budget step and `ϵ`.
    pub step: usize,
    /// See `step`.
    pub epsilon_rel: f32,
    /// The row's shading mode.
    pub shading: ShadingMode,
    /// Splats of the varied models.
    pub splats: usize,
    /// Render seconds.
    pub render_s: f64,
    /// PSNR against the exact surface (`f64::INFINITY` when identical).
    pub psnr_db: f64,
}

/// The Pareto front of `backend`'s rows (every step and shading mode): the
/// configurations no other renders both faster and closer to the exact
/// surface (higher PSNR), fastest first. "Speed against error" in one list:
/// each is the most accurate of the configurations at least as fast.
#[must_use]
pub fn pareto(rows: &[SweepRow], backend: &str) -> Vec<ParetoPoint> {
    let mut pts: Vec<ParetoPoint> = rows
        .iter()
        .filter_map(|r| {
            let b = r.backends.iter().find(|b| b.name == backend)?;
            Some(ParetoPoint {
                step: r.step,
                epsilon_rel: r.epsilon_rel,
                shading: r.shading,
                splats: r.splats,
                render_s: b.render_s,
                psnr_db: b.errors.image_psnr_db.unwrap_or(f64::INFINITY),
            })
        })
        .collect();
    // Fastest first (higher PSNR first among equal times); a point joins
    // the front when it beats every faster one's PSNR.
    pts.sort_by(|a, b| {
        a.render_s
            .total_cmp(&b.render_s)
            .then(b.psnr_db.total_cmp(&a.psnr_db))
    });
    let mut best = f64::NEG_INFINITY;
    pts.retain(|p| {
        let keep = p.psnr_db > best;
        best = best.max(p.psnr_db);
        keep
    });
    pts
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(step: usize, shading: ShadingMode, render_s: f64, psnr: f64) -> SweepRow {
        SweepRow {
            step,
            epsilon_rel: 0.01,
            shading,
            splats: 100 * (step + 1),
            scene_splats: 100 * (step + 1),
            splat_seconds: 0.0,
            backends: vec![BackendFigures {
                name: "octree",
                build_s: 0.0,
                render_s,
                mrays_per_s: 1.0,
                memory_bytes: 1,
                errors: TruthErrors {
                    coverage: 1.0,
                    false_hits: 0.0,
                    depth_rel_p50: 0.0,
                    depth_rel_p99: 0.0,
                    normal_deg_mean: 0.0,
                    normal_deg_p99: 0.0,
                    image_psnr_db: Some(psnr),
                },
            }],
            backends_identical: true,
        }
    }

    #[test]
    fn the_pareto_front_keeps_what_nothing_faster_beats() {
        let rows = [
            row(0, ShadingMode::Flat, 0.10, 20.0),
            row(0, ShadingMode::Phong, 0.12, 24.0),
            row(1, ShadingMode::Flat, 0.15, 23.0), // slower than Phong at step 0, worse
            row(1, ShadingMode::Phong, 0.20, 28.0),
            row(2, ShadingMode::Blended, 0.20, 27.0), // as fast as the one before, worse
            row(2, ShadingMode::Phong, 0.30, 28.0),   // slower, no better
        ];
        let front = pareto(&rows, "octree");
        let got: Vec<(usize, ShadingMode)> = front.iter().map(|p| (p.step, p.shading)).collect();
        assert_eq!(
            got,
            [
                (0, ShadingMode::Flat),
                (0, ShadingMode::Phong),
                (1, ShadingMode::Phong)
            ]
        );
        assert!(pareto(&rows, "embree").is_empty());
    }

    #[test]
    fn geometric_plan_spans_the_range_in_order() {
        let p = SweepPlan::geometric(0.05, 0.0005, 5, 32, 24).unwrap();
        assert_eq!(p.epsilons_rel.len(), 5);
        assert!((p.epsilons_rel[0] - 0.05).abs() < 1e-7);
        assert!((p.epsilons_rel[4] - 0.0005).abs() < 1e-8);
        assert!(
            (p.epsilons_rel[2] - 0.005).abs() < 1e-6,
            "{:?}",
            p.epsilons_rel
        );
        assert!(p.epsilons_rel.windows(2).all(|w| w[1] < w[0]));
        for (c, f, n) in [
            (0.001, 0.01, 5),
            (0.01, 0.0, 5),
            (f32::NAN, 0.1, 5),
            (0.1, 0.01, 1),
        ] {
            assert!(SweepPlan::geometric(c, f, n, 8, 8).is_err(), "{c} {f} {n}");
        }
    }

    #[test]
    fn csv_line_matches_the_header() {
        let e = TruthErrors {
            coverage: 1.0,
            false_hits: 0.0,
            depth_rel_p50: 0.0,
            depth_rel_p99: 0.0,
            normal_deg_mean: 1.5,
            normal_deg_p99: 3.0,
            image_psnr_db: None,
        };
        let r = SweepRow {
            step: 2,
            epsilon_rel: 0.01,
            shading: ShadingMode::Blended,
            splats: 10,
            scene_splats: 12,
            splat_seconds: 0.5,
            backends: vec![
                BackendFigures {
                    name: "octree",
                    build_s: 0.1,
                    render_s: 0.3,
                    mrays_per_s: 2.5,
                    memory_bytes: 1000,
                    errors: e.clone(),
                },
                BackendFigures {
                    name: "embree",
                    build_s: 0.2,
                    render_s: 0.4,
                    mrays_per_s: 2.0,
                    memory_bytes: 2000,
                    errors: TruthErrors {
                        image_psnr_db: Some(30.0),
                        ..e
                    },
                },
            ],
            backends_identical: false,
        };
        let mesh = MeshRow {
            triangles: 7,
            scene_splats: 2,
            backends: r.backends.clone(),
            backends_identical: true,
        };
        let text = csv_text(&SweepResult {
            rows: vec![r],
            mesh: Some(mesh),
        });
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let cells: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(header.len(), cells.len());
        let cell = |k: &str| cells[header.iter().position(|h| *h == k).unwrap()];
        assert_eq!(cell("shading"), "blended");
        assert_eq!(cell("normal_deg_mean"), "1.5");
        assert_eq!(cell("psnr_db"), "inf");
        assert_eq!(cell("embree_psnr_db"), "30");
        assert_eq!(cell("backends_identical"), "false");
        assert_eq!(cell("embree_render_s"), "0.4");
        assert_eq!(cell("embree_mrays_per_s"), "2");
        assert_eq!(cell("octree_memory_bytes"), "1000");
        assert_eq!(cell("triangles"), "0");
        assert_eq!(
            header.join(","),
            "step,epsilon,shading,splats,scene_splats,triangles,splat_seconds,\
octree_build_s,embree_build_s,octree_render_s,embree_render_s,\
octree_mrays_per_s,embree_mrays_per_s,octree_memory_bytes,embree_memory_bytes,\
coverage,false_hits,depth_rel_p50,depth_rel_p99,normal_deg_mean,normal_deg_p99,psnr_db,\
backends_identical,embree_coverage,embree_normal_deg_mean,embree_psnr_db"
        );
        // The mesh row: last, its speeds, its measured errors.
        let m: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert!(lines.next().is_none());
        assert_eq!(m.len(), header.len());
        let cell = |k: &str| m[header.iter().position(|h| *h == k).unwrap()];
        assert_eq!((cell("shading"), cell("triangles")), ("mesh", "7"));
        assert_eq!((cell("splats"), cell("scene_splats")), ("0", "2"));
        assert_eq!(cell("embree_render_s"), "0.4");
        for k in ["normal_deg_mean", "embree_normal_deg_mean"] {
            assert_eq!(cell(k), "1.5", "{k}");
        }
        assert_eq!((cell("psnr_db"), cell("embree_psnr_db")), ("inf", "30"));
        assert_eq!(cell("backends_identical"), "true");
    }
}
