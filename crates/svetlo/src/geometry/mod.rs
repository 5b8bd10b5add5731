//! Rays, bounding boxes, shapes and the record of a ray hitting a surface.

pub mod aabb;
pub mod interaction;
pub mod mesh;
pub mod motion;
pub mod ray;
pub mod sdfgrid;
pub mod shapes;
pub mod sphere;
pub mod triangle;

pub use aabb::Aabb;
pub use interaction::SurfaceInteraction;
pub use mesh::{TriangleMesh, TriangleShading};
pub use motion::{AnimatedTransform, Motion};
pub use ray::Ray;
pub use sdfgrid::{SdfGrid, SdfNormals};
pub use sphere::Sphere;

/// The geometry of one shape of the scene. Rectangles, cubes, disks and cylinders
/// are meshed by the loader; spheres stay analytic (exact normals and solid-angle sampling);
/// SDF grids are intersected voxel by voxel (they have no area and cannot emit).
#[derive(Clone, Debug)]
pub enum Geometry {
    Mesh(TriangleMesh),
    Sphere(Sphere),
    /// Boxed: it is several times larger than the other variants.
    SdfGrid(Box<SdfGrid>),
}

impl Geometry {
    pub fn bounds(&self) -> Aabb {
        match self {
            Geometry::Mesh(m) => m.bounds(),
            Geometry::Sphere(s) => s.bounds(),
            Geometry::SdfGrid(g) => g.bounds(),
        }
    }
    pub fn area(&self) -> f32 {
        match self {
            Geometry::Mesh(m) => m.area(),
            Geometry::Sphere(s) => s.area(),
            // As in Mitsuba: the area of the level set is not computed.
            Geometry::SdfGrid(_) => 0.0,
        }
    }
    /// Number of primitives the accelerator sees for this shape.
    pub fn primitive_count(&self) -> usize {
        match self {
            Geometry::Mesh(m) => m.triangle_count(),
            Geometry::Sphere(_) => 1,
            Geometry::SdfGrid(g) => g.voxel_count(),
        }
    }
}
