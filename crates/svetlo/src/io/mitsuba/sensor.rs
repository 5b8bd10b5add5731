//! Sensor (camera, film, pixel filter, sampler) and integrator settings.

use super::xml::Node;
use super::Loader;
use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::film::Filter;
use crate::sampling::SamplerKind;
use glam::Mat4;

/// Horizontal field of view (the camera's convention) from a fov along Mitsuba's `fov_axis`.
/// `aspect` is width / height.
pub fn fov_x_from_axis(fov_deg: f32, axis: &str, aspect: f32) -> Option<f32> {
    let t = (0.5 * fov_deg.to_radians()).tan();
    let axis = match axis {
        "smaller" => {
            if aspect > 1.0 {
                "y"
            } else {
                "x"
            }
        }
        "larger" => {
            if aspect > 1.0 {
                "x"
            } else {
                "y"
            }
        }
        a => a,
    };
    // Half-extents on the z = 1 plane: x = tx, y = tx / aspect, diagonal = tx * sqrt(1 + 1/aspect²).
    let tx = match axis {
        "x" => t,
        "y" => t * aspect,
        "diagonal" => t / (1.0 + 1.0 / (aspect * aspect)).sqrt(),
        _ => return None,
    };
    Some(2.0 * tx.atan().to_degrees())
}

impl<'a> Loader<'a> {
    pub(super) fn sensor(&mut self, node: &'a Node) -> Result<()> {
        let ty = node.type_()?;
        let to_world = self.transform(node, "to_world")?.unwrap_or(Mat4::IDENTITY);
        if singular(&to_world) {
            return Err(node.loc.err("the sensor's to_world is singular (a zero scale, or axes that coincide): the camera would see nothing"));
        }
        let film = node.children.iter().find(|c| c.tag == "film");
        let (mut width, mut height) = (768, 576);
        if let Some(f) = film {
            let fty = f.type_()?;
            if fty != "hdrfilm" {
                self.warn(format!("{}:{}: film '{fty}' treated as hdrfilm", f.loc.file.display(), f.loc.line));
            }
            width = self.int(f, "width", 768)?;
            height = self.int(f, "height", 576)?;
            for k in ["crop_width", "crop_height", "crop_offset_x", "crop_offset_y"] {
                if self.prop(f, k)?.is_some() {
                    self.warn(format!("{}:{}: film '{k}' ignored (the full film is rendered)", f.loc.file.display(), f.loc.line));
                }
            }
            if let Some(r) = f.children.iter().find(|c| c.tag == "rfilter") {
                self.b.settings.filter = match r.type_()? {
                    "box" => Filter::Box,
                    "tent" => Filter::Tent { radius: positive(r, "radius", self.float(r, "radius", 1.0)?)? },
                    "gaussian" => Filter::Gaussian { stddev: positive(r, "stddev", self.float(r, "stddev", 0.5)?)? },
                    other => {
                        self.warn(format!("{}:{}: reconstruction filter '{other}' not supported; using gaussian", r.loc.file.display(), r.loc.line));
                        Filter::default()
                    }
                };
            }
        }
        let fl = film.unwrap_or(node);
        if !(1..=1 << 16).contains(&width) || !(1..=1 << 16).contains(&height) {
            return Err(fl.loc.err(format!("film size {width}x{height} is not between 1 and 65536")));
        }
        let (width, height) = (width as u32, height as u32);
        crate::limits::check_film(width, height).map_err(|e| fl.loc.err(e.to_string()))?;
        if let Some(s) = node.children.iter().find(|c| c.tag == "sampler") {
            let spp = self.int(s, "sample_count", 4)?;
            if !(1..=u32::MAX as i64).contains(&spp) {
                return Err(s.loc.err(format!("sample_count must be a positive integer, got {spp}")));
            }
            self.b.settings.spp = spp as u32;
            let seed = self.int(s, "seed", 0)?;
            if seed < 0 {
                return Err(s.loc.err(format!("seed must be non-negative, got {seed}")));
            }
            self.b.settings.seed = seed as u64;
            self.b.settings.sampler = match s.type_()? {
                "independent" => SamplerKind::Independent,
                "sobol" | "ldsampler" => SamplerKind::Sobol,
                t @ ("stratified" | "multijitter" | "orthogonal" | "halton" | "hammersley") => {
                    self.warn(format!("{}:{}: sampler '{t}' replaced by the Sobol sampler", s.loc.file.display(), s.loc.line));
                    SamplerKind::Sobol
                }
                other => return Err(s.loc.err(format!("unknown sampler type '{other}'"))),
            };
        }
        let aspect = width as f32 / height as f32;
        let near_clip = self.float(node, "near_clip", 1e-2)?;
        let far_clip = self.float(node, "far_clip", 1e4)?;
        if !(near_clip >= 0.0 && far_clip > near_clip) {
            return Err(node.loc.err(format!("need 0 <= near_clip ({near_clip}) < far_clip ({far_clip})")));
        }
        let projection = match ty {
            "perspective" | "thinlens" => {
                let fov_x = self.fov_x(node, aspect)?;
                let (aperture_radius, focus_distance) = if ty == "thinlens" {
                    let a = self.float(node, "aperture_radius", 0.03)?;
                    let f = self.float(node, "focus_distance", 0.0)?;
                    if !(a >= 0.0 && (a == 0.0 || f > 0.0)) {
                        return Err(node.loc.err(format!("thinlens needs aperture_radius >= 0 ({a}) and focus_distance > 0 ({f})")));
                    }
                    (a, f)
                } else {
                    (0.0, self.float(node, "focus_distance", 1.0)?)
                };
                Projection::Perspective { fov_x_deg: fov_x, aperture_radius, focus_distance }
            }
            "orthographic" => Projection::Orthographic,
            other => return Err(node.loc.err(format!("sensor type '{other}' is not supported (perspective, thinlens, orthographic)"))),
        };
        let shutter_open = self.float(node, "shutter_open", 0.0)?;
        let shutter_close = self.float(node, "shutter_close", shutter_open)?;
        if shutter_close < shutter_open {
            return Err(node.loc.err("shutter_close is before shutter_open"));
        }
        self.b.set_camera(Camera { to_world, projection, width, height, near_clip, far_clip, shutter_open, shutter_close });
        Ok(())
    }

    /// The horizontal fov from `fov` + `fov_axis` or a 35 mm `focal_length` (Mitsuba's default 50mm).
    pub(super) fn fov_x(&self, node: &'a Node, aspect: f32) -> Result<f32> {
        let (fov, axis) = match self.opt_float(node, "fov")? {
            Some(f) => (f, self.string(node, "fov_axis")?.unwrap_or("x").to_string()),
            None => {
                let fl = self.string(node, "focal_length")?.unwrap_or("50mm");
                let mm = super::props::parse_f32(fl.trim().trim_end_matches("mm"), &node.loc, "focal_length")?;
                if mm.is_nan() || mm <= 0.0 {
                    return Err(node.loc.err(format!("focal_length must be positive, got {fl}")));
                }
                // The diagonal of a 36 x 24 mm frame.
                (2.0 * (0.5 * (36.0f32.hypot(24.0)) / mm).atan().to_degrees(), "diagonal".to_string())
            }
        };
        if !(fov > 0.0 && fov < 180.0) {
            return Err(node.loc.err(format!("fov must be in (0, 180) degrees, got {fov}")));
        }
        fov_x_from_axis(fov, &axis, aspect).ok_or_else(|| node.loc.err(format!("fov_axis '{axis}' is not x, y, diagonal, smaller or larger")))
    }

    pub(super) fn integrator(&mut self, node: &'a Node) -> Result<()> {
        let ty = node.type_()?;
        match ty {
            "moment" => {
                let inner =
                    node.children.iter().find(|c| c.tag == "integrator").ok_or_else(|| node.loc.err("the moment integrator needs a nested integrator"))?;
                self.warn("moment integrator: its nested integrator is used (no second-moment output)".to_string());
                return self.integrator(inner);
            }
            "volpath" | "volpathmis" => {
                self.warn(format!("integrator '{ty}' replaced by 'path' (no participating media)"));
                self.b.settings.integrator = "path".into();
            }
            other => self.b.settings.integrator = other.to_string(),
        }
        let max_depth = self.int(node, "max_depth", -1)?;
        if max_depth < -1 || max_depth > i32::MAX as i64 {
            return Err(node.loc.err(format!("max_depth must be -1 (unbounded) or >= 0, got {max_depth}")));
        }
        let rr_depth = self.int(node, "rr_depth", 5)?;
        if !(1..=i32::MAX as i64).contains(&rr_depth) {
            return Err(node.loc.err(format!("rr_depth must be positive, got {rr_depth}")));
        }
        self.b.settings.max_depth = max_depth as i32;
        self.b.settings.rr_depth = rr_depth as i32;
        self.b.settings.hide_emitters = self.boolean(node, "hide_emitters", false)?;
        Ok(())
    }
}

/// Is the linear part of `m` singular, up to its scale?
fn singular(m: &Mat4) -> bool {
    let l = glam::Mat3::from_mat4(*m);
    let scale = l.x_axis.length() * l.y_axis.length() * l.z_axis.length();
    !(scale > 0.0 && (l.determinant() / scale).abs() > 1e-6)
}

fn positive(node: &Node, name: &str, v: f32) -> Result<f32> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(node.loc.err(format!("{name} must be positive, got {v}")))
    }
}
