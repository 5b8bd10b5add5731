//! Unidirectional path tracing: next-event estimation and BSDF sampling combined by
//! multiple importance sampling (power heuristic), Russian roulette.
//!
//! Estimator measure: solid angle at every vertex. Light selection by power; the light
//! strategy's density is `pmf(light) * pdf_li` in solid angle.

use super::{render_pixels, Integrator, PixelEstimator, Progress, RenderSettings};
use crate::bsdf::{Bsdf, LobeFlags, TransportMode};
use crate::error::Result;
use crate::film::Film;
use crate::geometry::{Ray, SurfaceInteraction};
use crate::lpe::aov::LayerSample;
use crate::lpe::{Event, Tracker};
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec3;

#[derive(Clone, Copy, Debug, Default)]
pub struct PathTracer;

impl Integrator for PathTracer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        render_pixels(scene, settings, progress, self)
    }
}

/// Next-event estimation from a surface point: one light chosen by the scene's light
/// selection, one point on it, weighted against BSDF sampling (`counts`: samples of each
/// strategy); the shadow ray sees the scene at `time`. Returns the contribution without the
/// path throughput, which light it reached and whether the light lies on the other side of
/// the surface (a transmission), for the path's events.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sample_light_mis_to(
    scene: &Scene,
    p: Vec3,
    ng: Vec3,
    frame: &crate::math::Frame,
    wo: Vec3,
    bsdf: &crate::bsdf::Bsdf,
    u_light: f32,
    u: glam::Vec2,
    counts: (f32, f32),
    time: f32,
) -> (Rgb, u32, bool) {
    if scene.lights.is_empty() {
        return (Rgb::BLACK, 0, false);
    }
    let (li, pmf, _) = scene.light_distribution.sample_discrete(u_light);
    let ls = light_sample_unshadowed(scene, li as u32, pmf, p, ng, frame, wo, bsdf, u, time);
    let (c, through) = settle(scene, ls, bsdf, wo, counts);
    (c, li as u32, through)
}

/// The contribution of light sample `ls` (None: none) once its shadow ray is tested, and
/// whether it arrives through the surface.
#[inline]
pub(crate) fn settle(scene: &Scene, ls: Option<Unshadowed>, bsdf: &crate::bsdf::Bsdf, wo: Vec3, counts: (f32, f32)) -> (Rgb, bool) {
    match ls {
        Some(ls) if !ls.shadow.is_some_and(|r| scene.occluded_ray(&r)) => ls.contribution(bsdf, wo, counts),
        _ => (Rgb::BLACK, false),
    }
}

/// A light sample at a surface point before its shadow ray is tested: callers that test
/// many rays at once (`direct`'s lockstep tiles) keep these until the answers come.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Unshadowed {
    /// The BSDF's value toward the light (local direction `wi`) and the radiance arriving.
    pub f: Rgb,
    pub li: Rgb,
    pub wi: Vec3,
    /// The light strategy's density (the light's choice included).
    pub pdf_light: f32,
    /// A delta light: no MIS weight.
    pub delta: bool,
    /// The segment (or the ray to infinity) that must be clear; None: nothing can block it.
    pub shadow: Option<Ray>,
}

impl Unshadowed {
    /// The contribution of the sample, its shadow ray clear (`counts`: samples of each
    /// strategy), and whether it arrives through the surface.
    #[inline(always)]
    pub fn contribution(&self, bsdf: &crate::bsdf::Bsdf, wo: Vec3, counts: (f32, f32)) -> (Rgb, bool) {
        let w = if self.delta { 1.0 } else { power_heuristic(counts.0, self.pdf_light, counts.1, bsdf.pdf(wo, self.wi, TransportMode::Radiance)) };
        (self.f * self.li * (self.wi.z.abs() * w / self.pdf_light), self.wi.z * wo.z < 0.0)
    }
}

/// Next-event estimation toward light `li`, chosen with probability `pmf` (see
/// [`sample_light_mis_to`]), up to its shadow ray ([`settle`] tests it); None where the
/// sample contributes nothing.
#[allow(clippy::too_many_arguments)]
pub(crate) fn light_sample_unshadowed(
    scene: &Scene,
    li: u32,
    pmf: f32,
    p: Vec3,
    ng: Vec3,
    frame: &crate::math::Frame,
    wo: Vec3,
    bsdf: &crate::bsdf::Bsdf,
    u: glam::Vec2,
    time: f32,
) -> Option<Unshadowed> {
    if pmf <= 0.0 {
        return None;
    }
    let light = &scene.lights[li as usize];
    let ls = light.sample_li(p, u, &scene.bounds)?;
    let f = bsdf_toward(bsdf, frame, wo, &ls)?;
    light_sample_finish(scene, ls, f, pmf, light.is_delta(), p, ng, time)
}

/// The local direction of light sample `ls` and the BSDF's value toward it (None where the
/// sample or that value adds nothing): [`light_sample_unshadowed`]'s first half.
#[inline(always)]
pub(crate) fn bsdf_toward(bsdf: &Bsdf, frame: &crate::math::Frame, wo: Vec3, ls: &crate::light::LightSample) -> Option<(Rgb, Vec3)> {
    if ls.pdf <= 0.0 || ls.li.is_black() {
        return None;
    }
    let wi = frame.to_local(ls.wi);
    let f = bsdf.eval(wo, wi, TransportMode::Radiance);
    (!f.is_black()).then_some((f, wi))
}

/// [`light_sample_unshadowed`]'s second half: the sample `ls` of a light chosen with
/// probability `pmf` (`delta`: a delta light), the BSDF's value `f` toward its local
/// direction `wi`, and its shadow ray from `p` (geometric normal `ng`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn light_sample_finish(
    scene: &Scene,
    ls: crate::light::LightSample,
    (f, wi): (Rgb, Vec3),
    pmf: f32,
    delta: bool,
    p: Vec3,
    ng: Vec3,
    time: f32,
) -> Option<Unshadowed> {
    let shadow = if ls.infinite { Some(scene.dir_ray_at(p, ng, ls.wi, time)) } else { scene.shadow_ray(p, ng, ls.p, ls.n, time) };
    Some(Unshadowed { f, li: ls.li, wi, pdf_light: pmf * ls.pdf, delta, shadow })
}

impl PixelEstimator for PathTracer {
    fn li(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb {
        camera_walk(scene, camera_ray, sampler, settings, &mut PathRules, &mut LayerSample::default())
    }
    fn li_layers(&self, scene: &Scene, camera_ray: &Ray, sampler: &mut dyn Sampler, settings: &RenderSettings, layers: &mut LayerSample) -> Rgb {
        camera_walk(scene, camera_ray, sampler, settings, &mut PathRules, layers)
    }
    fn supports_lpe(&self) -> bool {
        true
    }
}

/// The closest hit along `ray` where only its emission can count: None where the ray
/// escapes, `Some(None)` where it hits a shape without an area light (no surface record
/// built: at max depth 2 that is every other hit of a BSDF-sampled ray), else the record
/// `Scene::intersect` gives.
#[inline]
fn intersect_emitter(scene: &Scene, ray: &Ray) -> Option<Option<SurfaceInteraction>> {
    if !(scene.moving.is_empty() && scene.settings.ray_epsilon <= 0.0) {
        let hit = scene.intersect_prim(ray)?;
        return Some(if scene.shapes[hit.shape as usize].light.is_some() { scene.intersect(ray) } else { None });
    }
    // A static scene: what `Scene::intersect` does, the record built only for an emitter.
    let mut hit = scene.accel.intersect(ray)?;
    if !scene.static_shapes.is_empty() {
        hit.shape = scene.static_shapes[hit.shape as usize];
    }
    Some(scene.shapes[hit.shape as usize].light.is_some().then(|| scene.interaction(&hit, ray)))
}

/// A camera-path vertex that scattered by a non-specular BSDF sample, kept for the MIS
/// weight of the emitter (or the environment) its sample reaches.
struct ScatterPoint {
    p: Vec3,
    frame: crate::math::Frame,
    /// Toward the previous vertex, local shading frame.
    wo: Vec3,
    bsdf: Bsdf,
    /// The density of the sampled direction.
    pdf: f32,
}

impl ScatterPoint {
    /// The BSDF's density toward emitter point `y` ([`bsdf_pdf_toward`]); the sampled
    /// direction's where `y` is the point itself.
    fn pdf_toward(&self, y: Vec3) -> f32 {
        bsdf_pdf_toward(&self.bsdf, &self.frame, self.wo, self.p, y).unwrap_or(self.pdf)
    }
}

/// The density (solid angle, radiance transport) of `bsdf` at `p`, seen along `wo` (local
/// frame `frame`), for the direction from `p` to `y`. The MIS weight of an emitter point `y`
/// found by BSDF sampling takes this density rather than that of the sampled direction: the
/// sampled ray leaves from an offset origin, so its direction differs from the direction
/// `p → y` that next-event estimation weighs for the same `y`. Both strategies must weigh
/// one pair of densities per point for their weights to sum to one; on grazing chords (a
/// concave emitter seen from itself) the two directions' cosines differ by tens of percent.
/// None where `y` is `p`.
pub(crate) fn bsdf_pdf_toward(bsdf: &Bsdf, frame: &crate::math::Frame, wo: Vec3, p: Vec3, y: Vec3) -> Option<f32> {
    let d = y - p;
    let len = d.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    Some(bsdf.pdf(wo, frame.to_local(d / len), TransportMode::Radiance))
}

/// A camera-path vertex where the walk is about to scatter.
pub(crate) struct WalkVertex<'a> {
    pub si: &'a SurfaceInteraction,
    pub bsdf: &'a Bsdf,
    /// The BSDF's lobes.
    pub flags: LobeFlags,
    /// Toward the camera, local shading frame.
    pub wo: Vec3,
    /// Camera path throughput up to here.
    pub beta: Rgb,
    /// Path segments from the camera to here.
    pub depth: i32,
    /// The automata's states for the path's events before this vertex (from the camera).
    pub events: Tracker<'a>,
}

/// What a camera walk adds to path tracing's own rules (emission and next-event estimation
/// under MIS, BSDF sampling, Russian roulette): the methods built on it (`path`,
/// `distributed`, the photon methods' camera side) differ only here.
pub(crate) trait WalkRules {
    /// Radiance the method estimates at a vertex by other means, without the throughput;
    /// called after next-event estimation and before the BSDF sample. With AOVs, `layers`
    /// is the sample's: the rules add their estimate there by its paths, times `v.beta`.
    fn at_vertex(&mut self, _v: &WalkVertex, _sampler: &mut dyn Sampler, _layers: Option<&mut LayerSample>) -> Rgb {
        Rgb::BLACK
    }
    /// Whether the walk ends at the next hit (which then adds only its emission, to complete
    /// the MIS estimate of direct light) after the BSDF at a vertex with lobes `flags`
    /// sampled lobe `lobe`.
    fn ends_after(&self, _flags: LobeFlags, _lobe: LobeFlags) -> bool {
        false
    }
}

/// Plain path tracing: nothing added, never ends early.
struct PathRules;
impl WalkRules for PathRules {}

/// Radiance along `camera_ray` by path tracing under `rules`. Sample dimensions per vertex, in
/// order: light choice, light point (2), whatever `rules.at_vertex` draws, BSDF lobe, BSDF
/// direction (2), Russian roulette. Each contribution also goes to `layers` with the AOVs
/// its path's events match (the rules route their own estimates).
pub(crate) fn camera_walk<R: WalkRules + ?Sized>(
    scene: &Scene,
    camera_ray: &Ray,
    sampler: &mut dyn Sampler,
    settings: &RenderSettings,
    rules: &mut R,
    layers: &mut LayerSample,
) -> Rgb {
    let aovs = settings.aovs();
    let mut events = Tracker::camera(aovs);
    let mut l = Rgb::BLACK;
    let mut beta = Rgb::WHITE;
    let mut ray = *camera_ray;
    // Segments traced so far; the camera ray is segment 1.
    let mut depth = 0i32;
    // The previous vertex, for MIS on emitters found by BSDF sampling; None where there is
    // no other strategy (the camera, a specular sample).
    let mut prev: Option<ScatterPoint> = None;
    let mut eta_scale = 1.0f32;
    // The rules ended the walk at this hit: only its emission counts.
    let mut last = false;
    loop {
        depth += 1;
        let hide = depth == 1 && settings.hide_emitters;
        // Where only the hit's emission can count (nothing after it fits in max_depth), a hit
        // on a shape that does not emit adds nothing: found without its surface record.
        let emission_only = last || !settings.depth_allows(depth + 1);
        let hit = if emission_only { intersect_emitter(scene, &ray) } else { scene.intersect(&ray).map(Some) };
        let Some(hit) = hit else {
            if !hide {
                for &ei in &scene.environment_lights {
                    let light = &scene.lights[ei as usize];
                    let (le, pdf_light) = light.le_pdf_escaped(ray.d, prev.is_some());
                    if le.is_black() {
                        continue;
                    }
                    let w = prev.as_ref().map_or(1.0, |v| power_heuristic(1.0, v.pdf, 1.0, scene.light_pmf(ei) * pdf_light));
                    l += beta * le * w;
                    layers.add(events.ends(Event::BACKGROUND), beta * le * w);
                }
            }
            break;
        };
        let Some(si) = hit else { break };
        if let Some((li, area)) = scene.area_light(&si) {
            let le = area.l(si.ng, si.uv, si.wo);
            if !le.is_black() && !hide {
                let w = prev.as_ref().map_or(1.0, |v| power_heuristic(1.0, v.pdf_toward(si.p), 1.0, scene.light_pmf(li) * area.pdf_li(v.p, si.p, si.ng)));
                l += beta * le * w;
                layers.add(events.ends(aovs.light_event(Some(si.shape))), beta * le * w);
            }
        }
        // Another segment must fit in max_depth for anything more to count.
        if last || !settings.depth_allows(depth + 1) {
            break;
        }
        let bsdf = scene.bsdf(&si);
        let wo = si.to_local(si.wo);
        let flags = bsdf.flags();
        let u_light = sampler.next_1d();
        let u_l2 = sampler.next_2d();
        if flags.has_non_specular() {
            let (c, li, through) = sample_light_mis_to(scene, si.p, si.ng, &si.shading, wo, &bsdf, u_light, u_l2, (1.0, 1.0), si.time);
            l += beta * c;
            if !aovs.is_empty() && !c.is_black() {
                let here = aovs.scatter_event(si.shape, flags, None, through);
                layers.add(events.ends2(here, aovs.emitter_event(&scene.lights[li as usize])), beta * c);
            }
        }
        let v = WalkVertex { si: &si, bsdf: &bsdf, flags, wo, beta, depth, events };
        l += beta * rules.at_vertex(&v, sampler, (!aovs.is_empty()).then_some(&mut *layers));
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Radiance) else { break };
        if bs.pdf <= 0.0 || bs.f.is_black() {
            break;
        }
        beta *= bs.weight();
        if !bs.lobe.is_null() {
            events.push(aovs.scatter_event(si.shape, flags, Some(bs.lobe), bs.lobe.contains(LobeFlags::TRANSMISSION)));
        }
        if bs.lobe.contains(LobeFlags::TRANSMISSION) {
            eta_scale *= bs.eta * bs.eta;
        }
        last = rules.ends_after(flags, bs.lobe);
        ray = si.spawn_ray(si.to_world(bs.wi));
        prev = (!bs.lobe.is_specular()).then_some(ScatterPoint { p: si.p, frame: si.shading, wo, bsdf, pdf: bs.pdf });
        let u_rr = sampler.next_1d();
        if depth >= settings.rr_depth && !last {
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
