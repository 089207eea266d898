//! The octree of report §3.1, traversed front to back as in §3.2, generic
//! over the [`Primitive`] it holds.
//!
//! Build (§3.1, in [`build`]):
//! 1. the root is the bounding cube of every primitive;
//! 2. each primitive is inserted by its *centre* into the leaf containing it,
//!    and a leaf holding more than [`OctreeParams::max_leaf`] centres is split
//!    into eight octants, down to [`OctreeParams::max_depth`] (a cell whose
//!    centres all fall in one finest cell, e.g. coincident splats, stays a
//!    leaf);
//! 3. once the tree stands, each primitive is added to *every* leaf it
//!    overlaps ([`OverlapTest`]), so a ray finds it in whichever cell it meets
//!    it (fig. 8).
//!
//! Before step 1 the scene may be split into parts ([`parts`]: a model
//! standing on a wide floor becomes the model and the floor), each built
//! as an octree of its own; a ray tests each part's
//! padded content box and walks the parts it meets, nearest first, so a
//! ray leaving the floor away from the model meets a thin slab and nothing
//! else, and the model's rays descend from cells sized for the model. Each
//! part's candidates are found as in one tree, and the window does not
//! depend on the order hits are offered in, so the candidates are those of
//! one tree.
//!
//! Steps 1–2 are done as one parallel sort of the centres' Morton codes
//! followed by a recursive split of the sorted range — the same tree as
//! inserting one primitive at a time, since a cell is split exactly when it
//! holds more than `max_leaf` centres. Step 3 descends the tree once per
//! primitive, in parallel over chunks in Morton order; a stable counting sort
//! by leaf then groups the references (no sort of 64-bit pairs).
//!
//! The built tree is flattened into 8-byte [`Node`]s (children of a node
//! stored contiguously, empty children left out) and the leaves' references,
//! stored as the primitive's [`Pack`]s: copies of `Pack::LANES` primitives
//! (for discs, SoA), so a leaf's primitives are read contiguously and
//! filtered several at a time.
//!
//! The cells of level [`GRID_LEVEL`] (16 per axis) are also kept as a
//! uniform grid: a ray walks it cell by cell (3D-DDA) and descends only from
//! the nodes of the cells it crosses, instead of from the root (the upper
//! four levels were 59 % of the interior nodes a ray visited on the bundled
//! bunny; `docs/notes/backends.md`, round `octree-perf3`).
//!
//! Traversal (§3.2, in [`traverse`]) computes the entry and exit of a cell's
//! eight children at once, then visits the non-empty ones in the order given
//! by the ray direction's signs (`i ^ sign_mask`, a front-to-back order for
//! octants), skipping every cell whose entry lies beyond the far end of the
//! candidate window (`hits.far()`, nearest + `xi`, §4.3): no hit there can
//! still be a candidate. A leaf whose content box (its primitives' padded
//! footprints clipped to its padded cell) the ray misses within the window
//! is skipped: on a floor that box is a thin slab, which a shadow ray
//! leaving the floor or a primary ray skimming it passes over. In a leaf,
//! [`Pack::masks`] filters (on the SIMD path of [`OctreeParams::simd`],
//! `crate::simd`: the same lanes on every path); every lane it
//! lets through is decided by [`Primitive::intersect`] and offered to
//! [`CandidateHits::offer`], so the candidates are bit-identical to those of
//! the other backends.
//!
//! Robustness: cells are padded by a few ulps of the scene's coordinates both
//! when primitives are inserted and when rays are clipped, so that rounding
//! in the slab test or in a hit's position can never make a ray skip a cell
//! holding a primitive it hits. Zero direction components give infinite
//! inverse directions; the NaN of `0 * inf` (origin exactly on a padded
//! plane) is resolved to "miss this cell", which is safe because the padded
//! neighbour then contains the whole ray. A NaN ray visits cells but never
//! hits anything.

mod bins;
mod build;
mod fan;
mod packet;
mod parallel;
mod parts;
mod stream;
mod traverse;

use super::{Backend, BuildStats, CandidateHits, NoSkip, Query};
use crate::primitive::{Pack, Primitive};
use crate::simd::Isa;
use glam::Vec3;

/// How a primitive is tested against a leaf cell in step 3 of §3.1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OverlapTest {
    /// The exact test, [`Primitive::meets_box`] (for a disc: the elliptical
    /// disc meets the padded box).
    Exact,
    /// The report's approximation (§3.1): the primitive's coarse box
    /// ([`Primitive::coarse_half_extent`], for a splat the box of its
    /// bounding square `c ± r_u u ± r_v v`) meets the cell. Conservative
    /// (never misses an overlap), but adds references to cells the primitive
    /// misses.
    BoundingSquare,
}

/// How the leaves hold their primitives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// Each leaf's references copied into packs of its own, so a leaf's
    /// primitives are read contiguously and every pack is full but the
    /// last: the fastest layout, at about 5 copies of every primitive.
    Copies,
    /// Every primitive stored once, in packs grouped by the leaves that
    /// reference them (a leaf's own primitives together, then those it
    /// shares with one neighbour), but for the lone lanes a leaf would read
    /// in a lower leaf's packs, copied after its own (3 % of the
    /// references); a leaf lists the packs it needs with a
    /// mask of the lanes it references, and its list goes to the filter 16
    /// packs a call wherever they lie ([`crate::primitive::Pack::masks_at`]).
    /// About half the memory of [`Layout::Copies`] on the accel benchmark's
    /// surface, 1.5 times its pack tests per leaf (in Morton order 2.2),
    /// 0.7-0.85 of its speed (`docs/notes/backends.md`, issue 55 rounds 3
    /// and 4; round `octree-perf4` for the Morton order).
    Shared,
    /// [`Layout::Copies`] while the copies' packs would take at most this
    /// many bytes, [`Layout::Shared`] beyond: the copies are faster at
    /// every size measured (at 4M the shared layout runs at 0.69 / 0.62 of
    /// their primary / shadow rays in 0.61 of their memory: the benchmark
    /// in docs/results.md).
    Auto {
        /// Most bytes of packs and ids the copies may take.
        max_copies_bytes: usize,
    },
}

/// The default [`Layout::Auto`] bound: copies up to 512 MiB (about 6M
/// splats of the benchmark's surface with the default leaf bounds: 360.3
/// MB at 4M).
pub const AUTO_MAX_COPIES_BYTES: usize = 512 << 20;

/// Build parameters of the [`Octree`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OctreeParams {
    /// A cell above level 4 (the top-level grid's) holding more centres
    /// than this is split (§3.1).
    pub max_leaf: usize,
    /// A cell at level 4 (a cell of the top-level grid) or deeper holding
    /// more centres than this is split: the deep leaves may be larger,
    /// since a ray reaches them along the grid and skips the packs whose
    /// boxes it misses.
    pub deep_leaf: usize,
    /// Deepest level (root = 0), at most 21. Guarantees termination when many
    /// primitives share a centre.
    pub max_depth: u32,
    /// The primitive/cell test of step 3 (§3.1).
    pub overlap: OverlapTest,
    /// How the leaves hold their primitives.
    pub layout: Layout,
    /// The SIMD path of the leaf filter (`crate::simd`); `None`, or a path
    /// this CPU does not run: the process's ([`crate::simd::active`]).
    pub simd: Option<Isa>,
}

impl Default for OctreeParams {
    /// `max_leaf = 96`, `deep_leaf = 256`, `max_depth = 16`, exact overlap
    /// test (measured better than the bounding square: see
    /// `docs/notes/README.md`), copies in the leaves up to
    /// [`AUTO_MAX_COPIES_BYTES`], shared packs beyond.
    ///
    /// 96 centres a leaf: with 8-disc packs filtered a leaf at a time, large
    /// leaves cost little in the leaf and save descents and copies. The
    /// accel benchmark (AVX2, primary / shadow rays against Embree, memory
    /// against Embree's) at 35k, 1M, 4M splats: `max_leaf` 8 gave
    /// 0.99 / 1.05 (4.6x), 0.94 / 0.98 (4.6x), -; 64 gave 1.08 / 1.34
    /// (1.48x), 1.20 / 1.31 (1.62x), 1.70 / 1.67 (1.44x); 96 gave
    /// 1.05 / 1.31 (1.28x), 1.21 / 1.32 (1.38x), 1.73 / 1.83 (1.23x)
    /// (`docs/notes/README.md`, issue 25).
    ///
    /// 256 centres a deep leaf (level 4 and below; issue 55,
    /// `docs/notes/backends.md`, forty-sixth session): fewer copies where
    /// the scene is large, the same tree where it is small. Against 96
    /// everywhere, one thread, camera rays, one ray at a time: the
    /// blobby surface at 35k splats 3.8 MB against 3.9 at the same speed;
    /// at 100k 8.7 against 11.8 MB, 250k 22.6 against 29.2, both at the
    /// same speed; the 1.53M-splat clipped bunny's discs 123.2 against
    /// 167.4 MB and 3.5 % faster. 256 at every level instead was 13 %
    /// slower at 35k and 3 % at 100k.
    fn default() -> Self {
        OctreeParams {
            max_leaf: 96,
            deep_leaf: 256,
            max_depth: 16,
            overlap: OverlapTest::Exact,
            layout: Layout::Auto {
                max_copies_bytes: AUTO_MAX_COPIES_BYTES,
            },
            simd: None,
        }
    }
}

/// The level whose cells form the top-level [`Grid`] (`8^GRID_LEVEL`
/// cells).
const GRID_LEVEL: u32 = 4;

/// The cells of level [`GRID_LEVEL`] as a uniform grid: per cell, the node
/// covering it (the cell's own node, or a leaf above that level) and the
/// node's lower corner, derived with the same [`child_lo`] arithmetic as
/// build and descent.
struct Grid {
    /// Cells per axis.
    n: usize,
    /// Edge length of a cell (`root_size / n`, exact: halvings).
    cell: f32,
    /// Per cell (`x + n (y + n z)`): the node and its box.
    cells: Vec<GridCell>,
}

/// One cell of the [`Grid`]: the node covering it ([`NO_NODE`] when empty),
/// and that node's lower corner and edge.
#[derive(Clone, Copy, Debug)]
struct GridCell {
    lo: Vec3,
    size: f32,
    node: u32,
}

/// A grid cell with nothing in it.
const NO_NODE: u32 = u32::MAX;

/// Flag in [`Node::meta`] marking an interior node.
const INTERIOR: u32 = 1 << 31;

/// A box as its lower and upper corners.
type LeafBox = [Vec3; 2];

/// Packs per [`PackBoxes`].
const BOX_GROUP: usize = 4;

/// The boxes of [`BOX_GROUP`] consecutive packs as six columns, one lane
/// a pack: lower x, y, z, then upper x, y, z.
type PackBoxes = [glam::Vec4; 6];

/// Primitive id of a padding lane.
const NO_PRIMITIVE: u32 = u32::MAX;

/// Where a leaf entry's lane mask starts (at most 8 lanes per pack).
const ENTRY_MASK_SHIFT: u32 = 24;

/// The pack index bits of a leaf entry.
const ENTRY_PACK: u32 = (1 << ENTRY_MASK_SHIFT) - 1;

const _: () = assert!(
    <crate::primitive::DiscPack as Pack<crate::primitive::Disc>>::LANES <= 8,
    "a leaf entry holds an 8-lane mask"
);

/// One node of the flattened octree: 8 bytes, no bounds (a cell's box is
/// derived from its parent's during traversal).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
struct Node {
    /// Interior: index in `nodes` of its first stored child. Leaf: index of
    /// its first pack ([`Layout::Copies`]) or entry ([`Layout::Shared`]).
    first: u32,
    /// Interior: [`INTERIOR`] | 8-bit mask of the stored (non-empty)
    /// children, bit `o` for octant `o = x | y << 1 | z << 2` (1 = upper
    /// half); child `o` sits at `first + popcount(mask & ((1 << o) - 1))`.
    /// Leaf: the number of packs or entries (bit 31 clear).
    meta: u32,
}

/// Lower corner of child octant `oct` of the cell `(lo, 2 * half)`. Build
/// and traversal derive boxes with this same arithmetic, so they agree to
/// the bit.
#[inline]
fn child_lo(lo: Vec3, half: f32, oct: usize) -> Vec3 {
    Vec3::new(
        if oct & 1 != 0 { lo.x + half } else { lo.x },
        if oct & 2 != 0 { lo.y + half } else { lo.y },
        if oct & 4 != 0 { lo.z + half } else { lo.z },
    )
}

/// The octree of §3.1 over a set of primitives: one [`Tree`] per part of
/// the scene ([`parts`]: usually one; a model standing on a wide floor
/// gets a tree of its own), each with its own cube, grid and clip box.
pub struct Octree<P: Primitive> {
    /// The parts' trees, each over a group of primitives (ids global).
    parts: Vec<Tree<P>>,
    /// References over every part.
    references: usize,
    /// The layout built (the same for every part).
    shared: bool,
    /// The SIMD path of the leaf filter.
    isa: Isa,
    /// Primitives the tree was built over (ids `0..count`).
    count: usize,
    stats: BuildStats,
    /// Every primitive held, once, and its id ([`Octree::primitives`]),
    /// found when a fan is first built and kept for the next: 4 bytes and
    /// a primitive each, not in `stats`' build-time memory.
    held: std::sync::OnceLock<(Vec<u32>, Vec<P>)>,
}

/// The octree of §3.1 over one part of the primitives.
struct Tree<P: Primitive> {
    nodes: Vec<Node>,
    /// Per node: for a leaf, the box around its primitives' padded
    /// footprints clipped to its padded cell; for an interior node, the
    /// union of its children's. A ray that misses it skips the node (on a
    /// floor, a leaf's content is a thin slab).
    boxes: Vec<LeafBox>,
    /// The primitives, `P::Pack::LANES` to a pack (SoA): with
    /// [`Layout::Copies`] each leaf's references copied in reference order
    /// (the last pack of a leaf padded with empty lanes), with
    /// [`Layout::Shared`] every primitive once (a few twice), grouped by
    /// the leaves that reference it.
    packs: Vec<P::Pack>,
    /// Primitive id of each lane of `packs` ([`NO_PRIMITIVE`] on padding).
    pack_ids: Vec<u32>,
    /// [`Layout::Copies`]: the packs' boxes, [`BOX_GROUP`] consecutive
    /// packs to a [`PackBoxes`] (pack `i` in lane `i % BOX_GROUP` of group
    /// `i / BOX_GROUP`): each the box around its lanes' padded footprints
    /// clipped to its leaf's content box. A single ray skips the filter of
    /// a pack whose box it misses within its window, as it skips a leaf.
    /// Empty with [`Layout::Shared`].
    pack_boxes: Vec<PackBoxes>,
    /// What the packs' lanes leave out of their primitives
    /// ([`Pack::Side`], by global id: for clipped discs the clip lines of
    /// the clipped ones alone), one table for every part.
    side: std::sync::Arc<<P::Pack as Pack<P>>::Side>,
    /// [`Layout::Shared`]: the leaves' references, leaf after leaf: per
    /// entry, the index of a pack in `packs` (bits below
    /// [`ENTRY_MASK_SHIFT`]) and the mask of the lanes the leaf references
    /// (the bits above). Empty with [`Layout::Copies`], whose leaves own a
    /// range of `packs`.
    entries: Vec<u32>,
    /// The layout built is [`Layout::Shared`].
    shared: bool,
    /// The SIMD path of the leaf filter.
    isa: Isa,
    /// The nodes at level [`GRID_LEVEL`] as a uniform grid, walked cell by
    /// cell instead of descending the upper levels for every ray; `None`
    /// when the root is a leaf.
    grid: Option<Grid>,
    /// References (lanes holding a primitive).
    references: usize,
    /// Lower corner of the root cube.
    root_lo: Vec3,
    /// Edge length of the root cube.
    root_size: f32,
    /// The padded box around every primitive: rays are clipped to it
    /// before the grid walk, so a scene much flatter than its cube (a
    /// floor) is left where its content ends, not where the cube does.
    bounds: [Vec3; 2],
    /// Padding added to every cell, in world units.
    pad: f32,
}

impl<P: Primitive> Octree<P> {
    /// Builds the octree of §3.1 over `prims` (primitive `i` gets id `i`).
    ///
    /// Panics if there are 2^31 or more references or 2^32 primitives.
    #[must_use]
    pub fn new(prims: &[P], params: &OctreeParams) -> Octree<P> {
        build::build(prims, params, build::Insertion::Overlaps)
    }

    /// **A deliberately broken octree, for testing the validation tools.**
    /// Step 3 of §3.1 is skipped: each primitive sits only in the leaf
    /// holding its centre, so rays miss the parts that reach into
    /// neighbouring cells — exactly the holes fig. 8 warns about. Never
    /// render with it.
    #[cfg(feature = "test-backends")]
    #[must_use]
    pub fn without_overlap_insertion(prims: &[P], params: &OctreeParams) -> Octree<P> {
        build::build(prims, params, build::Insertion::CentreOnly)
    }

    /// Total references (a primitive counts once per leaf holding it).
    #[must_use]
    pub fn references(&self) -> usize {
        self.references
    }

    /// The parts the scene was split into, each with a tree of its own
    /// (`parts`: 1 unless a small model stands on a wide floor, or the
    /// like).
    #[must_use]
    pub fn parts(&self) -> usize {
        self.parts.len()
    }

    /// The SIMD path of the leaf filter.
    #[must_use]
    pub fn simd(&self) -> Isa {
        self.isa
    }

    /// The layout built: [`Layout::Copies`] or [`Layout::Shared`] (what
    /// [`Layout::Auto`] chose).
    #[must_use]
    pub fn layout(&self) -> Layout {
        if self.shared {
            Layout::Shared
        } else {
            Layout::Copies
        }
    }
}

impl<P: Primitive> Backend for Octree<P> {
    /// One traversal per kind of query, monomorphised: primary rays
    /// ([`NoSkip`]) pay nothing for the self-hit rule, and secondary rays
    /// without a pass-over rule nothing for that.
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if q.meets_nothing() {
            return;
        }
        let (ray, t_min, t_max) = (&q.ray, q.t_min, q.t_max);
        match (&q.from, q.pass) {
            (None, None) => self.gather(ray, t_min, t_max, NoSkip, hits),
            (Some(d), None) => self.gather(ray, t_min, t_max, d, hits),
            _ => self.gather(ray, t_min, t_max, q.secondary(), hits),
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        if q.meets_nothing() {
            return false;
        }
        let (ray, t_min, t_max) = (&q.ray, q.t_min, q.t_max);
        match (&q.from, q.pass) {
            (None, None) => self.any_hit(ray, t_min, t_max, NoSkip),
            (Some(d), None) => self.any_hit(ray, t_min, t_max, d),
            _ => self.any_hit(ray, t_min, t_max, q.secondary()),
        }
    }

    /// Packets of up to [`crate::accel::PACKET`] rays descending together
    /// (`packet`): the same candidates as one ray at a time.
    fn intersect_packet(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        self.gather_packets(qs, hits);
    }

    fn occluded_packet(&self, qs: &[Query], out: &mut [bool]) {
        self.any_hit_packets(qs, out);
    }

    fn occluded_each(&self, qs: &[Query], out: &mut [bool]) {
        self.occluded_stream(qs, out);
    }

    /// True: with a leaf taken once for the rays of a packet that share an
    /// origin (the integrator's batches), the octree renders the bunny in
    /// 0.92-0.93 of the CPU time of its single rays, and the glass,
    /// contact, scan and shading scenes in 0.85-0.90
    /// (`docs/notes/generation.md`, "Issue 25: octree packets, round 2", with
    /// the commands; before it, packets rendered the bunny 1.09 times
    /// slower, "Issue 25: ray packets").
    fn prefers_packets(&self) -> bool {
        true
    }

    /// The directions from the rays' origin in which no primitive's
    /// bounding ball lies (`fan`), for a run of at least 4096 rays and as
    /// many as the primitives.
    fn fan(&self, rays: &dyn crate::geometry::RaySet) -> Option<Box<dyn super::Fan + '_>> {
        self.build_fan(rays)
    }

    fn fan_pays(&self, rays: usize) -> bool {
        rays >= fan::MIN_RAYS.max(self.count)
    }

    /// The primitives' shadows along `dir` filed in a grid's cells, each
    /// cell's list answering the rays along it (`parallel`), for at least
    /// 4096 rays and 12 a primitive, and at most one list entry a ray.
    fn parallel(&self, dir: Vec3, rays: usize) -> Option<Box<dyn Backend + '_>> {
        Some(Box::new(self.build_parallel(dir, rays)?))
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}

/// Lanes per pack of `P`.
const fn lanes<P: Primitive>() -> usize {
    <P::Pack as Pack<P>>::LANES
}
