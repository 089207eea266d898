//! The disc filter with its per-lane answers kept ([`disc_hits_met`]):
//! the masks of [`super::disc_masks_met`] and, for every lane, the plane
//! parameter `t` and the normalised coordinates `(u, v)` of the hit point,
//! the very operations of [`crate::primitive::Disc`]'s intersection (eq.
//! (1)'s plane, then §2.1's disc coordinates) in its order, so a closest-hit
//! traversal decides a lane the filter passed from these bits instead of
//! running the exact test again (issue 55, thirty-first session).

use super::{CENTER, DiscColumns, Isa, LANES, NORMAL, RIM, U_SCALED, V_SCALED};
use std::mem::MaybeUninit;

/// Packs a [`LaneHits`] holds: a leaf's filter call
/// (`crate::accel::octree`'s chunk of packs).
pub const HITS_PACKS: usize = 16;

/// The memory of [`LaneHits`]' slots, one `(t, u, v)` column triple a
/// pack, never zeroed (a leaf's call fills a few of sixteen): declared by
/// the caller apart from the record of which are written, since the two in
/// one value were zeroed whole (1.5 kB a leaf, 118 instructions a random
/// box ray; `docs/notes/backends.md`, "Issue 55, thirty-first session").
pub struct HitSlots([MaybeUninit<[[f32; LANES]; 3]>; HITS_PACKS]);

impl Default for HitSlots {
    fn default() -> Self {
        Self::new()
    }
}

impl HitSlots {
    /// Slots with nothing in them.
    #[inline(always)]
    #[must_use]
    pub fn new() -> HitSlots {
        HitSlots([MaybeUninit::uninit(); HITS_PACKS])
    }
}

/// `(t, u, v)` of every lane of up to [`HITS_PACKS`] packs, written by
/// [`disc_hits_met`] into its [`HitSlots`] for the packs it filtered.
pub struct LaneHits<'a> {
    slots: &'a mut HitSlots,
    /// Bit `j` set once slot `j` is written.
    written: u32,
}

impl<'a> LaneHits<'a> {
    /// No slot written yet, in `slots`.
    #[inline(always)]
    #[must_use]
    pub fn new(slots: &'a mut HitSlots) -> LaneHits<'a> {
        LaneHits { slots, written: 0 }
    }

    /// Slot `j`'s columns.
    #[inline(always)]
    fn set(&mut self, j: usize, tuv: [[f32; LANES]; 3]) {
        self.slots.0[j].write(tuv);
        self.written |= 1 << j;
    }

    /// `(t, u, v)` of lane `lane` of pack `j`.
    ///
    /// Panics if pack `j` was not filtered into these slots.
    #[inline(always)]
    #[must_use]
    pub fn get(&self, j: usize, lane: usize) -> (f32, f32, f32) {
        assert!(self.written >> j & 1 != 0, "pack {j} was not filtered");
        // SAFETY: bit `j` of `written` is set only by `set(j, ..)`, which
        // wrote slot `j` whole, and `slots` is borrowed for our lifetime.
        let c = unsafe { self.slots.0[j].assume_init_ref() };
        (c[0][lane], c[1][lane], c[2][lane])
    }
}

/// [`super::disc_masks_met`] of the packs `packs[j]` for each bit `j` of
/// `met` (below [`HITS_PACKS`]) into `out[j]`, the same masks, and each
/// such pack's `(t, u, v)` into `hits` slot `j`: lane by lane the values
/// [`crate::primitive::Disc::intersect`] computes (`t = -n·(o - c) / n·d`,
/// then `u`, `v` of `(o - c) + d t` in the scaled axes; glam's dots added
/// left to right, no fused operations), on every path. A lane set in the
/// mask has `t` finite in `[t_min, t_max]` and `u² + v²` within the
/// relaxed rim; `intersect` with a nearer end `cut` hits it exactly when
/// `t <= cut` and `u * u + v * v <= 1`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn disc_hits_met<C: AsRef<DiscColumns>>(
    packs: &[C],
    met: u32,
    origin: [f32; 3],
    dir: [f32; 3],
    (t_min, t_max): (f32, f32),
    isa: Isa,
    out: &mut [u32],
    hits: &mut LaneHits<'_>,
) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { x86::avx2_hits_met(packs, met, origin, dir, (t_min, t_max), out, hits) }
        }
        _ => {
            let mut m = met;
            while m != 0 {
                let j = m.trailing_zeros() as usize;
                m &= m - 1;
                let (mask, tuv) = portable_hits(packs[j].as_ref(), origin, dir, t_min, t_max);
                out[j] = mask;
                hits.set(j, tuv);
            }
        }
    }
}

/// The portable filter (`super::portable_mask`'s operations, two halves
/// of four lanes) with each lane's `(t, u, v)`.
#[inline]
fn portable_hits(
    p: &DiscColumns,
    origin: [f32; 3],
    dir: [f32; 3],
    t_min: f32,
    t_max: f32,
) -> (u32, [[f32; LANES]; 3]) {
    use glam::Vec4;
    let mut tuv = [[0.0f32; LANES]; 3];
    let mut mask = 0;
    for h in 0..2 {
        let col = |k: usize| Vec4::from_slice(&p.cols[k][4 * h..4 * h + 4]);
        let [ox, oy, oz] = origin.map(Vec4::splat);
        let [dx, dy, dz] = dir.map(Vec4::splat);
        let (nx, ny, nz) = (col(NORMAL), col(NORMAL + 1), col(NORMAL + 2));
        let (cx, cy, cz) = (col(CENTER), col(CENTER + 1), col(CENTER + 2));
        let denom = nx * dx + ny * dy + nz * dz;
        let (ocx, ocy, ocz) = (ox - cx, oy - cy, oz - cz);
        let num = nx * ocx + ny * ocy + nz * ocz;
        let t = -num / denom;
        let in_range = (t.cmpge(Vec4::splat(t_min))
            & t.cmple(Vec4::splat(t_max))
            & t.abs().cmplt(Vec4::INFINITY))
        .bitmask();
        let (ux, uy, uz) = (col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2));
        let (vx, vy, vz) = (col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2));
        let (px, py, pz) = (ocx + dx * t, ocy + dy * t, ocz + dz * t);
        let u = px * ux + py * uy + pz * uz;
        let v = px * vx + py * vy + pz * vz;
        let r2 = u * u + v * v;
        mask |= (r2.cmple(Vec4::splat(RIM)).bitmask() & in_range) << (4 * h);
        for (c, x) in tuv.iter_mut().zip([t, u, v]) {
            c[4 * h..4 * h + 4].copy_from_slice(&x.to_array());
        }
    }
    (mask, tuv)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::super::x86::{avx2_dot as dot, avx2_in_range};
    use super::{CENTER, DiscColumns, LANES, LaneHits, NORMAL, RIM, U_SCALED, V_SCALED};
    use std::arch::x86_64::*;

    /// One pack: the mask of `super::super`'s `avx2_mask` and the lanes'
    /// `(t, u, v)`, the same operations (the rim test whatever `t`'s range).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn hit(
        p: &DiscColumns,
        o: [__m256; 3],
        d: [__m256; 3],
        tmin: __m256,
        tmax: __m256,
    ) -> (u32, [[f32; LANES]; 3]) {
        // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
        // (`DiscColumns` is 64-byte aligned, each column 32 bytes).
        let col = |k: usize| unsafe { _mm256_load_ps(p.cols[k].as_ptr()) };
        let n = [col(NORMAL), col(NORMAL + 1), col(NORMAL + 2)];
        let denom = dot(n, d);
        let oc = [
            _mm256_sub_ps(o[0], col(CENTER)),
            _mm256_sub_ps(o[1], col(CENTER + 1)),
            _mm256_sub_ps(o[2], col(CENTER + 2)),
        ];
        let t = _mm256_div_ps(_mm256_xor_ps(dot(n, oc), _mm256_set1_ps(-0.0)), denom);
        let in_range = avx2_in_range(t, tmin, tmax);
        let mut tuv = [[0.0f32; LANES]; 3];
        let store = |c: &mut [f32; LANES], x: __m256| {
            // SAFETY: `c` is 8 f32 (an unaligned store).
            unsafe { _mm256_storeu_ps(c.as_mut_ptr(), x) }
        };
        store(&mut tuv[0], t);
        // No lane in range: the mask is 0 and `u`, `v` are never read.
        if _mm256_movemask_ps(in_range) == 0 {
            return (0, tuv);
        }
        let p3 = [
            _mm256_add_ps(oc[0], _mm256_mul_ps(d[0], t)),
            _mm256_add_ps(oc[1], _mm256_mul_ps(d[1], t)),
            _mm256_add_ps(oc[2], _mm256_mul_ps(d[2], t)),
        ];
        // `p · axis`, `p` on the left as `Disc::intersect`'s `p.dot(axis)`.
        let u = dot(p3, [col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2)]);
        let v = dot(p3, [col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2)]);
        let r2 = _mm256_add_ps(_mm256_mul_ps(u, u), _mm256_mul_ps(v, v));
        let on = _mm256_cmp_ps::<_CMP_LE_OQ>(r2, _mm256_set1_ps(RIM));
        let mask = _mm256_movemask_ps(_mm256_and_ps(on, in_range)) as u32;
        store(&mut tuv[1], u);
        store(&mut tuv[2], v);
        (mask, tuv)
    }

    /// [`super::disc_hits_met`] with one pack per 256-bit register.
    ///
    /// # Safety
    /// The CPU must run AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn avx2_hits_met<C: AsRef<DiscColumns>>(
        packs: &[C],
        mut met: u32,
        origin: [f32; 3],
        dir: [f32; 3],
        (t_min, t_max): (f32, f32),
        out: &mut [u32],
        hits: &mut LaneHits<'_>,
    ) {
        let o = origin.map(|x| _mm256_set1_ps(x));
        let d = dir.map(|x| _mm256_set1_ps(x));
        let (tmin, tmax) = (_mm256_set1_ps(t_min), _mm256_set1_ps(t_max));
        while met != 0 {
            let j = met.trailing_zeros() as usize;
            met &= met - 1;
            let (mask, tuv) = hit(packs[j].as_ref(), o, d, tmin, tmax);
            out[j] = mask;
            hits.set(j, tuv);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{HitSlots, LaneHits, disc_hits_met};
    use crate::primitive::{Disc, DiscPack, Pack, Primitive};
    use crate::rng::SplitMix64;
    use crate::simd::{Isa, disc_masks_met};
    use crate::geometry::Ray;
    use glam::Vec3;

    /// On every path this CPU runs, 2,000 random packs of discs around
    /// the origin and rays through them: the masks are `disc_masks_met`'s
    /// and, for every lane `Disc::intersect` hits within `[0, cut]` (cut
    /// the span's end or a nearer one), the lane is set and its `(t, u, v)`
    /// are the hit's, bit for bit; no lane outside the mask is hit.
    #[test]
    fn lane_hits_are_the_exact_tests_bit_for_bit_on_every_path() {
        let mut slots = HitSlots::new();
        let mut rng = SplitMix64::new(31);
        let mut f = move || rng.next_f32() * 2.0 - 1.0;
        let mut v3 = move |s: f32| Vec3::new(f() * s, f() * s, f() * s);
        let mut hit_lanes = 0;
        let mut lanes = 0;
        for _ in 0..2_000 {
            let discs: Vec<Disc> = (0..8)
                .map(|_| {
                    let n = v3(1.0).normalize_or(Vec3::Z);
                    let (a, b) = n.any_orthonormal_pair();
                    Disc {
                        center: v3(0.5),
                        normal: n,
                        u_scaled: a / (0.1 + 0.4 * v3(1.0).x.abs()),
                        v_scaled: b / (0.1 + 0.4 * v3(1.0).y.abs()),
                    }
                })
                .collect();
            let pack = DiscPack::from_fn(|l| (l < 7).then(|| discs[l]));
            let packs = [pack; 3];
            let ray = Ray::new(v3(2.0), v3(1.0));
            let (t_min, t_max) = (0.0, if v3(1.0).x > 0.0 { f32::INFINITY } else { 3.0 });
            let (o, d) = (ray.origin.to_array(), ray.dir.to_array());
            for isa in Isa::ALL.into_iter().filter(|i| i.supported()) {
                let (mut want, mut got) = ([0u32; 3], [0u32; 3]);
                let mut hits = LaneHits::new(&mut slots);
                disc_masks_met(&packs, 0b101, o, d, t_min, t_max, isa, &mut want);
                disc_hits_met(&packs, 0b101, o, d, (t_min, t_max), isa, &mut got, &mut hits);
                assert_eq!(want, got, "{isa:?}");
                for (l, disc) in discs.iter().enumerate().take(7) {
                    lanes += 1;
                    let cut = if l % 2 == 0 { t_max } else { 1.5 };
                    let exact = disc.intersect(&ray, t_min, cut);
                    let (t, u, v) = hits.get(2, l);
                    let from = (got[2] >> l & 1 != 0 && t <= cut && u * u + v * v <= 1.0)
                        .then_some((t.to_bits(), u.to_bits(), v.to_bits()));
                    let exact = exact.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits()));
                    assert_eq!(from, exact, "{isa:?} lane {l}");
                    hit_lanes += usize::from(exact.is_some());
                }
                assert_eq!(got[2] >> 7, 0, "padding");
            }
        }
        // Rays from within 2 of discs within 0.5 of the origin: about one
        // lane in two hundred hits (measured: 198 of 42,000; printed).
        eprintln!("{hit_lanes} of {lanes} lanes hit");
        assert!(hit_lanes * 250 >= lanes && hit_lanes * 100 <= lanes, "{hit_lanes} of {lanes}");
    }

    #[test]
    #[should_panic(expected = "not filtered")]
    fn an_unfiltered_pack_is_not_read() {
        let _ = LaneHits::new(&mut HitSlots::new()).get(3, 0);
    }
}
