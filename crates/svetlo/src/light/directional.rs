//! Lights at infinity: directional (Mitsuba `directional`, `irradiance` on a surface facing
//! it) and the shared construction of rays entering the scene from infinity: a point
//! uniform on the disk of the scene's bounding sphere perpendicular to the direction of
//! travel, one radius behind the center (pdf 1 / (π R²)).

use super::SceneBounds;
use crate::geometry::Ray;
use crate::math::{warp, Frame, PI};
use glam::{Vec2, Vec3};

/// A ray travelling along `d` that enters the bounding sphere through a uniform point of
/// its cross-section disk. Returns the ray and the disk's area density.
pub(super) fn ray_from_infinity(bounds: &SceneBounds, d: Vec3, u: Vec2, time: f32) -> (Ray, f32) {
    let disk = warp::square_to_uniform_disk_concentric(u) * bounds.radius;
    let frame = Frame::from_normal(d);
    let o = bounds.center + frame.to_world(Vec3::new(disk.x, disk.y, 0.0)) - d * bounds.radius;
    let mut ray = Ray::new(o, d);
    ray.time = time;
    (ray, disk_pdf(bounds))
}

/// Area density of a uniform point on the bounding sphere's cross-section.
pub(super) fn disk_pdf(bounds: &SceneBounds) -> f32 {
    1.0 / (PI * bounds.radius * bounds.radius)
}

/// A point standing for "infinitely far in direction `wi`" as seen from `p_ref`: outside
/// the bounding sphere whatever `p_ref` is (it may be a camera outside the scene's box).
pub(super) fn point_at_infinity(bounds: &SceneBounds, p_ref: Vec3, wi: Vec3) -> Vec3 {
    p_ref + wi * (2.0 * bounds.radius + (p_ref - bounds.center).length())
}
