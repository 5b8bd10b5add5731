//! Materials as the scene describes them (textured parameters). At a hit point a
//! material becomes a [`Bsdf`] with every texture evaluated.

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

impl Material {
    /// The model one side of this material describes, with textures evaluated at `uv`.
    fn model(&self, uv: Vec2) -> Option<BsdfModel> {
        match self {
            Material::Diffuse { reflectance } => Some(BsdfModel::Diffuse(Diffuse { reflectance: reflectance.eval(uv).clamp(0.0, 1.0) })),
            Material::TwoSided { front, .. } => front.model(uv),
            Material::Mask { inner, .. } => inner.model(uv),
            Material::Null => None,
            // Filled in by the BSDF models as they land; until then, a neutral diffuse.
            _ => Some(BsdfModel::Diffuse(Diffuse { reflectance: Rgb::splat(0.5) })),
        }
    }

    /// The BSDF at a surface point with texture coordinates `uv`. A null material gives a
    /// BSDF that lets every ray pass (opacity 0).
    pub fn bsdf(&self, uv: Vec2) -> Bsdf {
        match self {
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
