//! The path tracer of `path.rs`, eight paths at a time: the same estimator (next-event
//! estimation and BSDF sampling combined by the power heuristic, Russian roulette, Mitsuba's
//! `max_depth`), with the rays of eight paths traced as one packet (`accel::packet`).
//!
//! Scope: static scenes of triangle meshes, (two-sided) Lambertian
//! materials of constant reflectance, area lights of constant radiance on meshes, no
//! environment light, the independent sampler. `SimdPathTracer` checks that
//! (`SimdKernel::new`) and otherwise, or without AVX2, runs the scalar tracer.
//!
//! Each lane draws its random numbers from its own copy of the scalar tracer's sampler, in
//! the same order, and the samples of a tile are added to the film in the scalar order, so
//! that the image equals the scalar tracer's up to float rounding (paths that meet a shared
//! edge may pick the other triangle).

use super::path::PathTracer;
use super::{camera_sample, render_tiles, Integrator, Progress, RenderSettings};
use crate::accel::packet::{PacketBvh, Rays8, LANES};
use crate::bsdf::Material;
use crate::error::{Error, Result};
use crate::film::{Film, FilmTile};
use crate::geometry::ray::{offset_ray_origin, SHADOW_EPSILON};
use crate::geometry::{Geometry, TriangleMesh};
use crate::light::{AreaLight, Light, LightSample};
use crate::math::{warp, Frame, INV_PI};
use crate::sampling::sampler::IndependentSampler;
use crate::sampling::{power_heuristic, Distribution1D, Sampler, SamplerKind};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// `path`: the eight-wide kernel when the scene qualifies and the CPU has AVX2, else the
/// scalar [`PathTracer`]. `path:simd=false` always runs the scalar one.
#[derive(Clone, Copy, Debug)]
pub struct SimdPathTracer {
    pub simd: bool,
}

impl Default for SimdPathTracer {
    fn default() -> Self {
        SimdPathTracer { simd: true }
    }
}

impl SimdPathTracer {
    /// Options `key=value,...`: `simd=true|false`.
    pub fn parse(opts: &str) -> Result<Self> {
        let mut t = SimdPathTracer::default();
        for kv in opts.split(',').filter(|s| !s.is_empty()) {
            match kv.split_once('=') {
                Some(("simd", v)) => t.simd = v.parse().map_err(|_| Error::Settings(format!("path: simd must be true or false, got '{v}'")))?,
                _ => return Err(Error::Settings(format!("path: unknown option '{kv}' (available: simd=true|false)"))),
            }
        }
        Ok(t)
    }
}

impl Integrator for SimdPathTracer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        if self.simd && crate::accel::packet::avx2() {
            if let Some(k) = SimdKernel::new(scene, settings) {
                return k.render(scene, settings, progress);
            }
        }
        PathTracer.render(scene, settings, progress)
    }
}

/// A triangle as shading sees it.
#[derive(Clone, Copy, Debug)]
struct Tri {
    p: [Vec3; 3],
    /// (geometric normal, shading frame) when constant over the triangle; else interpolated per hit.
    flat: Option<(Vec3, Frame)>,
    shape: u32,
    /// Index in its mesh.
    prim: u32,
}

/// A shape's material and emission.
#[derive(Clone, Copy, Debug)]
struct ShapeData {
    front: Rgb,
    /// Reflectance seen from the back (two-sided); None: black there.
    back: Option<Rgb>,
    /// Light index and radiance when the shape emits.
    light: Option<(u32, Rgb)>,
}

/// A mesh area light as `AreaLight::sample_li` samples it, unpacked: its triangles' vertices
/// and the normals it gives sampled points.
struct MeshLight {
    /// 1 / area (0 for a light without area).
    pdf_area: f32,
    tri_distribution: Distribution1D,
    /// First vertex and edges (p0, p1 - p0, p2 - p0) and, when constant over the triangle,
    /// the sampled point's normal.
    tris: Vec<([Vec3; 3], Option<Vec3>)>,
    radiance: Rgb,
    /// The light's index, for the normals of `TriangleMesh::surface` where not constant.
    light: u32,
}

/// Everything the kernel needs of a qualifying scene.
pub struct SimdKernel {
    bvh: PacketBvh,
    tris: Vec<Tri>,
    shapes: Vec<ShapeData>,
    /// Per light of the scene.
    lights: Vec<MeshLight>,
}

/// `AreaLight`'s per-triangle normal: the geometric normal on the side all vertex normals
/// face, None when they disagree (then interpolated at the point).
fn constant_normal(m: &TriangleMesh, t: usize) -> Option<Vec3> {
    let [p0, p1, p2] = m.vertices(t);
    let ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
    if m.normals.is_empty() {
        return Some(ng);
    }
    let sides = m.indices[t].map(|i| ng.dot(m.normals[i as usize]));
    if sides.iter().all(|&d| d > 0.0) {
        Some(ng)
    } else if sides.iter().all(|&d| d < 0.0) {
        Some(-ng)
    } else {
        None
    }
}

/// The constant reflectance of a diffuse model, clamped as `Material::bsdf` does.
fn diffuse_constant(m: &Material) -> Option<Rgb> {
    match m {
        Material::Diffuse { reflectance: Texture::Constant(c) } => Some(c.clamp(0.0, 1.0)),
        _ => None,
    }
}

fn area_of(scene: &Scene, li: u32) -> Option<&AreaLight> {
    match scene.lights.get(li as usize)? {
        Light::Area(a) => Some(a),
        _ => None,
    }
}

impl SimdKernel {
    /// The kernel's data, or None when the scene or the settings are out of its scope.
    pub fn new(scene: &Scene, settings: &RenderSettings) -> Option<SimdKernel> {
        if settings.sampler != SamplerKind::Independent || !scene.moving.is_empty() || !scene.static_shapes.is_empty() || !scene.environment_lights.is_empty() {
            return None;
        }
        let mut lights = Vec::with_capacity(scene.lights.len());
        for (li, l) in scene.lights.iter().enumerate() {
            let Light::Area(a) = l else { return None };
            let (Geometry::Mesh(m), Texture::Constant(radiance), Some(dist)) = (&*a.geometry, &a.radiance, &a.tri_distribution) else { return None };
            if dist.is_empty() {
                return None;
            }
            let tris = (0..m.triangle_count())
                .map(|t| {
                    let [p0, p1, p2] = m.vertices(t);
                    ([p0, p1 - p0, p2 - p0], constant_normal(m, t))
                })
                .collect();
            let pdf_area = if a.area > 0.0 { 1.0 / a.area } else { 0.0 };
            lights.push(MeshLight { pdf_area, tri_distribution: dist.clone(), tris, radiance: *radiance, light: li as u32 });
        }
        let mut shapes = Vec::with_capacity(scene.shapes.len());
        let mut tris = Vec::new();
        let mut verts = Vec::new();
        for (si, s) in scene.shapes.iter().enumerate() {
            let Geometry::Mesh(m) = &*s.geometry else { return None };
            let mat = scene.materials.get(s.material as usize)?;
            let (front, back) = match mat {
                Material::TwoSided { front, back } => (diffuse_constant(front)?, Some(diffuse_constant(back)?)),
                m => (diffuse_constant(m)?, None),
            };
            let light = match s.light {
                Some(li) => {
                    let a = area_of(scene, li)?;
                    let Texture::Constant(le) = a.radiance else { return None };
                    Some((li, le))
                }
                None => None,
            };
            shapes.push(ShapeData { front, back, light });
            for t in 0..m.triangle_count() {
                let p = m.vertices(t);
                verts.push(p);
                tris.push(Tri { p, flat: s.flat.get(t).copied().flatten(), shape: si as u32, prim: t as u32 });
            }
        }
        Some(SimdKernel { bvh: PacketBvh::build(&verts), tris, shapes, lights })
    }

    pub fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        render_tiles(scene, settings, progress, &|tile: &mut FilmTile, s0: u32, n: u32| {
            #[cfg(target_arch = "x86_64")]
            if self.bvh.simd() {
                // SAFETY: `simd()` is true only where AVX2 was detected at run time.
                return unsafe { self.render_tile_avx2(scene, settings, tile, s0, n) };
            }
            self.render_tile(scene, settings, tile, s0, n)
        })
    }

    /// Samples `s0..s0 + n` of every pixel of the tile, eight paths in lockstep; a lane
    /// whose path ends takes the next camera sample.
    /// `render_tile` compiled for AVX2 (the lanes' scalar shading too: VEX code, no FMA
    /// contraction, so the same results).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn render_tile_avx2(&self, scene: &Scene, settings: &RenderSettings, tile: &mut FilmTile, s0: u32, n: u32) {
        self.render_tile(scene, settings, tile, s0, n)
    }

    #[inline(always)]
    fn render_tile(&self, scene: &Scene, settings: &RenderSettings, tile: &mut FilmTile, s0: u32, n: u32) {
        let (x0, y0, w) = (tile.x0, tile.y0, tile.x1 - tile.x0);
        let jobs = (w * (tile.y1 - tile.y0) * n) as usize;
        let job_xys = |j: usize| {
            let j = j as u32;
            let (pix, s) = (j / n, j % n);
            (x0 + pix % w, y0 + pix / w, s0 + s)
        };
        let mut results: Vec<(Vec2, Rgb)> = vec![(Vec2::ZERO, Rgb::BLACK); jobs];
        let proto = IndependentSampler::new(settings.spp, settings.seed);
        let mut lanes: [Lane; LANES] = std::array::from_fn(|_| Lane::new(proto.clone()));
        let mut rays = Rays8::default();
        let mut next = 0usize;
        let mut active = 0u8;
        loop {
            for (l, lane) in lanes.iter_mut().enumerate() {
                if active & (1 << l) != 0 || next >= jobs {
                    continue;
                }
                let (x, y, s) = job_xys(next);
                let (raster, ray) = camera_sample(&scene.camera, &mut lane.sampler, x, y, s);
                lane.start(next, raster);
                set_ray(&mut rays, l, ray.o, ray.d, ray.t_max);
                active |= 1 << l;
                next += 1;
            }
            if active == 0 {
                break;
            }
            let hits = self.bvh.intersect(&rays, active);
            let mut shadow = Rays8::default();
            let mut smask = 0u8;
            let mut pending = [Rgb::BLACK; LANES];
            let mut ends = 0u8;
            for (l, lane) in lanes.iter_mut().enumerate() {
                if active & (1 << l) == 0 {
                    continue;
                }
                let d = Vec3::new(rays.d[0][l], rays.d[1][l], rays.d[2][l]);
                match self.shade(scene, settings, lane, hits.prim[l], hits.b1[l], hits.b2[l], d) {
                    Step::End => ends |= 1 << l,
                    Step::Go { nee, next } => {
                        match nee {
                            Nee::None => {}
                            Nee::Free(c) => lane.l += c,
                            Nee::Shadow { o, d, t_max, c } => {
                                set_ray(&mut shadow, l, o, d, t_max);
                                smask |= 1 << l;
                                pending[l] = c;
                            }
                        }
                        match next {
                            Some((o, d)) => set_ray(&mut rays, l, o, d, f32::INFINITY),
                            None => ends |= 1 << l,
                        }
                    }
                }
            }
            let blocked = self.bvh.occluded(&shadow, smask);
            for (l, lane) in lanes.iter_mut().enumerate() {
                if smask & !blocked & (1 << l) != 0 {
                    lane.l += pending[l];
                }
                if ends & (1 << l) != 0 {
                    results[lane.job] = (lane.raster, lane.l);
                }
            }
            active &= !ends;
        }
        for (raster, l) in results {
            tile.add_sample(raster, l);
        }
    }

    /// One vertex of a lane's path, as one iteration of the scalar tracer's loop: emission
    /// found, the light sample (its shadow ray left to the packet), the BSDF sample and
    /// Russian roulette.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn shade(&self, scene: &Scene, settings: &RenderSettings, lane: &mut Lane, prim: u32, b1: f32, b2: f32, d: Vec3) -> Step {
        lane.depth += 1;
        let Some(tri) = self.tris.get(prim as usize) else { return Step::End };
        let sh = &self.shapes[tri.shape as usize];
        let p = tri.p[0] * (1.0 - b1 - b2) + tri.p[1] * b1 + tri.p[2] * b2;
        let (ng, frame) = match tri.flat {
            Some(f) => f,
            None => {
                // As `Scene::interaction`: interpolated normal, tangent along dp/du.
                let Geometry::Mesh(m) = &*scene.shapes[tri.shape as usize].geometry else { return Step::End };
                let (ng, ns, _uv, dpdu) = m.surface(tri.prim as usize, b1, b2);
                (ng, Frame::from_normal_tangent(ns, dpdu))
            }
        };
        let wo_w = -d;
        if let Some((li, le)) = sh.light {
            let hide = lane.depth == 1 && settings.hide_emitters;
            let le = if ng.dot(wo_w) <= 0.0 { Rgb::BLACK } else { le };
            if !le.is_black() && !hide {
                let w = if lane.prev_specular {
                    1.0
                } else {
                    let pdf_li = area_of(scene, li).map_or(0.0, |a| a.pdf_li(lane.prev_p, p, ng));
                    power_heuristic(1.0, lane.prev_pdf, 1.0, scene.light_pmf(li) * pdf_li)
                };
                lane.l += lane.beta * le * w;
            }
        }
        if !settings.depth_allows(lane.depth + 1) {
            return Step::End;
        }
        let wo = frame.to_local(wo_w);
        // The model of the side wo is on, and whether directions are mirrored to +z for it.
        let side = if wo.z >= 0.0 { Some((sh.front, 1.0f32)) } else { sh.back.map(|b| (b, -1.0f32)) };
        let u_light = lane.sampler.next_1d();
        let u_l2 = lane.sampler.next_2d();
        let nee = self.sample_light(scene, lane, p, ng, &frame, wo, side, u_light, u_l2);
        // The component choice (one lobe: unused).
        let _uc = lane.sampler.next_1d();
        let u = lane.sampler.next_2d();
        let Some((refl, flip)) = side else { return Step::Go { nee, next: None } };
        if wo.z * flip <= 0.0 {
            return Step::Go { nee, next: None };
        }
        let wi_m = warp::square_to_cosine_hemisphere(u);
        let pdf = warp::square_to_cosine_hemisphere_pdf(wi_m);
        if pdf <= 0.0 {
            return Step::Go { nee, next: None };
        }
        let f = refl * INV_PI;
        let wi = Vec3::new(wi_m.x, wi_m.y, wi_m.z * flip);
        if f.is_black() {
            return Step::Go { nee, next: None };
        }
        lane.beta *= f * (wi.z.abs() / pdf);
        lane.prev_specular = false;
        lane.prev_pdf = pdf;
        lane.prev_p = p;
        let dir = frame.to_world(wi);
        let o = offset_ray_origin(p, ng, dir);
        let u_rr = lane.sampler.next_1d();
        if lane.depth >= settings.rr_depth {
            let q = lane.beta.max_component().min(0.95);
            if u_rr >= q {
                return Step::Go { nee, next: None };
            }
            lane.beta /= q;
        }
        if lane.beta.is_black() {
            return Step::Go { nee, next: None };
        }
        Step::Go { nee, next: Some((o, dir)) }
    }

    /// `path::sample_light_mis` for a Lambertian side, times the path throughput, with the
    /// shadow ray returned instead of traced.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn sample_light(&self, scene: &Scene, lane: &Lane, p: Vec3, ng: Vec3, frame: &Frame, wo: Vec3, side: Option<(Rgb, f32)>, u_light: f32, u: Vec2) -> Nee {
        if scene.lights.is_empty() {
            return Nee::None;
        }
        let (li, pmf, _) = scene.light_distribution.sample_discrete(u_light);
        if pmf <= 0.0 {
            return Nee::None;
        }
        let Some(ls) = self.lights.get(li).and_then(|ml| ml.sample_li(scene, p, u)) else { return Nee::None };
        if ls.pdf <= 0.0 || ls.li.is_black() {
            return Nee::None;
        }
        let wi = frame.to_local(ls.wi);
        let Some((refl, flip)) = side else { return Nee::None };
        // Lambert in the side's frame: both directions above it.
        if wo.z * flip <= 0.0 || wi.z * flip <= 0.0 {
            return Nee::None;
        }
        let f = refl * INV_PI;
        if f.is_black() {
            return Nee::None;
        }
        let pdf_light = pmf * ls.pdf;
        let bsdf_pdf = (wi.z * flip).max(0.0) * INV_PI;
        let w = power_heuristic(1.0, pdf_light, 1.0, bsdf_pdf);
        let c = lane.beta * (f * ls.li * (wi.z.abs() * w / pdf_light));
        // `Scene::occluded_at`'s segment.
        let d = ls.p - p;
        let o = offset_ray_origin(p, ng, d);
        let d = ls.p - o;
        let dist = d.length();
        if dist == 0.0 {
            return Nee::Free(c);
        }
        Nee::Shadow { o, d: d / dist, t_max: dist * (1.0 - SHADOW_EPSILON), c }
    }
}

impl MeshLight {
    /// `AreaLight::sample_li` (mesh, constant radiance), step for step.
    #[inline(always)]
    fn sample_li(&self, scene: &Scene, p_ref: Vec3, u: Vec2) -> Option<LightSample> {
        let (t, _, ur) = self.tri_distribution.sample_discrete(u.x);
        let b = warp::square_to_uniform_triangle(Vec2::new(ur, u.y));
        let ([p0, e1, e2], n) = self.tris[t];
        let p = p0 + e1 * b.x + e2 * b.y;
        let n = match n {
            Some(n) => n,
            None => {
                let Light::Area(a) = &scene.lights[self.light as usize] else { return None };
                let Geometry::Mesh(m) = &*a.geometry else { return None };
                m.surface(t, b.x, b.y).0
            }
        };
        if self.pdf_area <= 0.0 {
            return None;
        }
        let d = p - p_ref;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let cos_l = n.dot(-wi);
        if cos_l <= 0.0 {
            return None;
        }
        Some(LightSample { wi, li: self.radiance, pdf: self.pdf_area * dist2 / cos_l, p, n, infinite: false })
    }
}

/// Next-event estimation's outcome at one vertex.
enum Nee {
    None,
    /// Counts without a shadow ray (zero-length segment).
    Free(Rgb),
    /// Counts when the segment is clear.
    Shadow {
        o: Vec3,
        d: Vec3,
        t_max: f32,
        c: Rgb,
    },
}

enum Step {
    End,
    /// The light sample, and the next ray (None: the path ends after the light sample).
    Go {
        nee: Nee,
        next: Option<(Vec3, Vec3)>,
    },
}

/// One path in flight.
struct Lane {
    sampler: IndependentSampler,
    job: usize,
    raster: Vec2,
    l: Rgb,
    beta: Rgb,
    depth: i32,
    prev_specular: bool,
    prev_pdf: f32,
    prev_p: Vec3,
}

impl Lane {
    fn new(sampler: IndependentSampler) -> Lane {
        Lane { sampler, job: 0, raster: Vec2::ZERO, l: Rgb::BLACK, beta: Rgb::WHITE, depth: 0, prev_specular: true, prev_pdf: 0.0, prev_p: Vec3::ZERO }
    }
    fn start(&mut self, job: usize, raster: Vec2) {
        self.job = job;
        self.raster = raster;
        self.l = Rgb::BLACK;
        self.beta = Rgb::WHITE;
        self.depth = 0;
        self.prev_specular = true;
        self.prev_pdf = 0.0;
        self.prev_p = Vec3::ZERO;
    }
}

#[inline(always)]
fn set_ray(r: &mut Rays8, l: usize, o: Vec3, d: Vec3, t_max: f32) {
    for a in 0..3 {
        r.o[a][l] = o[a];
        r.d[a][l] = d[a];
    }
    r.t_max[l] = t_max;
}
