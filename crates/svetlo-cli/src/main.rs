//! `svetlo`: render a scene, compare two images, describe or convert a scene.
//!
//! Exit codes (README, "Exit codes and limits"): 0 success (or a passing comparison),
//! 1 runtime failure (render or write error, failing Z-test), 2 bad command line or options
//! (including `--integrator name:key=value` options and compare's input images), 3 the scene
//! cannot be loaded, 130 interrupted by SIGINT or SIGTERM (images still written).

/// `println!` that tolerates a closed stdout (`svetlo info scene.xml | head -1`).
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

/// `eprintln!` that tolerates a closed stderr.
macro_rules! tell {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

mod compare;
mod convert;
mod dask;
mod glare;
mod illuminance;
mod info;
mod preview;
mod radiosity;
mod render;
mod report;
mod signals;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(name = "svetlo", version, about = "A physically based renderer: one scene, every light transport method.")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// Memory budget (e.g. 8G, 512M): films, textures and meshes whose headers announce more
    /// are refused before anything is allocated. Default: half the machine's memory.
    #[arg(long, global = true, value_name = "SIZE", value_parser = parse_memory)]
    pub max_memory: Option<u64>,
}

fn parse_memory(s: &str) -> Result<u64, String> {
    svetlo::limits::parse_size(s).ok_or_else(|| format!("'{s}' is not a size (a number of bytes, or with K, M, G or T)"))
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene to OUT.exr and OUT.png (and OUT_var.exr with --variance).
    Render(render::RenderArgs),
    /// Compare an image with a reference: relMSE, and the Z-test given the reference's variance.
    Compare(compare::CompareArgs),
    /// Convert a scene between pbrt-v4 and Mitsuba XML (meshes as PLY, images as EXR).
    Convert(convert::ConvertArgs),
    /// Describe a scene: shapes, materials, lights, camera, settings and loader warnings.
    Info(info::InfoArgs),
    /// Solve a scene by radiosity: convergence report, solved mesh (PLY), progressive snapshots.
    Radiosity(radiosity::RadiosityArgs),
    /// Illuminance (lux) or daylight factor on a work plane: CSV, JSON and a false-colour plan.
    Illuminance(illuminance::IlluminanceArgs),
    /// Discomfort glare (CIE UGR) for an observer position and view direction.
    Glare(glare::GlareArgs),
    /// A lighting report: one self-contained HTML page with plans, tables, UGR and luminaires.
    Report(report::ReportArgs),
    /// Render with a live browser view: compare methods, restart from the page (Ctrl-C ends).
    Serve(preview::ServeArgs),
}

/// A mistake in what the user asked for (exit code 2), as opposed to a failure while doing it.
#[derive(Debug)]
pub struct Usage(pub String);

impl std::fmt::Display for Usage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

/// `--format`: the scene file's format when its extension does not say it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    Mitsuba,
    Pbrt,
}

impl FormatArg {
    pub fn format(f: Option<FormatArg>) -> Option<svetlo::io::SceneFormat> {
        f.map(|f| match f {
            FormatArg::Mitsuba => svetlo::io::SceneFormat::Mitsuba,
            FormatArg::Pbrt => svetlo::io::SceneFormat::Pbrt,
        })
    }
}

/// A scene that cannot be loaded (exit code 3).
#[derive(Debug)]
pub struct SceneError(pub svetlo::Error);

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl std::error::Error for SceneError {}

pub const EXIT_FAIL: u8 = 1;
pub const EXIT_USAGE: u8 = 2;
pub const EXIT_SCENE: u8 = 3;
pub const EXIT_INTERRUPTED: u8 = 130;

/// Load a scene for a subcommand; its errors exit with [`EXIT_SCENE`].
/// The one loading path of the CLI: the format from `--format`, else from the extension.
pub fn load_scene(path: &std::path::Path, format: Option<FormatArg>, define: &[(String, String)]) -> anyhow::Result<svetlo::scene::Scene> {
    svetlo::io::load_scene_as(path, FormatArg::format(format), define).map_err(|e| anyhow::Error::new(SceneError(e)).context("cannot load the scene"))
}

/// The exit code of an error: what kind of mistake it is, wherever in the chain it sits.
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if e.chain().any(|c| c.is::<SceneError>()) {
        EXIT_SCENE
    } else if e.chain().any(|c| c.is::<Usage>() || matches!(c.downcast_ref::<svetlo::Error>(), Some(svetlo::Error::Settings(_)))) {
        EXIT_USAGE
    } else {
        EXIT_FAIL
    }
}

/// `-D name=value`: a scene parameter for `<default>` / `$name` substitution.
pub fn parse_define(s: &str) -> Result<(String, String), String> {
    let (name, value) = s.split_once('=').ok_or_else(|| format!("expected NAME=VALUE, got '{s}'"))?;
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!("'{name}' is not a parameter name (letters, digits and '_')"));
    }
    Ok((name.to_string(), value.to_string()))
}

/// Keep freed memory in the process for reuse (glibc): a render allocates and frees films
/// and tiles pass after pass, and by default glibc hands blocks of 128 kB and more back to
/// the kernel at once, so every pass faults in fresh zeroed pages again (in a virtual machine
/// each fault costs microseconds: 0.1 s of 1 s on a 256² render with eight AOVs). Blocks up
/// to 32 MB (glibc's largest setting) now come from the heap, and the heap is not trimmed.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; called before any other thread
    // exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    if let Some(m) = cli.max_memory {
        svetlo::limits::set_max_memory(m);
    }
    let result = match cli.command {
        Command::Render(a) => render::run(&a),
        Command::Compare(a) => compare::run(&a),
        Command::Convert(a) => convert::run(&a),
        Command::Info(a) => info::run(&a),
        Command::Radiosity(a) => radiosity::run(&a),
        Command::Illuminance(a) => illuminance::run(&a),
        Command::Glare(a) => glare::run(&a),
        Command::Report(a) => report::run(&a),
        Command::Serve(a) => preview::serve(&a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            tell!("error: {e:#}");
            ExitCode::from(exit_code(&e))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defines_parse() {
        assert_eq!(parse_define("spp=4"), Ok(("spp".into(), "4".into())));
        assert_eq!(parse_define("a_1=x=y"), Ok(("a_1".into(), "x=y".into())));
        assert_eq!(parse_define("empty="), Ok(("empty".into(), String::new())));
        assert!(parse_define("spp").is_err());
        assert!(parse_define("=4").is_err());
        assert!(parse_define("a b=4").is_err());
    }

    #[test]
    fn cli_definition_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }
}
