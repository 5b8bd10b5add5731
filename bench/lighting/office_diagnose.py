#!/usr/bin/env python3
"""Where svetlo and Radiance part in the office of bench/lighting/office.py: one bounce off the
ceiling, with every other surface black, so that the interreflected light on the work plane is a
plain integral of the ceiling's direct illuminance.

For each form of ies2rad's luminaire (its box of six emitting faces, the box without its bottom
face, the top face alone) the table gives, as means over the same work-plane points:
  - Radiance's one-bounce light: rtrace -I -ab 1 (-aa 0, -ad 2048) minus -ab 0;
  - the same light computed from Radiance's own direct illuminance of the ceiling (rtrace -I -ab 0
    on a 5 cm grid facing down) by the integral E(p) = sum rho/pi E_c(x) cos cos / r^2 dA;
  - for the whole box, svetlo's gathering (the same room minus the black room), and the ceiling's
    direct flux of both renderers.
If Radiance's ambient calculation agreed with its own direct light, the first two columns would
agree; the bench prints their ratio. (Measured: they agree for the top face alone and for the box
without its bottom face, and part by about 12 % for the full box, with 1 or 12 luminaires; svetlo
agrees with the integral. See README, "Lighting design".)

Needs pyradiance and a built svetlo, as office.py. Usage: bench/lighting/office_diagnose.py
[--svetlo target/release/svetlo] [--luminaires 12] [--spp 256]
"""
import argparse
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import office  # noqa: E402

RHO_CEILING = 0.7
STEP = 0.05  # the ceiling grid of the integral, m
VARIANTS = [("box (ies2rad)", ""), ("box without bottom face", "d"), ("top face only", "d1234")]


def ceiling_only():
    return [(name, RHO_CEILING if name == "ceiling" else 0.0, *rest) for name, _, *rest in office.FACES]


def luminaire_rad(d, drop):
    """ies2rad's luminaire as `illum` (bodiless, as svetlo's emitter), without the faces `drop`
    names (ies2rad calls them lum.d, lum.u, lum.1 ... lum.4)."""
    env = office.radiance_env()
    (d / "lum.ies").write_bytes(office.IES.read_bytes())
    subprocess.run(["ies2rad", "-dm", "-c", "1", "1", "1", "-t", "default", "-o", "lum", "lum.ies"], cwd=d, env=env, check=True)
    rad = (d / "lum.rad").read_text()
    rad = re.sub(r"^'lum_dist' light 'lum_light'$", "'lum_dist' illum 'lum_light'", rad, flags=re.M)
    for face in drop:
        rad, n = re.subn(r"'lum_light' polygon 'lum\." + face + r"'\n0\n0\n12(\n\t[^\n]*){4}\n", "", rad)
        assert n == 1, f"ies2rad's output has no face lum.{face}"
    (d / "lum.rad").write_text(rad)


def rtrace(d, lines, args):
    env = office.radiance_env()
    out = subprocess.run(["rtrace", "-h", "-I", "-dj", "0", *args, "office.oct"], cwd=d, env=env, check=True,
                         input="".join(lines), capture_output=True, text=True).stdout.split()
    rgb = np.array(out, float).reshape(-1, 3)
    return 179.0 * (rgb @ np.array([0.265, 0.670, 0.065]))


def radiance_variant(drop, pts):
    with tempfile.TemporaryDirectory() as t:
        d = Path(t)
        luminaire_rad(d, drop)
        (d / "office.rad").write_text(office.radiance_scene(ceiling_only()))
        with open(d / "office.oct", "wb") as f:
            subprocess.run(["oconv", "office.rad"], cwd=d, env=office.radiance_env(), check=True, stdout=f)
        plane = [f"{x} {y} {z} 0 0 1\n" for x, y, z in pts]
        ambient = rtrace(d, plane, ["-ab", "1", "-aa", "0", "-ad", "2048", "-as", "0", "-lw", "1e-6"]) - rtrace(d, plane, ["-ab", "0"])
        xs, ys = np.arange(STEP / 2, office.L, STEP), np.arange(STEP / 2, office.W, STEP)
        cx, cy = (a.ravel() for a in np.meshgrid(xs, ys, indexing="ij"))
        ec = rtrace(d, [f"{x} {y} {office.H - 1e-3} 0 0 -1\n" for x, y in zip(cx, cy)], ["-ab", "0", "-ds", "0.01"])
    dz = office.H - office.Z_PLANE
    integral = [float((ec * RHO_CEILING / math.pi * dz * dz / ((cx - px) ** 2 + (cy - py) ** 2 + dz * dz) ** 2).sum()) * STEP * STEP for px, py, _ in pts]
    return float(np.mean(ambient)), float(np.mean(integral)), float(ec.sum()) * STEP * STEP


def svetlo_one_bounce(exe, idx, spp):
    means = []
    for faces in (ceiling_only(), [(n, 0.0, *r) for n, _, *r in office.FACES]):
        with tempfile.TemporaryDirectory() as t:
            d = Path(t)
            (d / "office.xml").write_text(office.svetlo_scene(False, faces))
            lux, _, _ = office.run_svetlo(d, exe, "path", spp, "")
            means.append(sum(lux[k] for k in idx) / len(idx))
    return means[0] - means[1]


def svetlo_ceiling_flux(exe, spp):
    with tempfile.TemporaryDirectory() as t:
        d = Path(t)
        (d / "office.xml").write_text(office.svetlo_scene(False, [(n, 0.0, *r) for n, _, *r in office.FACES]))
        plane = f"origin=0,0,{office.H - 1e-3} u=0,{office.W},0 v={office.L},0,0"  # u x v = -z: facing down
        subprocess.run([exe, "illuminance", str(d / "office.xml"), "--plane", plane, "--spacing", "0.1", "--spp", str(spp), "-o", str(d / "c")], check=True, capture_output=True)
        import json

        return sum(json.loads((d / "c.json").read_text())["lux"]) * 0.01


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--svetlo", default=str(office.ROOT / "target" / "release" / "svetlo"))
    ap.add_argument("--luminaires", type=int, default=12)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--stride", type=int, default=8)
    a = ap.parse_args()
    if not office.IES.exists():
        print(f"{office.IES} is missing (../shared/photometry)", file=sys.stderr)
        return 2
    office.LUMINAIRES = office.LUMINAIRES[: a.luminaires]
    idx = office.subset(a.stride)
    pts = [office.points()[k] for k in idx]
    print(f"one bounce off the ceiling (rho {RHO_CEILING}, all else black), {a.luminaires} x {office.IES.name}, {len(pts)} work-plane points\n")
    print("| Radiance's luminaire | Radiance -ab 1 | integral of Radiance's direct ceiling E | ratio | ceiling flux (Radiance) |")
    print("|---|---|---|---|---|")
    for label, drop in VARIANTS:
        amb, integral, flux = radiance_variant(drop, pts)
        print(f"| {label} | {amb:.2f} lx | {integral:.2f} lx | {amb / integral:.4f} | {flux:.0f} lm |")
    sv = svetlo_one_bounce(a.svetlo, idx, a.spp)
    print(f"\nsvetlo gathering ({a.spp} spp), same points: {sv:.2f} lx; svetlo's ceiling flux {svetlo_ceiling_flux(a.svetlo, 16):.0f} lm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
