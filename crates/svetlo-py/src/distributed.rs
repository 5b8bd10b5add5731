//! The pieces of a render split over processes (`svetlo.distributed`): the plan of a render's
//! work units (sample passes, or Metropolis chain blocks) cut into chunks, what the chunks
//! share computed once (the Metropolis bootstrap), one chunk rendered to raw film sums
//! (bytes), and sums merged into the local render's film; SPPM's steps (photon batches,
//! row blocks advanced one iteration, rows developed); and radiosity's (ranges of
//! form-factor rows, the one solve from them whose solution every chunk shows). The settings go through the same
//! CLI-ordered overrides as `render`, so a piece is a piece of exactly the render
//! `svetlo.render` would make. Settings come as the dict of keywords Python passes on.

use crate::errors::{option_err, to_py};
use crate::images::to_array;
use crate::render::{scene_for, settings, Overrides, PyFilm};
use crate::scene::PyScene;
use pyo3::prelude::*;
use pyo3::pybacked::PyBackedBytes;
use pyo3::types::{PyBytes, PyDict};
use std::sync::Arc;
use svetlo::film::raw::PartialFilm;
use svetlo::film::Film;
use svetlo::integrator::passes::chunk_nodes;
use svetlo::integrator::photon::{Sppm, SppmOptions, SppmRows};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::scene::Scene;

/// The render settings keywords a piece takes (those of `render`, less time and AOVs).
const KEYS: &[&str] = &["integrator", "spp", "seed", "max_depth", "width", "height", "filter", "sampler", "rr_depth", "hide_emitters", "ray_epsilon"];

/// A render's method, settings and (resized) scene, as `render` would make them.
struct Resolved {
    name: String,
    settings: RenderSettings,
    scene: Arc<Scene>,
}

fn get<'py, T: FromPyObject<'py>>(d: &Bound<'py, PyDict>, k: &str) -> PyResult<Option<T>> {
    match d.get_item(k)? {
        Some(v) if !v.is_none() => Ok(Some(v.extract()?)),
        _ => Ok(None),
    }
}

fn resolve(scene: &PyScene, opts: &Bound<'_, PyDict>, threads: usize) -> PyResult<Resolved> {
    for k in opts.keys() {
        let k: String = k.extract()?;
        if !KEYS.contains(&k.as_str()) {
            return Err(option_err(format!("unknown setting '{k}' for a distributed render (settings: {})", KEYS.join(", "))));
        }
    }
    if threads > 1024 {
        return Err(option_err(format!("threads must be in 0..=1024 (0: all cores), got {threads}")));
    }
    let o = Overrides {
        spp: get(opts, "spp")?,
        time: None,
        seed: get(opts, "seed")?,
        max_depth: get(opts, "max_depth")?,
        width: get(opts, "width")?,
        height: get(opts, "height")?,
        filter: get(opts, "filter")?,
        threads,
        sampler: get(opts, "sampler")?,
        rr_depth: get(opts, "rr_depth")?,
        hide_emitters: get(opts, "hide_emitters")?,
        ray_epsilon: get(opts, "ray_epsilon")?,
    };
    let integrator: Option<String> = get(opts, "integrator")?;
    let name = integrator.unwrap_or_else(|| scene.scene.settings.integrator.clone());
    svetlo::methods::by_name(&name).map_err(to_py)?;
    let s = settings(&scene.scene, &o)?;
    let sc = scene_for(&scene.scene, &o)?;
    svetlo::limits::check_film(sc.camera.width, sc.camera.height).map_err(to_py)?;
    Ok(Resolved { name, settings: s, scene: sc })
}

/// How `name` is split: "passes" (sample passes), "chains" (Metropolis chain blocks from one
/// bootstrap), "sppm" (photon batches and row blocks per iteration), or None.
fn scheme(name: &str) -> Option<&'static str> {
    if svetlo::methods::pass_separable(name) {
        Some("passes")
    } else if svetlo::methods::splits(name) {
        Some("chains")
    } else if name.split(':').next() == Some("sppm") {
        Some("sppm")
    } else {
        None
    }
}

fn splittable(r: &Resolved) -> PyResult<()> {
    if svetlo::methods::splits(&r.name) {
        return Ok(());
    }
    Err(option_err(format!(
        "integrator '{}' is not a sum of independent pixel samples or of Metropolis chains: its work cannot be rendered apart (methods that can: {}, {}; sppm has its own scheme)",
        r.name,
        svetlo::methods::PASS_SEPARABLE.join(", "),
        svetlo::methods::CHAIN_SEPARABLE.join(", ")
    )))
}

/// The plan of a render: a dict with integrator, scheme ("passes", "chains" or "sppm"), spp,
/// width, height; for passes and chains also units (samples per pixel or chains in all),
/// shared (the units of what all chunks share: 1 for a bootstrap, photon paths for photon
/// mapping, 0 for nothing), passes (the number of work units) and nodes, a list of (first unit, end unit, first
/// sample or chain, end sample or chain), solve (radiosity: one solve that every chunk shows,
/// from `radiosity_solve`) and rows (the form-factor rows that solve spreads over
/// `radiosity_rows` tasks; 0: it makes its own); for sppm photons (per iteration).
#[pyfunction]
#[pyo3(signature = (scene, chunks, opts))]
pub fn plan_chunks<'py>(py: Python<'py>, scene: &PyScene, chunks: usize, opts: &Bound<'py, PyDict>) -> PyResult<Bound<'py, PyDict>> {
    if chunks == 0 {
        return Err(option_err("chunks must be at least 1"));
    }
    let r = resolve(scene, opts, 0)?;
    let d = PyDict::new(py);
    d.set_item("integrator", &r.name)?;
    d.set_item("spp", r.settings.spp)?;
    d.set_item("width", r.scene.camera.width)?;
    d.set_item("height", r.scene.camera.height)?;
    let Some(kind) = scheme(&r.name) else {
        splittable(&r)?;
        unreachable!("a method that splits has a scheme");
    };
    d.set_item("scheme", kind)?;
    if kind == "sppm" {
        d.set_item("photons", sppm_of(&r.name)?.photons_per_iteration(&r.scene))?;
        return Ok(d);
    }
    let plan = svetlo::methods::unit_plan(&r.name, &r.scene, &r.settings).map_err(to_py)?;
    let nodes: Vec<(u32, u32, u32, u32)> = chunk_nodes(&plan, chunks)
        .into_iter()
        .map(|n| {
            let (first, last) = (plan[n.start as usize], plan[n.end as usize - 1]);
            (n.start, n.end, first.0, last.0 + last.1)
        })
        .collect();
    let radiosity = r.name.split(':').next() == Some("radiosity");
    let rows = if radiosity { svetlo::methods::radiosity_rows(&r.name, &r.scene, &r.settings).map_err(to_py)? } else { 0 };
    d.set_item("solve", radiosity)?;
    d.set_item("rows", rows)?;
    d.set_item("units", plan.last().map_or(0, |p| p.0 + p.1))?;
    d.set_item("shared", svetlo::methods::shared_units(&r.name).map_err(to_py)?)?;
    d.set_item("passes", plan.len())?;
    d.set_item("nodes", nodes)?;
    Ok(d)
}

/// Units `start..end` of what every chunk shares (`plan_chunks`'s `shared`), as bytes: the
/// Metropolis bootstrap (one unit), a batch of photon mapping's photon paths.
#[pyfunction]
#[pyo3(signature = (scene, start, end, opts, threads=0))]
pub fn shared_batch<'py>(py: Python<'py>, scene: &PyScene, start: u64, end: u64, opts: &Bound<'py, PyDict>, threads: usize) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, threads)?;
    splittable(&r)?;
    let out = py.allow_threads(|| svetlo::methods::shared_batch(&r.name, &r.scene, &r.settings, start..end, &Progress::new())).map_err(to_py)?;
    Ok(PyBytes::new(py, &out))
}

/// Render units `start..end` (a node from `plan_chunks`) from the shared batches (in order;
/// none: computed here) and return their raw film sums as bytes.
#[pyfunction]
#[pyo3(signature = (scene, start, end, opts, shared=Vec::new(), threads=0))]
pub fn render_passes<'py>(
    py: Python<'py>,
    scene: &PyScene,
    start: u32,
    end: u32,
    opts: &Bound<'py, PyDict>,
    shared: Vec<PyBackedBytes>,
    threads: usize,
) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, threads)?;
    splittable(&r)?;
    if start >= end {
        return Err(option_err(format!("passes {start}..{end} are empty")));
    }
    let refs: Vec<&[u8]> = shared.iter().map(|b| &b[..]).collect();
    let part = py.allow_threads(|| svetlo::methods::render_passes(&r.name, &r.scene, &r.settings, start..end, &refs, &Progress::new())).map_err(to_py)?;
    let bytes = py.allow_threads(|| part.to_bytes());
    Ok(PyBytes::new(py, &bytes))
}

fn parse(parts: Vec<PyBackedBytes>) -> svetlo::Result<Vec<PartialFilm>> {
    parts.iter().map(|b| PartialFilm::from_bytes(b)).collect()
}

/// The dict Python gets for a film: image, aovs, spp, film.
fn film_dict(py: Python<'_>, film: Film) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("spp", film.spp_done)?;
    d.set_item("image", to_array(py, film.image())?)?;
    let aovs = PyDict::new(py);
    for (n, img) in film.layer_images() {
        aovs.set_item(n, to_array(py, img)?)?;
    }
    d.set_item("aovs", aovs)?;
    d.set_item("film", PyFilm { film })?;
    Ok(d)
}

/// Merge raw film sums (bytes from `render_passes`): with `exact`, they must partition the
/// render's units and the result is the local render's, bit for bit; without, any subset is
/// summed in unit order (an image of the render so far). Returns a dict: image, film, spp.
#[pyfunction]
#[pyo3(signature = (parts, exact=true))]
pub fn merge_films(py: Python<'_>, parts: Vec<PyBackedBytes>, exact: bool) -> PyResult<Bound<'_, PyDict>> {
    let film = py
        .allow_threads(|| {
            let parts = parse(parts)?;
            if exact {
                PartialFilm::merge(parts)
            } else {
                PartialFilm::preview(&parts)
            }
        })
        .map_err(to_py)?;
    film_dict(py, film)
}

/// Join the raw sums of two sibling nodes of the pass tree (bytes from `render_passes` or an
/// earlier join) into their parent's: the addition the tree makes there, so parts joined as
/// they arrive merge into the local render's bits.
#[pyfunction]
pub fn join_films<'py>(py: Python<'py>, left: PyBackedBytes, right: PyBackedBytes) -> PyResult<Bound<'py, PyBytes>> {
    let bytes = py
        .allow_threads(|| -> svetlo::Result<Vec<u8>> { Ok(PartialFilm::join(PartialFilm::from_bytes(&left)?, PartialFilm::from_bytes(&right)?)?.to_bytes()) })
        .map_err(to_py)?;
    Ok(PyBytes::new(py, &bytes))
}

fn sppm_of(name: &str) -> PyResult<Sppm> {
    let o = name.split_once(':').map_or("", |(_, o)| o);
    if name.split(':').next() != Some("sppm") {
        return Err(option_err(format!("integrator '{name}' is not sppm")));
    }
    Ok(Sppm { options: SppmOptions::parse(o).map_err(to_py)? })
}

/// SPPM: photon paths `start..end` of iteration `iteration`, as bytes.
#[pyfunction]
#[pyo3(signature = (scene, iteration, start, end, opts, threads=0))]
pub fn sppm_photons<'py>(
    py: Python<'py>,
    scene: &PyScene,
    iteration: u32,
    start: u64,
    end: u64,
    opts: &Bound<'py, PyDict>,
    threads: usize,
) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, threads)?;
    let sppm = sppm_of(&r.name)?;
    let b = py.allow_threads(|| sppm.photon_batch(&r.scene, &r.settings, iteration, start..end)).map_err(to_py)?;
    Ok(PyBytes::new(py, &b))
}

/// SPPM: rows `start..end` advanced by their next iteration from that iteration's photon
/// batches (in path order); `state` None: the rows before the first iteration. Returns the
/// rows' state as bytes.
#[pyfunction]
#[pyo3(signature = (scene, start, end, state, batches, opts, threads=0))]
#[allow(clippy::too_many_arguments)]
pub fn sppm_iterate<'py>(
    py: Python<'py>,
    scene: &PyScene,
    start: u32,
    end: u32,
    state: Option<PyBackedBytes>,
    batches: Vec<PyBackedBytes>,
    opts: &Bound<'py, PyDict>,
    threads: usize,
) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, threads)?;
    let sppm = sppm_of(&r.name)?;
    let out = py
        .allow_threads(|| {
            let mut st = match state {
                Some(b) => SppmRows::from_bytes(&b)?,
                None => sppm.start_rows(&r.scene, &r.settings, start..end)?,
            };
            if st.rows != (start..end) {
                return Err(svetlo::Error::Invalid(format!("sppm: the state is of rows {}..{}, not {start}..{end}", st.rows.start, st.rows.end)));
            }
            let refs: Vec<&[u8]> = batches.iter().map(|b| &b[..]).collect();
            sppm.iterate_rows(&r.scene, &r.settings, &mut st, &refs)?;
            Ok(st.to_bytes())
        })
        .map_err(to_py)?;
    Ok(PyBytes::new(py, &out))
}

/// SPPM: the film of row states (bytes from `sppm_iterate`) that cover the image, as the
/// raw sums of one whole-render part (bytes for `merge_films`).
#[pyfunction]
#[pyo3(signature = (scene, parts, opts))]
pub fn sppm_develop<'py>(py: Python<'py>, scene: &PyScene, parts: Vec<PyBackedBytes>, opts: &Bound<'py, PyDict>) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, 0)?;
    let sppm = sppm_of(&r.name)?;
    let film = py
        .allow_threads(|| {
            let rows = parts.iter().map(|b| SppmRows::from_bytes(b)).collect::<svetlo::Result<Vec<_>>>()?;
            let film = sppm.develop_rows(&r.scene, &r.settings, rows)?;
            Ok::<_, svetlo::Error>(PartialFilm { passes: 0..1, passes_total: 1, film, mutations: 0 }.to_bytes())
        })
        .map_err(to_py)?;
    Ok(PyBytes::new(py, &film))
}

/// Radiosity: rows `start..end` of the form-factor matrix (of `plan_chunks`'s rows), as bytes.
#[pyfunction]
#[pyo3(signature = (scene, start, end, opts, threads=0))]
pub fn radiosity_rows<'py>(py: Python<'py>, scene: &PyScene, start: u64, end: u64, opts: &Bound<'py, PyDict>, threads: usize) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, threads)?;
    let b = py.allow_threads(|| svetlo::methods::radiosity_row_batch(&r.name, &r.scene, &r.settings, start..end)).map_err(to_py)?;
    Ok(PyBytes::new(py, &b))
}

/// Radiosity: the solve from every block of rows (bytes from `radiosity_rows`, any order;
/// none where the plan spreads no rows), as the solution's bytes: `render_passes`'s one
/// shared batch.
#[pyfunction]
#[pyo3(signature = (scene, rows, opts, threads=0))]
pub fn radiosity_solve<'py>(
    py: Python<'py>,
    scene: &PyScene,
    rows: Vec<PyBackedBytes>,
    opts: &Bound<'py, PyDict>,
    threads: usize,
) -> PyResult<Bound<'py, PyBytes>> {
    let r = resolve(scene, opts, threads)?;
    let refs: Vec<&[u8]> = rows.iter().map(|b| &b[..]).collect();
    let b = py.allow_threads(|| svetlo::methods::radiosity_solve(&r.name, &r.scene, &r.settings, &refs)).map_err(to_py)?;
    Ok(PyBytes::new(py, &b))
}

/// This process's radiosity counters: solves begun and form-factor rows computed since it
/// started (a dict with `solves` and `rows`; tests read them on the workers).
#[pyfunction]
pub fn radiosity_counters(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let (solves, rows) = svetlo::radiosity::counters();
    let d = PyDict::new(py);
    d.set_item("solves", solves)?;
    d.set_item("rows", rows)?;
    Ok(d)
}
