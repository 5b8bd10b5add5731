//! The camera side of the photon methods: a path tracer (NEE and BSDF sampling under the
//! power heuristic, Russian roulette, exactly `path`'s rules) that hands every vertex with a
//! diffuse lobe to the method, which estimates the non-delta scattering there from photons.
//!
//! How path space is split at such a vertex x (depth d from the camera):
//! * light arriving straight from an emitter: NEE plus one BSDF sample, weighted by MIS, as
//!   `path` does; the BSDF-sampled ray is traced only to see whether it meets an emitter;
//! * everything else reaching x through its non-delta lobes: photons (the method's callback);
//! * the delta lobes of x (a plastic's coating): when the BSDF sample picked one, the walk
//!   goes on, so that the next vertex is handled the same way.
//!
//! Vertices with only glossy or only specular lobes are path-traced through.

use crate::bsdf::{Bsdf, LobeFlags, TransportMode};
use crate::geometry::{Ray, SurfaceInteraction};
use crate::integrator::path::sample_light_mis;
use crate::integrator::RenderSettings;
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec3;

/// A camera-path vertex whose BSDF has a diffuse lobe.
pub(crate) struct DiffuseVertex<'a> {
    pub si: &'a SurfaceInteraction,
    pub bsdf: &'a Bsdf,
    /// Toward the camera, local shading frame.
    pub wo: Vec3,
    /// Camera path throughput up to here.
    pub beta: Rgb,
    /// Path segments from the camera to here.
    pub depth: i32,
    /// How many diffuse vertices came before this one on the path.
    pub index: u32,
}

/// Radiance along `camera_ray` from emission and NEE; `at_diffuse` returns the photon part at
/// each diffuse vertex (without the throughput, which the walk applies).
pub(crate) fn camera_walk(
    scene: &Scene,
    camera_ray: &Ray,
    sampler: &mut dyn Sampler,
    settings: &RenderSettings,
    at_diffuse: &mut dyn FnMut(&DiffuseVertex, &mut dyn Sampler) -> Rgb,
) -> Rgb {
    let mut l = Rgb::BLACK;
    let mut beta = Rgb::WHITE;
    let mut ray = *camera_ray;
    let mut depth = 0i32;
    let mut prev_specular = true;
    let mut prev_pdf = 0.0f32;
    let mut prev_p = ray.o;
    let mut eta_scale = 1.0f32;
    let mut diffuse_index = 0u32;
    // The last BSDF sample left a diffuse vertex through a non-delta lobe: photons account for
    // that light, except what comes straight from an emitter.
    let mut terminal = false;
    loop {
        depth += 1;
        let hide = depth == 1 && settings.hide_emitters;
        let Some(si) = scene.intersect(&ray) else {
            if !hide {
                for &ei in &scene.environment_lights {
                    let light = &scene.lights[ei as usize];
                    let le = light.le_escaped(ray.d);
                    if le.is_black() {
                        continue;
                    }
                    let w = if prev_specular { 1.0 } else { power_heuristic(1.0, prev_pdf, 1.0, scene.light_pmf(ei) * light.pdf_li_escaped(ray.d)) };
                    l += beta * le * w;
                }
            }
            break;
        };
        if let Some((li, area)) = scene.area_light(&si) {
            let le = area.l(si.ng, si.uv, si.wo);
            if !le.is_black() && !hide {
                let w = if prev_specular { 1.0 } else { power_heuristic(1.0, prev_pdf, 1.0, scene.light_pmf(li) * area.pdf_li(prev_p, si.p, si.ng)) };
                l += beta * le * w;
            }
        }
        if terminal || !settings.depth_allows(depth + 1) {
            break;
        }
        let bsdf = scene.material(&si).bsdf(si.uv);
        let wo = si.to_local(si.wo);
        let flags = bsdf.flags();
        let u_light = sampler.next_1d();
        let u_l2 = sampler.next_2d();
        if flags.has_non_specular() {
            l += beta * sample_light_mis(scene, si.p, si.ng, &si.shading, wo, &bsdf, u_light, u_l2, (1.0, 1.0), si.time);
        }
        let diffuse = flags.intersects(LobeFlags::DIFFUSE);
        if diffuse {
            let v = DiffuseVertex { si: &si, bsdf: &bsdf, wo, beta, depth, index: diffuse_index };
            l += beta * at_diffuse(&v, sampler);
            diffuse_index += 1;
        }
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance) else { break };
        if bs.pdf <= 0.0 || bs.f.is_black() {
            break;
        }
        beta *= bs.weight();
        if bs.lobe.contains(LobeFlags::TRANSMISSION) {
            eta_scale *= bs.eta * bs.eta;
        }
        prev_specular = bs.lobe.is_specular();
        prev_pdf = bs.pdf;
        prev_p = si.p;
        terminal = diffuse && !prev_specular;
        ray = si.spawn_ray(si.to_world(bs.wi));
        let u_rr = sampler.next_1d();
        if depth >= settings.rr_depth && !terminal {
            let q = (beta * eta_scale).max_component().min(0.95);
            if u_rr >= q {
                break;
            }
            beta /= q;
        }
        if beta.is_black() {
            break;
        }
    }
    l
}
