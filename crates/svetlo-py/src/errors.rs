//! The exception hierarchy: `SvetloError` and below it scene, option and image errors; the
//! library's typed errors map onto them with the CLI's messages, and scene errors carry
//! `file`, `line` and `column` as attributes.

use pyo3::exceptions::{PyException, PyKeyboardInterrupt};
use pyo3::prelude::*;

pyo3::create_exception!(svetlo, SvetloError, PyException, "Base class of every error svetlo raises.");
pyo3::create_exception!(
    svetlo,
    SceneError,
    SvetloError,
    "A scene could not be loaded or is invalid. Attributes: file (str or None), line and column (int or None; 1-based), key (load_dict: the dictionary path, else None)."
);
pyo3::create_exception!(svetlo, OptionError, SvetloError, "A render setting or a method option is invalid (unknown key, value out of range).");
pyo3::create_exception!(svetlo, ImageError, SvetloError, "An image could not be read or written, or two images do not match. Attribute: file.");
pyo3::create_exception!(
    svetlo,
    RenderInterrupted,
    PyKeyboardInterrupt,
    "Ctrl-C during a render. The render stopped after its current pass; `e.result` is the RenderResult of the samples done and `e.image` its image."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("SvetloError", py.get_type::<SvetloError>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("OptionError", py.get_type::<OptionError>())?;
    m.add("ImageError", py.get_type::<ImageError>())?;
    m.add("RenderInterrupted", py.get_type::<RenderInterrupted>())?;
    Ok(())
}

/// An exception of type `E` with attributes set on its value.
fn with_attrs<E: pyo3::PyTypeInfo>(msg: String, attrs: &[(&str, PyObject)]) -> PyErr {
    Python::with_gil(|py| {
        let err = PyErr::from_type(py.get_type::<E>(), msg);
        let v = err.value(py);
        for (k, val) in attrs {
            // Setting an attribute on a fresh exception cannot fail short of memory exhaustion;
            // the message is still there if it does.
            let _ = v.setattr(*k, val);
        }
        err
    })
}

/// The library's error as the matching Python exception.
pub fn to_py(e: svetlo::Error) -> PyErr {
    use svetlo::Error as E;
    let msg = e.to_string();
    Python::with_gil(|py| {
        let none = || py.None();
        let s = |p: &std::path::Path| p.display().to_string().into_pyobject(py).map(|o| o.into_any().unbind()).unwrap_or_else(|_| py.None());
        let int = |n: u32| n.into_pyobject(py).map(|o| o.into_any().unbind()).unwrap_or_else(|_| py.None());
        match &e {
            E::SceneAt { file, line, col, .. } => {
                with_attrs::<SceneError>(msg, &[("file", s(file)), ("line", int(*line)), ("column", int(*col)), ("key", none())])
            }
            E::Scene { file, .. } | E::Mesh { file, .. } | E::Io { file, .. } => {
                with_attrs::<SceneError>(msg, &[("file", s(file)), ("line", none()), ("column", none()), ("key", none())])
            }
            E::Photometry { file, line, .. } => with_attrs::<SceneError>(msg, &[("file", s(file)), ("line", int(*line)), ("column", none()), ("key", none())]),
            E::Image { file, .. } => with_attrs::<ImageError>(msg, &[("file", s(file))]),
            // Over the memory budget: not the scene's fault as such, nor an option's alone.
            E::TooLarge { .. } => SvetloError::new_err(msg),
            E::Settings(_) => OptionError::new_err(msg),
            _ => with_attrs::<SceneError>(msg, &[("file", none()), ("line", none()), ("column", none()), ("key", none())]),
        }
    })
}

/// A `load_dict` error at a dictionary entry: a `SceneError` whose `key` is the entry's path
/// (it has no file or line of its own).
pub fn scene_key_err(msg: String, key: &str) -> PyErr {
    Python::with_gil(|py| {
        let k = key.into_pyobject(py).map(|o| o.into_any().unbind()).unwrap_or_else(|_| py.None());
        with_attrs::<SceneError>(msg, &[("file", py.None()), ("line", py.None()), ("column", py.None()), ("key", k)])
    })
}

/// An error reading or writing an image file: an `ImageError` naming the file.
pub fn to_py_image(e: svetlo::Error) -> PyErr {
    match &e {
        svetlo::Error::Io { file, .. } | svetlo::Error::Image { file, .. } => {
            let f = Python::with_gil(|py| file.display().to_string().into_pyobject(py).map(|o| o.into_any().unbind()).unwrap_or_else(|_| py.None()));
            with_attrs::<ImageError>(e.to_string(), &[("file", f)])
        }
        _ => to_py(e),
    }
}

pub fn option_err(msg: impl Into<String>) -> PyErr {
    OptionError::new_err(msg.into())
}

pub fn image_err(msg: impl Into<String>) -> PyErr {
    with_attrs::<ImageError>(msg.into(), &[("file", Python::with_gil(|py| py.None()))])
}
