//! The pixel-sample driver of every camera-side method: passes over tiles in parallel, each
//! pixel sample filtered into its tile and, for methods that also write away from their own
//! pixel (light tracing, BDPT's t = 1), emitting splats ([`render_pixels`](super::render_pixels)
//! is this driver with nothing to splat). Tiles keep their splats in lists, added to
//! pass-local buffers in tile order (tiles run in chunks, bounding the lists' memory) that
//! join the film when the pass is complete, so the image does not depend on the number of
//! threads or on scheduling. Besides the film, an estimator may feed extra images
//! ("channels", box reconstruction, divided by the spp at the end), e.g. one per strategy.

use super::passes::{self, next_pass_spp, pass_plan};
use super::{Progress, RenderSettings};
use crate::accel::packet::{Rays8, LANES};
use crate::error::{Error, Result};
use crate::film::{Film, FilmTile, Filter};
use crate::geometry::Ray;
use crate::path::ShadowPackets;
use crate::sampling::{sampler::make_sampler, Sampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;
use rayon::prelude::*;
use std::sync::atomic::Ordering;
use std::time::Instant;

const TILE: u32 = 16;
/// Pixel samples per chunk of tiles, bounding the memory splat lists take.
const MAX_PASS_SAMPLES: u64 = 1 << 19;

/// A contribution away from the filtered pixel sample: channel 0 is the film's splat
/// buffer, channel c > 0 the extra image c - 1, [`NO_CHANNEL`] none of them; and bit i of
/// `layers` AOV layer i (one entry for all the layers a contribution goes to).
#[derive(Clone, Copy, Debug)]
pub struct Splat {
    pub raster: Vec2,
    pub channel: u32,
    pub value: Rgb,
    pub layers: u32,
}

/// A splat for AOV layers only (a restricted beauty that does not take it).
pub const NO_CHANNEL: u32 = u32::MAX;

/// What one pixel sample produced.
pub struct SampleOut<'a> {
    pub splats: &'a mut Vec<Splat>,
    /// The sample's own-pixel contributions per AOV layer (and to a restricted beauty).
    pub layers: crate::lpe::aov::LayerSample,
}

impl SampleOut<'_> {
    /// Splat `value` to the beauty and the AOV layers of `mask`.
    #[inline]
    pub fn splat_layers(&mut self, mask: crate::lpe::LayerMask, raster: Vec2, value: Rgb) {
        let channel = if mask & crate::lpe::aov::BEAUTY != 0 { 0 } else { NO_CHANNEL };
        let layers = mask & !crate::lpe::aov::BEAUTY;
        if channel != NO_CHANNEL || layers != 0 {
            self.push_layers(channel, raster, value, layers);
        }
    }
    #[inline]
    pub fn splat(&mut self, raster: Vec2, value: Rgb) {
        self.push(0, raster, value);
    }
    #[inline]
    pub fn push(&mut self, channel: u32, raster: Vec2, value: Rgb) {
        self.push_layers(channel, raster, value, 0);
    }
    #[inline]
    fn push_layers(&mut self, channel: u32, raster: Vec2, value: Rgb, layers: u32) {
        if !value.is_black() && value.is_finite() {
            self.splats.push(Splat { raster, channel, value, layers });
        }
    }
}

/// Splats waiting for their shadow rays, in the order they were made: the rays of
/// consecutive connections (to the camera, from one light path or several) go as one packet
/// (`path::ShadowPackets`), and the splats leave in that order, so the splat list is that
/// of testing each ray alone.
pub(crate) struct ShadowedSplats {
    splats: [(Rgb, Vec2); LANES],
    /// The waiting rays in the packet's lanes, stored there as they come (not copied in at
    /// the flush); `active`: the lanes that have a ray to test. Lanes out of `active` keep
    /// older rays, which the packet walk does not look at.
    rays: Rays8,
    active: u8,
    n: usize,
}

impl ShadowedSplats {
    /// A segment of no length cannot be blocked: a ray of no length, which no packet tests.
    pub const CLEAR: Ray = Ray { o: glam::Vec3::ZERO, d: glam::Vec3::Z, t_max: 0.0, time: 0.0 };

    pub fn new() -> ShadowedSplats {
        ShadowedSplats { splats: [(Rgb::BLACK, Vec2::ZERO); LANES], rays: Rays8::default(), active: 0, n: 0 }
    }

    /// Splat `l` at `raster` unless `shadow` is blocked.
    #[inline]
    pub fn push(&mut self, packets: &ShadowPackets, l: Rgb, raster: Vec2, shadow: Ray, out: &mut SampleOut) {
        let i = self.n;
        self.splats[i] = (l, raster);
        // (`ShadowPackets::occluded`'s lanes: a ray of no length is clear.)
        if shadow.t_max > 0.0 || shadow.t_max.is_nan() {
            for k in 0..3 {
                self.rays.o[k][i] = shadow.o[k];
                self.rays.d[k][i] = shadow.d[k];
            }
            self.rays.t_max[i] = shadow.t_max;
            self.active |= 1 << i;
        }
        self.n += 1;
        if self.n == LANES {
            self.flush(packets, out);
        }
    }

    /// Test the waiting rays and splat the clear ones (at the end of a tile).
    pub fn flush(&mut self, packets: &ShadowPackets, out: &mut SampleOut) {
        let blocked = packets.occluded_lanes(&self.rays, self.active);
        for (i, &(l, r)) in self.splats[..self.n].iter().enumerate() {
            if blocked & (1 << i) == 0 {
                out.splat(r, l);
            }
        }
        self.n = 0;
        self.active = 0;
    }
}

/// One pixel sample of a method that splats.
pub trait SplatEstimator: Sync {
    /// Per-thread scratch space (subpath buffers), reused across samples.
    type Scratch: Send;
    fn scratch(&self) -> Self::Scratch;
    /// Whether the estimator reports its contributions by path (AOVs, `--lpe`).
    fn supports_lpe(&self) -> bool {
        false
    }
    /// Radiance to add at `raster` through the pixel filter; light-side results go to `out`.
    #[allow(clippy::too_many_arguments)]
    fn sample(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        ray: &Ray,
        raster: Vec2,
        sampler: &mut dyn Sampler,
        scratch: &mut Self::Scratch,
        out: &mut SampleOut,
    ) -> Rgb;

    /// Samples `s0..s0 + n` of every pixel of the tile, pixels in rows and samples innermost
    /// (the order that makes the image independent of the thread count). The default draws
    /// each camera sample and calls [`Self::sample`]; kernels that trace many paths at once
    /// take the whole tile.
    fn render_tile(&self, t: TileJob, sampler: &mut dyn Sampler, scratch: &mut Self::Scratch, splats: &mut Vec<Splat>) {
        render_tile_by_sample(self, t, sampler, scratch, splats);
    }
}

/// [`SplatEstimator::render_tile`]'s default: each camera sample drawn and given to
/// [`SplatEstimator::sample`] (for estimators that batch only in some renders).
pub fn render_tile_by_sample<E: SplatEstimator + ?Sized>(est: &E, t: TileJob, sampler: &mut dyn Sampler, scratch: &mut E::Scratch, splats: &mut Vec<Splat>) {
    let [x0, y0, x1, y1] = t.rect;
    let cam = t.scene.camera.ray_generator();
    let aovs = t.settings.aovs();
    let mut out = SampleOut { splats, layers: Default::default() };
    for y in y0..y1 {
        for x in x0..x1 {
            for s in t.s0..t.s0 + t.n {
                let (raster, ray) = super::camera_sample(&cam, sampler, x, y, s);
                let l = est.sample(t.scene, t.settings, &ray, raster, sampler, scratch, &mut out);
                if aovs.is_empty() {
                    t.tile.add_sample(raster, l);
                } else {
                    let beauty = if aovs.restricts_beauty() { out.layers.beauty } else { l };
                    t.tile.add_sample_touched(raster, beauty, &out.layers.aov[..aovs.aov_count()], out.layers.touched);
                    out.layers.clear();
                }
            }
        }
    }
}

/// One tile's share of a pass: samples `s0..s0 + n` of its pixels.
pub struct TileJob<'a> {
    pub scene: &'a Scene,
    pub settings: &'a RenderSettings,
    /// The tile's own pixels `[x0, y0, x1, y1)`. The film tile is larger by the filter's
    /// radius (samples near the border reach the neighbours): only `rect` is sampled.
    pub rect: [u32; 4],
    pub tile: &'a mut FilmTile,
    pub s0: u32,
    pub n: u32,
}

/// The film (splats scaled by the spp done) and the extra channels (already divided by it).
pub struct SplatRender {
    pub film: Film,
    pub channels: Vec<Vec<Rgb>>,
}

/// Render with an estimator that splats; `channels` extra images of the film's size.
pub fn render_splatting<E: SplatEstimator>(scene: &Scene, settings: &RenderSettings, progress: &Progress, est: &E, channels: usize) -> Result<SplatRender> {
    render_chunked(scene, settings, progress, est, channels, MAX_PASS_SAMPLES)
}

/// `render_splatting` with at most about `chunk_samples` pixel samples per chunk of tiles.
pub(super) fn render_chunked<E: SplatEstimator>(
    scene: &Scene,
    settings: &RenderSettings,
    progress: &Progress,
    est: &E,
    channels: usize,
    chunk_samples: u64,
) -> Result<SplatRender> {
    settings.validate()?;
    settings.check_lpe_support("this method", est.supports_lpe())?;
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let tiles: Vec<(u32, u32, u32, u32)> = (0..h.div_ceil(TILE))
        .flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx * TILE, ty * TILE, ((tx + 1) * TILE).min(w), ((ty + 1) * TILE).min(h))))
        .collect();
    progress.total.store(settings.spp as u64 * w as u64 * h as u64, Ordering::Relaxed);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))?;
    let start = Instant::now();
    let proto = make_sampler(settings.sampler, settings.spp, settings.seed);
    // Untimed renders follow the fixed pass plan, and may be asked for one node of its tree.
    let plan = settings.time_limit.is_none().then(|| pass_plan(settings.spp, w as u64 * h as u64));
    let range = match (&settings.pass_range, &plan) {
        (Some(r), Some(plan)) => {
            if !passes::is_node(r, plan.len() as u32) {
                return Err(Error::Settings(format!(
                    "passes {}..{} are not a node of the pass tree of this render ({} passes for {} spp)",
                    r.start,
                    r.end,
                    plan.len(),
                    settings.spp
                )));
            }
            progress.total.store(plan[r.start as usize..r.end as usize].iter().map(|p| p.1 as u64).sum::<u64>() * w as u64 * h as u64, Ordering::Relaxed);
            r.clone()
        }
        (Some(_), None) => return Err(Error::Settings("a range of passes needs a render without a time limit".into())),
        (None, Some(plan)) => 0..plan.len() as u32,
        (None, None) => 0..u32::MAX,
    };
    let layout = PassLayout { w, h, filter: settings.filter, names: settings.aovs().names(), channels };
    let add = |a: &mut PassSum, b: &PassSum| {
        a.0.add(&b.0);
        for (d, s) in a.1.iter_mut().zip(&b.1) {
            for (x, y) in d.iter_mut().zip(s) {
                *x += *y;
            }
        }
    };
    let mut sum: passes::TreeSum<PassSum> = passes::TreeSum::default();
    // Pass sums folded into the tree, reused for later passes.
    let mut spare: Vec<PassSum> = Vec::new();
    // Box tiles share no pixel (`Film::tile`): each tile's passes then add up by the pass
    // tree on their own, with the bits the pass films' tree would give, and the pass films
    // keep only splats; no pass copies its tiles into a film or clears one.
    let own_tiles = settings.filter == Filter::Box;
    let mut tile_sums: Vec<passes::TreeSum<FilmTile>> = if own_tiles { tiles.iter().map(|_| Default::default()).collect() } else { Vec::new() };
    let mut tile_spare: Vec<Vec<FilmTile>> = vec![Vec::new(); tile_sums.len()];
    // Tiles go in chunks so that the splat lists in memory stay bounded on large films; each
    // chunk's splats go into its pass's film in chunk and tile order (so each pixel sums them
    // in an order fixed by the tiles, whatever the threads). The chunks form a pipeline: while
    // the workers render one, one of them adds the previous chunk's splats and tiles to its
    // pass (`rayon::join`), so no thread waits for that serial merge (light tracing's splats
    // took 4-5 % of the CPU on the main thread while the workers idled). Passes are begun in
    // order and finished in order, at most two at a time.
    let mut open: std::collections::VecDeque<OpenPass> = std::collections::VecDeque::new();
    // The chunk rendered last and not yet merged: it belongs to `open`'s front.
    let mut pending: Option<ChunkResults> = None;
    let mut spp_done = 0u32;
    // Samples per pixel of the passes begun (finished or not), for timed pass sizes.
    let mut spp_begun = 0u32;
    let mut pass_spp = 1u32;
    let mut pass = range.start;
    let mut cancelled = false;
    loop {
        // The next chunk to render: the open pass's next one, or the first of a new pass.
        // A timed render sizes a pass by the time its finished passes took, so it begins one
        // only when none is open (no pipelining across its passes).
        let busy = open.back().is_some_and(|p| p.chunks_begun < p.chunks) || (plan.is_none() && (!open.is_empty() || pending.is_some()));
        if !busy && !cancelled {
            let next = match (&plan, settings.time_limit) {
                (Some(plan), _) if pass < range.end => Some(plan[pass as usize]),
                (None, Some(limit)) if spp_begun < settings.spp => {
                    if spp_begun > 0 {
                        let timing = (limit.as_secs_f64(), start.elapsed().as_secs_f64(), spp_done);
                        pass_spp = next_pass_spp(pass_spp, settings.spp, w as u64 * h as u64, Some(timing));
                    }
                    Some((spp_begun, pass_spp.min(settings.spp - spp_begun)))
                }
                _ => None,
            };
            let stop = progress.cancelled() || settings.time_limit.is_some_and(|t| start.elapsed() >= t);
            if let (Some((s0, n)), false) = (next, stop) {
                // Cleared or made by the worker that merges the pass's first chunk.
                let sum = spare.pop();
                let tiles_per_chunk = ((chunk_samples / (n as u64 * (TILE * TILE) as u64)).max(1)).min(tiles.len().max(1) as u64) as usize;
                open.push_back(OpenPass {
                    s0,
                    n,
                    sum,
                    ready: false,
                    tiles: Vec::with_capacity(tiles.len()),
                    tiles_per_chunk,
                    chunks: tiles.len().div_ceil(tiles_per_chunk),
                    chunks_begun: 0,
                });
                pass += 1;
                spp_begun += n;
            }
        }
        let job = match open.back_mut() {
            Some(p) if p.chunks_begun < p.chunks && !cancelled => {
                let ci = p.chunks_begun;
                p.chunks_begun += 1;
                let first = ci * p.tiles_per_chunk;
                let chunk = &tiles[first..(first + p.tiles_per_chunk).min(tiles.len())];
                // Tiles folded into their sums before (the workers clear them); the workers
                // make the others.
                let job_tiles: Vec<Option<FilmTile>> = (first..first + chunk.len()).map(|i| tile_spare.get_mut(i).and_then(|s| s.pop())).collect();
                Some((chunk, job_tiles, p.s0, p.n))
            }
            _ => None,
        };
        if job.is_none() && pending.is_none() {
            break;
        }
        // The pending chunk's pass, taken out for the merge (and back unless it is complete).
        // (Not `zip`: its argument, the pop, would run with nothing pending too.)
        let merging = pending.take().and_then(|r| open.pop_front().map(|p| (r, p)));
        let render = |(chunk, job_tiles, s0, n): ChunkJob| -> ChunkResults {
            chunk
                .par_iter()
                .zip(job_tiles)
                // One tile a task: rayon's adaptive split leaves each worker runs of about
                // tiles / (2 threads) that are never split again unless stolen, and the last
                // such run kept one thread busy while the others waited 10 % of each pass.
                .with_max_len(1)
                .map(|(&(x0, y0, x1, y1), tile)| {
                    if progress.cancelled() {
                        return None;
                    }
                    // Made and cleared here, not on the calling thread while the workers wait
                    // (a few ms at each of the first passes' boundaries, before tiles recycle).
                    let mut tile = tile.unwrap_or_else(|| Film::tile_of(w, h, layout.filter, layout.names.len(), x0, y0, x1, y1));
                    tile.clear();
                    let mut splats = Vec::new();
                    let mut sampler = proto.clone_box();
                    let mut scratch = est.scratch();
                    let job = TileJob { scene, settings, rect: [x0, y0, x1, y1], tile: &mut tile, s0, n };
                    est.render_tile(job, sampler.as_mut(), &mut scratch, &mut splats);
                    progress.done.fetch_add(n as u64 * ((x1 - x0) * (y1 - y0)) as u64, Ordering::Relaxed);
                    Some((tile, splats))
                })
                .collect()
        };
        // A complete pass joins the sums in the merging task too: its tiles' tree sums and the
        // pass tree's film additions are no serial step between chunks either.
        let all_tiles = tiles.len();
        let (sums, tile_sums_ref, tile_spare_ref, spare_ref) = (&mut sum, &mut tile_sums, &mut tile_spare, &mut spare);
        let layout = &layout;
        let merge = move |(results, mut p): (ChunkResults, OpenPass)| -> Merged {
            if !p.merge_chunk(results, layout) {
                return Merged::Cancelled;
            }
            if p.tiles.len() < all_tiles {
                return Merged::Chunk(Box::new(p));
            }
            let OpenPass { n, sum, tiles: pass_tiles, .. } = p;
            let (mut film, extra) = sum.unwrap_or_else(|| layout.new_sum());
            if own_tiles {
                for ((t, s), spare) in pass_tiles.into_iter().zip(tile_sums_ref.iter_mut()).zip(tile_spare_ref.iter_mut()) {
                    s.push_recycling(t, |a, b| a.add(b), spare);
                }
            } else {
                for t in &pass_tiles {
                    film.merge_tile(t);
                }
            }
            film.spp_done = n;
            sums.push_recycling((film, extra), add, spare_ref);
            Merged::Pass(n)
        };
        let (merged, rendered) = pool.install(|| rayon::join(|| merging.map(merge), || job.map(render)));
        match merged {
            Some(Merged::Cancelled) => cancelled = true,
            Some(Merged::Chunk(p)) => open.push_front(*p),
            Some(Merged::Pass(n)) => {
                spp_done += n;
                if progress.wants_pass(spp_done) {
                    // The splats' scale so far, so that an observer sees a developed image.
                    if let Some((mut f, _)) = sum.peek(add) {
                        for t in tile_sums.iter().filter_map(|s| s.peek(|a, b| a.add(b))) {
                            f.merge_tile(&t);
                        }
                        f.splat_scale = spp_done as f32;
                        progress.pass_done(&f);
                    }
                }
            }
            None => {}
        }
        if cancelled {
            break; // cancelled mid-pass: the incomplete passes are dropped
        }
        pending = rendered;
    }
    let (mut film, mut extra) = sum.finish(|a, b| add(a, &b)).unwrap_or_else(|| layout.new_sum());
    for t in tile_sums.into_iter().filter_map(|s| s.finish(|a, b| a.add(&b))) {
        film.merge_tile(&t);
    }
    film.spp_done = spp_done;
    // Each pixel sample traced one light path: N = W H spp paths, and the camera's
    // importance is normalised so that splats scale by W H / N = 1 / spp.
    film.splat_scale = spp_done.max(1) as f32;
    let inv = 1.0 / spp_done.max(1) as f32;
    for img in &mut extra {
        for p in img.iter_mut() {
            *p *= inv;
        }
    }
    Ok(SplatRender { film, channels: extra })
}

/// What merging a chunk into its pass came to.
enum Merged {
    /// A tile of the chunk was cancelled: the pass stays incomplete.
    Cancelled,
    /// The pass awaits more chunks.
    Chunk(Box<OpenPass>),
    /// The pass (of this many samples per pixel) was complete and joined the sums.
    Pass(u32),
}

/// A chunk's tiles with their splats, in tile order; None where cancelled.
type ChunkResults = Vec<Option<(FilmTile, Vec<Splat>)>>;

/// A chunk to render: its tiles' rectangles, their recycled film tiles (None: to be made),
/// and the pass's samples.
type ChunkJob<'a> = (&'a [(u32, u32, u32, u32)], Vec<Option<FilmTile>>, u32, u32);

/// A pass's film and extra channels; passes add up by the pass tree.
type PassSum = (Film, Vec<Vec<Rgb>>);

/// What a pass's film and channels look like, to make them on a worker.
struct PassLayout<'a> {
    w: u32,
    h: u32,
    filter: Filter,
    names: &'a [String],
    channels: usize,
}

impl PassLayout<'_> {
    fn new_sum(&self) -> PassSum {
        (Film::with_layers(self.w, self.h, self.filter, self.names), vec![vec![Rgb::BLACK; (self.w * self.h) as usize]; self.channels])
    }
}

/// A pass begun and not yet in the sums: its film and channels take its chunks' splats and
/// its tiles, chunk by chunk in order.
struct OpenPass {
    s0: u32,
    n: u32,
    /// The pass's film and channels once its first chunk is merged; before, a recycled sum
    /// still to be cleared, or None (to be made). Clearing or making it (megabytes of zeros)
    /// is the merging worker's work, not the calling thread's while the workers wait.
    sum: Option<PassSum>,
    ready: bool,
    /// The tiles of the chunks merged so far, in tile order.
    tiles: Vec<FilmTile>,
    tiles_per_chunk: usize,
    chunks: usize,
    chunks_begun: usize,
}

impl OpenPass {
    /// Adds one chunk's results (in tile order) to the pass; false when a tile of it was
    /// cancelled, which leaves the pass incomplete.
    fn merge_chunk(&mut self, results: ChunkResults, layout: &PassLayout) -> bool {
        if results.iter().any(|t| t.is_none()) {
            return false;
        }
        if !self.ready {
            match &mut self.sum {
                Some((f, e)) => {
                    f.clear();
                    e.iter_mut().for_each(|c| c.fill(Rgb::BLACK));
                }
                None => self.sum = Some(layout.new_sum()),
            }
            self.ready = true;
        }
        let Some((film, extra)) = self.sum.as_mut() else { return false };
        let (w, h) = (layout.w, layout.h);
        for (t, splats) in results.into_iter().flatten() {
            self.tiles.push(t);
            if splats.iter().all(|sp| sp.channel == 0 && sp.layers == 0) {
                // Beauty splats only (light tracing's): the film's loop over them.
                film.splat_pixels(splats.iter().filter_map(|sp| Some((pixel_index(sp.raster.x, w)?, pixel_index(sp.raster.y, h)?, sp.value))));
                continue;
            }
            for sp in splats {
                let (Some(x), Some(y)) = (pixel_index(sp.raster.x, w), pixel_index(sp.raster.y, h)) else {
                    continue;
                };
                match sp.channel {
                    0 => film.splat_pixel(x, y, sp.value),
                    NO_CHANNEL => {}
                    c => {
                        if let Some(e) = extra.get_mut(c as usize - 1) {
                            e[(y * w + x) as usize] += sp.value;
                        }
                    }
                }
                if sp.layers != 0 {
                    film.splat_layers(sp.layers, Vec2::new(x as f32 + 0.5, y as f32 + 0.5), sp.value);
                }
            }
        }
        true
    }
}

/// The pixel column (row) of raster coordinate `v` on a film `n` pixels wide (high); None
/// outside it, and for NaN. `v.floor() as u32` for `v >= 0` is `v as u32`, so this is the
/// floor without the software `floorf` call of baseline x86-64 (no SSE4.1): the splat merge
/// called it twice per splat (~1.4 % of a light-tracing render's instructions). The result
/// as f32 plus 0.5 is `v.floor() + 0.5`, bit for bit.
#[inline]
fn pixel_index(v: f32, n: u32) -> Option<u32> {
    (v >= 0.0).then_some(v as u32).filter(|&i| i < n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Material;
    use crate::camera::{Camera, Projection};
    use crate::geometry::{Geometry, Sphere};
    use crate::light::Light;
    use crate::scene::SceneBuilder;
    use crate::texture::Texture;
    use glam::{Mat4, Vec3};

    /// Splitting the tiles into chunks changes neither the image nor the channels.
    #[test]
    fn pass_sizes_without_time_limit_depend_on_nothing_but_the_film() {
        // The image is the sum of its passes in order: their sizes must not follow timing.
        let mut seq = vec![1u32];
        while seq.len() < 9 {
            seq.push(next_pass_spp(*seq.last().unwrap_or(&1), 4096, 256 * 256, None));
        }
        assert_eq!(seq, [1, 2, 4, 8, 16, 32, 64, 64, 64]);
        assert_eq!(next_pass_spp(8, 4096, 1920 * 1080, None), 2, "large films take small passes");
        assert_eq!(next_pass_spp(8, 4096, 8000 * 8000, None), 1);
        assert_eq!(next_pass_spp(8, 64, 256 * 256, None), 8, "at least MIN_PASSES passes");
        // With a time limit the passes end near it.
        assert_eq!(next_pass_spp(1, 4096, 100, Some((10.0, 9.9, 100))), 1);
        assert_eq!(next_pass_spp(1, 4096, 100, Some((10.0, 1.0, 100))), 50);
    }

    /// A point-lit diffuse ball seen by a `w` x `h` pinhole camera.
    fn lit_ball(w: u32, h: u32) -> crate::scene::Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.6)) });
        b.add_shape(Geometry::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 4.0), radius: 1.5, flip_normals: false }), m, None, "ball").unwrap();
        b.add_light(Light::Point { position: Vec3::new(1.0, 2.0, 0.0), intensity: Rgb::splat(10.0) });
        b.set_camera(Camera {
            to_world: Mat4::IDENTITY,
            projection: Projection::Perspective { fov_x_deg: 50.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: w,
            height: h,
            near_clip: 0.01,
            far_clip: 100.0,
            shutter_open: 0.0,
            shutter_close: 0.0,
        });
        b.build().unwrap()
    }

    #[test]
    fn chunking_does_not_change_the_image() {
        let scene = lit_ball(40, 36);
        let settings = RenderSettings { spp: 3, max_depth: 3, ..Default::default() };
        let est = crate::integrator::bdpt::test_estimator(&scene, &settings);
        let big = render_chunked(&scene, &settings, &Progress::new(), &est, 2, u64::MAX).unwrap();
        let small = render_chunked(&scene, &settings, &Progress::new(), &est, 2, 1).unwrap();
        assert!(big.film.image().mean().max_component() > 0.0);
        assert_eq!(big.film.image().data, small.film.image().data);
        assert_eq!(big.channels, small.channels);
    }

    /// An observer sees every pass, in order, with developed splats; the last film it sees is
    /// the render's result; watching changes nothing in the image.
    #[test]
    fn observer_sees_each_pass_and_changes_nothing() {
        use std::sync::{Arc, Mutex};
        let scene = lit_ball(24, 20);
        let settings = RenderSettings { spp: 6, max_depth: 3, ..Default::default() };
        let est = crate::integrator::bdpt::test_estimator(&scene, &settings);
        type Passes = Mutex<Vec<(u32, Vec<Rgb>)>>;
        let seen: Arc<Passes> = Arc::default();
        let log = seen.clone();
        let progress = Progress::observed(move |f: &Film| log.lock().unwrap().push((f.spp_done, f.image().data)));
        let watched = render_chunked(&scene, &settings, &progress, &est, 0, u64::MAX).unwrap();
        let plain = render_chunked(&scene, &settings, &Progress::new(), &est, 0, u64::MAX).unwrap();
        assert_eq!(watched.film.image().data, plain.film.image().data);
        let seen = seen.lock().unwrap();
        assert!(!seen.is_empty());
        assert!(seen.windows(2).all(|w| w[0].0 < w[1].0), "passes in order");
        let (spp, last) = seen.last().unwrap();
        assert_eq!(*spp, 6);
        assert_eq!(*last, plain.film.image().data, "the last pass shown is the result, splats scaled");
    }

    /// A watcher that declines passes is asked about each one and shown only those it wants.
    #[test]
    fn declined_passes_are_not_shown() {
        use crate::integrator::PassObserver;
        use std::sync::Mutex;
        struct OnlyTheEnd {
            asked: Mutex<Vec<u32>>,
            shown: Mutex<Vec<u32>>,
        }
        impl PassObserver for std::sync::Arc<OnlyTheEnd> {
            fn wants(&self, spp_done: u32) -> bool {
                self.asked.lock().unwrap().push(spp_done);
                spp_done == 6
            }
            fn show(&self, film: &Film) {
                self.shown.lock().unwrap().push(film.spp_done);
            }
        }
        let scene = lit_ball(16, 12);
        let settings = RenderSettings { spp: 6, max_depth: 3, ..Default::default() };
        let est = crate::integrator::bdpt::test_estimator(&scene, &settings);
        let w = std::sync::Arc::new(OnlyTheEnd { asked: Mutex::default(), shown: Mutex::default() });
        let progress = Progress::watched(w.clone());
        render_chunked(&scene, &settings, &progress, &est, 0, u64::MAX).unwrap();
        assert_eq!(*w.asked.lock().unwrap(), [1, 2, 3, 4, 5, 6], "asked once per pass (six of 1 spp)");
        assert_eq!(*w.shown.lock().unwrap(), [6]);
    }

    /// Counts the pixel samples it is asked for, per pixel.
    struct CountingEstimator(Vec<std::sync::atomic::AtomicU32>, u32);
    impl SplatEstimator for CountingEstimator {
        type Scratch = ();
        fn scratch(&self) {}
        fn sample(&self, _: &Scene, _: &RenderSettings, _: &Ray, raster: Vec2, _: &mut dyn Sampler, _: &mut (), _: &mut SampleOut) -> Rgb {
            self.0[(raster.y as u32 * self.1 + raster.x as u32) as usize].fetch_add(1, Ordering::Relaxed);
            Rgb::BLACK
        }
    }

    /// Every pixel gets exactly spp samples whatever the filter (film tiles extend past their
    /// pixels by the filter radius; those borders belong to the neighbours).
    #[test]
    fn each_pixel_is_sampled_spp_times() {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.5)) });
        b.add_shape(Geometry::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 4.0), radius: 1.0, flip_normals: false }), m, None, "ball").unwrap();
        b.add_light(Light::Point { position: Vec3::ZERO, intensity: Rgb::splat(1.0) });
        let (w, h) = (37, 21);
        b.set_camera(Camera {
            to_world: Mat4::IDENTITY,
            projection: Projection::Perspective { fov_x_deg: 50.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: w,
            height: h,
            near_clip: 0.01,
            far_clip: 100.0,
            shutter_open: 0.0,
            shutter_close: 0.0,
        });
        let scene = b.build().unwrap();
        for filter in [crate::film::Filter::Box, crate::film::Filter::Tent { radius: 1.5 }, crate::film::Filter::Gaussian { stddev: 0.5 }] {
            // One chunk a pass, and several (the pipeline merges one while rendering the next,
            // across passes too), with passes of 1 and 2 samples.
            for (spp, chunk_samples, threads) in [(3, u64::MAX, 2), (3, 64, 3), (16, 200, 2), (16, 200, 1)] {
                let settings = RenderSettings { spp, filter, threads, ..Default::default() };
                let est = CountingEstimator((0..w * h).map(|_| Default::default()).collect(), w);
                let r = render_chunked(&scene, &settings, &Progress::new(), &est, 0, chunk_samples).unwrap();
                assert!(est.0.iter().all(|c| c.load(Ordering::Relaxed) == spp), "{filter:?}: some pixel not sampled exactly {spp} times");
                // Each pass reached the film (a pass rendered and then dropped kept its counts).
                assert_eq!(r.film.spp_done, spp, "{filter:?}, chunks of {chunk_samples} samples");
            }
        }
    }

    /// `pixel_index` is the merge's former `floor` test, and the splat's pixel centre is
    /// the same bits (-0.0 floors to -0.0 and to 0, both centred at 0.5), at the edges too.
    #[test]
    fn pixel_index_is_the_floor_test() {
        let floor_way = |v: f32, n: u32| {
            let x = v.floor();
            (x >= 0.0 && (x as u32) < n).then_some((x + 0.5).to_bits())
        };
        let n = 256u32;
        let mut vs = vec![0.0, -0.0, -1e-30, -0.5, -1.0, 0.5, 1.0, 255.0, 255.99998, 256.0, 256.5, 1e9, 1e30, f32::MIN_POSITIVE];
        vs.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, -f32::MAX]);
        vs.extend((0..20_000).map(|i| i as f32 * 0.013_7 - 3.0));
        vs.push(f32::from_bits((256.0f32).to_bits() - 1));
        for v in vs {
            let got = pixel_index(v, n).map(|i| (i as f32 + 0.5).to_bits());
            assert_eq!(got, floor_way(v, n), "v = {v}");
        }
        // Films wider than f32's integers are exact: the index is the truncation itself.
        assert_eq!(pixel_index(16_777_217.0, u32::MAX), Some(16_777_216));
    }
}
