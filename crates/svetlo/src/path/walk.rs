//! Random walks: camera subpaths (radiance transport) and light subpaths (importance
//! transport: non-symmetric refraction and the shading-normal correction).
//!
//! Sampler dimensions, in order: light subpath: light choice (1), origin (2), direction (2);
//! then per bounce: lobe (1), direction (2), Russian roulette (1).

use super::vertex::{infinite_light_density, lambertian_sample, shading_correction};
use super::{Event, PathConfig, Vertex};
use crate::bsdf::{LobeFlags, TransportMode};
use crate::geometry::{Ray, SurfaceInteraction};
use crate::light::EmissionSample;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// The lens point a camera ray leaves from (its origin is on the near plane).
fn lens_point(scene: &Scene, cfg: &PathConfig, ray: &Ray) -> Vec3 {
    let m = cfg.lens.map_or_else(|| scene.camera.to_world.inverse(), |l| l.to_camera());
    let o = m.transform_point3(ray.o);
    let d = m.transform_vector3(ray.d);
    let o_lens = if d.z != 0.0 { o - d * (o.z / d.z) } else { o };
    scene.camera.to_world.transform_point3(o_lens)
}

/// A camera subpath for the camera ray `ray` through film position `raster`: the camera
/// vertex, then what the walk finds (a vertex at infinity last if the ray escapes into
/// environment light). Replaces the contents of `path`.
pub fn camera_subpath<S: Sampler + ?Sized>(scene: &Scene, cfg: &PathConfig, ray: &Ray, raster: Vec2, sampler: &mut S, path: &mut Vec<Vertex>) {
    camera_subpath_traced(scene, cfg, ray, raster, sampler, path, &|r: &Ray| scene.intersect(r));
}

/// [`camera_subpath`] with its rays traced by `trace`, which answers as `Scene::intersect`.
pub(crate) fn camera_subpath_traced<S: Sampler + ?Sized, T: Fn(&Ray) -> Option<SurfaceInteraction>>(
    scene: &Scene,
    cfg: &PathConfig,
    ray: &Ray,
    raster: Vec2,
    sampler: &mut S,
    path: &mut Vec<Vertex>,
    trace: &T,
) {
    path.clear();
    if cfg.max_camera_vertices == 0 {
        return;
    }
    let mut cam = Vertex::camera(lens_point(scene, cfg, ray), raster, Rgb::WHITE);
    cam.time = ray.time;
    path.push(cam);
    let (_, pdf_dir) = cfg.lens.map_or((0.0, 0.0), |l| l.pdf_we(ray));
    let mut w = Walk::new(*ray, Rgb::WHITE, pdf_dir, cfg.max_camera_vertices, cfg.rr_depth, TransportMode::Radiance);
    if w.goes_on(path) {
        while w.step(scene, trace(w.ray()).as_ref(), sampler, path) {}
    }
}

/// A light subpath: a light chosen by the scene's light selection, a ray from it by
/// `Light::sample_le`, then the walk. Replaces the contents of `path` (empty if the scene
/// has no light or max_depth leaves no room).
pub fn light_subpath<S: Sampler + ?Sized>(scene: &Scene, cfg: &PathConfig, time: f32, sampler: &mut S, path: &mut Vec<Vertex>) {
    light_subpath_traced(scene, cfg, time, sampler, path, &|r: &Ray| scene.intersect(r));
}

/// [`light_subpath`] with its rays traced by `trace`, which answers as `Scene::intersect`.
pub(crate) fn light_subpath_traced<S: Sampler + ?Sized, T: Fn(&Ray) -> Option<SurfaceInteraction>>(
    scene: &Scene,
    cfg: &PathConfig,
    time: f32,
    sampler: &mut S,
    path: &mut Vec<Vertex>,
    trace: &T,
) {
    let mut lw = None;
    light_walk(scene, cfg, time, sampler, path, &mut lw);
    let Some(mut lw) = lw else { return };
    if lw.walk.goes_on(path) {
        while lw.walk.step(scene, trace(lw.walk.ray()).as_ref(), sampler, path) {}
    }
    lw.finish(path);
}

/// A light subpath between its emitter vertex and its end: the walk, and what its first
/// hit's density needs once the walk is done (see [`light_walk`]).
pub(crate) struct LightWalk {
    pub walk: Walk,
    /// From an infinite light: the direction and the entry disk's positional density.
    infinite: Option<(Vec3, f32)>,
}

impl LightWalk {
    /// After the walk: from infinity the first hit's density is the entry disk's, projected
    /// on the surface.
    #[inline]
    pub fn finish(&self, path: &mut [Vertex]) {
        if let (Some((d, pdf_pos)), true) = (self.infinite, path.len() > 1) {
            let cos = if path[1].on_surface() { path[1].ng.dot(d).abs() } else { 1.0 };
            path[1].pdf_fwd = pdf_pos * cos;
        }
    }
}

/// [`light_subpath`] up to its walk: the emitter vertex pushed into `path` (cleared first)
/// and the walk to run from it written to `out` (None: the path ends there, or is empty), so
/// that walks of several paths can trace their rays together. Same sampler dimensions as
/// `light_subpath`. (Written in place: a returned walk was copied into the caller's slot
/// in wider words than its fields had just been stored with, a store-forwarding stall.)
pub(crate) fn light_walk<S: Sampler + ?Sized>(
    scene: &Scene,
    cfg: &PathConfig,
    time: f32,
    sampler: &mut S,
    path: &mut Vec<Vertex>,
    out: &mut Option<LightWalk>,
) {
    *out = None;
    path.clear();
    let (u_light, u_pos, u_dir) = light_walk_draws(sampler);
    let Some((li, pmf)) = light_walk_light(scene, cfg, u_light) else { return };
    let Some(es) = scene.lights[li].sample_le(u_pos, u_dir, time, &scene.bounds) else { return };
    light_walk_from(scene, cfg, time, li, pmf, &es, path, out);
}

/// [`light_walk`]'s draws: the light choice, the origin, the direction.
#[inline(always)]
pub(crate) fn light_walk_draws<S: Sampler + ?Sized>(sampler: &mut S) -> (f32, Vec2, Vec2) {
    let u_light = sampler.next_1d();
    let u_pos = sampler.next_2d();
    let u_dir = sampler.next_2d();
    (u_light, u_pos, u_dir)
}

/// [`light_walk`]'s light (index, probability) for its draw `u_light`; None: no path.
#[inline(always)]
pub(crate) fn light_walk_light(scene: &Scene, cfg: &PathConfig, u_light: f32) -> Option<(usize, f32)> {
    if cfg.max_light_vertices == 0 || scene.lights.is_empty() {
        return None;
    }
    let (li, pmf, _) = scene.light_distribution.sample_discrete(u_light);
    if pmf <= 0.0 {
        return None;
    }
    Some((li, pmf))
}

/// [`light_walk`] after its emission sample `es` of light `li` (chosen with probability
/// `pmf`), with `path` cleared and `out` None.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn light_walk_from(
    scene: &Scene,
    cfg: &PathConfig,
    time: f32,
    li: usize,
    pmf: f32,
    es: &EmissionSample,
    path: &mut Vec<Vertex>,
    out: &mut Option<LightWalk>,
) {
    if es.pdf_pos <= 0.0 || es.pdf_dir <= 0.0 || es.le.is_black() {
        return;
    }
    let light = &scene.lights[li];
    let d = es.ray.d;
    let infinite = light.is_infinite();
    if infinite {
        path.push(Vertex::light_infinite(Some(li as u32), es.ray.o, -d, Rgb::splat(1.0 / (pmf * es.pdf_pos)), infinite_light_density(scene, d)));
    } else {
        let n = if matches!(light, crate::light::Light::Area(_)) { es.n } else { Vec3::ZERO };
        Vertex::push_light_point(path, li as u32, es.ray.o, n, es.le, Rgb::splat(1.0 / (pmf * es.pdf_pos)), pmf * es.pdf_pos);
    }
    if let Some(v) = path.last_mut() {
        v.time = time;
    }
    let beta = es.le * (es.n.dot(d).abs() / (pmf * es.pdf_pos * es.pdf_dir));
    let walk = Walk::new(es.ray, beta, es.pdf_dir, cfg.max_light_vertices, cfg.rr_depth, TransportMode::Importance);
    *out = Some(LightWalk { walk, infinite: infinite.then_some((d, es.pdf_pos)) });
}

/// Extend `path` (whose last vertex is where `ray` starts) by tracing `ray` and sampling
/// BSDFs until `max_vertices`, Russian roulette, an absorbed or escaped ray. `pdf_dir` is
/// the solid-angle density with which `ray`'s direction was chosen.
#[allow(clippy::too_many_arguments)]
pub fn random_walk<S: Sampler + ?Sized>(
    scene: &Scene,
    ray: Ray,
    sampler: &mut S,
    beta: Rgb,
    pdf_dir: f32,
    max_vertices: usize,
    rr_depth: i32,
    mode: TransportMode,
    path: &mut Vec<Vertex>,
) {
    let mut w = Walk::new(ray, beta, pdf_dir, max_vertices, rr_depth, mode);
    if w.goes_on(path) {
        while w.step(scene, scene.intersect(w.ray()).as_ref(), sampler, path) {}
    }
}

/// A random walk between two of its rays: [`random_walk`] with the tracing left to the
/// caller, so that the rays of several walks can be traced as one packet. Each walk draws
/// from its own sampler in `random_walk`'s order, whatever the others do.
#[derive(Clone)]
pub(crate) struct Walk {
    /// The ray to trace next.
    pub(super) ray: Ray,
    pub(super) beta: Rgb,
    /// Solid-angle density of `ray`'s direction (0 after a specular choice).
    pub(super) pdf_fwd: f32,
    /// Throughput of the scattering alone (what Russian roulette looks at), and the
    /// radiance scaling of refraction it undoes.
    pub(super) scatter: Rgb,
    pub(super) eta_scale: f32,
    pub(super) max_vertices: usize,
    pub(super) rr_depth: i32,
    pub(super) mode: TransportMode,
}

impl Walk {
    #[inline]
    pub fn new(ray: Ray, beta: Rgb, pdf_dir: f32, max_vertices: usize, rr_depth: i32, mode: TransportMode) -> Walk {
        Walk { ray, beta, pdf_fwd: pdf_dir, scatter: Rgb::WHITE, eta_scale: 1.0, max_vertices, rr_depth, mode }
    }

    /// The ray to trace next.
    #[inline]
    pub fn ray(&self) -> &Ray {
        &self.ray
    }

    /// Whether `path` has room for the vertex the next ray finds (before the first step).
    #[inline]
    pub fn goes_on(&self, path: &[Vertex]) -> bool {
        path.len() < self.max_vertices
    }

    /// One bounce: the vertex `hit` (what `ray()` met; None: it escaped) appended to `path`,
    /// and the next direction sampled there. Returns whether the walk goes on, with `ray()`
    /// the next ray to trace. The hit comes by reference: moved in by value, its copy read
    /// 8-byte words that the record's 4-byte stores had just written, a store-forwarding
    /// stall per bounce (about 5 % of light tracing's CPU).
    #[inline(always)]
    pub fn step<S: Sampler + ?Sized>(&mut self, scene: &Scene, hit: Option<&SurfaceInteraction>, sampler: &mut S, path: &mut Vec<Vertex>) -> bool {
        if !self.arrive(scene, hit, path) {
            return false;
        }
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        let u_rr = sampler.next_1d();
        self.scatter(uc, u, u_rr, path)
    }

    /// The first half of [`Self::step`]: the vertex `hit` appended to `path`. Returns whether
    /// the walk samples a direction there ([`Self::scatter`], with the vertex's three draws).
    #[inline(always)]
    pub fn arrive(&mut self, scene: &Scene, hit: Option<&SurfaceInteraction>, path: &mut Vec<Vertex>) -> bool {
        let Some(si) = hit else {
            if self.mode == TransportMode::Radiance && !scene.environment_lights.is_empty() {
                let prev = path.last().expect("a walk starts from a vertex");
                let v = Vertex::light_infinite(None, prev.p + self.ray.d, self.ray.d, self.beta, self.pdf_fwd);
                path.push(v);
            }
            return false;
        };
        let prev = path.last().expect("a walk starts from a vertex");
        let pdf_fwd = prev.convert_density_to_point(self.pdf_fwd, si.p, si.ng);
        Vertex::push_surface(path, scene, si, self.beta, pdf_fwd);
        path.len() < self.max_vertices
    }

    /// [`Self::arrive`] with the vertex's density in area measure left out (0): None where
    /// the ray escaped, else whether the walk samples a direction there. For light tracing's
    /// lockstep walks, which read no densities (it weighs no strategy against another).
    #[inline(always)]
    pub fn arrive_unsettled(&mut self, scene: &Scene, hit: Option<&SurfaceInteraction>, path: &mut Vec<Vertex>) -> Option<bool> {
        let Some(si) = hit else {
            self.arrive(scene, None, path);
            return None;
        };
        Vertex::push_surface(path, scene, si, self.beta, 0.0);
        Some(path.len() < self.max_vertices)
    }

    /// [`Self::arrive_unsettled`] at a hit whose vertex `push` writes (given the ray traced
    /// and the walk's throughput, as `push_surface` takes them): whether the walk samples a
    /// direction there.
    #[inline(always)]
    pub fn arrive_pushed(&self, path: &mut Vec<Vertex>, push: impl FnOnce(&Ray, Rgb, &mut Vec<Vertex>)) -> bool {
        push(&self.ray, self.beta, path);
        path.len() < self.max_vertices
    }

    /// The second half of [`Self::step`]: the direction sampled at the vertex just arrived
    /// at, with its draws `uc` (lobe), `u` (direction) and `u_rr` (Russian roulette).
    #[inline(always)]
    pub fn scatter(&mut self, uc: f32, u: Vec2, u_rr: f32, path: &mut [Vertex]) -> bool {
        let mode = self.mode;
        let segments = (path.len() - 1) as i32;
        let v = path.last().expect("just pushed");
        let bsdf = v.bsdf.as_ref().expect("surface vertices have a BSDF");
        // The vertex's wo is the hit's, -d of the ray traced (`Vertex::at_surface`), taken
        // from the ray: the vertex was just stored, and its wo read back in 8-byte words that
        // span two of its stores, a store-forwarding stall per bounce.
        let wo = -self.ray.d;
        debug_assert_eq!(wo.to_array().map(f32::to_bits), v.wo.to_array().map(f32::to_bits), "the hit of another ray");
        let (bs, mut pdf_rev) = match lambertian_sample(bsdf, &v.shading, wo, uc, u) {
            Some(Some(s)) => s,
            Some(None) => return false,
            None => match sample_generic(bsdf, &v.shading, wo, uc, u, mode) {
                Some(s) => s,
                None => return false,
            },
        };
        if bs.pdf <= 0.0 || bs.f.is_black() {
            return false;
        }
        let wi_world = v.shading.to_world(bs.wi);
        let w = bs.weight() * shading_correction(v.ng, v.shading.n, wo, wi_world, mode);
        let mut next = Ray::new(crate::geometry::ray::offset_ray_origin(v.p, v.ng, wi_world), wi_world);
        next.time = self.ray.time;
        self.ray = next;
        self.beta *= w;
        self.scatter *= w;
        if mode == TransportMode::Radiance && bs.lobe.contains(LobeFlags::TRANSMISSION) {
            self.eta_scale *= bs.eta * bs.eta;
        }
        self.pdf_fwd = bs.pdf;
        let v = path.last_mut().expect("just pushed");
        v.event = Event::from_lobe(bs.lobe);
        if bs.lobe.is_specular() {
            v.delta = true;
            self.pdf_fwd = 0.0;
            pdf_rev = 0.0;
        }
        let n = path.len();
        let rev = path[n - 1].convert_density(pdf_rev, &path[n - 2]);
        path[n - 2].pdf_rev = rev;
        if segments >= self.rr_depth {
            let q = (self.scatter * self.eta_scale).max_component().min(0.95);
            if u_rr >= q {
                return false;
            }
            self.beta /= q;
            self.scatter /= q;
        }
        !self.beta.is_black() && path.len() < self.max_vertices
    }
}

#[inline]
fn flip(m: TransportMode) -> TransportMode {
    match m {
        TransportMode::Radiance => TransportMode::Importance,
        TransportMode::Importance => TransportMode::Radiance,
    }
}

/// [`Walk::scatter`]'s sample where [`lambertian_sample`] does not take the vertex: the
/// BSDF's sample in the local frame and its reverse density (unused when the walk ends
/// there). Out of line: the BSDF calls' inline Lambertian case is dead here.
#[inline(never)]
fn sample_generic(
    bsdf: &crate::bsdf::Bsdf,
    frame: &crate::math::Frame,
    wo: Vec3,
    uc: f32,
    u: Vec2,
    mode: TransportMode,
) -> Option<(crate::bsdf::BsdfSample, f32)> {
    let wo = frame.to_local(wo);
    let bs = bsdf.sample(wo, uc, u, mode)?;
    let pdf_rev = bsdf.pdf(bs.wi, wo, flip(mode));
    Some((bs, pdf_rev))
}
