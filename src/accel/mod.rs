//! Acceleration backends and the contract they share (DESIGN §2).
//!
//! Every backend answers the same two questions about a ray — the candidate
//! hits within the blending window `xi` of the nearest hit (§4.3), and
//! whether anything is hit at all (shadow rays) — using the one ray–splat
//! routine [`intersect_disc`]. Nothing above [`Backend`] knows which ran.

pub mod brute;
pub mod embree;
pub mod octree;
pub mod resolve;

use crate::splat::Disc;
use glam::Vec3;

/// A ray `origin + t * dir`. `dir` is expected to be unit length, so `t` is a
/// distance; nothing here divides by its length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Ray origin.
    pub origin: Vec3,
    /// Ray direction (unit length by convention).
    pub dir: Vec3,
}

impl Ray {
    /// A ray from `origin` along `dir` (normalised here).
    #[must_use]
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir: dir.normalize(),
        }
    }

    /// The point at parameter `t`.
    #[must_use]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// One ray–splat hit: the small record of pbrt's two-phase intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Index of the splat in its [`crate::splat::SplatSet`].
    pub id: u32,
    /// Ray parameter of the hit.
    pub t: f32,
    /// Local coordinate along `u_axis`, divided by `r_u`.
    pub u: f32,
    /// Local coordinate along `v_axis`, divided by `r_v`.
    pub v: f32,
}

impl Candidate {
    /// `|(u, v)|`: 0 at the centre, 1 on the rim (the weight of eq. 5 is one
    /// minus this).
    #[must_use]
    pub fn radial(&self) -> f32 {
        (self.u * self.u + self.v * self.v).sqrt()
    }
}

/// Intersects a ray with one splat disc, relative to the splat centre.
///
/// Accepts `t_min <= t <= t_max` and the closed disc `u² + v² <= 1` (the rim
/// counts as on the splat). A ray parallel to the splat plane (`n·d == 0`)
/// misses, and so does a near-parallel one whose `t` is not finite; NaN in
/// the ray or disc makes every comparison false, hence a miss. No division
/// happens unless `n·d != 0`.
#[inline]
#[must_use]
pub fn intersect_disc(disc: &Disc, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let denom = disc.normal.dot(ray.dir);
    if denom == 0.0 {
        return None;
    }
    let oc = ray.origin - disc.center;
    let t = -disc.normal.dot(oc) / denom;
    if !(t >= t_min && t <= t_max && t.is_finite()) {
        return None;
    }
    let p = oc + ray.dir * t;
    let u = p.dot(disc.u_scaled);
    let v = p.dot(disc.v_scaled);
    if u * u + v * v <= 1.0 {
        Some((t, u, v))
    } else {
        None
    }
}

/// How many candidates a window keeps. Beyond it the farthest (by `(t, id)`)
/// are dropped and [`CandidateHits::overflowed`] is set.
pub const MAX_CANDIDATES: usize = 32;

/// The candidate hits of one ray: the nearest at `t0`, and every other hit
/// with `t` in `[t0, t0 + xi]` (§4.3), kept sorted by `(t, id)` without
/// duplicate ids. The final set does not depend on the order in which hits
/// are offered, so any two backends that find the same hits produce the
/// same candidates.
#[derive(Clone, Debug)]
pub struct CandidateHits {
    xi: f32,
    len: usize,
    /// Smallest `t` of a hit dropped for lack of room (`+inf` when none):
    /// the window overflowed iff that hit still lies inside the final window.
    min_dropped: f32,
    items: [Candidate; MAX_CANDIDATES],
}

impl CandidateHits {
    /// An empty window of width `xi` (scene-relative, see
    /// [`crate::accel::SceneScale`]).
    #[must_use]
    pub fn new(xi: f32) -> CandidateHits {
        CandidateHits {
            xi,
            len: 0,
            min_dropped: f32::INFINITY,
            items: [Candidate {
                id: 0,
                t: 0.0,
                u: 0.0,
                v: 0.0,
            }; MAX_CANDIDATES],
        }
    }

    /// Empties the window, keeping `xi`.
    pub fn clear(&mut self) {
        self.len = 0;
        self.min_dropped = f32::INFINITY;
    }

    /// The window width `xi`.
    #[must_use]
    pub fn xi(&self) -> f32 {
        self.xi
    }

    /// The candidates, nearest first.
    #[must_use]
    pub fn as_slice(&self) -> &[Candidate] {
        &self.items[..self.len]
    }

    /// The nearest candidate, if any.
    #[must_use]
    pub fn nearest(&self) -> Option<&Candidate> {
        self.as_slice().first()
    }

    /// True when no hit was recorded.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when more than [`MAX_CANDIDATES`] hits fell in the final window.
    ///
    /// Like the candidates themselves this does not depend on the order in
    /// which hits were offered: a hit dropped while the window was full only
    /// counts if it still lies within `t0 + xi` of the final nearest hit.
    #[must_use]
    pub fn overflowed(&self) -> bool {
        self.len > 0 && self.min_dropped <= self.far()
    }

    /// The far end of the window, `t0 + xi`, or `+inf` while empty: a hit
    /// beyond it can never be a candidate, so traversal may stop there.
    #[must_use]
    pub fn far(&self) -> f32 {
        if self.len == 0 {
            f32::INFINITY
        } else {
            self.items[0].t + self.xi
        }
    }

    /// Offers a hit. Returns the (possibly shrunk) far end of the window.
    pub fn offer(&mut self, c: Candidate) -> f32 {
        if c.t.is_nan() || c.t > self.far() {
            return self.far();
        }
        let items = &mut self.items[..self.len];
        if items.iter().any(|h| h.id == c.id) {
            return self.far();
        }
        let pos = items.partition_point(|h| (h.t, h.id) < (c.t, c.id));
        if self.len == MAX_CANDIDATES {
            if pos == MAX_CANDIDATES {
                self.min_dropped = self.min_dropped.min(c.t);
                return self.far();
            }
            self.min_dropped = self.min_dropped.min(self.items[MAX_CANDIDATES - 1].t);
            self.len -= 1;
        }
        self.items.copy_within(pos..self.len, pos + 1);
        self.items[pos] = c;
        self.len += 1;
        if pos == 0 {
            let far = self.far();
            self.len = self.as_slice().partition_point(|h| h.t <= far);
        }
        self.far()
    }
}

/// Scene-relative tolerances (DESIGN §2): never absolute constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneScale {
    /// Bounding-box diagonal of the splat set.
    pub diagonal: f32,
    /// Blending window `xi` of §4.3.
    pub xi: f32,
    /// Self-intersection distance `eps_self` of §3.2 (fig. 9 right).
    pub eps_self: f32,
}

impl SceneScale {
    /// Default fractions of the diagonal: `xi = 1e-3 d`, `eps_self = 1e-4 d`.
    #[must_use]
    pub fn from_diagonal(diagonal: f32) -> SceneScale {
        SceneScale {
            diagonal,
            xi: 1e-3 * diagonal,
            eps_self: 1e-4 * diagonal,
        }
    }
}

/// Figures about one built acceleration structure.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildStats {
    /// Wall seconds to build.
    pub build_seconds: f64,
    /// Bytes held by the structure (excluding the splats themselves).
    pub memory_bytes: usize,
    /// Octree: interior plus leaf nodes.
    pub nodes: usize,
    /// Octree: leaves.
    pub leaves: usize,
    /// Octree: mean splat references per non-empty leaf.
    pub mean_refs_per_leaf: f64,
}

/// Which backend to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendKind {
    /// Every ray against every splat (the oracle; small scenes only).
    Brute,
    /// Embree 4 user-geometry discs.
    Embree,
    /// The octree of §3.1.
    Octree,
}

impl std::str::FromStr for BackendKind {
    type Err = String;
    fn from_str(s: &str) -> Result<BackendKind, String> {
        match s {
            "brute" => Ok(BackendKind::Brute),
            "embree" => Ok(BackendKind::Embree),
            "octree" => Ok(BackendKind::Octree),
            _ => Err(format!(
                "unknown backend '{s}' (expected octree, embree or brute)"
            )),
        }
    }
}

impl BackendKind {
    /// The backend's name as the command line spells it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Brute => "brute",
            BackendKind::Embree => "embree",
            BackendKind::Octree => "octree",
        }
    }

    /// Builds this backend over `splats`.
    pub fn build(self, splats: &[crate::splat::Splat]) -> Result<Box<dyn Backend>, String> {
        Ok(match self {
            BackendKind::Brute => {
                let discs: Vec<Disc> = splats.iter().map(|s| s.disc_geometry()).collect();
                let start = std::time::Instant::now();
                let mut b = brute::Brute::new(&discs);
                b.set_build_seconds(start.elapsed().as_secs_f64());
                Box::new(b)
            }
            BackendKind::Embree => {
                let device = crate::embree::Device::new().map_err(|e| e.to_string())?;
                Box::new(embree::EmbreeBackend::new(&device, splats).map_err(|e| e.to_string())?)
            }
            BackendKind::Octree => Box::new(octree::Octree::new(
                splats,
                &octree::OctreeParams::default(),
            )),
        })
    }
}

/// One acceleration backend (DESIGN §2). Implemented by the brute-force
/// oracle, the octree and Embree.
pub trait Backend: Send + Sync {
    /// Short name: `brute`, `octree`, `embree`.
    fn name(&self) -> &'static str;

    /// Fills `hits` (cleared first) with the candidate hits of `ray` in
    /// `[t_min, t_max]`: the nearest and all within `hits.xi()` of it.
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits);

    /// True when any splat is hit with `t` in `[t_min, t_max]`.
    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool;

    /// Build figures.
    fn stats(&self) -> &BuildStats;
}
