//! Bad input to the Mitsuba plugins of issue #20 (projector, ...): typed errors that name
//! the file and the line of the offending element, never a panic.

use std::path::Path;
use svetlo::io::load_scene_from_str;

const SENSOR: &str = r#"<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>"#;

/// Load `body` (placed on line 3 of a scene) and return the error's text.
fn error_of(body: &str) -> String {
    let text = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>");
    match load_scene_from_str(&text, Path::new("/nowhere/bad.xml"), &[]) {
        Ok(_) => panic!("loaded:\n{body}"),
        Err(e) => e.to_string(),
    }
}

fn assert_names_line(body: &str, words: &str) {
    let e = error_of(body);
    assert!(e.contains("bad.xml:3"), "no file:line in '{e}'");
    assert!(e.contains(words), "'{e}' does not say '{words}'");
}

#[test]
fn projector_bad_input() {
    assert_names_line(r#"<emitter type="projector"><float name="scale" value="-1"/></emitter>"#, "scale");
    assert_names_line(r#"<emitter type="projector"><float name="fov" value="180"/></emitter>"#, "fov");
    assert_names_line(r#"<emitter type="projector"><float name="fov" value="0"/></emitter>"#, "fov");
    assert_names_line(r#"<emitter type="projector"><float name="fov" value="40"/><string name="fov_axis" value="z"/></emitter>"#, "fov_axis");
    assert_names_line(r#"<emitter type="projector"><transform name="to_world"><scale x="0"/></transform></emitter>"#, "degenerate");
    let e = error_of(r#"<emitter type="projector"><texture type="bitmap" name="irradiance"><string name="filename" value="missing.png"/></texture></emitter>"#);
    assert!(e.contains("missing.png"), "{e}");
}

#[test]
fn projector_loads() {
    let text = format!("<scene version=\"3.0.0\">\n{SENSOR}\n<emitter type=\"projector\"><float name=\"fov\" value=\"60\"/><rgb name=\"irradiance\" value=\"0.5\"/></emitter>\n</scene>");
    let s = load_scene_from_str(&text, Path::new("/nowhere/ok.xml"), &[]).expect("loads");
    assert!(matches!(s.lights.as_slice(), [svetlo::light::Light::Projector(_)]));
}
