#!/usr/bin/env python3
"""svetlo against Mitsuba 3 on several scenes, one render thread each, CPU time.

For every scene: both renderers in fresh processes, alternating, pinned to one core
(`taskset -c 0`). Mitsuba 3.9.1 deadlocks on one pinned core when its pools have one
worker (loading a bitmap, writing an EXR, shutting down), so its pool gets two workers
that share the core (the CPU time is still one core's) and the pixels go out via numpy;
prints the median ratio svetlo / Mitsuba of
 - the render call's CPU time (svetlo's `cpu` line; Mitsuba's process_time around mi.render),
 - the whole process's CPU time (load + build + render + write, from wait4),
and each renderer's relMSE at equal spp against the scene's reference. CPU time of one
thread is what stays comparable on a busy machine; quote the ratios, not the seconds.

    python3 bench/mitsuba/compare.py [--repeats 3] [--only NAME,...] [--variant scalar_rgb] [--spp N --res N]
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "scenes", "mitsuba-data")
CBOX = os.path.join(DATA, "scenes", "cbox")
SPHERES = os.path.join(DATA, "tests", "scenes", "bsdf_spheres")
SPOT = os.path.join(DATA, "tests", "scenes", "spot_light")

# name, scene, reference, svetlo integrator, Mitsuba integrator (None: the scene's),
# spp, resolution (None: the scene's), max depth (None: the scene's)
SCENES = [
    ("cbox path", f"{CBOX}/cbox-rgb.xml", f"{CBOX}/refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr", "path", None, 64, 256, 6),
    ("cbox light/ptracer", f"{CBOX}/cbox-rgb.xml", f"{CBOX}/refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr", "light", "ptracer", 16, 256, 6),
    ("spheres arealight", f"{SPHERES}/test_arealight_path.xml", f"{SPHERES}/refs/test_arealight_ref_rgb.exr", "path", None, 128, None, None),
    ("spheres envmap", f"{SPHERES}/test_envmap_path.xml", f"{SPHERES}/refs/test_envmap_ref_rgb.exr", "path", None, 128, None, None),
    ("spot_light direct", f"{SPOT}/test_spot_direct.xml", f"{SPOT}/refs/test_spot_ref_rgb.exr", "direct", None, 32, None, None),
]


def read_exr(path):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False), dtype=np.float64)


def rel_mse(img, ref):
    if img.shape != ref.shape:
        return float("nan")
    d = img - ref
    return float(np.mean(d * d / (ref * ref + 0.01)))


def run(cmd, env=None):
    """(stdout, CPU seconds of the whole process and its children)."""
    p = subprocess.Popen(["taskset", "-c", "0"] + cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    out = p.stdout.read()
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{out}")
    return out, ru.ru_utime + ru.ru_stime


def line_value(out, key):
    return next((float(l.split()[1]) for l in out.splitlines() if l.startswith(key + " ")), float("nan"))


def svetlo(binary, sc, out):
    name, scene, _, integ, _, spp, res, depth = sc
    cmd = [binary, "render", scene, "-o", out, "--spp", str(spp), "--threads", "1", "--integrator", integ]
    if res:
        cmd += ["-D", f"res={res}", "--width", str(res), "--height", str(res), "--filter", "box"]
    if depth:
        cmd += ["--max-depth", str(depth)]
    text, whole = run(cmd)
    return line_value(text, "cpu"), whole


def mitsuba(variant, sc, out):
    name, scene, _, _, minteg, spp, res, depth = sc
    kw = [f"spp={spp}"] + ([f"res={res}"] if res else []) + ([f"max_depth={depth}"] if depth else [])
    integ = f"mi.load_dict({{'type': '{minteg}', 'max_depth': {depth or -1}}})" if minteg else "None"
    code = (
        "import drjit as dr, mitsuba as mi, time;"
        f"mi.set_variant('{variant}');"
        "dr.set_thread_count(2);"
        f"s = mi.load_file(r'{scene}', {', '.join(kw)});"
        f"integ = {integ};"
        "t0 = time.process_time();"
        f"img = mi.render(s, spp={spp}) if integ is None else mi.render(s, integrator=integ, spp={spp});"
        # Dr.Jit evaluates lazily: the render is only done once its pixels are evaluated.
        "dr.eval(img); dr.sync_thread();"
        "print('cpu', time.process_time() - t0, flush=True);"
        # Bitmap.write (OpenEXR's thread pool) and Dr.Jit's shutdown deadlock on one
        # pinned core in 3.9.1: save the pixels with numpy and leave without the teardown.
        f"import numpy, os; numpy.save(r'{out}', numpy.array(img)); os._exit(0)"
    )
    text, whole = run([sys.executable, "-c", code])
    return line_value(text, "cpu"), whole


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", default="", help="comma-separated scene names (prefixes)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--spp", type=int, default=0, help="override every scene's spp (quick runs)")
    ap.add_argument("--res", type=int, default=0, help="override every scene's resolution (quick runs)")
    ap.add_argument("--svetlo", default=os.path.join(ROOT, "target", "release", "svetlo"))
    a = ap.parse_args()
    scenes = [s for s in SCENES if not a.only or any(s[0].startswith(o) for o in a.only.split(","))]
    scenes = [s[:5] + (a.spp or s[5], a.res or s[6], s[7]) for s in scenes]
    tmp = tempfile.mkdtemp(prefix="svetlo-bench-")
    print(f"Mitsuba {a.variant}, one thread each, {a.repeats} alternating runs, medians of CPU time")
    print(f"{'scene':<22}{'spp':>5}{'render CPU ratio':>18}{'process CPU ratio':>19}{'relMSE svetlo':>15}{'relMSE Mitsuba':>16}")
    for sc in scenes:
        if not os.path.exists(sc[1]):
            print(f"{sc[0]:<22} (scene missing: {sc[1]})")
            continue
        ref = read_exr(sc[2])
        r_s, w_s, r_m, w_m = [], [], [], []
        for rep in range(a.repeats):
            out_s, out_m = os.path.join(tmp, f"s{rep}.exr"), os.path.join(tmp, f"m{rep}.npy")
            r, w = svetlo(a.svetlo, sc, out_s)
            r_s.append(r), w_s.append(w)
            r, w = mitsuba(a.variant, sc, out_m)
            r_m.append(r), w_m.append(w)
        e_s, e_m = rel_mse(read_exr(out_s), ref), rel_mse(np.load(out_m).astype(np.float64)[..., :3], ref)
        med = statistics.median
        print(f"{sc[0]:<22}{sc[5]:>5}{med(r_s) / med(r_m):>18.2f}{med(w_s) / med(w_m):>19.2f}{e_s:>15.3e}{e_m:>16.3e}")


if __name__ == "__main__":
    main()
