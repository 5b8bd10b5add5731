//! Materials as the scene describes them (textured parameters). At a hit point a
//! material becomes a [`Bsdf`] with every texture evaluated.

use super::blinn::BlinnPhong;
use super::conductor::{RoughConductor, SmoothConductor};
use super::cook_torrance::CookTorrance;
use super::dielectric::{RoughDielectric, SmoothDielectric, ThinDielectric};
use super::glass::ThinGlass;
use super::lobes::glossy_sampling_weight;
use super::microfacet::Microfacet;
use super::oren_nayar::OrenNayar;
use super::phong::Phong;
use super::plastic::{self, RoughPlastic, SmoothPlastic};
use super::ward::{Ward, WardVariant};
use super::{diffuse::Diffuse, Bsdf, BsdfModel};
use crate::math::Frame;
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::Vec3;

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
    /// svetlo's `glass`: a thin absorbing pane of clear glazing (`bsdf/glass.rs`), the
    /// per-channel internal transmissivity along the normal.
    Glass { eta: f32, transmissivity: Rgb },
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
    /// pbrt-v4 `coateddiffuse` / `coatedconductor`: the layered BSDF of `bsdf/coated.rs`.
    Coated(Box<CoatedMaterial>),
    /// pbrt-v4 `mix`, Mitsuba `blendbsdf`: (1 - amount) a + amount b (`bsdf/mix.rs`). Both
    /// must scatter (no null or mask inside); a two-sided blend wraps the mix, not its parts.
    Mix { amount: Texture, a: Box<Material>, b: Box<Material> },
    /// pbrt-v4 `diffusetransmission` (`bsdf/diffuse_transmission.rs`), the same from both sides.
    DiffuseTransmission { reflectance: Texture, transmittance: Texture },
    /// Nothing scatters (e.g. a pure emitter); rays pass through unchanged.
    Null,
    /// Mitsuba `normalmap`: `inner` in the shading frame the tangent-space normal texture gives.
    NormalMap { normals: Texture, inner: Box<Material> },
    /// Mitsuba `bumpmap`: `inner` in the shading frame of the surface displaced by
    /// `scale` times the height texture.
    BumpMap { height: Texture, scale: f32, inner: Box<Material> },
    /// Mitsuba `blendbsdf`: (1 - weight) a + weight b.
    Blend { weight: Texture, a: Box<Material>, b: Box<Material> },
    /// Mitsuba `principled` and `principledthin` (`bsdf/principled.rs`).
    Principled(Box<super::principled::PrincipledMaterial>),
}

/// The differential geometry at a hit that surface detail (normal and bump maps) needs.
#[derive(Clone, Copy, Debug)]
pub struct ShadingGeometry {
    pub shading: Frame,
    pub ng: Vec3,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
}

/// The base of a coated material (IORs relative to the outside; divided by the coating's
/// IOR when the BSDF is built, as pbrt does).
#[derive(Clone, Debug)]
pub enum CoatedBase {
    Diffuse(Texture),
    Conductor { eta: Rgb, k: Rgb, roughness: Option<Roughness> },
}

/// pbrt-v4's layered material parameters.
#[derive(Clone, Debug)]
pub struct CoatedMaterial {
    pub base: CoatedBase,
    /// The coating's IOR and roughness (None: smooth).
    pub eta: f32,
    pub roughness: Option<Roughness>,
    pub thickness: f32,
    pub albedo: Rgb,
    pub g: f32,
    pub max_depth: u32,
    pub n_samples: u32,
}

impl CoatedMaterial {
    fn model(&self, uv: TexPoint) -> BsdfModel {
        let w = Rgb::WHITE;
        let top = match &self.roughness {
            None => BsdfModel::SmoothDielectric(SmoothDielectric { eta: self.eta, specular_reflectance: w, specular_transmittance: w }),
            Some(r) => {
                BsdfModel::RoughDielectric(RoughDielectric { distribution: r.at(uv), eta: self.eta, specular_reflectance: w, specular_transmittance: w })
            }
        };
        let bottom = match &self.base {
            CoatedBase::Diffuse(t) => BsdfModel::Diffuse(Diffuse { reflectance: t.eval(uv).clamp(0.0, 1.0) }),
            CoatedBase::Conductor { eta, k, roughness } => {
                let (eta, k) = (*eta / self.eta, *k / self.eta);
                match roughness {
                    None => BsdfModel::SmoothConductor(SmoothConductor { eta, k, specular_reflectance: w }),
                    Some(r) => BsdfModel::RoughConductor(RoughConductor { distribution: r.at(uv), eta, k, specular_reflectance: w }),
                }
            }
        };
        BsdfModel::Coated(Box::new(super::coated::Coated {
            top,
            bottom,
            thickness: self.thickness,
            albedo: self.albedo,
            g: self.g,
            max_depth: self.max_depth,
            n_samples: self.n_samples,
        }))
    }
}

impl Default for Material {
    fn default() -> Self {
        Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.5)) }
    }
}

impl Roughness {
    /// The microfacet distribution at `uv` (alphas read from the first channel).
    pub fn at(&self, uv: TexPoint) -> Microfacet {
        Microfacet::new(self.kind, self.alpha_u.eval_f32(uv), self.alpha_v.eval_f32(uv))
    }
}

/// Mean of a texture for sampling heuristics. Bitmaps (and procedural textures) would need
/// a pass over every texel per hit, so they use the local value: that changes only how samples are spread
/// between lobes (the estimate stays unbiased), not the BSDF.
fn sampling_mean(t: &Texture, uv: TexPoint) -> f32 {
    match t {
        Texture::Bitmap { .. } | Texture::Procedural(_) => t.eval(uv).mean(),
        _ => t.mean().mean(),
    }
}

impl Material {
    /// Whether a path may pass through a surface of this material (transmission or a null
    /// interaction); unknown compositions count as crossing. Packet traversals break ties
    /// between coincident faces differently from the scene's BVH, which matters only where
    /// paths cross surfaces (a glass box's bottom lying on the floor).
    pub fn may_cross(&self) -> bool {
        match self {
            Material::Diffuse { .. }
            | Material::Conductor { .. }
            | Material::Plastic { .. }
            | Material::Phong { .. }
            | Material::BlinnPhong { .. }
            | Material::CookTorrance { .. }
            | Material::OrenNayar { .. }
            | Material::Ward { .. } => false,
            Material::TwoSided { front, back } => front.may_cross() || back.may_cross(),
            Material::NormalMap { inner, .. } | Material::BumpMap { inner, .. } => inner.may_cross(),
            Material::Mix { a, b, .. } | Material::Blend { a, b, .. } => a.may_cross() || b.may_cross(),
            _ => true,
        }
    }

    /// The Mitsuba plugin name this material stands for (`svetlo info`, Python's `scene.info()`).
    pub fn kind_name(&self) -> String {
        let rough = |r: bool, smooth: &str, rough: &str| if r { rough.to_string() } else { smooth.to_string() };
        match self {
            Material::Diffuse { .. } => "diffuse".into(),
            Material::Conductor { roughness, .. } => rough(roughness.is_some(), "conductor", "roughconductor"),
            Material::Dielectric { roughness, .. } => rough(roughness.is_some(), "dielectric", "roughdielectric"),
            Material::ThinDielectric { .. } => "thindielectric".into(),
            Material::Glass { .. } => "glass".into(),
            Material::Plastic { roughness, .. } => rough(roughness.is_some(), "plastic", "roughplastic"),
            Material::Phong { .. } => "phong".into(),
            Material::BlinnPhong { .. } => "blinnphong".into(),
            Material::CookTorrance { .. } => "cooktorrance".into(),
            Material::OrenNayar { .. } => "roughdiffuse".into(),
            Material::Ward { .. } => "ward".into(),
            Material::TwoSided { front, .. } => format!("twosided({})", front.kind_name()),
            Material::Mask { inner, .. } => format!("mask({})", inner.kind_name()),
            Material::Coated(c) => match c.base {
                CoatedBase::Diffuse(_) => "coateddiffuse".into(),
                CoatedBase::Conductor { .. } => "coatedconductor".into(),
            },
            Material::Mix { a, b, .. } => format!("mix({}, {})", a.kind_name(), b.kind_name()),
            Material::DiffuseTransmission { .. } => "diffusetransmission".into(),
            Material::Null => "null".into(),
            Material::NormalMap { inner, .. } => format!("normalmap({})", inner.kind_name()),
            Material::BumpMap { inner, .. } => format!("bumpmap({})", inner.kind_name()),
            Material::Blend { a, b, .. } => format!("blendbsdf({}, {})", a.kind_name(), b.kind_name()),
            Material::Principled(p) => if p.thin { "principledthin" } else { "principled" }.into(),
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
            Material::Coated(m) => {
                r(&m.roughness)
                    && match &m.base {
                        CoatedBase::Diffuse(t) => c(t),
                        CoatedBase::Conductor { roughness, .. } => r(roughness),
                    }
            }
            Material::Mix { amount, a, b } => c(amount) && a.is_uniform() && b.is_uniform(),
            Material::DiffuseTransmission { reflectance, transmittance } => c(reflectance) && c(transmittance),
            Material::Null | Material::Glass { .. } => true,
            Material::NormalMap { .. } | Material::BumpMap { .. } => false,
            Material::Blend { weight, a, b } => c(weight) && a.is_uniform() && b.is_uniform(),
            Material::Principled(p) => p.is_uniform(),
        }
    }

    /// The model one side of this material describes, with textures evaluated at `uv`.
    fn model(&self, uv: TexPoint) -> Option<BsdfModel> {
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
            Material::Glass { eta, transmissivity } => Some(BsdfModel::ThinGlass(ThinGlass { eta: *eta, transmissivity: *transmissivity })),
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
            Material::Coated(m) => Some(m.model(uv)),
            Material::DiffuseTransmission { reflectance, transmittance } => {
                Some(BsdfModel::DiffuseTransmission(super::diffuse_transmission::DiffuseTransmission {
                    reflectance: reflectance.eval(uv).clamp(0.0, 1.0),
                    transmittance: transmittance.eval(uv).clamp(0.0, 1.0),
                }))
            }
            Material::Mix { amount, a, b } => {
                let amount = amount.eval_f32(uv).clamp(0.0, 1.0);
                let (a, b) = (a.model(uv)?, b.model(uv)?);
                Some(if amount <= 0.0 {
                    a
                } else if amount >= 1.0 {
                    b
                } else {
                    BsdfModel::Mix(Box::new(super::mix::Mix { a, b, amount }))
                })
            }
            Material::Null => None,
            // Without the geometry there is no perturbed frame (see `bsdf_with_detail`).
            Material::NormalMap { inner, .. } | Material::BumpMap { inner, .. } => inner.model(uv),
            Material::Blend { weight, a, b } => {
                Some(BsdfModel::Blend(Box::new(super::blend::Blend { a: a.bsdf(uv), b: b.bsdf(uv), weight: weight.eval_f32(uv).clamp(0.0, 1.0) })))
            }
            Material::Principled(p) => Some(p.model(uv)),
        }
    }

    /// The BSDF at a surface point (its uv, or the full [`TexPoint`] for mesh attributes),
    /// without surface detail: normal and bump maps need the geometry of
    /// [`Self::bsdf_with_detail`]. A null material gives a BSDF that lets every ray pass
    /// (opacity 0).
    #[inline]
    pub fn bsdf(&self, uv: impl Into<TexPoint>) -> Bsdf {
        // A constant Lambertian, the most common case, built inline; the rest out of line.
        if let Material::Diffuse { reflectance: Texture::Constant(c) } = self {
            return Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: c.clamp(0.0, 1.0) }));
        }
        self.bsdf_at(uv.into())
    }

    #[inline(never)]
    fn bsdf_at(&self, uv: TexPoint) -> Bsdf {
        match self {
            // Built in place, without the Option of `model`.
            Material::Diffuse { reflectance } => Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: reflectance.eval(uv).clamp(0.0, 1.0) })),
            Material::Null => Bsdf { front: BsdfModel::Diffuse(Diffuse { reflectance: Rgb::BLACK }), back: None, opacity: 0.0, detail: None },
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
            Material::NormalMap { inner, .. } | Material::BumpMap { inner, .. } => inner.bsdf(uv),
            _ => Bsdf::new(self.model(uv).unwrap_or(BsdfModel::Diffuse(Diffuse { reflectance: Rgb::BLACK }))),
        }
    }

    /// Build now the tables that this material's BSDFs look up at every hit (rough plastic's
    /// coating albedos, where the roughness is a constant): scene loading calls it, so that
    /// the render does not pay for them at its first hits (Mitsuba builds them when it
    /// loads the plugin). Tables are built once per process; a textured roughness still
    /// builds its tables on first use.
    pub fn prepare_tables(&self) {
        match self {
            Material::Plastic { eta, roughness: Some(r), .. } => {
                if let Texture::Constant(_) = r.alpha_u {
                    RoughPlastic::prepare_tables(r.kind, r.alpha_u.eval_f32(TexPoint::default()), *eta);
                }
            }
            Material::TwoSided { front: a, back: b } | Material::Mix { a, b, .. } | Material::Blend { a, b, .. } => {
                a.prepare_tables();
                b.prepare_tables();
            }
            Material::Mask { inner, .. } | Material::NormalMap { inner, .. } | Material::BumpMap { inner, .. } => inner.prepare_tables(),
            _ => {}
        }
    }

    /// Does the material perturb the shading frame (a normal or bump map, outermost or
    /// under `twosided` / `mask`)? Then its BSDF needs [`Self::bsdf_with_detail`].
    pub fn has_detail(&self) -> bool {
        match self {
            Material::NormalMap { .. } | Material::BumpMap { .. } => true,
            Material::TwoSided { front, .. } => front.has_detail(),
            Material::Mask { inner, .. } => inner.has_detail(),
            _ => false,
        }
    }

    /// The BSDF at a point with its surface detail: a normal or bump map sets the BSDF's
    /// perturbed frame (a map nested inside another map's BSDF is not applied).
    pub fn bsdf_with_detail(&self, p: TexPoint, g: &ShadingGeometry) -> Bsdf {
        use super::detail::{bump_map_normal, normal_map_normal, Detail};
        let with = |inner: &Material, n: Vec3| {
            let mut b = inner.bsdf(p);
            b.detail = Some(Detail::new(n, true));
            b
        };
        match self {
            Material::NormalMap { normals, inner } => with(inner, normal_map_normal(normals.eval(p))),
            Material::BumpMap { height, scale, inner } => with(inner, bump_map_normal(height.eval_f32_grad(p) * *scale, &g.shading, g.ng, g.dpdu, g.dpdv)),
            Material::TwoSided { front, back } => {
                let mut b = front.bsdf_with_detail(p, g);
                b.back = back.model(p);
                b
            }
            Material::Mask { opacity, inner } => {
                let mut b = inner.bsdf_with_detail(p, g);
                b.opacity *= opacity.eval_f32(p).clamp(0.0, 1.0);
                b
            }
            _ => self.bsdf(p),
        }
    }

    /// Every texture of the material, nested materials' included.
    pub fn textures_mut(&mut self) -> Vec<&mut Texture> {
        let mut out: Vec<&mut Texture> = Vec::new();
        fn rough<'m>(r: &'m mut Option<Roughness>, out: &mut Vec<&'m mut Texture>) {
            if let Some(Roughness { alpha_u, alpha_v, .. }) = r {
                out.push(alpha_u);
                out.push(alpha_v);
            }
        }
        match self {
            Material::Diffuse { reflectance } => out.push(reflectance),
            Material::Conductor { specular_reflectance, roughness, .. } => {
                out.push(specular_reflectance);
                rough(roughness, &mut out);
            }
            Material::Dielectric { specular_reflectance, specular_transmittance, roughness, .. } => {
                out.push(specular_reflectance);
                out.push(specular_transmittance);
                rough(roughness, &mut out);
            }
            Material::ThinDielectric { specular_reflectance, specular_transmittance, .. } => {
                out.push(specular_reflectance);
                out.push(specular_transmittance);
            }
            Material::Plastic { diffuse_reflectance, specular_reflectance, roughness, .. } => {
                out.push(diffuse_reflectance);
                out.push(specular_reflectance);
                rough(roughness, &mut out);
            }
            Material::Phong { diffuse_reflectance, specular_reflectance, exponent }
            | Material::BlinnPhong { diffuse_reflectance, specular_reflectance, exponent } => out.extend([diffuse_reflectance, specular_reflectance, exponent]),
            Material::CookTorrance { diffuse_reflectance, specular_reflectance, alpha, .. } => out.extend([diffuse_reflectance, specular_reflectance, alpha]),
            Material::OrenNayar { reflectance, alpha } => out.extend([reflectance, alpha]),
            Material::Ward { diffuse_reflectance, specular_reflectance, alpha_u, alpha_v, .. } => {
                out.extend([diffuse_reflectance, specular_reflectance, alpha_u, alpha_v])
            }
            Material::TwoSided { front, back } => {
                out.extend(front.textures_mut());
                out.extend(back.textures_mut());
            }
            Material::Mask { opacity, inner } => {
                out.push(opacity);
                out.extend(inner.textures_mut());
            }
            Material::Null | Material::Glass { .. } => {}
            Material::NormalMap { normals, inner } => {
                out.push(normals);
                out.extend(inner.textures_mut());
            }
            Material::BumpMap { height, inner, .. } => {
                out.push(height);
                out.extend(inner.textures_mut());
            }
            Material::Blend { weight, a, b } => {
                out.push(weight);
                out.extend(a.textures_mut());
                out.extend(b.textures_mut());
            }
            Material::Mix { amount, a, b } => {
                out.push(amount);
                out.extend(a.textures_mut());
                out.extend(b.textures_mut());
            }
            Material::DiffuseTransmission { reflectance, transmittance } => out.extend([reflectance, transmittance]),
            Material::Coated(c) => {
                let c = &mut **c;
                match &mut c.base {
                    CoatedBase::Diffuse(t) => out.push(t),
                    CoatedBase::Conductor { roughness, .. } => rough(roughness, &mut out),
                }
                rough(&mut c.roughness, &mut out);
            }
            Material::Principled(p) => out.extend(p.textures_mut()),
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Preparing a material builds the coating tables of the rough plastics inside it, which
    /// its BSDFs then use; a textured roughness is left for its first use.
    #[test]
    fn prepare_tables_builds_rough_plastic_tables() {
        // Roughness and IOR used by no other test, so that nothing else built these tables.
        let (kind, alpha, eta) = (MicrofacetKind::Beckmann, 0.3217f32, 1.4321f32);
        let plastic = |alpha: Texture| Material::Plastic {
            diffuse_reflectance: Texture::Constant(Rgb::splat(0.5)),
            specular_reflectance: Texture::Constant(Rgb::WHITE),
            eta,
            nonlinear: false,
            roughness: Some(Roughness { kind, alpha_u: alpha.clone(), alpha_v: alpha }),
        };
        let m = Material::TwoSided { front: Box::new(plastic(Texture::Constant(Rgb::splat(alpha)))), back: Box::new(Material::default()) };
        assert!(plastic::cached_tables(kind, alpha, eta).is_none());
        m.prepare_tables();
        let built = plastic::cached_tables(kind, alpha, eta).expect("tables built by prepare_tables");
        let BsdfModel::RoughPlastic(rp) = m.bsdf(glam::Vec2::new(0.3, 0.7)).front else { panic!("not a rough plastic") };
        assert!(std::ptr::eq(rp.tables, built));
        // Not constant: nothing to prepare.
        let checker = Texture::Checkerboard { color0: Rgb::splat(0.61), color1: Rgb::splat(0.62), to_uv: Default::default() };
        plastic(checker).prepare_tables();
        assert!(plastic::cached_tables(kind, 0.61, eta).is_none() && plastic::cached_tables(kind, 0.62, eta).is_none());
    }
}
