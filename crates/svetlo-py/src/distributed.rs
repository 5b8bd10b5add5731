//! The pieces of a render split over processes (`svetlo.distributed`): the plan of a render's
//! pass tree cut into chunks, one chunk rendered to raw film sums (bytes), and sums merged
//! into the local render's film. The settings go through the same CLI-ordered overrides as
//! `render`, so a chunk is a piece of exactly the render `svetlo.render` would make.

use crate::errors::{option_err, to_py};
use crate::images::to_array;
use crate::render::{resized, settings, Overrides, PyFilm};
use crate::scene::PyScene;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use svetlo::film::raw::PartialFilm;
use svetlo::integrator::passes::{chunk_nodes, pass_plan};
use svetlo::integrator::Progress;

/// The render's method, settings and (resized) scene, as `render` would make them.
fn resolve(
    scene: &PyScene,
    integrator: Option<String>,
    o: &Overrides,
) -> PyResult<(String, svetlo::integrator::RenderSettings, std::sync::Arc<svetlo::scene::Scene>)> {
    let name = integrator.unwrap_or_else(|| scene.scene.settings.integrator.clone());
    svetlo::methods::by_name(&name).map_err(to_py)?;
    if !svetlo::methods::pass_separable(&name) {
        return Err(option_err(format!(
            "integrator '{name}' is not a sum of independent pixel samples: its passes cannot be rendered apart (methods that can: {})",
            svetlo::methods::PASS_SEPARABLE.join(", ")
        )));
    }
    let s = settings(&scene.scene, o)?;
    let sc = resized(&scene.scene, o.width, o.height)?;
    svetlo::limits::check_film(sc.camera.width, sc.camera.height).map_err(to_py)?;
    Ok((name, s, sc))
}

/// The chunks of a render: a dict with integrator, spp, width, height, passes (their count)
/// and nodes, a list of (first pass, end pass, first sample, end sample).
#[pyfunction]
#[pyo3(signature = (scene, chunks, integrator=None, spp=None, seed=None, max_depth=None, width=None, height=None,
                    filter=None, sampler=None, rr_depth=None, hide_emitters=None))]
#[allow(clippy::too_many_arguments)]
pub fn plan_chunks<'py>(
    py: Python<'py>,
    scene: &PyScene,
    chunks: usize,
    integrator: Option<String>,
    spp: Option<u32>,
    seed: Option<u64>,
    max_depth: Option<i32>,
    width: Option<u32>,
    height: Option<u32>,
    filter: Option<String>,
    sampler: Option<String>,
    rr_depth: Option<i32>,
    hide_emitters: Option<bool>,
) -> PyResult<Bound<'py, PyDict>> {
    if chunks == 0 {
        return Err(option_err("chunks must be at least 1"));
    }
    let o = Overrides { spp, time: None, seed, max_depth, width, height, filter, threads: 0, sampler, rr_depth, hide_emitters };
    let (name, s, sc) = resolve(scene, integrator, &o)?;
    let plan = pass_plan(s.spp, sc.camera.width as u64 * sc.camera.height as u64);
    let nodes: Vec<(u32, u32, u32, u32)> = chunk_nodes(&plan, chunks)
        .into_iter()
        .map(|r| {
            let (first, last) = (plan[r.start as usize], plan[r.end as usize - 1]);
            (r.start, r.end, first.0, last.0 + last.1)
        })
        .collect();
    let d = PyDict::new(py);
    d.set_item("integrator", name)?;
    d.set_item("spp", s.spp)?;
    d.set_item("width", sc.camera.width)?;
    d.set_item("height", sc.camera.height)?;
    d.set_item("passes", plan.len())?;
    d.set_item("nodes", nodes)?;
    Ok(d)
}

/// Render passes `start..end` (a node from `plan_chunks`) and return their raw film sums as bytes.
#[pyfunction]
#[pyo3(signature = (scene, start, end, integrator=None, spp=None, seed=None, max_depth=None, width=None, height=None,
                    filter=None, threads=0, sampler=None, rr_depth=None, hide_emitters=None))]
#[allow(clippy::too_many_arguments)]
pub fn render_passes<'py>(
    py: Python<'py>,
    scene: &PyScene,
    start: u32,
    end: u32,
    integrator: Option<String>,
    spp: Option<u32>,
    seed: Option<u64>,
    max_depth: Option<i32>,
    width: Option<u32>,
    height: Option<u32>,
    filter: Option<String>,
    threads: usize,
    sampler: Option<String>,
    rr_depth: Option<i32>,
    hide_emitters: Option<bool>,
) -> PyResult<Bound<'py, PyBytes>> {
    if threads > 1024 {
        return Err(option_err(format!("threads must be in 0..=1024 (0: all cores), got {threads}")));
    }
    let o = Overrides { spp, time: None, seed, max_depth, width, height, filter, threads, sampler, rr_depth, hide_emitters };
    let (name, s, sc) = resolve(scene, integrator, &o)?;
    if start >= end {
        return Err(option_err(format!("passes {start}..{end} are empty")));
    }
    let part = py.allow_threads(|| svetlo::methods::render_passes(&name, &sc, &s, start..end, &Progress::new())).map_err(to_py)?;
    let bytes = py.allow_threads(|| part.to_bytes());
    Ok(PyBytes::new(py, &bytes))
}

fn parse(parts: Vec<Vec<u8>>) -> svetlo::Result<Vec<PartialFilm>> {
    parts.iter().map(|b| PartialFilm::from_bytes(b)).collect()
}

/// Merge raw film sums (bytes from `render_passes`): with `exact`, they must partition the
/// render's passes and the result is the local render's, bit for bit; without, any subset is
/// summed in pass order (an image of the render so far). Returns a dict: image, film, spp.
#[pyfunction]
#[pyo3(signature = (parts, exact=true))]
pub fn merge_films(py: Python<'_>, parts: Vec<Vec<u8>>, exact: bool) -> PyResult<Bound<'_, PyDict>> {
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
