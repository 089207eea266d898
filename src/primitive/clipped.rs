//! The clipped disc: a splat's disc with one or two clip lines in its
//! plane (a splat on an edge or at a corner, [`Clip`]). A primitive of its
//! own, used only for a scene some of whose splats are clipped, so that
//! the 48-byte [`Disc`] and its SIMD filter stay what they are for every
//! other scene (`docs/DESIGN.md`, "The primitive contract").

use super::clip::Clip;
use super::{Disc, DiscPack, Hit, Local, Pack, PackRay, PackRays, Primitive};
use crate::geometry::Ray;
use crate::simd;
use glam::Vec3;

/// A disc and the clip lines that cut it ([`Clip::NONE`] for a whole
/// disc of a scene that also holds clipped ones).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClippedDisc {
    /// The whole disc.
    pub disc: Disc,
    /// Its clip lines, in the disc's normalised coordinates.
    pub clip: Clip,
}

impl Primitive for ClippedDisc {
    type Pack = ClippedPack;

    /// The disc's own hit ([`Disc::intersect`], bit for bit), kept when
    /// its normalised `(u, v)` lies on the kept side of every clip line
    /// ([`Clip::keeps`]; the line itself is kept, as the rim is).
    #[inline]
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let hit = self.disc.intersect(ray, t_min, t_max)?;
        self.clip.keeps(hit.u, hit.v).then_some(hit)
    }

    #[inline]
    fn center(&self) -> Vec3 {
        self.disc.center
    }

    /// The whole disc's box: conservative for the clipped part.
    fn half_extent(&self) -> Vec3 {
        self.disc.half_extent()
    }

    fn coarse_half_extent(&self) -> Vec3 {
        self.disc.coarse_half_extent()
    }

    /// The whole disc's exact test: conservative (a box meeting only the
    /// clipped-away part is reported as met, and its leaf then tests a
    /// disc that `intersect` misses there).
    fn meets_box(&self, lo: Vec3, hi: Vec3) -> bool {
        self.disc.meets_box(lo, hi)
    }

    /// [`Disc::locate`], except that a point whose projection lies on the
    /// clipped-away side of a line is not beside this splat at all
    /// (`radial2` infinite): the self-hit rule then never takes the splat
    /// across a crease for the surface a ray leaves (a valley whose faces
    /// meet within 75° would otherwise skip the other face beside the
    /// departure point).
    #[inline]
    fn locate(&self, p: Vec3) -> Local {
        let mut l = self.disc.locate(p);
        if !self.clip.is_none() {
            let d = p - self.disc.center;
            let (u, v) = (d.dot(self.disc.u_scaled), d.dot(self.disc.v_scaled));
            if !self.clip.keeps(u, v) {
                l.radial2 = f32::INFINITY;
            }
        }
        l
    }
}

/// [`DiscPack`]'s lanes with each lane's clip: the disc filter runs on
/// the discs (it passes every lane the whole disc's `intersect` hits,
/// hence every lane the clipped one hits) and `intersect` decides.
#[derive(Clone, Copy, Debug)]
pub struct ClippedPack {
    discs: DiscPack,
    clips: [Clip; simd::LANES],
}

impl Pack<ClippedDisc> for ClippedPack {
    const LANES: usize = <DiscPack as Pack<Disc>>::LANES;
    const EMPTY: ClippedPack = ClippedPack {
        discs: <DiscPack as Pack<Disc>>::EMPTY,
        clips: [Clip::NONE; simd::LANES],
    };

    fn set(&mut self, lane: usize, p: &ClippedDisc) {
        self.discs.set(lane, &p.disc);
        self.clips[lane] = p.clip;
    }

    #[inline]
    fn get(&self, lane: usize) -> ClippedDisc {
        ClippedDisc {
            disc: self.discs.get(lane),
            clip: self.clips[lane],
        }
    }

    #[inline]
    fn may_hit(&self, ray: &PackRay) -> u32 {
        self.discs.may_hit(ray)
    }

    /// [`DiscPack`]'s masks on the path `isa`: one call of
    /// [`simd::disc_masks`] over the packs' discs, read in place.
    #[inline]
    fn masks(packs: &[Self], ray: &PackRay, isa: simd::Isa, out: &mut [u32]) {
        super::disc::pack_masks(packs, ray, isa, out);
    }

    /// [`DiscPack`]'s per-ray masks on the path `isa`:
    /// [`simd::disc_masks_rays`] over the packs' discs in one call.
    #[inline]
    fn masks_rays(
        packs: &[Self],
        rays: &PackRays,
        active: u32,
        isa: simd::Isa,
        out: &mut [[u32; simd::RAYS]],
        any: &mut [u32],
    ) {
        super::disc::pack_masks_rays(packs, rays, active, isa, out, any);
    }
}

impl AsRef<DiscPack> for ClippedPack {
    fn as_ref(&self) -> &DiscPack {
        &self.discs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::primitive::clip::ClipLine;
    use crate::splat::Splat;

    /// The line `a u + b v <= d`.
    fn line(a: f32, b: f32, d: f32) -> ClipLine {
        ClipLine { a, b, d }
    }

    fn clipped(clip: Clip) -> ClippedDisc {
        let s = Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap();
        ClippedDisc {
            disc: s.disc_geometry(),
            clip,
        }
    }

    #[test]
    fn the_clipped_away_part_is_missed_and_the_rest_is_the_disc_bit_for_bit() {
        let s = Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap();
        // Keep u <= 0.25 (u along the splat's own u axis).
        let c = clipped(Clip::one(line(1.0, 0.0, 0.25)));
        let mut kept = 0;
        let mut cut = 0;
        for i in 0..41 {
            for j in 0..41 {
                let (x, y) = (i as f32 / 20.0 - 1.0, j as f32 / 20.0 - 1.0);
                let p = s.u_axis * x + s.v_axis * y;
                let ray = Ray::new(p + Vec3::new(0.1, -0.2, 3.0), -Vec3::new(0.1, -0.2, 3.0));
                let whole = c.disc.intersect(&ray, 0.0, f32::INFINITY);
                let part = c.intersect(&ray, 0.0, f32::INFINITY);
                match (whole, part) {
                    (Some(w), Some(h)) => {
                        assert_eq!(w, h);
                        assert!(h.u <= 0.25);
                        kept += 1;
                    }
                    (Some(w), None) => {
                        assert!(w.u > 0.25);
                        cut += 1;
                    }
                    (None, None) => {}
                    (None, Some(_)) => panic!("a clipped disc hit outside its disc"),
                }
            }
        }
        assert!(kept > 500 && cut > 200, "{kept} kept, {cut} cut");
    }

    #[test]
    fn pack_lanes_round_trip_and_filter_conservatively() {
        let c = clipped(Clip::two(line(0.6, -0.8, -0.1), line(-1.0, 0.0, 0.5)));
        let pack = ClippedPack::from_fn(|l| (l % 3 == 0).then_some(c));
        for l in 0..ClippedPack::LANES {
            if l % 3 == 0 {
                assert_eq!(pack.get(l), c);
            }
        }
        let ray = Ray::new(Vec3::new(0.0, 0.0, 2.0), -Vec3::Z);
        let m = pack.may_hit(&PackRay::new(&ray, 0.0, f32::INFINITY));
        assert_eq!(m, 0b100_1001 & ((1 << ClippedPack::LANES) - 1));
    }

    #[test]
    fn locate_puts_the_clipped_away_side_out_of_reach() {
        let s = Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap();
        let c = clipped(Clip::one(line(1.0, 0.0, 0.0)));
        let kept = c.locate(s.u_axis * -0.3);
        assert_eq!(kept, c.disc.locate(s.u_axis * -0.3));
        assert!(c.locate(s.u_axis * 0.3).radial2.is_infinite());
    }
}
