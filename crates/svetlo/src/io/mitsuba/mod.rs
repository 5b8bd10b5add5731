//! Mitsuba scene files (version 3 and the 0.5/0.6 dialect of Bitterli's scenes).
//!
//! Two passes: [`xml`] parses the file into an owned tree with includes, defaults and
//! `$name` parameters expanded; the [`Loader`] then walks the tree and feeds a
//! [`SceneBuilder`]. Objects with an `id` are found by [`Loader::lookup`], so a `<ref>`
//! may name an object defined later in the file (as `cbox-rgb.xml` does).
//!
//! What is not supported either fails with a typed error naming the element, or, where a
//! reasonable fallback exists, loads with a line in `Scene::warnings`.

mod bsdf;
mod classic;
mod emitter;
mod luminaire;
mod props;
mod refs;
mod sensor;
mod shape;
mod support;
mod texture;
mod xml;

pub use props::{look_at, parse_transform};
pub use sensor::fov_x_from_axis;
pub use support::{unsupported_plugins, Consequence, Unsupported};
pub use xml::{Loc, Node};

use crate::error::{Error, Result};
use crate::scene::{Scene, SceneBuilder};
use crate::texture::Bitmap;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Load a Mitsuba XML scene; `defaults` fill `<default>` parameters (`-D name=value`) and
/// take precedence over the file's own defaults.
pub fn load_scene(path: &Path, defaults: &[(String, String)]) -> Result<Scene> {
    load_parsed(xml::parse(path, defaults)?, path)
}

/// Load a Mitsuba XML scene held in memory (no file system needed unless it names files).
/// `origin` stands for the file in error messages, and relative file names in the scene
/// (includes, meshes, textures) are resolved against its folder.
pub fn load_scene_from_str(text: &str, origin: &Path, defaults: &[(String, String)]) -> Result<Scene> {
    load_parsed(xml::parse_str(text, origin, defaults)?, origin)
}

/// Load a scene given as its element tree, as a file would parse (for front ends that build
/// scenes without text: Python's `load_dict`); `<default>`, `$name` and includes apply as in
/// a file. `origin` stands for the file: relative names resolve against its folder.
pub fn load_scene_from_tree(root: Node, origin: &Path, defaults: &[(String, String)]) -> Result<Scene> {
    load_parsed(xml::expand_tree(root, origin, defaults)?, origin)
}

fn load_parsed(parsed: xml::Parsed, path: &Path) -> Result<Scene> {
    let mut ids = HashMap::new();
    collect_ids(&parsed.root, &mut ids)?;
    refs::check_cycles(&ids)?;
    let mut loader = Loader {
        ids,
        search_paths: parsed.search_paths.clone(),
        b: SceneBuilder::new(),
        materials_by_id: HashMap::new(),
        default_material: None,
        bitmaps: HashMap::new(),
        mesh_files: HashMap::new(),
        shape_count: 0,
        has_sensor: false,
        plugin_depth: 0,
        plugin_instances: 0,
        queried: Default::default(),
    };
    for p in &parsed.unused_params {
        loader.warn(format!("parameter '{p}' given on the command line is not used by the scene"));
    }
    loader.scene(&parsed.root)?;
    let mut unused = Vec::new();
    loader.queried.borrow().unused(&parsed.root, &mut unused);
    loader.b.warnings.extend(unused);
    if !loader.has_sensor {
        return Err(Error::Scene { file: path.to_path_buf(), msg: "the scene has no <sensor>".into() });
    }
    loader.b.build()
}

fn collect_ids<'a>(n: &'a Node, ids: &mut HashMap<&'a str, &'a Node>) -> Result<()> {
    for c in &n.children {
        if c.tag != "ref" {
            if let Some(id) = c.id() {
                if let Some(prev) = ids.insert(id, c) {
                    return Err(c.loc.err(format!("duplicate id '{id}' (first defined at {}:{})", prev.loc.file.display(), prev.loc.line)));
                }
            }
        }
        collect_ids(c, ids)?;
    }
    Ok(())
}

pub(crate) struct Loader<'a> {
    ids: HashMap<&'a str, &'a Node>,
    search_paths: Vec<PathBuf>,
    b: SceneBuilder,
    materials_by_id: HashMap<&'a str, u32>,
    default_material: Option<u32>,
    bitmaps: HashMap<(PathBuf, bool), Arc<Bitmap>>,
    /// Mesh files read so far, by (file, plugin type, flip_tex_coords or shape_index): a file
    /// that several shapes name (the same sphere placed ten times) is parsed once.
    mesh_files: HashMap<(PathBuf, &'static str, u32), Arc<crate::io::mesh_files::LoadedMesh>>,
    shape_count: usize,
    has_sensor: bool,
    /// Plugins being built (nested and referenced) and built so far: see [`Loader::nested`].
    plugin_depth: usize,
    plugin_instances: usize,
    /// Properties asked for, to report the ones nobody read.
    queried: std::cell::RefCell<props::Queried>,
}

impl<'a> Loader<'a> {
    fn warn(&mut self, msg: impl Into<String>) {
        self.b.warnings.push(msg.into());
    }

    /// Resolve a file named by `name` in an element written at `node`: next to that file,
    /// then in the scene's folder and the `<path>` folders.
    fn resolve(&self, node: &Node, name: &str) -> Option<PathBuf> {
        xml::resolve_in(name, &node.loc.dir(), &self.search_paths)
    }

    /// A required file property (`filename`), resolved, or an error naming the element.
    fn file_prop(&self, node: &'a Node) -> Result<PathBuf> {
        let p = self
            .prop(node, "filename")?
            .ok_or_else(|| node.loc.err(format!("<{} type=\"{}\"> needs a 'filename'", node.tag, node.attr("type").unwrap_or("?"))))?;
        let name = p.req("value")?;
        self.resolve(p, name)
            .ok_or_else(|| p.loc.err(format!("file '{name}' not found (looked next to {} and in the scene's search paths)", p.loc.file.display())))
    }

    fn scene(&mut self, root: &'a Node) -> Result<()> {
        self.check_version(root)?;
        for c in &root.children {
            match c.tag.as_str() {
                "integrator" => self.integrator(c)?,
                "sensor" => {
                    if self.has_sensor {
                        self.warn(format!("{}:{}: only the first <sensor> is used", c.loc.file.display(), c.loc.line));
                    } else {
                        self.sensor(c)?;
                        self.has_sensor = true;
                    }
                }
                "shape" => {
                    // A shapegroup is a definition; instances place it.
                    if c.type_()? != "shapegroup" {
                        self.shape(c, glam::Mat4::IDENTITY)?;
                    }
                }
                "emitter" => {
                    if c.type_()? == "area" {
                        if c.id().is_none() {
                            self.warn(format!("{}:{}: an area emitter outside a shape emits nothing", c.loc.file.display(), c.loc.line));
                        }
                    } else {
                        self.emitter(c)?;
                    }
                }
                // Definitions, instantiated where referenced.
                "bsdf" | "texture" => {}
                "medium" => return Err(c.loc.err("participating media (<medium>) are not supported")),
                "float" | "integer" | "boolean" | "string" | "rgb" | "spectrum" | "point" | "vector" | "transform" => {
                    self.warn(format!("{}:{}: scene-level <{}> ignored", c.loc.file.display(), c.loc.line, c.tag))
                }
                other => return Err(c.loc.err(format!("unknown element <{other}> in <scene>"))),
            }
        }
        Ok(())
    }
}
