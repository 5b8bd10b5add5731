//! Radiosity methods on the Cornell box meshed ever finer: time and memory to a 1 % residual
//! for Gauss-Seidel on the full matrix, progressive refinement (rows on demand) and the
//! hierarchical solver; form factors or links; the form-factor rows progressive needs before
//! its image (with the ambient term) is within 5 % of the converged one; relMSE against the
//! Tungsten reference.
//!
//! cargo run --release --example radiosity_bench -- [--scene DIR] [--sizes 0.5,0.25,0.125,0.0625] [--max-matrix N] [--epsilon E]
//!
//! Prints a Markdown table row per element size as it goes. Sizes whose full matrix would have
//! more than `--max-matrix` elements (default 20000: ~1.5 GB of form factors, minutes on two
//! cores) skip the matrix methods.

use std::time::Instant;
use svetlo::film::Filter;
use svetlo::integrator::{render_pixels, Progress, RenderSettings};
use svetlo::radiosity::display::RadiosityView;
use svetlo::radiosity::form_factor::{Method, RowSource};
use svetlo::radiosity::mesh::{MeshOptions, RadiosityMesh};
use svetlo::radiosity::solver::{self, SolveOptions, SolverKind};
use svetlo::radiosity::{RadiosityOptions, Shading};
use svetlo::scene::Scene;
use svetlo::Rgb;

fn relmse(scene: &Scene, view: &RadiosityView, reference: &svetlo::film::Image) -> f64 {
    let settings = RenderSettings { spp: 4, filter: Filter::Box, ..RenderSettings::from_scene(scene) };
    let film = render_pixels(scene, &settings, &Progress::new(), view).expect("render");
    svetlo::film::compare::rel_mse(&film.image(), reference).expect("relmse")
}

/// Power-weighted relative L1 difference.
fn display_error(b: &[Rgb], exact: &[Rgb], area: &[f32]) -> f64 {
    let (mut d, mut t) = (0.0f64, 0.0f64);
    for ((x, y), a) in b.iter().zip(exact).zip(area) {
        d += *a as f64 * ((x.r - y.r).abs() + (x.g - y.g).abs() + (x.b - y.b).abs()) as f64;
        t += *a as f64 * (y.r + y.g + y.b) as f64;
    }
    d / t
}

fn mib(b: usize) -> f64 {
    b as f64 / (1u64 << 20) as f64
}

fn main() {
    let mut dir = std::path::PathBuf::from("../shared/scenes/bitterli/cornell-box");
    let mut sizes = vec![0.5f32, 0.25, 0.125, 0.0625];
    let mut max_matrix = 20_000usize;
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
    let defaults = [("resx", "256"), ("resy", "256")].map(|(a, b)| (a.to_string(), b.to_string()));
    let scene = svetlo::io::load_scene(&dir.join("mitsuba3/scene_v3.xml"), &defaults).expect("scene");
    let reference = svetlo::io::read_image(&dir.join("TungstenRender_box4x4_256x256.pfm")).expect("reference");
    let method = Method::default();
    // Fraction of the n² pairs with a non-zero form factor, from the last matrix built (to
    // project the matrix's size where it is not built).
    let mut density = f64::NAN;
    println!(
        "| element size | elements | GS: form factors | GS: s to 1 % | GS: MiB | GS relMSE | progressive: rows for 5 % image (of n) | progressive: rows / s to 1 % | progressive: MiB (est.) | HR: leaves | HR: links | links / leaf | HR: s to 1 % | HR: MiB | HR relMSE | GS / HR form factors |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for h in sizes {
        let mesh_opts = MeshOptions { max_edge: Some(h), max_elements: usize::MAX, ..Default::default() };
        let mesh = RadiosityMesh::build(&scene, &mesh_opts).expect("mesh");
        let n = mesh.elements.len();
        let mut row = format!("| {h} | {n} |");
        let mut gs_nnz = None;
        if n <= max_matrix {
            // Gauss-Seidel on the whole matrix.
            let t = Instant::now();
            let source = RowSource::new(&scene, &mesh, method).expect("source");
            let m = source.matrix();
            let sys = svetlo::radiosity::system(&mesh, solver::Rows::Matrix(&m));
            let sol = SolverKind::GaussSeidel.solve(&sys, &SolveOptions { tolerance: 1e-2, ..Default::default() }).expect("gs");
            let gs_secs = t.elapsed().as_secs_f64();
            let e = relmse(&scene, &RadiosityView::new(&mesh, &sol.b, Shading::Gouraud), &reference);
            // The converged solution the progressive display is measured against.
            let exact = SolverKind::GaussSeidel.solve(&sys, &SolveOptions { tolerance: 1e-5, ..Default::default() }).expect("exact").b;
            gs_nnz = Some(m.nnz());
            density = m.nnz() as f64 / (n as f64 * n as f64);
            row += &format!(" {} | {gs_secs:.1} | {:.1} | {e:.2e} |", m.nnz(), mib(m.memory()));
            // Progressive refinement with rows computed as elements shoot.
            let lazy = RowSource::new(&scene, &mesh, method).expect("source");
            let psys = svetlo::radiosity::system(&mesh, solver::Rows::OnDemand(&lazy));
            let mut first_good: Option<u64> = None;
            let mut rows_now = 0u64;
            let t = Instant::now();
            let psol = solver::progressive::solve(&psys, &SolveOptions { tolerance: 1e-2, ..Default::default() }, &mut |_, st| {
                rows_now = lazy.rows_computed.load(std::sync::atomic::Ordering::Relaxed);
                if first_good.is_none() && display_error(&st.display(&psys.reflectance), &exact, &psys.area) < 0.05 {
                    first_good = Some(rows_now);
                }
            })
            .expect("progressive");
            let p_secs = t.elapsed().as_secs_f64();
            let rows = psol.history.last().map(|s| s.rows).unwrap_or(0);
            let per_row = m.nnz() as f64 / n as f64;
            row += &format!(
                " {} ({:.0} %) | {rows} / {p_secs:.1} | {:.1} |",
                first_good.map(|r| r.to_string()).unwrap_or("-".into()),
                first_good.map(|r| 100.0 * r as f64 / n as f64).unwrap_or(f64::NAN),
                mib((rows as f64 * per_row * 8.0) as usize)
            );
            drop(sys);
        } else {
            row += " (not run) | | | | | | |";
        }
        // Hierarchical, finest leaves the size of the matrix's elements (h² / 2).
        let opts = RadiosityOptions::parse(&format!("solver=hierarchical,element-size={h},min-area={},tolerance=1e-2,epsilon={epsilon}", h * h / 2.0))
            .expect("options");
        let t = Instant::now();
        let s = svetlo::radiosity::solve(&scene, &opts, -1).expect("hierarchical");
        let secs = t.elapsed().as_secs_f64();
        let hs = s.hierarchy.as_ref().expect("stats");
        let e = relmse(&scene, &s.view(Shading::Gouraud), &reference);
        row += &format!(
            " {} | {} | {:.1} | {secs:.1} | {:.1} | {e:.2e} | {} |",
            hs.leaves,
            hs.links,
            hs.links as f64 / hs.leaves as f64,
            mib(hs.memory),
            gs_nnz.map(|g| format!("{:.1}", g as f64 / hs.links as f64)).unwrap_or_else(|| format!(
                "~{:.0} (projected: {:.2} n² form factors)",
                (n as f64 * n as f64 * density) / hs.links as f64,
                density
            ))
        );
        println!("{row}");
    }
}
