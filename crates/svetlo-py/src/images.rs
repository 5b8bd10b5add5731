//! Images between the library and numpy: a rendered image becomes an array without a copy (the
//! array's base owns the library's buffer); arrays passed in are checked (shape, finite values)
//! and copied. `write`, `read`, `relmse` and `ztest` are the CLI's `compare` as functions.

use crate::errors::{image_err, to_py_image};
use numpy::ndarray::Array3;
use numpy::{PyArray3, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use svetlo::film::compare::{rel_mse, z_test_with, MIN_PASS_FRACTION, SIGNIFICANCE};
use svetlo::film::Image;
use svetlo::Rgb;

const _: () = assert!(std::mem::size_of::<Rgb>() == 12 && std::mem::align_of::<Rgb>() == 4);

/// The pixels as a flat `f32` buffer, reusing the allocation.
fn rgb_to_f32(v: Vec<Rgb>) -> Vec<f32> {
    let mut v = std::mem::ManuallyDrop::new(v);
    let (ptr, len, cap) = (v.as_mut_ptr(), v.len(), v.capacity());
    // SAFETY: `Rgb` is `repr(C)` with three `f32` fields (size 12, align 4, checked above), so
    // `len` pixels are `3 len` initialised floats, and the allocation (`cap` pixels, align 4)
    // has exactly the layout of `3 cap` floats, which is what the new Vec will free.
    unsafe { Vec::from_raw_parts(ptr as *mut f32, len * 3, cap * 3) }
}

/// An image as a `(height, width, 3)` float32 array that owns the image's buffer.
pub fn to_array(py: Python<'_>, img: Image) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let (w, h) = (img.width, img.height);
    let a = Array3::from_shape_vec((h, w, 3), rgb_to_f32(img.data)).map_err(|e| image_err(format!("internal: image buffer does not match its size: {e}")))?;
    Ok(PyArray3::from_owned_array(py, a))
}

/// A `(height, width, 3)` array as an image; `what` names the argument in errors.
pub fn from_array(a: &PyReadonlyArray3<'_, f32>, what: &str) -> PyResult<Image> {
    let shape = a.shape();
    let (h, w) = (shape[0], shape[1]);
    if shape[2] != 3 {
        return Err(image_err(format!("{what}: expected an array of shape (height, width, 3), got {shape:?}")));
    }
    if w == 0 || h == 0 {
        return Err(image_err(format!("{what} is empty ({shape:?})")));
    }
    let v = a.as_array();
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let c = Rgb::new(v[[y, x, 0]], v[[y, x, 1]], v[[y, x, 2]]);
            if !c.is_finite() {
                return Err(image_err(format!("{what}: pixel (x={x}, y={y}) is not finite ({}, {}, {})", c.r, c.g, c.b)));
            }
            data.push(c);
        }
    }
    Ok(Image::new(w, h, data))
}

/// Write an image: the format follows the extension (.exr linear float, .png sRGB, .pfm).
#[pyfunction]
pub fn write(path: PathBuf, image: PyReadonlyArray3<'_, f32>) -> PyResult<()> {
    let img = from_array(&image, "image")?;
    image.py().allow_threads(|| svetlo::io::write_image(&path, &img)).map_err(to_py_image)
}

/// Read an image (EXR, PFM, PNG, JPEG) as a float32 (height, width, 3) array of linear RGB.
#[pyfunction]
pub fn read(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let img = py.allow_threads(|| svetlo::io::read_image(&path)).map_err(to_py_image)?;
    to_array(py, img)
}

/// Write a multi-layer EXR: the beauty as R, G, B and each `(name, image)` as `name.R` ... (the
/// CLI's AOV output).
#[pyfunction]
pub fn write_layers(path: PathBuf, image: PyReadonlyArray3<'_, f32>, layers: Vec<(String, PyReadonlyArray3<'_, f32>)>) -> PyResult<()> {
    let beauty = from_array(&image, "image")?;
    let layers = layers.iter().map(|(n, a)| Ok((n.clone(), from_array(a, n)?))).collect::<PyResult<Vec<_>>>()?;
    image.py().allow_threads(|| svetlo::io::image_io::write_exr_layers(&path, &beauty, &layers)).map_err(to_py_image)
}

/// Read a multi-layer EXR: the beauty and the list of (name, image) layers, in file order
/// (EXR sorts channels by name).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn read_layers(py: Python<'_>, path: PathBuf) -> PyResult<(Bound<'_, PyArray3<f32>>, Vec<(String, Bound<'_, PyArray3<f32>>)>)> {
    let (beauty, layers) = py.allow_threads(|| svetlo::io::image_io::read_exr_layers(&path)).map_err(to_py_image)?;
    let layers = layers.into_iter().map(|(n, im)| Ok((n, to_array(py, im)?))).collect::<PyResult<Vec<_>>>()?;
    Ok((to_array(py, beauty)?, layers))
}

/// Mean over pixels and channels of (x - r)^2 / (r^2 + 0.01).
#[pyfunction]
pub fn relmse(image: PyReadonlyArray3<'_, f32>, reference: PyReadonlyArray3<'_, f32>) -> PyResult<f64> {
    let (a, b) = (from_array(&image, "image")?, from_array(&reference, "reference")?);
    rel_mse(&a, &b).map_err(|e| image_err(e.to_string()))
}

/// Mitsuba's per-pixel Z-test: a dict with the verdict and its statistics.
#[pyfunction]
#[pyo3(signature = (image, reference, reference_variance, spp, significance=SIGNIFICANCE, min_fraction=MIN_PASS_FRACTION))]
pub fn ztest<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, f32>,
    reference: PyReadonlyArray3<'py, f32>,
    reference_variance: PyReadonlyArray3<'py, f32>,
    spp: u32,
    significance: f64,
    min_fraction: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let (a, r, v) = (from_array(&image, "image")?, from_array(&reference, "reference")?, from_array(&reference_variance, "reference_variance")?);
    if !(significance > 0.0 && significance < 1.0 && (0.0..=1.0).contains(&min_fraction)) {
        return Err(crate::errors::option_err(format!(
            "ztest: significance must be in (0, 1) and min_fraction in [0, 1], got {significance} and {min_fraction}"
        )));
    }
    let t = z_test_with(&a, &r, &v, spp, significance, min_fraction).map_err(|e| image_err(e.to_string()))?;
    let d = PyDict::new(py);
    d.set_item("passed", t.pass)?;
    d.set_item("fraction_passing", t.fraction_passing)?;
    d.set_item("channels", t.channels)?;
    d.set_item("failed", t.failed)?;
    d.set_item("alpha", t.alpha)?;
    d.set_item("min_p", t.min_p)?;
    d.set_item("relmse", t.relmse)?;
    d.set_item("mean_image", (t.mean_image.r, t.mean_image.g, t.mean_image.b))?;
    d.set_item("mean_reference", (t.mean_reference.r, t.mean_reference.g, t.mean_reference.b))?;
    d.set_item("spp", t.spp)?;
    d.set_item("min_fraction", min_fraction)?;
    Ok(d)
}
