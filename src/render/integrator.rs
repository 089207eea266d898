//! The Whitted integrator of §1.2: primary rays through pixel centres (or
//! stratified samples), shadow rays to every light, mirror reflection,
//! refraction with Fresnel and total internal reflection, recursion to a
//! maximum depth. It sees only the [`Backend`] trait and the shared
//! resolver, so every backend renders with identical shading.

use crate::accel::{Backend, CandidateHits, Departure, Fan, PACKET, Query, Ray};
use crate::progress::{Progress, notify};
use crate::resolve::{
    Resolved, Silhouette, SurfaceHit, resolve_models_kept, resolve_with_triangles,
};
use crate::scene::{Light, Material, Scene};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Rays traced, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RayCounts {
    /// Camera rays.
    pub primary: u64,
    /// Shadow rays.
    pub shadow: u64,
    /// Mirror and Fresnel reflection rays.
    pub reflection: u64,
    /// Refraction rays.
    pub refraction: u64,
}

impl RayCounts {
    /// All rays.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.reflection + self.refraction
    }

    /// The counts of two renders added (of bands rendered apart).
    #[must_use]
    pub fn plus(self, o: RayCounts) -> RayCounts {
        RayCounts {
            primary: self.primary + o.primary,
            shadow: self.shadow + o.shadow,
            reflection: self.reflection + o.reflection,
            refraction: self.refraction + o.refraction,
        }
    }
}

/// A rendered frame: linear radiance and the arbitrary output variables of
/// the first sample of every pixel (the pixel centre when `spp == 1`).
#[derive(Clone, Debug)]
pub struct Frame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Linear RGB radiance, row-major, top row first.
    pub rgb: Vec<Vec3>,
    /// Primary hit distance, `+inf` on a miss.
    pub depth: Vec<f32>,
    /// Resolved shading normal of the primary hit (zero on a miss).
    pub normal: Vec<Vec3>,
    /// Resolved splat id of the primary hit, `u32::MAX` on a miss.
    pub splat: Vec<u32>,
    /// Unlit colour of the primary hit (the material's colour times the
    /// splat's, linear), zero on a miss.
    pub albedo: Vec<Vec3>,
    /// Of the direct light at the primary hit (every light sample of §1.2,
    /// weighted by its irradiance `power / d²` summed over the channels),
    /// the share arriving from in front of the shading normal (`n·l > 0`):
    /// where this differs between two renders, a shading normal has moved
    /// a light across the terminator. Zero on a miss and on mirror and
    /// glass hits (no direct light).
    pub light_facing: Vec<f32>,
    /// The share of that light (same weights) that is also unoccluded: its
    /// shadow ray reaches the light. `light_facing - light_lit` is the
    /// share shadowed by other surfaces (cast shadows, shadow acne).
    pub light_lit: Vec<f32>,
    /// Rays traced.
    pub rays: RayCounts,
    /// Wall seconds spent rendering.
    pub seconds: f64,
}

impl Frame {
    /// An empty `width` × `height` frame with room for its pixels, no rays
    /// counted yet.
    #[must_use]
    pub fn with_capacity(width: u32, height: u32) -> Frame {
        let n = width as usize * height as usize;
        Frame {
            width,
            height,
            rgb: Vec::with_capacity(n),
            depth: Vec::with_capacity(n),
            normal: Vec::with_capacity(n),
            splat: Vec::with_capacity(n),
            albedo: Vec::with_capacity(n),
            light_facing: Vec::with_capacity(n),
            light_lit: Vec::with_capacity(n),
            rays: RayCounts::default(),
            seconds: 0.0,
        }
    }

    /// Appends the pixels of `rows` (as wide as this frame) after this
    /// frame's, adding its rays; this frame's size and seconds stay.
    pub fn append(&mut self, rows: Frame) {
        self.rgb.extend(rows.rgb);
        self.depth.extend(rows.depth);
        self.normal.extend(rows.normal);
        self.splat.extend(rows.splat);
        self.albedo.extend(rows.albedo);
        self.light_facing.extend(rows.light_facing);
        self.light_lit.extend(rows.light_lit);
        self.rays = self.rays.plus(rows.rays);
    }
}

/// A small counter-based generator (PCG-style hash), deterministic per
/// pixel and sample, so renders are reproducible and backends see the same
/// sample positions.
#[derive(Clone, Copy)]
struct Rng(u64);

impl Rng {
    fn new(a: u32, b: u32, c: u32) -> Rng {
        Rng(((a as u64) << 40) ^ ((b as u64) << 20) ^ c as u64 ^ 0x9E37_79B9_7F4A_7C15)
    }
    fn next_f32(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let mut x = self.0;
        x ^= x >> 33;
        x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
        x ^= x >> 33;
        (x >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A surface hit as the integrator needs it, whatever produced it: the
/// splats through a backend and the resolver, or an exact surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadeHit {
    /// Where and how the ray meets the surface (for an exact surface:
    /// `normal`, `geometric_normal` its own, `shadow_origin` the point,
    /// `blended` 1).
    pub surface: SurfaceHit,
    /// Material index into the scene's materials.
    pub material: u16,
    /// Colour of the surface data (multiplies the material's albedo).
    pub color: Vec3,
}

/// What the integrator traces against (`docs/DESIGN.md`, "The backend contract": nothing above the backend
/// knows which backend runs; this trait also lets the exact mesh surface of
/// `compare --truth` go through the same integrator).
pub trait Surfaces: Sync {
    /// The resolved hit of `ray`: a camera ray when `from` is `None`, else
    /// a secondary ray leaving the hit `from`, which skips the surface it
    /// leaves as the surfaces define it. `hits` is scratch space.
    fn hit(&self, ray: &Ray, from: Option<&ShadeHit>, hits: &mut CandidateHits)
    -> Option<ShadeHit>;
    /// Any hit before `t_max` of a ray leaving the hit `from` (a shadow ray;
    /// `t_max` already short of the light by the surfaces' `eps_self`).
    fn occluded(&self, ray: &Ray, from: &ShadeHit, t_max: f32) -> bool;
    /// `eps_self` (§3.2): secondary rays start this far from their origin.
    fn eps_self(&self) -> f32;

    /// True when the integrator should hand coherent batches to
    /// [`Surfaces::hits`] and [`Surfaces::occluded_batch`] (the answers
    /// are the same either way). False by default.
    fn packets(&self) -> bool {
        false
    }

    /// [`Surfaces::hit`] of each camera ray of a batch (the primary rays of
    /// a small screen tile) into `out`; `hits` holds a window per ray
    /// (scratch). The default traces one at a time.
    fn hits(&self, rays: &[Ray], hits: &mut [CandidateHits], out: &mut [Option<ShadeHit>]) {
        for ((ray, h), o) in rays.iter().zip(hits.iter_mut()).zip(out.iter_mut()) {
            *o = self.hit(ray, None, h);
        }
    }

    /// [`Surfaces::occluded`] of shadow rays `(ray, t_max, from)`, each
    /// leaving its hit `from` (toward the samples of one sphere light from
    /// one hit, or toward one light from the hits of a screen tile), into
    /// `out`. The default asks one at a time.
    fn occluded_batch(&self, rays: &[(Ray, f32, &ShadeHit)], out: &mut [bool]) {
        for ((ray, t_max, from), o) in rays.iter().zip(out.iter_mut()) {
            *o = self.occluded(ray, from, *t_max);
        }
    }

    /// What the backend these surfaces trace through knows once about a
    /// run of `rays` camera rays leaving one origin ([`Backend::fan`]),
    /// which `make` makes only where it may pay ([`Backend::fan_pays`]);
    /// `None` (the default) where there is no such backend or it would
    /// not pay.
    fn fan(&self, rays: usize, make: &dyn Fn() -> Vec<Ray>) -> Option<Box<dyn Fan + '_>> {
        let _ = (rays, make);
        None
    }

    /// What the backend these surfaces trace through knows once about the
    /// `rays` shadow rays along `dir` of a directional light
    /// ([`Backend::parallel`]); `None` (the default) where there is no
    /// such backend or it would not pay.
    fn parallel(&self, dir: Vec3, rays: usize) -> Option<Box<dyn Backend + '_>> {
        let _ = (dir, rays);
        None
    }

    /// These surfaces traced through `backend` in place of their own
    /// (a fan's [`Fan::backend`], which answers every query as theirs
    /// does); `None` (the default): not possible.
    fn through<'s>(&'s self, backend: &'s dyn Backend) -> Option<Box<dyn Surfaces + 's>> {
        let _ = backend;
        None
    }
}

/// The splats of a scene through one backend and the shared resolver.
pub struct SplatSurfaces<'a> {
    /// The scene (splats, materials, options).
    pub scene: &'a Scene,
    /// The acceleration backend.
    pub backend: &'a dyn Backend,
    /// The splats' silhouette constants and Phong bits
    /// (`resolve::silhouettes` of `scene.splats` and
    /// `scene.shading_for`), where the caller keeps them; `None` computes
    /// them a candidate at a time (the same hits).
    pub kept: Option<&'a [Silhouette]>,
}

impl SplatSurfaces<'_> {
    /// What the candidate `hits` a backend gathered for `ray` resolve to
    /// (§3.2, eq. 5; each splat with its model's shading mode and window;
    /// a triangle hit a window of one, `resolve_with_triangles`).
    #[must_use]
    pub fn resolve(&self, hits: &CandidateHits, ray: &Ray) -> Option<Resolved> {
        let sc = self.scene;
        let model = |id| (sc.shading_for(id), sc.xi_for(id));
        if sc.triangles.tris.is_empty() {
            return resolve_models_kept(hits, ray, &sc.splats, self.kept, model);
        }
        resolve_with_triangles(hits, ray, &sc.splats, model, |c| sc.triangle_hit(c, ray))
    }

    /// The surface the query's ray meets, with its material and colour:
    /// its window gathered (into `hits`) and resolved, and gathered again
    /// past candidates beyond their Phong fields' silhouettes
    /// (`Resolved::Beyond`) until a surface or nothing is left.
    #[must_use]
    pub fn surface(&self, q: Query, hits: &mut CandidateHits) -> Option<ShadeHit> {
        self.surface_hit(q, hits).map(|h| self.shade_hit(h))
    }

    /// [`SplatSurfaces::surface`] without the material and colour: the
    /// resolved hit alone.
    #[must_use]
    pub fn surface_hit(&self, mut q: Query, hits: &mut CandidateHits) -> Option<SurfaceHit> {
        loop {
            self.backend.intersect_from(&q, hits);
            match self.resolve(hits, &q.ray)? {
                Resolved::Hit(h) => return Some(h),
                // Beyond every candidate gathered: strictly farther, so
                // the loop ends.
                Resolved::Beyond(t) => q.t_min = t,
            }
        }
    }

    /// The resolved hit of each camera ray `qs` (at most `PACKET`) into
    /// `out`, the windows gathered in one [`Backend::intersect_packet`]
    /// call (into `hits`, one per query) and resolved as
    /// [`SplatSurfaces::surface_hit`] resolves them: the same hits.
    pub fn surface_hits(
        &self,
        qs: &[Query],
        hits: &mut [CandidateHits],
        out: &mut [Option<SurfaceHit>],
    ) {
        self.surface_hits_gathered(qs, hits, out, |qs, hits| self.backend.intersect_packet(qs, hits));
    }

    /// [`SplatSurfaces::surface_hits`] with the first windows gathered by
    /// `gather` (into `hits`, one per query), which must give what
    /// [`Backend::intersect_packet`] gives (a fan's lists, found once for
    /// a camera's rays): the same hits.
    pub fn surface_hits_gathered(
        &self,
        qs: &[Query],
        hits: &mut [CandidateHits],
        out: &mut [Option<SurfaceHit>],
        gather: impl FnOnce(&[Query], &mut [CandidateHits]),
    ) {
        gather(qs, hits);
        for ((q, h), o) in qs.iter().zip(hits.iter_mut()).zip(out.iter_mut()) {
            *o = match self.resolve(h, &q.ray) {
                None => None,
                Some(Resolved::Hit(s)) => Some(s),
                Some(Resolved::Beyond(t)) => self.surface_hit(Query { t_min: t, ..*q }, h),
            };
        }
    }

    /// The resolved hit `h` with its material and colour.
    fn shade_hit(&self, h: SurfaceHit) -> ShadeHit {
        let sc = self.scene;
        ShadeHit {
            surface: h,
            material: sc.material_for(h.id),
            color: sc.color_at(h.id, h.point),
        }
    }

    /// The query of a secondary ray leaving `from` (starting at
    /// `ray.origin`, the hit's point or its shadow origin), from `eps_self`
    /// to `t_max`: the shared self-hit rule of every backend skips the
    /// splat it starts on and its overlapping, similarly oriented
    /// neighbours (`accel::Departure`), measured from where the ray starts.
    fn leaving(&self, ray: &Ray, from: &ShadeHit, t_max: f32) -> Query<'_> {
        Query {
            ray: *ray,
            t_min: self.eps_self(),
            t_max,
            from: Some(Departure {
                id: from.surface.id,
                point: ray.origin,
                normal: from.surface.geometric_normal,
            }),
            pass: None,
        }
    }

    /// The query of a shadow ray leaving `from` ([`SplatSurfaces::leaving`]),
    /// which also passes the hits on Phong splats' discs beyond their curved
    /// surfaces' silhouettes (the scene's [`crate::accel::PassOver`], when
    /// it has Phong splats): a shadow ray sees the surface the resolver
    /// shows a camera ray, in every backend alike.
    fn shadow(&self, ray: &Ray, from: &ShadeHit, t_max: f32) -> Query<'_> {
        Query {
            pass: self
                .scene
                .has_phong()
                .then_some(self.scene as &dyn crate::accel::PassOver),
            ..self.leaving(ray, from, t_max)
        }
    }
}

impl Surfaces for SplatSurfaces<'_> {
    fn hit(
        &self,
        ray: &Ray,
        from: Option<&ShadeHit>,
        hits: &mut CandidateHits,
    ) -> Option<ShadeHit> {
        let q = match from {
            None => Query::new(*ray, 0.0, f32::INFINITY),
            Some(f) => self.leaving(ray, f, f32::INFINITY),
        };
        self.surface(q, hits)
    }

    fn occluded(&self, ray: &Ray, from: &ShadeHit, t_max: f32) -> bool {
        self.backend.occluded_from(&self.shadow(ray, from, t_max))
    }

    fn eps_self(&self) -> f32 {
        self.scene.options.scale.eps_self
    }

    fn packets(&self) -> bool {
        crate::accel::use_packets(self.backend)
    }

    /// One [`Backend::intersect_packet`] call per [`PACKET`] rays, each
    /// window then resolved as [`Surfaces::hit`] resolves it.
    fn hits(&self, rays: &[Ray], hits: &mut [CandidateHits], out: &mut [Option<ShadeHit>]) {
        for ((rays, hits), out) in rays
            .chunks(PACKET)
            .zip(hits.chunks_mut(PACKET))
            .zip(out.chunks_mut(PACKET))
        {
            let qs: [Query; PACKET] = std::array::from_fn(|k| {
                Query::new(rays[k.min(rays.len() - 1)], 0.0, f32::INFINITY)
            });
            let mut found = [None; PACKET];
            let n = rays.len();
            self.surface_hits(&qs[..n], hits, &mut found[..n]);
            for (f, o) in found.iter().zip(out.iter_mut()) {
                *o = f.map(|s| self.shade_hit(s));
            }
        }
    }

    /// One [`Backend::occluded_packet`] call per [`PACKET`] rays.
    fn occluded_batch(&self, rays: &[(Ray, f32, &ShadeHit)], out: &mut [bool]) {
        for (rays, out) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            let qs: [Query; PACKET] = std::array::from_fn(|k| {
                let (ray, t_max, from) = rays[k.min(rays.len() - 1)];
                self.shadow(&ray, from, t_max)
            });
            self.backend.occluded_packet(&qs[..rays.len()], out);
        }
    }

    fn fan(&self, rays: usize, make: &dyn Fn() -> Vec<Ray>) -> Option<Box<dyn Fan + '_>> {
        if !self.backend.fan_pays(rays) {
            return None;
        }
        self.backend.fan(&make().as_slice())
    }

    fn parallel(&self, dir: Vec3, rays: usize) -> Option<Box<dyn Backend + '_>> {
        self.backend.parallel(dir, rays)
    }

    fn through<'s>(&'s self, backend: &'s dyn Backend) -> Option<Box<dyn Surfaces + 's>> {
        Some(Box::new(SplatSurfaces { backend, ..*self }))
    }
}

struct Tracer<'a> {
    scene: &'a Scene,
    surfaces: &'a dyn Surfaces,
    /// What the camera rays and the shadow rays are traced against:
    /// `surfaces`, or `surfaces` through their backend's fan
    /// ([`camera_fan`]), with the same hits and occlusion (its lists
    /// answer the shadow rays toward a light at the eye, a headlight).
    camera: &'a dyn Surfaces,
    /// Per light of the scene, what its shadow rays are traced against
    /// where not `camera`: a directional light's, `surfaces` through their
    /// backend's lists along it ([`Surfaces::parallel`]), with the same
    /// occlusion.
    lit: Vec<Option<&'a dyn Surfaces>>,
    /// Hand the surfaces coherent batches ([`Surfaces::packets`]).
    packets: bool,
    /// Per light, whether the shadow rays of a screen tile's hits toward
    /// it are traced together ([`Tracer::shadows_ahead`]): a point or
    /// directional light's, but not where lists answer them one at a time,
    /// a directional light's with lists of its own (`lit`) and a light at
    /// the eye's through the camera's fan.
    ahead: Vec<bool>,
}

struct Scratch {
    hits: CandidateHits,
    rays: RayCounts,
    rng: Rng,
    /// The primary hit's light shares (`Frame::light_facing`,
    /// `Frame::light_lit`): weights of all, facing and lit light samples,
    /// tallied by `direct` at depth 0.
    light: [f32; 3],
    /// Whether the shadow ray toward light `i` of the tile's hit `k` is
    /// occluded, at `k` × lights + `i` ([`Tracer::shadows_ahead`]).
    occluded: Vec<bool>,
    /// The tile's hit `k` whose answers in `occluded` the next
    /// [`Tracer::direct`] takes.
    ahead: Option<usize>,
}

/// The facing normal of `hit`: its normal, turned toward the side the ray came from.
fn facing(hit: &ShadeHit) -> Vec3 {
    if hit.surface.front {
        hit.surface.normal
    } else {
        -hit.surface.normal
    }
}

/// The direction `l` toward a point or directional `light` from `p`, the
/// light's distance (`inf` for a directional light) and the irradiance it
/// brings, as [`Tracer::direct`] takes them; `None` for a sphere light.
fn toward(light: &Light, p: Vec3) -> Option<(Vec3, f32, Vec3)> {
    match *light {
        Light::Point { position, power } => {
            let to = position - p;
            let d2 = to.length_squared();
            let d = d2.sqrt();
            Some((to / d, d, power / d2))
        }
        Light::Directional { direction, power } => Some((-direction, f32::INFINITY, power)),
        Light::Sphere { .. } => None,
    }
}

/// The shadow ray from the hit `from` to the light at distance `dist`
/// along `dir` from its point (`inf`: a directional light), and that
/// light's distance from where the ray starts: the hit's shadow origin
/// (`ShadeHit::shadow_origin`), aimed at the light itself.
fn shadow_ray(from: &ShadeHit, dir: Vec3, dist: f32) -> (Ray, f32) {
    let origin = from.surface.shadow_origin;
    if !dist.is_finite() || origin == from.surface.point {
        return (Ray { origin, dir }, dist);
    }
    let to = from.surface.point + dir * dist - origin;
    let d = to.length();
    (
        Ray {
            origin,
            dir: to / d,
        },
        d,
    )
}

fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Exact Fresnel reflectance for unpolarised light; `cos_i > 0`, `eta` the
/// ratio of indices (incident over transmitted). Returns 1 under total
/// internal reflection.
fn fresnel(cos_i: f32, eta: f32) -> f32 {
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (rs * rs + rp * rp)
}

impl Tracer<'_> {
    fn intersect(&self, ray: &Ray, from: Option<&ShadeHit>, s: &mut Scratch) -> Option<ShadeHit> {
        self.surfaces.hit(ray, from, &mut s.hits)
    }

    /// Is the light at distance `dist` along `dir` visible from the hit,
    /// its shadow ray traced against `through`?
    fn visible(&self, through: &dyn Surfaces, from: &ShadeHit, dir: Vec3, dist: f32, s: &mut Scratch) -> bool {
        s.rays.shadow += 1;
        let (ray, d) = shadow_ray(from, dir, dist);
        !through.occluded(&ray, from, d - self.surfaces.eps_self())
    }

    /// The light samples `(l, d, e)` of one hit (see [`Tracer::direct`]):
    /// the shadow rays of those facing `n` traced as one batch
    /// ([`Surfaces::occluded_batch`]), then every sample handed to `add`
    /// in order, as one at a time would.
    fn shadow_batch(
        &self,
        from: &ShadeHit,
        n: Vec3,
        batch: &[(Vec3, f32, Vec3)],
        s: &mut Scratch,
        mut add: impl FnMut(Vec3, Vec3, bool),
    ) {
        let eps = self.surfaces.eps_self();
        let none = Ray {
            origin: from.surface.shadow_origin,
            dir: Vec3::Z,
        };
        let mut rays = [(none, 0.0f32, from); PACKET];
        let mut traced = 0;
        for &(l, d, _) in batch {
            if n.dot(l) > 0.0 {
                let (ray, d) = shadow_ray(from, l, d);
                rays[traced] = (ray, d - eps, from);
                traced += 1;
            }
        }
        let mut occluded = [false; PACKET];
        self.camera
            .occluded_batch(&rays[..traced], &mut occluded[..traced]);
        s.rays.shadow += traced as u64;
        let mut next = 0;
        for &(l, _, e) in batch {
            let visible = n.dot(l) > 0.0 && {
                next += 1;
                !occluded[next - 1]
            };
            add(l, e, visible);
        }
    }

    /// Irradiance-weighted light reaching `p` with facing normal `n`, plus
    /// the Blinn–Phong highlight toward `-view` when `spec > 0`; and the
    /// weights of all, facing and lit light samples (`Frame::light_lit`).
    fn direct(
        &self,
        hit: &ShadeHit,
        n: Vec3,
        view: Vec3,
        albedo: Vec3,
        spec: (f32, f32),
        s: &mut Scratch,
    ) -> (Vec3, [f32; 3]) {
        let p = hit.surface.point;
        let mut sum = Vec3::ZERO;
        // Weights of all, facing and lit light samples (`Frame::light_lit`).
        let mut tally = [0.0f32; 3];
        let weight = |e: Vec3| e.x + e.y + e.z;
        // One light sample, direction `l`, irradiance `e`, whose shadow ray
        // (traced only when it faces `n`) found it `visible`: counted, and
        // added when it faces `n` and nothing blocks it.
        let mut add = |l: Vec3, e: Vec3, visible: bool| {
            tally[0] += weight(e);
            if n.dot(l) > 0.0 {
                tally[1] += weight(e);
                if visible {
                    tally[2] += weight(e);
                    let cos = n.dot(l);
                    let mut c = albedo * cos;
                    if spec.0 > 0.0 {
                        let h = (l - view).normalize_or_zero();
                        c += Vec3::splat(spec.0 * n.dot(h).max(0.0).powf(spec.1));
                    }
                    sum += c * e;
                }
            }
        };
        // Whether the light at distance `d` along `l` is seen from the hit:
        // its shadow ray, traced alone, only when it faces `n`.
        let seen = |through: Option<&dyn Surfaces>, l: Vec3, d: f32, s: &mut Scratch| {
            n.dot(l) > 0.0 && self.visible(through.unwrap_or(self.camera), hit, l, d, s)
        };
        // The hit's shadow rays toward its point and directional lights
        // where they were traced with those of its screen tile
        // ([`Tracer::shadows_ahead`]).
        let ahead = s.ahead.take();
        let lights = self.scene.lights.len();
        for (i, (light, &through)) in self.scene.lights.iter().zip(&self.lit).enumerate() {
            let lit = |l: Vec3, d: f32, s: &mut Scratch| match ahead.filter(|_| self.ahead[i]) {
                Some(k) => n.dot(l) > 0.0 && !s.occluded[k * lights + i],
                None => seen(through, l, d, s),
            };
            // The same `l`, `d` and irradiance as `toward` (which
            // `shadows_ahead` uses): written out here, the made scenes
            // render about 2 % faster than through the call.
            match *light {
                Light::Point { position, power } => {
                    let to = position - p;
                    let d2 = to.length_squared();
                    let d = d2.sqrt();
                    add(to / d, power / d2, lit(to / d, d, s));
                }
                Light::Directional { direction, power } => {
                    add(-direction, power, lit(-direction, f32::INFINITY, s));
                }
                Light::Sphere {
                    position,
                    radius,
                    power,
                    samples,
                } => {
                    // Stratified points on the disc of the sphere facing `p`.
                    let axis = (p - position).normalize_or_zero();
                    let (a, b) = crate::splat::tangent_frame(if axis == Vec3::ZERO {
                        Vec3::Z
                    } else {
                        axis
                    });
                    let k = (samples as f32).sqrt().ceil() as u32;
                    let share = 1.0 / (k * k) as f32;
                    // With packets, up to `PACKET` samples are drawn (the
                    // same draws in the same order), their shadow rays
                    // traced as one batch from the one hit, then added in
                    // order: the same sums as one at a time.
                    let mut batch = [(Vec3::ZERO, 0.0f32, Vec3::ZERO); PACKET];
                    let mut len = 0;
                    for i in 0..k {
                        for j in 0..k {
                            let r = radius * ((i as f32 + s.rng.next_f32()) / k as f32).sqrt();
                            let phi =
                                std::f32::consts::TAU * (j as f32 + s.rng.next_f32()) / k as f32;
                            let q = position + a * (r * phi.cos()) + b * (r * phi.sin());
                            let to = q - p;
                            let d2 = to.length_squared();
                            let d = d2.sqrt();
                            if !self.packets {
                                add(to / d, power * (share / d2), seen(through, to / d, d, s));
                                continue;
                            }
                            batch[len] = (to / d, d, power * (share / d2));
                            len += 1;
                            if len == PACKET {
                                self.shadow_batch(hit, n, &batch[..len], s, &mut add);
                                len = 0;
                            }
                        }
                    }
                    if len > 0 {
                        self.shadow_batch(hit, n, &batch[..len], s, &mut add);
                    }
                }
            }
        }
        (sum, tally)
    }

    /// The shadow rays toward each point and directional light of the
    /// camera samples `hits` (a screen tile's) that [`Tracer::direct`]
    /// shades first (diffuse and Phong surfaces), traced as one batch a
    /// light ([`Surfaces::occluded_batch`]) into `s.occluded` (light `i`
    /// of hit `k` at `k` × lights + `i`); `shades[k]` tells which hits
    /// have them. The same rays, answers and counts as one at a time.
    fn shadows_ahead(&self, hits: &[Option<ShadeHit>], s: &mut Scratch, shades: &mut [bool; PACKET]) {
        let lights = self.scene.lights.len();
        let eps = self.surfaces.eps_self();
        for (k, hit) in hits.iter().enumerate() {
            shades[k] = hit.is_some_and(|h| {
                matches!(
                    self.scene.materials[h.material as usize],
                    Material::Diffuse { .. } | Material::Phong { .. }
                )
            });
        }
        // A hit that shades, to fill the batch's unused places.
        let Some(first) = (hits.iter().zip(shades.iter()))
            .find_map(|(h, &sh)| h.as_ref().filter(|_| sh))
        else {
            return;
        };
        for (i, light) in self.scene.lights.iter().enumerate() {
            if !self.ahead[i] {
                continue;
            }
            let mut rays = [(Ray::new(Vec3::ZERO, Vec3::Z), 0.0f32, first); PACKET];
            let mut at = [0usize; PACKET];
            let mut traced = 0;
            for (k, hit) in hits.iter().enumerate() {
                let Some(hit) = hit.as_ref().filter(|_| shades[k]) else {
                    continue;
                };
                let Some((l, d, _)) = toward(light, hit.surface.point) else {
                    continue;
                };
                if facing(hit).dot(l) > 0.0 {
                    let (ray, d) = shadow_ray(hit, l, d);
                    rays[traced] = (ray, d - eps, hit);
                    at[traced] = k;
                    traced += 1;
                }
            }
            let mut occluded = [false; PACKET];
            self.camera
                .occluded_batch(&rays[..traced], &mut occluded[..traced]);
            s.rays.shadow += traced as u64;
            for (&k, &o) in at.iter().zip(&occluded).take(traced) {
                s.occluded[k * lights + i] = o;
            }
        }
    }

    fn shade(&self, ray: &Ray, hit: Option<ShadeHit>, depth: u32, s: &mut Scratch) -> Vec3 {
        let Some(hit) = hit else {
            return self.scene.background;
        };
        let sc = self.scene;
        let n = facing(&hit);
        let material = sc.materials[hit.material as usize];
        let deeper = depth + 1 < sc.options.max_depth;
        match material {
            Material::Diffuse { color } => {
                let albedo = color * hit.color;
                let (direct, tally) = self.direct(&hit, n, ray.dir, albedo, (0.0, 0.0), s);
                if depth == 0 {
                    s.light = tally;
                }
                albedo * sc.options.ambient + direct
            }
            Material::Phong {
                color,
                specular,
                shininess,
            } => {
                let albedo = color * hit.color;
                let (direct, tally) =
                    self.direct(&hit, n, ray.dir, albedo, (specular, shininess), s);
                if depth == 0 {
                    s.light = tally;
                }
                albedo * sc.options.ambient + direct
            }
            Material::Mirror { color } => {
                if !deeper {
                    return Vec3::ZERO;
                }
                let r = Ray::new(hit.surface.point, reflect(ray.dir, n));
                color * self.trace(&r, &hit, depth + 1, s, false)
            }
            Material::Glass { color, ior } => {
                if !deeper {
                    return Vec3::ZERO;
                }
                let cos_i = (-ray.dir.dot(n)).clamp(0.0, 1.0);
                let eta = if hit.surface.front { 1.0 / ior } else { ior };
                let f = fresnel(cos_i, eta);
                let refl = Ray::new(hit.surface.point, reflect(ray.dir, n));
                let mut out = f * self.trace(&refl, &hit, depth + 1, s, false);
                if f < 1.0 {
                    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
                    let dir = eta * ray.dir + (eta * cos_i - k.max(0.0).sqrt()) * n;
                    let refr = Ray::new(hit.surface.point, dir);
                    out += (1.0 - f) * color * self.trace(&refr, &hit, depth + 1, s, true);
                }
                out
            }
        }
    }

    fn trace(
        &self,
        ray: &Ray,
        from: &ShadeHit,
        depth: u32,
        s: &mut Scratch,
        refraction: bool,
    ) -> Vec3 {
        if refraction {
            s.rays.refraction += 1;
        } else {
            s.rays.reflection += 1;
        }
        let hit = self.intersect(ray, Some(from), s);
        self.shade(ray, hit, depth, s)
    }
}

impl Tracer<'_> {
    /// Renders image rows `y .. y + R` into `rows`, pixels in tiles of
    /// `W`×`R` (`W R <= PACKET`; a square-ish tile is more coherent than a
    /// row): the primary rays of a tile traced as one batch
    /// ([`Surfaces::hits`]) when it holds more than one pixel, then each
    /// pixel's samples shaded in order, the upper row's pixels first, every
    /// sample with its own generator seeded by its pixel and index: the same
    /// rays, draws and sums whatever the tile, so the same pixels.
    fn tile_rows<const W: usize, const R: usize>(
        &self,
        y: usize,
        s: &mut Scratch,
        rows: &mut [Frame; R],
    ) {
        const { assert!(W * R <= PACKET) };
        let batched = W * R > 1;
        let scene = self.scene;
        let cam = &scene.camera;
        let w = cam.width as usize;
        let k = (cam.spp as f32).sqrt().ceil() as u32;
        let per_pixel = cam.spp;
        let mut batch_hits: [CandidateHits; PACKET] =
            std::array::from_fn(|_| CandidateHits::new(scene.options.scale.xi));
        for x0 in (0..w).step_by(W) {
            let xs = x0..(x0 + W).min(w);
            let np = xs.len();
            let mut sums = [[Vec3::ZERO; W]; R];
            for i in 0..per_pixel {
                let mut rays = [Ray {
                    origin: Vec3::ZERO,
                    dir: Vec3::Z,
                }; PACKET];
                let mut rngs = [Rng(0); PACKET];
                for r in 0..R {
                    let yr = y + r;
                    for (p, x) in xs.clone().enumerate() {
                        let mut rng = Rng::new(x as u32, yr as u32, i);
                        let (ox, oy) = if per_pixel == 1 {
                            (0.5, 0.5)
                        } else {
                            let (cx, cy) = (i % k, i / k % k);
                            (
                                (cx as f32 + rng.next_f32()) / k as f32,
                                (cy as f32 + rng.next_f32()) / k as f32,
                            )
                        };
                        rays[r * np + p] = cam.ray(x as f32 + ox, yr as f32 + oy);
                        rngs[r * np + p] = rng;
                    }
                }
                let mut hits = [None; PACKET];
                let mut ahead = [false; PACKET];
                if batched {
                    self.camera
                        .hits(&rays[..R * np], &mut batch_hits, &mut hits[..R * np]);
                    if self.ahead.contains(&true) {
                        self.shadows_ahead(&hits[..R * np], s, &mut ahead);
                    }
                } else {
                    hits[0] = self.camera.hit(&rays[0], None, &mut s.hits);
                }
                for (r, row) in rows.iter_mut().enumerate() {
                    for p in 0..np {
                        let (ray, hit) = (&rays[r * np + p], hits[r * np + p]);
                        s.rng = rngs[r * np + p];
                        s.rays.primary += 1;
                        if i == 0 {
                            row.depth.push(hit.map_or(f32::INFINITY, |h| h.surface.t));
                            row.normal
                                .push(hit.map_or(Vec3::ZERO, |h| h.surface.normal));
                            row.splat.push(hit.map_or(u32::MAX, |h| h.surface.id));
                            row.albedo.push(hit.map_or(Vec3::ZERO, |h| {
                                scene.materials[h.material as usize].color() * h.color
                            }));
                        }
                        s.light = [0.0; 3];
                        s.ahead = ahead[r * np + p].then_some(r * np + p);
                        sums[r][p] += self.shade(ray, hit, 0, s);
                        if i == 0 {
                            let [all, facing, lit] = s.light;
                            let share = |x: f32| if all > 0.0 { x / all } else { 0.0 };
                            row.light_facing.push(share(facing));
                            row.light_lit.push(share(lit));
                        }
                    }
                }
            }
            for (row, sums) in rows.iter_mut().zip(&sums) {
                for sum in &sums[..np] {
                    row.rgb.push(*sum / per_pixel as f32);
                }
            }
        }
    }
}

/// Renders the scene's camera view with `backend`. Parallel over rows with
/// rayon; reports stage `render` to `progress` as rows are done.
#[must_use]
pub fn render(scene: &Scene, backend: &dyn Backend, progress: Option<Progress<'_>>) -> Frame {
    render_surfaces(scene, &SplatSurfaces {
            scene,
            backend,
            kept: None,
        }, progress)
}

/// Renders rows `rows` of the scene's camera view: a frame as wide as the
/// image and `rows.len()` high, whose pixels are those rows of
/// [`render`]'s frame, bit for bit (every pixel's samples are seeded by its
/// own coordinates), so bands rendered apart and stacked make the image.
#[must_use]
pub fn render_rows(
    scene: &Scene,
    backend: &dyn Backend,
    rows: std::ops::Range<u32>,
    progress: Option<Progress<'_>>,
) -> Frame {
    render_surfaces_rows(scene, &SplatSurfaces {
            scene,
            backend,
            kept: None,
        }, rows, progress)
}

/// Renders the scene's camera, lights and materials against any
/// [`Surfaces`]; reports stage `render` to `progress` as rows are done
/// (from rayon's threads).
#[must_use]
pub fn render_surfaces(
    scene: &Scene,
    surfaces: &dyn Surfaces,
    progress: Option<Progress<'_>>,
) -> Frame {
    render_surfaces_rows(scene, surfaces, 0..scene.camera.height, progress)
}

/// [`render_surfaces`] for rows `rows` of the image only (see
/// [`render_rows`]).
fn render_surfaces_rows(
    scene: &Scene,
    surfaces: &dyn Surfaces,
    rows: std::ops::Range<u32>,
    progress: Option<Progress<'_>>,
) -> Frame {
    let cam = &scene.camera;
    let rows = rows.start.min(cam.height)..rows.end.min(cam.height);
    let h = rows.len();
    let start = Instant::now();
    let fan = camera_fan(cam, rows.clone(), surfaces);
    let through = fan.as_ref().and_then(|f| surfaces.through(f.backend()?));
    // A directional light's shadow rays: one a camera sample, so at least
    // one a pixel (the lists' memory is bounded by the rays told).
    let pixels = h * cam.width as usize;
    let along: Vec<_> = (scene.lights.iter())
        .map(|light| match *light {
            Light::Directional { direction, .. } => surfaces.parallel(-direction, pixels),
            _ => None,
        })
        .collect();
    let lit: Vec<_> = along.iter().map(|b| surfaces.through(b.as_deref()?)).collect();
    // A light at the eye (within `eps_self`: the same point written twice
    // may round apart), whose shadow rays a fan's lists answer.
    let near = scene.options.scale.eps_self;
    let at_eye = |light: &Light| {
        matches!(*light, Light::Point { position, .. } if position.distance(cam.origin) <= near)
    };
    let ahead = (scene.lights.iter().zip(&lit))
        .map(|(light, l)| {
            !matches!(light, Light::Sphere { .. }) && l.is_none() && !(through.is_some() && at_eye(light))
        })
        .collect();
    let tracer = Tracer {
        scene,
        surfaces,
        camera: through.as_deref().unwrap_or(surfaces),
        lit: lit.iter().map(|s| s.as_deref()).collect(),
        packets: surfaces.packets(),
        ahead,
    };
    let rows_done = AtomicUsize::new(0);
    let new_row = || Frame::with_capacity(cam.width, 1);
    // With packets, rows in pairs (their pixels in 4×2 tiles, each tile's
    // primary rays traced as one batch; a last odd row in 8×1 tiles), else
    // one by one, pixel by pixel.
    let step = if tracer.packets { 2 } else { 1 };
    let rows: Vec<Frame> = (rows.start as usize..rows.end as usize)
        .step_by(step)
        .collect::<Vec<_>>()
        .into_par_iter()
        // Each row (pair) a piece of its own: a model leaves some rows far
        // dearer than others, and a run of rows split no further kept one
        // thread busy alone at the end.
        .with_max_len(1)
        .flat_map_iter(|y| {
            let mut s = Scratch {
                hits: CandidateHits::new(scene.options.scale.xi),
                rays: RayCounts::default(),
                rng: Rng::new(y as u32, 0, 0),
                light: [0.0; 3],
                occluded: vec![false; PACKET * scene.lights.len()],
                ahead: None,
            };
            let mut pair = [new_row(), new_row()];
            let n = if !tracer.packets {
                tracer.tile_rows::<1, 1>(y, &mut s, std::array::from_mut(&mut pair[0]));
                1
            } else if y + 1 < rows.end as usize {
                tracer.tile_rows::<{ PACKET / 2 }, 2>(y, &mut s, &mut pair);
                2
            } else {
                tracer.tile_rows::<PACKET, 1>(y, &mut s, std::array::from_mut(&mut pair[0]));
                1
            };
            if progress.is_some() {
                let done = rows_done.fetch_add(n, Ordering::Relaxed) + n;
                notify(progress, "render", done as f64 / h as f64);
            }
            pair[0].rays = s.rays;
            pair.into_iter().take(n)
        })
        .collect();
    let mut frame = Frame::with_capacity(cam.width, h as u32);
    for row in rows {
        frame.append(row);
    }
    frame.seconds = start.elapsed().as_secs_f64();
    frame
}

/// The fan of the camera rays of `rows` (their pixel centres, row by
/// row: one origin, the camera's) where `surfaces`' backend makes one
/// ([`Surfaces::fan`]); the rays are dropped once it is made. A fan answers
/// every query as its backend does, bit for bit, so the image is the same
/// with or without it.
fn camera_fan<'s>(
    cam: &crate::scene::Camera,
    rows: std::ops::Range<u32>,
    surfaces: &'s dyn Surfaces,
) -> Option<Box<dyn Fan + 's>> {
    let n = rows.len() * cam.width as usize;
    surfaces.fan(n, &|| cam.pixel_rays(rows.clone()))
}

#[cfg(test)]
mod tests {
    use super::fresnel;

    #[test]
    fn fresnel_limits() {
        // Normal incidence, glass: ((1-1.5)/(1+1.5))^2 = 0.04.
        assert!((fresnel(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-6);
        // Beyond the critical angle inside glass: total internal reflection.
        assert_eq!(fresnel(0.1, 1.5), 1.0);
        // Matched indices: no reflection.
        assert!(fresnel(0.7, 1.0).abs() < 1e-7);
    }
}
