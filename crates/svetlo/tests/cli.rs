//! Library side of what the command line does: render a scene, write EXR/PNG/variance and read
//! them back, compare images; determinism over thread counts; cancellation.

mod common;

use common::scenes::shared;
use glam::{Mat4, Vec3};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use svetlo::bsdf::Material;
use svetlo::camera::{Camera, Projection};
use svetlo::film::compare::{rel_mse, z_test};
use svetlo::film::{Filter, Image};
use svetlo::geometry::{Geometry, Sphere, TriangleMesh};
use svetlo::integrator::path::PathTracer;
use svetlo::integrator::{render_pixels, Integrator, Progress, RenderSettings};
use svetlo::io::image_io::{read_image, write_exr, write_image, write_png};
use svetlo::light::Light;
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::texture::Texture;
use svetlo::Rgb;

/// Mitsuba's `lookat`: camera space looks down +z with +x to the image's left.
fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let dir = (target - origin).normalize();
    let left = up.cross(dir).normalize();
    let up = dir.cross(left);
    Mat4::from_cols(left.extend(0.0), up.extend(0.0), dir.extend(0.0), origin.extend(1.0))
}

/// A diffuse sphere on a floor, lit by a spherical area light and a point light.
fn tiny_scene(width: u32, height: u32) -> Scene {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::new(0.7, 0.5, 0.3)) });
    let white = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.8)) });
    let floor = TriangleMesh {
        positions: vec![Vec3::new(-5.0, -1.0, -5.0), Vec3::new(5.0, -1.0, -5.0), Vec3::new(5.0, -1.0, 5.0), Vec3::new(-5.0, -1.0, 5.0)],
        indices: vec![[0, 2, 1], [0, 3, 2]],
        ..Default::default()
    };
    b.add_shape(Geometry::Mesh(floor), white, None, "floor").unwrap();
    b.add_shape(Geometry::Sphere(Sphere { center: Vec3::ZERO, radius: 1.0, flip_normals: false }), grey, None, "ball").unwrap();
    b.add_shape(
        Geometry::Sphere(Sphere { center: Vec3::new(1.5, 3.0, -1.0), radius: 0.5, flip_normals: false }),
        white,
        Some(Texture::Constant(Rgb::splat(8.0))),
        "lamp",
    )
    .unwrap();
    b.add_light(Light::Point { position: Vec3::new(-2.0, 2.0, -2.0), intensity: Rgb::new(3.0, 4.0, 5.0) });
    b.set_camera(Camera {
        to_world: look_at(Vec3::new(0.0, 1.0, -5.0), Vec3::ZERO, Vec3::Y),
        projection: Projection::Perspective { fov_x_deg: 45.0, aperture_radius: 0.0, focus_distance: 1.0 },
        width,
        height,
        near_clip: 0.01,
        far_clip: 1000.0,
        shutter_open: 0.0,
        shutter_close: 0.0,
    });
    b.build().unwrap()
}

fn settings(spp: u32, threads: usize, seed: u64) -> RenderSettings {
    RenderSettings { spp, threads, seed, max_depth: 4, filter: Filter::Gaussian { stddev: 0.5 }, ..Default::default() }
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("svetlo-libcli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn render_writes_images_that_read_back() {
    let scene = tiny_scene(24, 16);
    let film = PathTracer.render(&scene, &settings(8, 0, 3), &Progress::new()).unwrap();
    assert_eq!(film.spp_done, 8);
    let img = film.image();
    let var = film.variance_image();
    // Something is lit, nothing is invalid.
    assert!(img.mean().max_component() > 0.0);
    assert!(img.data.iter().chain(&var.data).all(|c| c.is_finite() && c.min_component() >= 0.0));
    let d = tmp_dir("render");
    write_exr(&d.join("out.exr"), &img).unwrap();
    write_png(&d.join("out.png"), &img).unwrap();
    write_image(&d.join("out_var.exr"), &var).unwrap();
    write_image(&d.join("out.pfm"), &img).unwrap();
    assert_eq!(read_image(&d.join("out.exr")).unwrap(), img);
    assert_eq!(read_image(&d.join("out_var.exr")).unwrap(), var);
    assert_eq!(read_image(&d.join("out.pfm")).unwrap(), img);
    let png = read_image(&d.join("out.png")).unwrap();
    assert_eq!((png.width, png.height), (24, 16));
    // The PNG is the clamped image up to 8-bit quantisation.
    for (a, b) in img.data.iter().zip(&png.data) {
        for k in 0..3 {
            assert!((a[k].clamp(0.0, 1.0) - b[k]).abs() < 0.008);
        }
    }
}

#[test]
fn two_renders_of_one_scene_pass_the_z_test_against_each_other() {
    // A 4-spp render against a 64-spp "reference" with the variance image the film estimates:
    // the same integrator, so the Z-test must pass (at its own 1 % family-wise level).
    let scene = tiny_scene(24, 16);
    let reference = PathTracer.render(&scene, &settings(64, 0, 1), &Progress::new()).unwrap();
    let render = PathTracer.render(&scene, &settings(4, 0, 2), &Progress::new()).unwrap();
    let t = z_test(&render.image(), &reference.image(), &reference.variance_image(), 4).unwrap();
    assert!(t.pass, "{t:?}");
    // Scaling the render by 1.5 is detected.
    let img = render.image();
    let biased = Image::new(img.width, img.height, img.data.iter().map(|c| *c * 1.5).collect());
    let t = z_test(&biased, &reference.image(), &reference.variance_image(), 4).unwrap();
    assert!(!t.pass, "{t:?}");
}

#[test]
fn image_does_not_depend_on_thread_count() {
    let scene = tiny_scene(40, 24); // several tiles of 16
    let one = render_pixels(&scene, &settings(6, 1, 9), &Progress::new(), &PathTracer).unwrap();
    let two = render_pixels(&scene, &settings(6, 2, 9), &Progress::new(), &PathTracer).unwrap();
    let (a, b) = (one.image(), two.image());
    assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits)));
    assert_eq!(one.variance_image(), two.variance_image());
    // A different seed gives a different image (the comparison above can fail).
    let other = render_pixels(&scene, &settings(6, 2, 10), &Progress::new(), &PathTracer).unwrap();
    assert_ne!(other.image(), a);
}

#[test]
fn cancelled_before_start_returns_an_empty_valid_film() {
    let scene = tiny_scene(16, 16);
    let progress = Progress::new();
    progress.cancel.store(true, Ordering::Relaxed);
    let film = PathTracer.render(&scene, &settings(32, 0, 0), &progress).unwrap();
    assert_eq!(film.spp_done, 0);
    let img = film.image();
    assert_eq!((img.width, img.height), (16, 16));
    assert!(img.data.iter().all(|c| *c == Rgb::BLACK));
}

#[test]
fn cancelled_while_rendering_keeps_the_passes_done() {
    let scene = tiny_scene(64, 48);
    let progress = Progress::new();
    let spp = 1_000_000;
    let finished = std::sync::atomic::AtomicBool::new(false);
    let film = std::thread::scope(|s| {
        s.spawn(|| {
            // Cancel once some work is done (and give up if the render ended on its own).
            while progress.done.load(Ordering::Relaxed) < 64 * 48 * 2 && !finished.load(Ordering::Relaxed) {
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            progress.cancel.store(true, Ordering::Relaxed);
        });
        let film = PathTracer.render(&scene, &settings(spp, 2, 0), &progress);
        finished.store(true, Ordering::Relaxed);
        film.unwrap()
    });
    assert!(film.spp_done >= 1 && film.spp_done < spp, "spp done {}", film.spp_done);
    let img = film.image();
    assert!(img.data.iter().all(|c| c.is_finite()));
    assert!(img.mean().max_component() > 0.0);
    // The progress counters add up to whole passes at least as far as the film.
    assert!(progress.done.load(Ordering::Relaxed) >= film.spp_done as u64 * 64 * 48);
}

#[test]
fn time_limit_stops_early() {
    let scene = tiny_scene(32, 32);
    let mut s = settings(1_000_000, 0, 0);
    s.time_limit = Some(std::time::Duration::from_millis(300));
    let film = PathTracer.render(&scene, &s, &Progress::new()).unwrap();
    // A million passes of even this tiny film take minutes: the limit stopped it.
    assert!(film.spp_done >= 1 && film.spp_done < 1_000_000);
}

/// The Tungsten reference of the Bitterli Cornell box and its 4x4 block average (a PFM) agree:
/// checks EXR (half float) reading and the PFM row order against real files.
#[test]
fn shared_reference_exr_and_pfm_agree() {
    let Some(root) = shared() else { return };
    let dir = root.join("bitterli/cornell-box");
    let exr = read_image(&dir.join("TungstenRender.exr")).unwrap();
    let pfm = read_image(&dir.join("TungstenRender_box4x4_256x256.pfm")).unwrap();
    assert_eq!((exr.width, exr.height), (1024, 1024));
    assert_eq!((pfm.width, pfm.height), (256, 256));
    let mut avg = Vec::with_capacity(256 * 256);
    for by in 0..256 {
        for bx in 0..256 {
            let mut s = Rgb::BLACK;
            for y in 0..4 {
                for x in 0..4 {
                    s += exr.get(bx * 4 + x, by * 4 + y);
                }
            }
            avg.push(s / 16.0);
        }
    }
    let avg = Image::new(256, 256, avg);
    let e = rel_mse(&avg, &pfm).unwrap();
    eprintln!("relMSE of the 4x4 block average of the EXR vs the PFM: {e:e}");
    assert!(e < 1e-8, "relMSE of block average vs PFM: {e}");
    // Flipped upside down it would not match: the test can tell the row order.
    let flipped = Image::new(256, 256, (0..256 * 256).map(|i| pfm.get(i % 256, 255 - i / 256)).collect());
    assert!(rel_mse(&avg, &flipped).unwrap() > 1e-3);
}

/// Mitsuba's float32 references read with the right size and plausible values.
#[test]
fn shared_mitsuba_reference_reads() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/scenes/cbox/refs");
    let img = read_image(&dir.join("cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).unwrap();
    let var = read_image(&dir.join("cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp_var.exr")).unwrap();
    assert_eq!((img.width, img.height), (var.width, var.height));
    let m = img.mean();
    assert!(m.is_finite() && m.min_component() > 0.0, "{m:?}");
    // The reference passes the Z-test against itself, its own variance and any spp.
    assert!(z_test(&img, &img, &var, 4096).unwrap().pass);
}
