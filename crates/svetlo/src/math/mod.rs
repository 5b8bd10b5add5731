//! Vector math (glam, f32), orthonormal frames and sample warps.

pub(crate) mod acosf;
pub mod approx;
pub(crate) mod expf;
pub mod frame;
pub mod lane;
pub mod warp;

pub use frame::Frame;
pub use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};

pub const PI: f32 = std::f32::consts::PI;
pub const INV_PI: f32 = std::f32::consts::FRAC_1_PI;
pub const INV_2PI: f32 = 0.5 * std::f32::consts::FRAC_1_PI;
pub const INV_4PI: f32 = 0.25 * std::f32::consts::FRAC_1_PI;

/// Largest f32 strictly below 1: keeps `u * n` inside `[0, n)`.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

#[inline]
pub fn sqr(x: f32) -> f32 {
    x * x
}

#[inline]
pub fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

#[inline]
pub fn lerp(t: f32, a: f32, b: f32) -> f32 {
    a + t * (b - a)
}

/// Reflect `wo` about `n` (both pointing away from the surface).
#[inline]
pub fn reflect(wo: Vec3, n: Vec3) -> Vec3 {
    2.0 * wo.dot(n) * n - wo
}

/// Transform a point by an affine 4x4 matrix.
#[inline]
pub fn xform_point(m: &Mat4, p: Vec3) -> Vec3 {
    m.transform_point3(p)
}

/// Transform a direction (no translation).
#[inline]
pub fn xform_vector(m: &Mat4, v: Vec3) -> Vec3 {
    m.transform_vector3(v)
}

/// Transform a normal: by the inverse transpose of the linear part.
#[inline]
pub fn xform_normal(inv: &Mat4, n: Vec3) -> Vec3 {
    let m = Mat3::from_mat4(*inv).transpose();
    (m * n).normalize_or_zero()
}
