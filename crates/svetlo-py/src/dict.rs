//! Mitsuba 3's dictionary scene format turned into the element tree that the library's one
//! Mitsuba loader reads, as if the dict were an XML file (so every plugin, default and check
//! of that loader applies, and the two cannot drift). Each element has a line number as in
//! the XML the tree prints as (one element per line, `dict_to_xml`), and for each line the
//! dictionary path that produced it, so that a loader error at a line is told as the key
//! (`scene['box']['bsdf']`). Built in Rust: walking the dict in Python cost 3x the XML load,
//! and going through XML text cost the printing and the parse again.

use crate::errors::SceneError;
use numpy::PyArrayMethods;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyMapping, PyString, PyTuple};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use svetlo::io::mitsuba::{Loc, Node};

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
    static BY_TYPE: std::sync::OnceLock<HashMap<&'static str, &'static str>> = std::sync::OnceLock::new();
    BY_TYPE.get_or_init(|| TAGS.iter().flat_map(|(tag, types)| types.split(' ').map(move |t| (t, *tag))).collect()).get(t).copied()
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

/// A finite number as the shortest text that reads back to it (as Python's repr; whole
/// numbers, common in matrices, without the float formatter).
fn num(v: f64, where_: &str) -> PyResult<String> {
    let mut o = String::new();
    push_num(&mut o, v, where_)?;
    Ok(o)
}

fn push_num(o: &mut String, v: f64, where_: &str) -> PyResult<()> {
    use std::fmt::Write;
    if !v.is_finite() {
        return Err(err(format!("load_dict: {where_}: {v} is not a finite number")));
    }
    // Exact below 2^53; -0.0 keeps its sign through the float formatter.
    let whole = v.fract() == 0.0 && v.abs() < 9.0e15 && !(v == 0.0 && v.is_sign_negative());
    let _ = if whole { write!(o, "{}", v as i64) } else { write!(o, "{v:?}") };
    Ok(())
}

fn nums(v: &[f64], sep: &str, where_: &str) -> PyResult<String> {
    let mut o = String::with_capacity(v.len() * 8);
    for (i, &x) in v.iter().enumerate() {
        if i > 0 {
            o.push_str(sep);
        }
        push_num(&mut o, x, where_)?;
    }
    Ok(o)
}

/// `d[key]`, or None when absent (a dict is asked without raising KeyError). The key is
/// interned by the caller (`intern!`) when it is a constant: a fresh str per lookup costs its
/// allocation and hash.
fn get<'py>(d: &Bound<'py, PyAny>, key: &Bound<'py, PyString>) -> Option<Bound<'py, PyAny>> {
    match d.downcast::<PyDict>() {
        Ok(dict) => dict.get_item(key).ok().flatten(),
        Err(_) => d.get_item(key).ok(),
    }
}

/// A mapping's entries in order, keys as strings: a dict's read in one pass, other mappings
/// through `keys()` and lookups.
fn entries<'py>(d: &Bound<'py, PyAny>, where_: &str) -> PyResult<Vec<(String, Bound<'py, PyAny>)>> {
    let bad_key = || err(format!("load_dict: {where_}: keys are strings"));
    if let Ok(dict) = d.downcast::<PyDict>() {
        return dict.iter().map(|(k, v)| Ok((k.extract::<String>().map_err(|_| bad_key())?, v))).collect();
    }
    let m = d.downcast::<PyMapping>()?;
    m.keys()?
        .iter()
        .map(|k| {
            let name = k.extract::<String>().map_err(|_| bad_key())?;
            let v = d.get_item(&k).map_err(|_| err(format!("load_dict: {where_}: '{name}' vanished while read")))?;
            Ok((name, v))
        })
        .collect()
}

fn key_path(parent: &str, key: &str) -> String {
    // Python's repr of a plain key: 'name' (keys with quotes are rare; escape them as repr would).
    if key.contains('\'') || key.contains('\\') {
        format!("{parent}[{key:?}]")
    } else {
        format!("{parent}['{key}']")
    }
}

/// Builds the tree, numbering its elements' lines as [`print_xml`] prints them.
struct Builder<'py> {
    py: Python<'py>,
    file: Arc<PathBuf>,
    /// The dictionary path of each line.
    keys: Vec<String>,
    ids: HashMap<String, &'static str>,
}

type Attrs = Vec<(String, String)>;

fn attr(k: &str, v: impl Into<String>) -> (String, String) {
    (k.to_string(), v.into())
}

impl<'py> Builder<'py> {
    /// The next line, produced by `key`.
    fn line(&mut self, key: &str) -> Loc {
        self.keys.push(key.to_string());
        Loc { file: self.file.clone(), line: self.keys.len() as u32, col: 1 }
    }

    fn leaf(&mut self, tag: &str, attrs: Attrs, key: &str) -> Node {
        Node { tag: tag.to_string(), attrs, children: Vec::new(), loc: self.line(key) }
    }

    /// An element whose children `fill` makes; its closing tag takes a line when it has any.
    fn parent(&mut self, tag: &str, attrs: Attrs, key: &str, fill: impl FnOnce(&mut Self, &mut Vec<Node>) -> PyResult<()>) -> PyResult<Node> {
        let loc = self.line(key);
        let mut children = Vec::new();
        fill(self, &mut children)?;
        if !children.is_empty() {
            self.keys.push(key.to_string());
        }
        Ok(Node { tag: tag.to_string(), attrs, children, loc })
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
            // Rows when the first item is a sequence: a failed extract (an exception) costs more
            // than the check.
            let first = v.get_item(0).ok();
            let rows_first = first.as_ref().is_some_and(|f| f.is_instance_of::<PyList>() || f.is_instance_of::<PyTuple>());
            if !rows_first {
                let x = v.extract::<Vec<f64>>().ok()?;
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
        // numpy float64 arrays (ScalarTransform4f's matrix) read directly: through `tolist`
        // they cost several times the rest of a dict's walk.
        if let Ok(a) = v.downcast::<numpy::PyArrayDyn<f64>>() {
            let ro = a.try_readonly().ok()?;
            let view = ro.as_array();
            return Some((view.iter().copied().collect(), view.shape().to_vec()));
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
        // Imported only for values that need it (an import costs microseconds per call).
        let a = self.py.import("numpy").ok()?.getattr("asarray").ok()?.call((v,), Some(&kw)).ok()?;
        let shape: Vec<usize> = a.getattr("shape").ok()?.extract().ok()?;
        let flat: Vec<f64> = a.call_method0("ravel").ok()?.call_method0("tolist").ok()?.extract().ok()?;
        Some((flat, shape))
    }

    fn property(&mut self, name: &str, v: &Bound<'py, PyAny>, where_: &str) -> PyResult<Node> {
        let n = || attr("name", name);
        let node = if v.is_instance_of::<PyBool>() {
            let b: bool = v.extract()?;
            self.leaf("boolean", vec![n(), attr("value", b.to_string())], where_)
        } else if v.is_instance_of::<PyInt>() {
            let i: i128 = v.extract().map_err(|_| err(format!("load_dict: {where_}: integer out of range")))?;
            self.leaf("integer", vec![n(), attr("value", i.to_string())], where_)
        } else if v.is_instance_of::<PyFloat>() {
            let x: f64 = v.extract()?;
            self.leaf("float", vec![n(), attr("value", num(x, where_)?)], where_)
        } else if let Ok(s) = v.downcast::<PyString>() {
            self.leaf("string", vec![n(), attr("value", s.to_cow()?)], where_)
        } else if v.is_instance_of::<PyDict>() || (!v.is_instance_of::<PyList>() && !v.is_instance_of::<PyTuple>() && v.downcast::<PyMapping>().is_ok()) {
            self.object(Some(name), v, where_, None)?
        } else {
            // numpy scalars, 3-vectors, transforms (anything with a 4x4 `.matrix`, or 4x4
            // arrays), paths. Transforms are asked for `.matrix` first: they are common, and a
            // failed attribute lookup costs an exception.
            let seq = v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>();
            let matrix = if seq { None } else { v.getattr(pyo3::intern!(self.py, "matrix")).ok() };
            if matrix.is_none() && !seq && v.hasattr(pyo3::intern!(self.py, "__fspath__"))? {
                let p: String = self.py.import("os")?.call_method1("fspath", (v,))?.extract()?;
                return Ok(self.leaf("string", vec![n(), attr("value", p)], where_));
            }
            let src = matrix.as_ref().unwrap_or(v);
            match self.numbers(src) {
                Some((x, shape)) if shape.is_empty() => {
                    // A numpy scalar: its dtype says bool, integer or float.
                    let kind = v.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<String>()).unwrap_or_default();
                    if kind == "b" {
                        self.leaf("boolean", vec![n(), attr("value", (x[0] != 0.0).to_string())], where_)
                    } else if kind == "i" || kind == "u" {
                        self.leaf("integer", vec![n(), attr("value", (x[0] as i64).to_string())], where_)
                    } else {
                        self.leaf("float", vec![n(), attr("value", num(x[0], where_)?)], where_)
                    }
                }
                Some((x, shape)) if shape == [3] && matrix.is_none() => self.leaf("point", vec![n(), attr("value", nums(&x, ", ", where_)?)], where_),
                Some((x, shape)) if shape == [4, 4] => {
                    let value = nums(&x, " ", where_)?;
                    self.parent("transform", vec![n()], where_, |b, children| {
                        children.push(b.leaf("matrix", vec![attr("value", value)], where_));
                        Ok(())
                    })?
                }
                _ => {
                    let r = v.repr().map(|r| r.to_string()).unwrap_or_default();
                    let r: String = r.chars().take(60).collect();
                    return Err(err(format!("load_dict: {where_}: cannot translate a value of type {} ({r})", v.get_type().name()?)));
                }
            }
        };
        Ok(node)
    }

    fn object(&mut self, name: Option<&str>, d: &Bound<'py, PyAny>, where_: &str, object_id: Option<&str>) -> PyResult<Node> {
        let items = entries(d, where_)?;
        let find = |k: &str| items.iter().find(|(n, _)| n == k).map(|(_, v)| v);
        let t: String = match find("type").map(|t| t.extract::<String>()) {
            Some(Ok(t)) => t,
            Some(Err(_)) | None => {
                let got = find("type").and_then(|t| t.repr().ok()).map(|r| r.to_string()).unwrap_or_else(|| "None".into());
                return Err(err(format!("load_dict: {where_}: a nested dictionary needs a 'type' (str), got {got}")));
            }
        };
        let mut name_attr: Attrs = name.map(|n| vec![attr("name", n)]).unwrap_or_default();
        let extra = |allowed: &[&str]| -> Vec<String> { items.iter().filter(|(k, _)| !allowed.contains(&k.as_str())).map(|(k, _)| format!("'{k}'")).collect() };
        match t.as_str() {
            "ref" => {
                let ex = extra(&["type", "id"]);
                let id: Option<String> = find("id").and_then(|i| i.extract().ok());
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
                let mut attrs = vec![attr("id", id)];
                attrs.extend(name_attr);
                return Ok(self.leaf("ref", attrs, where_));
            }
            "rgb" | "spectrum" => {
                let ex = extra(&["type", "value"]);
                let Some(v) = find("value").filter(|_| ex.is_empty()) else {
                    let more = if ex.is_empty() { String::new() } else { format!("; unknown keys [{}]", ex.join(", ")) };
                    return Err(err(format!("load_dict: {where_}: an {t} value is {{'type': '{t}', 'value': ...}}{more}")));
                };
                let (x, shape) = self.numbers(v).ok_or_else(|| err(format!("load_dict: {where_}: an {t} value is numbers")))?;
                let text = if t == "spectrum" && shape.len() == 2 && shape[1] == 2 {
                    // Wavelength-value pairs, Mitsuba's list form.
                    x.chunks(2).map(|p| Ok(format!("{}:{}", num(p[0], where_)?, num(p[1], where_)?))).collect::<PyResult<Vec<_>>>()?.join(", ")
                } else if x.len() == 1 || x.len() == 3 {
                    nums(&x, ", ", where_)?
                } else {
                    return Err(err(format!("load_dict: {where_}: an {t} value is one number or three, got {}", x.len())));
                };
                name_attr.push(attr("value", text));
                return Ok(self.leaf(&t, name_attr, where_));
            }
            _ => {}
        }
        let tag = tag_of(&t).ok_or_else(|| err(format!("load_dict: {where_}: unknown plugin type '{t}'")))?;
        let own_id: Option<String> = match find("id") {
            Some(i) => Some(i.extract().map_err(|_| err(format!("load_dict: {where_}: 'id' must be a str")))?),
            None => object_id.map(str::to_string),
        };
        let mut attrs = vec![attr("type", t.as_str())];
        attrs.extend(own_id.map(|i| attr("id", i)));
        attrs.extend(name_attr);
        self.parent(tag, attrs, where_, |b, children| {
            for (k, v) in &items {
                if k == "type" || k == "id" {
                    continue;
                }
                if k.is_empty() {
                    return Err(err(format!("load_dict: {where_}: keys are non-empty strings")));
                }
                let sub = key_path(where_, k);
                children.push(b.property(k, v, &sub)?);
            }
            Ok(())
        })
    }
}

/// Every referable object's id and tag: top-level keys, and nested dicts' 'id' entries.
fn collect_ids(d: &Bound<'_, PyMapping>, key: Option<String>, ids: &mut HashMap<String, &'static str>) -> PyResult<()> {
    let py = d.py();
    let tag = get(d.as_any(), pyo3::intern!(py, "type")).and_then(|t| t.extract::<String>().ok()).and_then(|t| tag_of(&t));
    let own: Option<String> = get(d.as_any(), pyo3::intern!(py, "id")).and_then(|i| i.extract().ok()).or(key);
    if let (Some(tag), Some(id)) = (tag, own) {
        ids.entry(id).or_insert(tag);
    }
    for v in d.values()?.iter() {
        // Only dicts (and other mappings) hold objects; the common values are ruled out first,
        // as the Mapping ABC's isinstance check is slow.
        let plain = v.is_instance_of::<PyString>()
            || v.is_instance_of::<PyFloat>()
            || v.is_instance_of::<PyInt>()
            || v.is_instance_of::<PyList>()
            || v.is_instance_of::<PyTuple>();
        if plain {
            continue;
        }
        if let Ok(m) = v.downcast::<PyMapping>() {
            collect_ids(m, None, ids)?;
        }
    }
    Ok(())
}

/// The element tree of a scene dict (its file standing as `file`) and, per line, the
/// dictionary path it came from.
fn tree(py: Python<'_>, scene: &Bound<'_, PyAny>, file: &Path) -> PyResult<(Node, Vec<String>)> {
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
    let mut b = Builder { py, file: Arc::new(file.to_path_buf()), keys: Vec::new(), ids };
    let node = b.parent("scene", vec![attr("version", "3.0.0")], "scene", |b, children| {
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
            children.push(b.object(None, m.as_any(), &where_, Some(&k))?);
        }
        Ok(())
    })?;
    // A scene without entries still closes on a line of its own, as it prints.
    if node.children.is_empty() {
        b.keys.push("scene".into());
    }
    Ok((node, b.keys))
}

/// The tree as XML, one element per line (the lines its elements are numbered by).
fn print_xml(n: &Node, depth: usize, out: &mut String) {
    for _ in 0..depth {
        out.push_str("  ");
    }
    out.push('<');
    out.push_str(&n.tag);
    for (k, v) in &n.attrs {
        out.push(' ');
        out.push_str(k);
        out.push('=');
        out.push_str(&quote(v));
    }
    if n.children.is_empty() && depth > 0 {
        out.push_str("/>\n");
        return;
    }
    out.push_str(">\n");
    for c in &n.children {
        print_xml(c, depth + 1, out);
    }
    for _ in 0..depth {
        out.push_str("  ");
    }
    out.push_str("</");
    out.push_str(&n.tag);
    out.push_str(">\n");
}

/// The XML for a scene dict and, per line, the dictionary path it came from.
#[pyfunction]
pub fn dict_to_xml(py: Python<'_>, scene: &Bound<'_, PyAny>) -> PyResult<(String, Vec<String>)> {
    let (root, keys) = tree(py, scene, Path::new("<dict>"))?;
    let mut xml = String::with_capacity(64 * keys.len());
    print_xml(&root, 0, &mut xml);
    Ok((xml, keys))
}

/// Load a scene dict: its tree goes to the loader directly (the GIL released while the scene
/// is built). `origin` stands for the file; a loader error at a line is raised as a
/// `SceneError` naming the dictionary key (`e.key`).
#[pyfunction]
#[pyo3(signature = (scene, origin, params=None))]
pub fn load_dict(py: Python<'_>, scene: &Bound<'_, PyAny>, origin: PathBuf, params: Option<Vec<(String, String)>>) -> PyResult<crate::scene::PyScene> {
    let d = crate::scene::defines(params)?;
    let (root, keys) = tree(py, scene, &origin)?;
    match py.allow_threads(|| svetlo::io::mitsuba::load_scene_from_tree(root, &origin, &d)) {
        Ok(scene) => Ok(crate::scene::PyScene::new(scene, &origin)),
        Err(svetlo::Error::SceneAt { line, msg, .. }) if line >= 1 && (line as usize) <= keys.len() => {
            let key = &keys[line as usize - 1];
            Err(crate::errors::scene_key_err(format!("load_dict: {key}: {msg}"), key))
        }
        Err(e) => Err(crate::errors::to_py(e)),
    }
}
