//! Light path expressions on real renders: AOVs that partition path space sum to the beauty;
//! `C .{k} L` is the difference of renders at max depth k + 1 and k; the same AOV agrees
//! between integrators; `--lpe` restricts the beauty; layers survive a multi-layer EXR; the
//! image does not depend on the thread count.
//!
//! Scenes: `scenes/caustic.xml` of this repository (diffuse floor and wall, a glass sphere,
//! a small spherical light), rendered small.

mod common;

use common::lpe::{aovs, assert_close, repo_scene, sum};
use std::sync::Arc;
use svetlo::film::{Film, Image};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::lpe::AovSet;
use svetlo::scene::Scene;

fn caustic(res: u32) -> Scene {
    repo_scene("caustic.xml", res)
}

fn render(scene: &Scene, method: &str, s: &RenderSettings) -> Film {
    svetlo::methods::by_name(method).expect("method").render(scene, s, &Progress::new()).expect("render")
}

fn settings(spp: u32, max_depth: i32, seed: u64, set: Option<Arc<AovSet>>) -> RenderSettings {
    RenderSettings { spp, max_depth, seed, threads: 2, lpe: set, ..Default::default() }
}

/// A partition of all paths: by the first scattering event (none, diffuse and then the
/// emitter, diffuse and more, glossy or singular and anything).
const PARTITION: &[(&str, &str)] = &[("emit", "C [LB]"), ("d1", "C D [LB]"), ("dmore", "C D [^LB]+ [LB]"), ("spec", "C [GS] .* [LB]")];

#[test]
fn partition_aovs_sum_to_the_beauty() {
    let scene = caustic(20);
    let set = aovs(&scene, PARTITION, None);
    for method in ["path", "light", "bdpt"] {
        let film = render(&scene, method, &settings(4, 6, 3, Some(set.clone())));
        let layers: Vec<Image> = film.layer_images().into_iter().map(|(_, i)| i).collect();
        assert_eq!(layers.len(), PARTITION.len());
        let beauty = film.image();
        assert!(beauty.mean().max_component() > 0.0);
        // The diffuse classes hold something on this scene (the camera does not see the
        // light, and light tracing cannot see C S ... paths).
        for (i, l) in layers.iter().enumerate() {
            if PARTITION[i].0.starts_with('d') {
                assert!(l.mean().max_component() > 0.0, "{method}: AOV {} is empty", PARTITION[i].0);
            }
        }
        assert_close(&sum(&layers), &beauty, method);
    }
}

/// The same render with and without AOVs has the same beauty (AOVs only observe), and the
/// path tracer's eight-wide kernel and its scalar tracer agree on it up to rounding.
#[test]
fn aovs_do_not_change_the_beauty() {
    let scene = caustic(16);
    let set = aovs(&scene, PARTITION, None);
    for method in ["path", "light", "bdpt"] {
        let with = render(&scene, method, &settings(3, 5, 7, Some(set.clone()))).image();
        let without = render(&scene, method, &settings(3, 5, 7, None)).image();
        assert_close(&with, &without, method);
    }
}

/// `--lpe` restricts the beauty: the restricted beauty equals the AOV of the same expression.
#[test]
fn restricted_beauty_equals_its_aov() {
    let scene = caustic(16);
    for method in ["path", "light", "bdpt"] {
        let set = aovs(&scene, &[("direct", "L D E")], Some("C D L"));
        let film = render(&scene, method, &settings(3, 5, 2, Some(set)));
        let b = film.image();
        assert!(b.mean().max_component() > 0.0);
        assert_close(&b, &film.layer("direct").expect("layer"), method);
    }
}

/// The path tracer with the same seed at max depth k + 1 and k draws the same random
/// numbers up to the k-th vertex, so their difference is exactly the paths of k + 1
/// segments: the AOV `C .{k} [LB]`.
#[test]
fn depth_identity_path() {
    let scene = caustic(16);
    for k in 1..=3 {
        let expr = format!("C .{{{k}}} [LB]");
        let set = aovs(&scene, &[("k", &expr)], None);
        let film = render(&scene, "path", &settings(4, k + 1, 5, Some(set)));
        let hi = film.image();
        let lo = render(&scene, "path", &settings(4, k, 5, None)).image();
        let mut diff = hi.clone();
        for (d, l) in diff.data.iter_mut().zip(&lo.data) {
            *d -= *l;
        }
        assert_close(&film.layer("k").expect("layer"), &diff, &expr);
    }
}

/// Image means over K seeds: (mean, standard error).
fn mean_se(vals: &[f64]) -> (f64, f64) {
    let k = vals.len() as f64;
    let m = vals.iter().sum::<f64>() / k;
    let v = vals.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (k - 1.0);
    (m, (v / k).sqrt())
}

/// For light and BDPT the depth identity holds in expectation: the AOV `C .{k} [LB]` and the
/// difference of renders at depth k + 1 and k (independent seeds) have equal image means
/// within 5 standard errors over 6 batches.
#[test]
fn depth_identity_light_and_bdpt() {
    let scene = caustic(12);
    let k = 2;
    let set = aovs(&scene, &[("k", "C .{2} [LB]")], None);
    for method in ["light", "bdpt"] {
        let (mut a, mut d) = (Vec::new(), Vec::new());
        for b in 0..6u64 {
            let f = render(&scene, method, &settings(8, k + 1, 100 + b, Some(set.clone())));
            a.push(f.layer("k").expect("layer").mean().mean() as f64);
            let hi = render(&scene, method, &settings(8, k + 1, 200 + b, None)).image().mean().mean() as f64;
            let lo = render(&scene, method, &settings(8, k, 300 + b, None)).image().mean().mean() as f64;
            d.push(hi - lo);
        }
        let ((ma, sa), (md, sd)) = (mean_se(&a), mean_se(&d));
        assert!(ma > 0.0);
        let z = (ma - md) / (sa * sa + sd * sd).sqrt();
        assert!(z.abs() < 5.0, "{method}: AOV {ma} +- {sa} vs difference {md} +- {sd} (z = {z})");
    }
}

/// One AOV from path, light and BDPT agrees (image means within 5 standard errors over 6
/// batches): the caustic seen on the floor and the paths seen on a diffuse surface that
/// reach the light from a non-singular one.
#[test]
fn aov_agrees_across_integrators() {
    let scene = caustic(12);
    // The path tracer rarely finds the small light through the glass, so paths that reach it
    // right after a singular event (caustics) make its estimate heavy-tailed: its batch means
    // fall short (by the caustic's 0.01 of 0.26, z ~ -4 under independent sampling, -8 under
    // Sobol, whose error bars are narrower). The caustic is compared between the methods that
    // trace from the light, and all three compare the paths whose last scattering before the
    // light is not singular, which the path tracer reaches by light sampling.
    let set = aovs(&scene, &[("caustic", "C D S+ L"), ("diffuse_nee", "C D (.* [DG])? L")], None);
    for (aov, methods) in [("caustic", &["light", "bdpt"][..]), ("diffuse_nee", &["path", "light", "bdpt"][..])] {
        let mut res = Vec::new();
        for &method in methods {
            let v: Vec<f64> =
                (0..6u64).map(|b| render(&scene, method, &settings(8, 8, 40 + b, Some(set.clone()))).layer(aov).expect("layer").mean().mean() as f64).collect();
            res.push((method, mean_se(&v)));
        }
        println!("{aov}: {res:?}");
        for i in 0..res.len() {
            for j in i + 1..res.len() {
                let ((a, (ma, sa)), (b, (mb, sb))) = (res[i], res[j]);
                let z = (ma - mb) / (sa * sa + sb * sb).sqrt();
                assert!(z.abs() < 5.0, "{aov}: {a} {ma} +- {sa} vs {b} {mb} +- {sb} (z = {z})");
            }
        }
    }
}

#[test]
fn same_layers_whatever_the_thread_count() {
    let scene = caustic(16);
    let set = aovs(&scene, PARTITION, None);
    for method in ["path", "bdpt"] {
        let mut s = settings(3, 5, 9, Some(set.clone()));
        s.threads = 1;
        let one = render(&scene, method, &s);
        s.threads = 3;
        let three = render(&scene, method, &s);
        for ((_, a), (_, b)) in one.layer_images().iter().zip(three.layer_images().iter()) {
            assert_eq!(a.data, b.data, "{method}");
        }
    }
}

#[test]
fn layers_round_trip_through_a_multilayer_exr() {
    let scene = caustic(12);
    let set = aovs(&scene, PARTITION, None);
    let film = render(&scene, "path", &settings(2, 5, 1, Some(set)));
    let dir = std::env::temp_dir().join(format!("svetlo-lpe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("layers.exr");
    svetlo::io::image_io::write_exr_layers(&p, &film.image(), &film.layer_images()).unwrap();
    let ch = svetlo::io::image_io::read_exr_channels(&p).unwrap();
    let names: Vec<&str> = ch.iter().map(|(n, _)| n.as_str()).collect();
    for n in ["R", "G", "B", "d1.R", "d1.G", "d1.B", "spec.B", "emit.R", "dmore.G"] {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
    let d1 = film.layer("d1").unwrap();
    let got = &ch.iter().find(|(n, _)| n == "d1.G").unwrap().1;
    assert_eq!(got.len(), d1.data.len());
    for (g, want) in got.iter().zip(&d1.data) {
        assert_eq!(*g, want.g);
    }
    // The beauty reads back as an ordinary RGB image.
    let back = svetlo::io::read_image(&p).unwrap();
    assert_eq!(back.data, film.image().data);
    std::fs::remove_dir_all(&dir).ok();
}

/// Every method routes AOVs now; an estimator that does not say it supports them is refused
/// by the render driver rather than rendering layers it never filled.
struct NoLayers;
impl svetlo::integrator::PixelEstimator for NoLayers {
    fn li(&self, _: &Scene, _: &svetlo::geometry::Ray, _: &mut dyn svetlo::sampling::Sampler, _: &RenderSettings) -> svetlo::Rgb {
        svetlo::Rgb::WHITE
    }
}

#[test]
fn estimators_without_lpe_support_are_refused() {
    let scene = caustic(8);
    let set = aovs(&scene, PARTITION, None);
    let e = svetlo::integrator::render_pixels(&scene, &settings(1, 4, 1, Some(set)), &Progress::new(), &NoLayers);
    assert!(e.is_err_and(|e| e.to_string().contains("light path expressions")));
    assert!(svetlo::integrator::render_pixels(&scene, &settings(1, 4, 1, None), &Progress::new(), &NoLayers).is_ok());
}

#[test]
fn labels_that_name_nothing_warn() {
    let scene = caustic(8);
    let mut set = AovSet::compile(&[("x".into(), "C 'nosuchshape' L".into()), ("y".into(), "C [^.] L".into())], None).unwrap();
    let w = set.bind(&scene);
    assert!(w.iter().any(|w| w.contains("'nosuchshape' names no shape")), "{w:?}");
    assert!(w.iter().any(|w| w.contains("can match no path")), "{w:?}");
}
