"""svetlo: a physically based renderer with every light-transport method of one lecture.

The scene part is Mitsuba 3's habits::

    import svetlo
    scene = svetlo.load_file("scenes/cornell-box.xml", spp=64)   # <default> parameters
    scene = svetlo.load_dict({"type": "scene", ...})              # Mitsuba 3's dict format
    img = svetlo.render(scene, integrator="bdpt", spp=64, seed=1)  # (height, width, 3) float32

and the methods are svetlo's (``svetlo.methods()``): path, light, bdpt, direct, whitted,
distributed, zbuffer, radiosity, photon, sppm, pssmlt, mlt. A render releases the GIL, shows
a tqdm bar when tqdm is installed (or calls ``progress``), and stops on Ctrl-C with
:class:`RenderInterrupted` (a ``KeyboardInterrupt``) whose ``.image`` is the partial image.
``svetlo.distributed`` (``import svetlo.distributed``) renders on a Dask cluster, bit for bit
the local image.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import sys
import warnings
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, Union

import numpy as np

from . import _svetlo
from ._svetlo import (
    ImageError,
    OptionError,
    RadiositySolution,
    RenderInterrupted,
    Scene,
    SceneError,
    SvetloError,
    __version__,
)
from ._dict import ScalarTransform4f, load_dict

__all__ = [
    "__version__",
    "Scene",
    "RadiositySolution",
    "RenderResult",
    "ZTest",
    "SvetloError",
    "SceneError",
    "OptionError",
    "ImageError",
    "RenderInterrupted",
    "ScalarTransform4f",
    "load_file",
    "load_string",
    "load_dict",
    "render",
    "render_result",
    "radiosity",
    "methods",
    "write",
    "read",
    "write_layers",
    "read_layers",
    "relmse",
    "ztest",
]

PathLike = Union[str, "os.PathLike[str]"]


def _param_str(key: str, value: Any) -> str:
    """A scene parameter as the text a ``-D name=value`` would give."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, np.integer, np.floating)):
        if isinstance(value, (float, np.floating)) and not np.isfinite(value):
            raise OptionError(f"scene parameter '{key}': {value} is not a finite number")
        return repr(value.item() if isinstance(value, np.generic) else value)
    if isinstance(value, str):
        return value
    raise TypeError(f"scene parameter '{key}': expected a number, bool or str, got {type(value).__name__}")


def _params(params: Mapping[str, Any]) -> List[Tuple[str, str]]:
    return [(k, _param_str(k, v)) for k, v in params.items()]


def load_file(path: PathLike, **params: Any) -> Scene:
    """Load a Mitsuba XML scene file.

    Keyword arguments fill the scene's ``<default name=... value=...>`` parameters (the CLI's
    ``-D name=value``), e.g. ``load_file("cbox.xml", spp=64, resx=128)``. Numbers and bools are
    written as the XML would spell them. Raises :class:`SceneError` (with ``file``, ``line``
    and ``column``) when the file is malformed.
    """
    return _svetlo.load_file(path, _params(params))


def load_string(text: str, origin: PathLike = "<string>", **params: Any) -> Scene:
    """Load a Mitsuba XML scene held in a string (``mi.load_string``).

    ``origin`` names the scene in error messages; relative file names inside (meshes,
    textures) are resolved against its folder (the current directory by default).
    """
    if not isinstance(text, str):
        raise TypeError(f"load_string: expected the XML as str, got {type(text).__name__}")
    return _svetlo.load_string(text, origin, _params(params))


def methods() -> List[Tuple[str, str, bool]]:
    """The rendering methods: (name, what it computes, whether it takes options)."""
    return _svetlo.methods()


def _option_value(method: str, key: str, value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, np.integer, np.floating)):
        if isinstance(value, (float, np.floating)) and not np.isfinite(value):
            raise OptionError(f"{method}: option '{key}' is {value}, not a finite number")
        return repr(value.item() if isinstance(value, np.generic) else value)
    if isinstance(value, str):
        if any(c in value for c in ",=:") or not value:
            raise OptionError(f"{method}: option '{key}' has the value {value!r}, which may not be empty or contain ',', '=' or ':'")
        return value
    raise TypeError(f"{method}: option '{key}' must be a number, bool or str, got {type(value).__name__}")


def _method_spec(integrator: Optional[str], options: Optional[Mapping[str, Any]], scene: Scene) -> Optional[str]:
    """``NAME:key=value,...`` for the registry; option keys may use '_' for '-'."""
    if integrator is not None and not isinstance(integrator, str):
        raise TypeError(f"integrator must be a method name (str), got {type(integrator).__name__}")
    if not options:
        return integrator
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be a dict of method options, got {type(options).__name__}")
    name = integrator if integrator is not None else scene.info()["settings"]["integrator"]
    base, _, given = name.partition(":")
    parts = [given] if given else []
    for k, v in options.items():
        if not isinstance(k, str) or not k:
            raise OptionError(f"{base}: option names are non-empty strings, got {k!r}")
        parts.append(f"{k.replace('_', '-')}={_option_value(base, k, v)}")
    return f"{base}:{','.join(parts)}"


@dataclasses.dataclass
class RenderResult:
    """Everything a render returns.

    Attributes:
        image: (height, width, 3) float32 linear Rec.709 RGB; the array owns the renderer's
            buffer (no copy was made).
        variance: per-sample variance of each pixel's own samples (box filter), as Mitsuba's
            ``_var`` references; splats of light paths are not in it. Computed on first use.
        spp: sample passes done (fewer than planned after Ctrl-C or a time limit).
        spp_planned: the samples per pixel asked for.
        seconds: wall time of the render.
        render_seconds: the library's render call alone (``seconds`` less thread start and wake-up).
        develop_seconds: turning the film into the image (the library's ``Film::image``).
        interrupted: whether Ctrl-C (or a cancel) stopped it early.
        integrator: the method that ran, with its options.
        report: the method's own report (e.g. Metropolis acceptance), or None.
        aovs: the AOVs asked for (``aovs=``, ``aov_preset=``), one (height, width, 3) array
            each, by name, in the order asked.
        strategies: for ``strategies=N`` with bdpt, {(s, t): (weighted, unweighted)} images.
    """

    image: np.ndarray
    film: Any = dataclasses.field(repr=False)
    spp: int
    spp_planned: int
    seconds: float
    render_seconds: float
    develop_seconds: float
    interrupted: bool
    integrator: str
    report: Optional[str]
    aovs: Dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    strategies: Dict[Tuple[int, int], Tuple[np.ndarray, np.ndarray]] = dataclasses.field(default_factory=dict)

    @functools.cached_property
    def variance(self) -> np.ndarray:
        return self.film.variance()


class _Bar:
    """Progress shown through tqdm when it is installed, else nothing."""

    def __init__(self, time_limit: Optional[float]):
        self.time_limit = time_limit
        self.bar = None
        try:
            from tqdm.auto import tqdm
        except ImportError:
            return
        self.bar = tqdm(total=1000, unit="‰", leave=False, desc="svetlo", file=sys.stderr)

    def __call__(self, done: int, total: int, elapsed: float) -> None:
        if self.bar is None:
            return
        frac = done / total if total else 0.0
        if self.time_limit:
            frac = max(frac, elapsed / self.time_limit)
        n = int(min(max(frac, 0.0), 1.0) * 1000)
        if n > self.bar.n:
            self.bar.update(n - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()



def render_result(
    scene: Scene,
    *,
    integrator: Optional[str] = None,
    options: Optional[Mapping[str, Any]] = None,
    spp: Optional[int] = None,
    time: Optional[float] = None,
    seed: Optional[int] = None,
    max_depth: Optional[int] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    filter: Optional[str] = None,
    threads: int = 0,
    sampler: Optional[str] = None,
    rr_depth: Optional[int] = None,
    hide_emitters: Optional[bool] = None,
    ray_epsilon: Optional[float] = None,
    aovs: Optional[Mapping[str, str]] = None,
    lpe: Optional[str] = None,
    aov_preset: Optional[str] = None,
    strategies: Optional[int] = None,
    progress: Union[bool, None, Callable[[int, int, float], Any]] = None,
) -> RenderResult:
    """Render ``scene`` and return a :class:`RenderResult` (image, variance, spp done, ...).

    Arguments are those of :func:`render`, plus ``strategies``: with ``integrator="bdpt"``,
    also keep one image per (s, t) strategy for paths of up to this many segments (the CLI's
    ``--strategies DIR --strategy-depth N``).
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"render: expected a svetlo.Scene (from load_file, load_string or load_dict), got {type(scene).__name__}")
    for name, v in (("spp", spp), ("seed", seed), ("max_depth", max_depth), ("width", width), ("height", height), ("threads", threads), ("rr_depth", rr_depth), ("strategies", strategies)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))):
            raise TypeError(f"render: {name} must be an integer, got {type(v).__name__}")
    if seed is not None and seed < 0:
        raise OptionError(f"seed must be a non-negative integer, got {seed}")
    if spp is not None and spp < 1:
        raise OptionError(f"spp must be at least 1, got {spp}")
    if not 0 <= threads <= 1024:
        raise OptionError(f"threads must be in 0..=1024 (0: all cores), got {threads}")
    if time is not None:
        if isinstance(time, bool) or not isinstance(time, (int, float, np.integer, np.floating)):
            raise TypeError(f"render: time must be a number of seconds, got {type(time).__name__}")
        if not (np.isfinite(time) and time > 0):
            raise OptionError(f"time must be a positive number of seconds, got {time}")
    if ray_epsilon is not None:
        if isinstance(ray_epsilon, bool) or not isinstance(ray_epsilon, (int, float, np.integer, np.floating)):
            raise TypeError(f"render: ray_epsilon must be a distance (a number), got {type(ray_epsilon).__name__}")
        if not (np.isfinite(ray_epsilon) and ray_epsilon >= 0):
            raise OptionError(f"ray_epsilon must be a distance of 0 or more, got {ray_epsilon}")
    spec = _method_spec(integrator, options, scene)
    if aovs is not None:
        if not isinstance(aovs, Mapping) or not all(isinstance(k, str) and isinstance(v, str) for k, v in aovs.items()):
            raise TypeError("render: aovs must be a dict of name -> light path expression (str -> str)")
    for name, v in (("lpe", lpe), ("aov_preset", aov_preset)):
        if v is not None and not isinstance(v, str):
            raise TypeError(f"render: {name} must be a string, got {type(v).__name__}")
    bar = None
    if progress is None or progress is True:
        bar = _Bar(time)
        callback = bar if bar.bar is not None else None
    elif progress is False:
        callback = None
    elif callable(progress):
        callback = progress
    else:
        raise TypeError("progress must be None (a tqdm bar when tqdm is installed), False, True or a callable(done, total, seconds)")
    try:
        r = _svetlo.render(
            scene,
            integrator=spec,
            spp=spp,
            time=None if time is None else float(time),
            seed=seed,
            max_depth=max_depth,
            width=width,
            height=height,
            filter=filter,
            threads=threads,
            sampler=sampler,
            rr_depth=rr_depth,
            hide_emitters=hide_emitters,
            strategies=strategies,
            callback=callback,
            aovs=None if aovs is None else list(aovs.items()),
            lpe=lpe,
            aov_preset=aov_preset,
            ray_epsilon=None if ray_epsilon is None else float(ray_epsilon),
        )
    finally:
        if bar is not None:
            bar.close()
    for w in r["warnings"]:
        warnings.warn(w, stacklevel=3)
    result = RenderResult(
        image=r["image"],
        film=r["film"],
        spp=r["spp"],
        spp_planned=r["spp_planned"],
        seconds=r["seconds"],
        render_seconds=r["render_seconds"],
        develop_seconds=r["develop_seconds"],
        interrupted=r["interrupted"],
        integrator=r["integrator"],
        report=r["report"],
        aovs=dict(r["aovs"]),
        strategies={(s, t): (w, u) for s, t, w, u in r["strategies"]},
    )
    if result.interrupted:
        e = RenderInterrupted(f"render interrupted after {result.spp} of {result.spp_planned} spp; the partial image is e.image (e.result holds the rest)")
        e.result = result
        e.image = result.image
        raise e
    return result


def render(
    scene: Scene,
    *,
    integrator: Optional[str] = None,
    options: Optional[Mapping[str, Any]] = None,
    spp: Optional[int] = None,
    time: Optional[float] = None,
    seed: Optional[int] = None,
    max_depth: Optional[int] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    filter: Optional[str] = None,
    threads: int = 0,
    sampler: Optional[str] = None,
    rr_depth: Optional[int] = None,
    hide_emitters: Optional[bool] = None,
    ray_epsilon: Optional[float] = None,
    aovs: Optional[Mapping[str, str]] = None,
    lpe: Optional[str] = None,
    aov_preset: Optional[str] = None,
    progress: Union[bool, None, Callable[[int, int, float], Any]] = None,
) -> np.ndarray:
    """Render ``scene``; return the image as a (height, width, 3) float32 array of linear RGB.

    Every argument left out keeps the scene file's value, exactly as ``svetlo render`` does:
    the same scene, settings and seed give the CLI's image bit for bit.

    Args:
        scene: a :class:`Scene` (``load_file``, ``load_string``, ``load_dict``).
        integrator: the method (``svetlo.methods()``): "path", "light", "bdpt", "direct",
            "whitted", "distributed", "zbuffer", "radiosity", "photon", "sppm", "pssmlt",
            "mlt"; ``"name:key=value,..."`` also works. Default: the scene's ``<integrator>``.
        options: the method's options as a dict, e.g. ``{"solver": "hierarchical"}`` for
            radiosity or ``{"photons": 100000}`` for sppm; '_' in a key stands for '-'. An
            unknown key raises :class:`OptionError` naming it.
        spp: samples per pixel (the maximum when ``time`` is given).
        time: stop after this many seconds, keeping whole sample passes.
        seed: random seed (a non-negative integer).
        max_depth: path segments from the camera (Mitsuba's meaning: 1 emitters seen
            directly, 2 direct light, -1 unbounded).
        width, height: image size in pixels; one alone keeps the scene's aspect ratio.
        filter: pixel reconstruction filter, "box", "tent" (radius 1) or "gaussian" (sigma 0.5).
        threads: worker threads, 0 for all cores (at most 1024).
        sampler: "independent" or "sobol".
        rr_depth: depth at which Russian roulette starts.
        hide_emitters: do not show emitters seen directly by the camera.
        ray_epsilon: skip hits nearer than this distance to a ray's origin, on every ray
            (the CLI's ``--ray-epsilon``; Tungsten's references of thin glass need 5e-4).
        aovs: light path expressions as ``{name: expression}`` (the CLI's ``--aov``, e.g.
            ``{"caustic": "C D S+ L"}``); their images are ``render_result(...).aovs[name]``
            (``render`` itself returns the beauty only).
        lpe: restrict the beauty to the paths this expression matches (``--lpe``).
        aov_preset: "lecture" adds one AOV per method class of the lecture (local, whitted,
            cook, radiosity, rest).
        progress: None (default) shows a tqdm bar when tqdm is installed; False shows nothing;
            a callable is called as ``progress(done, total, seconds)`` every 20 ms from the
            calling thread (an exception in it cancels the render and is raised).

    Raises:
        RenderInterrupted: on Ctrl-C (a ``KeyboardInterrupt``); the render stops after its
            current pass and ``e.image`` is the image of the samples done.
        OptionError: a bad setting or method option. SceneError: the scene cannot be
            rendered by that method (e.g. bdpt with an orthographic camera).

    The GIL is released while the render runs; other Python threads keep running.
    """
    return render_result(
        scene,
        integrator=integrator,
        options=options,
        spp=spp,
        time=time,
        seed=seed,
        max_depth=max_depth,
        width=width,
        height=height,
        filter=filter,
        threads=threads,
        sampler=sampler,
        rr_depth=rr_depth,
        hide_emitters=hide_emitters,
        ray_epsilon=ray_epsilon,
        aovs=aovs,
        lpe=lpe,
        aov_preset=aov_preset,
        progress=progress,
    ).image


def radiosity(scene: Scene, *, max_depth: Optional[int] = None, **options: Any) -> RadiositySolution:
    """Solve ``scene`` by finite-element radiosity and return the solution.

    Keyword options are those of ``integrator="radiosity"`` ('_' for '-'): ``solver``
    (auto, jacobi, gauss-seidel, southwell, progressive, ssg, two-level, hierarchical),
    ``form_factors`` (analytic, hemicube, raycast), ``element_size``, ``tolerance``,
    ``omega``, ``epsilon``, ``min_area``, ``refine``, ``importance``, ``shading``, ...

    The solution has per-element arrays (``triangles``, ``normals``, ``areas``,
    ``reflectance``, ``emission``, ``b``), display vertices (``vertices``, ``vertex_b``,
    ``faces``), the convergence ``history`` (step, residual, seconds, rows), ``image()``
    through the scene's camera and ``write_ply(path)``.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"radiosity: expected a svetlo.Scene, got {type(scene).__name__}")
    spec = ",".join(f"{k.replace('_', '-')}={_option_value('radiosity', k, v)}" for k, v in options.items())
    return _svetlo.radiosity(scene, spec, max_depth)


def _write_ply(self: RadiositySolution, path: PathLike) -> None:
    """Write the solved mesh as ASCII PLY: sRGB colours of B/pi and B itself as floats."""
    v, vb, f = self.vertices, self.vertex_b, self.faces
    srgb = np.clip(vb / np.pi, 0.0, 1.0)
    srgb = np.where(srgb <= 0.0031308, 12.92 * srgb, 1.055 * np.power(srgb, 1 / 2.4) - 0.055)
    rgb8 = np.round(srgb * 255).astype(np.uint8)
    with open(path, "w") as out:
        out.write("ply\nformat ascii 1.0\ncomment svetlo radiosity: colours are sRGB of B/pi clamped to 1; b_r, b_g, b_b are B in W/m^2\n")
        out.write(f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n")
        out.write("property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float b_r\nproperty float b_g\nproperty float b_b\n")
        out.write(f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
        for p, c, b in zip(v, rgb8, vb):
            out.write(f"{p[0]} {p[1]} {p[2]} {c[0]} {c[1]} {c[2]} {b[0]} {b[1]} {b[2]}\n")
        for a, b, c in f:
            out.write(f"3 {a} {b} {c}\n")


RadiositySolution.write_ply = _write_ply  # type: ignore[attr-defined]


def _image_arg(a: Any, what: str) -> np.ndarray:
    if not isinstance(a, np.ndarray):
        try:
            a = np.asarray(a)
        except Exception as e:  # noqa: BLE001 - anything numpy cannot read is the caller's type error
            raise TypeError(f"{what}: expected a (height, width, 3) array, got {type(a).__name__}") from e
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{what}: expected a float array, got dtype {a.dtype}")
    if a.ndim != 3 or a.shape[2] != 3:
        raise ImageError(f"{what}: expected shape (height, width, 3), got {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def write(path: PathLike, image: Any) -> None:
    """Write a (height, width, 3) image: .exr (linear float), .png (sRGB, tone mapped), .pfm."""
    _svetlo.write(path, _image_arg(image, "image"))


def read(path: PathLike) -> np.ndarray:
    """Read an image (EXR, PFM, PNG, JPEG) as a (height, width, 3) float32 array of linear RGB."""
    return _svetlo.read(path)


def write_layers(path: PathLike, image: Any, aovs: Mapping[str, Any]) -> None:
    """Write one EXR with ``image`` as R, G, B and each AOV as ``NAME.R``, ``NAME.G``, ``NAME.B``
    (the CLI's ``--aov`` output; OpenEXR's layer naming)."""
    _svetlo.write_layers(path, _image_arg(image, "image"), [(str(n), _image_arg(a, str(n))) for n, a in aovs.items()])


def read_layers(path: PathLike) -> Tuple[np.ndarray, Dict[str, np.ndarray]]:
    """Read a multi-layer EXR (e.g. ``svetlo render --aov ...``): the beauty and ``{name: image}``."""
    beauty, layers = _svetlo.read_layers(path)
    return beauty, dict(layers)


def relmse(image: Any, reference: Any) -> float:
    """Relative MSE: the mean over pixels and channels of (x - r)^2 / (r^2 + 0.01) (``svetlo compare``)."""
    return _svetlo.relmse(_image_arg(image, "image"), _image_arg(reference, "reference"))


@dataclasses.dataclass
class ZTest:
    """The verdict of :func:`ztest`; true in a boolean context when the image passes."""

    passed: bool
    fraction_passing: float
    channels: int
    failed: int
    alpha: float
    min_p: float
    relmse: float
    mean_image: Tuple[float, float, float]
    mean_reference: Tuple[float, float, float]
    spp: int
    min_fraction: float

    def __bool__(self) -> bool:
        return self.passed


def ztest(image: Any, reference: Any, reference_variance: Any, spp: int, *, significance: float = 0.01, min_fraction: float = 0.9975) -> ZTest:
    """Mitsuba's per-pixel Z-test (``svetlo compare IMAGE REF --ref-var VAR --spp N``).

    Each pixel channel (in CIE XYZ) of ``image``, the mean of ``spp`` samples, is tested
    against ``reference`` with per-sample variance ``reference_variance``
    (``z = |x - r| sqrt(spp / var)``) at the Šidák-corrected level for a family-wise
    ``significance``; the image passes when at least ``min_fraction`` of channels pass.
    """
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise OptionError(f"ztest: spp must be a positive integer, got {spp!r}")
    d = _svetlo.ztest(_image_arg(image, "image"), _image_arg(reference, "reference"), _image_arg(reference_variance, "reference_variance"), int(spp), significance, min_fraction)
    return ZTest(**d)
