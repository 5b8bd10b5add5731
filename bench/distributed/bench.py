"""Distributed rendering on Dask (issue #17): speed-up with 1 and 2 worker processes, the
scheduler's overhead per task, and bytes sent back per task against the film's size.

    python3 bench/distributed/bench.py [--size 512] [--spp 4] [--integrator bdpt] [--repeats 2]
    python3 bench/distributed/bench.py --schemes [--repeats 3]

``--schemes`` times the methods that are not plain sums of samples, each by its own scheme
(radiosity: form-factor rows spread, one solve; photon: photon batches; sppm: photon batches
and row blocks per iteration; pssmlt: chain blocks from one bootstrap) on 1 and 2 worker
processes, and radiosity against every chunk solving for itself (the scheme before).

Wall times on a shared machine are noisy: runs alternate (local, 1 worker, 2 workers, ...)
and the medians are reported, with the machine's load average beside them. Every distributed
image is checked against the local one, bit for bit.
"""

import argparse
import os
import statistics
import sys
import time
import zlib

import numpy as np

import svetlo
import svetlo.distributed as sd
from svetlo import _svetlo

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CBOX = os.path.join(ROOT, "scenes", "cornell-box.xml")


def cluster(n):
    from distributed import Client, LocalCluster

    c = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
    return c, Client(c)


def schemes(a):
    """Speed-up of the non-separable schemes: median wall time on 1 worker over 2 workers."""
    cases = [
        # ~4400 elements, hemicube 64: the form factors dominate, the display is cheap.
        ("radiosity", dict(integrator="radiosity", options={"element-size": 0.25, "form-factors": "hemicube", "hemicube-resolution": 64}, spp=4, width=64, height=64), {}),
        ("photon", dict(integrator="photon", options={"photons": 100000, "caustic_photons": 10000, "gather": 8}, spp=4, width=64, height=64), {}),
        ("sppm", dict(integrator="sppm", options={"photons": 50000}, spp=4, width=64, height=64), {}),
        ("pssmlt", dict(integrator="pssmlt", options={"chains": 64, "bootstrap": 20000}, spp=16, width=64, height=64), {}),
    ]
    clusters = {n: cluster(n) for n in (1, 2)}
    scene = svetlo.load_file(CBOX)
    print(f"schemes on cornell-box, medians of {a.repeats} alternating runs; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for name, kw, extra in cases:
        kw = dict(kw, seed=1)
        ref = svetlo.render(scene, threads=1, progress=False, **kw)
        times = {1: [], 2: [], "per-chunk solve, 2": []}
        for _ in range(a.repeats):
            for n, (_, client) in clusters.items():
                t = time.perf_counter()
                img = sd.render(CBOX, client=client, chunks=4, threads=1, progress=False, **kw, **extra)
                times[n].append(time.perf_counter() - t)
                assert np.array_equal(img.view(np.uint32), ref.view(np.uint32)), f"{name}: distributed image differs from the local one"
            if name == "radiosity":
                # The scheme before: every chunk solves for itself (render_passes without the
                # shared solution), 4 chunks on 2 workers.
                _, client = clusters[2]
                src = sd.scene_source(CBOX)
                opts = dict(spp=kw["spp"], seed=1, width=kw["width"], height=kw["height"], integrator=svetlo._method_spec(kw["integrator"], kw["options"], None))
                plan = client.submit(sd._plan_task, src, 4, opts, pure=False).result()
                t = time.perf_counter()
                parts = client.gather([client.submit(sd._render_task, src, s0, s1, opts, 1, 0, pure=False) for s0, s1, _, _ in plan["nodes"]])
                img = _svetlo.merge_films([sd.unpack(p) for _, p in parts])["image"]
                times["per-chunk solve, 2"].append(time.perf_counter() - t)
                assert np.array_equal(img.view(np.uint32), ref.view(np.uint32))
        m1, m2 = statistics.median(times[1]), statistics.median(times[2])
        line = f"  {name:9s} 1 worker {m1:6.2f} s, 2 workers {m2:6.2f} s: speed-up {m1 / m2:4.2f}"
        if times["per-chunk solve, 2"]:
            mp = statistics.median(times["per-chunk solve, 2"])
            line += f"; every chunk solving, 2 workers {mp:6.2f} s ({mp / m2:4.2f}x the shared solve)"
        print(line, flush=True)
        if name == "radiosity":
            # What spreads and what does not, on one thread in this process: the rows, then
            # the solve from them (mesh, assembly, solver) and one display chunk.
            opts = dict(spp=kw["spp"], seed=1, width=kw["width"], height=kw["height"], integrator=svetlo._method_spec(kw["integrator"], kw["options"], None))
            plan = _svetlo.plan_chunks(scene, 4, opts)
            t = time.perf_counter()
            rows = _svetlo.radiosity_rows(scene, 0, plan["rows"], opts, threads=1)
            t_rows = time.perf_counter() - t
            t = time.perf_counter()
            sol = _svetlo.radiosity_solve(scene, [rows], opts, threads=1)
            t_solve = time.perf_counter() - t
            a0, a1, _, _ = plan["nodes"][0]
            t = time.perf_counter()
            _svetlo.render_passes(scene, a0, a1, opts, shared=[sol], threads=1)
            t_show = time.perf_counter() - t
            f = t_rows / (t_rows + t_solve)
            print(
                f"    one thread: {plan['rows']} rows {t_rows:.2f} s ({len(rows) / 1e6:.1f} MB), solve from them {t_solve:.2f} s (solution {len(sol) / 1e3:.0f} kB), "
                f"one display chunk {t_show:.2f} s: rows are {f:.0%} of the solve, so 2 workers can at best be {1 / (1 - f / 2):.2f}x"
            )
    for c, client in clusters.values():
        client.close()
        c.close()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--schemes", action="store_true", help="time radiosity, photon, sppm and pssmlt on 1 and 2 workers")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--integrator", default="bdpt")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--chunks", type=int, default=8)
    a = ap.parse_args()
    if a.schemes:
        return schemes(a)
    kw = dict(integrator=a.integrator, spp=a.spp, seed=1, width=a.size, height=a.size)
    scene = svetlo.load_file(CBOX)
    clusters = {n: cluster(n) for n in (1, 2)}
    times = {"local, 1 thread": [], "local, 2 threads": [], "dask, 1 worker": [], "dask, 2 workers": []}
    ref = None
    for _ in range(a.repeats):
        for th in (1, 2):
            t = time.perf_counter()
            img = svetlo.render(scene, threads=th, progress=False, **kw)
            times[f"local, {th} thread{'s' if th > 1 else ''}"].append(time.perf_counter() - t)
            ref = img if ref is None else ref
        for n, (_, client) in clusters.items():
            t = time.perf_counter()
            img = sd.render(CBOX, client=client, chunks=a.chunks, threads=1, progress=False, **kw)
            times[f"dask, {n} worker{'s' if n > 1 else ''}"].append(time.perf_counter() - t)
            assert np.array_equal(img.view(np.uint32), ref.view(np.uint32)), "distributed image differs from the local one"
    base = statistics.median(times["local, 1 thread"])
    print(f"{a.integrator} {a.size}x{a.size}, {a.spp} spp, {a.chunks} chunks; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for k, v in times.items():
        m = statistics.median(v)
        print(f"  {k:18s} median {m:7.2f} s   speed-up over local 1 thread {base / m:4.2f}")

    # Overhead per task: many tiny tasks (an 8x8 film, 64-sample passes), wall time less the
    # tasks' own render time, per task.
    _, client = clusters[2]
    small = dict(integrator="direct", spp=64 * 40, seed=1, width=8, height=8)
    for chunks in (8, 32):
        job = sd.submit(CBOX, client=client, chunks=chunks, threads=1, **small)
        t = time.perf_counter()
        r = job.result()
        wall = time.perf_counter() - t
        n = len(job.nodes)
        busy = sum(job.task_seconds.values())
        print(f"  overhead: {n} tasks in {wall:.3f} s wall, {busy:.3f} s rendering: {(wall - busy / 2) / n * 1e3:.1f} ms per task (2 workers)")

    # Bytes per task: one node's raw sums, plain and zlib level 1, by film size.
    print("  bytes per task (one node of the pass tree, independent of its spp):")
    for size in (64, 256, 512, 1024):
        for integ in ("path", "bdpt"):
            raw = _svetlo.render_passes(scene, 0, 1, dict(integrator=integ, spp=1, width=size, height=size, max_depth=3))
            z = zlib.compress(raw, 1)
            print(f"    {integ:5s} {size:5d}^2: {len(raw) / 1e6:8.2f} MB raw ({len(raw) / size ** 2:.0f} B/pixel), zlib-1 {len(z) / 1e6:8.2f} MB ({len(z) / len(raw):.0%})")
    for c, client in clusters.values():
        client.close()
        c.close()


if __name__ == "__main__":
    sys.exit(main())
