//! The preview page in headless Chromium (tests/browser/preview.mjs, playwright-core): the
//! image appears and changes, Stop keeps the samples, the split view and the error plot have
//! content, and changing the integrator restarts the render. Needs node, Chromium
//! (`/usr/bin/chromium` or `$CHROMIUM`) and `npm ci` in tests/browser; `.ci/run` installs
//! them and sets `SVETLO_BROWSER_TEST=1`, which turns a missing piece into a failure.

use std::path::PathBuf;
use std::process::Command;

#[test]
fn preview_page_in_headless_chromium() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/browser");
    let chromium = std::env::var_os("CHROMIUM").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    let required = std::env::var_os("SVETLO_BROWSER_TEST").is_some();
    let node_ok = Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
    let missing: Vec<&str> = [
        (!node_ok).then_some("node"),
        (!chromium.is_file()).then_some("chromium"),
        (!dir.join("node_modules/playwright-core").is_dir()).then_some("playwright-core (npm ci in crates/svetlo-cli/tests/browser)"),
    ]
    .into_iter()
    .flatten()
    .collect();
    if !missing.is_empty() {
        assert!(!required, "SVETLO_BROWSER_TEST is set but these are missing: {missing:?}");
        eprintln!("skipping the browser test: missing {missing:?}");
        return;
    }
    let out = std::env::temp_dir().join(format!("svetlo-preview-browser-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let scene = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let o = Command::new("node")
        .arg(dir.join("preview.mjs"))
        .env("SVETLO_BIN", env!("CARGO_BIN_EXE_svetlo"))
        .env("SVETLO_SCENE", &scene)
        .env("SVETLO_OUT", &out)
        .env("CHROMIUM", &chromium)
        .output()
        .expect("node runs");
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "browser test failed (screenshots in {}):\n{stdout}\n{stderr}", out.display());
    assert!(stdout.contains("RESULT "), "{stdout}");
    // Stop kept the samples done: the EXR is the lit Cornell box, fewer spp than asked.
    let img = svetlo::io::image_io::read_image(&out.join("stopped.exr")).expect("the stopped render wrote its EXR");
    assert_eq!((img.width, img.height), (96, 96));
    let mean = img.mean();
    assert!(mean.min_component() > 0.01 && mean.is_finite(), "mean {mean:?}");
    let result = std::fs::read_to_string(out.join("result.json")).unwrap();
    let spp: u64 = result.split("\"spp\":").nth(1).and_then(|r| r.split(',').next()).and_then(|n| n.parse().ok()).expect("spp in the result");
    assert!(spp > 0 && spp < 1_000_000, "stopped after {spp} spp");
    // The restarted render with another integrator wrote its own image.
    assert!(out.join("cmp-whitted.exr").is_file());
    let _ = std::fs::remove_dir_all(&out);
}
