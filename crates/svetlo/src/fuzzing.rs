//! The entry points of the fuzz targets (`fuzz/`), here so that the stable test
//! `tests/fuzz_replay.rs` feeds the corpus and every crash reproducer to exactly the same
//! code. Each takes arbitrary bytes; an error is a correct answer, a panic, abort, hang or
//! memory blow-up is a bug.

use std::path::Path;

/// The budget the targets run under: inputs are small, so anything asking for more is a
/// header that lies (and is refused the same way at any budget).
pub const FUZZ_MEMORY: u64 = 512 << 20;

fn text(data: &[u8]) -> Option<&str> {
    std::str::from_utf8(data).ok()
}

/// A Mitsuba scene held in memory, resolved against a folder that does not exist (so only
/// absolute names reach the file system, and those must be regular files within budget).
pub fn mitsuba_xml(data: &[u8]) {
    crate::limits::set_max_memory(FUZZ_MEMORY);
    if let Some(t) = text(data) {
        let _ = crate::io::load_scene_from_str(t, Path::new("/nonexistent-svetlo-fuzz/scene.xml"), &[]);
    }
}

/// An OBJ file's bytes, with and without the texture-coordinate flip.
pub fn obj(data: &[u8]) {
    crate::limits::set_max_memory(FUZZ_MEMORY);
    let _ = crate::io::mesh_files::load_obj_bytes(data, Path::new("fuzz.obj"), data.len().is_multiple_of(2));
}

/// A PLY file's bytes.
pub fn ply(data: &[u8]) {
    crate::limits::set_max_memory(FUZZ_MEMORY);
    let _ = crate::io::mesh_files::load_ply_bytes(data, Path::new("fuzz.ply"), false);
}

/// An image's bytes: EXR and PFM by magic number, PNG (and the other 8-bit formats) by content.
pub fn image(data: &[u8]) {
    crate::limits::set_max_memory(FUZZ_MEMORY);
    let _ = crate::io::image_io::decode_image(data, Path::new("fuzz.png"));
}

/// A luminaire file's bytes, through both parsers (IES LM-63 and EULUMDAT).
pub fn photometry(data: &[u8]) {
    let _ = crate::photometry::ies::parse(data, Path::new("fuzz.ies"));
    let _ = crate::photometry::eulumdat::parse(data, Path::new("fuzz.ldt"));
}

/// A `--integrator` string (`name:key=value,...`).
pub fn integrator_options(data: &[u8]) {
    if let Some(t) = text(data) {
        let _ = crate::methods::by_name(t);
    }
}

/// A light path expression (the first line) and a path to match (each later byte one vertex:
/// its base class and label bits). Besides not crashing, the camera-first automaton, the
/// light-first one and every split of the path into a camera prefix and a light subpath must
/// agree: the bidirectional methods rely on it.
pub fn lpe(data: &[u8]) {
    let (expr, path) = match data.iter().position(|&b| b == b'\n') {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &data[..0]),
    };
    let Some(expr) = text(expr) else { return };
    let Ok(mut l) = crate::lpe::Lpe::new(expr) else { return };
    // Labels named in the expression bound to the first bits, as an AOV set binds them.
    let n = l.labels().len();
    l.bind_labels((0..n as u8).collect());
    let events: Vec<crate::lpe::Event> =
        path.iter().take(64).map(|&b| crate::lpe::Event { base: b % crate::lpe::automaton::BASE_COUNT as u8, labels: (b as u32 >> 4) & 0xf }).collect();
    let forward = l.matches(&events);
    assert_eq!(forward, l.matches_from_light(&events), "'{expr}': the reverse automaton disagrees on {events:?}");
    for k in 0..=events.len() {
        let q = events[..k].iter().fold(crate::lpe::Lpe::START, |s, &e| l.step(s, e));
        let r = events[k..].iter().rev().fold(crate::lpe::Lpe::START, |s, &e| l.rev_step(s, e));
        assert_eq!(forward, l.meets(q, r), "'{expr}': the split at {k} disagrees on {events:?}");
    }
}

/// A target's entry point.
pub type Entry = fn(&[u8]);

/// The targets by name, as `fuzz/corpus/<name>` and the reproducers' folders are named.
pub const TARGETS: &[(&str, Entry)] = &[
    ("mitsuba_xml", mitsuba_xml),
    ("obj", obj),
    ("ply", ply),
    ("image", image),
    ("integrator_options", integrator_options),
    ("photometry", photometry),
    ("lpe", lpe),
];
