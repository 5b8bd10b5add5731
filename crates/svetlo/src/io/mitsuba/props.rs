//! Typed access to a plugin's properties (`<float name=.. value=..>` and friends), with
//! errors that name the element, and Mitsuba's transform operations.

use super::xml::{Loc, Node};
use super::Loader;
use crate::error::Result;
use crate::io::spectra::{self, SpectrumKind};
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Mat4, Vec3, Vec4};

/// Parse one number; "abc" is an error at `loc`.
pub fn parse_f32(s: &str, loc: &Loc, what: &str) -> Result<f32> {
    let v: f32 = s.trim().parse().map_err(|_| loc.err(format!("{what}: cannot read '{s}' as a number")))?;
    if v.is_nan() {
        return Err(loc.err(format!("{what}: value is NaN")));
    }
    // "inf", or 1e39 (beyond f32): no quantity of a scene means anything at infinity.
    if v.is_infinite() {
        return Err(loc.err(format!("{what}: '{}' is not a finite number", s.trim())));
    }
    Ok(v)
}

/// Parse a list of numbers separated by commas and/or whitespace.
pub fn parse_list(s: &str, loc: &Loc, what: &str) -> Result<Vec<f32>> {
    s.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).map(|t| parse_f32(t, loc, what)).collect()
}

/// Which plugins asked for properties, and which properties were asked for: what a plugin
/// that was read holds but nobody asked for is reported (Mitsuba rejects such "unreferenced
/// properties"; svetlo warns, since it reads a subset of Mitsuba's plugins).
#[derive(Default)]
pub struct Queried {
    plugins: std::collections::HashSet<usize>,
    props: std::collections::HashSet<usize>,
}

/// The property elements that are checked for use.
const PROPERTY_TAGS: &[&str] = &["float", "integer", "boolean", "string", "rgb", "srgb", "spectrum", "point", "vector", "transform", "texture"];

impl Queried {
    fn note(&mut self, plugin: &Node, prop: Option<&Node>) {
        self.plugins.insert(plugin as *const Node as usize);
        if let Some(p) = prop {
            self.props.insert(p as *const Node as usize);
        }
    }

    /// Warnings for the unused properties of every plugin that was read, in file order.
    pub fn unused(&self, n: &Node, out: &mut Vec<String>) {
        if self.plugins.contains(&(n as *const Node as usize)) {
            for c in &n.children {
                if PROPERTY_TAGS.contains(&c.tag.as_str()) && !self.props.contains(&(c as *const Node as usize)) {
                    if let Some(name) = c.name() {
                        out.push(format!(
                            "{}:{}: <{} name=\"{name}\"> of <{} type=\"{}\"> is not used (svetlo does not read it)",
                            c.loc.file.display(),
                            c.loc.line,
                            c.tag,
                            n.tag,
                            n.attr("type").unwrap_or("?")
                        ));
                    }
                }
            }
        }
        for c in &n.children {
            self.unused(c, out);
        }
    }
}

impl<'a> Loader<'a> {
    /// The child property `name` of a plugin; a `<ref name=.. id=..>` resolves to its target.
    pub fn prop(&self, node: &'a Node, name: &str) -> Result<Option<&'a Node>> {
        let found = node.children.iter().find(|c| c.name() == Some(name));
        self.queried.borrow_mut().note(node, found);
        match found {
            Some(c) if c.tag == "ref" => Ok(Some(self.lookup(c)?)),
            other => Ok(other),
        }
    }

    /// The element a `<ref id=..>` names.
    pub fn lookup(&self, r: &'a Node) -> Result<&'a Node> {
        let id = r.req("id")?;
        self.ids.get(id).copied().ok_or_else(|| r.loc.err(format!("reference to unknown id '{id}'")))
    }

    fn expect<'n>(&self, p: &'n Node, tags: &[&str], name: &str) -> Result<&'n Node> {
        if tags.contains(&p.tag.as_str()) {
            Ok(p)
        } else {
            Err(p.loc.err(format!("property '{name}' is a <{}>, expected {}", p.tag, tags.iter().map(|t| format!("<{t}>")).collect::<Vec<_>>().join(" or "))))
        }
    }

    pub fn opt_float(&self, node: &'a Node, name: &str) -> Result<Option<f32>> {
        match self.prop(node, name)? {
            None => Ok(None),
            Some(p) => {
                let p = self.expect(p, &["float", "integer"], name)?;
                Ok(Some(parse_f32(p.req("value")?, &p.loc, name)?))
            }
        }
    }

    pub fn float(&self, node: &'a Node, name: &str, default: f32) -> Result<f32> {
        Ok(self.opt_float(node, name)?.unwrap_or(default))
    }

    pub fn int(&self, node: &'a Node, name: &str, default: i64) -> Result<i64> {
        match self.prop(node, name)? {
            None => Ok(default),
            Some(p) => {
                let p = self.expect(p, &["integer", "float"], name)?;
                let s = p.req("value")?.trim();
                if let Ok(v) = s.parse::<i64>() {
                    return Ok(v);
                }
                let f = parse_f32(s, &p.loc, name)?;
                if f.fract() == 0.0 && f.abs() < 1e15 {
                    Ok(f as i64)
                } else {
                    Err(p.loc.err(format!("{name}: '{s}' is not an integer")))
                }
            }
        }
    }

    pub fn boolean(&self, node: &'a Node, name: &str, default: bool) -> Result<bool> {
        match self.prop(node, name)? {
            None => Ok(default),
            Some(p) => {
                let p = self.expect(p, &["boolean"], name)?;
                match p.req("value")?.trim().to_ascii_lowercase().as_str() {
                    "true" | "1" => Ok(true),
                    "false" | "0" => Ok(false),
                    other => Err(p.loc.err(format!("{name}: '{other}' is not a boolean (true or false)"))),
                }
            }
        }
    }

    pub fn string(&self, node: &'a Node, name: &str) -> Result<Option<&'a str>> {
        match self.prop(node, name)? {
            None => Ok(None),
            Some(p) => Ok(Some(self.expect(p, &["string"], name)?.req("value")?)),
        }
    }

    /// A `<point>` or `<vector>`: `value="x, y, z"` or x/y/z attributes (missing ones are 0).
    pub fn vec3(&self, node: &'a Node, name: &str) -> Result<Option<Vec3>> {
        match self.prop(node, name)? {
            None => Ok(None),
            Some(p) => {
                let p = self.expect(p, &["point", "vector"], name)?;
                Ok(Some(xyz_attrs(p, 0.0)?))
            }
        }
    }

    pub fn transform(&self, node: &'a Node, name: &str) -> Result<Option<Mat4>> {
        match self.prop(node, name)? {
            None => Ok(None),
            Some(p) => Ok(Some(parse_transform(self.expect(p, &["transform"], name)?)?)),
        }
    }

    /// A colour property as a texture: rgb, srgb, spectrum, float, a nested or referenced texture.
    pub fn spectrum(&mut self, node: &'a Node, name: &str, default: Rgb, kind: SpectrumKind) -> Result<Texture> {
        match self.prop(node, name)? {
            None => Ok(Texture::Constant(default)),
            Some(p) if p.tag == "texture" => self.texture(p, kind),
            Some(p) => Ok(Texture::Constant(color_of(p, name, kind)?)),
        }
    }

    /// A colour that must be constant (light intensities).
    pub fn constant_color(&mut self, node: &'a Node, name: &str, default: Rgb, kind: SpectrumKind) -> Result<Rgb> {
        match self.prop(node, name)? {
            None => Ok(default),
            Some(p) if p.tag == "texture" => Err(p.loc.err(format!("a texture for '{name}' is not supported here (give a constant colour)"))),
            Some(p) => color_of(p, name, kind),
        }
    }

    /// A scalar that may be textured (roughness, opacity): float or texture.
    pub fn float_texture(&mut self, node: &'a Node, name: &str, default: f32) -> Result<Texture> {
        match self.prop(node, name)? {
            None => Ok(Texture::Constant(Rgb::splat(default))),
            Some(p) if p.tag == "texture" => self.texture(p, SpectrumKind::Unbounded),
            Some(p) => Ok(Texture::Constant(color_of(p, name, SpectrumKind::Unbounded)?)),
        }
    }
}

/// The RGB value of an `rgb`, `srgb`, `spectrum`, `float` or `integer` element. Radiance,
/// intensity and reflectance must be finite and non-negative (a negative one gives negative
/// pixels, or black from the Metropolis methods).
pub fn color_of(p: &Node, name: &str, kind: SpectrumKind) -> Result<Rgb> {
    let c = color_value(p, name, kind)?;
    if !c.is_finite() {
        return Err(p.loc.err(format!("{name}: {c:?} is not finite")));
    }
    if kind != SpectrumKind::Unbounded && c.min_component() < 0.0 {
        return Err(p.loc.err(format!("{name}: {c:?} is negative (radiance, intensity and reflectance are at least 0)")));
    }
    Ok(c)
}

fn color_value(p: &Node, name: &str, kind: SpectrumKind) -> Result<Rgb> {
    let value = p.req("value")?;
    match p.tag.as_str() {
        "float" | "integer" => Ok(Rgb::splat(parse_f32(value, &p.loc, name)?)),
        "rgb" | "srgb" => {
            let c = if let Some(hex) = value.trim().strip_prefix('#') {
                let n = u32::from_str_radix(hex, 16).ok().filter(|_| hex.len() == 6).ok_or_else(|| p.loc.err(format!("{name}: bad colour '{value}'")))?;
                let ch = |s: u32| ((n >> s) & 0xff) as f32 / 255.0;
                Rgb::new(ch(16), ch(8), ch(0))
            } else {
                let v = parse_list(value, &p.loc, name)?;
                match v.len() {
                    1 => Rgb::splat(v[0]),
                    3 => Rgb::new(v[0], v[1], v[2]),
                    n => return Err(p.loc.err(format!("{name}: an rgb value has 1 or 3 components, not {n}"))),
                }
            };
            if p.tag == "srgb" || value.trim().starts_with('#') {
                Ok(c.map(Rgb::srgb_to_linear))
            } else {
                Ok(c)
            }
        }
        "spectrum" => {
            if value.contains(':') {
                let mut samples = Vec::new();
                for entry in value.split(',').map(str::trim).filter(|e| !e.is_empty()) {
                    let (l, v) = entry.split_once(':').ok_or_else(|| p.loc.err(format!("{name}: spectrum entry '{entry}' is not wavelength:value")))?;
                    samples.push((parse_f32(l, &p.loc, name)?, parse_f32(v, &p.loc, name)?));
                }
                if samples.windows(2).any(|w| w[1].0 <= w[0].0) {
                    return Err(p.loc.err(format!("{name}: spectrum wavelengths must increase")));
                }
                Ok(spectra::sampled_to_rgb(&samples, kind))
            } else {
                let v = parse_list(value, &p.loc, name)?;
                match v.len() {
                    1 => Ok(spectra::uniform_to_rgb(v[0], kind)),
                    _ => Err(p.loc.err(format!("{name}: a spectrum is one value or a 'wavelength:value, ...' list"))),
                }
            }
        }
        other => Err(p.loc.err(format!("property '{name}' is a <{other}>, expected a colour (rgb, srgb, spectrum, float or texture)"))),
    }
}

/// x/y/z attributes or a `value` list of three.
fn xyz_attrs(p: &Node, default: f32) -> Result<Vec3> {
    if let Some(v) = p.attr("value") {
        let l = parse_list(v, &p.loc, &p.tag)?;
        return match l.len() {
            3 => Ok(Vec3::new(l[0], l[1], l[2])),
            1 => Ok(Vec3::splat(l[0])),
            n => Err(p.loc.err(format!("<{}>: expected 3 values, got {n}", p.tag))),
        };
    }
    let get = |k: &str| p.attr(k).map(|s| parse_f32(s, &p.loc, k)).transpose().map(|v| v.unwrap_or(default));
    Ok(Vec3::new(get("x")?, get("y")?, get("z")?))
}

fn vec3_attr(p: &Node, k: &str) -> Result<Vec3> {
    let l = parse_list(p.req(k)?, &p.loc, k)?;
    if l.len() != 3 {
        return Err(p.loc.err(format!("<{}> {k}: expected 3 values, got {}", p.tag, l.len())));
    }
    Ok(Vec3::new(l[0], l[1], l[2]))
}

/// Mitsuba's look-at: camera (or object) at `origin` looking along +z toward `target`,
/// +y toward `up`, +x = up × dir (the image's left for a camera).
pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (target - origin).normalize_or_zero();
    let left = up.normalize_or_zero().cross(dir).normalize_or_zero();
    if dir == Vec3::ZERO || left == Vec3::ZERO {
        return None;
    }
    let new_up = dir.cross(left);
    Some(Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0)))
}

/// A `<transform>`: its operations apply in order, each one after (left of) the previous.
pub fn parse_transform(t: &Node) -> Result<Mat4> {
    let mut m = Mat4::IDENTITY;
    for op in &t.children {
        let step = match op.tag.as_str() {
            "translate" => Mat4::from_translation(xyz_attrs(op, 0.0)?),
            "scale" => Mat4::from_scale(xyz_attrs(op, 1.0)?),
            "rotate" => {
                let axis = xyz_attrs(op, 0.0)?;
                let angle = parse_f32(op.req("angle")?, &op.loc, "angle")?;
                let axis = axis.normalize_or_zero();
                if axis == Vec3::ZERO {
                    return Err(op.loc.err("<rotate> needs a non-zero axis (x, y, z or value)"));
                }
                Mat4::from_axis_angle(axis, angle.to_radians())
            }
            "matrix" => {
                let v = parse_list(op.req("value")?, &op.loc, "matrix")?;
                match v.len() {
                    // Row-major in the file; glam is column-major. Shapes, lights and cameras
                    // are placed by affine maps: a projective last row has no meaning here.
                    16 if v[12..] != [0.0, 0.0, 0.0, 1.0] => {
                        return Err(op.loc.err(format!("<matrix>: the last row must be 0 0 0 1 (an affine transform), got {:?}", &v[12..])));
                    }
                    16 => Mat4::from_cols_array(&v.try_into().expect("16 values")).transpose(),
                    9 => Mat4::from_cols(Vec4::new(v[0], v[3], v[6], 0.0), Vec4::new(v[1], v[4], v[7], 0.0), Vec4::new(v[2], v[5], v[8], 0.0), Vec4::W),
                    n => return Err(op.loc.err(format!("<matrix> needs 16 (or 9) values, got {n}"))),
                }
            }
            "lookat" => {
                let up = if op.attr("up").is_some() { vec3_attr(op, "up")? } else { Vec3::Y };
                look_at(vec3_attr(op, "origin")?, vec3_attr(op, "target")?, up)
                    .ok_or_else(|| op.loc.err("<lookat>: origin equals target, or up is parallel to the view direction"))?
            }
            other => return Err(op.loc.err(format!("unknown transform operation <{other}>"))),
        };
        m = step * m;
    }
    if !m.is_finite() {
        return Err(t.loc.err("transform is not finite"));
    }
    Ok(m)
}
