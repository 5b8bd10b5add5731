//! A radiosity solution from Python: the elements and their radiosity as numpy arrays, the
//! convergence history, and its image through the scene's camera.

use crate::errors::{option_err, to_py};
use crate::images::to_array;
use crate::scene::PyScene;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;
use svetlo::film::Filter;
use svetlo::integrator::{render_pixels, Progress, RenderSettings};
use svetlo::radiosity::{RadiosityOptions, Shading, Solved};
use svetlo::scene::Scene;
use svetlo::Rgb;

/// A solved radiosity system (`svetlo.radiosity(scene, ...)`).
#[pyclass(frozen, name = "RadiositySolution", module = "svetlo")]
pub struct PyRadiosity {
    scene: Arc<Scene>,
    solved: Solved,
    shading: Shading,
}

fn rgb_rows(v: &[Rgb]) -> Array2<f32> {
    Array2::from_shape_fn((v.len(), 3), |(i, k)| v[i][k])
}

/// Solve `scene` by radiosity with `options` (`key=value,...`, as `radiosity:...`).
#[pyfunction]
#[pyo3(signature = (scene, options, max_depth=None))]
pub fn radiosity(py: Python<'_>, scene: &PyScene, options: &str, max_depth: Option<i32>) -> PyResult<PyRadiosity> {
    let opts = RadiosityOptions::parse(options).map_err(to_py)?;
    let depth = max_depth.unwrap_or(scene.scene.settings.max_depth);
    if depth < -1 {
        return Err(option_err(format!("max_depth must be -1 (unbounded) or >= 0, got {depth}")));
    }
    let s = scene.scene.clone();
    let solved = py.allow_threads(|| svetlo::radiosity::solve(&s, &opts, depth)).map_err(to_py)?;
    Ok(PyRadiosity { scene: s, solved, shading: opts.shading })
}

#[pymethods]
impl PyRadiosity {
    /// Radiosity B of every element (W/m², RGB): shape (elements, 3).
    #[getter]
    fn b<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        PyArray2::from_owned_array(py, rgb_rows(&self.solved.b))
    }

    /// Corners of every element: shape (elements, 3 corners, 3).
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f32>> {
        let e = &self.solved.mesh.elements;
        PyArray3::from_owned_array(py, Array3::from_shape_fn((e.len(), 3, 3), |(i, c, k)| e[i].p[c][k]))
    }

    /// Unit normal of the radiating side of every element: (elements, 3).
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let e = &self.solved.mesh.elements;
        PyArray2::from_owned_array(py, Array2::from_shape_fn((e.len(), 3), |(i, k)| e[i].normal[k]))
    }

    /// Area of every element: (elements,).
    #[getter]
    fn areas<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        PyArray1::from_owned_array(py, Array1::from_iter(self.solved.mesh.elements.iter().map(|e| e.area)))
    }

    /// Diffuse albedo of every element: (elements, 3).
    #[getter]
    fn reflectance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let v: Vec<Rgb> = self.solved.mesh.elements.iter().map(|e| e.reflectance).collect();
        PyArray2::from_owned_array(py, rgb_rows(&v))
    }

    /// Emitted radiosity E = π Le of every element: (elements, 3).
    #[getter]
    fn emission<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let v: Vec<Rgb> = self.solved.mesh.elements.iter().map(|e| e.emission).collect();
        PyArray2::from_owned_array(py, rgb_rows(&v))
    }

    /// Scene shape index of every element: (elements,).
    #[getter]
    fn shape<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        PyArray1::from_owned_array(py, Array1::from_iter(self.solved.mesh.elements.iter().map(|e| e.shape)))
    }

    /// Welded display vertices: (vertices, 3).
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        let v = &self.solved.mesh.vertices;
        PyArray2::from_owned_array(py, Array2::from_shape_fn((v.len(), 3), |(i, k)| v[i][k]))
    }

    /// Radiosity at the display vertices (Gouraud values): (vertices, 3).
    #[getter]
    fn vertex_b<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f32>> {
        PyArray2::from_owned_array(py, rgb_rows(&self.solved.vertex_radiosity()))
    }

    /// Display-vertex indices of every element, wound so that the normal is the radiating side: (elements, 3).
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let e = &self.solved.mesh.elements;
        let wound: Vec<[u32; 3]> = e
            .iter()
            .map(|e| {
                let [a, b, c] = e.vertex;
                if (e.p[1] - e.p[0]).cross(e.p[2] - e.p[0]).dot(e.normal) >= 0.0 {
                    [a, b, c]
                } else {
                    [a, c, b]
                }
            })
            .collect();
        PyArray2::from_owned_array(py, Array2::from_shape_fn((e.len(), 3), |(i, k)| wound[i][k]))
    }

    /// The convergence history: dict of arrays step, residual, seconds, rows.
    #[getter]
    fn history<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let h = &self.solved.history;
        let d = PyDict::new(py);
        d.set_item("step", PyArray1::from_iter(py, h.iter().map(|s| s.step as u64)))?;
        d.set_item("residual", PyArray1::from_iter(py, h.iter().map(|s| s.residual)))?;
        d.set_item("seconds", PyArray1::from_iter(py, h.iter().map(|s| s.seconds)))?;
        d.set_item("rows", PyArray1::from_iter(py, h.iter().map(|s| s.rows)))?;
        Ok(d)
    }

    /// The solver that ran (the automatic choice resolved).
    #[getter]
    fn solver(&self) -> String {
        format!("{:?}", self.solved.solver).to_lowercase()
    }

    #[getter]
    fn converged(&self) -> bool {
        self.solved.converged
    }

    /// Seconds spent meshing, on form factors and solving.
    #[getter]
    fn timings(&self) -> (f64, f64, f64) {
        (self.solved.mesh_seconds, self.solved.form_factor_seconds, self.solved.solve_seconds)
    }

    /// Form-factor rows computed and non-zero form factors stored.
    #[getter]
    fn form_factors(&self) -> (u64, usize) {
        (self.solved.rows_computed, self.solved.nnz)
    }

    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.solved.mesh.warnings.clone()
    }

    fn __len__(&self) -> usize {
        self.solved.mesh.elements.len()
    }

    /// The solution seen through the scene's camera (box filter, `spp` jittered samples per pixel).
    #[pyo3(signature = (spp=1, seed=0, threads=0))]
    fn image<'py>(&self, py: Python<'py>, spp: u32, seed: u64, threads: usize) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let settings = RenderSettings { spp, seed, threads, filter: Filter::Box, ..RenderSettings::from_scene(&self.scene) };
        settings.validate().map_err(to_py)?;
        let view = self.solved.view(self.shading);
        let film = py.allow_threads(|| render_pixels(&self.scene, &settings, &Progress::new(), &view)).map_err(to_py)?;
        to_array(py, film.image())
    }

    fn __repr__(&self) -> String {
        format!(
            "<svetlo.RadiositySolution: {} elements, solver {}, {}>",
            self.solved.mesh.elements.len(),
            self.solver(),
            if self.solved.converged { "converged" } else { "not converged" }
        )
    }
}
