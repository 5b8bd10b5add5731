//! Loading scenes (a file, or Mitsuba XML held in a string) and looking into them: what
//! `svetlo info` prints, as data.

use crate::errors::{option_err, to_py};
use glam::{Mat4, Vec3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use svetlo::camera::Projection;
use svetlo::geometry::Geometry;
use svetlo::scene::Scene;

/// A loaded scene (immutable). Renders share it; freeing it while a render runs is safe (the
/// render keeps its own reference).
#[pyclass(frozen, name = "Scene", module = "svetlo")]
pub struct PyScene {
    pub scene: Arc<Scene>,
    /// The file it came from, or the name a string was loaded under.
    origin: String,
}

fn v3(v: Vec3) -> (f32, f32, f32) {
    (v.x, v.y, v.z)
}

fn mat(m: &Mat4) -> Vec<Vec<f32>> {
    // Row-major, as numpy and Mitsuba's matrices print.
    (0..4).map(|r| (0..4).map(|c| m.col(c)[r]).collect()).collect()
}

/// `-D name=value` pairs from a dict of parameters (values already strings).
pub(crate) fn defines(params: Option<Vec<(String, String)>>) -> PyResult<Vec<(String, String)>> {
    let params = params.unwrap_or_default();
    for (k, _) in &params {
        if k.is_empty() || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(option_err(format!("'{k}' is not a scene parameter name (letters, digits and '_')")));
        }
    }
    Ok(params)
}

/// Load a Mitsuba XML scene file; `params` fill its `<default>` parameters.
#[pyfunction]
#[pyo3(signature = (path, params=None))]
pub fn load_file(py: Python<'_>, path: PathBuf, params: Option<Vec<(String, String)>>) -> PyResult<PyScene> {
    let d = defines(params)?;
    let scene = py.allow_threads(|| svetlo::io::load_scene_as(&path, None, &d).inspect(prepare)).map_err(to_py)?;
    Ok(PyScene { scene: Arc::new(scene), origin: path.display().to_string() })
}

/// Load a Mitsuba XML scene from a string. `origin` names it in error messages, and relative
/// file names in it are resolved against the folder of `origin`.
#[pyfunction]
#[pyo3(signature = (text, origin, params=None))]
pub fn load_string(py: Python<'_>, text: &str, origin: PathBuf, params: Option<Vec<(String, String)>>) -> PyResult<PyScene> {
    let d = defines(params)?;
    let scene = py.allow_threads(|| svetlo::io::load_scene_from_str(text, &origin, &d).inspect(prepare)).map_err(to_py)?;
    Ok(PyScene { scene: Arc::new(scene), origin: origin.display().to_string() })
}

/// The set-up of the scene's own integrator (its acceleration structures) made with loading,
/// as the CLI does and Mitsuba's `load_file` builds its BVH: `render` then starts at tracing.
/// Renders with other settings or methods build what they need themselves.
fn prepare(scene: &Scene) {
    if let Ok(method) = svetlo::methods::by_name(&scene.settings.integrator) {
        method.prepare(scene, &svetlo::integrator::RenderSettings::from_scene(scene));
    }
}

impl PyScene {
    pub(crate) fn new(scene: Scene, origin: &std::path::Path) -> Self {
        PyScene { scene: Arc::new(scene), origin: origin.display().to_string() }
    }

    fn camera_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = &self.scene.camera;
        let d = PyDict::new(py);
        match c.projection {
            Projection::Perspective { fov_x_deg, aperture_radius, focus_distance } => {
                d.set_item("type", if aperture_radius > 0.0 { "thinlens" } else { "perspective" })?;
                d.set_item("fov_x", fov_x_deg)?;
                d.set_item("aperture_radius", aperture_radius)?;
                d.set_item("focus_distance", focus_distance)?;
            }
            Projection::Orthographic => d.set_item("type", "orthographic")?,
        }
        d.set_item("width", c.width)?;
        d.set_item("height", c.height)?;
        d.set_item("position", v3(c.to_world.transform_point3(Vec3::ZERO)))?;
        d.set_item("direction", v3(c.to_world.transform_vector3(Vec3::Z).normalize_or_zero()))?;
        d.set_item("to_world", mat(&c.to_world))?;
        d.set_item("near_clip", c.near_clip)?;
        d.set_item("far_clip", c.far_clip)?;
        d.set_item("shutter", (c.shutter_open, c.shutter_close))?;
        Ok(d)
    }

    fn shapes_list<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let l = PyList::empty(py);
        for s in &self.scene.shapes {
            let d = PyDict::new(py);
            d.set_item("name", &s.name)?;
            match &*s.geometry {
                Geometry::Mesh(m) => {
                    d.set_item("type", "mesh")?;
                    d.set_item("triangles", m.triangle_count())?;
                }
                Geometry::Sphere(sp) => {
                    d.set_item("type", "sphere")?;
                    d.set_item("center", v3(sp.center))?;
                    d.set_item("radius", sp.radius)?;
                }
                Geometry::SdfGrid(g) => {
                    d.set_item("type", "sdfgrid")?;
                    d.set_item("resolution", g.res)?;
                    d.set_item("voxels", g.voxel_count())?;
                }
            }
            d.set_item("material", s.material)?;
            d.set_item("emitter", s.light)?;
            d.set_item("moving", s.motion.is_some())?;
            l.append(d)?;
        }
        Ok(l)
    }

    fn emitters_list<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let l = PyList::empty(py);
        for (i, light) in self.scene.lights.iter().enumerate() {
            let d = PyDict::new(py);
            d.set_item("type", light.kind_name())?;
            let shape = self.scene.shapes.iter().position(|s| s.light == Some(i as u32));
            d.set_item("shape", shape)?;
            l.append(d)?;
        }
        Ok(l)
    }

    fn bbox_tuple(&self) -> ((f32, f32, f32), (f32, f32, f32)) {
        let mut b = self.scene.accel.bounds();
        for m in &self.scene.moving {
            b = b.union(m.bounds);
        }
        (v3(b.min), v3(b.max))
    }
}

#[pymethods]
impl PyScene {
    /// Image width in pixels (the scene's film).
    #[getter]
    fn width(&self) -> u32 {
        self.scene.camera.width
    }

    #[getter]
    fn height(&self) -> u32 {
        self.scene.camera.height
    }

    /// The file the scene came from (or the origin a string or dict was loaded under).
    #[getter]
    fn origin(&self) -> &str {
        &self.origin
    }

    /// The camera: type, fov_x (degrees), aperture, width, height, position, direction, to_world (4x4, row-major), clip planes, shutter.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.camera_dict(py)
    }

    /// Axis-aligned bounds of the geometry: ((xmin, ymin, zmin), (xmax, ymax, zmax)).
    #[getter]
    fn bbox(&self) -> ((f32, f32, f32), (f32, f32, f32)) {
        self.bbox_tuple()
    }

    /// One dict per shape: name, type (mesh or sphere), triangles or center/radius, material index, emitter index or None.
    #[getter]
    fn shapes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        self.shapes_list(py)
    }

    /// The Mitsuba plugin name of each material (e.g. 'diffuse', 'twosided(roughconductor)').
    #[getter]
    fn materials(&self) -> Vec<String> {
        self.scene.materials.iter().map(|m| m.kind_name()).collect()
    }

    /// One dict per emitter: type (area, point, spot, directional, constant, envmap) and, for area lights, the shape's index.
    #[getter]
    fn emitters<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        self.emitters_list(py)
    }

    /// What the loader ignored or adapted.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.scene.warnings.clone()
    }

    /// What `svetlo info` prints, as a dict: shapes, materials, emitters, camera, settings, bounds, bbox, warnings.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("origin", &self.origin)?;
        d.set_item("shapes", self.shapes_list(py)?)?;
        d.set_item("materials", self.materials())?;
        d.set_item("emitters", self.emitters_list(py)?)?;
        d.set_item("camera", self.camera_dict(py)?)?;
        let s = &self.scene.settings;
        let st = PyDict::new(py);
        st.set_item("integrator", &s.integrator)?;
        st.set_item("spp", s.spp)?;
        st.set_item("max_depth", s.max_depth)?;
        st.set_item("rr_depth", s.rr_depth)?;
        st.set_item("sampler", format!("{:?}", s.sampler).to_lowercase())?;
        st.set_item("seed", s.seed)?;
        st.set_item("filter", format!("{:?}", s.filter))?;
        st.set_item("hide_emitters", s.hide_emitters)?;
        d.set_item("settings", st)?;
        let bounds = PyDict::new(py);
        bounds.set_item("center", v3(self.scene.bounds.center))?;
        bounds.set_item("radius", self.scene.bounds.radius)?;
        d.set_item("bounds", bounds)?;
        d.set_item("bbox", self.bbox_tuple())?;
        d.set_item("warnings", self.warnings())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let s = &self.scene;
        format!(
            "<svetlo.Scene '{}': {} shapes, {} materials, {} emitters, {}x{}>",
            Path::new(&self.origin).display(),
            s.shapes.len(),
            s.materials.len(),
            s.lights.len(),
            s.camera.width,
            s.camera.height
        )
    }
}
