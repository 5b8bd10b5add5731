//! Distributed ray tracing (Cook, Porter and Carpenter 1984): light path class
//! L D? (G|S)* E. Every integral of the image is sampled by distributing rays rather than
//! branching: pixel area (anti-aliasing, stratified), lens (depth of field, the thin-lens
//! camera), shutter time (motion blur: rays carry their time to every bounce and shadow
//! ray), area lights (soft shadows), and glossy reflection and refraction (BSDF sampling).
//!
//! At each hit the light reflected directly from the emitters is estimated with one light
//! sample and one BSDF sample combined by the power heuristic (as `path` does); the path
//! then continues only through glossy and specular scattering (Cook's method has no diffuse
//! interreflection): it continues when the BSDF sample is a delta lobe, or when the
//! material has no diffuse lobe at all. A material mixing a diffuse and a glossy lobe
//! (plastic, Phong, Ward, ...) ends the path after its direct light, since its sampled
//! weight cannot be split between the lobes; its delta lobes (smooth plastic's coating)
//! still reflect. So with max_depth 2 it is direct illumination and equals `path`.
//!
//! Pixel samples are stratified: when the settings ask for the independent sampler (the
//! default), the Owen-scrambled Sobol sampler is used instead.

use super::path::sample_light_mis;
use super::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::bsdf::{LobeFlags, TransportMode};
use crate::error::Result;
use crate::film::Film;
use crate::geometry::Ray;
use crate::sampling::{power_heuristic, Sampler, SamplerKind};
use crate::scene::Scene;
use crate::spectrum::Rgb;

#[derive(Clone, Copy, Debug, Default)]
pub struct Distributed;

impl Integrator for Distributed {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        let mut s = settings.clone();
        if s.sampler == SamplerKind::Independent {
            s.sampler = SamplerKind::Sobol;
        }
        render_pixels(scene, &s, progress, self)
    }
}

impl PixelEstimator for Distributed {
    fn li(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        let mut l = Rgb::BLACK;
        let mut beta = Rgb::WHITE;
        let mut ray = *camera_ray;
        let mut depth = 0i32;
        // The previous vertex, for MIS on emitters found by BSDF sampling.
        let mut prev_specular = true;
        let mut prev_pdf = 0.0f32;
        let mut prev_p = ray.o;
        // Set after a diffuse BSDF sample: only emission is gathered at the next hit.
        let mut last = false;
        loop {
            depth += 1;
            let hide = depth == 1 && settings.hide_emitters;
            let Some(si) = scene.intersect(&ray) else {
                if !hide {
                    for &ei in &scene.environment_lights {
                        let light = &scene.lights[ei as usize];
                        let le = light.le_escaped(ray.d);
                        if !le.is_black() {
                            let w = if prev_specular { 1.0 } else { power_heuristic(1.0, prev_pdf, 1.0, scene.light_pmf(ei) * light.pdf_li_escaped(ray.d)) };
                            l += beta * le * w;
                        }
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
            if last || !settings.depth_allows(depth + 1) {
                break;
            }
            let bsdf = scene.material(&si).bsdf(si.uv);
            let wo = si.to_local(si.wo);
            let u_light = sampler.next_1d();
            let u_l2 = sampler.next_2d();
            if bsdf.flags().has_non_specular() {
                l += beta * sample_light_mis(scene, si.p, si.ng, &si.shading, wo, &bsdf, u_light, u_l2, (1.0, 1.0), si.time);
            }
            let uc = sampler.next_1d();
            let u = sampler.next_2d();
            let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance) else { break };
            if bs.pdf <= 0.0 || bs.f.is_black() {
                break;
            }
            beta *= bs.weight();
            prev_specular = bs.lobe.is_specular();
            prev_pdf = bs.pdf;
            prev_p = si.p;
            // Otherwise the bounce only completes the MIS estimate of direct light.
            let continues = bs.lobe.is_specular() || !bsdf.flags().intersects(LobeFlags::DIFFUSE);
            last = !continues;
            let time = ray.time;
            ray = si.spawn_ray(si.to_world(bs.wi));
            ray.time = time;
            let u_rr = sampler.next_1d();
            if depth >= settings.rr_depth && !last {
                let q = beta.max_component().min(0.95);
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
}
