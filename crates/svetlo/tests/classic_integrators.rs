//! The classic integrators against the path tracer where their light path classes coincide
//! (issue 5): `whitted` equals `path` on point-lit scenes with mirrors and glass;
//! `distributed` equals `path` for direct light from area lights (max_depth 2) and at any
//! depth on scenes without diffuse lobes. Two-sample
//! per-pixel Z-tests (Šidák over all pixel channels, family level 1 %), plus the z of the
//! image means.

mod classic_scenes;

use classic_scenes::*;
use glam::{Mat4, Vec3};
use svetlo::light::Light;
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::Rgb;

/// A diffuse floor (the only non-specular surface, and planar: it cannot light itself
/// within 3 segments), a mirror sphere and a glass sphere, lit by a point, a spot and a
/// directional light. With max_depth 3 both methods see exactly E D L and E S D L.
fn mirror_scene() -> Scene {
    let mut b = SceneBuilder::new();
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 6.0), Vec3::new(6.0, 0.0, 0.0)), diffuse(Rgb::new(0.7, 0.5, 0.3)), None, "floor");
    add(&mut b, sphere(Vec3::new(-0.7, 0.8, 0.0), 0.8), mirror(), None, "mirror");
    add(&mut b, sphere(Vec3::new(1.0, 0.6, 0.6), 0.6), glass(), None, "glass");
    b.add_light(Light::Point { position: Vec3::new(0.5, 3.0, 1.5), intensity: Rgb::splat(8.0) });
    b.add_light(Light::spot(&look_at(Vec3::new(-2.0, 3.0, 2.0), Vec3::new(0.0, 0.0, 0.0), Vec3::Y), Rgb::new(10.0, 12.0, 6.0), 35.0, Some(25.0)));
    b.add_light(Light::Directional { direction: Vec3::new(0.3, -1.0, -0.2).normalize(), irradiance: Rgb::new(0.3, 0.4, 0.5) });
    b.set_camera(camera(look_at(Vec3::new(0.0, 2.5, 5.0), Vec3::new(0.0, 0.5, 0.0), Vec3::Y), 45.0, 32, 24));
    b.build().expect("scene")
}

/// A small diffuse card hidden behind a glass sphere: the camera sees it only through the
/// glass (E S S D L, 4 segments); lit by a point light between sphere and card.
fn glass_scene() -> Scene {
    let mut b = SceneBuilder::new();
    add(&mut b, sphere(Vec3::new(0.0, 0.0, 5.0), 1.0), glass(), None, "ball");
    add(&mut b, quad(Vec3::new(-0.3, -0.3, 7.0), Vec3::new(0.0, 0.6, 0.0), Vec3::new(0.6, 0.0, 0.0)), diffuse(Rgb::new(0.9, 0.6, 0.2)), None, "card");
    b.add_light(Light::Point { position: Vec3::new(0.8, 0.8, 6.5), intensity: Rgb::splat(3.0) });
    b.set_camera(camera(Mat4::IDENTITY, 30.0, 24, 24));
    b.build().expect("scene")
}

fn check(label: &str, a: &svetlo::film::Film, b: &svetlo::film::Film) {
    let c = compare(a, b, 0.01, 1e-4);
    eprintln!("{label}: {c:?}");
    assert!(c.mean_a > 1e-3, "{label}: the image is black");
    assert_eq!(c.failed, 0, "{label}: {} of {} pixel channels differ ({c:?})", c.failed, c.tested);
    assert!(c.mean_z.abs() < 4.0, "{label}: image means differ by {:.2} standard errors", c.mean_z);
}

#[test]
fn whitted_equals_path_with_point_lights_and_mirrors() {
    let scene = mirror_scene();
    let w = render(&scene, "whitted", 256, 3, 1);
    let p = render(&scene, "path", 1024, 3, 2);
    check("mirror scene, max_depth 3", &w, &p);
}

#[test]
fn whitted_equals_path_through_glass() {
    let scene = glass_scene();
    let w = render(&scene, "whitted", 256, 4, 3);
    let p = render(&scene, "path", 1024, 4, 4);
    check("glass scene, max_depth 4", &w, &p);
}

/// max_depth 1 shows only emitters (none here), 2 the local model without reflections.
#[test]
fn whitted_depth_meaning() {
    let scene = mirror_scene();
    let w1 = render(&scene, "whitted", 1, 1, 1).image();
    assert!(w1.data.iter().all(|c| c.is_black()));
    let w2 = render(&scene, "whitted", 256, 2, 1);
    let p2 = render(&scene, "path", 1024, 2, 6);
    check("max_depth 2", &w2, &p2);
}

/// Area-lit diffuse and glossy surfaces (Lambert floor, Phong and rough-conductor spheres,
/// a Ward panel), a thin-lens camera: soft shadows, glossy highlights, depth of field.
fn area_lit_scene(aperture: f32) -> Scene {
    let mut b = SceneBuilder::new();
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 6.0), Vec3::new(6.0, 0.0, 0.0)), diffuse(Rgb::new(0.6, 0.6, 0.5)), None, "floor");
    add(&mut b, sphere(Vec3::new(-0.8, 0.7, 0.0), 0.7), phong_material(0.4, 0.5, 40.0), None, "phong");
    add(&mut b, sphere(Vec3::new(0.9, 0.6, 0.4), 0.6), rough_conductor(0.2), None, "metal");
    let ward = svetlo::bsdf::Material::Ward {
        diffuse_reflectance: svetlo::texture::Texture::Constant(Rgb::splat(0.3)),
        specular_reflectance: svetlo::texture::Texture::Constant(Rgb::splat(0.6)),
        alpha_u: svetlo::texture::Texture::Constant(Rgb::splat(0.1)),
        alpha_v: svetlo::texture::Texture::Constant(Rgb::splat(0.4)),
        variant: svetlo::bsdf::ward::WardVariant::Balanced,
    };
    add(&mut b, quad(Vec3::new(-2.0, 0.0, -1.5), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0)), ward, None, "panel");
    // Emits downward (normal a x b = -y).
    add(
        &mut b,
        quad(Vec3::new(-0.5, 3.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0)),
        diffuse(Rgb::BLACK),
        Some(Rgb::new(6.0, 5.0, 4.0)),
        "lamp",
    );
    let mut cam = camera(look_at(Vec3::new(0.0, 2.0, 5.0), Vec3::new(0.0, 0.6, 0.0), Vec3::Y), 45.0, 32, 24);
    if aperture > 0.0 {
        cam.projection = svetlo::camera::Projection::Perspective { fov_x_deg: 45.0, aperture_radius: aperture, focus_distance: 5.0 };
    }
    b.set_camera(cam);
    b.build().expect("scene")
}

#[test]
fn distributed_equals_path_direct_light() {
    let scene = area_lit_scene(0.15);
    let d = render(&scene, "distributed", 256, 2, 7);
    let p = render(&scene, "path", 256, 2, 8);
    check("area-lit, max_depth 2", &d, &p);
}

/// No diffuse lobe anywhere (rough metal floor and sphere, glass): the path classes agree
/// at every depth.
#[test]
fn distributed_equals_path_without_diffuse() {
    let mut b = SceneBuilder::new();
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 6.0), Vec3::new(6.0, 0.0, 0.0)), rough_conductor(0.3), None, "floor");
    add(&mut b, sphere(Vec3::new(-0.7, 0.7, 0.0), 0.7), rough_conductor(0.08), None, "metal");
    add(&mut b, sphere(Vec3::new(0.9, 0.6, 0.5), 0.6), glass(), None, "glass");
    add(&mut b, quad(Vec3::new(-1.0, 3.0, -1.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0)), diffuse(Rgb::BLACK), Some(Rgb::splat(3.0)), "lamp");
    b.set_camera(camera(look_at(Vec3::new(0.0, 2.0, 5.0), Vec3::new(0.0, 0.6, 0.0), Vec3::Y), 45.0, 32, 24));
    let scene = b.build().expect("scene");
    let d = render(&scene, "distributed", 256, 6, 9);
    let p = render(&scene, "path", 256, 6, 10);
    check("no diffuse, max_depth 6", &d, &p);
}
