//! pbrt-v4's image lights (`goniometric`, `projection`) and procedural textures: emission
//! sampling against its density (chi-square), the `power` normalisation, pbrt's frame and
//! image conventions, values against closed forms, exports both ways, bad parameters, and
//! the project's scenes `scenes/pbrt/lights.pbrt` and `procedural.pbrt` rendered.

use glam::{Mat4, Vec2, Vec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use svetlo::bsdf::Material;
use svetlo::geometry::Ray;
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::io::load_pbrt_from_str;
use svetlo::light::{Goniometric, Light, Projector, SceneBounds};
use svetlo::math::warp::{equal_area_sphere_to_square, equal_area_square_to_sphere};
use svetlo::math::PI;
use svetlo::sampling::stats::{chi_square_test, sidak_alpha};
use svetlo::sampling::Pcg32;
use svetlo::scene::Scene;
use svetlo::texture::{Bitmap, TexPoint, Texture};
use svetlo::Rgb;

/// Chi-square tests in this file (Šidák correction).
const CHI2_TESTS: usize = 2;
const SAMPLES: usize = 200_000;

fn bounds() -> SceneBounds {
    SceneBounds { center: Vec3::ZERO, radius: 10.0 }
}

fn u2(rng: &mut Pcg32) -> Vec2 {
    Vec2::new(rng.next_f32(), rng.next_f32())
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

fn own_scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/pbrt").join(name)
}

fn scene_dir() -> PathBuf {
    own_scene("")
}

/// Texels: a fixed pseudo-random image with some zero texels.
fn test_values(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = Pcg32::new(seed, 5);
    (0..n * n).map(|_| if rng.next_f32() < 0.2 { 0.0 } else { 0.1 + 3.0 * rng.next_f32() }).collect()
}

fn oblique() -> Mat4 {
    Mat4::from_translation(Vec3::new(0.5, -1.0, 2.0)) * Mat4::from_rotation_x(0.7) * Mat4::from_rotation_z(-1.2)
}

/// The goniometric light's emitted directions, binned by the image's texels (each split
/// 2 × 2 on the equal-area square, where the density is uniform): counts match each
/// texel's share of the image, the reported pdf is `pdf_le`'s, the radiance is `eval`'s,
/// and each sample's flux weight is exactly the light's power (sampling ∝ intensity).
#[test]
fn goniometric_emission_sampling() {
    let n = 8;
    let values = test_values(n, 3);
    let g = Goniometric::new(&oblique(), Rgb::new(1.0, 0.6, 0.3), values.clone(), n).unwrap();
    let light = Light::Goniometric(Box::new(g.clone()));
    let b = bounds();
    let mut rng = Pcg32::new(17, 1);
    let mut observed = vec![0.0f64; n * n * 4 + 1];
    let power = light.power(&b);
    for _ in 0..SAMPLES {
        let Some(es) = light.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b) else {
            observed[n * n * 4] += 1.0;
            continue;
        };
        assert!((es.ray.o - g.position).length() < 1e-5);
        assert_eq!(es.pdf_pos, 1.0);
        let (pp, pd) = light.pdf_le(&es.ray, es.n, &b);
        assert_eq!(pp, 0.0, "a delta position");
        assert!(close(es.pdf_dir, pd, 1e-3), "{} vs {pd}", es.pdf_dir);
        assert!(close(es.le.g, g.eval(es.ray.d).g, 1e-6));
        assert!(close(es.le.luminance() / es.pdf_dir, power, 1e-3), "weight {} vs power {power}", es.le.luminance() / es.pdf_dir);
        let uv = equal_area_sphere_to_square(g.to_local(es.ray.d)) * (2 * n) as f32;
        let (x, y) = ((uv.x as usize).min(2 * n - 1), (uv.y as usize).min(2 * n - 1));
        let texel = (y / 2) * n + x / 2;
        observed[texel * 4 + (y % 2) * 2 + x % 2] += 1.0;
    }
    let sum: f64 = values.iter().map(|&v| v as f64).sum();
    let mut expected: Vec<f64> = (0..n * n * 4).map(|k| values[k / 4] as f64 / sum / 4.0 * SAMPLES as f64).collect();
    expected.push(0.0);
    let r = chi_square_test(&observed, &expected, 5.0);
    eprintln!("goniometric sample_le: chi2 {:.1}, dof {}, p {:.4}", r.statistic, r.dof, r.p_value);
    assert!(r.p_value > sidak_alpha(0.01, CHI2_TESTS), "p = {:.2e}", r.p_value);
}

/// ∫ pdf_le dω = 1 and ∫ I dω = power, by a (cos θ, φ) midpoint rule that knows nothing
/// of the equal-area map.
#[test]
fn goniometric_densities_integrate() {
    let n = 8;
    let g = Goniometric::new(&oblique(), Rgb::WHITE, test_values(n, 4), n).unwrap();
    let light = Light::Goniometric(Box::new(g.clone()));
    let b = bounds();
    let (nt, np) = (500, 1000);
    let (mut pdf, mut flux) = (0.0f64, 0.0f64);
    for i in 0..nt {
        let c = 1.0 - 2.0 * (i as f64 + 0.5) / nt as f64;
        let s = (1.0 - c * c).sqrt();
        for j in 0..np {
            let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
            let w = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
            pdf += light.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64;
            flux += g.eval(w).luminance() as f64;
        }
    }
    let dw = 4.0 * std::f64::consts::PI / (nt * np) as f64;
    assert!((pdf * dw - 1.0).abs() < 5e-3, "∫ pdf = {}", pdf * dw);
    let p = light.power(&b) as f64;
    assert!((flux * dw - p).abs() < 5e-3 * p, "∫ I = {} vs power {p}", flux * dw);
}

fn world(body: &str) -> String {
    format!("Camera \"perspective\"\nFilm \"rgb\" \"integer xresolution\" 8 \"integer yresolution\" 8\nWorldBegin\n{body}\n")
}

/// pbrt's frame: the image's pole (its +z, the square's centre) is the light's +y. A 3 × 3
/// image, 5 in the centre texel and 1 elsewhere, seen from a point on each axis; with a
/// rotation of the CTM the beam turns with it. Irradiance at distance r facing the light is
/// I / r² (closed form for a point).
#[test]
fn goniometric_frame_and_inverse_square() {
    let dir = std::env::temp_dir().join(format!("svetlo-gonio-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let img = Bitmap::new(3, 3, (0..9).map(|i| Rgb::splat(if i == 4 { 5.0 } else { 1.0 })).collect());
    svetlo::io::image_io::write_exr(&dir.join("g.exr"), &svetlo::film::Image::new(3, 3, img.data().to_vec())).unwrap();
    let load = |xf: &str| {
        let text = world(&format!("{xf}\nLightSource \"goniometric\" \"string filename\" \"g.exr\" \"rgb I\" [ 2 1 0.5 ]"));
        let scene = load_pbrt_from_str(&text, &dir.join("g.pbrt")).unwrap_or_else(|e| panic!("{e}"));
        scene.lights[0].clone()
    };
    let b = bounds();
    let li = |l: &Light, p: Vec3| l.sample_li(p, Vec2::splat(0.5), &b).map_or(Rgb::BLACK, |s| s.li);
    let l = load("");
    let r = 3.0f32;
    let up = li(&l, Vec3::new(0.0, r, 0.0));
    assert!(close(up.r, 2.0 * 5.0 / (r * r), 1e-5) && close(up.b, 0.5 * 5.0 / (r * r), 1e-5), "toward +y: {up:?}");
    let down = li(&l, Vec3::new(0.0, -r, 0.0));
    assert!(close(down.r, 2.0 / (r * r), 1e-5), "toward -y: {down:?}");
    // Rotate 90° about z: the light's +y is the world's -x.
    let l = load("Rotate 90 0 0 1");
    assert!(close(li(&l, Vec3::new(-r, 0.0, 0.0)).r, 10.0 / (r * r), 1e-5));
    assert!(close(li(&l, Vec3::new(0.0, r, 0.0)).r, 2.0 / (r * r), 1e-5));
    // Power: 4π × the image's mean (13/9) × the colour's luminance, and `power` sets it.
    let Light::Goniometric(g) = &l else { panic!("a goniometric light") };
    assert!(close(g.power(), 4.0 * PI * 13.0 / 9.0 * Rgb::new(2.0, 1.0, 0.5).luminance(), 1e-5));
    let text = world("LightSource \"goniometric\" \"string filename\" \"g.exr\" \"rgb I\" [ 2 1 0.5 ] \"float scale\" 7 \"float power\" 100");
    let scene = load_pbrt_from_str(&text, &dir.join("g.pbrt")).unwrap();
    let p = scene.lights[0].power(&b);
    assert!(close(p, 100.0, 1e-5), "power {p}");
    let Light::Goniometric(g) = &scene.lights[0] else { panic!() };
    assert!(close(g.intensity.r / g.intensity.g, 2.0, 1e-5), "the colour is kept: {:?}", g.intensity);
    // `scale` multiplies without `power`.
    let text = world("LightSource \"goniometric\" \"string filename\" \"g.exr\" \"float scale\" 3");
    let s3 = load_pbrt_from_str(&text, &dir.join("g.pbrt")).unwrap();
    assert!(close(s3.lights[0].power(&b), 3.0 * 4.0 * PI * 13.0 / 9.0, 1e-5));
    // A non-square image and a missing file are errors at the directive's line.
    svetlo::io::image_io::write_exr(&dir.join("wide.exr"), &svetlo::film::Image::new(4, 2, vec![Rgb::WHITE; 8])).unwrap();
    for (body, what) in [
        ("LightSource \"goniometric\" \"string filename\" \"wide.exr\"", "square"),
        ("LightSource \"goniometric\" \"string filename\" \"none.exr\"", "not found"),
        ("LightSource \"goniometric\" \"string filename\" \"g.exr\" \"float power\" -2", "power"),
        ("LightSource \"goniometric\" \"string filename\" \"g.exr\" \"string power\" \"x\"", "expected"),
    ] {
        let e = load_pbrt_from_str(&world(body), &dir.join("bad.pbrt")).err().unwrap_or_else(|| panic!("accepted {body}")).to_string();
        assert!(e.contains("bad.pbrt:4:") && e.contains(what), "{body}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// pbrt's projection light: the image is the intensity (× scale, no 1/cos³), `fov` spans
/// the shorter axis, the image's top is toward the light's +y and its left toward −x; the
/// `power` normalisation is pbrt's (pixel-centre quadrature of luminance × cos³θ).
#[test]
fn projection_conventions_and_power() {
    let dir = std::env::temp_dir().join(format!("svetlo-proj-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // 4 × 2: texel (x, y) has value 1 + x + 4 y in red, 1 in green.
    let data: Vec<Rgb> = (0..8).map(|i| Rgb::new(1.0 + i as f32, 1.0, 0.0)).collect();
    svetlo::io::image_io::write_exr(&dir.join("p.exr"), &svetlo::film::Image::new(4, 2, data.clone())).unwrap();
    let load = |extra: &str| -> Light {
        let text = world(&format!("LightSource \"projection\" \"string filename\" \"p.exr\" \"float fov\" 60 {extra}"));
        load_pbrt_from_str(&text, &dir.join("p.pbrt")).unwrap_or_else(|e| panic!("{e}")).lights[0].clone()
    };
    let l = load("\"float scale\" 2");
    let Light::Projector(pr) = &l else { panic!("a projector") };
    let ty = (30.0f32).to_radians().tan();
    let tx = 2.0 * ty;
    // Screen coordinates (sx, sy) in [-1, 1]² (x right, y up as seen along +z).
    let at = |sx: f32, sy: f32| pr.intensity(Vec3::new(sx * tx, sy * ty, 1.0).normalize());
    for (x, y) in [(0usize, 0usize), (3, 0), (1, 1), (2, 1)] {
        let (sx, sy) = (-1.0 + (x as f32 + 0.5) * 0.5, 1.0 - (y as f32 + 0.5));
        let i = at(sx, sy);
        assert!(close(i.r, 2.0 * (1.0 + (x + 4 * y) as f32), 1e-5), "texel ({x}, {y}): {i:?}");
    }
    // Top-left texel is toward −x and +y.
    assert!(close(at(-0.9, 0.9).r, 2.0, 1e-5));
    // The fov is vertical for a landscape image: just inside and outside both edges.
    assert!(at(0.0, 0.99).g > 0.0 && at(0.0, 1.01).g == 0.0);
    assert!(at(0.99, 0.0).g > 0.0 && at(1.01, 0.0).g == 0.0);
    assert_eq!(pr.intensity(-Vec3::Z), Rgb::BLACK, "behind");
    // pbrt's power: A · mean(luminance × cos³ at texel centres) · scale, A = 4 tan² aspect.
    let mut sum = 0.0f64;
    for y in 0..2 {
        for x in 0..4 {
            let q = Vec3::new((-1.0 + (x as f32 + 0.5) * 0.5) * tx, (1.0 - (y as f32 + 0.5)) * ty, 1.0);
            let c = 1.0 / q.length();
            sum += (data[y * 4 + x].luminance() * c * c * c) as f64;
        }
    }
    let want = 2.0 * 4.0 * (ty * ty * 2.0) as f64 * sum / 8.0;
    assert!(close(l.power(&bounds()), want as f32, 1e-5), "{} vs {want}", l.power(&bounds()));
    let p = load("\"float scale\" 2 \"float power\" 50").power(&bounds());
    assert!(close(p, 50.0, 1e-5), "power {p}");
    for (body, what) in [
        ("LightSource \"projection\" \"float fov\" 30", "filename"),
        ("LightSource \"projection\" \"string filename\" \"p.exr\" \"float fov\" 180", "fov"),
        ("LightSource \"projection\" \"string filename\" \"p.exr\" \"float scale\" -1", "scale"),
    ] {
        let e = load_pbrt_from_str(&world(body), &dir.join("bad.pbrt")).err().unwrap_or_else(|| panic!("accepted {body}")).to_string();
        assert!(e.contains("bad.pbrt:4:") && e.contains(what), "{body}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// pbrt's projection samples emission by its image (texels by luminance × cos³θ, uniform on
/// the image plane inside one): texel sub-cells counted against that, the pdf against
/// `pdf_le`, and the mean flux weight against an independent quadrature of ∫ I dω.
#[test]
fn projection_emission_sampling() {
    let (w, h) = (6usize, 3usize);
    let mut rng = Pcg32::new(8, 2);
    let data: Vec<Rgb> = (0..w * h).map(|i| if i % 5 == 2 { Rgb::BLACK } else { Rgb::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) }).collect();
    let image = Arc::new(Bitmap::new(w, h, data.clone()));
    let pr = Projector::pbrt(&oblique(), 40.0, image, 1.5).unwrap();
    let light = Light::Projector(Box::new(pr.clone()));
    let b = bounds();
    let to_local = oblique().inverse();
    let (ty, tx) = ((20.0f32).to_radians().tan(), 2.0 * (20.0f32).to_radians().tan());
    // Plane coordinates in pbrt's frame: x right (toward −x of the projector's local frame
    // is the image's left), y up.
    let texel_of = |d: Vec3| {
        let l = to_local.transform_vector3(d);
        let (sx, sy) = (l.x / (l.z * tx), l.y / (l.z * ty));
        let (fx, fy) = ((sx + 1.0) * w as f32, (1.0 - sy) * h as f32);
        ((fx as usize).min(2 * w - 1), (fy as usize).min(2 * h - 1))
    };
    let weight = |x: usize, y: usize| {
        let q = Vec3::new((-1.0 + 2.0 * (x as f32 + 0.5) / w as f32) * tx, (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * ty, 1.0);
        let c = 1.0 / q.length();
        data[y * w + x].luminance() as f64 * (c * c * c) as f64
    };
    let mut observed = vec![0.0f64; w * h * 4 + 1];
    let mut flux = 0.0f64;
    for _ in 0..SAMPLES {
        let Some(es) = light.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b) else {
            observed[w * h * 4] += 1.0;
            continue;
        };
        assert!(close(es.pdf_dir, light.pdf_le(&es.ray, es.n, &b).1, 1e-3));
        assert!(close(es.le.r, pr.intensity(es.ray.d).r, 1e-6));
        flux += (es.le.luminance() / es.pdf_dir) as f64;
        let (x2, y2) = texel_of(es.ray.d);
        observed[((y2 / 2) * w + x2 / 2) * 4 + (y2 % 2) * 2 + x2 % 2] += 1.0;
    }
    let total: f64 = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).map(|(x, y)| weight(x, y)).sum();
    let mut expected: Vec<f64> = (0..w * h * 4).map(|k| weight((k / 4) % w, (k / 4) / w) / total / 4.0 * SAMPLES as f64).collect();
    expected.push(0.0);
    let r = chi_square_test(&observed, &expected, 5.0);
    eprintln!("projection sample_le: chi2 {:.1}, dof {}, p {:.4}", r.statistic, r.dof, r.p_value);
    assert!(r.p_value > sidak_alpha(0.01, CHI2_TESTS), "p = {:.2e}", r.p_value);
    // ∫ I dω over the image plane, dω = cos³θ dA, by a fine midpoint rule.
    let m = 600;
    let mut exact = 0.0f64;
    for i in 0..m {
        for j in 0..m / 2 {
            let q = Vec3::new((-1.0 + 2.0 * (i as f32 + 0.5) / m as f32) * tx, (1.0 - 2.0 * (j as f32 + 0.5) / (m / 2) as f32) * ty, 1.0);
            let c = 1.0 / q.length();
            let wd = oblique().transform_vector3(q).normalize();
            exact += (pr.intensity(wd).luminance() * c * c * c) as f64;
        }
    }
    exact *= (4.0 * tx * ty) as f64 / (m * m / 2) as f64;
    let est = flux / SAMPLES as f64;
    assert!((est - exact).abs() < 5e-3 * exact, "MC ∫ I dω = {est} vs quadrature {exact}");
}

/// `convert`: the lights of `scenes/pbrt/lights.pbrt` written to pbrt read back the same;
/// to Mitsuba, the projection becomes Mitsuba's projector with the same intensity at the
/// texel centres, and the goniometric light a point of the same power (with a note).
#[test]
fn convert_image_lights() {
    let scene = svetlo::io::load_pbrt(&own_scene("lights.pbrt")).expect("lights.pbrt");
    let b = bounds();
    let dir = std::env::temp_dir().join(format!("svetlo-convert-lights-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut rng = Pcg32::new(4, 4);
    let dirs: Vec<Vec3> = (0..200).map(|_| svetlo::math::warp::square_to_uniform_sphere(u2(&mut rng))).collect();
    let projector_dirs = |pr: &Projector| -> Vec<Vec3> {
        let Texture::Bitmap { image, .. } = &pr.irradiance else { panic!("an image") };
        let (w, h) = (image.width, image.height);
        let m = pr.to_world();
        (0..w * h)
            .map(|k| {
                let (x, y) = (k % w, k / w);
                let (u, v) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                let q = Vec3::new((1.0 - 2.0 * u) * pr.tan_x, (1.0 - 2.0 * v) * pr.tan_y, 1.0);
                m.transform_vector3(q).normalize()
            })
            .collect()
    };
    for (format, file) in [(svetlo::io::SceneFormat::Pbrt, "back.pbrt"), (svetlo::io::SceneFormat::Mitsuba, "back.xml")] {
        let out = dir.join(file);
        let notes = svetlo::io::export::export_scene(&scene, &out, format).expect("export");
        let back = svetlo::io::load_scene_as(&out, None, &[]).expect("reload");
        assert_eq!(back.lights.len(), scene.lights.len(), "{file}");
        for (a, z) in scene.lights.iter().zip(&back.lights) {
            match (a, z) {
                (Light::Goniometric(g), Light::Goniometric(h)) => {
                    for d in &dirs {
                        assert!(close(g.eval(*d).r, h.eval(*d).r, 1e-4), "{file}: {d}");
                    }
                }
                (Light::Goniometric(g), Light::Point { position, .. }) => {
                    assert!(format == svetlo::io::SceneFormat::Mitsuba);
                    assert!((*position - g.position).length() < 1e-5);
                    assert!(close(a.power(&b), z.power(&b), 1e-4), "{file}: power {} vs {}", a.power(&b), z.power(&b));
                    assert!(notes.iter().any(|n| n.contains("goniometric")), "{notes:?}");
                }
                (Light::Projector(p), Light::Projector(q)) => {
                    for d in projector_dirs(p) {
                        let (i, j) = (p.intensity(d), q.intensity(d));
                        assert!(close(i.r, j.r, 1e-3) && close(i.b, j.b, 1e-3), "{file}: {d}: {i:?} vs {j:?}");
                    }
                }
                (a, z) => panic!("{file}: {} came back as {}", a.kind_name(), z.kind_name()),
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The reflectance texture of the scene's only shape.
fn reflectance(scene: &Scene) -> Texture {
    let m = &scene.materials[scene.shapes[0].material as usize];
    let m = match m {
        Material::TwoSided { front, .. } => &**front,
        m => m,
    };
    match m {
        Material::Diffuse { reflectance } => reflectance.clone(),
        other => panic!("not a diffuse: {}", other.kind_name()),
    }
}

fn textured(defs: &str) -> Texture {
    let text = world(&format!(
        "{defs}\nMaterial \"diffuse\" \"texture reflectance\" \"t\"\nShape \"trianglemesh\" \"point3 P\" [ 0 0 0 1 0 0 0 1 0 ] \"integer indices\" [ 0 1 2 ]"
    ));
    reflectance(&load_pbrt_from_str(&text, &scene_dir().join("tex.pbrt")).unwrap_or_else(|e| panic!("{defs}: {e}")))
}

fn at(uv: Vec2, p: Vec3, n: Vec3) -> TexPoint {
    TexPoint { uv, p, n, ..Default::default() }
}

/// The loader's procedural textures against closed forms: bilerp at its corners (and the uv
/// mapping's scale), directionmix along and across its direction (turned by the CTM), fbm
/// and wrinkled as their octave sums in the texture space of the CTM, marble at zero
/// variation, dots under a planar mapping, textured mix and scale.
#[test]
fn procedural_textures_through_the_loader() {
    use svetlo::texture::noise::{fbm, noise2, turbulence};
    let t = textured(
        "Texture \"t\" \"spectrum\" \"bilerp\" \"rgb v00\" [ 1 0 0 ] \"rgb v10\" [ 0 1 0 ] \"rgb v01\" [ 0 0 1 ] \"rgb v11\" [ 1 1 1 ] \"float uscale\" 2",
    );
    let o = Vec3::ZERO;
    assert_eq!(t.eval(at(Vec2::new(0.0, 0.0), o, o)), Rgb::new(1.0, 0.0, 0.0));
    assert_eq!(t.eval(at(Vec2::new(0.5, 0.0), o, o)), Rgb::new(0.0, 1.0, 0.0), "s = 2u");
    assert_eq!(t.eval(at(Vec2::new(0.0, 1.0), o, o)), Rgb::new(0.0, 0.0, 1.0));
    assert_eq!(t.eval(at(Vec2::new(0.5, 1.0), o, o)), Rgb::WHITE);
    // Float bilerp defaults (0, 1, 0, 1): t itself.
    let f = textured("Texture \"t\" \"float\" \"bilerp\"");
    assert!((f.eval_f32(at(Vec2::new(0.3, 0.7), o, o)) - 0.7).abs() < 1e-6);

    let t = textured("Rotate 90 1 0 0\nTexture \"t\" \"spectrum\" \"directionmix\" \"rgb tex1\" [ 1 0 0 ] \"rgb tex2\" [ 0 1 0 ]");
    // dir (0, 1, 0) turned by Rotate 90 about x: +z.
    let near = |a: Rgb, b: Rgb| (a - b).map(f32::abs).max_component() < 1e-6;
    assert!(near(t.eval(at(Vec2::ZERO, o, Vec3::Z)), Rgb::new(1.0, 0.0, 0.0)));
    assert!(near(t.eval(at(Vec2::ZERO, o, Vec3::Y)), Rgb::new(0.0, 1.0, 0.0)));

    let p = Vec3::new(0.3, -1.2, 2.7);
    let t = textured("Translate 1 2 3\nTexture \"t\" \"float\" \"fbm\" \"float roughness\" 0.7 \"integer octaves\" 5");
    let q = p - Vec3::new(1.0, 2.0, 3.0);
    assert_eq!(t.eval_f32(at(Vec2::ZERO, p, o)), fbm(q, 0.7, 5));
    let t = textured("Scale 2 2 2\nTexture \"t\" \"float\" \"wrinkled\"");
    assert_eq!(t.eval_f32(at(Vec2::ZERO, p, o)), turbulence(p * 0.5, 0.5, 8));
    let t = textured("Texture \"t\" \"spectrum\" \"marble\" \"float variation\" 0");
    // y = 0: t = 1/2 is the start of the spline's segment 3 (of 6): 1.5 × its control colour.
    let m = t.eval(at(Vec2::ZERO, Vec3::new(0.4, 0.0, 0.9), o));
    assert!((m - Rgb::splat(0.75)).map(f32::abs).max_component() < 1e-6, "{m:?}");
    // y = 0.3: t = (1 + sin 0.3) / 2, inside segment 3: the cubic Bézier (Bernstein form) of
    // control colours 3..6, × 1.5.
    let m = t.eval(at(Vec2::ZERO, Vec3::new(0.4, 0.3, 0.9), o));
    let x = 6.0 * (0.5 + 0.5 * 0.3f32.sin()) - 3.0;
    let bez = |a: f32, b: f32, c: f32, d: f32| {
        let y = 1.0 - x;
        y * y * y * a + 3.0 * y * y * x * b + 3.0 * y * x * x * c + x * x * x * d
    };
    assert!((m.r - 1.5 * bez(0.5, 0.6, 0.58, 0.58)).abs() < 1e-5, "{m:?}");
    assert!((m.g - 1.5 * bez(0.5, 0.59, 0.58, 0.58)).abs() < 1e-5, "{m:?}");
    assert!((m.b - 1.5 * bez(0.5, 0.58, 0.6, 0.6)).abs() < 1e-5, "{m:?}");

    // Dots under a planar mapping (s = x, t = z): a cell with a dot shows `inside` at its
    // centre, every cell's corner shows `outside`.
    let t = textured("Texture \"t\" \"float\" \"dots\" \"string mapping\" \"planar\" \"vector3 v1\" [ 1 0 0 ] \"vector3 v2\" [ 0 0 1 ] \"float inside\" 0.9 \"float outside\" 0.1");
    let mut dots = 0;
    for s in 0..10 {
        for u in 0..10 {
            let (sc, tc) = (s as f32, u as f32);
            let corner = t.eval_f32(at(Vec2::ZERO, Vec3::new(sc + 0.5, 7.0, tc + 0.5), o));
            assert!((corner - 0.1).abs() < 1e-6);
            if noise2(sc + 0.5, tc + 0.5) > 0.0 {
                let c = Vec3::new(sc + 0.15 * noise2(sc + 1.5, tc + 2.8), -3.0, tc + 0.15 * noise2(sc + 4.5, tc + 9.8));
                assert!((t.eval_f32(at(Vec2::ZERO, c, o)) - 0.9).abs() < 1e-6);
                dots += 1;
            }
        }
    }
    assert!(dots > 20, "{dots} dots in 100 cells");

    // Textured mix and scale.
    let t = textured(
        "Texture \"a\" \"float\" \"bilerp\"\nTexture \"t\" \"spectrum\" \"mix\" \"rgb tex1\" [ 1 0 0 ] \"rgb tex2\" [ 0 0 1 ] \"texture amount\" \"a\"",
    );
    let v = t.eval(at(Vec2::new(0.0, 0.25), o, o));
    assert!((v.r - 0.75).abs() < 1e-6 && (v.b - 0.25).abs() < 1e-6, "{v:?}");
    let t = textured("Texture \"a\" \"float\" \"bilerp\"\nTexture \"t\" \"spectrum\" \"scale\" \"rgb tex\" [ 0.5 1 2 ] \"texture scale\" \"a\"");
    assert_eq!(t.eval(at(Vec2::new(0.0, 0.5), o, o)), Rgb::new(0.25, 0.5, 1.0));
}

/// Spherical and cylindrical mappings put an image (or any 2-D texture) where pbrt does:
/// spherical s = θ/π (from +z), t = φ/2π; cylindrical s = (π + atan2(y, x)) / 2π, t = z.
#[test]
fn mappings_through_the_loader() {
    let t = textured("Texture \"t\" \"float\" \"bilerp\" \"string mapping\" \"spherical\"");
    let o = Vec3::ZERO;
    // Float bilerp is t: φ / 2π. Direction +y: φ = π/2.
    assert!((t.eval_f32(at(Vec2::ZERO, Vec3::new(0.0, 2.0, 0.0), o)) - 0.25).abs() < 1e-6);
    // In the texture space of the CTM: Translate moves the sphere's centre.
    let t = textured("Translate 0 0 5\nTexture \"t\" \"float\" \"bilerp\" \"string mapping\" \"cylindrical\"");
    assert!((t.eval_f32(at(Vec2::ZERO, Vec3::new(1.0, 0.0, 5.5), o)) - 0.5).abs() < 1e-6, "t = z in texture space");
    // An image under a cylindrical mapping: the left column of a 2-wide image at s < 1/2.
    let dir = std::env::temp_dir().join(format!("svetlo-map-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    svetlo::io::image_io::write_exr(&dir.join("two.exr"), &svetlo::film::Image::new(2, 1, vec![Rgb::new(1.0, 0.0, 0.0), Rgb::new(0.0, 0.0, 1.0)])).unwrap();
    let text = world("Texture \"t\" \"spectrum\" \"imagemap\" \"string filename\" \"two.exr\" \"string mapping\" \"cylindrical\" \"string filter\" \"point\"\nMaterial \"diffuse\" \"texture reflectance\" \"t\"\nShape \"sphere\"");
    let tex = reflectance(&load_pbrt_from_str(&text, &dir.join("m.pbrt")).unwrap());
    // (x, y) = (−1, −0.1): atan2 ≈ −π + 0.1, s ≈ 0.016 (left column); (−1, 0.1): s ≈ 0.98.
    assert_eq!(tex.eval(at(Vec2::ZERO, Vec3::new(-1.0, -0.1, 0.3), o)), Rgb::new(1.0, 0.0, 0.0));
    assert_eq!(tex.eval(at(Vec2::ZERO, Vec3::new(-1.0, 0.1, 0.3), o)), Rgb::new(0.0, 0.0, 1.0));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bad texture parameters are errors naming the file and line.
#[test]
fn bad_texture_parameters() {
    for (body, what) in [
        ("Texture \"t\" \"float\" \"marble\"", "spectrum texture"),
        ("Texture \"t\" \"float\" \"fbm\" \"integer octaves\" -1", "octaves"),
        ("Texture \"t\" \"float\" \"fbm\" \"float octaves\" 2", "expected"),
        ("Texture \"t\" \"float\" \"dots\" \"string mapping\" \"toroidal\"", "mapping 'toroidal'"),
        ("Texture \"t\" \"spectrum\" \"ptex\" \"string filename\" \"a.ptx\"", "not supported"),
        ("Texture \"t\" \"spectrum\" \"directionmix\" \"vector3 dir\" [ 0 0 0 ]", "non-zero"),
        ("Texture \"t\" \"float\" \"bilerp\" \"texture v00\" \"nope\"", "no float texture"),
    ] {
        let e = load_pbrt_from_str(&world(body), Path::new("bad.pbrt")).err().unwrap_or_else(|| panic!("accepted {body}")).to_string();
        assert!(e.contains("bad.pbrt:4:") && e.contains(what), "{body}: {e}");
    }
}

fn render(scene: &Scene, integrator: &str, spp: u32) -> svetlo::film::Image {
    let mut s = RenderSettings::from_scene(scene);
    s.spp = spp;
    let integ = svetlo::methods::by_name(integrator).expect("integrator");
    integ.render(scene, &s, &Progress::new()).expect("render").image()
}

/// The project's scenes for this feature load (every light and shape arrives) and render to
/// finite, non-black images with the path tracer and, for the lights, with light tracing
/// and BDPT (which sample the lights' emission). The projection's two colours reach the
/// back wall: red-dominated and blue-dominated pixels both appear.
#[test]
fn own_scenes_render() {
    let lights = svetlo::io::load_pbrt(&own_scene("lights.pbrt")).expect("lights.pbrt");
    assert_eq!(lights.lights.len(), 2);
    assert!(lights.lights.iter().any(|l| matches!(l, Light::Goniometric(_))) && lights.lights.iter().any(|l| matches!(l, Light::Projector(_))));
    for integ in ["path", "light", "bdpt"] {
        let img = render(&lights, integ, 2);
        assert!(img.data.iter().all(|c| c.is_finite()), "{integ}: non-finite pixels");
        let mean: f32 = img.data.iter().map(|c| c.mean()).sum::<f32>() / img.data.len() as f32;
        assert!(mean > 1e-3, "{integ}: black ({mean})");
        assert!(img.data.iter().any(|c| c.r > 3.0 * c.b && c.r > 0.05), "{integ}: no red pixel");
        assert!(img.data.iter().any(|c| c.b > 3.0 * c.r && c.b > 0.05), "{integ}: no blue pixel");
    }
    let procedural = svetlo::io::load_pbrt(&own_scene("procedural.pbrt")).expect("procedural.pbrt");
    assert_eq!((procedural.shapes.len(), procedural.lights.len()), (6, 2));
    let img = render(&procedural, "path", 2);
    assert!(img.data.iter().all(|c| c.is_finite()));
    let mean: f32 = img.data.iter().map(|c| c.mean()).sum::<f32>() / img.data.len() as f32;
    assert!(mean > 1e-3, "procedural: black ({mean})");
}

/// The path tracer, BDPT and the light tracer agree on `lights.pbrt` (per-pixel Z-test): the
/// goniometric and projection lights' NEE and their importance-sampled emission give the
/// same image.
/// (48 × 32: a few seconds.)
#[test]
fn lights_scene_path_bdpt_and_light_tracing_agree() {
    use svetlo::film::compare::z_test;
    use svetlo::film::Image;
    let scene = svetlo::io::load_pbrt(&own_scene("lights.pbrt")).expect("lights.pbrt");
    let run = |integ: &str, seed: u64| {
        let mut s = RenderSettings::from_scene(&scene);
        s.spp = 256;
        s.seed = seed;
        let f = svetlo::methods::by_name(integ).unwrap().render(&scene, &s, &Progress::new()).unwrap();
        (f.image(), f.variance_image(), f.spp_done)
    };
    let (a, va, n) = run("path", 1);
    let (b, vb, _) = run("bdpt", 2);
    let var = Image::new(va.width, va.height, va.data.iter().zip(&vb.data).map(|(x, y)| *x + *y).collect());
    let z = z_test(&a, &b, &var, n).expect("z-test");
    println!("path vs bdpt: {:.3} % pass, relMSE {:.2e}", 100.0 * z.fraction_passing, z.relmse);
    assert!(z.pass, "path vs bdpt: {:.3} % pass", 100.0 * z.fraction_passing);
    // The light tracer splats, so its film has no per-pixel sample variance: compare the
    // luminance of 8 × 8-pixel blocks over independent batches (Student's t on 2 × 11 dof;
    // |t| < 5 for all 24 blocks fails by chance with probability about 1 %).
    let batches = |integ: &str, base: u64| -> Vec<Vec<f64>> {
        (0..12u64)
            .map(|k| {
                let mut s = RenderSettings::from_scene(&scene);
                s.spp = 32;
                s.seed = base + k;
                let img = svetlo::methods::by_name(integ).unwrap().render(&scene, &s, &Progress::new()).unwrap().image();
                let mut blocks = vec![0.0f64; (img.width / 8 * (img.height / 8)) as usize];
                for y in 0..img.height {
                    for x in 0..img.width {
                        blocks[((y / 8) * (img.width / 8) + x / 8) as usize] += img.data[(y * img.width + x) as usize].luminance() as f64 / 64.0;
                    }
                }
                blocks
            })
            .collect()
    };
    let stats = |b: &[Vec<f64>], i: usize| {
        let n = b.len() as f64;
        let m = b.iter().map(|v| v[i]).sum::<f64>() / n;
        let var = b.iter().map(|v| (v[i] - m).powi(2)).sum::<f64>() / (n - 1.0);
        (m, var / n)
    };
    let (pa, lb) = (batches("path", 100), batches("light", 200));
    for i in 0..pa[0].len() {
        let ((ma, sa), (mb, sb)) = (stats(&pa, i), stats(&lb, i));
        let t = (ma - mb) / (sa + sb).sqrt().max(1e-12);
        assert!(t.abs() < 5.0, "block {i}: path {ma:.5} vs light tracing {mb:.5} (t = {t:.2})");
    }
}

/// The equal-area map the goniometric light uses is the infinite light's: texel centres
/// round-trip through it.
#[test]
fn goniometric_uses_the_equal_area_map() {
    let g = Goniometric::new(&Mat4::IDENTITY, Rgb::WHITE, (0..64).map(|i| i as f32).collect(), 8).unwrap();
    for k in 0..64 {
        let uv = Vec2::new(((k % 8) as f32 + 0.5) / 8.0, ((k / 8) as f32 + 0.5) / 8.0);
        assert_eq!(g.eval(equal_area_square_to_sphere(uv)).r, k as f32);
    }
}

/// `convert` of `scenes/pbrt/procedural.pbrt`: to pbrt, every shape's reflectance texture
/// reads back the same at random points (uv, position, normal), mappings and texture
/// spaces included; to Mitsuba, each procedural texture becomes its mean, with a note.
#[test]
fn convert_procedural_textures() {
    let scene = svetlo::io::load_pbrt(&own_scene("procedural.pbrt")).expect("procedural.pbrt");
    let dir = std::env::temp_dir().join(format!("svetlo-convert-tex-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let refl = |s: &Scene, i: usize| {
        let m = &s.materials[s.shapes[i].material as usize];
        match m {
            Material::TwoSided { front, .. } => match &**front {
                Material::Diffuse { reflectance } => reflectance.clone(),
                other => panic!("{}", other.kind_name()),
            },
            other => panic!("{}", other.kind_name()),
        }
    };
    let mut rng = Pcg32::new(12, 9);
    let points: Vec<TexPoint> = (0..200)
        .map(|_| {
            let uv = u2(&mut rng);
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 6.0 - Vec3::splat(3.0);
            let n = svetlo::math::warp::square_to_uniform_sphere(u2(&mut rng));
            TexPoint { uv, p, n, ..Default::default() }
        })
        .collect();
    let out = dir.join("back.pbrt");
    svetlo::io::export::export_scene(&scene, &out, svetlo::io::SceneFormat::Pbrt).expect("export");
    let back = svetlo::io::load_scene_as(&out, None, &[]).expect("reload");
    assert_eq!(back.shapes.len(), scene.shapes.len());
    for i in 0..scene.shapes.len() {
        let (a, b) = (refl(&scene, i), refl(&back, i));
        for q in &points {
            let (x, y) = (a.eval(*q), b.eval(*q));
            assert!((x - y).map(f32::abs).max_component() < 1e-4 * (1.0 + x.max_component()), "shape {i} ({}): {x:?} vs {y:?} at {q:?}", scene.shapes[i].name);
        }
    }
    let out = dir.join("back.xml");
    let notes = svetlo::io::export::export_scene(&scene, &out, svetlo::io::SceneFormat::Mitsuba).expect("export");
    let back = svetlo::io::load_scene_as(&out, None, &[]).expect("reload");
    for name in ["bilerp", "marble", "scale", "mix", "dots"] {
        assert!(notes.iter().any(|n| n.contains(&format!("'{name}'"))), "no note for {name}: {notes:?}");
    }
    for i in 0..scene.shapes.len() {
        let (a, b) = (refl(&scene, i).mean(), refl(&back, i));
        assert!(b.is_constant(), "shape {i}");
        assert!((a - b.mean()).map(f32::abs).max_component() < 1e-4, "shape {i}: mean {a:?} vs {:?}", b.mean());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// 8-bit imagemaps keep their codes (as Mitsuba's bitmaps do) with the values pbrt gives
/// them: sRGB-decoded by default, code / 255 exactly with `"string encoding" "linear"` (the
/// loader once decoded sRGB and encoded it again, a few ulps off).
#[test]
fn eight_bit_imagemaps_keep_their_codes() {
    let dir = std::env::temp_dir().join(format!("svetlo-imagemap8-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let codes = [10u8, 128, 255, 0, 64, 201];
    image::RgbImage::from_raw(2, 1, codes.to_vec()).unwrap().save(dir.join("c.png")).unwrap();
    for (encoding, decode) in [("", Rgb::srgb_to_linear as fn(f32) -> f32), ("\"string encoding\" \"linear\"", |x| x)] {
        let text = world(&format!(
            "Texture \"t\" \"spectrum\" \"imagemap\" \"string filename\" \"c.png\" {encoding}\nMaterial \"diffuse\" \"texture reflectance\" \"t\"\nShape \"sphere\""
        ));
        let tex = reflectance(&load_pbrt_from_str(&text, &dir.join("m.pbrt")).unwrap());
        let Texture::Bitmap { image, .. } = &tex else { panic!("not a bitmap texture: {encoding}") };
        assert!(image.is_8bit(), "{encoding}: an 8-bit PNG keeps its codes");
        for (x, c) in codes.chunks(3).enumerate() {
            let want = Rgb::new(decode(c[0] as f32 / 255.0), decode(c[1] as f32 / 255.0), decode(c[2] as f32 / 255.0));
            assert_eq!(image.texel(x, 0), want, "{encoding}: texel {x}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
