#!/usr/bin/env python3
"""svetlo's accelerator against Embree (embreex) on the same mesh and the same rays.

Starts the Rust bench (crates/svetlo/examples/raycast_bench.rs --serve), which builds
the mesh and svetlo's BVH and writes the mesh, the rays and svetlo's hits to --out;
builds Embree's scene on the same mesh; checks that both find the same hits; then,
for each ray set, query and thread count, alternates one svetlo run and one Embree
run (--repeat times), so that both see the same load on a shared machine, and
prints both throughputs and their ratio.

embreex casts one ray per rtcIntersect1/rtcOccluded1 call from a Cython loop that
holds the GIL, so its 2-thread numbers come from 2 forked processes sharing the
committed scene, each casting half of the rays. The loop's own cost per ray is
measured (rays that miss the scene's bounds) and reported; it is included in the
Embree numbers, as svetlo's per-ray call cost is in svetlo's.
"""

import argparse
import json
import multiprocessing as mp
import os
import statistics
import subprocess
import sys
import time

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


class RustBench:
    """The Rust bench in --serve mode: one cast per request."""

    def __init__(self, args):
        cmd = [args.rust_bin, "--out", args.out, "--serve"]
        if args.subdiv:
            cmd += ["--subdiv", str(args.subdiv)]
        print("$", " ".join(cmd), flush=True)
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
        self.build = json.loads(self.proc.stdout.readline())
        if self.proc.stdout.readline().strip() != "ready":
            raise RuntimeError("raycast_bench did not start")

    def cast(self, name, query, threads):
        self.proc.stdin.write(f"{name} {query} {threads}\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def load_mesh(path):
    head = np.fromfile(path, dtype="<u4", count=2)
    nv, nt = int(head[0]), int(head[1])
    v = np.fromfile(path, dtype="<f4", count=3 * nv, offset=8).reshape(nv, 3)
    f = np.fromfile(path, dtype="<u4", count=3 * nt, offset=8 + 12 * nv).reshape(nt, 3).astype(np.int32)
    return v, f


def load_rays(path):
    n = int(np.fromfile(path, dtype="<u4", count=1)[0])
    r = np.fromfile(path, dtype="<f4", count=7 * n, offset=4).reshape(n, 7)
    return np.ascontiguousarray(r[:, 0:3]), np.ascontiguousarray(r[:, 3:6]), np.ascontiguousarray(r[:, 6])


def load_hits(path):
    h = np.fromfile(path, dtype=np.dtype([("prim", "<i4"), ("t", "<f4")]))
    return h["prim"], h["t"]


def cast(scene, o, d, tmax, query):
    # embreex writes the hit distances into `dists`: hand it a fresh copy every time.
    # Embree's tfar must be finite-or-inf; our inf is fine.
    return scene.run(o, d, dists=tmax.copy(), query=query)


# Forked workers see the parent's committed scene and rays (copy-on-write).
_G = {}


def _worker(k, nproc, query, start_evt, q):
    o, d, tmax = _G["rays"]
    n = len(o)
    lo, hi = k * n // nproc, (k + 1) * n // nproc
    start_evt.wait()
    t0, c0 = time.perf_counter(), time.thread_time()
    cast(_G["scene"], o[lo:hi], d[lo:hi], tmax[lo:hi], query)
    q.put((t0, time.perf_counter(), time.thread_time() - c0))


def time_cast(scene, rays, query, threads):
    """(wall seconds, CPU seconds summed over the workers)."""
    o, d, tmax = rays
    if threads == 1:
        t0, c0 = time.perf_counter(), time.thread_time()
        cast(scene, o, d, tmax, query)
        return time.perf_counter() - t0, time.thread_time() - c0
    ctx = mp.get_context("fork")
    _G["scene"], _G["rays"] = scene, rays
    evt, q = ctx.Event(), ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(k, threads, query, evt, q)) for k in range(threads)]
    for p in procs:
        p.start()
    time.sleep(0.2)
    evt.set()
    spans = [q.get() for _ in procs]
    for p in procs:
        p.join()
    return max(s[1] for s in spans) - min(s[0] for s in spans), sum(s[2] for s in spans)


def check_hits(scene, rays, svetlo_hits):
    """Same hit triangles (up to ties on shared edges) and same distances as svetlo?"""
    o, d, tmax = rays
    r = scene.run(o, d, dists=tmax.copy(), output=1)
    prim_e, t_e = r["primID"], r["tfar"]
    prim_s, t_s = svetlo_hits
    hit_e, hit_s = prim_e >= 0, prim_s >= 0
    both = hit_e & hit_s
    same_prim = np.mean(prim_e[both] == prim_s[both]) if both.any() else 1.0
    rel = np.abs(t_e[both] - t_s[both]) / np.maximum(t_s[both], 1e-6)
    return {
        "hits_embree": int(hit_e.sum()),
        "hits_svetlo": int(hit_s.sum()),
        "hit_disagree": int((hit_e != hit_s).sum()),
        "same_prim": float(same_prim),
        "max_rel_dt": float(rel.max()) if both.any() else 0.0,
    }


def fmt_runs(xs):
    return f"{statistics.median(xs):6.2f} [{min(xs):.2f}-{max(xs):.2f}]"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "bench", "out"))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--subdiv", type=int, default=0, help="cube-sphere subdivision (289: 1M triangles)")
    ap.add_argument("--rust-bin", default=os.path.join(ROOT, "target", "release", "examples", "raycast_bench"))
    ap.add_argument("--json", help="also write all results to this file")
    args = ap.parse_args()
    threads = [int(t) for t in args.threads.split(",")]

    if not os.path.exists(args.rust_bin):
        subprocess.run(["cargo", "build", "--release", "-p", "svetlo", "--example", "raycast_bench"], check=True, cwd=ROOT)
    rust = RustBench(args)
    build = rust.build
    print(f"mesh: {build['triangles']} triangles; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")

    v, f = load_mesh(os.path.join(args.out, "mesh.bin"))
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, v, f)
    one = np.zeros((1, 3), np.float32)
    t0 = time.perf_counter()
    scene.run(one, one + np.float32(1.0))  # the first query commits (builds) the scene
    embree_build = time.perf_counter() - t0
    print(f"build: svetlo {build['build_s']:.2f} s ({build['rayon_threads']} threads), "
          f"{build['build_1thread_s']:.2f} s (1 thread); Embree {embree_build:.2f} s (its own TBB threads)")

    # embreex's loop cost per ray, measured on rays that miss the scene's bounding box.
    n = 1 << 18
    far = (np.ones((n, 3), np.float32) * 1e3, np.ones((n, 3), np.float32), np.full(n, np.inf, np.float32))
    overhead_ns = min(time_cast(scene, far, "INTERSECT", 1)[1] for _ in range(3)) / n * 1e9
    print(f"embreex per-ray call overhead (rays missing the bounds): {overhead_ns:.0f} ns")

    rows = []
    print("Mrays/s: wall clock, median [min-max] of the repeats; 'cpu' columns: rays per CPU-second of one")
    print("thread (wall time minus the time spent waiting for a core: steadier on a loaded machine).")
    header = (f"{'rays':<11}{'query':<9}{'thr':>3}  {'svetlo':<22}{'Embree':<22}{'ratio':>6}  "
              f"{'svetlo cpu':<11}{'Embree cpu':<11}{'ratio':>6}  check")
    print(header)
    print("-" * len(header))
    for name in ("coherent", "incoherent", "segments"):
        rays = load_rays(os.path.join(args.out, f"rays_{name}.bin"))
        chk = check_hits(scene, rays, load_hits(os.path.join(args.out, f"hits_{name}.bin")))
        for query in ("closest", "occluded"):
            eq = "INTERSECT" if query == "closest" else "OCCLUDED"
            for th in threads:
                s = {"mrays": [], "cpu_mrays_per_thread": []}
                times = []
                for _ in range(args.repeat):
                    r = rust.cast(name, query, th)
                    s["mrays"] += r["mrays"]
                    s["cpu_mrays_per_thread"] += r["cpu_mrays_per_thread"]
                    times.append(time_cast(scene, rays, eq, th))
                e = [len(rays[0]) / w / 1e6 for w, _ in times]
                e_cpu = [len(rays[0]) / c / 1e6 for _, c in times]
                ratio = statistics.median(s["mrays"]) / statistics.median(e)
                ratio_cpu = statistics.median(s["cpu_mrays_per_thread"]) / statistics.median(e_cpu)
                note = (f"hits {chk['hits_svetlo']}/{chk['hits_embree']}, same tri {100 * chk['same_prim']:.3f}%, "
                        f"max rel dt {chk['max_rel_dt']:.1e}") if query == "closest" and th == threads[0] else ""
                print(f"{name:<11}{query:<9}{th:>3}  {fmt_runs(s['mrays']):<22}{fmt_runs(e):<22}{ratio:6.2f}  "
                      f"{statistics.median(s['cpu_mrays_per_thread']):7.2f}    {statistics.median(e_cpu):7.2f}    {ratio_cpu:6.2f}  {note}", flush=True)
                rows.append({"set": name, "query": query, "threads": th, "svetlo": s["mrays"], "embree": e, "ratio": ratio,
                             "svetlo_cpu": s["cpu_mrays_per_thread"], "embree_cpu": e_cpu, "ratio_cpu": ratio_cpu, "check": chk})
    rust.close()
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"build": build, "embree_build_s": embree_build, "embreex_overhead_ns": overhead_ns, "rows": rows}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
