//! Rays, bounding boxes, shapes and the record of a ray hitting a surface.

pub mod aabb;
pub mod interaction;
pub mod mesh;
pub mod motion;
pub mod ray;
pub mod shapes;
pub mod sphere;
pub mod triangle;

pub use aabb::Aabb;
pub use interaction::SurfaceInteraction;
pub use mesh::{TriangleMesh, TriangleShading};
pub use motion::{AnimatedTransform, Motion};
pub use ray::Ray;
pub use sphere::Sphere;

/// The geometry of one shape of the scene. Rectangles, cubes, disks and cylinders
/// are meshed by the loader; spheres stay analytic (exact normals and solid-angle sampling).
#[derive(Clone, Debug)]
pub enum Geometry {
    Mesh(TriangleMesh),
    Sphere(Sphere),
}

impl Geometry {
    pub fn bounds(&self) -> Aabb {
        match self {
            Geometry::Mesh(m) => m.bounds(),
            Geometry::Sphere(s) => s.bounds(),
        }
    }
    pub fn area(&self) -> f32 {
        match self {
            Geometry::Mesh(m) => m.area(),
            Geometry::Sphere(s) => s.area(),
        }
    }
    /// Number of primitives the accelerator sees for this shape.
    pub fn primitive_count(&self) -> usize {
        match self {
            Geometry::Mesh(m) => m.triangle_count(),
            Geometry::Sphere(_) => 1,
        }
    }
}
