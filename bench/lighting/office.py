#!/usr/bin/env python3
"""The office of issue #14: 10 x 8 x 3 m, 12 luminaires, a 0.25 m grid at 0.8 m; svetlo's three
illuminance estimators against Radiance's rtrace -I, and UGR for two observers.

The room: ceiling 0.7, walls 0.5, floor 0.2 (Lambertian grey). The luminaire:
../shared/photometry/ies/radiance_examp1.ies (Radiance's own two-lamp fluorescent example,
5297 lm integrated), 4 x 3 pendants with their length along x, 0.6 m under the ceiling (the file is a
direct/indirect luminaire: about half its flux goes up; hung 5 cm under the ceiling, the light
bounces between Radiance's luminaire box and the ceiling, which svetlo's bodiless emitter lacks); svetlo
reads the IES file (<emitter type="ies">, ies2rad's frame), Radiance gets it through ies2rad.

For each estimator the table gives Emin, Eavg, Emax, U0 = Emin/Eavg, the largest relative
standard error over the grid, the CPU seconds (all threads) of the run, and the CPU seconds to a
1 % standard error at EVERY grid point, extrapolated from the run by error ~ 1/sqrt(cost)
(radiosity has a discretisation bound instead, so only its time). Radiance's error is from
`--copies` independent estimates per point in one rtrace run (-u+, no ambient cache). It also
checks each svetlo estimator point by point against Radiance: |difference| < 4 sigma + 2 %
(exit 1 if not), and prints the Markdown table for README.

Needs: pip install pyradiance (it ships the Radiance binaries), a built svetlo
(cargo build --release -p svetlo-cli).
Usage: bench/lighting/office.py [--svetlo target/release/svetlo] [--spp 256] [--photons 2000]
       [--ad 128] [--copies 4] [--radiosity element-size=0.5] [--spread]
"""
import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
IES = ROOT.parent / "shared" / "photometry" / "ies" / "radiance_examp1.ies"
L, W, H, Z_PLANE, SPACING = 10.0, 8.0, 3.0, 0.8, 0.25
Z_LUM = H - 0.6  # direct/indirect pendants (the file has uplight): 0.6 m suspensions
LUMINAIRES = [(1.25 + 2.5 * i, 4.0 / 3.0 + 8.0 / 3.0 * j - 0.0, Z_LUM) for i in range(4) for j in range(3)]
# Faces as (name, reflectance, corner, edge a, edge b) with a x b pointing into the room.
FACES = [
    ("floor", 0.2, (0, 0, 0), (L, 0, 0), (0, W, 0)),
    ("ceiling", 0.7, (0, 0, H), (0, W, 0), (L, 0, 0)),
    ("wall_s", 0.5, (0, 0, 0), (0, 0, H), (L, 0, 0)),
    ("wall_n", 0.5, (0, W, 0), (L, 0, 0), (0, 0, H)),
    ("wall_w", 0.5, (0, 0, 0), (0, W, 0), (0, 0, H)),
    ("wall_e", 0.5, (L, 0, 0), (0, 0, H), (0, W, 0)),
]
# Observers (CIE 117 practice: seated eye height 1.2 m, looking along the room's long axis and
# across it, from the middle of a wall).
OBSERVERS = [((0.5, W / 2, 1.2), (1, 0, 0)), ((L / 2, 0.5, 1.2), (0, 1, 0))]


def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def radiance_env():
    import pyradiance

    base = Path(pyradiance.__file__).parent
    return dict(os.environ, RAYPATH=f".:{base / 'lib'}", PATH=f"{base / 'bin'}:{os.environ['PATH']}")


def add(a, b, s=1.0):
    return tuple(x + s * y for x, y in zip(a, b))


def points():
    nu, nv = round(L / SPACING), round(W / SPACING)
    return [((i + 0.5) * SPACING, (j + 0.5) * SPACING, Z_PLANE) for i in range(nu) for j in range(nv)]


def svetlo_scene(spread, faces=None):
    faces = FACES if faces is None else faces
    out = ['<scene version="3.0.0">',
           '<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>']
    for x, y, z in LUMINAIRES:
        sp = '<boolean name="spread" value="true"/>' if spread else ""
        out.append(f'<emitter type="ies"><string name="filename" value="{IES}"/>{sp}<transform name="to_world"><translate value="{x},{y},{z}"/></transform></emitter>')
    for name, rho, c, a, b in faces:
        # Mitsuba's rectangle spans [-1, 1]^2 with normal +z: columns a/2, b/2, a x b, centre.
        n = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
        ln = sum(v * v for v in n) ** 0.5
        n = tuple(v / ln for v in n)
        ctr = add(add(c, a, 0.5), b, 0.5)
        m = [a[0] / 2, b[0] / 2, n[0], ctr[0], a[1] / 2, b[1] / 2, n[1], ctr[1], a[2] / 2, b[2] / 2, n[2], ctr[2], 0, 0, 0, 1]
        out.append(f'<shape type="rectangle" id="{name}"><bsdf type="diffuse"><rgb name="reflectance" value="{rho}"/></bsdf>'
                   f'<transform name="to_world"><matrix value="{" ".join(str(v) for v in m)}"/></transform></shape>')
    out.append("</scene>")
    return "\n".join(out) + "\n"


def radiance_scene(faces=None):
    faces = FACES if faces is None else faces
    out = []
    for name, rho, c, a, b in faces:
        out.append(f"void plastic m_{name} 0 0 5 {rho} {rho} {rho} 0 0")
        vs = [c, add(c, a), add(add(c, a), b), add(c, b)]
        out.append(f"m_{name} polygon {name} 0 0 12 " + " ".join(f"{v[0]} {v[1]} {v[2]}" for v in vs))
    for x, y, z in LUMINAIRES:
        out.append(f"!xform -t {x} {y} {z} lum.rad")
    return "\n".join(out) + "\n"


def stats(lux, se):
    n = len(lux)
    eavg = sum(lux) / n
    return min(lux), eavg, max(lux), min(lux) / eavg, max(s / max(v, 1e-12) for s, v in zip(se, lux))


def subset(stride):
    """Indices of the grid points Radiance evaluates: every `stride`-th in each direction."""
    nu, nv = round(L / SPACING), round(W / SPACING)
    o = stride // 2
    return [i * nv + j for i in range(o, nu, stride) for j in range(o, nv, stride)]


def run_radiance(d, ad, copies, idx, bodies):
    env = radiance_env()
    (d / "lum.ies").write_bytes(IES.read_bytes())
    subprocess.run(["ies2rad", "-dm", "-c", "1", "1", "1", "-t", "default", "-o", "lum", "lum.ies"], cwd=d, env=env, check=True)
    if not bodies:
        # ies2rad's luminaire is a black box of `light`: it absorbs interreflected light and
        # hides the ceiling above it. svetlo's emitter has no body; Radiance's `illum` (a
        # source that every other ray passes through) models the same room.
        rad = (d / "lum.rad").read_text()
        new = re.sub(r"^'lum_dist' light 'lum_light'$", "'lum_dist' illum 'lum_light'", rad, flags=re.M)
        assert new != rad, "ies2rad's output changed: no light material to turn into illum"
        (d / "lum.rad").write_text(new)
    (d / "office.rad").write_text(radiance_scene())
    with open(d / "office.oct", "wb") as f:
        subprocess.run(["oconv", "office.rad"], cwd=d, env=env, check=True, stdout=f)
    pts = [points()[k] for k in idx]
    inp = "".join(f"{x} {y} {z} 0 0 1\n" for _ in range(copies) for x, y, z in pts)
    cpu0 = child_cpu()
    out = subprocess.run(
        ["rtrace", "-h", "-I", "-u+", "-aa", "0", "-ab", "8", "-ad", str(ad), "-as", "0", "-lw", "1e-4", "-dj", "0", "office.oct"],
        cwd=d, env=env, check=True, input=inp, capture_output=True, text=True,
    ).stdout.split()
    cpu = child_cpu() - cpu0
    v = [179.0 * (0.265 * float(out[3 * k]) + 0.670 * float(out[3 * k + 1]) + 0.065 * float(out[3 * k + 2])) for k in range(len(out) // 3)]
    n = len(pts)
    mean = [sum(v[c * n + p] for c in range(copies)) / copies for p in range(n)]
    se = [(sum((v[c * n + p] - mean[p]) ** 2 for c in range(copies)) / (copies - 1) / copies) ** 0.5 for p in range(n)]
    return mean, se, cpu


def run_svetlo(d, exe, integrator, spp, radiosity):
    plane = f"origin=0,0,{Z_PLANE} u={L},0,0 v=0,{W},0"
    cmd = [exe, "illuminance", str(d / "office.xml"), "--plane", plane, "--spacing", str(SPACING), "--integrator", integrator, "--spp", str(spp), "-o", str(d / f"grid_{integrator}")]
    if integrator == "radiosity":
        cmd += ["--radiosity", radiosity]
    cpu0 = child_cpu()
    subprocess.run(cmd, check=True, capture_output=True)
    cpu = child_cpu() - cpu0
    g = json.loads((d / f"grid_{integrator}.json").read_text())
    return g["lux"], g["std_err"], cpu


def run_glare(d, exe):
    res = []
    for eye, direction in OBSERVERS:
        out = subprocess.run([exe, "glare", str(d / "office.xml"), "--eye", ",".join(map(str, eye)), "--dir", ",".join(map(str, direction))],
                             check=True, capture_output=True, text=True).stdout
        ugr = next((ln for ln in out.splitlines() if "UGR" in ln), out.strip().splitlines()[0] if out.strip() else "")
        res.append((eye, direction, ugr.strip()))
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--svetlo", default=str(ROOT / "target" / "release" / "svetlo"))
    ap.add_argument("--spp", type=int, default=256, help="gathering samples per point")
    ap.add_argument("--photons", type=int, default=2000, help="light tracing photons per grid point")
    ap.add_argument("--ad", type=int, default=128)
    ap.add_argument("--copies", type=int, default=4)
    ap.add_argument("--stride", type=int, default=4, help="Radiance evaluates every STRIDE-th grid point each way (its -aa 0 gathering costs ~0.1 s per point per estimate here)")
    ap.add_argument("--radiosity", default="element-size=0.5")
    ap.add_argument("--radiance-bodies", action="store_true", help="keep ies2rad's luminaires as black boxes (light) instead of illum")
    ap.add_argument("--spread", action="store_true", help="svetlo emits over the luminous opening (Radiance always does)")
    a = ap.parse_args()
    if not IES.exists():
        print(f"{IES} is missing (../shared/photometry)", file=sys.stderr)
        return 2
    rows, bad = [], []
    with tempfile.TemporaryDirectory() as t:
        d = Path(t)
        (d / "office.xml").write_text(svetlo_scene(a.spread))
        idx = subset(a.stride)
        rm, rse, rcpu = run_radiance(d, a.ad, a.copies, idx, a.radiance_bodies)
        r_stats = stats(rm, rse)
        # Cost to 1 % at every point of the full grid: each point's own (se/0.01)^2 scaling of
        # the CPU per point, summed over the subset and scaled up to the grid.
        per_point = rcpu / len(idx)
        r_to1 = sum(per_point * (s / m / 0.01) ** 2 for s, m in zip(rse, rm)) * len(points()) / len(idx)
        rows.append((f"Radiance rtrace -I (-ab 8 -ad {a.ad}, {a.copies} copies, {len(idx)} points)", r_stats, rcpu * len(points()) / len(idx), r_to1, None))
        for integ, spp in (("path", a.spp), ("light", a.photons), ("radiosity", 1)):
            full, full_se, scpu = run_svetlo(d, a.svetlo, integ, spp, a.radiosity)
            s_stats = stats(full, full_se)
            sm, sse = [full[k] for k in idx], [full_se[k] for k in idx]
            worst, worst_k = 0.0, 0
            for k in range(len(rm)):
                mc_se = sse[k] if integ != "radiosity" else 0.0
                bound = sse[k] if integ == "radiosity" else 0.0
                tol = 4.0 * (rse[k] ** 2 + mc_se ** 2) ** 0.5 + bound + 0.02 * rm[k]
                q = abs(sm[k] - rm[k]) / tol
                if q > worst:
                    worst, worst_k = q, k
            if worst >= 1.0:
                bad.append(integ)
            to1 = scpu * (s_stats[4] / 0.01) ** 2 if integ != "radiosity" else None
            label = {"path": f"svetlo gathering ({spp} spp)", "light": f"svetlo light tracing ({spp} photons/point)", "radiosity": f"svetlo radiosity ({a.radiosity})"}[integ]
            rows.append((label, s_stats, scpu, to1, (worst, worst_k, sm[worst_k], rm[worst_k], sum(sm) / len(sm) / (sum(rm) / len(rm)))))
        glare = run_glare(d, a.svetlo)
    pts = points()
    body = "black boxes (light)" if a.radiance_bodies else "bodiless (illum)"
    print(f"office {L} x {W} x {H} m, 12 x {IES.name}{' (spread)' if a.spread else ''}, {len(pts)} points (0.25 m grid at 0.8 m); Radiance's luminaires {body}\n")
    print(f"Radiance evaluates {len(idx)} of the points (every {a.stride}th each way); its CPU column is scaled to the full grid; the Eavg ratio compares those points.\n")
    print("| estimator | Emin | Eavg | Emax | U0 | worst rel. s.e. | CPU s | CPU s to 1 % at every point | Eavg / Radiance | worst point vs Radiance (of 4σ + 2 %) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for label, (emin, eavg, emax, u0, wr), cpu, to1, cmp in rows:
        to1s = f"{to1:.0f}" if to1 is not None else "— (mesh bound)"
        cs = f"{cmp[4]:.4f} | {cmp[0]:.2f} ({cmp[2]:.1f} vs {cmp[3]:.1f} lx)" if cmp else "1 | —"
        print(f"| {label} | {emin:.1f} lx | {eavg:.1f} lx | {emax:.1f} lx | {u0:.3f} | {100 * wr:.2f} % | {cpu:.1f} | {to1s} | {cs} |")
    r1 = rows[0][3]
    print("\nCPU to 1 % at every point, svetlo / Radiance: " + ", ".join(f"{lab.split(' (')[0]} {to1 / r1:.2f}" for lab, _, _, to1, _ in rows[1:] if to1 is not None))
    print("\nUGR (svetlo glare, CIE 117 tabular):")
    for eye, direction, ugr in glare:
        print(f"  eye {eye} dir {direction}: {ugr}")
    if bad:
        print(f"\nFAILED against Radiance: {', '.join(bad)}", file=sys.stderr)
        print("(expected with ies2rad's box luminaires: Radiance's ambient rays see ~11 % less of the ceiling's light than its own direct calculation;"
              " bench/lighting/office_diagnose.py measures it, README 'Lighting design' explains)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
