//! Whitted ray tracing (1980): light path class L(D|G)S*E. At each hit the local model
//! (`local.rs`: every light a point, shadow rays) for the non-specular part of the BSDF,
//! then recursion through every ideal specular branch (mirror reflection, and reflection and
//! refraction of dielectrics weighted by their Fresnel terms — both branches are traced, not
//! sampled), a pass-through branch for masks. Deterministic apart from the pixel positions.
//!
//! `max_depth` has Mitsuba's meaning: a path of k segments from the camera counts only if
//! k <= max_depth, the shadow ray of the local model being the last segment; so max_depth 2
//! is the ray-cast local model and `whitted` coincides with `path` wherever the path classes
//! do (point lights, mirrors, glass). Unbounded depth is capped at [`UNBOUNDED_DEPTH`]
//! segments, and branches whose weight falls below [`MIN_WEIGHT`] are dropped, since the
//! branching grows as 2^depth inside glass.

use super::local::LocalLights;
use super::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::bsdf::{fresnel, Bsdf, BsdfModel, TransportMode};
use crate::error::Result;
use crate::film::Film;
use crate::geometry::Ray;
use crate::lpe::aov::LayerSample;
use crate::lpe::{Event, Tracker};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// Depth used when `max_depth` is -1.
pub const UNBOUNDED_DEPTH: i32 = 24;
/// Branches carrying less than this (largest channel of the path weight) are not traced.
pub const MIN_WEIGHT: f32 = 1e-4;

#[derive(Clone, Copy, Debug, Default)]
pub struct Whitted;

impl Integrator for Whitted {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        let est = WhittedEstimator { lights: LocalLights::new(scene) };
        render_pixels(scene, settings, progress, &est)
    }
}

pub(crate) struct WhittedEstimator {
    pub lights: LocalLights,
}

#[inline]
fn flip(w: Vec3) -> Vec3 {
    Vec3::new(w.x, w.y, -w.z)
}

/// The ideal specular branches of one model for `wo` (local, on the model's +z side):
/// (direction, weight = f |cos| without any sampling probability).
fn model_branches(model: &BsdfModel, wo: Vec3, out: &mut Vec<(Vec3, Rgb)>) {
    let mode = TransportMode::Radiance;
    let mut push = |s: Option<crate::bsdf::BsdfSample>, scale: f32| {
        if let Some(s) = s {
            if s.lobe.is_specular() && scale > 0.0 {
                out.push((s.wi, s.weight() * scale));
            }
        }
    };
    // The models choose a branch by comparing `uc` with its probability: uc = 0 picks the
    // reflection, uc = 1 the transmission; the probability then multiplies back in.
    match model {
        BsdfModel::SmoothConductor(m) => push(m.sample(wo, 0.5, Vec2::ZERO, mode), 1.0),
        BsdfModel::SmoothDielectric(m) => {
            let f = fresnel::dielectric(wo.z, m.eta).0;
            push(m.sample(wo, 0.0, Vec2::ZERO, mode), f);
            push(m.sample(wo, 1.0, Vec2::ZERO, mode), 1.0 - f);
        }
        BsdfModel::ThinDielectric(m) => {
            let r = m.reflectance(wo.z);
            push(m.sample(wo, 0.0, Vec2::ZERO, mode), r);
            push(m.sample(wo, 1.0, Vec2::ZERO, mode), 1.0 - r);
        }
        BsdfModel::ThinGlass(m) => {
            let r = m.reflection_probability(wo.z);
            push(m.sample(wo, 0.0, Vec2::ZERO, mode), r);
            push(m.sample(wo, 1.0, Vec2::ZERO, mode), 1.0 - r);
        }
        BsdfModel::SmoothPlastic(m) if wo.z > 0.0 => {
            let f = fresnel::dielectric(wo.z, m.eta).0;
            out.push((fresnel::reflect_z(wo), m.specular_reflectance * f));
        }
        _ => {}
    }
}

/// Specular branches of a BSDF (two-sided and mask wrappers included), local directions.
pub(crate) fn specular_branches(bsdf: &Bsdf, wo: Vec3) -> Vec<(Vec3, Rgb)> {
    let mut out = Vec::new();
    if bsdf.opacity < 1.0 {
        out.push((-wo, Rgb::splat(1.0 - bsdf.opacity)));
    }
    if bsdf.opacity <= 0.0 {
        return out;
    }
    let start = out.len();
    if wo.z >= 0.0 || bsdf.front.handles_back_side() {
        model_branches(&bsdf.front, wo, &mut out);
    } else if let Some(b) = &bsdf.back {
        model_branches(b, flip(wo), &mut out);
        for br in &mut out[start..] {
            br.0 = flip(br.0);
        }
    }
    for br in &mut out[start..] {
        br.1 *= bsdf.opacity;
    }
    out
}

impl WhittedEstimator {
    /// Radiance along `ray` at `depth` segments; `throughput` is the product of the branch
    /// weights so far, with which each contribution also goes to the layers its events
    /// (`events`: the path so far) match.
    #[allow(clippy::too_many_arguments)]
    fn trace(&self, scene: &Scene, ray: &Ray, depth: i32, throughput: Rgb, settings: &RenderSettings, events: &Tracker, layers: &mut LayerSample) -> Rgb {
        let aovs = settings.aovs();
        let hide = depth == 1 && settings.hide_emitters;
        let Some(si) = scene.intersect(ray) else {
            let mut l = Rgb::BLACK;
            if !hide {
                for &ei in &scene.environment_lights {
                    let le = scene.lights[ei as usize].le_escaped(ray.d);
                    l += le;
                    layers.add(events.ends(Event::BACKGROUND), throughput * le);
                }
            }
            return l;
        };
        let mut l = Rgb::BLACK;
        if let Some((_, area)) = scene.area_light(&si) {
            if !hide {
                let le = area.l(si.ng, si.uv, si.wo);
                l += le;
                layers.add(events.ends(aovs.light_event(Some(si.shape))), throughput * le);
            }
        }
        let max = if settings.max_depth < 0 { UNBOUNDED_DEPTH } else { settings.max_depth };
        if depth + 1 > max {
            return l;
        }
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        let flags = bsdf.flags();
        if flags.has_non_specular() {
            if aovs.is_empty() {
                l += self.lights.shade(scene, si.p, si.ng, &si.shading, wo, &bsdf, true, si.time);
            } else {
                self.lights.shade_each(scene, si.p, si.ng, &si.shading, wo, &bsdf, true, si.time, |i, c, through| {
                    l += c;
                    let here = aovs.scatter_event(si.shape, flags, None, through);
                    layers.add(events.ends2(here, aovs.emitter_event(&scene.lights[i])), throughput * c);
                });
            }
        }
        let null_first = bsdf.opacity < 1.0;
        for (k, (wi, w)) in specular_branches(&bsdf, wo).into_iter().enumerate() {
            let t = throughput * w;
            if t.max_component() < MIN_WEIGHT {
                continue;
            }
            let mut r = si.spawn_ray(si.to_world(wi));
            r.time = ray.time;
            let mut next = *events;
            // The mask's pass-through branch (first) is no vertex of the path.
            if !(aovs.is_empty() || null_first && k == 0) {
                next.push(Event::scatter(flags, true, wi.z * wo.z < 0.0, aovs.shape_labels(si.shape)));
            }
            l += w * self.trace(scene, &r, depth + 1, t, settings, &next, layers);
        }
        l
    }
}

impl PixelEstimator for WhittedEstimator {
    fn li(&self, scene: &Scene, ray: &Ray, _sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        self.trace(scene, ray, 1, Rgb::WHITE, settings, &Tracker::camera(settings.aovs()), &mut LayerSample::default())
    }
    fn li_layers(&self, scene: &Scene, ray: &Ray, _sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        self.trace(scene, ray, 1, Rgb::WHITE, settings, &Tracker::camera(settings.aovs()), layers)
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}
