//! Helpers of the light-path-expression tests (tests/lpe*.rs): the project's scenes, AOV sets,
//! renders with them, and image sums and comparisons.

use std::path::Path;
use std::sync::Arc;
use svetlo::film::{Film, Filter, Image};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::lpe::AovSet;
use svetlo::scene::Scene;

/// `scenes/NAME` of the repository at `res`² pixels (its `res` parameter).
pub fn repo_scene(name: &str, res: u32) -> Scene {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name);
    svetlo::io::load_scene(&p, &[("res".into(), res.to_string())]).expect("scene")
}

/// The AOVs `(name, expression)`, bound to `scene` (every label names something).
pub fn aovs(scene: &Scene, list: &[(&str, &str)], beauty: Option<&str>) -> Arc<AovSet> {
    let l: Vec<(String, String)> = list.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    let mut set = AovSet::compile(&l, beauty).expect("expressions");
    assert!(set.bind(scene).is_empty());
    Arc::new(set)
}

/// A render by `method` on two threads with a box filter.
pub fn render(scene: &Scene, method: &str, spp: u32, max_depth: i32, seed: u64, set: Option<Arc<AovSet>>) -> Film {
    let s = RenderSettings { spp, max_depth, seed, threads: 2, filter: Filter::Box, lpe: set, ..Default::default() };
    svetlo::methods::by_name(method).expect("method").render(scene, &s, &Progress::new()).expect("render")
}

/// Per pixel channel, equal up to float rounding (relative 1e-4 of the larger, or 1e-6).
pub fn assert_close(a: &Image, b: &Image, what: &str) {
    let mut worst = 0.0f32;
    for (x, y) in a.data.iter().zip(&b.data) {
        for (u, v) in [(x.r, y.r), (x.g, y.g), (x.b, y.b)] {
            let tol = 1e-4 * u.abs().max(v.abs()) + 1e-6;
            worst = worst.max((u - v).abs() / tol);
        }
    }
    assert!(worst <= 1.0, "{what}: differs by {worst} tolerances");
}

/// The images' sum, per pixel.
pub fn sum(imgs: &[Image]) -> Image {
    let mut out = imgs[0].clone();
    for i in &imgs[1..] {
        for (a, b) in out.data.iter_mut().zip(&i.data) {
            *a += *b;
        }
    }
    out
}
