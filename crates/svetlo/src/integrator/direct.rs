//! Direct illumination (Mitsuba's `direct`): emitters seen by the camera, plus light arriving
//! straight from emitters at the first surface, by `emitter_samples` light samples and
//! `bsdf_samples` BSDF samples combined by the power heuristic with the sample counts.
//!
//! Unlike Mitsuba, which picks one emitter per light sample, each light sample takes every
//! delta light (point, spot, projector, directional, luminaire) and one of the others, chosen
//! by the scene's light selection renormalised over them. Delta lights cannot be reached by
//! BSDF sampling, so the split keeps the estimator unbiased and the MIS weights exact; it
//! removes the variance of choosing between a delta light and the rest (on Mitsuba's spot
//! test, a textured spot under a constant sky, that choice was most of the variance) for one
//! shadow ray per delta light.

use super::path::{bsdf_pdf_toward, light_mis_to};
use super::{camera_sample, render_tiles, Integrator, Progress, RenderSettings};
use crate::bsdf::{LobeFlags, TransportMode};
use crate::error::Result;
use crate::film::{Film, FilmTile};
use crate::geometry::{Ray, SurfaceInteraction};
use crate::light::Light;
use crate::lpe::aov::LayerSample;
use crate::lpe::{Event, Tracker};
use crate::math::{warp, INV_PI};
use crate::sampling::{power_heuristic, Distribution1D, IndependentSampler, Sampler, SamplerKind, SobolSampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

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
        let est = DirectEstimator { cfg: *self, lights: LightPlan::new(scene) };
        // One build of the tile loop per sampler: its draws inline (no call through `dyn`).
        render_tiles(scene, settings, progress, true, &|tile: &mut FilmTile, rect: [u32; 4], s0: u32, n: u32| match settings.sampler {
            SamplerKind::Independent => est.render_tile(scene, settings, tile, rect, s0, n, IndependentSampler::new(settings.spp, settings.seed)),
            SamplerKind::Sobol => est.render_tile(scene, settings, tile, rect, s0, n, SobolSampler::new(settings.spp, settings.seed)),
        })
    }
}

/// How a light sample covers the scene's lights.
struct LightPlan {
    /// Every delta light, each sampled at every light sample.
    deltas: Vec<u32>,
    /// The other lights (indices into the scene's), one chosen per light sample by the
    /// scene's selection renormalised over them.
    others: Vec<u32>,
    dist: Distribution1D,
    /// Probability of choosing each light (by scene index) among `others`.
    pmf: Vec<f32>,
}

impl LightPlan {
    fn new(scene: &Scene) -> LightPlan {
        let (deltas, others): (Vec<u32>, Vec<u32>) = (0..scene.lights.len() as u32).partition(|&i| scene.lights[i as usize].is_delta());
        let mut weights: Vec<f32> = others.iter().map(|&i| scene.light_pmf(i)).collect();
        if weights.iter().sum::<f32>() <= 0.0 {
            weights.fill(1.0);
        }
        let total: f32 = weights.iter().sum();
        let mut pmf = vec![0.0; scene.lights.len()];
        for (&i, w) in others.iter().zip(&weights) {
            pmf[i as usize] = w / total;
        }
        LightPlan { deltas, dist: Distribution1D::new(&weights), others, pmf }
    }
}

/// Light sampling of a `constant` environment: cosine-weighted about the shading normal
/// (Mitsuba samples the whole sphere uniformly). On the side `wo` lies on only when the BSDF
/// reflects and nothing else (no transmission, no perturbed normal), where it cannot scatter
/// light from the other side; else on both sides alike. On a diffuse surface this is BSDF
/// sampling's own density: the two strategies then agree and their MIS sum has no variance.
#[derive(Clone, Copy)]
struct SkySampling {
    one_side: bool,
}

impl SkySampling {
    /// For `bsdf`, whose flags are `flags`.
    fn new(bsdf: &crate::bsdf::Bsdf, flags: LobeFlags) -> SkySampling {
        SkySampling { one_side: !flags.intersects(LobeFlags::TRANSMISSION) && bsdf.detail.is_none() }
    }

    /// A direction in the local shading frame and its density.
    fn sample(self, wo: Vec3, u: Vec2) -> Option<(Vec3, f32)> {
        let (u, side) = if self.one_side {
            if wo.z == 0.0 {
                return None;
            }
            (u, wo.z.signum())
        } else if u.x < 0.5 {
            (Vec2::new(2.0 * u.x, u.y), 1.0)
        } else {
            (Vec2::new(2.0 * u.x - 1.0, u.y), -1.0)
        };
        let mut wi = warp::square_to_cosine_hemisphere(u);
        wi.z *= side;
        let pdf = self.pdf(wo, wi);
        (pdf > 0.0).then_some((wi, pdf))
    }

    fn pdf(self, wo: Vec3, wi: Vec3) -> f32 {
        if self.one_side {
            if wi.z * wo.z > 0.0 {
                wi.z.abs() * INV_PI
            } else {
                0.0
            }
        } else {
            wi.z.abs() * (0.5 * INV_PI)
        }
    }
}

/// The estimator of one render: the settings and the scene's light plan.
struct DirectEstimator {
    cfg: DirectIntegrator,
    lights: LightPlan,
}

impl DirectEstimator {
    /// Samples `s0..s0 + n` of every pixel of `rect` (the tile's own pixels), pixels in rows
    /// and samples innermost, as the pixel-sample driver takes them; each pixel's samples go
    /// to the film as one run (the sums of adding them one by one).
    #[allow(clippy::too_many_arguments)]
    fn render_tile<S: Sampler>(&self, scene: &Scene, settings: &RenderSettings, tile: &mut FilmTile, rect: [u32; 4], s0: u32, n: u32, mut sampler: S) {
        let [x0, y0, x1, y1] = rect;
        let cam = scene.camera.ray_generator();
        let aovs = settings.aovs();
        let mut layers = LayerSample::default();
        let mut run: Vec<(Vec2, Rgb)> = Vec::with_capacity(n as usize);
        for y in y0..y1 {
            for x in x0..x1 {
                for s in s0..s0 + n {
                    let (raster, ray) = camera_sample(&cam, &mut sampler, x, y, s);
                    let l = self.estimate(scene, &ray, &mut sampler, settings, &mut layers);
                    if aovs.is_empty() {
                        run.push((raster, l));
                    } else {
                        let beauty = if aovs.restricts_beauty() { layers.beauty } else { l };
                        tile.add_sample_touched(raster, beauty, &layers.aov[..aovs.aov_count()], layers.touched);
                        layers.clear();
                    }
                }
                tile.add_samples(&run);
                run.clear();
            }
        }
    }

    /// Paths `C [LB]` (emitters seen) and `C x [LB]` (one scattering at the first surface),
    /// each contribution also routed to the layers its events match.
    #[inline(always)]
    fn estimate<S: Sampler>(&self, scene: &Scene, ray: &Ray, sampler: &mut S, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
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
        // A delta light's sample may read a large texture (a textured spot's): its texels are
        // asked for now, to arrive while the BSDF is built and the other light is sampled.
        for &d in &self.lights.deltas {
            scene.lights[d as usize].prefetch_li(si.p);
        }
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
        let DirectIntegrator { emitter_samples, bsdf_samples } = self.cfg;
        let sky = SkySampling::new(&bsdf, flags);
        let (ne, nb) = (emitter_samples as f32, bsdf_samples as f32);
        if flags.has_non_specular() {
            for _ in 0..emitter_samples {
                let ul = sampler.next_1d();
                let u = sampler.next_2d();
                // Each light's contribution, also routed to the layers its events match (out of
                // line: without AOVs this closure is the sum alone, and inlines).
                let mut add = |(c, li, through): (Rgb, u32, bool), l: &mut Rgb| {
                    *l += c / ne;
                    if !aovs.is_empty() && !c.is_black() {
                        route_light_sample(scene, &events, layers, (si.shape, flags), (li, through), c / ne);
                    }
                };
                // The other light's sample is made first (the delta lights' texels, asked for
                // above, arrive meanwhile) and added last, in the order of the sum.
                let other = (!self.lights.dist.is_empty()).then(|| {
                    let (k, pmf, _) = self.lights.dist.sample_discrete(ul);
                    let li = self.lights.others[k];
                    let (c, through) = match &scene.lights[li as usize] {
                        Light::Constant { radiance } => sky_mis_to(scene, &si, wo, &bsdf, sky, *radiance, pmf, u, (ne, nb)),
                        _ => light_mis_to(scene, li, pmf, si.p, si.ng, &si.shading, wo, &bsdf, u, (ne, nb), si.time),
                    };
                    (c, li, through)
                });
                // Delta lights ignore the point sample: the same one serves them all.
                for &d in &self.lights.deltas {
                    let (c, through) = light_mis_to(scene, d, 1.0, si.p, si.ng, &si.shading, wo, &bsdf, u, (ne, nb), si.time);
                    add((c, d, through), &mut l);
                }
                if let Some(o) = other {
                    add(o, &mut l);
                }
            }
        }
        for _ in 0..bsdf_samples {
            let uc = sampler.next_1d();
            let u = sampler.next_2d();
            let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance) else { continue };
            if bs.pdf <= 0.0 {
                continue;
            }
            let wi = si.to_world(bs.wi);
            let r = si.spawn_ray(wi);
            let mut hit = None;
            let (le, pdf_light, end) = match scene.intersect(&r) {
                Some(s2) => match scene.area_light(&s2) {
                    Some((li, area)) => {
                        hit = Some(s2.p);
                        (area.l(s2.ng, s2.uv, s2.wo), self.lights.pmf[li as usize] * area.pdf_li(si.p, s2.p, s2.ng), aovs.light_event(Some(s2.shape)))
                    }
                    None => continue,
                },
                None => {
                    let mut le = Rgb::BLACK;
                    let mut pdf = 0.0;
                    for &ei in &scene.environment_lights {
                        let light = &scene.lights[ei as usize];
                        le += light.le_escaped(wi);
                        let density = match light {
                            Light::Constant { .. } => sky.pdf(wo, bs.wi),
                            _ => light.pdf_li_escaped(wi),
                        };
                        pdf += self.lights.pmf[ei as usize] * density;
                    }
                    (le, pdf, Event::BACKGROUND)
                }
            };
            if le.is_black() {
                continue;
            }
            let w = if bs.lobe.is_specular() || emitter_samples == 0 {
                1.0
            } else {
                // The density toward the emitter point, as next-event estimation weighs it.
                let pdf_bsdf = hit.and_then(|y| bsdf_pdf_toward(&bsdf, &si.shading, wo, si.p, y)).unwrap_or(bs.pdf);
                power_heuristic(nb, pdf_bsdf, ne, pdf_light)
            };
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

/// Adds `c`, the contribution of a light sample of light `li` at a surface of shape `shape`
/// with BSDF flags `flags` (arriving `through` it), to the layers its events match.
#[inline(never)]
fn route_light_sample(scene: &Scene, events: &Tracker, layers: &mut LayerSample, (shape, flags): (u32, LobeFlags), (li, through): (u32, bool), c: Rgb) {
    let aovs = events.set();
    let here = aovs.scatter_event(shape, flags, None, through);
    layers.add(events.ends2(here, aovs.emitter_event(&scene.lights[li as usize])), c);
}

/// Next-event estimation toward a constant environment of radiance `le`, chosen with
/// probability `pmf`, by [`SkySampling`]: the contribution and whether it arrives through
/// the surface.
#[allow(clippy::too_many_arguments)]
fn sky_mis_to(
    scene: &Scene,
    si: &SurfaceInteraction,
    wo: Vec3,
    bsdf: &crate::bsdf::Bsdf,
    sky: SkySampling,
    le: Rgb,
    pmf: f32,
    u: Vec2,
    counts: (f32, f32),
) -> (Rgb, bool) {
    const NONE: (Rgb, bool) = (Rgb::BLACK, false);
    let Some((wi, pdf)) = sky.sample(wo, u) else { return NONE };
    let f = bsdf.eval(wo, wi, TransportMode::Radiance);
    if f.is_black() || pmf <= 0.0 {
        return NONE;
    }
    if scene.occluded_dir_at(si.p, si.ng, si.to_world(wi), si.time) {
        return NONE;
    }
    let pdf_light = pmf * pdf;
    let w = power_heuristic(counts.0, pdf_light, counts.1, bsdf.pdf(wo, wi, TransportMode::Radiance));
    (f * le * (wi.z.abs() * w / pdf_light), wi.z * wo.z < 0.0)
}
