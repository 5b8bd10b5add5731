//! Direct illumination (Mitsuba's `direct`): emitters seen by the camera, plus light arriving
//! straight from emitters at the first surface, by `emitter_samples` light samples and
//! `bsdf_samples` BSDF samples combined by the power heuristic with the sample counts.

use super::path::sample_light_mis_to;
use super::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::bsdf::{LobeFlags, TransportMode};
use crate::error::Result;
use crate::film::Film;
use crate::geometry::Ray;
use crate::lpe::aov::LayerSample;
use crate::lpe::{Event, Tracker};
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
        self.estimate(scene, ray, sampler, settings, &mut LayerSample::default())
    }
    fn li_layers(&self, scene: &Scene, ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        self.estimate(scene, ray, sampler, settings, layers)
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}

impl DirectIntegrator {
    /// Paths `C [LB]` (emitters seen) and `C x [LB]` (one scattering at the first surface),
    /// each contribution also routed to the layers its events match.
    fn estimate(&self, scene: &Scene, ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        let aovs = settings.aovs();
        let events = Tracker::camera(aovs);
        let mut l = Rgb::BLACK;
        let Some(si) = scene.intersect(ray) else {
            if !settings.hide_emitters {
                for &ei in &scene.environment_lights {
                    let le = scene.lights[ei as usize].le_escaped(ray.d);
                    l += le;
                    layers.add(events.ends(Event::BACKGROUND), le);
                }
            }
            return l;
        };
        if let Some((_, area)) = scene.area_light(&si) {
            if !settings.hide_emitters {
                let le = area.l(si.ng, si.uv, si.wo);
                l += le;
                layers.add(events.ends(aovs.light_event(Some(si.shape))), le);
            }
        }
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        let flags = bsdf.flags();
        let (ne, nb) = (self.emitter_samples as f32, self.bsdf_samples as f32);
        if flags.has_non_specular() {
            for _ in 0..self.emitter_samples {
                let ul = sampler.next_1d();
                let u = sampler.next_2d();
                let (c, li, through) = sample_light_mis_to(scene, si.p, si.ng, &si.shading, wo, &bsdf, ul, u, (ne, nb), si.time);
                l += c / ne;
                if !aovs.is_empty() && !c.is_black() {
                    let here = aovs.scatter_event(si.shape, flags, None, through);
                    layers.add(events.ends2(here, aovs.emitter_event(&scene.lights[li as usize])), c / ne);
                }
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
            let (le, pdf_light, end) = match scene.intersect(&r) {
                Some(s2) => match scene.area_light(&s2) {
                    Some((li, area)) => (area.l(s2.ng, s2.uv, s2.wo), scene.light_pmf(li) * area.pdf_li(si.p, s2.p, s2.ng), aovs.light_event(Some(s2.shape))),
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
                    (le, pdf, Event::BACKGROUND)
                }
            };
            if le.is_black() {
                continue;
            }
            let w = if bs.lobe.is_specular() || self.emitter_samples == 0 { 1.0 } else { power_heuristic(nb, bs.pdf, ne, pdf_light) };
            let c = le * bs.weight() * (w / nb);
            l += c;
            if !aovs.is_empty() {
                // A null lobe (a mask let the ray through) is no vertex of the path.
                let mask = if bs.lobe.is_null() {
                    events.ends(end)
                } else {
                    events.ends2(aovs.scatter_event(si.shape, flags, Some(bs.lobe), bs.lobe.contains(LobeFlags::TRANSMISSION)), end)
                };
                layers.add(mask, c);
            }
        }
        l
    }
}
