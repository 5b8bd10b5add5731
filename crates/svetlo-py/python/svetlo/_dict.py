"""Mitsuba 3's dictionary scene format, read by svetlo's one Mitsuba loader.

Why that loader: it is svetlo's one scene reader, with every plugin, default, unit and check
already in it and tested against Mitsuba; a second path from dicts into the scene builder
would duplicate all of it and drift. The extension (crates/svetlo-py/src/dict.rs) turns the
dict into the element tree the XML would parse to, numbering its elements by the lines of
that XML (``to_xml`` prints it), so that an error the loader reports at a line is told as the
dictionary key that produced it (``SceneError.key``, e.g. ``scene['box']['bsdf']``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any, List, Sequence, Tuple

import numpy as np

from . import _svetlo

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


def _matrix(v: Any) -> np.ndarray:
    m = getattr(v, "matrix", None)
    return np.array(m if m is not None else v, dtype=np.float64).reshape(4, 4)


def to_xml(scene: Mapping[str, Any]) -> Tuple[str, List[str]]:
    """The XML for a scene dict and, per line (0-based), the dictionary path it came from."""
    return _svetlo.dict_to_xml(scene)


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
    where = os.fspath(origin) if origin is not None else os.path.join(os.getcwd(), "<dict>")
    if params:
        from . import _params

        return _svetlo.load_dict(scene, where, _params(params))
    return _svetlo.load_dict(scene, where)
