//! Integrators: each method of the lecture renders a [`Scene`] into a [`Film`].
//!
//! Camera-side methods implement [`PixelEstimator`] (radiance along one camera ray) and share
//! the parallel, deterministic, cancellable driver [`render_pixels`].

pub mod bdpt;
pub mod direct;
pub mod distributed;
pub mod light;
pub mod local;
pub mod metropolis;
pub mod mlt;
pub mod passes;
pub mod path;
pub mod path_simd;
pub mod photon;
pub mod pssmlt;
pub mod splat;
pub mod whitted;
pub mod zbuffer;

use crate::error::{Error, Result};
use crate::film::{Film, Filter};
use crate::sampling::{Sampler, SamplerKind};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// Settings every Monte Carlo integrator shares, so that they solve the same problem.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Samples per pixel (camera methods) or the method's equivalent; the maximum with `time_limit`.
    pub spp: u32,
    /// Stop after this much wall time, keeping whole passes.
    pub time_limit: Option<Duration>,
    /// Mitsuba 3's meaning: path segments from the camera; -1 unbounded.
    pub max_depth: i32,
    /// Russian roulette starts at this depth.
    pub rr_depth: i32,
    pub seed: u64,
    /// Worker threads; 0 = all cores.
    pub threads: usize,
    pub sampler: SamplerKind,
    pub filter: Filter,
    /// Do not show emitters seen directly by the camera.
    pub hide_emitters: bool,
    /// AOVs by light path expression and the beauty's restriction (None: neither).
    pub lpe: Option<std::sync::Arc<crate::lpe::AovSet>>,
    /// Render only these passes of the untimed pass plan, a node of its tree (see
    /// [`passes`]): the film then holds that node's raw sums, to be combined with the other
    /// nodes' by [`crate::film::raw::PartialFilm::merge`]. Only the camera-side pass driver
    /// honours it; [`crate::methods::render_passes`] refuses the other methods.
    pub pass_range: Option<std::ops::Range<u32>>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            spp: 16,
            time_limit: None,
            max_depth: -1,
            rr_depth: 5,
            seed: 0,
            threads: 0,
            sampler: SamplerKind::default(),
            filter: Filter::default(),
            hide_emitters: false,
            lpe: None,
            pass_range: None,
        }
    }
}

impl RenderSettings {
    /// The scene file's settings.
    pub fn from_scene(scene: &Scene) -> Self {
        let s = &scene.settings;
        RenderSettings {
            spp: s.spp,
            max_depth: s.max_depth,
            rr_depth: s.rr_depth,
            seed: s.seed,
            sampler: s.sampler,
            filter: s.filter,
            hide_emitters: s.hide_emitters,
            ..Default::default()
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.spp == 0 {
            return Err(Error::Settings("spp must be at least 1".into()));
        }
        if self.max_depth < -1 {
            return Err(Error::Settings(format!("max_depth must be -1 (unbounded) or >= 0, got {}", self.max_depth)));
        }
        if self.rr_depth < 1 {
            return Err(Error::Settings(format!("rr_depth must be >= 1, got {}", self.rr_depth)));
        }
        Ok(())
    }

    /// The render's AOVs (the empty set when there are none).
    #[inline]
    pub fn aovs(&self) -> &crate::lpe::AovSet {
        self.lpe.as_deref().unwrap_or(crate::lpe::AovSet::empty())
    }

    /// An error when AOVs or a beauty restriction are asked of a method that cannot route
    /// its contributions by path.
    pub fn check_lpe_support(&self, method: &str, supported: bool) -> Result<()> {
        if !supported && !self.aovs().is_empty() {
            return Err(Error::Settings(format!("{method} does not support light path expressions (AOVs or --lpe)")));
        }
        Ok(())
    }

    /// Whether a path may have `segments` segments.
    #[inline]
    pub fn depth_allows(&self, segments: i32) -> bool {
        self.max_depth < 0 || segments <= self.max_depth
    }
}

/// Who watches a render form: shown the film as it stands after each complete pass (camera
/// methods), round of mutations (Metropolis) or iteration (SPPM), on the render's own thread.
pub trait PassObserver: Send + Sync {
    /// Whether it wants the film of the pass that brings the render to `spp_done` samples per
    /// pixel. Assembling that film costs work (the passes summed so far), so a watcher that
    /// would skip it says so here, before the render builds it.
    fn wants(&self, _spp_done: u32) -> bool {
        true
    }
    /// The film: copy what is needed and return quickly (the preview develops the image and
    /// hands it to its server).
    fn show(&self, film: &Film);
}

/// A closure that wants every pass.
struct EveryPass<F>(F);

impl<F: Fn(&Film) + Send + Sync> PassObserver for EveryPass<F> {
    fn show(&self, film: &Film) {
        (self.0)(film)
    }
}

/// Progress of a render, shared with whoever shows it; setting `cancel` stops the render
/// after the current pass, keeping the samples done.
#[derive(Default)]
pub struct Progress {
    /// Work units done and planned (samples x pixels, or the method's own unit).
    pub done: AtomicU64,
    pub total: AtomicU64,
    pub cancel: AtomicBool,
    /// Who watches the film form; `None` costs one branch per pass.
    observer: Option<Box<dyn PassObserver>>,
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("done", &self.done)
            .field("total", &self.total)
            .field("cancel", &self.cancel)
            .field("observed", &self.observer.is_some())
            .finish()
    }
}

impl Progress {
    pub fn new() -> Self {
        Self::default()
    }
    /// Progress whose film is shown to `observer` after every pass.
    pub fn observed(observer: impl Fn(&Film) + Send + Sync + 'static) -> Self {
        Self::watched(EveryPass(observer))
    }
    /// Progress watched by `observer`, which chooses the passes it is shown.
    pub fn watched(observer: impl PassObserver + 'static) -> Self {
        Progress { observer: Some(Box::new(observer)), ..Self::default() }
    }
    /// Whether anyone watches at all.
    pub fn is_observed(&self) -> bool {
        self.observer.is_some()
    }
    /// Whether the film of the pass reaching `spp_done` samples per pixel should be built and
    /// shown ([`Self::pass_done`]); false when nobody watches.
    pub fn wants_pass(&self, spp_done: u32) -> bool {
        self.observer.as_ref().is_some_and(|o| o.wants(spp_done))
    }
    /// A pass is complete: show the film to the observer, if any.
    pub fn pass_done(&self, film: &Film) {
        if let Some(o) = &self.observer {
            o.show(film);
        }
    }
    pub fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
    pub fn fraction(&self) -> f64 {
        let t = self.total.load(Ordering::Relaxed);
        if t == 0 {
            0.0
        } else {
            self.done.load(Ordering::Relaxed) as f64 / t as f64
        }
    }
}

pub trait Integrator: Sync {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film>;
    /// Builds what the method derives from the scene's geometry alone and keeps with the
    /// scene (the path kernel's packet tree and unpacked triangles), so that a render that
    /// follows starts at tracing. The CLI calls it as part of loading, as Mitsuba builds its
    /// BVH in `load_file`; a render without it builds the same itself. The image is the same
    /// either way.
    fn prepare(&self, _scene: &Scene, _settings: &RenderSettings) {}
    /// A report of the last render for people (e.g. Metropolis acceptance rates), if the
    /// method keeps one.
    fn report(&self) -> Option<String> {
        None
    }
}

/// Radiance along one camera ray: the core of every camera-side method.
pub trait PixelEstimator: Sync {
    fn li(&self, scene: &Scene, ray: &crate::geometry::Ray, sampler: &mut dyn Sampler, settings: &RenderSettings) -> Rgb;
    /// [`Self::li`] that also reports each contribution with the layers its path matches
    /// (`settings.aovs()`); estimators that do say so in [`Self::supports_lpe`].
    fn li_layers(
        &self,
        scene: &Scene,
        ray: &crate::geometry::Ray,
        sampler: &mut dyn Sampler,
        settings: &RenderSettings,
        _layers: &mut crate::lpe::aov::LayerSample,
    ) -> Rgb {
        self.li(scene, ray, sampler, settings)
    }
    fn supports_lpe(&self) -> bool {
        false
    }
}

/// Run a pixel estimator over the film: passes of a few samples per pixel over all tiles in
/// parallel, tiles merged in a fixed order (deterministic for any thread count), stopping early
/// on cancellation or when the time budget is spent. Each pass is kept whole.
/// Starts sample `s` of pixel (x, y) and draws its camera ray: film position, lens point and
/// time, the first five dimensions of every camera-side method, in this order.
#[inline(always)]
pub(crate) fn camera_sample<S: Sampler + ?Sized>(cam: &crate::camera::RayGenerator, sampler: &mut S, x: u32, y: u32, s: u32) -> (Vec2, crate::geometry::Ray) {
    sampler.start_pixel_sample(x, y, s);
    let pf = sampler.next_2d();
    let lens = sampler.next_2d();
    let time = sampler.next_1d();
    let raster = Vec2::new(x as f32 + pf.x, y as f32 + pf.y);
    (raster, cam.generate_ray(raster, lens, time))
}

pub fn render_pixels(scene: &Scene, settings: &RenderSettings, progress: &Progress, est: &dyn PixelEstimator) -> Result<Film> {
    // The splatting driver with nothing to splat: one chunk of all tiles per pass.
    Ok(splat::render_chunked(scene, settings, progress, &NoSplats(est), 0, u64::MAX)?.film)
}

/// A kernel that renders a whole tile at once: `(film tile, [x0, y0, x1, y1) of the tile's own
/// pixels, s0, n)` adds samples `s0..s0 + n` of every pixel of the rectangle (pixels in rows,
/// samples innermost, for the same image whatever the thread count).
pub(crate) type TileFn<'a> = dyn Fn(&mut crate::film::FilmTile, [u32; 4], u32, u32) + Sync + 'a;

/// The pass and tile driver of [`render_pixels`] for kernels that take a whole tile at once;
/// `supports_lpe`: the kernel routes its samples to the AOV layers itself.
pub(crate) fn render_tiles(scene: &Scene, settings: &RenderSettings, progress: &Progress, supports_lpe: bool, render_tile: &TileFn) -> Result<Film> {
    Ok(splat::render_chunked(scene, settings, progress, &TileKernel(render_tile, supports_lpe), 0, u64::MAX)?.film)
}

/// A whole-tile kernel seen as a splatting estimator that never splats.
struct TileKernel<'a, 'b>(&'a TileFn<'b>, bool);

impl splat::SplatEstimator for TileKernel<'_, '_> {
    type Scratch = ();
    fn scratch(&self) {}
    fn sample(&self, _: &Scene, _: &RenderSettings, _: &crate::geometry::Ray, _: Vec2, _: &mut dyn Sampler, _: &mut (), _: &mut splat::SampleOut) -> Rgb {
        unreachable!("TileKernel renders whole tiles")
    }
    fn render_tile(&self, t: splat::TileJob, _: &mut dyn Sampler, _: &mut (), _: &mut Vec<splat::Splat>) {
        (self.0)(t.tile, t.rect, t.s0, t.n)
    }
    fn supports_lpe(&self) -> bool {
        self.1
    }
}

/// A pixel estimator seen as a splatting one that never splats.
struct NoSplats<'a>(&'a dyn PixelEstimator);

impl splat::SplatEstimator for NoSplats<'_> {
    type Scratch = ();
    fn scratch(&self) {}
    fn sample(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        ray: &crate::geometry::Ray,
        _raster: Vec2,
        sampler: &mut dyn Sampler,
        _scratch: &mut (),
        out: &mut splat::SampleOut,
    ) -> Rgb {
        if settings.aovs().is_empty() {
            self.0.li(scene, ray, sampler, settings)
        } else {
            self.0.li_layers(scene, ray, sampler, settings, &mut out.layers)
        }
    }
    fn supports_lpe(&self) -> bool {
        self.0.supports_lpe()
    }
}
