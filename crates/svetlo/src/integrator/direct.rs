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

use super::path::{bsdf_pdf_toward, bsdf_toward, light_sample_finish, light_sample_unshadowed, settle, Unshadowed};
use super::path_simd::LaneSampler;
use super::{camera_sample, render_tiles, Integrator, Progress, RenderSettings};
use crate::accel::packet::{Rays8, LANES};
use crate::bsdf::{Bsdf, BsdfSample, LobeFlags, TransportMode};
use crate::error::Result;
use crate::film::{Film, FilmTile};
use crate::geometry::{Ray, SurfaceInteraction};
use crate::light::Light;
use crate::lpe::aov::LayerSample;
use crate::lpe::{AovSet, Event, Tracker};
use crate::math::{warp, INV_PI};
use crate::path::ShadowPackets;
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
        self.render_with(scene, settings, progress, true)
    }
}

impl DirectIntegrator {
    /// The render, eight samples in lockstep where `lockstep` allows and packets can (else
    /// one sample at a time, for comparisons): the same image either way.
    fn render_with(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress, lockstep: bool) -> Result<Film> {
        let est = DirectEstimator { cfg: *self, lights: LightPlan::new(scene) };
        // Eight samples at a time where packets answer as the scene's BVH does (see
        // `render_tile_lockstep`); not with AOVs, nor several BSDF samples.
        let packets = if lockstep && settings.aovs().is_empty() && self.bsdf_samples <= 1 {
            ShadowPackets::new(scene).filter(ShadowPackets::exact_closest)
        } else {
            None
        };
        let (est, packets) = (&est, packets.as_ref());
        // One build of the tile loop per sampler: its draws inline (no call through `dyn`).
        render_tiles(scene, settings, progress, true, &|tile: &mut FilmTile, rect: [u32; 4], s0: u32, n: u32| {
            let job = (scene, settings, tile, rect, s0, n);
            match settings.sampler {
                SamplerKind::Independent => est.render_tile(job, packets, IndependentSampler::new(settings.spp, settings.seed)),
                SamplerKind::Sobol => est.render_tile(job, packets, SobolSampler::new(settings.spp, settings.seed)),
            }
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

/// A tile's share of a pass: the scene, the settings, the film tile, its own pixels
/// `[x0, y0, x1, y1)` and the samples `s0..s0 + n` of each.
type TileJob<'a> = (&'a Scene, &'a RenderSettings, &'a mut FilmTile, [u32; 4], u32, u32);

/// The ray of a lane with nothing to trace (of no length: no packet walk tests it).
const IDLE: Ray = Ray { o: Vec3::ZERO, d: Vec3::Z, t_max: 0.0, time: 0.0 };

/// A lane's camera sample once its first surface is known: what its BSDF sample still needs
/// once the packets' answers come (the BSDF itself is made again in the rare case that needs
/// it: kept for every lane, it cost a copy of its few hundred bytes per sample).
#[derive(Clone, Copy)]
struct LaneHit {
    /// Toward the camera, local shading frame.
    wo: Vec3,
    sky: SkySampling,
    /// The BSDF sample, its direction in the world and its ray, where one leaves.
    scatter: Option<(BsdfSample, Vec3, Ray)>,
}

impl DirectEstimator {
    /// Samples `s0..s0 + n` of every pixel of the job's rectangle, pixels in rows and samples
    /// innermost, as the pixel-sample driver takes them: eight at a time with `packets`,
    /// else one by one.
    fn render_tile<S: LaneSampler>(&self, job: TileJob, packets: Option<&ShadowPackets>, sampler: S) {
        match packets {
            Some(packets) => self.render_tile_lockstep_on_cpu(job, packets, sampler),
            None => self.render_tile_by_sample(job, sampler),
        }
    }

    /// [`Self::render_tile_lockstep`] in its AVX2 build where the CPU has it (the lanes'
    /// sampler steps and camera rays eight wide; the scalar code VEX-encoded, with no FMA
    /// contraction, so the same results).
    fn render_tile_lockstep_on_cpu<S: LaneSampler>(&self, job: TileJob, packets: &ShadowPackets, sampler: S) {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: `avx2()` detects AVX2 at run time.
            return unsafe { self.render_tile_lockstep_avx2(job, packets, sampler) };
        }
        self.render_tile_lockstep(job, packets, sampler)
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn render_tile_lockstep_avx2<S: LaneSampler>(&self, job: TileJob, packets: &ShadowPackets, sampler: S) {
        self.render_tile_lockstep(job, packets, sampler)
    }

    /// [`Self::render_tile`] one sample at a time; each pixel's samples go to the film as one
    /// run (the sums of adding them one by one).
    fn render_tile_by_sample<S: Sampler>(&self, (scene, settings, tile, rect, s0, n): TileJob, mut sampler: S) {
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

    /// [`Self::render_tile`] eight samples in lockstep, each lane drawing from its own copy of
    /// `sampler`: the camera rays go as one packet, then every light sample's shadow ray and
    /// every BSDF ray of the eight as packets (`ShadowPackets`, whose answers and surface
    /// records are the scene BVH's, bit for bit). Each lane's draws and arithmetic are those
    /// of [`Self::estimate`], its terms summed in the same order: the same image. Without
    /// AOVs, and one BSDF sample at most.
    #[inline(always)]
    fn render_tile_lockstep<S: LaneSampler>(&self, (scene, settings, tile, rect, s0, n): TileJob, packets: &ShadowPackets, sampler: S) {
        let [x0, y0, x1, y1] = rect;
        let w = x1 - x0;
        let jobs = w * (y1 - y0) * n;
        let cam = scene.camera.ray_generator();
        let pinhole = cam.is_pinhole();
        let DirectIntegrator { emitter_samples, bsdf_samples } = self.cfg;
        let counts = (emitter_samples as f32, bsdf_samples as f32);
        let aovs = settings.aovs();
        let mut samplers: [S; LANES] = std::array::from_fn(|_| sampler.clone());
        let mut results: Vec<(Vec2, Rgb)> = Vec::with_capacity(jobs as usize);
        // The light samples of the eight lanes, each lane's in the order of its sum: (lane, its
        // contribution should its shadow ray be clear, that ray), and whether it is blocked.
        let mut terms: Vec<(usize, Rgb, Option<Ray>)> = Vec::new();
        let mut blocked: Vec<bool> = Vec::new();
        let mut j = 0;
        while j < jobs {
            let k = (jobs - j).min(LANES as u32) as usize;
            let mut rays = [IDLE; LANES];
            let mut raster = [Vec2::ZERO; LANES];
            let active = (0xffu32 >> (LANES - k)) as u8;
            let first = if pinhole {
                // The lanes' samplers started, their numbers drawn side by side
                // (`LaneSampler::camera_draws`), then their rays all at once (`pinhole_lanes`:
                // the same rays, a square root and divisions each), which are the packet.
                let mut px = [(0, 0); LANES];
                for (l, px) in px.iter_mut().enumerate().take(k) {
                    let (pix, s) = ((j + l as u32) / n, (j + l as u32) % n);
                    *px = (x0 + pix % w, y0 + pix / w);
                    samplers[l].start_pixel_sample(px.0, px.1, s0 + s);
                }
                let d = S::camera_draws(&mut samplers, active);
                let mut film = [[0.0f32; LANES]; 2];
                for l in 0..k {
                    raster[l] = Vec2::new(px[l].0 as f32 + d[0][l], px[l].1 as f32 + d[1][l]);
                    (film[0][l], film[1][l]) = (raster[l].x, raster[l].y);
                }
                let r = cam.pinhole_lanes(&film, &d[4]);
                let lane = |a: &[[f32; LANES]; 3], l: usize| Vec3::new(a[0][l], a[1][l], a[2][l]);
                for (l, ray) in rays.iter_mut().enumerate().take(k) {
                    *ray = Ray { o: lane(&r.o, l), d: lane(&r.d, l), t_max: r.t_max[l], time: r.time[l] };
                }
                packets.closest_packet(&Rays8 { o: r.o, d: r.d, t_max: r.t_max }, active)
            } else {
                for l in 0..k {
                    let (pix, s) = ((j + l as u32) / n, (j + l as u32) % n);
                    (raster[l], rays[l]) = camera_sample(&cam, &mut samplers[l], x0 + pix % w, y0 + pix / w, s0 + s);
                }
                packets.closest(&rays, active)
            };
            // The first surfaces, and the texels the delta lights' samples there will read
            // asked for: they arrive while the eight lanes are shaded.
            let mut hits: [Option<SurfaceInteraction>; LANES] = [None; LANES];
            for l in 0..k {
                hits[l] = packets.interaction(scene, &first, l, &rays[l]);
                if let Some(si) = &hits[l] {
                    for &d in &self.lights.deltas {
                        scene.lights[d as usize].prefetch_li(si.p);
                    }
                }
            }
            // With one light and one BSDF sample (the default), the eight lanes' numbers side
            // by side (`LaneSampler::vertex_draws`: its rows are the draws each lane makes in
            // order, light choice and point first, then the BSDF's; a lane that misses does
            // not read them, and its sampler restarts at its next sample).
            let hit_lanes = (0..k).filter(|&l| hits[l].is_some()).fold(0u8, |m, l| m | 1 << l);
            // (Not `then`'s closure: built apart from this function, without its AVX2.)
            let nums = if emitter_samples == 1 && bsdf_samples == 1 && hit_lanes != 0 { Some(S::vertex_draws(&mut samplers, hit_lanes)) } else { None };
            let mut sums = [Rgb::BLACK; LANES];
            let mut lanes: [Option<LaneHit>; LANES] = [None; LANES];
            terms.clear();
            for l in 0..k {
                let (ray, sampler) = (&rays[l], &mut samplers[l]);
                let mut sum = Rgb::BLACK;
                let Some(si) = &hits[l] else {
                    if !settings.hide_emitters {
                        for &ei in &scene.environment_lights {
                            sum += scene.lights[ei as usize].le_escaped(ray.d);
                        }
                    }
                    sums[l] = sum;
                    continue;
                };
                if let Some((_, area)) = scene.area_light(si) {
                    if !settings.hide_emitters {
                        sum += area.l(si.ng, si.uv, si.wo);
                    }
                }
                sums[l] = sum;
                let bsdf = scene.bsdf(si);
                let wo = si.to_local(si.wo);
                let flags = bsdf.flags();
                let sky = SkySampling::new(&bsdf, flags);
                // A sample's contribution is made before its shadow ray is tested (the same
                // operations: it is dropped if the ray is blocked).
                // The row of `nums` the BSDF sample's numbers start at.
                let mut row = 0;
                if flags.has_non_specular() {
                    for _ in 0..emitter_samples {
                        let (ul, u) = match &nums {
                            Some(d) => (d[0][l], Vec2::new(d[1][l], d[2][l])),
                            None => (sampler.next_1d(), sampler.next_2d()),
                        };
                        row = 3;
                        let other = if self.lights.dist.is_empty() {
                            None
                        } else {
                            Some(lane_term(l, self.other_light_sample(scene, si, wo, &bsdf, sky, ul, u).1, &bsdf, wo, counts))
                        };
                        for &d in &self.lights.deltas {
                            terms.push(lane_term(l, delta_light_sample(scene, d, si, wo, &bsdf, u), &bsdf, wo, counts));
                        }
                        terms.extend(other);
                    }
                }
                let mut scatter = None;
                if bsdf_samples == 1 {
                    let (uc, u) = match &nums {
                        Some(d) => (d[row][l], Vec2::new(d[row + 1][l], d[row + 2][l])),
                        None => (sampler.next_1d(), sampler.next_2d()),
                    };
                    if let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance).filter(|bs| bs.pdf > 0.0) {
                        let wi = si.to_world(bs.wi);
                        scatter = Some((bs, wi, si.spawn_ray(wi)));
                    }
                }
                lanes[l] = Some(LaneHit { wo, sky, scatter });
            }
            // The shadow rays, eight at a time (a term without one is clear).
            blocked.clear();
            for chunk in terms.chunks(LANES) {
                let mut shadow = [IDLE; LANES];
                for (r, (_, _, ray)) in shadow.iter_mut().zip(chunk) {
                    if let Some(ray) = ray {
                        *r = *ray;
                    }
                }
                let mask = packets.occluded(&shadow[..chunk.len()]);
                blocked.extend((0..chunk.len()).map(|i| mask >> i & 1 != 0));
            }
            let mut second_rays = [IDLE; LANES];
            let mut second_active = 0u8;
            for (l, h) in lanes.iter().enumerate() {
                if let Some(LaneHit { scatter: Some((_, _, r)), .. }) = h {
                    second_rays[l] = *r;
                    second_active |= 1 << l;
                }
            }
            let second = (second_active != 0).then(|| packets.closest(&second_rays, second_active));
            // Each lane's terms in `estimate`'s order: emission (above), light samples, BSDF sample.
            let mut t = 0;
            for l in 0..k {
                let (Some(h), Some(si)) = (&lanes[l], &hits[l]) else { continue };
                let mut sum = sums[l];
                while t < terms.len() && terms[t].0 == l {
                    let c = if blocked[t] { Rgb::BLACK } else { terms[t].1 };
                    sum += c / counts.0;
                    t += 1;
                }
                if let (Some((bs, wi, r)), Some(second)) = (&h.scatter, &second) {
                    let hit = packets.interaction(scene, second, l, r);
                    if let Some((c, _)) = self.bsdf_term(scene, aovs, (si, None, h.wo, h.sky), bs, *wi, hit) {
                        sum += c;
                    }
                }
                sums[l] = sum;
            }
            results.extend((0..k).map(|l| (raster[l], sums[l])));
            j += k as u32;
        }
        tile.add_samples(&results);
    }

    /// The light other than the delta lights that a light sample `(ul, u)` at `si` takes,
    /// and that light's sample before its shadow ray (None: it adds nothing).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn other_light_sample(
        &self,
        scene: &Scene,
        si: &SurfaceInteraction,
        wo: Vec3,
        bsdf: &Bsdf,
        sky: SkySampling,
        ul: f32,
        u: Vec2,
    ) -> (u32, Option<Unshadowed>) {
        let (k, pmf, _) = self.lights.dist.sample_discrete(ul);
        let li = self.lights.others[k];
        let ls = match &scene.lights[li as usize] {
            Light::Constant { radiance } => sky_unshadowed(scene, si, wo, bsdf, sky, *radiance, pmf, u),
            _ => light_sample_unshadowed(scene, li, pmf, si.p, si.ng, &si.shading, wo, bsdf, u, si.time),
        };
        (li, ls)
    }

    /// The contribution of BSDF sample `bs` (direction `wi` in the world) at `si`, whose ray
    /// met `hit` (None: it escaped), and the event its path ends with; None where it adds
    /// nothing (a surface that does not emit, or no radiance). `bsdf`: the BSDF at `si`, made
    /// again where None and needed.
    #[inline(always)]
    fn bsdf_term(
        &self,
        scene: &Scene,
        aovs: &AovSet,
        (si, bsdf, wo, sky): (&SurfaceInteraction, Option<&Bsdf>, Vec3, SkySampling),
        bs: &BsdfSample,
        wi: Vec3,
        hit: Option<SurfaceInteraction>,
    ) -> Option<(Rgb, Event)> {
        let DirectIntegrator { emitter_samples, bsdf_samples } = self.cfg;
        let (ne, nb) = (emitter_samples as f32, bsdf_samples as f32);
        let mut at = None;
        let (le, pdf_light, end) = match hit {
            Some(s2) => {
                let (li, area) = scene.area_light(&s2)?;
                at = Some(s2.p);
                (area.l(s2.ng, s2.uv, s2.wo), self.lights.pmf[li as usize] * area.pdf_li(si.p, s2.p, s2.ng), aovs.light_event(Some(s2.shape)))
            }
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
            return None;
        }
        let w = if bs.lobe.is_specular() || emitter_samples == 0 {
            1.0
        } else {
            // The density toward the emitter point, as next-event estimation weighs it.
            let pdf_bsdf = at
                .and_then(|y| match bsdf {
                    Some(b) => bsdf_pdf_toward(b, &si.shading, wo, si.p, y),
                    None => bsdf_pdf_toward(&scene.bsdf(si), &si.shading, wo, si.p, y),
                })
                .unwrap_or(bs.pdf);
            power_heuristic(nb, pdf_bsdf, ne, pdf_light)
        };
        Some((le * bs.weight() * (w / nb), end))
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
                    let (li, ls) = self.other_light_sample(scene, &si, wo, &bsdf, sky, ul, u);
                    let (c, through) = settle(scene, ls, &bsdf, wo, (ne, nb));
                    (c, li, through)
                });
                // Delta lights ignore the point sample: the same one serves them all.
                for &d in &self.lights.deltas {
                    let ls = light_sample_unshadowed(scene, d, 1.0, si.p, si.ng, &si.shading, wo, &bsdf, u, si.time);
                    let (c, through) = settle(scene, ls, &bsdf, wo, (ne, nb));
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
            let Some((c, end)) = self.bsdf_term(scene, aovs, (&si, Some(&bsdf), wo, sky), &bs, wi, scene.intersect(&si.spawn_ray(wi))) else { continue };
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

/// Lane `l`'s light sample `ls` as the lockstep tile keeps it: its contribution should its
/// shadow ray be clear, and that ray (inline: a call each cost more than the Lambertian's
/// arithmetic).
#[inline(always)]
fn lane_term(l: usize, ls: Option<Unshadowed>, bsdf: &Bsdf, wo: Vec3, counts: (f32, f32)) -> (usize, Rgb, Option<Ray>) {
    match ls {
        Some(ls) => (l, ls.contribution(bsdf, wo, counts).0, ls.shadow),
        None => (l, Rgb::BLACK, None),
    }
}

/// [`light_sample_unshadowed`] of delta light `d` (probability 1) at `si`: a spot's sample
/// inline (`Light::spot_sample_li_inline`), the same operations.
#[inline(always)]
fn delta_light_sample(scene: &Scene, d: u32, si: &SurfaceInteraction, wo: Vec3, bsdf: &Bsdf, u: Vec2) -> Option<Unshadowed> {
    let light = &scene.lights[d as usize];
    if !matches!(light, Light::Spot { .. }) {
        return light_sample_unshadowed(scene, d, 1.0, si.p, si.ng, &si.shading, wo, bsdf, u, si.time);
    }
    let ls = light.spot_sample_li_inline(si.p)?;
    let f = bsdf_toward(bsdf, &si.shading, wo, &ls)?;
    light_sample_finish(scene, ls, f, 1.0, true, si.p, si.ng, si.time)
}

/// Next-event estimation toward a constant environment of radiance `le`, chosen with
/// probability `pmf`, by [`SkySampling`], up to its shadow ray (None: it adds nothing).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sky_unshadowed(scene: &Scene, si: &SurfaceInteraction, wo: Vec3, bsdf: &Bsdf, sky: SkySampling, le: Rgb, pmf: f32, u: Vec2) -> Option<Unshadowed> {
    let (wi, pdf) = sky.sample(wo, u)?;
    let f = bsdf.eval(wo, wi, TransportMode::Radiance);
    if f.is_black() || pmf <= 0.0 {
        return None;
    }
    Some(Unshadowed { f, li: le, wi, pdf_light: pmf * pdf, delta: false, shadow: Some(scene.dir_ray_at(si.p, si.ng, si.to_world(wi), si.time)) })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Material;
    use crate::camera::Camera;
    use crate::geometry::{Geometry, TriangleMesh};
    use crate::scene::SceneBuilder;
    use crate::texture::{Bitmap, FilterMode, Texture, WrapMode};
    use glam::{Affine2, Mat4, Quat};
    use std::sync::Arc;

    /// A quad of two triangles with corners `c` (counter-clockwise seen from its front).
    fn quad(c: [Vec3; 4]) -> Geometry {
        Geometry::Mesh(TriangleMesh { positions: c.to_vec(), normals: vec![], uvs: vec![], indices: vec![[0, 1, 2], [0, 2, 3]] })
    }

    /// A floor and a wall under a constant sky, lit by an emitting quad, a textured spot and
    /// a point light: every kind of term of the estimator (emission seen, delta lights, the
    /// sky's and the area light's samples, BSDF samples escaping and reaching the emitter,
    /// blocked and clear shadow rays).
    fn lit_room() -> Scene {
        let mut b = SceneBuilder::new();
        let white = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.7)) });
        let (x, z) = (Vec3::X * 3.0, Vec3::Z * 3.0);
        b.add_shape(quad([-x - z, -x + z, x + z, x - z].map(|p| p + Vec3::new(0.0, -1.0, 4.0))), white, None, "floor").unwrap();
        b.add_shape(quad([Vec3::new(-1.0, -1.0, 5.0), Vec3::new(1.0, -1.0, 5.0), Vec3::new(1.0, 1.0, 5.0), Vec3::new(-1.0, 1.0, 5.0)]), white, None, "wall")
            .unwrap();
        let emitter = Texture::Constant(Rgb::new(4.0, 3.0, 2.0));
        b.add_shape(
            quad([Vec3::new(-0.5, 1.5, 3.5), Vec3::new(0.5, 1.5, 3.5), Vec3::new(0.5, 1.5, 4.5), Vec3::new(-0.5, 1.5, 4.5)]),
            white,
            Some(emitter),
            "lamp",
        )
        .unwrap();
        b.add_light(Light::Constant { radiance: Rgb::splat(0.2) });
        b.add_light(Light::point(Vec3::new(1.5, 1.0, 2.0), Rgb::splat(2.0)));
        let mut spot = Light::spot(
            &Mat4::from_rotation_translation(Quat::from_rotation_arc(Vec3::Z, Vec3::new(0.3, -0.5, 1.0).normalize()), Vec3::new(-1.0, 1.0, 1.0)),
            Rgb::splat(8.0),
            30.0,
            Some(20.0),
        );
        if let Light::Spot { texture, .. } = &mut spot {
            let texels = (0..64).map(|i| Rgb::new((i % 8) as f32 / 8.0, (i / 8) as f32 / 8.0, 0.5)).collect();
            let image = Arc::new(Bitmap::new(8, 8, texels));
            *texture = Some(Texture::Bitmap { image, filter: FilterMode::Bilinear, wrap: WrapMode::Repeat, to_uv: Affine2::IDENTITY });
        }
        b.add_light(spot);
        b.set_camera(Camera::pinhole(Mat4::IDENTITY, 70.0, 19, 13));
        b.build().unwrap()
    }

    /// Mitsuba's projector test in small: a 2000-unit square lit from 1 unit above, seen
    /// through a 170° lens (where packet shadow rays answered otherwise than the scene's BVH).
    fn vast_floor() -> Scene {
        let mut b = SceneBuilder::new();
        let white = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(1.0)) });
        let (x, y) = (Vec3::X * 1000.0, Vec3::Y * 1000.0);
        b.add_shape(quad([-x - y, x - y, x + y, -x + y]), white, None, "floor").unwrap();
        b.add_light(Light::point(Vec3::new(0.0, 0.0, 1.0), Rgb::splat(1.0)));
        let look_down = Mat4::from_rotation_translation(Quat::from_rotation_arc(Vec3::Z, -Vec3::Z), Vec3::Z);
        b.set_camera(Camera::pinhole(look_down, 170.0, 24, 24));
        b.build().unwrap()
    }

    /// The lockstep tiles give the image of one sample at a time, bit for bit, with either
    /// sampler, several light samples, and a tile's last packet short of eight lanes; on the
    /// vast floor too (it fails with the packets' shadow answers).
    #[test]
    fn lockstep_is_one_sample_at_a_time() {
        for (scene, sampler, spp, emitter_samples) in [
            (lit_room(), SamplerKind::Independent, 5, 1),
            (lit_room(), SamplerKind::Sobol, 4, 1),
            (lit_room(), SamplerKind::Independent, 3, 2),
            (vast_floor(), SamplerKind::Independent, 4, 1),
        ] {
            if ShadowPackets::new(&scene).is_none() {
                return; // no AVX2: one sample at a time only
            }
            let settings = RenderSettings { spp, sampler, seed: 7, threads: 1, ..Default::default() };
            let direct = DirectIntegrator { emitter_samples, bsdf_samples: 1 };
            let packed = direct.render_with(&scene, &settings, &Progress::new(), true).unwrap().image();
            let single = direct.render_with(&scene, &settings, &Progress::new(), false).unwrap().image();
            assert!(packed.mean().max_component() > 0.0);
            let bits = |d: &[Rgb]| d.iter().flat_map(|c| [c.r, c.g, c.b].map(f32::to_bits)).collect::<Vec<_>>();
            assert_eq!(bits(&packed.data), bits(&single.data), "{sampler:?}, {spp} spp, {emitter_samples} light samples");
        }
    }
}
