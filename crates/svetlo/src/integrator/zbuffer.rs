//! The Z-buffer pipeline with a local illumination model, on the CPU (`raster/`): the scene
//! camera's projection, near-plane clipping, a depth buffer of ss x ss subsamples per pixel
//! (supersampling anti-aliasing), deferred shading of the visible fragment of each
//! subsample with the material's own BSDF under the local model of `local.rs` (so Phong
//! and Blinn-Phong materials give the Phong and Blinn-Phong local models), an ambient term
//! (ambient radiance x the BSDF's diffuse albedo), and cast shadows from shadow maps (cube
//! maps for point, spot and area lights by their centre; an orthographic map for
//! directional lights). Light path class L(D|G)E.
//!
//! Shading: `Flat` once per triangle at its centroid with the geometric normal; `Gouraud`
//! at the three vertices, colours interpolated; `Phong` per subsample with the interpolated
//! shading normal and the exact surface point — what a ray caster computes, so the image
//! equals `whitted` at max_depth 2 except where shadow maps and ray-cast shadows disagree
//! (edges, within the map's bias). Spheres are tessellated for rasterisation; Phong shading
//! puts their fragments back on the exact sphere.
//!
//! The number of subsamples per pixel is the square nearest to `spp` (at most 8 x 8).
//! Moving shapes (motion blur) are drawn in their pose at the middle of the shutter.

use super::local::LocalLights;
use super::{Integrator, Progress, RenderSettings};
use crate::error::Result;
use crate::film::Film;
use crate::geometry::Geometry;
use crate::light::Light;
use crate::math::{Frame, PI};
use crate::raster::shadow::ShadowMap;
use crate::raster::{DepthBuffer, View, ViewProjection};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Mat3, Mat4, Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::Ordering;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Shading {
    Flat,
    Gouraud,
    #[default]
    Phong,
}

#[derive(Clone, Copy, Debug)]
pub struct ZBuffer {
    pub shading: Shading,
    /// Ambient radiance; each surface adds it times its diffuse albedo.
    pub ambient: Rgb,
    pub shadows: bool,
    /// Texels per side of each shadow map face.
    pub shadow_map_resolution: u32,
    /// Sphere tessellation: segments around the axis (half as many along it).
    pub sphere_segments: u32,
}

impl Default for ZBuffer {
    fn default() -> Self {
        ZBuffer { shading: Shading::Phong, ambient: Rgb::BLACK, shadows: true, shadow_map_resolution: 1024, sphere_segments: 64 }
    }
}

/// A triangle to rasterise: the shape and primitive it shades as.
struct RasterTri {
    shape: u32,
    prim: u32,
    v: [Vec3; 3],
}

fn sphere_triangles(c: Vec3, r: f32, seg: u32) -> Vec<[Vec3; 3]> {
    let (nu, nv) = (seg.max(4), (seg / 2).max(2));
    let p = |i: u32, j: u32| {
        let phi = 2.0 * PI * i as f32 / nu as f32;
        let theta = PI * j as f32 / nv as f32;
        c + r * Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
    };
    let mut out = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, cc, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            if j > 0 {
                out.push([a, b, cc]);
            }
            if j + 1 < nv {
                out.push([a, cc, d]);
            }
        }
    }
    out
}

/// Where each shape is drawn: moving shapes at the middle of the shutter (reference pose to
/// world, and its inverse); `None` for static shapes.
fn poses(scene: &Scene) -> Vec<Option<(Mat4, Mat4)>> {
    let mid = 0.5 * (scene.camera.shutter_open + scene.camera.shutter_close);
    scene
        .shapes
        .iter()
        .map(|s| {
            let m = s.motion.as_ref()?.relative(mid);
            Some((m, m.inverse()))
        })
        .collect()
}

/// A surface point as the shader needs it.
struct Surface {
    p: Vec3,
    ng: Vec3,
    ns: Vec3,
    uv: Vec2,
    dpdu: Vec3,
}

impl ZBuffer {
    fn triangles(&self, scene: &Scene, poses: &[Option<(Mat4, Mat4)>]) -> Vec<RasterTri> {
        let mut tris = Vec::new();
        for (si, s) in scene.shapes.iter().enumerate() {
            let first = tris.len();
            match &*s.geometry {
                Geometry::Mesh(m) => {
                    for t in 0..m.triangle_count() {
                        tris.push(RasterTri { shape: si as u32, prim: t as u32, v: m.vertices(t) });
                    }
                }
                Geometry::Sphere(sp) => {
                    for (k, v) in sphere_triangles(sp.center, sp.radius, self.sphere_segments).into_iter().enumerate() {
                        tris.push(RasterTri { shape: si as u32, prim: k as u32, v });
                    }
                }
            }
            if let Some((m, _)) = poses[si] {
                for t in &mut tris[first..] {
                    t.v = t.v.map(|p| m.transform_point3(p));
                }
            }
        }
        tris
    }

    /// The surface at barycentrics `b` of a raster triangle.
    fn surface(scene: &Scene, poses: &[Option<(Mat4, Mat4)>], t: &RasterTri, b: [f32; 3]) -> Surface {
        let q = t.v[0] * b[0] + t.v[1] * b[1] + t.v[2] * b[2];
        let pose = poses[t.shape as usize];
        let mut s = match &*scene.shapes[t.shape as usize].geometry {
            Geometry::Mesh(m) => {
                let (ng, ns, uv, dpdu) = m.surface(t.prim as usize, b[1], b[2]);
                Surface { p: q, ng, ns, uv, dpdu }
            }
            Geometry::Sphere(s) => {
                let q = pose.map_or(q, |(_, inv)| inv.transform_point3(q));
                let p = s.center + (q - s.center).normalize_or_zero() * s.radius;
                let (n, uv, dpdu) = s.surface(p);
                Surface { p, ng: n, ns: n, uv, dpdu }
            }
        };
        if let Some((m, inv)) = pose {
            // Normals by the inverse transpose; the mesh point is already in place.
            let normal = Mat3::from_mat4(inv).transpose();
            if matches!(&*scene.shapes[t.shape as usize].geometry, Geometry::Sphere(_)) {
                s.p = m.transform_point3(s.p);
            }
            s.ng = (normal * s.ng).normalize();
            s.ns = (normal * s.ns).normalize();
            s.dpdu = Mat3::from_mat4(m) * s.dpdu;
        }
        s
    }

    fn shadow_maps(&self, scene: &Scene, lights: &LocalLights, tris: &[RasterTri]) -> Vec<Option<ShadowMap>> {
        let res = self.shadow_map_resolution.max(16);
        // Vertices clipped at a near plane very close to the light project far outside the
        // map, where f32 edge functions lose the precision to cover texels right.
        let near = 1e-2 * scene.bounds.radius;
        scene
            .lights
            .iter()
            .enumerate()
            .map(|(i, l)| {
                if !self.shadows {
                    return None;
                }
                // An emitter does not shadow itself.
                let own = if let Light::Area(a) = l { Some(a.shape) } else { None };
                let occluders: Vec<[Vec3; 3]> = tris.iter().filter(|t| Some(t.shape) != own).map(|t| t.v).collect();
                match l {
                    Light::Directional { direction, .. } => Some(ShadowMap::directional(*direction, scene.bounds.center, scene.bounds.radius, res, &occluders)),
                    Light::Point { position, .. } | Light::Spot { position, .. } => Some(ShadowMap::point(*position, res, &occluders, near)),
                    Light::Area(_) => {
                        // The proxy's position seen from the scene's centre (fixed for meshes).
                        let s = lights.sample(scene, i, scene.bounds.center)?;
                        Some(ShadowMap::point(s.p?, res, &occluders, near))
                    }
                    _ => None,
                }
            })
            .collect()
    }

    #[allow(clippy::too_many_arguments)]
    fn shade(&self, scene: &Scene, lights: &LocalLights, maps: &[Option<ShadowMap>], shape: u32, s: &Surface, eye: Vec3, settings: &RenderSettings) -> Rgb {
        let wo_w = (eye - s.p).normalize_or_zero();
        let mut l = Rgb::BLACK;
        let sh = &scene.shapes[shape as usize];
        if let (Some(li), false) = (sh.light, settings.hide_emitters) {
            if let Light::Area(a) = &scene.lights[li as usize] {
                l += a.l(s.ng, s.uv, wo_w);
            }
        }
        let bsdf = scene.materials[sh.material as usize].bsdf(s.uv);
        l += self.ambient * bsdf.diffuse_albedo();
        let frame = Frame::from_normal_tangent(s.ns, s.dpdu);
        let wo = frame.to_local(wo_w);
        for (i, map) in maps.iter().enumerate() {
            let Some(ls) = lights.sample(scene, i, s.p) else { continue };
            let wi = frame.to_local(ls.wi);
            let f = bsdf.eval(wo, wi, crate::bsdf::TransportMode::Radiance);
            if f.is_black() {
                continue;
            }
            if let Some(m) = map {
                if !m.lit(s.p, s.ng) {
                    continue;
                }
            }
            l += f * ls.li * wi.z.abs();
        }
        l
    }
}

impl Integrator for ZBuffer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        settings.validate()?;
        let cam = &scene.camera;
        let ss = ((settings.spp as f32).sqrt().round() as u32).clamp(1, 8);
        let (w, h) = (cam.width * ss, cam.height * ss);
        let projection = match cam.projection {
            crate::camera::Projection::Perspective { .. } => ViewProjection::Perspective { half: cam.film_half_extent() },
            crate::camera::Projection::Orthographic => ViewProjection::Orthographic { half: cam.film_half_extent() },
        };
        let view = View { world_to_camera: cam.to_world.inverse(), projection, width: w, height: h, near: cam.near_clip.max(1e-5) };
        let eye = cam.to_world.transform_point3(Vec3::ZERO);
        let view_dir = cam.to_world.transform_vector3(Vec3::Z).normalize();
        let lights = LocalLights::new(scene);
        let poses = poses(scene);
        let tris = self.triangles(scene, &poses);
        let maps = self.shadow_maps(scene, &lights, &tris);
        progress.total.store((w * h) as u64, Ordering::Relaxed);

        // Visibility pass: the nearest triangle and its barycentrics per subsample.
        let mut depth = DepthBuffer::new(w, h);
        let mut ids: Vec<(u32, [f32; 3])> = vec![(u32::MAX, [0.0; 3]); (w * h) as usize];
        for (k, t) in tris.iter().enumerate() {
            view.raster_triangle(t.v, |f| {
                if f.z <= cam.far_clip && depth.test_and_set(f.x, f.y, f.z) {
                    ids[(f.y * w + f.x) as usize] = (k as u32, f.b);
                }
            });
        }
        if progress.cancelled() {
            return Ok(Film::new(cam.width, cam.height, settings.filter));
        }

        // Shading pass, rows in parallel.
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| crate::error::Error::Settings(format!("thread pool: {e}")))?;
        let colours: Vec<Rgb> = pool.install(|| {
            (0..h)
                .into_par_iter()
                .flat_map_iter(|y| {
                    let row: Vec<Rgb> = (0..w)
                        .map(|x| {
                            let (k, b) = ids[(y * w + x) as usize];
                            if k == u32::MAX {
                                let raster = Vec2::new((x as f32 + 0.5) / ss as f32, (y as f32 + 0.5) / ss as f32);
                                let d = cam.generate_ray(raster, Vec2::splat(0.5), 0.5).d;
                                return if settings.hide_emitters {
                                    Rgb::BLACK
                                } else {
                                    scene.environment_lights.iter().map(|&e| scene.lights[e as usize].le_escaped(d)).sum()
                                };
                            }
                            let t = &tris[k as usize];
                            let eye_for = |p: Vec3| match projection {
                                ViewProjection::Perspective { .. } => eye,
                                ViewProjection::Orthographic { .. } => p - view_dir,
                            };
                            match self.shading {
                                Shading::Phong => {
                                    let s = Self::surface(scene, &poses, t, b);
                                    self.shade(scene, &lights, &maps, t.shape, &s, eye_for(s.p), settings)
                                }
                                Shading::Flat => {
                                    let mut s = Self::surface(scene, &poses, t, [1.0 / 3.0; 3]);
                                    s.ns = s.ng;
                                    self.shade(scene, &lights, &maps, t.shape, &s, eye_for(s.p), settings)
                                }
                                Shading::Gouraud => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
                                    .iter()
                                    .zip(b)
                                    .map(|(vb, wgt)| {
                                        let s = Self::surface(scene, &poses, t, *vb);
                                        self.shade(scene, &lights, &maps, t.shape, &s, eye_for(s.p), settings) * wgt
                                    })
                                    .sum(),
                            }
                        })
                        .collect();
                    progress.done.fetch_add(w as u64, Ordering::Relaxed);
                    row
                })
                .collect()
        });
        let mut film = Film::new(cam.width, cam.height, settings.filter);
        for y in 0..h {
            for x in 0..w {
                let raster = Vec2::new((x as f32 + 0.5) / ss as f32, (y as f32 + 0.5) / ss as f32);
                film.add_sample(raster, colours[(y * w + x) as usize]);
            }
        }
        film.spp_done = ss * ss;
        Ok(film)
    }
}
