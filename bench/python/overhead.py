"""What the Python package costs over the library: the render call's overhead, and load_dict
against loading the same Cornell box from XML.

    python bench/python/overhead.py [--reps 200]

Overhead of a render = the Python call's wall time less the library's render call inside it
(`RenderResult.render_seconds`, timed on the render thread around `Integrator::render`) and
less `Film::image` (`develop_seconds`, which a Rust caller needs as well): what keyword
handling, settings, the render thread, the wake-up, the arrays and the result cost. On a
loaded machine the median is dominated by the wake-up of the calling thread once the render
thread is done (the scheduler's latency); the minimum shows the binding's own cost.
Loading: medians over alternating runs of `load_dict(d)` and `load_file(xml)` for the same
scene (the dict's XML translation written to a file, and the bundled scenes/cornell-box.xml).
"""

import argparse
import pathlib
import statistics
import sys
import tempfile
import time

import svetlo
from svetlo import _dict

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "crates" / "svetlo-py" / "tests"))


def cornell_dict(res):
    T = svetlo.ScalarTransform4f
    rgb = lambda *v: {"type": "rgb", "value": list(v)}
    wall = lambda tf, ref: {"type": "rectangle", "to_world": tf, "bsdf": {"type": "ref", "id": ref}}
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": -1},
        "sensor": {
            "type": "perspective", "fov": 19.5, "fov_axis": "x",
            "to_world": T().look_at(origin=[0, 1, 6.8], target=[0, 1, 0], up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": 64},
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "gaussian"}},
        },
        "white": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": rgb(0.725, 0.71, 0.68)}},
        "red": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": rgb(0.63, 0.065, 0.05)}},
        "green": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": rgb(0.14, 0.45, 0.091)}},
        "floor": wall(T().rotate([1, 0, 0], -90), "white"),
        "ceiling": wall(T().translate([0, 2, 0]).rotate([1, 0, 0], 90), "white"),
        "back": wall(T().translate([0, 1, -1]), "white"),
        "left": wall(T().translate([-1, 1, 0]).rotate([0, 1, 0], 90), "red"),
        "right": wall(T().translate([1, 1, 0]).rotate([0, 1, 0], -90), "green"),
        "light": {"type": "rectangle", "to_world": T().translate([0, 1.99, 0]).rotate([1, 0, 0], 90).scale(0.23),
                  "bsdf": {"type": "ref", "id": "white"}, "emitter": {"type": "area", "radiance": rgb(17, 12, 4)}},
        "tall": {"type": "cube", "to_world": T().translate([-0.33, 0.6, -0.3]).rotate([0, 1, 0], 18).scale([0.3, 0.6, 0.3]), "bsdf": {"type": "ref", "id": "white"}},
        "short": {"type": "cube", "to_world": T().translate([0.33, 0.3, 0.3]).rotate([0, 1, 0], -18).scale(0.3), "bsdf": {"type": "ref", "id": "white"}},
    }


def med_ms(xs):
    return 1e3 * statistics.median(xs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--reps", type=int, default=200)
    a = ap.parse_args()

    print("render overhead (Python call wall time - library render call - Film::image), medians over", a.reps, "calls")
    print(f"{'scene':28s} {'call ms':>9s} {'render ms':>10s} {'image ms':>9s} {'overhead ms':>12s} {'(min)':>7s}")
    scene = svetlo.load_file(ROOT / "scenes" / "cornell-box.xml")
    for res, spp in ((16, 1), (256, 1), (512, 4)):
        reps = a.reps if res < 512 else max(5, a.reps // 20)
        calls, renders, develops = [], [], []
        for _ in range(reps):
            t0 = time.perf_counter()
            r = svetlo.render_result(scene, integrator="path", spp=spp, width=res, height=res, threads=1, progress=False)
            calls.append(time.perf_counter() - t0)
            renders.append(r.render_seconds)
            develops.append(r.develop_seconds)
            # Freed here, not inside the next timed call.
            del r
        over = [c - r - d for c, r, d in zip(calls, renders, develops)]
        print(f"{f'cornell-box {res}x{res} {spp} spp':28s} {med_ms(calls):9.3f} {med_ms(renders):10.3f} {med_ms(develops):9.3f} {med_ms(over):12.3f} {1e3 * min(over):7.3f}")

    d = cornell_dict(512)
    with tempfile.TemporaryDirectory() as tmp:
        xml_path = pathlib.Path(tmp) / "cbox_from_dict.xml"
        xml_path.write_text(_dict.to_xml(d)[0])
        bundled = ROOT / "scenes" / "cornell-box.xml"
        t_dict, t_xml, t_bundled, t_translate = [], [], [], []
        for _ in range(a.reps):
            t0 = time.perf_counter()
            svetlo.load_dict(d)
            t1 = time.perf_counter()
            svetlo.load_file(xml_path)
            t2 = time.perf_counter()
            svetlo.load_file(bundled)
            t3 = time.perf_counter()
            _dict.to_xml(d)
            t4 = time.perf_counter()
            t_dict.append(t1 - t0)
            t_xml.append(t2 - t1)
            t_bundled.append(t3 - t2)
            t_translate.append(t4 - t3)
    print()
    print("loading the Cornell box, medians over", a.reps, "alternating runs")
    print(f"  load_dict                      {med_ms(t_dict):8.3f} ms  (the same dict printed as XML: {med_ms(t_translate):.3f} ms)")
    print(f"  load_file (the dict's XML)     {med_ms(t_xml):8.3f} ms")
    print(f"  load_file (scenes/cornell-box) {med_ms(t_bundled):8.3f} ms")
    print(f"  load_dict / load_file          {statistics.median(t_dict) / statistics.median(t_bundled):8.3f}")


if __name__ == "__main__":
    main()
