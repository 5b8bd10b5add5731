//! Photon mapping and SPPM: consistent, not unbiased, so they are tested for convergence.
//!
//! * White furnace (closed diffuse sphere emitting inward): radiance Le Σ_{i<D} ρ^i for
//!   max_depth D. A lookup disc centred on a sphere catches exactly π r² of it, and the
//!   radiance is uniform, so the density estimates carry no bias there: the mean of
//!   independent renders (seeds) must match by a t-test.
//! * The measured Cornell box against Mitsuba's 4096-spp reference, averaged over 8x8 blocks
//!   (exact for the box filter) to a 32x32 render: relMSE must fall as photons (photon
//!   mapping) or iterations (SPPM) grow, by a factor the replicate spread makes significant.
//! * Same image for any thread count.
//!
//! kd-tree queries against brute force are unit tests of `accel::kdtree`.

mod common;

use common::scenes::shared;
use glam::{Mat4, Vec3};
use svetlo::bsdf::Material;
use svetlo::camera::Camera;
use svetlo::film::compare::rel_mse;
use svetlo::film::{Filter, Image};
use svetlo::geometry::{Geometry, Sphere};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::io::{load_scene, read_image};
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::texture::Texture;
use svetlo::Rgb;

/// Two-sided Student-t critical value at p = 1e-3 for 9 degrees of freedom (10 replicates).
const T_CRIT_9: f64 = 4.781;

fn furnace(rho: f32) -> Scene {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(rho)) });
    let s = Sphere { center: Vec3::ZERO, radius: 1.0, flip_normals: true };
    b.add_shape(Geometry::Sphere(s), m, Some(Texture::Constant(Rgb::WHITE)), "furnace").expect("shape");
    b.set_camera(Camera::pinhole(Mat4::IDENTITY, 60.0, 8, 8));
    b.build().expect("scene")
}

fn render(scene: &Scene, integrator: &str, spp: u32, max_depth: i32, seed: u64, threads: usize) -> Image {
    let settings = RenderSettings { spp, max_depth, seed, threads, filter: Filter::Box, ..Default::default() };
    svetlo::methods::by_name(integrator).expect("integrator").render(scene, &settings, &Progress::new()).expect("render").image()
}

fn mean_and_stderr(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// Ten independent renders (seeds): their image means against `expected` by a t-test.
fn furnace_t_test(integrator: &str, spp: u32, max_depth: i32, expected: f64) {
    let scene = furnace(0.5);
    let means: Vec<f64> = (0..10).map(|seed| render(&scene, integrator, spp, max_depth, 100 + seed, 0).mean().mean() as f64).collect();
    let (m, se) = mean_and_stderr(&means);
    let t = (m - expected) / (se + 1e-6 * expected);
    println!("{integrator} furnace depth {max_depth}: mean {m:.5} ± {se:.1e} expected {expected:.5}, t = {t:.2}");
    assert!(t.abs() < T_CRIT_9, "{integrator} furnace depth {max_depth}: {m} vs {expected}, t = {t:.2}");
}

/// SPPM is biased at any finite iteration even here: the radius shrinks more after an
/// iteration that brought more photons (and more flux), a negative correlation of order
/// (1 - α) / N per iteration. With a few photons per disc and 8 iterations it is ~3 % of the
/// photon part; it must have shrunk below the test's resolution after 64 iterations.
#[test]
fn sppm_white_furnace() {
    furnace_t_test("sppm:photons=4000", 64, -1, 2.0);
}

/// max_depth 3: emission, one and two bounces: 1 + 0.5 + 0.25 (the photon's segments count).
#[test]
fn sppm_white_furnace_depth() {
    furnace_t_test("sppm:photons=4000", 64, 3, 1.75);
}

#[test]
fn photon_white_furnace() {
    furnace_t_test("photon:photons=5000,caustic-photons=1000,gather=4,k=16", 2, -1, 2.0);
    // Precomputed radiance per photon path length: gather hits at depth 2 of 3 read one-segment photons only.
    furnace_t_test("photon:photons=5000,caustic-photons=1000,gather=4,k=16", 2, 3, 1.75);
    furnace_t_test("photon:photons=5000,caustic-photons=1000,gather=4,k=16,precompute=0", 2, 3, 1.75);
    furnace_t_test("photon:photons=5000,caustic-photons=1000,gather=0,k=16", 2, 4, 1.875);
}

#[test]
fn same_image_whatever_the_thread_count() {
    let scene = furnace(0.7);
    for name in ["sppm:photons=500", "photon:photons=2000,caustic-photons=500,gather=2"] {
        let a = render(&scene, name, 3, -1, 5, 1);
        let b = render(&scene, name, 3, -1, 5, 3);
        assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_array() == y.to_array()), "{name}: image depends on the thread count");
    }
}

/// Average `s`x`s` blocks (a box-filtered render at the lower resolution, exactly).
fn block_average(img: &Image, s: usize) -> Image {
    let (w, h) = (img.width / s, img.height / s);
    let mut data = vec![Rgb::BLACK; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut sum = Rgb::BLACK;
            for dy in 0..s {
                for dx in 0..s {
                    sum += img.get(x * s + dx, y * s + dy);
                }
            }
            data[y * w + x] = sum / (s * s) as f32;
        }
    }
    Image::new(w, h, data)
}

/// The measured Cornell box at 32x32 with its Mitsuba reference averaged down to that size.
fn cbox_small() -> Option<(Scene, Image)> {
    let dir = shared()?.join("mitsuba-data/scenes/cbox");
    let reference = read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    let mut scene = load_scene(&dir.join("cbox-rgb.xml"), &[]).expect("scene");
    assert_eq!((reference.width, reference.height), (256, 256));
    (scene.camera.width, scene.camera.height) = (32, 32);
    Some((scene, block_average(&reference, 8)))
}

/// relMSE over the pixels away from the emitter (none of the 3x3 around them has a reference
/// above 1): pixels that see a sliver of the emitter carry the camera side's coverage noise,
/// the same for every method, and would hide the photon part's convergence.
fn rel_mse_off_emitter(img: &Image, reference: &Image) -> f64 {
    let (w, h) = (reference.width as i64, reference.height as i64);
    let bright = |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h && reference.get(x as usize, y as usize).max_component() >= 1.0;
    let keep: Vec<usize> = (0..reference.data.len())
        .filter(|&i| {
            let (x, y) = ((i as i64) % w, (i as i64) / w);
            !(-1..=1).any(|dy| (-1..=1).any(|dx| bright(x + dx, y + dy)))
        })
        .collect();
    assert!(keep.len() * 10 > reference.data.len() * 9, "the mask keeps too few pixels");
    let pick = |im: &Image| Image::new(keep.len(), 1, keep.iter().map(|&i| im.data[i]).collect());
    rel_mse(&pick(img), &pick(reference)).expect("relmse")
}

/// relMSE of renders with `a` and `b` settings over `seeds` replicates; asserts that `b` is
/// below `factor` times `a` with the difference beyond 3 standard errors.
fn assert_error_falls(scene: &Scene, reference: &Image, a: (&str, u32), b: (&str, u32), factor: f64, seeds: u64) -> (f64, f64) {
    let errs = |(name, spp): (&str, u32)| -> Vec<f64> {
        (0..seeds).map(|s| rel_mse_off_emitter(&render(scene, name, spp, scene.settings.max_depth, 10 + s, 0), reference)).collect()
    };
    let (ea, eb) = (errs(a), errs(b));
    let ((ma, sa), (mb, sb)) = (mean_and_stderr(&ea), mean_and_stderr(&eb));
    println!("{} x{}: relMSE {ma:.3e} ± {sa:.1e};  {} x{}: relMSE {mb:.3e} ± {sb:.1e};  ratio {:.2}", a.0, a.1, b.0, b.1, mb / ma);
    let z = (factor * ma - mb) / (factor * factor * sa * sa + sb * sb).sqrt();
    assert!(mb < factor * ma && z > 3.0, "error did not fall: {ma:.3e} -> {mb:.3e} (z = {z:.2} for factor {factor})");
    (ma, mb)
}

/// SPPM's error against Mitsuba falls as iterations grow: 64 iterations against 4 (the
/// asymptotic rate, n^-2/3 for α = 2/3, predicts a factor of 6).
#[test]
fn sppm_converges_on_cbox() {
    let Some((scene, reference)) = cbox_small() else { return };
    assert_error_falls(&scene, &reference, ("sppm:photons=4000", 4), ("sppm:photons=4000", 64), 0.4, 3);
}

/// Photon mapping's error shrinks with more photons when k grows as their square root (the
/// consistent regime: k -> inf, k / N -> 0; with k fixed the variance of each estimate stays
/// ~1/k). The global map is read directly (no final gather): density estimation is all there is.
#[test]
fn photon_map_error_shrinks_with_photons() {
    let Some((scene, reference)) = cbox_small() else { return };
    assert_error_falls(
        &scene,
        &reference,
        ("photon:photons=5000,caustic-photons=1000,gather=0,k=20", 64),
        ("photon:photons=80000,caustic-photons=1000,gather=0,k=80", 64),
        0.5,
        3,
    );
}

/// The same with the final gather (Jensen's full method).
#[test]
fn photon_final_gather_converges_on_cbox() {
    let Some((scene, reference)) = cbox_small() else { return };
    assert_error_falls(
        &scene,
        &reference,
        ("photon:photons=2000,caustic-photons=1000,gather=4,k=50", 4),
        ("photon:photons=32000,caustic-photons=1000,gather=4,k=50", 32),
        0.5,
        3,
    );
}

/// Full resolution against Mitsuba: a convergence table (run with --ignored --nocapture).
#[test]
#[ignore]
fn cbox_full_resolution_table() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/scenes/cbox");
    let reference = read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    let scene = load_scene(&dir.join("cbox-rgb.xml"), &[]).expect("scene");
    let mut last = f64::INFINITY;
    for its in [4u32, 16, 64, 256] {
        let e = rel_mse(&render(&scene, "sppm:photons=65536", its, scene.settings.max_depth, 1, 0), &reference).expect("relmse");
        println!("sppm {its:4} iterations: relMSE {e:.3e}");
        assert!(e < last, "SPPM error grew: {last:.3e} -> {e:.3e}");
        last = e;
    }
    for (n, spp) in [(50_000u64, 4u32), (200_000, 16), (800_000, 64)] {
        let e = rel_mse(&render(&scene, &format!("photon:photons={n},gather=8"), spp, scene.settings.max_depth, 1, 0), &reference).expect("relmse");
        println!("photon {n:7} photons, {spp} spp: relMSE {e:.3e}");
    }
}
