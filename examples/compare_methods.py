"""One scene through path, bdpt, sppm, mlt and radiosity at equal time: the images side by
side, and relMSE against a long path-traced reference as the time budget grows (PNG).

    python examples/compare_methods.py [--scene scenes/cornell-box.xml] [--size 128] [--seconds 2]

Every method gets the same wall-time budgets (seconds/4, seconds/2, seconds); radiosity is not
a sampling method and runs once, at its own time. The reference is path tracing for 4x the
largest budget, so its own error is small next to the curves only at larger budgets.
"""

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import svetlo  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
# MLT's bootstrap (100k paths by default) alone would take most of a short budget.
METHODS = [("path", {}), ("bdpt", {}), ("sppm", {}), ("mlt", {"bootstrap": 20000}), ("radiosity", {})]


def srgb(img):
    x = np.clip(img, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "cornell-box.xml"))
    ap.add_argument("--size", type=int, default=128, help="image width and height")
    ap.add_argument("--seconds", type=float, default=2.0, help="the largest time budget per method")
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--out", default="compare_methods.png")
    a = ap.parse_args()

    scene = svetlo.load_file(a.scene, res=a.size)
    common = dict(width=a.size, height=a.size, max_depth=a.max_depth, progress=False)
    ref = svetlo.render(scene, integrator="path", spp=1 << 20, time=4 * a.seconds, seed=1000, **common)
    budgets = [a.seconds / 4, a.seconds / 2, a.seconds]
    curves, finals = {}, {}
    for name, opts in METHODS:
        points = []
        for i, t in enumerate([None] if name == "radiosity" else budgets):
            timed = {} if t is None else {"time": t, "spp": 1 << 16}
            r = svetlo.render_result(scene, integrator=name, options=opts, seed=i + 1, **timed, **common)
            points.append((r.seconds, svetlo.relmse(r.image, ref)))
            finals[name] = r.image
        curves[name] = points
        print(f"{name:10s} " + "  ".join(f"{s:6.2f} s: relMSE {e:.3e}" for s, e in points))

    fig = plt.figure(figsize=(3 * (len(METHODS) + 1), 6.5))
    for i, (name, img) in enumerate([("reference (path)", ref)] + list(finals.items())):
        ax = fig.add_subplot(2, len(METHODS) + 1, i + 1)
        ax.imshow(srgb(img), interpolation="nearest")
        ax.set_title(name)
        ax.axis("off")
    ax = fig.add_subplot(2, 1, 2)
    for name, pts in curves.items():
        s, e = zip(*pts)
        ax.loglog(s, e, "o-" if len(pts) > 1 else "s", label=name)
    ax.set_xlabel("render time (s)")
    ax.set_ylabel("relMSE against the reference")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.out, dpi=100)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
