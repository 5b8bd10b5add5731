//! First pass over a Mitsuba XML file: parse it, expand `<include>`, apply `<default>` and
//! `$name` substitution, collect `<path>` folders, and normalise the 0.5/0.6 dialect
//! (camelCase names, `lookAt`). The result is an owned tree whose every element knows the
//! file, line and column it came from, so later errors can point at it.

use crate::error::{Error, Result};
use crate::limits::{MAX_ELEMENT_DEPTH, MAX_INCLUDES, MAX_SCENE_TEXT};
use std::cell::Cell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where an element was written.
#[derive(Clone, Debug)]
pub struct Loc {
    pub file: Arc<PathBuf>,
    pub line: u32,
    pub col: u32,
}

impl Loc {
    pub fn err(&self, msg: impl Into<String>) -> Error {
        Error::SceneAt { file: (*self.file).clone(), line: self.line, col: self.col, msg: msg.into() }
    }
    /// The folder of the file this element came from.
    pub fn dir(&self) -> PathBuf {
        self.file.parent().map(Path::to_path_buf).unwrap_or_default()
    }
}

#[derive(Clone, Debug)]
pub struct Node {
    pub tag: String,
    pub attrs: Vec<(String, String)>,
    pub children: Vec<Node>,
    pub loc: Loc,
}

impl Node {
    pub fn attr(&self, k: &str) -> Option<&str> {
        self.attrs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str())
    }
    /// A required attribute.
    pub fn req(&self, k: &str) -> Result<&str> {
        self.attr(k).ok_or_else(|| self.loc.err(format!("<{}> needs a '{k}' attribute", self.tag)))
    }
    pub fn name(&self) -> Option<&str> {
        self.attr("name")
    }
    pub fn type_(&self) -> Result<&str> {
        self.req("type")
    }
    pub fn id(&self) -> Option<&str> {
        self.attr("id")
    }
}

/// The expanded scene: its root `<scene>` element and the folders `<path>` added.
pub struct Parsed {
    pub root: Node,
    pub search_paths: Vec<PathBuf>,
    /// Parameters given by the caller that no `$name` used.
    pub unused_params: Vec<String>,
}

struct Ctx {
    params: HashMap<String, String>,
    used: std::collections::HashSet<String>,
    search_paths: Vec<PathBuf>,
    stack: Vec<PathBuf>,
    /// Includes expanded and bytes of text parsed so far: includes that fan out (each file
    /// including the next twice) would otherwise take exponential time without a cycle.
    includes: usize,
    text_bytes: u64,
}

impl Ctx {
    fn new(origin: &Path, defaults: &[(String, String)]) -> Self {
        Ctx {
            params: defaults.iter().cloned().collect(),
            used: Default::default(),
            search_paths: vec![origin.parent().map(Path::to_path_buf).unwrap_or_default()],
            stack: Vec::new(),
            includes: 0,
            text_bytes: 0,
        }
    }

    fn into_parsed(self, root: Node, defaults: &[(String, String)]) -> Parsed {
        let unused_params = defaults.iter().map(|(k, _)| k.clone()).filter(|k| !self.used.contains(k)).collect();
        Parsed { root, search_paths: self.search_paths, unused_params }
    }

    fn charge(&mut self, path: &Path, bytes: usize) -> Result<()> {
        self.text_bytes += bytes as u64;
        if self.text_bytes > MAX_SCENE_TEXT {
            return Err(Error::Scene {
                file: path.to_path_buf(),
                msg: format!("the scene and its includes exceed {} of text", crate::limits::human(MAX_SCENE_TEXT)),
            });
        }
        Ok(())
    }
}

/// Parse `path` and everything it includes. `defaults` override `<default>` values.
pub fn parse(path: &Path, defaults: &[(String, String)]) -> Result<Parsed> {
    let canon = std::fs::canonicalize(path).map_err(|e| Error::Io { file: path.to_path_buf(), source: e })?;
    let text = crate::limits::read_text(path)?;
    parse_text(&text, path, Some(canon), defaults)
}

/// Parse a scene held in memory. `origin` names it in errors, and relative file names
/// (includes, meshes, textures) are resolved against `origin`'s folder.
pub fn parse_str(text: &str, origin: &Path, defaults: &[(String, String)]) -> Result<Parsed> {
    parse_text(text, origin, None, defaults)
}

fn parse_text(text: &str, path: &Path, canon: Option<PathBuf>, defaults: &[(String, String)]) -> Result<Parsed> {
    let mut ctx = Ctx::new(path, defaults);
    ctx.charge(path, text.len())?;
    let root = parse_document(text, path, canon, &mut ctx)?;
    Ok(ctx.into_parsed(root, defaults))
}

fn parse_file(path: &Path, ctx: &mut Ctx) -> Result<Node> {
    let canon = std::fs::canonicalize(path).map_err(|e| Error::Io { file: path.to_path_buf(), source: e })?;
    if ctx.stack.contains(&canon) {
        let chain: Vec<String> = ctx.stack.iter().chain(std::iter::once(&canon)).map(|p| p.display().to_string()).collect();
        return Err(Error::Scene { file: path.to_path_buf(), msg: format!("include cycle: {}", chain.join(" -> ")) });
    }
    let text = crate::limits::read_text(path)?;
    ctx.charge(path, text.len())?;
    parse_document(&text, path, Some(canon), ctx)
}

/// One document's root `<scene>`, its includes expanded; `canon` (the file's canonical path,
/// `None` for a scene held in memory) joins the include stack that detects cycles.
fn parse_document(text: &str, path: &Path, canon: Option<PathBuf>, ctx: &mut Ctx) -> Result<Node> {
    let opts = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
    let doc = roxmltree::Document::parse_with_options(text, opts).map_err(|e| {
        let p = e.pos();
        Error::SceneAt { file: path.to_path_buf(), line: p.row, col: p.col, msg: format!("malformed XML: {e}") }
    })?;
    let d = Doc { lines: LineIndex::new(text), file: Arc::new(path.to_path_buf()) };
    let root = doc.root_element();
    let loc = d.loc(root);
    if root.tag_name().name() != "scene" {
        return Err(loc.err(format!("not a Mitsuba scene: the root element is <{}>, not <scene>", root.tag_name().name())));
    }
    let attrs = root.attributes().map(|a| (a.name().to_string(), a.value().to_string())).collect();
    let raw = Node { tag: "scene".into(), attrs, children: read_children(&d, root, 1)?, loc };
    expand_document(raw, canon, ctx)
}

/// A scene's root element, built by other means than parsing text (Python's `load_dict`),
/// expanded as a parsed file is: `<default>`, `$name`, `<path>`, `<include>` and the 0.6
/// dialect's names. `origin` stands for the file: relative names resolve against its folder.
pub fn expand_tree(root: Node, origin: &Path, defaults: &[(String, String)]) -> Result<Parsed> {
    if root.tag != "scene" {
        return Err(root.loc.err(format!("not a Mitsuba scene: the root element is <{}>, not <scene>", root.tag)));
    }
    fn check_depth(n: &Node, depth: usize) -> Result<()> {
        if depth >= MAX_ELEMENT_DEPTH {
            return Err(n.loc.err(format!("elements nest more than {MAX_ELEMENT_DEPTH} deep")));
        }
        n.children.iter().try_for_each(|c| check_depth(c, depth + 1))
    }
    root.children.iter().try_for_each(|c| check_depth(c, 1))?;
    let mut ctx = Ctx::new(origin, defaults);
    let root = expand_document(root, None, &mut ctx)?;
    Ok(ctx.into_parsed(root, defaults))
}

/// A document's raw tree with its includes, defaults and parameters applied.
fn expand_document(mut root: Node, canon: Option<PathBuf>, ctx: &mut Ctx) -> Result<Node> {
    if ctx.stack.len() >= MAX_ELEMENT_DEPTH {
        return Err(root.loc.err(format!("includes nest more than {MAX_ELEMENT_DEPTH} deep")));
    }
    let pushed = canon.is_some();
    ctx.stack.extend(canon);
    let children = expand(std::mem::take(&mut root.children), ctx);
    if pushed {
        ctx.stack.pop();
    }
    root.children = children?;
    Ok(root)
}

/// Line and column (1-based, in characters) of byte offsets, asked in increasing order as the
/// tree is walked: a cursor moves forward through the text, so a file's positions cost one
/// pass over it in all (roxmltree's `text_pos_at` scans from the start each time, quadratic
/// in the number of elements).
struct LineIndex<'t> {
    text: &'t str,
    /// Byte offset, line and column of the cursor.
    cursor: Cell<(usize, u32, u32)>,
}

impl<'t> LineIndex<'t> {
    fn new(text: &'t str) -> Self {
        LineIndex { text, cursor: Cell::new((0, 1, 1)) }
    }

    fn pos(&self, byte: usize) -> (u32, u32) {
        let byte = byte.min(self.text.len());
        let (mut at, mut line, mut col) = self.cursor.get();
        if byte < at {
            (at, line, col) = (0, 1, 1);
        }
        for c in self.text[at..byte].chars() {
            if c == '\n' {
                line += 1;
                col = 1;
            } else {
                col += 1;
            }
        }
        at = byte;
        self.cursor.set((at, line, col));
        (line, col)
    }
}

/// One parsed document: where its elements are, and the file they came from.
struct Doc<'t> {
    lines: LineIndex<'t>,
    file: Arc<PathBuf>,
}

impl Doc<'_> {
    fn loc(&self, n: roxmltree::Node) -> Loc {
        let (line, col) = self.lines.pos(n.range().start);
        Loc { file: self.file.clone(), line, col }
    }
}

/// The elements under `parent` as written (tags of the 0.6 dialect normalised), each with
/// where it was written.
fn read_children(d: &Doc, parent: roxmltree::Node, depth: usize) -> Result<Vec<Node>> {
    let mut out = Vec::new();
    for n in parent.children().filter(|n| n.is_element()) {
        let loc = d.loc(n);
        // The loader walks the tree recursively: bound its depth here, once for every pass.
        if depth >= MAX_ELEMENT_DEPTH {
            return Err(loc.err(format!("elements nest more than {MAX_ELEMENT_DEPTH} deep")));
        }
        let attrs = n.attributes().map(|a| (a.name().to_string(), a.value().to_string())).collect();
        let children = read_children(d, n, depth + 1)?;
        out.push(Node { tag: normalise_tag(n.tag_name().name()), attrs, children, loc });
    }
    Ok(out)
}

/// Apply `$name` parameters and the 0.6 dialect's property names to `nodes` in document
/// order, take `<default>` and `<path>` into the context and replace `<include>` by the
/// included file's elements.
fn expand(nodes: Vec<Node>, ctx: &mut Ctx) -> Result<Vec<Node>> {
    let mut out = Vec::with_capacity(nodes.len());
    for mut node in nodes {
        for (k, v) in &mut node.attrs {
            let sub = substitute(v, &node.loc, ctx)?;
            // Property names of the 0.6 dialect are camelCase (toWorld, sampleCount, intIOR).
            // (Parameter names of <default> are left alone: `$resX` must still find them.)
            *v = if k == "name" && node.tag != "default" { camel_to_snake(&sub) } else { sub };
        }
        match node.tag.as_str() {
            "default" => {
                let name = node.req("name")?.to_string();
                let value = node.req("value")?.to_string();
                ctx.params.entry(name).or_insert(value);
            }
            "path" => {
                let v = node.req("value")?;
                let p = Path::new(v);
                let dir = if p.is_absolute() { p.to_path_buf() } else { node.loc.dir().join(p) };
                ctx.search_paths.push(dir);
            }
            "include" => {
                let fname = node.req("filename")?;
                ctx.includes += 1;
                if ctx.includes > MAX_INCLUDES {
                    return Err(node.loc.err(format!("more than {MAX_INCLUDES} includes in one scene (do the includes fan out?)")));
                }
                let target = resolve_in(fname, &node.loc.dir(), &ctx.search_paths).ok_or_else(|| node.loc.err(format!("included file '{fname}' not found")))?;
                let inc = parse_file(&target, ctx)?;
                out.extend(inc.children);
            }
            _ => {
                node.children = expand(std::mem::take(&mut node.children), ctx)?;
                out.push(node);
            }
        }
    }
    Ok(out)
}

/// Find a file: as given if absolute, else next to the referring file, else in the search paths.
pub fn resolve_in(name: &str, dir: &Path, search: &[PathBuf]) -> Option<PathBuf> {
    let p = Path::new(name);
    if p.is_absolute() {
        return p.exists().then(|| p.to_path_buf());
    }
    std::iter::once(dir).chain(search.iter().rev().map(|p| p.as_path())).map(|d| d.join(p)).find(|c| c.exists())
}

/// Replace every `$name` by its parameter; an unknown name is an error.
fn substitute(v: &str, loc: &Loc, ctx: &mut Ctx) -> Result<String> {
    if !v.contains('$') {
        return Ok(v.to_string());
    }
    let mut out = String::with_capacity(v.len());
    let mut rest = v;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
        if len == 0 {
            out.push('$');
            rest = after;
            continue;
        }
        let name = &after[..len];
        let val = ctx.params.get(name).ok_or_else(|| loc.err(format!("undefined parameter '${name}' (give it with <default> or -D {name}=...)")))?;
        out.push_str(val);
        ctx.used.insert(name.to_string());
        rest = &after[len..];
    }
    out.push_str(rest);
    Ok(out)
}

fn normalise_tag(t: &str) -> String {
    match t {
        "lookAt" => "lookat".into(),
        _ => t.to_string(),
    }
}

/// `toWorld` -> `to_world`, `intIOR` -> `int_ior`; snake_case names pass unchanged.
pub fn camel_to_snake(s: &str) -> String {
    if !s.chars().any(|c| c.is_ascii_uppercase()) {
        return s.to_string();
    }
    let mut out = String::with_capacity(s.len() + 4);
    let mut prev_lower = false;
    for c in s.chars() {
        if c.is_ascii_uppercase() {
            if prev_lower {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
            prev_lower = false;
        } else {
            out.push(c);
            prev_lower = c.is_ascii_lowercase() || c.is_ascii_digit();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::camel_to_snake;

    #[test]
    fn camel_names() {
        assert_eq!(camel_to_snake("toWorld"), "to_world");
        assert_eq!(camel_to_snake("sampleCount"), "sample_count");
        assert_eq!(camel_to_snake("intIOR"), "int_ior");
        assert_eq!(camel_to_snake("fovAxis"), "fov_axis");
        assert_eq!(camel_to_snake("max_depth"), "max_depth");
        assert_eq!(camel_to_snake("alphaU"), "alpha_u");
    }
}
