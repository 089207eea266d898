//! Speed against error over the splat budget: the measured counterpart of the
//! report's resolution scaling (§4.4, fig. 16), where the same model is shown
//! with 350k, 110k and 35k splats, flat (Gaussian blending) against Phong
//! splats (normal fields of eq. 4, blended by eq. 5).
//!
//! Each budget step regenerates the splats of every model made from points
//! or a mesh with another error threshold `ϵ` (§2.1); shapes and splat files
//! stay as they are. Both backends are built once per step and render the
//! scene in every shading mode; each render is compared with the exact
//! surface of `compare --truth`, which does not depend on the budget and is
//! rendered once.

use crate::accel::BackendKind;
use crate::progress::Progress;
use crate::render::integrator::{Frame, render};
use crate::resolve::ShadingMode;
use crate::scene::{ModelSpec, Scene, SceneFile, build_scene};
use crate::validate::compare::{TruthErrors, render_truth, truth_errors};
use crate::validate::truth::Truth;
use std::path::Path;

/// The shading modes of a sweep, in CSV and plot order.
pub const MODES: [ShadingMode; 3] = [ShadingMode::Flat, ShadingMode::Blended, ShadingMode::Phong];

/// The name of a shading mode as the scene files and `--shading` spell it.
#[must_use]
pub fn mode_name(m: ShadingMode) -> &'static str {
    match m {
        ShadingMode::Flat => "flat",
        ShadingMode::Blended => "blended",
        ShadingMode::Phong => "phong",
    }
}

/// What a sweep varies and how it renders.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepPlan {
    /// The error thresholds `ϵ` (§2.1, fraction of each model's bounding-box
    /// diagonal), one per budget step, coarse first.
    pub epsilons: Vec<f32>,
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
    ) -> Result<SweepPlan, String> {
        if !(fine > 0.0 && coarse > fine && coarse.is_finite()) {
            return Err(format!(
                "epsilon range {coarse}..{fine} must be finite with coarse > fine > 0"
            ));
        }
        if steps < 2 {
            return Err(format!("steps {steps} must be at least 2"));
        }
        let ratio = f64::from(fine) / f64::from(coarse);
        let epsilons = (0..steps)
            .map(|i| (f64::from(coarse) * ratio.powf(i as f64 / (steps - 1) as f64)) as f32)
            .collect();
        Ok(SweepPlan {
            epsilons,
            width,
            height,
        })
    }
}

/// One row of the sweep: one budget step in one shading mode, every figure
/// measured in this run.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepRow {
    /// Budget step, 0 = coarsest.
    pub step: usize,
    /// `ϵ` of the step (§2.1), fraction of the bounding-box diagonal.
    pub epsilon: f32,
    /// Shading mode (§4: flat, blended by eq. 5, Phong fields of eq. 4).
    pub shading: ShadingMode,
    /// Splats of the varied models (points and meshes).
    pub splats: usize,
    /// Splats of the whole scene (with shapes and splat files).
    pub scene_splats: usize,
    /// Seconds `build_scene` spent reading, sampling and generating splats.
    pub splat_seconds: f64,
    /// Octree build seconds (once per step).
    pub octree_build_s: f64,
    /// Embree build seconds (once per step).
    pub embree_build_s: f64,
    /// Octree render seconds in this mode.
    pub octree_render_s: f64,
    /// Embree render seconds in this mode.
    pub embree_render_s: f64,
    /// The octree's render against the exact surface.
    pub octree: TruthErrors,
    /// Embree's render against the exact surface.
    pub embree: TruthErrors,
    /// True when both backends' errors are equal bit for bit (the contract of
    /// DESIGN §2 says they should be).
    pub backends_identical: bool,
}

/// The CSV header, matching [`csv_line`].
pub const CSV_HEADER: &str = "step,epsilon,shading,splats,scene_splats,splat_seconds,\
octree_build_s,embree_build_s,octree_render_s,embree_render_s,\
coverage,false_hits,depth_rel_p50,depth_rel_p99,normal_deg_mean,normal_deg_p99,psnr_db,\
backends_identical,embree_coverage,embree_normal_deg_mean,embree_psnr_db";

fn psnr(p: Option<f64>) -> String {
    p.map_or("inf".to_string(), |p| p.to_string())
}

/// One CSV line (no newline) for `r`: the unprefixed truth errors are the
/// octree's, `embree_*` repeats the key ones for Embree. An infinite PSNR
/// (identical images) is written `inf`.
#[must_use]
pub fn csv_line(r: &SweepRow) -> String {
    let (o, e) = (&r.octree, &r.embree);
    format!(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        r.step,
        r.epsilon,
        mode_name(r.shading),
        r.splats,
        r.scene_splats,
        r.splat_seconds,
        r.octree_build_s,
        r.embree_build_s,
        r.octree_render_s,
        r.embree_render_s,
        o.coverage,
        o.false_hits,
        o.depth_rel_p50,
        o.depth_rel_p99,
        o.normal_deg_mean,
        o.normal_deg_p99,
        psnr(o.image_psnr_db),
        r.backends_identical,
        e.coverage,
        e.normal_deg_mean,
        psnr(e.image_psnr_db),
    )
}

/// The whole CSV text, header first, one line per row.
#[must_use]
pub fn csv_text(rows: &[SweepRow]) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        s.push_str(&csv_line(r));
        s.push('\n');
    }
    s
}

fn is_generated(m: &ModelSpec) -> bool {
    m.points.is_some() || m.mesh.is_some()
}

/// Sets the camera resolution (keeping the vertical field of view) and the
/// shading mode of every material.
fn set_view(scene: &mut Scene, plan: &SweepPlan, mode: ShadingMode) -> Result<(), String> {
    scene.set_view(Some(plan.width), Some(plan.height), Some(1), Some(mode))
}

/// Moves a step's scene into the coordinates of the reference (first) step,
/// so that the one render of the exact surface serves every step: the
/// re-centring offset of a scene depends on its splats' bounding box, hence
/// slightly on the budget. Camera, lights and the scene-relative `xi` and
/// `eps_self` are the reference's too.
fn reframe(step: &mut Scene, reference: &Scene) {
    let shift = step.offset - reference.offset;
    for s in &mut step.splats {
        s.center += shift;
    }
    step.offset = reference.offset;
    step.camera = reference.camera;
    step.lights.clone_from(&reference.lights);
    step.options = reference.options;
    step.shading_of.clone_from(&reference.shading_of);
}

/// Runs a sweep over `plan` for the scene `file` (relative paths against
/// `base`): per budget step the splats are generated once, both backends
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
) -> Result<Vec<SweepRow>, String> {
    if !file.models.iter().any(is_generated) {
        return Err(
            "the scene has no model made from points or a mesh: nothing to vary".to_string(),
        );
    }
    let generated: Vec<u16> = (0..file.models.len())
        .filter(|&i| is_generated(&file.models[i]))
        .map(|i| i as u16)
        .collect();
    let mut reference: Option<(Scene, Frame)> = None;
    let mut rows = Vec::new();
    for (step, &eps) in plan.epsilons.iter().enumerate() {
        let mut f = file.clone();
        for m in f.models.iter_mut().filter(|m| is_generated(m)) {
            m.splat.epsilon = Some(eps);
        }
        let mut scene = build_scene(&f, base, progress)?;
        set_view(&mut scene, plan, ShadingMode::Phong)?;
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
        let octree = BackendKind::Octree.build(&scene.splats)?;
        let embree = BackendKind::Embree.build(&scene.splats)?;
        let (ob, eb) = (octree.stats().build_seconds, embree.stats().build_seconds);
        log(&format!(
            "step {step}: epsilon {eps:.5}, {splats} splats ({} in the scene) generated in {:.2} s; build octree {ob:.3} s, embree {eb:.3} s",
            scene.splats.len(),
            scene.load.splat_seconds
        ));
        let diagonal = scene.options.scale.diagonal;
        for mode in MODES {
            set_view(&mut scene, plan, mode)?;
            let errors = |backend: &dyn crate::accel::Backend| {
                let fr = render(&scene, backend, None);
                let seconds = fr.seconds;
                (
                    seconds,
                    truth_errors(fr, truth_frame, &scene.camera, diagonal),
                )
            };
            let (os, oe) = errors(octree.as_ref());
            let (es, ee) = errors(embree.as_ref());
            let row = SweepRow {
                step,
                epsilon: eps,
                shading: mode,
                splats,
                scene_splats: scene.splats.len(),
                splat_seconds: scene.load.splat_seconds,
                octree_build_s: ob,
                embree_build_s: eb,
                octree_render_s: os,
                embree_render_s: es,
                backends_identical: oe == ee,
                octree: oe,
                embree: ee,
            };
            log(&format!(
                "  {:<7} render octree {:.3} s, embree {:.3} s; coverage {:.5}, false hits {:.5}, depth/diag p50 {:.2e} p99 {:.2e}, normal deg mean {:.3} p99 {:.3}, PSNR {}{}",
                mode_name(mode),
                os,
                es,
                row.octree.coverage,
                row.octree.false_hits,
                row.octree.depth_rel_p50,
                row.octree.depth_rel_p99,
                row.octree.normal_deg_mean,
                row.octree.normal_deg_p99,
                row.octree
                    .image_psnr_db
                    .map_or("inf".to_string(), |p| format!("{p:.2} dB")),
                if row.backends_identical {
                    ", backends identical".to_string()
                } else {
                    format!(
                        "; embree differs: normal deg mean {:.3}, PSNR {}",
                        row.embree.normal_deg_mean,
                        row.embree
                            .image_psnr_db
                            .map_or("inf".to_string(), |p| format!("{p:.2} dB"))
                    )
                }
            ));
            rows.push(row);
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometric_plan_spans_the_range_in_order() {
        let p = SweepPlan::geometric(0.05, 0.0005, 5, 32, 24).unwrap();
        assert_eq!(p.epsilons.len(), 5);
        assert!((p.epsilons[0] - 0.05).abs() < 1e-7);
        assert!((p.epsilons[4] - 0.0005).abs() < 1e-8);
        assert!((p.epsilons[2] - 0.005).abs() < 1e-6, "{:?}", p.epsilons);
        assert!(p.epsilons.windows(2).all(|w| w[1] < w[0]));
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
            epsilon: 0.01,
            shading: ShadingMode::Blended,
            splats: 10,
            scene_splats: 12,
            splat_seconds: 0.5,
            octree_build_s: 0.1,
            embree_build_s: 0.2,
            octree_render_s: 0.3,
            embree_render_s: 0.4,
            octree: e.clone(),
            embree: TruthErrors {
                image_psnr_db: Some(30.0),
                ..e
            },
            backends_identical: false,
        };
        let text = csv_text(&[r]);
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
    }
}
