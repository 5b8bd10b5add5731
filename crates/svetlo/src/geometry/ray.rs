use glam::Vec3;

/// A ray `o + t d`, valid for `t` in `(0, t_max)`. `d` need not be normalised
/// but is for every ray the integrators trace. `time` is the scene time
/// the ray sees moving shapes at (the camera's shutter interval; 0 when not given).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3,
    pub d: Vec3,
    pub t_max: f32,
    pub time: f32,
}

impl Ray {
    #[inline]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Ray { o, d, t_max: f32::INFINITY, time: 0.0 }
    }
    #[inline]
    pub fn with_max(o: Vec3, d: Vec3, t_max: f32) -> Self {
        Ray { o, d, t_max, time: 0.0 }
    }
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// Offset a point off a surface along its geometric normal, to the side of `w`,
/// far enough that the new ray does not hit the surface it starts from.
/// The offset scales with the coordinates' magnitude (float spacing grows with it).
#[inline]
pub fn offset_ray_origin(p: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
    let mag = p.abs().max_element().max(1.0);
    // ~16 ulps of the largest coordinate: above the error of a hit point (barycentric
    // interpolation on triangles, reprojection on spheres: a few ulps), and small enough
    // that moving the origin biases nothing measurable (the furnace tests see 5e-5 offsets).
    let eps = mag * 2e-6;
    if w.dot(ng) >= 0.0 {
        p + ng * eps
    } else {
        p - ng * eps
    }
}

/// The fraction of a segment's length left unused at its far end by shadow rays,
/// so that the ray does not hit the surface it is aimed at.
pub const SHADOW_EPSILON: f32 = 1e-4;
