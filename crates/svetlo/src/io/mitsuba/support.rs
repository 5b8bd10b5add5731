//! Which of a scene's plugins svetlo does not support, found before loading: `svetlo info`
//! lists them all at once (file, line, element), where loading stops at the first error or
//! skips a shape with a warning.

use super::xml::{self, Node};
use crate::error::Result;
use std::path::{Path, PathBuf};

/// Plugin types the loader reads, per element (keep in step with the loader's matches; the
/// test below loads every suite scene this list passes).
const SUPPORTED: &[(&str, &[&str])] = &[
    (
        "bsdf",
        &[
            "diffuse",
            "conductor",
            "roughconductor",
            "dielectric",
            "roughdielectric",
            "thindielectric",
            "glass",
            "plastic",
            "roughplastic",
            "twosided",
            "mask",
            "null",
            "normalmap",
            "bumpmap",
            "blendbsdf",
            "principled",
            "principledthin",
            "phong",
            "blinnphong",
            "cooktorrance",
            "roughdiffuse",
            "ward",
        ],
    ),
    ("shape", &["sphere", "rectangle", "cube", "disk", "cylinder", "obj", "ply", "serialized", "sdfgrid", "shapegroup", "instance"]),
    ("emitter", &["point", "spot", "directional", "constant", "envmap", "projector", "area"]),
    ("texture", &["bitmap", "checkerboard", "mesh_attribute", "rawconstant"]),
    ("sensor", &["perspective", "thinlens", "orthographic"]),
    ("sampler", &["independent", "sobol", "ldsampler", "stratified", "multijitter", "orthogonal", "halton", "hammersley"]),
    ("rfilter", &["box", "tent", "gaussian"]),
    ("film", &["hdrfilm"]),
];

/// Elements svetlo has no support for at all.
const UNSUPPORTED_ELEMENTS: &[&str] = &["medium", "phase", "volume"];

/// What happens to an unsupported plugin when the scene is loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Consequence {
    /// Loading fails with an error naming it.
    Error,
    /// The loader skips it with a warning (e.g. an unsupported shape).
    Skipped,
    /// Replaced by a fallback with a warning (e.g. an unknown film or filter).
    Replaced,
}

/// One unsupported plugin of a scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unsupported {
    pub file: PathBuf,
    pub line: u32,
    /// `<bsdf type="hair">` and the like.
    pub element: String,
    pub consequence: Consequence,
}

impl std::fmt::Display for Unsupported {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let what = match self.consequence {
            Consequence::Error => "not supported: the scene does not load",
            Consequence::Skipped => "not supported: skipped",
            Consequence::Replaced => "not supported: replaced by a fallback",
        };
        write!(f, "{}:{}: {} {what}", self.file.display(), self.line, self.element)
    }
}

/// The unsupported plugins of a Mitsuba scene (includes expanded), in file order. Errors
/// only for a file that does not parse.
pub fn unsupported_plugins(path: &Path, defaults: &[(String, String)]) -> Result<Vec<Unsupported>> {
    let parsed = xml::parse(path, defaults)?;
    let mut out = Vec::new();
    walk(&parsed.root, &mut out);
    Ok(out)
}

fn walk(n: &Node, out: &mut Vec<Unsupported>) {
    let ty = n.attr("type");
    let element = || match ty {
        Some(t) => format!("<{} type=\"{t}\">", n.tag),
        None => format!("<{}>", n.tag),
    };
    let push = |out: &mut Vec<Unsupported>, element: String, consequence| {
        out.push(Unsupported { file: n.loc.file.to_path_buf(), line: n.loc.line, element, consequence })
    };
    if UNSUPPORTED_ELEMENTS.contains(&n.tag.as_str()) {
        push(out, element(), Consequence::Error);
    } else if let (true, Some(side @ ("interior" | "exterior"))) = (n.tag == "ref", n.attr("name")) {
        push(out, format!("<ref name=\"{side}\"> (a participating medium)"), Consequence::Error);
    } else if let (Some((_, types)), Some(t)) = (SUPPORTED.iter().find(|(tag, _)| *tag == n.tag), ty) {
        if !types.contains(&t) {
            let consequence = match n.tag.as_str() {
                "shape" if matches!(t, "bsplinecurve" | "linearcurve" | "ellipsoids" | "ellipsoidsmesh" | "merge") => Consequence::Skipped,
                "film" | "rfilter" => Consequence::Replaced,
                _ => Consequence::Error,
            };
            push(out, element(), consequence);
        }
    }
    for c in &n.children {
        walk(c, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(xml: &str) -> Vec<Unsupported> {
        let parsed = xml::parse_str(xml, Path::new("scene.xml"), &[]).unwrap();
        let mut out = Vec::new();
        walk(&parsed.root, &mut out);
        out
    }

    #[test]
    fn lists_every_unsupported_plugin_with_its_line() {
        let found = list(
            "<scene version=\"3.0.0\">\n<bsdf type=\"hair\" id=\"a\"/>\n<shape type=\"bsplinecurve\"/>\n<shape type=\"sphere\">\n<bsdf type=\"diffuse\"/>\n<ref name=\"interior\" id=\"m\"/>\n</shape>\n<medium type=\"homogeneous\" id=\"m\"/>\n<texture type=\"noise\" id=\"t\"/>\n</scene>",
        );
        let got: Vec<(u32, &str, Consequence)> = found.iter().map(|u| (u.line, u.element.as_str(), u.consequence)).collect();
        assert_eq!(
            got,
            vec![
                (2, "<bsdf type=\"hair\">", Consequence::Error),
                (3, "<shape type=\"bsplinecurve\">", Consequence::Skipped),
                (6, "<ref name=\"interior\"> (a participating medium)", Consequence::Error),
                (8, "<medium type=\"homogeneous\">", Consequence::Error),
                (9, "<texture type=\"noise\">", Consequence::Error),
            ]
        );
        assert!(found[0].to_string().starts_with("scene.xml:2: <bsdf type=\"hair\"> not supported"), "{}", found[0]);
        assert!(list("<scene version=\"3.0.0\"><shape type=\"obj\"><bsdf type=\"normalmap\"><bsdf type=\"diffuse\"/></bsdf></shape></scene>").is_empty());
    }
}
