//! Every scene of Mitsuba 3's render-test suite (participating media aside) against its
//! reference, with Mitsuba's own Z-test (`svetlo::film::compare::z_test`).
//!
//! Each scene renders with the integrator its file name ends in (`_path`, `_direct`,
//! `_ptracer`, as Mitsuba's suite does), seed 0. The full rule of issue #20 is
//! spp = max(16, 2e6 / pixels): `cargo test --release --test mitsuba_suite -- --ignored`.
//! The default run takes a tenth of that (spp = max(16, 2e5 / pixels)): the Z-test stays
//! exact at any spp (it scales the tolerance by sqrt(n)), only its power drops, so a
//! regression that moves a pixel by more than a few percent still shows.
//!
//! Needs `../shared/scenes` beside the repository; without it the tests say so and pass.

mod common;

use common::scenes::shared;
use std::path::Path;
use svetlo::film::compare::z_test;
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::io::{load_scene, read_image};

/// (scene file under `mitsuba-data/tests/scenes`, reference stem in its `refs/`).
const SCENES: &[(&str, &str)] = &[
    ("bsdf_spheres/test_arealight_path.xml", "test_arealight"),
    ("bsdf_spheres/test_bumpmap_path.xml", "test_bumpmap"),
    ("bsdf_spheres/test_constant_path.xml", "test_constant"),
    ("bsdf_spheres/test_envmap_path.xml", "test_envmap"),
    ("bsdf_spheres/test_normalmap_identity_roughconductor_path.xml", "test_normalmap_identity_roughconductor"),
    ("bsdf_spheres/test_normalmap_path.xml", "test_normalmap"),
    ("bsdf_spheres/test_normalmap_roughconductor_path.xml", "test_normalmap_roughconductor"),
    ("bsdf_spheres/test_pointlight_path.xml", "test_pointlight"),
    ("bsdf_spheres/test_roughdielectric_path.xml", "test_roughdielectric"),
    ("bsdf_spheres/test_roughplastic_linear_path.xml", "test_roughplastic_linear"),
    ("bsdf_spheres/test_roughplastic_nonlinear_path.xml", "test_roughplastic_nonlinear"),
    ("bsdf_spheres/test_textured_diffuse_path.xml", "test_textured_diffuse"),
    ("bsdf_spheres/test_textured_roughconductor_path.xml", "test_textured_roughconductor"),
    ("bsdf_spheres/test_texturedprincipled1_path.xml", "test_texturedprincipled1"),
    ("bsdf_spheres/test_texturedprincipled2_path.xml", "test_texturedprincipled2"),
    ("bsdf_spheres/test_texturedprincipledthin_path.xml", "test_texturedprincipledthin"),
    ("floating_sphere/test_directional_direct.xml", "test_directional"),
    ("infinite_mirrors/scene_path.xml", "scene"),
    ("instancing/test_instancing_path.xml", "test_instancing"),
    ("mesh_attributes/test_mesh_attributes_1_face_direct.xml", "test_mesh_attributes_1_face"),
    ("mesh_attributes/test_mesh_attributes_3_face_direct.xml", "test_mesh_attributes_3_face"),
    ("mesh_attributes/test_mesh_attributes_3_vertex_direct.xml", "test_mesh_attributes_3_vertex"),
    ("orthographic_sensor/test_orthographic_path.xml", "test_orthographic"),
    ("projector/test_projector_constant_direct.xml", "test_projector_constant"),
    ("projector/test_projector_textured_direct.xml", "test_projector_textured"),
    ("spot_light/test_spot_direct.xml", "test_spot"),
    ("texture_interp/test_texture_interp_direct.xml", "test_texture_interp"),
    ("various_emitters/test_various_emitters_ptracer.xml", "test_various_emitters"),
    ("various_shapes/test_various_shapes_path.xml", "test_various_shapes"),
];

/// Scenes not expected to pass yet, each with the reason. The default test asserts every
/// other scene passes, and prints how these fare.
const KNOWN_FAILING: &[(&str, &str)] = &[];

/// The integrator Mitsuba's suite renders a scene with: the file name's last `_` part.
fn integrator_of(rel: &str) -> &str {
    let stem = Path::new(rel).file_stem().and_then(|s| s.to_str()).unwrap_or("");
    stem.rsplit('_').next().unwrap_or("path")
}

struct Outcome {
    spp: u32,
    fraction: f64,
    relmse: f64,
    pass: bool,
}

/// Render one scene at `samples / pixels` spp (at least 16) and Z-test it; Err for a scene
/// that does not load or render.
fn run(root: &Path, rel: &str, stem: &str, samples: f64) -> Result<Outcome, String> {
    let path = root.join("mitsuba-data/tests/scenes").join(rel);
    let refs = path.parent().expect("parent").join("refs");
    let reference = read_image(&refs.join(format!("{stem}_ref_rgb.exr"))).map_err(|e| e.to_string())?;
    let variance = read_image(&refs.join(format!("{stem}_ref_rgb_var.exr"))).map_err(|e| e.to_string())?;
    let spp = ((samples / (reference.width * reference.height) as f64).round() as u32).max(16);
    let defaults = vec![("integrator".to_string(), integrator_of(rel).to_string()), ("spp".to_string(), spp.to_string())];
    let scene = load_scene(&path, &defaults).map_err(|e| e.to_string())?;
    let mut settings = RenderSettings::from_scene(&scene);
    settings.seed = 0;
    settings.spp = spp;
    let method = svetlo::methods::by_name(&scene.settings.integrator).map_err(|e| e.to_string())?;
    let film = method.render(&scene, &settings, &Progress::new()).map_err(|e| e.to_string())?;
    let z = z_test(&film.image(), &reference, &variance, film.spp_done).map_err(|e| e.to_string())?;
    Ok(Outcome { spp: film.spp_done, fraction: z.fraction_passing, relmse: z.relmse, pass: z.pass })
}

/// Render the whole list and print the pass table; returns the scenes that failed and
/// were not expected to.
fn suite(samples: f64) -> Vec<String> {
    let Some(root) = shared() else { return Vec::new() };
    let mut unexpected = Vec::new();
    let mut passed = 0;
    println!("| scene | spp | pass fraction | relMSE | result |\n|---|---|---|---|---|");
    // SVETLO_SUITE=substring renders only the matching scenes (for work on one plugin).
    let only = std::env::var("SVETLO_SUITE").unwrap_or_default();
    for &(rel, stem) in SCENES.iter().filter(|(rel, _)| rel.contains(only.as_str())) {
        let known = KNOWN_FAILING.iter().find(|(s, _)| *s == rel).map(|(_, why)| *why);
        let (row, pass) = match run(&root, rel, stem, samples) {
            Ok(o) => (format!("| {rel} | {} | {:.4} | {:.2e} | {} |", o.spp, o.fraction, o.relmse, if o.pass { "PASS" } else { "FAIL" }), o.pass),
            Err(e) => (format!("| {rel} | - | - | - | ERROR: {} |", e.lines().next().unwrap_or("")), false),
        };
        println!("{row}{}", known.map(|w| format!(" (known: {w})")).unwrap_or_default());
        passed += pass as usize;
        if !pass && known.is_none() {
            unexpected.push(row);
        }
    }
    println!("{passed} pass");
    unexpected
}

#[test]
fn every_scene_reduced_spp() {
    let failed = suite(2e5);
    assert!(failed.is_empty(), "scenes failing Mitsuba's Z-test:\n{}", failed.join("\n"));
}

/// The full rule of issue #20 (about a minute of 2 cores per scene at most).
#[test]
#[ignore]
fn every_scene_full_spp() {
    let failed = suite(2e6);
    assert!(failed.is_empty(), "scenes failing Mitsuba's Z-test:\n{}", failed.join("\n"));
}

/// Per-sample variance of `direct` on Mitsuba's spot-light scene (a white plane under a
/// constant environment and a textured spot) against Mitsuba's own (the reference's `_var`
/// image): Mitsuba's Z-test takes the reference's variance as the image's, so a noisier
/// estimator fails it however unbiased. Ratios of the variances (in luminance) summed over
/// the pixels lit by the spot and over the others; for comparison, the estimator `direct`
/// used before (one light chosen among all, the sky sampled uniformly, MIS with one BSDF
/// sample: `path` at max_depth 2), with Mitsuba's light selection and with svetlo's default.
#[test]
fn direct_variance_beats_mitsuba_on_the_spot_scene() {
    let Some(root) = shared() else { return };
    let path = root.join("mitsuba-data/tests/scenes/spot_light/test_spot_direct.xml");
    let refs = path.parent().expect("parent").join("refs");
    let reference = read_image(&refs.join("test_spot_ref_rgb.exr")).expect("reference");
    let ref_var = read_image(&refs.join("test_spot_ref_rgb_var.exr")).expect("variance");
    let mut scene = load_scene(&path, &[]).expect("scene");
    let mut settings = RenderSettings::from_scene(&scene);
    settings.seed = 3;
    settings.spp = 256;
    settings.max_depth = 2;
    // Spot-lit pixels: brighter than the environment alone makes the white plane (0.1).
    let lit: Vec<bool> = reference.data.iter().map(|c| c.mean() > 0.12).collect();
    let ratios = |scene: &svetlo::scene::Scene, method: &str| {
        let film = svetlo::methods::by_name(method).expect("method").render(scene, &settings, &Progress::new()).expect("render");
        let var = film.variance_image();
        let mut sums = [[0.0f64; 2]; 2];
        for ((v, r), &l) in var.data.iter().zip(&ref_var.data).zip(&lit) {
            // In luminance: the reference's variance is a spectral render's, converted to RGB
            // channel by channel (its red is negative on some saturated pixels).
            sums[l as usize][0] += v.luminance() as f64;
            sums[l as usize][1] += r.luminance() as f64;
        }
        (sums[0][0] / sums[0][1], sums[1][0] / sums[1][1])
    };
    // `direct` with svetlo's emitter choice (half by power, half alike); before, a path of
    // depth 2 (the old one-light estimator) with that choice and with Mitsuba's (all alike).
    let (env, spot) = ratios(&scene, "direct");
    let (env_mixed, spot_mixed) = ratios(&scene, "path");
    scene.set_light_selection(svetlo::scene::LightSelection::Uniform);
    let (env_before, spot_before) = ratios(&scene, "path");
    println!("variance / Mitsuba's  environment-lit  spot-lit");
    println!("direct                {env:>15.3}  {spot:>8.3}");
    println!("before, uniform       {env_before:>15.3}  {spot_before:>8.3}");
    println!("before, by power      {env_mixed:>15.3}  {spot_mixed:>8.3}");
    assert!(lit.iter().filter(|&&l| l).count() > 100, "too few spot-lit pixels");
    // The sums' noise is a few percent over hundreds of pixels: the margin is wide.
    for (what, r) in [("environment", env), ("spot", spot)] {
        assert!(r < 0.8, "{what}-lit pixels: {r:.3} times Mitsuba's variance");
    }
}

#[test]
fn integrator_from_file_name() {
    assert_eq!(integrator_of("a/test_spot_direct.xml"), "direct");
    assert_eq!(integrator_of("a/test_various_emitters_ptracer.xml"), "ptracer");
    assert_eq!(integrator_of("scene_path.xml"), "path");
}
