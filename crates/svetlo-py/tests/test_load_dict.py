"""`svetlo.load_dict` against `mitsuba.load_dict`: the same dictionaries rendered by both agree
by a per-pixel two-sample Z-test; and the translation's own behaviour (escaping, refs,
transforms, errors naming the key)."""

import math

import numpy as np
import pytest

import svetlo

mi = pytest.importorskip("mitsuba", reason="the load_dict comparison needs mitsuba==3.9.1 (pip install mitsuba==3.9.1)")
mi.set_variant("scalar_rgb")
T = mi.ScalarTransform4f

RES = 20
SPP = 256
DEPTH = 5
RGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])


def rgb(*v):
    return {"type": "rgb", "value": list(v) if len(v) == 3 else v[0]}


def sensor(origin=(0, 1, 5), target=(0, 0.6, 0), fov=40):
    return {
        "type": "perspective",
        "fov": fov,
        "to_world": T().look_at(origin=list(origin), target=list(target), up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": SPP},
    }


def floor(bsdf=None):
    return {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3), "bsdf": bsdf or {"type": "diffuse", "reflectance": rgb(0.6, 0.6, 0.6)}}


def area_light(y=3.0, radiance=8.0):
    return {
        "type": "rectangle",
        "to_world": T().translate([0, y, 0]).rotate([1, 0, 0], 90).scale(0.6),
        "emitter": {"type": "area", "radiance": rgb(radiance, radiance, radiance)},
    }


def ball(bsdf, center=(0, 0.7, 0), radius=0.7):
    return {"type": "sphere", "center": list(center), "radius": radius, "bsdf": bsdf}


def cornell_box():
    white, red, green = rgb(0.725, 0.71, 0.68), rgb(0.63, 0.065, 0.05), rgb(0.14, 0.45, 0.091)
    wall = lambda tf, ref: {"type": "rectangle", "to_world": tf, "bsdf": {"type": "ref", "id": ref}}
    return {
        "type": "scene",
        "sensor": sensor(origin=(0, 1, 6.8), target=(0, 1, 0), fov=19.5),
        "white": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": white}},
        "red": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": red}},
        "green": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": green}},
        "floor": wall(T().rotate([1, 0, 0], -90), "white"),
        "ceiling": wall(T().translate([0, 2, 0]).rotate([1, 0, 0], 90), "white"),
        "back": wall(T().translate([0, 1, -1]), "white"),
        "left": wall(T().translate([-1, 1, 0]).rotate([0, 1, 0], 90), "red"),
        "right": wall(T().translate([1, 1, 0]).rotate([0, 1, 0], -90), "green"),
        "light": {
            "type": "rectangle",
            "to_world": T().translate([0, 1.99, 0]).rotate([1, 0, 0], 90).scale(0.23),
            "bsdf": {"type": "ref", "id": "white"},
            "emitter": {"type": "area", "radiance": rgb(17, 12, 4)},
        },
        "box": {"type": "cube", "to_world": T().translate([0.33, 0.3, 0.3]).rotate([0, 1, 0], -18).scale(0.3), "bsdf": {"type": "ref", "id": "white"}},
    }


def lit(objects, light=None):
    d = {"type": "scene", "sensor": sensor(), "floor": floor()}
    d["light"] = light if light is not None else area_light()
    d.update(objects)
    return d


def envmap_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("env") / "sky.exr"
    h, w = 16, 32
    y = np.linspace(1, 0, h)[:, None, None]
    img = np.concatenate([0.3 + 1.5 * y, 0.4 + 1.2 * y, 0.8 + 0.9 * y], axis=2) * np.ones((1, w, 1))
    img[2:5, 20:24] = [30.0, 28.0, 20.0]  # a sun
    svetlo.write(p, img.astype(np.float32))
    return p


SCENES = {
    "cornell_box": lambda env: cornell_box(),
    "diffuse_point": lambda env: lit({"ball": ball({"type": "diffuse", "reflectance": rgb(0.2, 0.5, 0.8)})},
                                     {"type": "point", "position": [1.5, 3, 2], "intensity": rgb(20, 20, 20)}),
    "roughconductor": lambda env: lit({"ball": ball({"type": "roughconductor", "material": "Au", "distribution": "ggx", "alpha": 0.3})}),
    "conductor_smooth": lambda env: lit({"ball": ball({"type": "conductor", "material": "Cu"})}),
    "dielectric": lambda env: lit({"ball": ball({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0})}),
    "roughdielectric": lambda env: lit({"ball": ball({"type": "roughdielectric", "alpha": 0.2, "int_ior": 1.33})}),
    "roughplastic": lambda env: lit({"ball": ball({"type": "roughplastic", "diffuse_reflectance": rgb(0.7, 0.2, 0.1), "alpha": 0.15})}),
    "plastic_checkerboard": lambda env: lit({"ball": ball({"type": "plastic", "diffuse_reflectance": {"type": "checkerboard", "color0": rgb(0.1, 0.1, 0.1), "color1": rgb(0.8, 0.8, 0.2), "to_uv": T().scale([4, 4, 1])}})}),
    "spot": lambda env: lit({"ball": ball({"type": "diffuse"})},
                            {"type": "spot", "to_world": T().look_at(origin=[0, 4, 1], target=[0, 0, 0], up=[0, 1, 0]), "intensity": rgb(40, 40, 40), "cutoff_angle": 25, "beam_width": 15}),
    "directional_thindielectric": lambda env: lit({"ball": ball({"type": "diffuse", "reflectance": rgb(0.5, 0.5, 0.5)}, center=(-0.6, 0.4, 0), radius=0.4),
                                                   "pane": {"type": "rectangle", "to_world": T().translate([0.5, 0.6, 0.5]).rotate([0, 1, 0], 30).scale(0.5), "bsdf": {"type": "thindielectric"}}},
                                                  {"type": "directional", "direction": [-1, -2, -1], "irradiance": rgb(3, 3, 3)}),
    "constant_env_transforms": lambda env: lit({"cube": {"type": "cube", "to_world": T().translate([0, 0.5, 0]).rotate([0, 1, 0], 40).rotate([1, 0, 0], 10).scale([0.4, 0.5, 0.3]), "bsdf": {"type": "diffuse", "reflectance": rgb(0.8, 0.3, 0.3)}},
                                                "disk": {"type": "disk", "to_world": T().translate([0.9, 0.8, -0.5]).rotate([0, 1, 0], -30).scale(0.4), "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse"}}}},
                                               {"type": "constant", "radiance": rgb(0.8, 0.9, 1.0)}),
    "envmap": lambda env: lit({"ball": ball({"type": "roughconductor", "material": "Al", "alpha": 0.1})},
                              {"type": "envmap", "filename": str(env), "to_world": T().rotate([0, 1, 0], 20)}),
}


def mitsuba_mean_and_variance(d, spp):
    """Mitsuba's image (XYZ) and per-sample variance, from its moment integrator."""
    d = dict(d, integrator={"type": "moment", "nested": {"type": "path", "max_depth": DEPTH}})
    out = np.array(mi.render(mi.load_dict(d), spp=spp, seed=7))
    mean, m2 = out[..., 3:6].astype(np.float64), out[..., 6:9].astype(np.float64)
    return mean, np.maximum(m2 - mean * mean, 0.0) * spp / max(spp - 1, 1)


def two_sample_z(svetlo_rgb, svetlo_var_rgb, n_s, mi_xyz, mi_var_xyz, n_m):
    """Per pixel channel (XYZ) p-values of the difference of the two means.

    svetlo's variance is per RGB channel; the variance of an XYZ channel, a weighted sum of
    R, G, B, is bounded by Cauchy-Schwarz as (sum |w_k| sigma_k)^2: a conservative test.
    """
    xs = svetlo_rgb.astype(np.float64) @ RGB_TO_XYZ.T
    sd = np.sqrt(np.maximum(svetlo_var_rgb.astype(np.float64), 0.0)) @ np.abs(RGB_TO_XYZ).T
    var = sd * sd / n_s + mi_var_xyz / n_m
    # Pixels both see as exact (no variance) may differ by float rounding: a relative floor.
    var = var + (1e-4 * np.maximum(np.abs(xs), np.abs(mi_xyz))) ** 2 + 1e-12
    z = np.abs(xs - mi_xyz) / np.sqrt(var)
    return np.vectorize(lambda x: math.erfc(x / math.sqrt(2)))(z)


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    return envmap_file(tmp_path_factory)


@pytest.mark.parametrize("name", list(SCENES))
def test_load_dict_agrees_with_mitsuba(name, env):
    d = SCENES[name](env)
    scene = svetlo.load_dict(d)
    res = svetlo.render_result(scene, integrator="path", spp=SPP, max_depth=DEPTH, seed=3, filter="box", progress=False)
    assert res.image.shape == (RES, RES, 3)
    m_mean, m_var = mitsuba_mean_and_variance(d, SPP)
    p = two_sample_z(res.image, res.variance, SPP, m_mean, m_var, SPP)
    # Šidák over pixels at a family-wise 1 %, as Mitsuba's own render tests; all but 0.5 % of
    # channels must pass (a systematic difference fails far more: see the negative control).
    alpha = 1 - (1 - 0.01) ** (1 / (RES * RES))
    frac = np.mean(p > alpha)
    assert frac >= 0.995, f"{name}: {100 * frac:.2f} % of channels pass; svetlo mean {res.image.mean():.4f}, mitsuba (Y) {m_mean[..., 1].mean():.4f}"
    assert res.image.mean() > 1e-3


def test_the_z_test_sees_a_small_difference(env):
    # Negative control: 10 % less light fails the same test.
    d = SCENES["diffuse_point"](env)
    res = svetlo.render_result(svetlo.load_dict(d), integrator="path", spp=SPP, max_depth=DEPTH, seed=3, filter="box", progress=False)
    m_mean, m_var = mitsuba_mean_and_variance(d, SPP)
    p = two_sample_z(0.9 * res.image, res.variance, SPP, m_mean, m_var, SPP)
    alpha = 1 - (1 - 0.01) ** (1 / (RES * RES))
    assert np.mean(p > alpha) < 0.95


def test_own_transform_matches_mitsuba():
    ops = lambda t: t.translate([1, 2, 3]).rotate([0.3, 1, 0.2], 37).scale([2, 0.5, 1.5]).look_at(origin=[1, 0, 4], target=[0, 1, 0], up=[0, 1, 0])
    np.testing.assert_allclose(ops(svetlo.ScalarTransform4f()).matrix, np.array(ops(T()).matrix), atol=1e-5)


def test_same_scene_as_xml(tmp_path):
    # The dict and the equivalent XML file load to the same render, bit for bit.
    xml = tmp_path / "s.xml"
    xml.write_text(f"""<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0.6, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="{RES}"/><integer name="height" value="{RES}"/><rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="8"/></sampler></sensor>
  <bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.4, 0.5, 0.6"/></bsdf>
  <shape type="sphere"><point name="center" value="0, 0.7, 0"/><float name="radius" value="0.7"/><ref id="grey"/></shape>
  <emitter type="point"><point name="position" value="1.5, 3, 2"/><rgb name="intensity" value="20"/></emitter>
</scene>""")
    s = sensor()
    s["sampler"]["sample_count"] = 8
    d = {"type": "scene", "sensor": s, "grey": {"type": "diffuse", "reflectance": rgb(0.4, 0.5, 0.6)},
         "ball": {"type": "sphere", "center": [0, 0.7, 0], "radius": 0.7, "bsdf": {"type": "ref", "id": "grey"}},
         "lamp": {"type": "point", "position": np.array([1.5, 3, 2]), "intensity": rgb(20)}}
    sa, sb = svetlo.load_file(xml), svetlo.load_dict(d)
    unnamed = lambda sc: [{k: v for k, v in sh.items() if k != "name"} for sh in sc.shapes]
    assert unnamed(sa) == unnamed(sb) and sa.materials == sb.materials and sa.emitters == sb.emitters
    # Mitsuba's look_at matrix and the XML loader's <lookat> may differ in the last bits only.
    np.testing.assert_allclose(sa.camera["to_world"], sb.camera["to_world"], atol=1e-6)
    a = svetlo.render(sa, integrator="direct", seed=1, progress=False)
    b = svetlo.render(sb, integrator="direct", seed=1, progress=False)
    np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-5)


def test_strings_are_escaped(tmp_path):
    # A file name with XML's special characters reaches the loader intact.
    odd = tmp_path / 'a "quoted" <&> name.exr'
    svetlo.write(odd, np.full((4, 8, 3), 0.5, np.float32))
    d = {"type": "scene", "sensor": sensor(), "sky": {"type": "envmap", "filename": str(odd)}}
    img = svetlo.render(svetlo.load_dict(d), spp=4, progress=False)
    np.testing.assert_allclose(img, 0.5, rtol=1e-5)


def test_errors_name_the_key():
    d = lit({"ball": ball({"type": "roughconductor", "alpha": "very"})})
    with pytest.raises(svetlo.SceneError) as info:
        svetlo.load_dict(d)
    assert info.value.key == "scene['ball']['bsdf']['alpha']", (info.value.key, str(info.value))
    assert "alpha" in str(info.value)
    with pytest.raises(svetlo.SceneError, match=r"scene\['ball'\]\['bsdf'\]: unknown plugin type 'velvet'"):
        svetlo.load_dict(lit({"ball": ball({"type": "velvet"})}))
    with pytest.raises(svetlo.SceneError, match=r"scene\['ball'\]\['radius'\]: cannot translate"):
        svetlo.load_dict(lit({"ball": {"type": "sphere", "radius": object()}}))
    with pytest.raises(svetlo.SceneError, match="'type': 'scene'"):
        svetlo.load_dict({"type": "sphere"})
    with pytest.raises(TypeError):
        svetlo.load_dict([1, 2])
    with pytest.raises(svetlo.SceneError, match=r"scene\['ball'\]\['bsdf'\]: reference to unknown id 'nowhere'"):
        svetlo.load_dict(lit({"ball": ball({"type": "ref", "id": "nowhere"})}))
    with pytest.raises(svetlo.SceneError, match="finite"):
        svetlo.load_dict(lit({"ball": ball({"type": "diffuse", "reflectance": rgb(float("nan"), 0, 0)})}))


def test_the_tree_is_its_printed_xml():
    # load_dict hands its element tree to the loader; the XML it prints (to_xml) is the same
    # tree as text: both load to bit-identical renders, and an error's line in that text is
    # the line whose key load_dict names.
    from svetlo import _dict

    d = lit({"ball": ball({"type": "roughconductor", "alpha": 0.2}), "floor": {"type": "rectangle", "to_world": svetlo.ScalarTransform4f().rotate([1, 0, 0], -90).scale(3),
             "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": rgb(0.2), "color1": rgb(0.8)}}}}})
    text, keys = _dict.to_xml(d)
    assert len(keys) == text.count("\n")
    a = svetlo.render(svetlo.load_dict(d), integrator="path", spp=4, seed=2, progress=False)
    b = svetlo.render(svetlo.load_string(text), integrator="path", spp=4, seed=2, progress=False)
    assert a.tobytes() == b.tobytes()
    # The bad entry comes after elements that take several lines (a transform, nested bsdfs).
    bad = lit({"floor": d["floor"], "ball": ball({"type": "roughconductor", "alpha": "very"})})
    text, keys = _dict.to_xml(bad)
    with pytest.raises(svetlo.SceneError) as from_text:
        svetlo.load_string(text)
    with pytest.raises(svetlo.SceneError) as from_dict:
        svetlo.load_dict(bad)
    assert from_text.value.line is not None and from_dict.value.line is None
    assert keys[from_text.value.line - 1] == from_dict.value.key == "scene['ball']['bsdf']['alpha']"
