//! Direct illumination (Mitsuba's `direct`): emitters seen by the camera, plus light arriving
//! straight from emitters at the first surface, by `emitter_samples` light samples and
//! `bsdf_samples` BSDF samples combined by the power heuristic with the sample counts.

use super::path::sample_light_mis;
use super::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::bsdf::TransportMode;
use crate::error::Result;
use crate::film::Film;
use crate::geometry::Ray;
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;

#[derive(Clone, Copy, Debug)]
pub struct DirectIntegrator {
    pub emitter_samples: u32,
    pub bsdf_samples: u32,
}

impl Default for DirectIntegrator {
    fn default() -> Self {
        DirectIntegrator { emitter_samples: 1, bsdf_samples: 1 }
    }
}

impl Integrator for DirectIntegrator {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        render_pixels(scene, settings, progress, self)
    }
}

impl PixelEstimator for DirectIntegrator {
    fn li(&self, scene: &Scene, ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        let mut l = Rgb::BLACK;
        let Some(si) = scene.intersect(ray) else {
            if !settings.hide_emitters {
                for &ei in &scene.environment_lights {
                    l += scene.lights[ei as usize].le_escaped(ray.d);
                }
            }
            return l;
        };
        if let Some((_, area)) = scene.area_light(&si) {
            if !settings.hide_emitters {
                l += area.l(si.ng, si.uv, si.wo);
            }
        }
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        let (ne, nb) = (self.emitter_samples as f32, self.bsdf_samples as f32);
        if bsdf.flags().has_non_specular() {
            for _ in 0..self.emitter_samples {
                let ul = sampler.next_1d();
                let u = sampler.next_2d();
                let c = sample_light_mis(scene, si.p, si.ng, &si.shading, wo, &bsdf, ul, u, (ne, nb), si.time);
                l += c / ne;
            }
        }
        for _ in 0..self.bsdf_samples {
            let uc = sampler.next_1d();
            let u = sampler.next_2d();
            let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance) else { continue };
            if bs.pdf <= 0.0 {
                continue;
            }
            let wi = si.to_world(bs.wi);
            let r = si.spawn_ray(wi);
            let (le, pdf_light) = match scene.intersect(&r) {
                Some(s2) => match scene.area_light(&s2) {
                    Some((li, area)) => (area.l(s2.ng, s2.uv, s2.wo), scene.light_pmf(li) * area.pdf_li(si.p, s2.p, s2.ng)),
                    None => continue,
                },
                None => {
                    let mut le = Rgb::BLACK;
                    let mut pdf = 0.0;
                    for &ei in &scene.environment_lights {
                        let light = &scene.lights[ei as usize];
                        le += light.le_escaped(wi);
                        pdf += scene.light_pmf(ei) * light.pdf_li_escaped(wi);
                    }
                    (le, pdf)
                }
            };
            if le.is_black() {
                continue;
            }
            let w = if bs.lobe.is_specular() || self.emitter_samples == 0 { 1.0 } else { power_heuristic(nb, bs.pdf, ne, pdf_light) };
            l += le * bs.weight() * (w / nb);
        }
        l
    }
}
