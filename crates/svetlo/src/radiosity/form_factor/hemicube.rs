//! Hemicube form factors (Cohen & Greenberg 1985). By the Nusselt analogy the form factor
//! from a point to a surface is the fraction of the unit disc covered by the surface's
//! projection onto the hemisphere and then onto the base plane. A half cube over the point
//! is cut into pixels, each carrying its precomputed delta form factor:
//!   top face (x, y, 1):    ΔF = ΔA / (π (x² + y² + 1)²)
//!   side face (1, y, z):   ΔF = z ΔA / (π (1 + y² + z²)²)
//! The item buffer (which element each pixel sees) is found by casting one ray through each
//! pixel centre into the scene's BVH rather than by scan conversion: the same visible-surface
//! answer, with no near-plane clipping to get wrong.

use super::super::mesh::RadiosityMesh;
use crate::geometry::ray::offset_ray_origin;
use crate::geometry::Ray;
use crate::math::{Frame, PI};
use crate::scene::Scene;
use glam::Vec3;

/// The hemicube's pixels: (direction in the local frame, delta form factor). `res` pixels
/// across the top face; the side faces are res × res/2. The deltas sum to 1 − O(1/res²).
pub fn pixels(res: u32) -> Vec<(Vec3, f32)> {
    let res = res.max(2) & !1;
    let h = 2.0 / res as f32;
    let da = h * h;
    let mut out = Vec::with_capacity((res * res * 3) as usize);
    for iy in 0..res {
        for ix in 0..res {
            let (x, y) = (-1.0 + (ix as f32 + 0.5) * h, -1.0 + (iy as f32 + 0.5) * h);
            let r2 = x * x + y * y + 1.0;
            out.push((Vec3::new(x, y, 1.0).normalize(), da / (PI * r2 * r2)));
        }
    }
    for iz in 0..res / 2 {
        for iy in 0..res {
            let (y, z) = (-1.0 + (iy as f32 + 0.5) * h, (iz as f32 + 0.5) * h);
            let r2 = 1.0 + y * y + z * z;
            let df = z * da / (PI * r2 * r2);
            // The four side faces: +x, -x, +y, -y.
            for d in [Vec3::new(1.0, y, z), Vec3::new(-1.0, -y, z), Vec3::new(-y, 1.0, z), Vec3::new(y, -1.0, z)] {
                out.push((d.normalize(), df));
            }
        }
    }
    out
}

/// Row i by a hemicube at the element's centroid.
pub fn row(scene: &Scene, mesh: &RadiosityMesh, i: usize, pixels: &[(Vec3, f32)]) -> Vec<(u32, f32)> {
    let e = &mesh.elements[i];
    let frame = Frame::from_normal(e.normal);
    let o = offset_ray_origin(e.centroid, e.normal, e.normal);
    let mut hits: Vec<(u32, f32)> = Vec::new();
    for (d, df) in pixels {
        let d = frame.to_world(*d);
        let ray = Ray::new(o, d);
        if let Some(h) = scene.intersect_prim(&ray) {
            if let Some(j) = mesh.element_at(&h, ray.at(h.t), d) {
                if j as usize != i {
                    hits.push((j, *df));
                }
            }
        }
    }
    super::merge(hits)
}

#[cfg(test)]
mod tests {
    #[test]
    fn delta_form_factors_sum_to_one() {
        for res in [8u32, 32, 128] {
            let s: f64 = super::pixels(res).iter().map(|p| p.1 as f64).sum();
            // Midpoint rule on a smooth integrand: error falls as 1/res².
            assert!((s - 1.0).abs() < 2.0 / (res * res) as f64, "res {res}: {s}");
        }
    }
}
