"""Reference values of Mitsuba 3 BSDFs for tests/bsdf_mitsuba.rs.

Run with Mitsuba 3 installed (pip install mitsuba; written with 3.9.1):
    python3 gen_mitsuba_bsdf_refs.py > mitsuba_bsdf_refs.csv
Each row: model id, kind (eval or sample), wo (svetlo's, = Mitsuba's si.wi), then
  eval:   wi, f (RGB, without the cosine), pdf
  sample: uc, u1, u2, wi, weight (RGB), delta (1/0)
The model ids match MODELS in tests/bsdf_mitsuba.rs.
"""
import random
import mitsuba as mi

mi.set_variant("scalar_rgb")

def rgb(v):
    return {"type": "rgb", "value": v}

ETA, K = [0.2, 0.9, 1.1], [3.9, 2.4, 2.2]
MODELS = [
    {"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.2, "alpha_v": 0.4, "eta": rgb(ETA), "k": rgb(K)},
    {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.3, "eta": rgb(ETA), "k": rgb(K)},
    {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.5, "ext_ior": 1.0},
    {"type": "roughdielectric", "distribution": "beckmann", "alpha_u": 0.1, "alpha_v": 0.3, "int_ior": 1.33, "ext_ior": 1.0},
    {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1, "int_ior": 1.5168, "ext_ior": 1.0, "diffuse_reflectance": rgb([0.02, 0.2, 0.1])},
    {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.4, "int_ior": 1.9, "ext_ior": 1.0, "nonlinear": True, "diffuse_reflectance": rgb([0.5, 0.5, 0.5])},
    {"type": "plastic", "int_ior": 1.9, "ext_ior": 1.0, "diffuse_reflectance": rgb([0.1, 0.27, 0.36])},
    {"type": "plastic", "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": True, "diffuse_reflectance": rgb([0.8, 0.8, 0.8])},
    {"type": "diffuse", "reflectance": rgb([0.5, 0.5, 0.5])},
    {"type": "conductor", "eta": rgb(ETA), "k": rgb(K)},
    {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0},
    {"type": "thindielectric", "int_ior": 1.5, "ext_ior": 1.0},
    {"type": "roughplastic", "distribution": "ggx", "alpha": 0.6, "int_ior": 1.49, "ext_ior": 1.0, "diffuse_reflectance": rgb([0.3, 0.6, 0.9])},
]

def uniform_dir(rng):
    z = 1 - 2 * rng.random()
    r = max(0.0, 1 - z * z) ** 0.5
    import math
    p = 2 * math.pi * rng.random()
    return [r * math.cos(p), r * math.sin(p), z]

def fmt(v):
    return ",".join("%.9g" % x for x in v)

rng = random.Random(1234)
ctx = mi.BSDFContext()
for mid, d in enumerate(MODELS):
    b = mi.load_dict(d)
    for _ in range(60):
        wo, wi = uniform_dir(rng), uniform_dir(rng)
        if d["type"] not in ("roughdielectric", "dielectric", "thindielectric") and rng.random() < 0.8:
            wo[2], wi[2] = abs(wo[2]), abs(wi[2])
        si = mi.SurfaceInteraction3f()
        si.n = mi.Normal3f(0, 0, 1)
        si.sh_frame = mi.Frame3f(si.n)
        si.wi = mi.Vector3f(wo)
        f = b.eval(ctx, si, mi.Vector3f(wi))
        pdf = b.pdf(ctx, si, mi.Vector3f(wi))
        c = abs(wi[2])
        fv = [f[i] / c for i in range(3)]
        print("%d,eval,%s,%s,%s,%.9g" % (mid, fmt(wo), fmt(wi), fmt(fv), pdf))
    for _ in range(20):
        wo = uniform_dir(rng)
        if d["type"] not in ("roughdielectric", "dielectric", "thindielectric"):
            wo[2] = abs(wo[2])
        uc, u1, u2 = rng.random(), rng.random(), rng.random()
        si = mi.SurfaceInteraction3f()
        si.n = mi.Normal3f(0, 0, 1)
        si.sh_frame = mi.Frame3f(si.n)
        si.wi = mi.Vector3f(wo)
        bs, w = b.sample(ctx, si, uc, mi.Point2f(u1, u2))
        delta = 1 if mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta) else 0
        print("%d,sample,%s,%.9g,%.9g,%.9g,%s,%s,%d" % (mid, fmt(wo), uc, u1, u2, fmt(list(bs.wo)), fmt([w[i] for i in range(3)]), delta))
