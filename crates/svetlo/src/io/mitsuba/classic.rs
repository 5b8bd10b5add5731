//! The classic BRDFs: Mitsuba 0.6's `phong`, `roughdiffuse` and `ward`, and svetlo's own
//! `blinnphong` and `cooktorrance`. Parameter names are accepted in Mitsuba 3's snake_case
//! and Mitsuba 0.6's camelCase (`diffuse_reflectance` or `diffuseReflectance`).

use super::xml::Node;
use super::Loader;
use crate::bsdf::ward::WardVariant;
use crate::bsdf::Material;
use crate::error::Result;
use crate::io::spectra::SpectrumKind;
use crate::spectrum::Rgb;
use crate::texture::Texture;

impl<'a> Loader<'a> {
    /// The first of `names` the node gives, or the first name when none is given.
    fn alias<'n>(&self, node: &'a Node, names: &[&'n str]) -> Result<&'n str> {
        for n in names {
            if self.prop(node, n)?.is_some() {
                return Ok(n);
            }
        }
        Ok(names[0])
    }

    fn refl(&mut self, node: &'a Node, names: &[&str], default: f32) -> Result<Texture> {
        let n = self.alias(node, names)?;
        self.spectrum(node, n, Rgb::splat(default), SpectrumKind::Reflectance)
    }

    fn nonneg(&mut self, node: &'a Node, names: &[&str], default: f32) -> Result<Texture> {
        let n = self.alias(node, names)?;
        let t = self.float_texture(node, n, default)?;
        if let Texture::Constant(c) = &t {
            if !(c.r >= 0.0 && c.r.is_finite()) {
                return Err(node.loc.err(format!("{n} must be non-negative and finite, got {}", c.r)));
            }
        }
        Ok(t)
    }

    /// Warn when the constant parts of kd + ks exceed 1: such a material creates energy.
    fn check_energy(&mut self, node: &'a Node, kd: &Texture, ks: &Texture) {
        if let (Texture::Constant(d), Texture::Constant(s)) = (kd, ks) {
            if (*d + *s).max_component() > 1.0 {
                self.warn(format!(
                    "{}:{}: diffuse + specular reflectance exceeds 1; the material reflects more light than it receives",
                    node.loc.file.display(),
                    node.loc.line
                ));
            }
        }
    }

    /// A classic BRDF, or None when `ty` is not one.
    pub(super) fn classic_bsdf(&mut self, node: &'a Node, ty: &str) -> Result<Option<Material>> {
        const KD: [&str; 2] = ["diffuse_reflectance", "diffuseReflectance"];
        const KS: [&str; 2] = ["specular_reflectance", "specularReflectance"];
        Ok(Some(match ty {
            "phong" | "blinnphong" => {
                let diffuse_reflectance = self.refl(node, &KD, 0.5)?;
                let specular_reflectance = self.refl(node, &KS, 0.2)?;
                let exponent = self.nonneg(node, &["exponent"], 30.0)?;
                self.check_energy(node, &diffuse_reflectance, &specular_reflectance);
                if ty == "phong" {
                    Material::Phong { diffuse_reflectance, specular_reflectance, exponent }
                } else {
                    Material::BlinnPhong { diffuse_reflectance, specular_reflectance, exponent }
                }
            }
            "cooktorrance" => {
                let diffuse_reflectance = self.refl(node, &KD, 0.5)?;
                let specular_reflectance = self.refl(node, &KS, 1.0)?;
                self.check_energy(node, &diffuse_reflectance, &specular_reflectance);
                let alpha = self.nonneg(node, &["alpha"], 0.1)?;
                let int = self.float(node, "int_ior", 1.49)?;
                let ext = self.float(node, "ext_ior", 1.000277)?;
                if !(int > 0.0 && ext > 0.0 && int.is_finite() && ext.is_finite()) {
                    return Err(node.loc.err(format!("cooktorrance: indices of refraction must be positive, got {int} / {ext}")));
                }
                Material::CookTorrance { diffuse_reflectance, specular_reflectance, alpha, eta: int / ext }
            }
            "roughdiffuse" => {
                let reflectance = self.refl(node, &["reflectance", "diffuse_reflectance", "diffuseReflectance"], 0.5)?;
                let alpha = self.nonneg(node, &["alpha"], 0.2)?;
                let fast = self.alias(node, &["use_fast_approx", "useFastApprox"])?;
                if !self.boolean(node, fast, false)? {
                    self.warn(format!(
                        "{}:{}: roughdiffuse: svetlo implements Oren-Nayar's qualitative model only (Mitsuba's useFastApprox=true)",
                        node.loc.file.display(),
                        node.loc.line
                    ));
                }
                Material::OrenNayar { reflectance, alpha }
            }
            "ward" => {
                let diffuse_reflectance = self.refl(node, &KD, 0.5)?;
                let specular_reflectance = self.refl(node, &KS, 0.2)?;
                self.check_energy(node, &diffuse_reflectance, &specular_reflectance);
                let (alpha_u, alpha_v) = if self.prop(node, "alpha")?.is_some() {
                    let a = self.nonneg(node, &["alpha"], 0.1)?;
                    (a.clone(), a)
                } else {
                    (self.nonneg(node, &["alpha_u", "alphaU", "alphaX"], 0.1)?, self.nonneg(node, &["alpha_v", "alphaV", "alphaY"], 0.1)?)
                };
                let variant = match self.string(node, "variant")?.unwrap_or("balanced") {
                    "ward" => WardVariant::Ward,
                    "ward-duer" => WardVariant::WardDuer,
                    "balanced" => WardVariant::Balanced,
                    o => return Err(node.loc.err(format!("ward variant '{o}' is not ward, ward-duer or balanced"))),
                };
                Material::Ward { diffuse_reflectance, specular_reflectance, alpha_u, alpha_v, variant }
            }
            _ => return Ok(None),
        }))
    }
}
