//! Scalar operations written for eight-lane loops: each is the scalar code's function
//! operation for operation (the same bits), its branches as selects, so that a loop over
//! lanes that calls it compiles to vector code (the path kernel's `shade8`, light tracing's
//! `step8`).

use super::warp;
use super::PI;

/// The lanes set in `mask`, lowest first: a walk over its bits (a loop over all lanes that
/// skipped the unset ones tested and branched per lane).
#[inline(always)]
pub(crate) fn lanes_of(mask: u32) -> impl Iterator<Item = usize> {
    let mut m = mask;
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            l
        })
    })
}

/// `glam`'s `a.dot(b)`, operation for operation.
#[inline(always)]
pub(crate) fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
}

/// `warp::square_to_cosine_hemisphere`, operation for operation, its branches as selects.
#[inline(always)]
pub(crate) fn cosine_hemisphere(ux: f32, uy: f32) -> [f32; 3] {
    let (ox, oy) = (2.0 * ux - 1.0, 2.0 * uy - 1.0);
    let x_major = ox.abs() > oy.abs();
    let ratio = if x_major { oy / ox } else { ox / oy };
    let (sn, cs) = warp::sin_cos_quarter((PI / 4.0) * ratio);
    let (dx, dy) = if ox == 0.0 && oy == 0.0 {
        (0.0, 0.0)
    } else if x_major {
        (ox * cs, ox * sn)
    } else {
        (oy * sn, oy * cs)
    };
    [dx, dy, (1.0 - (dx * dx + dy * dy)).max(0.0).sqrt()]
}

/// `geometry::ray::offset_ray_origin`, operation for operation.
#[inline(always)]
pub(crate) fn offset3(p: [f32; 3], ng: [f32; 3], w: [f32; 3]) -> [f32; 3] {
    let m = |a: f32, b: f32| if a > b { a } else { b };
    let mag = m(m(p[0].abs(), p[1].abs()), p[2].abs()).max(1.0);
    let eps = mag * 2e-6;
    if dot3(w, ng) >= 0.0 {
        [p[0] + ng[0] * eps, p[1] + ng[1] * eps, p[2] + ng[2] * eps]
    } else {
        [p[0] - ng[0] * eps, p[1] - ng[1] * eps, p[2] - ng[2] * eps]
    }
}
