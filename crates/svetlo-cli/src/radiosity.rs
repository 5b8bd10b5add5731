//! `svetlo radiosity SCENE.xml --report`: solve a scene by radiosity and say how it went
//! (mesh, form factors, memory, residual against steps and time); optionally write the solved
//! mesh as a PLY with per-vertex colours, and, for a progressive solve, intermediate images
//! with the ambient term.

use crate::{parse_define, Usage};
use anyhow::{Context, Result};
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::film::{Film, Filter};
use svetlo::integrator::{render_pixels, Progress, RenderSettings};
use svetlo::radiosity::display::RadiosityView;
use svetlo::radiosity::{RadiosityOptions, Shading};
use svetlo::Rgb;

#[derive(Args, Debug)]
pub struct RadiosityArgs {
    /// Scene file (Mitsuba XML).
    pub scene: PathBuf,
    /// Print the convergence history (residual against steps, time and form-factor rows).
    #[arg(long)]
    pub report: bool,
    /// Form factors: analytic, hemicube or raycast.
    #[arg(long, value_name = "METHOD")]
    pub form_factors: Option<String>,
    /// Solver: jacobi, gauss-seidel, southwell, progressive, ssg, two-level or hierarchical.
    #[arg(long, value_name = "NAME")]
    pub solver: Option<String>,
    /// Longest element edge, in scene units.
    #[arg(long, value_name = "LENGTH")]
    pub element_size: Option<f32>,
    /// Relative residual to reach.
    #[arg(long, value_name = "T")]
    pub tolerance: Option<f64>,
    /// Over-relaxation factor, or `adaptive` (progressive).
    #[arg(long, value_name = "W")]
    pub omega: Option<String>,
    /// Hierarchical solver: oracle threshold ε.
    #[arg(long, value_name = "EPS")]
    pub epsilon: Option<f64>,
    /// Hierarchical solver: smallest element area (scene units²).
    #[arg(long, value_name = "AREA")]
    pub min_area: Option<f32>,
    /// Hierarchical solver: refinement oracle, f or bf.
    #[arg(long, value_name = "RULE")]
    pub refine: Option<String>,
    /// Hierarchical solver: weight the BF oracle by importance from the camera (Smits' BFV).
    #[arg(long)]
    pub importance: bool,
    /// More options as key=value (see the library's RadiosityOptions::parse), repeatable.
    #[arg(short = 'O', value_name = "KEY=VALUE")]
    pub option: Vec<String>,
    /// Write the solved mesh (PLY, per-vertex colours = tone-mapped radiance B/π, and the radiosity as floats).
    #[arg(long, value_name = "OUT.ply")]
    pub ply: Option<PathBuf>,
    /// Progressive solver: write an image (PNG, with the ambient term) at each reported step into this folder.
    #[arg(long, value_name = "DIR")]
    pub snapshots: Option<PathBuf>,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

fn options(a: &RadiosityArgs) -> Result<RadiosityOptions> {
    let mut kv: Vec<String> = vec![];
    if let Some(v) = &a.form_factors {
        kv.push(format!("form-factors={v}"));
    }
    if let Some(v) = &a.solver {
        kv.push(format!("solver={v}"));
    }
    if let Some(v) = a.element_size {
        kv.push(format!("element-size={v}"));
    }
    if let Some(v) = a.tolerance {
        kv.push(format!("tolerance={v}"));
    }
    if let Some(v) = &a.omega {
        kv.push(format!("omega={v}"));
    }
    if let Some(v) = a.epsilon {
        kv.push(format!("epsilon={v}"));
    }
    if let Some(v) = a.min_area {
        kv.push(format!("min-area={v}"));
    }
    if let Some(v) = &a.refine {
        kv.push(format!("refine={v}"));
    }
    if a.importance {
        kv.push("importance=true".into());
    }
    kv.extend(a.option.iter().cloned());
    RadiosityOptions::parse(&kv.join(",")).map_err(|e| Usage(e.to_string()).into())
}

fn write_ply(path: &PathBuf, solved: &svetlo::radiosity::Solved) -> Result<()> {
    let mesh = &solved.mesh;
    let vb = solved.vertex_radiosity();
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?);
    writeln!(out, "ply\nformat ascii 1.0\ncomment svetlo radiosity: colours are sRGB of B/pi clamped to 1; b_r, b_g, b_b are B in W/m^2")?;
    writeln!(out, "element vertex {}\nproperty float x\nproperty float y\nproperty float z", mesh.vertices.len())?;
    writeln!(out, "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float b_r\nproperty float b_g\nproperty float b_b")?;
    writeln!(out, "element face {}\nproperty list uchar int vertex_indices\nend_header", mesh.elements.len())?;
    let byte = |x: f32| (Rgb::linear_to_srgb((x / std::f32::consts::PI).min(1.0)) * 255.0).round() as u8;
    for (p, c) in mesh.vertices.iter().zip(&vb) {
        writeln!(out, "{} {} {} {} {} {} {} {} {}", p.x, p.y, p.z, byte(c.r), byte(c.g), byte(c.b), c.r, c.g, c.b)?;
    }
    for e in &mesh.elements {
        // Wind each face so that its normal is the side that radiates.
        let [a, b2, c] = e.vertex;
        let n = (e.p[1] - e.p[0]).cross(e.p[2] - e.p[0]);
        if n.dot(e.normal) >= 0.0 {
            writeln!(out, "3 {a} {b2} {c}")?;
        } else {
            writeln!(out, "3 {a} {c} {b2}")?;
        }
    }
    out.flush()?;
    Ok(())
}

pub fn run(a: &RadiosityArgs) -> Result<ExitCode> {
    let opts = options(a)?;
    let scene = crate::load_scene(&a.scene, &a.define)?;
    if let Some(dir) = &a.snapshots {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let settings = RenderSettings { spp: 1, filter: Filter::Box, ..RenderSettings::from_scene(&scene) };
    let mut snapshot_error: Option<anyhow::Error> = None;
    let mut observe = |mesh: &svetlo::radiosity::mesh::RadiosityMesh, shots: usize, st: &svetlo::radiosity::solver::progressive::State| {
        let Some(dir) = &a.snapshots else { return };
        let reflectance: Vec<Rgb> = mesh.elements.iter().map(|e| e.reflectance).collect();
        let b = st.display(&reflectance);
        let view = RadiosityView::new(mesh, &b, Shading::Gouraud);
        let r = render_pixels(&scene, &settings, &Progress::new(), &view)
            .map_err(anyhow::Error::from)
            .and_then(|f: Film| svetlo::io::image_io::write_png(&dir.join(format!("shot_{shots:07}.png")), &f.image()).map_err(anyhow::Error::from));
        if let Err(e) = r {
            snapshot_error.get_or_insert(e);
        }
    };
    let solved = svetlo::radiosity::solve_observed(&scene, &opts, scene.settings.max_depth, &mut observe)?;
    if let Some(e) = snapshot_error {
        return Err(e.context("cannot write a snapshot"));
    }
    for w in &solved.mesh.warnings {
        tell!("warning: {w}");
    }
    say!("scene        {}", a.scene.display());
    say!(
        "{}     {} in {} patches, {} display vertices, area {:.4}",
        if solved.hierarchy.is_some() { "display " } else { "elements" },
        solved.mesh.elements.len(),
        solved.mesh.patches.len(),
        solved.mesh.vertices.len(),
        solved.mesh.total_area()
    );
    if solved.hierarchy.is_none() {
        say!(
            "form factors {:?}: {} rows computed, {} stored ({:.1} MiB)",
            opts.form_factors,
            solved.rows_computed,
            solved.nnz,
            solved.matrix_bytes as f64 / (1 << 20) as f64
        );
    }
    if let Some(h) = &solved.hierarchy {
        say!(
            "hierarchy    {} links, {} nodes, {} leaves (elements), {} link form factors computed, {} refine passes, {:.1} MiB",
            h.links,
            h.nodes,
            h.leaves,
            h.form_factors,
            h.passes,
            h.memory as f64 / (1 << 20) as f64
        );
    }
    say!("solver       {:?}, tolerance {:.1e}: {}", solved.solver, opts.solve.tolerance, if solved.converged { "converged" } else { "NOT converged" });
    say!("time         mesh {:.3} s, form factors {:.3} s, solve {:.3} s", solved.mesh_seconds, solved.form_factor_seconds, solved.solve_seconds);
    if a.report {
        say!("{:>10} {:>12} {:>10} {:>12}", "step", "residual", "seconds", "rows");
        for s in &solved.history {
            say!("{:>10} {:>12.4e} {:>10.4} {:>12}", s.step, s.residual, s.seconds, s.rows);
        }
    }
    if let Some(p) = &a.ply {
        write_ply(p, &solved)?;
        say!("wrote        {}", p.display());
    }
    Ok(ExitCode::SUCCESS)
}
