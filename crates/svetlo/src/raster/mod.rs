//! A small CPU triangle rasteriser for the `zbuffer` integrator and its shadow maps: a view
//! (perspective or orthographic, Mitsuba's camera conventions), clipping against the near
//! plane, and scan conversion by edge functions at pixel centres with perspective-correct
//! barycentrics of the *original* triangle (so that callers can interpolate anything).

pub mod shadow;

use glam::{Mat4, Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub enum ViewProjection {
    /// Half extents of the image on the plane z = 1 (tan of the half fields of view).
    Perspective { half: Vec2 },
    /// Half extents of the image in camera units.
    Orthographic { half: Vec2 },
}

/// Camera space looks down +z, +x is the image's left and +y its top (as `camera`).
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub world_to_camera: Mat4,
    pub projection: ViewProjection,
    pub width: u32,
    pub height: u32,
    /// Nothing nearer than this (camera-space z) is drawn.
    pub near: f32,
}

/// A fragment: pixel, barycentrics (b0, b1, b2) on the original triangle and camera-space depth z.
#[derive(Clone, Copy, Debug)]
pub struct Fragment {
    pub x: u32,
    pub y: u32,
    pub b: [f32; 3],
    pub z: f32,
}

impl View {
    /// Raster position (pixels, origin top-left) of a camera-space point in front of the view.
    #[inline]
    pub fn project(&self, pc: Vec3) -> Vec2 {
        let (c, half) = match self.projection {
            ViewProjection::Perspective { half } => (Vec2::new(pc.x / pc.z, pc.y / pc.z), half),
            ViewProjection::Orthographic { half } => (Vec2::new(pc.x, pc.y), half),
        };
        let ndc = 0.5 * (Vec2::ONE - c / half);
        Vec2::new(ndc.x * self.width as f32, ndc.y * self.height as f32)
    }

    /// Scan-convert a world-space triangle, calling `frag` at every covered pixel centre.
    pub fn raster_triangle(&self, tri: [Vec3; 3], mut frag: impl FnMut(Fragment)) {
        let pc = tri.map(|p| self.world_to_camera.transform_point3(p));
        // Clip against z >= near, carrying barycentrics of the original triangle.
        let verts = [(pc[0], [1.0, 0.0, 0.0]), (pc[1], [0.0, 1.0, 0.0]), (pc[2], [0.0, 0.0, 1.0])];
        let mut poly: [(Vec3, [f32; 3]); 4] = [(Vec3::ZERO, [0.0; 3]); 4];
        let mut n = 0;
        for i in 0..3 {
            let (a, ba) = verts[i];
            let (b, bb) = verts[(i + 1) % 3];
            let (ina, inb) = (a.z >= self.near, b.z >= self.near);
            if ina {
                poly[n] = (a, ba);
                n += 1;
            }
            if ina != inb {
                let t = (self.near - a.z) / (b.z - a.z);
                let p = a + (b - a) * t;
                let bc = [ba[0] + (bb[0] - ba[0]) * t, ba[1] + (bb[1] - ba[1]) * t, ba[2] + (bb[2] - ba[2]) * t];
                poly[n] = (Vec3::new(p.x, p.y, self.near), bc);
                n += 1;
            }
        }
        for k in 1..n.saturating_sub(1) {
            self.raster_clipped([poly[0], poly[k], poly[k + 1]], &mut frag);
        }
    }

    fn raster_clipped(&self, v: [(Vec3, [f32; 3]); 3], frag: &mut impl FnMut(Fragment)) {
        let s = v.map(|(p, _)| self.project(p));
        let area = (s[1] - s[0]).perp_dot(s[2] - s[0]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let lo = s[0].min(s[1]).min(s[2]);
        let hi = s[0].max(s[1]).max(s[2]);
        let x0 = (lo.x - 0.5).ceil().max(0.0) as i64;
        let y0 = (lo.y - 0.5).ceil().max(0.0) as i64;
        let x1 = ((hi.x - 0.5).floor() as i64).min(self.width as i64 - 1);
        let y1 = ((hi.y - 0.5).floor() as i64).min(self.height as i64 - 1);
        let perspective = matches!(self.projection, ViewProjection::Perspective { .. });
        let inv_z = v.map(|(p, _)| 1.0 / p.z);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let q = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                // Screen-space barycentrics from the edge functions.
                let l0 = (s[2] - s[1]).perp_dot(q - s[1]) / area;
                let l1 = (s[0] - s[2]).perp_dot(q - s[2]) / area;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                // Perspective: attributes are linear in screen space only after division by z.
                let (w, z) = if perspective {
                    let w = [l0 * inv_z[0], l1 * inv_z[1], l2 * inv_z[2]];
                    let sum = w[0] + w[1] + w[2];
                    ([w[0] / sum, w[1] / sum, w[2] / sum], 1.0 / sum)
                } else {
                    ([l0, l1, l2], l0 * v[0].0.z + l1 * v[1].0.z + l2 * v[2].0.z)
                };
                let mut b = [0.0f32; 3];
                for (k, wk) in w.iter().enumerate() {
                    for (j, bj) in b.iter_mut().enumerate() {
                        *bj += wk * v[k].1[j];
                    }
                }
                frag(Fragment { x: x as u32, y: y as u32, b, z });
            }
        }
    }
}

impl View {
    /// The depth key of camera-space depth `z`: larger is nearer, and affine in raster
    /// space (1/z for perspective, -z for orthographic), so that it interpolates
    /// incrementally and the depth test needs no division.
    #[inline]
    pub fn key(&self, z: f32) -> f32 {
        match self.projection {
            ViewProjection::Perspective { .. } => 1.0 / z,
            ViewProjection::Orthographic { .. } => -z,
        }
    }

    /// Camera-space depth of a key (`key(z)` inverted; +inf for the empty key of perspective).
    #[inline]
    pub fn depth_of_key(&self, key: f32) -> f32 {
        match self.projection {
            ViewProjection::Perspective { .. } => 1.0 / key,
            ViewProjection::Orthographic { .. } => -key,
        }
    }

    /// Scan-convert a triangle given in *camera space*, calling `frag(index, key)` at every
    /// covered pixel centre (`index` = y * width + x; `key` as [`Self::key`]). Triangles
    /// crossing the near plane are clipped. The fast path of the Z-buffer: no barycentrics
    /// (shading is deferred to the visible fragments), edge functions and key stepped
    /// incrementally, and each row walks only the span inside all three edges.
    #[inline]
    pub fn raster_keys(&self, pc: [Vec3; 3], mut frag: impl FnMut(usize, f32)) {
        let near = self.near;
        if pc[0].z >= near && pc[1].z >= near && pc[2].z >= near {
            self.raster_span(pc, &mut frag);
            return;
        }
        if pc[0].z < near && pc[1].z < near && pc[2].z < near {
            return;
        }
        let mut poly = [Vec3::ZERO; 4];
        let mut n = 0;
        for i in 0..3 {
            let (a, b) = (pc[i], pc[(i + 1) % 3]);
            let (ina, inb) = (a.z >= near, b.z >= near);
            if ina {
                poly[n] = a;
                n += 1;
            }
            if ina != inb {
                let t = (near - a.z) / (b.z - a.z);
                let p = a + (b - a) * t;
                poly[n] = Vec3::new(p.x, p.y, near);
                n += 1;
            }
        }
        for k in 1..n.saturating_sub(1) {
            self.raster_span([poly[0], poly[k], poly[k + 1]], &mut frag);
        }
    }

    #[inline(always)]
    fn raster_span(&self, v: [Vec3; 3], frag: &mut impl FnMut(usize, f32)) {
        let s = v.map(|p| self.project(p));
        let area = (s[1] - s[0]).perp_dot(s[2] - s[0]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let lo = s[0].min(s[1]).min(s[2]);
        let hi = s[0].max(s[1]).max(s[2]);
        let x0 = ceil_i(lo.x - 0.5).max(0);
        let y0 = ceil_i(lo.y - 0.5).max(0);
        let x1 = floor_i(hi.x - 0.5).min(self.width as i32 - 1);
        let y1 = floor_i(hi.y - 0.5).min(self.height as i32 - 1);
        if x0 > x1 || y0 > y1 {
            return;
        }
        let inv_area = 1.0 / area;
        // Normalised edge functions w_i (barycentrics in raster space) as a_i x + b_i y + c_i.
        let edge = |p: Vec2, q: Vec2| {
            let d = q - p;
            // (q - p) x (r - p) for r = (x, y)
            let a = -d.y * inv_area;
            let b = d.x * inv_area;
            let c = (d.y * p.x - d.x * p.y) * inv_area;
            (a, b, c)
        };
        let e = [edge(s[1], s[2]), edge(s[2], s[0]), edge(s[0], s[1])];
        let inv_a = e.map(|(a, _, _)| if a != 0.0 { 1.0 / a } else { 0.0 });
        let k = v.map(|p| self.key(p.z));
        let (ka, kb, kc) =
            (e[0].0 * k[0] + e[1].0 * k[1] + e[2].0 * k[2], e[0].1 * k[0] + e[1].1 * k[1] + e[2].1 * k[2], e[0].2 * k[0] + e[1].2 * k[1] + e[2].2 * k[2]);
        let width = self.width as usize;
        let (xs, xe) = (x0, x1);
        for y in y0..=y1 {
            let py = y as f32 + 0.5;
            // The span of pixel centres inside all three edges on this row.
            let (mut l, mut r) = (xs, xe);
            for (&(a, b, c), &ia) in e.iter().zip(&inv_a) {
                let w = b * py + c; // value at x = 0 (pixel centre x + 0.5 below)
                if a > 0.0 {
                    l = l.max(ceil_i(-w * ia - 0.5));
                } else if a < 0.0 {
                    r = r.min(floor_i(-w * ia - 0.5));
                } else if w < 0.0 {
                    r = l - 1;
                }
            }
            // Rounding of the span is checked exactly below, one pixel either side.
            let (l, r) = ((l - 1).max(xs), (r + 1).min(xe));
            if l > r {
                continue;
            }
            let px = l as f32 + 0.5;
            let mut w = [e[0].0 * px + e[0].1 * py + e[0].2, e[1].0 * px + e[1].1 * py + e[1].2, e[2].0 * px + e[2].1 * py + e[2].2];
            let mut key = ka * px + kb * py + kc;
            let row = y as usize * width;
            for x in l..=r {
                if w[0] >= 0.0 && w[1] >= 0.0 && w[2] >= 0.0 {
                    frag(row + x as usize, key);
                }
                w[0] += e[0].0;
                w[1] += e[1].0;
                w[2] += e[2].0;
                key += ka;
            }
        }
    }
}

/// Floor and ceiling to integers without a libm call (saturating far outside the image).
#[inline(always)]
fn floor_i(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) > v {
        // Saturating: below i32::MIN the cast gave MIN already (a light at y = -2^32).
        i.saturating_sub(1)
    } else {
        i
    }
}

#[inline(always)]
fn ceil_i(v: f32) -> i32 {
    let i = v as i32;
    if (i as f32) < v {
        i.saturating_add(1)
    } else {
        i
    }
}

/// A depth buffer (camera-space z; +inf where empty).
#[derive(Clone, Debug)]
pub struct DepthBuffer {
    pub width: u32,
    pub height: u32,
    pub z: Vec<f32>,
}

impl DepthBuffer {
    pub fn new(width: u32, height: u32) -> Self {
        DepthBuffer { width, height, z: vec![f32::INFINITY; (width * height) as usize] }
    }
    /// Keep the fragment if nearer than what is stored; true when kept.
    #[inline]
    pub fn test_and_set(&mut self, x: u32, y: u32, z: f32) -> bool {
        let i = (y * self.width + x) as usize;
        if z < self.z[i] {
            self.z[i] = z;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_and_ceil_saturate_far_outside_the_image() {
        // Projected coordinates of a light at y = 2^32 and beyond: no overflow (a wrapped
        // value would turn an off-screen bound into an on-screen one).
        for v in [-3e9f32, -2.2e9, -1e30, f32::NEG_INFINITY] {
            assert_eq!(floor_i(v), i32::MIN, "{v}");
            assert_eq!(ceil_i(v), i32::MIN, "{v}");
        }
        for v in [3e9f32, 2.2e9, 1e30, f32::INFINITY] {
            assert_eq!(ceil_i(v), i32::MAX, "{v}");
            assert_eq!(floor_i(v), i32::MAX, "{v}");
        }
        assert_eq!((floor_i(-1.5), ceil_i(-1.5), floor_i(2.0), ceil_i(2.0)), (-2, -1, 2, 2));
    }

    fn view() -> View {
        View { world_to_camera: Mat4::IDENTITY, projection: ViewProjection::Perspective { half: Vec2::splat(1.0) }, width: 64, height: 64, near: 0.1 }
    }

    /// Coverage of a big triangle: pixel centres inside it, counted against the exact test.
    #[test]
    fn coverage_and_depth_are_exact() {
        let v = view();
        // A plane z = 2 + x seen by the camera; a triangle on it.
        let tri = [Vec3::new(-1.0, -1.0, 1.0), Vec3::new(1.5, -0.5, 3.5), Vec3::new(0.0, 1.5, 2.0)];
        let mut n = 0;
        v.raster_triangle(tri, |f| {
            n += 1;
            let p = tri[0] * f.b[0] + tri[1] * f.b[1] + tri[2] * f.b[2];
            assert!((p.z - f.z).abs() < 1e-4 * p.z, "depth {} vs {}", f.z, p.z);
            let r = v.project(p);
            assert!((r.x - (f.x as f32 + 0.5)).abs() < 1e-3 && (r.y - (f.y as f32 + 0.5)).abs() < 1e-3);
        });
        assert!(n > 100);
    }

    /// The fast path covers exactly the pixels of the reference scan conversion (up to
    /// centres on an edge), with the same depth.
    #[test]
    fn fast_path_matches_reference() {
        let v = view();
        let mut rng = crate::sampling::rng::Pcg32::new(3, 1);
        let mut differ = 0;
        let mut total = 0;
        for _ in 0..200 {
            let mut r = || Vec3::new(4.0 * rng.next_f32() - 2.0, 4.0 * rng.next_f32() - 2.0, 3.0 * rng.next_f32() - 0.5);
            let tri = [r(), r(), r()];
            let mut a = std::collections::HashMap::new();
            v.raster_triangle(tri, |f| {
                a.insert((f.y * v.width + f.x) as usize, f.z);
            });
            let mut b = std::collections::HashMap::new();
            v.raster_keys(tri, |i, k| {
                b.insert(i, v.depth_of_key(k));
            });
            total += a.len();
            for (i, z) in &b {
                match a.get(i) {
                    Some(za) => assert!((z - za).abs() <= 1e-3 * za.abs().max(1e-3), "depth {z} vs {za}"),
                    None => differ += 1,
                }
            }
            differ += a.keys().filter(|i| !b.contains_key(i)).count();
        }
        assert!(total > 1000);
        assert!(differ * 1000 <= total, "{differ} of {total} pixels differ");
    }

    /// A triangle crossing the near plane is clipped, not wrapped behind the camera.
    #[test]
    fn near_plane_clipping() {
        let v = view();
        let tri = [Vec3::new(-0.5, -0.5, -1.0), Vec3::new(0.5, -0.5, 2.0), Vec3::new(0.0, 0.5, 2.0)];
        let mut n = 0;
        v.raster_triangle(tri, |f| {
            n += 1;
            assert!(f.z >= v.near * 0.999);
            assert!(f.b.iter().all(|&b| b >= -1e-5));
        });
        assert!(n > 0);
        let behind = [Vec3::new(-0.5, -0.5, -1.0), Vec3::new(0.5, -0.5, -2.0), Vec3::new(0.0, 0.5, -2.0)];
        v.raster_triangle(behind, |_| panic!("drew a triangle behind the camera"));
    }
}
