//! Surface detail (`normalmap`, `bumpmap`) and `blendbsdf` as whole `Bsdf`s: chi-square
//! goodness of fit of `sample` against `pdf` (with `sample`'s values equal to `eval`/`pdf`),
//! the adjoint relation between the transport modes, the identity map and the mixture.
//! Fixed seeds; each family rejects with 1 % probability overall when the code is right.

mod common;

use common::*;
use glam::{Vec2, Vec3};
use svetlo::bsdf::blend::Blend;
use svetlo::bsdf::conductor::RoughConductor;
use svetlo::bsdf::detail::{normal_map_normal, Detail};
use svetlo::bsdf::dielectric::SmoothDielectric;
use svetlo::bsdf::diffuse::Diffuse;
use svetlo::bsdf::microfacet::Microfacet;
use svetlo::bsdf::{Bsdf, BsdfModel, MicrofacetKind, TransportMode};
use svetlo::sampling::stats::sidak_alpha;
use svetlo::sampling::Pcg32;
use svetlo::Rgb;

const FAMILY_ALPHA: f64 = 0.01;
const BINS: SphereBins = SphereBins { n_cos: 10, n_phi: 20 };
const N: usize = 100_000;

fn diffuse(r: f32) -> BsdfModel {
    BsdfModel::Diffuse(Diffuse { reflectance: Rgb::splat(r) })
}
fn rough_conductor(au: f32, av: f32) -> BsdfModel {
    BsdfModel::RoughConductor(RoughConductor {
        distribution: Microfacet::new(MicrofacetKind::Ggx, au, av),
        eta: Rgb::new(0.2, 0.9, 1.1),
        k: Rgb::new(3.9, 2.4, 2.2),
        specular_reflectance: Rgb::WHITE,
    })
}
fn glass() -> BsdfModel {
    BsdfModel::SmoothDielectric(SmoothDielectric { eta: 1.5, specular_reflectance: Rgb::WHITE, specular_transmittance: Rgb::WHITE })
}
fn detailed(m: BsdfModel, texel: Rgb) -> Bsdf {
    Bsdf { detail: Some(Detail::new(normal_map_normal(texel), true)), ..Bsdf::new(m) }
}

/// Perturbed normals: slightly and strongly tilted, in different azimuths.
const TEXELS: [(f32, f32, f32); 3] = [(0.6, 0.45, 0.95), (0.9, 0.5, 0.6), (0.3, 0.15, 0.7)];

fn run(label: &str, cases: &[(String, Bsdf)], wos: &[Vec3], modes: &[TransportMode]) {
    let total = cases.len() * wos.len() * modes.len();
    let level = sidak_alpha(FAMILY_ALPHA, total);
    let mut failures = Vec::new();
    let mut k = 0u64;
    for (name, b) in cases {
        for &wo in wos {
            for &mode in modes {
                k += 1;
                let o = chi2_test(b, wo, mode, BINS, N, 77 + k);
                if o.p_value < level || o.impossible > 0 || o.mismatches * 10_000 > N {
                    failures.push(format!(
                        "{name} wo={wo:?} {mode:?}: p={:.3e} mismatches={} impossible={} {}",
                        o.p_value,
                        o.mismatches,
                        o.impossible,
                        o.first_mismatch.unwrap_or_default()
                    ));
                }
            }
        }
    }
    eprintln!("{label}: {total} tests at Šidák level {level:.2e}");
    assert!(failures.is_empty(), "{label}: {} of {total} failed:\n{}", failures.len(), failures.join("\n"));
}

/// Directions above and below the perturbed normals, grazing included.
fn wos() -> Vec<Vec3> {
    vec![dir_deg(10.0, 30.0), dir_deg(55.0, 200.0), dir_deg(80.0, 10.0)]
}

#[test]
fn chi2_normal_mapped() {
    let mut cases = Vec::new();
    for t in TEXELS {
        let texel = Rgb::new(t.0, t.1, t.2);
        cases.push((format!("normalmap {t:?} diffuse"), detailed(diffuse(0.7), texel)));
        cases.push((format!("normalmap {t:?} roughconductor 0.25/0.05"), detailed(rough_conductor(0.25, 0.05), texel)));
    }
    run("normal-mapped", &cases, &wos(), &[TransportMode::Radiance, TransportMode::Importance]);
}

#[test]
fn chi2_blend() {
    let cases = vec![
        (
            "blend diffuse/roughconductor 0.3".to_string(),
            Bsdf::new(BsdfModel::Blend(Box::new(Blend { a: Bsdf::new(diffuse(0.8)), b: Bsdf::new(rough_conductor(0.3, 0.3)), weight: 0.3 }))),
        ),
        (
            "blend roughconductor/glass 0.6".to_string(),
            Bsdf::new(BsdfModel::Blend(Box::new(Blend { a: Bsdf::new(rough_conductor(0.1, 0.4)), b: Bsdf::new(glass()), weight: 0.6 }))),
        ),
        (
            "blend with normal map".to_string(),
            Bsdf::new(BsdfModel::Blend(Box::new(Blend { a: detailed(diffuse(0.5), Rgb::new(0.8, 0.4, 0.7)), b: Bsdf::new(diffuse(0.9)), weight: 0.5 }))),
        ),
    ];
    run("blend", &cases, &wos(), &[TransportMode::Radiance]);
}

/// The flat normal map changes nothing (the identity scene of Mitsuba's suite).
#[test]
fn identity_map_is_no_map() {
    let mut rng = Pcg32::new(3, 5);
    for m in [diffuse(0.6), rough_conductor(0.25, 0.05)] {
        let plain = Bsdf::new(m.clone());
        let mapped = detailed(m, Rgb::new(0.5, 0.5, 1.0));
        for _ in 0..1000 {
            let (wo, wi) = (uniform_dir(&mut rng), uniform_dir(&mut rng));
            let (a, b) = (plain.eval(wo, wi, TransportMode::Radiance), mapped.eval(wo, wi, TransportMode::Radiance));
            assert!((a - b).max_component().abs() <= 1e-5 * a.max_component().max(1.0), "{wo} {wi}: {a:?} vs {b:?}");
            assert!((plain.pdf(wo, wi, TransportMode::Radiance) - mapped.pdf(wo, wi, TransportMode::Radiance)).abs() <= 1e-4);
        }
    }
}

/// f_importance(wo, wi) = f_radiance(wi, wo) wherever neither direction needs the mirrored
/// normal (the frame follows the direction the path arrives from).
#[test]
fn modes_are_adjoint() {
    let mut rng = Pcg32::new(9, 1);
    let mut checked = 0;
    for t in TEXELS {
        let d = Detail::new(normal_map_normal(Rgb::new(t.0, t.1, t.2)), true);
        for m in [diffuse(0.6), rough_conductor(0.3, 0.1)] {
            let b = Bsdf { detail: Some(d), ..Bsdf::new(m) };
            for _ in 0..2000 {
                let (wo, wi) = (uniform_dir(&mut rng), uniform_dir(&mut rng));
                if wo.z * wo.dot(d.n) <= 0.0 || wi.z * wi.dot(d.n) <= 0.0 {
                    continue;
                }
                let (fi, fr) = (b.eval(wo, wi, TransportMode::Importance), b.eval(wi, wo, TransportMode::Radiance));
                assert!((fi - fr).max_component().abs() <= 1e-4 * fr.max_component().max(1e-3), "{wo} {wi}: {fi:?} vs {fr:?}");
                checked += 1;
            }
        }
    }
    assert!(checked > 1000, "{checked}");
}

/// The blend is the weighted sum of its parts in value and density, and conserves energy
/// (white furnace: albedo <= 1 for white parts).
#[test]
fn blend_is_the_mixture() {
    let (a, b) = (Bsdf::new(diffuse(1.0)), Bsdf::new(rough_conductor(0.2, 0.2)));
    let w = 0.35;
    let blend = Bsdf::new(BsdfModel::Blend(Box::new(Blend { a: a.clone(), b: b.clone(), weight: w })));
    let mut rng = Pcg32::new(4, 4);
    for _ in 0..1000 {
        let (wo, wi) = (uniform_dir(&mut rng), uniform_dir(&mut rng));
        let m = TransportMode::Radiance;
        let want = a.eval(wo, wi, m) * (1.0 - w) + b.eval(wo, wi, m) * w;
        assert!((blend.eval(wo, wi, m) - want).max_component().abs() <= 1e-6);
        let want_pdf = a.pdf(wo, wi, m) * (1.0 - w) + b.pdf(wo, wi, m) * w;
        assert!((blend.pdf(wo, wi, m) - want_pdf).abs() <= 1e-5 * want_pdf.max(1.0));
    }
    let mut rng = Pcg32::new(8, 2);
    for wo in wos() {
        let (mut sum, n) = (0.0f64, 200_000);
        for _ in 0..n {
            if let Some(s) = blend.sample(wo, rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()), TransportMode::Radiance) {
                sum += s.weight().max_component() as f64;
            }
        }
        assert!(sum / (n as f64) < 1.0 + 0.01, "albedo {} at {wo}", sum / n as f64);
    }
}
