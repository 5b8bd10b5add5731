//! Bidirectional path tracing (Veach 1997, ch. 10): per pixel sample one camera subpath and
//! one light subpath, every prefix pair (s, t) connected, each strategy weighted by the
//! power heuristic over all strategies that could have produced the same path (computed in
//! time linear in the path's length, see `path/mis.rs`). Strategies with t = 1 land on other
//! pixels and are splatted (scaled by 1/spp, one light path per pixel sample).
//!
//! Estimator measure: area at every vertex (solid angle for vertices at infinity).
//! `render_with_strategies` also returns one image per (s, t), weighted and unweighted,
//! reconstructed with a box filter: the weighted ones sum to the BDPT image (exactly so
//! when the render's filter is the box).

use super::light::require_connectible_camera;
use super::splat::{render_splatting, render_tile_by_sample, SampleOut, ShadowedSplats, Splat, SplatEstimator, TileJob};
use super::{Integrator, Progress, RenderSettings};
use crate::error::Result;
use crate::film::{Film, Image};
use crate::geometry::Ray;
use crate::lpe::{AovSet, Event, LayerMask, LightTracker, ProductView, Tracker};
use crate::path::{
    camera_subpath, camera_subpath_traced, connect, light_subpath, light_subpath_traced, weighted_camera_connection, Connection, PathConfig, ShadowPackets,
    Vertex,
};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;

#[derive(Clone, Copy, Debug, Default)]
pub struct Bdpt;

/// The images of one strategy: s light vertices, t camera vertices (s + t - 1 segments).
#[derive(Clone, Debug)]
pub struct StrategyImage {
    pub s: usize,
    pub t: usize,
    /// Its share of the BDPT image (MIS-weighted).
    pub weighted: Image,
    /// What the strategy estimates alone (the full contribution of the paths it samples).
    pub unweighted: Image,
}

#[derive(Default)]
pub(crate) struct Scratch {
    camera: Vec<Vertex>,
    light: Vec<Vertex>,
}

struct Estimator {
    cfg: PathConfig,
    /// Strategy index by (s, t) for the per-strategy images: index[s][t].
    index: Vec<Vec<Option<u32>>>,
    /// The shadow rays of t = 1 strategies as packets (None: one at a time).
    packets: Option<ShadowPackets>,
}

impl Estimator {
    fn strategy(&self, s: usize, t: usize) -> Option<u32> {
        self.index.get(s).and_then(|r| r.get(t)).copied().flatten()
    }
}

impl SplatEstimator for Estimator {
    type Scratch = Scratch;
    fn scratch(&self) -> Scratch {
        Scratch { camera: Vec::with_capacity(16), light: Vec::with_capacity(16) }
    }
    fn supports_lpe(&self) -> bool {
        // The per-strategy images are beauty only.
        self.index.is_empty()
    }
    fn sample(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        ray: &Ray,
        raster: Vec2,
        sampler: &mut dyn Sampler,
        sc: &mut Scratch,
        out: &mut SampleOut,
    ) -> Rgb {
        sample_bdpt(scene, settings, &self.cfg, ray, raster, sampler, sc, out, |_, _, s, t, c, v, out| {
            if let Some(k) = self.strategy(s, t) {
                let at = c.raster.unwrap_or(raster);
                out.push(1 + 2 * k, at, v);
                out.push(2 + 2 * k, at, c.l);
            }
            true
        })
    }

    /// Without AOVs or strategy images, where packets apply: `sample`'s samples in its order,
    /// with the t = 1 strategies' shadow rays tested eight at a time across samples
    /// (`ShadowedSplats` keeps the splat list that of testing each alone).
    fn render_tile(&self, t: TileJob, sampler: &mut dyn Sampler, sc: &mut Scratch, splats: &mut Vec<Splat>) {
        let Some(packets) = self.packets.as_ref().filter(|_| t.settings.aovs().is_empty() && self.index.is_empty()) else {
            return render_tile_by_sample(self, t, sampler, sc, splats);
        };
        let [x0, y0, x1, y1] = t.rect;
        let (scene, cfg) = (t.scene, &self.cfg);
        let cam = scene.camera.ray_generator();
        let mut out = SampleOut { splats, layers: Default::default() };
        let mut pending = ShadowedSplats::new();
        for y in y0..y1 {
            for x in x0..x1 {
                for i in t.s0..t.s0 + t.n {
                    let (raster, ray) = super::camera_sample(&cam, sampler, x, y, i);
                    // `sample_bdpt` with no AOVs and every strategy counted, the walks' hits
                    // made from the packet tree's triangle table.
                    let trace = |r: &Ray| packets.intersect(scene, r);
                    camera_subpath_traced(scene, cfg, &ray, raster, sampler, &mut sc.camera, &trace);
                    light_subpath_traced(scene, cfg, ray.time, sampler, &mut sc.light, &trace);
                    let mut l = Rgb::BLACK;
                    for tc in 1..=sc.camera.len() {
                        for s in 0..=sc.light.len() {
                            if s + tc < 2 || !cfg.allows(s + tc) {
                                continue;
                            }
                            if tc == 1 {
                                if let Some((v, r, shadow)) = weighted_camera_connection(scene, cfg, &sc.light, &sc.camera, s, sampler) {
                                    pending.push(packets, v, r, shadow.unwrap_or(ShadowedSplats::CLEAR), &mut out);
                                }
                            } else if let Some(c) = connect(scene, cfg, &sc.light, &sc.camera, s, tc, sampler, true) {
                                // t >= 2: the camera subpath's own pixel.
                                l += c.l * c.weight;
                            }
                        }
                    }
                    t.tile.add_sample(raster, l);
                }
            }
        }
        pending.flush(packets, &mut out);
    }
}

/// One BDPT sample: a camera and a light subpath, every strategy (s, t) connected and
/// MIS-weighted; t = 1 strategies are splatted, the others returned as the pixel's value.
/// `visit(light, camera, s, t, connection, weighted value, out)` sees each connection first
/// and says whether it counts (BDPT's strategy images). Every connection is made whether or not it counts, so the
/// sample dimensions consumed do not depend on `visit`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sample_bdpt(
    scene: &Scene,
    settings: &RenderSettings,
    cfg: &PathConfig,
    ray: &Ray,
    raster: Vec2,
    sampler: &mut dyn Sampler,
    sc: &mut Scratch,
    out: &mut SampleOut,
    mut visit: impl FnMut(&[Vertex], &[Vertex], usize, usize, &Connection, Rgb, &mut SampleOut) -> bool,
) -> Rgb {
    camera_subpath(scene, cfg, ray, raster, sampler, &mut sc.camera);
    light_subpath(scene, cfg, ray.time, sampler, &mut sc.light);
    let aovs = settings.aovs();
    let mut l = Rgb::BLACK;
    let mut router = StrategyRouter::new(aovs, &sc.light, &sc.camera);
    for t in 1..=sc.camera.len() {
        router.at_t(&sc.camera, t);
        for s in 0..=sc.light.len() {
            router.at_s(scene, &sc.light, s);
            if s + t < 2 || !cfg.allows(s + t) {
                continue;
            }
            let Some(c) = connect(scene, cfg, &sc.light, &sc.camera, s, t, sampler, true) else { continue };
            let v = c.l * c.weight;
            if !visit(&sc.light, &sc.camera, s, t, &c, v, out) {
                continue;
            }
            let mask = router.layers(scene, &sc.light, &sc.camera, s, t, &c);
            match c.raster {
                Some(r) => out.splat_layers(mask, r, v),
                None => {
                    l += v;
                    out.layers.add(mask, v);
                }
            }
        }
    }
    l
}

/// Vertices whose events a [`StrategyRouter`] keeps (the rest are computed when asked).
const CACHED: usize = 8;

/// The reflection events of a subpath's first vertices ([`AovSet::reflect_event`]: one look
/// at each BSDF per sample), from which its sampled and connected events follow.
struct SubpathEvents {
    reflect: [Event; CACHED],
    n: usize,
}

impl SubpathEvents {
    #[inline]
    fn new(aovs: &AovSet, path: &[Vertex]) -> Self {
        let mut e = SubpathEvents { reflect: [Event::CAMERA; CACHED], n: 0 };
        if !aovs.is_empty() {
            e.n = path.len().min(CACHED);
            for (r, v) in e.reflect.iter_mut().zip(path) {
                *r = aovs.reflect_event(v);
            }
        }
        e
    }
    #[inline]
    fn reflect(&self, aovs: &AovSet, path: &[Vertex], i: usize) -> Event {
        if i < self.n {
            self.reflect[i]
        } else {
            aovs.reflect_event(&path[i])
        }
    }
    #[inline]
    fn sampled(&self, aovs: &AovSet, path: &[Vertex], i: usize) -> Option<Event> {
        AovSet::sampled_from(self.reflect(aovs, path, i), &path[i])
    }
    #[inline]
    fn connected(&self, aovs: &AovSet, path: &[Vertex], i: usize, q: glam::Vec3) -> Event {
        AovSet::connected(self.reflect(aovs, path, i), &path[i], q)
    }
}

/// The automata along both subpaths of a BDPT sample as its loops advance t (outer) and s
/// (inner), so that routing strategy (s, t) costs a few steps, not a walk of both subpaths.
pub(crate) struct StrategyRouter<'a> {
    aovs: &'a AovSet,
    states: RouterStates<'a>,
    /// The subpaths' vertex events (with AOVs), computed once per sample, not per strategy.
    le: SubpathEvents,
    ce: SubpathEvents,
}

/// A light state not yet computed.
const NO_STATE: u32 = u32::MAX;

/// The automata's states as the loops left them.
enum RouterStates<'a> {
    /// No AOVs: every path goes to the beauty.
    Off,
    /// The set's product automata (the common case): one integer per subpath.
    Product {
        view: ProductView<'a>,
        /// Forward state over camera[0..t-1].
        cam: u32,
        /// Reverse state over light[0..max(s-1, 1)] as sampled ([`NO_STATE`]: none yet).
        light: u32,
        /// `light` for each s below CACHED as the first t left it (it does not depend on t).
        light_at: [u32; CACHED],
    },
    /// One state per automaton (sets too large for a product; boxed, as the other variants
    /// are a few words and the router is made once per sample).
    Each(Box<EachStates<'a>>),
}

/// [`RouterStates::Each`]'s states, as `Product`'s but one per automaton.
struct EachStates<'a> {
    cam: Tracker<'a>,
    light: Option<LightTracker<'a>>,
    light_at: [Option<LightTracker<'a>>; CACHED],
}

impl<'a> StrategyRouter<'a> {
    pub fn new(aovs: &'a AovSet, light: &[Vertex], camera: &[Vertex]) -> Self {
        let states = if aovs.is_empty() {
            RouterStates::Off
        } else if let Some(view) = aovs.product_view() {
            RouterStates::Product { view, cam: view.camera(), light: NO_STATE, light_at: [NO_STATE; CACHED] }
        } else {
            RouterStates::Each(Box::new(EachStates { cam: Tracker::camera(aovs), light: None, light_at: [None; CACHED] }))
        };
        StrategyRouter { aovs, states, le: SubpathEvents::new(aovs, light), ce: SubpathEvents::new(aovs, camera) }
    }
    #[inline]
    pub fn at_t(&mut self, camera: &[Vertex], t: usize) {
        if matches!(self.states, RouterStates::Off) {
            return;
        }
        let sampled = if t >= 3 { self.ce.sampled(self.aovs, camera, t - 2) } else { None };
        match &mut self.states {
            RouterStates::Off => {}
            RouterStates::Product { view, cam, light, .. } => {
                if let Some(e) = sampled {
                    *cam = view.step(*cam, e);
                }
                *light = NO_STATE;
            }
            RouterStates::Each(st) => {
                if let Some(e) = sampled {
                    st.cam.push(e);
                }
                st.light = None;
            }
        }
    }
    #[inline]
    pub fn at_s(&mut self, scene: &Scene, light: &[Vertex], s: usize) {
        if s == 0 {
            return;
        }
        let (aovs, le) = (self.aovs, &self.le);
        match &mut self.states {
            RouterStates::Off => {}
            RouterStates::Product { view, light: r, light_at, .. } => {
                if let Some(&cached) = light_at.get(s).filter(|c| **c != NO_STATE) {
                    *r = cached;
                    return;
                }
                if *r == NO_STATE {
                    *r = view.light(aovs.endpoint_event(scene, &light[0]));
                } else if s >= 3 {
                    if let Some(e) = le.sampled(aovs, light, s - 2) {
                        *r = view.rev_step(*r, e);
                    }
                }
                if let Some(c) = light_at.get_mut(s) {
                    *c = *r;
                }
            }
            RouterStates::Each(st) => {
                let EachStates { light: lt, light_at, .. } = &mut **st;
                if let Some(Some(cached)) = light_at.get(s) {
                    *lt = Some(*cached);
                    return;
                }
                match lt {
                    None => *lt = Some(LightTracker::light(aovs, aovs.endpoint_event(scene, &light[0]))),
                    Some(lt) if s >= 3 => {
                        if let Some(e) = le.sampled(aovs, light, s - 2) {
                            lt.push(e);
                        }
                    }
                    Some(_) => {}
                }
                if let Some(c) = light_at.get_mut(s) {
                    *c = *lt;
                }
            }
        }
    }

    /// The layers that take strategy (s, t)'s path: the camera prefix forward, the light
    /// subpath backward, and the two connected vertices' events toward each other.
    #[inline]
    pub fn layers(&self, scene: &Scene, light: &[Vertex], camera: &[Vertex], s: usize, t: usize, c: &Connection) -> LayerMask {
        let aovs = self.aovs;
        let (le, ce) = (&self.le, &self.ce);
        match &self.states {
            RouterStates::Off => crate::lpe::aov::BEAUTY,
            RouterStates::Product { view, cam, light: r, .. } => {
                if s == 0 {
                    // The camera subpath found an emitter (or escaped) at vertex t - 1.
                    return view.ends(*cam, aovs.endpoint_event(scene, &camera[t - 1]));
                }
                let mut r = if s == 1 && t >= 2 {
                    view.light(Self::sampled_light_event(aovs, scene, c))
                } else if *r != NO_STATE {
                    *r
                } else {
                    let mut r = view.light(aovs.endpoint_event(scene, &light[0]));
                    for e in light[1..(s - 1).max(1)].iter().filter_map(|v| aovs.sampled_event(v)) {
                        r = view.rev_step(r, e);
                    }
                    r
                };
                if t == 1 {
                    if s >= 2 {
                        r = view.rev_step(r, le.connected(aovs, light, s - 1, c.sampled_p));
                    }
                    return view.meets(view.camera(), r);
                }
                let toward = if s == 1 { c.sampled_p } else { light[s - 1].p };
                let q = view.step(*cam, ce.connected(aovs, camera, t - 1, toward));
                if s >= 2 {
                    r = view.rev_step(r, le.connected(aovs, light, s - 1, camera[t - 1].p));
                }
                view.meets(q, r)
            }
            RouterStates::Each(st) => {
                let (mut cam, lt) = (st.cam, &st.light);
                if s == 0 {
                    return cam.ends(aovs.endpoint_event(scene, &camera[t - 1]));
                }
                let mut lt = if s == 1 && t >= 2 {
                    LightTracker::light(aovs, Self::sampled_light_event(aovs, scene, c))
                } else {
                    match lt {
                        Some(lt) => *lt,
                        None => LightTracker::along(aovs, scene, light, (s - 1).max(1)),
                    }
                };
                if t == 1 {
                    if s >= 2 {
                        lt.push(le.connected(aovs, light, s - 1, c.sampled_p));
                    }
                    return lt.meets_camera();
                }
                let toward = if s == 1 { c.sampled_p } else { light[s - 1].p };
                cam.push(ce.connected(aovs, camera, t - 1, toward));
                if s >= 2 {
                    lt.push(le.connected(aovs, light, s - 1, camera[t - 1].p));
                }
                lt.meets(&cam)
            }
        }
    }

    /// The light event of strategy (1, t)'s sampled light point.
    #[inline]
    fn sampled_light_event(aovs: &AovSet, scene: &Scene, c: &Connection) -> Event {
        c.sampled_light.map_or(Event::BACKGROUND, |li| aovs.emitter_event(&scene.lights[li as usize]))
    }
}

impl Bdpt {
    /// Render, and keep the images of every strategy with at most `max_segments` segments
    /// (within max_depth).
    pub fn render_with_strategies(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &Progress,
        max_segments: usize,
    ) -> Result<(Film, Vec<StrategyImage>)> {
        require_connectible_camera(scene, "bdpt")?;
        let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
        let max_segments = if settings.max_depth >= 0 { max_segments.min(settings.max_depth as usize) } else { max_segments };
        let mut list = Vec::new();
        let mut index = vec![vec![None; max_segments + 2]; max_segments + 2];
        for n in 2..=max_segments + 1 {
            for s in (0..n).rev() {
                index[s][n - s] = Some(list.len() as u32);
                list.push((s, n - s));
            }
        }
        let est = Estimator { cfg, index, packets: None };
        let r = render_splatting(scene, settings, progress, &est, 2 * list.len())?;
        let (w, h) = (r.film.width as usize, r.film.height as usize);
        let mut channels = r.channels.into_iter();
        let mut images = Vec::with_capacity(list.len());
        for (s, t) in list {
            let weighted = Image::new(w, h, channels.next().unwrap_or_default());
            let unweighted = Image::new(w, h, channels.next().unwrap_or_default());
            images.push(StrategyImage { s, t, weighted, unweighted });
        }
        Ok((r.film, images))
    }
}

/// A BDPT estimator whose strategy (1, 2) feeds channels 1 and 2 (for the driver's tests).
#[cfg(test)]
pub(crate) fn test_estimator(scene: &Scene, settings: &RenderSettings) -> impl SplatEstimator {
    let mut index = vec![vec![None; 3]; 3];
    index[1][2] = Some(0);
    Estimator { cfg: PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters), index, packets: None }
}

impl Bdpt {
    /// The render with the t = 1 shadow rays as packets where the scene allows them
    /// (`packets`), or each alone: the same image, bit for bit.
    pub fn render_traced(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress, packets: bool) -> Result<Film> {
        require_connectible_camera(scene, "bdpt")?;
        let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
        let est = Estimator { cfg, index: Vec::new(), packets: if packets { ShadowPackets::new(scene) } else { None } };
        Ok(render_splatting(scene, settings, progress, &est, 0)?.film)
    }
}

impl Integrator for Bdpt {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        self.render_traced(scene, settings, progress, true)
    }
}
