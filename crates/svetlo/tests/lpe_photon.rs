//! Light path expressions on the photon methods (`photon`, `sppm`): photons carry their light
//! subpath's events as a reverse-automaton state, and each density estimate is split by photon
//! into the layers its whole path (camera prefix, lookup point, photon path) matches.
//!
//! - White furnace (closed Lambertian sphere, ρ = 0.5, emitting 1 inward), where the photon
//!   estimators carry no blur bias (uniform radiance): the AOVs `C L`, `C D L`, `C D D L` and
//!   `C D D D+ L` are 1, ρ, ρ² and ρ³/(1 − ρ) in closed form. Per pixel, over independent
//!   renders (seeds), each method's AOV is Z-tested against that value and against the same AOV
//!   of the path tracer (variances pooled over the pixels, which the furnace makes
//!   exchangeable; Šidák over pixels, AOVs and methods, family level 1e-3).
//! - The caustic scene: the AOVs of a partition of path space sum to the beauty, `--lpe`
//!   restricts the beauty to its AOV, and AOVs leave the beauty as it was.

mod common;

use common::lpe::{aovs, assert_close, render, repo_scene, sum};
use glam::{Mat4, Vec3};
use svetlo::bsdf::Material;
use svetlo::camera::Camera;
use svetlo::film::{Film, Image};
use svetlo::geometry::{Geometry, Sphere};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::sampling::stats::two_sided_p;
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::texture::Texture;
use svetlo::Rgb;

fn furnace(rho: f32) -> Scene {
    let mut b = SceneBuilder::new();
    let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(rho)) });
    let s = Sphere { center: Vec3::ZERO, radius: 1.0, flip_normals: true };
    b.add_shape(Geometry::Sphere(s), m, Some(Texture::Constant(Rgb::WHITE)), "furnace").expect("shape");
    b.set_camera(Camera::pinhole(Mat4::IDENTITY, 60.0, 8, 8));
    b.build().expect("scene")
}

const FURNACE_AOVS: &[(&str, &str)] = &[("emit", "C L"), ("d1", "C D L"), ("d2", "C D D L"), ("dmore", "C D D D+ L")];

/// Per AOV of `FURNACE_AOVS`, per pixel (red channel; the furnace is grey): the mean over
/// `seeds` renders and the variance of one render, pooled over the pixels.
fn furnace_stats(scene: &Scene, method: &str, spp: u32, max_depth: i32, seeds: u64) -> Vec<(Vec<f64>, f64)> {
    let set = aovs(scene, FURNACE_AOVS, None);
    let films: Vec<Film> = (0..seeds).map(|s| render(scene, method, spp, max_depth, 500 + s, Some(set.clone()))).collect();
    for f in &films {
        let layers: Vec<Image> = f.layer_images().into_iter().map(|(_, i)| i).collect();
        assert_close(&sum(&layers), &f.image(), &format!("{method}: the furnace's AOVs partition its paths"));
    }
    FURNACE_AOVS
        .iter()
        .map(|(name, _)| {
            let px: Vec<Vec<f64>> = films.iter().map(|f| f.layer(name).expect("layer").data.iter().map(|c| c.r as f64).collect()).collect();
            let n = px[0].len();
            let means: Vec<f64> = (0..n).map(|i| px.iter().map(|p| p[i]).sum::<f64>() / seeds as f64).collect();
            let ss: f64 = (0..n).map(|i| px.iter().map(|p| (p[i] - means[i]).powi(2)).sum::<f64>()).sum();
            (means, ss / (n as f64 * (seeds - 1) as f64))
        })
        .collect()
}

/// Two means of `k1` and `k2` renders with per-render variances `v1`, `v2`, by a Z-test on
/// their difference beyond f32 rounding (relative 1e-4: the path tracer's `C D L` in the
/// furnace is nearly noise-free, its spread 1e-5 relative).
fn z_ok(m1: f64, v1: f64, k1: f64, m2: f64, v2: f64, k2: f64, level: f64) -> bool {
    let d = (m1 - m2).abs() - (1e-4 * m1.abs().max(m2.abs()) + 1e-6);
    let var = v1 / k1 + v2 / k2;
    d <= 0.0 || (var > 0.0 && two_sided_p(d / var.sqrt()) >= level)
}

#[test]
fn photon_aovs_in_the_furnace_match_closed_form_and_the_path_tracer() {
    let scene = furnace(0.5);
    let expected = [1.0, 0.5, 0.25, 0.25];
    let seeds = 10u64;
    let path = furnace_stats(&scene, "path", 16, -1, seeds);
    let methods: &[(&str, u32)] = &[
        ("photon:photons=5000,caustic-photons=1000,gather=4,k=16", 2),
        ("photon:photons=5000,caustic-photons=1000,gather=0,k=16", 2),
        ("sppm:photons=4000", 64),
    ];
    let pixels = path[0].0.len();
    // Šidák: every pixel of every AOV, against the closed form and the path tracer, per method
    // and for the path tracer itself.
    let tests = (pixels * FURNACE_AOVS.len() * (2 * methods.len() + 1)) as f64;
    let level = 1.0 - (1.0f64 - 1e-3).powf(1.0 / tests);
    for (a, ((pm, pv), want)) in path.iter().zip(expected).enumerate() {
        let bad = pm.iter().filter(|&&m| !z_ok(m, *pv, seeds as f64, want, 0.0, 1.0, level)).count();
        assert_eq!(bad, 0, "path AOV {}: {bad} pixels off {want}", FURNACE_AOVS[a].1);
    }
    for &(method, spp) in methods {
        let st = furnace_stats(&scene, method, spp, -1, seeds);
        for (a, ((mm, mv), ((pm, pv), want))) in st.iter().zip(path.iter().zip(expected)).enumerate() {
            let mean = mm.iter().sum::<f64>() / mm.len() as f64;
            eprintln!("{method} {}: mean {mean:.4} (expected {want}), per-render sd {:.2e}", FURNACE_AOVS[a].1, mv.sqrt());
            assert!(mean > 0.0, "{method} {}: empty", FURNACE_AOVS[a].1);
            let off_closed = mm.iter().filter(|&&m| !z_ok(m, *mv, seeds as f64, want, 0.0, 1.0, level)).count();
            assert_eq!(off_closed, 0, "{method} AOV {}: {off_closed} pixels off the closed form {want}", FURNACE_AOVS[a].1);
            let off_path = mm.iter().zip(pm).filter(|(&m, &p)| !z_ok(m, *mv, seeds as f64, p, *pv, seeds as f64, level)).count();
            assert_eq!(off_path, 0, "{method} AOV {}: {off_path} pixels differ from the path tracer's", FURNACE_AOVS[a].1);
        }
    }
}

/// max_depth 3 leaves paths of at most two bounces: photons must not bring `C D D D+ L`.
#[test]
fn photon_aovs_respect_max_depth() {
    let scene = furnace(0.5);
    let set = aovs(&scene, FURNACE_AOVS, None);
    for method in ["photon:photons=3000,caustic-photons=500,gather=2,k=16", "photon:photons=3000,caustic-photons=500,gather=0,k=16", "sppm:photons=2000"] {
        let f = render(&scene, method, 4, 3, 9, Some(set.clone()));
        assert!(f.layer("d2").expect("layer").mean().mean() > 0.1, "{method}: C D D L empty");
        assert!(f.layer("dmore").expect("layer").data.iter().all(|c| c.is_black()), "{method}: three bounces at max_depth 3");
    }
}

const PARTITION: &[(&str, &str)] =
    &[("emit", "C [LB]"), ("d1", "C D [LB]"), ("dmore", "C D [^LB]+ [LB]"), ("spec", "C [GS] .* [LB]"), ("caustic", "C D S+ [LB]")];

const PHOTON_METHODS: &[&str] =
    &["photon:photons=4000,caustic-photons=4000,gather=2,precompute=0", "photon:photons=4000,caustic-photons=4000,gather=0", "sppm:photons=2000"];

/// The caustic scene (diffuse floor and wall, glass sphere): a partition's AOVs sum to the
/// beauty, the caustic (`C D S+ L`: the caustic map, and photons through the glass) is not
/// empty, and the AOVs leave the beauty unchanged.
#[test]
fn photon_partition_sums_to_the_beauty() {
    let scene = repo_scene("caustic.xml", 16);
    let set = aovs(&scene, PARTITION, None);
    for &method in PHOTON_METHODS {
        let film = render(&scene, method, 2, 8, 3, Some(set.clone()));
        let layers: Vec<Image> = film.layer_images().into_iter().map(|(_, i)| i).collect();
        assert!(layers[1].mean().max_component() > 0.0 && layers[2].mean().max_component() > 0.0, "{method}: diffuse layers empty");
        assert!(layers[4].mean().max_component() > 0.0, "{method}: no caustic");
        assert_close(&sum(&layers[..4]), &film.image(), method);
        let plain = render(&scene, method, 2, 8, 3, None);
        assert_close(&film.image(), &plain.image(), &format!("{method}: AOVs changed the beauty"));
    }
}

/// `--lpe` restricts the beauty to the paths of its AOV.
#[test]
fn photon_restricted_beauty_equals_its_aov() {
    let scene = repo_scene("caustic.xml", 12);
    let set = aovs(&scene, &[("indirect", "L .+ D E")], Some("C D .+ L"));
    for &method in PHOTON_METHODS {
        let film = render(&scene, method, 2, 6, 2, Some(set.clone()));
        assert!(film.image().mean().max_component() > 0.0, "{method}");
        assert_close(&film.image(), &film.layer("indirect").expect("layer"), method);
    }
}

/// Same image and layers whatever the thread count.
#[test]
fn photon_aovs_do_not_depend_on_threads() {
    let scene = repo_scene("caustic.xml", 12);
    let set = aovs(&scene, PARTITION, None);
    for &method in PHOTON_METHODS {
        let run = |threads| {
            let s = RenderSettings { spp: 2, max_depth: 6, seed: 4, threads, lpe: Some(set.clone()), ..Default::default() };
            svetlo::methods::by_name(method).unwrap().render(&scene, &s, &Progress::new()).unwrap()
        };
        let (a, b) = (run(1), run(3));
        for ((_, x), (_, y)) in a.layer_images().into_iter().zip(b.layer_images()) {
            assert!(x.data.iter().zip(&y.data).all(|(p, q)| p.to_array() == q.to_array()), "{method}");
        }
    }
}
