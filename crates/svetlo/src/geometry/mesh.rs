//! Indexed triangle meshes in world space, with optional per-vertex normals and uvs.

use super::Aabb;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug, Default)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (world space, unit), or empty.
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates, or empty.
    pub uvs: Vec<Vec2>,
    pub indices: Vec<[u32; 3]>,
}

impl TriangleMesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }
    #[inline]
    pub fn vertices(&self, tri: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[tri];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }
    pub fn triangle_area(&self, tri: usize) -> f32 {
        let [p0, p1, p2] = self.vertices(tri);
        0.5 * (p1 - p0).cross(p2 - p0).length()
    }
    pub fn area(&self) -> f32 {
        (0..self.triangle_count()).map(|i| self.triangle_area(i)).sum()
    }
    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.positions)
    }
    /// Apply an affine transform (points, and normals by the inverse transpose).
    pub fn transform(&mut self, m: &glam::Mat4) {
        let inv = m.inverse();
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        for n in &mut self.normals {
            *n = crate::math::xform_normal(&inv, *n);
        }
        if m.determinant() < 0.0 {
            // A mirroring transform flips winding; keep geometric normals consistent with shading ones.
            for t in &mut self.indices {
                t.swap(1, 2);
            }
        }
    }
    /// dp/du of a triangle (constant over it): from the uvs, or the first edge without them.
    fn dpdu(&self, [i0, i1, i2]: [usize; 3]) -> Vec3 {
        let (p0, p1, p2) = (self.positions[i0], self.positions[i1], self.positions[i2]);
        if self.uvs.is_empty() {
            return p1 - p0;
        }
        let (t0, t1, t2) = (self.uvs[i0], self.uvs[i1], self.uvs[i2]);
        let (du1, du2) = (t1 - t0, t2 - t0);
        let det = du1.x * du2.y - du1.y * du2.x;
        if det.abs() > 1e-12 {
            ((p1 - p0) * du2.y - (p2 - p0) * du1.y) / det
        } else {
            p1 - p0
        }
    }

    /// (dp/du, dp/dv) of a triangle (constant over it), as Mitsuba derives them from the
    /// uvs; without uvs (uv = the barycentrics) the two edges from the first vertex.
    pub fn dp_duv(&self, tri: usize) -> (Vec3, Vec3) {
        let [i0, i1, i2] = self.indices[tri].map(|i| i as usize);
        let (e1, e2) = (self.positions[i1] - self.positions[i0], self.positions[i2] - self.positions[i0]);
        if self.uvs.is_empty() {
            return (e1, e2);
        }
        let (d1, d2) = (self.uvs[i1] - self.uvs[i0], self.uvs[i2] - self.uvs[i0]);
        let det = d1.x * d2.y - d1.y * d2.x;
        if det.abs() <= 1e-12 {
            return (e1, e2);
        }
        ((e1 * d2.y - e2 * d1.y) / det, (e2 * d1.x - e1 * d2.x) / det)
    }

    /// Texture coordinates at barycentrics (b1, b2); the barycentrics themselves without uvs.
    #[inline]
    pub fn uv(&self, tri: usize, b1: f32, b2: f32) -> Vec2 {
        if self.uvs.is_empty() {
            return Vec2::new(b1, b2);
        }
        let [i0, i1, i2] = self.indices[tri].map(|i| i as usize);
        self.uvs[i0] * (1.0 - b1 - b2) + self.uvs[i1] * b1 + self.uvs[i2] * b2
    }

    /// (geometric normal, shading frame) of a triangle whose shading does not vary over it (no
    /// vertex normals, or three equal ones), as [`Self::surface`] gives them at any point of it:
    /// hits then need no interpolation or normalisation. `None` for smooth-shaded triangles.
    pub fn flat_shading(&self, tri: usize) -> Option<(Vec3, crate::math::Frame)> {
        let idx = self.indices[tri].map(|i| i as usize);
        // Smooth-shaded (the common case of a mesh with normals): nothing more to compute.
        if !self.normals.is_empty() {
            let [n0, n1, n2] = idx.map(|i| self.normals[i]);
            if n0 != n1 || n0 != n2 {
                return None;
            }
        }
        let [p0, p1, p2] = idx.map(|i| self.positions[i]);
        let ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        let ns = if self.normals.is_empty() {
            ng
        } else {
            let [n0, n1, n2] = idx.map(|i| self.normals[i]);
            if n0 != n1 || n0 != n2 {
                return None;
            }
            let n = n0.normalize_or_zero();
            if n == Vec3::ZERO {
                ng
            } else {
                n
            }
        };
        let ng = if !self.normals.is_empty() && ng.dot(ns) < 0.0 { -ng } else { ng };
        Some((ng, crate::math::Frame::from_normal_tangent(ns, self.dpdu(idx))))
    }

    /// Interpolated attributes at barycentrics (b1, b2): (geometric normal, shading normal, uv, dp/du).
    pub fn surface(&self, tri: usize, b1: f32, b2: f32) -> (Vec3, Vec3, Vec2, Vec3) {
        let s = self.shading(tri);
        let (ng, ns) = s.normals_at(b1, b2);
        (ng, ns, self.uv(tri, b1, b2), s.dpdu)
    }

    /// What `surface` needs of a triangle whatever the point on it, for callers that hit the
    /// same triangles again and again.
    pub fn shading(&self, tri: usize) -> TriangleShading {
        let idx = self.indices[tri].map(|i| i as usize);
        let [p0, p1, p2] = idx.map(|i| self.positions[i]);
        TriangleShading {
            ng: (p1 - p0).cross(p2 - p0).normalize_or_zero(),
            normals: if self.normals.is_empty() { None } else { Some(idx.map(|i| self.normals[i])) },
            dpdu: self.dpdu(idx),
        }
    }
}

/// A triangle's geometric normal, vertex normals and dp/du (see [`TriangleMesh::shading`]).
#[derive(Clone, Copy, Debug)]
pub struct TriangleShading {
    /// Unit normal of the vertices' winding (zero for a degenerate triangle).
    pub ng: Vec3,
    pub normals: Option<[Vec3; 3]>,
    pub dpdu: Vec3,
}

/// A triangle's normals as a hit on it needs them: constant (a shape's `flat` entry: geometric
/// normal and shading frame), or interpolated per hit (as `Scene::interaction` makes them).
/// Kept per triangle by the packet tracers, which shade their hits without the mesh.
#[derive(Clone, Copy, Debug)]
pub enum TriangleFrame {
    Flat(Vec3, crate::math::Frame),
    Smooth(TriangleShading),
}

impl TriangleFrame {
    /// Triangle `t` of `m`, with the shape's `flat` entry for it where it has one.
    pub fn new(flat: Option<(Vec3, crate::math::Frame)>, m: &TriangleMesh, t: usize) -> TriangleFrame {
        match flat {
            Some((ng, frame)) => TriangleFrame::Flat(ng, frame),
            None => TriangleFrame::Smooth(m.shading(t)),
        }
    }

    /// (geometric normal, shading frame) at barycentrics (b1, b2): `Scene::interaction`'s.
    #[inline(always)]
    pub fn at(&self, b1: f32, b2: f32) -> (Vec3, crate::math::Frame) {
        match self {
            TriangleFrame::Flat(ng, frame) => (*ng, *frame),
            TriangleFrame::Smooth(s) => {
                let (ng, ns) = s.normals_at(b1, b2);
                (ng, crate::math::Frame::from_normal_tangent(ns, s.dpdu))
            }
        }
    }
}

impl TriangleShading {
    /// (geometric normal, shading normal) at barycentrics (b1, b2), as `TriangleMesh::surface`.
    #[inline]
    pub fn normals_at(&self, b1: f32, b2: f32) -> (Vec3, Vec3) {
        let Some([n0, n1, n2]) = self.normals else { return (self.ng, self.ng) };
        let n = (n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2).normalize_or_zero();
        let ns = if n == Vec3::ZERO { self.ng } else { n };
        // The geometric normal follows the shading normal's side, as in Mitsuba, so that
        // one-sided materials and emitters face where the mesh's normals say.
        (if self.ng.dot(ns) < 0.0 { -self.ng } else { self.ng }, ns)
    }
}
