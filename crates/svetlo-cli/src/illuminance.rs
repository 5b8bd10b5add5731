//! `svetlo illuminance SCENE --plane 'origin=.. u=.. v=..' --spacing S`: lux on a work plane
//! by gathering (`path`) or light tracing (`light`), written as OUT.csv and OUT.json with
//! Emin, Eavg, Emax, U0 = Emin/Eavg and Emin/Emax.

use crate::parse_define;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::integrator::RenderSettings;
use svetlo::photometry::illuminance::{gather, light_trace, IlluminanceGrid, WorkPlane};

#[derive(Args, Debug)]
pub struct IlluminanceArgs {
    /// Scene file (Mitsuba XML).
    pub scene: PathBuf,
    /// The work plane: 'origin=x,y,z u=x,y,z v=x,y,z' (E on the side of u × v).
    #[arg(long)]
    pub plane: String,
    /// Grid spacing in scene units.
    #[arg(long, default_value_t = 0.25)]
    pub spacing: f32,
    /// Estimator: path (gathering) or light (light tracing).
    #[arg(long, default_value = "path")]
    pub integrator: String,
    /// Samples per point (path) or photons per grid point (light).
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Output prefix: writes PREFIX.csv and PREFIX.json.
    #[arg(short, long, default_value = "grid")]
    pub output: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

pub fn summary(g: &IlluminanceGrid) -> String {
    let worst = g.std_err.iter().zip(&g.lux).map(|(s, e)| if *e > 0.0 { s / e } else { 0.0 }).fold(0.0, f64::max);
    format!(
        "{}: Emin {:.1} lx, Eavg {:.1} lx, Emax {:.1} lx, U0 {:.3}, Emin/Emax {:.3}; largest relative standard error {:.2} %",
        g.method,
        g.min(),
        g.mean(),
        g.max(),
        g.uniformity(),
        g.min() / g.max().max(1e-300),
        100.0 * worst
    )
}

pub fn run(a: &IlluminanceArgs) -> Result<ExitCode> {
    let plane = WorkPlane::parse(&a.plane, a.spacing).map_err(|e| crate::Usage(format!("--plane: {e}")))?;
    let scene = svetlo::io::load_scene(&a.scene, &a.define).context("cannot load the scene")?;
    let settings = RenderSettings { seed: a.seed, ..RenderSettings::from_scene(&scene) };
    let grid = match a.integrator.as_str() {
        "path" => gather(&scene, &plane, a.spp.max(2), &settings),
        "light" => {
            let (nu, nv) = plane.dims();
            light_trace(&scene, &plane, a.spp as u64 * (nu * nv) as u64, &settings)
        }
        other => bail!(crate::Usage(format!("--integrator: '{other}' is not an illuminance estimator (path, light)"))),
    };
    let csv = a.output.with_extension("csv");
    let json = a.output.with_extension("json");
    std::fs::write(&csv, grid.to_csv()).with_context(|| format!("cannot write {}", csv.display()))?;
    std::fs::write(&json, grid.to_json()).with_context(|| format!("cannot write {}", json.display()))?;
    println!("{}", summary(&grid));
    println!("wrote {} and {}", csv.display(), json.display());
    Ok(ExitCode::SUCCESS)
}
