//! Watertight ray-triangle intersection (Woop, Benthin and Wald 2013): no ray passes
//! between two triangles that share an edge, whatever its direction.

use glam::Vec3;

/// Precomputed per-ray data for the watertight test: the permutation making the
/// dominant axis z, and the shear that maps the ray to +z.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    pub o: Vec3,
    // Crate-visible so that the SIMD test in accel/ reproduces this one bit for bit.
    pub(crate) kx: usize,
    pub(crate) ky: usize,
    pub(crate) kz: usize,
    pub(crate) sx: f32,
    pub(crate) sy: f32,
    pub(crate) sz: f32,
}

impl WatertightRay {
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        let a = d.abs();
        // The dominant axis and its permutation without branches: which axis dominates is a
        // coin toss for incoherent rays, and the branches it compiled to were 5 % of a
        // render's mispredictions (the 1M-triangle mesh, one set-up per traced ray). The
        // same choice as the nested comparisons `x > y ? (x > z ? 0 : 2) : (y > z ? 1 : 2)`.
        let (x_y, x_z, y_z) = (a.x > a.y, a.x > a.z, a.y > a.z);
        let kz = usize::from(x_y) * (2 - 2 * usize::from(x_z)) + usize::from(!x_y) * (2 - usize::from(y_z));
        let comp = [d.x, d.y, d.z, 0.0];
        let dz = comp[kz & 3];
        // (kz + 1) % 3 and (kz + 2) % 3, swapped for a negative dz (the winding stays that of
        // the +z view): two bits each of a constant, at 2 kz (6 further for the swap). An array
        // for a table was written to the stack for every ray.
        let at = 2 * (kz & 3) + 6 * usize::from(dz < 0.0);
        let (kx, ky) = ((0x489 >> at) & 3, (0x252 >> at) & 3);
        // SAFETY: kz is 0, 1 or 2 by its sum above, and kx, ky are two bits of 0x489 or 0x252
        // at an even shift, each pair 0, 1 or 2. Said so that the users' clamps to 0..3 fold
        // away (`TriRay8::new`'s offsets: a compare and a move each, every ray).
        unsafe { std::hint::assert_unchecked(kx < 3 && ky < 3 && kz < 3) };
        let sz = 1.0 / dz;
        WatertightRay { o, kx, ky, kz, sx: comp[kx & 3] / dz, sy: comp[ky & 3] / dz, sz }
    }

    /// Returns (t, b1, b2) with the hit point `(1-b1-b2) p0 + b1 p1 + b2 p2`.
    #[inline]
    pub fn intersect(&self, p0: Vec3, p1: Vec3, p2: Vec3, t_max: f32) -> Option<(f32, f32, f32)> {
        let a = p0 - self.o;
        let b = p1 - self.o;
        let c = p2 - self.o;
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            // Fall back to double precision on edges, as the paper does.
            let (cxd, cyd, bxd, byd, axd, ayd) = (cx as f64, cy as f64, bx as f64, by as f64, ax as f64, ay as f64);
            u = (cxd * byd - cyd * bxd) as f32;
            v = (axd * cyd - ayd * cxd) as f32;
            w = (bxd * ayd - byd * axd) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        // Reject hits behind the origin or beyond t_max without dividing.
        if det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det) {
            return None;
        }
        if det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det) {
            return None;
        }
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        if t.is_nan() || t <= 0.0 {
            return None;
        }
        Some((t, v * inv, w * inv))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_and_misses() {
        let (p0, p1, p2) = (Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0));
        let r = WatertightRay::new(Vec3::new(0.25, 0.25, 1.0), Vec3::new(0.0, 0.0, -1.0));
        let (t, b1, b2) = r.intersect(p0, p1, p2, f32::INFINITY).expect("hit");
        assert!((t - 1.0).abs() < 1e-6 && (b1 - 0.25).abs() < 1e-6 && (b2 - 0.25).abs() < 1e-6);
        assert!(r.intersect(p0, p1, p2, 0.5).is_none());
        // Asymmetric point: b1 weights p1, b2 weights p2.
        let r = WatertightRay::new(Vec3::new(0.1, 0.6, 1.0), Vec3::new(0.0, 0.0, -1.0));
        let (_, b1, b2) = r.intersect(p0, p1, p2, f32::INFINITY).expect("hit");
        assert!((b1 - 0.1).abs() < 1e-6 && (b2 - 0.6).abs() < 1e-6, "barycentrics ({b1}, {b2})");
        let r = WatertightRay::new(Vec3::new(0.75, 0.75, 1.0), Vec3::new(0.0, 0.0, -1.0));
        assert!(r.intersect(p0, p1, p2, f32::INFINITY).is_none());
    }

    #[test]
    fn permutation_is_the_nested_choice() {
        // The branch-free set-up against the nested comparisons it replaces, ties, zeros,
        // signed zeros and infinities included.
        let vals = [0.0f32, -0.0, 1.0, -1.0, 2.0, -2.0, 0.5, f32::INFINITY, f32::NEG_INFINITY, f32::MIN_POSITIVE];
        for &x in &vals {
            for &y in &vals {
                for &z in &vals {
                    let d = Vec3::new(x, y, z);
                    let a = d.abs();
                    let kz = if a.x > a.y {
                        if a.x > a.z {
                            0
                        } else {
                            2
                        }
                    } else if a.y > a.z {
                        1
                    } else {
                        2
                    };
                    let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
                    if d[kz] < 0.0 {
                        std::mem::swap(&mut kx, &mut ky);
                    }
                    let r = WatertightRay::new(Vec3::ZERO, d);
                    assert_eq!((r.kx, r.ky, r.kz), (kx, ky, kz), "{d}");
                    let same = |p: f32, q: f32| p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan());
                    assert!(same(r.sx, d[kx] / d[kz]) && same(r.sy, d[ky] / d[kz]) && same(r.sz, 1.0 / d[kz]), "{d}");
                }
            }
        }
    }

    #[test]
    fn shared_edge_is_watertight() {
        // Two triangles sharing the diagonal of a unit square: rays through the diagonal hit one.
        let q = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        for i in 0..1000 {
            let s = (i as f32 + 0.5) / 1000.0;
            let d = Vec3::new(0.0031 * (i % 7) as f32, -0.002 * (i % 5) as f32, -1.0);
            let r = WatertightRay::new(Vec3::new(s, s, 0.0) - d, d);
            let hit = r.intersect(q[0], q[1], q[2], f32::INFINITY).is_some() || r.intersect(q[0], q[2], q[3], f32::INFINITY).is_some();
            assert!(hit, "ray {i} slipped through the shared edge");
        }
    }
}
