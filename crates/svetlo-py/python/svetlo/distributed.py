"""Renders spread over a Dask cluster, bit for bit the image of a local render.

::

    from dask.distributed import Client, LocalCluster
    import svetlo.distributed
    client = Client(LocalCluster(n_workers=4, threads_per_worker=1))
    img = svetlo.distributed.render("scene.xml", client=client, integrator="bdpt", spp=4096, seed=1)

How: an untimed render's samples are split into passes, and the passes' film sums are added by
a fixed pairwise tree (the library's ``integrator::passes``), the same for a local render. The
client cuts that tree into ``chunks`` nodes of about equal work; each task renders one node on
a worker and returns the node's raw film sums (weighted radiance, weights, variance sums, splats,
AOV layers) as bytes; the client adds the nodes by the tree. Float sums are associated exactly as
in a local render, so the image is the local one to the bit, whatever the number of workers,
the chunks, the order in which tasks finish, or tasks rerun after a worker died.

Scenes reach the workers shipped (the default): the client reads the scene file and the files
it references (includes, meshes, textures, spectra) and sends them once to every worker, which
writes them to a folder of its own and loads the scene once, keeping it for later tasks keyed by
the content of all those files. With ``ship=False`` the workers load the client's path (a
shared file system). Workers must run the same svetlo build on the same kind of CPU: the path
tracer's eight-wide kernel depends on AVX2 (``integrator="path:simd=false"`` does not).

Every method but zbuffer splits, each into the local render's image bit for bit: the methods
that are sums of independent pixel samples (path, light, bdpt, direct, whitted, distributed)
by passes; photon by passes too, its photon paths traced once by index batches
that every chunk builds the maps from; radiosity by passes of its display, showing one
solution that one task solves from the form-factor rows that ``form_factor_batches`` tasks
compute by ranges (hierarchical radiosity, whose links are refined between solves, and
progressive refinement with rows on demand solve in that one task, not spread); pssmlt and mlt by blocks of 16 chains started from one
bootstrap that a single task computes; sppm iteration by iteration, photon batches then
blocks of rows (:class:`SppmRender`). :func:`render_independent` averages independent
renders with distinct seeds, for any method.

From a shell, ``python -m svetlo.distributed scene.xml --workers 2 --spp 256 -o out.exr``
(or ``--scheduler tcp://host:8786``) renders the same image and prints progress as chunks
complete (:func:`main`; ``svetlo render --dask ADDRESS`` runs it).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import hashlib
import os
import re
import sys
import tempfile
import threading
import time
import uuid
import zlib
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, Union

import numpy as np

import svetlo
from svetlo import OptionError, RenderInterrupted, RenderResult, Scene, SvetloError, _svetlo

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["render", "submit", "render_independent", "DistributedRender", "SceneSource", "scene_source", "radiosity_counters"]

# Attribute values that may name a file (Mitsuba: filename="..." on includes, meshes,
# textures, spectra, IES files; <string name="filename" value="..."/>).
_FILE_ATTR = re.compile(r'(?:filename|value)\s*=\s*"([^"]+)"')
# A scene and its files above this size are refused for shipping: use a shared path.
MAX_SHIP_BYTES = 2 << 30


@dataclasses.dataclass(frozen=True)
class SceneSource:
    """A scene file and, when shipped, the bytes of every file it needs.

    ``key`` hashes the content of all of them and the ``<default>`` parameters: workers keep
    the loaded scene under it. ``files`` maps paths relative to ``root`` to their bytes (None:
    not shipped, the workers read ``path``).
    """

    key: str
    path: str
    root: str
    name: str
    params: Tuple[Tuple[str, str], ...]
    files: Optional[Dict[str, bytes]]

    @property
    def nbytes(self) -> int:
        return sum(len(b) for b in (self.files or {}).values())


def _referenced(path: str, seen: Dict[str, bytes]) -> None:
    """Add `path` and, for XML, the existing files its attributes name (includes recursively)."""
    real = os.path.realpath(path)
    if real in seen:
        return
    with open(real, "rb") as f:
        data = f.read()
    seen[real] = data
    if not real.lower().endswith(".xml"):
        return
    text = data.decode("utf-8", errors="replace")
    folder = os.path.dirname(real)
    for name in set(_FILE_ATTR.findall(text)):
        if "$" in name:
            continue
        cand = name if os.path.isabs(name) else os.path.join(folder, name)
        if os.path.isfile(cand):
            _referenced(cand, seen)


def scene_source(path: PathLike, params: Optional[Mapping[str, Any]] = None, ship: bool = True) -> SceneSource:
    """Read the scene file at `path` (and with `ship` the files it needs) into a :class:`SceneSource`."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        # The local loader's own error, with its message and attributes.
        svetlo.load_file(path, **(params or {}))
        raise OptionError(f"{path}: not a scene file")
    files: Dict[str, bytes] = {}
    _referenced(path, files)
    real = os.path.realpath(path)
    root = os.path.commonpath([os.path.dirname(p) for p in files])
    h = hashlib.sha256()
    ps = tuple(svetlo._params(params or {}))
    h.update(repr(ps).encode())
    total = 0
    for p in sorted(files):
        rel = os.path.relpath(p, root)
        h.update(rel.encode() + b"\0" + len(files[p]).to_bytes(8, "little"))
        h.update(files[p])
        total += len(files[p])
    if ship and total > MAX_SHIP_BYTES:
        raise OptionError(f"{path}: the scene and its files take {total} bytes, over {MAX_SHIP_BYTES} to ship: put them on a shared path and pass ship=False")
    shipped = {os.path.relpath(p, root): b for p, b in files.items()} if ship else None
    if not ship:
        h.update(os.path.abspath(path).encode())
    return SceneSource(key=h.hexdigest(), path=os.path.abspath(path), root=root, name=os.path.relpath(real, root), params=ps, files=shipped)


# --- Worker side: scenes loaded once per process, by content.

_CACHE: "collections.OrderedDict[str, Scene]" = collections.OrderedDict()
_CACHE_SIZE = 4
_LOCK = threading.Lock()
_STATS = {"loads": 0, "hits": 0}


def cache_stats() -> Dict[str, int]:
    """This process's scene cache: loads, hits, scenes held (for tests and monitoring)."""
    with _LOCK:
        return dict(_STATS, held=len(_CACHE))


def _unpack(src: SceneSource) -> str:
    """Write a shipped scene's files under this machine's temporary folder; its path there."""
    base = os.path.join(tempfile.gettempdir(), f"svetlo-dask-{src.key[:24]}")
    if not os.path.isdir(base):
        tmp = f"{base}.{os.getpid()}.{uuid.uuid4().hex[:8]}"
        for rel, data in (src.files or {}).items():
            dst = os.path.normpath(os.path.join(tmp, rel))
            if not dst.startswith(os.path.normpath(tmp) + os.sep):
                raise OptionError(f"shipped scene file {rel!r} leaves its folder")
            os.makedirs(os.path.dirname(dst), exist_ok=True)
            with open(dst, "wb") as f:
                f.write(data)
        try:
            os.rename(tmp, base)
        except OSError:
            # Another process unpacked the same content first: same bytes, use theirs.
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)
    return os.path.join(base, src.name)


def _as_client_error(e: SvetloError, local_root: str, client_root: str) -> SvetloError:
    """The error the client would have had loading its own copy: the same type, message and
    attributes, with the worker's folder replaced by the client's."""
    msg = str(e).replace(local_root, client_root)
    out = type(e)(msg)
    for k, v in vars(e).items():
        setattr(out, k, v.replace(local_root, client_root) if isinstance(v, str) else v)
    return out


def _scene(src: SceneSource) -> Scene:
    with _LOCK:
        s = _CACHE.get(src.key)
        if s is not None:
            _CACHE.move_to_end(src.key)
            _STATS["hits"] += 1
            return s
    params = dict(src.params)
    if src.files is None:
        s = svetlo.load_file(src.path, **params)
    else:
        path = _unpack(src)
        try:
            s = svetlo.load_file(path, **params)
        except SvetloError as e:
            raise _as_client_error(e, path[: -len(src.name)].rstrip(os.sep), src.root) from None
    with _LOCK:
        _CACHE[src.key] = s
        _STATS["loads"] += 1
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return s


def _worker_threads() -> int:
    """Threads per task: the worker's cores shared among its task slots."""
    try:
        from distributed import get_worker

        slots = max(1, get_worker().state.nthreads)
    except Exception:
        slots = 1
    return max(1, (os.cpu_count() or 1) // slots)


def _threads(threads: Optional[int]) -> int:
    return _worker_threads() if threads is None else threads


def _plan_task(src: SceneSource, chunks: int, opts: Dict[str, Any]) -> Dict[str, Any]:
    return _svetlo.plan_chunks(_scene(src), chunks, opts)


def _shared_task(src: SceneSource, start: int, end: int, opts: Dict[str, Any], threads: Optional[int]) -> bytes:
    return _svetlo.shared_batch(_scene(src), start, end, opts, threads=_threads(threads))


def _radiosity_rows_task(src: SceneSource, start: int, end: int, opts: Dict[str, Any], threads: Optional[int]) -> bytes:
    return _svetlo.radiosity_rows(_scene(src), start, end, opts, threads=_threads(threads))


def _radiosity_solve_task(src: SceneSource, opts: Dict[str, Any], threads: Optional[int], *rows: bytes) -> bytes:
    return _svetlo.radiosity_solve(_scene(src), list(rows), opts, threads=_threads(threads))


def radiosity_counters() -> Dict[str, int]:
    """This process's radiosity solves begun and form-factor rows computed (for tests and
    monitoring: ``client.run(svetlo.distributed.radiosity_counters)`` reads the workers')."""
    return dict(_svetlo.radiosity_counters())


def _render_task(src: SceneSource, start: int, end: int, opts: Dict[str, Any], threads: Optional[int], compress: int, *shared: bytes) -> Tuple[float, bytes]:
    t0 = time.perf_counter()
    raw = _svetlo.render_passes(_scene(src), start, end, opts, shared=list(shared), threads=_threads(threads))
    return time.perf_counter() - t0, pack(raw, compress)


def _sppm_photons_task(src: SceneSource, iteration: int, start: int, end: int, opts: Dict[str, Any], threads: Optional[int]) -> bytes:
    return _svetlo.sppm_photons(_scene(src), iteration, start, end, opts, threads=_threads(threads))


def _sppm_rows_task(src: SceneSource, start: int, end: int, state: Optional[bytes], opts: Dict[str, Any], threads: Optional[int], *batches: bytes) -> bytes:
    return _svetlo.sppm_iterate(_scene(src), start, end, state, list(batches), opts, threads=_threads(threads))


def _sppm_develop_task(src: SceneSource, opts: Dict[str, Any], *parts: bytes) -> Dict[str, Any]:
    d = _svetlo.sppm_develop(_scene(src), list(parts), opts)
    return {"image": d["image"], "spp": d["spp"]}


def _independent_task(src: SceneSource, opts: Dict[str, Any], threads: Optional[int]) -> Tuple[np.ndarray, int]:
    r = svetlo.render_result(_scene(src), threads=_threads(threads), progress=False, **opts)
    return r.image, r.spp


# --- Transfers: film sums as bytes, optionally byte-shuffled and deflated (exact).


def pack(raw: bytes, level: int) -> bytes:
    """The film sums `raw` as sent back: as they are (level 0), or with the bytes of every
    4-byte word regrouped by significance (sign and exponent bytes together, which repeat)
    and deflated at zlib `level`. Lossless: :func:`unpack` returns `raw` exactly."""
    if level == 0:
        return b"\0" + raw
    n = len(raw) // 4 * 4
    planes = np.frombuffer(raw, dtype=np.uint8, count=n).reshape(-1, 4).T.tobytes()
    return b"\1" + zlib.compress(planes + raw[n:], level)


def unpack(data: bytes) -> bytes:
    """The film sums that :func:`pack` packed."""
    if data[:1] == b"\0":
        return data[1:]
    if data[:1] != b"\1":
        raise SvetloError("a distributed task sent back bytes that are not packed film sums")
    planes = zlib.decompress(data[1:])
    n = len(planes) // 4 * 4
    return np.frombuffer(planes, dtype=np.uint8, count=n).reshape(4, -1).T.tobytes() + planes[n:]


# --- Client side.


def _source(scene: Union[PathLike, Scene, SceneSource], params: Optional[Mapping[str, Any]], ship: bool) -> SceneSource:
    if isinstance(scene, SceneSource):
        return scene
    if isinstance(scene, Scene):
        if not os.path.isfile(scene.origin):
            raise OptionError(f"a distributed render needs the scene's file; this scene came from {scene.origin!r} (load_string or load_dict): write it to a file and pass its path")
        return scene_source(scene.origin, params, ship)
    if isinstance(scene, (str, os.PathLike)):
        return scene_source(scene, params, ship)
    raise TypeError(f"scene must be a path, a svetlo.Scene loaded from a file or a SceneSource, got {type(scene).__name__}")


def _default_client(client):
    if client is not None:
        return client
    from distributed import get_client

    return get_client()


_OPTS = ("spp", "seed", "max_depth", "width", "height", "filter", "sampler", "rr_depth", "hide_emitters", "ray_epsilon")


def _split(a: int, b: int) -> int:
    """Where the pass tree splits passes [a, b): after the largest power of two below b - a
    (``integrator::passes::split``)."""
    return a + (1 << ((b - a - 1).bit_length() - 1))


def _family(node: Tuple[int, int], passes: int) -> Tuple[Tuple[int, int], Tuple[int, int], bool]:
    """(parent, sibling, whether `node` is the left child) of a node of the tree over passes."""
    a, b = 0, passes
    while True:
        if b - a < 2:
            raise SvetloError(f"passes {node[0]}..{node[1]} are not a node of the tree over {passes} passes")
        m = _split(a, b)
        left, right = (a, m), (m, b)
        if node == left or node == right:
            return (a, b), (right if node == left else left), node == left
        a, b = left if node[1] <= m else right


class DistributedRender:
    """A render in flight on a cluster (from :func:`submit`).

    ``progress()`` says how far it is, ``partial()`` gives the image of the chunks done so far
    (their sums in unit order: close to, but not the bits of, the final image), ``cancel()``
    stops the chunks not yet done, ``result()`` waits and merges.
    """

    def __init__(self, client, src: SceneSource, plan: Dict[str, Any], opts: Dict[str, Any], threads: Optional[int], compress: int, shipped, batches: int = 1, row_batches: int = 1):
        self.client, self.source, self.plan, self.opts = client, src, plan, opts
        self._shipped = shipped
        self.start_time = time.perf_counter()
        self.nodes: List[Tuple[int, int, int, int]] = [tuple(n) for n in plan["nodes"]]
        token = uuid.uuid4().hex[:12]
        ref = shipped if shipped is not None else src
        # What every chunk shares is computed once, by index batches (the Metropolis
        # bootstrap: one task; photon mapping's photon paths: `batches` tasks); the chunks take
        # the batches' futures, so the bytes go from worker to worker, not through the client.
        units = plan["shared"]
        cuts = sorted({k * units // max(1, min(batches, units)) for k in range(min(batches, units) + 1)}) if units else []
        self.shared = [
            client.submit(_shared_task, ref, a, b, opts, threads, key=f"svetlo-shared-{token}-{a}-{b}", pure=False) for a, b in zip(cuts, cuts[1:])
        ]
        # Radiosity: `row_batches` tasks compute ranges of form-factor rows, one task solves
        # from all of them, and every chunk shows that solution (none solves again).
        self.row_tasks: List[Any] = []
        if plan.get("solve"):
            rows = plan["rows"]
            k = max(1, min(row_batches, rows))
            rcuts = [i * rows // k for i in range(k + 1)] if rows else []
            self.row_tasks = [
                client.submit(_radiosity_rows_task, ref, a, b, opts, threads, key=f"svetlo-ff-rows-{token}-{a}-{b}", pure=False) for a, b in zip(rcuts, rcuts[1:])
            ]
            self.shared = [client.submit(_radiosity_solve_task, ref, opts, threads, *self.row_tasks, key=f"svetlo-radiosity-solve-{token}", pure=False)]
        self.futures = [
            client.submit(_render_task, ref, a, b, opts, threads, compress, *self.shared, key=f"svetlo-passes-{token}-{a}-{b}", pure=False, retries=0)
            for a, b, _, _ in self.nodes
        ]
        # Chunks done, and their sums joined as they arrive: two siblings of the pass tree
        # are added into their parent at once (the addition the whole tree's merge makes
        # there), so the client holds at most one part per level and the last merge is short.
        self._done: Dict[int, bool] = {}
        self._sums: Dict[Tuple[int, int], bytes] = {}
        self._passes = int(plan["passes"])
        self.task_seconds: Dict[int, float] = {}
        self.bytes_received = 0
        self._lock = threading.Lock()
        self.cancelled = False

    @property
    def spp_planned(self) -> int:
        return self.plan["spp"]

    def _collect(self, i: int, fut) -> None:
        secs, data = fut.result()
        with self._lock:
            if i in self._done:
                return
            self.bytes_received += len(data)
            self._done[i] = True
            self.task_seconds[i] = secs
            a, b = self.nodes[i][0], self.nodes[i][1]
            self._add_node((a, b), unpack(data))

    def _add_node(self, node: Tuple[int, int], raw: bytes) -> None:
        """Keep the sums of `node`, joined with its sibling's (and up) where those are here."""
        while node != (0, self._passes):
            parent, sibling, is_left = _family(node, self._passes)
            other = self._sums.pop(sibling, None)
            if other is None:
                break
            raw = _svetlo.join_films(raw, other) if is_left else _svetlo.join_films(other, raw)
            node = parent
        self._sums[node] = raw

    def _poll(self) -> None:
        for i, f in enumerate(self.futures):
            if i not in self._done and f.status == "finished":
                self._collect(i, f)
            elif f.status == "error":
                f.result()  # raises the task's exception

    def progress(self) -> Tuple[int, int]:
        """(samples per pixel done, planned); for Metropolis chains, the chains' share of spp."""
        self._poll()
        with self._lock:
            done = sum(self.nodes[i][3] - self.nodes[i][2] for i in self._done)
        return done * self.spp_planned // max(1, self.plan["units"]), self.spp_planned

    def partial(self) -> Optional[np.ndarray]:
        """The image of the chunks done so far (None before the first)."""
        self._poll()
        with self._lock:
            parts = list(self._sums.values())
        if not parts:
            return None
        return _svetlo.merge_films(parts, exact=False)["image"]

    def cancel(self) -> None:
        """Cancel the chunks not yet done; those done stay."""
        self.cancelled = True
        self.client.cancel([f for i, f in enumerate(self.futures) if i not in self._done])

    def _complete(self) -> bool:
        return len(self._done) == len(self.nodes)

    def _merged(self) -> Dict[str, Any]:
        with self._lock:
            parts = [self._sums[k] for k in sorted(self._sums)]
        return _svetlo.merge_films(parts, exact=self._complete())

    def _result(self, interrupted: bool) -> RenderResult:
        t0 = time.perf_counter()
        m = self._merged()
        merge = time.perf_counter() - t0
        secs = time.perf_counter() - self.start_time
        return RenderResult(
            image=m["image"],
            film=m["film"],
            spp=m["spp"],
            spp_planned=self.spp_planned,
            seconds=secs,
            render_seconds=sum(self.task_seconds.values()),
            develop_seconds=merge,
            interrupted=interrupted,
            integrator=self.plan["integrator"],
            report=None,
            aovs=dict(m["aovs"]),
        )

    def _pending(self) -> List[Any]:
        return [f for i, f in enumerate(self.futures) if i not in self._done]

    def _take(self, f) -> None:
        self._collect(self._index[f.key], f)

    def result(self, callback: Optional[Callable[[int, int, float], Any]] = None) -> RenderResult:
        """Wait for every chunk and merge them: the local render's result, bit for bit.

        ``callback(spp_done, spp_planned, seconds)`` is called as chunks complete. On Ctrl-C
        the chunks left are cancelled and :class:`svetlo.RenderInterrupted` carries the
        image of those done (``e.result``, ``e.image``). A task's exception is raised as is
        (the same exception a local render or load would raise), the other tasks cancelled.
        """
        from distributed import as_completed

        self._index = {f.key: i for i, f in enumerate(self.futures)}
        try:
            for f in as_completed(self._pending()):
                if f.status == "cancelled":
                    continue
                try:
                    self._take(f)
                except BaseException:
                    self.cancel()
                    raise
                if callback is not None:
                    done, total = self.progress()
                    callback(done, total, time.perf_counter() - self.start_time)
        except KeyboardInterrupt:
            self.cancel()
            r = self._result(True)
            e = RenderInterrupted(f"distributed render interrupted after {r.spp} of {r.spp_planned} spp; the partial image is e.image (e.result holds the rest)")
            e.result, e.image = r, r.image
            raise e from None
        return self._result(self.cancelled and not self._complete())


class SppmRender(DistributedRender):
    """An SPPM render in flight (from :func:`submit` with ``integrator="sppm"``).

    SPPM's iterations are sequential: each visible point's radius shrinks by the photons it
    gathered in the iterations before. So each iteration is a stage: ``photon_batches`` tasks
    trace its photon paths by index (seeded by the global path index), then ``row_blocks``
    tasks each advance a block of rows by one iteration, reading every batch (Dask moves them
    between workers). A pixel's statistics are its own, so blocks of rows advance apart,
    their state (20 bytes per visible-point slot, 12 per pixel) staying on the workers between
    iterations. The image is the local render's bit for bit, for any batch and block counts.
    ``progress()`` counts whole iterations, ``partial()`` is the image after the last one.
    """

    def __init__(self, client, src: SceneSource, plan: Dict[str, Any], opts: Dict[str, Any], threads: Optional[int], shipped, row_blocks: int, photon_batches: int):
        self.client, self.source, self.plan, self.opts = client, src, plan, opts
        self._shipped = shipped
        self.start_time = time.perf_counter()
        self.task_seconds: Dict[int, float] = {}
        self.bytes_received = 0
        self._lock = threading.Lock()
        self.cancelled = False
        self.shared = None
        token = uuid.uuid4().hex[:12]
        self._ref = ref = shipped if shipped is not None else src
        h, photons, iterations = plan["height"], plan["photons"], plan["spp"]
        blocks = max(1, min(row_blocks, h))
        batches = max(1, min(photon_batches, photons))
        self.rows = [(k * h // blocks, (k + 1) * h // blocks) for k in range(blocks)]
        cuts = [k * photons // batches for k in range(batches + 1)]
        self.stages: List[List[Any]] = []
        states: List[Any] = [None] * blocks
        for it in range(iterations):
            pb = [
                client.submit(_sppm_photons_task, ref, it, cuts[k], cuts[k + 1], opts, threads, key=f"svetlo-sppm-photons-{token}-{it}-{k}", pure=False)
                for k in range(batches)
                if cuts[k] < cuts[k + 1]
            ]
            states = [
                client.submit(_sppm_rows_task, ref, a, b, states[k], opts, threads, *pb, key=f"svetlo-sppm-rows-{token}-{it}-{a}-{b}", pure=False)
                for k, (a, b) in enumerate(self.rows)
            ]
            self.stages.append(states)
        self.futures = [f for st in self.stages for f in st]
        self._done_iterations = 0
        self._final: Optional[bytes] = None

    def _poll(self) -> None:
        for f in self.futures:
            if f.status == "error":
                f.result()
        while self._done_iterations < len(self.stages) and all(f.status == "finished" for f in self.stages[self._done_iterations]):
            self._done_iterations += 1

    def progress(self) -> Tuple[int, int]:
        """(iterations done, planned)."""
        self._poll()
        return self._done_iterations, self.spp_planned

    def _develop(self, iterations: int) -> Optional[bytes]:
        if iterations == 0:
            return None
        futs = self.stages[iterations - 1]
        return self.client.submit(_sppm_develop_bytes_task, self._ref, self.opts, *futs, pure=False).result()

    def partial(self) -> Optional[np.ndarray]:
        """The image after the last iteration every row block has finished (None before)."""
        self._poll()
        raw = self._develop(self._done_iterations)
        return None if raw is None else _svetlo.merge_films([raw])["image"]

    def cancel(self) -> None:
        """Cancel the iterations not yet done; the last whole one stays."""
        self.cancelled = True
        self._poll()
        self.client.cancel([f for st in self.stages[self._done_iterations :] for f in st])

    def _complete(self) -> bool:
        return self._done_iterations == len(self.stages)

    def _merged(self) -> Dict[str, Any]:
        raw = self._final if self._final is not None else self._develop(self._done_iterations)
        if raw is None:
            raise RenderInterrupted("the SPPM render was stopped before its first iteration")
        self.bytes_received += len(raw)
        return _svetlo.merge_films([raw])

    def _pending(self) -> List[Any]:
        return [f for st in self.stages[self._done_iterations :] for f in st]

    def _take(self, f) -> None:
        self._poll()


def _sppm_develop_bytes_task(src: SceneSource, opts: Dict[str, Any], *parts: bytes) -> bytes:
    return _svetlo.sppm_develop(_scene(src), list(parts), opts)


def submit(
    scene: Union[PathLike, Scene, SceneSource],
    *,
    client=None,
    integrator: Optional[str] = None,
    options: Optional[Mapping[str, Any]] = None,
    chunks: Optional[int] = None,
    params: Optional[Mapping[str, Any]] = None,
    ship: bool = True,
    threads: Optional[int] = None,
    compress: int = 0,
    photon_batches: Optional[int] = None,
    form_factor_batches: Optional[int] = None,
    **settings: Any,
) -> DistributedRender:
    """Start a distributed render and return its :class:`DistributedRender` at once.

    Arguments are those of :func:`render`.
    """
    client = _default_client(client)
    bad = set(settings) - set(_OPTS)
    if bad:
        raise TypeError(f"unknown render settings: {', '.join(sorted(bad))} (distributed renders take {', '.join(_OPTS)})")
    if "time" in settings:
        raise OptionError("a distributed render is planned by spp: time limits are not deterministic")
    if options and integrator is None:
        raise OptionError("options need the integrator named")
    spec = svetlo._method_spec(integrator, options, None) if options else integrator
    opts = {k: v for k, v in settings.items() if v is not None}
    opts["integrator"] = spec
    workers = None
    if chunks is None or photon_batches is None:
        workers = len(client.scheduler_info().get("workers", {})) or 1
    if chunks is None:
        chunks = 4 * workers
    if photon_batches is None:
        photon_batches = workers
    if form_factor_batches is None:
        form_factor_batches = chunks
    for name, v in (("chunks", chunks), ("photon_batches", photon_batches), ("form_factor_batches", form_factor_batches)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise OptionError(f"{name} must be a positive integer, got {v!r}")
    if not (0 <= compress <= 9):
        raise OptionError(f"compress is a zlib level 0..9 (0: none), got {compress}")
    src = _source(scene, params, ship)
    # Shipped files go to every worker once; tasks refer to them by future.
    shipped = client.scatter(src, broadcast=True, hash=False) if src.files is not None else None
    ref = shipped if shipped is not None else src
    plan = client.submit(_plan_task, ref, chunks, opts, pure=False).result()
    if plan["scheme"] == "sppm":
        return SppmRender(client, src, plan, opts, threads, shipped, row_blocks=chunks, photon_batches=photon_batches)
    return DistributedRender(client, src, plan, opts, threads, compress, shipped, batches=photon_batches, row_batches=form_factor_batches)


def render(
    scene: Union[PathLike, Scene, SceneSource],
    *,
    client=None,
    integrator: Optional[str] = None,
    options: Optional[Mapping[str, Any]] = None,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    chunks: Optional[int] = None,
    params: Optional[Mapping[str, Any]] = None,
    ship: bool = True,
    threads: Optional[int] = None,
    compress: int = 0,
    photon_batches: Optional[int] = None,
    form_factor_batches: Optional[int] = None,
    progress: Union[bool, None, Callable[[int, int, float], Any]] = None,
    result: bool = False,
    **settings: Any,
) -> Union[np.ndarray, RenderResult]:
    """Render on a Dask cluster; the image a local ``svetlo.render`` makes, bit for bit.

    Args:
        scene: the scene file's path (or a :class:`svetlo.Scene` loaded from a file, or a
            :class:`SceneSource`); ``params`` fill its ``<default>`` parameters.
        client: a ``dask.distributed.Client`` (default: the current one).
        integrator, options, spp, seed and the other settings (max_depth, width, height,
            filter, sampler, rr_depth, hide_emitters, ray_epsilon): as :func:`svetlo.render`.
        chunks: how many tasks (nodes of the tree over the render's passes, or over its
            Metropolis chain blocks; fewer if there are fewer). Default: 4 per worker. For
            sppm: the blocks of rows, each a task per iteration.
        photon_batches: photon and sppm: tasks tracing the photon maps' paths (each
            iteration's, for sppm) by index (default: one per worker).
        form_factor_batches: radiosity: tasks computing ranges of the form-factor matrix's
            rows before the one solve task (default: ``chunks``; the hierarchical solver and
            progressive rows on demand make their own in the solve task).
        ship: send the scene's files to the workers (default) or let them read the path.
        threads: threads per task (default: the worker's cores over its task slots).
        compress: zlib level for the film sums sent back, after regrouping their bytes by
            significance (lossless; 0: sent as they are).
        progress: None shows a tqdm bar when tqdm is installed, False nothing, a callable
            is called as ``progress(spp_done, spp_planned, seconds)`` as chunks complete.
        result: return the :class:`svetlo.RenderResult` instead of the image.

    Raises the exceptions a local render raises (a scene error on a worker is the same
    :class:`svetlo.SceneError`); :class:`svetlo.RenderInterrupted` on Ctrl-C, with the image
    of the chunks done.
    """
    job = submit(
        scene, client=client, integrator=integrator, options=options, chunks=chunks, params=params, ship=ship, threads=threads, compress=compress, photon_batches=photon_batches, form_factor_batches=form_factor_batches, spp=spp, seed=seed, **settings
    )
    bar = None
    if progress is None or progress is True:
        b = svetlo._Bar(None)
        bar = b if b.bar is not None else None
        cb = (lambda d, t, s: b(d, t, s)) if bar is not None else None
    elif progress is False:
        cb = None
    elif callable(progress):
        cb = progress
    else:
        raise TypeError("progress must be None, False, True or a callable(spp_done, spp_planned, seconds)")
    try:
        r = job.result(cb)
    finally:
        if bar is not None:
            bar.close()
    return r if result else r.image


def render_independent(
    scene: Union[PathLike, Scene, SceneSource],
    *,
    client=None,
    renders: int,
    seed: int = 0,
    integrator: Optional[str] = None,
    options: Optional[Mapping[str, Any]] = None,
    params: Optional[Mapping[str, Any]] = None,
    ship: bool = True,
    threads: Optional[int] = None,
    **settings: Any,
) -> Tuple[np.ndarray, List[np.ndarray]]:
    """The rule for the methods that are not sums of independent pixel samples (sppm,
    pssmlt, mlt; any method works): `renders` independent renders, seeds ``seed``,
    ``seed + 1``, ..., each on a worker, averaged in seed order (deterministic for given
    seeds). Returns (mean image, the renders' images).

    What it does to each method: pssmlt and mlt run independent bootstraps and chains, so the
    average is as unbiased as one render (each render's normalisation is its own bootstrap's)
    with variance over `renders`; sppm's bias shrinks with its iterations, not with
    `renders`, so N renders of k iterations have the bias of k iterations and the variance of
    N k: prefer more iterations per render where bias dominates. photon: independent maps.
    """
    client = _default_client(client)
    if isinstance(renders, bool) or not isinstance(renders, int) or renders < 1:
        raise OptionError(f"renders must be a positive integer, got {renders!r}")
    if "time" in settings:
        raise OptionError("independent renders are planned by spp or iterations, not time")
    src = _source(scene, params, ship)
    shipped = client.scatter(src, broadcast=True, hash=False) if src.files is not None else None
    ref = shipped if shipped is not None else src
    base = dict(integrator=integrator, options=options, **{k: v for k, v in settings.items() if v is not None})
    futs = [client.submit(_independent_task, ref, dict(base, seed=seed + i), threads, pure=False) for i in range(renders)]
    try:
        out = client.gather(futs)
    except BaseException:
        client.cancel(futs)
        raise
    images = [img for img, _ in out]
    mean = np.zeros_like(images[0], dtype=np.float64)
    for img in images:
        mean += img
    return (mean / renders).astype(np.float32), images


# --- Command line: python -m svetlo.distributed.


def _cli_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m svetlo.distributed",
        description="Render a scene on a Dask cluster: the image a local render makes, bit for bit.",
    )
    p.add_argument("scene", help="scene file (Mitsuba XML)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://host:8786")
    where.add_argument("--workers", metavar="N", type=int, help="start a LocalCluster of N worker processes (default: one per core)")
    p.add_argument("-o", "--output", metavar="OUT", help="image to write (.exr, .png, .pfm; an .exr gets OUT.png beside it). Default: <scene name>.exr")
    p.add_argument("--integrator", metavar="NAME", help="method, with options as NAME:key=value,... (default: the scene's)")
    p.add_argument("--spp", type=int, metavar="N")
    p.add_argument("--seed", type=int, metavar="S")
    p.add_argument("--max-depth", type=int, metavar="D")
    p.add_argument("--width", type=int, metavar="W")
    p.add_argument("--height", type=int, metavar="H")
    p.add_argument("--filter", choices=["box", "tent", "gaussian"])
    p.add_argument("--sampler", choices=["independent", "sobol"])
    p.add_argument("--chunks", type=int, metavar="N", help="render tasks (default: 4 per worker)")
    p.add_argument("--photon-batches", type=int, metavar="N", help="photon and sppm: photon tracing tasks (default: one per worker)")
    p.add_argument("--form-factor-batches", type=int, metavar="N", help="radiosity: form-factor row tasks (default: --chunks)")
    p.add_argument("--threads", type=int, metavar="N", help="threads per task (default: the worker's cores over its task slots)")
    p.add_argument("--compress", type=int, default=0, metavar="LEVEL", help="zlib level for the film sums sent back (lossless; 0: none)")
    p.add_argument("--no-ship", action="store_true", help="workers read the scene's path (a shared file system) instead of being sent its files")
    p.add_argument("-D", dest="define", action="append", default=[], metavar="NAME=VALUE", help="scene parameter for <default> / $name (repeatable)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    return p


def _write_outputs(out: str, image: np.ndarray) -> List[str]:
    svetlo.write(out, image)
    written = [out]
    if out.lower().endswith(".exr"):
        png = out[:-4] + ".png"
        svetlo.write(png, image)
        written.append(png)
    return written


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m svetlo.distributed``: render on a cluster, write the image. Exit status 0,
    2 for bad options, 3 for a scene error, 1 for other failures, 130 when interrupted (the
    image of the chunks done is written)."""
    a = _cli_parser().parse_args(argv)
    say = (lambda *m: None) if a.quiet else (lambda *m: print("svetlo.distributed:", *m, file=sys.stderr, flush=True))
    params = {}
    for d in a.define:
        name, eq, value = d.partition("=")
        if not eq or not name:
            print(f"error: -D takes NAME=VALUE, got {d!r}", file=sys.stderr)
            return 2
        params[name] = value
    if a.workers is not None and a.workers < 1:
        print(f"error: --workers must be at least 1, got {a.workers}", file=sys.stderr)
        return 2
    out = a.output or os.path.splitext(os.path.basename(a.scene))[0] + ".exr"
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        print("error: svetlo.distributed needs dask's distributed scheduler: pip install 'dask[distributed]'", file=sys.stderr)
        return 1
    settings = dict(spp=a.spp, seed=a.seed, max_depth=a.max_depth, width=a.width, height=a.height, filter=a.filter, sampler=a.sampler)
    cluster = None
    t0 = time.perf_counter()
    try:
        if a.scheduler:
            say(f"connecting to {a.scheduler}")
            client = Client(a.scheduler)
        else:
            n = a.workers or os.cpu_count() or 1
            say(f"starting a local cluster of {n} worker processes")
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
            client = Client(cluster)
        with client:
            workers = len(client.scheduler_info().get("workers", {}))
            job = submit(
                a.scene,
                client=client,
                integrator=a.integrator,
                chunks=a.chunks,
                params=params or None,
                ship=not a.no_ship,
                threads=a.threads,
                compress=a.compress,
                photon_batches=a.photon_batches,
                form_factor_batches=a.form_factor_batches,
                **{k: v for k, v in settings.items() if v is not None},
            )
            say(f"{job.plan['integrator']}: {len(job.futures)} tasks on {workers} workers, {job.spp_planned} spp planned")
            cb = (lambda d, t, secs: say(f"{d}/{t} spp ({secs:.1f} s)")) if not a.quiet else None
            try:
                r = job.result(cb)
            except RenderInterrupted as e:
                written = _write_outputs(out, e.image)
                print(f"interrupted: wrote the {e.result.spp} spp done to {', '.join(written)}", file=sys.stderr)
                return 130
    except KeyboardInterrupt:
        print("interrupted before any chunk was done", file=sys.stderr)
        return 130
    except svetlo.SceneError as e:
        print(f"error: {e}", file=sys.stderr)
        return 3
    except (OptionError, TypeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except (SvetloError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    finally:
        if cluster is not None:
            cluster.close()
    written = _write_outputs(out, r.image)
    h, w = r.image.shape[:2]
    say(f"wrote {', '.join(written)}: {w}x{h}, {r.spp} spp, {time.perf_counter() - t0:.1f} s, {job.bytes_received} bytes of film sums received")
    return 0


if __name__ == "__main__":
    # Run the imported module's main, not this __main__ copy: tasks must refer to
    # svetlo.distributed's functions (and its scene cache), which the workers import.
    from svetlo.distributed import main as _main

    sys.exit(_main())
