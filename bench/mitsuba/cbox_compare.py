#!/usr/bin/env python3
"""svetlo against Mitsuba 3 on the same scene, same resolution, spp and depth, in one run.

Runs each renderer several times, alternating, and prints the time ratio and each image's
RMSE / relMSE against the reference. Usage (from the repository root):

    python3 bench/mitsuba/cbox_compare.py [--spp 64] [--res 256] [--depth 6] [--repeats 3]

Mitsuba variants: scalar_rgb and llvm_ad_rgb (the LLVM one needs libLLVM 19: bench/mitsuba/run.sh
installs Debian's libllvm19 and points DRJIT_LIBLLVM_PATH at it).
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "scenes")
DEFAULT_SCENE = os.path.join(SHARED, "mitsuba-data", "scenes", "cbox", "cbox-rgb.xml")
DEFAULT_REF = os.path.join(SHARED, "mitsuba-data", "scenes", "cbox", "refs", "cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")


def read_exr(path):
    import mitsuba as mi
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False), dtype=np.float64)


def errors(img, ref):
    d = img - ref
    return float(np.sqrt(np.mean(d * d))), float(np.mean(d * d / (ref * ref + 0.01)))


def run_svetlo(binary, scene, spp, res, depth, out):
    """(whole process, render only) in seconds; the render time is the CLI's `time` line."""
    t0 = time.perf_counter()
    p = subprocess.run([binary, "render", scene, "-o", out, "--spp", str(spp), "--max-depth", str(depth),
                        "-D", f"res={res}", "--width", str(res), "--height", str(res), "--filter", "box"],
                       check=True, capture_output=True, text=True)
    total = time.perf_counter() - t0
    render = next((float(l.split()[1]) for l in (p.stdout + p.stderr).splitlines() if l.startswith("time ")), float("nan"))
    return total, render


def run_mitsuba(variant, scene, spp, res, depth, out):
    # A fresh process per run, as the CLI user would experience it (includes JIT compilation).
    # Render only: mi.render including its JIT compilation (kernels cached on disk by Dr.Jit
    # after the first run), synchronised by the bitmap conversion.
    code = (
        "import mitsuba as mi, sys, time;"
        f"mi.set_variant('{variant}');"
        f"s = mi.load_file(r'{scene}', spp={spp}, res={res}, max_depth={depth});"
        "t0 = time.perf_counter();"
        f"img = mi.render(s, spp={spp});"
        "b = mi.Bitmap(img);"
        "print('render', time.perf_counter() - t0);"
        f"b.write(r'{out}')"
    )
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    total = time.perf_counter() - t0
    render = next((float(l.split()[1]) for l in p.stdout.splitlines() if l.startswith("render ")), float("nan"))
    return total, render


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default=DEFAULT_SCENE)
    ap.add_argument("--ref", default=DEFAULT_REF)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--depth", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variants", default="scalar_rgb,llvm_ad_rgb")
    ap.add_argument("--svetlo", default=os.path.join(ROOT, "target", "release", "svetlo"))
    a = ap.parse_args()
    if not os.path.exists(a.scene):
        sys.exit(f"scene not found: {a.scene} (the shared scenes folder must sit beside the repository)")
    ref = read_exr(a.ref)
    tmp = tempfile.mkdtemp(prefix="svetlo-bench-")
    runners = [("svetlo", lambda o: run_svetlo(a.svetlo, a.scene, a.spp, a.res, a.depth, o))]
    for v in a.variants.split(","):
        runners.append((f"mitsuba {v}", lambda o, v=v: run_mitsuba(v, a.scene, a.spp, a.res, a.depth, o)))
    times = {name: [] for name, _ in runners}
    renders = {name: [] for name, _ in runners}
    errs = {}
    for rep in range(a.repeats):
        for name, fn in runners:  # alternate renderers so that machine load hits all alike
            out = os.path.join(tmp, f"{name.replace(' ', '_')}_{rep}.exr")
            total, render = fn(out)
            times[name].append(total)
            renders[name].append(render)
            errs[name] = errors(read_exr(out), ref) if ref.shape == read_exr(out).shape else (float("nan"), float("nan"))
    base = min(times["svetlo"])
    rbase = min(renders["svetlo"])
    print(f"scene {os.path.basename(a.scene)}  {a.res}x{a.res}  spp {a.spp}  max_depth {a.depth}  repeats {a.repeats}")
    print("time: the whole process as a user runs it (best of the repeats); render: the render call alone")
    print(f"{'renderer':<22}{'time (s)':>10}{'time / svetlo':>15}{'render (s)':>12}{'render / svetlo':>17}{'RMSE':>10}{'relMSE':>12}")
    for name, _ in runners:
        t = min(times[name])
        r = min(renders[name])
        rmse, rel = errs[name]
        print(f"{name:<22}{t:>10.3f}{t / base:>15.2f}{r:>12.3f}{r / rbase:>17.2f}{rmse:>10.5f}{rel:>12.3e}")


if __name__ == "__main__":
    main()
