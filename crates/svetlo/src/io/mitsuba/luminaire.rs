//! `<emitter type="ies">`: a luminaire from an IES LM-63 or EULUMDAT file (`filename`), with
//! `scale` (multiplies the flux), `color` (normalised to luminance 1), `tilt` (degrees: the
//! installed tilt at which an IES tilt table is read) and `spread` (emit from the file's
//! luminous opening instead of its centre).

use super::xml::Node;
use super::Loader;
use crate::error::Result;
use crate::io::spectra::SpectrumKind;
use crate::light::{Light, Luminaire};
use crate::photometry;
use crate::spectrum::Rgb;
use glam::Mat4;
use std::sync::Arc;

impl<'a> Loader<'a> {
    pub(super) fn luminaire(&mut self, node: &'a Node, to_world: Option<Mat4>) -> Result<Light> {
        let path = self.file_prop(node)?;
        let scale = self.float(node, "scale", 1.0)?;
        if !(scale >= 0.0 && scale.is_finite()) {
            return Err(node.loc.err(format!("ies emitter: scale must be non-negative, got {scale}")));
        }
        let tilt = self.float(node, "tilt", 0.0)?;
        let spread = self.boolean(node, "spread", false)?;
        let color = self.constant_color(node, "color", Rgb::WHITE, SpectrumKind::Illuminant)?;
        let is_ldt = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("ldt"));
        let p = if is_ldt {
            photometry::load(&path)?
        } else {
            let bytes = std::fs::read(&path).map_err(|source| crate::error::Error::Io { file: path.clone(), source })?;
            photometry::ies::parse_with_tilt(&bytes, &path, tilt as f64)?
        };
        let opening = spread.then_some(p.opening);
        let mut lum = Luminaire::new(Arc::new(p.table), &to_world.unwrap_or(Mat4::IDENTITY), scale, color, opening);
        lum.opening = p.opening;
        let file = path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        lum.name = if p.label.trim().is_empty() { file } else { format!("{file} ({})", p.label.trim()) };
        lum.input_watts = p.input_watts.map(|w| w * scale as f64);
        Ok(Light::Luminaire(Box::new(lum)))
    }
}
