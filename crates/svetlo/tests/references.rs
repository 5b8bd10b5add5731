//! Renders of the shared test scenes against Mitsuba 3 and Tungsten references.
//!
//! Mitsuba's scenes come with a 32k-spp reference and its per-sample variance: the render passes
//! Mitsuba's own per-pixel Z-test (Šidák-corrected at 1 %, 99.75 % of pixel channels). The
//! Bitterli scenes have block-averaged Tungsten references without variance: relMSE bounds.
//! Needs `../shared/scenes` beside the repository; without it each test says so and passes.

mod common;

use common::scenes::shared;
use std::path::Path;
use svetlo::film::compare::{rel_mse, z_test};
use svetlo::film::{Filter, Image};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::io::{load_scene, read_image};

fn render_file(scene_path: &Path, defaults: &[(&str, &str)], tweak: impl Fn(&mut RenderSettings)) -> (Image, u32) {
    let defaults: Vec<(String, String)> = defaults.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    let scene = load_scene(scene_path, &defaults).unwrap_or_else(|e| panic!("{}: {e}", scene_path.display()));
    let mut settings = RenderSettings::from_scene(&scene);
    settings.seed = 1;
    tweak(&mut settings);
    let integ = svetlo::methods::by_name(&scene.settings.integrator).expect("integrator");
    let film = integ.render(&scene, &settings, &Progress::new()).expect("render");
    (film.image(), film.spp_done)
}

/// Render a Mitsuba test scene at its own settings and Z-test it against `refs/<stem>_ref_rgb.exr`.
fn mitsuba_z_test(rel_scene: &str, ref_stem: &str) {
    let Some(root) = shared() else { return };
    let scene = root.join("mitsuba-data/tests/scenes").join(rel_scene);
    let refdir = scene.parent().expect("parent").join("refs");
    let reference = read_image(&refdir.join(format!("{ref_stem}_ref_rgb.exr"))).expect("reference");
    let variance = read_image(&refdir.join(format!("{ref_stem}_ref_rgb_var.exr"))).expect("variance");
    let (img, spp) = render_file(&scene, &[], |_| {});
    let z = z_test(&img, &reference, &variance, spp).expect("z-test");
    println!("{rel_scene}: {} spp, {:.4} % pass, relMSE {:.3e}, mean {:?} vs {:?}", spp, 100.0 * z.fraction_passing, z.relmse, z.mean_image, z.mean_reference);
    assert!(z.pass, "{rel_scene}: Z-test FAIL, {:.4} % of pixel channels pass (need 99.75 %)", 100.0 * z.fraction_passing);
}

#[test]
fn bsdf_spheres_arealight() {
    mitsuba_z_test("bsdf_spheres/test_arealight_path.xml", "test_arealight");
}

#[test]
fn bsdf_spheres_pointlight() {
    mitsuba_z_test("bsdf_spheres/test_pointlight_path.xml", "test_pointlight");
}

#[test]
fn bsdf_spheres_constant() {
    mitsuba_z_test("bsdf_spheres/test_constant_path.xml", "test_constant");
}

#[test]
fn bsdf_spheres_envmap() {
    mitsuba_z_test("bsdf_spheres/test_envmap_path.xml", "test_envmap");
}

#[test]
fn bsdf_spheres_roughdielectric() {
    mitsuba_z_test("bsdf_spheres/test_roughdielectric_path.xml", "test_roughdielectric");
}

#[test]
fn floating_sphere_directional() {
    mitsuba_z_test("floating_sphere/test_directional_direct.xml", "test_directional");
}

#[test]
fn infinite_mirrors() {
    mitsuba_z_test("infinite_mirrors/scene_path.xml", "scene");
}

#[test]
fn spot_light() {
    mitsuba_z_test("spot_light/test_spot_direct.xml", "test_spot");
}

#[test]
fn orthographic_sensor() {
    mitsuba_z_test("orthographic_sensor/test_orthographic_path.xml", "test_orthographic");
}

#[test]
fn instancing() {
    mitsuba_z_test("instancing/test_instancing_path.xml", "test_instancing");
}

/// The measured Cornell box (Mitsuba 3.9.1 llvm_ad_rgb, 4096 spp reference with variance).
#[test]
fn cbox_rgb_measured() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/scenes/cbox");
    let reference = read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    let variance = read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp_var.exr")).expect("variance");
    let (img, spp) = render_file(&dir.join("cbox-rgb.xml"), &[("spp", "16")], |_| {});
    let z = z_test(&img, &reference, &variance, spp).expect("z-test");
    println!("cbox-rgb: {spp} spp, {:.4} % pass, relMSE {:.3e}", 100.0 * z.fraction_passing, z.relmse);
    assert!(z.pass, "cbox-rgb: Z-test FAIL, {:.4} % pass", 100.0 * z.fraction_passing);
}

/// Bitterli's Cornell box at 256x256, box filter, against Tungsten's 4x4 block average.
/// relMSE <= 2e-3 needs the render's own noise well below that: 512 spp gives ~6e-4 here.
#[test]
fn bitterli_cornell_box() {
    let Some(root) = shared() else { return };
    let dir = root.join("bitterli/cornell-box");
    let reference = read_image(&dir.join("TungstenRender_box4x4_256x256.pfm")).expect("reference");
    let (img, spp) = render_file(&dir.join("mitsuba3/scene_v3.xml"), &[("resx", "256"), ("resy", "256"), ("spp", "512")], |s| s.filter = Filter::Box);
    let e = rel_mse(&img, &reference).expect("relmse");
    println!("bitterli cornell-box: {spp} spp, relMSE {e:.3e}");
    assert!(e <= 2e-3, "relMSE {e} > 2e-3");
}

/// Veach's MIS scene, direct lighting only (Mitsuba depth 2, see the shared README), against
/// Tungsten's 5x5 block average at 256x144.
#[test]
fn bitterli_veach_mis() {
    let Some(root) = shared() else { return };
    let dir = root.join("bitterli/veach-mis");
    let reference = read_image(&dir.join("TungstenRender_box5x5_256x144.pfm")).expect("reference");
    let (img, spp) = render_file(&dir.join("mitsuba3/scene.xml"), &[("resx", "256"), ("resy", "144"), ("spp", "256")], |s| {
        s.filter = Filter::Box;
        s.max_depth = 2;
    });
    let e = rel_mse(&img, &reference).expect("relmse");
    println!("bitterli veach-mis: {spp} spp, relMSE {e:.3e}");
    assert!(e <= 2e-3, "relMSE {e} > 2e-3");
}
