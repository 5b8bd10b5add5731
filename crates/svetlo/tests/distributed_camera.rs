//! Distributed ray tracing's camera integrals against closed forms (issue 5): depth of field
//! of the thin lens, and anti-aliasing by stratified pixel samples.
//!
//! The camera looks down +z at a large emitting half-plane (max_depth 1: the image is the
//! emitter's radiance times the fraction of the pixel's and lens's rays that hit it).
//! - Depth of field: a ray through film point c (on the plane z = 1) and lens point l, focused
//!   at distance f, meets the plane z = d at c d + l (1 - d / f). So the edge x = 0 at depth d
//!   is blurred by the lens disc scaled by R |1/d - 1/f| in film units: a pixel sees the
//!   fraction G(-c.x / s) of it, s = R (1/d - 1/f), G(a) = (acos a - a sqrt(1 - a²)) / π the
//!   part of the unit disc with x > a; averaged over the pixel. In focus (d = f) the edge is sharp.
//! - Anti-aliasing: with a pinhole, a pixel's value is the exact area of the pixel on the
//!   emitting side of a tilted edge. Independent samples have squared error p (1 - p) / N
//!   per pixel; stratified (Sobol) samples must do much better.

mod classic_scenes;

use classic_scenes::*;
use glam::{Mat4, Vec2};
use svetlo::camera::{Camera, Projection};
use svetlo::film::{Film, Filter};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::Rgb;

const LE: f32 = 2.0;
const W: u32 = 64;
const H: u32 = 8;

/// The half-plane `n · (x, y) > 0` at depth `d`, emitting toward the camera at the origin.
fn edge_scene(d: f32, n: Vec2, projection: Projection, height: u32) -> Scene {
    let mut b = SceneBuilder::new();
    // A big quad on the emitting side: corners along the edge direction t and inward n.
    let t = Vec2::new(-n.y, n.x);
    let big = 100.0;
    let (c, a, e) = ((-big * t).extend(d), (2.0 * big * t).extend(0.0), (big * n).extend(0.0));
    // Normal a x e must face the camera (-z).
    let (a, e) = if a.cross(e).z < 0.0 { (a, e) } else { (e, a) };
    add(&mut b, quad(c, a, e), diffuse(Rgb::BLACK), Some(Rgb::splat(LE)), "edge");
    b.set_camera(Camera { to_world: Mat4::IDENTITY, projection, width: W, height, near_clip: 1e-3, far_clip: 1e4, shutter_open: 0.0, shutter_close: 0.0 });
    b.build().expect("scene")
}

/// A render with the independent sampler (`distributed` switches it to Sobol itself).
fn render_with(scene: &Scene, name: &str, spp: u32, seed: u64) -> Film {
    let settings = RenderSettings { spp, max_depth: 1, seed, filter: Filter::Box, sampler: svetlo::sampling::SamplerKind::Independent, ..Default::default() };
    svetlo::methods::by_name(name).expect("integrator").render(scene, &settings, &Progress::new()).expect("render")
}

/// Part of the unit disc with x > a.
fn disc_beyond(a: f64) -> f64 {
    let a = a.clamp(-1.0, 1.0);
    (a.acos() - a * (1.0 - a * a).sqrt()) / std::f64::consts::PI
}

/// Z-test of each pixel of `film` (green channel) against `expected`; Šidák over the pixels.
fn z_failures(label: &str, film: &Film, expected: &[f64]) -> usize {
    let (img, var) = (film.image(), film.variance_image());
    let level = svetlo::sampling::stats::sidak_alpha(0.01, expected.len());
    let mut failed = 0;
    for (i, &e) in expected.iter().enumerate() {
        let (v, s2) = (img.data[i].g as f64, var.data[i].g as f64 / film.spp_done as f64);
        let ok = if s2 <= 1e-12 {
            // Every sample alike (all hit or all missed): as likely as that is for
            // independent samples of a pixel covered by the fraction p (stratified ones make
            // it rarer still, so this is conservative).
            let (p, n) = (e / LE as f64, film.spp_done as i32);
            let chance = if (v - LE as f64).abs() < 1e-4 {
                p.powi(n)
            } else if v.abs() < 1e-6 {
                (1.0 - p).powi(n)
            } else {
                0.0
            };
            chance >= level
        } else {
            svetlo::sampling::stats::two_sided_p((v - e).abs() / s2.sqrt()) >= level
        };
        if !ok {
            failed += 1;
            eprintln!("{label}: pixel {} ({}, {}): {v} vs {e} (sd {})", i, i as u32 % W, i as u32 / W, s2.sqrt());
        }
    }
    failed
}

#[test]
fn thin_lens_blur_matches_the_circle_of_confusion() {
    let (fov, radius, focus) = (30.0f32, 0.2f32, 4.0f32);
    let half_x = (0.5 * fov.to_radians()).tan() as f64;
    let projection = Projection::Perspective { fov_x_deg: fov, aperture_radius: radius, focus_distance: focus };
    for (d, label) in [(2.5f32, "in front of the focus"), (focus, "in focus"), (9.0, "behind the focus")] {
        let scene = edge_scene(d, Vec2::X, projection, H);
        let film = render_with(&scene, "distributed", 256, 3);
        let s = radius as f64 * (1.0 / d as f64 - 1.0 / focus as f64);
        // c.x = (1 - 2 rx / W) half_x, averaged over the pixel's rx by the midpoint rule.
        let expected: Vec<f64> = (0..W * H)
            .map(|i| {
                let px = (i % W) as f64;
                let m = 4000;
                let sum: f64 = (0..m)
                    .map(|k| {
                        let cx = (1.0 - 2.0 * (px + (k as f64 + 0.5) / m as f64) / W as f64) * half_x;
                        if s == 0.0 {
                            f64::from(u8::from(cx > 0.0))
                        } else if s > 0.0 {
                            disc_beyond(-cx / s)
                        } else {
                            1.0 - disc_beyond(-cx / s)
                        }
                    })
                    .sum();
                LE as f64 * sum / m as f64
            })
            .collect();
        let blurred = expected.iter().filter(|&&e| e > 1e-3 * LE as f64 && e < 0.999 * LE as f64).count() / H as usize;
        eprintln!("{label} (d = {d}): {blurred} partially covered columns");
        assert_eq!(z_failures(label, &film, &expected), 0, "{label}");
        if d == focus {
            assert!(blurred <= 1);
        } else {
            assert!(blurred >= 4, "{label}: the blur is too narrow to test ({blurred} columns)");
        }
    }
}

/// Area of the unit pixel square at (px, py) where a x + b y + c > 0 (raster coordinates).
fn covered(px: f64, py: f64, (a, b, c): (f64, f64, f64)) -> f64 {
    let sq = [(px, py), (px + 1.0, py), (px + 1.0, py + 1.0), (px, py + 1.0)];
    let f = |p: (f64, f64)| a * p.0 + b * p.1 + c;
    let mut poly = Vec::new();
    for i in 0..4 {
        let (p, q) = (sq[i], sq[(i + 1) % 4]);
        let (fp, fq) = (f(p), f(q));
        if fp > 0.0 {
            poly.push(p);
        }
        if (fp > 0.0) != (fq > 0.0) {
            let t = fp / (fp - fq);
            poly.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
        }
    }
    let n = poly.len();
    (0..n).map(|i| poly[i].0 * poly[(i + 1) % n].1 - poly[(i + 1) % n].0 * poly[i].1).sum::<f64>().abs() / 2.0
}

#[test]
fn stratified_pixel_samples_beat_independent_ones() {
    let fov = 30.0f32;
    let n = Vec2::new(1.0, 0.37).normalize();
    // Tall enough that the edge crosses many pixels (the squared errors average out).
    let h = 48;
    let scene = edge_scene(3.0, n, Projection::Perspective { fov_x_deg: fov, aperture_radius: 0.0, focus_distance: 1.0 }, h);
    let half = scene.camera.film_half_extent().as_dvec2();
    // n · c > 0 with c = (1 - 2 r / size) half: linear in the raster position r.
    let (nx, ny) = (n.x as f64, n.y as f64);
    let line = (-2.0 * nx * half.x / W as f64, -2.0 * ny * half.y / h as f64, nx * half.x + ny * half.y);
    let expected: Vec<f64> = (0..W * h).map(|i| LE as f64 * covered((i % W) as f64, (i / W) as f64, line)).collect();
    let spp = 64;
    let sobol = render_with(&scene, "distributed", spp, 5);
    assert_eq!(z_failures("distributed", &sobol, &expected), 0);
    let independent = render_with(&scene, "path", spp, 6);
    assert_eq!(z_failures("path", &independent, &expected), 0);
    let mse = |f: &Film| f.image().data.iter().zip(&expected).map(|(v, e)| (v.g as f64 - e).powi(2)).sum::<f64>();
    // What independent sampling gives on average: Le² p (1 - p) / N per pixel.
    let iid: f64 = expected.iter().map(|e| e * (LE as f64 - e) / spp as f64).sum();
    let (ms, mi) = (mse(&sobol), mse(&independent));
    eprintln!("squared error: stratified {ms:.3e}, independent {mi:.3e}, independent expected {iid:.3e}");
    assert!(iid > 0.0);
    assert!(ms < 0.25 * iid, "stratified pixel samples are not better than independent ones ({ms} vs {iid})");
    assert!(mi > 0.4 * iid, "the independent render is implausibly good ({mi} vs {iid})");
}
