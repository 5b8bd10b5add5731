//! The wide node and its traversal: SIMD slab tests for eight child boxes (two
//! groups of four lanes), children visited nearest first, stack entries skipped
//! once a nearer hit is known. Incoherent rays over a large mesh wait on memory at
//! every level, so the width is chosen for a shallow tree, not for the SIMD unit.

use super::build::MAX_STACK;
use crate::geometry::Aabb;
use glam::{Vec3, Vec4};
use std::mem::MaybeUninit;

/// Set in a child code that names a leaf: `LEAF_BIT | start << 4 | (count - 1)`.
pub const LEAF_BIT: u32 = 1 << 31;
/// An unused child slot. Its box is empty, so the slab test never selects it.
pub const EMPTY_CHILD: u32 = u32::MAX;
const LEAF_COUNT_BITS: u32 = 4;
/// Children per node.
pub const WIDTH: usize = 8;
const GROUPS: usize = WIDTH / 4;
/// Most entries (groups) one leaf code can hold.
pub const LEAF_MAX_ENTRIES: usize = 1 << LEAF_COUNT_BITS;

#[inline]
pub fn leaf_code(start: usize, count: usize) -> u32 {
    assert!((1..=LEAF_MAX_ENTRIES).contains(&count), "leaf of {count} entries");
    assert!(start < (1 << (31 - LEAF_COUNT_BITS)), "too many leaf entries for the child code");
    LEAF_BIT | (start as u32) << LEAF_COUNT_BITS | (count as u32 - 1)
}

/// (start, count) of a leaf code.
#[inline]
pub fn leaf_range(code: u32) -> (usize, usize) {
    let c = code & !LEAF_BIT;
    ((c >> LEAF_COUNT_BITS) as usize, (c & ((1 << LEAF_COUNT_BITS) - 1)) as usize + 1)
}

/// Child boxes in SoA form (`planes[min x, y, z, max x, y, z][group]`, one lane per
/// child) and their codes: an inner node's index, or a leaf code. Four cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub struct Node {
    planes: [[Vec4; GROUPS]; 6],
    pub(super) children: [u32; WIDTH],
}

impl Node {
    pub fn empty() -> Node {
        let (inf, ninf) = ([Vec4::INFINITY; GROUPS], [Vec4::NEG_INFINITY; GROUPS]);
        Node { planes: [inf, inf, inf, ninf, ninf, ninf], children: [EMPTY_CHILD; WIDTH] }
    }

    pub fn new(boxes: &[Aabb], children: [u32; WIDTH]) -> Node {
        let mut n = Node::empty();
        n.children = children;
        for (k, b) in boxes.iter().enumerate() {
            for a in 0..3 {
                n.planes[a][k / 4][k % 4] = b.min[a];
                n.planes[3 + a][k / 4][k % 4] = b.max[a];
            }
        }
        n
    }

    /// The planes' bits (a zero's sign aside) and the child codes, for comparing trees.
    #[cfg(test)]
    pub(super) fn bits_for_test(&self) -> (Vec<u32>, [u32; WIDTH]) {
        (self.planes.iter().flatten().flat_map(|v| v.to_array()).map(|x| (x + 0.0).to_bits()).collect(), self.children)
    }

    /// Union of the children's boxes.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for k in 0..WIDTH {
            if self.children[k] != EMPTY_CHILD {
                let p = |a: usize| self.planes[a][k / 4][k % 4];
                b = b.union(Aabb { min: Vec3::new(p(0), p(1), p(2)), max: Vec3::new(p(3), p(4), p(5)) });
            }
        }
        b
    }
}

/// Per-ray data for the slab test: origin and inverse direction, broadcast by the SIMD
/// tests at use (a broadcast costs what reloading a spilled splat costs).
#[derive(Clone, Copy, Debug)]
pub struct BoxRay {
    o: [f32; 3],
    /// The inverse direction, and 1 in the fourth lane (written by one store).
    inv: [f32; 4],
    /// Byte offset into `Node::planes` of the near and far slab's planes per axis (the fourth
    /// unused): a plane is then loaded at node + offset, with no index scaling and no bounds
    /// check (each of which cost an instruction per plane in every node visit).
    near: [u32; 4],
    far: [u32; 4],
}

/// Bytes of one plane's row in `Node::planes` (the eight children's values).
pub(super) const PLANE_BYTES: usize = std::mem::size_of::<[Vec4; GROUPS]>();

/// Slack on the far distance: 1 + 2 gamma(3) (PBRT's bound on the rounding error of
/// the slab test), so that a box whose face a triangle touches is not missed.
pub(super) const FAR_SLACK: f32 = 1.0 + 2.0 * (3.0 * f32::EPSILON * 0.5) / (1.0 - 3.0 * f32::EPSILON * 0.5);

impl BoxRay {
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> BoxRay {
        // A zero component gives an infinite inverse: the slab's distances are -inf and +inf
        // for an origin inside it, and NaN (0 * inf) for one on its plane, which the tests'
        // max/min chains pass over (the ray runs along the face: it may meet what lies there).
        // A negative inverse (-0 included) swaps the slab's near and far planes: the near
        // plane's row is the axis's, three rows further when swapped.
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            // All lanes at once (SSE2, always there on x86_64): the per-axis sign tests and
            // offsets were a fifth of a ray's set-up. The same quotients as `Vec3::recip`.
            // SAFETY: SSE2 is part of x86_64; the stores write whole four-lane fields.
            unsafe {
                let inv = _mm_div_ps(_mm_set1_ps(1.0), _mm_setr_ps(d.x, d.y, d.z, 1.0));
                let rows = 3 * PLANE_BYTES as i32;
                let flip = _mm_and_si128(_mm_srai_epi32::<31>(_mm_castps_si128(inv)), _mm_set1_epi32(rows));
                let p = PLANE_BYTES as i32;
                let near = _mm_add_epi32(_mm_setr_epi32(0, p, 2 * p, 0), flip);
                let far = _mm_sub_epi32(_mm_setr_epi32(rows, rows + p, rows + 2 * p, 0), flip);
                let mut r = BoxRay { o: o.to_array(), inv: [0.0; 4], near: [0; 4], far: [0; 4] };
                _mm_storeu_ps(r.inv.as_mut_ptr(), inv);
                _mm_storeu_si128(r.near.as_mut_ptr() as *mut __m128i, near);
                _mm_storeu_si128(r.far.as_mut_ptr() as *mut __m128i, far);
                r
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let inv = d.recip();
            let neg = inv.is_negative_bitmask();
            let flip = [neg & 1, (neg >> 1) & 1, (neg >> 2) & 1];
            let p = PLANE_BYTES as u32;
            BoxRay {
                o: o.to_array(),
                inv: [inv.x, inv.y, inv.z, 1.0],
                near: [3 * flip[0], 1 + 3 * flip[1], 2 + 3 * flip[2], 0].map(|k| k * p),
                far: [3 - 3 * flip[0], 4 - 3 * flip[1], 5 - 3 * flip[2], 0].map(|k| k * p),
            }
        }
    }

    /// The row of planes of `n` at byte offset `off` (one of `near`, `far`).
    #[inline(always)]
    pub(super) fn plane(n: &Node, off: usize) -> &[Vec4; GROUPS] {
        debug_assert!(off.is_multiple_of(PLANE_BYTES) && off < 6 * PLANE_BYTES);
        // SAFETY: `off` comes from `new`: a multiple of a row's size below six rows, so the
        // row lies inside `n.planes` (rows are contiguous, `planes` being an array).
        unsafe { &*((n.planes.as_ptr() as *const u8).add(off) as *const [Vec4; GROUPS]) }
    }

    /// The slab test of `test`, all eight children in one AVX register: the same
    /// operations in the same order, so the result is bit-identical.
    ///
    /// # Safety
    /// The CPU must support AVX, and the caller must be compiled with it enabled
    /// (`#[target_feature(enable = "avx")]`) so that this inlines into AVX code.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn test_avx(&self, n: &Node, t_max: f32) -> ([f32; WIDTH], u32) {
        use std::arch::x86_64::*;
        // A row of `planes` is eight contiguous floats (two Vec4 groups), 32-byte aligned by the node's alignment.
        let plane = |off: u32| _mm256_load_ps(Self::plane(n, off as usize).as_ptr() as *const f32);
        let o = |a: usize| _mm256_set1_ps(self.o[a]);
        let inv = |a: usize| _mm256_set1_ps(self.inv[a]);
        let slab = |k: u32, a: usize| _mm256_mul_ps(_mm256_sub_ps(plane(k), o(a)), inv(a));
        let (tnx, tny, tnz) = (slab(self.near[0], 0), slab(self.near[1], 1), slab(self.near[2], 2));
        let (tfx, tfy, tfz) = (slab(self.far[0], 0), slab(self.far[1], 1), slab(self.far[2], 2));
        // max/min return their second operand when either is NaN: each slab's distance goes
        // first, the running bound second, so that a NaN slab is skipped.
        let tn = _mm256_max_ps(tnx, _mm256_max_ps(tny, _mm256_max_ps(tnz, _mm256_setzero_ps())));
        let tf = _mm256_mul_ps(_mm256_min_ps(tfx, _mm256_min_ps(tfy, _mm256_min_ps(tfz, _mm256_set1_ps(t_max)))), _mm256_set1_ps(FAR_SLACK));
        let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32;
        let mut tn_all = [0.0; WIDTH];
        _mm256_storeu_ps(tn_all.as_mut_ptr(), tn);
        (tn_all, mask)
    }

    #[inline(always)]
    fn test_dispatch<const AVX: bool>(&self, n: &Node, t_max: f32) -> ([f32; WIDTH], u32) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: AVX = true is only instantiated inside `#[target_feature(enable = "avx")]`
            // functions, which callers enter only after detecting AVX at run time.
            return unsafe { self.test_avx(n, t_max) };
        }
        self.test(n, t_max)
    }

    /// Entry distances of the children and the mask of those the ray meets in `[0, t_max]`.
    #[inline(always)]
    fn test(&self, n: &Node, t_max: f32) -> ([f32; WIDTH], u32) {
        let p = |off: u32| Self::plane(n, off as usize);
        let o = self.o.map(Vec4::splat);
        let inv = self.inv.map(Vec4::splat);
        let mut tn_all = [0.0; WIDTH];
        let mut mask = 0;
        for g in 0..GROUPS {
            let tnx = (p(self.near[0])[g] - o[0]) * inv[0];
            let tny = (p(self.near[1])[g] - o[1]) * inv[1];
            let tnz = (p(self.near[2])[g] - o[2]) * inv[2];
            let tfx = (p(self.far[0])[g] - o[0]) * inv[0];
            let tfy = (p(self.far[1])[g] - o[1]) * inv[1];
            let tfz = (p(self.far[2])[g] - o[2]) * inv[2];
            // As in `test_avx`: a NaN slab distance is passed over (glam's max/min on SSE
            // keep the second operand then, as the portable ones keep the number).
            let tn = tnx.max(tny.max(tnz.max(Vec4::ZERO)));
            let tf = tfx.min(tfy.min(tfz.min(Vec4::splat(t_max)))) * FAR_SLACK;
            mask |= tn.cmple(tf).bitmask() << (4 * g);
            tn.write_to_slice(&mut tn_all[4 * g..4 * g + 4]);
        }
        (tn_all, mask)
    }
}

/// Asks for the cache lines of `len` bytes at `p` ahead of use: the traversal of an
/// incoherent ray waits on memory, and a pushed child is often visited soon after.
#[inline(always)]
pub fn prefetch<T>(p: *const T, len: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        // A plain loop: `step_by` costs more set-up than the prefetches themselves on short runs.
        let mut off = 0;
        while off < len {
            // SAFETY: prefetching is a hint; it never faults, whatever the address.
            unsafe { std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>((p as *const i8).wrapping_add(off)) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, len);
}

/// Asks for a child's lines ahead of its visit: a node's four, or as many of a leaf's
/// primitives and one line more (`leaf_at(code)`: where they start; a triangle block is five
/// lines). The address is chosen without a branch: near the tree's bottom whether a child is a
/// leaf is a coin toss, and a mispredicted branch cost more than a line asked for in vain.
#[inline(always)]
pub(super) fn prefetch_child(enabled: bool, nodes: &[Node], code: u32, leaf_at: &impl Fn(u32) -> *const u8) {
    if !enabled {
        return;
    }
    let leaf = code & LEAF_BIT != 0;
    let node = nodes.as_ptr().wrapping_add(code as usize) as *const u8;
    let p = if leaf { leaf_at(code) } else { node };
    prefetch(p, std::mem::size_of::<Node>());
    // A node's first line again (already asked for), a leaf's fifth.
    prefetch(p.wrapping_add(std::mem::size_of::<Node>() * usize::from(leaf)), 1);
}

/// Walks the tree rooted at `nodes[0]`, calling `leaf(code, t_max)` on every leaf the
/// ray reaches. The callback returns whether it found a hit (and then has lowered
/// `t_max` to it). With `ANY`, stops at the first hit. Returns whether any leaf hit.
/// With `prefetch`, pushed children are prefetched (a leaf's primitives at `leaf_at(code)`):
/// worth it only when the tree does not fit in the caches.
#[inline(always)]
pub fn traverse<const ANY: bool, const AVX: bool>(
    nodes: &[Node],
    ray: &BoxRay,
    t_max: &mut f32,
    prefetch: bool,
    leaf_at: impl Fn(u32) -> *const u8,
    mut leaf: impl FnMut(u32, &mut f32) -> bool,
) -> bool {
    if nodes.is_empty() {
        return false;
    }
    let mut stack = Walk::stack();
    let mut walk = Walk::new();
    while walk.step::<ANY, AVX>(&mut stack, nodes, ray, t_max, prefetch, false, false, &leaf_at, &mut leaf) {}
    walk.found()
}

/// How many of the entries `hits` (child slots) go below slot `k`'s when they are pushed
/// with the nearest on top: the farther ones, and those as far in a lower slot. This is the
/// order a stable sort by decreasing distance of the entries in slot order gives (the
/// insertion sort the walk had), without a branch on the distances (none is NaN).
#[inline(always)]
pub(super) fn entries_below<const AVX: bool>(tn: &[f32; WIDTH], hits: u32, k: usize) -> usize {
    #[cfg(target_arch = "x86_64")]
    if AVX {
        use std::arch::x86_64::*;
        // SAFETY: AVX = true is only instantiated inside functions compiled with AVX, which
        // callers enter only after detecting it at run time (as `test_dispatch`).
        let (farther, tied) = unsafe {
            let (all, t) = (_mm256_loadu_ps(tn.as_ptr()), _mm256_set1_ps(tn[k]));
            (_mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(all, t)) as u32, _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(all, t)) as u32)
        };
        return ((farther | tied & ((1 << k) - 1)) & hits).count_ones() as usize;
    }
    (0..WIDTH).filter(|&j| hits >> j & 1 != 0 && (tn[j] > tn[k] || tn[j] == tn[k] && j < k)).count()
}

/// A walk's stack: (child code, entry distance) of the children still to visit.
pub type WalkStack = [MaybeUninit<(u32, f32)>; MAX_STACK];

/// Where one ray's walk of a tree stands, one visit at a time: several rays' walks can
/// then take turns, so that one ray's wait on memory overlaps another's work. The stack
/// lives apart (see [`Walk::stack`]): it is large, and a walk is moved about.
#[derive(Clone, Copy, Debug)]
pub struct Walk {
    /// Entries on the stack.
    sp: usize,
    /// The entry (child code) the next step visits.
    cur: u32,
    found: bool,
    /// `cur` was asked for by the last step (a child just chosen or pushed): its lines are
    /// likely still on their way, where an entry pushed steps ago is likely in cache.
    fresh: bool,
}

impl Walk {
    /// A walk from the root of a non-empty tree.
    #[inline(always)]
    pub fn new() -> Walk {
        Walk { sp: 0, cur: 0, found: false, fresh: true }
    }

    /// An empty stack for a walk (uninitialized: no work).
    #[inline(always)]
    pub const fn stack() -> WalkStack {
        [const { MaybeUninit::uninit() }; MAX_STACK]
    }

    /// Whether the next entry was asked for by the last step (see `fresh`).
    #[inline(always)]
    pub fn fresh(&self) -> bool {
        self.fresh
    }

    /// Whether a leaf hit (with `ANY`, the walk ended there).
    #[inline(always)]
    pub fn found(&self) -> bool {
        self.found
    }

    /// Visits the current entry (as [`traverse`] does) and moves to the next one. Returns
    /// whether the walk goes on; `stack` must be the one this walk started with. With
    /// `interleaved` (other walks step before this one's next step), a next entry that was
    /// not pushed (and so not prefetched) is prefetched too: its lines arrive meanwhile.
    /// With `lazy` (interleaved closest-hit walks), the farther of two children is pushed
    /// unasked and asked for only when popped, the walk then yielding its turn.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn step<const ANY: bool, const AVX: bool>(
        &mut self,
        stack: &mut WalkStack,
        nodes: &[Node],
        ray: &BoxRay,
        t_max: &mut f32,
        prefetch: bool,
        interleaved: bool,
        lazy: bool,
        leaf_at: &impl Fn(u32) -> *const u8,
        leaf: &mut impl FnMut(u32, &mut f32) -> bool,
    ) -> bool {
        // A closest-hit walk culls many of the entries it pushes: asked for at the push, their
        // lines take miss slots that the walks' next nodes wait for.
        let lazy = !ANY && lazy;
        let cur = self.cur;
        let mut sp = self.sp;
        // Whether the entry popped below was pushed by this step.
        let mut pushed_now = false;
        if cur & LEAF_BIT == 0 {
            debug_assert!((cur as usize) < nodes.len());
            // SAFETY: `cur` is the root (0, of a non-empty tree) or an inner node's code taken from
            // a node of this tree, which the build makes an index into `nodes`. Unchecked: the
            // check's compare and branch on every node visit, and the length kept in a register.
            let node = unsafe { nodes.get_unchecked(cur as usize) };
            let (tn, mut mask) = ray.test_dispatch::<AVX>(node, *t_max);
            if mask != 0 {
                let c = &node.children;
                // `& (WIDTH - 1)`: the mask has WIDTH bits, and saying so drops the bounds checks.
                let first = mask.trailing_zeros() as usize & (WIDTH - 1);
                mask &= mask - 1;
                if mask & mask.wrapping_sub(1) == 0 {
                    // One or two children: on to the nearer, the other one pushed. Without a
                    // branch on their number (a coin toss for the predictor): with one, the
                    // second is the first again, written above the stack's top and not counted.
                    let two = mask != 0;
                    let second = if two { mask.trailing_zeros() as usize & (WIDTH - 1) } else { first };
                    // Occlusion needs no order: any hit ends the walk.
                    let (near, far) = if ANY || tn[first] <= tn[second] { (first, second) } else { (second, first) };
                    if !lazy {
                        prefetch_child(prefetch, nodes, c[far], leaf_at);
                    }
                    stack[sp].write((c[far], tn[far]));
                    self.sp = sp + usize::from(two);
                    self.cur = c[near];
                    self.fresh = true;
                    prefetch_child(interleaved, nodes, c[near], leaf_at);
                    return true;
                }
                let second = mask.trailing_zeros() as usize & (WIDTH - 1);
                mask &= mask - 1;
                // Three or more children: push all, the nearest on top.
                pushed_now = true;
                if ANY {
                    stack[sp].write((c[first], tn[first]));
                    stack[sp + 1].write((c[second], tn[second]));
                    sp += 2;
                    prefetch_child(prefetch, nodes, c[first], leaf_at);
                    prefetch_child(prefetch, nodes, c[second], leaf_at);
                    while mask != 0 {
                        let k = mask.trailing_zeros() as usize & (WIDTH - 1);
                        mask &= mask - 1;
                        prefetch_child(prefetch, nodes, c[k], leaf_at);
                        stack[sp].write((c[k], tn[k]));
                        sp += 1;
                    }
                } else {
                    // Each entry straight to its place in the order the insertion sort of the
                    // entries in bit order gave (see `entries_below`): that sort's branches on
                    // the distances were mispredicted.
                    let hits = mask | 1 << first | 1 << second;
                    let mut rest = hits;
                    while rest != 0 {
                        let k = rest.trailing_zeros() as usize & (WIDTH - 1);
                        rest &= rest - 1;
                        prefetch_child(prefetch, nodes, c[k], leaf_at);
                        stack[sp + entries_below::<AVX>(&tn, hits, k)].write((c[k], tn[k]));
                    }
                    sp += hits.count_ones() as usize;
                }
            }
        } else if cur != EMPTY_CHILD && leaf(cur, t_max) {
            self.found = true;
            if ANY {
                return false;
            }
        }
        // Pop the next entry that may still hold a nearer hit.
        loop {
            if sp == 0 {
                self.sp = 0;
                return false;
            }
            sp -= 1;
            // SAFETY: every entry below sp was written by a push.
            let (n, t) = unsafe { stack[sp].assume_init() };
            // With ANY, t_max stays put until the walk ends, so every pushed entry qualifies.
            if ANY || t <= *t_max * FAR_SLACK {
                self.cur = n;
                self.sp = sp;
                self.fresh = pushed_now;
                if lazy && !pushed_now {
                    // Asked for now; other walks step while it comes.
                    prefetch_child(interleaved, nodes, n, leaf_at);
                    self.fresh = true;
                }
                return true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_ray_is_the_per_axis_set_up() {
        // The all-axes set-up against the per-axis inverse and sign tests it replaces, signed
        // zeros, infinities, NaN and subnormals included.
        let vals = [0.0f32, -0.0, 1.0, -1.0, 3.0, -0.7, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, 1e-40, -1e-40, f32::MAX];
        for &x in &vals {
            for &y in &vals {
                for &z in &vals {
                    let (o, d) = (Vec3::new(0.5, -2.0, 7.0), Vec3::new(x, y, z));
                    let r = BoxRay::new(o, d);
                    let inv = d.recip();
                    assert_eq!(r.o, o.to_array());
                    assert_eq!(r.inv[..3].iter().map(|v| v.to_bits()).collect::<Vec<_>>(), inv.to_array().map(f32::to_bits), "{d}");
                    for a in 0..3 {
                        let flip = inv[a].is_sign_negative() as usize;
                        assert_eq!(r.near[a] as usize, (a + 3 * flip) * PLANE_BYTES, "{d}");
                        assert_eq!(r.far[a] as usize, (a + 3 - 3 * flip) * PLANE_BYTES, "{d}");
                    }
                }
            }
        }
    }
}
