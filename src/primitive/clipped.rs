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

    /// The whole disc's: conservative for the clipped part.
    fn bounding_radius(&self) -> f32 {
        self.disc.bounding_radius()
    }

    /// The whole disc's: conservative for the clipped part.
    fn semi_axes(&self) -> Option<(Vec3, Vec3)> {
        self.disc.semi_axes()
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

/// [`DiscPack`]'s lanes, nothing more: the clip lines live in the
/// structure's [`ClipTable`] (the pack's [`Pack::Side`]), looked up by
/// primitive id for the lanes the disc filter passes. The filter runs on
/// the discs (it passes every lane the whole disc's `intersect` hits,
/// hence every lane the clipped one hits) and `intersect` decides, on the
/// disc and the clip as stored, bit for bit.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct ClippedPack {
    discs: DiscPack,
}

impl Pack<ClippedDisc> for ClippedPack {
    const LANES: usize = <DiscPack as Pack<Disc>>::LANES;
    const EMPTY: ClippedPack = ClippedPack {
        discs: <DiscPack as Pack<Disc>>::EMPTY,
    };
    type Side = ClipTable;

    fn side(prims: &[ClippedDisc]) -> ClipTable {
        ClipTable::new(prims)
    }

    type Prep = ();

    fn prep(_ray: &PackRay) {}

    fn side_bytes(side: &ClipTable) -> usize {
        side.bytes()
    }

    /// The disc alone (its clip is the side table's).
    fn set(&mut self, lane: usize, p: &ClippedDisc) {
        self.discs.set(lane, &p.disc);
    }

    #[inline]
    fn get(&self, lane: usize, id: u32, side: &ClipTable) -> ClippedDisc {
        ClippedDisc {
            disc: self.discs.get(lane, id, &()),
            clip: side.clip(id),
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

    /// [`DiscPack`]'s masks of the met packs in one call.
    #[inline]
    fn masks_met(packs: &[Self], met: u32, ray: &PackRay, (): &(), isa: simd::Isa, out: &mut [u32]) {
        super::disc::pack_masks_met(packs, met, ray, isa, out);
    }

    const LANE_HITS: bool = true;

    /// [`DiscPack`]'s masks and lanes' answers of the met packs in one
    /// call.
    #[inline(always)]
    fn hits_met(
        packs: &[Self],
        met: u32,
        ray: &PackRay,
        (): &(),
        isa: simd::Isa,
        out: &mut [u32],
        hits: &mut simd::LaneHits<'_>,
    ) {
        super::disc::pack_hits_met(packs, met, ray, isa, out, hits);
    }

    /// The disc's hit ([`super::disc::lane_disc_hit`]) kept as
    /// [`ClippedDisc::intersect`] keeps it: on the kept side of the clip
    /// lines of `id` ([`ClipTable::clip`]).
    #[inline(always)]
    fn lane_hit(
        &self,
        _lane: usize,
        id: u32,
        side: &ClipTable,
        _ray: &Ray,
        (_t_min, cut): (f32, f32),
        tuv: (f32, f32, f32),
    ) -> Option<Hit> {
        let hit = super::disc::lane_disc_hit(cut, tuv)?;
        side.clip_ref(id).keeps(hit.u, hit.v).then_some(hit)
    }

    /// [`DiscPack`]'s masks of the packs `packs[at[j]]` in one call.
    #[inline]
    fn masks_at(packs: &[Self], at: &[u32], ray: &PackRay, isa: simd::Isa, out: &mut [u32]) {
        super::disc::pack_masks_at(packs, at, ray, isa, out);
    }

    /// [`DiscPack`]'s per-ray masks of the packs `packs[at[j]]` in one
    /// call.
    #[inline]
    fn masks_rays_at(
        packs: &[Self],
        at: &[u32],
        rays: &PackRays,
        active: u32,
        isa: simd::Isa,
        out: &mut [[u32; simd::RAYS]],
        any: &mut [u32],
    ) {
        super::disc::pack_masks_rays_at(packs, at, rays, active, isa, out, any);
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

/// The clip lines of the clipped splats alone, by primitive id: per 64
/// ids a word with a bit set for each clipped one and the count of
/// clipped ids before the word, and the clipped ones' [`Clip`]s in id
/// order. An id's clip is [`Clip::NONE`] when its bit is clear (one load
/// of a word, 16 bytes per 64 splats), else the entry counted by the bits
/// before it. A structure over [`ClippedDisc`]s with no clipped splat
/// holds nothing at all; with `k` clipped ones, `28 k` bytes and the
/// words, once each, not once per reference as a clip in every lane
/// would be (`docs/DESIGN.md`, "Clipped splats: a second primitive").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClipTable {
    /// Per 64 ids (empty when no splat is clipped).
    words: Vec<ClipWord>,
    /// The clipped splats' clips, in id order.
    clips: Vec<Clip>,
}

/// 64 ids of a [`ClipTable`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct ClipWord {
    /// Bit `i` set when id `64 w + i` is clipped.
    bits: u64,
    /// Clipped ids below `64 w`.
    before: u32,
}

impl ClipTable {
    /// The table of `prims` (primitive `i` has id `i`).
    ///
    /// Panics if `prims` holds 2^32 or more primitives.
    #[must_use]
    pub fn new(prims: &[ClippedDisc]) -> ClipTable {
        assert!(u32::try_from(prims.len()).is_ok(), "at most 2^32 - 1 ids");
        let clips: Vec<Clip> = prims
            .iter()
            .filter(|p| !p.clip.is_none())
            .map(|p| p.clip)
            .collect();
        if clips.is_empty() {
            return ClipTable::default();
        }
        let mut before = 0u32;
        let words = prims
            .chunks(64)
            .map(|chunk| {
                let bits = chunk
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| !p.clip.is_none())
                    .fold(0u64, |b, (i, _)| b | 1 << i);
                let w = ClipWord { bits, before };
                before += bits.count_ones();
                w
            })
            .collect();
        ClipTable { words, clips }
    }

    /// The clip of primitive `id` ([`Clip::NONE`] when it is not clipped,
    /// or beyond the table).
    #[inline]
    #[must_use]
    pub fn clip(&self, id: u32) -> Clip {
        *self.clip_ref(id)
    }

    /// Where [`ClipTable::clip`] reads the clip of `id`: the table's entry
    /// or a static [`Clip::NONE`]. One copy from memory whichever it is
    /// (returning the two values from two branches had the compiler merge
    /// them through overlapping stack stores, which stalled the leaf's
    /// exact test on reloading them; `docs/notes/backends.md`, "Issue 55,
    /// ninth session").
    #[inline]
    fn clip_ref(&self, id: u32) -> &Clip {
        static NONE: Clip = Clip::NONE;
        let Some(w) = self.words.get((id >> 6) as usize) else {
            return &NONE;
        };
        let bit = 1u64 << (id & 63);
        if w.bits & bit == 0 {
            return &NONE;
        }
        let k = w.before as usize + (w.bits & (bit - 1)).count_ones() as usize;
        &self.clips[k]
    }

    /// The clipped splats it holds.
    #[must_use]
    pub fn clipped(&self) -> usize {
        self.clips.len()
    }

    /// Bytes held.
    #[must_use]
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.words.as_slice()) + std::mem::size_of_val(self.clips.as_slice())
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
        // Ids 0..LANES, the clipped ones in the side table.
        let prims: Vec<ClippedDisc> = (0..ClippedPack::LANES)
            .map(|l| if l % 3 == 0 { c } else { clipped(Clip::NONE) })
            .collect();
        let side = ClippedPack::side(&prims);
        for l in 0..ClippedPack::LANES {
            if l % 3 == 0 {
                assert_eq!(pack.get(l, l as u32, &side), c);
            }
        }
        assert_eq!(
            std::mem::size_of::<ClippedPack>(),
            std::mem::size_of::<DiscPack>(),
            "a lane holds a disc, no clip"
        );
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

    #[test]
    fn the_table_holds_the_clipped_alone_and_gives_every_id_its_clip() {
        let edge = Clip::one(line(1.0, 0.0, 0.25));
        let corner = Clip::two(line(0.6, -0.8, -0.1), line(-1.0, 0.0, 0.5));
        // Ids across word boundaries: 0, 63, 64, 130 and the last clipped.
        let n = 200;
        let want = |i: usize| match i {
            0 | 64 | 199 => edge,
            63 | 130 => corner,
            _ => Clip::NONE,
        };
        let prims: Vec<ClippedDisc> = (0..n).map(|i| clipped(want(i))).collect();
        let t = ClipTable::new(&prims);
        assert_eq!(t.clipped(), 5);
        for i in 0..n {
            assert_eq!(t.clip(i as u32), want(i), "id {i}");
        }
        assert_eq!(t.clip(n as u32 + 100), Clip::NONE);
        assert_eq!(t.clip(u32::MAX), Clip::NONE);
        // 5 clips and 4 words of 64 ids.
        assert_eq!(
            t.bytes(),
            5 * std::mem::size_of::<Clip>() + 4 * std::mem::size_of::<ClipWord>()
        );
        // No clipped splat: nothing held.
        let whole: Vec<ClippedDisc> = (0..n).map(|_| clipped(Clip::NONE)).collect();
        let t = ClipTable::new(&whole);
        assert_eq!(t.bytes(), 0);
        assert!((0..n as u32).all(|i| t.clip(i) == Clip::NONE));
    }
}
