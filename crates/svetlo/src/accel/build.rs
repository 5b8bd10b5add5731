//! Binary binned-SAH build (all three axes, parallel over subtrees), then collapse
//! into the wide (WIDTH-ary) tree. Knows nothing of what a primitive is: it sees boxes only.
//! Leaves are emitted through a callback that packs the primitives however the
//! caller stores them and returns the leaf's child code.
//!
//! The primitives' boxes travel with the primitive order (contiguous, in SIMD registers, no
//! lookup through the order), all three axes are binned in one pass, and the pass that
//! partitions a node also bins its two children (their bins keep their centroids' bounds too,
//! so that a split's children have their bounds and grids before that pass): one pass over a
//! node's primitives where there were five, and two at the nodes near the root that bin
//! themselves on all threads. The tree is the one the straightforward build
//! (`reference`, kept for the tests) gives: the same splits, the same primitive order, the
//! same boxes (min and max are exact, whatever the order of the unions; only the sign of a
//! zero may differ, which no comparison sees).

use super::pages::PagedVec;
use super::wide::{Node, EMPTY_CHILD, LEAF_BIT, WIDTH};
use crate::geometry::Aabb;
use glam::{Vec3A, Vec3Swizzles};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

#[cfg(test)]
mod reference;

const BINS: usize = 32;
// The split search keeps a bin's occupancy in one bit of a u32.
const _: () = assert!(BINS <= 32);
// Bin indices are masked with BINS - 1 (see `best_split`).
const _: () = assert!(BINS.is_power_of_two());
/// Subtrees smaller than this are built on the current thread.
const PARALLEL_MIN: usize = 8 * 1024;
/// Nodes of at least this many primitives bin into two sets of bins (see `best_split`).
const TWO_BIN_SETS_MIN: usize = 256;
/// Below this depth SAH splits give way to median splits, which bounds the depth
/// (and so the traversal stack) on pathological inputs.
const SAH_MAX_DEPTH: usize = 40;
/// Binary depth never exceeds SAH_MAX_DEPTH + 32, and a wide node pushes at most WIDTH - 1 entries.
pub const MAX_STACK: usize = (WIDTH - 1) * (SAH_MAX_DEPTH + 33);

/// What the SAH needs to know about the leaves of one kind of primitive.
#[derive(Clone, Copy, Debug)]
pub struct LeafParams {
    /// Primitives are intersected in groups of this size (4 for SIMD triangles):
    /// a leaf of n primitives costs ceil(n / group).
    pub group: usize,
    /// Largest leaf, in primitives.
    pub max_leaf: usize,
    /// Cost of a node visit relative to one group test.
    pub traversal_cost: f32,
}

/// A node of the binary tree: a leaf (`count` primitives of the order from `start`) or, where
/// `count` is 0, the inner node at `start` in the [`Arena`]. Eight bytes, copied freely.
#[derive(Clone, Copy, PartialEq, Eq)]
struct BNode {
    start: u32,
    count: u32,
}

impl BNode {
    fn leaf(start: usize, count: usize) -> BNode {
        BNode { start: start as u32, count: count as u32 }
    }
    fn is_leaf(self) -> bool {
        self.count != 0
    }
}

/// A binary inner node: its two children and their boxes (one cache line).
#[derive(Clone, Copy)]
struct Inner {
    bounds: [Aabb; 2],
    children: [BNode; 2],
}

/// The binary tree's inner nodes, in one allocation that the build's threads fill at the places
/// they claim (one allocation per node was a tenth of the build's memory and its page faults).
/// The places depend on the threads' timing, the tree does not.
struct Arena {
    /// Room for `cap` nodes, of which the first `next` are claimed.
    ptr: *mut Inner,
    cap: usize,
    next: AtomicUsize,
}

// SAFETY: each place is written once, by the thread that claimed it (`push`), and read only
// after the build's threads have joined (`into_nodes`).
unsafe impl Sync for Arena {}

impl Arena {
    fn push(&self, node: Inner) -> BNode {
        let i = self.next.fetch_add(1, Ordering::Relaxed);
        // A tree over n primitives has at most n - 1 inner nodes (every leaf holds one at least).
        assert!(i < self.cap, "more inner nodes than primitives");
        // SAFETY: i < cap lies in the room, and no other push claims the same place.
        unsafe { self.ptr.add(i).write(node) };
        BNode { start: i as u32, count: 0 }
    }
}

/// A box in SIMD registers (lanes x, y, z; w unused).
#[derive(Clone, Copy, Debug)]
struct Box3 {
    min: Vec3A,
    max: Vec3A,
}

impl Box3 {
    const EMPTY: Box3 = Box3 { min: Vec3A::INFINITY, max: Vec3A::NEG_INFINITY };

    #[inline(always)]
    fn new(b: &Aabb) -> Box3 {
        Box3 { min: b.min.into(), max: b.max.into() }
    }
    #[inline(always)]
    fn union(self, o: Box3) -> Box3 {
        Box3 { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    #[inline(always)]
    fn grow(self, p: Vec3A) -> Box3 {
        Box3 { min: self.min.min(p), max: self.max.max(p) }
    }
    /// The centroid, by the operations of [`Aabb::center`] lane by lane (the same bits).
    #[inline(always)]
    fn center(self) -> Vec3A {
        0.5 * (self.min + self.max)
    }
    /// [`Aabb::surface_area`] in the registers, by the same operations in the same order
    /// (the same bits).
    #[inline(always)]
    fn surface_area(self) -> f32 {
        if self.min.cmpgt(self.max).any() {
            return 0.0;
        }
        let e = self.max - self.min;
        let p = e * e.yzx();
        2.0 * (p.x + p.y + p.z)
    }
    #[inline(always)]
    fn aabb(self) -> Aabb {
        Aabb { min: self.min.into(), max: self.max.into() }
    }
}

/// A bin as one row of sixteen lanes: its primitives' box (the lower corner, then the upper
/// corner negated) and their centroids' box (the same way), so that a union is one vector
/// minimum where the CPU has AVX-512, two where it has AVX (min(-a, -b) is -max(a, b), a zero's
/// sign aside, which neither a comparison nor the surface area's value sees). The centroids'
/// boxes give a split's children their centroid bounds, and so their bins' grids, before the
/// partition that bins them (see [`partition`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Bin {
    lo: Vec3A,
    neg_hi: Vec3A,
    c_lo: Vec3A,
    neg_c_hi: Vec3A,
}

/// The instruction sets a bin's union is compiled for (a const parameter: the binning loops have
/// one copy per set, picked at run time by [`isa`]).
const SSE: u8 = 0;
const AVX: u8 = 1;
const AVX512: u8 = 2;

fn isa() -> u8 {
    if crate::cpu::avx512() {
        AVX512
    } else if crate::cpu::avx() {
        AVX
    } else {
        SSE
    }
}

impl Bin {
    const EMPTY: Bin = Bin { lo: Vec3A::INFINITY, neg_hi: Vec3A::INFINITY, c_lo: Vec3A::INFINITY, neg_c_hi: Vec3A::INFINITY };

    #[inline(always)]
    fn of(b: &Box3, c: Vec3A) -> Bin {
        Bin { lo: b.min, neg_hi: -b.max, c_lo: c, neg_c_hi: -c }
    }
    #[inline(always)]
    fn union(self, o: Bin) -> Bin {
        Bin { lo: self.lo.min(o.lo), neg_hi: self.neg_hi.min(o.neg_hi), c_lo: self.c_lo.min(o.c_lo), neg_c_hi: self.neg_c_hi.min(o.neg_c_hi) }
    }
    /// `*self = self.union(*o)`, in one or two instructions where `ISA` has them (the same lanes).
    ///
    /// # Safety
    /// `ISA` must be [`SSE`], or [`AVX`] (or [`AVX512`]) inside code compiled for AVX (AVX-512F),
    /// into which this inlines.
    #[inline(always)]
    unsafe fn add<const ISA: u8>(&mut self, o: &Bin) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            let (a, b) = (self as *mut Bin as *mut f32, o as *const Bin as *const f32);
            // SAFETY: the caller's CPU has the set (see above); a bin is 64-byte aligned.
            unsafe {
                if ISA == AVX512 {
                    _mm512_store_ps(a, _mm512_min_ps(_mm512_load_ps(a), _mm512_load_ps(b)));
                    return;
                }
                if ISA == AVX {
                    _mm256_store_ps(a, _mm256_min_ps(_mm256_load_ps(a), _mm256_load_ps(b)));
                    _mm256_store_ps(a.add(8), _mm256_min_ps(_mm256_load_ps(a.add(8)), _mm256_load_ps(b.add(8))));
                    return;
                }
            }
        }
        *self = self.union(*o);
    }
    /// The union of this bin's box with `acc` (the sweep's boxes, centroids left out).
    #[inline(always)]
    fn grow_box(&self, acc: Box3) -> Box3 {
        Box3 { min: acc.min.min(self.lo), max: acc.max.min(self.neg_hi) }
    }
    #[inline(always)]
    fn box3(&self) -> Box3 {
        Box3 { min: self.lo, max: -self.neg_hi }
    }
    #[inline(always)]
    fn centroids(&self) -> Box3 {
        Box3 { min: self.c_lo, max: -self.neg_c_hi }
    }
}

/// A thread's bins for one node, kept from node to node: each search empties the bins it
/// filled (a node of a few primitives fills a few of the 3 x 32), where every node filled all of
/// them anew (stores and copies, on nodes of mostly a few dozen primitives).
struct Bins {
    bins: [[Bin; BINS]; 3],
    /// The second set of boxes of large nodes (see `fill_bins_with`).
    odd: [[Bin; BINS]; 3],
    counts: [[u32; BINS]; 3],
}

impl Bins {
    fn new() -> Bins {
        Bins { bins: [[Bin::EMPTY; BINS]; 3], odd: [[Bin::EMPTY; BINS]; 3], counts: [[0; BINS]; 3] }
    }

    /// Adds `o`'s boxes and counts to these (the odd sets are left as they are).
    fn merge(&mut self, o: &Bins) {
        for axis in 0..3 {
            for k in 0..BINS {
                self.bins[axis][k] = self.bins[axis][k].union(o.bins[axis][k]);
                self.counts[axis][k] += o.counts[axis][k];
            }
        }
    }
}

/// A node's bins, made on first use: a recursion's node at relative depth d bins into slot d,
/// and its partition bins its left child into slot d + 1 and its right child into slot d (its
/// own, emptied by its split search), so that a right child's bins wait in their slot while the
/// left subtree is built below it.
type Slot = Option<Box<Bins>>;
/// Slots in a stack: nodes bin only above `SAH_MAX_DEPTH`.
const SLOTS: usize = SAH_MAX_DEPTH + 1;

fn slot(s: &mut Slot) -> &mut Bins {
    s.get_or_insert_with(|| Box::new(Bins::new()))
}

/// Builds the wide tree over `n` primitives, `bound(i)` the box of the i-th. Returns the nodes
/// (root first; none when there is no primitive) and the primitive order the leaves refer to.
/// `emit_leaf` gets each leaf's slice of that order, in depth-first order, and returns its
/// child code (with `LEAF_BIT` set).
///
/// The boxes are asked for by index, on rayon's threads (the pass over a million triangles'
/// vertices was the build's largest serial part), so that a caller need not keep an array of
/// them beside the build's own; the build's large arrays are [`PagedVec`]s.
pub fn build_wide(n: usize, bound: impl Fn(usize) -> Aabb + Sync, params: LeafParams, mut emit_leaf: impl FnMut(&[u32]) -> u32) -> (PagedVec<Node>, Vec<u32>) {
    use rayon::prelude::*;
    let mut order: Vec<u32> = (0..n as u32).into_par_iter().collect();
    if n == 0 {
        return (PagedVec::with_capacity(0), order);
    }
    // The root's bounds as the boxes are made: this pass is bound by memory, not by the cores.
    let mut boxes = PagedVec::with_capacity(n);
    let empty = || (Box3::EMPTY, Box3::EMPTY);
    let grow = |(b, c): (Box3, Box3), x: &Box3| (b.union(*x), c.grow(x.center()));
    let both = |a: (Box3, Box3), b: (Box3, Box3)| (a.0.union(b.0), a.1.union(b.1));
    // Min and max are exact in any order (a zero's sign aside).
    let (root_box, root_centroids) = boxes.extend_par_reduce(n, |i| Box3::new(&bound(i)), empty, grow, both);
    let root_bounds = root_box.aabb();
    // On huge pages where large: its 4 KiB page faults were 2 % of the build's CPU time.
    let mut inner: PagedVec<Inner> = PagedVec::with_capacity(n - 1);
    let arena = Arena { ptr: inner.as_mut_ptr(), cap: inner.capacity(), next: AtomicUsize::new(0) };
    let threads = rayon::current_num_threads().max(1);
    let cx = Ctx { p: params, arena: &arena, isa: isa(), fuse_max: (n / threads).max(PARALLEL_MIN - 1), spare: Mutex::new(Vec::new()) };
    let mut slots: Vec<Slot> = (0..SLOTS).map(|_| None).collect();
    let root = build_rec(&cx, &mut slots, false, &mut boxes, &mut order, 0, root_bounds, root_centroids, 0);
    // SAFETY: the first `next` places were written (`Arena::push`), the threads have joined.
    unsafe { inner.set_len(arena.next.into_inner()) };
    drop(boxes);
    let mut nodes = PagedVec::with_capacity(n / 2 + 1);
    // The root is always an inner node, even over a single leaf, so that traversal starts uniformly.
    let root_wide = match root.is_leaf() {
        true => WideChildren { len: 1, nodes: [root; WIDTH], boxes: [root_bounds; WIDTH] },
        false => collapse(&inner, root),
    };
    nodes.push(Node::empty());
    fill_node(0, &root_wide, &inner, &order, &mut nodes, &mut emit_leaf);
    (nodes, order)
}

/// The children of a wide node: the first `len` of `nodes` and `boxes` (on the stack: one
/// per wide node, no allocation).
struct WideChildren {
    len: usize,
    nodes: [BNode; WIDTH],
    boxes: [Aabb; WIDTH],
}

fn fill_node(idx: usize, wide: &WideChildren, inner: &[Inner], order: &[u32], nodes: &mut PagedVec<Node>, emit_leaf: &mut impl FnMut(&[u32]) -> u32) {
    let mut codes = [EMPTY_CHILD; WIDTH];
    for (k, &child) in wide.nodes[..wide.len].iter().enumerate() {
        codes[k] = if child.is_leaf() {
            let code = emit_leaf(&order[child.start as usize..(child.start + child.count) as usize]);
            debug_assert!(code & LEAF_BIT != 0);
            code
        } else {
            let ci = nodes.len();
            nodes.push(Node::empty());
            fill_node(ci, &collapse(inner, child), inner, order, nodes, emit_leaf);
            ci as u32
        };
    }
    nodes[idx] = Node::new(&wide.boxes[..wide.len], codes);
}

/// The up-to-WIDTH children of a binary inner node in the wide tree: open the
/// child of largest surface area until there are WIDTH (or only leaves remain).
/// On equal areas the last one opens; an opened child's place takes the last child and
/// its two children go last (the order a vector's `swap_remove` and `push` give).
fn collapse(inner: &[Inner], node: BNode) -> WideChildren {
    debug_assert!(!node.is_leaf(), "collapse of a leaf");
    // The arena's nodes lie at places of the build's timing, far apart: each opened node's
    // children are asked for at once, so that the loads of a wide node (and of its children's
    // collapses, next) overlap rather than wait one after the other.
    let fetch = |c: &[BNode; 2]| {
        for b in c.iter().filter(|b| !b.is_leaf()) {
            super::wide::prefetch(inner.as_ptr().wrapping_add(b.start as usize), size_of::<Inner>());
        }
    };
    let Inner { bounds, children } = inner[node.start as usize];
    fetch(&children);
    let mut w = WideChildren { len: 2, nodes: [node; WIDTH], boxes: [bounds[0]; WIDTH] };
    w.nodes[..2].copy_from_slice(&children);
    w.boxes[..2].copy_from_slice(&bounds);
    while w.len < WIDTH {
        let mut best: Option<(usize, f32)> = None;
        for i in 0..w.len {
            if !w.nodes[i].is_leaf() {
                let a = w.boxes[i].surface_area();
                if best.is_none_or(|(_, b)| a.total_cmp(&b).is_ge()) {
                    best = Some((i, a));
                }
            }
        }
        let Some((i, _)) = best else { break };
        let Inner { bounds, children } = inner[w.nodes[i].start as usize];
        fetch(&children);
        let last = w.len - 1;
        w.nodes[i] = w.nodes[last];
        w.boxes[i] = w.boxes[last];
        w.nodes[last] = children[0];
        w.boxes[last] = bounds[0];
        w.nodes[last + 1] = children[1];
        w.boxes[last + 1] = bounds[1];
        w.len += 1;
    }
    w
}

fn groups(n: usize, group: usize) -> f32 {
    n.div_ceil(group) as f32
}

/// What the recursion's calls share.
struct Ctx<'a> {
    p: LeafParams,
    arena: &'a Arena,
    isa: u8,
    /// Children of at most this many primitives are binned by their parent's partition (one
    /// pass over them where there were two); larger ones bin themselves, on all threads: near
    /// the root, where there are fewer subtrees than threads.
    fuse_max: usize,
    /// Slot stacks (their bins empty) for the subtrees that start on other threads.
    spare: Mutex<Vec<Vec<Slot>>>,
}

impl Ctx<'_> {
    fn stack(&self) -> Vec<Slot> {
        let spare = self.spare.lock().unwrap_or_else(|e| e.into_inner()).pop();
        spare.unwrap_or_else(|| (0..SLOTS).map(|_| None).collect())
    }
    fn give_back(&self, stack: Vec<Slot>) {
        self.spare.lock().unwrap_or_else(|e| e.into_inner()).push(stack);
    }
}

/// The subtree over `boxes` (and the primitive ids `order`, permuted alongside), which start
/// at `first` in the whole order, bounded by `bb`, their centroids by `cb`. Inner nodes go to
/// `cx.arena`. `slots[0]` holds the node's bins, filled where `binned` (by the parent's
/// partition), else empty; the slots after it are the subtree's (see [`Slot`]).
#[allow(clippy::too_many_arguments)]
fn build_rec(cx: &Ctx, slots: &mut [Slot], binned: bool, boxes: &mut [Box3], order: &mut [u32], first: usize, bb: Aabb, cb: Box3, depth: usize) -> BNode {
    let (p, n) = (cx.p, order.len());
    let leaf = BNode::leaf(first, n);
    if n <= 1 {
        debug_assert!(!binned, "a single primitive binned");
        return leaf;
    }
    let ext = cb.aabb().extent();
    let mid = n / 2;
    if depth >= SAH_MAX_DEPTH {
        debug_assert!(!binned, "a median split's node binned");
        if n <= p.max_leaf {
            return leaf;
        }
        #[cfg(test)]
        MEDIAN_SPLITS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let axis = ext.max_position();
        // The permutation that selecting on the order itself would give (same comparisons in
        // the same places), applied to both arrays.
        let mut idx: Vec<u32> = (0..n as u32).collect();
        idx.select_nth_unstable_by(mid, |&a, &b| boxes[a as usize].center()[axis].total_cmp(&boxes[b as usize].center()[axis]));
        let (old_boxes, old_order) = (boxes.to_vec(), order.to_vec());
        for (k, &i) in idx.iter().enumerate() {
            boxes[k] = old_boxes[i as usize];
            order[k] = old_order[i as usize];
        }
        return split_folded(cx, slots, boxes, order, first, mid, depth);
    }
    let scale = bin_scale(Vec3A::from(ext));
    // Above SAH_MAX_DEPTH a stack has two slots from this node's on (see `SLOTS`).
    let (own, below) = slots.split_at_mut(1);
    let bins = slot(&mut own[0]);
    if !binned {
        fill_bins(cx.isa, bins, boxes, cb.min, scale);
    }
    let split = best_split(bins, scale, p.group);
    let leaf_cost = groups(n, p.group);
    match split {
        Some(s) => {
            // Costs are in units of parent area: traversal + sum of area ratio * groups.
            let split_cost = p.traversal_cost + s.cost / bb.surface_area().max(f32::MIN_POSITIVE);
            if n <= p.max_leaf && leaf_cost <= split_cost {
                return leaf;
            }
            // The children that will search for a split bin in the partition's pass, on the
            // grids their centroid bounds give: the left one into the next slot, the right one
            // into this node's.
            let sizes = [s.count, n - s.count];
            let fused = sizes.map(|m| m >= 2 && depth + 1 < SAH_MAX_DEPTH && m <= cx.fuse_max);
            let grid = |k: usize| (s.centroids[k].min, bin_scale(s.centroids[k].max - s.centroids[k].min));
            let kids = [fused[0].then(|| (slot(&mut below[0]), grid(0))), fused[1].then(|| (slot(&mut own[0]), grid(1)))];
            let l = partition(cx.isa, boxes, order, &SideTest::new(cb.min, scale, s.axis, s.bin), kids);
            // The side test is the bins' (see `SideTest`): both sides are the bins' and not empty.
            debug_assert_eq!(l, s.count);
            return split_into(cx, slots, boxes, order, first, l, depth, s.bounds, s.centroids, fused);
        }
        None => {
            // All centroids coincide: nothing to gain from splitting but leaf size.
            if n <= p.max_leaf {
                return leaf;
            }
        }
    }
    split_folded(cx, slots, boxes, order, first, mid, depth)
}

/// Bins per unit of each axis of a centroid box's extent `ext` (0 on a flat axis).
#[inline(always)]
fn bin_scale(ext: Vec3A) -> Vec3A {
    Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(BINS as f32) / ext, Vec3A::ZERO)
}

/// Median splits made (the tests check that they reach that path).
#[cfg(test)]
static MEDIAN_SPLITS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Splits at `mid`, bounding each side by a pass over it.
fn split_folded(cx: &Ctx, slots: &mut [Slot], boxes: &mut [Box3], order: &mut [u32], first: usize, mid: usize, depth: usize) -> BNode {
    let (left, right) = boxes.split_at(mid);
    let ((lb, lc), (rb, rc)) = (bound_seq(left), bound_seq(right));
    split_into(cx, slots, boxes, order, first, mid, depth, [lb, rb], [lc, rc], [false; 2])
}

/// The box and the centroids' box of `boxes`.
fn bound_seq(boxes: &[Box3]) -> (Box3, Box3) {
    boxes.iter().fold((Box3::EMPTY, Box3::EMPTY), |(b, c), x| (b.union(*x), c.grow(x.center())))
}

/// Builds the two children of a split at `mid`, given their boxes and centroid bounds, and
/// whether their bins are filled (the left one's in `slots[1]`, the right one's in `slots[0]`).
#[allow(clippy::too_many_arguments)]
fn split_into(
    cx: &Ctx,
    slots: &mut [Slot],
    boxes: &mut [Box3],
    order: &mut [u32],
    first: usize,
    mid: usize,
    depth: usize,
    bounds: [Box3; 2],
    centroids: [Box3; 2],
    binned: [bool; 2],
) -> BNode {
    let n = order.len();
    let (lbox, rbox) = boxes.split_at_mut(mid);
    let (lord, rord) = order.split_at_mut(mid);
    let (lb, rb) = (bounds[0].aabb(), bounds[1].aabb());
    // Median splits below SAH_MAX_DEPTH may run out of slots; they use none.
    let (own, below) = slots.split_at_mut(slots.len().min(1));
    let (a, b) = if n >= PARALLEL_MIN {
        rayon::join(
            || build_rec(cx, below, binned[0], lbox, lord, first, lb, centroids[0], depth + 1),
            || {
                // The right side may run on another thread: a stack of its own, its bins moved there.
                let mut stack = cx.stack();
                if let Some(s) = own.first_mut() {
                    std::mem::swap(&mut stack[0], s);
                }
                let b = build_rec(cx, &mut stack, binned[1], rbox, rord, first + mid, rb, centroids[1], depth + 1);
                cx.give_back(stack);
                b
            },
        )
    } else {
        let a = build_rec(cx, below, binned[0], lbox, lord, first, lb, centroids[0], depth + 1);
        (a, build_rec(cx, slots, binned[1], rbox, rord, first + mid, rb, centroids[1], depth + 1))
    };
    cx.arena.push(Inner { bounds: [lb, rb], children: [a, b] })
}

/// `(((c - lo) * scale) as usize).min(BINS - 1)` on the three axes at once, with the same
/// result: the distance `(c - lo) * scale` is non-negative or NaN (0 * inf). `minps` and
/// `maxps` return their second operand when one is NaN (or both are zeros): the minimum with
/// BINS - 1 keeps a NaN, the maximum with 0 then turns it (and -0) into 0, as the saturating
/// `as usize` does, and truncation of what is left, in [0, BINS - 1], is the cast's.
#[inline(always)]
fn bin_indices(c: Vec3A, lo: Vec3A, scale: Vec3A) -> [usize; 3] {
    let v = (c - lo) * scale;
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86_64 baseline.
        let i = unsafe {
            let m = _mm_max_ps(_mm_min_ps(_mm_set1_ps((BINS - 1) as f32), v.into()), _mm_setzero_ps());
            let mut out = [0i32; 4];
            _mm_storeu_si128(out.as_mut_ptr() as *mut __m128i, _mm_cvttps_epi32(m));
            out
        };
        [i[0] as usize, i[1] as usize, i[2] as usize]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let one = |x: f32| (x as usize).min(BINS - 1);
        [one(v.x), one(v.y), one(v.z)]
    }
}

/// Whether a centroid's bin on the split axis is left of the split bin, as
/// `bin_indices(c, lo, scale)[axis] < bin`, with the same result: for a split bin in
/// 1..=BINS - 1, the clamped and truncated distance is below it exactly when the distance
/// `(c - lo) * scale` is not at least it (a NaN, which the clamp makes 0, is not), so one
/// compare of the distances (all three axes at once, one bit of the mask) does without the
/// clamp and the conversion.
struct SideTest {
    lo: Vec3A,
    scale: Vec3A,
    axis: usize,
    bin: Vec3A,
}

impl SideTest {
    fn new(lo: Vec3A, scale: Vec3A, axis: usize, bin: usize) -> SideTest {
        debug_assert!((1..BINS).contains(&bin), "split bin {bin}");
        SideTest { lo, scale, axis, bin: Vec3A::splat(bin as f32) }
    }

    #[inline(always)]
    fn left(&self, c: Vec3A) -> bool {
        let v = (c - self.lo) * self.scale;
        v.cmpge(self.bin).bitmask() >> self.axis & 1 == 0
    }
}

/// A node's best binned SAH split.
struct Split {
    /// Sum of area * groups of the two sides.
    cost: f32,
    axis: usize,
    /// The first bin of the right side.
    bin: usize,
    /// Primitives on the left side.
    count: usize,
    /// The sides' boxes and their centroids' boxes (the unions of their bins).
    bounds: [Box3; 2],
    centroids: [Box3; 2],
}

/// Best binned SAH split over the three axes of the filled `bins` (`scale` bins per unit, 0 on a
/// flat axis), which are left empty.
fn best_split(bins: &mut Bins, scale: Vec3A, g: usize) -> Option<Split> {
    let occupied = occupied_bins(&bins.counts);
    let Bins { bins: bin_b, counts: bin_n, .. } = bins;
    // ceil(n / g) without a division where g is a power of two (leaf groups are).
    let shift = g.is_power_of_two().then(|| g.trailing_zeros());
    let groups_of = |n: usize| match shift {
        Some(s) => ((n + g - 1) >> s) as f32,
        None => groups(n, g),
    };
    // The boxes swept are kept as bins are (the upper corner negated).
    const NONE: Box3 = Box3 { min: Vec3A::INFINITY, max: Vec3A::INFINITY };
    let area = |b: Box3| Box3 { min: b.min, max: -b.max }.surface_area();
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        // A flat axis: its scale is 0 (the extent was not positive).
        if scale[axis] <= 0.0 {
            continue;
        }
        let (bin_b, bin_n, occupied) = (&bin_b[axis], &bin_n[axis], occupied[axis]);
        // The cost of the bins from each occupied one up (bin 0 never starts a right side).
        let mut right_cost = [0.0f32; BINS];
        let (mut acc, mut cnt) = (NONE, 0usize);
        let mut m = occupied & !1;
        while m != 0 {
            let k = 31 - m.leading_zeros() as usize;
            m &= !(1 << k);
            acc = bin_b[k].grow_box(acc);
            cnt += bin_n[k] as usize;
            right_cost[k] = area(acc) * groups_of(cnt);
        }
        // Split candidates: between an occupied bin `a` and the next occupied one `b`, every
        // split in a+1..=b has the same two sides, hence the same cost, and the first of equal
        // costs wins: only a+1 is tried. An empty bin changes neither box nor count, so the
        // unions and costs are those of a sweep over all bins.
        let (mut acc, mut cnt) = (NONE, 0usize);
        let mut m = occupied;
        while m != 0 {
            let a = m.trailing_zeros() as usize;
            m &= m - 1;
            acc = bin_b[a].grow_box(acc);
            cnt += bin_n[a] as usize;
            if m == 0 {
                break;
            }
            let b = m.trailing_zeros() as usize;
            if !right_cost[b].is_finite() {
                continue;
            }
            let cost = area(acc) * groups_of(cnt) + right_cost[b];
            if best.is_none_or(|x| cost < x.0) {
                best = Some((cost, axis, a + 1));
            }
        }
    }
    // The sides' bounds and counts: unions of their bins (exact, a zero's sign aside).
    let split = best.map(|(cost, axis, bin)| {
        let (mut sides, mut count) = ([Bin::EMPTY; 2], 0usize);
        let mut m = occupied[axis];
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let s = usize::from(k >= bin);
            sides[s] = sides[s].union(bin_b[axis][k]);
            count += if s == 0 { bin_n[axis][k] as usize } else { 0 };
        }
        Split { cost, axis, bin, count, bounds: sides.map(|b| b.box3()), centroids: sides.map(|b| b.centroids()) }
    });
    // Empty what was filled (a flat axis's primitives went to its bin 0).
    for ((set, n), &occ) in bin_b.iter_mut().zip(bin_n.iter_mut()).zip(&occupied) {
        let mut m = occ;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            set[k] = Bin::EMPTY;
            n[k] = 0;
        }
    }
    split
}

/// Bins `boxes` into `bins` (empty, the odd set left empty), on the grid from `lo` at `scale`
/// bins per unit. The nodes near the root on rayon's threads, chunk by chunk: unions are exact
/// in any order and counts add up, so the merged bins are the serial pass's (a zero's sign aside).
fn fill_bins(isa: u8, bins: &mut Bins, boxes: &[Box3], lo: Vec3A, scale: Vec3A) {
    if boxes.len() >= PARALLEL_MIN {
        use rayon::prelude::*;
        let fill = |chunk: &[Box3]| {
            let mut b = Box::new(Bins::new());
            fill_bins(isa, &mut b, chunk, lo, scale);
            b
        };
        let merged = boxes.par_chunks(PARALLEL_MIN / 2).map(fill).reduce_with(|mut a, b| {
            a.merge(&b);
            a
        });
        if let Some(m) = merged {
            bins.merge(&m);
        }
        return;
    }
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: the CPU has the set `isa` names.
        match isa {
            AVX512 => return unsafe { fill_bins_avx512(bins, boxes, lo, scale) },
            AVX => return unsafe { fill_bins_avx(bins, boxes, lo, scale) },
            _ => {}
        }
    }
    fill_bins_with::<SSE>(bins, boxes, lo, scale);
}

/// [`fill_bins`] compiled for AVX: each bin's union two instructions (see [`Bin`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn fill_bins_avx(bins: &mut Bins, boxes: &[Box3], lo: Vec3A, scale: Vec3A) {
    fill_bins_with::<AVX>(bins, boxes, lo, scale);
}

/// [`fill_bins`] compiled for AVX-512: each bin's union one instruction.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,avx512f")]
unsafe fn fill_bins_avx512(bins: &mut Bins, boxes: &[Box3], lo: Vec3A, scale: Vec3A) {
    fill_bins_with::<AVX512>(bins, boxes, lo, scale);
}

/// Adds one box, of centroid `c`, to a set of bins and its counts (`ISA` as in [`Bin::add`]).
#[inline(always)]
fn bin_one<const ISA: u8>(set: &mut [[Bin; BINS]; 3], counts: &mut [[u32; BINS]; 3], b: &Box3, c: Vec3A, lo: Vec3A, scale: Vec3A) {
    let k = bin_indices(c, lo, scale);
    let row = Bin::of(b, c);
    for axis in 0..3 {
        // The mask keeps the index (at most BINS - 1) and drops the bounds checks.
        let i = k[axis] & (BINS - 1);
        // SAFETY: `ISA` is only instantiated inside code compiled for it.
        unsafe { set[axis][i].add::<ISA>(&row) };
        counts[axis][i] += 1;
    }
}

#[inline(always)]
fn fill_bins_with<const ISA: u8>(bins: &mut Bins, boxes: &[Box3], lo: Vec3A, scale: Vec3A) {
    let Bins { bins: bin_b, odd: odd_b, counts: bin_n } = bins;
    if boxes.len() >= TWO_BIN_SETS_MIN {
        // Neighbours often land in the same bin: two sets of boxes (even and odd primitives)
        // halve the chains of unions through memory. Unions are exact in any order: the
        // merged boxes are one set's (a zero's sign aside).
        let pairs = boxes.chunks_exact(2);
        let rest = pairs.remainder();
        for pair in pairs {
            bin_one::<ISA>(bin_b, bin_n, &pair[0], pair[0].center(), lo, scale);
            bin_one::<ISA>(odd_b, bin_n, &pair[1], pair[1].center(), lo, scale);
        }
        for b in rest {
            bin_one::<ISA>(bin_b, bin_n, b, b.center(), lo, scale);
        }
        // The counts are both sets': an odd bin in use is an occupied one.
        let occupied = occupied_bins(bin_n);
        for ((set, odd), &occ) in bin_b.iter_mut().zip(odd_b.iter_mut()).zip(&occupied) {
            let mut m = occ;
            while m != 0 {
                let k = m.trailing_zeros() as usize;
                m &= m - 1;
                set[k] = set[k].union(odd[k]);
                odd[k] = Bin::EMPTY;
            }
        }
    } else {
        for b in boxes {
            bin_one::<ISA>(bin_b, bin_n, b, b.center(), lo, scale);
        }
    }
}

/// A child's bins, with the lower corner and scale of its grid.
type Kid<'a> = Option<(&'a mut Bins, (Vec3A, Vec3A))>;

/// Partitions `boxes` and `order` by `side` (the left side first, in the order of the swaps,
/// which is the tree's primitive order) and adds each primitive to its side's bins where `kids`
/// has them: the children's split searches need no pass of their own over their primitives.
/// Returns the left side's size.
fn partition(isa: u8, boxes: &mut [Box3], order: &mut [u32], side: &SideTest, kids: [Kid; 2]) -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: the CPU has the set `isa` names.
        match isa {
            AVX512 => return unsafe { partition_avx512(boxes, order, side, kids) },
            AVX => return unsafe { partition_avx(boxes, order, side, kids) },
            _ => {}
        }
    }
    partition_with::<SSE>(boxes, order, side, kids)
}

/// [`partition`] compiled for AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn partition_avx(boxes: &mut [Box3], order: &mut [u32], side: &SideTest, kids: [Kid; 2]) -> usize {
    partition_with::<AVX>(boxes, order, side, kids)
}

/// [`partition`] compiled for AVX-512.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,avx512f")]
unsafe fn partition_avx512(boxes: &mut [Box3], order: &mut [u32], side: &SideTest, kids: [Kid; 2]) -> usize {
    partition_with::<AVX512>(boxes, order, side, kids)
}

#[inline(always)]
fn partition_with<const ISA: u8>(boxes: &mut [Box3], order: &mut [u32], side: &SideTest, kids: [Kid; 2]) -> usize {
    let [mut left, mut right] = kids;
    let mut l = 0;
    for k in 0..boxes.len() {
        let b = boxes[k];
        let c = b.center();
        if side.left(c) {
            // The swap, with the box at k already in registers.
            boxes[k] = boxes[l];
            boxes[l] = b;
            order.swap(k, l);
            l += 1;
            if let Some((bins, (lo, scale))) = &mut left {
                bin_one::<ISA>(&mut bins.bins, &mut bins.counts, &b, c, *lo, *scale);
            }
        } else if let Some((bins, (lo, scale))) = &mut right {
            bin_one::<ISA>(&mut bins.bins, &mut bins.counts, &b, c, *lo, *scale);
        }
    }
    l
}

/// The occupied bins of each axis (a bin's occupancy in one bit): what is swept and emptied.
fn occupied_bins(counts: &[[u32; BINS]; 3]) -> [u32; 3] {
    counts.map(|n| {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            // The 32 counts compared with 0 four at a time, narrowed to bytes, their sign bits
            // gathered: a few instructions where the fold took a hundred and fifty.
            const _: () = assert!(BINS == 32);
            // SAFETY: SSE2 is part of the x86_64 baseline; the eight loads of four read the 32 counts.
            unsafe {
                let p = n.as_ptr() as *const __m128i;
                let zero = _mm_setzero_si128();
                let empty = |k: usize| _mm_cmpeq_epi32(_mm_loadu_si128(p.add(k)), zero);
                let low = _mm_packs_epi16(_mm_packs_epi32(empty(0), empty(1)), _mm_packs_epi32(empty(2), empty(3)));
                let high = _mm_packs_epi16(_mm_packs_epi32(empty(4), empty(5)), _mm_packs_epi32(empty(6), empty(7)));
                !(_mm_movemask_epi8(low) as u32 | (_mm_movemask_epi8(high) as u32) << 16)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        (0..BINS).fold(0u32, |m, k| m | u32::from(n[k] != 0) << k)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::rng::Pcg32;
    use glam::Vec3;

    /// Build with both builders and compare everything the caller sees: the order, the
    /// leaves handed out (in turn), and the nodes' boxes and codes, bit for bit (a zero's sign
    /// aside: unions in another order may pick the other zero).
    fn same_tree(bounds: &[Aabb], params: LeafParams) {
        let mut leaves_new = Vec::new();
        let (nodes_new, order_new) = build_wide(
            bounds.len(),
            |i| bounds[i],
            params,
            |s| {
                leaves_new.push(s.to_vec());
                leaf_code_for_test(leaves_new.len())
            },
        );
        let mut leaves_old = Vec::new();
        let (nodes_old, order_old) = reference::build_wide_reference(bounds, params, |s| {
            leaves_old.push(s.to_vec());
            leaf_code_for_test(leaves_old.len())
        });
        assert_eq!(order_new, order_old);
        assert_eq!(leaves_new, leaves_old);
        assert_eq!(nodes_new.len(), nodes_old.len());
        for (a, b) in nodes_new.iter().zip(&nodes_old) {
            assert_eq!(a.bits_for_test(), b.bits_for_test());
        }
    }

    fn leaf_code_for_test(k: usize) -> u32 {
        super::super::wide::leaf_code(k, 1)
    }

    fn tri_box(rng: &mut Pcg32, center: Vec3, size: f32) -> Aabb {
        let mut v = || center + size * Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5);
        Aabb::from_points(&[v(), v(), v()])
    }

    #[test]
    fn same_tree_as_the_reference_build() {
        let tri = LeafParams { group: 8, max_leaf: 16, traversal_cost: 0.15 };
        let one = LeafParams { group: 1, max_leaf: 4, traversal_cost: 1.0 };
        let odd = LeafParams { group: 3, max_leaf: 12, traversal_cost: 0.5 };
        let mut rng = Pcg32::new(7, 3);
        // A soup, large enough for the parallel split.
        let point = |rng: &mut Pcg32| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let soup: Vec<Aabb> = (0..20_000)
            .map(|_| {
                let c = point(&mut rng) * 10.0;
                tri_box(&mut rng, c, 0.3)
            })
            .collect();
        // Clusters of small triangles (meshes placed apart), on a plane (a flat axis), and
        // with corners on zeros of both signs.
        let mut clusters = Vec::new();
        for c in 0..12 {
            let center = Vec3::new(0.0, 3.0 * c as f32 - 18.0, (c % 3) as f32);
            for _ in 0..700 {
                let c = center + point(&mut rng) - 0.5;
                clusters.push(tri_box(&mut rng, c, 0.05));
            }
        }
        let flat: Vec<Aabb> = (0..3000)
            .map(|i| {
                let x = rng.next_f32() * 4.0;
                let z = if i % 2 == 0 { 0.0 } else { -0.0 };
                Aabb { min: Vec3::new(x, rng.next_f32(), z), max: Vec3::new(x + 0.01, rng.next_f32() + 1.0, -z) }
            })
            .collect();
        // Identical boxes (no split by centroid), and a geometric series that runs the SAH
        // past its depth limit into median splits.
        let same = vec![Aabb { min: Vec3::ZERO, max: Vec3::ONE }; 100];
        let deep: Vec<Aabb> = (0..400).map(|i| Aabb::from_points(&[Vec3::splat(0.8f32.powi(i)), Vec3::splat(0.8f32.powi(i) * 1.001)])).collect();
        for set in [&soup, &clusters, &flat, &same, &deep] {
            for params in [tri, one, odd] {
                same_tree(set, params);
            }
        }
        // The children binned in their parent's partition or by themselves (`Ctx::fuse_max`
        // depends on the threads): the same tree either way.
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("rayon pool");
            pool.install(|| same_tree(&soup, tri));
        }
        assert!(MEDIAN_SPLITS.load(std::sync::atomic::Ordering::Relaxed) > 0, "the deep set did not reach the median splits");
        same_tree(&soup[..1], tri);
        same_tree(&[], tri);
    }

    #[test]
    fn occupied_bins_are_the_nonzero_counts() {
        let mut rng = Pcg32::new(3, 5);
        for _ in 0..2000 {
            let mut counts = [[0u32; BINS]; 3];
            for row in &mut counts {
                for c in row.iter_mut() {
                    // Mostly empty bins, some counts with only high bits set.
                    *c = match rng.next_u32() % 8 {
                        0 => rng.next_u32(),
                        1 => 1,
                        2 => 0x8000_0000,
                        3 => 0x1_0000,
                        _ => 0,
                    };
                }
            }
            let want = counts.map(|n| (0..BINS).fold(0u32, |m, k| m | u32::from(n[k] != 0) << k));
            assert_eq!(occupied_bins(&counts), want);
        }
    }

    #[test]
    fn side_test_is_the_bin_index_compare() {
        let mut rng = Pcg32::new(9, 2);
        let specials = [0.0f32, -0.0, 1e-30, -1e-30, 1e30, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 31.0, 30.999998, 1.0, 0.99999994];
        for case in 0..200_000 {
            let mut pick = |k: usize| match rng.next_u32() % 8 {
                0 => specials[(rng.next_u32() as usize + k) % specials.len()],
                _ => rng.next_f32() * 12.0 - 4.0,
            };
            let (c, lo) = (Vec3A::new(pick(0), pick(1), pick(2)), Vec3A::new(pick(3), pick(4), pick(5)));
            let scale = Vec3A::new(pick(6), pick(7), pick(8)).abs() * 3.0;
            let (axis, bin) = (case % 3, 1 + (case / 3) % (BINS - 1));
            let want = bin_indices(c, lo, scale)[axis] < bin;
            assert_eq!(SideTest::new(lo, scale, axis, bin).left(c), want, "c {c} lo {lo} scale {scale} axis {axis} bin {bin}");
        }
    }

    #[test]
    fn bin_indices_match_the_saturating_cast() {
        let scalar = |c: f32, lo: f32, scale: f32| (((c - lo) * scale) as usize).min(BINS - 1);
        let cases = [
            (0.0f32, 0.0f32, 0.0f32),
            (-0.0, 0.0, 3.0),
            (1.0, 0.0, 31.9),
            (1.0, 0.0, 32.0),
            (5.0, 1.0, 1e30),
            (0.0, 0.0, f32::INFINITY),
            (1e-30, 0.0, f32::INFINITY),
            (2.0, 1.0, 31.0),
        ];
        for &(c, lo, scale) in &cases {
            let got = bin_indices(Vec3A::splat(c), Vec3A::splat(lo), Vec3A::splat(scale));
            assert_eq!(got, [scalar(c, lo, scale); 3], "c {c} lo {lo} scale {scale}");
        }
        let mut rng = Pcg32::new(1, 1);
        for _ in 0..100_000 {
            let (lo, c, scale) = (rng.next_f32() * 10.0 - 5.0, rng.next_f32() * 10.0, rng.next_f32() * 40.0);
            let c = lo + c;
            assert_eq!(bin_indices(Vec3A::splat(c), Vec3A::splat(lo), Vec3A::splat(scale))[1], scalar(c, lo, scale));
        }
    }
}
