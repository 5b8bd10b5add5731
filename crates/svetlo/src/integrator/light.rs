//! Light tracing (particle tracing): paths start at the lights and every vertex is
//! connected to the camera (next-event estimation toward the lens), splatting where it
//! lands on the film. This is BDPT's t = 1 family alone, unweighted: it sees every path
//! whose last scattering before the camera is diffuse or glossy, and none that reach the
//! camera through a specular surface (a mirror or glass seen directly stays black).
//!
//! Estimator measure: area at every vertex. One light path per pixel sample, so with
//! W·H·spp paths the splats are divided by spp (see `camera/importance.rs`).

use super::splat::{render_splatting, render_tile_by_sample, SampleOut, ShadowedSplats, Splat, SplatEstimator, TileJob};
use super::{Integrator, Progress, RenderSettings};
use crate::accel::packet::{Rays8, LANES};
use crate::error::{Error, Result};
use crate::film::{Film, FilmTile};
use crate::geometry::Ray;
use crate::light::emit8::EmitLanes;
use crate::light::{EmissionSample, Light};
use crate::lpe::LightTracker;
use crate::math::lane::lanes_of;
use crate::path::{
    camera_connection, connect, light_subpath, light_subpath_traced, light_walk_draws, light_walk_from, light_walk_light, set_lane, BatchScratch, CameraBatch,
    LightWalk, PathConfig, ShadowPackets, Staged, Vertex, WalkLanes,
};
use crate::sampling::{IndependentSampler, Sampler, SamplerKind, SobolSampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;

#[derive(Clone, Copy, Debug, Default)]
pub struct LightTracer;

/// How the light tracer traces its rays where the scene allows packets (`ShadowPackets`);
/// every way gives the same image, bit for bit (tests compare them).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tracing {
    /// Eight light paths walk in lockstep, their rays traced as packets, and the shadow rays
    /// of their camera connections tested as packets (in scenes where packets' closest hits
    /// are exact, `ShadowPackets::exact_closest`; elsewhere as `PacketShadows`).
    #[default]
    Lockstep,
    /// One path at a time, the shadow rays of consecutive connections as packets.
    PacketShadows,
    /// Every ray alone through the scene's BVH.
    Single,
}

struct Estimator {
    cfg: PathConfig,
    /// Shadow rays of one subpath's connections as packets (None: one at a time).
    packets: Option<ShadowPackets>,
    tracing: Tracing,
    /// The camera connections of a finished lockstep path eight at a time (a pinhole).
    batch: Option<CameraBatch>,
}

impl SplatEstimator for Estimator {
    /// One subpath per lane (`sample` uses the first).
    type Scratch = Vec<Vec<Vertex>>;
    fn scratch(&self) -> Vec<Vec<Vertex>> {
        (0..LANES).map(|_| Vec::with_capacity(16)).collect()
    }
    fn sample(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        ray: &Ray,
        _raster: Vec2,
        sampler: &mut dyn Sampler,
        paths: &mut Vec<Vec<Vertex>>,
        out: &mut SampleOut,
    ) -> Rgb {
        let path = &mut paths[0];
        light_subpath(scene, &self.cfg, ray.time, sampler, path);
        // With AOVs: the reverse automata's states over the vertices before the connected one.
        let aovs = settings.aovs();
        let mut events = (!aovs.is_empty() && !path.is_empty()).then(|| LightTracker::light(aovs, aovs.endpoint_event(scene, &path[0])));
        for s in 1..=path.len() {
            if let Some(c) = connect(scene, &self.cfg, path, &[], s, 1, sampler, false) {
                if let Some(r) = c.raster {
                    match events {
                        None => out.splat(r, c.l),
                        Some(mut e) => {
                            if s >= 2 {
                                e.push(aovs.connected_event(&path[s - 1], c.sampled_p));
                            }
                            out.splat_layers(e.meets_camera(), r, c.l);
                        }
                    }
                }
            }
            if let (Some(e), true) = (events.as_mut(), s >= 2) {
                if let Some(ev) = aovs.sampled_event(&path[s - 1]) {
                    e.push(ev);
                }
            }
        }
        Rgb::BLACK
    }
    fn supports_lpe(&self) -> bool {
        true
    }
    /// With packets (and no AOVs): the samples of `sample`, in its order, with the shadow
    /// rays of the connections to the camera tested eight at a time across light paths.
    fn render_tile(&self, t: TileJob, sampler: &mut dyn Sampler, paths: &mut Vec<Vec<Vertex>>, splats: &mut Vec<Splat>) {
        let Some(packets) = self.packets.as_ref().filter(|_| t.settings.aovs().is_empty() && self.tracing != Tracing::Single) else {
            return render_tile_by_sample(self, t, sampler, paths, splats);
        };
        if self.tracing == Tracing::Lockstep && packets.exact_closest() {
            // The lanes draw from the render's own sampler type (`make_sampler`'s, fresh: the
            // same numbers as `sampler`'s), so that the walks' draws are not virtual calls.
            let (spp, seed) = (t.settings.spp, t.settings.seed);
            return match t.settings.sampler {
                SamplerKind::Independent => self.render_tile_lockstep(t, packets, IndependentSampler::new(spp, seed), paths, splats),
                SamplerKind::Sobol => self.render_tile_lockstep(t, packets, SobolSampler::new(spp, seed), paths, splats),
            };
        }
        let path = &mut paths[0];
        let [x0, y0, x1, y1] = t.rect;
        let cam = t.scene.camera.ray_generator();
        let mut out = SampleOut { splats, layers: Default::default() };
        let mut pending = ShadowedSplats::new();
        for y in y0..y1 {
            for x in x0..x1 {
                for s in t.s0..t.s0 + t.n {
                    let (raster, ray) = super::camera_sample(&cam, sampler, x, y, s);
                    // The walk's hits made from the packet tree's triangle table.
                    light_subpath_traced(t.scene, &self.cfg, ray.time, sampler, path, &|r: &Ray| packets.intersect(t.scene, r));
                    for s in 1..=path.len() {
                        if let Some(c) = camera_connection(t.scene, &self.cfg, path, s, sampler) {
                            pending.push(packets, c.l, c.raster, c.shadow.unwrap_or(ShadowedSplats::CLEAR), &mut out);
                        }
                    }
                    t.tile.add_sample(raster, Rgb::BLACK);
                }
            }
        }
        pending.flush(packets, &mut out);
    }
}

impl Estimator {
    /// `render_tile` with the light subpaths of eight pixel samples walked in lockstep: each
    /// lane draws from its own sampler in `sample`'s order, the lanes' rays go as one packet
    /// (tied lanes again alone: `ShadowPackets::closest`), and a lane whose walk is over makes
    /// its camera connections and takes the tile's next sample, so that the packets stay
    /// full. The connections are computed and tested eight at a time across samples and
    /// splatted in sample order (`OrderedSplats`), so the splat list is `sample`'s.
    fn render_tile_lockstep<S: Sampler + Clone>(&self, t: TileJob, packets: &ShadowPackets, sampler: S, paths: &mut [Vec<Vertex>], splats: &mut Vec<Splat>) {
        let [x0, y0, x1, y1] = t.rect;
        let (s0, n) = (t.s0, t.n);
        let scene = t.scene;
        let cam = scene.camera.ray_generator();
        let mut out = SampleOut { splats, layers: Default::default() };
        let mut conns = OrderedSplats::default();
        let mut samplers: [S; LANES] = std::array::from_fn(|_| sampler.clone());
        let mut walks: [Option<LightWalk>; LANES] = std::array::from_fn(|_| None);
        // Each lane's sample (its index in the tile's order).
        let mut seq = [0usize; LANES];
        // The lanes' rays, each put in from its walk (a copy of the walk's `Ray` in 16-byte
        // words read back the walk's narrower stores: a store-forwarding stall a path).
        let mut rays = Rays8::default();
        let mut samples = (y0..y1).flat_map(|y| (x0..x1).flat_map(move |x| (s0..s0 + n).map(move |s| (x, y, s)))).enumerate();
        let mut active = 0u8;
        let mut more = true;
        let mut blacks = BlackSamples::default();
        let mut lambert = WalkLanes::default();
        // The starts of the lanes' paths: their light (index, probability), emission
        // samples taken alone, and times.
        let mut emit = EmitLanes::default();
        let mut starts: [Option<(usize, f32)>; LANES] = [None; LANES];
        let mut emitted: [Option<EmissionSample>; LANES] = [None; LANES];
        let mut times = [0f32; LANES];
        loop {
            // Idle lanes take the next samples (in lane order, so in sample order), their
            // emission samples on framed mesh lights as one step (`EmitLanes`), the others
            // alone; a walk that ends at once is finished here and its lane takes the next.
            // Which lane takes which sample changes nothing: each lane draws from its
            // own sampler, started at the sample, and the splats keep sample order.
            let mut idle = !active;
            while more && idle != 0 {
                let mut taken = 0u8;
                for l in lanes_of(idle.into()) {
                    let Some((i, (x, y, s))) = samples.next() else {
                        more = false;
                        break;
                    };
                    let sampler = &mut samplers[l];
                    let (raster, ray) = super::camera_sample(&cam, sampler, x, y, s);
                    blacks.push(t.tile, raster);
                    seq[l] = conns.open(i);
                    times[l] = ray.time;
                    let (u_light, u_pos, u_dir) = light_walk_draws(sampler);
                    starts[l] = light_walk_light(scene, &self.cfg, u_light);
                    if let Some((li, _)) = starts[l] {
                        match &scene.lights[li] {
                            Light::Area(a) if emit.gather(l, a, u_pos, u_dir) => {}
                            light => emitted[l] = light.sample_le(u_pos, u_dir, ray.time, &scene.bounds),
                        }
                    }
                    taken |= 1 << l;
                }
                emit.run();
                for l in lanes_of(taken.into()) {
                    let (path, walk) = (&mut paths[l], &mut walks[l]);
                    *walk = None;
                    path.clear();
                    if let Some((li, pmf)) = starts[l] {
                        let es = match &scene.lights[li] {
                            Light::Area(a) if emit.has(l) => Some(emit.sample(l, a, times[l])),
                            _ => emitted[l].take(),
                        };
                        if let Some(es) = es {
                            light_walk_from(scene, &self.cfg, times[l], li, pmf, &es, path, walk);
                        }
                    }
                    match walk {
                        Some(w) if w.walk.goes_on(path) => {
                            set_lane(&mut rays, l, w.walk.ray());
                            active |= 1 << l;
                        }
                        _ => self.finish_lane(scene, packets, walk.as_ref(), path, &mut samplers[l], seq[l], &mut conns, &mut out),
                    }
                }
                emit.clear();
                idle = taken & !active;
            }
            if active == 0 {
                break;
            }
            let hits = packets.closest_packet(&rays, active);
            // Each lane arrives at its hit and draws its vertex's numbers; Lambertian vertices
            // scatter together (`WalkLanes`), the others alone. A lane's walk goes on (bit 1)
            // or ends (bit 0) in `going`, its fate after the Lambertian step if gathered.
            let mut going = 0u8;
            for l in lanes_of(active.into()) {
                let Some(w) = walks[l].as_mut() else { continue };
                let path = &mut paths[l];
                // (The vertices' densities are left out: light tracing reads none.) A constant
                // diffuse surface's vertex is written from the hit at once.
                let arrived = match packets.diffuse(&hits, l) {
                    Some(d) => Some(w.walk.arrive_pushed(path, |ray, beta, path| d.push(ray, beta, path))),
                    None => {
                        let hit = packets.interaction(scene, &hits, l, w.walk.ray());
                        w.walk.arrive_unsettled(scene, hit.as_ref(), path)
                    }
                };
                if arrived != Some(true) {
                    continue;
                }
                let sampler = &mut samplers[l];
                let uc = sampler.next_1d();
                let u = sampler.next_2d();
                let u_rr = sampler.next_1d();
                if !lambert.gather(l, &w.walk, path, uc, u, u_rr) && w.walk.scatter(uc, u, u_rr, path) {
                    going |= 1 << l;
                }
            }
            lambert.run(&mut rays);
            // (Only lane `l`'s own bit of `active` changes in the loop.)
            for l in lanes_of(active.into()) {
                let Some(w) = walks[l].as_mut() else { continue };
                let goes_on = if lambert.has(l) { lambert.finish(l, &mut w.walk, &mut paths[l], &rays) } else { going & (1 << l) != 0 };
                if goes_on {
                    if !lambert.has(l) {
                        set_lane(&mut rays, l, w.walk.ray());
                    }
                } else {
                    active &= !(1 << l);
                    self.finish_lane(scene, packets, walks[l].as_ref(), &mut paths[l], &mut samplers[l], seq[l], &mut conns, &mut out);
                }
            }
            lambert.clear();
        }
        blacks.flush(t.tile);
        conns.finish(self.batch.as_ref(), packets, &mut out);
    }

    /// A lane's path after its walk (sample `i`): its camera connections, in order, to
    /// `conns` (lens samples drawn as `sample` draws them).
    #[allow(clippy::too_many_arguments)]
    fn finish_lane<S: Sampler>(
        &self,
        scene: &Scene,
        packets: &ShadowPackets,
        walk: Option<&LightWalk>,
        path: &mut [Vertex],
        sampler: &mut S,
        i: usize,
        conns: &mut OrderedSplats,
        out: &mut SampleOut,
    ) {
        if let Some(w) = walk {
            w.finish(path);
        }
        // (The lens samples a pinhole's lanes do not read are left undrawn: the lane's
        // sampler restarts at its next sample.)
        let mut owed = 0;
        for s in 1..=path.len() {
            match &self.batch {
                Some(batch) => match batch.stage_lazy(scene, &self.cfg, path, s, sampler, &mut owed, &mut conns.lanes) {
                    Staged::None | Staged::Scalar(None) => {}
                    Staged::Scalar(Some((l, raster, ray))) => conns.scalar(packets, i, l, raster, ray),
                    Staged::Lane(k) => {
                        conns.lane(i, k);
                        if conns.lanes.is_full() {
                            conns.run_lanes(batch, packets);
                        }
                    }
                },
                None => {
                    if let Some(c) = camera_connection(scene, &self.cfg, path, s, sampler) {
                        conns.scalar(packets, i, c.l, c.raster, c.shadow);
                    }
                }
            }
        }
        conns.made(i);
        conns.release(out);
    }
}

/// The pixel samples of a lockstep tile, black (light tracing adds its light by splats),
/// given to the film in runs (`FilmTile::add_black_samples`): the same sums as adding each
/// alone (the tile takes nothing else meanwhile), in under a third of the instructions.
struct BlackSamples {
    at: [Vec2; Self::RUN],
    n: usize,
}

impl Default for BlackSamples {
    fn default() -> Self {
        BlackSamples { at: [Vec2::ZERO; Self::RUN], n: 0 }
    }
}

impl BlackSamples {
    const RUN: usize = 64;

    #[inline]
    fn push(&mut self, tile: &mut FilmTile, raster: Vec2) {
        self.at[self.n] = raster;
        self.n += 1;
        if self.n == Self::RUN {
            self.flush(tile);
        }
    }

    fn flush(&mut self, tile: &mut FilmTile) {
        tile.add_black_samples(&self.at[..self.n]);
        self.n = 0;
    }
}

/// One pixel sample's camera connections: (contribution, raster, whether it is splatted,
/// which implies `SampleOut::splat`'s test of the contribution), the last unknown until
/// its shadow ray has been tested. A lane's connection is put in when its lane has run,
/// and only if it is splatted (a placeholder put in when it was staged cost a store per
/// connection and a look-up of its slot); its place is kept only before a connection
/// computed alone (`OrderedSplats::scalar`).
#[derive(Default)]
struct Slot {
    splats: Vec<(Rgb, Vec2, bool)>,
    /// Connections whose lane or shadow ray is still to run, once `made` (before, less the
    /// lanes that have run: it may be below zero).
    waiting: isize,
    /// Whether all its connections are made.
    made: bool,
}

/// The camera connections of the samples in flight: computed in lanes eight at a time
/// across samples (`CameraBatch`), their shadow rays tested as the lanes' packet (those
/// computed alone: eight at a time too), and splatted in sample order, the order of testing
/// each alone. A slot per sample from the oldest unsplatted one on (`base`), in a ring
/// whose emptied slots are reused where they are (slots moved through a deque were read
/// back in words that spanned their stores: a store-forwarding stall a sample); connections
/// whose results are to come are named by (sample, index in its slot).
#[derive(Default)]
struct OrderedSplats {
    /// Sample `base + k`'s slot at `(head + k) % slots.len()`, for k < `open`.
    slots: Vec<Slot>,
    head: usize,
    open: usize,
    base: usize,
    /// The staged lanes, and whose connection each is (sample, index in its slot; `PUSH`:
    /// put in after the slot's others).
    lanes: BatchScratch,
    lane_of: [(usize, usize); LANES],
    /// Lanes staged for the sample being made (added to its `waiting` by [`Self::made`]).
    staged: isize,
    /// Shadow rays of connections computed alone, waiting for a packet.
    rays: Rays8,
    ray_of: [(usize, usize); LANES],
    n_rays: usize,
}

impl OrderedSplats {
    /// A slot for sample `i` (samples open in order); returns the key of [`Self::slot`].
    fn open(&mut self, i: usize) -> usize {
        debug_assert_eq!(i, self.base + self.open);
        if self.open == self.slots.len() {
            // Full: the open slots to the front, in order, and a new one after them.
            self.slots.rotate_left(self.head);
            self.head = 0;
            self.slots.push(Slot::default());
        }
        self.open += 1;
        i
    }

    const PUSH: usize = usize::MAX;

    #[inline]
    fn slot(&mut self, i: usize) -> &mut Slot {
        let k = self.head + (i - self.base);
        let n = self.slots.len();
        &mut self.slots[if k >= n { k - n } else { k }]
    }

    /// Sample `i`'s next connection is in lane `k` of `lanes`.
    #[inline]
    fn lane(&mut self, i: usize, k: usize) {
        self.lane_of[k] = (i, Self::PUSH);
        self.staged += 1;
    }

    /// Sample `i`'s connections are all staged.
    #[inline]
    fn made(&mut self, i: usize) {
        let staged = std::mem::take(&mut self.staged);
        let slot = self.slot(i);
        slot.waiting += staged;
        slot.made = true;
    }

    /// The staged lanes' connections and their shadow rays as one packet, into their slots.
    fn run_lanes(&mut self, batch: &CameraBatch, packets: &ShadowPackets) {
        batch.run(&mut self.lanes);
        let (rays, tested) = self.lanes.shadow_rays();
        let splatted = self.lanes.splatted() & !packets.occluded_lanes(rays, tested);
        for k in 0..self.lanes.staged() {
            let (i, at) = self.lane_of[k];
            let splatted = splatted & (1 << k) != 0;
            let (l, raster) = (self.lanes.l(k), self.lanes.raster(k));
            let slot = self.slot(i);
            if at != Self::PUSH {
                slot.splats[at] = (l, raster, splatted);
            } else if splatted {
                slot.splats.push((l, raster, true));
            }
            slot.waiting -= 1;
        }
        self.lanes.clear();
    }

    /// Sample `i`'s next connection, computed alone: its shadow ray (None or of no length:
    /// clear) waits for a packet.
    fn scalar(&mut self, packets: &ShadowPackets, i: usize, l: Rgb, raster: Vec2, shadow: Option<Ray>) {
        // What `SampleOut::splat` would drop is left out here (`release` does not test).
        if l.is_black() || !l.is_finite() {
            return;
        }
        // The sample's lanes still to run (the last staged) keep their places before it.
        let n = self.lanes.staged();
        let first = (0..n).rev().take_while(|&k| self.lane_of[k] == (i, Self::PUSH)).last();
        if let Some(first) = first {
            let slot = self.slot(i);
            let at = slot.splats.len();
            slot.splats.resize(at + n - first, (Rgb::BLACK, Vec2::ZERO, false));
            for (k, at) in (first..n).zip(at..) {
                self.lane_of[k].1 = at;
            }
        }
        let slot = self.slot(i);
        let at = slot.splats.len();
        // (`ShadowedSplats::push`'s test: a ray of no length is clear.)
        let Some(ray) = shadow.filter(|r| r.t_max > 0.0 || r.t_max.is_nan()) else {
            slot.splats.push((l, raster, true));
            return;
        };
        slot.splats.push((l, raster, false));
        slot.waiting += 1;
        let k = self.n_rays;
        for j in 0..3 {
            self.rays.o[j][k] = ray.o[j];
            self.rays.d[j][k] = ray.d[j];
        }
        self.rays.t_max[k] = ray.t_max;
        self.ray_of[k] = (i, at);
        self.n_rays += 1;
        if self.n_rays == LANES {
            self.test_rays(packets);
        }
    }

    /// The waiting shadow rays of connections computed alone, as one packet.
    fn test_rays(&mut self, packets: &ShadowPackets) {
        let n = self.n_rays;
        let blocked = packets.occluded_lanes(&self.rays, ((1u32 << n) - 1) as u8);
        for k in 0..n {
            let (i, at) = self.ray_of[k];
            let slot = self.slot(i);
            slot.splats[at].2 = blocked & (1 << k) == 0;
            slot.waiting -= 1;
        }
        self.n_rays = 0;
    }

    /// The leading samples whose connections are all made and known, splatted in order.
    fn release(&mut self, out: &mut SampleOut) {
        while self.open > 0 {
            let s = &mut self.slots[self.head];
            if !s.made || s.waiting > 0 {
                break;
            }
            for &(l, raster, splat) in &s.splats {
                if splat {
                    out.splats.push(Splat { raster, channel: 0, value: l, layers: 0 });
                }
            }
            s.splats.clear();
            s.made = false;
            self.head = if self.head + 1 == self.slots.len() { 0 } else { self.head + 1 };
            self.open -= 1;
            self.base += 1;
        }
    }

    /// The tile's end: what still waits is run and tested, and every sample splatted.
    fn finish(&mut self, batch: Option<&CameraBatch>, packets: &ShadowPackets, out: &mut SampleOut) {
        if let Some(batch) = batch.filter(|_| self.lanes.staged() > 0) {
            self.run_lanes(batch, packets);
        }
        if self.n_rays > 0 {
            self.test_rays(packets);
        }
        self.release(out);
        debug_assert_eq!(self.open, 0);
    }
}

/// Checks shared by the methods that connect to the camera.
pub(crate) fn require_connectible_camera(scene: &Scene, method: &str) -> Result<()> {
    if matches!(scene.camera.projection, crate::camera::Projection::Orthographic) {
        return Err(Error::Settings(format!(
            "the {method} integrator connects paths to the camera, which an orthographic camera does not allow; use path or bdpt"
        )));
    }
    Ok(())
}

impl LightTracer {
    /// The render with its rays traced as `tracing` says (the image is the same).
    pub fn render_traced(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress, tracing: Tracing) -> Result<Film> {
        require_connectible_camera(scene, "light")?;
        let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
        let batch = CameraBatch::new(&cfg);
        let est = Estimator { cfg, packets: ShadowPackets::new(scene), tracing, batch };
        Ok(render_splatting(scene, settings, progress, &est, 0)?.film)
    }
}

impl Integrator for LightTracer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        self.render_traced(scene, settings, progress, Tracing::default())
    }
}
