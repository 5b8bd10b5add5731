//! Radiosity on Mitsuba's measured Cornell box (`cbox-rgb`) against its 4096-spp Mitsuba 3
//! reference: relMSE of the radiosity image (flat and Gouraud) against the element count, for
//! Gauss-Seidel on the full matrix and for the hierarchical solver. Both solve with the scene's
//! own max_depth (6: five diffuse bounces), as the reference's path tracer does.
//!
//! cargo run --release --example radiosity_cbox -- [--scene DIR] [--sizes 140,100,70,50,35] [--max-matrix N] [--epsilon E]
//!
//! Element sizes are in scene units (the box is 556 wide). Prints a Markdown table row per size.

use std::time::Instant;
use svetlo::film::Filter;
use svetlo::integrator::{render_pixels, Progress, RenderSettings};
use svetlo::radiosity::{RadiosityOptions, Shading, Solved};
use svetlo::scene::Scene;

fn relmse(scene: &Scene, s: &Solved, shading: Shading, reference: &svetlo::film::Image) -> f64 {
    let settings = RenderSettings { spp: 4, filter: Filter::Box, ..RenderSettings::from_scene(scene) };
    let film = render_pixels(scene, &settings, &Progress::new(), &s.view(shading)).expect("render");
    svetlo::film::compare::rel_mse(&film.image(), reference).expect("relmse")
}

fn main() {
    let mut dir = std::path::PathBuf::from("../shared/scenes/mitsuba-data/scenes/cbox");
    let mut sizes = vec![140.0f32, 100.0, 70.0, 50.0, 35.0];
    let mut max_matrix = 10_000usize;
    let mut epsilon = 0.005f64;
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().unwrap_or_else(|| panic!("{k} needs a value"));
        match k.as_str() {
            "--scene" => dir = val().into(),
            "--sizes" => sizes = val().split(',').map(|s| s.parse().expect("--sizes a,b,c")).collect(),
            "--max-matrix" => max_matrix = val().parse().expect("--max-matrix N"),
            "--epsilon" => epsilon = val().parse().expect("--epsilon E"),
            o => panic!("unknown argument {o}"),
        }
    }
    let scene = svetlo::io::load_scene(&dir.join("cbox-rgb.xml"), &[]).expect("scene");
    let reference = svetlo::io::read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    let depth = scene.settings.max_depth;
    println!("| element size | GS elements | GS s | GS relMSE Gouraud | GS relMSE flat | HR leaves | HR links | HR s | HR relMSE Gouraud | HR relMSE flat |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for h in sizes {
        let mut row = format!("| {h} |");
        let gs = RadiosityOptions::parse(&format!("solver=gauss-seidel,element-size={h},tolerance=1e-2")).expect("options");
        let n = svetlo::radiosity::mesh::RadiosityMesh::build(&scene, &gs.mesh).expect("mesh").elements.len();
        if n <= max_matrix {
            let t = Instant::now();
            let s = svetlo::radiosity::solve(&scene, &gs, depth).expect("gs");
            let secs = t.elapsed().as_secs_f64();
            let (g, f) = (relmse(&scene, &s, Shading::Gouraud, &reference), relmse(&scene, &s, Shading::Flat, &reference));
            row += &format!(" {n} | {secs:.1} | {g:.2e} | {f:.2e} |");
        } else {
            row += &format!(" {n} | (not run) | | |");
        }
        let hr = RadiosityOptions::parse(&format!("solver=hierarchical,element-size={h},tolerance=1e-2,epsilon={epsilon}")).expect("options");
        let t = Instant::now();
        let s = svetlo::radiosity::solve(&scene, &hr, depth).expect("hierarchical");
        let secs = t.elapsed().as_secs_f64();
        let hs = s.hierarchy.clone().expect("stats");
        let (g, f) = (relmse(&scene, &s, Shading::Gouraud, &reference), relmse(&scene, &s, Shading::Flat, &reference));
        row += &format!(" {} | {} | {secs:.1} | {g:.2e} | {f:.2e} |", hs.leaves, hs.links);
        println!("{row}");
    }
}
