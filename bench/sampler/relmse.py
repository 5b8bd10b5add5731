#!/usr/bin/env python3
"""Samplers against each other on Mitsuba's Cornell box: relMSE * spp against the reference.

For each sampler and spp, renders cbox-rgb (256x256, max_depth 6, box filter, path tracer) and
prints relMSE * spp (relMSE = mean over pixel channels of (img - ref)^2 / (ref^2 + 0.01), the
measure of bench/mitsuba) twice: raw, and with the reference's own noise taken out (its
per-sample variance / 4096, from the _var image, divided the same way). Under independent
sampling relMSE * spp is flat; a low-discrepancy sampler should make it fall with spp.

With --cost, also measures each sampler's CPU time per sample (one render thread, whole
process, median of alternating runs) relative to the first sampler.

Usage (from the repository root, after `cargo build --release`):

    python3 bench/sampler/relmse.py [--samplers independent,sobol] [--spp 4,16,64,256,1024]
                                    [--seeds 1] [--cost 64] [--repeats 5] [--svetlo BINARY]
"""
import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "scenes")
CBOX = os.path.join(SHARED, "mitsuba-data", "scenes", "cbox")
SCENE = os.path.join(CBOX, "cbox-rgb.xml")
REF = os.path.join(CBOX, "refs", "cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")
REF_VAR = os.path.join(CBOX, "refs", "cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp_var.exr")
REF_SPP = 4096


def read_exr(path):
    import mitsuba as mi
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False), dtype=np.float64)


def render(binary, sampler, spp, seed, out, threads, extra=()):
    """CPU seconds (user + sys) of the whole process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([binary, "render", SCENE, "-o", out, "--spp", str(spp), "--sampler", sampler, "--seed", str(seed),
                    "--threads", str(threads), "--max-depth", "6", "--filter", "box", *extra],
                   check=True, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samplers", default="independent,sobol")
    ap.add_argument("--spp", default="4,16,64,256,1024")
    ap.add_argument("--seeds", type=int, default=1, help="renders per (sampler, spp), averaged")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--cost", type=int, default=0, help="spp of the cost runs (0: no cost runs)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--extra", default="", help="more CLI arguments, e.g. '--integrator path:simd=false'")
    ap.add_argument("--svetlo", default=os.path.join(ROOT, "target", "release", "svetlo"))
    a = ap.parse_args()
    if not os.path.exists(SCENE):
        sys.exit(f"scene not found: {SCENE} (the shared scenes folder must sit beside the repository)")
    samplers = a.samplers.split(",")
    spps = [int(s) for s in a.spp.split(",") if s]
    extra = a.extra.split()
    ref = read_exr(REF)
    w = 1.0 / (ref * ref + 0.01)
    ref_noise = float(np.mean(read_exr(REF_VAR) / REF_SPP * w))
    tmp = tempfile.mkdtemp(prefix="svetlo-sampler-")
    print(f"cbox-rgb 256x256, max_depth 6, box filter; reference {os.path.basename(REF)}")
    print(f"reference noise (its own relMSE): {ref_noise:.3e}; 'corr' columns subtract it")
    if spps:
        head = "".join(f"{s:>9} spp" for s in spps)
        print(f"relMSE * spp{'':<13}{head}")
        for sampler in samplers:
            raw, corr = [], []
            for spp in spps:
                rel = []
                for seed in range(a.seeds):
                    out = os.path.join(tmp, f"{sampler}_{spp}_{seed}.exr")
                    render(a.svetlo, sampler, spp, seed, out, a.threads, extra)
                    d = read_exr(out) - ref
                    rel.append(float(np.mean(d * d * w)))
                m = statistics.mean(rel)
                raw.append(m * spp)
                corr.append((m - ref_noise) * spp)
            print(f"{sampler:<16}{'raw':<9}" + "".join(f"{v:>13.4f}" for v in raw), flush=True)
            print(f"{sampler:<16}{'corr':<9}" + "".join(f"{v:>13.4f}" for v in corr), flush=True)
    if a.cost:
        times = {s: [] for s in samplers}
        for _ in range(a.repeats):
            for s in samplers:  # alternating, so that machine load hits all alike
                times[s].append(render(a.svetlo, s, a.cost, 0, os.path.join(tmp, "cost.exr"), 1, extra))
        base = statistics.median(times[samplers[0]])
        print(f"CPU time per sample, one thread, {a.cost} spp, median of {a.repeats} alternating runs:")
        for s in samplers:
            m = statistics.median(times[s])
            print(f"{s:<16}{m:>9.3f} s{m / base:>9.3f} x {samplers[0]}")


if __name__ == "__main__":
    main()
