//! A render from Python: the CLI's overrides applied over the scene's settings in the CLI's
//! order (so that both give the same image bit for bit), the render run on a thread of its own
//! with the GIL released, and the calling thread woken every few milliseconds to deliver
//! Ctrl-C (which cancels the render, keeping the passes done) and progress callbacks.

use crate::errors::{option_err, to_py};
use crate::images::to_array;
use crate::scene::PyScene;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use svetlo::film::{Film, Filter};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::sampling::SamplerKind;

/// The spp of a render bounded by `time` alone: large enough never to be reached (the CLI's).
const TIME_ONLY_SPP: u32 = 1 << 24;
/// How often the calling thread looks for Ctrl-C and reports progress.
const POLL: Duration = Duration::from_millis(20);

/// The settings a render call asks for, over the scene file's.
pub(crate) struct Overrides {
    pub(crate) spp: Option<u32>,
    pub(crate) time: Option<f64>,
    pub(crate) seed: Option<u64>,
    pub(crate) max_depth: Option<i32>,
    pub(crate) width: Option<u32>,
    pub(crate) height: Option<u32>,
    pub(crate) filter: Option<String>,
    pub(crate) threads: usize,
    pub(crate) sampler: Option<String>,
    pub(crate) rr_depth: Option<i32>,
    pub(crate) hide_emitters: Option<bool>,
    /// The CLI's `--ray-epsilon`: skip hits nearer than this to a ray's origin.
    pub(crate) ray_epsilon: Option<f32>,
}

/// The CLI's `configure`, step for step: settings from the scene, then each override.
pub(crate) fn settings(scene: &svetlo::scene::Scene, o: &Overrides) -> PyResult<RenderSettings> {
    let mut s = RenderSettings::from_scene(scene);
    if let Some(spp) = o.spp {
        if spp == 0 {
            return Err(option_err("spp must be at least 1"));
        }
        s.spp = spp;
    } else if o.time.is_some() {
        s.spp = TIME_ONLY_SPP;
    }
    if let Some(t) = o.time {
        if !(t > 0.0 && t.is_finite() && t < 1e9) {
            return Err(option_err(format!("time: {t} is not a positive number of seconds")));
        }
        s.time_limit = Some(Duration::from_secs_f64(t));
    }
    if let Some(seed) = o.seed {
        s.seed = seed;
    }
    if let Some(d) = o.max_depth {
        s.max_depth = d;
    }
    s.threads = o.threads;
    if let Some(f) = &o.filter {
        s.filter = match f.as_str() {
            "box" => Filter::Box,
            "tent" => Filter::Tent { radius: 1.0 },
            "gaussian" => Filter::Gaussian { stddev: 0.5 },
            other => return Err(option_err(format!("filter: unknown filter '{other}' (box, tent, gaussian)"))),
        };
    }
    if let Some(k) = &o.sampler {
        s.sampler = match k.as_str() {
            "independent" => SamplerKind::Independent,
            "sobol" => SamplerKind::Sobol,
            other => return Err(option_err(format!("sampler: unknown sampler '{other}' (independent, sobol)"))),
        };
    }
    if let Some(r) = o.rr_depth {
        s.rr_depth = r;
    }
    if let Some(h) = o.hide_emitters {
        s.hide_emitters = h;
    }
    s.validate().map_err(to_py)?;
    Ok(s)
}

/// The scene as the overrides change it: the resolution, as the CLI sizes it, and the ray
/// epsilon (a copy only when something changes).
pub(crate) fn scene_for(scene: &Arc<svetlo::scene::Scene>, o: &Overrides) -> PyResult<Arc<svetlo::scene::Scene>> {
    let sized = resized(scene, o.width, o.height)?;
    let Some(d) = o.ray_epsilon else { return Ok(sized) };
    if !(0.0..1e30).contains(&d) {
        return Err(option_err(format!("ray_epsilon: {d} is not a distance of 0 or more")));
    }
    if sized.settings.ray_epsilon == d {
        return Ok(sized);
    }
    let mut copy = (*sized).clone();
    copy.settings.ray_epsilon = d;
    Ok(Arc::new(copy))
}

/// The scene at the requested resolution (a copy only when it changes), as the CLI sizes it.
fn resized(scene: &Arc<svetlo::scene::Scene>, width: Option<u32>, height: Option<u32>) -> PyResult<Arc<svetlo::scene::Scene>> {
    for (v, what) in [(width, "width"), (height, "height")] {
        if let Some(v) = v {
            if !(1..=65536).contains(&v) {
                return Err(option_err(format!("{what} must be in 1..=65536, got {v}")));
            }
        }
    }
    let cam = &scene.camera;
    let aspect = cam.width as f64 / cam.height as f64;
    let (w, h) = match (width, height) {
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, ((w as f64 / aspect).round() as u32).max(1)),
        (None, Some(h)) => (((h as f64 * aspect).round() as u32).max(1), h),
        (None, None) => return Ok(scene.clone()),
    };
    if (w, h) == (cam.width, cam.height) {
        return Ok(scene.clone());
    }
    let mut copy = (**scene).clone();
    copy.camera.width = w;
    copy.camera.height = h;
    Ok(Arc::new(copy))
}

type Strategies = Vec<svetlo::integrator::bdpt::StrategyImage>;

/// Render `scene` with `integrator` (a registry name with options, `NAME:key=value,...`).
/// Returns a dict: image, variance, spp, seconds, interrupted, report, integrator, strategies.
#[pyfunction]
#[pyo3(signature = (scene, integrator=None, spp=None, time=None, seed=None, max_depth=None, width=None, height=None,
                    filter=None, threads=0, sampler=None, rr_depth=None, hide_emitters=None, strategies=None, callback=None,
                    aovs=None, lpe=None, aov_preset=None, ray_epsilon=None))]
#[allow(clippy::too_many_arguments)]
pub fn render<'py>(
    py: Python<'py>,
    scene: &PyScene,
    integrator: Option<String>,
    spp: Option<u32>,
    time: Option<f64>,
    seed: Option<u64>,
    max_depth: Option<i32>,
    width: Option<u32>,
    height: Option<u32>,
    filter: Option<String>,
    threads: usize,
    sampler: Option<String>,
    rr_depth: Option<i32>,
    hide_emitters: Option<bool>,
    strategies: Option<u32>,
    callback: Option<PyObject>,
    aovs: Option<Vec<(String, String)>>,
    lpe: Option<String>,
    aov_preset: Option<String>,
    ray_epsilon: Option<f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let name = integrator.unwrap_or_else(|| scene.scene.settings.integrator.clone());
    let method = svetlo::methods::by_name(&name).map_err(to_py)?;
    let is_bdpt = name == "bdpt";
    if strategies.is_some() && !is_bdpt {
        return Err(option_err(format!("strategies needs integrator='bdpt' (the render would use '{name}')")));
    }
    if let Some(d) = strategies {
        if !(1..=32).contains(&d) {
            return Err(option_err(format!("strategies: the longest path must be 1..=32 segments, got {d}")));
        }
    }
    let o = Overrides { spp, time, seed, max_depth, width, height, filter, threads, sampler, rr_depth, hide_emitters, ray_epsilon };
    let mut settings = settings(&scene.scene, &o)?;
    let the_scene = scene_for(&scene.scene, &o)?;
    // The CLI's --aov, --aov-preset and --lpe.
    let request = svetlo::lpe::AovSet::request(&the_scene, aovs.as_deref().unwrap_or(&[]), aov_preset.as_deref(), lpe.as_deref());
    let mut warnings = Vec::new();
    if let Some((set, w)) = request.map_err(|e| option_err(format!("light path expression: {e}")))? {
        settings.lpe = Some(Arc::new(set));
        warnings = w;
    }
    // The CLI's check: a film over the memory budget is refused before any allocation.
    svetlo::limits::check_film(the_scene.camera.width, the_scene.camera.height).map_err(to_py)?;
    let progress = Progress::new();
    let start = Instant::now();
    // The worker wakes the waiting thread when it is done.
    let (finished, waiter) = (AtomicBool::new(false), std::thread::current());
    let mut interrupt: Option<PyErr> = None;
    let mut callback_error: Option<PyErr> = None;
    let result: svetlo::Result<(Film, Strategies, f64)> = std::thread::scope(|s| {
        let worker = s.spawn(|| {
            let t0 = Instant::now();
            let r = match strategies {
                Some(d) => svetlo::integrator::bdpt::Bdpt.render_with_strategies(&the_scene, &settings, &progress, d as usize),
                None => method.render(&the_scene, &settings, &progress).map(|f| (f, Vec::new())),
            };
            let elapsed = t0.elapsed().as_secs_f64();
            finished.store(true, Ordering::Release);
            waiter.unpark();
            r.map(|(f, st)| (f, st, elapsed))
        });
        loop {
            py.allow_threads(|| std::thread::park_timeout(POLL));
            // A worker that panicked (a bug) never sets `finished`: its end is noticed too.
            if finished.load(Ordering::Acquire) || worker.is_finished() {
                break;
            }
            if interrupt.is_none() {
                if let Err(e) = py.check_signals() {
                    progress.cancel.store(true, Ordering::SeqCst);
                    interrupt = Some(e);
                }
            }
            if let (Some(cb), None) = (&callback, &callback_error) {
                let (done, total) = (progress.done.load(Ordering::Relaxed), progress.total.load(Ordering::Relaxed));
                if let Err(e) = cb.call1(py, (done, total, start.elapsed().as_secs_f64())) {
                    progress.cancel.store(true, Ordering::SeqCst);
                    // Ctrl-C while the callback ran surfaces there: it is still an interrupt.
                    if e.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) {
                        interrupt.get_or_insert(e);
                    } else {
                        callback_error = Some(e);
                    }
                }
            }
        }
        match worker.join() {
            Ok(r) => r,
            Err(_) => Err(svetlo::Error::Invalid(format!("the {name} render panicked"))),
        }
    });
    let seconds = start.elapsed().as_secs_f64();
    if let Some(e) = callback_error {
        return Err(e);
    }
    let (film, strategy_images, render_seconds) = result.map_err(to_py)?;
    // A signal handler that raised something else than KeyboardInterrupt: that error, as Python would.
    if let Some(e) = interrupt.take_if(|e| !e.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py)) {
        return Err(e);
    }
    let d = PyDict::new(py);
    d.set_item("integrator", &name)?;
    d.set_item("spp", film.spp_done)?;
    d.set_item("spp_planned", settings.spp)?;
    d.set_item("seconds", seconds)?;
    // The library's render call alone: what the Rust API would have taken.
    d.set_item("render_seconds", render_seconds)?;
    d.set_item("interrupted", interrupt.is_some() || progress.cancelled())?;
    d.set_item("report", method.report())?;
    let t_image = Instant::now();
    let image = film.image();
    // Developing the film is part of any render through the library's API too.
    d.set_item("develop_seconds", t_image.elapsed().as_secs_f64())?;
    d.set_item("image", to_array(py, image)?)?;
    let layers = PyList::empty(py);
    for (n, im) in film.layer_images() {
        layers.append((n, to_array(py, im)?))?;
    }
    d.set_item("aovs", layers)?;
    d.set_item("warnings", warnings)?;
    // The variance image costs as much again: made when asked for.
    d.set_item("film", PyFilm { film })?;
    let st = PyList::empty(py);
    for im in strategy_images {
        st.append((im.s, im.t, to_array(py, im.weighted)?, to_array(py, im.unweighted)?))?;
    }
    d.set_item("strategies", st)?;
    Ok(d)
}

/// A rendered film kept for what is developed on demand (the per-sample variance).
#[pyclass(frozen, name = "Film", module = "svetlo")]
pub struct PyFilm {
    pub(crate) film: Film,
}

#[pymethods]
impl PyFilm {
    /// Per-sample variance of each pixel's own samples, (height, width, 3) float32.
    fn variance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        to_array(py, self.film.variance_image())
    }

    #[getter]
    fn spp(&self) -> u32 {
        self.film.spp_done
    }
}

/// The methods of the registry: (name, summary, takes options).
#[pyfunction]
pub fn methods() -> Vec<(&'static str, &'static str, bool)> {
    svetlo::methods::METHODS.iter().map(|m| (m.name, m.summary, m.options)).collect()
}
