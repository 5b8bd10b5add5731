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
