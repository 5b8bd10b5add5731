//! The structural guards of the loader: `<ref>` cycles found before anything is built, a
//! bound on how deep plugins nest (references included) and on how many are built, and the
//! scene's `version`. Together with the element depth bound of [`super::xml`], no scene can
//! drive the recursive loader into a stack overflow or exponential work.

use super::xml::Node;
use super::Loader;
use crate::error::Result;
use crate::limits::{MAX_PLUGIN_DEPTH, MAX_PLUGIN_INSTANCES};
use std::collections::HashMap;

/// The newest scene format this loader reads.
const MAX_VERSION_MAJOR: u32 = 3;

/// The ids one element uses: `<ref id>` below it, and the elements with an id nested in it
/// (building the outer one builds them), not looking inside those.
fn edges<'a>(n: &'a Node, out: &mut Vec<(&'a str, &'a Node)>) {
    for c in &n.children {
        if c.tag == "ref" {
            if let Some(id) = c.id() {
                out.push((id, c));
            }
        } else if let Some(id) = c.id() {
            out.push((id, c));
        } else {
            edges(c, out);
        }
    }
}

/// One id on the search stack: the id, the ids it uses (with where), the next one to follow.
type Frame<'a> = (&'a str, Vec<(&'a str, &'a Node)>, usize);

/// Fail on a cycle of references (a `twosided` whose nested BSDF refers back to it, a
/// shapegroup that instances itself), naming the chain.
pub(super) fn check_cycles(ids: &HashMap<&str, &Node>) -> Result<()> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        Open,
        Done,
    }
    let mut mark: HashMap<&str, Mark> = HashMap::new();
    // Iterative depth-first search: a chain of 100 000 references must not overflow the stack.
    let mut roots: Vec<&str> = ids.keys().copied().collect();
    roots.sort_unstable();
    for root in roots {
        if mark.contains_key(root) {
            continue;
        }
        // (id, its edges, the next edge to follow)
        let mut stack: Vec<Frame> = Vec::new();
        let mut out = Vec::new();
        edges(ids[root], &mut out);
        mark.insert(root, Mark::Open);
        stack.push((root, out, 0));
        while let Some(top) = stack.last_mut() {
            let Some(&(next, at)) = top.1.get(top.2) else {
                mark.insert(top.0, Mark::Done);
                stack.pop();
                continue;
            };
            top.2 += 1;
            match mark.get(next) {
                Some(Mark::Done) => {}
                Some(Mark::Open) => {
                    let start = stack.iter().position(|(id, _, _)| *id == next).unwrap_or(0);
                    let chain: Vec<&str> = stack[start..].iter().map(|(id, _, _)| *id).chain(std::iter::once(next)).collect();
                    return Err(at.loc.err(format!("reference cycle: {}", chain.join(" -> "))));
                }
                // An unknown id: reported where it is used.
                None if !ids.contains_key(next) => {}
                None => {
                    let mut out = Vec::new();
                    edges(ids[next], &mut out);
                    mark.insert(next, Mark::Open);
                    stack.push((next, out, 0));
                }
            }
        }
    }
    Ok(())
}

impl<'a> Loader<'a> {
    /// Build one plugin inside the depth and count bounds.
    pub(super) fn nested<T>(&mut self, node: &'a Node, build: impl FnOnce(&mut Self) -> Result<T>) -> Result<T> {
        if self.plugin_depth >= MAX_PLUGIN_DEPTH {
            return Err(node.loc.err(format!("plugins nest more than {MAX_PLUGIN_DEPTH} deep (counting references)")));
        }
        self.plugin_instances += 1;
        if self.plugin_instances > MAX_PLUGIN_INSTANCES {
            return Err(node.loc.err(format!("the scene builds more than {MAX_PLUGIN_INSTANCES} plugins (do references fan out?)")));
        }
        self.plugin_depth += 1;
        let r = build(self);
        self.plugin_depth -= 1;
        r
    }

    /// `version="3.0.0"` and older are read; a newer major version loads with a warning (its
    /// elements are read as version 3 defines them); a malformed one is an error.
    pub(super) fn check_version(&mut self, root: &'a Node) -> Result<()> {
        let Some(v) = root.attr("version") else { return Ok(()) };
        let parts: Option<Vec<u32>> = v.trim().split('.').map(|p| p.parse().ok()).collect();
        match parts.as_deref() {
            Some([major, ..]) if *major <= MAX_VERSION_MAJOR => Ok(()),
            Some([major, ..]) => {
                self.warn(format!(
                    "{}:{}: scene version {v} is newer than this loader understands ({MAX_VERSION_MAJOR}.x); read as version {MAX_VERSION_MAJOR} (major version {major})",
                    root.loc.file.display(),
                    root.loc.line
                ));
                Ok(())
            }
            _ => Err(root.loc.err(format!("scene version '{v}' is not a version number (like 3.0.0)"))),
        }
    }
}
