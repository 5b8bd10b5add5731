"""Mitsuba 3's dictionary scene format, translated into the Mitsuba XML that svetlo's loader reads.

Why XML: the XML loader is svetlo's one scene reader, with every plugin, default, unit and
check already in it and tested against Mitsuba; a second path from dicts into the scene
builder would duplicate all of it and drift. The translation is mechanical (each dict becomes
an element, each value a property), generated one element per line so that an error the
loader reports at a line is mapped back to the dictionary key that produced it
(``SceneError.key``, e.g. ``scene['box']['bsdf']``). Attribute values are escaped by
``xml.sax.saxutils.quoteattr``; nothing from the dict is written outside an attribute.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _svetlo
from ._svetlo import SceneError

# Plugin type -> XML tag, for every plugin of Mitsuba 3 (svetlo's loader says which it does not support).
_TAGS: Dict[str, str] = {}
for _tag, _types in {
    "sensor": "perspective thinlens orthographic radiancemeter irradiancemeter batch distant",
    "film": "hdrfilm specfilm",
    "rfilter": "box tent gaussian mitchell catmullrom lanczos",
    "sampler": "independent stratified multijitter orthogonal ldsampler",
    "integrator": "path direct bdpt ptracer light whitted distributed zbuffer radiosity photon sppm pssmlt mlt "
    "volpath volpathmis moment aov depth stokes prb prb_basic prb_reparam direct_projective prb_projective",
    "emitter": "area point spot directional constant envmap projector directionalarea",
    "bsdf": "diffuse dielectric thindielectric roughdielectric conductor roughconductor plastic roughplastic "
    "twosided mask null bumpmap normalmap blendbsdf principled principledthin hair measured pplastic polarizer "
    "retarder circular roughcoating phong blinnphong cooktorrance roughdiffuse ward",
    "shape": "obj ply serialized sphere cube rectangle disk cylinder shapegroup instance sdfgrid bsplinecurve "
    "linearcurve ellipsoids ellipsoidsmesh merge",
    "texture": "bitmap checkerboard mesh_attribute volume",
    "medium": "homogeneous heterogeneous",
    "volume": "constvolume gridvolume",
}.items():
    for _t in _types.split():
        _TAGS[_t] = _tag


def _fmt(x: Any) -> str:
    v = float(x)
    if not math.isfinite(v):
        raise ValueError(f"{v} is not a finite number")
    return repr(v)


def _fmt_all(a: np.ndarray) -> List[str]:
    """Finite numbers as text (shortest round trip)."""
    if not np.isfinite(a).all():
        raise ValueError(f"{a[~np.isfinite(a)].reshape(-1)[0]} is not a finite number")
    return [repr(v) for v in a.reshape(-1).tolist()]


_ESCAPES = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "\n": "&#10;", "\r": "&#13;", "\t": "&#9;"})


def quoteattr(s: str) -> str:
    """An XML attribute value, quoted, with every character that could end or change it escaped."""
    return '"' + s.translate(_ESCAPES) + '"'


def _is_map(v: Any) -> bool:
    return type(v) is dict or isinstance(v, Mapping)


class ScalarTransform4f:
    """A 4x4 affine transform with Mitsuba's builder methods, for dicts written without Mitsuba.

    ``ScalarTransform4f().translate([0, 1, 0]).rotate([0, 1, 0], 30).scale(2)`` composes as
    Mitsuba does (each call multiplies on the right). ``load_dict`` also accepts Mitsuba's own
    ``mi.ScalarTransform4f``, a 4x4 nested list or a numpy array.
    """

    def __init__(self, matrix: Any = None):
        self.matrix = np.eye(4) if matrix is None else np.array(matrix, dtype=np.float64).reshape(4, 4)

    def _then(self, m: np.ndarray) -> "ScalarTransform4f":
        return ScalarTransform4f(self.matrix @ m)

    def translate(self, v: Sequence[float]) -> "ScalarTransform4f":
        m = np.eye(4)
        m[:3, 3] = np.asarray(v, dtype=np.float64).reshape(3)
        return self._then(m)

    def scale(self, v: Any) -> "ScalarTransform4f":
        s = np.broadcast_to(np.asarray(v, dtype=np.float64), (3,))
        return self._then(np.diag([s[0], s[1], s[2], 1.0]))

    def rotate(self, axis: Sequence[float], angle: float) -> "ScalarTransform4f":
        # The axis as given, not normalised: Mitsuba's rotate does the same.
        a = np.asarray(axis, dtype=np.float64).reshape(3)
        t = math.radians(angle)
        c, s = math.cos(t), math.sin(t)
        x, y, z = a
        r = np.array(
            [
                [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
            ]
        )
        m = np.eye(4)
        m[:3, :3] = r
        return self._then(m)

    def look_at(self, origin: Sequence[float], target: Sequence[float], up: Sequence[float]) -> "ScalarTransform4f":
        o, t, u = (np.asarray(v, dtype=np.float64).reshape(3) for v in (origin, target, up))
        d = t - o
        d = d / np.linalg.norm(d)
        left = np.cross(u, d)
        left = left / np.linalg.norm(left)
        new_up = np.cross(d, left)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
        return self._then(m)

    def __matmul__(self, other: "ScalarTransform4f") -> "ScalarTransform4f":
        return ScalarTransform4f(self.matrix @ _matrix(other))

    def __repr__(self) -> str:
        return f"ScalarTransform4f({self.matrix.tolist()})"


def _matrix(v: Any) -> Optional[np.ndarray]:
    """The 4x4 matrix of a transform value (svetlo's, Mitsuba's, nested lists, numpy), or None."""
    m = getattr(v, "matrix", None)
    src = m if m is not None else v
    try:
        a = np.array(src, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if a.shape != (4, 4):
        return None
    return a


class _Writer:
    """XML lines and, for each, the dictionary path that produced it."""

    def __init__(self, ids: Dict[str, str]) -> None:
        self.lines: List[str] = []
        self.keys: List[str] = []
        # id -> XML tag of every object that can be referenced.
        self.ids = ids

    def emit(self, depth: int, text: str, key: str) -> None:
        self.lines.append("  " * depth + text)
        self.keys.append(key)


def _path(parent: str, key: str) -> str:
    return f"{parent}[{key!r}]"


def _is_vec3(v: Any) -> bool:
    if isinstance(v, (str, bytes, Mapping)):
        return False
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return a.shape == (3,)


def _color_value(v: Any, where: str) -> str:
    if type(v) in (float, int):
        return _fmt(v)
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.size not in (1, 3):
        raise SceneError(f"load_dict: {where}: an rgb value is one number or three, got {a.size}")
    return ", ".join(_fmt_all(a))


def _property(w: _Writer, depth: int, name: str, v: Any, where: str) -> None:
    n = quoteattr(name)
    tv = type(v)
    if tv is float:
        w.emit(depth, f"<float name={n} value=\"{_fmt(v)}\"/>", where)
    elif tv is int:
        w.emit(depth, f"<integer name={n} value=\"{v}\"/>", where)
    elif tv is str:
        w.emit(depth, f"<string name={n} value={quoteattr(v)}/>", where)
    elif _is_map(v):
        _object(w, depth, name, v, where)
    elif isinstance(v, (bool, np.bool_)):
        w.emit(depth, f"<boolean name={n} value={quoteattr('true' if v else 'false')}/>", where)
    elif isinstance(v, (int, np.integer)):
        w.emit(depth, f"<integer name={n} value={quoteattr(str(int(v)))}/>", where)
    elif isinstance(v, (float, np.floating)):
        w.emit(depth, f"<float name={n} value={quoteattr(_fmt(v))}/>", where)
    elif isinstance(v, str):
        w.emit(depth, f"<string name={n} value={quoteattr(v)}/>", where)
    elif isinstance(v, os.PathLike):
        w.emit(depth, f"<string name={n} value={quoteattr(os.fspath(v))}/>", where)
    elif _is_vec3(v):
        w.emit(depth, f"<point name={n} value=\"{', '.join(_fmt_all(np.asarray(v, dtype=np.float64)))}\"/>", where)
    elif _matrix(v) is not None:
        w.emit(depth, f"<transform name={n}>", where)
        w.emit(depth + 1, f"<matrix value=\"{' '.join(_fmt_all(_matrix(v)))}\"/>", where)
        w.emit(depth, "</transform>", where)
    else:
        raise SceneError(f"load_dict: {where}: cannot translate a value of type {type(v).__name__} ({v!r:.60})")


def _object(w: _Writer, depth: int, name: Optional[str], d: Mapping[str, Any], where: str, object_id: Optional[str] = None) -> None:
    t = d.get("type")
    if not isinstance(t, str):
        raise SceneError(f"load_dict: {where}: a nested dictionary needs a 'type' (str), got {t!r}")
    name_attr = f" name={quoteattr(name)}" if name is not None else ""
    if t == "ref":
        ref = d.get("id")
        extra = sorted(set(d) - {"type", "id"})
        if not isinstance(ref, str) or extra:
            raise SceneError(f"load_dict: {where}: a reference is {{'type': 'ref', 'id': str}}" + (f"; unknown keys {extra}" if extra else ""))
        tag = w.ids.get(ref)
        if tag is None:
            raise SceneError(f"load_dict: {where}: reference to unknown id '{ref}'")
        # A reference to a texture is a named property; one to a bsdf or an emitter is a child
        # object, which the XML writes without a name.
        if tag != "texture" and name not in ("interior", "exterior"):
            name_attr = ""
        w.emit(depth, f"<ref id={quoteattr(ref)}{name_attr}/>", where)
        return
    if t in ("rgb", "spectrum"):
        extra = sorted(set(d) - {"type", "value"})
        if "value" not in d or extra:
            raise SceneError(f"load_dict: {where}: an {t} value is {{'type': '{t}', 'value': ...}}" + (f"; unknown keys {extra}" if extra else ""))
        v = d["value"]
        if t == "spectrum" and not isinstance(v, (int, float, np.number)):
            # Wavelength-value pairs, Mitsuba's list form.
            try:
                pairs = ", ".join(f"{_fmt(a)}:{_fmt(b)}" for a, b in v)
            except (TypeError, ValueError) as e:
                raise SceneError(f"load_dict: {where}: a spectrum value is a number or (wavelength, value) pairs") from e
            w.emit(depth, f"<spectrum{name_attr} value={quoteattr(pairs)}/>", where)
            return
        try:
            value = _color_value(v, where)
        except (TypeError, ValueError) as e:
            raise SceneError(f"load_dict: {where}: {t} value: {e}") from e
        w.emit(depth, f"<{t}{name_attr} value={quoteattr(value)}/>", where)
        return
    tag = _TAGS.get(t)
    if tag is None:
        raise SceneError(f"load_dict: {where}: unknown plugin type '{t}'")
    own_id = d.get("id", object_id)
    if own_id is not None and not isinstance(own_id, str):
        raise SceneError(f"load_dict: {where}: 'id' must be a str, got {type(own_id).__name__}")
    id_attr = f" id={quoteattr(own_id)}" if own_id is not None else ""
    w.emit(depth, f"<{tag} type={quoteattr(t)}{id_attr}{name_attr}>", where)
    for k, v in d.items():
        if k in ("type", "id"):
            continue
        if not isinstance(k, str) or not k:
            raise SceneError(f"load_dict: {where}: keys are non-empty strings, got {k!r}")
        sub = _path(where, k)
        if _is_map(v) and v.get("type") not in ("rgb", "spectrum", "ref"):
            # A nested plugin: Mitsuba names it by its key (the emitter, bsdf, film, ...).
            _object(w, depth + 1, k, v, sub)
        else:
            _property(w, depth + 1, k, v, sub)
    w.emit(depth, f"</{tag}>", where)


def _collect_ids(scene: Mapping[str, Any]) -> Dict[str, str]:
    """Every referable object's id and tag: top-level keys, and nested dicts' 'id' entries."""
    ids: Dict[str, str] = {}

    def walk(d: Mapping[str, Any], key: Optional[str]) -> None:
        t = d.get("type")
        own = d.get("id", key)
        if isinstance(t, str) and t in _TAGS and isinstance(own, str):
            ids.setdefault(own, _TAGS[t])
        for k, v in d.items():
            if _is_map(v):
                walk(v, None)

    for k, v in scene.items():
        if _is_map(v):
            walk(v, k)
    return ids


def to_xml(scene: Mapping[str, Any]) -> Tuple[str, List[str]]:
    """The XML for a scene dict and, per line (0-based), the dictionary path it came from."""
    if not _is_map(scene):
        raise TypeError(f"load_dict: expected a dict, got {type(scene).__name__}")
    if scene.get("type") != "scene":
        raise SceneError(f"load_dict: the top-level dictionary must have 'type': 'scene', got {scene.get('type')!r}")
    w = _Writer(_collect_ids(scene))
    w.emit(0, '<scene version="3.0.0">', "scene")
    for k, v in scene.items():
        if k == "type":
            continue
        if not isinstance(k, str) or not k:
            raise SceneError(f"load_dict: scene: keys are non-empty strings, got {k!r}")
        where = _path("scene", k)
        if not _is_map(v):
            raise SceneError(f"load_dict: {where}: a scene's entries are objects (dicts with a 'type'), got {type(v).__name__}")
        if v.get("type") in ("rgb", "spectrum", "ref"):
            raise SceneError(f"load_dict: {where}: a '{v.get('type')}' cannot stand at the top level of a scene")
        # Top-level keys are ids, as in Mitsuba: {'type': 'ref', 'id': key} finds them.
        _object(w, 1, None, v, where, object_id=k)
    w.emit(0, "</scene>", "scene")
    return "\n".join(w.lines) + "\n", w.keys


def load_dict(scene: Mapping[str, Any], origin: "os.PathLike[str] | str | None" = None, **params: Any) -> "_svetlo.Scene":
    """Load a scene from Mitsuba 3's dictionary format (``mi.load_dict``).

    The same keys, types and nesting as Mitsuba: ``{"type": "scene", "sensor": {...},
    "light": {"type": "point", ...}, "box": {"type": "cube", "bsdf": {...}}}``, with values
    as ints, floats, bools, strings, 3-vectors (lists, tuples, numpy, ``mi.ScalarPoint3f``),
    transforms (:class:`ScalarTransform4f`, ``mi.ScalarTransform4f``, 4x4 arrays),
    ``{"type": "rgb", "value": [r, g, b]}``, ``{"type": "spectrum", "value": v}`` and
    ``{"type": "ref", "id": "name"}`` (top-level keys are ids). Relative file names resolve
    against the folder of ``origin`` (default: the current directory).

    Raises :class:`SceneError` whose ``key`` is the dictionary path of the offending entry,
    e.g. ``scene['box']['bsdf']``.
    """
    from . import _params

    text, keys = to_xml(scene)
    where = os.fspath(origin) if origin is not None else os.path.join(os.getcwd(), "<dict>")
    try:
        return _svetlo.load_string(text, where, _params(params))
    except SceneError as e:
        line = getattr(e, "line", None)
        if isinstance(line, int) and 1 <= line <= len(keys):
            key = keys[line - 1]
            msg = str(e)
            # The loader's "FILE:LINE:COL: message", told as the dictionary entry instead.
            prefix = f"{where}:{line}:{getattr(e, 'column', '')}: "
            msg = msg[len(prefix):] if msg.startswith(prefix) else msg
            err = SceneError(f"load_dict: {key}: {msg}")
            err.file, err.line, err.column, err.key = None, None, None, key
            raise err from None
        raise
