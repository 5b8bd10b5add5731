#!/usr/bin/env python3
"""Equal-time error of path, light and bdpt (and Mitsuba 3's `path`) on the scenes where
tracing from the lights should win: scenes/caustic.xml and scenes/indirect-room.xml.

Each method renders for the same wall time (svetlo: `--time T`; Mitsuba: the spp its own
calibration run says fit in T); the error is relMSE against a long, high-spp reference
(svetlo bdpt, `--ref-spp`, cached under target/bench-bidir/). relMSE = mean over pixels and
channels of (x - r)^2 / (r^2 + 0.01), the project's convention. Usage (repository root):

    python3 bench/bidir/compare.py [--time 10] [--ref-spp 1024] [--mitsuba scalar_rgb|llvm_ad_rgb|none]

Timing on a shared machine is noisy and relMSE heavy-tailed (rare bright paths): methods
run alternately for `--repeats` rounds with different seeds and the table shows the means;
the ratio of errors at equal time is what matters.
"""
import argparse
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = ["caustic", "indirect-room"]
METHODS = ["path", "light", "bdpt"]


def read_exr(path):
    import mitsuba as mi
    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False), dtype=np.float64)


def relmse(img, ref):
    return float(np.mean((img - ref) ** 2 / (ref * ref + 0.01)))


def svetlo(binary, scene, out, extra):
    t0 = time.perf_counter()
    r = subprocess.run([binary, "render", scene, "-o", out] + extra, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    spp = next((int(l.split()[1]) for l in r.stdout.splitlines() if l.startswith("spp")), 0)
    secs = next((float(l.split()[1]) for l in r.stdout.splitlines() if l.startswith("time")), wall)
    return spp, secs


def mitsuba_path(variant, scene, spp, out, seed=0):
    """Render in a fresh process; returns the render time alone (load and JIT excluded)."""
    code = (
        "import mitsuba as mi, time;"
        f"mi.set_variant('{variant}');"
        f"s = mi.load_file(r'{scene}', spp={spp}, integrator='path');"
        "import numpy as np;"
        "t0 = time.perf_counter();"
        f"img = mi.render(s, spp={spp}, seed={seed});"
        "arr = np.array(img);"  # forces the (lazy, JIT-compiled) render to run
        "print(time.perf_counter() - t0);"
        f"mi.Bitmap(arr).write(r'{out}')"
    )
    r = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return float(r.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--time", type=float, default=10.0, help="seconds per method and scene")
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--mitsuba", default="scalar_rgb", help="Mitsuba 3 variant, or 'none'")
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--methods", default=",".join(METHODS), help="svetlo integrators, e.g. path,bdpt,sppm,photon (path is the baseline)")
    ap.add_argument("--repeats", type=int, default=3, help="rounds (seeds), methods alternating; spp, time and relMSE are averaged")
    ap.add_argument("--svetlo", default=os.path.join(ROOT, "target", "release", "svetlo"))
    a = ap.parse_args()
    methods = a.methods.split(",")
    if "path" not in methods:
        methods.insert(0, "path")
    work = os.path.join(ROOT, "target", "bench-bidir")
    os.makedirs(work, exist_ok=True)
    rows = []
    for name in a.scenes.split(","):
        scene = os.path.join(ROOT, "scenes", f"{name}.xml")
        ref_path = os.path.join(work, f"ref_{name}_bdpt_{a.ref_spp}spp.exr")
        if not os.path.exists(ref_path):
            print(f"{name}: rendering the reference (bdpt, {a.ref_spp} spp) ...", flush=True)
            tmp = ref_path + ".tmp.exr"
            svetlo(a.svetlo, scene, tmp, ["--integrator", "bdpt", "--spp", str(a.ref_spp), "--seed", "987654321"])
            os.replace(tmp, ref_path)
        ref = read_exr(ref_path)
        runs = {}
        mi_spp = None
        for rep in range(a.repeats):
            for m in methods:
                out = os.path.join(work, f"{name}_{m}_{rep}.exr")
                spp, secs = svetlo(a.svetlo, scene, out, ["--integrator", m, "--time", str(a.time), "--seed", str(1 + rep)])
                runs.setdefault(f"svetlo {m}", []).append((spp, secs, relmse(read_exr(out), ref)))
            if a.mitsuba != "none":
                out = os.path.join(work, f"{name}_mitsuba_path_{rep}.exr")
                if mi_spp is None:
                    t4 = mitsuba_path(a.mitsuba, scene, 4, out)
                    mi_spp = max(1, int(4 * a.time / max(t4, 1e-3)))
                secs = mitsuba_path(a.mitsuba, scene, mi_spp, out, rep)
                if rep == 0 and abs(secs - a.time) > 0.1 * a.time:  # the short calibration misjudges: rescale once
                    mi_spp = max(1, int(mi_spp * a.time / max(secs, 1e-3)))
                    secs = mitsuba_path(a.mitsuba, scene, mi_spp, out, rep)
                runs.setdefault(f"mitsuba {a.mitsuba} path", []).append((mi_spp, secs, relmse(read_exr(out), ref)))
        # Means over the rounds: relMSE is heavy-tailed (rare bright paths), one run says little.
        results = {k: tuple(float(np.mean([r[i] for r in v])) for i in range(3)) for k, v in runs.items()}
        base = results["svetlo path"][2]
        for k, (spp, secs, e) in results.items():
            rows.append((name, k, spp, secs, e, base / e if e > 0 else float("inf")))
        # The reference's own error, for scale: bdpt's error at equal time shrinks by its spp ratio.
        if "svetlo bdpt" in results:
            bspp, _, be = results["svetlo bdpt"]
            rows.append((name, "(reference floor, est.)", a.ref_spp, float("nan"), be * bspp / a.ref_spp, float("nan")))
    print(f"\nequal time: {a.time:g} s per method, means of {a.repeats} runs; reference: svetlo bdpt {a.ref_spp} spp")
    print(f"{'scene':<15}{'method':<28}{'spp':>7}{'time (s)':>10}{'relMSE':>12}{'path / it':>11}")
    for r in rows:
        print(f"{r[0]:<15}{r[1]:<28}{r[2]:>7.0f}{r[3]:>10.2f}{r[4]:>12.3e}{r[5]:>11.2f}")


if __name__ == "__main__":
    main()
