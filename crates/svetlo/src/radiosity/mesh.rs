//! Scene surfaces as radiosity elements.
//!
//! Every triangle of a shape is split regularly into n² congruent sub-triangles (n per
//! shape, from its longest edge and the maximum element edge). One n per shape makes the
//! subdivision conforming inside a shape: two triangles sharing an edge split it at the same
//! points, so the display mesh has no T-vertices. Spheres are tessellated as a lat-long mesh.
//!
//! An element is one side of a sub-triangle: the front (the side of the geometric normal the
//! scene uses) always, the back too when the material is two-sided. Patches (Cohen's two-level
//! substructuring) are the input triangles; their elements are the sub-triangles.

use crate::accel::PrimHit;
use crate::error::{Error, Result};
use crate::geometry::{shapes, Geometry, TriangleMesh};
use crate::light::Light;
use crate::math::PI;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::collections::HashMap;

/// How to cut the scene into elements.
#[derive(Clone, Debug)]
pub struct MeshOptions {
    /// Longest edge an element may have, in scene units. None: a fifth of the radius of the
    /// scene's bounding sphere (about 2k elements and a few seconds for the Cornell box).
    pub max_edge: Option<f32>,
    /// Refuse to build more elements than this (the full matrix grows with its square).
    pub max_elements: usize,
    /// Segments around a sphere's equator.
    pub sphere_segments: usize,
    /// Splits per triangle edge for each shape, overriding `max_edge` where given (the
    /// hierarchical solver's display mesh uses powers of two, matching its quadtrees).
    pub shape_splits: Vec<u32>,
}

impl Default for MeshOptions {
    fn default() -> Self {
        MeshOptions { max_edge: None, max_elements: 1 << 20, sphere_segments: 32, shape_splits: vec![] }
    }
}

/// One side of a planar triangle with constant radiosity.
#[derive(Clone, Debug)]
pub struct Element {
    pub shape: u32,
    pub patch: u32,
    /// The back side of a two-sided surface.
    pub back: bool,
    pub p: [Vec3; 3],
    /// Display-mesh vertex of each corner (for Gouraud interpolation).
    pub vertex: [u32; 3],
    /// Unit normal of the side that radiates.
    pub normal: Vec3,
    pub centroid: Vec3,
    pub area: f32,
    /// Diffuse albedo ρ per channel.
    pub reflectance: Rgb,
    /// Emitted radiosity E = π Le (W/m²).
    pub emission: Rgb,
    /// Radiosity ρ E_direct reflected once from the lights with a position and no surface
    /// (luminaires, point, spot, directional), which the form factors cannot carry: the
    /// solvers start from it as from emission, displays count it as reflected light.
    pub lit: Rgb,
}

impl Element {
    /// What the system starts from: emission plus the reflected light of positional lights.
    #[inline]
    pub fn source(&self) -> Rgb {
        self.emission + self.lit
    }

    /// Point at barycentrics (b1, b2) (weights of p[1], p[2]).
    #[inline]
    pub fn point(&self, b1: f32, b2: f32) -> Vec3 {
        self.p[0] * (1.0 - b1 - b2) + self.p[1] * b1 + self.p[2] * b2
    }
    /// Radius of the bounding sphere around the centroid.
    pub fn radius(&self) -> f32 {
        self.p.iter().map(|v| (*v - self.centroid).length()).fold(0.0, f32::max)
    }
}

/// A group of elements: the input triangle they came from (one side).
#[derive(Clone, Debug)]
pub struct Patch {
    pub first: u32,
    pub count: u32,
    pub area: f32,
}

/// How hits on one shape map to elements.
#[derive(Clone, Debug)]
enum ShapeMap {
    /// Not meshed (no diffuse side, or degenerate): rays hitting it are absorbed.
    None,
    /// Triangle t, sub-triangle s: element `front + t n² + s` (and `back + ...`).
    Mesh { n: u32, front: u32, back: Option<u32> },
    /// Lat-long tessellation with `nu` columns and `nv` rows; `cells` maps (row, col, upper) to the local element.
    Sphere { nu: u32, nv: u32, center: Vec3, front: u32, back: Option<u32>, cells: Vec<u32> },
}

/// The elements of a scene, their patches, and a shared vertex set for display.
#[derive(Clone, Debug)]
pub struct RadiosityMesh {
    pub elements: Vec<Element>,
    pub patches: Vec<Patch>,
    /// Welded display vertices: elements of one shape and side sharing a corner and a normal share it.
    pub vertices: Vec<Vec3>,
    maps: Vec<ShapeMap>,
    pub warnings: Vec<String>,
}

/// Index of the sub-triangle containing barycentrics (b1, b2) in a triangle split n × n, and
/// the barycentrics inside it. Row j (along b2) holds 2(n − j) − 1 triangles, upright ones at
/// even positions; rows before j hold j(2n − j).
pub fn sub_triangle(n: u32, b1: f32, b2: f32) -> (u32, Vec2) {
    let nf = n as f32;
    let (u, v) = ((b1 * nf).clamp(0.0, nf), (b2 * nf).clamp(0.0, nf));
    let j = (v.floor() as u32).min(n - 1);
    let i = (u.floor() as u32).min(n - 1 - j);
    let (fu, fv) = (u - i as f32, v - j as f32);
    let row = j * (2 * n - j);
    if fu + fv <= 1.0 || i + j + 1 >= n {
        (row + 2 * i, Vec2::new(fu.clamp(0.0, 1.0), fv.clamp(0.0, 1.0)))
    } else {
        // Inverted triangle with corners (i+1, j+1), (i, j+1), (i+1, j): weights of the last two.
        (row + 2 * i + 1, Vec2::new(1.0 - fu, 1.0 - fv))
    }
}

/// Grid corners (i, j) of sub-triangle s, in the order `sub_triangle`'s barycentrics use.
fn sub_triangle_corners(n: u32, s: u32) -> [(u32, u32); 3] {
    let mut j = 0;
    while s >= (j + 1) * (2 * n - j - 1) {
        j += 1;
    }
    let k = s - j * (2 * n - j);
    let i = k / 2;
    if k.is_multiple_of(2) {
        [(i, j), (i + 1, j), (i, j + 1)]
    } else {
        [(i + 1, j + 1), (i, j + 1), (i + 1, j)]
    }
}

struct Welder {
    map: HashMap<(u32, bool, [i64; 3], [i32; 3]), u32>,
    step: f32,
}

impl Welder {
    fn id(&mut self, vertices: &mut Vec<Vec3>, shape: u32, back: bool, p: Vec3, n: Vec3) -> u32 {
        let q = |x: f32| (x / self.step).round() as i64;
        let qn = |x: f32| (x * 1000.0).round() as i32;
        let key = (shape, back, [q(p.x), q(p.y), q(p.z)], [qn(n.x), qn(n.y), qn(n.z)]);
        *self.map.entry(key).or_insert_with(|| {
            vertices.push(p);
            (vertices.len() - 1) as u32
        })
    }
}

impl RadiosityMesh {
    /// Mesh every shape of the scene. Shapes with neither diffuse reflectance nor emission on
    /// either side get no elements: rays that hit them are absorbed (their radiosity is 0).
    pub fn build(scene: &Scene, opts: &MeshOptions) -> Result<Self> {
        if let Some(e) = opts.max_edge {
            if !(e > 0.0 && e.is_finite()) {
                return Err(Error::Settings(format!("radiosity: element size must be positive, got {e}")));
            }
        }
        let diag = scene.bounds.radius.max(1e-6);
        let max_edge = opts.max_edge.unwrap_or(diag / 5.0);
        let mut mesh = RadiosityMesh { elements: vec![], patches: vec![], vertices: vec![], maps: vec![], warnings: vec![] };
        let mut welder = Welder { map: HashMap::new(), step: diag * 1e-6 };
        for (si, shape) in scene.shapes.iter().enumerate() {
            let material = &scene.materials[shape.material as usize];
            let emission = match shape.light.map(|l| &scene.lights[l as usize]) {
                Some(Light::Area(a)) => a.radiance.mean() * PI,
                _ => Rgb::BLACK,
            };
            // The albedo at the patch's centre stands for the element (textures are averaged over one element).
            let albedo = |uv: Vec2| {
                let b = material.bsdf(uv);
                let back = b.back.as_ref().map(|m| m.diffuse_albedo() * b.opacity);
                (b.diffuse_albedo(), back)
            };
            let (tri_mesh, sphere) = match &*shape.geometry {
                // An implicit surface has no elements: radiosity leaves it out.
                Geometry::SdfGrid(_) => {
                    mesh.maps.push(ShapeMap::None);
                    continue;
                }
                Geometry::Mesh(m) => (m.clone(), None),
                Geometry::Sphere(s) => {
                    let mut m = shapes::uv_sphere(opts.sphere_segments.max(4));
                    for p in &mut m.positions {
                        *p = s.center + *p * s.radius;
                    }
                    if s.flip_normals {
                        for n in &mut m.normals {
                            *n = -*n;
                        }
                    }
                    (m, Some(*s))
                }
            };
            let (front_albedo, back_albedo) = albedo(Vec2::splat(0.5));
            let two_sided = back_albedo.is_some();
            if front_albedo.is_black() && emission.is_black() && back_albedo.is_none_or(|b| b.is_black()) {
                mesh.maps.push(ShapeMap::None);
                continue;
            }
            let longest = (0..tri_mesh.triangle_count())
                .map(|t| {
                    let [a, b, c] = tri_mesh.vertices(t);
                    (b - a).length().max((c - b).length()).max((a - c).length())
                })
                .fold(0.0f32, f32::max);
            let n = match sphere {
                None => match opts.shape_splits.get(si) {
                    Some(&k) => k.max(1),
                    None => ((longest / max_edge).ceil() as u32).max(1),
                },
                Some(_) => 1,
            };
            let per_side = tri_mesh.triangle_count() as u64 * (n as u64 * n as u64);
            let total = mesh.elements.len() as u64 + per_side * if two_sided { 2 } else { 1 };
            if total > opts.max_elements as u64 {
                return Err(Error::Settings(format!(
                    "radiosity: shape '{}' would bring the element count to {total}, above the limit {}; use a larger element size",
                    shape.name, opts.max_elements
                )));
            }
            let front = mesh.elements.len() as u32;
            mesh.add_side(&mut welder, si as u32, &tri_mesh, n, false, emission, &|uv| albedo(uv).0);
            let back = if two_sided {
                let b = mesh.elements.len() as u32;
                mesh.add_side(&mut welder, si as u32, &tri_mesh, n, true, Rgb::BLACK, &|uv| albedo(uv).1.unwrap_or(Rgb::BLACK));
                Some(b)
            } else {
                None
            };
            mesh.maps.push(match sphere {
                None => ShapeMap::Mesh { n, front, back },
                Some(s) => {
                    let nu = opts.sphere_segments.max(4) as u32;
                    let nv = (nu / 2).max(2);
                    // uv_sphere's triangle order: per cell, the upper one unless on row 0, the lower one unless on the last row.
                    let mut cells = vec![u32::MAX; (nu * nv * 2) as usize];
                    let mut k = 0;
                    for vi in 0..nv {
                        for ui in 0..nu {
                            if vi != 0 {
                                cells[((vi * nu + ui) * 2) as usize] = k;
                                k += 1;
                            }
                            if vi != nv - 1 {
                                cells[((vi * nu + ui) * 2 + 1) as usize] = k;
                                k += 1;
                            }
                        }
                    }
                    ShapeMap::Sphere { nu, nv, center: s.center, front, back, cells }
                }
            });
        }
        if mesh.elements.is_empty() {
            return Err(Error::Invalid("radiosity: the scene has no diffuse or emitting surface to mesh".into()));
        }
        mesh.light_by_delta_lights(scene);
        if !mesh.elements.iter().any(|e| !e.source().is_black()) {
            mesh.warnings.push(
                "radiosity: no surface emits or receives light (environment lights are not part of the radiosity solution); the image will be black".into(),
            );
        }
        Ok(mesh)
    }

    /// Set each element's `lit`: ρ times the irradiance from every delta light, averaged over
    /// four points of the element (its centroid and the midpoints toward its corners) with
    /// shadow rays. A spread luminaire's opening is sampled at one point per element point.
    fn light_by_delta_lights(&mut self, scene: &Scene) {
        use rayon::prelude::*;
        let lights: Vec<&Light> = scene.lights.iter().filter(|l| l.is_delta()).collect();
        if lights.is_empty() {
            return;
        }
        self.elements.par_iter_mut().for_each(|e| {
            if e.reflectance.is_black() {
                return;
            }
            let pts = [e.centroid, (e.centroid + e.p[0]) * 0.5, (e.centroid + e.p[1]) * 0.5, (e.centroid + e.p[2]) * 0.5];
            let us = [Vec2::new(0.25, 0.25), Vec2::new(0.75, 0.25), Vec2::new(0.25, 0.75), Vec2::new(0.75, 0.75)];
            let mut irradiance = Rgb::BLACK;
            for l in &lights {
                for (p, u) in pts.iter().zip(us) {
                    let Some(ls) = l.sample_li(*p, u, &scene.bounds) else { continue };
                    let cos = e.normal.dot(ls.wi);
                    if cos <= 0.0 {
                        continue;
                    }
                    let blocked = if ls.infinite { scene.occluded_dir(*p, e.normal, ls.wi) } else { scene.occluded_between(*p, e.normal, ls.p, ls.n, 0.0) };
                    if !blocked {
                        irradiance += ls.li * (cos / ls.pdf);
                    }
                }
            }
            e.lit = e.reflectance * irradiance * 0.25;
        });
    }

    #[allow(clippy::too_many_arguments)]
    fn add_side(&mut self, welder: &mut Welder, shape: u32, m: &TriangleMesh, n: u32, back: bool, emission: Rgb, albedo: &dyn Fn(Vec2) -> Rgb) {
        let nf = n as f32;
        for t in 0..m.triangle_count() {
            let [p0, p1, p2] = m.vertices(t);
            let (ng, _, _, _) = m.surface(t, 1.0 / 3.0, 1.0 / 3.0);
            // The scene's front is the side of `ng` (which follows the shading normals); the
            // element keeps the parent's corner order, so its normal is stored, not implied by winding.
            let normal = if back { -ng } else { ng };
            let first = self.elements.len() as u32;
            let mut patch_area = 0.0;
            for s in 0..n * n {
                let corners = sub_triangle_corners(n, s);
                let pos = corners.map(|(i, j)| p0 + (p1 - p0) * (i as f32 / nf) + (p2 - p0) * (j as f32 / nf));
                let vertex = pos.map(|p| welder.id(&mut self.vertices, shape, back, p, normal));
                let centroid = (pos[0] + pos[1] + pos[2]) / 3.0;
                let area = 0.5 * (pos[1] - pos[0]).cross(pos[2] - pos[0]).length();
                let cb = corners.iter().fold(Vec2::ZERO, |a, &(i, j)| a + Vec2::new(i as f32, j as f32)) / (3.0 * nf);
                let (_, _, uv, _) = m.surface(t, cb.x, cb.y);
                patch_area += area;
                self.elements.push(Element {
                    shape,
                    patch: self.patches.len() as u32,
                    back,
                    p: pos,
                    vertex,
                    normal,
                    centroid,
                    area,
                    reflectance: albedo(uv).clamp(0.0, 1.0),
                    emission,
                    lit: Rgb::BLACK,
                });
            }
            self.patches.push(Patch { first, count: n * n, area: patch_area });
        }
    }

    /// The element a ray hit, given the side it arrived from (`d` the ray's direction).
    /// None: the shape has no element on that side (absorbed).
    pub fn element_at(&self, hit: &PrimHit, p: Vec3, d: Vec3) -> Option<u32> {
        match self.maps.get(hit.shape as usize)? {
            ShapeMap::None => None,
            ShapeMap::Mesh { n, front, back } => {
                let (s, _) = sub_triangle(*n, hit.b1, hit.b2);
                let local = hit.prim * n * n + s;
                let f = front + local;
                if d.dot(self.elements[f as usize].normal) < 0.0 {
                    Some(f)
                } else {
                    back.map(|b| b + local)
                }
            }
            ShapeMap::Sphere { nu, nv, center, front, back, cells } => {
                let w = (p - *center).normalize_or_zero();
                let theta = w.z.clamp(-1.0, 1.0).acos() / PI * *nv as f32;
                let mut phi = w.y.atan2(w.x);
                if phi < 0.0 {
                    phi += 2.0 * PI;
                }
                let phi = phi / (2.0 * PI) * *nu as f32;
                let (vi, ui) = ((theta as u32).min(nv - 1), (phi as u32).min(nu - 1));
                let (fv, fu) = (theta - vi as f32, phi - ui as f32);
                let cell = ((vi * nu + ui) * 2) as usize;
                let upper = if vi == 0 {
                    false
                } else if vi == nv - 1 {
                    true
                } else {
                    fu + fv < 1.0
                };
                let local = cells[cell + if upper { 0 } else { 1 }];
                let f = front + local;
                if d.dot(self.elements[f as usize].normal) < 0.0 {
                    Some(f)
                } else {
                    back.map(|b| b + local)
                }
            }
        }
    }

    /// Barycentric weights of the element's three corners at a hit (for Gouraud display).
    pub fn corner_weights(&self, hit: &PrimHit, p: Vec3, e: &Element) -> [f32; 3] {
        match self.maps.get(hit.shape as usize) {
            Some(ShapeMap::Mesh { n, .. }) => {
                let (_, b) = sub_triangle(*n, hit.b1, hit.b2);
                let _ = p;
                [1.0 - b.x - b.y, b.x, b.y]
            }
            _ => {
                // Project onto the element's plane and solve for barycentrics.
                let (e1, e2, q) = (e.p[1] - e.p[0], e.p[2] - e.p[0], p - e.p[0]);
                let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
                let (q1, q2) = (q.dot(e1), q.dot(e2));
                let det = d11 * d22 - d12 * d12;
                if det <= 0.0 {
                    return [1.0 / 3.0; 3];
                }
                let b1 = ((d22 * q1 - d12 * q2) / det).clamp(0.0, 1.0);
                let b2 = ((d11 * q2 - d12 * q1) / det).clamp(0.0, 1.0 - b1);
                [1.0 - b1 - b2, b1, b2]
            }
        }
    }

    pub fn total_area(&self) -> f64 {
        self.elements.iter().map(|e| e.area as f64).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sub_triangles_tile_the_parent() {
        for n in 1..6u32 {
            // Every sub-triangle index is reached, and the corners round-trip through sub_triangle.
            let mut seen = vec![false; (n * n) as usize];
            for s in 0..n * n {
                let c = sub_triangle_corners(n, s);
                let cb = c.iter().fold(Vec2::ZERO, |a, &(i, j)| a + Vec2::new(i as f32, j as f32)) / (3.0 * n as f32);
                let (s2, b) = sub_triangle(n, cb.x, cb.y);
                assert_eq!(s, s2, "n={n}");
                assert!((b - Vec2::splat(1.0 / 3.0)).length() < 1e-4, "n={n} s={s} {b:?}");
                seen[s as usize] = true;
            }
            assert!(seen.iter().all(|&x| x));
        }
        // Corners of the parent map to valid indices.
        for (b1, b2) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.5, 0.5)] {
            let (s, _) = sub_triangle(4, b1, b2);
            assert!(s < 16);
        }
    }
}
