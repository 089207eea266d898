//! The render worker: one thread owning the scene and the backends, taking
//! the pages' jobs one at a time (the renderer already uses every core).
//! A frame renders in bands of rows ([`render_rows`], the same pixels a
//! whole render gives them); between bands the worker drops a job whose
//! page has asked for something newer or has closed.

use super::source::{Source, ViewCamera};
use crate::accel::{Backend, CandidateHits, Query, registry};
use crate::render::integrator::{Frame, SplatSurfaces, render_rows};
use crate::render::output::{png_bytes, rgb8_png};
use crate::resolve::ShadingMode;
use crate::scene::{Camera, parse_scene_str, scene_camera, scene_lights};
use crate::{Error, Result};
use image::{ImageBuffer, Rgb};
use serde::Serialize;
use serde_json::json;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

/// Rows per band: how often a frame in flight checks for cancellation.
pub const BAND_ROWS: u32 = 16;
/// The preview's resolution divisor (reduced resolution while moving).
pub const PREVIEW_DIVISOR: u32 = 4;

/// What the page sees of an image: the radiance or an AOV.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Show {
    /// The sRGB image (the PNG `splatray render` writes).
    #[default]
    Rgb,
    /// Primary hit distance, near bright.
    Depth,
    /// Shading normal, `0.5 + 0.5 n`.
    Normal,
    /// Splat id, one colour each.
    Splat,
    /// Unlit colour.
    Albedo,
}

/// One message for a page: a frame (a JSON header and PNG bytes) or JSON.
#[derive(Debug)]
pub enum Out {
    /// A JSON header and the image.
    Frame(String, Vec<u8>),
    /// A JSON message.
    Text(String),
}

/// A page's side of its jobs: the generation its newest request has, and
/// where its messages go.
#[derive(Debug)]
pub struct Session {
    /// Bumped by every new render request; a job of an older one is dropped.
    pub generation: AtomicU64,
    /// Set when the page has gone.
    pub closed: AtomicBool,
    /// The page's outbox.
    pub tx: tokio::sync::mpsc::UnboundedSender<Out>,
}

/// What a page asks to be rendered.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    /// The camera (for the reply).
    pub camera_id: u64,
    /// The scene text of the view ([`Source::text`]), the camera read from it.
    pub text: String,
    /// The backend.
    pub backend: String,
    /// The shading mode, `None`: the scene's own.
    pub shading: Option<ShadingMode>,
    /// What to show.
    pub show: Show,
    /// Samples per pixel of the refined frame after the full one (none
    /// when not above the full one's).
    pub refine_spp: u32,
}

/// A job.
#[derive(Debug)]
pub enum Task {
    /// Preview, full and refined frames of a view.
    Render(RenderRequest),
    /// The full frame with every renderer backend, and the pixels where
    /// they differ.
    Diff(RenderRequest),
    /// One pixel's hit and candidates, with every renderer backend.
    Pick(RenderRequest, u32, u32),
}

/// A job of a page.
#[derive(Debug)]
pub struct Job {
    /// The page.
    pub session: Arc<Session>,
    /// Its generation when asked.
    pub generation: u64,
    /// What to do.
    pub task: Task,
}

impl Job {
    fn live(&self) -> bool {
        !self.session.closed.load(Ordering::SeqCst)
            && self.session.generation.load(Ordering::SeqCst) == self.generation
    }

    fn send(&self, out: Out) {
        let _ = self.session.tx.send(out);
    }
}

/// Counters the server reports at `/stats`.
#[derive(Debug, Default)]
pub struct Stats {
    /// Bands of rows rendered, ever.
    pub bands: AtomicU64,
    /// Frames sent, ever.
    pub frames: AtomicU64,
    /// Jobs dropped part-way (a newer request, or the page gone).
    pub cancelled: AtomicU64,
    /// True while a job runs.
    pub busy: AtomicBool,
}

/// The queue between the pages and the worker.
#[derive(Debug, Default)]
pub struct Queue {
    jobs: Mutex<(Vec<Job>, bool)>,
    ready: Condvar,
}

impl Queue {
    /// Queues `job`; a queued job of the same page that it supersedes (a
    /// render of an older generation) is dropped.
    pub fn push(&self, job: Job) {
        let mut q = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        q.0.retain(|j| !Arc::ptr_eq(&j.session, &job.session) || j.live());
        q.0.push(job);
        self.ready.notify_one();
    }

    /// Stops the worker after the job in hand.
    pub fn stop(&self) {
        self.jobs.lock().unwrap_or_else(|e| e.into_inner()).1 = true;
        self.ready.notify_all();
    }

    fn pop(&self) -> Option<Job> {
        let mut q = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if q.1 {
                return None;
            }
            // Jobs of gone pages and superseded renders are skipped.
            q.0.retain(Job::live);
            if !q.0.is_empty() {
                return Some(q.0.remove(0));
            }
            q = self.ready.wait(q).unwrap_or_else(|e| e.into_inner());
        }
    }
}

/// The worker's state: the scene, the backends built so far, the shading
/// applied.
pub struct Worker {
    source: Arc<Source>,
    scene: crate::scene::Scene,
    backends: HashMap<String, Box<dyn Backend>>,
    shading: Option<ShadingMode>,
    stats: Arc<Stats>,
}

impl Worker {
    /// A worker over `source`'s scene, which it re-aims and re-shades.
    #[must_use]
    pub fn new(source: Arc<Source>, scene: crate::scene::Scene, stats: Arc<Stats>) -> Worker {
        Worker {
            source,
            scene,
            backends: HashMap::new(),
            shading: None,
            stats,
        }
    }

    /// Builds the backend `name` now (before the first page asks).
    ///
    /// # Errors
    /// An unknown name or a failed build.
    pub fn prepare(&mut self, name: &str) -> Result<()> {
        self.backend(name).map(|_| ())
    }

    /// Runs jobs from `queue` until it is stopped.
    pub fn run(mut self, queue: &Queue) {
        while let Some(job) = queue.pop() {
            self.stats.busy.store(true, Ordering::SeqCst);
            let r = match &job.task {
                Task::Render(req) => self.render_job(&job, req),
                Task::Diff(req) => self.diff_job(&job, req),
                Task::Pick(req, x, y) => self.pick_job(&job, req, *x, *y),
            };
            if let Err(e) = r {
                job.send(Out::Text(error_json(&e.to_string())));
            }
            self.stats.busy.store(false, Ordering::SeqCst);
        }
    }

    fn backend(&mut self, name: &str) -> Result<&dyn Backend> {
        if !self.backends.contains_key(name) {
            let info = registry::lookup(name)?;
            let b = info.build_scene(&self.scene)?;
            self.backends.insert(name.to_string(), b);
        }
        Ok(self.backends[name].as_ref())
    }

    /// The full-quality camera of `req` read back from its scene text, the
    /// scene's lights read back too, and the shading asked for applied.
    fn setup(&mut self, req: &RenderRequest) -> Result<Camera> {
        let file = parse_scene_str(&req.text)?;
        // As `render` sets a scene up (`Scene::set_view` after the load, which
        // re-forms the image plane): the same camera to the last bit.
        self.scene.camera = scene_camera(&file.camera, self.scene.shift, self.scene.offset)?;
        self.scene.set_view(None, None, None, None)?;
        let cam = self.scene.camera;
        // A cloud's headlight and key light follow its camera.
        self.scene.lights = scene_lights(&file.lights, self.scene.shift, self.scene.offset)?;
        if self.shading != req.shading {
            let (mode, of) = &self.source.shading;
            self.scene.options.shading = *mode;
            self.scene.shading_of.clone_from(of);
            if req.shading.is_some() {
                self.scene.set_view(None, None, None, req.shading)?;
            }
            self.shading = req.shading;
        }
        Ok(cam)
    }

    /// Renders `cam` with `backend` in bands, `None` when the job is
    /// dropped part-way.
    fn frame(&mut self, job: &Job, cam: Camera, backend: &str) -> Result<Option<Frame>> {
        self.backend(backend)?;
        self.scene.camera = cam;
        let b = self.backends[backend].as_ref();
        let start = Instant::now();
        let (w, h) = (cam.width, cam.height);
        let mut f = Frame::with_capacity(w, h);
        let mut y = 0;
        while y < h {
            if !job.live() {
                self.stats.cancelled.fetch_add(1, Ordering::Relaxed);
                return Ok(None);
            }
            let band = render_rows(&self.scene, b, y..(y + BAND_ROWS).min(h), None);
            self.stats.bands.fetch_add(1, Ordering::Relaxed);
            f.append(band);
            y += BAND_ROWS;
        }
        f.seconds = start.elapsed().as_secs_f64();
        Ok(Some(f))
    }

    fn send_frame(
        &self,
        job: &Job,
        req: &RenderRequest,
        stage: &str,
        spp: u32,
        f: &Frame,
    ) -> Result<()> {
        let png = encode(f, req.show)?;
        let header = json!({
            "type": "frame",
            "stage": stage,
            "camera": req.camera_id,
            "width": f.width,
            "height": f.height,
            "spp": spp,
            "seconds": f.seconds,
            "rays": f.rays.total(),
            "mrays_per_s": f.rays.total() as f64 / f.seconds.max(1e-9) / 1e6,
            "backend": req.backend,
            "show": req.show,
        });
        self.stats.frames.fetch_add(1, Ordering::Relaxed);
        job.send(Out::Frame(header.to_string(), png));
        Ok(())
    }

    fn render_job(&mut self, job: &Job, req: &RenderRequest) -> Result<()> {
        let full = self.setup(req)?;
        // Reduced resolution, one sample.
        self.scene.camera = full;
        let (pw, ph) = (
            (full.width / PREVIEW_DIVISOR).max(1),
            (full.height / PREVIEW_DIVISOR).max(1),
        );
        self.scene.set_view(Some(pw), Some(ph), Some(1), None)?;
        let preview = self.scene.camera;
        let mut stages = vec![("preview", preview), ("full", full)];
        if req.refine_spp > full.spp {
            // Only the samples change (`set_view` would re-form the image
            // plane a second time, which `render` of the text does not).
            let refined = Camera {
                spp: req.refine_spp,
                ..full
            };
            stages.push(("refined", refined));
        }
        for (stage, cam) in stages {
            match self.frame(job, cam, &req.backend)? {
                Some(f) => self.send_frame(job, req, stage, cam.spp, &f)?,
                None => return Ok(()),
            }
        }
        Ok(())
    }

    fn diff_job(&mut self, job: &Job, req: &RenderRequest) -> Result<()> {
        let full = self.setup(req)?;
        let names: Vec<&str> = registry::renderers().iter().map(|b| b.name).collect();
        let mut frames = Vec::new();
        for name in &names {
            match self.frame(job, full, name)? {
                Some(f) => frames.push(f),
                None => return Ok(()),
            }
        }
        let base = &frames[0];
        let mut differ = vec![false; base.rgb.len()];
        let mut counts = Vec::new();
        for f in &frames[1..] {
            let mut n = 0u64;
            for (i, d) in differ.iter_mut().enumerate() {
                let same = f.splat[i] == base.splat[i]
                    && f.rgb[i].to_array().map(f32::to_bits)
                        == base.rgb[i].to_array().map(f32::to_bits);
                if !same {
                    *d = true;
                    n += 1;
                }
            }
            counts.push(n);
        }
        // The image dimmed, the pixels that differ red.
        let img = crate::render::output::to_srgb8(base);
        let data: Vec<u8> = img
            .pixels()
            .zip(&differ)
            .flat_map(|(p, &d)| if d { [255, 0, 0] } else { p.0.map(|c| c / 3) })
            .collect();
        let over = ImageBuffer::<Rgb<u8>, _>::from_raw(base.width, base.height, data)
            .ok_or_else(|| Error::invalid("image size mismatch"))?;
        let header = json!({
            "type": "frame",
            "stage": "diff",
            "camera": req.camera_id,
            "width": base.width,
            "height": base.height,
            "spp": full.spp,
            "backends": names,
            "differing": counts,
            "seconds": frames.iter().map(|f| f.seconds).collect::<Vec<_>>(),
            "backend": req.backend,
            "show": "diff",
        });
        job.send(Out::Frame(header.to_string(), rgb8_png(&over)?));
        Ok(())
    }

    fn pick_job(&mut self, job: &Job, req: &RenderRequest, x: u32, y: u32) -> Result<()> {
        let cam = self.setup(req)?;
        if x >= cam.width || y >= cam.height {
            return Err(Error::invalid(format!(
                "pick: pixel ({x}, {y}) is outside the {}x{} image",
                cam.width, cam.height
            )));
        }
        self.scene.camera = cam;
        let ray = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
        let names: Vec<&str> = registry::renderers().iter().map(|b| b.name).collect();
        let mut out = Vec::new();
        for name in names {
            self.backend(name)?;
            let b = self.backends[name].as_ref();
            let mut hits = CandidateHits::new(self.scene.options.scale.xi);
            b.intersect_from(&Query::new(ray, 0.0, f32::INFINITY), &mut hits);
            let candidates: Vec<_> = hits
                .as_slice()
                .iter()
                .map(|c| json!({"id": c.id, "t": c.t, "u": c.u, "v": c.v}))
                .collect();
            let surf = SplatSurfaces {
                scene: &self.scene,
                backend: b,
                kept: None,
            };
            let mut h2 = CandidateHits::new(self.scene.options.scale.xi);
            let hit = surf
                .surface(Query::new(ray, 0.0, f32::INFINITY), &mut h2)
                .map(|h| h.surface)
                .map(|h| json!({"splat": h.id, "t": h.t, "normal": h.normal.to_array()}));
            out.push(json!({"backend": name, "hit": hit, "candidates": candidates}));
        }
        job.send(Out::Text(
            json!({"type": "pick", "x": x, "y": y, "backends": out}).to_string(),
        ));
        Ok(())
    }
}

/// An error message for a page.
#[must_use]
pub fn error_json(message: &str) -> String {
    json!({"type": "error", "message": message}).to_string()
}

/// The frame as PNG: the radiance (the bytes `splatray render` writes) or
/// an AOV made visible.
fn encode(f: &Frame, show: Show) -> Result<Vec<u8>> {
    let px: Vec<[u8; 3]> = match show {
        Show::Rgb => return png_bytes(f),
        Show::Depth => {
            let finite = f.depth.iter().copied().filter(|d| d.is_finite());
            let (lo, hi) = finite.fold((f32::INFINITY, 0.0f32), |(a, b), d| (a.min(d), b.max(d)));
            f.depth
                .iter()
                .map(|&d| {
                    if d.is_finite() {
                        let v = 1.0 - (d - lo) / (hi - lo).max(1e-12);
                        [(40.0 + 215.0 * v) as u8; 3]
                    } else {
                        [0; 3]
                    }
                })
                .collect()
        }
        Show::Normal => f
            .normal
            .iter()
            .map(|n| (n.to_array()).map(|c| ((0.5 + 0.5 * c).clamp(0.0, 1.0) * 255.0) as u8))
            .collect(),
        Show::Splat => f
            .splat
            .iter()
            .map(|&id| {
                if id == u32::MAX {
                    [0; 3]
                } else {
                    let h = id.wrapping_mul(2_654_435_761);
                    [(h >> 24) as u8, (h >> 16) as u8, (h >> 8) as u8]
                }
            })
            .collect(),
        Show::Albedo => f
            .albedo
            .iter()
            .map(|c| c.to_array().map(crate::io::linear_to_srgb8))
            .collect(),
    };
    let img = ImageBuffer::<Rgb<u8>, _>::from_raw(f.width, f.height, px.concat())
        .ok_or_else(|| Error::invalid("image size mismatch"))?;
    rgb8_png(&img)
}

/// The camera the page starts with, as JSON.
#[must_use]
pub fn camera_json(c: &ViewCamera) -> serde_json::Value {
    serde_json::to_value(c).unwrap_or_default()
}
