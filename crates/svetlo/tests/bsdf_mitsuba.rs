//! Agreement with Mitsuba 3 (3.9.1, `scalar_rgb`) on BSDF values: `eval`, `pdf` and the
//! weights of delta samples, for the materials as the scene describes them (through
//! `Material::bsdf`, so the one-sided wrapper and the texture wiring are tested too).
//! The reference values come from tests/data/gen_mitsuba_bsdf_refs.py.
//!
//! Tolerances: 1e-3 relative where both renderers evaluate the same closed form. Beckmann
//! models get 1 %: Mitsuba approximates the Beckmann Smith G1 by a rational fit (< 0.35 %
//! error) where svetlo evaluates it exactly. Rough plastic gets 1 % for the same reason and
//! because both integrate the coating's transmittance numerically.

use glam::{Vec2, Vec3};
use svetlo::bsdf::material::Roughness;
use svetlo::bsdf::{Bsdf, Material, MicrofacetKind, TransportMode};
use svetlo::texture::Texture;
use svetlo::Rgb;

const REFS: &str = include_str!("data/mitsuba_bsdf_refs.csv");

fn rough(kind: MicrofacetKind, au: f32, av: f32) -> Option<Roughness> {
    Some(Roughness { kind, alpha_u: Texture::from(au), alpha_v: Texture::from(av) })
}

/// The materials of MODELS in gen_mitsuba_bsdf_refs.py, in the same order, with their
/// tolerance.
fn models() -> Vec<(Material, f32)> {
    use MicrofacetKind::{Beckmann, Ggx};
    let (eta, k) = (Rgb::new(0.2, 0.9, 1.1), Rgb::new(3.9, 2.4, 2.2));
    let white = || Texture::from(Rgb::WHITE);
    let rgb = |r, g, b| Texture::from(Rgb::new(r, g, b));
    vec![
        (Material::Conductor { eta, k, specular_reflectance: white(), roughness: rough(Ggx, 0.2, 0.4) }, 1e-3),
        (Material::Conductor { eta, k, specular_reflectance: white(), roughness: rough(Beckmann, 0.3, 0.3) }, 1e-2),
        (Material::Dielectric { eta: 1.5, specular_reflectance: white(), specular_transmittance: white(), roughness: rough(Ggx, 0.3, 0.3) }, 1e-3),
        (Material::Dielectric { eta: 1.33, specular_reflectance: white(), specular_transmittance: white(), roughness: rough(Beckmann, 0.1, 0.3) }, 1e-2),
        (
            Material::Plastic {
                diffuse_reflectance: rgb(0.02, 0.2, 0.1),
                specular_reflectance: white(),
                eta: 1.5168,
                nonlinear: false,
                roughness: rough(Ggx, 0.1, 0.1),
            },
            1e-2,
        ),
        (
            Material::Plastic {
                diffuse_reflectance: rgb(0.5, 0.5, 0.5),
                specular_reflectance: white(),
                eta: 1.9,
                nonlinear: true,
                roughness: rough(Beckmann, 0.4, 0.4),
            },
            1e-2,
        ),
        (Material::Plastic { diffuse_reflectance: rgb(0.1, 0.27, 0.36), specular_reflectance: white(), eta: 1.9, nonlinear: false, roughness: None }, 1e-3),
        (Material::Plastic { diffuse_reflectance: rgb(0.8, 0.8, 0.8), specular_reflectance: white(), eta: 1.5, nonlinear: true, roughness: None }, 1e-3),
        (Material::Diffuse { reflectance: rgb(0.5, 0.5, 0.5) }, 1e-4),
        (Material::Conductor { eta, k, specular_reflectance: white(), roughness: None }, 1e-4),
        (Material::Dielectric { eta: 1.5, specular_reflectance: white(), specular_transmittance: white(), roughness: None }, 1e-4),
        (Material::ThinDielectric { eta: 1.5, specular_reflectance: white(), specular_transmittance: white() }, 1e-4),
        (
            Material::Plastic {
                diffuse_reflectance: rgb(0.3, 0.6, 0.9),
                specular_reflectance: white(),
                eta: 1.49,
                nonlinear: false,
                roughness: rough(Ggx, 0.6, 0.6),
            },
            1e-2,
        ),
    ]
}

fn v3(x: &[f32]) -> Vec3 {
    Vec3::new(x[0], x[1], x[2])
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-6
}

#[test]
fn eval_pdf_and_delta_samples_match_mitsuba() {
    let mats = models();
    let bsdfs: Vec<Bsdf> = mats.iter().map(|(m, _)| m.bsdf(Vec2::new(0.3, 0.7))).collect();
    let (mut evals, mut deltas, mut failures) = (0, 0, Vec::new());
    let mut worst = vec![0f32; mats.len()];
    for line in REFS.lines() {
        let cols: Vec<&str> = line.split(',').collect();
        let id: usize = cols[0].parse().unwrap();
        let nums: Vec<f32> = cols[2..].iter().map(|s| s.parse().unwrap()).collect();
        let (b, tol) = (&bsdfs[id], mats[id].1);
        let wo = v3(&nums[0..3]);
        match cols[1] {
            "eval" => {
                let wi = v3(&nums[3..6]);
                // Skip directions within 0.5° of the horizon, where f32 rounding dominates.
                if wo.z.abs() < 0.01 || wi.z.abs() < 0.01 {
                    continue;
                }
                let f = b.eval(wo, wi, TransportMode::Radiance);
                let pdf = b.pdf(wo, wi, TransportMode::Radiance);
                let ok = (0..3).all(|c| close(f[c], nums[6 + c], tol)) && close(pdf, nums[9], tol);
                let rel = |a: f32, b: f32| (a - b).abs() / (a.abs().max(b.abs()) + 1e-6);
                worst[id] = (0..3).map(|c| rel(f[c], nums[6 + c])).fold(rel(pdf, nums[9]), f32::max).max(worst[id]);
                if !ok {
                    failures.push(format!("model {id} eval wo {wo:?} wi {wi:?}: f {f:?} pdf {pdf} vs mitsuba {:?} {}", &nums[6..9], nums[9]));
                }
                evals += 1;
            }
            "sample" => {
                let (uc, u) = (nums[3], Vec2::new(nums[4], nums[5]));
                let (mwi, mw, delta) = (v3(&nums[6..9]), Rgb::new(nums[9], nums[10], nums[11]), nums[12] == 1.0);
                if !delta {
                    continue;
                }
                deltas += 1;
                match b.sample(wo, uc, u, TransportMode::Radiance) {
                    Some(s) if s.lobe.is_specular() => {
                        let w = s.weight();
                        if (s.wi - mwi).length() > 1e-4 || !(0..3).all(|c| close(w[c], mw[c], tol.max(1e-4))) {
                            failures.push(format!("model {id} sample wo {wo:?} uc {uc}: wi {:?} w {w:?} vs mitsuba {mwi:?} {mw:?}", s.wi));
                        }
                    }
                    other => failures.push(format!("model {id} sample wo {wo:?} uc {uc}: got {other:?}, mitsuba a delta lobe")),
                }
            }
            _ => panic!("bad row {line}"),
        }
    }
    eprintln!(
        "compared {evals} evaluations and {deltas} delta samples; worst relative difference per model: {:?}",
        worst.iter().map(|w| format!("{w:.1e}")).collect::<Vec<_>>()
    );
    assert!(evals > 500 && deltas > 40);
    assert!(failures.is_empty(), "{} mismatches:\n{}", failures.len(), failures.join("\n"));
}
