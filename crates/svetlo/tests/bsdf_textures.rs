//! Every texturable parameter of every BSDF the Mitsuba loader knows, given as a checkerboard,
//! against the same BSDF with that parameter a constant of the value the checkerboard holds at
//! the test point. The point (uv 0.25, 0.25) lies in a cell where Mitsuba 3's colour lookup
//! gives `color0` and its scalar lookup (`eval_1`: roughness, exponents, opacity) `color1`, so a
//! parameter read through the wrong path (or not read from its texture at all) fails.

use glam::{Vec2, Vec3};
use std::path::Path;
use svetlo::bsdf::TransportMode;
use svetlo::io::load_scene_from_str;

/// (bsdf type, other properties, parameter, colour0, colour1, scalar parameter?)
const CASES: &[(&str, &str, &str, f32, f32, bool)] = &[
    ("diffuse", "", "reflectance", 0.2, 0.7, false),
    ("conductor", "", "specular_reflectance", 0.3, 0.9, false),
    ("roughconductor", "", "specular_reflectance", 0.3, 0.9, false),
    ("roughconductor", "", "alpha", 0.1, 0.4, true),
    ("roughconductor", r#"<float name="alpha_v" value="0.2"/>"#, "alpha_u", 0.1, 0.4, true),
    ("roughconductor", r#"<float name="alpha_u" value="0.2"/>"#, "alpha_v", 0.1, 0.4, true),
    ("dielectric", "", "specular_reflectance", 0.3, 0.9, false),
    ("dielectric", "", "specular_transmittance", 0.3, 0.9, false),
    ("roughdielectric", "", "specular_reflectance", 0.3, 0.9, false),
    ("roughdielectric", "", "specular_transmittance", 0.3, 0.9, false),
    ("roughdielectric", "", "alpha", 0.1, 0.4, true),
    ("thindielectric", "", "specular_reflectance", 0.3, 0.9, false),
    ("thindielectric", "", "specular_transmittance", 0.3, 0.9, false),
    ("plastic", "", "diffuse_reflectance", 0.2, 0.7, false),
    ("plastic", "", "specular_reflectance", 0.3, 0.9, false),
    ("roughplastic", "", "diffuse_reflectance", 0.2, 0.7, false),
    ("roughplastic", "", "specular_reflectance", 0.3, 0.9, false),
    ("roughplastic", "", "alpha", 0.1, 0.4, true),
    ("phong", "", "diffuse_reflectance", 0.2, 0.5, false),
    ("phong", "", "specular_reflectance", 0.1, 0.4, false),
    ("phong", "", "exponent", 10.0, 60.0, true),
    ("blinnphong", "", "diffuse_reflectance", 0.2, 0.5, false),
    ("blinnphong", "", "specular_reflectance", 0.1, 0.4, false),
    ("blinnphong", "", "exponent", 10.0, 60.0, true),
    ("cooktorrance", "", "diffuse_reflectance", 0.2, 0.5, false),
    ("cooktorrance", "", "specular_reflectance", 0.1, 0.4, false),
    ("cooktorrance", "", "alpha", 0.1, 0.4, true),
    ("roughdiffuse", "", "reflectance", 0.2, 0.7, false),
    ("roughdiffuse", "", "alpha", 0.1, 0.4, true),
    ("ward", "", "diffuse_reflectance", 0.2, 0.5, false),
    ("ward", "", "specular_reflectance", 0.1, 0.4, false),
    ("ward", r#"<float name="alpha_v" value="0.2"/>"#, "alpha_u", 0.1, 0.4, true),
    ("ward", r#"<float name="alpha_u" value="0.2"/>"#, "alpha_v", 0.1, 0.4, true),
];

fn scene_with(bsdf: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>
  <shape type="sphere">{bsdf}</shape>
</scene>"#
    )
}

fn material(xml: &str) -> svetlo::bsdf::Material {
    let scene = load_scene_from_str(&scene_with(xml), Path::new("bsdf_textures.xml"), &[]).unwrap_or_else(|e| panic!("{e}\n{xml}"));
    scene.materials[scene.shapes[0].material as usize].clone()
}

/// Directions above the surface and through it (for the dielectrics).
fn directions() -> Vec<(Vec3, Vec3)> {
    let d = |x: f32, y: f32, z: f32| Vec3::new(x, y, z).normalize();
    vec![
        (d(0.3, 0.1, 0.9), d(-0.2, 0.3, 0.8)),
        (d(0.6, -0.2, 0.5), d(-0.5, 0.1, 0.6)),
        (d(0.1, 0.1, 1.0), d(-0.1, -0.1, 1.0)),
        (d(0.2, 0.4, 0.7), d(-0.3, -0.1, -0.9)),
        (d(0.0, 0.5, 0.6), d(0.1, -0.6, 0.5)),
    ]
}

#[test]
fn every_texturable_parameter_reads_its_texture_as_mitsuba() {
    let uv = Vec2::splat(0.25);
    let mut failures = Vec::new();
    for &(ty, extra, param, c0, c1, scalar) in CASES {
        let checker =
            format!(r#"<texture type="checkerboard" name="{param}"><float name="color0" value="{c0}"/><float name="color1" value="{c1}"/></texture>"#);
        let expected = if scalar { c1 } else { c0 };
        let textured = material(&format!(r#"<bsdf type="{ty}">{extra}{checker}</bsdf>"#)).bsdf(uv);
        let constant = material(&format!(r#"<bsdf type="{ty}">{extra}<float name="{param}" value="{expected}"/></bsdf>"#)).bsdf(uv);
        // The other cell's value must give a different BSDF, or the case proves nothing.
        let other = material(&format!(r#"<bsdf type="{ty}">{extra}<float name="{param}" value="{}"/></bsdf>"#, if scalar { c0 } else { c1 })).bsdf(uv);
        let mut differs = false;
        // Plastics choose between their lobes by the textures' means over the surface (as
        // Mitsuba does): their pdfs and sample weights differ from a constant's, f does not.
        let same_sampling = !ty.ends_with("plastic");
        for (wo, wi) in directions() {
            let [ft, fc, fo] = [&textured, &constant, &other].map(|b| b.eval(wo, wi, TransportMode::Radiance));
            let (pt, pc) = (textured.pdf(wo, wi, TransportMode::Radiance), constant.pdf(wo, wi, TransportMode::Radiance));
            let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * a.abs().max(b.abs()) + 1e-7;
            if !(0..3).all(|k| close(ft[k], fc[k])) || (same_sampling && !close(pt, pc)) {
                failures.push(format!("{ty}.{param}: textured f {ft:?} pdf {pt} vs constant {expected}: f {fc:?} pdf {pc}"));
            }
            differs |= (0..3).any(|k| !close(fo[k], fc[k]));
        }
        // Delta BSDFs have no eval: compare their sampled weights instead.
        if !differs && same_sampling {
            // Both lobes of the dielectrics: the sample choice follows uc.
            let w = |b: &svetlo::bsdf::Bsdf| {
                [0.01, 0.5, 0.99].map(|uc| b.sample(Vec3::new(0.3, 0.1, 0.9).normalize(), uc, Vec2::new(0.4, 0.6), TransportMode::Radiance).map(|s| s.weight()))
            };
            let (wt, wc, wo) = (w(&textured), w(&constant), w(&other));
            assert_ne!(format!("{wc:?}"), format!("{wo:?}"), "{ty}.{param}: the two values give the same BSDF");
            if format!("{wt:?}") != format!("{wc:?}") {
                failures.push(format!("{ty}.{param}: textured sample weights {wt:?} vs constant {wc:?}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
