"""The Python render against the CLI, and the properties of the binding itself: no copy, the
GIL released, Ctrl-C, memory, errors."""

import gc
import os
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

import svetlo

# Each method with options that keep it to a fraction of a second at 24x24.
METHODS = [
    ("path", {}),
    ("path", {"simd": False}),
    ("light", {}),
    ("bdpt", {}),
    ("direct", {}),
    ("whitted", {}),
    ("distributed", {}),
    ("zbuffer", {}),
    ("radiosity", {"element_size": 0.5}),
    ("photon", {"photons": 20000}),
    ("sppm", {"photons": 5000}),
    ("pssmlt", {}),
    ("mlt", {}),
]


def cli_spec(name, options):
    if not options:
        return name
    return name + ":" + ",".join(f"{k.replace('_', '-')}={str(v).lower() if isinstance(v, bool) else v}" for k, v in options.items())


@pytest.mark.parametrize("name,options", METHODS, ids=[cli_spec(n, o) for n, o in METHODS])
def test_equals_cli_bit_for_bit(cli, cbox_path, tmp_path, name, options):
    out = tmp_path / "cli.exr"
    args = [str(cli), "render", str(cbox_path), "-o", str(out), "--spp", "4", "--seed", "3", "--max-depth", "5",
            "--width", "24", "--height", "20", "--integrator", cli_spec(name, options), "--threads", "2", "-D", "res=32"]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    scene = svetlo.load_file(cbox_path, res=32)
    img = svetlo.render(scene, integrator=name, options=options, spp=4, seed=3, max_depth=5, width=24, height=20, threads=1, progress=False)
    ref = svetlo.read(out)
    assert img.shape == ref.shape == (20, 24, 3)
    assert img.dtype == np.float32
    assert np.array_equal(img, ref), f"{name}: max difference {np.max(np.abs(img - ref))}"
    assert img.mean() > 0


def test_scene_defaults_and_filter_sampler_match_cli(cli, cbox_path, tmp_path):
    out = tmp_path / "cli.exr"
    r = subprocess.run([str(cli), "render", str(cbox_path), "-o", str(out), "-D", "spp=3", "-D", "res=16", "--filter", "tent", "--sampler", "sobol", "--seed", "9"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    img = svetlo.render(svetlo.load_file(cbox_path, spp=3, res=16), filter="tent", sampler="sobol", seed=9, progress=False)
    assert np.array_equal(img, svetlo.read(out))


def test_ray_epsilon_equals_cli_bit_for_bit(cli, cbox_path, tmp_path):
    out = tmp_path / "cli.exr"
    args = [str(cli), "render", str(cbox_path), "-o", str(out), "--spp", "2", "--seed", "4", "-D", "res=24", "--ray-epsilon", "0.05", "--threads", "2"]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    scene = svetlo.load_file(cbox_path, res=24)
    img = svetlo.render(scene, spp=2, seed=4, ray_epsilon=0.05, progress=False)
    assert np.array_equal(img, svetlo.read(out))
    # The epsilon changes the image (hits near each origin are skipped, in corners and at
    # the light) and one larger than the scene skips every hit; the scene itself keeps 0.
    plain = svetlo.render(scene, spp=2, seed=4, progress=False)
    assert not np.array_equal(img, plain)
    assert np.array_equal(svetlo.render(scene, spp=2, seed=4, ray_epsilon=0, progress=False), plain)
    assert svetlo.render(scene, spp=1, ray_epsilon=1e6, progress=False).max() == 0
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(svetlo.OptionError, match="ray_epsilon"):
            svetlo.render(scene, spp=1, ray_epsilon=bad, progress=False)
    with pytest.raises(TypeError, match="ray_epsilon"):
        svetlo.render(scene, spp=1, ray_epsilon="5e-4", progress=False)


def test_array_is_not_a_copy(cbox_path):
    scene = svetlo.load_file(cbox_path, res=16, spp=1)
    res = svetlo.render_result(scene, progress=False)
    img = res.image
    assert img.shape == (16, 16, 3) and img.dtype == np.float32 and img.flags.c_contiguous
    # The array does not own its data: its base is the object holding the Rust buffer.
    assert not img.flags.owndata
    assert img.base is not None and not isinstance(img.base, np.ndarray)
    img[0, 0, 0] = 42.0  # writable, and it is the same memory the next view sees
    assert np.asarray(img)[0, 0, 0] == 42.0


def test_gil_released_during_render(cbox_path):
    scene = svetlo.load_file(cbox_path, res=32)
    count = 0
    stop = threading.Event()

    def counter():
        nonlocal count
        while not stop.is_set():
            count += 1

    t = threading.Thread(target=counter)
    t.start()
    try:
        time.sleep(0.05)
        before = count
        res = svetlo.render_result(scene, spp=10_000_000, time=0.6, threads=1, progress=False)
        during = count - before
    finally:
        stop.set()
        t.join()
    assert res.seconds >= 0.5
    # A thread that holds the GIL for the whole render would leave the counter at about zero;
    # a pure-Python loop counts millions per second.
    assert during > 100_000, during


def test_ctrl_c_interrupts_with_partial_image(cbox_path):
    scene = svetlo.load_file(cbox_path, res=32)
    sent = []

    def progress(done, total, seconds):
        if done > 0 and not sent:
            sent.append(seconds)
            os.kill(os.getpid(), signal.SIGINT)

    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt) as info:
        svetlo.render(scene, spp=100_000, progress=progress, threads=1)
    assert time.monotonic() - t0 < 30
    e = info.value
    assert isinstance(e, svetlo.RenderInterrupted)
    assert e.result.interrupted and 1 <= e.result.spp < 100_000
    assert e.image.shape == (32, 32, 3) and e.image.mean() > 0
    assert e.image is e.result.image


def test_progress_callback_and_its_errors(cbox_path):
    scene = svetlo.load_file(cbox_path, res=16)
    calls = []
    svetlo.render(scene, spp=20000, time=0.3, progress=lambda d, t, s: calls.append((d, t, s)), threads=1)
    # The render sets its total once it starts; done never decreases.
    assert calls and calls[-1][1] > 0 and calls[-1][0] > 0
    assert [d for d, _, _ in calls] == sorted(d for d, _, _ in calls)

    class Boom(Exception):
        pass

    def bad(d, t, s):
        raise Boom("from the callback")

    with pytest.raises(Boom):
        svetlo.render(scene, spp=100_000, progress=bad, threads=1)


def rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="needs /proc (Linux)")
def test_renders_in_a_loop_do_not_grow_memory(cbox_path):
    scene = svetlo.load_file(cbox_path, res=128, spp=1)
    for _ in range(10):
        svetlo.render(scene, progress=False, integrator="direct")
    gc.collect()
    before = rss_bytes()
    for _ in range(100):
        img = svetlo.render(scene, progress=False, integrator="direct")
        del img
    gc.collect()
    grown = rss_bytes() - before
    # Each render makes a 128x128 image and a variance image (2 x 196 KiB): a leak of either
    # would add 39 MiB over the loop.
    assert grown < 12 * 2**20, f"grew by {grown / 2**20:.1f} MiB"


def test_scene_freed_while_rendering(cbox_path):
    scene = svetlo.load_file(cbox_path, res=24)
    out = {}

    def work(s):
        out["img"] = svetlo.render(s, spp=10_000, time=0.5, progress=False, threads=1)

    t = threading.Thread(target=work, args=(scene,))
    t.start()
    time.sleep(0.1)
    del scene
    gc.collect()
    t.join()
    assert out["img"].shape == (24, 24, 3) and np.isfinite(out["img"]).all() and out["img"].mean() > 0


def test_time_limit_and_result(cbox_path):
    scene = svetlo.load_file(cbox_path, res=16)
    r = svetlo.render_result(scene, spp=10_000_000, time=0.3, progress=False)
    assert not r.interrupted and 1 <= r.spp < r.spp_planned and r.seconds < 10
    assert r.variance.shape == r.image.shape and (r.variance >= 0).all()
    assert r.aovs == {}


def test_bdpt_strategies_sum_to_the_image(cbox_path):
    scene = svetlo.load_file(cbox_path, res=16)
    r = svetlo.render_result(scene, integrator="bdpt", spp=4, max_depth=3, strategies=3, filter="box", progress=False)
    assert (1, 1) in r.strategies or (1, 2) in r.strategies
    total = sum(w for w, _ in r.strategies.values())
    np.testing.assert_allclose(total, r.image, rtol=1e-4, atol=1e-5)
    with pytest.raises(svetlo.OptionError, match="bdpt"):
        svetlo.render_result(scene, integrator="path", strategies=3, progress=False)


def test_bad_arguments(cbox_path):
    scene = svetlo.load_file(cbox_path, res=8)
    with pytest.raises(TypeError, match="spp"):
        svetlo.render(scene, spp="many")
    with pytest.raises(TypeError, match="Scene"):
        svetlo.render("scenes/cornell-box.xml")
    with pytest.raises(svetlo.OptionError, match="spp"):
        svetlo.render(scene, spp=0)
    with pytest.raises(svetlo.OptionError, match="seed"):
        svetlo.render(scene, seed=-1)
    with pytest.raises(svetlo.OptionError, match="time"):
        svetlo.render(scene, time=float("nan"))
    with pytest.raises(svetlo.OptionError, match="max_depth"):
        svetlo.render(scene, max_depth=-3)
    with pytest.raises(svetlo.OptionError, match="threads"):
        svetlo.render(scene, threads=5000)
    # A film over the memory budget is refused before anything is allocated.
    with pytest.raises(svetlo.SvetloError, match="memory"):
        svetlo.render(scene, width=65536, height=65536)
    with pytest.raises(svetlo.OptionError, match="filter"):
        svetlo.render(scene, filter="lanczos")
    with pytest.raises(svetlo.OptionError, match="unknown integrator 'nope'"):
        svetlo.render(scene, integrator="nope")
    # An unknown option key is named.
    with pytest.raises(svetlo.OptionError, match="flux-capacitor"):
        svetlo.render(scene, integrator="sppm", options={"flux_capacitor": 1})
    with pytest.raises(svetlo.OptionError, match="takes no options"):
        svetlo.render(scene, integrator="bdpt", options={"x": 1})
    with pytest.raises(svetlo.OptionError, match="alpha"):
        svetlo.render(scene, integrator="sppm", options={"alpha": float("nan")})
    with pytest.raises(TypeError, match="radius"):
        svetlo.render(scene, integrator="sppm", options={"radius": [1, 2]})
    with pytest.raises(TypeError, match="scene parameter 'spp'"):
        svetlo.load_file(cbox_path, spp=[1])
    assert issubclass(svetlo.OptionError, svetlo.SvetloError) and issubclass(svetlo.SceneError, svetlo.SvetloError)


def test_scene_errors_carry_file_and_line(tmp_path):
    p = tmp_path / "bad.xml"
    p.write_text('<scene version="3.0.0">\n  <shape type="sphere">\n    <float name="radius" value="big"/>\n  </shape>\n</scene>\n')
    with pytest.raises(svetlo.SceneError) as info:
        svetlo.load_file(p)
    e = info.value
    assert e.file == str(p) and e.line == 3 and e.column >= 1, (e.file, e.line, e.column)
    assert "radius" in str(e) and str(p) in str(e)
    with pytest.raises(svetlo.SceneError) as info:
        svetlo.load_file(tmp_path / "missing.xml")
    assert info.value.file == str(tmp_path / "missing.xml")
    with pytest.raises(svetlo.SceneError) as info:
        svetlo.load_string("<scene version='3.0.0'>\n<shape type='cube'>\n</scene>", origin="inline.xml")
    assert info.value.file == "inline.xml" and info.value.line is not None


def test_scene_info(cbox_path):
    scene = svetlo.load_file(cbox_path, res=40)
    info = scene.info()
    assert info["camera"]["type"] == "perspective" and (info["camera"]["width"], info["camera"]["height"]) == (40, 40)
    assert abs(info["camera"]["fov_x"] - 19.5) < 1e-4
    np.testing.assert_allclose(info["camera"]["position"], (0, 1, 6.8), atol=1e-5)
    assert len(info["shapes"]) == len(scene.shapes) > 5
    assert any(s["emitter"] is not None for s in info["shapes"])
    assert [e["type"] for e in info["emitters"]] == ["area"] and info["emitters"][0]["shape"] is not None
    assert "twosided(diffuse)" in info["materials"]
    (lo, hi) = info["bbox"]
    assert lo[1] <= 0.0 + 1e-5 and hi[1] >= 2.0 - 1e-5
    assert info["settings"]["integrator"] == "path" and info["settings"]["spp"] == 64
    assert scene.width == 40 and "cornell-box.xml" in repr(scene)
    assert [m[0] for m in svetlo.methods()][:3] == ["path", "light", "bdpt"]


def test_images_and_comparisons(tmp_path, cbox_path):
    scene = svetlo.load_file(cbox_path, res=16)
    r = svetlo.render_result(scene, spp=64, integrator="direct", filter="box", progress=False)
    for ext in ("exr", "pfm"):
        svetlo.write(tmp_path / f"a.{ext}", r.image)
        assert np.array_equal(svetlo.read(tmp_path / f"a.{ext}"), r.image)
    svetlo.write(tmp_path / "a.png", r.image)
    assert svetlo.read(tmp_path / "a.png").shape == (16, 16, 3)
    assert svetlo.relmse(r.image, r.image) == 0.0
    assert svetlo.relmse(r.image.astype(np.float64), 2 * r.image) > 0
    # A second render with another seed passes the Z-test against the first; a darkened one fails.
    other = svetlo.render(scene, spp=64, integrator="direct", filter="box", seed=1, progress=False)
    assert svetlo.ztest(other, r.image, r.variance, 64)
    t = svetlo.ztest(0.5 * other, r.image, r.variance, 64)
    assert not t and t.failed > 0
    bad = r.image.copy()
    bad[3, 5, 1] = np.nan
    with pytest.raises(svetlo.ImageError, match=r"x=5, y=3"):
        svetlo.relmse(bad, r.image)
    with pytest.raises(svetlo.ImageError, match="shape"):
        svetlo.write(tmp_path / "b.exr", np.zeros((4, 4)))
    with pytest.raises(svetlo.ImageError):
        svetlo.relmse(r.image, r.image[:8])
    with pytest.raises(svetlo.ImageError, match="unsupported"):
        svetlo.write(tmp_path / "b.tga", r.image)
    with pytest.raises(svetlo.ImageError):
        svetlo.read(tmp_path / "nothing.exr")


def test_radiosity_solution(cbox_path, tmp_path):
    scene = svetlo.load_file(cbox_path, res=16)
    sol = svetlo.radiosity(scene, solver="progressive", element_size=0.5)
    n = len(sol)
    assert n > 50 and sol.solver == "progressive"
    assert sol.b.shape == (n, 3) and sol.triangles.shape == (n, 3, 3) and sol.areas.shape == (n,)
    assert (sol.b >= 0).all() and (sol.b >= sol.emission - 1e-4).all()
    # B = E + rho * (gathered): above E only where the surface reflects.
    h = sol.history
    assert len(h["residual"]) >= 2 and h["residual"][-1] < h["residual"][0]
    assert sol.vertex_b.shape == sol.vertices.shape and sol.faces.max() < len(sol.vertices)
    np.testing.assert_allclose(sol.areas.sum(), 0.5 * np.linalg.norm(np.cross(sol.triangles[:, 1] - sol.triangles[:, 0], sol.triangles[:, 2] - sol.triangles[:, 0]), axis=1).sum(), rtol=1e-4)
    # The solution's image is the radiosity method's render with the same options.
    img = svetlo.render(scene, integrator="radiosity", options={"solver": "progressive", "element_size": 0.5}, spp=1, filter="box", seed=0, progress=False)
    assert np.array_equal(sol.image(spp=1), img)
    sol.write_ply(tmp_path / "s.ply")
    text = (tmp_path / "s.ply").read_text()
    assert f"element face {n}" in text
    with pytest.raises(svetlo.OptionError):
        svetlo.radiosity(scene, solver="magic")


# Light path expressions: AOVs from Python are the CLI's layers, bit for bit.
AOVS = {"seen": "C L", "direct": "C <R.> L", "indirect": "C . .+ L", "caustic": "C D S+ L"}


@pytest.mark.parametrize("name", ["path", "bdpt", "light"])
def test_aovs_equal_cli_layers(cli, cbox_path, tmp_path, name):
    out = tmp_path / "cli.exr"
    args = [str(cli), "render", str(cbox_path), "-o", str(out), "--spp", "4", "--seed", "5", "--max-depth", "5",
            "--integrator", name, "--threads", "2", "-D", "res=20"]
    for n, e in AOVS.items():
        args += ["--aov", f"{n}={e}"]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    beauty, layers = svetlo.read_layers(out)
    res = svetlo.render_result(svetlo.load_file(cbox_path, res=20), integrator=name, spp=4, seed=5, max_depth=5, threads=1, aovs=AOVS, progress=False)
    # The EXR keeps its channels sorted by name; the render keeps the order asked.
    assert list(res.aovs) == list(AOVS) and sorted(layers) == sorted(AOVS)
    assert np.array_equal(res.image, beauty)
    for n in AOVS:
        assert res.aovs[n].shape == (20, 20, 3) and res.aovs[n].dtype == np.float32
        assert np.array_equal(res.aovs[n], layers[n]), f"{name}: AOV {n} differs from the CLI's"
    # Seen, direct and indirect partition every path (no path is in two or in none).
    total = res.aovs["seen"] + res.aovs["direct"] + res.aovs["indirect"]
    assert np.allclose(total, res.image, rtol=1e-4, atol=1e-6), np.max(np.abs(total - res.image))
    assert res.aovs["direct"].mean() > 0 and res.aovs["indirect"].mean() > 0


def test_lpe_restricts_beauty_and_preset(cbox_path):
    scene = svetlo.load_file(cbox_path, res=16)
    kw = dict(integrator="path", spp=4, seed=2, max_depth=5, threads=1, progress=False)
    full = svetlo.render_result(scene, aov_preset="lecture", **kw)
    assert list(full.aovs) == ["local", "whitted", "cook", "radiosity", "rest"]
    direct_only = svetlo.render(scene, lpe="C <R.> L", **kw)
    with_direct = svetlo.render_result(scene, aovs={"d": "C <R.> L"}, **kw)
    # The restricted beauty is the AOV of the same expression, and less than the full image.
    assert np.array_equal(direct_only, with_direct.aovs["d"])
    assert direct_only.sum() < full.image.sum()
    # In a diffuse box the radiosity class (C D* L) is every path: its AOV is the beauty.
    assert np.allclose(full.aovs["radiosity"], full.image, rtol=1e-4, atol=1e-6)


def test_aov_errors(cbox_path):
    scene = svetlo.load_file(cbox_path, res=8)
    with pytest.raises(svetlo.OptionError, match="AOV 'bad'"):
        svetlo.render(scene, aovs={"bad": "C (D"}, spp=1, progress=False)
    with pytest.raises(svetlo.OptionError, match="preset"):
        svetlo.render(scene, aov_preset="nope", spp=1, progress=False)
    with pytest.raises(TypeError, match="aovs"):
        svetlo.render(scene, aovs=["C D L"], spp=1, progress=False)
