//! `svetlo`: render a scene, compare two images, describe a scene.
//!
//! Exit codes: 0 success (or a passing comparison), 1 failure (render error, failing Z-test),
//! 2 bad command line or bad input, 130 render interrupted by Ctrl-C (images still written).

mod compare;
mod illuminance;
mod info;
mod radiosity;
mod render;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(name = "svetlo", version, about = "A physically based renderer: one scene, every light transport method.")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene to OUT.exr and OUT.png (and OUT_var.exr with --variance).
    Render(render::RenderArgs),
    /// Compare an image with a reference: relMSE, and the Z-test given the reference's variance.
    Compare(compare::CompareArgs),
    /// Describe a scene: shapes, materials, lights, camera, settings and loader warnings.
    Info(info::InfoArgs),
    /// Solve a scene by radiosity: convergence report, solved mesh (PLY), progressive snapshots.
    Radiosity(radiosity::RadiosityArgs),
    /// Illuminance (lux) on a work plane: grid CSV and JSON with Emin, Eavg, Emax, U0.
    Illuminance(illuminance::IlluminanceArgs),
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

pub const EXIT_FAIL: u8 = 1;
pub const EXIT_USAGE: u8 = 2;
pub const EXIT_INTERRUPTED: u8 = 130;

/// `-D name=value`: a scene parameter for `<default>` / `$name` substitution.
pub fn parse_define(s: &str) -> Result<(String, String), String> {
    let (name, value) = s.split_once('=').ok_or_else(|| format!("expected NAME=VALUE, got '{s}'"))?;
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(format!("'{name}' is not a parameter name (letters, digits and '_')"));
    }
    Ok((name.to_string(), value.to_string()))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(&a),
        Command::Compare(a) => compare::run(&a),
        Command::Info(a) => info::run(&a),
        Command::Radiosity(a) => radiosity::run(&a),
        Command::Illuminance(a) => illuminance::run(&a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<Usage>().is_some() {
                ExitCode::from(EXIT_USAGE)
            } else {
                ExitCode::from(EXIT_FAIL)
            }
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
