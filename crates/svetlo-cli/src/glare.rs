//! `svetlo glare SCENE --eye x,y,z --dir x,y,z`: the CIE Unified Glare Rating for one
//! observer, with each luminaire's luminance, solid angle and position index.

use crate::parse_define;
use anyhow::Result;
use clap::Args;
use glam::Vec3;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::integrator::RenderSettings;
use svetlo::photometry::glare::{ugr, Glare};

#[derive(Args, Debug)]
pub struct GlareArgs {
    /// Scene file (Mitsuba XML).
    pub scene: PathBuf,
    /// The observer's eye: x,y,z.
    #[arg(long, value_parser = parse_vec3)]
    pub eye: Vec3,
    /// The view direction: x,y,z (usually horizontal).
    #[arg(long, value_parser = parse_vec3)]
    pub dir: Vec3,
    /// The observer's vertical.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,1")]
    pub up: Vec3,
    /// Gathering rays for the background luminance.
    #[arg(long, default_value_t = 4096, value_parser = clap::value_parser!(u32).range(16..))]
    pub spp: u32,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

/// `x,y,z` as three finite numbers.
pub fn parse_vec3(s: &str) -> std::result::Result<Vec3, String> {
    let xs: Vec<f32> = s.split(',').map(|x| x.trim().parse::<f32>().map_err(|_| format!("'{s}' is not x,y,z"))).collect::<std::result::Result<_, _>>()?;
    if xs.len() != 3 || xs.iter().any(|x| !x.is_finite()) {
        return Err(format!("'{s}' is not three numbers x,y,z"));
    }
    Ok(Vec3::new(xs[0], xs[1], xs[2]))
}

/// Check an observer's vectors (a usage error otherwise).
pub fn check_view(dir: Vec3, up: Vec3) -> Result<()> {
    if dir.length_squared() == 0.0 || dir.cross(up).length_squared() < 1e-12 {
        anyhow::bail!(crate::Usage("--dir must be non-zero and not along --up".into()));
    }
    Ok(())
}

pub fn describe(g: &Glare) -> String {
    let mut s = match g.ugr {
        Some(u) => format!("UGR {u:.1} (background luminance {:.2} ± {:.2} cd/m²)\n", g.background, g.background_se),
        None => format!("UGR undefined: no luminaire with a luminous area in view (background {:.2} cd/m²)\n", g.background),
    };
    for src in &g.sources {
        s += &format!(
            "  light {}: L {:.0} cd/m², ω {:.2e} sr, p {:.2}, L²ω/p² {:.3e}\n",
            src.light, src.luminance, src.solid_angle, src.position_index, src.term
        );
    }
    if g.skipped > 0 {
        s += &format!("  {} luminaire(s) not rated: behind or below the line of sight, hidden, or without a luminous area\n", g.skipped);
    }
    s
}

pub fn run(a: &GlareArgs) -> Result<ExitCode> {
    check_view(a.dir, a.up)?;
    let scene = crate::load_scene(&a.scene, None, &a.define)?;
    let settings = RenderSettings { seed: a.seed, ..RenderSettings::from_scene(&scene) };
    let g = ugr(&scene, a.eye, a.dir, a.up, a.spp, &settings);
    print!("{}", describe(&g));
    Ok(ExitCode::SUCCESS)
}
