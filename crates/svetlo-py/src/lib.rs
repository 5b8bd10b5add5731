//! `svetlo._svetlo`: the Python extension module, a thin layer over the library. The Python
//! package around it (`python/svetlo`) adds keyword handling, `load_dict`, progress bars and
//! the documentation; everything that renders is the library's, chosen through its one method
//! registry (`svetlo::methods`).

mod dict;
mod distributed;
mod errors;
mod images;
mod radiosity;
mod render;
mod scene;

use pyo3::prelude::*;

#[pymodule]
fn _svetlo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<scene::PyScene>()?;
    m.add_class::<radiosity::PyRadiosity>()?;
    m.add_class::<render::PyFilm>()?;
    m.add_function(wrap_pyfunction!(scene::load_file, m)?)?;
    m.add_function(wrap_pyfunction!(scene::load_string, m)?)?;
    m.add_function(wrap_pyfunction!(dict::dict_to_xml, m)?)?;
    m.add_function(wrap_pyfunction!(dict::load_dict, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::methods, m)?)?;
    m.add_function(wrap_pyfunction!(images::write, m)?)?;
    m.add_function(wrap_pyfunction!(images::read, m)?)?;
    m.add_function(wrap_pyfunction!(images::write_layers, m)?)?;
    m.add_function(wrap_pyfunction!(images::read_layers, m)?)?;
    m.add_function(wrap_pyfunction!(images::relmse, m)?)?;
    m.add_function(wrap_pyfunction!(images::ztest, m)?)?;
    m.add_function(wrap_pyfunction!(radiosity::radiosity, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::plan_chunks, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::render_passes, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::merge_films, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::join_films, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::shared_batch, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::sppm_photons, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::sppm_iterate, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::sppm_develop, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::radiosity_rows, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::radiosity_solve, m)?)?;
    m.add_function(wrap_pyfunction!(distributed::radiosity_counters, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
