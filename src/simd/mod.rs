//! Wide SIMD kernels chosen at run time: the one module besides `embree`
//! that holds `unsafe` code (`docs/DESIGN.md`, "Wide SIMD").
//!
//! The binary is built for baseline x86-64 (SSE2), so it runs on any x86-64
//! machine; the octree's hottest loop, the disc filter of a leaf
//! ([`crate::primitive::DiscPack`], eq. (1)'s plane and the disc test of
//! §2.1), also exists compiled for AVX2 (8 discs at once) and AVX-512
//! (16 at once), each behind `#[target_feature]` and entered only once
//! [`Isa::supported`] has seen the CPU run it. Every path does the same IEEE
//! operations per lane in the same order (no fused multiply-add), so every
//! path passes exactly the lanes the portable one does and the candidates
//! stay bit-identical (the conformance suite builds the octree on every
//! path this CPU runs and compares). The face search's count of the points
//! near a plane ([`count_within`], the normals stage's hottest loop) is
//! dispatched the same way, and counts the same points on every path; so
//! are the sets of the points its refitted planes hold ([`held_within`]),
//! the same bits; so
//! are the normal equations of generation's quadric fits
//! ([`normal_equations6`]), the same sums bit for bit, and the scan of
//! the neighbour search's bounded queries ([`keys_within`]), the same
//! points, and the sorts of its neighbourhoods' keys ([`sort_keys`]), the
//! same order; so are the cells of a camera's fan that its rays fall in
//! ([`gnomonic_keys`]), the same keys.
//!
//! The path is AVX2 where the CPU runs it ([`default_path`] says why not
//! AVX-512), or the one named by [`SIMD_VAR`] (`portable`, `avx2`,
//! `avx512`), read once with the rest of the process's configuration by
//! `crate::config` (this module reads no environment); an octree can also
//! be built
//! for a given path ([`crate::accel::octree::OctreeParams::simd`]), which is
//! how the registry's `octree-<path>` variants force each one.

mod count;
mod fan;
mod hits;
mod lsq;
mod near;
mod rows;
mod sort;
mod tri;
mod triples;
pub use count::{count_within, held_within};
pub use fan::{FanBits, GnomonicGrid, KEY_ELSEWHERE, KEY_MISS, NO_CELL, gnomonic_cell, gnomonic_key, gnomonic_keys};
pub use hits::{HITS_PACKS, HitSlots, LaneHits, disc_hits_met};
pub use lsq::{Row6, normal_equations6};
pub use near::keys_within;
pub use rows::{RowNumber, ray_from_row, rays_from_f32_rows, rays_from_rows, rows_as_rays};
pub use sort::{SORT_NETWORK_MAX, SORT_NETWORK_MIN, same_network, sort_keys};
pub use triples::triple_normals;
pub use tri::{SURE, Shear, TRI_LANES, TriColumns, tri_masks, tri_masks_sheared};

/// The sides of 8 points `(xs[i], ys[i])` of a line `a·x + b·y = d`: bit
/// `i` set where `a·x + b·y − d ≤ 0` (not a number: not set). The same
/// products, sum and difference per lane, in the same order, as the scalar
/// `a * x + b * y - d` (no fused multiply-add), so the same bits and
/// sides; baseline x86-64 (SSE) compares the 8 lanes and takes their
/// signs in two instructions each, which the compiler did not find
/// (`crate::splat::rim`'s clipped areas).
#[inline(always)]
pub fn side_mask8(xs: &[f32; 8], ys: &[f32; 8], (a, b, d): (f32, f32, f32)) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{
            _mm_add_ps, _mm_cmple_ps, _mm_loadu_ps, _mm_movemask_ps, _mm_mul_ps, _mm_set1_ps,
            _mm_setzero_ps, _mm_sub_ps,
        };
        // SAFETY: unaligned loads of 4 floats at offsets 0 and 4 of two
        // 8-float arrays, within the references' own memory; SSE is part
        // of baseline x86-64.
        unsafe {
            let (va, vb, vd) = (_mm_set1_ps(a), _mm_set1_ps(b), _mm_set1_ps(d));
            let side = |k: usize| {
                let x = _mm_loadu_ps(xs.as_ptr().add(k));
                let y = _mm_loadu_ps(ys.as_ptr().add(k));
                let f = _mm_sub_ps(_mm_add_ps(_mm_mul_ps(va, x), _mm_mul_ps(vb, y)), vd);
                _mm_movemask_ps(_mm_cmple_ps(f, _mm_setzero_ps())) as u32
            };
            side(0) | (side(4) << 4)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        (0..8)
            .map(|i| u32::from(a * xs[i] + b * ys[i] - d <= 0.0) << i)
            .sum()
    }
}

/// Asks the CPU to bring the cache lines `x` lies in (up to its first 192
/// bytes, and its last byte's) into the caches, without waiting for them:
/// a hint that changes no value, for records a loop will read soon after
/// at scattered places (the resolver's splats of a window,
/// `crate::resolve::resolve_models`). Baseline x86-64 (SSE) has the
/// instruction; elsewhere this does nothing.
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = std::ptr::from_ref(x).cast::<i8>();
        let size = std::mem::size_of::<T>();
        // SAFETY: a prefetch reads nothing into the program and never
        // faults, even at an address outside any mapping; `p` comes from
        // a reference, and `wrapping_add` keeps the offsets (all within
        // `x`) defined pointer arithmetic.
        unsafe {
            let mut at = 0;
            while at < size.min(192) {
                _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(at));
                at += 64;
            }
            if size > 0 {
                _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(size - 1));
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// A piece of work [`vex`] runs: `run` must be `#[inline(always)]`, so
/// that it is compiled into each path's function (a closure is not
/// inlined into a larger function and would keep the baseline's code).
pub trait Kernel {
    /// What the work answers.
    type Out;
    /// Does the work.
    fn run(self) -> Self::Out;
}

/// `k.run()`, compiled for AVX (three-operand VEX forms, no fused
/// multiply-add: the `fma` feature is not enabled) where `isa` is a wide
/// path the CPU runs, else as built (baseline SSE2). The same IEEE
/// operations in the same order on either path, so the same bits: only
/// their encoding, register copies and spills differ. For 4-wide glam
/// code whose two-operand SSE2 form spends a third of its instructions on
/// copies and spills (the resolver's four-wide silhouette test,
/// `crate::resolve`; issue 55, thirty-third session). One call's worth of
/// work (a window), not a short one called in a loop: the AVX path is a
/// call.
#[inline(always)]
pub fn vex<K: Kernel>(isa: Isa, k: K) -> K::Out {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2, so AVX.
            unsafe { on_avx(k) }
        }
        _ => as_built(k),
    }
}

/// [`vex`]'s baseline path, a function of its own so that the dispatch
/// around it stays a few instructions (inlined, its frame and saved
/// registers were paid on the AVX path too).
#[inline(never)]
fn as_built<K: Kernel>(k: K) -> K::Out {
    k.run()
}

/// [`vex`]'s AVX path: `k.run()` inlined and compiled with AVX enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn on_avx<K: Kernel>(k: K) -> K::Out {
    k.run()
}

/// The environment variable that forces a path for the whole process
/// (read by `crate::config`).
pub const SIMD_VAR: &str = "SPLATRAY_SIMD";

/// Lanes of one disc pack: eight `f32` per column.
pub const LANES: usize = 8;

/// A set of kernels, from narrowest to widest.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// Baseline: SSE2 on x86-64 (through glam's 4-lane vectors), whatever
    /// the target has elsewhere (NEON on aarch64, or scalar code).
    Portable,
    /// AVX2: a pack's eight lanes in one 256-bit register.
    Avx2,
    /// AVX-512 (F): two packs, sixteen lanes, in one 512-bit register.
    Avx512,
}

impl Isa {
    /// Every path, narrowest first.
    pub const ALL: [Isa; 3] = [Isa::Portable, Isa::Avx2, Isa::Avx512];

    /// The name [`SIMD_VAR`] and reports use.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }

    /// The path called `name`.
    #[must_use]
    pub fn parse(name: &str) -> Option<Isa> {
        Isa::ALL.into_iter().find(|i| i.name() == name)
    }

    /// True when this CPU runs the path.
    #[must_use]
    pub fn supported(self) -> bool {
        match self {
            Isa::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => std::arch::is_x86_feature_detected!("avx2"),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(not(target_arch = "x86_64"))]
            Isa::Avx2 | Isa::Avx512 => false,
        }
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The paths this CPU runs, narrowest first.
#[must_use]
pub fn available() -> Vec<Isa> {
    Isa::ALL.into_iter().filter(|i| i.supported()).collect()
}

/// The path taken when [`SIMD_VAR`] is unset: AVX2 where the CPU runs it,
/// else the portable one. AVX-512 is only taken when asked for: on the
/// AVX-512 Xeon this was measured on, pairing two packs in a 512-bit
/// register was slower than AVX2 (the accel benchmark at 35k splats,
/// primary / shadow rays against Embree: AVX2 1.011 / 1.071, AVX-512
/// 0.871 / 0.882, portable 0.936 / 0.891; `docs/notes/README.md`).
#[must_use]
pub fn default_path() -> Isa {
    if Isa::Avx2.supported() {
        Isa::Avx2
    } else {
        Isa::Portable
    }
}

/// Eight discs stored column by column: centre, normal, `u / r_u`,
/// `v / r_v`, each as x, y, z columns of [`LANES`] lanes (32-byte aligned,
/// so a column is one aligned AVX load). Padding lanes have a zero normal.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct DiscColumns {
    /// Columns 0-2 centre, 3-5 normal, 6-8 `u_scaled`, 9-11 `v_scaled`.
    pub cols: [[f32; LANES]; 12],
}

impl AsRef<DiscColumns> for DiscColumns {
    fn as_ref(&self) -> &DiscColumns {
        self
    }
}

/// Column indices in [`DiscColumns::cols`].
pub const CENTER: usize = 0;
/// First normal column.
pub const NORMAL: usize = 3;
/// First `u_scaled` column.
pub const U_SCALED: usize = 6;
/// First `v_scaled` column.
pub const V_SCALED: usize = 9;

/// The rim test's bound, relaxed by `1e-4`: the filter is conservative,
/// each lane it passes is decided by the exact disc test.
const RIM: f32 = 1.0001;

/// Bit `l` of `out[i]` set when lane `l` of `packs[i]` may be hit in
/// `[t_min, t_max]` by the ray (`origin`, `dir`), with the path `isa`: the
/// operations of [`crate::primitive::Disc`]'s intersection per lane (plane
/// parameter `t = -n·(o - c) / n·d`, then `(u, v)` of the hit point),
/// the rim relaxed by `1e-4`. `out` must be at least as long as `packs`.
/// A path the CPU does not run is replaced by the portable one.
#[inline]
pub fn disc_masks<C: AsRef<DiscColumns>>(
    packs: &[C],
    origin: [f32; 3],
    dir: [f32; 3],
    t_min: f32,
    t_max: f32,
    isa: Isa,
    out: &mut [u32],
) {
    let out = &mut out[..packs.len()];
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { x86::avx2_masks(packs, origin, dir, t_min, t_max, out) }
        }
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 if Isa::Avx512.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX-512 F.
            unsafe { x86::avx512_masks(packs, origin, dir, t_min, t_max, out) }
        }
        _ => {
            for (p, m) in packs.iter().zip(out.iter_mut()) {
                *m = portable_mask(p.as_ref(), origin, dir, t_min, t_max);
            }
        }
    }
}

/// [`disc_masks`] of the packs `packs[j]` for each bit `j` set in `met`
/// into `out[j]`, the other slots of `out` left as they are: each the mask
/// [`disc_masks`] gives the pack (a leaf's packs whose box the ray meets,
/// `crate::accel::octree`). `packs` and `out` must reach the highest bit.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn disc_masks_met<C: AsRef<DiscColumns>>(
    packs: &[C],
    met: u32,
    origin: [f32; 3],
    dir: [f32; 3],
    t_min: f32,
    t_max: f32,
    isa: Isa,
    out: &mut [u32],
) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { x86::avx2_masks_met(packs, met, origin, dir, (t_min, t_max), out) }
        }
        _ => {
            let mut m = met;
            while m != 0 {
                let j = m.trailing_zeros() as usize;
                m &= m - 1;
                disc_masks(&packs[j..=j], origin, dir, t_min, t_max, isa, &mut out[j..=j]);
            }
        }
    }
}

/// Rays per call of [`disc_masks_rays`] (a packet, `crate::accel::PACKET`).
pub const RAYS: usize = 8;

/// A cone from the rays' shared origin holding every ray's half-line
/// (`t >= 0`): unit `axis`, and the cosine and sine of a half-angle a
/// little wider than the widest ray's, below 90°.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    /// Unit axis.
    pub axis: [f32; 3],
    /// Cosine of the half-angle.
    pub cos: f32,
    /// Sine of the half-angle.
    pub sin: f32,
}

/// Relative slack of [`Cone`]'s lane test: a lane is dropped only when
/// its disc lies farther from the cone than its largest radius plus this
/// fraction of `|c - o|_1 + r`; rounding in the test, in the cone and in
/// [`crate::primitive::Disc`]'s own hit point is below `1e-6` of that.
const CONE_SLACK: f32 = 1e-5;

impl Cone {
    /// The cone around the directions `dirs` (per axis, one lane per ray;
    /// repeat a ray to fill the lanes), or `None` when it would be 60°
    /// wide or more (too wide to drop anything) or a direction is not
    /// finite and non-zero.
    #[must_use]
    pub fn around(dirs: &[[f32; RAYS]; 3]) -> Option<Cone> {
        use glam::{Vec3, Vec4};
        let half = |a: usize, h: usize| Vec4::from_slice(&dirs[a][4 * h..4 * h + 4]);
        let [x, y, z] = [0, 1, 2].map(|a| [half(a, 0), half(a, 1)]);
        let len2 = [0, 1].map(|h| x[h] * x[h] + y[h] * y[h] + z[h] * z[h]);
        // NaN compares false; a finite square means finite components.
        let ok = |v: Vec4| (v.cmpgt(Vec4::ZERO) & v.cmplt(Vec4::INFINITY)).all();
        if !(ok(len2[0]) && ok(len2[1])) {
            return None;
        }
        let sum = |v: [Vec4; 2]| (v[0] + v[1]).element_sum();
        let axis = Vec3::new(sum(x), sum(y), sum(z)).normalize_or_zero();
        // The narrowest cosine (by its square, from the dot products), then
        // a little less: the cosines are off by a few ulps, the margin
        // holds each ray strictly inside.
        let [ax, ay, az] = axis.to_array().map(Vec4::splat);
        let dot = [0, 1].map(|h| x[h] * ax + y[h] * ay + z[h] * az);
        if !(dot[0].cmpgt(Vec4::ZERO).all() && dot[1].cmpgt(Vec4::ZERO).all()) {
            return None;
        }
        let cos2 = (dot[0] * dot[0] / len2[0]).min(dot[1] * dot[1] / len2[1]);
        let cos = cos2.min_element().min(1.0).sqrt() - 1e-6;
        if cos.is_nan() || cos < 0.5 {
            return None;
        }
        Some(Cone {
            axis: axis.to_array(),
            cos,
            sin: (1.0 - cos * cos).max(0.0).sqrt(),
        })
    }
}

/// Bit `l` of `out[j][k]`, for each ray `k` set in `active`, set when lane
/// `l` of `packs[j]` may be hit in `[t_min[k], t_max[k]]` by the ray
/// (`origin`, `dirs[k]`), for rays sharing one origin (issue 25: a shadow
/// batch leaves one hit, primary rays one eye), on the path `isa`; bit `k`
/// of `rays[j]` set when `out[j][k]` is not zero (the rays a pack passes
/// a lane to). Each pack is read once for all the rays, and what depends
/// only on the origin (`o - c`, `n·(o - c)` of eq. (1)'s plane parameter)
/// is computed once, with the same IEEE operations as for one ray, so each
/// ray's lanes are those of [`disc_masks`] for it; with a `cone` holding
/// every ray, first the lanes whose disc lies farther from the cone than
/// its largest radius (plus [`CONE_SLACK`]) are dropped for all the rays
/// at once, and the rays are tested only when a lane is left: no ray of
/// the cone can hit such a disc, so a lane is still passed whenever
/// [`crate::primitive::Disc::intersect`] hits it. `out[j][k]` of a ray not
/// in `active` is 0. `out` and `rays` must be at least as long as `packs`.
/// AVX-512 runs the AVX2 kernel (one pack fills a 256-bit register); a
/// path the CPU does not run is replaced by the portable one, which gives
/// the same lanes.
// The packet's fields as the kernels take them.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn disc_masks_rays<C: AsRef<DiscColumns>>(
    packs: &[C],
    origin: [f32; 3],
    dirs: &[[f32; 3]; RAYS],
    t_min: &[f32; RAYS],
    t_max: &[f32; RAYS],
    cone: Option<&Cone>,
    active: u32,
    isa: Isa,
    out: &mut [[u32; RAYS]],
    rays: &mut [u32],
) {
    let active = active & ((1 << RAYS) - 1);
    let out = &mut out[..packs.len()];
    let rays = &mut rays[..packs.len()];
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe {
                x86::avx2_masks_rays(packs, origin, dirs, t_min, t_max, cone, active, out, rays);
            }
        }
        _ => {
            for ((pack, out), any) in packs.iter().zip(out.iter_mut()).zip(rays.iter_mut()) {
                let pack = pack.as_ref();
                let near = cone.map_or(u32::MAX, |c| portable_cone(pack, origin, c));
                *out = [0; RAYS];
                *any = 0;
                if near == 0 {
                    continue;
                }
                let mut left = active;
                while left != 0 {
                    let k = left.trailing_zeros() as usize;
                    left &= left - 1;
                    out[k] = portable_mask(pack, origin, dirs[k], t_min[k], t_max[k]) & near;
                    *any |= u32::from(out[k] != 0) << k;
                }
            }
        }
    }
}

/// The lanes of `p` not dropped by the cone test of [`disc_masks_rays`]:
/// with `w = c - o`, `h = |w × a|` and `s = w·a`, `h cos - s sin` is at
/// most the distance from the centre to the cone (that of the half-space
/// bounding the cone along the generator nearest `c`), and a disc hit by a
/// ray of the cone has its centre within its largest radius
/// `r = 1 / min(|u_scaled|, |v_scaled|)` of the hit; a lane is dropped
/// when `h cos - s sin > r + slack` (NaN: kept).
#[inline]
fn portable_cone(p: &DiscColumns, origin: [f32; 3], cone: &Cone) -> u32 {
    use glam::Vec4;
    let half = |h: usize| {
        let col = |k: usize| Vec4::from_slice(&p.cols[k][4 * h..4 * h + 4]);
        let [ax, ay, az] = cone.axis.map(Vec4::splat);
        let wx = col(CENTER) - Vec4::splat(origin[0]);
        let wy = col(CENTER + 1) - Vec4::splat(origin[1]);
        let wz = col(CENTER + 2) - Vec4::splat(origin[2]);
        let (qx, qy, qz) = (wy * az - wz * ay, wz * ax - wx * az, wx * ay - wy * ax);
        let h = (qx * qx + qy * qy + qz * qz).sqrt();
        let s = wx * ax + wy * ay + wz * az;
        let dist = h * Vec4::splat(cone.cos) - s * Vec4::splat(cone.sin);
        let sq = |x: Vec4, y: Vec4, z: Vec4| x * x + y * y + z * z;
        let us = sq(col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2));
        let vs = sq(col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2));
        let r = Vec4::ONE / us.min(vs).sqrt();
        let l1 = wx.abs() + wy.abs() + wz.abs();
        let bound = r + (l1 + r) * Vec4::splat(CONE_SLACK);
        // Kept unless `dist > bound` (false on NaN).
        !dist.cmpgt(bound).bitmask() & 0xf
    };
    half(0) | half(1) << 4
}

/// The portable filter: the pack as two halves of four lanes (glam's
/// `Vec4`, SSE2 on x86-64).
#[inline]
fn portable_mask(p: &DiscColumns, origin: [f32; 3], dir: [f32; 3], t_min: f32, t_max: f32) -> u32 {
    use glam::Vec4;
    let half = |h: usize| {
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
        if in_range == 0 {
            return 0;
        }
        let (ux, uy, uz) = (col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2));
        let (vx, vy, vz) = (col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2));
        let (px, py, pz) = (ocx + dx * t, ocy + dy * t, ocz + dz * t);
        let u = px * ux + py * uy + pz * uz;
        let v = px * vx + py * vy + pz * vz;
        let r2 = u * u + v * v;
        r2.cmple(Vec4::splat(RIM)).bitmask() & in_range
    };
    half(0) | half(1) << 4
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{CENTER, CONE_SLACK, Cone, DiscColumns, NORMAL, RAYS, RIM, U_SCALED, V_SCALED};
    use std::arch::x86_64::*;

    /// `a · b` lane by lane, `(a_x b_x + a_y b_y) + a_z b_z` as the portable
    /// filter adds.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn avx2_dot(a: [__m256; 3], b: [__m256; 3]) -> __m256 {
        _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])),
            _mm256_mul_ps(a[2], b[2]),
        )
    }

    /// The lanes whose plane parameter `t` is finite and within
    /// `[t_min, t_max]` (all ones), as the portable filter's `in_range`.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn avx2_in_range(t: __m256, t_min: __m256, t_max: __m256) -> __m256 {
        let sign = _mm256_set1_ps(-0.0);
        _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(t, t_min),
                _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max),
            ),
            _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_andnot_ps(sign, t), _mm256_set1_ps(f32::INFINITY)),
        )
    }

    /// `u² + v²` of the points `(o - c) + d t` in each disc's scaled axes
    /// (the rim test of the disc filter), the operations in the portable
    /// filter's order.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn avx2_rim2(p: &DiscColumns, oc: [__m256; 3], d: [__m256; 3], t: __m256) -> __m256 {
        // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
        // (`DiscColumns` is 64-byte aligned, each column 32 bytes).
        let col = |k: usize| unsafe { _mm256_load_ps(p.cols[k].as_ptr()) };
        let (ux, uy, uz) = (col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2));
        let (vx, vy, vz) = (col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2));
        let px = _mm256_add_ps(oc[0], _mm256_mul_ps(d[0], t));
        let py = _mm256_add_ps(oc[1], _mm256_mul_ps(d[1], t));
        let pz = _mm256_add_ps(oc[2], _mm256_mul_ps(d[2], t));
        let u = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(px, ux), _mm256_mul_ps(py, uy)),
            _mm256_mul_ps(pz, uz),
        );
        let v = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(px, vx), _mm256_mul_ps(py, vy)),
            _mm256_mul_ps(pz, vz),
        );
        _mm256_add_ps(_mm256_mul_ps(u, u), _mm256_mul_ps(v, v))
    }

    /// One pack's mask of [`super::disc_masks`] (the ray's origin, direction
    /// and span broadcast): the pack in one 256-bit register.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn avx2_mask(p: &DiscColumns, o: [__m256; 3], d: [__m256; 3], tmin: __m256, tmax: __m256) -> u32 {
        // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
        // (`DiscColumns` is 64-byte aligned, each column 32 bytes).
        let col = |k: usize| unsafe { _mm256_load_ps(p.cols[k].as_ptr()) };
        let (nx, ny, nz) = (col(NORMAL), col(NORMAL + 1), col(NORMAL + 2));
        let (cx, cy, cz) = (col(CENTER), col(CENTER + 1), col(CENTER + 2));
        let denom = avx2_dot([nx, ny, nz], d);
        let (ocx, ocy, ocz) = (
            _mm256_sub_ps(o[0], cx),
            _mm256_sub_ps(o[1], cy),
            _mm256_sub_ps(o[2], cz),
        );
        let num = avx2_dot([nx, ny, nz], [ocx, ocy, ocz]);
        let t = _mm256_div_ps(_mm256_xor_ps(num, _mm256_set1_ps(-0.0)), denom);
        let in_range = avx2_in_range(t, tmin, tmax);
        let in_range = _mm256_movemask_ps(in_range) as u32;
        if in_range == 0 {
            return 0;
        }
        let r2 = avx2_rim2(p, [ocx, ocy, ocz], d, t);
        let on = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(r2, _mm256_set1_ps(RIM))) as u32;
        on & in_range
    }

    /// [`super::disc_masks`] with one pack per 256-bit register.
    ///
    /// # Safety
    /// The CPU must run AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn avx2_masks<C: AsRef<DiscColumns>>(
        packs: &[C],
        origin: [f32; 3],
        dir: [f32; 3],
        t_min: f32,
        t_max: f32,
        out: &mut [u32],
    ) {
        let o = origin.map(|x| _mm256_set1_ps(x));
        let d = dir.map(|x| _mm256_set1_ps(x));
        let (tmin, tmax) = (_mm256_set1_ps(t_min), _mm256_set1_ps(t_max));
        for (p, m) in packs.iter().zip(out.iter_mut()) {
            *m = avx2_mask(p.as_ref(), o, d, tmin, tmax);
        }
    }

    /// [`super::disc_masks_met`] with one pack per 256-bit register.
    ///
    /// # Safety
    /// The CPU must run AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn avx2_masks_met<C: AsRef<DiscColumns>>(
        packs: &[C],
        mut met: u32,
        origin: [f32; 3],
        dir: [f32; 3],
        (t_min, t_max): (f32, f32),
        out: &mut [u32],
    ) {
        let o = origin.map(|x| _mm256_set1_ps(x));
        let d = dir.map(|x| _mm256_set1_ps(x));
        let (tmin, tmax) = (_mm256_set1_ps(t_min), _mm256_set1_ps(t_max));
        while met != 0 {
            let j = met.trailing_zeros() as usize;
            met &= met - 1;
            out[j] = avx2_mask(packs[j].as_ref(), o, d, tmin, tmax);
        }
    }

    /// [`super::disc_masks_rays`]: per pack, its columns and `n·(o - c)`
    /// once, then each ray of `active` as in [`avx2_masks`].
    ///
    /// # Safety
    /// The CPU must run AVX2.
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn avx2_masks_rays<C: AsRef<DiscColumns>>(
        packs: &[C],
        origin: [f32; 3],
        dirs: &[[f32; 3]; RAYS],
        t_min: &[f32; RAYS],
        t_max: &[f32; RAYS],
        cone: Option<&Cone>,
        active: u32,
        out: &mut [[u32; RAYS]],
        rays: &mut [u32],
    ) {
        let [ox, oy, oz] = origin.map(|x| _mm256_set1_ps(x));
        let rim = _mm256_set1_ps(RIM);
        let sign = _mm256_set1_ps(-0.0);
        for ((p, out), any) in packs.iter().zip(out.iter_mut()).zip(rays.iter_mut()) {
            let p = p.as_ref();
            *out = [0; RAYS];
            *any = 0;
            // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
            // (`DiscColumns` is 64-byte aligned, each column 32 bytes).
            let col = |k: usize| unsafe { _mm256_load_ps(p.cols[k].as_ptr()) };
            let (cx, cy, cz) = (col(CENTER), col(CENTER + 1), col(CENTER + 2));
            // The cone test of `portable_cone`, the same operations.
            let near = match cone {
                None => _mm256_castsi256_ps(_mm256_set1_epi32(-1)),
                Some(cone) => {
                    let [ax, ay, az] = cone.axis.map(|x| _mm256_set1_ps(x));
                    let (wx, wy, wz) = (
                        _mm256_sub_ps(cx, ox),
                        _mm256_sub_ps(cy, oy),
                        _mm256_sub_ps(cz, oz),
                    );
                    let cross = |a: __m256, b: __m256, c: __m256, d: __m256| {
                        _mm256_sub_ps(_mm256_mul_ps(a, b), _mm256_mul_ps(c, d))
                    };
                    let (qx, qy, qz) = (
                        cross(wy, az, wz, ay),
                        cross(wz, ax, wx, az),
                        cross(wx, ay, wy, ax),
                    );
                    let h = _mm256_sqrt_ps(avx2_dot([qx, qy, qz], [qx, qy, qz]));
                    let s = avx2_dot([wx, wy, wz], [ax, ay, az]);
                    let dist = _mm256_sub_ps(
                        _mm256_mul_ps(h, _mm256_set1_ps(cone.cos)),
                        _mm256_mul_ps(s, _mm256_set1_ps(cone.sin)),
                    );
                    let u = [col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2)];
                    let v = [col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2)];
                    let m = _mm256_min_ps(avx2_dot(u, u), avx2_dot(v, v));
                    let r = _mm256_div_ps(_mm256_set1_ps(1.0), _mm256_sqrt_ps(m));
                    let l1 = _mm256_add_ps(
                        _mm256_add_ps(_mm256_andnot_ps(sign, wx), _mm256_andnot_ps(sign, wy)),
                        _mm256_andnot_ps(sign, wz),
                    );
                    let bound = _mm256_add_ps(
                        r,
                        _mm256_mul_ps(_mm256_add_ps(l1, r), _mm256_set1_ps(CONE_SLACK)),
                    );
                    let near = _mm256_cmp_ps::<_CMP_NGT_UQ>(dist, bound);
                    if _mm256_movemask_ps(near) == 0 {
                        continue;
                    }
                    near
                }
            };
            let (nx, ny, nz) = (col(NORMAL), col(NORMAL + 1), col(NORMAL + 2));
            let (ocx, ocy, ocz) = (
                _mm256_sub_ps(ox, cx),
                _mm256_sub_ps(oy, cy),
                _mm256_sub_ps(oz, cz),
            );
            let num = avx2_dot([nx, ny, nz], [ocx, ocy, ocz]);
            let neg = _mm256_xor_ps(num, sign);
            let mut left = active;
            while left != 0 {
                let k = left.trailing_zeros() as usize;
                left &= left - 1;
                let [dx, dy, dz] = dirs[k].map(|x| _mm256_set1_ps(x));
                let denom = avx2_dot([nx, ny, nz], [dx, dy, dz]);
                let t = _mm256_div_ps(neg, denom);
                let in_range = avx2_in_range(t, _mm256_set1_ps(t_min[k]), _mm256_set1_ps(t_max[k]));
                // No early exit on an empty range here: most packs have
                // lanes in range, and a branch per ray keeps the rays'
                // chains from overlapping.
                let r2 = avx2_rim2(p, [ocx, ocy, ocz], [dx, dy, dz], t);
                let on = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(r2, rim), in_range);
                let m = _mm256_movemask_ps(_mm256_and_ps(on, near)) as u32;
                out[k] = m;
                *any |= u32::from(m != 0) << k;
            }
        }
    }

    /// [`super::disc_masks`] with two packs per 512-bit register (the last
    /// pack of an odd count alone, its upper half padding).
    ///
    /// # Safety
    /// The CPU must run AVX-512 F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn avx512_masks<C: AsRef<DiscColumns>>(
        packs: &[C],
        origin: [f32; 3],
        dir: [f32; 3],
        t_min: f32,
        t_max: f32,
        out: &mut [u32],
    ) {
        let [ox, oy, oz] = origin.map(|x| _mm512_set1_ps(x));
        let [dx, dy, dz] = dir.map(|x| _mm512_set1_ps(x));
        let tmin = _mm512_set1_ps(t_min);
        let tmax = _mm512_set1_ps(t_max);
        let inf = _mm512_set1_ps(f32::INFINITY);
        let rim = _mm512_set1_ps(RIM);
        let sign = _mm512_set1_epi32(i32::MIN);
        let mut i = 0;
        while i < packs.len() {
            let a = packs[i].as_ref();
            let b = packs.get(i + 1).map(AsRef::as_ref);
            // Column `k` of pack `a` in the lower half, of `b` (or zeros:
            // a zero normal, never hit) in the upper.
            let col = |k: usize| {
                // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
                // (`DiscColumns` is 64-byte aligned, each column 32 bytes).
                let lo = unsafe { _mm256_load_ps(a.cols[k].as_ptr()) };
                let hi = match b {
                    // SAFETY: as above.
                    Some(b) => unsafe { _mm256_load_ps(b.cols[k].as_ptr()) },
                    None => _mm256_setzero_ps(),
                };
                _mm512_castpd_ps(_mm512_insertf64x4::<1>(
                    _mm512_castpd256_pd512(_mm256_castps_pd(lo)),
                    _mm256_castps_pd(hi),
                ))
            };
            let (nx, ny, nz) = (col(NORMAL), col(NORMAL + 1), col(NORMAL + 2));
            let (cx, cy, cz) = (col(CENTER), col(CENTER + 1), col(CENTER + 2));
            let denom = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(nx, dx), _mm512_mul_ps(ny, dy)),
                _mm512_mul_ps(nz, dz),
            );
            let (ocx, ocy, ocz) = (
                _mm512_sub_ps(ox, cx),
                _mm512_sub_ps(oy, cy),
                _mm512_sub_ps(oz, cz),
            );
            let num = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(nx, ocx), _mm512_mul_ps(ny, ocy)),
                _mm512_mul_ps(nz, ocz),
            );
            let neg = _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(num), sign));
            let t = _mm512_div_ps(neg, denom);
            let in_range = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(t, tmin)
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(t, tmax)
                & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(_mm512_abs_ps(t), inf);
            let mask = if in_range == 0 {
                0
            } else {
                let (ux, uy, uz) = (col(U_SCALED), col(U_SCALED + 1), col(U_SCALED + 2));
                let (vx, vy, vz) = (col(V_SCALED), col(V_SCALED + 1), col(V_SCALED + 2));
                let px = _mm512_add_ps(ocx, _mm512_mul_ps(dx, t));
                let py = _mm512_add_ps(ocy, _mm512_mul_ps(dy, t));
                let pz = _mm512_add_ps(ocz, _mm512_mul_ps(dz, t));
                let u = _mm512_add_ps(
                    _mm512_add_ps(_mm512_mul_ps(px, ux), _mm512_mul_ps(py, uy)),
                    _mm512_mul_ps(pz, uz),
                );
                let v = _mm512_add_ps(
                    _mm512_add_ps(_mm512_mul_ps(px, vx), _mm512_mul_ps(py, vy)),
                    _mm512_mul_ps(pz, vz),
                );
                let r2 = _mm512_add_ps(_mm512_mul_ps(u, u), _mm512_mul_ps(v, v));
                _mm512_cmp_ps_mask::<_CMP_LE_OQ>(r2, rim) & in_range
            };
            out[i] = u32::from(mask & 0xff);
            if b.is_some() {
                out[i + 1] = u32::from(mask >> 8);
            }
            i += 2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Packs of random discs (some lanes padding, some normals edge-on to
    /// the rays, NaN and infinite components) against random rays: every
    /// path this CPU runs gives the portable path's masks.
    #[test]
    fn every_path_gives_the_portable_masks() {
        let mut rng = SplitMix64::new(7);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let mut packs = Vec::new();
        for p in 0..37 {
            let mut cols = [[0.0f32; LANES]; 12];
            for l in 0..LANES {
                if (p + l) % 7 == 3 {
                    continue; // padding
                }
                for (k, col) in cols.iter_mut().enumerate() {
                    col[l] = f(if k < 3 { 2.0 } else { 1.5 });
                }
                match (p * 5 + l) % 23 {
                    0 => cols[NORMAL][l] = f32::NAN,
                    1 => cols[CENTER + 1][l] = f32::INFINITY,
                    2 => cols[NORMAL + 2][l] = 0.0,
                    _ => {}
                }
            }
            packs.push(DiscColumns { cols });
        }
        let mut total = 0;
        for r in 0..400 {
            let origin = [f(3.0), f(3.0), f(3.0)];
            let mut dir = [f(1.0), f(1.0), f(1.0)];
            if r % 17 == 0 {
                dir[r % 3] = 0.0;
            }
            let (t_min, t_max) = if r % 3 == 0 {
                (0.0, f32::INFINITY)
            } else {
                (0.1, 2.5)
            };
            for n in [1, 2, 5, packs.len()] {
                let mut want = vec![0; n];
                disc_masks(
                    &packs[..n],
                    origin,
                    dir,
                    t_min,
                    t_max,
                    Isa::Portable,
                    &mut want,
                );
                total += want.iter().map(|m| m.count_ones()).sum::<u32>();
                for isa in available() {
                    let mut got = vec![u32::MAX; n];
                    disc_masks(&packs[..n], origin, dir, t_min, t_max, isa, &mut got);
                    assert_eq!(got, want, "{isa}, ray {r}, {n} packs");
                }
            }
        }
        assert!(
            total > 1000,
            "the rays hit too few lanes to test much: {total}"
        );
    }

    /// Packets of rays sharing an origin (narrow and wide cones, zero and
    /// positive `t_min`, finite and infinite `t_max`) against packs of
    /// random discs: [`disc_masks_rays`] without a cone gives each ray the
    /// lanes of [`disc_masks`]; with the rays' cone, a subset of them that
    /// still holds every lane the exact disc test hits; every path the
    /// same lanes as the portable one, and the cone drops most lanes.
    #[test]
    fn shared_origin_rays_get_their_own_lanes() {
        use crate::primitive::{Disc, Pack, Primitive};
        use glam::Vec3;
        let mut rng = SplitMix64::new(11);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let mut packs = Vec::new();
        for _ in 0..64 {
            let mut pack = DiscColumns::EMPTY;
            for l in 0..LANES - 1 {
                let n = Vec3::new(f(1.0), f(1.0), f(1.0)).normalize();
                let u = n.any_orthonormal_vector();
                let v = n.cross(u);
                let (ru, rv) = (0.05 + f(0.04).abs(), 0.05 + f(0.04).abs());
                let d = Disc {
                    center: Vec3::new(f(1.0), f(1.0), f(1.0)),
                    normal: n,
                    u_scaled: u / ru,
                    v_scaled: v / rv,
                };
                pack.set(l, &d);
            }
            packs.push(pack);
        }
        let (mut hits, mut dropped) = (0, 0);
        for r in 0..300 {
            let origin = [f(1.2), f(1.2), f(1.2)];
            // Aimed at a disc centre, spread by 0.02 or 0.3.
            let p = &packs[r % packs.len()];
            let aim = Vec3::new(
                p.cols[CENTER][r % 7],
                p.cols[CENTER + 1][r % 7],
                p.cols[CENTER + 2][r % 7],
            );
            let spread = if r % 2 == 0 { 0.02 } else { 0.3 };
            let base = aim - Vec3::from(origin);
            let dirs: [[f32; 3]; RAYS] = std::array::from_fn(|_| {
                (base + Vec3::new(f(spread), f(spread), f(spread)) * base.length())
                    .normalize()
                    .to_array()
            });
            let t_min = [if r % 3 == 0 { 0.0 } else { 1e-3 }; RAYS];
            let t_max: [f32; RAYS] = std::array::from_fn(|k| {
                if k % 2 == 0 {
                    f32::INFINITY
                } else {
                    1.0 + f(0.5)
                }
            });
            let cone = Cone::around(&std::array::from_fn(|a| dirs.map(|d| d[a])));
            if spread < 0.1 {
                assert!(cone.is_some(), "ray {r}: a narrow packet has a cone");
            }
            let active = if r % 5 == 0 { 0b1011_0110 } else { 0xff };
            for pack in &packs {
                let mut want = [0; RAYS];
                for k in 0..RAYS {
                    let mut m = [0];
                    disc_masks(
                        std::slice::from_ref(pack),
                        origin,
                        dirs[k],
                        t_min[k],
                        t_max[k],
                        Isa::Portable,
                        &mut m,
                    );
                    if active & (1 << k) != 0 {
                        want[k] = m[0];
                    }
                }
                // One pack alone, and the pack after two others in one call.
                let three = [
                    packs[(r + 1) % packs.len()],
                    packs[(r + 5) % packs.len()],
                    *pack,
                ];
                let masks = |packs: &[DiscColumns], c: Option<&Cone>, isa: Isa| {
                    let mut out = [[u32::MAX; RAYS]; 3];
                    let mut rays = [u32::MAX; 3];
                    disc_masks_rays(
                        packs, origin, &dirs, &t_min, &t_max, c, active, isa, &mut out, &mut rays,
                    );
                    let j = packs.len() - 1;
                    let any = (0..RAYS).fold(0, |a, k| a | u32::from(out[j][k] != 0) << k);
                    assert_eq!(rays[j], any, "{isa}, ray {r}: the rays a pack passes");
                    out[j]
                };
                for isa in available() {
                    for ps in [std::slice::from_ref(pack), &three[..]] {
                        assert_eq!(masks(ps, None, isa), want, "{isa}, ray {r}, no cone");
                    }
                }
                let c = cone.as_ref();
                if let Some(c) = c {
                    dropped += LANES as u32 - portable_cone(pack, origin, c).count_ones();
                }
                let coned = masks(std::slice::from_ref(pack), c, Isa::Portable);
                for isa in available() {
                    for ps in [std::slice::from_ref(pack), &three[..]] {
                        assert_eq!(masks(ps, c, isa), coned, "{isa}, ray {r}, cone");
                    }
                }
                for k in 0..RAYS {
                    if active & (1 << k) == 0 {
                        continue;
                    }
                    assert_eq!(coned[k] & !want[k], 0, "ray {r}/{k}: the cone adds lanes");
                    let ray = crate::geometry::Ray {
                        origin: origin.into(),
                        dir: dirs[k].into(),
                    };
                    for l in 0..LANES {
                        if pack
                            .get(l, 0, &())
                            .intersect(&ray, t_min[k], t_max[k])
                            .is_some()
                        {
                            hits += 1;
                            assert!(
                                coned[k] & (1 << l) != 0,
                                "ray {r}/{k}: lane {l} hit but dropped"
                            );
                        }
                    }
                }
            }
        }
        assert!(
            hits > 200 && dropped > 50_000,
            "too little tested: {hits} hits, {dropped} dropped"
        );
    }

    #[test]
    fn names_round_trip() {
        for i in Isa::ALL {
            assert_eq!(Isa::parse(i.name()), Some(i));
        }
        assert_eq!(Isa::parse("sse9"), None);
        assert!(available().contains(&Isa::Portable));
    }
}
