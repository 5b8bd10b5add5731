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
        assert_eq!(code, 3, "{cmd}: {err}");
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

/// Start a render that would take a minute, with `sig` reset to its default disposition in
/// the child: the test must not depend on what its own parent ignores (CI may start it with
/// SIGINT ignored, which the child would inherit and, by convention, keep).
fn start_long_render(d: &Path, sig: libc::c_int) -> std::process::Child {
    use std::os::unix::process::CommandExt;
    let scene = d.join("tiny.xml");
    std::fs::write(&scene, TINY_XML).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_svetlo"));
    cmd.args(["render", s(&scene), "-o", s(&d.join("c.exr")), "--time", "60", "-D", "res=64"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            libc::signal(sig, libc::SIG_DFL);
            Ok(())
        });
    }
    cmd.spawn().unwrap()
}

#[test]
fn ctrl_c_and_sigterm_write_the_image_and_exit_130() {
    for (sig, name) in [(libc::SIGINT, "INT"), (libc::SIGTERM, "TERM")] {
        let d = tmp(&format!("signal-{name}"));
        let child = start_long_render(&d, sig);
        std::thread::sleep(std::time::Duration::from_millis(1500));
        let k = Command::new("kill").args([&format!("-{name}"), &child.id().to_string()]).status().unwrap();
        assert!(k.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(130), "SIG{name}: {err}");
        assert!(err.contains("interrupted after"), "{err}");
        assert!(d.join("c.exr").is_file() && d.join("c.png").is_file(), "SIG{name}");
    }
}

#[test]
fn exit_codes_follow_the_documented_classes() {
    let d = tmp("exitcodes");
    let scene = d.join("tiny.xml");
    std::fs::write(&scene, TINY_XML).unwrap();
    let bad = d.join("bad.xml");
    std::fs::write(&bad, TINY_XML.replace("<bsdf type=\"diffuse\"/>", "<bsdf type=\"nope\"/>")).unwrap();
    let o = s(&d.join("o.exr")).to_string();
    let cases: Vec<(Vec<&str>, i32, &str)> = vec![
        // Options of a method (checked when the render starts) are usage errors, like the rest.
        (vec!["render", s(&scene), "-o", &o, "--integrator", "radiosity:element-size=0"], 2, "element"),
        (vec!["render", s(&scene), "-o", &o, "--integrator", "pssmlt:large-step=2"], 2, "large"),
        (vec!["render", s(&scene), "-o", &o, "--threads", "100000"], 2, "--threads"),
        (vec!["render", s(&scene), "-o", &o, "--threads", "-1"], 2, "--threads"),
        (vec!["render", s(&scene), "-o", s(&d), "--spp", "1"], 2, "is a folder"),
        (vec!["render", s(&scene), "-o", &o, "--width", "65536", "--height", "65536"], 2, "budget"),
        (vec!["render", s(&scene), "-o", &o, "--max-memory", "lots"], 2, "--max-memory"),
        (vec!["render", s(&scene), "-o", &o, "--max-memory", "1M", "-D", "res=1000"], 3, "budget"),
        // The scene cannot be loaded.
        (vec!["render", s(&bad), "-o", &o], 3, "bad.xml"),
        (vec!["info", s(&bad)], 3, "nope"),
        (vec!["render", "/dev/zero", "-o", &o], 3, "not a regular file"),
    ];
    for (args, want, needle) in cases {
        let (code, out, err) = run(&args);
        assert_eq!(code, want, "{args:?}: {out}{err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn a_closed_stdout_is_not_a_panic() {
    let d = tmp("stdout");
    let scene = d.join("tiny.xml");
    std::fs::write(&scene, TINY_XML).unwrap();
    for args in [vec!["render", s(&scene), "-o", s(&d.join("p.exr")), "--spp", "1"], vec!["info", s(&scene)]] {
        let mut child =
            Command::new(env!("CARGO_BIN_EXE_svetlo")).args(&args).stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped()).spawn().unwrap();
        // Close the reading end before the child prints: its writes fail with EPIPE.
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
    }
}

#[test]
fn a_full_disk_leaves_no_partial_image() {
    // The file size limit stands in for a full disk: writes past 64 KiB fail (EFBIG; SIGXFSZ
    // is ignored so that the process sees the error). A 256x256 EXR does not fit; every file
    // left behind must be whole (readable) and no temporary file may remain.
    let d = tmp("diskfull");
    let scene = d.join("tiny.xml");
    std::fs::write(&scene, TINY_XML).unwrap();
    let out = d.join("full.exr");
    let cmd = "trap '' XFSZ; ulimit -f 128; exec \"$0\" render \"$1\" -o \"$2\" --spp 1 -D res=256".to_string();
    let o = Command::new("sh").args(["-c", &cmd, env!("CARGO_BIN_EXE_svetlo"), s(&scene), s(&out)]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(!out.exists(), "a partial EXR was left behind");
    for f in std::fs::read_dir(&d).unwrap() {
        let p = f.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        assert!(!name.contains(".tmp"), "temporary file left: {name}");
        if name != "tiny.xml" {
            svetlo::io::read_image(&p).unwrap_or_else(|e| panic!("{name} is not whole: {e}"));
        }
    }
}

#[test]
fn render_without_emitters_is_black_with_a_warning() {
    let d = tmp("noemitter");
    let scene = d.join("dark.xml");
    let text = TINY_XML.lines().filter(|l| !l.contains("<emitter")).collect::<Vec<_>>().join("\n");
    std::fs::write(&scene, text).unwrap();
    for m in ["mlt", "pssmlt", "path"] {
        let out = d.join(format!("{m}.exr"));
        let (code, _, err) = run(&["render", s(&scene), "-o", s(&out), "--integrator", m, "-D", "res=8", "--spp", "4"]);
        assert_eq!(code, 0, "{m}: {err}");
        assert!(err.contains("no emitter"), "{m}: {err}");
        let img = svetlo::io::read_image(&out).unwrap();
        assert!(img.data.iter().all(|c| *c == Rgb::BLACK), "{m}");
    }
}

#[test]
fn light_tracing_warns_about_environment_emitters() {
    let d = tmp("envlight");
    let scene = d.join("env.xml");
    std::fs::write(&scene, TINY_XML.replace("<emitter type=\"point\">", "<emitter type=\"constant\"/><emitter type=\"point\">")).unwrap();
    let (code, _, err) = run(&["render", s(&scene), "-o", s(&d.join("e.exr")), "--integrator", "light", "-D", "res=8", "--spp", "1"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("light tracing does not see environment emitters"), "{err}");
    let (_, _, err) = run(&["render", s(&scene), "-o", s(&d.join("p.exr")), "--integrator", "path", "-D", "res=8", "--spp", "1"]);
    assert!(!err.contains("environment emitters"), "{err}");
}

/// `svetlo info` lists every unsupported plugin by file and line before it tries to load,
/// and still reports the loading error.
#[test]
fn info_lists_unsupported_plugins() {
    let d = tmp("unsupported");
    let scene = d.join("u.xml");
    let text = "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"/>\n<shape type=\"bsplinecurve\"/>\n<shape type=\"sphere\">\n<bsdf type=\"hair\"/>\n</shape>\n</scene>\n";
    std::fs::write(&scene, text).unwrap();
    let (code, stdout, err) = run(&["info", s(&scene)]);
    assert_eq!(code, 3, "{stdout}{err}");
    assert!(stdout.contains("unsupported 2"), "{stdout}");
    assert!(stdout.contains("u.xml:3: <shape type=\"bsplinecurve\"> not supported: skipped"), "{stdout}");
    assert!(stdout.contains("u.xml:5: <bsdf type=\"hair\"> not supported: the scene does not load"), "{stdout}");
    assert!(err.contains("hair"), "{err}");
}

/// pbrt-v4 scenes through the CLI: `convert` both ways (meshes beside the output), `render`
/// of a pbrt file under another name with `--format pbrt`, and a bad pbrt file exits 3
/// naming its file and line.
#[test]
fn pbrt_convert_render_and_errors() {
    let d = tmp("pbrt");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/pbrt/shapes.pbrt");
    let xml = d.join("shapes.xml");
    let (code, stdout, err) = run(&["convert", s(&src), "-o", s(&xml)]);
    assert_eq!(code, 0, "{stdout}{err}");
    assert!(stdout.contains("wrote") && d.join("shapes_files").is_dir(), "{stdout}");
    let (code, stdout, err) = run(&["info", s(&xml)]);
    assert_eq!(code, 0, "{stdout}{err}");
    let back = d.join("again.pbrt");
    let (code, _, err) = run(&["convert", s(&xml), "-o", s(&back)]);
    assert_eq!(code, 0, "{err}");
    let renamed = d.join("scene.txt");
    std::fs::copy(&back, &renamed).unwrap();
    let out = d.join("r.exr");
    let (code, stdout, err) = run(&["render", s(&renamed), "--format", "pbrt", "-o", s(&out), "--spp", "1", "--width", "16", "--height", "12"]);
    assert_eq!(code, 0, "{stdout}{err}");
    assert!(out.is_file());
    let bad = d.join("bad.pbrt");
    std::fs::write(&bad, "Camera \"perspective\"\nWorldBegin\nShape \"sphere\" \"float radius\" [ 1\n").unwrap();
    let (code, _, err) = run(&["convert", s(&bad), "-o", s(&d.join("x.xml"))]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("bad.pbrt:3"), "{err}");
    let _ = std::fs::remove_dir_all(&d);
}

/// `render --dask` with `SVETLO_PYTHON` set to `python` (never a real cluster: dask is not
/// needed by cargo test).
fn run_dask(python: &str, args: &[&str]) -> (i32, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_svetlo")).args(args).env("SVETLO_PYTHON", python).env("RUST_BACKTRACE", "1").output().expect("the binary runs");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    (o.status.code().unwrap_or(-1), err)
}

#[test]
fn dask_without_a_python_or_its_package_is_a_clear_error() {
    let d = tmp("dask");
    let out = d.join("out.exr");
    let args = ["render", "scene.xml", "--dask", "tcp://127.0.0.1:8786", "--spp", "4", "-o", s(&out)];
    let (code, err) = run_dask("/nonexistent/python3", &args);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("no Python at '/nonexistent/python3'") && err.contains("SVETLO_PYTHON") && err.contains("dask[distributed]"), "{err}");
    // A program that runs but cannot import the package (`false` exits 1 whatever it is given).
    if Path::new("/bin/false").exists() {
        let (code, err) = run_dask("/bin/false", &args);
        assert_eq!(code, 1, "{err}");
        assert!(err.contains("cannot import svetlo.distributed") && err.contains("SVETLO_PYTHON"), "{err}");
    }
    // Options a distributed render does not take, and bad addresses, are usage errors before
    // any Python runs.
    for extra in [&["--time", "3"][..], &["--lpe", "C D L"], &["--variance"]] {
        let mut a = args.to_vec();
        a.extend_from_slice(extra);
        let (code, err) = run_dask("/nonexistent/python3", &a);
        assert_eq!(code, 2, "{extra:?}: {err}");
        assert!(err.contains("--dask does not take"), "{err}");
    }
    let (code, err) = run_dask("/nonexistent/python3", &["render", "scene.xml", "--dask", "local:0", "-o", s(&out)]);
    assert_eq!(code, 2, "{err}");
    let (code, err) = run_dask("/nonexistent/python3", &["render", "scene.xml", "--chunks", "3", "-o", s(&out)]);
    assert_eq!(code, 2, "--chunks without --dask: {err}");
}
