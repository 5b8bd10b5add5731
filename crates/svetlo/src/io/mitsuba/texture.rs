//! `bitmap` and `checkerboard` textures.

use super::xml::Node;
use super::Loader;
use crate::error::Result;
use crate::io::spectra::SpectrumKind;
use crate::spectrum::Rgb;
use crate::texture::{Bitmap, FilterMode, Texture, WrapMode};
use glam::{Affine2, Mat4, Vec2};
use std::path::Path;
use std::sync::Arc;

/// The 2-D part of a 4x4 `to_uv`: x and y rows, translation from the last column.
fn to_uv(m: Mat4) -> Affine2 {
    Affine2::from_cols(Vec2::new(m.x_axis.x, m.x_axis.y), Vec2::new(m.y_axis.x, m.y_axis.y), Vec2::new(m.w_axis.x, m.w_axis.y))
}

impl<'a> Loader<'a> {
    pub(super) fn bitmap(&mut self, path: &Path, raw: bool) -> Result<Arc<Bitmap>> {
        let key = (path.to_path_buf(), raw);
        if let Some(b) = self.bitmaps.get(&key) {
            return Ok(b.clone());
        }
        let img = crate::io::image_io::read_bitmap(path, raw)?;
        if img.width == 0 || img.height == 0 {
            return Err(crate::Error::Image { file: path.to_path_buf(), msg: "image is empty".into() });
        }
        if let Some(i) = img.texels().position(|c| !c.is_finite()) {
            return Err(crate::Error::Image { file: path.to_path_buf(), msg: format!("pixel {} is not finite", i) });
        }
        let b = Arc::new(img);
        self.bitmaps.insert(key, b.clone());
        Ok(b)
    }

    pub(super) fn texture(&mut self, node: &'a Node, kind: SpectrumKind) -> Result<Texture> {
        let to_uv = to_uv(self.transform(node, "to_uv")?.unwrap_or(Mat4::IDENTITY));
        match node.type_()? {
            "bitmap" => {
                let path = self.file_prop(node)?;
                let raw = self.boolean(node, "raw", false)?;
                let filter = match self.string(node, "filter_type")?.unwrap_or("bilinear") {
                    "bilinear" => FilterMode::Bilinear,
                    "nearest" => FilterMode::Nearest,
                    o => return Err(node.loc.err(format!("filter_type '{o}' is not bilinear or nearest"))),
                };
                let wrap = match self.string(node, "wrap_mode")?.unwrap_or("repeat") {
                    "repeat" => WrapMode::Repeat,
                    "mirror" => WrapMode::Mirror,
                    "clamp" => WrapMode::Clamp,
                    o => return Err(node.loc.err(format!("wrap_mode '{o}' is not repeat, mirror or clamp"))),
                };
                let image = self.bitmap(&path, raw)?;
                if kind == SpectrumKind::Reflectance && !raw && image.texels().any(|c| c.max_component() > 1.0) {
                    self.warn(format!("{}: reflectance texture has values above 1", path.display()));
                }
                Ok(Texture::Bitmap { image, filter, wrap, to_uv })
            }
            "checkerboard" => {
                let color0 = self.constant_color(node, "color0", Rgb::splat(0.4), kind)?;
                let color1 = self.constant_color(node, "color1", Rgb::splat(0.2), kind)?;
                Ok(Texture::Checkerboard { color0, color1, to_uv })
            }
            // A constant given as is, not as a colour (Mitsuba's `rawconstant`: normal maps).
            "rawconstant" => {
                let v = self.prop(node, "value")?.ok_or_else(|| node.loc.err("rawconstant needs a 'value'"))?;
                let c = match v.tag.as_str() {
                    "vector" | "point" => {
                        let p = self.vec3(node, "value")?.unwrap_or_default();
                        Rgb::new(p.x, p.y, p.z)
                    }
                    _ => super::props::color_of(v, "value", SpectrumKind::Unbounded)?,
                };
                if !c.is_finite() {
                    return Err(v.loc.err(format!("rawconstant: {c:?} is not finite")));
                }
                Ok(Texture::Constant(c))
            }
            "mesh_attribute" => {
                let name = self.string(node, "name")?.ok_or_else(|| node.loc.err("mesh_attribute needs a 'name' (vertex_NAME or face_NAME)"))?;
                if !(name.starts_with("vertex_") || name.starts_with("face_")) {
                    return Err(node.loc.err(format!("mesh_attribute name '{name}' must start with vertex_ or face_")));
                }
                Ok(Texture::UnboundAttribute(name.to_string()))
            }
            other => Err(node.loc.err(format!("texture type '{other}' is not supported (bitmap, checkerboard, mesh_attribute)"))),
        }
    }
}
