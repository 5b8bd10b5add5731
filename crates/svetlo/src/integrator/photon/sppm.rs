//! Stochastic progressive photon mapping (Hachisuka & Jensen 2009).
//!
//! Each iteration: a camera pass finds, for every pixel, visible points (the diffuse vertices
//! of one camera path, see `camera.rs`; emission and NEE along it go straight into the
//! pixel), then a photon pass traces `photons` paths, and every visible point gathers the
//! photons within its radius. Per visible point (pixel and its n-th diffuse vertex) the
//! statistics N (photons), r (radius) and τ (flux) are updated as in the paper:
//! `N' = N + αM`, `r' = r sqrt(N' / (N + M))`, `τ' = (τ + Φ) r'² / r²`, and the pixel's
//! estimate is `Σ τ / (π r² · photons emitted so far)` plus the mean of the direct part.
//! Radii shrink to zero while the photons in them grow, so bias and variance both vanish.
//!
//! Photons of one segment are left out (NEE has direct light); depth as `photon`.
//! Iteration i's camera samples are sample i of each pixel and its photons are seeded by
//! (seed, i, photon index): the image is the same for any thread count. `--spp` is the number
//! of iterations; a time budget stops after a whole iteration.

use super::camera::camera_walk;
use super::map::{visible, Photon, Route, SAME_ORIENTATION_COS};
use super::trace::trace_photons;
use super::{parse_count, parse_pairs, parse_positive, pixel_footprint, segments_left};
use crate::accel::KdTree;
use crate::bsdf::{Bsdf, LobeFlags, TransportMode};
use crate::error::{Error, Result};
use crate::film::{Film, Filter};
use crate::geometry::SurfaceInteraction;
use crate::integrator::{Integrator, Progress, RenderSettings};
use crate::lpe::aov::LayerSample;
use crate::lpe::{AovSet, Tracker};
use crate::math::PI;
use crate::path::PathConfig;
use crate::sampling::sampler::make_sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::Ordering;
use std::time::Instant;

#[derive(Clone, Debug, PartialEq)]
pub struct SppmOptions {
    /// Photon paths per iteration; None: four per pixel (on bench/photon's indirect-room one per
    /// pixel left SPPM variance-limited: relMSE 6.5e-4 against 3.9e-4 with four, at equal time).
    pub photons: Option<u64>,
    /// Initial gather radius (scene units); None: 2 pixel footprints.
    pub radius: Option<f32>,
    /// Fraction of new photons kept per iteration (Hachisuka's α).
    pub alpha: f32,
    /// Visible points per pixel: the first this many diffuse vertices of a camera path (more
    /// come only through delta lobes of diffuse-and-specular surfaces, such as plastic).
    pub max_visible: u32,
    /// Count only photons the visible point sees (`map::visible`): no light leaks through thin
    /// walls. Photons on surfaces facing another way are left out in any case.
    pub visibility: bool,
}

impl Default for SppmOptions {
    fn default() -> Self {
        SppmOptions { photons: None, radius: None, alpha: 2.0 / 3.0, max_visible: 3, visibility: true }
    }
}

impl SppmOptions {
    /// `photons=N,radius=R,alpha=A,visible=N,visibility=true|false`.
    pub fn parse(params: &str) -> Result<Self> {
        let m = "sppm";
        let mut o = SppmOptions::default();
        for (k, v) in parse_pairs(m, params)? {
            match k {
                "photons" => o.photons = Some(parse_count(m, k, v)?.max(1)),
                "radius" => o.radius = Some(parse_positive(m, k, v)?),
                "alpha" => {
                    let a = parse_positive(m, k, v)?;
                    if a >= 1.0 {
                        return Err(Error::Settings(format!("sppm: alpha must be in (0, 1), got {a}")));
                    }
                    o.alpha = a;
                }
                "visible" => o.max_visible = parse_count(m, k, v)?.clamp(1, 16) as u32,
                "visibility" => o.visibility = v.parse().map_err(|_| Error::Settings(format!("sppm: visibility is true or false, got '{v}'")))?,
                _ => return Err(Error::Settings(format!("sppm: unknown option '{k}' (photons, radius, alpha, visible, visibility)"))),
            }
        }
        Ok(o)
    }
}

#[derive(Clone, Debug, Default)]
pub struct Sppm {
    pub options: SppmOptions,
}

/// Where one camera path met a diffuse surface this iteration.
struct VisiblePoint<'a> {
    si: SurfaceInteraction,
    bsdf: Bsdf,
    wo: Vec3,
    beta: Rgb,
    depth: i32,
    /// The path's events before it (AOVs).
    events: Tracker<'a>,
}

/// Progressive statistics of one visible-point slot (pixel, n-th diffuse vertex).
#[derive(Clone, Copy, Debug)]
struct Stats {
    r: f32,
    n: f32,
    tau: Rgb,
}

/// The progressive state of rows `rows` of an SPPM render after `iterations` iterations: all
/// a machine that renders those rows keeps from one iteration to the next. Pixels do not
/// share statistics (a visible point's radius shrinks by its own photon counts), so rows
/// advance apart once every machine has the iteration's photons.
#[derive(Clone, Debug)]
pub struct SppmRows {
    pub rows: Range<u32>,
    width: u32,
    slots: u32,
    /// Layers per slot and pixel: with AOVs each AOV's, then the (restricted) beauty's; 0 without.
    layers: u32,
    pub iterations: u32,
    stats: Vec<Stats>,
    /// Sum over iterations of the camera-side part (emission, NEE).
    direct: Vec<Rgb>,
    /// τ of each slot split by layer (`layers` per slot); the radii follow all photons, so
    /// the layers of a partition of path space sum to the beauty.
    tau_layers: Vec<Rgb>,
    /// The camera-side part split by layer (`layers` per pixel).
    direct_layers: Vec<Rgb>,
}

const ROWS_MAGIC: &[u8; 8] = b"SVLSPPM2";
const ROWS_HEADER: usize = 32;
/// More layers than any AOV set has: a header asking for more is malformed.
const MAX_LAYERS: u32 = 4096;

/// The layers an AOV set asks per slot and pixel.
fn layer_count(aovs: &AovSet) -> u32 {
    if aovs.is_empty() {
        0
    } else {
        aovs.aov_count() as u32 + 1
    }
}

impl SppmRows {
    /// Little-endian bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let rgbs = self.direct.len() + self.tau_layers.len() + self.direct_layers.len();
        let mut out = Vec::with_capacity(ROWS_HEADER + self.stats.len() * 20 + rgbs * 12);
        out.extend_from_slice(ROWS_MAGIC);
        for v in [self.rows.start, self.rows.end, self.width, self.slots, self.layers, self.iterations] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for st in &self.stats {
            for v in [st.r, st.n, st.tau.r, st.tau.g, st.tau.b] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        for d in self.direct.iter().chain(&self.tau_layers).chain(&self.direct_layers) {
            for v in [d.r, d.g, d.b] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    /// Read [`Self::to_bytes`]'s output; malformed bytes are an error.
    pub fn from_bytes(b: &[u8]) -> Result<SppmRows> {
        let bad = |m: String| Error::Invalid(format!("sppm rows: {m}"));
        if b.len() < ROWS_HEADER || &b[..8] != ROWS_MAGIC {
            return Err(bad("not svetlo SPPM rows (bad magic or short)".into()));
        }
        let u = |i: usize| u32::from_le_bytes(b[8 + 4 * i..12 + 4 * i].try_into().expect("4 bytes"));
        let (r0, r1, width, slots, layers, iterations) = (u(0), u(1), u(2), u(3), u(4), u(5));
        let px = (r1.saturating_sub(r0) as u64) * width as u64;
        // Sizes from the header are checked against the bytes before anything is allocated.
        let (s, l) = (slots as u64, layers as u64);
        let want = px.checked_mul(20 * s + 12 + 12 * s * l + 12 * l).and_then(|x| x.checked_add(ROWS_HEADER as u64));
        if r0 >= r1 || slots == 0 || slots > 16 || layers == 1 || layers > MAX_LAYERS || want != Some(b.len() as u64) {
            return Err(bad(format!("rows {r0}..{r1} of width {width} with {slots} slots and {layers} layers do not fit {} bytes", b.len())));
        }
        let f: Vec<f32> = b[ROWS_HEADER..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect();
        let (n_px, n_stats) = (px as usize, (px * s) as usize);
        let (sf, rest) = f.split_at(5 * n_stats);
        let stats = sf.chunks_exact(5).map(|c| Stats { r: c[0], n: c[1], tau: Rgb { r: c[2], g: c[3], b: c[4] } }).collect();
        let mut rgbs = rest.chunks_exact(3).map(|c| Rgb { r: c[0], g: c[1], b: c[2] });
        let direct = rgbs.by_ref().take(n_px).collect();
        let tau_layers = rgbs.by_ref().take(n_stats * layers as usize).collect();
        let direct_layers = rgbs.collect();
        Ok(SppmRows { rows: r0..r1, width, slots, layers, iterations, stats, direct, tau_layers, direct_layers })
    }
}

fn thread_pool(settings: &RenderSettings) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))
}

impl Sppm {
    /// Photon paths per iteration.
    pub fn photons_per_iteration(&self, scene: &Scene) -> u64 {
        self.options.photons.unwrap_or(4 * scene.camera.width as u64 * scene.camera.height as u64).max(1)
    }

    /// The state of rows `rows` before the first iteration (with room for `settings`' AOVs).
    pub fn start_rows(&self, scene: &Scene, settings: &RenderSettings, rows: Range<u32>) -> Result<SppmRows> {
        if rows.start >= rows.end || rows.end > scene.camera.height {
            return Err(Error::Settings(format!("sppm: rows {}..{} of a film {} high", rows.start, rows.end, scene.camera.height)));
        }
        let r0 = self.options.radius.unwrap_or(2.0 * pixel_footprint(scene));
        let (w, slots) = (scene.camera.width, self.options.max_visible);
        let px = (rows.end - rows.start) as usize * w as usize;
        let layers = layer_count(settings.aovs());
        Ok(SppmRows {
            rows,
            width: w,
            slots,
            layers,
            iterations: 0,
            stats: vec![Stats { r: r0, n: 0.0, tau: Rgb::BLACK }; px * slots as usize],
            direct: vec![Rgb::BLACK; px],
            tau_layers: vec![Rgb::BLACK; px * slots as usize * layers as usize],
            direct_layers: vec![Rgb::BLACK; px * layers as usize],
        })
    }

    /// Iteration `iteration`'s photon paths `range`, traced from the seed and their indices:
    /// ranges of an iteration traced apart and concatenated in order are its photons.
    /// With AOVs the photons carry their light state, for [`Route`].
    fn photons(&self, scene: &Scene, settings: &RenderSettings, iteration: u64, range: Range<u64>) -> Vec<Photon> {
        let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
        trace_photons(scene, settings.seed, iteration, range, &cfg, settings.aovs(), |_, d| {
            // Photons on diffuse surfaces, at least two segments from the light.
            let keep = (d.segments >= 2 && d.surface.intersects(LobeFlags::DIFFUSE)).then(|| Photon::from_deposit(d, 1.0));
            (keep, true)
        })
    }

    /// [`Self::photons`] as bytes, for [`Self::iterate_rows`] on another machine.
    pub fn photon_batch(&self, scene: &Scene, settings: &RenderSettings, iteration: u32, range: Range<u64>) -> Result<Vec<u8>> {
        if range.start >= range.end || range.end > self.photons_per_iteration(scene) || iteration >= settings.spp {
            return Err(Error::Settings(format!("sppm: photon paths {}..{} of iteration {iteration}", range.start, range.end)));
        }
        super::jensen::check_light_states("sppm", settings)?;
        let pool = thread_pool(settings)?;
        Ok(pool.install(|| super::map::photons_to_bytes(&self.photons(scene, settings, iteration as u64, range))))
    }

    /// Advance `state` by its next iteration, given that iteration's photons as batches from
    /// [`Self::photon_batch`] covering its photon paths in order.
    pub fn iterate_rows(&self, scene: &Scene, settings: &RenderSettings, state: &mut SppmRows, batches: &[&[u8]]) -> Result<()> {
        if (state.width, state.slots, state.layers) != (scene.camera.width, self.options.max_visible, layer_count(settings.aovs()))
            || state.rows.end > scene.camera.height
            || state.iterations >= settings.spp
        {
            return Err(Error::Settings(format!("sppm: rows state of another render (iteration {} of {})", state.iterations, settings.spp)));
        }
        let mut photons = Vec::new();
        for b in batches {
            super::map::photons_from_bytes(b, &mut photons)?;
        }
        let pool = thread_pool(settings)?;
        let tree = pool.install(|| KdTree::new(photons));
        pool.install(|| self.iterate(scene, settings, state, &tree));
        Ok(())
    }

    /// The film of rows that partition the image (any order), with `settings`' AOVs as layers.
    pub fn develop_rows(&self, scene: &Scene, settings: &RenderSettings, mut parts: Vec<SppmRows>) -> Result<Film> {
        let layers = layer_count(settings.aovs());
        parts.sort_by_key(|p| p.rows.start);
        let mut next = 0;
        let iterations = parts.first().map_or(0, |p| p.iterations);
        for p in &parts {
            if p.rows.start != next || (p.width, p.slots, p.layers, p.iterations) != (scene.camera.width, self.options.max_visible, layers, iterations) {
                return Err(Error::Invalid(format!(
                    "sppm: rows {}..{} (iteration {}) do not follow rows 0..{next} of one render",
                    p.rows.start, p.rows.end, p.iterations
                )));
            }
            next = p.rows.end;
        }
        if next != scene.camera.height {
            return Err(Error::Invalid(format!("sppm: rows cover 0..{next} of 0..{}", scene.camera.height)));
        }
        let mut all = SppmRows {
            rows: 0..next,
            width: scene.camera.width,
            slots: self.options.max_visible,
            layers,
            iterations,
            stats: Vec::new(),
            direct: Vec::new(),
            tau_layers: Vec::new(),
            direct_layers: Vec::new(),
        };
        for p in parts {
            all.stats.extend(p.stats);
            all.direct.extend(p.direct);
            all.tau_layers.extend(p.tau_layers);
            all.direct_layers.extend(p.direct_layers);
        }
        Ok(develop(scene, settings.aovs(), &all, self.photons_per_iteration(scene)))
    }

    /// One iteration of the rows of `state` (in the current thread pool): their camera pass,
    /// then every visible point gathers the photons of `tree` and updates its statistics.
    fn iterate(&self, scene: &Scene, settings: &RenderSettings, state: &mut SppmRows, tree: &KdTree<Photon>) {
        let o = &self.options;
        let cam = &scene.camera.ray_generator();
        let w = scene.camera.width as usize;
        let slots = o.max_visible as usize;
        let proto = make_sampler(settings.sampler, settings.spp, settings.seed);
        let it = state.iterations;
        let rows = state.rows.clone();
        let n_rows = rows.len();
        let aovs = settings.aovs();
        let nl = state.layers as usize;
        // Camera pass: rows in parallel, each pixel's visible points and direct part.
        type Pixel<'a> = (Rgb, LayerSample, Vec<Option<VisiblePoint<'a>>>);
        let vrows: Vec<Vec<Pixel>> = rows
            .into_par_iter()
            .with_max_len(1) // a row a task: see `splat::render_chunked`
            .map(|y| {
                let mut sampler = proto.clone_box();
                (0..w)
                    .map(|x| {
                        let (_, ray) = crate::integrator::camera_sample(cam, sampler.as_mut(), x as u32, y, it);
                        let mut vps: Vec<Option<VisiblePoint>> = (0..slots).map(|_| None).collect();
                        // The camera-side part split by layer (emission, NEE routed by path).
                        let mut layers = LayerSample::default();
                        let mut at_diffuse = |v: &super::camera::DiffuseVertex, _: &mut dyn crate::sampling::sampler::Sampler, _: Option<&mut LayerSample>| {
                            if let Some(slot) = vps.get_mut(v.index as usize) {
                                *slot = Some(VisiblePoint {
                                    si: *v.si,
                                    bsdf: v.bsdf.clone(),
                                    wo: v.wo,
                                    beta: v.beta,
                                    depth: v.depth,
                                    events: v.events.rebind(aovs),
                                });
                            }
                            Rgb::BLACK
                        };
                        let l = camera_walk(scene, &ray, sampler.as_mut(), settings, &mut at_diffuse, &mut layers);
                        (l, layers, vps)
                    })
                    .collect()
            })
            .collect();
        let alpha = o.alpha;
        let visibility = o.visibility;
        let max_depth = settings.max_depth;
        // Without layers each row gets a dummy chunk of one, so the zip below stays one type.
        let mut no_layers = Vec::new();
        let lrows = if nl == 0 {
            no_layers.resize(n_rows, Rgb::BLACK);
            no_layers.par_chunks_mut(1)
        } else {
            state.tau_layers.par_chunks_mut(w * slots * nl)
        };
        state.stats.par_chunks_mut(w * slots).zip(lrows).zip(vrows.par_iter()).for_each(|((srow, lrow), vrow)| {
            for (x, (_, _, vps)) in vrow.iter().enumerate() {
                for (s, vp) in vps.iter().enumerate() {
                    let Some(vp) = vp else { continue };
                    let st = &mut srow[x * slots + s];
                    let mut route = (nl > 0).then(|| Route::new(&vp.events, &vp.si, vp.bsdf.flags()));
                    let left = segments_left(max_depth, vp.depth);
                    let mut phi = Rgb::BLACK;
                    let mut m = 0u32;
                    // Lifted off the surface on the seen side, for the visibility test.
                    let n = if vp.si.wo.dot(vp.si.ng) >= 0.0 { vp.si.ng } else { -vp.si.ng };
                    tree.for_each_in_radius(vp.si.p, st.r, |ph, _| {
                        if (ph.segments as i32) > left {
                            return;
                        }
                        let wi = vp.si.to_local(ph.wi);
                        let cos_g = ph.wi.dot(vp.si.ng).abs();
                        if cos_g <= 0.0 {
                            return;
                        }
                        let f = vp.bsdf.eval(vp.wo, wi, TransportMode::Radiance);
                        if f.is_black() || ph.n.dot(n) <= SAME_ORIENTATION_COS || (visibility && !visible(scene, vp.si.p, n, ph.p, ph.n, vp.si.time)) {
                            return;
                        }
                        let v = f * ph.power * (wi.z.abs() / cos_g);
                        phi += v;
                        m += 1;
                        if let Some(rt) = &mut route {
                            rt.add_photon(ph, vp.si.ng, vp.si.wo.dot(vp.si.ng) > 0.0, v);
                        }
                    });
                    if m > 0 {
                        let n_new = st.n + alpha * m as f32;
                        let ratio = n_new / (st.n + m as f32);
                        st.tau = (st.tau + vp.beta * phi) * ratio;
                        if let Some(rt) = &route {
                            let tl = &mut lrow[(x * slots + s) * nl..(x * slots + s + 1) * nl];
                            let (aov, beauty) = tl.split_at_mut(nl - 1);
                            for (t, p) in aov.iter_mut().zip(&rt.out.aov) {
                                *t = (*t + vp.beta * *p) * ratio;
                            }
                            beauty[0] = (beauty[0] + vp.beta * rt.out.beauty) * ratio;
                        }
                        st.r *= ratio.sqrt();
                        st.n = n_new;
                    }
                }
            }
        });
        for (yi, row) in vrows.iter().enumerate() {
            for (x, (l, ls, _)) in row.iter().enumerate() {
                let px = yi * w + x;
                state.direct[px] += if l.is_finite() { *l } else { Rgb::BLACK };
                if nl > 0 {
                    let d = &mut state.direct_layers[px * nl..(px + 1) * nl];
                    for (t, v) in d.iter_mut().zip(ls.aov.iter().take(nl - 1).chain([&ls.beauty])) {
                        *t += if v.is_finite() { *v } else { Rgb::BLACK };
                    }
                }
            }
        }
        state.iterations += 1;
    }
}

impl Integrator for Sppm {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        settings.validate()?;
        super::jensen::check_light_states("sppm", settings)?;
        let start = Instant::now();
        let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
        let per_iter = self.photons_per_iteration(scene);
        let pool = thread_pool(settings)?;
        // The whole image is one block of rows, advanced by the steps a distributed render
        // takes apart (photon_batch, iterate_rows, develop_rows).
        let mut state = self.start_rows(scene, settings, 0..h as u32)?;
        progress.total.store(settings.spp as u64 * (w * h) as u64, Ordering::Relaxed);
        let mut per_iteration_s = 0.0f64;
        while state.iterations < settings.spp {
            if progress.cancelled() {
                break;
            }
            if let Some(t) = settings.time_limit {
                // Start an iteration only if it should end within the budget.
                let el = start.elapsed().as_secs_f64();
                if el >= t.as_secs_f64() || (state.iterations > 0 && el + per_iteration_s > t.as_secs_f64()) {
                    break;
                }
            }
            let tree = pool.install(|| KdTree::new(self.photons(scene, settings, state.iterations as u64, 0..per_iter)));
            if progress.cancelled() {
                break;
            }
            pool.install(|| self.iterate(scene, settings, &mut state, &tree));
            per_iteration_s = start.elapsed().as_secs_f64() / state.iterations as f64;
            progress.done.fetch_add((w * h) as u64, Ordering::Relaxed);
            if progress.wants_pass(state.iterations) {
                progress.pass_done(&develop(scene, settings.aovs(), &state, per_iter));
            }
        }
        Ok(develop(scene, settings.aovs(), &state, per_iter))
    }
}

/// The image of rows covering the film after their iterations: each pixel is its own
/// measurement (box reconstruction); with AOVs their layers too, and a restricted beauty
/// when the AOV set restricts it.
fn develop(scene: &Scene, aovs: &AovSet, state: &SppmRows, per_iter: u64) -> Film {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let (slots, nl, iterations) = (state.slots as usize, state.layers as usize, state.iterations);
    let mut film = Film::with_layers(scene.camera.width, scene.camera.height, Filter::Box, aovs.names());
    if iterations > 0 {
        let emitted = per_iter as f64 * iterations as f64;
        let mut layers = vec![Rgb::BLACK; nl];
        for y in 0..h {
            for x in 0..w {
                let px = y * w + x;
                let mut l = state.direct[px] / iterations as f32;
                for (t, d) in layers.iter_mut().zip(&state.direct_layers[px * nl..]) {
                    *t = *d / iterations as f32;
                }
                for s in 0..slots {
                    let st = &state.stats[px * slots + s];
                    if st.n > 0.0 {
                        let area_photons = (PI as f64 * st.r as f64 * st.r as f64 * emitted) as f32;
                        l += st.tau / area_photons;
                        for (t, v) in layers.iter_mut().zip(&state.tau_layers[(px * slots + s) * nl..]) {
                            *t += *v / area_photons;
                        }
                    }
                }
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                match layers.split_last() {
                    None => film.add_sample(p, l),
                    Some((beauty, aov)) => film.add_sample_layers(p, if aovs.restricts_beauty() { *beauty } else { l }, aov),
                }
            }
        }
    }
    film.spp_done = iterations;
    film
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse() {
        let o = SppmOptions::parse("photons=5000,radius=0.25,alpha=0.5,visible=2").unwrap();
        assert_eq!(o, SppmOptions { photons: Some(5000), radius: Some(0.25), alpha: 0.5, max_visible: 2, visibility: true });
        assert!(!SppmOptions::parse("visibility=false").unwrap().visibility);
        assert_eq!(SppmOptions::parse("").unwrap(), SppmOptions::default());
        for bad in ["alpha=1", "alpha=0", "alpha=-1", "radius=inf", "photons=x", "k=3", "photons", "visibility=maybe"] {
            assert!(SppmOptions::parse(bad).is_err(), "{bad}");
        }
    }
}
