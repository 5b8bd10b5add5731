//! Scenes and comparisons shared by the tests of the classic integrators: small scenes built
//! in code, and a per-pixel Z-test of two independent renders with their variance images.
#![allow(dead_code)]

use glam::{Mat4, Vec3, Vec4};
use svetlo::bsdf::Material;
use svetlo::camera::{Camera, Projection};
use svetlo::film::{Film, Filter};
use svetlo::geometry::{Geometry, Sphere, TriangleMesh};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::texture::Texture;
use svetlo::Rgb;

/// Mitsuba's look-at: +z toward the target, +x = up × z (the image's left).
pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let z = (target - origin).normalize();
    let x = up.cross(z).normalize();
    let y = z.cross(x);
    Mat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), Vec4::new(origin.x, origin.y, origin.z, 1.0))
}

pub fn camera(to_world: Mat4, fov_x_deg: f32, w: u32, h: u32) -> Camera {
    Camera {
        to_world,
        projection: Projection::Perspective { fov_x_deg, aperture_radius: 0.0, focus_distance: 1.0 },
        width: w,
        height: h,
        near_clip: 1e-2,
        far_clip: 1e4,
        shutter_open: 0.0,
        shutter_close: 0.0,
    }
}

/// A quad with corners c, c+a, c+a+b, c+b; its normal is a × b.
pub fn quad(c: Vec3, a: Vec3, b: Vec3) -> Geometry {
    Geometry::Mesh(TriangleMesh { positions: vec![c, c + a, c + a + b, c + b], normals: vec![], uvs: vec![], indices: vec![[0, 1, 2], [0, 2, 3]] })
}

pub fn sphere(center: Vec3, radius: f32) -> Geometry {
    Geometry::Sphere(Sphere { center, radius, flip_normals: false })
}

pub fn diffuse(r: Rgb) -> Material {
    Material::Diffuse { reflectance: Texture::Constant(r) }
}

pub fn mirror() -> Material {
    Material::Conductor { eta: Rgb::new(0.2, 0.9, 1.1), k: Rgb::new(3.9, 2.4, 2.2), specular_reflectance: Texture::Constant(Rgb::WHITE), roughness: None }
}

pub fn glass() -> Material {
    Material::Dielectric {
        eta: 1.5,
        specular_reflectance: Texture::Constant(Rgb::WHITE),
        specular_transmittance: Texture::Constant(Rgb::WHITE),
        roughness: None,
    }
}

pub fn add(b: &mut SceneBuilder, g: Geometry, m: Material, emission: Option<Rgb>, name: &str) {
    let mi = b.add_material(m);
    b.add_shape(g, mi, emission.map(Texture::Constant), name).expect("shape");
}

pub fn render(scene: &Scene, name: &str, spp: u32, max_depth: i32, seed: u64) -> Film {
    let settings = RenderSettings { spp, max_depth, seed, filter: Filter::Box, ..Default::default() };
    svetlo::methods::by_name(name).expect("integrator").render(scene, &settings, &Progress::new()).expect("render")
}

/// Outcome of comparing two renders pixel by pixel.
#[derive(Debug)]
pub struct Comparison {
    pub failed: usize,
    pub tested: usize,
    pub min_p: f64,
    pub mean_a: f64,
    pub mean_b: f64,
    /// z of the difference of the image means.
    pub mean_z: f64,
}

/// Two-sample per-pixel, per-channel Z-test of independent renders `a` and `b` (box filter,
/// so that each pixel's samples are its own): z = (a - b) / sqrt(va/na + vb/nb). A channel
/// fails below the Šidák level for `alpha` over all channels tested. Channels where both
/// variances vanish must agree to `exact_tol` (relative). Also the z of the image means.
pub fn compare(a: &Film, b: &Film, alpha: f64, exact_tol: f32) -> Comparison {
    let (ia, ib, va, vb) = (a.image(), b.image(), a.variance_image(), b.variance_image());
    let (na, nb) = (a.spp_done as f64, b.spp_done as f64);
    let n = ia.data.len() * 3;
    let level = 1.0 - (1.0 - alpha).powf(1.0 / n as f64);
    let mut failed = 0;
    let mut min_p = 1.0f64;
    let (mut sa, mut sb, mut sv) = (0.0, 0.0, 0.0);
    for i in 0..ia.data.len() {
        for c in 0..3 {
            let (x, y) = (ia.data[i][c] as f64, ib.data[i][c] as f64);
            let var = va.data[i][c] as f64 / na + vb.data[i][c] as f64 / nb;
            sa += x;
            sb += y;
            sv += var;
            if var <= 1e-12 {
                if (x - y).abs() > exact_tol as f64 * x.abs().max(y.abs()) + 1e-6 {
                    failed += 1;
                    min_p = 0.0;
                }
                continue;
            }
            let z = (x - y).abs() / var.sqrt();
            let p = svetlo::sampling::stats::two_sided_p(z);
            min_p = min_p.min(p);
            if p < level {
                failed += 1;
                if std::env::var("SVETLO_DEBUG_COMPARE").is_ok() {
                    eprintln!("pixel {} ch {c}: {x} vs {y}, var {} / {}", i, va.data[i][c], vb.data[i][c]);
                }
            }
        }
    }
    let mean_z = (sa - sb) / sv.sqrt().max(1e-12);
    Comparison { failed, tested: n, min_p, mean_a: sa / n as f64, mean_b: sb / n as f64, mean_z }
}

pub fn rough_conductor(alpha: f32) -> Material {
    Material::Conductor {
        eta: Rgb::new(0.2, 0.9, 1.1),
        k: Rgb::new(3.9, 2.4, 2.2),
        specular_reflectance: Texture::Constant(Rgb::WHITE),
        roughness: Some(svetlo::bsdf::material::Roughness {
            kind: svetlo::bsdf::MicrofacetKind::Ggx,
            alpha_u: Texture::Constant(Rgb::splat(alpha)),
            alpha_v: Texture::Constant(Rgb::splat(alpha)),
        }),
    }
}

pub fn phong_material(kd: f32, ks: f32, n: f32) -> Material {
    Material::Phong {
        diffuse_reflectance: Texture::Constant(Rgb::splat(kd)),
        specular_reflectance: Texture::Constant(Rgb::splat(ks)),
        exponent: Texture::Constant(Rgb::splat(n)),
    }
}

pub fn blinn_material(kd: f32, ks: f32, n: f32) -> Material {
    Material::BlinnPhong {
        diffuse_reflectance: Texture::Constant(Rgb::splat(kd)),
        specular_reflectance: Texture::Constant(Rgb::splat(ks)),
        exponent: Texture::Constant(Rgb::splat(n)),
    }
}
