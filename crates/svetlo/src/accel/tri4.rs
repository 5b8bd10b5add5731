//! Four triangles in SoA form, tested against one ray at once with the watertight
//! test of `geometry::triangle`, operation for operation in the same order, so
//! that each lane's result is bit-identical to the scalar test (no FMA, IEEE SSE).

use crate::geometry::triangle::WatertightRay;
use glam::{Vec3, Vec4};

/// `p[vertex][axis]`, one triangle per lane, and each lane's triangle id (kept beside
/// the vertices: a hit then costs no further cache miss). Unused lanes hold NaN
/// vertices, which every comparison of the test rejects.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct Tri4 {
    p: [[Vec4; 3]; 3],
    pub ids: [u32; 4],
}

impl Tri4 {
    /// Packs up to four triangles (vertices, id); missing lanes become NaN.
    pub fn new(tris: &[([Vec3; 3], u32)]) -> Tri4 {
        assert!(!tris.is_empty() && tris.len() <= 4);
        let mut p = [[Vec4::NAN; 3]; 3];
        let mut ids = [tris[0].1; 4];
        for (lane, (t, id)) in tris.iter().enumerate() {
            ids[lane] = *id;
            for (v, pv) in t.iter().enumerate() {
                for a in 0..3 {
                    p[v][a][lane] = pv[a];
                }
            }
        }
        Tri4 { p, ids }
    }

    #[inline]
    fn vertices(&self, lane: usize) -> [Vec3; 3] {
        let p = &self.p;
        [0, 1, 2].map(|v| Vec3::new(p[v][0][lane], p[v][1][lane], p[v][2][lane]))
    }

    /// Nearest hit among the four in `(0, t_max]`: (lane, t, b1, b2). On equal t the lowest lane wins.
    #[inline(always)]
    pub fn intersect(&self, r: &TriRay, t_max: f32) -> Option<(usize, f32, f32, f32)> {
        let [kx, ky, kz] = r.k;
        let p = &self.p;
        let az0 = p[0][kz] - r.oz;
        let bz0 = p[1][kz] - r.oz;
        let cz0 = p[2][kz] - r.oz;
        let ax = (p[0][kx] - r.ox) - r.sx * az0;
        let ay = (p[0][ky] - r.oy) - r.sy * az0;
        let bx = (p[1][kx] - r.ox) - r.sx * bz0;
        let by = (p[1][ky] - r.oy) - r.sy * bz0;
        let cx = (p[2][kx] - r.ox) - r.sx * cz0;
        let cy = (p[2][ky] - r.oy) - r.sy * cz0;
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let zero = Vec4::ZERO;
        // Lanes on an edge are redone by the scalar test, which falls back to f64 there.
        let edge = u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero);
        let neg = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
        let pos = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
        let det = u + v + w;
        let t_scaled = u * (r.sz * az0) + v * (r.sz * bz0) + w * (r.sz * cz0);
        let tmd = Vec4::splat(t_max) * det;
        let front = det.cmplt(zero) & t_scaled.cmplt(zero) & t_scaled.cmpge(tmd);
        let back = det.cmpgt(zero) & t_scaled.cmpgt(zero) & t_scaled.cmple(tmd);
        let valid = !(neg & pos) & (front | back) & !edge;
        let mut best: Option<(usize, f32, f32, f32)> = None;
        if valid.any() {
            let inv = det.recip();
            let t = t_scaled * inv;
            let valid = valid & t.cmpgt(zero);
            if valid.any() {
                let tt = Vec4::select(valid, t, Vec4::INFINITY);
                let tmin = tt.min_element();
                let lane = tt.cmpeq(Vec4::splat(tmin)).bitmask().trailing_zeros() as usize;
                best = Some((lane, tmin, (v * inv)[lane], (w * inv)[lane]));
            }
        }
        let on_edge = edge.bitmask();
        if on_edge != 0 {
            best = self.edge_lanes(on_edge, r, t_max, best);
        }
        best
    }

    #[cold]
    #[inline(never)]
    fn edge_lanes(&self, mut lanes: u32, r: &TriRay, t_max: f32, mut best: Option<(usize, f32, f32, f32)>) -> Option<(usize, f32, f32, f32)> {
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let [p0, p1, p2] = self.vertices(lane);
            if let Some((t, b1, b2)) = r.scalar.intersect(p0, p1, p2, t_max) {
                if best.is_none_or(|b| t < b.1 || (t == b.1 && lane < b.0)) {
                    best = Some((lane, t, b1, b2));
                }
            }
        }
        best
    }
}

/// The watertight ray's permutation and shear, splatted for four lanes.
#[derive(Clone, Copy, Debug)]
pub struct TriRay {
    k: [usize; 3],
    ox: Vec4,
    oy: Vec4,
    oz: Vec4,
    sx: Vec4,
    sy: Vec4,
    sz: Vec4,
    scalar: WatertightRay,
}

impl TriRay {
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> TriRay {
        let w = WatertightRay::new(o, d);
        let oa = o.to_array();
        TriRay {
            k: [w.kx, w.ky, w.kz],
            ox: Vec4::splat(oa[w.kx]),
            oy: Vec4::splat(oa[w.ky]),
            oz: Vec4::splat(oa[w.kz]),
            sx: Vec4::splat(w.sx),
            sy: Vec4::splat(w.sy),
            sz: Vec4::splat(w.sz),
            scalar: w,
        }
    }
}
