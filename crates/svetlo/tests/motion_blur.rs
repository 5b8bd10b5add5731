//! Motion blur (issue 5, Cook's distributed ray tracing): shapes animated by svetlo's XML
//! extension (`<animation name="to_world">` keyframes, the sensor's shutter interval).
//!
//! The image of a moving scene is the time integral of the images of the static scene over
//! the shutter. The reference is an unbiased estimate of that integral: K renders of the
//! scene frozen (shutter collapsed) at stratified, jittered times, one sample per pixel each;
//! its per-pixel variance is the sample variance over the K renders. The blurred render must
//! agree with it by a per-pixel, per-channel two-sample Z-test (Šidák over all channels,
//! family level 1 %); a render frozen at the middle of the shutter must not (the test's power).

mod classic_scenes;

use glam::{Mat4, Vec3};
use std::path::{Path, PathBuf};
use svetlo::film::{Filter, Image};
use svetlo::geometry::AnimatedTransform;
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::sampling::rng::Pcg32;
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::{Error, Rgb};

const RES: u32 = 32;

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/motion-blur.xml")
}

fn load(shutter: (f32, f32)) -> Scene {
    let d = |k: &str, v: String| (k.to_string(), v);
    let defs = [d("res", RES.to_string()), d("shutter_open", shutter.0.to_string()), d("shutter_close", shutter.1.to_string())];
    svetlo::io::load_scene(&scene_path(), &defs).expect("scenes/motion-blur.xml")
}

fn settings(spp: u32, max_depth: i32, seed: u64) -> RenderSettings {
    RenderSettings { spp, max_depth, seed, filter: Filter::Box, ..Default::default() }
}

fn render(scene: &Scene, name: &str, s: &RenderSettings) -> svetlo::film::Film {
    svetlo::methods::by_name(name).expect("integrator").render(scene, s, &Progress::new()).expect("render")
}

/// Per-pixel mean and variance of the mean over `k` one-sample renders, each of the scene
/// frozen at a time drawn from its own stratum of `[0, 1]` (or at `fixed` for all).
fn time_average(name: &str, max_depth: i32, k: u32, fixed: Option<f32>, seed: u64) -> (Image, Image) {
    let mut scene = load((0.0, 0.0));
    time_average_of(
        |t, f| {
            scene.camera.shutter_open = t;
            scene.camera.shutter_close = t;
            f(&scene)
        },
        name,
        max_depth,
        k,
        fixed,
        seed,
    )
}

/// As [`time_average`], of the scene `with_scene(t, render)` hands to `render` for each time drawn.
fn time_average_of(
    mut with_scene: impl FnMut(f32, &mut dyn FnMut(&Scene)),
    name: &str,
    max_depth: i32,
    k: u32,
    fixed: Option<f32>,
    seed: u64,
) -> (Image, Image) {
    let mut rng = Pcg32::new(seed, 7);
    let (mut w, mut h) = (0, 0);
    let (mut sum, mut sum2): (Vec<[f64; 3]>, Vec<[f64; 3]>) = (Vec::new(), Vec::new());
    for i in 0..k {
        let t = fixed.unwrap_or((i as f32 + rng.next_f32()) / k as f32);
        with_scene(t, &mut |scene: &Scene| {
            let img = render(scene, name, &settings(1, max_depth, seed * 1000 + i as u64)).image();
            (w, h) = (img.width, img.height);
            sum.resize(img.data.len(), [0.0; 3]);
            sum2.resize(img.data.len(), [0.0; 3]);
            for (p, c) in img.data.iter().enumerate() {
                for ch in 0..3 {
                    let v = c[ch] as f64;
                    sum[p][ch] += v;
                    sum2[p][ch] += v * v;
                }
            }
        });
    }
    let n = w * h;
    let kf = k as f64;
    let mut mean = Image::new(w, h, vec![Rgb::BLACK; n]);
    let mut var = Image::new(w, h, vec![Rgb::BLACK; n]);
    for p in 0..n {
        let m = |ch: usize| sum[p][ch] / kf;
        let v = |ch: usize| ((sum2[p][ch] / kf - m(ch) * m(ch)).max(0.0) * kf / (kf - 1.0)) / kf;
        mean.data[p] = Rgb::new(m(0) as f32, m(1) as f32, m(2) as f32);
        var.data[p] = Rgb::new(v(0) as f32, v(1) as f32, v(2) as f32);
    }
    (mean, var)
}

/// Channels failing the two-sample Z-test of a film against (mean, variance of the mean).
fn failures(label: &str, film: &svetlo::film::Film, reference: &(Image, Image)) -> usize {
    let mut var = film.variance_image();
    for v in var.data.iter_mut() {
        *v *= 1.0 / film.spp_done as f32;
    }
    failures_of(label, &film.image(), &var, reference)
}

/// The same test for an image and the variance of its mean.
fn failures_of(label: &str, img: &Image, var_mean: &Image, reference: &(Image, Image)) -> usize {
    let n = img.data.len() * 3;
    let level = svetlo::sampling::stats::sidak_alpha(0.01, n);
    let mut failed = 0;
    let (mut da, mut sv) = (0.0, 0.0);
    for p in 0..img.data.len() {
        for ch in 0..3 {
            let (a, r) = (img.data[p][ch] as f64, reference.0.data[p][ch] as f64);
            let v = var_mean.data[p][ch] as f64 + reference.1.data[p][ch] as f64;
            da += a - r;
            sv += v;
            if v <= 1e-12 {
                // (Rare events: one side may have missed a faint contribution the other saw once.)
                let bad = (a - r).abs() > 1e-4 * a.abs().max(r.abs()) + 1e-4;
                if bad && std::env::var("SVETLO_DEBUG_COMPARE").is_ok() {
                    eprintln!("pixel {p} ch {ch}: {a} vs {r}, both without variance");
                }
                failed += usize::from(bad);
                continue;
            }
            let bad = svetlo::sampling::stats::two_sided_p((a - r).abs() / v.sqrt()) < level;
            if bad && std::env::var("SVETLO_DEBUG_COMPARE").is_ok() {
                eprintln!("pixel {p} ch {ch}: {a} (var of mean {}) vs {r} (var of mean {})", var_mean.data[p][ch], reference.1.data[p][ch]);
            }
            failed += usize::from(bad);
        }
    }
    eprintln!("{label}: {failed} of {n} channels fail; z of the image means {:.2}", da / sv.sqrt());
    failed
}

#[test]
fn blurred_image_is_the_time_average_of_static_images() {
    let reference = time_average("direct", 2, 256, None, 1);
    let blurred = render(&load((0.0, 1.0)), "direct", &settings(256, 2, 2));
    assert_eq!(failures("direct, shutter [0, 1]", &blurred, &reference), 0);
    // Distributed ray tracing at max_depth 2 is direct illumination too (stratified pixel,
    // lens and time samples).
    let blurred = render(&load((0.0, 1.0)), "distributed", &settings(256, 2, 3));
    assert_eq!(failures("distributed, shutter [0, 1]", &blurred, &reference), 0);
    // The test sees motion: the scene frozen at the middle of the shutter fails it.
    let frozen = render(&load((0.5, 0.5)), "direct", &settings(256, 2, 4));
    let f = failures("direct, frozen at 0.5", &frozen, &reference);
    assert!(f >= 20, "a frozen render passes the motion-blur test ({f} channels fail)");
}

/// Whitted's shadow rays and the path tracer's indirect bounces see the moving shapes at the
/// camera ray's time too.
#[test]
fn whitted_and_path_blur_too() {
    let reference = time_average("whitted", 2, 128, None, 5);
    let blurred = render(&load((0.0, 1.0)), "whitted", &settings(128, 2, 6));
    assert_eq!(failures("whitted, shutter [0, 1]", &blurred, &reference), 0);
    let reference = time_average("path", 3, 256, None, 7);
    let blurred = render(&load((0.0, 1.0)), "path", &settings(256, 3, 8));
    assert_eq!(failures("path max_depth 3, shutter [0, 1]", &blurred, &reference), 0);
}

fn sphere_scene(shutter: (f32, f32), motion: Option<Vec3>) -> Scene {
    sphere_scene_at(shutter, Vec3::ZERO, motion)
}

/// A ball on a floor under a square lamp, displaced by `offset`, moving by `motion` over [0, 1].
fn sphere_scene_at(shutter: (f32, f32), offset: Vec3, motion: Option<Vec3>) -> Scene {
    use classic_scenes::*;
    let mut b = SceneBuilder::new();
    add(&mut b, quad(Vec3::new(-3.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 6.0), Vec3::new(6.0, 0.0, 0.0)), diffuse(Rgb::splat(0.6)), None, "floor");
    let c = Vec3::new(0.0, 0.6, 0.0) + offset;
    let mi = b.add_material(diffuse(Rgb::new(0.8, 0.4, 0.2)));
    match motion {
        None => b.add_shape(sphere(c, 0.6), mi, None, "ball").unwrap(),
        Some(d) => {
            let anim = AnimatedTransform::new(&[(0.0, Mat4::from_translation(c)), (1.0, Mat4::from_translation(c + d))]).unwrap();
            b.add_animated_shape(sphere(c, 0.6), mi, None, "ball", anim).unwrap()
        }
    }
    add(&mut b, quad(Vec3::new(-0.5, 3.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 1.0)), diffuse(Rgb::BLACK), Some(Rgb::splat(5.0)), "lamp");
    let mut cam = camera(look_at(Vec3::new(0.0, 2.0, 5.0), Vec3::new(0.0, 0.6, 0.0), Vec3::Y), 45.0, 24, 18);
    (cam.shutter_open, cam.shutter_close) = shutter;
    b.set_camera(cam);
    b.build().unwrap()
}

/// The shadow of a ball rolling over the floor is blurred too: shadow rays see the ball at
/// the time of the camera ray.
#[test]
fn shadows_move_with_the_object() {
    let d = Vec3::new(1.5, 0.0, 0.0);
    // The reference knows nothing of motion: a static ball placed where it is at time t.
    let reference = time_average_of(|t, f| f(&sphere_scene_at((0.0, 0.0), t * d, None)), "direct", 2, 256, None, 21);
    let blurred = render(&sphere_scene((0.0, 1.0), Some(d)), "direct", &settings(256, 2, 22));
    assert_eq!(failures("ball over the floor, direct", &blurred, &reference), 0);
}

/// Nothing moves: the shutter changes nothing, to the bit; a moving shape seen at the
/// instant of its first keyframe is the static shape.
#[test]
fn static_scenes_are_unchanged() {
    let s = settings(16, 3, 11);
    let a = render(&sphere_scene((0.0, 0.0), None), "path", &s).image();
    let b = render(&sphere_scene((0.0, 1.0), None), "path", &s).image();
    assert!(a.data == b.data, "a static scene's image depends on the shutter");
    let s = settings(256, 3, 12);
    let still = render(&sphere_scene((0.0, 0.0), None), "path", &s);
    let moving = render(&sphere_scene((0.0, 0.0), Some(Vec3::new(1.5, 0.0, 0.0))), "path", &settings(256, 3, 13));
    let c = classic_scenes::compare(&still, &moving, 0.01, 1e-4);
    assert_eq!(c.failed, 0, "{c:?}");
    // ... and it does move when the shutter is open.
    let open = render(&sphere_scene((0.0, 1.0), Some(Vec3::new(1.5, 0.0, 0.0))), "path", &settings(256, 3, 14));
    assert!(classic_scenes::compare(&still, &open, 0.01, 1e-4).failed > 10);
}

/// Scene bounds cover the whole motion, so directional lights and the environment see it.
#[test]
fn bounds_cover_the_motion() {
    let s = sphere_scene((0.0, 1.0), Some(Vec3::new(4.0, 0.0, 0.0)));
    assert!(s.bounds.center.distance(Vec3::new(4.6, 0.6, 0.0)) + 0.6 <= s.bounds.radius + 1e-3);
}

fn load_text(name: &str, body: &str) -> svetlo::Result<Scene> {
    let dir = std::env::temp_dir().join(format!("svetlo-motion-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("scene.xml");
    let xml = format!(
        r#"<scene version="3.0.0"><sensor type="perspective"><float name="fov" value="40"/>
           <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
           {body}</scene>"#
    );
    std::fs::write(&p, xml).unwrap();
    let r = svetlo::io::load_scene(&p, &[]);
    std::fs::remove_dir_all(&dir).unwrap();
    r
}

#[test]
fn bad_animations_are_typed_errors() {
    let key = |t: &str, x: f32| format!(r#"<transform time="{t}"><translate x="{x}"/></transform>"#);
    let anim = |keys: &str| format!(r#"<shape type="sphere"><animation name="to_world">{keys}</animation></shape>"#);
    let cases = [
        ("decreasing", anim(&(key("1", 0.0) + &key("0", 1.0))), "does not follow"),
        ("repeated", anim(&(key("0", 0.0) + &key("0", 1.0))), "does not follow"),
        ("no time", anim(r#"<transform><translate x="1"/></transform>"#), "time"),
        ("bad time", anim(&key("soon", 0.0)), "soon"),
        ("empty", anim(""), "at least one keyframe"),
        ("not a transform", anim(r#"<float name="x" value="1"/>"#), "keyframes"),
        ("shear", anim(r#"<transform time="0"><matrix value="1 0.5 0 0  0 1 0 0  0 0 1 0  0 0 0 1"/></transform>"#), "shear"),
        ("zero scale", anim(r#"<transform time="0"><scale x="0"/></transform>"#), "singular"),
        ("mirror flip", anim(r#"<transform time="0"><scale x="1"/></transform><transform time="1"><scale x="-1"/></transform>"#), "mirror"),
        ("other name", r#"<shape type="sphere"><animation name="uv_transform"><transform time="0"/></animation></shape>"#.to_string(), "only to_world"),
        (
            "both",
            format!(
                r#"<shape type="sphere"><transform name="to_world"><translate x="1"/></transform><animation name="to_world">{}</animation></shape>"#,
                key("0", 0.0)
            ),
            "not both",
        ),
        (
            "emitter",
            format!(r#"<shape type="sphere"><emitter type="area"/><animation name="to_world">{}{}</animation></shape>"#, key("0", 0.0), key("1", 1.0)),
            "emitting shape cannot be animated",
        ),
        (
            "instance",
            format!(
                r#"<shape type="shapegroup" id="g"><shape type="sphere"/></shape><shape type="instance"><ref id="g"/><animation name="to_world">{}</animation></shape>"#,
                key("0", 0.0)
            ),
            "instance cannot be animated",
        ),
    ];
    for (name, body, needle) in cases {
        match load_text(name, &body) {
            Ok(_) => panic!("{name}: loaded"),
            Err(e @ Error::SceneAt { .. }) => assert!(e.to_string().contains(needle), "{name}: {e}"),
            Err(e) => panic!("{name}: untyped location: {e}"),
        }
    }
    // The 0.6 spelling loads, and an animated shape inside an instance moves with it.
    let ok = format!(
        r#"<shape type="shapegroup" id="g"><shape type="sphere"><animation name="toWorld">{}{}</animation></shape></shape>
           <shape type="instance"><ref id="g"/><transform name="to_world"><translate y="2"/></transform></shape>"#,
        key("0", 0.0),
        key("1", 1.0)
    );
    let s = load_text("ok", &ok).expect("valid animation");
    assert_eq!(s.moving.len(), 1);
    let m = s.moving[0].motion.relative(1.0);
    assert!(m.transform_point3(Vec3::new(0.0, 2.0, 0.0)).distance(Vec3::new(1.0, 2.0, 0.0)) < 1e-5);
}

/// The rasteriser draws a moving shape where it is at the middle of the shutter.
#[test]
fn zbuffer_draws_the_middle_of_the_shutter() {
    let d = Vec3::new(1.5, 0.0, 0.5);
    let s = settings(4, 2, 1);
    let moving = render(&sphere_scene((0.0, 1.0), Some(d)), "zbuffer", &s).image();
    let still = render(&sphere_scene_at((0.0, 0.0), 0.5 * d, None), "zbuffer", &s).image();
    let start = render(&sphere_scene_at((0.0, 0.0), Vec3::ZERO, None), "zbuffer", &s).image();
    let differ =
        |a: &Image, b: &Image| a.data.iter().zip(&b.data).filter(|(x, y)| (**x - **y).max_component().abs() > 1e-3 * x.max_component().max(1e-3)).count();
    assert_eq!(differ(&moving, &still), 0);
    assert!(differ(&moving, &start) > 20);
}

/// The bidirectional methods connect subpaths at the camera ray's time: BDPT's blurred
/// shadow is the time average of static scenes too (a connection tested at time 0 would
/// leave the shadow sharp where the ball starts).
#[test]
fn bdpt_connections_see_the_scene_at_the_path_time() {
    let d = Vec3::new(1.5, 0.0, 0.0);
    let reference = time_average_of(|t, f| f(&sphere_scene_at((0.0, 0.0), t * d, None)), "direct", 2, 256, None, 31);
    // BDPT splats (t = 1) are not in the film's per-sample variance: take the variance of
    // the mean from 16 independent renders instead.
    let scene = sphere_scene((0.0, 1.0), Some(d));
    let renders: Vec<Image> = (0..16).map(|k| render(&scene, "bdpt", &settings(16, 2, 100 + k)).image()).collect();
    let mut mean = renders[0].clone();
    let mut var = renders[0].clone();
    for p in 0..mean.data.len() {
        let (mut m3, mut v3) = ([0.0f32; 3], [0.0f32; 3]);
        for ch in 0..3 {
            let xs: Vec<f64> = renders.iter().map(|im| im.data[p][ch] as f64).collect();
            let m = xs.iter().sum::<f64>() / 16.0;
            m3[ch] = m as f32;
            v3[ch] = (xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / 15.0 / 16.0) as f32;
        }
        mean.data[p] = svetlo::Rgb::new(m3[0], m3[1], m3[2]);
        var.data[p] = svetlo::Rgb::new(v3[0], v3[1], v3[2]);
    }
    assert_eq!(failures_of("ball over the floor, bdpt", &mean, &var, &reference), 0);
}
