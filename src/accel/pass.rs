//! Hits a shadow ray passes although its primitive is met: the rule that
//! lets a query see the surface a primitive stands for rather than the
//! primitive's whole disc (`docs/DESIGN.md`, "The backend contract", rule
//! 5), defined above the backends and asked by every one of them alike.

use super::departure::{Departure, Skip};
use crate::primitive::{Hit, Primitive};
use glam::Vec3;

/// Which accepted hits a query passes, whoever defines it: the scene's
/// Phong splats are the curved surfaces their fields describe (report
/// §4.1, eq. 4), and a ray that meets such a splat's disc beyond that
/// surface's silhouette passes it (`resolve::beyond_silhouette`). Every
/// backend asks [`PassOver::passes`] about each hit that
/// [`Primitive::intersect`] accepts and the self-hit rule keeps, so both
/// backends leave out the same hits.
pub trait PassOver: Sync {
    /// True when the ray along `dir` passes its hit `hit` on primitive `id`.
    fn passes(&self, id: u32, hit: &Hit, dir: Vec3) -> bool;
}

/// What a secondary query skips: the hits its departure's self-hit rule
/// skips ([`Departure::skips`]) and those its pass-over rule passes
/// ([`PassOver::passes`]), each when the query has one.
#[derive(Clone, Copy)]
pub struct Secondary<'a> {
    /// The surface the ray leaves, if any.
    pub from: Option<&'a Departure>,
    /// Hits the ray passes, if any.
    pub pass: Option<&'a dyn PassOver>,
}

impl Skip for Secondary<'_> {
    #[inline(always)]
    fn skips<P: Primitive>(self, dir: Vec3, id: u32, prim: &P, hit: &Hit) -> bool {
        self.from.is_some_and(|d| d.skips(dir, id, prim))
            || self.pass.is_some_and(|p| p.passes(id, hit, dir))
    }
}
