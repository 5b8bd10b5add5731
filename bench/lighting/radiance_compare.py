#!/usr/bin/env python3
"""svetlo's work-plane illuminance against Radiance's rtrace -I on the same room.

A 4 x 4 x 3 m room of grey Lambertian walls (reflectance 0.5), one luminaire from
../shared/photometry at the ceiling's centre (Radiance: ies2rad; svetlo: <emitter type="ies">,
both in ies2rad's frame), a 0.5 m grid at 0.8 m. Radiance runs without the ambient cache
(-aa 0: plain Monte Carlo gathering, -ab 8) several times with uncorrelated sampling (-u+),
which gives its standard error; svetlo runs `svetlo illuminance` with the estimator asked for.
Prints the grid's means, the largest |difference| over the combined error, and the CPU-time
ratio; exits 1 when a point differs by more than 4 combined standard errors + 2 %.

Needs: pip install pyradiance (it ships the Radiance binaries), a built svetlo.
Usage: bench/lighting/radiance_compare.py [--svetlo target/release/svetlo] [--ies rab_7.ies]
       [--integrator path|light|radiosity] [--spp 512] [--ad 1024] [--runs 4]
"""
import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "photometry" / "ies"
L, W, H, Z_LUM, Z_PLANE, SPACING, RHO = 4.0, 4.0, 3.0, 2.95, 0.8, 0.5, 0.5


def radiance_bin():
    import pyradiance  # noqa: F401  (its package directory holds bin/ and lib/)

    base = Path(pyradiance.__file__).parent
    return base / "bin", base / "lib"


def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def points():
    nu, nv = round(L / SPACING), round(W / SPACING)
    return [((i + 0.5) * SPACING, (j + 0.5) * SPACING, Z_PLANE) for i in range(nu) for j in range(nv)]


def run_radiance(d, ies, ad, runs):
    bindir, libdir = radiance_bin()
    env = dict(os.environ, RAYPATH=f".:{libdir}", PATH=f"{bindir}:{os.environ['PATH']}")
    shutil.copy(ies, d / "lum.ies")
    subprocess.run(["ies2rad", "-dm", "-c", "1", "1", "1", "-t", "default", "-o", "lum", "lum.ies"], cwd=d, env=env, check=True)
    (d / "room.rad").write_text(
        f"void plastic grey 0 0 5 {RHO} {RHO} {RHO} 0 0\n!genbox grey room {L} {W} {H} -i\n!xform -t {L / 2} {W / 2} {Z_LUM} lum.rad\n"
    )
    with open(d / "room.oct", "wb") as f:
        subprocess.run(["oconv", "room.rad"], cwd=d, env=env, check=True, stdout=f)
    inp = "".join(f"{x} {y} {z} 0 0 1\n" for x, y, z in points())
    grids, cpu0 = [], child_cpu()
    for _ in range(runs):
        out = subprocess.run(
            ["rtrace", "-h", "-I", "-u+", "-aa", "0", "-ab", "8", "-ad", str(ad), "-as", "0", "-lw", "1e-5", "-dj", "0", "room.oct"],
            cwd=d, env=env, check=True, input=inp, capture_output=True, text=True,
        ).stdout.split()
        rgb = [float(v) for v in out]
        grids.append([179.0 * (0.265 * rgb[3 * k] + 0.670 * rgb[3 * k + 1] + 0.065 * rgb[3 * k + 2]) for k in range(len(rgb) // 3)])
    cpu = child_cpu() - cpu0
    n = len(grids[0])
    mean = [sum(g[k] for g in grids) / runs for k in range(n)]
    se = [(sum((g[k] - mean[k]) ** 2 for g in grids) / (runs - 1) / runs) ** 0.5 for k in range(n)] if runs > 1 else [0.0] * n
    return mean, se, cpu


def run_svetlo(d, exe, ies, integrator, spp):
    xml = f"""<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <emitter type="ies"><string name="filename" value="{ies}"/><transform name="to_world"><translate value="{L / 2},{W / 2},{Z_LUM}"/></transform></emitter>
  <shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="{RHO}"/></bsdf><boolean name="flip_normals" value="true"/>
    <transform name="to_world"><scale x="{L / 2}" y="{W / 2}" z="{H / 2}"/><translate value="{L / 2},{W / 2},{H / 2}"/></transform></shape>
</scene>
"""
    (d / "room.xml").write_text(xml)
    plane = f"origin=0,0,{Z_PLANE} u={L},0,0 v=0,{W},0"
    cpu0 = child_cpu()
    subprocess.run([exe, "illuminance", str(d / "room.xml"), "--plane", plane, "--spacing", str(SPACING), "--integrator", integrator, "--spp", str(spp), "-o", str(d / "grid")], check=True, capture_output=True)
    cpu = child_cpu() - cpu0
    g = json.loads((d / "grid.json").read_text())
    return g["lux"], g["std_err"], cpu


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--svetlo", default=str(ROOT / "target" / "release" / "svetlo"))
    ap.add_argument("--ies", default="rab_7.ies")
    ap.add_argument("--integrator", default="path")
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--ad", type=int, default=1024)
    ap.add_argument("--runs", type=int, default=4)
    a = ap.parse_args()
    ies = SHARED / a.ies
    if not ies.exists():
        print(f"{ies} is missing (../shared/photometry)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as t:
        d = Path(t)
        rm, rse, rcpu = run_radiance(d, ies, a.ad, a.runs)
        sm, sse, scpu = run_svetlo(d, a.svetlo, ies, a.integrator, a.spp)
    worst, worst_k = 0.0, 0
    for k in range(len(rm)):
        tol = 4.0 * (rse[k] ** 2 + sse[k] ** 2) ** 0.5 + 0.02 * rm[k]
        r = abs(sm[k] - rm[k]) / tol
        if r > worst:
            worst, worst_k = r, k
    avg = lambda v: sum(v) / len(v)  # noqa: E731
    print(f"luminaire {a.ies}, {len(rm)} points, 0.5 m grid at 0.8 m in a 4 x 4 x 3 m room (rho {RHO})")
    print(f"Radiance rtrace -I (-ab 8 -ad {a.ad}, {a.runs} runs): Eavg {avg(rm):.2f} lx, Emin {min(rm):.2f}, Emax {max(rm):.2f}, mean rel. s.e. {100 * avg([s / m for s, m in zip(rse, rm)]):.2f} %, cpu {rcpu:.2f} s")
    print(f"svetlo {a.integrator} (spp {a.spp}): Eavg {avg(sm):.2f} lx, Emin {min(sm):.2f}, Emax {max(sm):.2f}, mean rel. s.e. {100 * avg([s / m for s, m in zip(sse, sm)]):.2f} %, cpu {scpu:.2f} s")
    print(f"Eavg ratio svetlo/Radiance {avg(sm) / avg(rm):.4f}; worst point {worst_k}: svetlo {sm[worst_k]:.2f} ± {sse[worst_k]:.2f}, Radiance {rm[worst_k]:.2f} ± {rse[worst_k]:.2f} ({worst:.2f} of the tolerance)")
    # Monte Carlo error falls as 1/sqrt(cost): CPU seconds to a 1 % mean relative standard error.
    rel = lambda se, m: avg([x / y for x, y in zip(se, m)])  # noqa: E731
    r1, s1 = rcpu * (rel(rse, rm) / 0.01) ** 2, scpu * (rel(sse, sm) / 0.01) ** 2
    print(f"cpu seconds to 1 % mean relative s.e.: Radiance {r1:.3f}, svetlo {s1:.3f} (ratio svetlo/Radiance {s1 / max(r1, 1e-12):.2f})")
    return 0 if worst < 1.0 else 1


if __name__ == "__main__":
    sys.exit(main())
