//! Mitsuba's parametric shapes as triangle meshes in their local frames (the loader applies
//! `to_world`). Flat ones are exact; curved ones are tessellated finely enough that the
//! chordal error is small against other error sources: with `n` segments around, the area
//! of a disk or cylinder is short by a factor 1 − sinc-like ≈ (2π/n)²/6 (6e-5 at 256).
//! Spheres normally stay analytic; [`uv_sphere`] is for spheres a transform distorts.

use super::TriangleMesh;
use crate::math::PI;
use glam::{Vec2, Vec3};

/// Segments around the circumference of tessellated disks, cylinders and spheres.
pub const CIRCLE_SEGMENTS: usize = 256;

/// Mitsuba `rectangle`: [-1,1]² in the z = 0 plane, facing +z, uv = (x+1)/2, (y+1)/2.
pub fn rectangle() -> TriangleMesh {
    let positions = vec![Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(-1.0, 1.0, 0.0)];
    let uvs = positions.iter().map(|p| Vec2::new(0.5 * (p.x + 1.0), 0.5 * (p.y + 1.0))).collect();
    TriangleMesh { positions, normals: vec![Vec3::Z; 4], uvs, indices: vec![[0, 1, 2], [0, 2, 3]] }
}

/// Mitsuba `cube`: [-1,1]³ with outward normals; each face has its own four vertices
/// (flat normals). Corners, their order and uvs follow Mitsuba 3's cube mesh (read from its
/// `vertex_positions_buffer` / `vertex_texcoords_buffer`), so textures land as there: the
/// corners (c0, c1, c2, c3) get uvs (0,1), (1,1), (1,0), (0,0), triangles (0,1,2), (3,0,2).
pub fn cube() -> TriangleMesh {
    // Each face: its outward normal and corner c0, with c1 = c0 + 2 a, c2 = c1 + 2 b, c3 = c0 + 2 b.
    let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
        ([0.0, -1.0, 0.0], [1.0, -1.0, -1.0], [0.0, 0.0, 1.0]),
        ([0.0, 1.0, 0.0], [1.0, 1.0, -1.0], [-1.0, 0.0, 0.0]),
        ([1.0, 0.0, 0.0], [1.0, -1.0, -1.0], [0.0, 1.0, 0.0]),
        ([0.0, 0.0, 1.0], [1.0, -1.0, 1.0], [0.0, 1.0, 0.0]),
        ([-1.0, 0.0, 0.0], [-1.0, -1.0, 1.0], [0.0, 1.0, 0.0]),
        ([0.0, 0.0, -1.0], [1.0, 1.0, -1.0], [0.0, -1.0, 0.0]),
    ];
    let mut m = TriangleMesh::default();
    for (n, c0, a) in faces {
        let (n, c0, a) = (Vec3::from(n), Vec3::from(c0), Vec3::from(a));
        // The second edge runs so that (c1 - c0) x (c2 - c1) points along n.
        let b = n.cross(a);
        let base = m.positions.len() as u32;
        let corners = [c0, c0 + 2.0 * a, c0 + 2.0 * a + 2.0 * b, c0 + 2.0 * b];
        for (p, uv) in corners.into_iter().zip([Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::ZERO]) {
            m.positions.push(p);
            m.normals.push(n);
            m.uvs.push(uv);
        }
        m.indices.push([base, base + 1, base + 2]);
        m.indices.push([base + 3, base, base + 2]);
    }
    m
}

/// Mitsuba `disk`: unit radius in the z = 0 plane, facing +z, uv = (r, φ/2π).
/// Built from concentric rings so that the polar uvs interpolate well.
pub fn disk(segments: usize) -> TriangleMesh {
    let segments = segments.max(3);
    let rings = 8;
    let mut m = TriangleMesh::default();
    let row = segments as u32 + 1;
    for ri in 0..=rings {
        let r = ri as f32 / rings as f32;
        for si in 0..=segments {
            let v = si as f32 / segments as f32;
            let phi = 2.0 * PI * v;
            m.positions.push(Vec3::new(r * phi.cos(), r * phi.sin(), 0.0));
            m.normals.push(Vec3::Z);
            m.uvs.push(Vec2::new(r, v));
        }
    }
    for ri in 0..rings as u32 {
        for si in 0..segments as u32 {
            let (a, b) = (ri * row + si, ri * row + si + 1);
            let (c, d) = (a + row, b + row);
            // Counter-clockwise seen from +z: a (inner), c (outer), d, b; the innermost ring is a fan.
            m.indices.push([a, c, d]);
            if ri > 0 {
                m.indices.push([a, d, b]);
            }
        }
    }
    m
}

/// Mitsuba `cylinder` in its canonical frame: radius 1 around +z from z = 0 to z = 1, open
/// ends, outward smooth normals, uv = (φ/2π, z).
pub fn cylinder(segments: usize) -> TriangleMesh {
    let segments = segments.max(3);
    let mut m = TriangleMesh::default();
    for si in 0..=segments {
        let u = si as f32 / segments as f32;
        let phi = 2.0 * PI * u;
        let n = Vec3::new(phi.cos(), phi.sin(), 0.0);
        for z in [0.0, 1.0] {
            m.positions.push(n + Vec3::Z * z);
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, z));
        }
    }
    for si in 0..segments as u32 {
        let (a, b, c, d) = (2 * si, 2 * si + 2, 2 * si + 3, 2 * si + 1);
        m.indices.push([a, b, c]);
        m.indices.push([a, c, d]);
    }
    m
}

/// Unit sphere as a latitude-longitude mesh with Mitsuba's uv (φ/2π, θ/π), outward normals.
pub fn uv_sphere(segments: usize) -> TriangleMesh {
    let nu = segments.max(4);
    let nv = (nu / 2).max(2);
    let mut m = TriangleMesh::default();
    let row = nu as u32 + 1;
    for vi in 0..=nv {
        let v = vi as f32 / nv as f32;
        let theta = PI * v;
        for ui in 0..=nu {
            let u = ui as f32 / nu as f32;
            let phi = 2.0 * PI * u;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            m.positions.push(n);
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    for vi in 0..nv as u32 {
        for ui in 0..nu as u32 {
            let (a, b) = (vi * row + ui, vi * row + ui + 1);
            let (c, d) = (a + row, b + row);
            // Counter-clockwise seen from outside; skip the triangles that collapse at the poles.
            if vi != 0 {
                m.indices.push([a, c, b]);
            }
            if vi != nv as u32 - 1 {
                m.indices.push([b, c, d]);
            }
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outward(m: &TriangleMesh, center: Vec3) -> bool {
        (0..m.triangle_count()).all(|t| {
            let [a, b, c] = m.vertices(t);
            let n = (b - a).cross(c - a);
            let mid = (a + b + c) / 3.0 - center;
            n.dot(mid) > 0.0
        })
    }

    #[test]
    fn rectangle_faces_plus_z_with_area_4() {
        let m = rectangle();
        assert!((m.area() - 4.0).abs() < 1e-6);
        let (ng, ns, uv, _) = m.surface(0, 0.2, 0.3);
        assert_eq!(ng, Vec3::Z);
        assert_eq!(ns, Vec3::Z);
        assert!(uv.x >= 0.0 && uv.x <= 1.0);
    }

    #[test]
    fn cube_is_closed_and_outward() {
        let m = cube();
        assert_eq!(m.triangle_count(), 12);
        assert!((m.area() - 24.0).abs() < 1e-5);
        assert!(outward(&m, Vec3::ZERO));
        // Geometric and shading normals agree on every face.
        for t in 0..12 {
            let (ng, ns, _, _) = m.surface(t, 0.3, 0.3);
            assert!(ng.dot(ns) > 0.999);
        }
    }

    /// uvs at points of each face as Mitsuba 3.9.1's cube gives them (ray hits).
    #[test]
    fn cube_uvs_match_mitsuba() {
        let m = cube();
        let cases = [
            ([1.0, 0.5, 0.2], [0.75, 0.4]),
            ([-1.0, 0.5, 0.2], [0.75, 0.6]),
            ([0.3, 1.0, -0.6], [0.35, 0.8]),
            ([0.3, -1.0, -0.6], [0.2, 0.65]),
            ([0.3, -0.4, 1.0], [0.3, 0.65]),
            ([0.3, -0.4, -1.0], [0.7, 0.65]),
        ];
        for (p, want) in cases {
            let p = Vec3::from(p);
            // The triangle containing p: barycentrics from the plane's 2-D solve.
            let hit = (0..m.triangle_count()).find_map(|t| {
                let [a, b, c] = m.vertices(t);
                let n = (b - a).cross(c - a);
                if n.dot(p - a).abs() > 1e-5 {
                    return None;
                }
                let (v0, v1, v2) = (b - a, c - a, p - a);
                let (d00, d01, d11, d20, d21) = (v0.dot(v0), v0.dot(v1), v1.dot(v1), v2.dot(v0), v2.dot(v1));
                let den = d00 * d11 - d01 * d01;
                let (b1, b2) = ((d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den);
                (b1 >= -1e-6 && b2 >= -1e-6 && b1 + b2 <= 1.0 + 1e-6).then(|| m.uv(t, b1, b2))
            });
            let uv = hit.expect("a face contains the point");
            assert!((uv - Vec2::from(want)).abs().max_element() < 1e-5, "{p}: {uv} vs Mitsuba {want:?}");
        }
    }

    #[test]
    fn disk_area_and_orientation() {
        let m = disk(CIRCLE_SEGMENTS);
        let exact = PI;
        let chord = exact * (1.0 - (2.0 * PI / CIRCLE_SEGMENTS as f32).powi(2) / 6.0);
        assert!((m.area() - chord).abs() < 1e-4, "{} vs {}", m.area(), chord);
        for t in 0..m.triangle_count() {
            let [a, b, c] = m.vertices(t);
            assert!((b - a).cross(c - a).z > 0.0);
        }
    }

    #[test]
    fn cylinder_area_and_outward() {
        let m = cylinder(CIRCLE_SEGMENTS);
        assert!((m.area() - 2.0 * PI).abs() < 2.0 * PI * 1e-4);
        assert!((0..m.triangle_count()).all(|t| {
            let [a, b, c] = m.vertices(t);
            let n = (b - a).cross(c - a);
            let mid = (a + b + c) / 3.0;
            n.dot(Vec3::new(mid.x, mid.y, 0.0)) > 0.0
        }));
    }

    #[test]
    fn uv_sphere_area_and_outward() {
        let m = uv_sphere(128);
        assert!((m.area() - 4.0 * PI).abs() < 4.0 * PI * 1e-3, "{}", m.area());
        assert!(outward(&m, Vec3::ZERO));
    }
}
