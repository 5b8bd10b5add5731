#!/usr/bin/env python3
"""svetlo's walks against Mitsuba's own Embree, without a Python loop per ray.

`embree_compare.py` calls embreex (Embree 4) once per ray from Cython. This script loads
the Embree 3 library that the mitsuba wheel ships (its symbols sit in the C++ namespace
`mitsuba`), builds the bench's mesh at the build quality Mitsuba asks for
(`RTC_BUILD_QUALITY_HIGH`: spatial splits) and at the default (`MEDIUM`), and casts every
ray set through the stream call (`rtcIntersect1M`, `rtcOccluded1M`), one thread. svetlo's
side is `raycast_bench --serve`, one by one and eight lanes at a time (`--lanes`, as the
path kernel casts). Runs alternate; the ratios are of rays per CPU second, medians.

Needs `pip install mitsuba numpy` and the bench's files in --out (run `run.sh` once, or
`raycast_bench --repeat 1 --threads 1` writes them).
"""

import argparse
import ctypes as C
import importlib.util
import json
import os
import re
import statistics
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from embree_compare import ROOT, load_hits, load_mesh, load_rays  # noqa: E402

QUALITY = {"medium": 1, "high": 2}  # RTCBuildQuality
BUFFER_INDEX, BUFFER_VERTEX = 0, 1
FORMAT_UINT3, FORMAT_FLOAT3 = 0x5003, 0x9003
RAYHIT_BYTES = 96  # RTCRayHit: the ray's 48 bytes, the hit's 36, aligned to 16


class Embree3:
    """The calls this bench needs from the mitsuba wheel's libembree3."""

    def __init__(self):
        spec = importlib.util.find_spec("mitsuba")
        if spec is None or not spec.submodule_search_locations:
            raise SystemExit("mitsuba is not installed (pip install mitsuba)")
        path = os.path.join(list(spec.submodule_search_locations)[0], "libembree3.so")
        dll = C.CDLL(path)
        syms = subprocess.run(["nm", "-D", "--defined-only", path], capture_output=True, text=True, check=True).stdout
        fns = {}
        for line in syms.splitlines():
            m = re.match(r"_ZN7mitsuba(\d+)(rtc\w+)", line.split()[-1])
            if m:
                fns[m.group(2)[: int(m.group(1))]] = dll[line.split()[-1]]
        sig = {
            "rtcNewDevice": (C.c_void_p, [C.c_char_p]),
            "rtcNewScene": (C.c_void_p, [C.c_void_p]),
            "rtcSetSceneBuildQuality": (None, [C.c_void_p, C.c_int]),
            "rtcNewGeometry": (C.c_void_p, [C.c_void_p, C.c_int]),
            "rtcSetSharedGeometryBuffer": (None, [C.c_void_p, C.c_int, C.c_uint, C.c_int, C.c_void_p, C.c_size_t, C.c_size_t, C.c_size_t]),
            "rtcCommitGeometry": (None, [C.c_void_p]),
            "rtcAttachGeometry": (C.c_uint, [C.c_void_p, C.c_void_p]),
            "rtcReleaseGeometry": (None, [C.c_void_p]),
            "rtcCommitScene": (None, [C.c_void_p]),
            "rtcReleaseScene": (None, [C.c_void_p]),
            "rtcIntersect1M": (None, [C.c_void_p, C.c_void_p, C.c_void_p, C.c_uint, C.c_size_t]),
            "rtcOccluded1M": (None, [C.c_void_p, C.c_void_p, C.c_void_p, C.c_uint, C.c_size_t]),
        }
        for name, (res, args) in sig.items():
            if name not in fns:
                raise SystemExit(f"{path} has no {name}")
            fns[name].restype, fns[name].argtypes = res, args
            setattr(self, name, fns[name])
        self.device = self.rtcNewDevice(b"threads=1")
        # RTCIntersectContext: flags (incoherent), filter (none), instID[0] (invalid).
        self.context = (C.c_uint32 * 6)(0, 0, 0, 0, 0xFFFFFFFF, 0)

    def build(self, vertices, faces, quality):
        """A committed scene of one triangle mesh and the CPU seconds of its commit."""
        s = self.rtcNewScene(self.device)
        self.rtcSetSceneBuildQuality(s, QUALITY[quality])
        g = self.rtcNewGeometry(self.device, 0)  # RTC_GEOMETRY_TYPE_TRIANGLE
        self.rtcSetSharedGeometryBuffer(g, BUFFER_VERTEX, 0, FORMAT_FLOAT3, vertices.ctypes.data, 0, 16, len(vertices))
        self.rtcSetSharedGeometryBuffer(g, BUFFER_INDEX, 0, FORMAT_UINT3, faces.ctypes.data, 0, 12, len(faces))
        self.rtcCommitGeometry(g)
        self.rtcAttachGeometry(s, g)
        self.rtcReleaseGeometry(g)
        c0 = time.process_time()
        self.rtcCommitScene(s)
        return s, time.process_time() - c0

    def cast(self, scene, rayhits, occluded):
        """The rays' hits (a fresh copy of `rayhits`) and the CPU seconds of the call."""
        x = rayhits.copy()
        c0 = time.process_time()
        call = self.rtcOccluded1M if occluded else self.rtcIntersect1M
        call(scene, C.byref(self.context), x.ctypes.data, len(x), RAYHIT_BYTES)
        return x, time.process_time() - c0


def rayhits(rays):
    """The bench's rays as RTCRayHit records (tnear 0, every mask bit, no hit yet)."""
    o, d, tmax = rays
    rh = np.zeros((len(o), RAYHIT_BYTES // 4), np.float32)
    rh[:, 0:3], rh[:, 4:7], rh[:, 8] = o, d, tmax
    u = rh.view(np.uint32)
    u[:, 9] = 0xFFFFFFFF  # mask
    u[:, 17:20] = 0xFFFFFFFF  # primID, geomID, instID[0]
    return rh


class Svetlo:
    """`raycast_bench --serve`, one by one or eight lanes at a time."""

    def __init__(self, binary, out, lanes):
        cmd = [binary, "--out", out, "--serve"] + (["--lanes"] if lanes else [])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
        self.build = json.loads(self.proc.stdout.readline())
        if self.proc.stdout.readline().strip() != "ready":
            raise RuntimeError("raycast_bench did not start")

    def cpu_mrays(self, name, query):
        self.proc.stdin.write(f"{name} {query} 1\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())["cpu_mrays_per_thread"][0]

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "bench", "out"))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sets", default="coherent,incoherent,segments")
    ap.add_argument("--rust-bin", default=os.path.join(ROOT, "target", "release", "examples", "raycast_bench"))
    args = ap.parse_args()

    e3 = Embree3()
    v, f = load_mesh(os.path.join(args.out, "mesh.bin"))
    v4 = np.zeros((len(v), 4), np.float32)  # Embree reads 16 bytes at the last vertex
    v4[:, :3] = v
    f = np.ascontiguousarray(f.astype(np.uint32))
    scenes, build_cpu = {}, {}
    for q in QUALITY:
        runs = []
        for _ in range(3):
            s, c = e3.build(v4, f, q)
            if q in scenes:
                e3.rtcReleaseScene(scenes[q])
            scenes[q] = s
            runs.append(c)
        build_cpu[q] = statistics.median(runs)
    sv = {"single": Svetlo(args.rust_bin, args.out, False), "lanes": Svetlo(args.rust_bin, args.out, True)}
    b = sv["single"].build
    print(f"mesh: {len(f)} triangles; build CPU, one thread: svetlo {b['build_1thread_cpu_s']:.3f} s, "
          f"Embree 3 medium {build_cpu['medium']:.3f} s, high {build_cpu['high']:.3f} s")
    print("rays per CPU second (M), one thread, medians of alternating runs; ratios svetlo / Embree 3")
    head = f"{'rays':<11}{'query':<9}{'E3 medium':>10}{'E3 high':>9}{'svetlo 1':>9}{'lanes':>7}  {'high/med':>8}{'1/high':>8}{'lanes/high':>11}  check"
    print(head)
    print("-" * len(head))
    for name in args.sets.split(","):
        rays = load_rays(os.path.join(args.out, f"rays_{name}.bin"))
        rh = rayhits(rays)
        prim_s, _ = load_hits(os.path.join(args.out, f"hits_{name}.bin"))
        for query in ("closest", "occluded"):
            occ = query == "occluded"
            runs = {k: [] for k in ("medium", "high", "single", "lanes")}
            for _ in range(args.repeat):
                for q in QUALITY:
                    x, c = e3.cast(scenes[q], rh, occ)
                    runs[q].append(len(rh) / c / 1e6)
                for k, s in sv.items():
                    runs[k].append(s.cpu_mrays(name, query))
            m = {k: statistics.median(r) for k, r in runs.items()}
            check = ""
            if not occ:
                prim_e = x.view(np.uint32)[:, 17].astype(np.int64)
                prim_e[prim_e == 0xFFFFFFFF] = -1
                both = (prim_e >= 0) & (prim_s >= 0)
                check = f"hits {int((prim_s >= 0).sum())}/{int((prim_e >= 0).sum())}, same tri {100 * np.mean(prim_e[both] == prim_s[both]):.3f}%"
            print(f"{name:<11}{query:<9}{m['medium']:>10.2f}{m['high']:>9.2f}{m['single']:>9.2f}{m['lanes']:>7.2f}  "
                  f"{m['high'] / m['medium']:>8.3f}{m['single'] / m['high']:>8.3f}{m['lanes'] / m['high']:>11.3f}  {check}", flush=True)
    for s in sv.values():
        s.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
