//! The classic pipeline's speed (issue 5): frames per second of the Z-buffer rasteriser on
//! the Cornell box and on a generated 1M-triangle mesh, one thread, and the time per sample
//! per pixel of `whitted` and `distributed` against `path` on the Cornell box.
//!
//! cargo run --release --example classic_bench -- [--res 512] [--frames 30] [--ss 1]
//!     [--subdiv 289] [--mc-res 256] [--mc-spp 4] [--skip mesh,mc]
//!
//! The Z-buffer is timed as an interactive program runs it: `prepare` once (triangles,
//! shadow maps), then `frame` per frame (transform, rasterise, shade the visible
//! subsamples, resolve); the median frame time is reported, and its two parts: visibility
//! (transform, rasterise, depth test) and shading (+ resolve). Prints one JSON object a line.

use std::path::Path;
use std::time::Instant;
use svetlo::geometry::{Geometry, TriangleMesh};
use svetlo::integrator::zbuffer::ZBuffer;
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::light::Light;
use svetlo::math::Vec3;
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::texture::Texture;
use svetlo::Rgb;

struct Args {
    res: u32,
    frames: usize,
    ss: u32,
    subdiv: usize,
    mc_res: u32,
    mc_spp: u32,
    skip: Vec<String>,
}

fn parse_args() -> Args {
    let mut a = Args { res: 512, frames: 30, ss: 1, subdiv: 289, mc_res: 256, mc_spp: 4, skip: Vec::new() };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().unwrap_or_else(|| panic!("{k} needs a value"));
        match k.as_str() {
            "--res" => a.res = val().parse().expect("--res N"),
            "--frames" => a.frames = val().parse().expect("--frames N"),
            "--ss" => a.ss = val().parse().expect("--ss N"),
            "--subdiv" => a.subdiv = val().parse().expect("--subdiv N"),
            "--mc-res" => a.mc_res = val().parse().expect("--mc-res N"),
            "--mc-spp" => a.mc_spp = val().parse().expect("--mc-spp N"),
            "--skip" => a.skip = val().split(',').map(str::to_string).collect(),
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

fn cornell(res: u32) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    svetlo::io::load_scene(&path, &[("res".into(), res.to_string())]).expect("scenes/cornell-box.xml")
}

/// A unit sphere of 12 n² triangles (a cube's faces projected), with bumps.
fn bumpy_sphere(n: usize) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    for (normal, u, v) in faces {
        let base = m.positions.len() as u32;
        for i in 0..=n {
            for j in 0..=n {
                let (s, t) = (2.0 * i as f32 / n as f32 - 1.0, 2.0 * j as f32 / n as f32 - 1.0);
                let p = (normal + s * u + t * v).normalize();
                let bump = 0.04 * ((9.0 * p.x).sin() * (11.0 * p.y).sin() * (7.0 * p.z).sin());
                m.positions.push(p * (1.0 + bump));
            }
        }
        let idx = |i: usize, j: usize| base + (i * (n + 1) + j) as u32;
        for i in 0..n {
            for j in 0..n {
                m.indices.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
                m.indices.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
            }
        }
    }
    svetlo::io::mesh_files::compute_vertex_normals(&mut m);
    m
}

/// The bumpy sphere on a floor, lit by a point light (a cube shadow map) and a directional one.
fn mesh_scene(res: u32, subdiv: usize) -> Scene {
    let mut b = SceneBuilder::new();
    let grey = b.add_material(svetlo::bsdf::Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.6)) });
    let blinn = b.add_material(svetlo::bsdf::Material::BlinnPhong {
        diffuse_reflectance: Texture::Constant(Rgb::new(0.5, 0.3, 0.2)),
        specular_reflectance: Texture::Constant(Rgb::splat(0.3)),
        exponent: Texture::Constant(Rgb::splat(40.0)),
    });
    let (c, a, d) = (Vec3::new(-4.0, -1.0, -4.0), Vec3::new(0.0, 0.0, 8.0), Vec3::new(8.0, 0.0, 0.0));
    let floor = TriangleMesh { positions: vec![c, c + a, c + a + d, c + d], normals: vec![], uvs: vec![], indices: vec![[0, 1, 2], [0, 2, 3]] };
    b.add_shape(Geometry::Mesh(floor), grey, None, "floor").expect("floor");
    b.add_shape(Geometry::Mesh(bumpy_sphere(subdiv)), blinn, None, "mesh").expect("mesh");
    b.add_light(Light::Point { position: Vec3::new(2.0, 4.0, 3.0), intensity: Rgb::splat(30.0) });
    b.add_light(Light::Directional { direction: Vec3::new(-0.3, -1.0, -0.2).normalize(), irradiance: Rgb::splat(0.5) });
    let to_world = svetlo::io::mitsuba::look_at(Vec3::new(0.0, 1.0, 4.0), Vec3::ZERO, Vec3::Y).expect("look-at");
    b.set_camera(svetlo::camera::Camera {
        to_world,
        projection: svetlo::camera::Projection::Perspective { fov_x_deg: 45.0, aperture_radius: 0.0, focus_distance: 1.0 },
        width: res,
        height: res,
        near_clip: 1e-2,
        far_clip: 1e4,
        shutter_open: 0.0,
        shutter_close: 0.0,
    });
    b.build().expect("mesh scene")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn bench_zbuffer(label: &str, scene: &Scene, args: &Args) {
    let z = ZBuffer::default();
    let t0 = Instant::now();
    let prepared = z.prepare(scene);
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (mut times, mut vis, mut shade) = (Vec::new(), Vec::new(), Vec::new());
    let mut mean = 0.0;
    for _ in 0..args.frames.max(1) {
        let t = Instant::now();
        let f = prepared.frame(scene, &scene.camera, args.ss, false, 1).expect("frame");
        times.push(t.elapsed().as_secs_f64() * 1e3);
        vis.push(f.visibility_time.as_secs_f64() * 1e3);
        shade.push(f.shading_time.as_secs_f64() * 1e3);
        mean = f.image.mean().mean();
    }
    let ms = median(times);
    let (vis, shade) = (median(vis), median(shade));
    println!(
        "{{\"bench\": \"zbuffer\", \"scene\": \"{label}\", \"triangles\": {}, \"res\": {}, \"ss\": {}, \"threads\": 1, \"prepare_ms\": {prepare_ms:.1}, \"frame_ms\": {ms:.2}, \"visibility_ms\": {vis:.2}, \"shading_ms\": {shade:.2}, \"fps\": {:.1}, \"image_mean\": {mean:.4}}}",
        prepared.triangle_count(),
        scene.camera.width,
        args.ss,
        1e3 / ms
    );
}

fn bench_mc(scene: &Scene, args: &Args) {
    let mut path_ms = 0.0;
    for name in ["path", "whitted", "distributed"] {
        let settings = RenderSettings { spp: args.mc_spp, threads: 1, max_depth: if name == "whitted" { 6 } else { -1 }, seed: 1, ..Default::default() };
        let integrator = svetlo::methods::by_name(name).expect("integrator");
        let t = Instant::now();
        let film = integrator.render(scene, &settings, &Progress::new()).expect("render");
        let ms = t.elapsed().as_secs_f64() * 1e3 / film.spp_done as f64;
        if name == "path" {
            path_ms = ms;
        }
        println!(
            "{{\"bench\": \"mc\", \"integrator\": \"{name}\", \"res\": {}, \"spp\": {}, \"threads\": 1, \"ms_per_spp\": {ms:.1}, \"relative_to_path\": {:.3}}}",
            scene.camera.width,
            film.spp_done,
            ms / path_ms
        );
    }
}

fn main() {
    let args = parse_args();
    let skip = |s: &str| args.skip.iter().any(|k| k == s);
    bench_zbuffer("cornell-box", &cornell(args.res), &args);
    if !skip("mesh") {
        let t = Instant::now();
        let scene = mesh_scene(args.res, args.subdiv);
        eprintln!("mesh scene built in {:.1} s", t.elapsed().as_secs_f64());
        bench_zbuffer("bumpy-sphere", &scene, &args);
    }
    if !skip("mc") {
        bench_mc(&cornell(args.mc_res), &args);
    }
}
