//! Radiosity on Mitsuba's measured Cornell box (`cbox-rgb`, one-sided diffuse walls from OBJ
//! files, no back faces) against its 4096-spp Mitsuba 3 reference: one point of the table of
//! element count against relMSE in bench/radiosity (README). Needs ../shared; skips without it.

use std::path::PathBuf;
use svetlo::film::{compare::rel_mse, Filter, Image};
use svetlo::integrator::{render_pixels, Progress, RenderSettings};
use svetlo::radiosity::{solve, RadiosityOptions, Shading};

fn cbox() -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/mitsuba-data/scenes/cbox");
    if p.join("cbox-rgb.xml").is_file() {
        Some(p)
    } else {
        eprintln!("SKIPPED: {} not found", p.display());
        None
    }
}

fn mean(img: &Image) -> [f64; 3] {
    let mut m = [0.0f64; 3];
    for px in &img.data {
        for k in 0..3 {
            m[k] += px[k] as f64;
        }
    }
    m.map(|x| x / img.data.len() as f64)
}

/// Full matrix at 140-unit elements (596 elements; the box is 556 wide), the scene's max_depth
/// (6: five diffuse bounces, as the reference's path tracer), Gouraud, 4 spp box filter.
/// Measured relMSE 9.0e-3 (the table falls to 4.3e-3 at 2 370 and 3.0e-3 at 8 438 elements);
/// the bound 1.2e-2 is a third above it, below the 1.6e-2 of the hierarchical solution with
/// 248 leaves. relMSE alone would let a uniform 10 % brightness error through (it adds
/// ~1e-2 × ⟨r²/(r² + 0.01)⟩), so the image's mean is also pinned per channel: radiosity
/// conserves energy on its mesh: measured means within 0.4 % of the reference (R, G, B 0.2110,
/// 0.1028, 0.0257 vs 0.2117, 0.1029, 0.0258), bound 1.5 % (a uniform 2 % error fails).
#[test]
fn cbox_rgb_agrees_with_the_mitsuba_reference() {
    let Some(dir) = cbox() else { return };
    let scene = svetlo::io::load_scene(&dir.join("cbox-rgb.xml"), &[]).expect("scene");
    let reference = svetlo::io::read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    let opts = RadiosityOptions::parse("solver=gauss-seidel,element-size=140").expect("options");
    let solved = solve(&scene, &opts, scene.settings.max_depth).expect("solve");
    let settings = RenderSettings { spp: 4, filter: Filter::Box, ..RenderSettings::from_scene(&scene) };
    let img = render_pixels(&scene, &settings, &Progress::new(), &solved.view(Shading::Gouraud)).expect("render").image();
    let e = rel_mse(&img, &reference).expect("relmse");
    let (mi, mr) = (mean(&img), mean(&reference));
    println!("cbox-rgb radiosity: {} elements, relMSE {e:.3e}, mean {mi:.4?} vs reference {mr:.4?}", solved.mesh.elements.len());
    assert!(e < 1.2e-2, "relMSE {e}");
    for k in 0..3 {
        assert!((mi[k] / mr[k] - 1.0).abs() < 0.015, "channel {k}: mean {} vs {}", mi[k], mr[k]);
    }
}
