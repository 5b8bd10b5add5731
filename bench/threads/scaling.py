#!/usr/bin/env python3
"""Thread scaling: one render thread against N, alternating runs, medians.

For each method on Mitsuba's cbox-rgb (256x256, box filter, depth 6) renders with `--threads 1`
and `--threads N` in turn and prints, from the CLI's own `time` (wall) and `cpu` lines of the
render call:

  wall speed-up   wall(1) / wall(N): the goal is >= 1.9 for N = 2 on a quiet machine
  CPU ratio       cpu(N) / cpu(1): > 1 when threads cost each other (spinning, shared caches)
  utilisation     cpu(N) / (N wall(N)): < 1 when workers wait (barriers, serial merges)

The images of the two runs are compared with `cmp`: the pass tree makes them equal bit for bit.
These machines are shared: run it with nothing else busy, and read the utilisation, which
noise from other processes lowers less than it changes the speed-up.

Usage (from the repository root, after `cargo build --release`):

    python3 bench/threads/scaling.py [--threads 2] [--repeats 5] [--methods path,bdpt,light]
                                     [--spp 64] [--svetlo BINARY]
"""
import argparse
import filecmp
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(os.path.dirname(ROOT), "shared", "scenes", "mitsuba-data", "scenes", "cbox", "cbox-rgb.xml")
# Samples per pixel of each method for renders of a few seconds on one thread.
SPP = {"path": 64, "bdpt": 16, "light": 32, "sppm": 16, "pssmlt": 16}


def render(binary, method, spp, threads, out):
    """(wall, cpu) seconds of the render call, as the CLI reports them."""
    cmd = [binary, "render", SCENE, "-o", out, "--spp", str(spp), "--threads", str(threads), "--integrator", method,
           "-D", "res=256", "--width", "256", "--height", "256", "--filter", "box", "--max-depth", "6"]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{p.stdout}{p.stderr}")
    vals = {}
    for line in (p.stdout + p.stderr).splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0] in ("time", "cpu"):
            vals[parts[0]] = float(parts[1])
    return vals["time"], vals["cpu"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--methods", default="path,bdpt,light")
    ap.add_argument("--spp", type=int, default=0, help="override every method's spp")
    ap.add_argument("--svetlo", default=os.path.join(ROOT, "target", "release", "svetlo"))
    a = ap.parse_args()
    if not os.path.exists(SCENE):
        sys.exit(f"needs Mitsuba's cbox-rgb at {SCENE} (../shared beside the repository)")
    n = a.threads
    print(f"cbox-rgb 256x256, 1 against {n} threads, {a.repeats} alternating runs, medians of the render call")
    print(f"{'method':<8}{'spp':>5}{'wall speed-up':>15}{'CPU ratio':>11}{'utilisation':>13}{'same bits':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        for method in a.methods.split(","):
            spp = a.spp or SPP.get(method, 16)
            one, many = [], []
            for _ in range(a.repeats):
                one.append(render(a.svetlo, method, spp, 1, os.path.join(tmp, "one.exr")))
                many.append(render(a.svetlo, method, spp, n, os.path.join(tmp, "many.exr")))
            w1 = statistics.median(w for w, _ in one)
            c1 = statistics.median(c for _, c in one)
            wn = statistics.median(w for w, _ in many)
            cn = statistics.median(c for _, c in many)
            util = statistics.median(c / (n * w) for w, c in many)
            same = filecmp.cmp(os.path.join(tmp, "one.exr"), os.path.join(tmp, "many.exr"), shallow=False)
            print(f"{method:<8}{spp:>5}{w1 / wn:>15.2f}{cn / c1:>11.2f}{util:>13.3f}{'yes' if same else 'NO':>11}")


if __name__ == "__main__":
    main()
