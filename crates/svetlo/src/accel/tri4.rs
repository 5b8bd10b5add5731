//! The 4-lane SSE test of a half [`Tri8`] block, for CPUs without AVX: the watertight
//! test of `geometry::triangle`, operation for operation in the same order, so that
//! each lane's result is bit-identical to the scalar test (no FMA, IEEE SSE).

use super::tri8::{nearest_lane, Hit, Tri8};
use crate::geometry::triangle::WatertightRay;
use glam::Vec4;

/// Four lanes (`half` 0: lanes 0..4, 1: lanes 4..8) of a [`Tri8`], tested at once.
/// Nearest hit in `(0, t_max]`: (lane of the block, t, b1, b2). On equal t the lowest lane wins.
#[inline(always)]
pub fn intersect_half(tri: &Tri8, half: usize, r: &TriRay, wr: &WatertightRay, t_max: f32) -> Option<Hit> {
    let [kx, ky, kz] = r.k;
    let off = 4 * (half & 1);
    let p = |v: usize, a: usize| {
        let row = &tri.p[v][a];
        Vec4::new(row[off], row[off + 1], row[off + 2], row[off + 3])
    };
    let az0 = p(0, kz) - r.oz;
    let bz0 = p(1, kz) - r.oz;
    let cz0 = p(2, kz) - r.oz;
    let ax = (p(0, kx) - r.ox) - r.sx * az0;
    let ay = (p(0, ky) - r.oy) - r.sy * (az0);
    let bx = (p(1, kx) - r.ox) - r.sx * bz0;
    let by = (p(1, ky) - r.oy) - r.sy * (bz0);
    let cx = (p(2, kx) - r.ox) - r.sx * cz0;
    let cy = (p(2, ky) - r.oy) - r.sy * (cz0);
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
    let mut best: Option<Hit> = None;
    if valid.any() {
        let inv = det.recip();
        let t = t_scaled * inv;
        let mask = (valid & t.cmpgt(zero)).bitmask();
        if mask != 0 {
            let (lane, t) = nearest_lane(mask, &t.to_array());
            best = Some((off + lane, t, (v * inv).to_array()[lane & 3], (w * inv).to_array()[lane & 3]));
        }
    }
    let on_edge = edge.bitmask() << off;
    if on_edge != 0 {
        best = tri.edge_lanes(on_edge, wr, t_max, best);
    }
    best
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
}

impl TriRay {
    #[inline(always)]
    pub fn new(w: &WatertightRay) -> TriRay {
        let oa = w.o.to_array();
        TriRay {
            k: [w.kx, w.ky, w.kz],
            ox: Vec4::splat(oa[w.kx]),
            oy: Vec4::splat(oa[w.ky]),
            oz: Vec4::splat(oa[w.kz]),
            sx: Vec4::splat(w.sx),
            sy: Vec4::splat(w.sy),
            sz: Vec4::splat(w.sz),
        }
    }
}
