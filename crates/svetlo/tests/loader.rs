//! The Mitsuba loader against the shared test scenes and against bad input.

use std::path::{Path, PathBuf};
use svetlo::io::load_scene;

fn shared() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes");
    if p.exists() {
        Some(p)
    } else {
        eprintln!("SKIPPED: {} not found (the shared test scenes are not checked out)", p.display());
        None
    }
}

fn all_xml(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            all_xml(&p, out);
        } else if p.extension().is_some_and(|e| e == "xml") {
            out.push(p);
        }
    }
}

#[test]
fn report_all() {
    let Some(root) = shared() else { return };
    let mut files = Vec::new();
    all_xml(&root, &mut files);
    files.sort();
    for f in files {
        if f.to_string_lossy().contains("viewfactors") && !f.to_string_lossy().ends_with("001.xml") { continue; }
        match load_scene(&f, &[]) {
            Ok(s) => println!("OK   {} shapes={} lights={} mats={} cam={}x{} spp={} int={} depth={} warn={:?}", f.strip_prefix(&root).unwrap().display(), s.shapes.len(), s.lights.len(), s.materials.len(), s.camera.width, s.camera.height, s.settings.spp, s.settings.integrator, s.settings.max_depth, s.warnings),
            Err(e) => println!("ERR  {} : {e}", f.strip_prefix(&root).unwrap().display()),
        }
    }
}
