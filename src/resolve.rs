//! The one function that turns a window of candidate hits into the surface
//! hit, shared by every backend (`docs/DESIGN.md`, "The backend contract";
//! report §3.2 and §4.3).

use crate::accel::{Candidate, CandidateHits};
use crate::geometry::Ray;
use crate::splat::Splat;
use crate::{Error, Result};
use glam::Vec3;

/// How the shading normal is formed (report §4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShadingMode {
    /// One constant normal per splat: the winning splat's.
    Flat,
    /// Eq. (5) over the window, each splat with its constant normal.
    Blended,
    /// Eq. (5) over the window of Phong normal fields, eq. (4) (§4.1–4.3).
    #[default]
    Phong,
}

impl std::str::FromStr for ShadingMode {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "flat" => Ok(ShadingMode::Flat),
            "blended" => Ok(ShadingMode::Blended),
            "phong" => Ok(ShadingMode::Phong),
            _ => Err(Error::invalid(format!(
                "unknown shading mode '{s}' (expected flat, blended or phong)"
            ))),
        }
    }
}

/// The resolved surface hit: the full description, built only for the
/// winning splat.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// The winning splat (§3.2, fig. 9 left).
    pub id: u32,
    /// Ray parameter of the winning splat's hit.
    pub t: f32,
    /// Hit point on the winning splat.
    pub point: Vec3,
    /// Shading normal (unit), on the splats' own side: not flipped toward the
    /// ray. Flip it when `front` is false.
    pub normal: Vec3,
    /// The winning splat's plane normal.
    pub geometric_normal: Vec3,
    /// True when the ray meets the splats' front side (`dir · n < 0`).
    pub front: bool,
    /// How many candidates were blended (same side as the nearest).
    pub blended: u32,
}

fn faces_front(s: &Splat, ray: &Ray) -> bool {
    s.normal.dot(ray.dir) < 0.0
}

/// Resolves the candidate window into one surface hit, or `None` when empty:
/// [`resolve_within`] over the whole window (`hits.xi()`).
#[must_use]
pub fn resolve(
    hits: &CandidateHits,
    ray: &Ray,
    splats: &[Splat],
    mode: ShadingMode,
) -> Option<SurfaceHit> {
    resolve_within(hits, ray, splats, mode, hits.xi())
}

/// Resolves the candidates within `window` of the nearest (at most the
/// window the backend gathered, `hits.xi()`) into one surface hit, or
/// `None` when empty. The window is the nearest splat's model's `xi`
/// ([`crate::scene::Scene::xi_for`]): a backend gathers the widest of the
/// scene's windows, and each surface blends over its own depth.
///
/// Among candidates facing the same side as the nearest, the winner is the
/// one whose hit lies closest to its splat's centre (smallest `|(u,v)|`,
/// ties by `(t, id)`). The shading normal is eq. (5):
/// `n = Σ (1 - |(u_i,v_i)|) n_i / Σ (1 - |(u_i,v_i)|)` over those same-side
/// candidates, with `n_i` the constant normal (`Blended`) or the Phong field
/// of eq. (4) (`Phong`). Front- and back-facing splats are never blended
/// (thin sheets). When every weight is zero (all hits on rims) or the sum
/// cancels, the winner's own normal is used.
#[must_use]
pub fn resolve_within(
    hits: &CandidateHits,
    ray: &Ray,
    splats: &[Splat],
    mode: ShadingMode,
    window: f32,
) -> Option<SurfaceHit> {
    let nearest = hits.nearest()?;
    let front = faces_front(&splats[nearest.id as usize], ray);
    let far = nearest.t + window.min(hits.xi());
    let same_side = hits
        .as_slice()
        .iter()
        .take_while(|c| c.t <= far)
        .filter(|c| faces_front(&splats[c.id as usize], ray) == front);
    let key = |c: &Candidate| (c.radial(), c.t, c.id);
    let winner = *same_side.clone().min_by(|a, b| {
        key(a)
            .partial_cmp(&key(b))
            .unwrap_or(std::cmp::Ordering::Equal)
    })?;
    let ws = &splats[winner.id as usize];
    let own = match mode {
        ShadingMode::Phong => ws.field_normal(winner.u, winner.v),
        _ => ws.normal,
    };
    let mut blended = 0u32;
    let normal = if mode == ShadingMode::Flat {
        blended = 1;
        own
    } else {
        let mut sum = Vec3::ZERO;
        for c in same_side {
            let s = &splats[c.id as usize];
            let w = (1.0 - c.radial()).max(0.0);
            let n = match mode {
                ShadingMode::Phong => s.field_normal(c.u, c.v),
                _ => s.normal,
            };
            sum += w * n;
            blended += 1;
        }
        sum.try_normalize().unwrap_or(own)
    };
    Some(SurfaceHit {
        id: winner.id,
        t: winner.t,
        point: ray.at(winner.t),
        normal,
        geometric_normal: ws.normal,
        front,
        blended,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::Candidate;

    /// Two parallel splats facing the ray, 0.05 apart: the nearer hit near
    /// its rim, the farther near its centre.
    fn two_layers() -> (Vec<Splat>, CandidateHits, Ray) {
        let splats = vec![
            Splat::disc(Vec3::new(0.0, 0.0, 0.0), Vec3::Z, 1.0).unwrap(),
            Splat::disc(Vec3::new(0.0, 0.0, -0.05), Vec3::Z, 1.0).unwrap(),
        ];
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
        let mut hits = CandidateHits::new(0.1);
        for (id, t, u) in [(0u32, 5.0f32, 0.9f32), (1, 5.05, 0.1)] {
            hits.offer(Candidate { id, t, u, v: 0.0 });
        }
        (splats, hits, ray)
    }

    #[test]
    fn the_window_decides_which_candidates_compete() {
        let (splats, hits, ray) = two_layers();
        // The whole gathered window: the hit nearer its centre wins.
        let all = resolve(&hits, &ray, &splats, ShadingMode::Flat).unwrap();
        assert_eq!((all.id, all.blended), (1, 1));
        let wide = resolve_within(&hits, &ray, &splats, ShadingMode::Blended, 0.06).unwrap();
        assert_eq!((wide.id, wide.blended), (1, 2));
        // A window narrower than the layers' distance: only the nearest.
        let narrow = resolve_within(&hits, &ray, &splats, ShadingMode::Blended, 0.01).unwrap();
        assert_eq!((narrow.id, narrow.blended), (0, 1));
        // Never wider than what was gathered.
        let mut few = CandidateHits::new(0.01);
        for c in hits.as_slice() {
            few.offer(*c);
        }
        let capped = resolve_within(&few, &ray, &splats, ShadingMode::Blended, 1.0).unwrap();
        assert_eq!(capped.id, 0);
    }
}
