//! Analytic sphere. Its normal points outward (inward if `flip_normals`).

use super::Aabb;
use crate::math::{INV_2PI, INV_PI, PI};
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Sphere {
    pub center: Vec3,
    pub radius: f32,
    pub flip_normals: bool,
}

impl Sphere {
    pub fn bounds(&self) -> Aabb {
        Aabb { min: self.center - Vec3::splat(self.radius), max: self.center + Vec3::splat(self.radius) }
    }
    pub fn area(&self) -> f32 {
        4.0 * PI * self.radius * self.radius
    }
    /// Nearest hit distance in `(0, t_max)`. Solved in f64 relative to the center for accuracy.
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, t_max: f32) -> Option<f32> {
        let oc = (o - self.center).as_dvec3();
        let d = d.as_dvec3();
        let a = d.length_squared();
        let b = oc.dot(d);
        let r = self.radius as f64;
        // Numerically stable discriminant (Hearn & Baker / Ray Tracing Gems ch. 7).
        let l = oc - d * (b / a);
        let disc = r * r - l.length_squared();
        if disc < 0.0 {
            return None;
        }
        let c = oc.length_squared() - r * r;
        let q = -(b + b.signum() * (a * disc).sqrt());
        let (mut t0, mut t1) = (c / q, q / a);
        if q == 0.0 {
            t0 = 0.0;
            t1 = 0.0;
        }
        if t0 > t1 {
            std::mem::swap(&mut t0, &mut t1);
        }
        let t_max = t_max as f64;
        if t0 > 0.0 && t0 < t_max {
            Some(t0 as f32)
        } else if t1 > 0.0 && t1 < t_max {
            Some(t1 as f32)
        } else {
            None
        }
    }
    /// (geometric normal, uv, dp/du) at a point on the sphere. uv follows Mitsuba's convention.
    /// (dp/du, dp/dv) at a point of the sphere for the uvs of [`Self::surface`]
    /// (u = phi / 2 pi, v = theta / pi).
    pub fn dp_duv(&self, p: Vec3) -> (Vec3, Vec3) {
        let n = ((p - self.center) / self.radius).normalize_or_zero();
        let sin_theta = (n.x * n.x + n.y * n.y).sqrt();
        let dpdu = Vec3::new(-n.y, n.x, 0.0) * (2.0 * PI * self.radius);
        let dpdv = if sin_theta > 1e-6 {
            Vec3::new(n.z * n.x / sin_theta, n.z * n.y / sin_theta, -sin_theta) * (PI * self.radius)
        } else {
            Vec3::new(n.z, 0.0, 0.0) * (PI * self.radius)
        };
        (dpdu, dpdv)
    }

    /// The normal of [`Self::surface`] alone (the same operations: the same bits).
    #[inline]
    pub fn normal(&self, p: Vec3) -> Vec3 {
        let n = ((p - self.center) / self.radius).normalize_or_zero();
        if self.flip_normals {
            -n
        } else {
            n
        }
    }

    /// [`Self::surface`]'s normal and dp/du without its uv (the same operations: the same
    /// bits).
    #[inline]
    pub fn normal_and_dpdu(&self, p: Vec3) -> (Vec3, Vec3) {
        let n = ((p - self.center) / self.radius).normalize_or_zero();
        let dpdu = Vec3::new(-n.y, n.x, 0.0) * (2.0 * PI * self.radius);
        (if self.flip_normals { -n } else { n }, dpdu)
    }

    pub fn surface(&self, p: Vec3) -> (Vec3, Vec2, Vec3) {
        let local = (p - self.center) / self.radius;
        let n = local.normalize_or_zero();
        let phi = n.y.atan2(n.x);
        let phi = if phi < 0.0 { phi + 2.0 * PI } else { phi };
        let theta = n.z.clamp(-1.0, 1.0).acos();
        let uv = Vec2::new(phi * INV_2PI, theta * INV_PI);
        let dpdu = Vec3::new(-n.y, n.x, 0.0) * (2.0 * PI * self.radius);
        let n = if self.flip_normals { -n } else { n };
        (n, uv, dpdu)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `normal` is `surface`'s normal bit for bit (a sphere light's samples take it), flipped or
    /// not, and `normal_and_dpdu` its normal and dp/du (the path kernel's hits that read no uv).
    #[test]
    fn normal_is_the_surface_normal() {
        let mut rng = crate::sampling::Pcg32::new(5, 1);
        for flip_normals in [false, true] {
            let s = Sphere { center: Vec3::new(0.3, 6.5, -2.8), radius: 0.05, flip_normals };
            for _ in 0..1000 {
                let d = crate::math::warp::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                let p = s.center + d * s.radius;
                let (n, _, dpdu) = s.surface(p);
                assert_eq!(s.normal(p).to_array().map(f32::to_bits), n.to_array().map(f32::to_bits));
                let (n2, dpdu2) = s.normal_and_dpdu(p);
                assert_eq!(n2.to_array().map(f32::to_bits), n.to_array().map(f32::to_bits));
                assert_eq!(dpdu2.to_array().map(f32::to_bits), dpdu.to_array().map(f32::to_bits));
            }
        }
    }
}
