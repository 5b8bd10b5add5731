//! Packet traversal: eight rays against one binary BVH over triangles at once (AVX2, or
//! the same code in AVX-512VL encodings where the CPU has them: twice the vector registers
//! and broadcast operands), for the lockstep path-tracing kernel. Each node holds its two
//! children's boxes, so a visit tests both boxes against all eight rays; a child is entered
//! when any active ray meets it. Triangles are stored by value in leaf order and tested against the eight rays
//! with the watertight test of `geometry::triangle` (per-lane axis permutation), operation
//! for operation, so that each lane's hit is bit-identical to the single-ray test's.
//!
//! The tree is its own (a binned-SAH build here) rather than the scene's wide BVH:
//! packets want narrow nodes with boxes stored for an eight-ray test, and the single-ray
//! layout is free to change.

use crate::geometry::triangle::WatertightRay;
use crate::geometry::{Aabb, Sphere};
use glam::Vec3;
use std::mem::MaybeUninit;

/// Lanes per packet.
pub const LANES: usize = 8;
const LEAF_BIT: u32 = 1 << 31;
const LEAF_COUNT_BITS: u32 = 3;
/// Most triangles per leaf.
const MAX_LEAF: usize = 2;
const BINS: usize = 32;
/// A node visit (two box tests of eight rays) against one triangle test of eight rays, for
/// the SAH. Leaves of up to 4 triangles and costs up to 2 measured the same on the Cornell
/// box; leaves of 1 were 20 % slower.
const NODE_COST: f32 = 1.0;
/// Depth bound: below it splits are median splits (bounded stack).
const MAX_DEPTH: usize = 48;
const STACK: usize = MAX_DEPTH + 40;
/// Slack on the far distance of the slab test (as the single-ray traversal's): a box a
/// triangle touches is not missed through rounding.
const FAR_SLACK: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);
/// Relative distance within which a second triangle's hit ties with a lane's nearest one
/// (`PacketBvh::intersect_ties`). Which of two such hits a walk keeps depends on the order it
/// tests them in (the test accepts t_scaled <= t_max * det, a few ulps either way), so two
/// trees can disagree there; 1e-5 is far above those few ulps.
const TIE_TOL: f32 = 1e-5;
/// Slack on the far distance of the closest-hit walks' box tests (and their stack pops).
/// `FAR_SLACK` covers the slab test's rounding, not the triangle test's: that one rounds at
/// the scale of the vertices, so a far-off triangle's t may come out a few ulps of the
/// vertices short of its plane's true distance (the cbox floor: 2.8025064 for 2.8025122).
/// Once a coplanar triangle has set t_max, the box of such a triangle (flat, entered at the
/// plane's distance) must still be entered, for the nearer hit and for the tie check out to
/// `TIE_TOL`; the occlusion walk keeps `FAR_SLACK`, as the scene BVH's.
const HIT_SLACK: f32 = 1.0 + 2.0 * TIE_TOL;

/// Two child boxes (`[child][min x, y, z, max x, y, z]`) and their codes: an inner node's
/// index, or `LEAF_BIT | start << 3 | (count - 1)` into the triangle arrays.
#[derive(Clone, Copy, Debug)]
struct Node {
    boxes: [[f32; 6]; 2],
    child: [u32; 2],
}

/// Eight rays, structure of arrays. Directions need not be normalised.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rays8 {
    pub o: [[f32; LANES]; 3],
    pub d: [[f32; LANES]; 3],
    pub t_max: [f32; LANES],
}

/// Closest hits of eight rays: `prim` is the triangle's index in the build's input
/// (`u32::MAX` for a miss), `b1`, `b2` its barycentrics as `WatertightRay::intersect` gives them.
#[derive(Clone, Copy, Debug)]
pub struct Hits8 {
    pub t: [f32; LANES],
    pub prim: [u32; LANES],
    pub b1: [f32; LANES],
    pub b2: [f32; LANES],
}

pub struct PacketBvh {
    nodes: Vec<Node>,
    /// Root code (the inner node 0: a tree of one leaf gets a node above it); None when empty.
    root: Option<u32>,
    /// Triangle vertices in leaf order, three a triangle (x, y, z, 0 each), and one vertex
    /// of padding: the SIMD test loads 256 bits from each vertex.
    verts: Vec<[f32; 4]>,
    /// Input index of each triangle.
    ids: Vec<u32>,
    isa: Isa,
}

/// The instruction set of the walk (chosen at build from what the CPU has; tests lower it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Isa {
    /// Each lane walks the tree alone with the scalar tests.
    Portable,
    /// The eight-wide walk.
    Avx2,
    /// The same walk with AVX-512VL encodings: 32 vector registers and broadcast operands.
    Avx512,
}

impl Isa {
    /// The best this CPU runs, lowered by `SVETLO_PACKET_ISA=portable|avx2` (for comparisons).
    fn detect() -> Isa {
        let cap = match std::env::var("SVETLO_PACKET_ISA").as_deref() {
            Ok("portable") => Isa::Portable,
            Ok("avx2") => Isa::Avx2,
            _ => Isa::Avx512,
        };
        Isa::cpu().min(cap)
    }

    fn cpu() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            let popcnt = std::arch::is_x86_feature_detected!("popcnt");
            if popcnt && crate::cpu::avx512() {
                return Isa::Avx512;
            }
            if popcnt && crate::cpu::avx2() {
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }
}

fn leaf(start: usize, count: usize) -> u32 {
    LEAF_BIT | (start as u32) << LEAF_COUNT_BITS | (count as u32 - 1)
}

fn leaf_range(code: u32) -> (usize, usize) {
    let c = code & !LEAF_BIT;
    ((c >> LEAF_COUNT_BITS) as usize, (c & ((1 << LEAF_COUNT_BITS) - 1)) as usize + 1)
}

/// Inverse directions for the portable walk's slab test (infinite for zero components).
struct Prep {
    inv: [[f32; LANES]; 3],
}

fn prep(r: &Rays8, active: u8) -> Prep {
    let mut p = Prep { inv: [[0.0; LANES]; 3] };
    for l in 0..LANES {
        if active & (1 << l) == 0 {
            continue;
        }
        let d = Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]);
        let inv = d.recip();
        for a in 0..3 {
            p.inv[a][l] = inv[a];
        }
    }
    p
}

/// Subtrees of at least this many triangles build their two halves in parallel.
const PARALLEL_MIN: usize = 16 * 1024;

/// A subtree's triangles: the bounds of their boxes (`bb`) and of their centroids (`cb`).
#[derive(Clone, Copy, Debug)]
struct Extent {
    bb: Aabb,
    cb: Aabb,
}

/// The subtree over `order` (`order[0]` is at `base` in the whole order): its nodes (root
/// first) and its code, node indices relative to the returned vector.
fn build_par(input: &Input, order: &mut [u32], base: usize, ext: Extent, depth: usize) -> (Vec<Node>, u32) {
    let n = order.len();
    let mut b = Build { input, nodes: Vec::new(), order, base, bins: Bins::default() };
    if n < PARALLEL_MIN {
        let code = b.rec(0, n, ext, depth);
        return (b.nodes, code);
    }
    let Some((mid, [le, re])) = b.split(0, n, ext, depth) else { return (Vec::new(), leaf(base, n)) };
    let (l, r) = order.split_at_mut(mid);
    let ((ln, lc), (rn, rc)) = rayon::join(|| build_par(input, l, base, le, depth + 1), || build_par(input, r, base + mid, re, depth + 1));
    // Parent first, then the left subtree, then the right: inner codes move by their offset.
    let reloc = |code: u32, off: usize| if code & LEAF_BIT != 0 { code } else { code + off as u32 };
    let mut nodes = Vec::with_capacity(1 + ln.len() + rn.len());
    nodes.push(Node { boxes: [box6(le.bb), box6(re.bb)], child: [reloc(lc, 1), reloc(rc, 1 + ln.len())] });
    for (sub, off) in [(&ln, 1), (&rn, 1 + ln.len())] {
        nodes.extend(sub.iter().map(|nd| Node { boxes: nd.boxes, child: nd.child.map(|c| reloc(c, off)) }));
    }
    (nodes, 0)
}

fn box6(b: Aabb) -> [f32; 6] {
    [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z]
}

/// The triangles as the build sees them: boxes (also as [`BinBox`]es) and centroids.
struct Input {
    bounds: Vec<Aabb>,
    boxes: Vec<BinBox>,
    centroids: Vec<Vec3>,
}

/// A box for the binning loop, where the build spends most of its time: on x86-64 its
/// corners in two SSE registers, a union one `minps` and one `maxps` (`Aabb::union` is six
/// scalar minnum/maxnum with their NaN checks). The same values as `Aabb::union`: `a.min(b)`
/// keeps `a` unless `b < a`, which is `minps(b, a)`, and no bound is NaN (vertices are
/// finite), where the two would differ.
#[derive(Clone, Copy, Debug)]
struct BinBox(#[cfg(target_arch = "x86_64")] [std::arch::x86_64::__m128; 2], #[cfg(not(target_arch = "x86_64"))] Aabb);

// SAFETY (each block): SSE and SSE2 are part of the x86-64 baseline.
#[cfg(target_arch = "x86_64")]
impl BinBox {
    fn empty() -> BinBox {
        use std::arch::x86_64::_mm_set1_ps;
        unsafe { BinBox([_mm_set1_ps(f32::INFINITY), _mm_set1_ps(f32::NEG_INFINITY)]) }
    }
    fn of(b: Aabb) -> BinBox {
        use std::arch::x86_64::_mm_set_ps;
        unsafe { BinBox([_mm_set_ps(0.0, b.min.z, b.min.y, b.min.x), _mm_set_ps(0.0, b.max.z, b.max.y, b.max.x)]) }
    }
    #[inline(always)]
    fn union(self, o: BinBox) -> BinBox {
        use std::arch::x86_64::{_mm_max_ps, _mm_min_ps};
        unsafe { BinBox([_mm_min_ps(o.0[0], self.0[0]), _mm_max_ps(o.0[1], self.0[1])]) }
    }
    fn aabb(self) -> Aabb {
        use std::arch::x86_64::{_mm_cvtss_f32, _mm_shuffle_ps};
        let v = |r| unsafe { Vec3::new(_mm_cvtss_f32(r), _mm_cvtss_f32(_mm_shuffle_ps::<0x55>(r, r)), _mm_cvtss_f32(_mm_shuffle_ps::<0xaa>(r, r))) };
        Aabb { min: v(self.0[0]), max: v(self.0[1]) }
    }
}

#[cfg(not(target_arch = "x86_64"))]
impl BinBox {
    fn empty() -> BinBox {
        BinBox(Aabb::EMPTY)
    }
    fn of(b: Aabb) -> BinBox {
        BinBox(b)
    }
    #[inline(always)]
    fn union(self, o: BinBox) -> BinBox {
        BinBox(self.0.union(o.0))
    }
    fn aabb(self) -> Aabb {
        self.0
    }
}

struct Build<'a> {
    input: &'a Input,
    nodes: Vec<Node>,
    order: &'a mut [u32],
    /// Position of `order[0]` in the whole order (leaf codes are absolute).
    base: usize,
    bins: Bins,
}

/// The SAH's bins per axis, kept between nodes: each node empties the bins it used (most
/// nodes are small and use a few), not all 96.
struct Bins {
    bounds: [[BinBox; BINS]; 3],
    counts: [[u32; BINS]; 3],
}

impl Default for Bins {
    fn default() -> Self {
        Bins { bounds: [[BinBox::empty(); BINS]; 3], counts: [[0; BINS]; 3] }
    }
}

/// A binned SAH split: (sum of area * count, axis, first bin of the right side), and the
/// two sides' box bounds (the unions of their bins).
type BinSplit = (f32, usize, usize, [Aabb; 2]);

impl Build<'_> {
    /// Builds the subtree over `order[lo..hi]` (of extent `ext`); returns its code.
    fn rec(&mut self, lo: usize, hi: usize, ext: Extent, depth: usize) -> u32 {
        let Some((mid, sides)) = self.split(lo, hi, ext, depth) else { return leaf(self.base + lo, hi - lo) };
        let idx = self.nodes.len();
        self.nodes.push(Node { boxes: [box6(sides[0].bb), box6(sides[1].bb)], child: [0; 2] });
        for (k, (a, b)) in [(lo, mid), (mid, hi)].into_iter().enumerate() {
            let code = self.rec(a, b, sides[k], depth + 1);
            self.nodes[idx].child[k] = code;
        }
        idx as u32
    }

    /// Where to split `order[lo..hi]` (of extent `ext`), reordering it, and the two sides'
    /// extents; None for a leaf. The sides' boxes come from the bins and their centroid
    /// bounds from the partition pass (min and max are exact in any order: the same bounds
    /// as folds over the sides, without two more passes over the triangles; only the sign
    /// of a zero bound may differ, which no comparison sees).
    fn split(&mut self, lo: usize, hi: usize, ext: Extent, depth: usize) -> Option<(usize, [Extent; 2])> {
        let n = hi - lo;
        if n <= 1 {
            return None;
        }
        let (bb, cb) = (ext.bb, ext.cb);
        let split = if depth >= MAX_DEPTH { None } else { self.best_split(lo, hi, &cb) };
        match split {
            Some((cost, axis, bin, [lbb, rbb])) => {
                // SAH in units of one triangle test: a node visit, then each child's
                // triangles weighted by the chance that a ray meeting the parent meets it.
                let split_cost = NODE_COST + cost / bb.surface_area().max(f32::MIN_POSITIVE);
                if n <= MAX_LEAF && n as f32 <= split_cost {
                    return None;
                }
                let (cmin, scale) = (cb.min[axis], BINS as f32 / cb.extent()[axis]);
                let mut l = lo;
                let (mut lcb, mut rcb) = (Aabb::EMPTY, Aabb::EMPTY);
                for k in lo..hi {
                    let c = self.input.centroids[self.order[k] as usize];
                    if bin_index(c[axis], cmin, scale) < bin {
                        self.order.swap(k, l);
                        l += 1;
                        lcb = lcb.grow(c);
                    } else {
                        rcb = rcb.grow(c);
                    }
                }
                Some((l, [Extent { bb: lbb, cb: lcb }, Extent { bb: rbb, cb: rcb }]))
            }
            None => {
                if n <= MAX_LEAF {
                    return None;
                }
                // Median along the widest centroid axis (coincident centroids, or too deep).
                let axis = cb.extent().max_position();
                let c = &self.input.centroids;
                self.order[lo..hi].select_nth_unstable_by(n / 2, |&a, &b| c[a as usize][axis].total_cmp(&c[b as usize][axis]));
                let mid = lo + n / 2;
                Some((mid, [self.extent(lo, mid), self.extent(mid, hi)]))
            }
        }
    }

    /// The extent of `order[lo..hi]`.
    fn extent(&self, lo: usize, hi: usize) -> Extent {
        let (o, input) = (&self.order[lo..hi], self.input);
        Extent {
            bb: o.iter().fold(Aabb::EMPTY, |acc, &i| acc.union(input.bounds[i as usize])),
            cb: o.iter().fold(Aabb::EMPTY, |acc, &i| acc.grow(input.centroids[i as usize])),
        }
    }

    /// Best binned SAH split over the three axes of `order[lo..hi]` (centroid bounds `cb`);
    /// None when the centroids coincide. The sweeps visit only the bins that hold
    /// triangles: every split position between two of them gives the same two sides and
    /// cost, and the first such position (the one a sweep over all bins keeps, as it keeps
    /// only a strictly lower cost) is the one after the left side's last bin. Small nodes,
    /// most of the tree, fill a few of the 32 bins.
    fn best_split(&mut self, lo: usize, hi: usize, cb: &Aabb) -> Option<BinSplit> {
        let ext = cb.extent();
        let Bins { bounds: bin_b, counts: bin_n } = &mut self.bins;
        // Per axis, the bins that hold triangles (bit k: bin k).
        let mut used = [0u32; 3];
        let input = self.input;
        for &i in &self.order[lo..hi] {
            let (c, tb) = (input.centroids[i as usize], input.boxes[i as usize]);
            for axis in 0..3 {
                if ext[axis] > 0.0 {
                    let k = bin_index(c[axis], cb.min[axis], BINS as f32 / ext[axis]);
                    bin_b[axis][k] = bin_b[axis][k].union(tb);
                    bin_n[axis][k] += 1;
                    used[axis] |= 1 << k;
                }
            }
        }
        let mut best: Option<(f32, usize, usize)> = None;
        for axis in (0..3).filter(|&a| ext[a] > 0.0) {
            let (bins, counts) = (&bin_b[axis], &bin_n[axis]);
            // The right side's area * count, from each used bin up.
            let mut right = [0.0f32; BINS];
            let (mut acc, mut cnt) = (Aabb::EMPTY, 0u32);
            for k in bits_down(used[axis]) {
                acc = acc.union(bins[k].aabb());
                cnt += counts[k];
                right[k] = acc.surface_area() * cnt as f32;
            }
            let (mut acc, mut cnt) = (Aabb::EMPTY, 0u32);
            let mut bits = used[axis];
            while bits != 0 {
                let k = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if bits == 0 {
                    break; // the last used bin: nothing right of it
                }
                acc = acc.union(bins[k].aabb());
                cnt += counts[k];
                let rcost = right[bits.trailing_zeros() as usize];
                if !rcost.is_finite() {
                    continue;
                }
                let cost = acc.surface_area() * cnt as f32 + rcost;
                if best.is_none_or(|b| cost < b.0) {
                    best = Some((cost, axis, k + 1));
                }
            }
        }
        let sides = best.map(|(_, axis, bin)| {
            let side = |bits: u32| bits_down(bits).fold(Aabb::EMPTY, |acc, k| acc.union(bin_b[axis][k].aabb()));
            let below = (1u32 << bin) - 1;
            [side(used[axis] & below), side(used[axis] & !below)]
        });
        for axis in 0..3 {
            for k in bits_down(used[axis]) {
                (bin_b[axis][k], bin_n[axis][k]) = (BinBox::empty(), 0);
            }
        }
        best.zip(sides).map(|((cost, axis, bin), sides)| (cost, axis, bin, sides))
    }
}

/// The set bits of `bits`, highest first.
fn bits_down(mut bits: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (bits != 0).then(|| {
            let k = 31 - bits.leading_zeros() as usize;
            bits &= !(1 << k);
            k
        })
    })
}

/// The bin of centroid coordinate `c` (`(x as usize).min(BINS - 1)` for every x, NaN
/// included, by the shorter conversion to i32).
#[inline]
fn bin_index(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as i32).clamp(0, BINS as i32 - 1) as usize
}

impl PacketBvh {
    /// The tree over triangles `tris` (vertices p0, p1, p2); hits name indices into it.
    pub fn build(tris: &[[Vec3; 3]]) -> PacketBvh {
        let bounds: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(t)).collect();
        let centroids: Vec<Vec3> = bounds.iter().map(|b| b.center()).collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let root = Extent { bb: bounds.iter().fold(Aabb::EMPTY, |a, b| a.union(*b)), cb: centroids.iter().fold(Aabb::EMPTY, |a, c| a.grow(*c)) };
        let input = Input { boxes: bounds.iter().map(|b| BinBox::of(*b)).collect(), bounds, centroids };
        let (nodes, root) = if tris.is_empty() {
            (Vec::new(), None)
        } else {
            let (mut nodes, code) = build_par(&input, &mut order, 0, root, 0);
            // A tree of one leaf gets a node above it, so that its bounds are tested as the
            // scene's BVH tests them: a shadow ray leaving a vast floor (Mitsuba's projector
            // tests: 2000 units, lit from 1 unit above) is offset by less than the watertight
            // test's rounding at that scale, and meets the floor again at t > 0 by rounding
            // on ~1 % of rays; the floor's flat box, which the ray leaves behind, rejects them.
            // (The other child's box is empty: no ray enters it.)
            let code = if code & LEAF_BIT != 0 {
                nodes.push(Node { boxes: [box6(root.bb), box6(Aabb::EMPTY)], child: [code, code] });
                0
            } else {
                code
            };
            (nodes, Some(code))
        };
        let mut verts: Vec<[f32; 4]> = Vec::with_capacity(3 * order.len() + 1);
        verts.extend(order.iter().flat_map(|&i| tris[i as usize].map(|p| [p.x, p.y, p.z, 0.0])));
        verts.push([0.0; 4]);
        PacketBvh { verts, ids: order, nodes, root, isa: Isa::detect() }
    }

    /// Whether an eight-wide path (AVX2 or AVX-512VL) is used (else each lane walks the tree alone).
    pub fn simd(&self) -> bool {
        self.isa > Isa::Portable
    }

    /// Closest hits of the rays of the lanes set in `active` (other lanes report a miss).
    pub fn intersect(&self, r: &Rays8, active: u8) -> Hits8 {
        let mut h = Hits8 { t: r.t_max, prim: [u32::MAX; LANES], b1: [0.0; LANES], b2: [0.0; LANES] };
        let Some(root) = self.root else { return h };
        if active == 0 {
            return h;
        }
        self.walk_nearest::<false>(root, r, active, &mut h);
        h
    }

    /// [`Self::intersect`], and the mask of lanes whose nearest hit ties with another
    /// triangle's: a hit within a relative 1e-5 of it (coplanar faces, such as a glass box's
    /// bottom lying on the floor, or a shared edge). Which triangle a lane keeps there
    /// depends on the order of the tests, so another tree (the scene's BVH) may keep the
    /// other; on every other lane any correct walk finds this very hit.
    pub fn intersect_ties(&self, r: &Rays8, active: u8) -> (Hits8, u8) {
        let mut h = Hits8 { t: r.t_max, prim: [u32::MAX; LANES], b1: [0.0; LANES], b2: [0.0; LANES] };
        let Some(root) = self.root else { return (h, 0) };
        if active == 0 {
            return (h, 0);
        }
        let ties = self.walk_nearest::<true>(root, r, active, &mut h);
        (h, ties)
    }

    /// The closest-hit walk on this CPU's instruction set; returns the tied lanes (with `TIES`).
    fn walk_nearest<const TIES: bool>(&self, root: u32, r: &Rays8, active: u8, h: &mut Hits8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // SAFETY: the instruction set was detected at run time.
            Isa::Avx512 => return unsafe { self.walk_avx512::<false, TIES>(root, r, active, h) },
            Isa::Avx2 => return unsafe { self.walk_avx2::<false, TIES>(root, r, active, h) },
            Isa::Portable => {}
        }
        self.walk_lanes::<false, TIES>(root, r, &prep(r, active), active, h)
    }

    /// Mask of the active lanes whose ray meets any triangle in (0, t_max).
    pub fn occluded(&self, r: &Rays8, active: u8) -> u8 {
        let mut h = Hits8 { t: r.t_max, prim: [u32::MAX; LANES], b1: [0.0; LANES], b2: [0.0; LANES] };
        let Some(root) = self.root else { return 0 };
        if active == 0 {
            return 0;
        }
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // SAFETY: the instruction set was detected at run time.
            Isa::Avx512 => return unsafe { self.walk_avx512::<true, false>(root, r, active, &mut h) },
            Isa::Avx2 => return unsafe { self.walk_avx2::<true, false>(root, r, active, &mut h) },
            Isa::Portable => {}
        }
        self.walk_lanes::<true, false>(root, r, &prep(r, active), active, &mut h)
    }

    /// Portable fallback: each lane walks the tree on its own with the scalar tests. Returns
    /// the lanes that hit (`ANY`), or else the tied lanes (with `TIES`; see `walk_simd!`).
    fn walk_lanes<const ANY: bool, const TIES: bool>(&self, root: u32, r: &Rays8, p: &Prep, active: u8, h: &mut Hits8) -> u8 {
        let mut blocked = 0u8;
        let mut ties = 0u8;
        for l in 0..LANES {
            if active & (1 << l) == 0 {
                continue;
            }
            let o = Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]);
            let w = WatertightRay::new(o, Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]));
            let inv = [p.inv[0][l], p.inv[1][l], p.inv[2][l]];
            let mut stack = [0u32; STACK];
            let mut sp = 1;
            stack[0] = root;
            'walk: while sp > 0 {
                sp -= 1;
                let code = stack[sp];
                if code & LEAF_BIT != 0 {
                    let (start, count) = leaf_range(code);
                    for i in start..start + count {
                        let v = &self.verts[3 * i..3 * i + 3];
                        let pt = |k: usize| Vec3::new(v[k][0], v[k][1], v[k][2]);
                        if TIES && !ANY && h.prim[l] != u32::MAX {
                            let tm = h.t[l];
                            if w.intersect(pt(0), pt(1), pt(2), tm * (1.0 + TIE_TOL)).is_some_and(|(t, _, _)| t >= tm * (1.0 - TIE_TOL)) {
                                ties |= 1 << l;
                            }
                        }
                        if let Some((t, b1, b2)) = w.intersect(pt(0), pt(1), pt(2), h.t[l]) {
                            if ANY {
                                blocked |= 1 << l;
                                break 'walk;
                            }
                            h.t[l] = t;
                            h.prim[l] = self.ids[i];
                            h.b1[l] = b1;
                            h.b2[l] = b2;
                        }
                    }
                    continue;
                }
                let node = &self.nodes[code as usize];
                for k in 0..2 {
                    let b = &node.boxes[k];
                    let mut tn = 0.0f32;
                    let mut tf = h.t[l];
                    for a in 0..3 {
                        // See `slab` of the SIMD walk: a NaN (the origin on a face of a slab
                        // the ray runs along) leaves the bounds as they are.
                        let (near, far) = if inv[a].is_sign_negative() { (b[a + 3], b[a]) } else { (b[a], b[a + 3]) };
                        tn = tn.max((near - o[a]) * inv[a]);
                        tf = tf.min((far - o[a]) * inv[a]);
                    }
                    if tn <= tf * if ANY { FAR_SLACK } else { HIT_SLACK } {
                        stack[sp] = node.child[k];
                        sp += 1;
                    }
                }
            }
        }
        if ANY {
            blocked
        } else {
            ties
        }
    }

    /// The exact test of the scalar tracer for the lanes of `lanes` (those where u, v or w
    /// came out zero: the scalar test goes to double precision there).
    #[cold]
    #[inline(never)]
    fn edge_lanes(&self, r: &Rays8, tri: usize, lanes: u8, t_max: &[f32; LANES]) -> [Option<(f32, f32, f32)>; LANES] {
        let v = &self.verts[3 * tri..3 * tri + 3];
        let pt = |k: usize| Vec3::new(v[k][0], v[k][1], v[k][2]);
        std::array::from_fn(|l| {
            if lanes & (1 << l) == 0 {
                return None;
            }
            let w = WatertightRay::new(Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]), Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]));
            w.intersect(pt(0), pt(1), pt(2), t_max[l])
        })
    }
}

/// The eight-wide walk, compiled once per instruction set (`$feat`). With `ANY`, lanes
/// retire at their first hit and the walk ends when none is left; returns the mask of
/// lanes that hit. Without, returns (with `TIES`) the lanes where a triangle was hit within
/// `TIE_TOL` of the lane's nearest hit so far, accepted or not: whichever of the two comes
/// second in the walk's order meets the other as the nearest so far (a box holding a hit
/// that close is entered: `HIT_SLACK` is wider than the triangle test's rounding). Lanes
/// that are not live carry t_max = -inf, which fails every box and stack test, so only the
/// triangle test needs the live mask.
#[cfg(target_arch = "x86_64")]
macro_rules! walk_simd {
    ($name:ident, $feat:literal) => {
        impl PacketBvh {
            /// # Safety
            /// The CPU must support the target features of this function.
            #[target_feature(enable = $feat)]
            unsafe fn $name<const ANY: bool, const TIES: bool>(&self, root: u32, r: &Rays8, active: u8, h: &mut Hits8) -> u8 {
                use std::arch::x86_64::*;
                let ld = |a: &[f32; LANES]| _mm256_loadu_ps(a.as_ptr());
                let o = [ld(&r.o[0]), ld(&r.o[1]), ld(&r.o[2])];
                let d = [ld(&r.d[0]), ld(&r.d[1]), ld(&r.d[2])];
                // `prep` in eight lanes: the slab test's inverse direction, and
                // `WatertightRay::new`'s permutation and shear, operation for operation.
                let sign = _mm256_set1_ps(-0.0);
                let abs = |x: __m256| _mm256_andnot_ps(sign, x);
                let one = _mm256_set1_ps(1.0);
                let inv = d.map(|x| _mm256_div_ps(one, x));
                let a = d.map(abs);
                let gt = |x: __m256, y: __m256| _mm256_cmp_ps::<_CMP_GT_OQ>(x, y);
                let (xy, xz, yz) = (gt(a[0], a[1]), gt(a[0], a[2]), gt(a[1], a[2]));
                let kz_is0 = _mm256_and_ps(xy, xz);
                let kz_is1 = _mm256_andnot_ps(xy, yz);
                let ki = |m: __m256, k: i32| _mm256_and_si256(_mm256_castps_si256(m), _mm256_set1_epi32(k));
                // kz = 0, 1 or 2; kx = next(kz), ky = next(kx), swapped when d[kz] < 0.
                let kz_m2 = _mm256_andnot_ps(_mm256_or_ps(kz_is0, kz_is1), _mm256_castsi256_ps(_mm256_set1_epi32(-1)));
                let kz = _mm256_or_si256(ki(kz_is1, 1), ki(kz_m2, 2));
                let kx0 = _mm256_or_si256(ki(kz_is0, 1), ki(kz_is1, 2));
                let ky0 = _mm256_or_si256(ki(kz_is0, 2), ki(kz_m2, 1));
                let pick = |m0: __m256, m1: __m256, v: &[__m256; 3]| _mm256_blendv_ps(_mm256_blendv_ps(v[2], v[1], m1), v[0], m0);
                let dkz = pick(kz_is0, kz_is1, &d);
                let swap = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(dkz, _mm256_setzero_ps()));
                let kx = _mm256_blendv_epi8(kx0, ky0, swap);
                let ky = _mm256_blendv_epi8(ky0, kx0, swap);
                let is_k = |k: __m256i, v: i32| _mm256_castsi256_ps(_mm256_cmpeq_epi32(k, _mm256_set1_epi32(v)));
                let (kx_is0, kx_is1, ky_is0, ky_is1) = (is_k(kx, 0), is_k(kx, 1), is_k(ky, 0), is_k(ky, 1));
                // 1 / d[kz]: the inverse the slab test already has.
                let sz = pick(kz_is0, kz_is1, &inv);
                let sx = _mm256_div_ps(pick(kx_is0, kx_is1, &d), dkz);
                let sy = _mm256_div_ps(pick(ky_is0, ky_is1, &d), dkz);
                let (okx, oky, okz) = (pick(kx_is0, kx_is1, &o), pick(ky_is0, ky_is1, &o), pick(kz_is0, kz_is1, &o));
                let zero_i = _mm256_setzero_si256();
                let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
                let mut live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_and_si256(_mm256_set1_epi32(active as i32), lane_bits), zero_i));
                let zero = _mm256_setzero_ps();
                let slack = _mm256_set1_ps(if ANY { FAR_SLACK } else { HIT_SLACK });
                let inf = _mm256_set1_ps(f32::INFINITY);
                let mut t_max = _mm256_blendv_ps(_mm256_set1_ps(f32::NEG_INFINITY), ld(&h.t), live);
                let mut hit_mask = 0u8;
                let mut ties = 0u8;
                // The closest hits' barycentrics and ids, kept in registers and stored at the end.
                let (mut hb1, mut hb2, mut hprim) = (ld(&h.b1), ld(&h.b2), _mm256_loadu_ps(h.prim.as_ptr() as *const f32));
                let verts = self.verts.as_ptr() as *const f32;
                // Entries: a code and the entry distances of the lanes that met its box (a
                // popped entry that no lane can still improve on is skipped).
                // The walk goes on to the nearer child it enters and pushes the other.
                // (Uninitialised: zeroing them was 1.3 % of the walks' instructions on veach-mis.)
                let mut stack = [MaybeUninit::<u32>::uninit(); STACK];
                let mut tns = [MaybeUninit::<__m256>::uninit(); STACK];
                let mut sp = 0;
                let mut code = root;
                'walk: loop {
                    if code & LEAF_BIT != 0 {
                        let (start, count) = leaf_range(code);
                        for i in start..start + count {
                            // One vertex's components in each lane's order, relative to the
                            // origin (a 256-bit load from the vertex: the padding keeps it in bounds).
                            let rel = |k: usize| {
                                let pv = _mm256_loadu_ps(verts.add(4 * (3 * i + k)));
                                (
                                    _mm256_sub_ps(_mm256_permutevar8x32_ps(pv, kx), okx),
                                    _mm256_sub_ps(_mm256_permutevar8x32_ps(pv, ky), oky),
                                    _mm256_sub_ps(_mm256_permutevar8x32_ps(pv, kz), okz),
                                )
                            };
                            let ((akx, aky, akz), (bkx, bky, bkz), (ckx, cky, ckz)) = (rel(0), rel(1), rel(2));
                            let ax = _mm256_sub_ps(akx, _mm256_mul_ps(sx, akz));
                            let ay = _mm256_sub_ps(aky, _mm256_mul_ps(sy, akz));
                            let bx = _mm256_sub_ps(bkx, _mm256_mul_ps(sx, bkz));
                            let by = _mm256_sub_ps(bky, _mm256_mul_ps(sy, bkz));
                            let cx = _mm256_sub_ps(ckx, _mm256_mul_ps(sx, ckz));
                            let cy = _mm256_sub_ps(cky, _mm256_mul_ps(sy, ckz));
                            let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
                            let vv = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
                            let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
                            // Off the edges (u, v, w all non-zero) the ray is inside iff their
                            // signs agree; a zero (or an underflowed product: harmless) sends the
                            // lane to the exact scalar test.
                            let on_edge = _mm256_cmp_ps::<_CMP_EQ_OQ>(_mm256_mul_ps(_mm256_mul_ps(u, vv), w), zero);
                            let mixed = _mm256_or_ps(_mm256_or_ps(_mm256_xor_ps(u, vv), _mm256_xor_ps(u, w)), on_edge);
                            let cand_v = _mm256_andnot_ps(mixed, live);
                            let cand = _mm256_movemask_ps(cand_v) as u8;
                            let edge = _mm256_movemask_ps(_mm256_and_ps(on_edge, live)) as u8;
                            // No branch on `cand`: with eight incoherent rays it goes either
                            // way, and a mispredicted branch costs more than the rest of the test.
                            // The lanes that hit as a vector mask (`ok_v`) and as bits (`m`): the
                            // blends below take the vector, so that t_max's chain from one
                            // triangle to the next does not go through the bits and back (a
                            // movemask, a broadcast and a compare: about 7 cycles a test).
                            let mut m;
                            let mut ok_v;
                            let (mut t, mut b1, mut b2) = (zero, zero, zero);
                            {
                                // det has the common sign; flipping t_scaled and t_max * det by it
                                // turns the scalar test's two cases into 0 < t_scaled' <= t_max * |det|.
                                let det = _mm256_add_ps(_mm256_add_ps(u, vv), w);
                                let t_scaled = _mm256_add_ps(
                                    _mm256_add_ps(_mm256_mul_ps(u, _mm256_mul_ps(sz, akz)), _mm256_mul_ps(vv, _mm256_mul_ps(sz, bkz))),
                                    _mm256_mul_ps(w, _mm256_mul_ps(sz, ckz)),
                                );
                                let sgn = _mm256_and_ps(det, sign);
                                let ts = _mm256_xor_ps(t_scaled, sgn);
                                let tmd = _mm256_xor_ps(_mm256_mul_ps(t_max, det), sgn);
                                let ok = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(ts, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(ts, tmd));
                                ok_v = _mm256_and_ps(ok, cand_v);
                                m = _mm256_movemask_ps(ok_v) as u8;
                                if TIES && !ANY {
                                    // Within TIE_TOL of the lane's nearest hit (t_max * |det| scaled).
                                    let near = _mm256_and_ps(
                                        _mm256_cmp_ps::<_CMP_GE_OQ>(ts, _mm256_mul_ps(tmd, _mm256_set1_ps(1.0 - TIE_TOL))),
                                        _mm256_cmp_ps::<_CMP_LE_OQ>(ts, _mm256_mul_ps(tmd, _mm256_set1_ps(1.0 + TIE_TOL))),
                                    );
                                    ties |= _mm256_movemask_ps(near) as u8 & cand & hit_mask;
                                }
                                // The closest-hit walk divides whether or not a lane hit: with
                                // incoherent rays `m != 0` is a coin toss, and the mispredicted
                                // branch cost more than the division.
                                if !ANY || m != 0 {
                                    let invd = _mm256_div_ps(one, det);
                                    t = _mm256_mul_ps(t_scaled, invd);
                                    // t > 0 (it may underflow).
                                    ok_v = _mm256_and_ps(ok_v, _mm256_cmp_ps::<_CMP_GT_OQ>(t, zero));
                                    m = _mm256_movemask_ps(ok_v) as u8;
                                    b1 = _mm256_mul_ps(vv, invd);
                                    b2 = _mm256_mul_ps(w, invd);
                                }
                            }
                            if edge != 0 {
                                let mut tm = [0.0f32; LANES];
                                _mm256_storeu_ps(tm.as_mut_ptr(), t_max);
                                let ex = self.edge_lanes(r, i, edge, &tm);
                                if TIES && !ANY && edge & hit_mask != 0 {
                                    // The exact test of the edge lanes that have a hit, out to TIE_TOL past it.
                                    let far = tm.map(|x| x * (1.0 + TIE_TOL));
                                    for (l, e) in self.edge_lanes(r, i, edge & hit_mask, &far).iter().enumerate() {
                                        if e.is_some_and(|(te, _, _)| te >= tm[l] * (1.0 - TIE_TOL)) {
                                            ties |= 1 << l;
                                        }
                                    }
                                }
                                let (mut ta, mut b1a, mut b2a) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
                                _mm256_storeu_ps(ta.as_mut_ptr(), t);
                                _mm256_storeu_ps(b1a.as_mut_ptr(), b1);
                                _mm256_storeu_ps(b2a.as_mut_ptr(), b2);
                                for (l, e) in ex.iter().enumerate() {
                                    if let Some((te, b1e, b2e)) = *e {
                                        (ta[l], b1a[l], b2a[l]) = (te, b1e, b2e);
                                        m |= 1 << l;
                                    }
                                }
                                t = ld(&ta);
                                b1 = ld(&b1a);
                                b2 = ld(&b2a);
                                ok_v = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_and_si256(_mm256_set1_epi32(m as i32), lane_bits), zero_i));
                            }
                            if ANY && m == 0 {
                                continue;
                            }
                            let ok = ok_v;
                            hit_mask |= m;
                            if ANY {
                                live = _mm256_andnot_ps(ok, live);
                                t_max = _mm256_blendv_ps(t_max, _mm256_set1_ps(f32::NEG_INFINITY), ok);
                                if hit_mask == active {
                                    return hit_mask;
                                }
                                continue;
                            }
                            t_max = _mm256_blendv_ps(t_max, t, ok);
                            // The closest-hit walk blends barycentrics and ids in on every test,
                            // hit or not (no branch).
                            let id = _mm256_castsi256_ps(_mm256_set1_epi32(*self.ids.get_unchecked(i) as i32));
                            hb1 = _mm256_blendv_ps(hb1, b1, ok);
                            hb2 = _mm256_blendv_ps(hb2, b2, ok);
                            hprim = _mm256_blendv_ps(hprim, id, ok);
                        }
                    } else {
                        let node = self.nodes.get_unchecked(code as usize);
                        let test = |b: &[f32; 6]| {
                            // Each slab's near and far planes by the sign of the inverse direction
                            // (its sign bit selects). A zero direction component gives an infinite
                            // inverse: then a plane off the origin is at -inf or +inf as it should
                            // be, and one through the origin at NaN, which the max and min chains
                            // below pass over (they return their second operand on a NaN).
                            let slab = |a: usize| {
                                let (lo, hi) = (_mm256_set1_ps(b[a]), _mm256_set1_ps(b[a + 3]));
                                let near = _mm256_mul_ps(_mm256_sub_ps(_mm256_blendv_ps(lo, hi, inv[a]), o[a]), inv[a]);
                                let far = _mm256_mul_ps(_mm256_sub_ps(_mm256_blendv_ps(hi, lo, inv[a]), o[a]), inv[a]);
                                (near, far)
                            };
                            let ((nx, fx), (ny, fy), (nz, fz)) = (slab(0), slab(1), slab(2));
                            let tn = _mm256_max_ps(nx, _mm256_max_ps(ny, _mm256_max_ps(nz, zero)));
                            let tf = _mm256_mul_ps(_mm256_min_ps(fx, _mm256_min_ps(fy, _mm256_min_ps(fz, t_max))), slack);
                            let m = _mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf);
                            // Lanes that miss the box enter it at infinity.
                            (_mm256_movemask_ps(m), _mm256_blendv_ps(inf, tn, m))
                        };
                        let (m0, tn0) = test(&node.boxes[0]);
                        let (m1, tn1) = test(&node.boxes[1]);
                        if ANY {
                            // Shadow rays toward one light take much the same way through the
                            // tree: here branches predict well, and beat the selects below.
                            match (m0 != 0, m1 != 0) {
                                (true, true) => {
                                    stack.get_unchecked_mut(sp).write(node.child[1]);
                                    tns.get_unchecked_mut(sp).write(tn1);
                                    sp += 1;
                                    code = node.child[0];
                                    continue 'walk;
                                }
                                (true, false) => {
                                    code = node.child[0];
                                    continue 'walk;
                                }
                                (false, true) => {
                                    code = node.child[1];
                                    continue 'walk;
                                }
                                (false, false) => {}
                            }
                        } else if m0 | m1 != 0 {
                            // Into the nearer child entered (the one most of the lanes meeting
                            // both enter first); the other is pushed, and kept when entered too.
                            // Selects, not branches: which children incoherent rays enter is a
                            // coin toss.
                            let both = (m0 & m1) as u32;
                            let first1 =
                                m0 == 0 || 2 * (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(tn1, tn0)) as u32 & both).count_ones() > both.count_ones();
                            let (near, far) = if first1 { (node.child[1], node.child[0]) } else { (node.child[0], node.child[1]) };
                            stack.get_unchecked_mut(sp).write(far);
                            tns.get_unchecked_mut(sp).write(_mm256_blendv_ps(tn1, tn0, _mm256_castsi256_ps(_mm256_set1_epi32(-(first1 as i32)))));
                            sp += (m0 != 0 && m1 != 0) as usize;
                            code = near;
                            continue 'walk;
                        }
                    }
                    // Pop the next entry that some lane can still improve on.
                    loop {
                        if sp == 0 {
                            break 'walk;
                        }
                        sp -= 1;
                        if _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tns.get_unchecked(sp).assume_init(), _mm256_mul_ps(t_max, slack))) != 0 {
                            code = stack.get_unchecked(sp).assume_init();
                            break;
                        }
                    }
                }
                if !ANY {
                    // Lanes without a hit keep their own t_max (inactive ones went to -inf);
                    // `prim`, `b1` and `b2` were only ever written where a lane hit.
                    let hit = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_and_si256(_mm256_set1_epi32(hit_mask as i32), lane_bits), zero_i));
                    _mm256_storeu_ps(h.t.as_mut_ptr(), _mm256_blendv_ps(ld(&r.t_max), t_max, hit));
                    _mm256_storeu_ps(h.b1.as_mut_ptr(), hb1);
                    _mm256_storeu_ps(h.b2.as_mut_ptr(), hb2);
                    _mm256_storeu_ps(h.prim.as_mut_ptr() as *mut f32, hprim);
                    return ties;
                }
                hit_mask
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
walk_simd!(walk_avx2, "avx2,popcnt");
#[cfg(target_arch = "x86_64")]
walk_simd!(walk_avx512, "avx2,popcnt,avx512f,avx512vl");

/// Relative distance along a ray within which a sphere's hit may lie outside what the scene
/// BVH's box test of it admits (its f32 box and slab test round; they are accurate to a few
/// 1e-7): `PacketSpheres` flags such lanes.
const SPHERE_BOX_TOL: f64 = 2e-5;

/// Analytic spheres against eight rays at once, for scenes of a few spheres beside their
/// triangles: every sphere is tested on every lane (no hierarchy), with the operations of
/// `Sphere::intersect` in f64 lanes (AVX), so that each lane's distance and decisions are
/// the scalar test's bit for bit. The scene's BVH tests its triangles first and then its
/// spheres up to the nearest triangle's distance, in its own order, skipping those whose box
/// its walk does not enter; what a lane here cannot be sure it would decide the same is
/// flagged (`unsure` masks) for the caller to trace again through the scene's BVH.
pub struct PacketSpheres {
    spheres: Vec<Sphere>,
    /// Per sphere: radius and radius squared (f64, as the scalar test computes them), and
    /// the rounding of its f32 box (`SPHERE_BOX_TOL` of its extent).
    r: Vec<f64>,
    rr: Vec<f64>,
    margin: Vec<f64>,
    /// Radius squared in f32, widened by `CULL_TOL` (the f32 cull of `test_avx2`).
    rr_cull: Vec<f32>,
    /// Radius squared in f32 (the reach test of `test_avx2`).
    rr32: Vec<f32>,
    isa: Isa,
}

/// Relative slack of the f32 cull that skips a sphere on the lanes whose ray passes surely
/// wide of it: its rounding is below 2e-6 of |o - c|^2 |d|^2, so a ray culled with this
/// slack has the f64 test's discriminant negative (a miss) by a wide margin.
const CULL_TOL: f32 = 1e-5;

/// Relative widening of |d|^2 t_max in the f32 reach test that skips a sphere on the lanes
/// whose ray meets it only beyond t_max or behind the origin (`test_avx2`): far above the
/// product's rounding. Shadow rays end 1e-4 short of the light.
const REACH_TOL: f32 = 1e-5;

/// Per lane, the nearest sphere a packet met (index into the spheres, `u32::MAX`: none).
pub type SphereIds = [u32; LANES];

impl PacketSpheres {
    pub fn new(spheres: &[Sphere]) -> PacketSpheres {
        let r: Vec<f64> = spheres.iter().map(|s| s.radius as f64).collect();
        PacketSpheres {
            rr: r.iter().map(|r| r * r).collect(),
            margin: spheres.iter().map(|s| SPHERE_BOX_TOL * (s.center.abs().max_element() + s.radius.abs()) as f64).collect(),
            rr_cull: spheres.iter().map(|s| s.radius * s.radius * (1.0 + 10.0 * CULL_TOL)).collect(),
            rr32: spheres.iter().map(|s| s.radius * s.radius).collect(),
            r,
            spheres: spheres.to_vec(),
            isa: Isa::detect(),
        }
    }

    pub fn len(&self) -> usize {
        self.spheres.len()
    }

    pub fn is_empty(&self) -> bool {
        self.spheres.is_empty()
    }

    /// After the triangles gave each lane its nearest distance `t` (the ray's t_max where
    /// none was hit): the nearest sphere met in (0, t) on the lanes of `active`, as the scene's
    /// BVH finds it; `t` is set to its distance. Returns the spheres met and the unsure lanes:
    /// two spheres at one f32 distance (the scene BVH's order decides), or the hit within
    /// rounding of the sphere's box (its walk might not enter it).
    pub fn nearest(&self, r: &Rays8, active: u8, t: &mut [f32; LANES]) -> (SphereIds, u8) {
        if active == 0 {
            return ([u32::MAX; LANES], 0);
        }
        #[cfg(target_arch = "x86_64")]
        match self.isa {
            // SAFETY: `isa` is at most what the CPU runs (`Isa::detect`).
            Isa::Avx512 => return unsafe { self.test_avx512::<false>(r, active, t) },
            // SAFETY: as above.
            Isa::Avx2 => return unsafe { self.test_avx2::<false>(r, active, t) },
            Isa::Portable => {}
        }
        self.test_lanes::<false>(r, active, t)
    }

    /// The lanes of `active` whose ray meets a sphere in (0, t_max), and the unsure ones
    /// among them (every sphere met within rounding of its box).
    pub fn occluded(&self, r: &Rays8, active: u8) -> (u8, u8) {
        if active == 0 {
            return (0, 0);
        }
        let mut t = r.t_max;
        #[cfg(target_arch = "x86_64")]
        if self.isa > Isa::Portable {
            // SAFETY: `isa` is at most what the CPU runs (`Isa::detect`).
            let (ids, unsure) = unsafe {
                if self.isa == Isa::Avx512 {
                    self.test_avx512::<true>(r, active, &mut t)
                } else {
                    self.test_avx2::<true>(r, active, &mut t)
                }
            };
            return (lanes_of(&ids), unsure);
        }
        let (ids, unsure) = self.test_lanes::<true>(r, active, &mut t);
        (lanes_of(&ids), unsure)
    }

    /// Whether a hit at `t` lies within rounding of sphere `k`'s box (`oc`: origin - center).
    #[inline(always)]
    fn near_box(&self, k: usize, oc: [f64; 3], d: [f64; 3], t: f64) -> bool {
        let dmax = d[0].abs().max(d[1].abs()).max(d[2].abs());
        let m = (0..3).map(|a| (oc[a] + t * d[a]).abs()).fold(0.0, f64::max);
        m > self.r[k] - self.margin[k] - SPHERE_BOX_TOL * t * dmax
    }

    /// Lane by lane through `Sphere::intersect` (CPUs without AVX2, and the reference of the
    /// tests). With `ANY`, a lane's id is that of a sphere it meets, any.
    fn test_lanes<const ANY: bool>(&self, r: &Rays8, active: u8, t: &mut [f32; LANES]) -> (SphereIds, u8) {
        let (mut ids, mut unsure) = ([u32::MAX; LANES], 0u8);
        for l in (0..LANES).filter(|l| active & (1 << l) != 0) {
            let o = Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]);
            let d = Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]);
            let t_max = t[l];
            let (mut best, mut near, mut sure_any) = (f32::INFINITY, false, false);
            for (k, s) in self.spheres.iter().enumerate() {
                let Some(th) = s.intersect(o, d, t_max) else { continue };
                let nb = self.near_box(k, (o - s.center).as_dvec3().to_array(), d.as_dvec3().to_array(), th as f64);
                if ANY {
                    ids[l] = k as u32;
                    sure_any |= !nb;
                } else if th < best {
                    (best, near, ids[l]) = (th, nb, k as u32);
                } else if th == best {
                    near = true;
                }
            }
            if ANY {
                near = ids[l] != u32::MAX && !sure_any;
            } else if ids[l] != u32::MAX {
                t[l] = best;
            }
            unsure |= (near as u8) << l;
        }
        (ids, unsure)
    }
}

fn lanes_of(ids: &SphereIds) -> u8 {
    (0..LANES).filter(|&l| ids[l] != u32::MAX).fold(0, |m, l| m | 1 << l)
}

/// `PacketSpheres::test_avx2` and its AVX-512VL copy (32 registers, broadcast operands):
/// one body.
#[cfg(target_arch = "x86_64")]
macro_rules! sphere_test_simd {
    ($name:ident, $feat:literal) => {
        /// `test_lanes` in two halves of four f64 lanes: `Sphere::intersect`'s operations in
        /// its order (no fused multiply-adds), so the same bits.
        ///
        /// # Safety
        /// The CPU must support the target features of this function.
        #[target_feature(enable = $feat)]
        unsafe fn $name<const ANY: bool>(&self, r: &Rays8, active: u8, t: &mut [f32; LANES]) -> (SphereIds, u8) {
            use std::arch::x86_64::*;
            let sign = _mm256_set1_pd(-0.0);
            let abs = |x: __m256d| _mm256_andnot_pd(sign, x);
            let zero = _mm256_setzero_pd();
            let dot = |a: [__m256d; 3], b: [__m256d; 3]| {
                _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(a[0], b[0]), _mm256_mul_pd(a[1], b[1])), _mm256_mul_pd(a[2], b[2]))
            };
            // Per half, where a lane of it passes a sphere's cull (rarely: they are made there, not
            // ahead for every call): origin (f32: the scalar test subtracts the center in f32),
            // direction, |d|^2, its largest component, t_max and the live lanes.
            // (Not `map`ped: `array::map` stayed a call, with the closures' AVX code out of line
            // behind it, 2.5 % of veach-mis's instructions.)
            let half_o = |h: usize| {
                let f = |a: usize| _mm_loadu_ps(r.o[a].as_ptr().add(4 * h));
                [f(0), f(1), f(2)]
            };
            let half_d = |h: usize| {
                let f = |a: usize| _mm256_cvtps_pd(_mm_loadu_ps(r.d[a].as_ptr().add(4 * h)));
                [f(0), f(1), f(2)]
            };
            let max_abs = |d: [__m256d; 3]| _mm256_max_pd(_mm256_max_pd(abs(d[0]), abs(d[1])), abs(d[2]));
            let half_t = |h: usize| _mm256_cvtps_pd(_mm_loadu_ps(t.as_ptr().add(4 * h)));
            let lane_bits = _mm256_setr_epi64x(1, 2, 4, 8);
            let half_mask = |bits: u8, h: usize| {
                let m = _mm256_set1_epi64x(((bits >> (4 * h)) & 0xf) as i64);
                _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_and_si256(m, lane_bits), lane_bits))
            };
            // The lanes still to test (with ANY, a lane surely blocked leaves).
            let mut live = active;
            // Whether any lane reached the f64 test (else nothing was met).
            let mut tested = false;
            // The cull's operands: eight lanes of f32.
            let o8 = [_mm256_loadu_ps(r.o[0].as_ptr()), _mm256_loadu_ps(r.o[1].as_ptr()), _mm256_loadu_ps(r.o[2].as_ptr())];
            let d8 = [_mm256_loadu_ps(r.d[0].as_ptr()), _mm256_loadu_ps(r.d[1].as_ptr()), _mm256_loadu_ps(r.d[2].as_ptr())];
            let dot8 =
                |a: [__m256; 3], b: [__m256; 3]| _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])), _mm256_mul_ps(a[2], b[2]));
            let a8 = dot8(d8, d8);
            // |d|^2 t_max, widened by REACH_TOL (infinite where t_max is: then nothing is beyond it),
            // for the reach test below.
            let reach_tol = _mm256_set1_ps(1.0 + REACH_TOL);
            let at8 = _mm256_mul_ps(_mm256_mul_ps(a8, _mm256_loadu_ps(t.as_ptr())), reach_tol);
            let mut best = [_mm256_set1_pd(f64::INFINITY); 2];
            let mut best_id = [_mm256_set1_pd(f64::from_bits(u32::MAX as u64)); 2];
            let mut near = [zero; 2];
            // With ANY: lanes with a hit outside rounding of the box / with any hit.
            let mut sure = [zero; 2];
            let mut any = [zero; 2];
            for (k, s) in self.spheres.iter().enumerate() {
                let c = [_mm_set1_ps(s.center.x), _mm_set1_ps(s.center.y), _mm_set1_ps(s.center.z)];
                let (rk, rr) = (_mm256_set1_pd(self.r[k]), _mm256_set1_pd(self.rr[k]));
                let tol = _mm256_sub_pd(rk, _mm256_set1_pd(self.margin[k]));
                let id = _mm256_set1_pd(f64::from_bits(k as u64));
                // Cull: the lanes whose ray passes farther from the center than the radius, by a
                // margin above the rounding (|(o - c) x d|^2 > |d|^2 (r^2 + tol |o - c|^2)).
                let oc8_at = |ax: usize| _mm256_sub_ps(o8[ax], _mm256_set1_ps(s.center[ax]));
                let oc8 = [oc8_at(0), oc8_at(1), oc8_at(2)];
                let cross = |i: usize, j: usize| _mm256_sub_ps(_mm256_mul_ps(oc8[i], d8[j]), _mm256_mul_ps(oc8[j], d8[i]));
                let cr = [cross(1, 2), cross(2, 0), cross(0, 1)];
                let oc2 = dot8(oc8, oc8);
                let cr2 = dot8(cr, cr);
                let bound = _mm256_mul_ps(a8, _mm256_add_ps(_mm256_set1_ps(self.rr_cull[k]), _mm256_mul_ps(_mm256_set1_ps(CULL_TOL), oc2)));
                let near_lanes = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(cr2, bound)) as u8;
                let mut lanes = near_lanes & live;
                // (Shadow rays only: the closest-hit rays it spared too few f64 tests to pay.)
                if ANY && lanes != 0 {
                    // Out of reach: the lanes whose ray meets the sphere only past t_max (a shadow
                    // ray toward a point on it) or only behind its origin. In units of |d|^2 t the
                    // roots are -b -+ sqrt(X), X = r^2 |d|^2 - |oc x d|^2 (= |d|^2 disc). With
                    // E = |oc|^2 |d|^2 and u = 2^-24, the rounding of X is below
                    // 8u (|oc x d| sqrt(E) + |oc x d|^2 + r^2 |d|^2) + 16u^2 E (the cross product's
                    // components are off by 2u |oc||d| each), that of b below 3u sqrt(E). The bound
                    // `s` on sqrt(X) takes four times the former under the root, and 1e-6 sqrt(E) for
                    // the latter and the f64 test's rounding (below 1e-8 sqrt(E)). Where a lane is out
                    // of reach by s, the f64 test finds no root in (0, t_max): skipping it keeps
                    // every bit.
                    let ru = _mm256_set1_ps(32.0 * f32::EPSILON * 0.5);
                    let rra = _mm256_mul_ps(_mm256_set1_ps(self.rr32[k]), a8);
                    let e = _mm256_mul_ps(oc2, a8);
                    let se = _mm256_sqrt_ps(e);
                    let dx = _mm256_add_ps(
                        _mm256_mul_ps(ru, _mm256_add_ps(_mm256_mul_ps(_mm256_sqrt_ps(cr2), se), _mm256_add_ps(cr2, rra))),
                        _mm256_mul_ps(_mm256_mul_ps(ru, ru), e),
                    );
                    let s = _mm256_sqrt_ps(_mm256_max_ps(_mm256_add_ps(_mm256_sub_ps(rra, cr2), dx), _mm256_setzero_ps()));
                    let s = _mm256_add_ps(_mm256_mul_ps(s, _mm256_set1_ps(1.0 + 1e-6)), _mm256_mul_ps(se, _mm256_set1_ps(1e-6)));
                    let nb = _mm256_xor_ps(dot8(oc8, d8), _mm256_set1_ps(-0.0));
                    let past = _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_sub_ps(nb, s), at8);
                    let behind = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_add_ps(nb, s), _mm256_setzero_ps());
                    lanes &= !(_mm256_movemask_ps(_mm256_or_ps(past, behind)) as u8);
                }
                for h in 0..2 {
                    if (lanes >> (4 * h)) & 0xf == 0 {
                        continue;
                    }
                    tested = true;
                    let (o, d) = (half_o(h), half_d(h));
                    let a = dot(d, d);
                    let oc_at = |ax: usize| _mm256_cvtps_pd(_mm_sub_ps(o[ax], c[ax]));
                    let oc = [oc_at(0), oc_at(1), oc_at(2)];
                    let b = dot(oc, d);
                    let ba = _mm256_div_pd(b, a);
                    let l_at = |ax: usize| _mm256_sub_pd(oc[ax], _mm256_mul_pd(d[ax], ba));
                    let l = [l_at(0), l_at(1), l_at(2)];
                    let disc = _mm256_sub_pd(rr, dot(l, l));
                    let go = _mm256_and_pd(half_mask(live, h), _mm256_cmp_pd::<_CMP_GE_OQ>(disc, zero));
                    if _mm256_movemask_pd(go) == 0 {
                        continue;
                    }
                    let cc = _mm256_sub_pd(dot(oc, oc), rr);
                    let root = _mm256_sqrt_pd(_mm256_mul_pd(a, disc));
                    // b.signum() (b is not NaN where the lane goes on).
                    let sgn = _mm256_or_pd(_mm256_and_pd(b, sign), _mm256_set1_pd(1.0));
                    let q = _mm256_xor_pd(_mm256_add_pd(b, _mm256_mul_pd(sgn, root)), sign);
                    let q0 = _mm256_cmp_pd::<_CMP_EQ_OQ>(q, zero);
                    let t0 = _mm256_andnot_pd(q0, _mm256_div_pd(cc, q));
                    let t1 = _mm256_andnot_pd(q0, _mm256_div_pd(q, a));
                    let swap = _mm256_cmp_pd::<_CMP_GT_OQ>(t0, t1);
                    let (lo, hi) = (_mm256_blendv_pd(t0, t1, swap), _mm256_blendv_pd(t1, t0, swap));
                    let t_max = half_t(h);
                    let within = |x| _mm256_and_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(x, zero), _mm256_cmp_pd::<_CMP_LT_OQ>(x, t_max));
                    let (ok0, ok1) = (within(lo), within(hi));
                    let th = _mm256_blendv_pd(hi, lo, ok0);
                    let hit = _mm256_and_pd(go, _mm256_or_pd(ok0, ok1));
                    if _mm256_movemask_pd(hit) == 0 {
                        continue;
                    }
                    // `near_box`.
                    let p_at = |ax: usize| abs(_mm256_add_pd(oc[ax], _mm256_mul_pd(th, d[ax])));
                    let p = [p_at(0), p_at(1), p_at(2)];
                    let m = _mm256_max_pd(_mm256_max_pd(_mm256_max_pd(p[0], p[1]), p[2]), zero);
                    let lim = _mm256_sub_pd(tol, _mm256_mul_pd(_mm256_mul_pd(_mm256_set1_pd(SPHERE_BOX_TOL), th), max_abs(d)));
                    let nb = _mm256_cmp_pd::<_CMP_GT_OQ>(m, lim);
                    if ANY {
                        any[h] = _mm256_or_pd(any[h], hit);
                        sure[h] = _mm256_or_pd(sure[h], _mm256_andnot_pd(nb, hit));
                        best_id[h] = _mm256_blendv_pd(best_id[h], id, hit);
                        // A lane surely blocked needs no further sphere.
                        live &= !((_mm256_movemask_pd(sure[h]) as u8 & 0xf) << (4 * h));
                        continue;
                    }
                    // The distance as f32 decides, as the scalar walk's t_max is f32.
                    let th32 = _mm256_cvtps_pd(_mm256_cvtpd_ps(th));
                    let closer = _mm256_and_pd(hit, _mm256_cmp_pd::<_CMP_LT_OQ>(th32, best[h]));
                    let tie = _mm256_and_pd(hit, _mm256_cmp_pd::<_CMP_EQ_OQ>(th32, best[h]));
                    best[h] = _mm256_blendv_pd(best[h], th32, closer);
                    best_id[h] = _mm256_blendv_pd(best_id[h], id, closer);
                    near[h] = _mm256_or_pd(_mm256_blendv_pd(near[h], nb, closer), tie);
                }
            }
            let mut ids = [u32::MAX; LANES];
            let mut unsure = 0u8;
            if !tested {
                return (ids, unsure);
            }
            for h in 0..2 {
                let mut id = [0u64; 4];
                _mm256_storeu_pd(id.as_mut_ptr() as *mut f64, best_id[h]);
                let mut bt = [0.0f64; 4];
                _mm256_storeu_pd(bt.as_mut_ptr(), best[h]);
                for j in 0..4 {
                    ids[4 * h + j] = id[j] as u32;
                    if !ANY && id[j] as u32 != u32::MAX {
                        t[4 * h + j] = bt[j] as f32;
                    }
                }
                let flags = if ANY { _mm256_andnot_pd(sure[h], any[h]) } else { near[h] };
                unsure |= ((_mm256_movemask_pd(flags) as u8) & 0xf) << (4 * h);
            }
            (ids, unsure)
        }
    };
}

#[cfg(target_arch = "x86_64")]
impl PacketSpheres {
    sphere_test_simd!(test_avx2, "avx2");
    sphere_test_simd!(test_avx512, "avx2,avx512f,avx512vl");
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::rng::Pcg32;

    fn brute(tris: &[[Vec3; 3]], o: Vec3, d: Vec3, t_max: f32) -> Option<(f32, u32, f32, f32)> {
        let w = WatertightRay::new(o, d);
        let mut best = None;
        let mut tm = t_max;
        for (i, t) in tris.iter().enumerate() {
            if let Some((th, b1, b2)) = w.intersect(t[0], t[1], t[2], tm) {
                tm = th;
                best = Some((th, i as u32, b1, b2));
            }
        }
        best
    }

    fn random_mesh(rng: &mut Pcg32, n: usize) -> Vec<[Vec3; 3]> {
        let mut p = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
        (0..n)
            .map(|_| {
                let c = p();
                let e1 = p() * 0.2;
                let e2 = p() * 0.2;
                [c, c + e1, c + e2]
            })
            .collect()
    }

    /// Every ISA path this CPU runs, down to the portable one.
    /// Lane `l` of `r` becomes the ray (o, d) up to `t_max`.
    fn set_lane(r: &mut Rays8, l: usize, o: Vec3, d: Vec3, t_max: f32) {
        for a in 0..3 {
            r.o[a][l] = o[a];
            r.d[a][l] = d[a];
        }
        r.t_max[l] = t_max;
    }

    fn isas() -> impl Iterator<Item = Isa> {
        [Isa::Avx512, Isa::Avx2, Isa::Portable].into_iter().filter(|&i| i <= Isa::cpu())
    }

    /// Closest hits and occlusion of one packet against brute force, lane by lane: the same
    /// triangle, t and barycentrics bit for bit (or a tie in t with another triangle).
    fn check(bvh: &PacketBvh, tris: &[[Vec3; 3]], r: &Rays8, active: u8) {
        let h = bvh.intersect(r, active);
        let occ = bvh.occluded(r, active);
        for l in 0..LANES {
            let o = Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]);
            let d = Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]);
            if active & (1 << l) == 0 {
                assert_eq!(h.prim[l], u32::MAX);
                assert_eq!(occ & (1 << l), 0);
                continue;
            }
            let want = brute(tris, o, d, r.t_max[l]);
            assert_eq!(want.is_some(), occ & (1 << l) != 0, "occlusion of lane {l} ({:?})", bvh.isa);
            match want {
                None => assert_eq!((h.prim[l], h.t[l]), (u32::MAX, r.t_max[l]), "lane {l}: false hit ({:?})", bvh.isa),
                Some((t, i, b1, b2)) => {
                    assert_ne!(h.prim[l], u32::MAX, "lane {l}: missed ({:?})", bvh.isa);
                    if h.prim[l] == i {
                        assert_eq!((h.t[l], h.b1[l], h.b2[l]), (t, b1, b2));
                    } else {
                        assert!((h.t[l] - t).abs() <= 1e-6 * t.max(1e-3), "not a tie: {} vs {t}", h.t[l]);
                    }
                }
            }
        }
    }

    fn run(bvh: &PacketBvh, tris: &[[Vec3; 3]], rng: &mut Pcg32, packets: usize) {
        for _ in 0..packets {
            let mut r = Rays8::default();
            let active = (rng.next_u32() & 0xff) as u8 | 1;
            for l in 0..LANES {
                let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0 - Vec3::splat(1.5);
                let mut d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
                if l == 3 {
                    d.y = 0.0; // axis-parallel components
                }
                let d = d.normalize();
                set_lane(&mut r, l, o, d, if rng.next_f32() < 0.3 { rng.next_f32() * 2.0 } else { f32::INFINITY });
            }
            check(bvh, tris, &r, active);
        }
    }

    /// The binned SAH build as it was before its sweeps skipped empty bins and the sides'
    /// bounds came from the bins (a sweep over all 32 bins, folds over each side): the
    /// reference the tree must equal node for node, as the images depend on its order.
    fn dense_reference(tris: &[[Vec3; 3]]) -> (Vec<Node>, Option<u32>, Vec<u32>) {
        struct Dense<'a> {
            bounds: &'a [Aabb],
            centroids: &'a [Vec3],
            nodes: Vec<Node>,
            order: Vec<u32>,
        }
        impl Dense<'_> {
            fn fold(&self, lo: usize, hi: usize) -> Aabb {
                self.order[lo..hi].iter().fold(Aabb::EMPTY, |acc, &i| acc.union(self.bounds[i as usize]))
            }
            fn rec(&mut self, lo: usize, hi: usize, bb: Aabb, depth: usize) -> u32 {
                let Some(mid) = self.split(lo, hi, bb, depth) else { return leaf(lo, hi - lo) };
                let idx = self.nodes.len();
                self.nodes.push(Node { boxes: [[0.0; 6]; 2], child: [0; 2] });
                for (k, (a, b)) in [(lo, mid), (mid, hi)].into_iter().enumerate() {
                    let cbb = self.fold(a, b);
                    let code = self.rec(a, b, cbb, depth + 1);
                    self.nodes[idx].boxes[k] = box6(cbb);
                    self.nodes[idx].child[k] = code;
                }
                idx as u32
            }
            fn split(&mut self, lo: usize, hi: usize, bb: Aabb, depth: usize) -> Option<usize> {
                let n = hi - lo;
                if n <= 1 {
                    return None;
                }
                let cb = self.order[lo..hi].iter().fold(Aabb::EMPTY, |b, &i| b.grow(self.centroids[i as usize]));
                let split = if depth >= MAX_DEPTH { None } else { self.best_split(lo, hi, &cb) };
                Some(match split {
                    Some((cost, axis, bin)) => {
                        if n <= MAX_LEAF && n as f32 <= NODE_COST + cost / bb.surface_area().max(f32::MIN_POSITIVE) {
                            return None;
                        }
                        let (cmin, scale) = (cb.min[axis], BINS as f32 / cb.extent()[axis]);
                        let mut l = lo;
                        for k in lo..hi {
                            if bin_index(self.centroids[self.order[k] as usize][axis], cmin, scale) < bin {
                                self.order.swap(k, l);
                                l += 1;
                            }
                        }
                        l
                    }
                    None if n <= MAX_LEAF => return None,
                    None => {
                        let axis = cb.extent().max_position();
                        let c = self.centroids;
                        self.order[lo..hi].select_nth_unstable_by(n / 2, |&a, &b| c[a as usize][axis].total_cmp(&c[b as usize][axis]));
                        lo + n / 2
                    }
                })
            }
            fn best_split(&self, lo: usize, hi: usize, cb: &Aabb) -> Option<(f32, usize, usize)> {
                let ext = cb.extent();
                let mut bin_b = [[Aabb::EMPTY; BINS]; 3];
                let mut bin_n = [[0u32; BINS]; 3];
                for &i in &self.order[lo..hi] {
                    let c = self.centroids[i as usize];
                    for axis in (0..3).filter(|&a| ext[a] > 0.0) {
                        let k = bin_index(c[axis], cb.min[axis], BINS as f32 / ext[axis]);
                        bin_b[axis][k] = bin_b[axis][k].union(self.bounds[i as usize]);
                        bin_n[axis][k] += 1;
                    }
                }
                let mut best: Option<(f32, usize, usize)> = None;
                for axis in (0..3).filter(|&a| ext[a] > 0.0) {
                    let mut right = [0.0f32; BINS];
                    let (mut acc, mut cnt) = (Aabb::EMPTY, 0u32);
                    for k in (1..BINS).rev() {
                        acc = acc.union(bin_b[axis][k]);
                        cnt += bin_n[axis][k];
                        right[k] = if cnt == 0 { f32::INFINITY } else { acc.surface_area() * cnt as f32 };
                    }
                    let (mut acc, mut cnt) = (Aabb::EMPTY, 0u32);
                    for k in 1..BINS {
                        acc = acc.union(bin_b[axis][k - 1]);
                        cnt += bin_n[axis][k - 1];
                        if cnt == 0 || !right[k].is_finite() {
                            continue;
                        }
                        let cost = acc.surface_area() * cnt as f32 + right[k];
                        if best.is_none_or(|b| cost < b.0) {
                            best = Some((cost, axis, k));
                        }
                    }
                }
                best
            }
        }
        let bounds: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(t)).collect();
        let centroids: Vec<Vec3> = bounds.iter().map(|b| b.center()).collect();
        let mut d = Dense { bounds: &bounds, centroids: &centroids, nodes: Vec::new(), order: (0..tris.len() as u32).collect() };
        let root = (!tris.is_empty()).then(|| {
            let bb = d.fold(0, tris.len());
            d.rec(0, tris.len(), bb, 0)
        });
        (d.nodes, root, d.order)
    }

    /// Nodes as bits, in depth-first order from `code` (the parallel build numbers them
    /// otherwise than the serial reference). A zero bound counts as +0: which sign a box
    /// keeps depends on the order of the unions (min keeps its first operand on a tie), and
    /// a walk only compares distances computed from bounds, where -0 and +0 are one value.
    fn tree_bits(nodes: &[Node], code: u32, out: &mut Vec<u32>) {
        out.push(code & LEAF_BIT);
        if code & LEAF_BIT != 0 {
            out.push(code);
            return;
        }
        let nd = &nodes[code as usize];
        out.extend(nd.boxes.iter().flatten().map(|v| (v + 0.0).to_bits()));
        for c in nd.child {
            tree_bits(nodes, c, out);
        }
    }

    #[test]
    fn bin_index_is_the_saturating_usize_conversion() {
        let xs = [f32::NAN, f32::NEG_INFINITY, -1e30, -1.0, -0.5, -0.0, 0.0, 0.3, 1.0, 30.99, 31.0, 31.5, 32.0, 32.001, 1e9, 3e9, 1e30, f32::INFINITY];
        for x in xs {
            assert_eq!(bin_index(x, 0.0, 1.0), (x as usize).min(BINS - 1), "{x}");
        }
    }

    #[test]
    fn build_equals_the_dense_sweep_reference() {
        let mut rng = Pcg32::new(11, 5);
        let mut meshes: Vec<Vec<[Vec3; 3]>> = [0, 1, 2, 3, 17, 300, 5000, PARALLEL_MIN + 3000].iter().map(|&n| random_mesh(&mut rng, n)).collect();
        // A grid of quads (coincident centroids along an axis, empty bins between rows) and
        // a stack of identical triangles (median splits).
        let grid = (0..40 * 40).flat_map(|k| {
            let p = |a: i32, b: i32| Vec3::new((k % 40 + a) as f32 * 0.25, (k / 40 + b) as f32 * 0.25, 1.0);
            [[p(0, 0), p(1, 0), p(1, 1)], [p(0, 0), p(1, 1), p(0, 1)]]
        });
        meshes.push(grid.collect());
        meshes.push(vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 9]);
        // Corners at -0 and +0: ties of the unions (whichever zero a box keeps, the same tree).
        let signed = (0..600).map(|k| {
            let z = |j: usize| if (k * 7 + j).is_multiple_of(3) { -0.0 } else { 0.0 };
            let (x, y) = ((k % 25) as f32 * 0.1, (k / 25) as f32 * 0.1);
            [Vec3::new(x, y, z(0)), Vec3::new(z(1), y + 0.1, z(2)), Vec3::new(x + 0.1, z(3), 0.05 * (k % 4) as f32)]
        });
        meshes.push(signed.collect());
        for tris in &meshes {
            let bvh = PacketBvh::build(tris);
            let (nodes, root, order) = dense_reference(tris);
            assert_eq!(bvh.ids, order, "{} triangles: leaf order", tris.len());
            let (mut got, mut want) = (Vec::new(), Vec::new());
            if let (Some(a), Some(b)) = (bvh.root, root) {
                // A one-leaf tree has the node above it (its other child never entered).
                let a = if b & LEAF_BIT != 0 { bvh.nodes[a as usize].child[0] } else { a };
                tree_bits(&bvh.nodes, a, &mut got);
                tree_bits(&nodes, b, &mut want);
            }
            assert_eq!(bvh.root.is_some(), root.is_some());
            assert!(got == want, "{} triangles: the trees differ", tris.len());
        }
    }

    #[test]
    fn packets_match_brute_force() {
        let mut rng = Pcg32::new(7, 3);
        // The last is built in parallel halves (over PARALLEL_MIN triangles).
        for n in [1, 3, 40, 600, PARALLEL_MIN + 3000] {
            let tris = random_mesh(&mut rng, n);
            let mut bvh = PacketBvh::build(&tris);
            let packets = if n > 1000 { 10 } else { 300 };
            for isa in isas() {
                bvh.isa = isa;
                run(&bvh, &tris, &mut rng, if isa == Isa::Portable { packets / 3 } else { packets });
            }
        }
    }

    /// Rays leaving Mitsuba's projector floor (a 2000-unit square, two triangles) toward a
    /// light 1 unit above meet nothing, as the scene's BVH answers: without a box above the
    /// one leaf, the watertight test met the floor again by rounding on ~1 % of them (the
    /// origin's offset is below its rounding at that scale) and the packet kernels lit a
    /// third of the projector test's pixels less than the scalar tracer.
    #[test]
    fn rays_leaving_a_vast_floor_meet_nothing() {
        let s = 1000.0;
        let (a, b, c, d) = (Vec3::new(-s, -s, 0.0), Vec3::new(s, -s, 0.0), Vec3::new(s, s, 0.0), Vec3::new(-s, s, 0.0));
        let tris = [[a, b, c], [a, c, d]];
        let light = Vec3::Z;
        let mut rng = Pcg32::new(5, 1);
        for isa in isas() {
            let mut bvh = PacketBvh::build(&tris);
            bvh.isa = isa;
            let (mut blocked, mut hit) = (0, 0);
            for _ in 0..500 {
                let mut r = Rays8::default();
                for l in 0..LANES {
                    let p = Vec3::new(rng.next_f32() * 60.0 - 30.0, rng.next_f32() * 60.0 - 30.0, 0.0);
                    let o = crate::geometry::ray::offset_ray_origin(p, Vec3::Z, light - p);
                    let dist = (light - o).length();
                    set_lane(&mut r, l, o, (light - o) / dist, dist * (1.0 - crate::geometry::ray::SHADOW_EPSILON));
                }
                blocked += bvh.occluded(&r, 0xff).count_ones();
                hit += bvh.intersect(&r, 0xff).prim.iter().filter(|&&p| p != u32::MAX).count();
            }
            assert_eq!((blocked, hit), (0, 0), "{isa:?}: rays leaving the floor met it");
        }
    }

    #[test]
    fn shared_edges_are_watertight() {
        // A grid of quads: rays through vertices and edges must hit.
        let mut tris = Vec::new();
        for i in 0..8 {
            for j in 0..8 {
                let p = |a: i32, b: i32| Vec3::new((i + a) as f32 * 0.25, (j + b) as f32 * 0.25, 1.0);
                tris.push([p(0, 0), p(1, 0), p(1, 1)]);
                tris.push([p(0, 0), p(1, 1), p(0, 1)]);
            }
        }
        let mut bvh = PacketBvh::build(&tris);
        let mut r = Rays8::default();
        for k in 0..64 {
            for l in 0..LANES {
                let x = ((k * 8 + l) % 9) as f32 * 0.25;
                let y = ((k * 8 + l) / 9 % 9) as f32 * 0.25;
                let d = Vec3::new(0.01 * (l as f32 - 4.0), -0.007 * (k % 5) as f32, 1.0).normalize();
                let o = Vec3::new(x, y, 1.0) - d * 2.0;
                set_lane(&mut r, l, o, d, f32::INFINITY);
            }
            // Rays through vertices and along edges (u, v or w exactly zero for the
            // untilted ones): the exact path for those lanes, as the scalar test.
            for isa in isas() {
                bvh.isa = isa;
                check(&bvh, &tris, &r, 0xff);
                check(&bvh, &tris, &r, 0x5a);
            }
            bvh.isa = Isa::cpu();
            let h = bvh.intersect(&r, 0xff);
            for l in 0..LANES {
                let x = ((k * 8 + l) % 9) as f32 * 0.25;
                let y = ((k * 8 + l) / 9 % 9) as f32 * 0.25;
                // Points on the grid's outer border may be missed by the tilt; inner ones never.
                if x > 0.0 && x < 2.0 && y > 0.0 && y < 2.0 {
                    assert_ne!(h.prim[l], u32::MAX, "ray {k}/{l} slipped through at ({x}, {y})");
                }
            }
        }
    }

    /// A box's bottom lying on a floor (coplanar, overlapping) among other triangles, rays
    /// from above and below: where two triangles are hit at the same distance, which one a
    /// walk keeps depends on its order of tests. `intersect_ties` flags those lanes (and
    /// otherwise gives `intersect`'s hits): every lane whose triangle is not brute force's is
    /// flagged, and so is every lane that meets both faces.
    #[test]
    fn coplanar_faces_are_flagged_as_ties() {
        let mut rng = Pcg32::new(5, 9);
        let mut tris = random_mesh(&mut rng, 60);
        let quad = |s: f32, x: f32| {
            [
                [Vec3::new(x - s, -s, 0.0), Vec3::new(x + s, -s, 0.0), Vec3::new(x + s, s, 0.0)],
                [Vec3::new(x - s, -s, 0.0), Vec3::new(x + s, s, 0.0), Vec3::new(x - s, s, 0.0)],
            ]
        };
        // The floor first and the bottom last: brute force keeps the bottom on a tie.
        let n_floor = 2;
        let mut all: Vec<[Vec3; 3]> = quad(2.0, 0.0).to_vec();
        all.append(&mut tris);
        all.extend(quad(0.5, 0.3));
        let bottom = [all.len() as u32 - 2, all.len() as u32 - 1];
        let mut bvh = PacketBvh::build(&all);
        for isa in isas() {
            bvh.isa = isa;
            let (mut differ, mut both, mut tied_lanes) = (0, 0, 0);
            for _ in 0..400 {
                let mut r = Rays8::default();
                let active = (rng.next_u32() & 0xff) as u8 | 1;
                for l in 0..LANES {
                    // Aimed at a point of the plane over the bottom, from above or below.
                    let target = Vec3::new(0.3 + rng.next_f32() - 0.5, rng.next_f32() - 0.5, 0.0);
                    let up = if rng.next_u32().is_multiple_of(2) { 1.0 } else { -1.0 };
                    let o = target + Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, up * (0.05 + rng.next_f32()));
                    set_lane(&mut r, l, o, (target - o).normalize(), f32::INFINITY);
                }
                let plain = bvh.intersect(&r, active);
                let (h, ties) = bvh.intersect_ties(&r, active);
                assert_eq!((h.t, h.prim, h.b1, h.b2), (plain.t, plain.prim, plain.b1, plain.b2), "{isa:?}: the same hits");
                for l in (0..LANES).filter(|l| active & (1 << l) != 0) {
                    let o = Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]);
                    let d = Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]);
                    let tied = ties & (1 << l) != 0;
                    tied_lanes += tied as u32;
                    let want = brute(&all, o, d, f32::INFINITY);
                    if want.map(|w| w.1) != Some(h.prim[l]) {
                        differ += 1;
                        assert!(tied, "{isa:?}: lane {l} took {} where brute force took {want:?}, not flagged", h.prim[l]);
                    }
                    let w = WatertightRay::new(o, d);
                    let meets = |i: u32| w.intersect(all[i as usize][0], all[i as usize][1], all[i as usize][2], f32::INFINITY).is_some();
                    if (0..n_floor).any(meets) && bottom.into_iter().any(meets) && want.is_some_and(|w| bottom.contains(&w.1)) {
                        both += 1;
                        assert!(tied, "{isa:?}: lane {l} meets the floor and the bottom at once, not flagged");
                    }
                    if tied {
                        // A flagged lane meets two triangles at one distance (not necessarily its nearest).
                        let mut ts: Vec<f32> = all.iter().filter_map(|t| w.intersect(t[0], t[1], t[2], f32::INFINITY).map(|h| h.0)).collect();
                        ts.sort_by(f32::total_cmp);
                        assert!(ts.windows(2).any(|p| p[1] <= p[0] * (1.0 + 2.0 * TIE_TOL)), "{isa:?}: lane {l} flagged without a tie: {ts:?}");
                    }
                }
            }
            // Most rays meet the overlap; the walk's order keeps the floor there.
            assert!(both > 500 && differ > 0, "{isa:?}: {both} rays met both faces, {differ} took the other");
            assert!(tied_lanes >= both, "{isa:?}: {tied_lanes} lanes flagged for {both} ties");
        }
    }

    /// A ray inside a glass box standing on the Cornell box floor (cbox-rgb.xml, world space:
    /// the floor's triangle 0, then the 12 of `cbox_smallbox`) reaches the floor plane y = 0
    /// at 2.8025122, but the triangle test, rounding at the scale of the vertices (~500), puts
    /// the floor at 2.8025064 and the box's bottom near t_max = 2.802507. The floor's flat box
    /// is then entered at 2.8025122: a cull within `FAR_SLACK` of t_max skipped it, and the
    /// walk missed a hit that brute force (and the tie check) must see.
    #[test]
    fn coplanar_floor_far_from_origin_is_found() {
        let v = |x: u32, y: u32, z: u32| Vec3::new(f32::from_bits(x), f32::from_bits(y), f32::from_bits(z));
        let tris = [
            [v(0x440a3333, 0, 0), v(0, 0, 0), v(0, 0, 0x440bcccd)],
            [v(0x43020000, 0x43250000, 0x42820000), v(0x42a40000, 0x43250000, 0x43610000), v(0x43700000, 0x43250000, 0x43880000)],
            [v(0x43020000, 0x43250000, 0x42820000), v(0x43700000, 0x43250000, 0x43880000), v(0x43910000, 0x43250000, 0x42e40000)],
            [v(0x43910000, 0, 0x42e40000), v(0x43910000, 0x43250000, 0x42e40000), v(0x43700000, 0x43250000, 0x43880000)],
            [v(0x43910000, 0, 0x42e40000), v(0x43700000, 0x43250000, 0x43880000), v(0x43700000, 0, 0x43880000)],
            [v(0x43020000, 0, 0x42820000), v(0x43020000, 0x43250000, 0x42820000), v(0x43910000, 0x43250000, 0x42e40000)],
            [v(0x43020000, 0, 0x42820000), v(0x43910000, 0x43250000, 0x42e40000), v(0x43910000, 0, 0x42e40000)],
            [v(0x42a40000, 0, 0x43610000), v(0x42a40000, 0x43250000, 0x43610000), v(0x43020000, 0x43250000, 0x42820000)],
            [v(0x42a40000, 0, 0x43610000), v(0x43020000, 0x43250000, 0x42820000), v(0x43020000, 0, 0x42820000)],
            [v(0x43700000, 0, 0x43880000), v(0x43700000, 0x43250000, 0x43880000), v(0x42a40000, 0x43250000, 0x43610000)],
            [v(0x43700000, 0, 0x43880000), v(0x42a40000, 0x43250000, 0x43610000), v(0x42a40000, 0, 0x43610000)],
            [v(0x43910000, 0, 0x42e40000), v(0x43700000, 0, 0x43880000), v(0x42a40000, 0, 0x43610000)],
            [v(0x43910000, 0, 0x42e40000), v(0x42a40000, 0, 0x43610000), v(0x43020000, 0, 0x42820000)],
        ];
        let o = Vec3::new(271.83633, 1.1461626, 171.39543);
        let d = Vec3::new(0.103113756, -0.40897685, -0.9067004);
        let want = brute(&tris, o, d, 2.802507).expect("brute force meets the floor");
        assert_eq!((want.0, want.1), (2.8025064, 0));
        let mut bvh = PacketBvh::build(&tris);
        for isa in isas() {
            bvh.isa = isa;
            for t_max in [2.802507, f32::INFINITY] {
                let mut r = Rays8::default();
                for l in 0..LANES {
                    set_lane(&mut r, l, o, d, t_max);
                }
                // Occlusion (`occluded`) culls as the scene BVH's shadow walk does: not checked here.
                for active in [1u8, 0xff] {
                    let plain = bvh.intersect(&r, active);
                    let (h, ties) = bvh.intersect_ties(&r, active);
                    assert_eq!((h.t, h.prim), (plain.t, plain.prim), "{isa:?}: the same hits");
                    for l in (0..LANES).filter(|l| active & (1 << l) != 0) {
                        // The floor (0) or a bottom triangle (11, 12) within a few ulps of it.
                        assert!([0, 11, 12].contains(&h.prim[l]), "{isa:?}: t_max {t_max}: lane {l} took {}", h.prim[l]);
                        assert!((h.t[l] - want.0).abs() <= 1e-6 * want.0, "{isa:?}: t_max {t_max}: lane {l} at {}", h.t[l]);
                    }
                    // The bottom triangle 11 is met at 2.8025074: past the short t_max, a tie
                    // with the floor without it.
                    if t_max.is_infinite() {
                        assert_eq!(ties, active, "{isa:?}: the floor and the bottom tie");
                    }
                }
            }
        }
    }

    /// The nearest of `spheres` along a ray as the scene BVH's leaf loop finds it, spheres
    /// taken in order with t_max shrinking: (index, t).
    fn spheres_in_order(spheres: &[Sphere], o: Vec3, d: Vec3, t_max: f32, order: &[usize]) -> Option<(usize, f32)> {
        let mut best = None;
        let mut tm = t_max;
        for &k in order {
            if let Some(t) = spheres[k].intersect(o, d, tm) {
                tm = t;
                best = Some((k, t));
            }
        }
        best
    }

    /// `PacketSpheres` (AVX2 and lane by lane) against `Sphere::intersect` taken in order, in
    /// either order: overlapping spheres, rays from inside, from their surfaces, and t_max
    /// cutting through them. Every lane not flagged unsure has the sequential walk's sphere and
    /// distance bit for bit whatever the order; occlusion likewise; few lanes are unsure.
    #[test]
    fn packet_spheres_match_sequential_tests() {
        let mut rng = Pcg32::new(23, 9);
        let mut spheres: Vec<Sphere> = (0..12)
            .map(|i| {
                let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - Vec3::splat(2.0);
                Sphere { center: c + Vec3::new(3.0, -7.0, 1.5), radius: 0.05 + rng.next_f32() * (if i % 3 == 0 { 2.0 } else { 0.5 }), flip_normals: i % 2 == 0 }
            })
            .collect();
        // Two equal spheres at one place: every hit on them is a tie in distance.
        spheres.push(spheres[4]);
        let forward: Vec<usize> = (0..spheres.len()).collect();
        let backward: Vec<usize> = forward.iter().rev().copied().collect();
        let mut packed = PacketSpheres::new(&spheres);
        let (mut lanes, mut unsure_n, mut hits) = (0usize, 0usize, 0usize);
        for isa in [Isa::Avx512, Isa::Avx2, Isa::Portable] {
            if isa > Isa::cpu() {
                continue;
            }
            packed.isa = isa;
            for p in 0..4000 {
                let mut r = Rays8::default();
                let active = if p % 5 == 0 { (rng.next_u32() & 0xff) as u8 } else { 0xff };
                for l in 0..LANES {
                    let d = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE).normalize_or(Vec3::X) * (0.5 + rng.next_f32());
                    let o = match l % 3 {
                        // On a sphere's surface (as a path leaves it), or inside one.
                        0 => {
                            let s = spheres[(rng.next_u32() as usize) % spheres.len()];
                            s.center + d.normalize() * s.radius * if l == 3 { 0.5 } else { 1.0 }
                        }
                        _ => Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - Vec3::splat(5.0) + Vec3::new(3.0, -7.0, 1.5),
                    };
                    let s = spheres[(rng.next_u32() as usize) % spheres.len()];
                    let d = match l {
                        // Grazing: toward a point at the radius (give or take 1e-5) from the
                        // center, across the line of sight (the f32 cull must keep it).
                        5 | 7 => {
                            let u = (s.center - o).cross(d).normalize_or(Vec3::Z);
                            // The line through o and c + k r u passes at r from c.
                            let (oc, r) = ((s.center - o).length(), s.radius);
                            let k = if oc > r * 1.01 { oc / (oc * oc - r * r).sqrt() } else { 1.0 };
                            s.center + u * r * k * (1.0 + (rng.next_f32() - 0.5) * 2e-5) - o
                        }
                        _ if l % 2 == 1 => (s.center - o).normalize_or(Vec3::Y),
                        _ => d,
                    };
                    set_lane(&mut r, l, o, d, if rng.next_f32() < 0.3 { rng.next_f32() * 6.0 } else { f32::INFINITY });
                }
                let mut t = r.t_max;
                let (ids, unsure) = packed.nearest(&r, active, &mut t);
                let (blocked, occ_unsure) = packed.occluded(&r, active);
                for l in 0..LANES {
                    let o = Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]);
                    let d = Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]);
                    if active & (1 << l) == 0 {
                        assert_eq!((ids[l], t[l], blocked & (1 << l), unsure & (1 << l)), (u32::MAX, r.t_max[l], 0, 0));
                        continue;
                    }
                    lanes += 1;
                    let want = [&forward, &backward].map(|order| spheres_in_order(&spheres, o, d, r.t_max[l], order));
                    assert_eq!(blocked & (1 << l) != 0, want[0].is_some(), "{isa:?}: occlusion of lane {l}");
                    hits += want[0].is_some() as usize;
                    if occ_unsure & (1 << l) != 0 {
                        assert!(blocked & (1 << l) != 0, "an unsure occlusion is a hit");
                    }
                    if unsure & (1 << l) != 0 {
                        unsure_n += 1;
                        continue;
                    }
                    for w in want {
                        match w {
                            None => assert_eq!((ids[l], t[l]), (u32::MAX, r.t_max[l]), "{isa:?}: lane {l}: false hit"),
                            // The twin spheres are one surface: either index is the hit.
                            Some((k, th)) => {
                                let same = ids[l] as usize == k
                                    || (spheres[ids[l] as usize].center == spheres[k].center && spheres[ids[l] as usize].radius == spheres[k].radius);
                                assert!(same && t[l].to_bits() == th.to_bits(), "{isa:?}: lane {l}: sphere {} at {} for {k} at {th}", ids[l], t[l]);
                            }
                        }
                    }
                }
            }
        }
        println!("{lanes} lanes, {hits} meet a sphere, {unsure_n} unsure");
        assert!(hits > lanes / 3, "rays meet spheres");
        assert!(unsure_n < lanes / 10, "{unsure_n} of {lanes} lanes unsure");
    }

    /// Shadow rays toward points on spheres (t_max short of the point by 1e-4, or within a few
    /// ulps either side of it), rays from the surfaces and from inside, and spheres behind the
    /// origin: the AVX2 test and its AVX-512 copy (whose f32 reach test skips the f64 one on
    /// lanes that meet a sphere only past t_max or behind them) give the lane-by-lane test's spheres,
    /// distances and unsure lanes bit for bit, for nearest hits and occlusion.
    #[test]
    fn sphere_reach_test_keeps_the_bits() {
        if Isa::cpu() == Isa::Portable {
            return;
        }
        let mut rng = Pcg32::new(5, 77);
        let spheres: Vec<Sphere> = (0..5)
            .map(|i| {
                let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 8.0 - Vec3::splat(4.0) + Vec3::new(0.0, 6.5, 0.0);
                Sphere { center: c, radius: [1.0, 0.5, 0.05, 0.002, 2.0][i], flip_normals: false }
            })
            .collect();
        let packed = PacketSpheres::new(&spheres);
        let (mut hits, mut near_misses) = (0usize, 0usize);
        for p in 0..20000 {
            let mut r = Rays8::default();
            for l in 0..LANES {
                let s = spheres[(rng.next_u32() as usize) % spheres.len()];
                // A point on the sphere: on the side facing the origin, or anywhere.
                let o = match p % 4 {
                    0 => s.center + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - Vec3::splat(0.5)).normalize_or(Vec3::X) * s.radius * 0.5,
                    1 => {
                        let t = spheres[(rng.next_u32() as usize) % spheres.len()];
                        t.center + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - Vec3::splat(0.5)).normalize_or(Vec3::X) * t.radius
                    }
                    _ => Vec3::new(rng.next_f32() * 20.0 - 10.0, rng.next_f32() * 3.0, rng.next_f32() * 20.0 - 10.0),
                };
                let u = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - Vec3::splat(0.5)).normalize_or(Vec3::Y);
                let u = if (o - s.center).dot(u) < 0.0 && l % 2 == 0 { -u } else { u };
                let target = s.center + u * s.radius;
                let (dir, dist) = ((target - o).normalize_or(Vec3::Z), (target - o).length());
                let scale = 0.25 + 2.0 * rng.next_f32();
                let t_max = match l % 4 {
                    0 => dist * (1.0 - 1e-4),
                    1 => f32::from_bits((dist.to_bits() as i32 + (rng.next_u32() % 9) as i32 - 4).max(0) as u32),
                    2 => dist * (1.0 + 1e-4),
                    _ => f32::INFINITY,
                } / scale;
                // Away from the sphere half of the time (then it is behind the origin).
                let d = if l == 5 { -dir } else { dir } * scale;
                set_lane(&mut r, l, o, d, t_max);
            }
            let active = if p % 7 == 0 { (rng.next_u32() & 0xff) as u8 } else { 0xff };
            for any in [false, true] {
                for isa in [Isa::Avx2, Isa::Avx512].into_iter().filter(|&i| i <= Isa::cpu()) {
                    let mut t_simd = r.t_max;
                    // SAFETY: the CPU runs `isa` (`Isa::cpu`).
                    let (ids_simd, un_simd) = unsafe {
                        match (isa, any) {
                            (Isa::Avx512, true) => packed.test_avx512::<true>(&r, active, &mut t_simd),
                            (Isa::Avx512, false) => packed.test_avx512::<false>(&r, active, &mut t_simd),
                            (_, true) => packed.test_avx2::<true>(&r, active, &mut t_simd),
                            (_, false) => packed.test_avx2::<false>(&r, active, &mut t_simd),
                        }
                    };
                    let mut t_lanes = r.t_max;
                    let (ids_lanes, un_lanes) =
                        if any { packed.test_lanes::<true>(&r, active, &mut t_lanes) } else { packed.test_lanes::<false>(&r, active, &mut t_lanes) };
                    if any {
                        assert_eq!((lanes_of(&ids_simd), un_simd), (lanes_of(&ids_lanes), un_lanes), "{isa:?} packet {p}: occlusion");
                    } else {
                        assert_eq!((ids_simd, un_simd), (ids_lanes, un_lanes), "{isa:?} packet {p}: nearest");
                        assert_eq!(t_simd.map(f32::to_bits), t_lanes.map(f32::to_bits), "{isa:?} packet {p}: distances");
                        if isa == Isa::Avx2 {
                            hits += lanes_of(&ids_lanes).count_ones() as usize;
                        }
                    }
                }
            }
            for l in (0..LANES).filter(|&l| l % 4 == 1 && active & (1 << l) != 0) {
                near_misses += (r.t_max[l].is_finite()) as usize;
            }
        }
        assert!(hits > 20000 && near_misses > 10000, "{hits} hits, {near_misses} rays ending at a sphere");
    }

    /// The twin spheres' hits are ties (unsure: the scene BVH's order picks one).
    #[test]
    fn equal_spheres_are_unsure() {
        let s = Sphere { center: Vec3::new(0.5, 0.25, 4.0), radius: 0.75, flip_normals: false };
        let packed = PacketSpheres::new(&[s, Sphere { flip_normals: true, ..s }]);
        let mut r = Rays8::default();
        for l in 0..LANES {
            set_lane(&mut r, l, Vec3::new(l as f32 * 0.01, 0.0, 0.0), Vec3::new(0.1, 0.05, 1.0), f32::INFINITY);
        }
        let mut t = r.t_max;
        let (ids, unsure) = packed.nearest(&r, 0xff, &mut t);
        assert!(ids.iter().all(|&i| i != u32::MAX), "every lane meets them: {ids:?}");
        assert_eq!(unsure, 0xff);
    }

    #[test]
    fn rays_along_box_faces() {
        // Two staircases of unit squares: rays that start on the planes of the leaves' boxes
        // and run along them (direction components of +0 and -0) must still find their hits.
        let mut tris = Vec::new();
        for i in 0..6 {
            let (x, y) = (i as f32, i as f32 * 0.5);
            let p = |a: f32, b: f32| Vec3::new(x + a, y, b);
            tris.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
            tris.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
            let q = |a: f32, b: f32| Vec3::new(x + 1.0, y + a * 0.5, b);
            tris.push([q(0.0, 0.0), q(1.0, 0.0), q(1.0, 1.0)]);
            tris.push([q(0.0, 0.0), q(1.0, 1.0), q(0.0, 1.0)]);
        }
        let mut bvh = PacketBvh::build(&tris);
        let mut rng = Pcg32::new(11, 5);
        for k in 0..200 {
            let mut r = Rays8::default();
            for l in 0..LANES {
                // Origins on the planes y = i / 2, x = i, z = 0 or z = 1, some on edges.
                let i = (rng.next_u32() % 7) as f32;
                let f = |rng: &mut Pcg32| if rng.next_u32().is_multiple_of(3) { (rng.next_u32() % 3) as f32 * 0.5 } else { rng.next_f32() * 6.0 };
                let mut o = Vec3::new(f(&mut rng), f(&mut rng), f(&mut rng));
                o[(k + l) % 3] = if (k + l) % 3 == 0 {
                    i
                } else if (k + l) % 3 == 1 {
                    i * 0.5
                } else {
                    (i as u32 % 2) as f32
                };
                let s = |rng: &mut Pcg32| if rng.next_u32().is_multiple_of(2) { 1.0f32 } else { -1.0 };
                let mut d = Vec3::new(s(&mut rng) * (0.2 + rng.next_f32()), s(&mut rng) * (0.2 + rng.next_f32()), s(&mut rng) * rng.next_f32());
                d[(k + l) % 3] = 0.0 * s(&mut rng);
                if l % 4 == 0 {
                    d[(k + l + 1) % 3] = 0.0 * s(&mut rng);
                }
                set_lane(&mut r, l, o, d, f32::INFINITY);
            }
            for isa in isas() {
                bvh.isa = isa;
                check(&bvh, &tris, &r, 0xff);
            }
        }
    }

    /// The AVX-512 copy (its box test picks the planes by permutes) and the AVX2 copy (by
    /// blends) visit the same nodes in the same order: the same hits, ties and occlusion
    /// bit for bit, with origins on the boxes' planes and zero direction components.
    #[test]
    fn simd_copies_agree() {
        if Isa::cpu() < Isa::Avx512 {
            return;
        }
        let mut rng = Pcg32::new(13, 7);
        for n in [3, 40, 600] {
            let tris = random_mesh(&mut rng, n);
            let mut bvh = PacketBvh::build(&tris);
            for k in 0..400 {
                let mut r = Rays8::default();
                for l in 0..LANES {
                    let v = tris[(rng.next_u32() as usize) % n][(rng.next_u32() % 3) as usize];
                    let mut o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0 - Vec3::splat(1.5);
                    // A vertex's coordinate is some box's plane.
                    o[(k + l) % 3] = v[(k + l) % 3];
                    let mut d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
                    if l % 2 == 0 {
                        d[(k + l) % 3] = if l % 4 == 0 { 0.0 } else { -0.0 };
                    }
                    set_lane(&mut r, l, o, d, if l == 5 { rng.next_f32() } else { f32::INFINITY });
                }
                let active = (rng.next_u32() & 0xff) as u8 | 1;
                let mut got = Vec::new();
                for isa in [Isa::Avx512, Isa::Avx2] {
                    bvh.isa = isa;
                    let (h, ties) = bvh.intersect_ties(&r, active);
                    let bits = |a: [f32; LANES]| a.map(f32::to_bits);
                    got.push((bits(h.t), h.prim, bits(h.b1), bits(h.b2), ties, bvh.occluded(&r, active)));
                }
                assert_eq!(got[0], got[1], "n {n}, packet {k}");
            }
        }
    }
}
