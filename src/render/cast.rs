//! Batches of rays cast at a scene's splats, one resolved hit or one
//! occlusion answer per ray: what the Python package's
//! `SplatScene.cast_rays` and `occluded` call (its binding only parses the
//! arrays and presents the answers).
//!
//! The rays are taken in chunks of [`CHUNK`] in parallel, with one
//! window per packet slot allocated per chunk, none per ray. A batch of
//! rays from scattered origins (issue 55's random rays) is traced in the
//! order of its origins' cells instead (`Order`), so consecutive rays
//! meet the same nodes and splats while they are in the caches. A run of at
//! least 4096 consecutive rays leaving one origin (a camera's; found by
//! sampling, the fan checking each ray's origin) is
//! first shown to the backend ([`crate::accel::Backend::fan`]): the rays
//! its [`Fan`] knows to miss everything are answered so without a
//! traversal (issue 55: the octree's fan, the directions in which no
//! splat's bounding ball lies, takes most of a camera's rays that miss
//! an object in view), and the others are traced in windows of 8192 by
//! the fan's keys, so that a packet holds neighbouring directions
//! whatever the order of the batch, by the fan's own backend where it has
//! one ([`Fan::backend`]: the octree's answers a ray from the list of
//! splats of its block of directions). When the backend prefers packets
//! ([`crate::accel::use_packets`]), the batch finds its packets itself:
//! runs of consecutive rays leaving one origin (a camera's or a scanner's
//! rays, in any order of directions) are split by their directions' signs
//! and traced [`PACKET`] at a time, so the octree takes each leaf once for
//! the packet ([`crate::accel::Backend::intersect_packet`]); a ray sharing
//! its origin with no neighbour is traced alone (a packet of rays from
//! unrelated origins would descend together for nothing). Every answer is
//! the one-ray-at-a-time answer, bit for bit: packets gather the same
//! candidate windows (`docs/DESIGN.md`, "The backend contract"), resolved
//! by the same resolver (§3.2, eq. 5), and a fan's misses are rays that
//! window would leave empty. Outputs other than the distance are written
//! only when asked for; [`cast_rays_owned`] makes them, written as misses
//! in parallel first.

use super::integrator::SplatSurfaces;
use crate::accel::{Backend, CandidateHits, FAN_ELSEWHERE, FAN_MISS, Fan, PACKET, PassOver, Query, Ray, RaySet};
use crate::resolve::SurfaceHit;
use crate::simd::{RowNumber, ray_from_row};
use glam::{DVec3, Vec3, Vec3A};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};

/// Rays per parallel task.
pub const CHUNK: usize = 512;

/// Pairs of neighbouring rows of which [`RayRows::scattered`] looks at one.
const ROW_SAMPLE: usize = 16;

/// Rows a parallel task of [`RayRows::convert_all`] converts.
const CONVERT: usize = 4096;

/// Where [`cast_rays`] writes its answers, one slot per ray.
pub struct CastOutputs<'a> {
    /// Distance in units of the ray's direction length (`inf`: a miss).
    pub t: &'a mut [f32],
    /// Splat id (`u32::MAX`: a miss), when asked for.
    pub ids: Option<&'a mut [u32]>,
    /// Resolved shading normal, three per ray (0: a miss), when asked for.
    pub normals: Option<&'a mut [f32]>,
}

/// The resolved hit of every ray of `rays` (directions of length `lens`,
/// which `t` is divided by) into `out`, as [`SplatSurfaces::surface_hit`]
/// resolves a camera ray alone.
///
/// Panics if `lens` or an output is shorter than the rays ask.
pub fn cast_rays(surfaces: &SplatSurfaces<'_>, rays: &[Ray], lens: &[f32], out: CastOutputs<'_>) {
    let order = Order::of(rays);
    let fans = unordered_fans(order.as_ref(), surfaces.backend, &rays);
    cast_planned(surfaces, &Held { rays, lens }, out, false, (order, fans), &mut Vec::new());
}

/// A batch's rays as rows of six numbers (origin, then direction) in a
/// frame `shift` from the scene's (the shift subtracted in `f64`), read
/// where the cast needs them: a camera's windows convert their own rows as
/// they trace them ([`cast_rows_owned`]), so the batch is never written
/// out as rays (a call converting 1M rows first spent 5 ms of 32 on it,
/// `docs/notes/backends.md`, "Issue 55, fifty-second session").
pub struct RayRows<'a, T> {
    rows: &'a [T],
    shift: DVec3,
    /// The first row found not to be a ray (`usize::MAX`: none).
    bad: AtomicUsize,
}

impl<'a, T: RowNumber> RayRows<'a, T> {
    /// The rows `rows` (six numbers each; a shorter tail is left out).
    #[must_use]
    pub fn new(rows: &'a [T], shift: DVec3) -> Self {
        RayRows {
            rows,
            shift,
            bad: AtomicUsize::new(usize::MAX),
        }
    }

    /// The rows from `start` converted into `rays` and `lens` (as many as
    /// `rays` holds), without a branch; false where one is not a ray: it
    /// gets a ray of NaN direction (which meets nothing) and the first
    /// such row's index is kept ([`RayRows::first_bad`]).
    ///
    /// # Panics
    /// If the rows from `start` are fewer than `rays`, or `lens` is shorter.
    pub fn convert(&self, start: usize, rays: &mut [Ray], lens: &mut [f32]) -> bool {
        let m = rays.len();
        let rows = &self.rows[6 * start..6 * (start + m)];
        let good = T::rays(rows, self.shift, rays, lens);
        if !good {
            let rows = rows.as_chunks::<6>().0;
            let bad = |i: &usize| !ray_from_row(&rows[*i], self.shift).2;
            for i in (0..m).filter(bad) {
                rays[i] = NOT_A_RAY;
            }
            self.bad.fetch_min(start + (0..m).find(bad).unwrap_or(0), Ordering::Relaxed);
        }
        good
    }

    /// The first row found not to be a ray by the conversions so far.
    #[must_use]
    pub fn first_bad(&self) -> Option<usize> {
        Some(self.bad.load(Ordering::Relaxed)).filter(|&i| i != usize::MAX)
    }

    /// Whether the rows are put in order ([`Order::wanted`]), judged on
    /// every [`ROW_SAMPLE`]th pair of neighbours and their origins' numbers
    /// as given (a full pass converting every origin cost 4 % of a call
    /// casting 1M box rays): an order only moves the work, never an answer.
    /// The pairs are read up to the eighth that share, where a camera's
    /// rows stop (all of them took 1.3 % of a camera `cast_rays` call's
    /// samples, on the calling thread).
    fn scattered(&self) -> bool {
        let n = self.len();
        if n < ORDER_MIN || u32::try_from(n).is_err() {
            return false;
        }
        let same = |i: usize| (0..3).all(|k| self.rows[6 * i + k].into().to_bits() == self.rows[6 * i + 6 + k].into().to_bits());
        let pairs = (0..n - 1).step_by(ROW_SAMPLE);
        let enough = pairs.len().div_ceil(8);
        pairs.filter(|&i| same(i)).nth(enough - 1).is_none()
    }

    /// Every row converted into `rays` and `lens` (resized to the rows;
    /// their memory reused), in parallel; false where one is not a ray.
    pub fn convert_all(&self, rays: &mut Vec<Ray>, lens: &mut Vec<f32>) -> bool {
        let n = self.len();
        rays.resize(n, Ray { origin: Vec3::ZERO, dir: Vec3::X });
        lens.resize(n, 1.0);
        rays.par_chunks_mut(CONVERT)
            .zip(lens.par_chunks_mut(CONVERT))
            .enumerate()
            .for_each(|(c, (rays, lens))| {
                self.convert(c * CONVERT, rays, lens);
            });
        self.first_bad().is_none()
    }
}

impl<T: RowNumber> RaySet for RayRows<'_, T> {
    fn len(&self) -> usize {
        self.rows.len() / 6
    }

    fn ray(&self, i: usize) -> Ray {
        let mut ray = [Ray { origin: Vec3::ZERO, dir: Vec3::X }];
        self.convert(i, &mut ray, &mut [0.0]);
        ray[0]
    }

    fn origin(&self, i: usize) -> Vec3 {
        let r: [f64; 3] = std::array::from_fn(|k| self.rows[6 * i + k].into());
        (DVec3::from_array(r) - self.shift).as_vec3()
    }
}

/// What a row that is not a ray is traced as: a NaN direction meets
/// nothing ([`RayRows::convert`]).
const NOT_A_RAY: Ray = Ray {
    origin: Vec3::ZERO,
    dir: Vec3::NAN,
};

/// A batch's rays as [`cast_planned`] takes them: one at a time (the fans'
/// samples) and a range at a time (its windows' and chunks' traces).
trait Batch: RaySet {
    /// The rays of `range` and their directions' lengths: the held ones,
    /// or rows converted into `buf`.
    fn range<'s>(&'s self, range: Range<usize>, buf: &'s mut Converted) -> (&'s [Ray], &'s [f32]);

    /// The rays of `range`, a window of the run from ray `first` whose fan
    /// is `fan`, with their lengths ([`Batch::range`]) and their keys
    /// ([`Fan::keys_each`]) into `keys`; a ray keyed [`FAN_MISS`] may be
    /// left unset (rows the fan keys before they are converted).
    fn keyed<'s>(
        &'s self,
        (range, first): (Range<usize>, usize),
        fan: &dyn Fan,
        buf: &'s mut Converted,
        keys: &mut Vec<u32>,
    ) -> (&'s [Ray], &'s [f32]) {
        let _ = first;
        keyed_by(self.range(range, buf), fan, keys)
    }
}

/// Rays (and their lengths) keyed by `fan` into `keys` ([`Fan::keys_each`]).
fn keyed_by<'s>(
    (rays, lens): (&'s [Ray], &'s [f32]),
    fan: &dyn Fan,
    keys: &mut Vec<u32>,
) -> (&'s [Ray], &'s [f32]) {
    keys.resize(rays.len(), 0);
    fan.keys_each(rays, keys);
    (rays, lens)
}

/// A task's rays converted from rows ([`Batch::range`]).
#[derive(Default)]
struct Converted {
    rays: Vec<Ray>,
    lens: Vec<f32>,
}

/// Rays and their directions' lengths, held.
struct Held<'a> {
    rays: &'a [Ray],
    lens: &'a [f32],
}

impl RaySet for Held<'_> {
    fn len(&self) -> usize {
        self.rays.len()
    }

    fn ray(&self, i: usize) -> Ray {
        self.rays[i]
    }
}

impl Batch for Held<'_> {
    fn range<'s>(&'s self, range: Range<usize>, _: &'s mut Converted) -> (&'s [Ray], &'s [f32]) {
        (&self.rays[range.clone()], &self.lens[range])
    }
}

impl<T: RowNumber> Batch for RayRows<'_, T> {
    fn range<'s>(&'s self, range: Range<usize>, buf: &'s mut Converted) -> (&'s [Ray], &'s [f32]) {
        let m = range.len();
        buf.rays.resize(m, Ray { origin: Vec3::ZERO, dir: Vec3::X });
        buf.lens.resize(m, 1.0);
        self.convert(range.start, &mut buf.rays, &mut buf.lens);
        (&buf.rays, &buf.lens)
    }

    /// The rows keyed as they are where the fan can ([`Fan::keys_of_rows`]:
    /// `f32` rows), and only those it does not know to miss converted
    /// (most of a camera's rays miss: converting them took about a tenth
    /// of a camera `cast_rays` call, `docs/notes/backends.md`, "Issue 55,
    /// fifty-third session"). A row keyed a miss is a ray (its direction
    /// one, `crate::simd::gnomonic_key`; its origin's bits the fan's first
    /// row's, which is one): any other is converted, so the call still
    /// names the first row that is not a ray.
    fn keyed<'s>(
        &'s self,
        (range, first): (Range<usize>, usize),
        fan: &dyn Fan,
        buf: &'s mut Converted,
        keys: &mut Vec<u32>,
    ) -> (&'s [Ray], &'s [f32]) {
        let m = range.len();
        let rows = &self.rows[6 * range.start..6 * range.end];
        let origin = T::as_rays(&self.rows[6 * first..6 * first + 6]).map(|r| r[0].origin.to_array().map(f32::to_bits));
        keys.resize(m, 0);
        match (T::as_rays(rows), origin) {
            (Some(raw), Some(origin)) if fan.keys_of_rows(raw, origin, keys) => {}
            _ => return keyed_by(self.range(range, buf), fan, keys),
        }
        buf.rays.resize(m, Ray { origin: Vec3::ZERO, dir: Vec3::X });
        buf.lens.resize(m, 1.0);
        let rows = rows.as_chunks::<6>().0;
        for (i, _) in keys.iter().enumerate().filter(|(_, k)| **k != FAN_MISS) {
            let (ray, len, ok) = ray_from_row(&rows[i], self.shift);
            (buf.rays[i], buf.lens[i]) = (if ok { ray } else { NOT_A_RAY }, len);
            if !ok {
                self.bad.fetch_min(range.start + i, Ordering::Relaxed);
            }
        }
        (&buf.rays, &buf.lens)
    }
}

/// A run of a batch's rays, as rays of their own (a fan's).
struct Part<'a>(&'a dyn RaySet, Range<usize>);

impl RaySet for Part<'_> {
    fn len(&self) -> usize {
        self.1.len()
    }

    fn ray(&self, i: usize) -> Ray {
        self.0.ray(self.1.start + i)
    }

    fn origin(&self, i: usize) -> Vec3 {
        self.0.origin(self.1.start + i)
    }
}

/// One ray's answer as [`cast_rays`] writes it: `t` (in units of the
/// direction's length), the splat id and the normal.
type Answer = (f32, u32, [f32; 3]);

/// The memory a caller keeps from one call of [`cast_rows_owned`] or
/// [`occluded_rows`] to the next, so a batch of scattered rays writes into
/// pages already mapped rather than fresh ones: the rows converted to rays
/// and their lengths, and the answers in the order traced (20 bytes a
/// ray). Fresh, a 1M-ray `cast_rays` of random rays mapped and zeroed about
/// 12,000 pages a call (issue 55, fifty-fifth session).
#[derive(Default)]
pub struct CastScratch {
    rays: Vec<Ray>,
    lens: Vec<f32>,
    answers: Vec<Answer>,
}

impl CastScratch {
    /// The most rays the held memory serves without growing.
    #[must_use]
    pub fn rays_held(&self) -> usize {
        self.rays.capacity().max(self.answers.capacity())
    }

    /// The held rays and lengths, taken out (for a caller converting rows
    /// into them, `RayRows::convert_all`); the answers' memory stays.
    pub fn take_rays(&mut self) -> (Vec<Ray>, Vec<f32>) {
        (std::mem::take(&mut self.rays), std::mem::take(&mut self.lens))
    }
}

/// [`cast_rays`]' answers in outputs of their own: `t`, and the splat ids
/// and normals where `ids` and `normals` ask for them.
pub struct CastAnswers {
    /// Distance in units of the ray's direction length (`inf`: a miss).
    pub t: Vec<f32>,
    /// Splat id (`u32::MAX`: a miss), when asked for.
    pub ids: Option<Vec<u32>>,
    /// Resolved shading normal, three per ray (0: a miss), when asked for.
    pub normals: Option<Vec<f32>>,
}

/// [`cast_rays`] into outputs made for the call: each is written as a
/// miss's answer in parallel before the rays are cast, and a fan's misses
/// are then left as written. Outputs zeroed by the caller took a pass on
/// one thread (the allocator's zeroing of reused memory) and a fan's
/// windows wrote their misses over them: 4.5 % of a camera call's time
/// (issue 55, forty-third session).
///
/// Panics if `lens` is shorter than `rays`.
pub fn cast_rays_owned(
    surfaces: &SplatSurfaces<'_>,
    rays: &[Ray],
    lens: &[f32],
    want: (bool, bool),
) -> CastAnswers {
    owned(surfaces, &Held { rays, lens }, want, Order::of(rays), &mut Vec::new())
}

/// [`cast_rays_owned`] of the rays `rows`: a batch traced in its own
/// order (a camera's rays) with each window converting its rows as it
/// takes them, one put in order ([`cast_rays`]: rays from scattered
/// origins) converted whole into `buf` first, its answers kept there in
/// the order traced before they are put in place (`buf`'s memory a caller
/// keeps from call to call, [`CastScratch`]).
///
/// # Errors
/// The index of the first row that is not a ray (checked before any is
/// cast where the batch is converted whole; else the answers are dropped).
pub fn cast_rows_owned<T: RowNumber>(
    surfaces: &SplatSurfaces<'_>,
    rows: &RayRows<'_, T>,
    want: (bool, bool),
    buf: &mut CastScratch,
) -> Result<CastAnswers, usize> {
    let answers = if rows.scattered() {
        if !rows.convert_all(&mut buf.rays, &mut buf.lens) {
            return Err(rows.first_bad().unwrap_or(0));
        }
        let (rays, lens) = (&buf.rays, &buf.lens);
        owned(surfaces, &Held { rays, lens }, want, Some(Order::build(rays)), &mut buf.answers)
    } else {
        owned(surfaces, rows, want, None, &mut buf.answers)
    };
    match rows.first_bad() {
        Some(i) => Err(i),
        None => Ok(answers),
    }
}

/// [`cast_rays_owned`] of `batch` (traced in `order` where it has one,
/// its answers in `got` first).
fn owned(
    surfaces: &SplatSurfaces<'_>,
    batch: &dyn Batch,
    (ids, normals): (bool, bool),
    order: Option<Order>,
    got: &mut Vec<Answer>,
) -> CastAnswers {
    let n = batch.len();
    let (t, id, normal) = answer(None, 1.0);
    // Allocated here, on the caller's thread: a vector allocated on one of
    // the pool's threads comes from that thread's arena, and the caller
    // freeing it there kept a batch's outputs more in the process (peak
    // memory 20 MB higher casting 1M rays three times).
    let mut a = CastAnswers {
        t: Vec::with_capacity(n),
        ids: ids.then(|| Vec::with_capacity(n)),
        normals: normals.then(|| Vec::with_capacity(3 * n)),
    };
    // The outputs written while the fans are built (the fill runs at the
    // memory's pace, the build's serial parts leave a core idle).
    let fill = |a: &mut CastAnswers| {
        fill(&mut a.t, t, n);
        if let Some(v) = &mut a.ids {
            fill(v, id, n);
        }
        if let Some(v) = &mut a.normals {
            fill(v, normal[0], 3 * n);
        }
    };
    let ((), fans) = rayon::join(
        || fill(&mut a),
        || unordered_fans(order.as_ref(), surfaces.backend, batch),
    );
    let out = CastOutputs {
        t: &mut a.t,
        ids: a.ids.as_deref_mut(),
        normals: a.normals.as_deref_mut(),
    };
    cast_planned(surfaces, batch, out, true, (order, fans), got);
    a
}

/// `m` copies of `x` appended to `v`, written in parallel.
fn fill<T: Clone + Send>(v: &mut Vec<T>, x: T, m: usize) {
    v.par_extend(rayon::iter::repeat_n(x, m));
}

/// The runs of a batch of one origin, each with its fan ([`fans`]).
type Fans<'b> = Vec<(Range<usize>, Box<dyn Fan + 'b>)>;

/// The fans of a batch that has no `order` (a batch traced in its
/// origins' order has none).
fn unordered_fans<'b>(order: Option<&Order>, backend: &'b dyn Backend, rays: &dyn RaySet) -> Fans<'b> {
    match order {
        Some(_) => Vec::new(),
        None => fans(backend, rays),
    }
}

/// [`cast_rays`] of a batch whose order ([`Order::of`]) or, without one,
/// whose fans are found, into outputs that already hold a miss's answer
/// in every slot where `missed` (a batch in order answered into `got`
/// first, [`cast_in_order`]).
fn cast_planned(
    surfaces: &SplatSurfaces<'_>,
    batch: &dyn Batch,
    out: CastOutputs<'_>,
    missed: bool,
    (order, fans): (Option<Order>, Fans<'_>),
    got: &mut Vec<Answer>,
) {
    let n = batch.len();
    assert!(out.t.len() >= n, "an output per ray");
    if let Some(order) = order {
        let mut buf = Converted::default();
        let (rays, lens) = batch.range(0..n, &mut buf);
        return cast_in_order(surfaces, (rays, lens), out, &order, got);
    }
    let packets = crate::accel::use_packets(surfaces.backend);
    let CastOutputs { t, ids, normals } = out;
    let (t, mut ids, mut normals) = (&mut t[..n], ids.map(|v| &mut v[..n]), normals.map(|v| &mut v[..3 * n]));
    for (run, fan) in &fans {
        // The fan's own answers where it has them (the same hits).
        let surfaces = &SplatSurfaces {
            backend: fan.backend().unwrap_or(surfaces.backend),
            ..*surfaces
        };
        let m = run.len();
        let ids = slots(ids.as_deref_mut().map(|v| &mut v[run.clone()]), 1, m, FAN_WINDOW);
        let normals = slots(
            normals.as_deref_mut().map(|v| &mut v[3 * run.start..3 * run.end]),
            3,
            m,
            FAN_WINDOW,
        );
        t[run.clone()]
            .par_chunks_mut(FAN_WINDOW)
            .zip(ids)
            .zip(normals)
            .enumerate()
            .for_each_init(
                || (Caster::new(surfaces), FanScratch::default(), Converted::default()),
                |(caster, scratch, buf), (c, ((t, ids), normals))| {
                    let start = run.start + c * FAN_WINDOW;
                    let window = (start..start + t.len(), run.start);
                    let (rays, lens) = batch.keyed(window, fan.as_ref(), buf, &mut scratch.keys);
                    let mut out = Writer { t, ids, normals, lens };
                    // Every slot a miss's first ([`answer`]), in one pass
                    // of stores: the fan's misses, most of a camera's
                    // rays, are then written (a call a ray was 5 % of a
                    // camera call's instructions).
                    if !missed {
                        out.misses();
                    }
                    keyed_window(rays, packets, scratch, &mut |idx, keys| {
                        caster.trace(rays, idx, Some((fan.as_ref(), keys)), &mut |i, f| out.put(i, f));
                    });
                },
            );
    }
    // The rays of no fan's run, chunk by chunk in place.
    let ids = slots(ids, 1, n, CHUNK);
    let normals = slots(normals, 3, n, CHUNK);
    t.par_chunks_mut(CHUNK)
        .zip(ids)
        .zip(normals)
        .enumerate()
        .for_each_init(Converted::default, |buf, (c, ((t, ids), normals))| {
            let range = c * CHUNK..(c * CHUNK + t.len());
            if !has_gap(&fans, &range) {
                return;
            }
            let (rays, lens) = batch.range(range.clone(), buf);
            let mut out = Writer { t, ids, normals, lens };
            let mut caster = Caster::new(surfaces);
            gaps(&fans, range, |piece| {
                batches(rays, piece, packets, &mut |idx| {
                    caster.trace(rays, idx, None, &mut |i, f| out.put(i, f));
                });
            });
        });
}

/// Where a task of [`cast_rays`] writes its rays' answers: the outputs'
/// slots of its rays, and their directions' lengths.
struct Writer<'o, 'l> {
    t: &'o mut [f32],
    ids: Option<&'o mut [u32]>,
    normals: Option<&'o mut [f32]>,
    lens: &'l [f32],
}

impl Writer<'_, '_> {
    /// A miss's answer ([`answer`] of `None`) in every slot.
    fn misses(&mut self) {
        let (t, id, n) = answer(None, 1.0);
        self.t.fill(t);
        if let Some(ids) = self.ids.as_deref_mut() {
            ids.fill(id);
        }
        if let Some(normals) = self.normals.as_deref_mut() {
            normals.fill(n[0]);
        }
    }

    /// Ray `i`'s answer ([`answer`]) into its slots.
    fn put(&mut self, i: usize, f: Option<SurfaceHit>) {
        let (t, id, n) = answer(f, self.lens[i]);
        self.t[i] = t;
        if let Some(ids) = self.ids.as_deref_mut() {
            ids[i] = id;
        }
        if let Some(normals) = self.normals.as_deref_mut() {
            normals[3 * i..3 * i + 3].copy_from_slice(&n);
        }
    }
}

/// A task's windows for [`cast_rays`]: one per packet slot, made once per
/// task, none per ray.
struct Caster<'s, 'a> {
    surfaces: &'s SplatSurfaces<'a>,
    hits: [CandidateHits; PACKET],
    found: [Option<SurfaceHit>; PACKET],
}

impl<'s, 'a> Caster<'s, 'a> {
    fn new(surfaces: &'s SplatSurfaces<'a>) -> Self {
        let xi = surfaces.scene.options.scale.xi;
        Caster {
            surfaces,
            hits: std::array::from_fn(|_| CandidateHits::new(xi)),
            found: [None; PACKET],
        }
    }

    /// The rays `idx` of `rays` (one, or a packet of one origin and
    /// direction signs) resolved, each answer handed to `write` by index;
    /// with `keyed`, rays of a fan's run with their keys (by index), each
    /// window first gathered by the fan where it can ([`Fan::gather_keyed`]:
    /// a camera's ray's block found once, when it was keyed).
    fn trace(
        &mut self,
        rays: &[Ray],
        idx: &[u16],
        keyed: Option<(&dyn Fan, &[u32])>,
        write: &mut impl FnMut(usize, Option<SurfaceHit>),
    ) {
        let query = |i: u16| Query::new(rays[usize::from(i)], 0.0, f32::INFINITY);
        let m = idx.len();
        let qs: [Query; PACKET] = std::array::from_fn(|k| query(idx[k.min(m - 1)]));
        match keyed {
            None if m == 1 => {
                write(usize::from(idx[0]), self.surfaces.surface_hit(qs[0], &mut self.hits[0]));
                return;
            }
            None => self.surfaces.surface_hits(&qs[..m], &mut self.hits[..m], &mut self.found[..m]),
            Some((fan, keys)) => {
                let backend = self.surfaces.backend;
                let gather = |qs: &[Query], hits: &mut [CandidateHits]| {
                    for ((q, h), &i) in qs.iter().zip(hits.iter_mut()).zip(idx) {
                        if !fan.gather_keyed(keys[usize::from(i)], q, h) {
                            backend.intersect_from(q, h);
                        }
                    }
                };
                self.surfaces.surface_hits_gathered(&qs[..m], &mut self.hits[..m], &mut self.found[..m], gather);
            }
        }
        for (&i, f) in idx.iter().zip(&self.found) {
            write(usize::from(i), *f);
        }
    }
}

/// Whether each ray of `rays` (directions of length `lens`) meets a
/// surface with `t` in `[t_near, t_far]` (in units of its direction's
/// length) into `out`: a shadow ray's question, the hits on Phong splats'
/// discs beyond their curved surfaces' silhouettes passed over (the
/// scene's [`PassOver`], as the renderer's shadow rays), in packets or
/// fans as [`cast_rays`] forms them; the answers of one ray at a time.
///
/// Panics if `lens` or `out` is shorter than `rays`.
pub fn occluded(surfaces: &SplatSurfaces<'_>, rays: &[Ray], lens: &[f32], span: (f32, f32), out: &mut [bool]) {
    assert!(lens.len() >= rays.len(), "a length per ray");
    occluded_planned(surfaces, &Held { rays, lens }, span, out, Order::of(rays));
}

/// [`occluded`] of the rays `rows`, as [`cast_rows_owned`] takes them: a
/// batch traced in its own order with each window converting only the
/// rows its fan does not know to miss, one put in order converted whole
/// into `buf` first.
///
/// # Errors
/// The index of the first row that is not a ray (`out` then holds
/// nothing to rely on).
///
/// # Panics
/// If `out` is shorter than the rows.
pub fn occluded_rows<T: RowNumber>(
    surfaces: &SplatSurfaces<'_>,
    rows: &RayRows<'_, T>,
    span: (f32, f32),
    out: &mut [bool],
    buf: &mut CastScratch,
) -> Result<(), usize> {
    if rows.scattered() {
        if !rows.convert_all(&mut buf.rays, &mut buf.lens) {
            return Err(rows.first_bad().unwrap_or(0));
        }
        let (rays, lens) = (&buf.rays, &buf.lens);
        occluded_planned(surfaces, &Held { rays, lens }, span, out, Some(Order::build(rays)));
    } else {
        occluded_planned(surfaces, rows, span, out, None);
    }
    rows.first_bad().map_or(Ok(()), Err)
}

/// [`occluded`] of `batch` (traced in `order` where it has one).
fn occluded_planned(
    surfaces: &SplatSurfaces<'_>,
    batch: &dyn Batch,
    (t_near, t_far): (f32, f32),
    out: &mut [bool],
    order: Option<Order>,
) {
    let n = batch.len();
    assert!(out.len() >= n, "an output per ray");
    let scene = surfaces.scene;
    let backend = surfaces.backend;
    let pass = scene.has_phong().then_some(scene as &dyn PassOver);
    let query = |ray: Ray, len: f32| Query {
        ray,
        t_min: t_near * len,
        t_max: t_far * len,
        from: None,
        pass,
    };
    if let Some(order) = order {
        // One at a time, in the order's sequence, then back in place.
        let mut buf = Converted::default();
        let (rays, lens) = batch.range(0..n, &mut buf);
        let mut got = vec![false; n];
        got.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each_init(
                || (GatheredRays::new(), Vec::with_capacity(CHUNK)),
                |(buf, qs), (c, got)| {
                    let chunk = order.gather(c, rays, lens, buf);
                    qs.clear();
                    qs.extend(chunk.iter().map(|(ray, len)| query(ray, len)));
                    backend.occluded_each(qs, got);
                },
            );
        out[..n]
            .par_iter_mut()
            .zip(&order.at)
            .for_each(|(o, &k)| *o = got[k as usize]);
        return;
    }
    let packets = crate::accel::use_packets(backend);
    // The rays `idx` of `rays` (one, or a packet) asked of `backend`, each
    // answer handed to `write` by index.
    let trace = |backend: &dyn Backend,
                 rays: &[Ray],
                 lens: &[f32],
                 idx: &[u16],
                 write: &mut dyn FnMut(usize, bool)| {
        if let &[i] = idx {
            let i = usize::from(i);
            write(i, backend.occluded_from(&query(rays[i], lens[i])));
            return;
        }
        let m = idx.len();
        let qs: [Query; PACKET] = std::array::from_fn(|k| {
            let i = usize::from(idx[k.min(m - 1)]);
            query(rays[i], lens[i])
        });
        let mut got = [false; PACKET];
        backend.occluded_packet(&qs[..m], &mut got[..m]);
        for (&i, g) in idx.iter().zip(&got) {
            write(usize::from(i), *g);
        }
    };
    // A fan's misses hold from `t >= 0` only.
    let fans = if t_near >= 0.0 {
        fans(backend, batch)
    } else {
        Vec::new()
    };
    let out = &mut out[..n];
    for (run, fan) in &fans {
        // The fan's own answers where it has them (the same answers).
        let backend = fan.backend().unwrap_or(backend);
        out[run.clone()]
            .par_chunks_mut(FAN_WINDOW)
            .enumerate()
            .for_each_init(
                || (FanScratch::default(), Converted::default()),
                |(scratch, buf), (c, out)| {
                    let start = run.start + c * FAN_WINDOW;
                    let window = (start..start + out.len(), run.start);
                    let (rays, lens) = batch.keyed(window, fan.as_ref(), buf, &mut scratch.keys);
                    // Every answer a miss's first (the fan's misses are then
                    // written).
                    out.fill(false);
                    keyed_window(rays, packets, scratch, &mut |idx, _| {
                        trace(backend, rays, lens, idx, &mut |i, g| out[i] = g);
                    });
                },
            );
    }
    // The rays of no fan's run, chunk by chunk in place.
    out.par_chunks_mut(CHUNK).enumerate().for_each_init(Converted::default, |buf, (c, out)| {
        let range = c * CHUNK..(c * CHUNK + out.len());
        if !has_gap(&fans, &range) {
            return;
        }
        let (rays, lens) = batch.range(range.clone(), buf);
        gaps(&fans, range, |piece| {
            batches(rays, piece, packets, &mut |idx| {
                trace(backend, rays, lens, idx, &mut |i, g| out[i] = g);
            });
        });
    });
}

/// A ray's answer in [`CastOutputs`]' terms: its distance in units of its
/// direction's length `len`, its splat id and shading normal (`inf`,
/// `u32::MAX` and 0 on a miss).
fn answer(f: Option<SurfaceHit>, len: f32) -> Answer {
    match f {
        None => (f32::INFINITY, u32::MAX, [0.0; 3]),
        Some(h) => {
            let t = if len == 1.0 { h.t } else { h.t / len };
            (t, h.id, h.normal.to_array())
        }
    }
}

/// [`cast_rays`] of a batch of scattered rays one at a time in `order`'s
/// sequence, the answers kept in that sequence in `got` (its memory the
/// caller's, [`CastScratch`]; resized to the batch) and then written in
/// place.
fn cast_in_order(
    surfaces: &SplatSurfaces<'_>,
    (rays, lens): (&[Ray], &[f32]),
    out: CastOutputs<'_>,
    order: &Order,
    got: &mut Vec<Answer>,
) {
    let n = rays.len();
    let xi = surfaces.scene.options.scale.xi;
    // Every slot is written below: a kept vector of this length is not
    // written twice (one of another, in parallel).
    if got.len() != n {
        got.clear();
        fill(got, answer(None, 1.0), n);
    }
    got.par_chunks_mut(CHUNK).enumerate().for_each_init(GatheredRays::new, |buf, (c, got)| {
        let mut hits = CandidateHits::new(xi);
        let chunk = order.gather(c, rays, lens, buf);
        for (g, (ray, len)) in got.iter_mut().zip(chunk.iter()) {
            let q = Query::new(ray, 0.0, f32::INFINITY);
            *g = answer(surfaces.surface_hit(q, &mut hits), len);
        }
    });
    place(&order.at, got, out);
}

/// The answers `got`, in an order's sequence, written in place: ray `j`'s
/// is `got[at[j]]`.
fn place(at: &[u32], got: &[Answer], out: CastOutputs<'_>) {
    let n = at.len();
    let ids = slots(out.ids.map(|v| &mut v[..n]), 1, n, CHUNK);
    let normals = slots(out.normals.map(|v| &mut v[..3 * n]), 3, n, CHUNK);
    out.t[..n]
        .par_chunks_mut(CHUNK)
        .zip(ids)
        .zip(normals)
        .enumerate()
        .for_each(|(c, ((t, mut ids), mut normals))| {
            for (j, &k) in at[c * CHUNK..c * CHUNK + t.len()].iter().enumerate() {
                let (tt, id, nn) = got[k as usize];
                t[j] = tt;
                if let Some(ids) = ids.as_deref_mut() {
                    ids[j] = id;
                }
                if let Some(normals) = normals.as_deref_mut() {
                    normals[3 * j..3 * j + 3].copy_from_slice(&nn);
                }
            }
        });
}

/// Fewest rays in a batch that [`Order`] puts in order.
const ORDER_MIN: usize = 4096;

/// Cells per axis of the grid over a batch's origins by which [`Order`]
/// sorts its rays.
const ORDER_CELLS: u32 = 16;

/// The sequence in which a batch of rays from scattered origins is traced
/// (issue 55's random rays): by the cell of a 16³ grid over the rays'
/// origins that holds its origin (cells in Morton order), then by the
/// signs of its direction, the batch's order kept among equals. Rays
/// traced one after another then start near each other and head the same
/// way, so they meet the same nodes, leaves and splats while these are
/// still in the caches: 0.71 of the CPU time of the batch's own order on
/// 1M rays from the bunny's bounding box (`docs/notes/backends.md`, "Issue
/// 55, twelfth session"). Each ray's answer is its own, in any order.
struct Order {
    /// The rays in the order traced (indices into the batch).
    ray: Vec<u32>,
    /// Each ray's place in that order (`ray[at[i]] == i`).
    at: Vec<u32>,
}

impl Order {
    /// Whether a batch of `rays` is put in order: at least [`ORDER_MIN`]
    /// of them, not sharing their origins ([`shares_origins`]).
    fn wanted(rays: &impl RaySet) -> bool {
        let n = rays.len();
        n >= ORDER_MIN && u32::try_from(n).is_ok() && !shares_origins(rays)
    }

    /// The rays (and their lengths) of chunk `c` of the order ([`CHUNK`]
    /// rays from `c * CHUNK`), copied in order, all read before any is
    /// traced: their loads from the batch's scattered places overlap,
    /// where reading each ray as it is traced waited on memory for every
    /// one (a fifth of the call; `docs/notes/backends.md`, "Issue 55,
    /// twelfth session").
    ///
    /// Into `got`, a buffer a task reuses chunk after chunk (one made and
    /// returned per chunk was copied whole on its way out).
    fn gather<'g>(
        &self,
        c: usize,
        rays: &[Ray],
        lens: &[f32],
        got: &'g mut GatheredRays,
    ) -> &'g GatheredRays {
        let idx = &self.ray[c * CHUNK..self.ray.len().min((c + 1) * CHUNK)];
        got.len = idx.len();
        for (k, &i) in idx.iter().enumerate() {
            got.rays[k] = rays[i as usize];
            got.lens[k] = lens[i as usize];
        }
        got
    }

    /// The order of `rays`, or `None` when the batch is short (below
    /// [`ORDER_MIN`] rays), holds 2^32 rays or more, or is not scattered:
    /// one ray in eight or more leaves its predecessor's origin (bit for
    /// bit), as runs of camera or scanner rays do (packets and fans take
    /// those in the batch's order).
    ///
    /// A counting sort by key, stable, in parallel: each task of
    /// [`ORDER_TASK`] rays counts its keys, the places are handed out key
    /// by key and, within a key, task by task (so in the batch's order),
    /// and each task then places its rays. Every step but the short walk
    /// over the counts runs on the threads (it ran on the calling thread
    /// alone, while the workers waited: `docs/notes/backends.md`, "Issue
    /// 55, thirty-ninth session").
    fn of(rays: &[Ray]) -> Option<Order> {
        Order::wanted(&rays).then(|| Order::build(rays))
    }

    /// [`Order::of`] `rays`, asked for.
    fn build(rays: &[Ray]) -> Order {
        let n = rays.len();
        let key = key_of(rays);
        let buckets = (ORDER_CELLS.pow(3) * 8) as usize;
        let mut keys = vec![0u16; n];
        let mut firsts: Vec<Vec<u32>> = keys
            .par_chunks_mut(ORDER_TASK)
            .zip(rays.par_chunks(ORDER_TASK))
            .map(|(ks, rs)| {
                let mut count = vec![0u32; buckets];
                for (k, r) in ks.iter_mut().zip(rs) {
                    *k = key(r);
                    count[usize::from(*k)] += 1;
                }
                count
            })
            .collect();
        let mut sum = 0;
        for b in 0..buckets {
            for task in &mut firsts {
                (task[b], sum) = (sum, sum + task[b]);
            }
        }
        let ray: Vec<AtomicU32> = (0..n).into_par_iter().map(|_| AtomicU32::new(0)).collect();
        let mut at = vec![0u32; n];
        at.par_chunks_mut(ORDER_TASK)
            .zip(keys.par_chunks(ORDER_TASK))
            .zip(firsts.par_iter_mut())
            .enumerate()
            .for_each(|(t, ((at, ks), next))| {
                for (j, (a, &k)) in at.iter_mut().zip(ks).enumerate() {
                    let place = &mut next[usize::from(k)];
                    *a = *place;
                    ray[*place as usize].store((t * ORDER_TASK + j) as u32, Ordering::Relaxed);
                    *place += 1;
                }
            });
        let ray = ray.into_iter().map(AtomicU32::into_inner).collect();
        Order { ray, at }
    }
}

/// Rays a task of [`Order::of`] counts and places.
const ORDER_TASK: usize = 1 << 17;

/// Rays a task of [`shares_origins`] compares.
const SHARE_TASK: usize = 1 << 14;

/// Whether one ray in eight or more of `rays` leaves its predecessor's
/// origin (bit for bit). In parallel, in tasks of [`SHARE_TASK`]
/// neighbours; a task started once enough are found adds nothing (a
/// camera's batch stops after about an eighth of its rays).
fn shares_origins(rays: &impl RaySet) -> bool {
    let bits = |i: usize| rays.origin(i).to_array().map(f32::to_bits);
    let pairs = rays.len().saturating_sub(1);
    let enough = rays.len().div_ceil(8);
    let found = AtomicUsize::new(0);
    (0..pairs.div_ceil(SHARE_TASK)).into_par_iter().for_each(|t| {
        if found.load(Ordering::Relaxed) < enough {
            let task = t * SHARE_TASK..pairs.min((t + 1) * SHARE_TASK);
            let shared = task.filter(|&i| bits(i) == bits(i + 1)).count();
            found.fetch_add(shared, Ordering::Relaxed);
        }
    });
    found.into_inner() >= enough
}

/// A cell index's bits spread to every third bit (bit `b` to bit `3b`):
/// one axis's share of a Morton index over [`ORDER_CELLS`] cells.
const SPREAD: [u32; ORDER_CELLS as usize] = {
    let mut t = [0u32; ORDER_CELLS as usize];
    let mut c = 0;
    while c < t.len() {
        let mut b = 0;
        while b < ORDER_CELLS.trailing_zeros() {
            t[c] |= ((c as u32) >> b & 1) << (3 * b);
            b += 1;
        }
        c += 1;
    }
    t
};

/// Each ray's key in [`Order`]: the Morton index of the cell of a grid of
/// [`ORDER_CELLS`]³ over the rays' origins holding its origin, then its
/// direction's signs ([`octant`]). The function giving it, made from the
/// box of the batch's origins.
fn key_of(rays: &[Ray]) -> impl Fn(&Ray) -> u16 + Sync + use<> {
    let (lo, hi) = rays
        .par_chunks(ORDER_MIN)
        .map(|c| {
            c.iter().fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), r| {
                let o = Vec3A::from(r.origin);
                (lo.min(o), hi.max(o))
            })
        })
        .reduce(
            || (Vec3A::INFINITY, Vec3A::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    // Cells per unit on each axis (0 across a flat or unbounded
    // extent: one cell); NaN and values out of range saturate into
    // the grid.
    let scale = Vec3A::splat(ORDER_CELLS as f32) / (hi - lo);
    let scale = Vec3A::select(scale.is_finite_mask(), scale, Vec3A::ZERO);
    move |r: &Ray| {
        let c = ((Vec3A::from(r.origin) - lo) * scale).to_array();
        let cell = |x: f32| SPREAD[(x as u32).min(ORDER_CELLS - 1) as usize];
        let k = cell(c[0]) | cell(c[1]) << 1 | cell(c[2]) << 2;
        ((k << 3) | octant(r) as u32) as u16
    }
}

/// A chunk's rays and their lengths, copied in [`Order`]'s sequence.
struct GatheredRays {
    rays: [Ray; CHUNK],
    lens: [f32; CHUNK],
    len: usize,
}

impl GatheredRays {
    /// An empty buffer, on the heap (14 kB).
    fn new() -> Box<GatheredRays> {
        Box::new(GatheredRays {
            rays: [Ray::new(Vec3::ZERO, Vec3::X); CHUNK],
            lens: [0.0; CHUNK],
            len: 0,
        })
    }

    /// Each ray with its direction's length, in order.
    fn iter(&self) -> impl Iterator<Item = (Ray, f32)> + '_ {
        self.rays[..self.len].iter().copied().zip(self.lens[..self.len].iter().copied())
    }
}

/// The rays `piece` of a chunk (indices into `rays`, the chunk's) to
/// `trace`: in the packets [`for_each_packet`] finds, or, without
/// `packets`, one at a time.
fn batches(rays: &[Ray], piece: Range<usize>, packets: bool, trace: &mut impl FnMut(&[u16])) {
    if packets {
        for_each_packet(rays, piece, trace);
    } else {
        piece.for_each(|i| trace(&[i as u16]));
    }
}

/// Fewest consecutive rays sharing an origin for which the backend is
/// asked for a fan ([`crate::accel::Backend::fan`], which may still
/// decline).
const FAN_RUN: usize = 4096;

/// Rays of a chunk of [`CHUNK`] between two that [`fans`] compares with
/// its first.
const FAN_SAMPLE: usize = 64;

/// The runs of at least [`FAN_RUN`] consecutive rays of `rays` leaving one
/// origin (bit for bit, as sampled) for which `backend` builds a fan, each
/// with its fan, in order (built in parallel). A chunk of [`CHUNK`] rays
/// whose every [`FAN_SAMPLE`]th ray and last leave its first ray's origin
/// is taken whole, unread between (reading every ray's origin took 2 % of
/// a camera `cast_rays` call): a ray of it leaving elsewhere is still
/// answered as its own, since a fan answers only the rays leaving its
/// origin (its keys and lists look at each ray's) and hands the others
/// to its backend.
fn fans<'b>(backend: &'b dyn Backend, rays: &dyn RaySet) -> Fans<'b> {
    let bits = |i: usize| rays.origin(i).to_array().map(f32::to_bits);
    let n = rays.len();
    // Whether each chunk of [`CHUNK`] is taken whole: a run steps over
    // such chunks.
    let whole: Vec<bool> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let (first, last) = (c * CHUNK, n.min(c * CHUNK + CHUNK) - 1);
            let o = bits(first);
            (first..=last).step_by(FAN_SAMPLE).all(|i| bits(i) == o) && bits(last) == o
        })
        .collect();
    let mut runs = Vec::new();
    let mut start = 0;
    while start < n {
        let o = bits(start);
        let mut end = start + 1;
        while end < n && bits(end) == o {
            end += if end % CHUNK == 0 && whole[end / CHUNK] {
                CHUNK.min(n - end)
            } else {
                1
            };
        }
        let len = end - start;
        if len >= FAN_RUN {
            runs.push(start..start + len);
        }
        start += len;
    }
    runs.into_par_iter()
        .filter_map(|run| {
            let fan = backend.fan(&Part(rays, run.clone()))?;
            Some((run, fan))
        })
        .collect()
}

/// Rays of a fan's run a task takes at once ([`keyed_window`]): eight rows
/// of a 1024-pixel-wide camera's rays, 192 kB of rays (they stay in the
/// core's cache from the fan's test to their traversal).
const FAN_WINDOW: usize = 8192;

/// What [`keyed_window`] keeps between windows (a task's): the window's
/// keys ([`Batch::keyed`]) among them.
#[derive(Default)]
struct FanScratch {
    keys: Vec<u32>,
    left: Vec<u16>,
    elsewhere: Vec<u16>,
    sorted: Vec<u16>,
    count: Vec<u32>,
}

/// The rays of a window of a fan's run (at most [`FAN_WINDOW`]; indices
/// into `rays`, the window's) to `trace` with the window's keys (by the
/// same indices, for [`Fan::gather_keyed`]), but for the rays the fan knows
/// to miss (whose answers the caller writes first, for the whole window;
/// such a ray may be left unset): in their keys' order (`s.keys`,
/// [`Batch::keyed`]'s; stable; those it holds no place for last), in
/// packets of one direction's signs ([`by_octant`]), or one at a time
/// without `packets`. So a packet holds rays of neighbouring directions
/// whatever the window's own order: taken row after row, a camera's
/// packets were strips of 8×1 pixels, and one cut past a gap of misses
/// joined rays from both sides of it (`docs/notes/backends.md`, "Issue
/// 55, fortieth session").
///
/// The keys are sorted by counting where they span at most four times
/// the window's rays (rows of a camera's image: a few rows of the fan's
/// blocks); otherwise (a batch in another order) the window's order is
/// kept.
fn keyed_window(rays: &[Ray], packets: bool, s: &mut FanScratch, trace: &mut impl FnMut(&[u16], &[u32])) {
    let n = rays.len();
    debug_assert!(n <= FAN_WINDOW && s.keys.len() == n);
    s.left.clear();
    s.elsewhere.clear();
    let (mut lo, mut hi) = (u32::MAX, 0);
    for (i, &k) in s.keys.iter().enumerate() {
        if k == FAN_ELSEWHERE {
            s.elsewhere.push(i as u16);
        } else if k != FAN_MISS {
            s.left.push(i as u16);
            (lo, hi) = (lo.min(k), hi.max(k));
        }
    }
    let order = if s.left.len() > PACKET && ((hi - lo) as usize) < 4 * n {
        let span = (hi - lo) as usize + 1;
        s.count.clear();
        s.count.resize(span + 1, 0);
        for &i in &s.left {
            s.count[(s.keys[usize::from(i)] - lo) as usize + 1] += 1;
        }
        for b in 0..span {
            s.count[b + 1] += s.count[b];
        }
        s.sorted.resize(s.left.len(), 0);
        for &i in &s.left {
            let place = &mut s.count[(s.keys[usize::from(i)] - lo) as usize];
            s.sorted[*place as usize] = i;
            *place += 1;
        }
        &s.sorted
    } else {
        &s.left
    };
    let keys = &s.keys;
    for order in [order, &s.elsewhere] {
        if packets {
            by_octant(rays, order, |p| trace(p, keys));
        } else {
            order.iter().for_each(|&i| trace(&[i], keys));
        }
    }
}

/// Whether some of the chunk `range` of a batch lies in none of the runs
/// of `fans` ([`gaps`]).
fn has_gap(fans: &[(Range<usize>, Box<dyn Fan + '_>)], range: &Range<usize>) -> bool {
    let mut any = false;
    gaps(fans, range.clone(), |_| any = true);
    any
}

/// The pieces of the chunk `range` of a batch that lie in none of the
/// runs of `fans` (sorted, not overlapping), each handed to `each`
/// relative to the chunk's start, in order.
fn gaps(fans: &[(Range<usize>, Box<dyn Fan + '_>)], range: Range<usize>, mut each: impl FnMut(Range<usize>)) {
    let mut at = range.start;
    let first = fans.partition_point(|(run, _)| run.end <= at);
    for (run, _) in &fans[first..] {
        if run.start >= range.end {
            break;
        }
        if run.start > at {
            each(at - range.start..run.start - range.start);
        }
        at = run.end.min(range.end);
    }
    if at < range.end {
        each(at - range.start..range.end - range.start);
    }
}

/// An optional output of `n` rays cut into chunks of `chunk` rays (`per`
/// slots a ray), or a `None` per chunk: one list per call, none per ray.
fn slots<T: Send>(out: Option<&mut [T]>, per: usize, n: usize, chunk: usize) -> Vec<Option<&mut [T]>> {
    match out {
        Some(v) => v.chunks_mut(per * chunk).map(Some).collect(),
        None => (0..n.div_ceil(chunk)).map(|_| None).collect(),
    }
}

/// The packets of the rays `range` of a chunk (at most [`CHUNK`] rays):
/// each run of consecutive rays leaving one origin (bit for bit) split by
/// the signs of their directions ([`by_octant`]); a ray whose origin no
/// neighbour shares is handed alone. Every ray is handed exactly once.
fn for_each_packet(rays: &[Ray], range: Range<usize>, mut each: impl FnMut(&[u16])) {
    debug_assert!(rays.len() <= CHUNK);
    let bits = |r: &Ray| r.origin.to_array().map(f32::to_bits);
    let mut start = range.start;
    while start < range.end {
        let o = bits(&rays[start]);
        let end = start
            + 1
            + rays[start + 1..range.end]
                .iter()
                .take_while(|r| bits(r) == o)
                .count();
        if end - start == 1 {
            each(&[start as u16]);
        } else {
            let idx: [u16; CHUNK] = std::array::from_fn(|k| (start + k) as u16);
            by_octant(rays, &idx[..end - start], &mut each);
        }
        start = end;
    }
}

/// The rays `idx` of a chunk, which share an origin, split by the signs of
/// their directions (the octree's front-to-back order needs one sign per
/// axis in a packet), [`PACKET`] rays at a time, each packet's indices
/// handed to `each` in increasing order.
fn by_octant(rays: &[Ray], idx: &[u16], mut each: impl FnMut(&[u16])) {
    let mut by = [[0u16; PACKET]; 8];
    let mut len = [0usize; 8];
    for &i in idx {
        let s = octant(&rays[usize::from(i)]);
        by[s][len[s]] = i;
        len[s] += 1;
        if len[s] == PACKET {
            each(&by[s]);
            len[s] = 0;
        }
    }
    for (b, &l) in by.iter().zip(&len) {
        if l > 0 {
            each(&b[..l]);
        }
    }
}

/// The signs of a direction's components, bit `k` for axis `k` (the sign
/// bit, so `-0.0` counts as negative, as the octree's traversal orders
/// children).
fn octant(r: &Ray) -> usize {
    usize::from(r.dir.x.is_sign_negative())
        | usize::from(r.dir.y.is_sign_negative()) << 1
        | usize::from(r.dir.z.is_sign_negative()) << 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The table's Morton index is the bit-by-bit interleave of the
    /// three cells, for every cell of the grid.
    #[test]
    fn spread_cells_interleave_bit_by_bit() {
        let bits = ORDER_CELLS.trailing_zeros();
        let mut distinct = std::collections::HashSet::new();
        for x in 0..ORDER_CELLS {
            for y in 0..ORDER_CELLS {
                for z in 0..ORDER_CELLS {
                    let mut want = 0u32;
                    for (a, c) in [x, y, z].into_iter().enumerate() {
                        for b in 0..bits {
                            want |= (c >> b & 1) << (3 * b + a as u32);
                        }
                    }
                    let got = SPREAD[x as usize]
                        | SPREAD[y as usize] << 1
                        | SPREAD[z as usize] << 2;
                    assert_eq!(got, want, "cell ({x}, {y}, {z})");
                    distinct.insert(got);
                }
            }
        }
        assert_eq!(distinct.len(), ORDER_CELLS.pow(3) as usize);
    }

    /// `n` rays from origins scattered over a box, directions mixed.
    fn scattered(n: usize, seed: u64) -> Vec<Ray> {
        let mut rng = SplitMix64::new(seed);
        let mut r = |a: f32, b: f32| a + (b - a) * rng.next_f32();
        (0..n)
            .map(|_| {
                let o = Vec3::new(r(-1.0, 1.0), r(0.0, 4.0), r(-2.0, 2.0));
                Ray::new(o, Vec3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)))
            })
            .collect()
    }

    /// `order` is a permutation of `rays` and its inverse, sorted by key
    /// with the batch's order kept among equal keys; rays of one key head
    /// the same way from within a 16th of the origins' extent on each axis.
    fn assert_ordered(rays: &[Ray], order: &Order) {
        let mut seen = vec![false; rays.len()];
        for (k, &i) in order.ray.iter().enumerate() {
            assert!(!seen[i as usize]);
            seen[i as usize] = true;
            assert_eq!(order.at[i as usize] as usize, k);
        }
        let key = key_of(rays);
        let keys: Vec<u16> = rays.iter().map(&key).collect();
        let extent = Vec3::new(2.0, 4.0, 4.0);
        for w in order.ray.windows(2) {
            let (i, j) = (w[0] as usize, w[1] as usize);
            assert!(keys[i] < keys[j] || (keys[i] == keys[j] && i < j));
            if keys[i] == keys[j] {
                let (a, b) = (&rays[i], &rays[j]);
                assert_eq!(octant(a), octant(b));
                let gap = (a.origin - b.origin).abs();
                assert!(gap.cmple(extent / 16.0 * 1.001).all(), "{a:?} {b:?}");
            }
        }
        assert!(order.ray.iter().enumerate().any(|(k, &i)| i as usize != k));
    }

    /// Rows are put in order while fewer than an eighth of the sampled
    /// pairs of neighbours share their origins' numbers: one pair short of
    /// it, they are; with that eighth, not (the sampling stops there).
    #[test]
    fn rows_are_scattered_below_an_eighth_of_pairs_sharing() {
        let rays = scattered(8192, 3);
        let mut rows: Vec<f32> = rays.iter().flat_map(|r| [r.origin.to_array(), r.dir.to_array()].concat()).collect();
        let pairs = (0..8191).step_by(ROW_SAMPLE);
        let enough = pairs.len().div_ceil(8);
        assert!(RayRows::new(&rows, DVec3::ZERO).scattered());
        for (k, i) in pairs.enumerate().take(enough) {
            let o: [f32; 3] = rows[6 * i..6 * i + 3].try_into().unwrap();
            rows[6 * i + 6..6 * i + 9].copy_from_slice(&o);
            assert_eq!(RayRows::new(&rows, DVec3::ZERO).scattered(), k + 1 < enough, "{k} pairs");
        }
        assert!(!RayRows::new(&rows[..6 * (ORDER_MIN - 1)], DVec3::ZERO).scattered());
    }

    #[test]
    fn scattered_rays_are_ordered_by_origin_cell_and_signs() {
        let mut rays = scattered(5000, 12);
        let order = Order::of(&rays).expect("5000 scattered rays are ordered");
        assert_ordered(&rays, &order);
        // Too few rays, or runs sharing an origin: no order.
        assert!(Order::of(&rays[..ORDER_MIN - 1]).is_none());
        for i in (0..rays.len()).step_by(4) {
            let o = rays[i].origin;
            rays[i + 1].origin = o;
        }
        assert!(Order::of(&rays).is_none());
    }

    /// A batch of several of `Order::of`'s tasks is one stable sort, and
    /// its tasks count the rays sharing their predecessor's origin as one
    /// loop would: a batch with one pair short of an eighth sharing is
    /// ordered, with one more it is not.
    #[test]
    fn a_batch_of_many_tasks_is_ordered_as_one() {
        let n = 2 * ORDER_TASK + 12_345;
        let mut rays = scattered(n, 5);
        assert_ordered(&rays, &Order::of(&rays).expect("scattered rays are ordered"));
        // The pairs `(i, i + 1)` made to share, spread over every task of
        // `shares_origins` and across their ends.
        let enough = n.div_ceil(8);
        let step = (n - 1) / enough;
        let pairs: Vec<usize> = (0..enough).map(|k| k * step).collect();
        assert!(pairs.iter().any(|&i| i % SHARE_TASK == SHARE_TASK - 1));
        for &i in &pairs[..enough - 1] {
            rays[i + 1].origin = rays[i].origin;
        }
        assert!(!shares_origins(&rays.as_slice()));
        assert!(Order::of(&rays).is_some());
        let last = pairs[enough - 1];
        rays[last + 1].origin = rays[last].origin;
        assert!(shares_origins(&rays.as_slice()));
        assert!(Order::of(&rays).is_none());
    }

    #[test]
    fn packets_share_an_origin_and_signs_and_take_every_ray_once() {
        // Three runs: 20 camera rays from one eye (signs mixed), a lone
        // ray, 5 rays from another eye.
        let eye = Vec3::new(0.0, 1.0, 5.0);
        let mut rays: Vec<Ray> = (0..20)
            .map(|i| Ray::new(eye, Vec3::new(i as f32 - 9.5, -1.0 - (i % 3) as f32, -4.0)))
            .collect();
        rays.push(Ray::new(Vec3::X, Vec3::Y));
        let other = Vec3::new(2.0, 0.0, 0.0);
        rays.extend((0..5).map(|i| Ray::new(other, Vec3::new(1.0, i as f32, 0.5))));
        let mut seen = vec![0; rays.len()];
        let mut sizes = Vec::new();
        for_each_packet(&rays, 0..rays.len(), |idx| {
            assert!(!idx.is_empty() && idx.len() <= PACKET);
            let first = &rays[usize::from(idx[0])];
            for &i in idx {
                let r = &rays[usize::from(i)];
                assert_eq!(r.origin, first.origin);
                assert_eq!(octant(r), octant(first));
                seen[usize::from(i)] += 1;
            }
            assert!(idx.windows(2).all(|w| w[0] < w[1]));
            sizes.push(idx.len());
        });
        assert!(seen.iter().all(|&k| k == 1), "{seen:?}");
        // The lone ray alone; the 5 of the second eye (one octant) as one
        // packet; the first eye's 20 (two octants, 10 each) as 8 + 2 twice.
        assert!(sizes.contains(&1) && sizes.contains(&5), "{sizes:?}");
        let mut sorted = sizes.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, [1, 2, 2, 5, PACKET, PACKET], "{sizes:?}");
    }
}
