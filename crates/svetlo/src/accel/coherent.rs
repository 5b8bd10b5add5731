//! Eight rays with directions in one octant from nearby origins (a pinhole camera's rays of
//! one pixel, which start on its near plane) walked through the triangle tree as one, as
//! Embree walks a packet: set up once as vectors (a ray per lane, no per-ray structs), each
//! inner node tested once for all eight, each leaf's triangles tested by the rays that enter
//! its box.
//!
//! An inner node's test is the single walk's slab test (`BoxRay::test_avx`, a child per lane)
//! on the rays' bounds: per axis the least and the greatest origin and inverse direction. A
//! rounded difference and a rounded product are monotone in each operand, and the test's
//! max/min chains are monotone too, so the bounds' entry distance is at most each ray's and
//! their exit at least each ray's: the walk enters every box that one of the rays enters in
//! its own walk (with the greatest of the rays' bounds on t). A leaf's box is then tested for
//! each ray (a ray per lane, the single test's operations), and each ray that enters it
//! tests the leaf's blocks as its single walk does (`Tri8::lanes_avx`): the same t, b1, b2,
//! bit for bit. The rays of one pixel differ by less than a pixel, so the walk takes about
//! the inner nodes one ray takes, where eight single walks took eight times as many.
//!
//! The single walk's answer depends on its order only among hits within rounding of one
//! another (which of two tied triangles is kept, whether the second passes the first's t_max
//! cut): the walk keeps each ray's nearest hit and notes any other within a factor `1 + TIE`
//! of it (hits that far are still accepted, to be seen), and a ray with such a rival, or with
//! a triangle that has it on an edge (the single test's double-precision case), is walked
//! again alone by its caller.
//!
//! The 1M-triangle mesh at depth 1 (camera rays only, 256x256 64 spp, one thread): render
//! CPU 0.864 of the interleaved single walks, with about as many instructions (+2.5 % in
//! the walk): one walk's choices for eight rays instead of eight walks' (their branches, the
//! single walks' mispredictions), and its nodes' loads once. Rays that are not alike
//! (bounces: scattered origins and directions) do not qualify: their bounds would span the
//! scene (bsdf_spheres took 5.8 times as long before that check). Full depth, where a
//! packet's lanes mix camera and bounce rays: 1.008 (within noise).

use super::build::MAX_STACK;
use super::bvh::LaneRays;
use super::tri8::{nearest_lane, Lanes, Tri8, TriRay8, LANES, NO_TRI};
use super::wide::{leaf_range, prefetch_child, BoxRay, Node, EMPTY_CHILD, FAR_SLACK, LEAF_BIT, PLANE_BYTES, WIDTH};
use std::arch::x86_64::*;
use std::mem::MaybeUninit;

/// Most difference of the rays' direction components, relative to the largest: about a
/// degree (a pixel's rays differ by a tenth of that at 256x256 and a 40-degree field of view).
/// Bounce rays that shared an octant and four or more lanes took 5.8 times as long walked as
/// one (bsdf_spheres).
pub const DIR_SPREAD: f32 = 1.0 / 64.0;
/// Most difference of the rays' origins, relative to the scene's size (camera rays start on
/// the near plane, a hundredth of a unit from the eye).
pub const ORIGIN_SPREAD: f32 = 1.0 / 1024.0;

/// Two hits nearer than this factor apart are a tie whose winner depends on the walk's order
/// (the rounding of the triangle test's t and of its t_max cut are a few ulps, 2^-22).
pub const TIE: f32 = 1.0 / 1024.0;

/// The eight rays, set up once: per axis the bounds of the origins and inverse directions
/// (inner nodes), the rays' origins and inverse directions (leaf boxes), and the watertight
/// test's permutation (shared), permuted origins and shears (triangles). Inactive lanes hold
/// a copy of the first active ray.
pub struct Coherent {
    /// Per axis, the origin that gives the least near-plane distance (the greatest origin
    /// for a positive inverse, the least for a negative one) and the greatest far-plane one.
    o_near: [f32; 3],
    o_far: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    /// Byte offsets of the near and far planes' rows in a node (one octant for all rays).
    near: [usize; 3],
    far: [usize; 3],
    o: [__m256; 3],
    inv: [__m256; 3],
    /// The permutation, as float offsets of an axis row of `Tri8::p`; per ray the origin
    /// permuted and the shear.
    k: [usize; 3],
    ok: [[f32; LANES]; 3],
    s: [[f32; LANES]; 3],
    t_max: [f32; LANES],
}

/// What the walk found, a ray per lane: the nearest hit's t (infinite for none), the nearest
/// t of any other hit (its rival), the hit's slot (block * 8 + lane; -1 for none) and
/// barycentrics, and the rays to walk again alone (a triangle had them on an edge, or two of
/// one block's hits were within the tie factor).
pub struct Found {
    pub t: [f32; LANES],
    pub rival: [f32; LANES],
    pub slot: [i32; LANES],
    pub b1: [f32; LANES],
    pub b2: [f32; LANES],
    pub again: u32,
}

/// The least and the greatest of the eight lanes of `v` (vector shuffles: the scalar folds
/// of `f32::min` and `max`, NaN-aware, cost four instructions a lane).
#[inline(always)]
unsafe fn min_max_lanes(v: __m256) -> (f32, f32) {
    let (lo, hi) = (_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
    let (mut mn, mut mx) = (_mm_min_ps(lo, hi), _mm_max_ps(lo, hi));
    mn = _mm_min_ps(mn, _mm_movehl_ps(mn, mn));
    mx = _mm_max_ps(mx, _mm_movehl_ps(mx, mx));
    (_mm_cvtss_f32(_mm_min_ss(mn, _mm_shuffle_ps::<1>(mn, mn))), _mm_cvtss_f32(_mm_max_ss(mx, _mm_shuffle_ps::<1>(mx, mx))))
}

/// A blend mask of the lanes of `m` (their sign bits set; AVX has no integer compare).
#[inline(always)]
unsafe fn lane_mask(m: u8) -> __m256 {
    let signs: [f32; LANES] = std::array::from_fn(|l| if m & (1 << l) != 0 { -0.0 } else { 0.0 });
    _mm256_loadu_ps(signs.as_ptr())
}

/// The eight lanes of `v`.
#[inline(always)]
unsafe fn lanes(v: __m256) -> [f32; LANES] {
    let mut a = [0.0f32; LANES];
    _mm256_storeu_ps(a.as_mut_ptr(), v);
    a
}

impl Coherent {
    /// The rays of `active` as one, or None where they do not share their octant and their
    /// watertight permutation, or where an origin or a direction has a non-finite component,
    /// a direction a zero one (the slab test's NaN cases) or a t_max is NaN, and where they
    /// are not alike (origins apart by more than `ORIGIN_SPREAD * scale`, `scale` the
    /// scene's size, or directions by more than [`DIR_SPREAD`]): left to the single walk.
    ///
    /// # Safety
    /// The CPU must support AVX, and the caller must be compiled with it enabled.
    #[inline(always)]
    pub unsafe fn new(rays: &impl LaneRays, active: u8, scale: f32) -> Option<Coherent> {
        let first = active.trailing_zeros() as usize & (LANES - 1);
        let lead = rays.ray(first);
        // First a cheap look for unlike rays (a packet's bounce rays, at every bounce): each
        // active ray beside the first one, before the vector set-up.
        let (o_tol, d_tol) = (ORIGIN_SPREAD * scale, DIR_SPREAD * lead.d.abs().max_element());
        let (ov, dv, t_max) = if let Some(r) = rays.rows() {
            // Rows: the same look, eight lanes at once (a component over its tolerance, as
            // `max_element`, which passes over NaN: an ordered compare), the inactive lanes
            // then blended to the first active one.
            let keep = lane_mask(active);
            let (lo, ld) = ([lead.o.x, lead.o.y, lead.o.z], [lead.d.x, lead.d.y, lead.d.z]);
            let abs = |v| _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
            let mut far = _mm256_setzero_ps();
            let (mut ov, mut dv) = ([_mm256_setzero_ps(); 3], [_mm256_setzero_ps(); 3]);
            for a in 0..3 {
                ov[a] = _mm256_blendv_ps(_mm256_set1_ps(lo[a]), _mm256_loadu_ps(r.o[a].as_ptr()), keep);
                dv[a] = _mm256_blendv_ps(_mm256_set1_ps(ld[a]), _mm256_loadu_ps(r.d[a].as_ptr()), keep);
                let o_far = _mm256_cmp_ps::<_CMP_GT_OQ>(abs(_mm256_sub_ps(ov[a], _mm256_set1_ps(lo[a]))), _mm256_set1_ps(o_tol));
                let d_far = _mm256_cmp_ps::<_CMP_GT_OQ>(abs(_mm256_sub_ps(dv[a], _mm256_set1_ps(ld[a]))), _mm256_set1_ps(d_tol));
                far = _mm256_or_ps(far, _mm256_or_ps(o_far, d_far));
            }
            if _mm256_movemask_ps(far) != 0 {
                return None;
            }
            let t = _mm256_blendv_ps(_mm256_set1_ps(lead.t_max), _mm256_loadu_ps(r.t_max.as_ptr()), keep);
            (ov, dv, lanes(t))
        } else {
            for r in (0..LANES).filter(|&l| active & (1 << l) != 0).map(|l| rays.ray(l)) {
                if (r.o - lead.o).abs().max_element() > o_tol || (r.d - lead.d).abs().max_element() > d_tol {
                    return None;
                }
            }
            let (mut o, mut d) = ([[0.0f32; LANES]; 3], [[0.0f32; LANES]; 3]);
            let mut t_max = [0.0f32; LANES];
            for l in 0..LANES {
                let r = if active & (1 << l) != 0 { rays.ray(l) } else { lead };
                (o[0][l], o[1][l], o[2][l]) = (r.o.x, r.o.y, r.o.z);
                (d[0][l], d[1][l], d[2][l]) = (r.d.x, r.d.y, r.d.z);
                t_max[l] = r.t_max;
            }
            let ov = [_mm256_loadu_ps(o[0].as_ptr()), _mm256_loadu_ps(o[1].as_ptr()), _mm256_loadu_ps(o[2].as_ptr())];
            let dv = [_mm256_loadu_ps(d[0].as_ptr()), _mm256_loadu_ps(d[1].as_ptr()), _mm256_loadu_ps(d[2].as_ptr())];
            (ov, dv, t_max)
        };
        let one = _mm256_set1_ps(1.0);
        // As `BoxRay::new`: 1 / d, an exact division, so the single walk's inverse bit for bit.
        // (Vector code out of closures and `map`: those are not compiled with the caller's AVX.)
        let inv = [_mm256_div_ps(one, dv[0]), _mm256_div_ps(one, dv[1]), _mm256_div_ps(one, dv[2])];
        let abs = |v| _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
        let finite = |v| _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(abs(v), _mm256_set1_ps(f32::INFINITY))) == 0xff;
        // A NaN bound would make the walk's greatest bound NaN, and every box test fail.
        let t_nan = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_UNORD_Q>(_mm256_loadu_ps(t_max.as_ptr()), _mm256_setzero_ps())) != 0;
        if t_nan || !(0..3).all(|a| finite(inv[a]) && finite(dv[a]) && finite(ov[a])) {
            return None;
        }
        let mut flip = [0usize; 3];
        for a in 0..3 {
            flip[a] = match _mm256_movemask_ps(inv[a]) {
                0 => 0,
                0xff => 1,
                _ => return None,
            };
        }
        // As `WatertightRay::new`: the dominant axis, the same for all.
        let gt = |a: usize, b: usize| _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(abs(dv[a]), abs(dv[b]))) as u32;
        let (xy, xz, yz) = (gt(0, 1), gt(0, 2), gt(1, 2));
        let kz = match (xy & xz, !xy & yz & 0xff) {
            (0xff, _) => 0,
            (_, 0xff) => 1,
            (0, 0) => 2,
            _ => return None,
        };
        let (mut kx, mut ky) = [(1, 2), (2, 0), (0, 1)][kz];
        if flip[kz] == 1 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = dv[kz];
        let s = [lanes(_mm256_div_ps(dv[kx], dz)), lanes(_mm256_div_ps(dv[ky], dz)), lanes(_mm256_div_ps(one, dz))];
        // Finite values (checked above): no NaN for the min and max to pass over.
        let (mut o_lo, mut o_hi, mut inv_lo, mut inv_hi) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        let (mut d_spread, mut d_len) = (0.0f32, 0.0f32);
        for a in 0..3 {
            (o_lo[a], o_hi[a]) = min_max_lanes(ov[a]);
            (inv_lo[a], inv_hi[a]) = min_max_lanes(inv[a]);
            let (lo, hi) = min_max_lanes(dv[a]);
            d_spread = d_spread.max(hi - lo);
            d_len = d_len.max(hi.abs()).max(lo.abs());
            // Origins apart by more than a small part of the scene (bounce rays): the rays'
            // bounds would take in much of the scene, and the walk with them.
            if o_hi[a] - o_lo[a] > ORIGIN_SPREAD * scale {
                return None;
            }
        }
        // Directions apart by more than about a degree: the same.
        if d_spread > DIR_SPREAD * d_len {
            return None;
        }
        Some(Coherent {
            o_near: [0, 1, 2].map(|a| if flip[a] == 0 { o_hi[a] } else { o_lo[a] }),
            o_far: [0, 1, 2].map(|a| if flip[a] == 0 { o_lo[a] } else { o_hi[a] }),
            inv_lo,
            inv_hi,
            near: [0, 1, 2].map(|a| (a + 3 * flip[a]) * PLANE_BYTES),
            far: [0, 1, 2].map(|a| (a + 3 - 3 * flip[a]) * PLANE_BYTES),
            o: ov,
            inv,
            k: [kx * LANES, ky * LANES, kz * LANES],
            ok: [lanes(ov[kx]), lanes(ov[ky]), lanes(ov[kz])],
            s,
            t_max,
        })
    }

    /// The slab test of `n`'s children (a child per lane) for all eight rays, bounded by
    /// `t_far`: entry distances at most each ray's, and the children that some ray may enter.
    #[inline(always)]
    unsafe fn test(&self, n: &Node, t_far: f32) -> (__m256, u32) {
        let ((nx, fx), (ny, fy), (nz, fz)) = (self.slab(n, 0), self.slab(n, 1), self.slab(n, 2));
        // The single test's chains, in its order.
        let tn = _mm256_max_ps(nx, _mm256_max_ps(ny, _mm256_max_ps(nz, _mm256_setzero_ps())));
        let tf = _mm256_mul_ps(_mm256_min_ps(fx, _mm256_min_ps(fy, _mm256_min_ps(fz, _mm256_set1_ps(t_far)))), _mm256_set1_ps(FAR_SLACK));
        (tn, _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32)
    }

    /// Axis `a`'s near and far distances of `n`'s children: at most, at least each ray's.
    /// (A method, not a closure: a closure is not compiled with its caller's AVX, and it
    /// stayed out of line with its intrinsics called one by one.)
    #[inline(always)]
    unsafe fn slab(&self, n: &Node, a: usize) -> (__m256, __m256) {
        let plane = |off: usize| _mm256_load_ps(BoxRay::plane(n, off).as_ptr() as *const f32);
        let (lo, hi) = (_mm256_set1_ps(self.inv_lo[a]), _mm256_set1_ps(self.inv_hi[a]));
        let dn = _mm256_sub_ps(plane(self.near[a]), _mm256_set1_ps(self.o_near[a]));
        let df = _mm256_sub_ps(plane(self.far[a]), _mm256_set1_ps(self.o_far[a]));
        (_mm256_min_ps(_mm256_mul_ps(dn, lo), _mm256_mul_ps(dn, hi)), _mm256_max_ps(_mm256_mul_ps(df, lo), _mm256_mul_ps(df, hi)))
    }

    /// The rays (a ray per lane) that enter child `c` of `n` within their bounds: the single
    /// test's operations in its order, each ray's own answer.
    #[inline(always)]
    unsafe fn test_child(&self, n: &Node, c: usize, bound: __m256) -> u32 {
        let plane = |off: usize| _mm256_broadcast_ss(&*(BoxRay::plane(n, off).as_ptr() as *const f32).add(c & (WIDTH - 1)));
        let slab = |off: usize, a: usize| _mm256_mul_ps(_mm256_sub_ps(plane(off), self.o[a]), self.inv[a]);
        let (tnx, tny, tnz) = (slab(self.near[0], 0), slab(self.near[1], 1), slab(self.near[2], 2));
        let (tfx, tfy, tfz) = (slab(self.far[0], 0), slab(self.far[1], 1), slab(self.far[2], 2));
        let tn = _mm256_max_ps(tnx, _mm256_max_ps(tny, _mm256_max_ps(tnz, _mm256_setzero_ps())));
        let tf = _mm256_mul_ps(_mm256_min_ps(tfx, _mm256_min_ps(tfy, _mm256_min_ps(tfz, bound))), _mm256_set1_ps(FAR_SLACK));
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32
    }
}

/// The running state of the rays' leaf tests (see [`Found`]), and each ray's bound on t:
/// its own t_max, lowered to `t * (1 + TIE)` by a hit at t.
struct Best {
    f: Found,
    bound: [f32; LANES],
}

impl Best {
    /// Tests ray `l` against the blocks `first..` of `blocks`; returns whether it found a nearer hit.
    #[inline(always)]
    unsafe fn leaf(&mut self, r: &Coherent, blocks: &[Tri8], first: usize, l: usize) -> bool {
        let l = l & (LANES - 1);
        let tray = TriRay8::from_parts(r.k, [r.ok[0][l], r.ok[1][l], r.ok[2][l]], [r.s[0][l], r.s[1][l], r.s[2][l]]);
        let mut lowered = false;
        for (i, block) in blocks.iter().enumerate() {
            let Lanes { mask, on_edge, t_scaled, det, v, w } = block.lanes_avx(&tray, self.bound[l]);
            self.f.again |= ((on_edge != 0) as u32) << l;
            if mask == 0 {
                continue;
            }
            // As `Tri8::intersect_avx`: t = t_scaled * (1 / det) must be > 0.
            let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
            let t = _mm256_mul_ps(t_scaled, inv);
            let m = mask & _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(t, _mm256_setzero_ps())) as u32;
            if m == 0 {
                continue;
            }
            let ta = lanes(t);
            let (lane, tb) = nearest_lane(m, &ta);
            // Another of the block's hits within the tie factor: walked again alone.
            let close = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t, _mm256_set1_ps(tb * (1.0 + TIE)))) as u32;
            self.f.again |= ((close & m & !(1 << lane) != 0) as u32) << l;
            let f = &mut self.f;
            if tb < f.t[l] {
                f.rival[l] = f.rival[l].min(f.t[l]);
                f.t[l] = tb;
                f.slot[l] = ((first + i) * LANES + lane) as i32;
                f.b1[l] = lanes(_mm256_mul_ps(v, inv))[lane & (LANES - 1)];
                f.b2[l] = lanes(_mm256_mul_ps(w, inv))[lane & (LANES - 1)];
                // Hits a little farther are still accepted, to be seen as rivals.
                self.bound[l] = r.t_max[l].min(tb * (1.0 + TIE));
                lowered = true;
            } else {
                f.rival[l] = f.rival[l].min(tb);
            }
        }
        lowered
    }
}

impl Best {
    /// Tests the rays of `rays` against the blocks `first..` of `blocks`, a triangle at a time
    /// for all rays (a ray per lane): lane by lane the operations of [`Best::leaf`], so the
    /// same answers, for the cost of one ray's test per triangle where a leaf is entered by
    /// most of the rays. Returns whether some ray found a nearer hit.
    #[inline(always)]
    unsafe fn leaf_lanes(&mut self, r: &Coherent, blocks: &[Tri8], first: usize, rays: u32) -> bool {
        let (sub, mul) = (|a, b| _mm256_sub_ps(a, b), |a, b| _mm256_mul_ps(a, b));
        let ld = |a: &[f32; LANES]| _mm256_loadu_ps(a.as_ptr());
        let zero = _mm256_setzero_ps();
        let inf = _mm256_set1_ps(f32::INFINITY);
        let [ox, oy, oz] = [ld(&r.ok[0]), ld(&r.ok[1]), ld(&r.ok[2])];
        let [sx, sy, sz] = [ld(&r.s[0]), ld(&r.s[1]), ld(&r.s[2])];
        let [kx, ky, kz] = r.k.map(|k| k.min(2 * LANES));
        let f = &mut self.f;
        let (mut best_t, mut rival, mut bound) = (ld(&f.t), ld(&f.rival), ld(&self.bound));
        let mut slot = _mm256_loadu_ps(f.slot.as_ptr() as *const f32);
        let (mut b1, mut b2) = (ld(&f.b1), ld(&f.b2));
        let in_rays = {
            let m: [u32; LANES] = std::array::from_fn(|l| if rays & (1 << l) != 0 { u32::MAX } else { 0 });
            _mm256_loadu_ps(m.as_ptr() as *const f32)
        };
        let t_max = ld(&r.t_max);
        let (mut edge, mut lowered) = (0u32, false);
        for (i, block) in blocks.iter().enumerate() {
            let base = block.p.as_ptr() as *const f32;
            for j in 0..LANES {
                // The build fills a block's lanes from the front.
                if block.ids[j] == NO_TRI {
                    break;
                }
                // SAFETY: kx, ky, kz are at most 2 * LANES and j < LANES: inside `p`.
                let p = |v: usize, k: usize| _mm256_broadcast_ss(&*base.add(v * 3 * LANES + k + j));
                let az0 = sub(p(0, kz), oz);
                let bz0 = sub(p(1, kz), oz);
                let cz0 = sub(p(2, kz), oz);
                let ax = sub(sub(p(0, kx), ox), mul(sx, az0));
                let ay = sub(sub(p(0, ky), oy), mul(sy, az0));
                let bx = sub(sub(p(1, kx), ox), mul(sx, bz0));
                let by = sub(sub(p(1, ky), oy), mul(sy, bz0));
                let cx = sub(sub(p(2, kx), ox), mul(sx, cz0));
                let cy = sub(sub(p(2, ky), oy), mul(sy, cz0));
                let u = sub(mul(cx, by), mul(cy, bx));
                let v = sub(mul(ax, cy), mul(ay, cx));
                let w = sub(mul(bx, ay), mul(by, ax));
                let on_edge = _mm256_or_ps(
                    _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero)),
                    _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
                );
                let mixed = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
                let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
                let t_scaled = _mm256_add_ps(_mm256_add_ps(mul(u, mul(sz, az0)), mul(v, mul(sz, bz0))), mul(w, mul(sz, cz0)));
                let sign = _mm256_and_ps(det, _mm256_set1_ps(-0.0));
                let ts = _mm256_xor_ps(t_scaled, sign);
                let tmd = _mm256_xor_ps(mul(bound, det), sign);
                let ok = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(ts, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(ts, tmd));
                edge |= _mm256_movemask_ps(on_edge) as u32;
                // Sign bits only (`mixed` is a sign): all that movemask and blendv read.
                let cand = _mm256_and_ps(_mm256_andnot_ps(_mm256_or_ps(on_edge, mixed), ok), in_rays);
                if _mm256_movemask_ps(cand) == 0 {
                    continue;
                }
                let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
                let t = mul(t_scaled, inv);
                let found = _mm256_and_ps(cand, _mm256_cmp_ps::<_CMP_GT_OQ>(t, zero));
                if _mm256_movemask_ps(found) == 0 {
                    continue;
                }
                // Nearer than the best so far (strictly: an equal t is a rival, so a tie).
                let nearer = _mm256_and_ps(found, _mm256_cmp_ps::<_CMP_LT_OQ>(t, best_t));
                // The other hits: the one displaced, or this one.
                rival = _mm256_min_ps(rival, _mm256_blendv_ps(_mm256_blendv_ps(inf, t, found), best_t, nearer));
                if _mm256_movemask_ps(nearer) == 0 {
                    continue;
                }
                lowered = true;
                best_t = _mm256_blendv_ps(best_t, t, nearer);
                slot = _mm256_blendv_ps(slot, _mm256_castsi256_ps(_mm256_set1_epi32(((first + i) * LANES + j) as i32)), nearer);
                b1 = _mm256_blendv_ps(b1, mul(v, inv), nearer);
                b2 = _mm256_blendv_ps(b2, mul(w, inv), nearer);
                // Hits a little farther are still accepted, to be seen as rivals.
                bound = _mm256_blendv_ps(bound, _mm256_min_ps(t_max, mul(t, _mm256_set1_ps(1.0 + TIE))), nearer);
            }
        }
        f.again |= edge & rays;
        f.t = lanes(best_t);
        f.rival = lanes(rival);
        _mm256_storeu_ps(f.slot.as_mut_ptr() as *mut f32, slot);
        f.b1 = lanes(b1);
        f.b2 = lanes(b2);
        self.bound = lanes(bound);
        lowered
    }
}

/// Fewest rays entering a leaf for which it is tested a triangle at a time for all rays.
const LEAF_LANES_MIN: u32 = 4;

/// Walks the tree rooted at `nodes[0]` with the rays of `r` (lanes of `active`), their
/// triangles in `tris`. With `prefetch_nodes`, pushed children are prefetched (a leaf's
/// triangles at `tris_at(code)`).
///
/// # Safety
/// The CPU must support AVX, and the caller must be compiled with it enabled.
#[inline(always)]
pub unsafe fn walk(nodes: &[Node], tris: &[Tri8], r: &Coherent, active: u8, prefetch_nodes: bool, tris_at: impl Fn(u32) -> *const u8) -> Found {
    let inf = f32::INFINITY;
    let found = Found { t: [inf; LANES], rival: [inf; LANES], slot: [-1; LANES], b1: [0.0; LANES], b2: [0.0; LANES], again: 0 };
    let mut best = Best { f: found, bound: r.t_max };
    // The greatest of the active rays' bounds: a box none of them may enter below it is passed over.
    // (Inactive lanes hold a copy of an active ray, so all lanes count.)
    let mut t_far = min_max_lanes(_mm256_loadu_ps(best.bound.as_ptr())).1;
    // Entries: (child code, the packet's entry distance, parent node * WIDTH + child slot).
    let mut stack: [MaybeUninit<(u32, f32, u32)>; MAX_STACK] = [const { MaybeUninit::uninit() }; MAX_STACK];
    let mut sp = 0usize;
    let (mut cur, mut from) = (0u32, 0u32);
    let push_prefetch = |code: u32| prefetch_child(prefetch_nodes, nodes, code, &tris_at);
    'walk: loop {
        if cur & LEAF_BIT == 0 {
            let node = &nodes[cur as usize];
            let (tn, mut mask) = r.test(node, t_far);
            if mask != 0 {
                let c = &node.children;
                let here = cur * WIDTH as u32;
                let first = mask.trailing_zeros() as usize & (WIDTH - 1);
                mask &= mask - 1;
                if mask == 0 {
                    (cur, from) = (c[first], here + first as u32);
                    continue;
                }
                // Push all, nearest on top (it is popped at once).
                let tn_all = lanes(tn);
                let base = sp;
                stack[sp].write((c[first], tn_all[first], here + first as u32));
                sp += 1;
                push_prefetch(c[first]);
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize & (WIDTH - 1);
                    mask &= mask - 1;
                    push_prefetch(c[k]);
                    stack[sp].write((c[k], tn_all[k], here + k as u32));
                    sp += 1;
                }
                // SAFETY: entries base..sp were written just above.
                let top = std::slice::from_raw_parts_mut(stack.as_mut_ptr().add(base) as *mut (u32, f32, u32), sp - base);
                for i in 1..top.len() {
                    let mut j = i;
                    while j > 0 && top[j - 1].1 < top[j].1 {
                        top.swap(j - 1, j);
                        j -= 1;
                    }
                }
            }
        } else if cur != EMPTY_CHILD {
            // The rays that enter the leaf's box (its parent's child `from % WIDTH`), each with its own bound.
            let parent = &nodes[(from / WIDTH as u32) as usize];
            let mut rays = r.test_child(parent, from as usize % WIDTH, _mm256_loadu_ps(best.bound.as_ptr())) & active as u32;
            let (start, count) = leaf_range(cur);
            let blocks = &tris[start..start + count];
            let mut lowered = false;
            if rays.count_ones() >= LEAF_LANES_MIN {
                lowered = best.leaf_lanes(r, blocks, start, rays);
            } else {
                while rays != 0 {
                    let l = rays.trailing_zeros() as usize;
                    rays &= rays - 1;
                    lowered |= best.leaf(r, blocks, start, l);
                }
            }
            if lowered {
                t_far = min_max_lanes(_mm256_loadu_ps(best.bound.as_ptr())).1;
            }
        }
        // Pop the next entry that some ray may still need.
        while sp > 0 {
            sp -= 1;
            // SAFETY: every entry below sp was written by a push.
            let (n, t, f) = stack[sp].assume_init();
            if t <= t_far * FAR_SLACK {
                (cur, from) = (n, f);
                continue 'walk;
            }
        }
        break;
    }
    best.f
}
