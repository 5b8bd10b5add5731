//! Ray-scene intersection. The only module that knows how the hierarchy is laid out:
//! everything else calls [`Accel::intersect`] and [`Accel::occluded`].

mod build;
mod bvh;
#[cfg(target_arch = "x86_64")]
mod coherent;
mod geometry_cache;
mod kdtree;
pub mod packet;
pub(crate) mod pages;
mod tri4;
mod tri8;
mod wide;

#[cfg(test)]
mod tests;

pub use bvh::{Accel, HitRecords, LaneRays, RAY_LANES};
pub use geometry_cache::GeometryCache;
pub use kdtree::{KdPoint, KdTree};
pub(crate) use wide::prefetch;

/// The closest hit of a ray: which primitive, where along the ray, and where on it
/// (barycentrics b1, b2 for a triangle; unused for a sphere).
#[derive(Clone, Copy, Debug)]
pub struct PrimHit {
    pub t: f32,
    pub shape: u32,
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
}
