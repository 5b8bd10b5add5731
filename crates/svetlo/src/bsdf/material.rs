//! Materials as the scene describes them (textured parameters). At a hit point a
//! material becomes a [`Bsdf`] with every texture evaluated.

use super::blinn::BlinnPhong;
use super::conductor::{RoughConductor, SmoothConductor};
use super::cook_torrance::CookTorrance;
use super::dielectric::{RoughDielectric, SmoothDielectric, ThinDielectric};
use super::lobes::glossy_sampling_weight;
use super::microfacet::Microfacet;
use super::oren_nayar::OrenNayar;
use super::phong::Phong;
use super::plastic::{self, RoughPlastic, SmoothPlastic};
use super::ward::{Ward, WardVariant};
use super::{diffuse::Diffuse, Bsdf, BsdfModel};
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::Vec2;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MicrofacetKind {
    Beckmann,
    #[default]
    Ggx,
}

/// Roughness of a microfacet model: `alpha_u` along the tangent, `alpha_v` along the bitangent.
#[derive(Clone, Debug)]
pub struct Roughness {
    pub kind: MicrofacetKind,
    pub alpha_u: Texture,
    pub alpha_v: Texture,
}

#[derive(Clone, Debug)]
pub enum Material {
    /// Mitsuba `diffuse`.
    Diffuse { reflectance: Texture },
    /// Mitsuba `conductor` (roughness None) and `roughconductor`. eta and k are complex IOR per channel.
    Conductor { eta: Rgb, k: Rgb, specular_reflectance: Texture, roughness: Option<Roughness> },
    /// Mitsuba `dielectric` and `roughdielectric`: `eta` = interior IOR / exterior IOR.
    Dielectric { eta: f32, specular_reflectance: Texture, specular_transmittance: Texture, roughness: Option<Roughness> },
    /// Mitsuba `thindielectric`.
    ThinDielectric { eta: f32, specular_reflectance: Texture, specular_transmittance: Texture },
    /// Mitsuba `plastic` and `roughplastic`: diffuse base under a dielectric coating.
    Plastic { diffuse_reflectance: Texture, specular_reflectance: Texture, eta: f32, nonlinear: bool, roughness: Option<Roughness> },
    /// Mitsuba 0.6 `phong`: the modified (energy-conserving) Phong of Lafortune and Willems.
    Phong { diffuse_reflectance: Texture, specular_reflectance: Texture, exponent: Texture },
    /// svetlo's `blinnphong`: normalised Blinn-Phong (see `bsdf/blinn.rs`).
    BlinnPhong { diffuse_reflectance: Texture, specular_reflectance: Texture, exponent: Texture },
    /// svetlo's `cooktorrance`: Beckmann D, V-groove G, dielectric Fresnel with `eta`.
    CookTorrance { diffuse_reflectance: Texture, specular_reflectance: Texture, alpha: Texture, eta: f32 },
    /// Mitsuba 0.6 `roughdiffuse` (qualitative Oren-Nayar), `alpha` the RMS slope.
    OrenNayar { reflectance: Texture, alpha: Texture },
    /// Mitsuba 0.6 `ward`.
    Ward { diffuse_reflectance: Texture, specular_reflectance: Texture, alpha_u: Texture, alpha_v: Texture, variant: WardVariant },
    /// Mitsuba `twosided`: front and back models (the same one twice in the common case).
    TwoSided { front: Box<Material>, back: Box<Material> },
    /// Mitsuba `mask`: the surface is present with probability `opacity`.
    Mask { opacity: Texture, inner: Box<Material> },
    /// Nothing scatters (e.g. a pure emitter); rays pass through unchanged.
    Null,
}

impl Default for Material {
    fn default() -> Self {
        Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.5)) }
    }
}

impl Roughness {
    /// The microfacet distribution at `uv` (alphas read from the first channel).
    pub fn at(&self, uv: Vec2) -> Microfacet {
        Microfacet::new(self.kind, self.alpha_u.eval_f32(uv), self.alpha_v.eval_f32(uv))
    }
}

/// Mean of a texture for sampling heuristics. Bitmaps would need a pass over every texel
/// per hit, so they use the local value: that changes only how samples are spread
/// between lobes (the estimate stays unbiased), not the BSDF.
fn sampling_mean(t: &Texture, uv: Vec2) -> f32 {
    match t {
        Texture::Bitmap { .. } => t.eval(uv).mean(),
        _ => t.mean().mean(),
    }
}

impl Material {
    /// The Mitsuba plugin name this material stands for (`svetlo info`, Python's `scene.info()`).
    pub fn kind_name(&self) -> String {
        let rough = |r: bool, smooth: &str, rough: &str| if r { rough.to_string() } else { smooth.to_string() };
        match self {
            Material::Diffuse { .. } => "diffuse".into(),
            Material::Conductor { roughness, .. } => rough(roughness.is_some(), "conductor", "roughconductor"),
            Material::Dielectric { roughness, .. } => rough(roughness.is_some(), "dielectric", "roughdielectric"),
            Material::ThinDielectric { .. } => "thindielectric".into(),
            Material::Plastic { roughness, .. } => rough(roughness.is_some(), "plastic", "roughplastic"),
            Material::Phong { .. } => "phong".into(),
            Material::BlinnPhong { .. } => "blinnphong".into(),
            Material::CookTorrance { .. } => "cooktorrance".into(),
            Material::OrenNayar { .. } => "roughdiffuse".into(),
            Material::Ward { .. } => "ward".into(),
            Material::TwoSided { front, .. } => format!("twosided({})", front.kind_name()),
            Material::Mask { inner, .. } => format!("mask({})", inner.kind_name()),
            Material::Null => "null".into(),
        }
    }

    /// Does the BSDF not depend on the surface point (no texture but constants)? Then one
    /// `bsdf()` serves every point, which the rasteriser's shading pass exploits.
    pub fn is_uniform(&self) -> bool {
        let c = |t: &Texture| matches!(t, Texture::Constant(_));
        let r = |r: &Option<Roughness>| r.as_ref().is_none_or(|r| c(&r.alpha_u) && c(&r.alpha_v));
        match self {
            Material::Diffuse { reflectance } => c(reflectance),
            Material::Conductor { specular_reflectance, roughness, .. } => c(specular_reflectance) && r(roughness),
            Material::Dielectric { specular_reflectance, specular_transmittance, roughness, .. } => {
                c(specular_reflectance) && c(specular_transmittance) && r(roughness)
            }
            Material::ThinDielectric { specular_reflectance, specular_transmittance, .. } => c(specular_reflectance) && c(specular_transmittance),
            Material::Plastic { diffuse_reflectance, specular_reflectance, roughness, .. } => c(diffuse_reflectance) && c(specular_reflectance) && r(roughness),
            Material::Phong { diffuse_reflectance, specular_reflectance, exponent }
            | Material::BlinnPhong { diffuse_reflectance, specular_reflectance, exponent } => c(diffuse_reflectance) && c(specular_reflectance) && c(exponent),
            Material::CookTorrance { diffuse_reflectance, specular_reflectance, alpha, .. } => c(diffuse_reflectance) && c(specular_reflectance) && c(alpha),
            Material::OrenNayar { reflectance, alpha } => c(reflectance) && c(alpha),
            Material::Ward { diffuse_reflectance, specular_reflectance, alpha_u, alpha_v, .. } => {
                c(diffuse_reflectance) && c(specular_reflectance) && c(alpha_u) && c(alpha_v)
            }
            Material::TwoSided { front, back } => front.is_uniform() && back.is_uniform(),
            Material::Mask { opacity, inner } => c(opacity) && inner.is_uniform(),
            Material::Null => true,
        }
    }

    /// The model one side of this material describes, with textures evaluated at `uv`.
    fn model(&self, uv: Vec2) -> Option<BsdfModel> {
        match self {
            Material::Diffuse { reflectance } => Some(BsdfModel::Diffuse(Diffuse { reflectance: reflectance.eval(uv).clamp(0.0, 1.0) })),
            Material::Conductor { eta, k, specular_reflectance, roughness } => {
                let specular_reflectance = specular_reflectance.eval(uv);
                Some(match roughness {
                    None => BsdfModel::SmoothConductor(SmoothConductor { eta: *eta, k: *k, specular_reflectance }),
                    Some(r) => BsdfModel::RoughConductor(RoughConductor { distribution: r.at(uv), eta: *eta, k: *k, specular_reflectance }),
                })
            }
            Material::Dielectric { eta, specular_reflectance, specular_transmittance, roughness } => {
                let (specular_reflectance, specular_transmittance) = (specular_reflectance.eval(uv), specular_transmittance.eval(uv));
                Some(match roughness {
                    None => BsdfModel::SmoothDielectric(SmoothDielectric { eta: *eta, specular_reflectance, specular_transmittance }),
                    Some(r) => BsdfModel::RoughDielectric(RoughDielectric { distribution: r.at(uv), eta: *eta, specular_reflectance, specular_transmittance }),
                })
            }
            Material::ThinDielectric { eta, specular_reflectance, specular_transmittance } => Some(BsdfModel::ThinDielectric(ThinDielectric {
                eta: *eta,
                specular_reflectance: specular_reflectance.eval(uv),
                specular_transmittance: specular_transmittance.eval(uv),
            })),
            Material::Plastic { diffuse_reflectance, specular_reflectance, eta, nonlinear, roughness } => {
                let weight = plastic::specular_sampling_weight(sampling_mean(diffuse_reflectance, uv), sampling_mean(specular_reflectance, uv));
                let diffuse = diffuse_reflectance.eval(uv).clamp(0.0, 1.0);
                let specular = specular_reflectance.eval(uv);
                Some(match roughness {
                    None => BsdfModel::SmoothPlastic(SmoothPlastic {
                        diffuse_reflectance: diffuse,
                        specular_reflectance: specular,
                        eta: *eta,
                        nonlinear: *nonlinear,
                        specular_sampling_weight: weight,
                    }),
                    // Mitsuba's roughplastic is isotropic: alpha_u is the roughness.
                    Some(r) => BsdfModel::RoughPlastic(RoughPlastic::new(r.kind, r.alpha_u.eval_f32(uv), diffuse, specular, *eta, *nonlinear, weight)),
                })
            }
            Material::Phong { diffuse_reflectance, specular_reflectance, exponent } => {
                let (kd, ks) = (diffuse_reflectance.eval(uv).clamp(0.0, 1.0), specular_reflectance.eval(uv).clamp(0.0, 1.0));
                let w = glossy_sampling_weight(kd, ks);
                Some(BsdfModel::Phong(Phong {
                    diffuse_reflectance: kd,
                    specular_reflectance: ks,
                    exponent: exponent.eval_f32(uv).max(0.0),
                    specular_sampling_weight: w,
                }))
            }
            Material::BlinnPhong { diffuse_reflectance, specular_reflectance, exponent } => {
                let (kd, ks) = (diffuse_reflectance.eval(uv).clamp(0.0, 1.0), specular_reflectance.eval(uv).clamp(0.0, 1.0));
                let w = glossy_sampling_weight(kd, ks);
                Some(BsdfModel::BlinnPhong(BlinnPhong {
                    diffuse_reflectance: kd,
                    specular_reflectance: ks,
                    exponent: exponent.eval_f32(uv).max(0.0),
                    specular_sampling_weight: w,
                }))
            }
            Material::CookTorrance { diffuse_reflectance, specular_reflectance, alpha, eta } => {
                let (kd, ks) = (diffuse_reflectance.eval(uv).clamp(0.0, 1.0), specular_reflectance.eval(uv).clamp(0.0, 1.0));
                let w = glossy_sampling_weight(kd, ks);
                let alpha = alpha.eval_f32(uv).max(super::microfacet::MIN_ALPHA);
                Some(BsdfModel::CookTorrance(CookTorrance { diffuse_reflectance: kd, specular_reflectance: ks, alpha, eta: *eta, specular_sampling_weight: w }))
            }
            Material::OrenNayar { reflectance, alpha } => {
                Some(BsdfModel::OrenNayar(OrenNayar::from_alpha(reflectance.eval(uv).clamp(0.0, 1.0), alpha.eval_f32(uv))))
            }
            Material::Ward { diffuse_reflectance, specular_reflectance, alpha_u, alpha_v, variant } => {
                let (kd, ks) = (diffuse_reflectance.eval(uv).clamp(0.0, 1.0), specular_reflectance.eval(uv).clamp(0.0, 1.0));
                let w = glossy_sampling_weight(kd, ks);
                let a = |t: &Texture| t.eval_f32(uv).max(super::microfacet::MIN_ALPHA);
                Some(BsdfModel::Ward(Ward {
                    diffuse_reflectance: kd,
                    specular_reflectance: ks,
                    alpha_u: a(alpha_u),
                    alpha_v: a(alpha_v),
                    variant: *variant,
                    specular_sampling_weight: w,
                }))
            }
            Material::TwoSided { front, .. } => front.model(uv),
            Material::Mask { inner, .. } => inner.model(uv),
            Material::Null => None,
        }
    }

    /// The BSDF at a surface point with texture coordinates `uv`. A null material gives a
    /// BSDF that lets every ray pass (opacity 0).
    pub fn bsdf(&self, uv: Vec2) -> Bsdf {
        match self {
            // The common case built in place, without the Option of `model`.
            Material::Diffuse { reflectance } => Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: reflectance.eval(uv).clamp(0.0, 1.0) })),
            Material::Null => Bsdf { front: BsdfModel::Diffuse(Diffuse { reflectance: Rgb::BLACK }), back: None, opacity: 0.0 },
            Material::TwoSided { front, back } => {
                let mut b = front.bsdf(uv);
                b.back = back.model(uv);
                b
            }
            Material::Mask { opacity, inner } => {
                let mut b = inner.bsdf(uv);
                b.opacity *= opacity.eval_f32(uv).clamp(0.0, 1.0);
                b
            }
            _ => Bsdf::new(self.model(uv).unwrap_or(BsdfModel::Diffuse(Diffuse { reflectance: Rgb::BLACK }))),
        }
    }
}
