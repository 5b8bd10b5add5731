"""svetlo.distributed on a LocalCluster of 2 worker processes: the merged image is the local
render's bit for bit (every pass-separable method, chunk counts that do not divide the spp,
a worker killed mid-render), scenes shipped to workers that cannot read the client's files,
the scene cache, errors raised as the local ones, cancellation and partial images."""

import os
import pathlib
import shutil
import signal
import time

import numpy as np
import pytest

import svetlo

distributed = pytest.importorskip("distributed", reason="svetlo.distributed needs dask[distributed] (pip install 'dask[distributed]')")
import svetlo.distributed as sd  # noqa: E402

from conftest import SCENES  # noqa: E402

CBOX = SCENES / "cornell-box.xml"


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def local(path, **kw):
    return svetlo.render_result(svetlo.load_file(path), progress=False, **kw)


@pytest.mark.parametrize("integrator", ["path", "direct", "light", "bdpt", "whitted", "distributed"])
def test_bitwise_equal_to_the_local_render(client, integrator):
    # 13 spp on 32x24: thirteen passes of 1 sample (a render has at least 8 passes); 3
    # chunks do not divide them.
    kw = dict(integrator=integrator, spp=13, seed=5, width=32, height=24, max_depth=5)
    r = sd.render(CBOX, client=client, chunks=3, progress=False, result=True, **kw)
    ref = local(CBOX, **kw)
    assert r.spp == ref.spp == 13 and not r.interrupted
    assert ref.image.max() > 0
    assert np.array_equal(bits(r.image), bits(ref.image)), f"{integrator}: the merged image is not the local one"
    assert np.array_equal(bits(r.variance), bits(ref.variance)), f"{integrator}: variance"


def test_ray_epsilon_reaches_the_workers(client):
    kw = dict(integrator="path", spp=8, seed=2, width=24, height=16, ray_epsilon=0.05)
    r = sd.render(CBOX, client=client, chunks=3, progress=False, result=True, **kw)
    ref = local(CBOX, **kw)
    assert np.array_equal(bits(r.image), bits(ref.image))
    assert not np.array_equal(bits(ref.image), bits(local(CBOX, **{**kw, "ray_epsilon": 0}).image))


def test_chunks_are_joined_as_they_arrive_into_the_local_bits(client):
    # 8 spp: eight passes of 1 sample, so 8 chunks carry equal work. The client joins two
    # siblings of the pass tree as soon as both are in, whatever order they come in.
    kw = dict(integrator="bdpt", spp=8, seed=3, width=24, height=16)
    ref = local(CBOX, **kw)
    job = sd.submit(CBOX, client=client, chunks=8, **kw)
    assert [n[3] - n[2] for n in job.nodes] == [1] * 8, job.nodes
    held = []
    r = job.result(lambda done, total, secs: held.append(len(job._sums)))
    assert list(job._sums) == [(0, 8)], "every chunk joined into the root"
    assert max(held) <= 4, f"at most one part per level of the tree held: {held}"
    assert np.array_equal(bits(r.image), bits(ref.image)) and np.array_equal(bits(r.variance), bits(ref.variance))
    # The tree's families as the client walks them (passes::split in Rust).
    assert sd._family((0, 8), 11) == ((0, 11), (8, 11), True)
    assert sd._family((8, 10), 11) == ((8, 11), (10, 11), True)
    assert sd._family((10, 11), 11) == ((8, 11), (8, 10), False)
    with pytest.raises(svetlo.SvetloError):
        sd._family((1, 3), 11)


def test_any_chunk_count_gives_the_same_bits(client):
    kw = dict(integrator="path", spp=40, seed=2, width=20, height=16, filter="tent")
    ref = local(CBOX, **kw).image
    for chunks in (1, 2, 5, 64):
        img = sd.render(CBOX, client=client, chunks=chunks, progress=False, **kw)
        assert np.array_equal(bits(img), bits(ref)), f"{chunks} chunks"
    # Workers that share the client's file system read the path itself.
    assert np.array_equal(bits(sd.render(CBOX, client=client, chunks=3, ship=False, progress=False, **kw)), bits(ref))
    # Photon mapping: the photon paths traced once, by batches of path indices on the
    # workers, every chunk building the maps from all batches.
    kw = dict(integrator="photon", options={"photons": 2000, "caustic_photons": 500, "gather": 4}, spp=7, seed=1, width=16, height=12)
    ref = local(CBOX, **kw).image
    for batches in (1, 3):
        job = sd.submit(CBOX, client=client, chunks=3, photon_batches=batches, **kw)
        assert len(job.shared) == batches
        assert np.array_equal(bits(job.result().image), bits(ref)), f"photon, {batches} photon batches"


def write_asset_scene(d: pathlib.Path, colour: str = "0.2, 0.3, 0.8") -> pathlib.Path:
    """The Cornell box with a cube from an OBJ file, pulled in through an include in a subfolder."""
    (d / "parts").mkdir(parents=True)
    v = [(x, y, z) for x in (-0.3, 0.3) for y in (0.0, 0.6) for z in (-0.3, 0.3)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join(f"f {a} {b} {c}\nf {a} {c} {e}\n" for a, b, c, e in faces)
    (d / "parts" / "cube.obj").write_text(obj)
    (d / "parts" / "cube.xml").write_text(
        '<scene version="3.0.0"><shape type="obj"><string name="filename" value="cube.obj"/>'
        f'<bsdf type="diffuse"><rgb name="reflectance" value="{colour}"/></bsdf></shape></scene>'
    )
    text = CBOX.read_text().replace("</scene>", '<include filename="parts/cube.xml"/>\n</scene>')
    p = d / "scene.xml"
    p.write_text(text)
    return p


def test_assets_ship_to_workers_that_cannot_read_the_clients_files(client, tmp_path):
    p = write_asset_scene(tmp_path / "scene")
    kw = dict(integrator="bdpt", spp=6, seed=9, width=24, height=24)
    ref = local(p, **kw).image
    src = sd.scene_source(p)
    assert sorted(src.files) == ["parts/cube.obj", "parts/cube.xml", "scene.xml"]
    # The client's copy is gone before any worker looks: they render from what was shipped.
    shutil.rmtree(tmp_path / "scene")
    img = sd.render(src, client=client, chunks=3, progress=False, **kw)
    assert np.array_equal(bits(img), bits(ref))
    # Without shipping the path itself must be readable: gone, it fails as a local load does.
    with pytest.raises(svetlo.SvetloError):
        sd.render(p, client=client, ship=False, progress=False, **kw)


def test_workers_load_a_scene_once_and_key_it_by_content(client, tmp_path):
    # A scene no other test renders (the cache is keyed by content).
    p = write_asset_scene(tmp_path / "s", colour="0.7, 0.3, 0.1")
    before = client.run(sd.cache_stats)
    kw = dict(integrator="direct", spp=8, width=12, height=12)
    sd.render(p, client=client, chunks=6, progress=False, **kw)
    sd.render(p, client=client, chunks=6, progress=False, **kw)
    after = client.run(sd.cache_stats)
    loads = sum(after[w]["loads"] - before.get(w, {"loads": 0})["loads"] for w in after)
    assert 1 <= loads <= 2, f"each worker loads the scene at most once for 14 tasks, got {loads} loads"
    # New content under the same name is a new scene.
    key = sd.scene_source(p).key
    (tmp_path / "s" / "parts" / "cube.obj").write_text((tmp_path / "s" / "parts" / "cube.obj").read_text().replace("0.6", "0.9"))
    assert sd.scene_source(p).key != key
    moved = local(p, **kw).image
    assert np.array_equal(bits(sd.render(p, client=client, chunks=2, progress=False, **kw)), bits(moved))


def test_a_killed_worker_loses_nothing(client):
    kw = dict(integrator="path", options={"simd": False}, spp=96, seed=4, width=48, height=48)
    ref = local(CBOX, **kw).image
    job = sd.submit(CBOX, client=client, chunks=12, **kw)
    # Kill the process of a worker while it runs one of the render's tasks.
    killed = None
    deadline = time.time() + 60
    while killed is None and time.time() < deadline:
        for w, keys in client.processing().items():
            if any(str(k).startswith("svetlo-passes-") for k in keys):
                pid = client.run(os.getpid, workers=[w])[w]
                os.kill(pid, signal.SIGKILL)
                killed = w
                break
        time.sleep(0.02)
    assert killed is not None, "no task of the render was seen running"
    r = job.result()
    assert not r.interrupted and r.spp == 96
    assert np.array_equal(bits(r.image), bits(ref)), "the image after a worker died is not the local one"
    client.wait_for_workers(2, timeout=60)


def test_scene_errors_come_back_as_the_local_exception(client, tmp_path):
    p = tmp_path / "broken.xml"
    p.write_text(CBOX.read_text().replace('<bsdf type="diffuse" id="black">', '<bsdf type="diffuse" id="black"', 1))
    with pytest.raises(svetlo.SceneError) as here:
        svetlo.load_file(p)
    with pytest.raises(svetlo.SceneError) as there:
        sd.render(p, client=client, spp=2, progress=False)
    assert str(there.value) == str(here.value)
    assert (there.value.file, there.value.line, there.value.column) == (here.value.file, here.value.line, here.value.column)
    with pytest.raises(svetlo.OptionError, match="not a sum of independent"):
        sd.render(CBOX, client=client, integrator="zbuffer", spp=2, progress=False)
    with pytest.raises(svetlo.OptionError):
        sd.render(CBOX, client=client, spp=0, progress=False)


def test_cancel_keeps_the_chunks_done_and_partial_images(client):
    kw = dict(integrator="path", options={"simd": False}, spp=256, seed=1, width=32, height=32)
    job = sd.submit(CBOX, client=client, chunks=16, **kw)
    deadline = time.time() + 60
    while job.progress()[0] == 0 and time.time() < deadline:
        time.sleep(0.02)
    part = job.partial()
    assert part is not None and part.shape == (32, 32, 3) and np.isfinite(part).all() and part.max() > 0
    job.cancel()
    r = job.result()
    done, planned = job.progress()
    assert planned == 256 and 0 < r.spp == done
    if r.spp < 256:
        assert r.interrupted
    assert np.isfinite(r.image).all()


@pytest.mark.parametrize("integrator", ["pssmlt", "mlt"])
def test_metropolis_chains_share_one_bootstrap_and_equal_the_local_render(client, integrator):
    """Chains split in blocks of 16 over the workers, all from one bootstrap computed by one
    task: the local render with the same chain count, bit for bit, for any chunk count."""
    kw = dict(integrator=integrator, options={"chains": 40, "bootstrap": 2000}, spp=8, seed=3, width=16, height=12)
    ref = local(CBOX, **kw)
    assert ref.image.max() > 0
    nodes = {1: [(0, 3)], 2: [(0, 2), (2, 3)], 3: [(0, 1), (1, 2), (2, 3)]}
    for chunks in (1, 2, 3):
        job = sd.submit(CBOX, client=client, chunks=chunks, **kw)
        assert len(job.shared) == 1 and [n[:2] for n in job.nodes] == nodes[chunks]
        r = job.result()
        assert r.spp == ref.spp == 8 and not r.interrupted
        assert np.array_equal(bits(r.image), bits(ref.image)), f"{integrator}, {chunks} chunks"
        assert job.progress() == (8, 8)


def test_sppm_iterations_split_into_photon_batches_and_row_blocks(client):
    """SPPM: each iteration's photons traced by batches of path indices, blocks of rows
    advanced by one iteration from every batch; the local render bit for bit for any number
    of blocks and batches."""
    kw = dict(integrator="sppm", options={"photons": 1500}, spp=3, seed=4, width=14, height=11)
    ref = local(CBOX, **kw)
    assert ref.image.max() > 0
    seen = []
    for chunks, batches in ((1, 1), (3, 2), (11, 3)):
        job = sd.submit(CBOX, client=client, chunks=chunks, photon_batches=batches, **kw)
        assert isinstance(job, sd.SppmRender) and len(job.rows) == chunks
        r = job.result(lambda d, t, s: seen.append((d, t)))
        assert r.spp == 3 and not r.interrupted and job.progress() == (3, 3)
        assert np.array_equal(bits(r.image), bits(ref.image)), f"{chunks} row blocks, {batches} photon batches"
        assert np.array_equal(bits(job.partial()), bits(ref.image))
    assert seen and all(t == 3 and 0 <= d <= 3 for d, t in seen)
    # Fewer iterations: the image after them is the local render of that many.
    two = sd.render(CBOX, client=client, chunks=2, progress=False, **dict(kw, spp=2))
    assert np.array_equal(bits(two), bits(local(CBOX, **dict(kw, spp=2)).image))


def test_the_image_does_not_depend_on_the_number_of_workers(client):
    """One in-process worker against the two worker processes: the same bits."""
    kw_m = dict(integrator="pssmlt", options={"chains": 20, "bootstrap": 1000}, spp=4, seed=8, width=12, height=10)
    kw_s = dict(integrator="sppm", options={"photons": 800}, spp=2, seed=8, width=12, height=10)
    two = [sd.render(CBOX, client=client, progress=False, **kw) for kw in (kw_m, kw_s)]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, distributed.Client(cluster) as one:
        ones = [sd.render(CBOX, client=one, progress=False, **kw) for kw in (kw_m, kw_s)]
    for a, b in zip(two, ones):
        assert np.array_equal(bits(a), bits(b))


def test_packed_transfers_are_lossless():
    raw = np.random.default_rng(1).random(1001, dtype=np.float64).tobytes() + b"xyz"
    for level in (0, 1, 9):
        assert sd.unpack(sd.pack(raw, level)) == raw
    with pytest.raises(svetlo.SvetloError):
        sd.unpack(b"\7junk")


def test_compressed_film_sums_give_the_same_bits(client):
    kw = dict(integrator="bdpt", spp=6, seed=2, width=32, height=24)
    ref = local(CBOX, **kw).image
    sizes = {}
    for level in (0, 1):
        job = sd.submit(CBOX, client=client, chunks=2, compress=level, **kw)
        assert np.array_equal(bits(job.result().image), bits(ref))
        sizes[level] = job.bytes_received
    # 60 bytes a pixel (beauty sums and splats) per task, plus headers.
    assert 2 * 60 * 32 * 24 <= sizes[0] < 2 * 60 * 32 * 24 + 1024
    assert sizes[1] < sizes[0]


# Two-sided 0.001 quantile of Student's t with 7 degrees of freedom (8 independent renders).
T7_0001 = 5.408


@pytest.mark.parametrize("integrator", ["pssmlt", "mlt"])
def test_independent_chains_agree_with_a_long_local_render(client, integrator):
    """The rule for the methods that are not pass-separable: independent renders (own
    bootstrap, own chains) averaged. The average is deterministic (the local renders of the
    same seeds, averaged, bit for bit) and agrees with a long path-traced reference: a t-test
    on the image mean per channel, the renders' spread plus the reference's standard error."""
    box = dict(width=16, height=16, filter="box")
    kw = dict(integrator=integrator, options={"bootstrap": 5000, "chains": 16}, spp=16, **box)
    n = 8
    mean, images = sd.render_independent(CBOX, client=client, renders=n, seed=100, **kw)
    scene = svetlo.load_file(CBOX)
    for i in (0, n - 1):
        assert np.array_equal(bits(images[i]), bits(svetlo.render(scene, seed=100 + i, progress=False, **kw)))
    assert np.array_equal(bits(mean), bits((np.sum(np.array(images, dtype=np.float64), axis=0) / n).astype(np.float32)))
    ref = svetlo.render_result(scene, integrator="path", spp=1024, seed=7, progress=False, **box)
    per_render = np.array([im.mean(axis=(0, 1)) for im in images], dtype=np.float64)
    se = np.sqrt(per_render.var(axis=0, ddof=1) / n + ref.variance.mean(axis=(0, 1)) / (1024 * 256))
    t = (per_render.mean(axis=0) - ref.image.mean(axis=(0, 1))) / se
    assert np.all(np.abs(t) < T7_0001), f"{integrator}: t = {t} against the path-traced reference"


def worker_radiosity_counters(client):
    """Radiosity solves begun and form-factor rows computed, summed over the workers."""
    per = client.run(sd.radiosity_counters)
    return sum(c["solves"] for c in per.values()), sum(c["rows"] for c in per.values())


@pytest.mark.parametrize(
    "options",
    [
        {"element-size": 1},
        {"element-size": 1, "form-factors": "hemicube", "hemicube-resolution": 16},
        {"element-size": 1, "form-factors": "raycast", "rays": 64, "shading": "flat", "reciprocity": True},
        {"element-size": 1, "solver": "hierarchical", "epsilon": 0.2},
    ],
    ids=["analytic", "hemicube", "raycast", "hierarchical"],
)
def test_radiosity_rows_spread_over_workers_and_one_solve_shared(client, options):
    """Form-factor rows computed by ranges on the workers (7 batches that do not divide the
    rows), one task solving from them, every display chunk showing that solution: the local
    render bit for bit, with exactly one solve and each row computed once on the workers."""
    kw = dict(integrator="radiosity", options=options, spp=5, seed=3, width=16, height=12, max_depth=-1)
    ref = local(CBOX, **kw)
    assert ref.image.max() > 0
    before = worker_radiosity_counters(client)
    job = sd.submit(CBOX, client=client, chunks=3, form_factor_batches=7, **kw)
    r = job.result()
    solves, rows = (a - b for a, b in zip(worker_radiosity_counters(client), before))
    hierarchical = options.get("solver") == "hierarchical"
    assert len(job.shared) == 1 and len(job.futures) == 3
    if hierarchical:
        # Its links are refined between solves: the solve task makes them, nothing is spread.
        assert job.plan["rows"] == 0 and job.row_tasks == [] and rows == 0
    else:
        assert job.plan["rows"] > 7 and job.plan["rows"] % 7 != 0 and len(job.row_tasks) == 7
        assert rows == job.plan["rows"], "every form-factor row computed once, by the row tasks"
    assert solves == 1, "one solve for the three chunks"
    assert r.spp == 5 and not r.interrupted
    assert np.array_equal(bits(r.image), bits(ref.image)), f"{options}: the merged image is not the local one"
    assert np.array_equal(bits(r.variance), bits(ref.variance))


def test_the_module_command_line_renders_the_local_image(tmp_path):
    """python -m svetlo.distributed on its own LocalCluster of 2 workers: the image file is
    the local render's, bit for bit, and progress lines are printed."""
    import subprocess
    import sys

    out = tmp_path / "out.exr"
    args = ["--integrator", "bdpt", "--spp", "7", "--seed", "4", "--width", "16", "--height", "12", "--chunks", "3"]
    p = subprocess.run([sys.executable, "-m", "svetlo.distributed", str(CBOX), "--workers", "2", "-o", str(out), *args], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "7/7 spp" in p.stderr and "wrote" in p.stderr, p.stderr
    assert (tmp_path / "out.png").is_file()
    ref = local(CBOX, integrator="bdpt", spp=7, seed=4, width=16, height=12).image
    svetlo.write(tmp_path / "ref.exr", ref)
    assert np.array_equal(bits(svetlo.read(out)), bits(svetlo.read(tmp_path / "ref.exr")))
    # Bad options exit 2 with a message, before any cluster starts.
    p = subprocess.run([sys.executable, "-m", "svetlo.distributed", str(CBOX), "--workers", "0"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "--workers" in p.stderr
