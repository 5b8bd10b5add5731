//! Time and error of radiosity option sets on one scene: for each set, the solver that ran,
//! elements (leaves for hierarchical), seconds to solve, and the relMSE of the radiosity image
//! (the set's own shading, 4 spp, box filter) against a reference image. Used to choose the
//! defaults (README, "Radiosity").
//!
//! cargo run --release --example radiosity_options -- --scene FILE.xml --reference REF.exr [-D name=value] 'opts1' 'opts2' ...
//!
//! An empty option string is the defaults.

use std::time::Instant;
use svetlo::film::Filter;
use svetlo::integrator::{render_pixels, Progress, RenderSettings};
use svetlo::radiosity::RadiosityOptions;

fn main() {
    let (mut scene_path, mut reference, mut defines, mut sets) = (None, None, vec![], vec![]);
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        match k.as_str() {
            "--scene" => scene_path = it.next(),
            "--reference" => reference = it.next(),
            "-D" => {
                let d = it.next().expect("-D name=value");
                let (a, b) = d.split_once('=').expect("-D name=value");
                defines.push((a.to_string(), b.to_string()));
            }
            _ => sets.push(k),
        }
    }
    let scene = svetlo::io::load_scene(std::path::Path::new(&scene_path.expect("--scene")), &defines).expect("scene");
    let reference = svetlo::io::read_image(std::path::Path::new(&reference.expect("--reference"))).expect("reference");
    println!("| options | solver | elements | s | relMSE |");
    println!("|---|---|---|---|---|");
    for set in sets {
        let opts = RadiosityOptions::parse(&set).expect("options");
        let t = Instant::now();
        let s = svetlo::radiosity::solve(&scene, &opts, scene.settings.max_depth).expect("solve");
        let secs = t.elapsed().as_secs_f64();
        let n = s.hierarchy.as_ref().map(|h| h.leaves).unwrap_or(s.mesh.elements.len());
        let settings = RenderSettings { spp: 4, filter: Filter::Box, ..RenderSettings::from_scene(&scene) };
        let film = render_pixels(&scene, &settings, &Progress::new(), &s.view(opts.shading)).expect("render");
        let e = svetlo::film::compare::rel_mse(&film.image(), &reference).expect("relmse");
        println!("| `{set}` | {:?} | {n} | {secs:.1} | {e:.2e} |", s.solver);
    }
}
