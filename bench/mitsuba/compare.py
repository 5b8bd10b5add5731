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

    python3 bench/mitsuba/compare.py [--repeats 3] [--only NAME,...] [--more] [--variant scalar_rgb] [--spp N --res N] [--threads N] [--mitsuba-avx2]

`--threads N` gives both N render threads on cores 0..N-1 (CPU ratios then compare the work,
the wall ratio the scaling). The scenes: Mitsuba's cbox-rgb (path; light against ptracer),
Bitterli's cornell-box and veach-mis (their Mitsuba 3 versions, Tungsten's references
box-downsampled), `bsdf_spheres` (area light, environment map, a bitmap-textured diffuse
sphere), `spot_light` (direct), and a generated 1M-triangle displaced sphere on a floor
(written once to bench/out/mesh1m/; no reference: its relMSE columns are empty); with
`--more`, Mitsuba's other thirteen bsdf_spheres scenes too.
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DATA = os.path.join(os.path.dirname(ROOT), "shared", "scenes", "mitsuba-data")
CBOX = os.path.join(DATA, "scenes", "cbox")
SPHERES = os.path.join(DATA, "tests", "scenes", "bsdf_spheres")
SPOT = os.path.join(DATA, "tests", "scenes", "spot_light")

BITTERLI = os.path.join(os.path.dirname(ROOT), "shared", "scenes", "bitterli")
MESH1M = os.path.join(ROOT, "bench", "out", "mesh1m")

# name, scene, reference (None: no reference), svetlo integrator, Mitsuba integrator (None:
# the scene's), spp, resolution (None: the scene's), max depth (None: the scene's), and
# further defines for both (the scene's own `<default>` parameters)
SCENES = [
    ("cbox path", f"{CBOX}/cbox-rgb.xml", f"{CBOX}/refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr", "path", None, 64, 256, 6, {}),
    ("cbox light/ptracer", f"{CBOX}/cbox-rgb.xml", f"{CBOX}/refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr", "light", "ptracer", 16, 256, 6, {}),
    ("bitterli cbox", f"{BITTERLI}/cornell-box/mitsuba3/scene_v3.xml", f"{BITTERLI}/cornell-box/TungstenRender_box4x4_256x256.pfm", "path", None, 64, None, None, {"resx": 256, "resy": 256}),
    ("veach-mis depth 2", f"{BITTERLI}/veach-mis/mitsuba3/scene.xml", None, "path", None, 64, None, None, {"resx": 256, "resy": 144, "max_depth": 2}),
    ("veach-mis", f"{BITTERLI}/veach-mis/mitsuba3/scene.xml", f"{BITTERLI}/veach-mis/TungstenRender_box5x5_256x144.pfm", "path", None, 64, None, None, {"resx": 256, "resy": 144}),
    ("spheres arealight", f"{SPHERES}/test_arealight_path.xml", f"{SPHERES}/refs/test_arealight_ref_rgb.exr", "path", None, 128, None, None, {}),
    ("spheres envmap", f"{SPHERES}/test_envmap_path.xml", f"{SPHERES}/refs/test_envmap_ref_rgb.exr", "path", None, 128, None, None, {}),
    ("spheres textured", f"{SPHERES}/test_textured_diffuse_path.xml", f"{SPHERES}/refs/test_textured_diffuse_ref_rgb.exr", "path", None, 128, None, None, {}),
    ("spot_light direct", f"{SPOT}/test_spot_direct.xml", f"{SPOT}/refs/test_spot_ref_rgb.exr", "direct", None, 32, None, None, {}),
    ("mesh 1M", f"{MESH1M}/scene.xml", None, "path", None, 64, None, None, {}),
]

# `--more`: Mitsuba's other bsdf_spheres scenes (glass, metals, plastics, principled, surface
# detail, point and constant lights), each at 128 spp, to show the speed on every BSDF family
# the kernel and the scalar tracer read, not only on the table's scenes.
MORE_SPHERES = [
    "bumpmap", "constant", "normalmap", "normalmap_identity_roughconductor", "normalmap_roughconductor", "pointlight",
    "roughdielectric", "roughplastic_linear", "roughplastic_nonlinear", "textured_roughconductor",
    "texturedprincipled1", "texturedprincipled2", "texturedprincipledthin",
]
MORE = [(f"spheres {n}", f"{SPHERES}/test_{n}_path.xml", f"{SPHERES}/refs/test_{n}_ref_rgb.exr", "path", None, 128, None, None, {}) for n in MORE_SPHERES]


def displacement(p):
    """Smooth bumps on the unit sphere (as crates/svetlo/examples/raycast_bench.rs)."""
    h = np.zeros(len(p), dtype=np.float32)
    f, a = 3.0, 0.12
    for o in range(5):
        s = o * 1.7
        h += a * np.sin(f * p[:, 0] + s) * np.sin(f * 1.3 * p[:, 1] + 2 * s) * np.cos(f * 0.9 * p[:, 2] + 0.5 * s)
        f, a = f * 2.3, a * 0.5
    return h


def write_mesh1m(n=289):
    """A cube sphere of 6 n^2 quads (12 n^2 = 1,002,252 triangles at n = 289), displaced,
    as binary PLY, on a floor under a rectangular light: the scene both renderers read."""
    scene = os.path.join(MESH1M, "scene.xml")
    if os.path.exists(scene):
        return
    os.makedirs(MESH1M, exist_ok=True)
    pos, tris = [], []
    faces = [((1, 0, 0), (0, 1, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)), ((0, 1, 0), (0, 0, 1), (1, 0, 0)),
             ((0, -1, 0), (1, 0, 0), (0, 0, 1)), ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (0, 1, 0), (1, 0, 0))]
    t = np.linspace(-1.0, 1.0, n + 1, dtype=np.float32)
    s_, t_ = np.meshgrid(t, t, indexing="ij")
    for k, (nrm, u, v) in enumerate(faces):
        p = np.array(nrm, np.float32) + s_.reshape(-1, 1) * np.array(u, np.float32) + t_.reshape(-1, 1) * np.array(v, np.float32)
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        pos.append(p * (1 + displacement(p))[:, None])
        base = k * (n + 1) ** 2
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        a = base + i * (n + 1) + j
        b, c, d = a + (n + 1), a + (n + 1) + 1, a + 1
        tris.append(np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], -2).reshape(-1, 3))
    pos, tris = np.concatenate(pos).astype("<f4"), np.concatenate(tris).astype("<u4")
    with open(os.path.join(MESH1M, "planet.ply"), "wb") as f:
        f.write(f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pos)}\nproperty float x\nproperty float y\nproperty float z\n"
                f"element face {len(tris)}\nproperty list uchar uint vertex_indices\nend_header\n".encode())
        rec = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<u4", 3)])
        rec["n"], rec["i"] = 3, tris
        f.write(pos.tobytes())
        f.write(rec.tobytes())
    with open(scene, "w") as f:
        f.write("""<scene version="3.0.0">
    <default name="spp" value="64"/>
    <integrator type="path"><integer name="max_depth" value="6"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, -5, 1.2" target="0, 0, -0.2" up="0, 0, 1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="256"/><integer name="height" value="256"/><rfilter type="box"/></film>
    </sensor>
    <shape type="ply"><string name="filename" value="planet.ply"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="6"/><translate z="-1.3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="1.2"/><rotate x="1" angle="180"/><translate x="1" y="-1" z="3.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="12, 12, 12"/></emitter></shape>
</scene>
""")


def read_exr(path):
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False), dtype=np.float64)


def rel_mse(img, ref):
    if img.shape != ref.shape:
        return float("nan")
    d = img - ref
    return float(np.mean(d * d / (ref * ref + 0.01)))


THREADS = 1


def run(cmd, env=None):
    """(stdout, CPU seconds of the whole process and its children, wall seconds)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(["taskset", "-c", f"0-{THREADS - 1}"] + cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    out = p.stdout.read()
    _, status, ru = os.wait4(p.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{out}")
    return out, ru.ru_utime + ru.ru_stime, time.perf_counter() - t0


def line_value(out, key):
    return next((float(l.split()[1]) for l in out.splitlines() if l.startswith(key + " ")), float("nan"))


def svetlo(binary, sc, out):
    name, scene, _, integ, _, spp, res, depth, defines = sc
    cmd = [binary, "render", scene, "-o", out, "--spp", str(spp), "--threads", str(THREADS), "--integrator", integ]
    if res:
        cmd += ["-D", f"res={res}", "--width", str(res), "--height", str(res), "--filter", "box"]
    if depth:
        cmd += ["--max-depth", str(depth)]
    for k, v in defines.items():
        cmd += ["-D", f"{k}={v}"]
    text, whole, wall = run(cmd)
    return line_value(text, "cpu"), whole, line_value(text, "time")


def mitsuba(variant, sc, out):
    name, scene, _, _, minteg, spp, res, depth, defines = sc
    kw = [f"spp={spp}"] + ([f"res={res}"] if res else []) + ([f"max_depth={depth}"] if depth else []) + [f"{k}={v}" for k, v in defines.items()]
    integ = f"mi.load_dict({{'type': '{minteg}', 'max_depth': {depth or -1}}})" if minteg else "None"
    code = (
        "import drjit as dr, mitsuba as mi, time;"
        f"mi.set_variant('{variant}');"
        + (AVX2_CODE if MITSUBA_AVX2 else "")
        +         f"dr.set_thread_count({max(THREADS, 2)});"
        f"s = mi.load_file(r'{scene}', {', '.join(kw)});"
        f"integ = {integ};"
        "t0, w0 = time.process_time(), time.perf_counter();"
        f"img = mi.render(s, spp={spp}) if integ is None else mi.render(s, integrator=integ, spp={spp});"
        # Dr.Jit evaluates lazily: the render is only done once its pixels are evaluated.
        "dr.eval(img); dr.sync_thread();"
        "print('cpu', time.process_time() - t0, flush=True); print('time', time.perf_counter() - w0, flush=True);"
        # Bitmap.write (OpenEXR's thread pool) and Dr.Jit's shutdown deadlock on one
        # pinned core in 3.9.1: save the pixels with numpy and leave without the teardown.
        f"import numpy, os; numpy.save(r'{out}', numpy.array(img)); os._exit(0)"
    )
    text, whole, wall = run([sys.executable, "-c", code])
    return line_value(text, "cpu"), whole, line_value(text, "time")


# `--mitsuba-avx2`: Dr.Jit's LLVM backend told to compile eight-wide AVX2 kernels (no AVX-512),
# as it does on a CPU without AVX-512, through its C entry point `jit_llvm_set_target` (not
# part of its Python API: a diagnostic, to tell what AVX-512 gives Mitsuba on this CPU).
AVX2_CODE = (
    "import ctypes, os;"
    "_core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), 'libdrjit-core.so'));"
    "_set = _core._Z19jit_llvm_set_targetPKcS0_j; _set.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32];"
    "_set(b'znver3', b'+avx,+avx2,+fma,+f16c,+sse4.2,+popcnt,+bmi,+bmi2,+lzcnt,+movbe,-avx512f,-avx512vl,-avx512dq,-avx512bw', 8);"
    "_width = _core._Z21jit_llvm_vector_widthv; _width.restype = ctypes.c_uint32;"
    "assert _width() == 8, 'Dr.Jit did not take the target';"
)
MITSUBA_AVX2 = False


def main():
    global THREADS, MITSUBA_AVX2
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", default="", help="comma-separated scene names (prefixes)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--spp", type=int, default=0, help="override every scene's spp (quick runs)")
    ap.add_argument("--res", type=int, default=0, help="override every scene's resolution (quick runs)")
    ap.add_argument("--threads", type=int, default=1, help="render threads of each renderer (cores 0..N-1)")
    ap.add_argument("--svetlo", default=os.path.join(ROOT, "target", "release", "svetlo"))
    ap.add_argument("--more", action="store_true", help="add Mitsuba's other bsdf_spheres scenes (every BSDF family)")
    ap.add_argument("--mitsuba-avx2", action="store_true", help="Mitsuba's LLVM kernels as on an AVX2-only CPU (eight-wide, no AVX-512; a diagnostic)")
    a = ap.parse_args()
    THREADS = max(1, a.threads)
    MITSUBA_AVX2 = a.mitsuba_avx2
    scenes = [s for s in SCENES + (MORE if a.more else []) if not a.only or any(s[0].startswith(o) for o in a.only.split(","))]
    scenes = [s[:5] + (a.spp or s[5], a.res or s[6], s[7], s[8]) for s in scenes]
    if any(s[0] == "mesh 1M" for s in scenes):
        write_mesh1m()
    tmp = tempfile.mkdtemp(prefix="svetlo-bench-")
    lanes = ", forced to AVX2 (eight lanes)" if MITSUBA_AVX2 else ""
    print(f"Mitsuba {a.variant}{lanes}, {THREADS} thread(s) each, {a.repeats} alternating runs, medians")
    print(f"{'scene':<22}{'spp':>5}{'render CPU ratio':>18}{'render wall ratio':>19}{'process CPU ratio':>19}{'relMSE svetlo':>15}{'relMSE Mitsuba':>16}")
    for sc in scenes:
        if not os.path.exists(sc[1]):
            print(f"{sc[0]:<22} (scene missing: {sc[1]})")
            continue
        ref = read_exr(sc[2]) if sc[2] and os.path.exists(sc[2]) else None
        r_s, w_s, t_s, r_m, w_m, t_m = [], [], [], [], [], []
        for rep in range(a.repeats):
            out_s, out_m = os.path.join(tmp, f"s{rep}.exr"), os.path.join(tmp, f"m{rep}.npy")
            r, w, t = svetlo(a.svetlo, sc, out_s)
            r_s.append(r), w_s.append(w), t_s.append(t)
            r, w, t = mitsuba(a.variant, sc, out_m)
            r_m.append(r), w_m.append(w), t_m.append(t)
        if ref is not None:
            e_s, e_m = f"{rel_mse(read_exr(out_s), ref):.3e}", f"{rel_mse(np.load(out_m).astype(np.float64)[..., :3], ref):.3e}"
        else:
            e_s = e_m = "-"
        med = statistics.median
        print(f"{sc[0]:<22}{sc[5]:>5}{med(r_s) / med(r_m):>18.2f}{med(t_s) / med(t_m):>19.2f}{med(w_s) / med(w_m):>19.2f}{e_s:>15}{e_m:>16}", flush=True)


if __name__ == "__main__":
    main()
