//! `svetlo convert`: a scene from one format to the other (pbrt-v4 <-> Mitsuba XML), with
//! its meshes (PLY) and images (EXR) written beside the output.

use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::io::SceneFormat;

#[derive(Args, Debug)]
pub struct ConvertArgs {
    /// Scene file (Mitsuba XML, or pbrt-v4 `.pbrt` / `.pbrt.gz`).
    pub scene: PathBuf,
    /// Output scene file: `.xml` for Mitsuba 3, `.pbrt` for pbrt-v4 (meshes and images go to
    /// `<stem>_files/` beside it).
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
    /// Input format (default: from the extension).
    #[arg(long, value_enum)]
    pub format: Option<crate::FormatArg>,
    /// Output format (default: from the output's extension).
    #[arg(long, value_enum)]
    pub to: Option<crate::FormatArg>,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = crate::parse_define)]
    pub define: Vec<(String, String)>,
}

pub fn run(a: &ConvertArgs) -> Result<ExitCode> {
    let to = crate::FormatArg::format(a.to).unwrap_or_else(|| SceneFormat::from_path(&a.output));
    if a.output.is_dir() {
        return Err(crate::Usage(format!("-o {} is a folder; give a scene file name", a.output.display())).into());
    }
    let scene = crate::load_scene(&a.scene, a.format, &a.define)?;
    for w in &scene.warnings {
        tell!("warning: {w}");
    }
    let notes = svetlo::io::export::export_scene(&scene, &a.output, to).with_context(|| format!("cannot write {}", a.output.display()))?;
    for n in &notes {
        tell!("warning: {n}");
    }
    say!(
        "wrote {} ({} shapes, {} lights, {} materials{})",
        a.output.display(),
        scene.shapes.len(),
        scene.lights.len(),
        scene.materials.len(),
        if notes.is_empty() { String::new() } else { format!("; {} approximations, listed above", notes.len()) }
    );
    Ok(ExitCode::SUCCESS)
}
