//! Mitsuba 3's dictionary scene format translated into the Mitsuba XML that the library's one
//! scene loader reads (so every plugin, default and check of that loader applies, and the two
//! cannot drift). One element per line, and for each line the dictionary path that produced
//! it, so that a loader error at a line is told as the key (`scene['box']['bsdf']`).
//! Attribute values are escaped; nothing from the dict is written outside an attribute.
//! Written in Rust because walking the dict in Python cost 3x the XML load itself.

use crate::errors::SceneError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyMapping, PyString, PyTuple};
use std::collections::HashMap;

/// Plugin type -> XML tag, for every plugin of Mitsuba 3 (the loader says which it lacks).
const TAGS: &[(&str, &str)] = &[
    ("sensor", "perspective thinlens orthographic radiancemeter irradiancemeter batch distant"),
    ("film", "hdrfilm specfilm"),
    ("rfilter", "box tent gaussian mitchell catmullrom lanczos"),
    ("sampler", "independent stratified multijitter orthogonal ldsampler"),
    (
        "integrator",
        "path direct bdpt ptracer light whitted distributed zbuffer radiosity photon sppm pssmlt mlt volpath volpathmis moment aov depth stokes prb prb_basic prb_reparam direct_projective prb_projective",
    ),
    ("emitter", "area point spot directional constant envmap projector directionalarea"),
    (
        "bsdf",
        "diffuse dielectric thindielectric roughdielectric conductor roughconductor plastic roughplastic twosided mask null bumpmap normalmap blendbsdf principled principledthin hair measured pplastic polarizer retarder circular roughcoating phong blinnphong cooktorrance roughdiffuse ward",
    ),
    ("shape", "obj ply serialized sphere cube rectangle disk cylinder shapegroup instance sdfgrid bsplinecurve linearcurve ellipsoids ellipsoidsmesh merge"),
    ("texture", "bitmap checkerboard mesh_attribute volume"),
    ("medium", "homogeneous heterogeneous"),
    ("volume", "constvolume gridvolume"),
];

fn tag_of(t: &str) -> Option<&'static str> {
    TAGS.iter().find(|(_, types)| types.split(' ').any(|x| x == t)).map(|(tag, _)| *tag)
}

fn err(msg: String) -> PyErr {
    SceneError::new_err(msg)
}

/// `"value"` with every character that could end or change an attribute escaped.
fn quote(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\n' => o.push_str("&#10;"),
            '\r' => o.push_str("&#13;"),
            '\t' => o.push_str("&#9;"),
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// A finite number as the shortest text that reads back to it (as Python's repr).
fn num(v: f64, where_: &str) -> PyResult<String> {
    if !v.is_finite() {
        return Err(err(format!("load_dict: {where_}: {v} is not a finite number")));
    }
    Ok(format!("{v:?}"))
}

fn nums(v: &[f64], sep: &str, where_: &str) -> PyResult<String> {
    Ok(v.iter().map(|&x| num(x, where_)).collect::<PyResult<Vec<_>>>()?.join(sep))
}

/// `d[key]`, or None when absent (a dict is asked without raising KeyError).
fn get<'py>(d: &Bound<'py, PyAny>, key: &str) -> Option<Bound<'py, PyAny>> {
    match d.downcast::<PyDict>() {
        Ok(dict) => dict.get_item(key).ok().flatten(),
        Err(_) => d.get_item(key).ok(),
    }
}

fn key_path(parent: &str, key: &str) -> String {
    // Python's repr of a plain key: 'name' (keys with quotes are rare; escape them as repr would).
    if key.contains('\'') || key.contains('\\') {
        format!("{parent}[{key:?}]")
    } else {
        format!("{parent}['{key}']")
    }
}

struct Writer<'py> {
    py: Python<'py>,
    xml: String,
    keys: Vec<String>,
    ids: HashMap<String, &'static str>,
    np_asarray: Bound<'py, PyAny>,
}

impl<'py> Writer<'py> {
    fn emit(&mut self, depth: usize, text: &str, key: &str) {
        for _ in 0..depth {
            self.xml.push_str("  ");
        }
        self.xml.push_str(text);
        self.xml.push('\n');
        self.keys.push(key.to_string());
    }

    /// A value as a flat float64 array and its shape, when it is numbers: lists, tuples and
    /// numpy arrays directly, anything else through `numpy.asarray`.
    fn numbers(&self, v: &Bound<'py, PyAny>) -> Option<(Vec<f64>, Vec<usize>)> {
        fn nested(v: &Bound<'_, PyAny>) -> Option<(Vec<f64>, Vec<usize>)> {
            if v.is_instance_of::<PyFloat>() || v.is_instance_of::<PyInt>() {
                return Some((vec![v.extract().ok()?], vec![]));
            }
            if !(v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>()) {
                return None;
            }
            if let Ok(x) = v.extract::<Vec<f64>>() {
                let n = x.len();
                return Some((x, vec![n]));
            }
            let rows = v.extract::<Vec<Vec<f64>>>().ok()?;
            let c = rows.first().map_or(0, Vec::len);
            if rows.iter().any(|r| r.len() != c) {
                return None;
            }
            let r = rows.len();
            Some((rows.into_iter().flatten().collect(), vec![r, c]))
        }
        if let Some(x) = nested(v) {
            return Some(x);
        }
        if v.hasattr("tolist").unwrap_or(false) {
            if let Some(x) = v.call_method0("tolist").ok().and_then(|l| nested(&l)) {
                return Some(x);
            }
        }
        let kw = PyDict::new(self.py);
        kw.set_item("dtype", "float64").ok()?;
        let a = self.np_asarray.call((v,), Some(&kw)).ok()?;
        let shape: Vec<usize> = a.getattr("shape").ok()?.extract().ok()?;
        let flat: Vec<f64> = a.call_method0("ravel").ok()?.call_method0("tolist").ok()?.extract().ok()?;
        Some((flat, shape))
    }

    fn property(&mut self, depth: usize, name: &str, v: &Bound<'py, PyAny>, where_: &str) -> PyResult<()> {
        let n = quote(name);
        if v.is_instance_of::<PyBool>() {
            let b: bool = v.extract()?;
            self.emit(depth, &format!("<boolean name={n} value=\"{b}\"/>"), where_);
        } else if v.is_instance_of::<PyInt>() {
            let i: i128 = v.extract().map_err(|_| err(format!("load_dict: {where_}: integer out of range")))?;
            self.emit(depth, &format!("<integer name={n} value=\"{i}\"/>"), where_);
        } else if v.is_instance_of::<PyFloat>() {
            let x: f64 = v.extract()?;
            self.emit(depth, &format!("<float name={n} value=\"{}\"/>", num(x, where_)?), where_);
        } else if let Ok(s) = v.downcast::<PyString>() {
            self.emit(depth, &format!("<string name={n} value={}/>", quote(&s.to_cow()?)), where_);
        } else if v.is_instance_of::<PyDict>() || v.downcast::<PyMapping>().is_ok() {
            self.object(depth, Some(name), v, where_, None)?;
        } else if !(v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>()) && v.hasattr("__fspath__")? {
            let p: String = self.py.import("os")?.call_method1("fspath", (v,))?.extract()?;
            self.emit(depth, &format!("<string name={n} value={}/>", quote(&p)), where_);
        } else {
            // numpy scalars, 3-vectors, transforms (anything with a 4x4 `.matrix`, or 4x4 arrays).
            let seq = v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>();
            let matrix = if seq { None } else { v.getattr("matrix").ok() };
            let src = matrix.as_ref().unwrap_or(v);
            match self.numbers(src) {
                Some((x, shape)) if shape.is_empty() => {
                    // A numpy scalar: its dtype says bool, integer or float.
                    let kind = v.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<String>()).unwrap_or_default();
                    if kind == "b" {
                        self.emit(depth, &format!("<boolean name={n} value=\"{}\"/>", x[0] != 0.0), where_);
                    } else if kind == "i" || kind == "u" {
                        self.emit(depth, &format!("<integer name={n} value=\"{}\"/>", x[0] as i64), where_);
                    } else {
                        self.emit(depth, &format!("<float name={n} value=\"{}\"/>", num(x[0], where_)?), where_);
                    }
                }
                Some((x, shape)) if shape == [3] && matrix.is_none() => {
                    self.emit(depth, &format!("<point name={n} value=\"{}\"/>", nums(&x, ", ", where_)?), where_);
                }
                Some((x, shape)) if shape == [4, 4] => {
                    self.emit(depth, &format!("<transform name={n}>"), where_);
                    self.emit(depth + 1, &format!("<matrix value=\"{}\"/>", nums(&x, " ", where_)?), where_);
                    self.emit(depth, "</transform>", where_);
                }
                _ => {
                    let r = v.repr().map(|r| r.to_string()).unwrap_or_default();
                    let r: String = r.chars().take(60).collect();
                    return Err(err(format!("load_dict: {where_}: cannot translate a value of type {} ({r})", v.get_type().name()?)));
                }
            }
        }
        Ok(())
    }

    fn object(&mut self, depth: usize, name: Option<&str>, d: &Bound<'py, PyAny>, where_: &str, object_id: Option<&str>) -> PyResult<()> {
        let m = d.downcast::<PyMapping>()?;
        let t: String = match get(d, "type").map(|t| t.extract::<String>()) {
            Some(Ok(t)) => t,
            Some(Err(_)) | None => {
                let got = get(d, "type").and_then(|t| t.repr().ok()).map(|r| r.to_string()).unwrap_or_else(|| "None".into());
                return Err(err(format!("load_dict: {where_}: a nested dictionary needs a 'type' (str), got {got}")));
            }
        };
        let mut name_attr = name.map(|n| format!(" name={}", quote(n))).unwrap_or_default();
        let keys: Vec<String> =
            m.keys()?.iter().map(|k| k.extract::<String>()).collect::<PyResult<_>>().map_err(|_| err(format!("load_dict: {where_}: keys are strings")))?;
        let extra = |allowed: &[&str]| -> Vec<String> { keys.iter().filter(|k| !allowed.contains(&k.as_str())).map(|k| format!("'{k}'")).collect() };
        match t.as_str() {
            "ref" => {
                let ex = extra(&["type", "id"]);
                let id: Option<String> = get(d, "id").and_then(|i| i.extract().ok());
                let Some(id) = id.filter(|_| ex.is_empty()) else {
                    let more = if ex.is_empty() { String::new() } else { format!("; unknown keys [{}]", ex.join(", ")) };
                    return Err(err(format!("load_dict: {where_}: a reference is {{'type': 'ref', 'id': str}}{more}")));
                };
                let Some(&tag) = self.ids.get(&id) else {
                    return Err(err(format!("load_dict: {where_}: reference to unknown id '{id}'")));
                };
                // A reference to a texture is a named property; one to a bsdf or an emitter a
                // child object, which the XML writes without a name.
                if tag != "texture" && !matches!(name, Some("interior") | Some("exterior")) {
                    name_attr.clear();
                }
                self.emit(depth, &format!("<ref id={}{name_attr}/>", quote(&id)), where_);
                return Ok(());
            }
            "rgb" | "spectrum" => {
                let ex = extra(&["type", "value"]);
                let Some(v) = get(d, "value").filter(|_| ex.is_empty()) else {
                    let more = if ex.is_empty() { String::new() } else { format!("; unknown keys [{}]", ex.join(", ")) };
                    return Err(err(format!("load_dict: {where_}: an {t} value is {{'type': '{t}', 'value': ...}}{more}")));
                };
                let (x, shape) = self.numbers(&v).ok_or_else(|| err(format!("load_dict: {where_}: an {t} value is numbers")))?;
                let text = if t == "spectrum" && shape.len() == 2 && shape[1] == 2 {
                    // Wavelength-value pairs, Mitsuba's list form.
                    x.chunks(2).map(|p| Ok(format!("{}:{}", num(p[0], where_)?, num(p[1], where_)?))).collect::<PyResult<Vec<_>>>()?.join(", ")
                } else if x.len() == 1 || x.len() == 3 {
                    nums(&x, ", ", where_)?
                } else {
                    return Err(err(format!("load_dict: {where_}: an {t} value is one number or three, got {}", x.len())));
                };
                self.emit(depth, &format!("<{t}{name_attr} value=\"{text}\"/>"), where_);
                return Ok(());
            }
            _ => {}
        }
        let tag = tag_of(&t).ok_or_else(|| err(format!("load_dict: {where_}: unknown plugin type '{t}'")))?;
        let own_id: Option<String> = match get(d, "id") {
            Some(i) => Some(i.extract().map_err(|_| err(format!("load_dict: {where_}: 'id' must be a str")))?),
            None => object_id.map(str::to_string),
        };
        let id_attr = own_id.map(|i| format!(" id={}", quote(&i))).unwrap_or_default();
        self.emit(depth, &format!("<{tag} type={}{id_attr}{name_attr}>", quote(&t)), where_);
        for k in &keys {
            if k == "type" || k == "id" {
                continue;
            }
            if k.is_empty() {
                return Err(err(format!("load_dict: {where_}: keys are non-empty strings")));
            }
            let sub = key_path(where_, k);
            let v = get(d, k).ok_or_else(|| err(format!("load_dict: {sub}: vanished while read")))?;
            self.property(depth + 1, k, &v, &sub)?;
        }
        self.emit(depth, &format!("</{tag}>"), where_);
        Ok(())
    }
}

/// Every referable object's id and tag: top-level keys, and nested dicts' 'id' entries.
fn collect_ids(d: &Bound<'_, PyMapping>, key: Option<String>, ids: &mut HashMap<String, &'static str>) -> PyResult<()> {
    let tag = get(d.as_any(), "type").and_then(|t| t.extract::<String>().ok()).and_then(|t| tag_of(&t));
    let own: Option<String> = get(d.as_any(), "id").and_then(|i| i.extract().ok()).or(key);
    if let (Some(tag), Some(id)) = (tag, own) {
        ids.entry(id).or_insert(tag);
    }
    for v in d.values()?.iter() {
        if let Ok(m) = v.downcast::<PyMapping>() {
            collect_ids(m, None, ids)?;
        }
    }
    Ok(())
}

/// The XML for a scene dict and, per line, the dictionary path it came from.
#[pyfunction]
pub fn dict_to_xml(py: Python<'_>, scene: &Bound<'_, PyAny>) -> PyResult<(String, Vec<String>)> {
    let Ok(root) = scene.downcast::<PyMapping>() else {
        return Err(pyo3::exceptions::PyTypeError::new_err(format!("load_dict: expected a dict, got {}", scene.get_type().name()?)));
    };
    let ty: Option<String> = root.get_item("type").ok().and_then(|t| t.extract().ok());
    if ty.as_deref() != Some("scene") {
        let got = root.get_item("type").ok().and_then(|t| t.repr().ok()).map(|r| r.to_string()).unwrap_or_else(|| "None".into());
        return Err(err(format!("load_dict: the top-level dictionary must have 'type': 'scene', got {got}")));
    }
    let mut ids = HashMap::new();
    for item in root.items()?.iter() {
        let (k, v): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item.extract()?;
        if let (Ok(k), Ok(m)) = (k.extract::<String>(), v.downcast::<PyMapping>()) {
            collect_ids(m, Some(k), &mut ids)?;
        }
    }
    let mut w = Writer { py, xml: String::new(), keys: Vec::new(), ids, np_asarray: py.import("numpy")?.getattr("asarray")? };
    w.emit(0, "<scene version=\"3.0.0\">", "scene");
    for item in root.items()?.iter() {
        let (k, v): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item.extract()?;
        let k: String = k.extract().map_err(|_| err("load_dict: scene: keys are strings".into()))?;
        if k == "type" {
            continue;
        }
        if k.is_empty() {
            return Err(err("load_dict: scene: keys are non-empty strings".into()));
        }
        let where_ = key_path("scene", &k);
        let Ok(m) = v.downcast::<PyMapping>() else {
            return Err(err(format!("load_dict: {where_}: a scene's entries are objects (dicts with a 'type'), got {}", v.get_type().name()?)));
        };
        let t: Option<String> = m.get_item("type").ok().and_then(|t| t.extract().ok());
        if let Some(t @ ("rgb" | "spectrum" | "ref")) = t.as_deref() {
            return Err(err(format!("load_dict: {where_}: a '{t}' cannot stand at the top level of a scene")));
        }
        // Top-level keys are ids, as in Mitsuba: {'type': 'ref', 'id': key} finds them.
        w.object(1, None, m.as_any(), &where_, Some(&k))?;
    }
    w.emit(0, "</scene>", "scene");
    Ok((w.xml, w.keys))
}
