//! Eight triangles in SoA form, the leaf block of the triangle BVH. With AVX all eight
//! are tested against one ray at once; without it, `tri4` tests each half of four.
//! Either way the test is the watertight one of `geometry::triangle`, operation for
//! operation in the same order (no FMA), so a lane's accept/reject and its t are
//! bit-identical to the scalar test's. Barycentrics are computed for a block's
//! nearest lane only, from the 1 / det the test has at hand.

use crate::geometry::triangle::WatertightRay;
use glam::Vec3;

/// A block's nearest hit: (lane, t, b1, b2).
pub type Hit = (usize, f32, f32, f32);

/// Triangles per block.
pub const LANES: usize = 8;
/// The id of an unused lane (its vertices are NaN, which every comparison of the test rejects).
pub const NO_TRI: u32 = u32::MAX;

/// `p[vertex][axis][lane]` and each lane's triangle id (kept beside the vertices: a hit
/// then costs no further cache miss). Five cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct Tri8 {
    pub(super) p: [[[f32; LANES]; 3]; 3],
    pub ids: [u32; LANES],
}

impl Tri8 {
    /// Packs up to eight triangles (vertices, id); missing lanes get NaN vertices and [`NO_TRI`].
    pub fn new(tris: &[([Vec3; 3], u32)]) -> Tri8 {
        assert!(!tris.is_empty() && tris.len() <= LANES);
        let mut p = [[[f32::NAN; LANES]; 3]; 3];
        let mut ids = [NO_TRI; LANES];
        for (lane, (t, id)) in tris.iter().enumerate() {
            ids[lane] = *id;
            for (v, pv) in t.iter().enumerate() {
                for a in 0..3 {
                    p[v][a][lane] = pv[a];
                }
            }
        }
        Tri8 { p, ids }
    }

    #[inline]
    pub fn vertices(&self, lane: usize) -> [Vec3; 3] {
        let p = &self.p;
        [0, 1, 2].map(|v| Vec3::new(p[v][0][lane], p[v][1][lane], p[v][2][lane]))
    }

    /// Nearest hit among the eight in `(0, t_max]`: (lane, t, b1, b2). On equal t the lowest lane wins.
    ///
    /// # Safety
    /// The CPU must support AVX, and the caller must be compiled with it enabled
    /// (`#[target_feature(enable = "avx")]`) so that this inlines into AVX code.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn intersect_avx(&self, r: &TriRay8, wr: &WatertightRay, t_max: f32) -> Option<Hit> {
        use std::arch::x86_64::*;
        let Lanes { mut mask, on_edge, t_scaled, det, v, w } = self.lanes_avx(r, t_max);
        let (mul, zero) = (|a, b| _mm256_mul_ps(a, b), _mm256_setzero_ps());
        let mut best: Option<Hit> = None;
        if mask != 0 {
            // As the scalar test: t = t_scaled * (1 / det), and t must be > 0 (it may underflow).
            let inv = _mm256_div_ps(_mm256_set1_ps(1.0), det);
            let t = mul(t_scaled, inv);
            mask &= _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(t, zero)) as u32;
            if mask != 0 {
                let mut ta = [0.0f32; LANES];
                _mm256_storeu_ps(ta.as_mut_ptr(), t);
                let (lane, t) = nearest_lane(mask, &ta);
                // Barycentrics of the nearest lane only (dead code for occlusion rays).
                let (mut b1, mut b2) = ([0.0f32; LANES], [0.0f32; LANES]);
                _mm256_storeu_ps(b1.as_mut_ptr(), mul(v, inv));
                _mm256_storeu_ps(b2.as_mut_ptr(), mul(w, inv));
                best = Some((lane, t, b1[lane & (LANES - 1)], b2[lane & (LANES - 1)]));
            }
        }
        if on_edge != 0 {
            best = self.edge_lanes(on_edge, wr, t_max, best);
        }
        best
    }

    /// The test's lanes up to their distances: the candidate hits (`mask`, edge lanes
    /// excluded), the lanes on an edge, and t_scaled, det, v, w.
    ///
    /// # Safety
    /// As [`Self::intersect_avx`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(super) unsafe fn lanes_avx(&self, r: &TriRay8, t_max: f32) -> Lanes {
        use std::arch::x86_64::*;
        let base = self.p.as_ptr() as *const f32;
        // SAFETY: `r.k*` are axis * LANES with axis < 3, so every offset stays inside `p`;
        // each row is 32-byte aligned by the struct's alignment.
        let ld = |v: usize, k: usize| _mm256_load_ps(base.add(v * 3 * LANES + k));
        let (sub, mul) = (|a, b| _mm256_sub_ps(a, b), |a, b| _mm256_mul_ps(a, b));
        let az0 = sub(ld(0, r.kz), r.oz);
        let bz0 = sub(ld(1, r.kz), r.oz);
        let cz0 = sub(ld(2, r.kz), r.oz);
        let ax = sub(sub(ld(0, r.kx), r.ox), mul(r.sx, az0));
        let ay = sub(sub(ld(0, r.ky), r.oy), mul(r.sy, az0));
        let bx = sub(sub(ld(1, r.kx), r.ox), mul(r.sx, bz0));
        let by = sub(sub(ld(1, r.ky), r.oy), mul(r.sy, bz0));
        let cx = sub(sub(ld(2, r.kx), r.ox), mul(r.sx, cz0));
        let cy = sub(sub(ld(2, r.ky), r.oy), mul(r.sy, cz0));
        let u = sub(mul(cx, by), mul(cy, bx));
        let v = sub(mul(ax, cy), mul(ay, cx));
        let w = sub(mul(bx, ay), mul(by, ax));
        let zero = _mm256_setzero_ps();
        let edge = _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero)), _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero));
        // Off the edges u, v, w are non-zero: the ray is inside iff their signs agree, and then
        // det has that sign too. Flipping t_scaled and t_max * det by det's sign turns the
        // scalar test's front and back cases into one: 0 < t_scaled' <= t_max * |det|.
        let mixed = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
        let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
        let t_scaled = _mm256_add_ps(_mm256_add_ps(mul(u, mul(r.sz, az0)), mul(v, mul(r.sz, bz0))), mul(w, mul(r.sz, cz0)));
        let sign = _mm256_and_ps(det, _mm256_set1_ps(-0.0));
        let ts = _mm256_xor_ps(t_scaled, sign);
        let tmd = _mm256_xor_ps(mul(_mm256_set1_ps(t_max), det), sign);
        let ok = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(ts, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(ts, tmd));
        let on_edge = _mm256_movemask_ps(edge) as u32;
        let mask = _mm256_movemask_ps(ok) as u32 & !(_mm256_movemask_ps(mixed) as u32) & !on_edge;
        Lanes { mask, on_edge, t_scaled, det, v, w }
    }

    /// Whether any of the eight is hit in `(0, t_max]`: `intersect_avx(..).is_some()`
    /// without choosing the nearest lane or its barycentrics (shadow rays read neither).
    ///
    /// # Safety
    /// As [`Self::intersect_avx`].
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn occludes_avx(&self, r: &TriRay8, wr: &WatertightRay, t_max: f32) -> bool {
        use std::arch::x86_64::*;
        let Lanes { mask, on_edge, t_scaled, det, .. } = self.lanes_avx(r, t_max);
        if mask != 0 {
            // As `intersect_avx`: t = t_scaled * (1 / det) must be > 0 (it may underflow).
            let t = _mm256_mul_ps(t_scaled, _mm256_div_ps(_mm256_set1_ps(1.0), det));
            if mask & _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(t, _mm256_setzero_ps())) as u32 != 0 {
                return true;
            }
        }
        on_edge != 0 && self.edge_lanes(on_edge, wr, t_max, None).is_some()
    }

    /// Lanes whose u, v or w is exactly zero: the scalar test, which falls back to f64 there.
    #[cold]
    #[inline(never)]
    pub(super) fn edge_lanes(&self, mut lanes: u32, r: &WatertightRay, t_max: f32, mut best: Option<Hit>) -> Option<Hit> {
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let [p0, p1, p2] = self.vertices(lane);
            if let Some((t, b1, b2)) = r.intersect(p0, p1, p2, t_max) {
                if best.is_none_or(|b| t < b.1 || (t == b.1 && lane < b.0)) {
                    best = Some((lane, t, b1, b2));
                }
            }
        }
        best
    }
}

/// The lane of least t among the set bits of `mask` (the lowest lane on ties).
#[inline(always)]
pub(super) fn nearest_lane(mut mask: u32, t: &[f32]) -> (usize, f32) {
    let mut lane = mask.trailing_zeros() as usize;
    let mut best = t[lane & (LANES - 1)];
    mask &= mask - 1;
    while mask != 0 {
        let l = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let tl = t[l & (LANES - 1)];
        if tl < best {
            (lane, best) = (l, tl);
        }
    }
    (lane, best)
}

/// What the block test's lanes give before the distances are divided out.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(super) struct Lanes {
    pub mask: u32,
    pub on_edge: u32,
    pub t_scaled: std::arch::x86_64::__m256,
    pub det: std::arch::x86_64::__m256,
    pub v: std::arch::x86_64::__m256,
    pub w: std::arch::x86_64::__m256,
}

/// The watertight ray's permutation (as float offsets of an axis row of [`Tri8::p`]) and
/// shear, broadcast to eight lanes. The scalar ray travels beside it, not in it: the cold
/// edge test takes its address, which would otherwise pin this whole struct in memory.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub struct TriRay8 {
    kx: usize,
    ky: usize,
    kz: usize,
    ox: std::arch::x86_64::__m256,
    oy: std::arch::x86_64::__m256,
    oz: std::arch::x86_64::__m256,
    sx: std::arch::x86_64::__m256,
    sy: std::arch::x86_64::__m256,
    sz: std::arch::x86_64::__m256,
}

#[cfg(target_arch = "x86_64")]
impl TriRay8 {
    /// # Safety
    /// As [`Tri8::intersect_avx`].
    #[inline(always)]
    pub unsafe fn new(w: &WatertightRay) -> TriRay8 {
        use std::arch::x86_64::_mm256_set1_ps as splat;
        let o = w.o.to_array();
        // The permutation is always in 0..3 (`& 3` lets the compiler see it, as `% 3` would cost a division).
        let (kx, ky, kz) = (w.kx & 3, w.ky & 3, w.kz & 3);
        let oa = [o[0], o[1], o[2], 0.0];
        TriRay8 {
            kx: kx.min(2) * LANES,
            ky: ky.min(2) * LANES,
            kz: kz.min(2) * LANES,
            ox: splat(oa[kx]),
            oy: splat(oa[ky]),
            oz: splat(oa[kz]),
            sx: splat(w.sx),
            sy: splat(w.sy),
            sz: splat(w.sz),
        }
    }

    /// The ray of a permutation given as float offsets of an axis row of [`Tri8::p`] (each
    /// axis * LANES, axis < 3), the origin permuted and the shear: what `new` makes of a
    /// `WatertightRay` with that permutation, origin and shear.
    ///
    /// # Safety
    /// As [`Tri8::intersect_avx`].
    #[inline(always)]
    pub(super) unsafe fn from_parts(k: [usize; 3], o: [f32; 3], s: [f32; 3]) -> TriRay8 {
        use std::arch::x86_64::_mm256_set1_ps as splat;
        debug_assert!(k.iter().all(|&k| k.is_multiple_of(LANES) && k < 3 * LANES));
        // No closures here: they are not compiled with the caller's AVX (the splats were calls).
        TriRay8 {
            // Clamped: `lanes_avx` loads at these offsets unchecked.
            kx: k[0].min(2 * LANES),
            ky: k[1].min(2 * LANES),
            kz: k[2].min(2 * LANES),
            ox: splat(o[0]),
            oy: splat(o[1]),
            oz: splat(o[2]),
            sx: splat(s[0]),
            sy: splat(s[1]),
            sz: splat(s[2]),
        }
    }
}
