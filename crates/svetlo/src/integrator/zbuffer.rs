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
use crate::bsdf::{Bsdf, BsdfModel};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::geometry::Geometry;
use crate::light::Light;
use crate::lpe::aov::LayerSample;
use crate::lpe::{AovSet, Event, LayerMask};
use crate::math::{Frame, PI};
use crate::raster::shadow::ShadowMap;
use crate::raster::{View, ViewProjection};
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
                // An implicit surface has no triangles to rasterise: not drawn.
                Geometry::SdfGrid(_) => {}
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
            // Never rasterised (see `triangles`).
            Geometry::SdfGrid(_) => Surface { p: q, ng: Vec3::Z, ns: Vec3::Z, uv: Vec2::ZERO, dpdu: Vec3::ZERO },
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
                    Light::Luminaire(lum) => Some(ShadowMap::point(lum.position, res, &occluders, near)),
                    Light::Projector(pr) => Some(ShadowMap::point(pr.position, res, &occluders, near)),
                    Light::Goniometric(g) => Some(ShadowMap::point(g.position, res, &occluders, near)),
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
    fn shade(&self, scene: &Scene, prepared: &Prepared, shape: u32, s: &Surface, eye: Vec3, hide_emitters: bool) -> Rgb {
        let (lights, maps) = (&prepared.lights, &prepared.maps);
        let wo_w = (eye - s.p).normalize_or_zero();
        let mut l = Rgb::BLACK;
        let sh = &scene.shapes[shape as usize];
        if let (Some(li), false) = (sh.light, hide_emitters) {
            if let Light::Area(a) = &scene.lights[li as usize] {
                l += a.l(s.ng, s.uv, wo_w);
            }
        }
        if prepared.emission_only {
            return l;
        }
        let owned;
        let bsdf = match &prepared.bsdfs[sh.material as usize] {
            Some(b) => b,
            None => {
                owned = scene.materials[sh.material as usize].bsdf(s.uv);
                &owned
            }
        };
        if !self.ambient.is_black() {
            l += self.ambient * bsdf.diffuse_albedo();
        }
        if let Some(lb) = &prepared.lambert[sh.material as usize] {
            return l + lb.lights(scene, prepared, s.p, s.ng, s.ns, wo_w);
        }
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

/// What a frame needs that does not depend on the camera: the scene's triangles (in world
/// space, moving shapes at mid-shutter), the lights as points and their shadow maps.
/// Prepared once; each [`Prepared::frame`] then only rasterises and shades.
pub struct Prepared {
    zbuffer: ZBuffer,
    lights: LocalLights,
    poses: Vec<Option<(Mat4, Mat4)>>,
    tris: Vec<RasterTri>,
    maps: Vec<Option<ShadowMap>>,
    /// The BSDF of each material that has no texture (the same at every point).
    bsdfs: Vec<Option<Bsdf>>,
    /// Those of them that are Lambertian on each side, as their constant f.
    lambert: Vec<Option<Lambert>>,
    /// Shade only the emitted light (`C L` and `C B`: the light path expressions' split).
    emission_only: bool,
}

/// A uniform BSDF that is Lambertian on each side it reflects from (`diffuse`, `twosided`
/// diffuse): f = ρ/π (times the opacity) when wo and wi lie on one side of the shading
/// normal, so shading needs two cosines, not a shading frame; or a one-sided Blinn-Phong,
/// which needs the half vector too (still no frame).
#[derive(Clone, Copy, Debug)]
struct Lambert {
    front: Rgb,
    back: Option<Rgb>,
    /// A one-sided Blinn-Phong instead (`front` unused): its specular lobe needs the half
    /// vector, which is taken in world space (equal to the frame's to float rounding).
    blinn: Option<BlinnLocal>,
}

#[derive(Clone, Copy, Debug)]
struct BlinnLocal {
    model: crate::bsdf::blinn::BlinnPhong,
    opacity: f32,
}

impl BlinnLocal {
    /// As `BlinnPhong::eval` then `* opacity`, with wo, wi in world space and their cosines.
    #[inline(always)]
    fn eval(&self, cos_o: f32, cos_i: f32, wo: Vec3, wi: Vec3, ns: Vec3) -> Rgb {
        if cos_o <= 0.0 || cos_i <= 0.0 {
            return Rgb::BLACK;
        }
        let m = &self.model;
        let n = m.exponent;
        let hz = (wo + wi).normalize().dot(ns);
        let lobe = (n + 1.0) / (8.0 * crate::math::PI) * hz.max(0.0).powf(n) / cos_o.max(cos_i);
        (m.diffuse_reflectance * crate::math::INV_PI + m.specular_reflectance * lobe) * self.opacity
    }
}

impl Lambert {
    fn of(b: &Bsdf) -> Option<Self> {
        if let (BsdfModel::BlinnPhong(m), None) = (&b.front, &b.back) {
            return Some(Lambert { front: Rgb::BLACK, back: None, blinn: Some(BlinnLocal { model: *m, opacity: b.opacity }) });
        }
        // As `Diffuse::eval` then `* opacity` in `Bsdf::eval`, in that order.
        let f = |m: &BsdfModel| match m {
            BsdfModel::Diffuse(d) => Some(d.reflectance * crate::math::INV_PI * b.opacity),
            _ => None,
        };
        let front = f(&b.front)?;
        let back = match &b.back {
            None => None,
            Some(m) => Some(f(m)?),
        };
        Some(Lambert { front, back, blinn: None })
    }

    /// Σ over lights of f L |cos θi| at `p` seen from direction `wo` (world space), with
    /// shadow maps. Only the cosines to the shading normal matter: no frame, no BSDF
    /// dispatch (the z of the frame's local directions is the dot with `ns`).
    #[inline(always)]
    fn lights(&self, scene: &Scene, prepared: &Prepared, p: Vec3, ng: Vec3, ns: Vec3, wo: Vec3) -> Rgb {
        let mut l = Rgb::BLACK;
        let cos_o = wo.dot(ns);
        for (i, map) in prepared.maps.iter().enumerate() {
            let Some(ls) = prepared.lights.sample(scene, i, p) else { continue };
            let cos_i = ls.wi.dot(ns);
            let f = match &self.blinn {
                None => self.eval(cos_o, cos_i),
                Some(b) => b.eval(cos_o, cos_i, wo, ls.wi, ns),
            };
            if f.is_black() {
                continue;
            }
            if let Some(m) = map {
                if !m.lit(p, ng) {
                    continue;
                }
            }
            l += f * ls.li * cos_i.abs();
        }
        l
    }

    /// `Bsdf::eval` for local directions with z = `cos_o`, `cos_i` (the back side mirrored).
    #[inline]
    fn eval(&self, cos_o: f32, cos_i: f32) -> Rgb {
        if cos_o >= 0.0 {
            if cos_o > 0.0 && cos_i > 0.0 {
                self.front
            } else {
                Rgb::BLACK
            }
        } else {
            match self.back {
                Some(b) if cos_i < 0.0 => b,
                _ => Rgb::BLACK,
            }
        }
    }
}

/// One frame: the colour of every subsample (`ss` x `ss` per pixel) and the image that
/// averages them (box resolve).
pub struct FrameImage {
    pub ss: u32,
    pub subsamples: Vec<Rgb>,
    /// The triangle each subsample sees (u32::MAX: none).
    pub triangles: Vec<u32>,
    pub image: crate::film::Image,
    /// Wall time of the visibility pass (transform, rasterise, depth test) and of the rest
    /// (shading the visible subsamples, resolve), for benchmarks.
    pub visibility_time: std::time::Duration,
    pub shading_time: std::time::Duration,
}

impl ZBuffer {
    /// The camera-independent work of a render (see [`Prepared`]).
    pub fn prepare(&self, scene: &Scene) -> Prepared {
        let lights = LocalLights::new(scene);
        let poses = poses(scene);
        let tris = self.triangles(scene, &poses);
        let maps = self.shadow_maps(scene, &lights, &tris);
        let bsdfs: Vec<Option<Bsdf>> = scene.materials.iter().map(|m| m.is_uniform().then(|| m.bsdf(Vec2::ZERO))).collect();
        let lambert = bsdfs.iter().map(|b| b.as_ref().and_then(Lambert::of)).collect();
        Prepared { zbuffer: *self, lights, poses, tris, maps, bsdfs, lambert, emission_only: false }
    }
}

/// Subsamples per pixel side for `spp`: the nearest square, at most 8 x 8.
pub fn subsamples_per_side(spp: u32) -> u32 {
    ((spp as f32).sqrt().round() as u32).clamp(1, 8)
}

impl Prepared {
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Render the scene as `camera` sees it with `ss` x `ss` subsamples per pixel, shading on
    /// `threads` threads (1: on the calling thread; 0: all cores).
    pub fn frame(&self, scene: &Scene, camera: &crate::camera::Camera, ss: u32, hide_emitters: bool, threads: usize) -> Result<FrameImage> {
        let cam = camera;
        let ss = ss.clamp(1, 8);
        let (w, h) = (cam.width * ss, cam.height * ss);
        let projection = match cam.projection {
            crate::camera::Projection::Perspective { .. } => ViewProjection::Perspective { half: cam.film_half_extent() },
            crate::camera::Projection::Orthographic => ViewProjection::Orthographic { half: cam.film_half_extent() },
        };
        let world_to_camera = cam.to_world.inverse();
        let view = View { world_to_camera, projection, width: w, height: h, near: cam.near_clip.max(1e-5) };

        // Visibility pass: the depth key and the nearest triangle of every subsample; nothing
        // else is computed for fragments that may be hidden later.
        let start = std::time::Instant::now();
        let far_key = view.key(cam.far_clip);
        let mut depth = vec![far_key; (w * h) as usize];
        let mut ids = vec![u32::MAX; (w * h) as usize];
        for (k, t) in self.tris.iter().enumerate() {
            let pc = t.v.map(|p| world_to_camera.transform_point3(p));
            view.raster_keys(pc, |i, key| {
                // SAFETY of the index: raster_keys only reports pixels inside the view.
                if key > depth[i] {
                    depth[i] = key;
                    ids[i] = k as u32;
                }
            });
        }

        let visibility_time = start.elapsed();
        // Shading pass: only the visible fragment of each subsample, rows in parallel.
        let eye = cam.to_world.transform_point3(Vec3::ZERO);
        let view_dir = cam.to_world.transform_vector3(Vec3::Z).normalize();
        // The line through a subsample centre: camera-space film point c = (1 - 2 r / size) half,
        // direction (c, 1) from the eye (perspective) or origin (c, 0) along +z (orthographic).
        let half = cam.film_half_extent();
        let lin = Mat3::from_mat4(cam.to_world);
        let step = Vec2::new(-2.0 * half.x / w as f32, -2.0 * half.y / h as f32);
        let line = |x: u32, y: u32| -> (Vec3, Vec3) {
            let c = half + Vec2::new(x as f32 + 0.5, y as f32 + 0.5) * step;
            match projection {
                ViewProjection::Perspective { .. } => (eye, lin * Vec3::new(c.x, c.y, 1.0)),
                ViewProjection::Orthographic { .. } => (cam.to_world.transform_point3(Vec3::new(c.x, c.y, 0.0)), view_dir),
            }
        };
        let fast_ok = self.zbuffer.shading == Shading::Phong && matches!(projection, ViewProjection::Perspective { .. });
        let pixel = |x: u32, y: u32, cached: &mut Option<MeshTri>, fast: &mut (u32, Option<FastTri>)| -> Rgb {
            {
                {
                    let k = ids[(y * w + x) as usize];
                    let (o, d) = line(x, y);
                    if k == u32::MAX {
                        let d = d.normalize();
                        return if hide_emitters { Rgb::BLACK } else { scene.environment_lights.iter().map(|&e| scene.lights[e as usize].le_escaped(d)).sum() };
                    }
                    if fast_ok && !self.emission_only {
                        if fast.0 != k {
                            *fast = (k, FastTri::new(self, scene, k, eye));
                        }
                        if let Some(c) = fast.1.as_ref().and_then(|ft| ft.shade(scene, self, eye, d)) {
                            return c;
                        }
                    }
                    let t = &self.tris[k as usize];
                    let b = barycentrics(t.v, o, d);
                    let eye_for = |p: Vec3| match projection {
                        ViewProjection::Perspective { .. } => eye,
                        ViewProjection::Orthographic { .. } => p - view_dir,
                    };
                    let z = &self.zbuffer;
                    match z.shading {
                        Shading::Phong => {
                            let s = match (&*scene.shapes[t.shape as usize].geometry, self.poses[t.shape as usize]) {
                                (Geometry::Mesh(m), None) => {
                                    // By reference: a MeshTri is too big to copy per subsample.
                                    if cached.as_ref().is_none_or(|c| c.id != k) {
                                        *cached = Some(MeshTri::new(k, m, t.prim as usize));
                                    }
                                    let Some(mt) = cached.as_ref() else { unreachable!("just cached") };
                                    mt.surface(t.v[0] * b[0] + t.v[1] * b[1] + t.v[2] * b[2], b)
                                }
                                _ => ZBuffer::surface(scene, &self.poses, t, b),
                            };
                            z.shade(scene, self, t.shape, &s, eye_for(s.p), hide_emitters)
                        }
                        Shading::Flat => {
                            let mut s = ZBuffer::surface(scene, &self.poses, t, [1.0 / 3.0; 3]);
                            s.ns = s.ng;
                            z.shade(scene, self, t.shape, &s, eye_for(s.p), hide_emitters)
                        }
                        Shading::Gouraud => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
                            .iter()
                            .zip(b)
                            .map(|(vb, wgt)| {
                                let s = ZBuffer::surface(scene, &self.poses, t, *vb);
                                z.shade(scene, self, t.shape, &s, eye_for(s.p), hide_emitters) * wgt
                            })
                            .sum(),
                    }
                }
            }
        };
        let shade_row = |y: u32, row: &mut [Rgb]| {
            let mut cached: Option<MeshTri> = None;
            let mut fast = (u32::MAX, None);
            for (x, out) in (0..w).zip(row.iter_mut()) {
                *out = pixel(x, y, &mut cached, &mut fast);
            }
        };
        // Written in place, row by row: no per-row vectors to allocate and concatenate.
        let mut subsamples = vec![Rgb::BLACK; (w * h) as usize];
        if threads == 1 {
            subsamples.chunks_mut(w as usize).enumerate().for_each(|(y, row)| shade_row(y as u32, row));
        } else {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| crate::error::Error::Settings(format!("thread pool: {e}")))?;
            pool.install(|| subsamples.par_chunks_mut(w as usize).enumerate().for_each(|(y, row)| shade_row(y as u32, row)));
        }
        let mut image = crate::film::Image::new(cam.width as usize, cam.height as usize, vec![Rgb::BLACK; (cam.width * cam.height) as usize]);
        let norm = 1.0 / (ss * ss) as f32;
        for y in 0..h {
            let row = &subsamples[(y * w) as usize..((y + 1) * w) as usize];
            let out = &mut image.data[((y / ss) * cam.width) as usize..((y / ss + 1) * cam.width) as usize];
            for (x, c) in row.iter().enumerate() {
                out[x / ss as usize] += *c * norm;
            }
        }
        Ok(FrameImage { ss, subsamples, triangles: ids, image, visibility_time, shading_time: start.elapsed() - visibility_time })
    }
}

/// The fast path of Phong shading under a perspective camera: a static mesh triangle with
/// a Lambertian material that does not emit. The camera ray's barycentrics become three
/// dot products with per-triangle vectors (the scalar triple products of the ray-plane
/// intersection, with the eye fixed), and shading is the Lambert light loop inline.
struct FastTri {
    v: [Vec3; 3],
    /// e2 x e1, e2 x s, s x e1 with s = eye - v0: det, b1 det and b2 det are their dots with d.
    n12: Vec3,
    q1: Vec3,
    q2: Vec3,
    ng: Vec3,
    normals: Option<[Vec3; 3]>,
    lambert: Lambert,
    ambient: Rgb,
}

impl FastTri {
    fn new(prepared: &Prepared, scene: &Scene, k: u32, eye: Vec3) -> Option<Self> {
        let t = &prepared.tris[k as usize];
        let sh = &scene.shapes[t.shape as usize];
        let lambert = prepared.lambert[sh.material as usize]?;
        if sh.light.is_some() || prepared.poses[t.shape as usize].is_some() {
            return None;
        }
        let Geometry::Mesh(m) = &*sh.geometry else { return None };
        // As MeshTri::new, without dp/du (not needed here; it costs a full `surface` call,
        // which tiny triangles of big meshes pay almost per subsample).
        let prim = t.prim as usize;
        let [p0, p1, p2] = m.vertices(prim);
        let ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        let normals = (!m.normals.is_empty()).then(|| m.indices[prim].map(|i| m.normals[i as usize]));
        let ambient = &prepared.zbuffer.ambient;
        let ambient = if ambient.is_black() { Rgb::BLACK } else { *ambient * prepared.bsdfs[sh.material as usize].as_ref()?.diffuse_albedo() };
        let (e1, e2) = (t.v[1] - t.v[0], t.v[2] - t.v[0]);
        let s = eye - t.v[0];
        Some(FastTri { v: t.v, n12: e2.cross(e1), q1: e2.cross(s), q2: s.cross(e1), ng, normals, lambert, ambient })
    }

    /// The colour seen along direction `d` from the eye; `None` for a ray parallel to the plane.
    #[inline(always)]
    fn shade(&self, scene: &Scene, prepared: &Prepared, eye: Vec3, d: Vec3) -> Option<Rgb> {
        let det = d.dot(self.n12);
        if det == 0.0 {
            return None;
        }
        let inv = 1.0 / det;
        let b1 = d.dot(self.q1) * inv;
        let b2 = d.dot(self.q2) * inv;
        let b0 = 1.0 - b1 - b2;
        let p = self.v[0] * b0 + self.v[1] * b1 + self.v[2] * b2;
        // As MeshTri::surface.
        let (ng, ns) = match self.normals {
            None => (self.ng, self.ng),
            Some(n) => {
                let ns = (n[0] * b0 + n[1] * b1 + n[2] * b2).normalize_or_zero();
                let ns = if ns == Vec3::ZERO { self.ng } else { ns };
                (if self.ng.dot(ns) < 0.0 { -self.ng } else { self.ng }, ns)
            }
        };
        let wo = (eye - p).normalize_or_zero();
        Some(self.ambient + self.lambert.lights(scene, prepared, p, ng, ns, wo))
    }
}

/// A static mesh triangle's shading inputs, fetched once for a run of subsamples that see
/// it (big triangles cover many in a row).
#[derive(Clone, Copy)]
struct MeshTri {
    id: u32,
    ng: Vec3,
    normals: Option<[Vec3; 3]>,
    uv: [Vec2; 3],
    dpdu: Vec3,
}

impl MeshTri {
    fn new(id: u32, m: &crate::geometry::TriangleMesh, prim: usize) -> Self {
        // dp/du is constant over a triangle.
        let (_, _, _, dpdu) = m.surface(prim, 1.0 / 3.0, 1.0 / 3.0);
        // The unflipped geometric normal: the flip toward the shading normal is per point.
        let [p0, p1, p2] = m.vertices(prim);
        let ng0 = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        let idx = m.indices[prim].map(|i| i as usize);
        let normals = (!m.normals.is_empty()).then(|| idx.map(|i| m.normals[i]));
        let uv = if m.uvs.is_empty() { [Vec2::ZERO, Vec2::X, Vec2::Y] } else { idx.map(|i| m.uvs[i]) };
        MeshTri { id, ng: ng0, normals, uv, dpdu }
    }

    /// As `TriangleMesh::surface` at barycentrics `b`, at point `p`.
    #[inline]
    fn surface(&self, p: Vec3, b: [f32; 3]) -> Surface {
        let uv = self.uv[0] * b[0] + self.uv[1] * b[1] + self.uv[2] * b[2];
        let (ng, ns) = match self.normals {
            None => (self.ng, self.ng),
            Some(n) => {
                let ns = (n[0] * b[0] + n[1] * b[1] + n[2] * b[2]).normalize_or_zero();
                let ns = if ns == Vec3::ZERO { self.ng } else { ns };
                (if self.ng.dot(ns) < 0.0 { -self.ng } else { self.ng }, ns)
            }
        };
        Surface { p, ng, ns, uv, dpdu: self.dpdu }
    }
}

/// Barycentrics of the point where the line `o + t d` meets the plane of triangle `v`
/// (perspective-correct by construction: the visible point of a subsample is found again
/// from its camera ray, so the visibility pass stores nothing but the triangle).
#[inline]
fn barycentrics(v: [Vec3; 3], o: Vec3, d: Vec3) -> [f32; 3] {
    let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return [1.0 / 3.0; 3];
    }
    let inv = 1.0 / det;
    let s = o - v[0];
    let b1 = s.dot(p) * inv;
    let b2 = d.dot(s.cross(e1)) * inv;
    [1.0 - b1 - b2, b1, b2]
}

impl Integrator for ZBuffer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        settings.validate()?;
        let cam = &scene.camera;
        let ss = subsamples_per_side(settings.spp);
        let prepared = self.prepare(scene);
        if progress.cancelled() {
            return Ok(Film::new(cam.width, cam.height, settings.filter));
        }
        let (w, h) = (cam.width * ss, cam.height * ss);
        progress.total.store((w * h) as u64, Ordering::Relaxed);
        let aovs = settings.aovs();
        let routes = if aovs.is_empty() { None } else { Some(self.routes(scene, aovs)?) };
        let mut prepared = prepared;
        let frame = prepared.frame(scene, cam, ss, settings.hide_emitters, settings.threads)?;
        // With AOVs: the emitted part apart (a second, cheap pass), the rest reflected once.
        let emitted = match routes {
            Some(_) => {
                prepared.emission_only = true;
                Some(prepared.frame(scene, cam, ss, settings.hide_emitters, settings.threads)?.subsamples)
            }
            None => None,
        };
        progress.done.store((w * h) as u64, Ordering::Relaxed);
        // Through the film, so that the scene's reconstruction filter applies to the subsamples.
        let mut film = Film::with_layers(cam.width, cam.height, settings.filter, aovs.names());
        let mut tile = film.tile(0, 0, cam.width, cam.height);
        let n = aovs.aov_count();
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let raster = Vec2::new((x as f32 + 0.5) / ss as f32, (y as f32 + 0.5) / ss as f32);
                let l = frame.subsamples[i];
                let (Some((background, masks)), Some(emitted)) = (&routes, &emitted) else {
                    tile.add_sample(raster, l);
                    continue;
                };
                let mut layers = LayerSample::default();
                match frame.triangles[i] {
                    u32::MAX => layers.add(*background, l),
                    k => {
                        let m = masks[prepared.tris[k as usize].shape as usize];
                        layers.add(m[0], emitted[i]);
                        layers.add(m[1], l - emitted[i]);
                    }
                }
                let beauty = if aovs.restricts_beauty() { layers.beauty } else { l };
                tile.add_sample_layers(raster, beauty, &layers.aov[..n]);
            }
        }
        film.merge_tile(&tile);
        film.spp_done = ss * ss;
        progress.pass_done(&film);
        Ok(film)
    }
}

impl ZBuffer {
    /// The layers of the paths the local model computes: the background (`C B`), and per
    /// shape its emission (`C L`) and its light reflected once (`C x L`, x the material's
    /// type); a typed error when an expression takes only some of one class, or with an
    /// ambient term (no light path).
    fn routes(&self, scene: &Scene, aovs: &AovSet) -> Result<(LayerMask, Vec<[LayerMask; 2]>)> {
        if !self.ambient.is_black() {
            return Err(Error::Settings("zbuffer: the ambient term is no light path: light path expressions need ambient 0".into()));
        }
        let lights = aovs.emitter_events(scene);
        let err = |e: String| {
            Error::Settings(format!(
                "zbuffer: the light path expression '{e}' takes only some of the paths of a class the local model keeps whole (per surface: C L, C x L)"
            ))
        };
        let background = aovs.class_layers(&[Event::CAMERA], &[], 0, &[Event::BACKGROUND]).map_err(err)?;
        let masks = scene
            .shapes
            .iter()
            .enumerate()
            .map(|(k, sh)| {
                let flags = scene.materials[sh.material as usize].bsdf(Vec2::splat(0.5)).flags();
                let emit = aovs.class_layers(&[Event::CAMERA], &[], 0, &[aovs.light_event(Some(k as u32))])?;
                // Reflection and (for transmissive lobes) transmission toward the light.
                let once = aovs.class_layers(&[Event::CAMERA, aovs.scatter_event(k as u32, flags, None, false)], &[], 0, &lights)?;
                if flags.intersects(crate::bsdf::LobeFlags::TRANSMISSION) {
                    let t = aovs.class_layers(&[Event::CAMERA, aovs.scatter_event(k as u32, flags, None, true)], &[], 0, &lights)?;
                    if t != once {
                        return Err(format!("(one of them, R against T at '{}')", sh.name));
                    }
                }
                Ok([emit, once])
            })
            .collect::<std::result::Result<Vec<_>, String>>()
            .map_err(err)?;
        Ok((background, masks))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::diffuse::Diffuse;
    use crate::bsdf::TransportMode;

    /// Unit vectors spread over the sphere, plus the cases on the horizon.
    fn directions() -> Vec<Vec3> {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut u = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut v: Vec<Vec3> = (0..200).map(|_| Vec3::new(2.0 * u() - 1.0, 2.0 * u() - 1.0, 2.0 * u() - 1.0).normalize()).collect();
        v.extend([Vec3::X, Vec3::Z, Vec3::NEG_Z, Vec3::new(0.6, 0.8, -0.0)]);
        v
    }

    #[test]
    fn lambert_equals_bsdf_eval_bitwise() {
        let d = |r: f32, g: f32, b: f32| BsdfModel::Diffuse(Diffuse { reflectance: Rgb::new(r, g, b) });
        let bsdfs = [
            Bsdf::new(d(0.7, 0.5, 0.3)),
            Bsdf { front: d(0.7, 0.5, 0.3), back: Some(d(0.1, 0.9, 0.4)), opacity: 1.0, detail: None },
            Bsdf { front: d(0.7, 0.5, 0.3), back: Some(d(0.2, 0.2, 0.2)), opacity: 0.37, detail: None },
        ];
        let dirs = directions();
        for b in &bsdfs {
            let lb = Lambert::of(b).expect("diffuse is Lambertian");
            assert!(lb.blinn.is_none());
            for wo in &dirs {
                for wi in &dirs {
                    let want = b.eval(*wo, *wi, TransportMode::Radiance);
                    let got = lb.eval(wo.z, wi.z);
                    assert_eq!((got.r.to_bits(), got.g.to_bits(), got.b.to_bits()), (want.r.to_bits(), want.g.to_bits(), want.b.to_bits()), "wo {wo} wi {wi}");
                }
            }
        }
        // A non-Lambertian side keeps the general path.
        let blinn = BsdfModel::BlinnPhong(crate::bsdf::blinn::BlinnPhong {
            diffuse_reflectance: Rgb::splat(0.5),
            specular_reflectance: Rgb::splat(0.2),
            exponent: 20.0,
            specular_sampling_weight: 0.5,
        });
        assert!(Lambert::of(&Bsdf { front: d(0.5, 0.5, 0.5), back: Some(blinn.clone()), opacity: 1.0, detail: None }).is_none());
        // Blinn-Phong in world space equals the BSDF in the shading frame to rounding.
        let bsdf = Bsdf { front: blinn, back: None, opacity: 0.8, detail: None };
        let local = Lambert::of(&bsdf).and_then(|l| l.blinn).expect("one-sided Blinn-Phong");
        let ns = Vec3::new(0.2, -0.5, 0.8).normalize();
        let frame = crate::math::Frame::from_normal_tangent(ns, Vec3::X);
        for wo in &dirs {
            for wi in &dirs {
                let want = bsdf.eval(frame.to_local(*wo), frame.to_local(*wi), TransportMode::Radiance);
                let got = local.eval(wo.dot(ns), wi.dot(ns), *wo, *wi, ns);
                let tol = 1e-3 * want.max_component().max(1e-3);
                assert!((got - want).max_component().abs() <= tol && (want - got).max_component().abs() <= tol, "wo {wo} wi {wi}: {got:?} vs {want:?}");
            }
        }
    }

    /// The fast path's barycentrics (triple products cached per triangle) agree with the
    /// ray-plane intersection of the general path to float rounding.
    #[test]
    fn fast_barycentrics_match_ray_plane() {
        let dirs = directions();
        let eye = Vec3::new(0.3, -0.2, 4.0);
        for (i, w) in dirs.windows(3).enumerate().take(60) {
            let v = [w[0] * 2.0, w[1] * 2.0 + Vec3::X, w[2] * 2.0 - Vec3::Y];
            let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
            let s = eye - v[0];
            let (n12, q1, q2) = (e2.cross(e1), e2.cross(s), s.cross(e1));
            let target = v[0] * 0.2 + v[1] * 0.3 + v[2] * 0.5 + dirs[i] * 1e-3;
            let d = target - eye;
            let want = barycentrics(v, eye, d);
            let det = d.dot(n12);
            let got = [1.0 - d.dot(q1) / det - d.dot(q2) / det, d.dot(q1) / det, d.dot(q2) / det];
            let scale = e1.length().max(e2.length()) * s.length();
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() <= 1e-4 * scale.max(1.0), "{got:?} vs {want:?}");
            }
        }
    }
}
