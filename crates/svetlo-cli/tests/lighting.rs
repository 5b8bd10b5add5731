//! The lighting-design commands end to end: `illuminance` (three estimators, CSV/JSON/PNG,
//! daylight factor), `glare`, `report` and `render --false-colour`, and their usage errors.

use std::path::{Path, PathBuf};
use std::process::Command;

fn run(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_svetlo")).args(args).env("RUST_BACKTRACE", "1").output().expect("the binary runs");
    let (out, err) = (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned());
    assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    (o.status.code().unwrap_or(-1), out, err)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("svetlo-lighting-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 4 × 4 × 3 m grey room with the isotropic 600 × 600 mm test luminaire 0.5 m below its
/// ceiling (closer, the ceiling's hot spot makes gathering heavy-tailed: 15 % low at 64 spp).
fn room(d: &Path, extra: &str) -> PathBuf {
    let ldt = Path::new(env!("CARGO_MANIFEST_DIR")).join("../svetlo/tests/data/photometry/isotropic_sym1.ldt");
    let xml = format!(
        r#"<scene version="3.0.0">
          <sensor type="perspective"><transform name="to_world"><lookat origin="0,-1.9,1.5" target="0,0,1.5" up="0,0,1"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>
          <emitter type="ies"><string name="filename" value="{}"/><transform name="to_world"><translate value="0,0,2.5"/></transform></emitter>
          <shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf><boolean name="flip_normals" value="true"/>
            <transform name="to_world"><scale x="2" y="2" z="1.5"/><translate value="0,0,1.5"/></transform></shape>
          {extra}
        </scene>"#,
        ldt.display()
    );
    let p = d.join("room.xml");
    std::fs::write(&p, xml).unwrap();
    p
}

const PLANE: &str = "origin=-2,-2,0.8 u=4,0,0 v=0,4,0";

#[test]
fn illuminance_by_three_estimators_writes_csv_json_and_a_false_colour_plan() {
    let d = tmp("illum");
    let scene = room(&d, "");
    let mut means = vec![];
    for (est, extra) in [("path", vec!["--spp", "256"]), ("light", vec!["--spp", "2000"]), ("radiosity", vec!["--radiosity", "element-size=0.5"])] {
        let out = d.join(est);
        let mut args = vec!["illuminance", scene.to_str().unwrap(), "--plane", PLANE, "--spacing", "1", "--integrator", est, "-o", out.to_str().unwrap()];
        args.extend(extra);
        let (code, stdout, err) = run(&args);
        assert_eq!(code, 0, "{est}: {err}");
        assert!(stdout.contains("Eavg") && stdout.contains("U0"), "{stdout}");
        let csv = std::fs::read_to_string(out.with_extension("csv")).unwrap();
        assert_eq!(csv.lines().count(), 17, "{csv}");
        let json = std::fs::read_to_string(out.with_extension("json")).unwrap();
        let avg: f64 = json.split("\"e_avg\":").nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
        means.push(avg);
        let png = svetlo::io::read_image(&out.with_extension("png")).expect("a png");
        assert!(png.width >= 4 * 16 && png.height >= 4 * 16);
    }
    // The same room by three methods: within 5 % (each is well under that here).
    for m in &means {
        assert!((m / means[0] - 1.0).abs() < 0.05, "{means:?}");
    }
}

#[test]
fn glare_report_and_false_colour_render() {
    let d = tmp("glare");
    let scene = room(&d, "");
    let (code, out, err) = run(&["glare", scene.to_str().unwrap(), "--eye", "0,-1.5,1.2", "--dir", "0,1,0", "--spp", "256"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("UGR ") && out.contains("light 0"), "{out}");
    let html = d.join("report.html");
    let (code, _, err) = run(&[
        "report",
        scene.to_str().unwrap(),
        "--plane",
        PLANE,
        "--spacing",
        "1",
        "--spp",
        "16",
        "--observer",
        "eye=0,-1.5,1.2 dir=0,1,0",
        "-o",
        html.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("data:image/png;base64,") && page.contains("UGR") && page.contains("isotropic_sym1.ldt"));
    assert!(!page.contains("http://") && !page.contains("https://"), "the page must be self-contained");
    let img = d.join("fc.exr");
    let (code, out, err) =
        run(&["render", scene.to_str().unwrap(), "--spp", "4", "-o", img.to_str().unwrap(), "--false-colour", "luminance", "--scale", "0:50"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("fc_falsecolour.png"), "{out}");
    assert!(d.join("fc_falsecolour.png").exists());
}

#[test]
fn lighting_usage_errors_exit_2_and_bad_skies_exit_3() {
    let d = tmp("bad");
    let scene = room(&d, "");
    let sc = scene.to_str().unwrap();
    let cases: &[&[&str]] = &[
        &["illuminance", sc, "--plane", "origin=0,0,0 u=1,0,0"],
        &["illuminance", sc, "--plane", PLANE, "--integrator", "magic"],
        &["illuminance", sc, "--plane", PLANE, "--scale", "5:1"],
        &["illuminance", sc, "--plane", PLANE, "--integrator", "radiosity", "--radiosity", "solver=nope"],
        &["illuminance", sc, "--plane", PLANE, "--daylight-factor", "--spp", "2"],
        &["glare", sc, "--eye", "0,0", "--dir", "0,1,0"],
        &["glare", sc, "--eye", "0,0,1", "--dir", "0,0,1"],
        &["report", sc, "--plane", PLANE, "--observer", "eye=0,0,1"],
        &["render", sc, "--false-colour", "radiance"],
    ];
    for args in cases {
        let (code, _, err) = run(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains("error"), "{args:?}: {err}");
    }
    for sky in [
        r#"<emitter type="cie_sky"><integer name="type" value="17"/></emitter>"#,
        r#"<emitter type="cie_sky"><float name="sun_elevation" value="120"/></emitter>"#,
    ] {
        let bad = d.join("sky.xml");
        std::fs::write(&bad, std::fs::read_to_string(room(&d, sky)).unwrap()).unwrap();
        let (code, _, err) = run(&["illuminance", bad.to_str().unwrap(), "--plane", PLANE]);
        assert_eq!(code, 3, "{sky}: {err}");
        assert!(err.contains("cie_sky"), "{err}");
    }
}
