//! The `svetlo` binary: exit codes and messages of render, compare and info.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use svetlo::film::Image;
use svetlo::io::image_io::{write_exr, write_pfm};
use svetlo::Rgb;

fn svetlo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_svetlo")).args(args).env("RUST_BACKTRACE", "1").output().expect("the binary runs")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("svetlo-bin-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Exit code, stdout, stderr; asserts that nothing panicked.
fn run(args: &[&str]) -> (i32, String, String) {
    let o = svetlo(args);
    let (out, err) = (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned());
    assert!(!err.contains("panicked") && !err.contains("stack backtrace"), "{args:?} panicked:\n{err}");
    (o.status.code().unwrap_or(-1), out, err)
}

#[test]
fn bad_spp_is_a_usage_error() {
    for spp in ["-5", "0", "many", "1.5"] {
        let (code, _, err) = run(&["render", "scene.xml", "--spp", spp]);
        assert_eq!(code, 2, "--spp {spp}: {err}");
        assert!(err.contains("--spp"), "{err}");
    }
}

#[test]
fn bad_options_are_usage_errors() {
    let cases: &[&[&str]] = &[
        &["render", "scene.xml", "-D", "novalue"],
        &["render", "scene.xml", "-D", "=3"],
        &["render", "scene.xml", "--time", "-1"],
        &["render", "scene.xml", "--max-depth", "-2"],
        &["render", "scene.xml", "--width", "0"],
        &["render", "scene.xml", "--filter", "lanczos"],
        &["render", "scene.xml", "--sampler", "halton"],
        &["render"],
        &["frobnicate"],
    ];
    for args in cases {
        let (code, _, err) = run(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains("error"), "{args:?}: {err}");
    }
}

#[test]
fn unknown_integrator_names_the_choices() {
    let (code, _, err) = run(&["render", "scene.xml", "--integrator", "nope"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown integrator 'nope'") && err.contains("path"), "{err}");
}

#[test]
fn missing_output_directory_is_reported_before_loading() {
    let (code, _, err) = run(&["render", "scene.xml", "-o", "/nonexistent-dir-svetlo/x.exr"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("/nonexistent-dir-svetlo"), "{err}");
}

#[test]
fn unloadable_scene_fails_naming_the_file() {
    let d = tmp("noscene");
    let scene = d.join("missing-scene.xml");
    let out = d.join("o.exr");
    for cmd in ["render", "info"] {
        let mut args = vec![cmd, s(&scene)];
        if cmd == "render" {
            args.extend(["-o", s(&out)]);
        }
        let (code, _, err) = run(&args);
        assert_eq!(code, 1, "{cmd}: {err}");
        assert!(err.contains("missing-scene.xml"), "{cmd}: {err}");
    }
    assert!(!out.exists());
}

/// Reference r, variance v (per sample) and an image, as files.
fn write_set(d: &Path, img: &Image, reference: &Image, var: &Image) -> (PathBuf, PathBuf, PathBuf) {
    let (a, b, c) = (d.join("img.exr"), d.join("ref.exr"), d.join("ref_var.exr"));
    write_exr(&a, img).unwrap();
    write_exr(&b, reference).unwrap();
    write_exr(&c, var).unwrap();
    (a, b, c)
}

fn gradient(w: usize, h: usize) -> Image {
    Image::new(w, h, (0..w * h).map(|i| Rgb::new(0.2 + (i % w) as f32 / w as f32, 0.5, 0.3 + (i / w) as f32 / h as f32)).collect())
}

#[test]
fn compare_exit_codes() {
    let d = tmp("compare");
    let r = gradient(16, 12);
    let var = Image::filled(16, 12, Rgb::splat(0.01));
    // Identical: PASS, relMSE 0.
    let (img, reference, v) = write_set(&d, &r, &r, &var);
    let (code, out, err) = run(&["compare", s(&img), s(&reference), "--ref-var", s(&v), "--spp", "16"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("PASS") && out.contains("relMSE      0.000000e0"), "{out}");
    // relMSE alone succeeds.
    let (code, out, _) = run(&["compare", s(&img), s(&reference)]);
    assert_eq!(code, 0);
    assert!(out.contains("relMSE") && !out.contains("Z-test"), "{out}");
    // 10 % bias, small variance: FAIL.
    let biased = Image::new(16, 12, r.data.iter().map(|c| *c * 1.1).collect());
    let (img, reference, v) = write_set(&d, &biased, &r, &Image::filled(16, 12, Rgb::splat(1e-4)));
    let (code, out, err) = run(&["compare", s(&img), s(&reference), "--ref-var", s(&v), "--spp", "64"]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(out.contains("FAIL"), "{out}");
    // The same in PFM.
    let (pi, pr) = (d.join("img.pfm"), d.join("ref.pfm"));
    write_pfm(&pi, &biased).unwrap();
    write_pfm(&pr, &r).unwrap();
    let (code, out, _) = run(&["compare", s(&pi), s(&pr), "--ref-var", s(&v), "--spp", "64"]);
    assert_eq!(code, 1, "{out}");
    let (code, out, _) = run(&["compare", s(&pr), s(&pr)]);
    assert_eq!(code, 0, "{out}");
}

#[test]
fn compare_bad_input_is_exit_2() {
    let d = tmp("compare-bad");
    let (a, b) = (d.join("a.exr"), d.join("b.exr"));
    write_exr(&a, &gradient(8, 8)).unwrap();
    write_exr(&b, &gradient(8, 4)).unwrap();
    let garbage = d.join("garbage.exr");
    std::fs::write(&garbage, b"not an exr").unwrap();
    let missing = d.join("missing.exr");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["compare", s(&a), s(&b)], "8x4"),
        (vec!["compare", s(&a), s(&a), "--ref-var", s(&b), "--spp", "4"], "8x4"),
        (vec!["compare", s(&a), s(&missing)], "missing.exr"),
        (vec!["compare", s(&garbage), s(&a)], "garbage.exr"),
        (vec!["compare", s(&a), s(&a), "--spp", "4"], "--ref-var"),
        (vec!["compare", s(&a), s(&a), "--ref-var", s(&a)], "--spp"),
        (vec!["compare", s(&a), s(&a), "--ref-var", s(&a), "--spp", "-3"], "--spp"),
    ];
    for (args, needle) in cases {
        let (code, out, err) = run(&args);
        assert_eq!(code, 2, "{args:?}: {out}{err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn help_and_version() {
    let (code, out, _) = run(&["--help"]);
    assert_eq!(code, 0);
    for cmd in ["render", "compare", "info"] {
        assert!(out.contains(cmd), "{out}");
    }
    let (code, out, _) = run(&["render", "--help"]);
    assert_eq!(code, 0);
    for opt in ["--spp", "--time", "--seed", "--max-depth", "--integrator", "--width", "--height", "--filter", "--threads", "--sampler", "-D", "--variance"] {
        assert!(out.contains(opt), "{opt} missing from:\n{out}");
    }
}

/// A tiny Mitsuba 3 scene: a diffuse sphere lit by a point light.
const TINY_XML: &str = r#"<scene version="3.0.0">
    <default name="res" value="24"/>
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, -4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/></film>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
    <emitter type="point"><point name="position" x="1" y="2" z="-3"/><rgb name="intensity" value="10"/></emitter>
</scene>
"#;

#[test]
fn render_end_to_end() {
    let d = tmp("e2e");
    let scene = d.join("tiny.xml");
    std::fs::write(&scene, TINY_XML).unwrap();
    let out = d.join("r.exr");
    let (code, stdout, err) = run(&["render", s(&scene), "-o", s(&out), "--spp", "4", "-D", "res=20", "--variance"]);
    assert_eq!(code, 0, "{stdout}{err}");
    assert!(stdout.contains("20x20") && stdout.contains("samples/s"), "{stdout}");
    for f in ["r.exr", "r.png", "r_var.exr"] {
        assert!(d.join(f).is_file(), "{f}");
    }
    let img = svetlo::io::read_image(&out).unwrap();
    assert_eq!((img.width, img.height), (20, 20));
    let (code, stdout, _) = run(&["info", s(&scene)]);
    assert_eq!(code, 0);
    assert!(stdout.contains("1 spheres") && stdout.contains("1 point"), "{stdout}");
}

#[test]
fn ctrl_c_writes_the_image_and_exits_130() {
    let d = tmp("ctrlc");
    let scene = d.join("tiny.xml");
    std::fs::write(&scene, TINY_XML).unwrap();
    let out = d.join("c.exr");
    let child = Command::new(env!("CARGO_BIN_EXE_svetlo"))
        .args(["render", s(&scene), "-o", s(&out), "--time", "60", "-D", "res=64"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let k = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(k.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted after"), "{err}");
    assert!(out.is_file() && d.join("c.png").is_file());
}
