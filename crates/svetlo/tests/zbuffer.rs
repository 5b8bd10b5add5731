//! The Z-buffer rasteriser against the ray-cast image of the same local model (`whitted`
//! at max_depth 2, which is exactly that model with ray-traced shadows): pixel agreement
//! away from silhouettes and shadow edges, with the disagreeing fraction bounded.

mod classic_scenes;

use classic_scenes::*;
use glam::Vec3;
use svetlo::film::Image;
use svetlo::integrator::zbuffer::{Shading, ZBuffer};
use svetlo::integrator::{Integrator, Progress, RenderSettings};
use svetlo::light::Light;
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::Rgb;

fn scene(with_occluders: bool) -> Scene {
    let mut b = SceneBuilder::new();
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 6.0), Vec3::new(6.0, 0.0, 0.0)), diffuse(Rgb::new(0.7, 0.6, 0.5)), None, "floor");
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -2.0), Vec3::new(6.0, 0.0, 0.0), Vec3::new(0.0, 3.0, 0.0)), blinn_material(0.5, 0.4, 30.0), None, "wall");
    if with_occluders {
        add(&mut b, sphere(Vec3::new(-0.8, 0.7, 0.0), 0.7), phong_material(0.4, 0.5, 40.0), None, "ball");
        add(&mut b, quad(Vec3::new(0.5, 0.8, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0)), diffuse(Rgb::new(0.2, 0.5, 0.8)), None, "card");
    }
    b.add_light(Light::Point { position: Vec3::new(0.5, 3.0, 1.5), intensity: Rgb::splat(6.0) });
    b.add_light(Light::Directional { direction: Vec3::new(0.4, -1.0, -0.3).normalize(), irradiance: Rgb::new(0.3, 0.3, 0.25) });
    // Emits downward; the local model sees it as a point at its centre.
    add(&mut b, quad(Vec3::new(-2.0, 2.5, 0.5), Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.5)), diffuse(Rgb::BLACK), Some(Rgb::splat(4.0)), "lamp");
    b.set_camera(camera(look_at(Vec3::new(0.0, 2.2, 5.0), Vec3::new(0.0, 0.6, 0.0), Vec3::Y), 50.0, 64, 48));
    b.build().expect("scene")
}

fn zbuffer(scene: &Scene, z: ZBuffer, spp: u32) -> Image {
    let settings = RenderSettings { spp, filter: svetlo::film::Filter::Box, ..Default::default() };
    z.render(scene, &settings, &Progress::new()).expect("render").image()
}

/// Fraction of pixels that disagree with the ray-cast render `b` (a film, for its per-pixel
/// variance): a channel disagrees when it differs by more than 4.5 standard errors of the
/// ray-cast pixel (silhouette pixels are noisy there: random against grid subsamples) plus
/// 1 % (+ 1e-3 absolute). Also the relative difference of the image means.
fn disagreement(a: &Image, film: &svetlo::film::Film) -> (f64, f64) {
    let (b, var) = (film.image(), film.variance_image());
    let n = film.spp_done as f32;
    let mut bad = 0;
    for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
        let v = var.data[i];
        if (0..3).any(|c| (x[c] - y[c]).abs() > 4.5 * (v[c] / n).sqrt() + 0.01 * x[c].max(y[c]) + 1e-3) {
            bad += 1;
            if std::env::var("SVETLO_DEBUG_COMPARE").is_ok() {
                eprintln!("pixel ({}, {}): {:?} vs {:?}", i % a.width, i / a.width, x, y);
            }
        }
    }
    let (ma, mb) = (a.mean().mean() as f64, b.mean().mean() as f64);
    (bad as f64 / a.data.len() as f64, (ma - mb).abs() / mb)
}

/// Without occluders the only differences are anti-aliasing of the few silhouette pixels
/// (regular 4x4 grid against 256 random samples per pixel).
#[test]
fn zbuffer_matches_ray_cast_local_model_without_shadows() {
    let s = scene(false);
    let z = zbuffer(&s, ZBuffer::default(), 16);
    let w = render(&s, "whitted", 256, 2, 1);
    let (frac, rel) = disagreement(&z, &w);
    eprintln!("no occluders: {:.2} % of pixels differ, means differ by {:.3} %", 100.0 * frac, 100.0 * rel);
    assert!(w.image().mean().mean() > 1e-2);
    assert!(frac < 0.005 && rel < 0.002, "{frac} {rel}");
}

/// With occluders, shadow-map edges add disagreement; it stays a small fraction, and it
/// shrinks when the map's resolution grows (the error is the map's, not the shading's).
#[test]
fn zbuffer_shadow_maps_bound_their_edge_error() {
    let s = scene(true);
    let w = render(&s, "whitted", 256, 2, 2);
    let coarse = zbuffer(&s, ZBuffer { shadow_map_resolution: 128, ..Default::default() }, 16);
    let fine = zbuffer(&s, ZBuffer { shadow_map_resolution: 2048, ..Default::default() }, 16);
    let (fc, rc) = disagreement(&coarse, &w);
    let (ff, rf) = disagreement(&fine, &w);
    eprintln!("shadow map 128: {:.2} % pixels, mean {:.3} %; 2048: {:.2} % pixels, mean {:.3} %", 100.0 * fc, 100.0 * rc, 100.0 * ff, 100.0 * rf);
    assert!(ff < 0.01 && rf < 0.003, "{ff} {rf}");
    assert!(ff <= fc);
    // Without shadows the image is brighter wherever a shadow was: the maps do cast them.
    let unshadowed = zbuffer(&s, ZBuffer { shadows: false, ..Default::default() }, 16);
    assert!(unshadowed.mean().mean() > 1.02 * fine.mean().mean());
}

/// On a plane lit by a directional light with a Lambertian BSDF the radiance is constant:
/// flat, Gouraud and Phong shading agree; with a point light and a glossy wall they differ
/// (Gouraud misses highlights inside big triangles), and Phong is the one that matches.
#[test]
fn shading_modes() {
    let mut b = SceneBuilder::new();
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 6.0), Vec3::new(6.0, 0.0, 0.0)), diffuse(Rgb::splat(0.5)), None, "floor");
    b.add_light(Light::Directional { direction: Vec3::new(0.2, -1.0, 0.1).normalize(), irradiance: Rgb::splat(1.0) });
    b.set_camera(camera(look_at(Vec3::new(0.0, 2.0, 4.0), Vec3::ZERO, Vec3::Y), 40.0, 32, 24));
    let s = b.build().expect("scene");
    let modes = [Shading::Flat, Shading::Gouraud, Shading::Phong];
    let imgs: Vec<_> = modes.iter().map(|&m| zbuffer(&s, ZBuffer { shading: m, ambient: Rgb::splat(0.1), ..Default::default() }, 4)).collect();
    let expect = 0.5 / std::f32::consts::PI * (1.0 / (1.0 + 0.04 + 0.01f32).sqrt()) + 0.1 * 0.5;
    for (m, img) in modes.iter().zip(&imgs) {
        let centre = img.data[(12 * 32 + 16) as usize];
        assert!((centre.g - expect).abs() < 1e-4, "{m:?}: {} vs {expect}", centre.g);
    }
    let s = scene(false);
    let w = render(&s, "whitted", 64, 2, 3);
    let g = zbuffer(&s, ZBuffer { shading: Shading::Gouraud, ..Default::default() }, 16);
    let p = zbuffer(&s, ZBuffer::default(), 16);
    let (fg, _) = disagreement(&g, &w);
    let (fp, _) = disagreement(&p, &w);
    eprintln!("gouraud {:.1} % vs phong {:.1} % pixels differ from the ray-cast image", 100.0 * fg, 100.0 * fp);
    assert!(fg > 0.2 && fp < 0.005);
}

/// Frames per second on the bundled Cornell box at 512² (one core, 1 sample per pixel,
/// shadow maps 1024). Run with --ignored --nocapture.
#[test]
#[ignore]
fn bench_cornell_box() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let mut s = svetlo::io::load_scene(&path, &[("resx".into(), "512".into()), ("resy".into(), "512".into())]).expect("scene");
    s.camera.width = 512;
    s.camera.height = 512;
    let settings = RenderSettings { spp: 1, threads: 1, ..Default::default() };
    let z = ZBuffer::default();
    let mut times = Vec::new();
    for _ in 0..5 {
        let t = std::time::Instant::now();
        z.render(&s, &settings, &Progress::new()).expect("render");
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    eprintln!("zbuffer cornell 512²: median {:.1} ms/frame ({} triangles)", 1e3 * times[2], s.shapes.len());
}
