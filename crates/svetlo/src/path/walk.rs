//! Random walks: camera subpaths (radiance transport) and light subpaths (importance
//! transport: non-symmetric refraction and the shading-normal correction).
//!
//! Sampler dimensions, in order: light subpath: light choice (1), origin (2), direction (2);
//! then per bounce: lobe (1), direction (2), Russian roulette (1).

use super::vertex::{infinite_light_density, shading_correction};
use super::{Event, PathConfig, Vertex};
use crate::bsdf::{LobeFlags, TransportMode};
use crate::geometry::Ray;
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
pub fn camera_subpath(scene: &Scene, cfg: &PathConfig, ray: &Ray, raster: Vec2, sampler: &mut dyn Sampler, path: &mut Vec<Vertex>) {
    path.clear();
    if cfg.max_camera_vertices == 0 {
        return;
    }
    let mut cam = Vertex::camera(lens_point(scene, cfg, ray), raster, Rgb::WHITE);
    cam.time = ray.time;
    path.push(cam);
    let (_, pdf_dir) = cfg.lens.map_or((0.0, 0.0), |l| l.pdf_we(ray));
    random_walk(scene, *ray, sampler, Rgb::WHITE, pdf_dir, cfg.max_camera_vertices, cfg.rr_depth, TransportMode::Radiance, path);
}

/// A light subpath: a light chosen by the scene's light selection, a ray from it by
/// `Light::sample_le`, then the walk. Replaces the contents of `path` (empty if the scene
/// has no light or max_depth leaves no room).
pub fn light_subpath(scene: &Scene, cfg: &PathConfig, time: f32, sampler: &mut dyn Sampler, path: &mut Vec<Vertex>) {
    path.clear();
    let u_light = sampler.next_1d();
    let u_pos = sampler.next_2d();
    let u_dir = sampler.next_2d();
    if cfg.max_light_vertices == 0 || scene.lights.is_empty() {
        return;
    }
    let (li, pmf, _) = scene.light_distribution.sample_discrete(u_light);
    if pmf <= 0.0 {
        return;
    }
    let light = &scene.lights[li];
    let Some(es) = light.sample_le(u_pos, u_dir, time, &scene.bounds) else { return };
    if es.pdf_pos <= 0.0 || es.pdf_dir <= 0.0 || es.le.is_black() {
        return;
    }
    let d = es.ray.d;
    let infinite = light.is_infinite();
    if infinite {
        path.push(Vertex::light_infinite(Some(li as u32), es.ray.o, -d, Rgb::splat(1.0 / (pmf * es.pdf_pos)), infinite_light_density(scene, d)));
    } else {
        let n = if matches!(light, crate::light::Light::Area(_)) { es.n } else { Vec3::ZERO };
        path.push(Vertex::light_point(li as u32, es.ray.o, n, es.le, Rgb::splat(1.0 / (pmf * es.pdf_pos)), pmf * es.pdf_pos));
    }
    if let Some(v) = path.last_mut() {
        v.time = time;
    }
    let beta = es.le * (es.n.dot(d).abs() / (pmf * es.pdf_pos * es.pdf_dir));
    random_walk(scene, es.ray, sampler, beta, es.pdf_dir, cfg.max_light_vertices, cfg.rr_depth, TransportMode::Importance, path);
    // From infinity the first hit's density is the entry disk's, projected on the surface.
    if infinite && path.len() > 1 {
        let cos = if path[1].on_surface() { path[1].ng.dot(d).abs() } else { 1.0 };
        path[1].pdf_fwd = es.pdf_pos * cos;
    }
}

/// Extend `path` (whose last vertex is where `ray` starts) by tracing `ray` and sampling
/// BSDFs until `max_vertices`, Russian roulette, an absorbed or escaped ray. `pdf_dir` is
/// the solid-angle density with which `ray`'s direction was chosen.
#[allow(clippy::too_many_arguments)]
pub fn random_walk(
    scene: &Scene,
    mut ray: Ray,
    sampler: &mut dyn Sampler,
    mut beta: Rgb,
    pdf_dir: f32,
    max_vertices: usize,
    rr_depth: i32,
    mode: TransportMode,
    path: &mut Vec<Vertex>,
) {
    let mut pdf_fwd = pdf_dir;
    // Throughput of the scattering alone (what Russian roulette looks at), and the radiance
    // scaling of refraction it undoes.
    let mut scatter = Rgb::WHITE;
    let mut eta_scale = 1.0f32;
    while path.len() < max_vertices {
        let Some(si) = scene.intersect(&ray) else {
            if mode == TransportMode::Radiance && !scene.environment_lights.is_empty() {
                let prev = path.last().expect("a walk starts from a vertex");
                let v = Vertex::light_infinite(None, prev.p + ray.d, ray.d, beta, pdf_fwd);
                path.push(v);
            }
            break;
        };
        let mut v = Vertex::surface(scene, &si, beta);
        let prev = path.last().expect("a walk starts from a vertex");
        v.pdf_fwd = prev.convert_density(pdf_fwd, &v);
        path.push(v);
        if path.len() >= max_vertices {
            break;
        }
        let segments = (path.len() - 1) as i32;
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        let u_rr = sampler.next_1d();
        let v = path.last().expect("just pushed");
        let bsdf = v.bsdf.as_ref().expect("surface vertices have a BSDF");
        let wo = v.shading.to_local(v.wo);
        let Some(bs) = bsdf.sample(wo, uc, u, mode) else { break };
        if bs.pdf <= 0.0 || bs.f.is_black() {
            break;
        }
        let wi_world = v.shading.to_world(bs.wi);
        let w = bs.weight() * shading_correction(v.ng, v.shading.n, v.wo, wi_world, mode);
        let mut pdf_rev = bsdf.pdf(bs.wi, wo, flip(mode));
        let mut next = Ray::new(crate::geometry::ray::offset_ray_origin(v.p, v.ng, wi_world), wi_world);
        next.time = ray.time;
        ray = next;
        beta *= w;
        scatter *= w;
        if mode == TransportMode::Radiance && bs.lobe.contains(LobeFlags::TRANSMISSION) {
            eta_scale *= bs.eta * bs.eta;
        }
        pdf_fwd = bs.pdf;
        let v = path.last_mut().expect("just pushed");
        v.event = Event::from_lobe(bs.lobe);
        if bs.lobe.is_specular() {
            v.delta = true;
            pdf_fwd = 0.0;
            pdf_rev = 0.0;
        }
        let n = path.len();
        let rev = path[n - 1].convert_density(pdf_rev, &path[n - 2]);
        path[n - 2].pdf_rev = rev;
        if segments >= rr_depth {
            let q = (scatter * eta_scale).max_component().min(0.95);
            if u_rr >= q {
                break;
            }
            beta /= q;
            scatter /= q;
        }
        if beta.is_black() {
            break;
        }
    }
}

#[inline]
fn flip(m: TransportMode) -> TransportMode {
    match m {
        TransportMode::Radiance => TransportMode::Importance,
        TransportMode::Importance => TransportMode::Radiance,
    }
}
