#!/usr/bin/env python3
"""Equal-time error of path, bdpt, pssmlt and mlt on the project's scenes where light is hard
to find: scenes/door.xml (a room lit through a door left ajar), scenes/caustic.xml and
scenes/indirect-room.xml.

Every method renders for the same wall time (`--time T`, bootstrap included for the
Metropolis methods); relMSE = mean over pixels and channels of (x - r)^2 / (r^2 + 0.01)
(`svetlo compare`) against a long bdpt reference (`--ref-time` seconds, cached under
target/bench-mlt/). The Metropolis methods print their acceptance rates per mutation.
Usage (repository root):

    python3 bench/mlt/compare.py [--time 10] [--ref-time 200] [--scenes door,caustic,indirect-room]

Timing on a shared machine is noisy: compare the errors within one run.
"""
import argparse
import os
import re
import subprocess
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
METHODS = ["path", "bdpt", "pssmlt:bootstrap=20000", "mlt:bootstrap=20000"]


def render(binary, scene, out, extra):
    t0 = time.perf_counter()
    r = subprocess.run([binary, "render", scene, "-o", out] + extra, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    spp = next((int(l.split()[1]) for l in r.stdout.splitlines() if l.startswith("spp")), 0)
    secs = next((float(l.split()[1]) for l in r.stdout.splitlines() if l.startswith("time")), wall)
    return spp, secs, r.stderr


def relmse(binary, img, ref):
    r = subprocess.run([binary, "compare", img, ref], check=True, capture_output=True, text=True)
    m = re.search(r"relMSE\s+([0-9.eE+-]+)", r.stdout)
    return float(m.group(1))


def acceptance(report):
    rates = []
    for line in report.splitlines():
        m = re.match(r"^(\S+(?: step)?)\s+(\d+)\s+([0-9.]+) %", line)
        if m:
            rates.append(f"{m.group(1)} {m.group(3)} %")
    return ", ".join(rates)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--time", type=float, default=10.0)
    ap.add_argument("--ref-time", type=float, default=200.0)
    ap.add_argument("--scenes", default="door,caustic,indirect-room")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    binary = os.path.join(ROOT, "target/release/svetlo")
    work = os.path.join(ROOT, "target/bench-mlt")
    os.makedirs(work, exist_ok=True)
    print(f"| scene | method | mutations or spp per pixel | time (s) | relMSE | path's relMSE / this | acceptance |")
    print("|---|---|---:|---:|---:|---:|---|")
    for name in a.scenes.split(","):
        scene = os.path.join(ROOT, "scenes", f"{name}.xml")
        ref = os.path.join(work, f"{name}_ref_bdpt_{int(a.ref_time)}s.exr")
        if not os.path.exists(ref):
            render(binary, scene, ref, ["--integrator", "bdpt", "--time", str(a.ref_time), "--seed", "12345"])
        errs = {}
        for m in METHODS:
            out = os.path.join(work, f"{name}_{m.split(':')[0]}.exr")
            spp, secs, report = render(binary, scene, out, ["--integrator", m, "--time", str(a.time), "--seed", str(a.seed)])
            e = relmse(binary, out, ref)
            errs[m] = (e, secs)
            ratio = errs["path"][0] / e
            print(f"| {name} | {m} | {spp} | {secs:.1f} | {e:.3e} | {ratio:.2f} | {acceptance(report)} |", flush=True)
        # The reference's own error, by bdpt's error scaled with the time ratio.
        floor = errs["bdpt"][0] * errs["bdpt"][1] / a.ref_time
        print(f"| {name} | (reference floor, est.) | | {a.ref_time:.0f} | {floor:.1e} | | |", flush=True)


if __name__ == "__main__":
    main()
