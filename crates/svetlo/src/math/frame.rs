//! Orthonormal frames: shading space has the normal along +z.

use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// A frame around a unit normal (Duff et al. 2017, branchless and continuous).
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    /// A frame with normal `n` whose first axis follows the tangent `dpdu` as closely as possible
    /// (anisotropic BSDFs need a stable tangent).
    pub fn from_normal_tangent(n: Vec3, dpdu: Vec3) -> Self {
        let s = dpdu - n * n.dot(dpdu);
        let len2 = s.length_squared();
        if len2.is_nan() || len2 <= 1e-12 || !len2.is_finite() {
            return Self::from_normal(n);
        }
        let s = s / len2.sqrt();
        Frame { s, t: n.cross(s), n }
    }

    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Trigonometry of a direction in the local frame (normal = +z).
pub mod local {
    use glam::Vec3;
    #[inline]
    pub fn cos_theta(w: Vec3) -> f32 {
        w.z
    }
    #[inline]
    pub fn abs_cos_theta(w: Vec3) -> f32 {
        w.z.abs()
    }
    #[inline]
    pub fn cos2_theta(w: Vec3) -> f32 {
        w.z * w.z
    }
    #[inline]
    pub fn sin2_theta(w: Vec3) -> f32 {
        (1.0 - w.z * w.z).max(0.0)
    }
    #[inline]
    pub fn tan2_theta(w: Vec3) -> f32 {
        sin2_theta(w) / cos2_theta(w)
    }
    #[inline]
    pub fn same_hemisphere(a: Vec3, b: Vec3) -> bool {
        a.z * b.z > 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.3, -0.5, 0.8).normalize(), Vec3::new(1e-8, 0.0, -1.0).normalize()] {
            let f = Frame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5);
            assert!((f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(f.n).abs() < 1e-5 && f.t.dot(f.n).abs() < 1e-5);
            let v = Vec3::new(0.2, 0.7, -0.1);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }
}
