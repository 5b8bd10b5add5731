use crate::math::Frame;
use glam::{Vec2, Vec3};

/// Where a ray met a surface, with everything shading needs.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    pub p: Vec3,
    /// Distance along the ray.
    pub t: f32,
    /// Geometric normal, as the shape defines it (not flipped toward the ray).
    pub ng: Vec3,
    /// Shading frame: interpolated normal (same side as `ng`) and a tangent along dp/du.
    pub shading: Frame,
    pub uv: Vec2,
    /// Index of the shape in `Scene::shapes`.
    pub shape: u32,
    /// Index of the primitive inside the shape (triangle index; 0 for a sphere).
    pub prim: u32,
    /// Barycentrics (b1, b2) of the point in its triangle (zero on other shapes): per-vertex
    /// mesh attributes are interpolated with them.
    pub bary: Vec2,
    /// Direction toward the ray origin (-ray.d), world space.
    pub wo: Vec3,
    /// The time of the ray that found the point (motion blur): rays leaving it keep it.
    pub time: f32,
}

impl SurfaceInteraction {
    /// Where textures are looked up at this point.
    #[inline]
    pub fn tex_point(&self) -> crate::texture::TexPoint {
        crate::texture::TexPoint { uv: self.uv, prim: self.prim, bary: self.bary, p: self.p, n: self.ng }
    }
    #[inline]
    pub fn to_local(&self, w: Vec3) -> Vec3 {
        self.shading.to_local(w)
    }
    #[inline]
    pub fn to_world(&self, w: Vec3) -> Vec3 {
        self.shading.to_world(w)
    }
    /// A ray leaving the surface in direction `d`, offset to avoid self-intersection.
    #[inline]
    pub fn spawn_ray(&self, d: Vec3) -> super::Ray {
        let mut r = super::Ray::new(super::ray::offset_ray_origin(self.p, self.ng, d), d);
        r.time = self.time;
        r
    }
}
