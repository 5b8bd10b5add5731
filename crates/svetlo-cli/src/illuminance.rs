//! `svetlo illuminance SCENE --plane 'origin=.. u=.. v=..' --spacing S`: lux on a work plane
//! by gathering (`path`), light tracing (`light`) or radiosity (`radiosity`), written as OUT.csv and OUT.json with
//! Emin, Eavg, Emax, U0 = Emin/Eavg and Emin/Emax.

use crate::parse_define;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::integrator::RenderSettings;
use svetlo::photometry::false_colour::{grid_picture, Scale};
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
    /// Estimator: path (gathering), light (light tracing) or radiosity.
    #[arg(long, default_value = "path")]
    pub integrator: String,
    /// Instead of a fixed --spp: sample until every point's relative standard error is at most
    /// this (e.g. 0.01): a pilot run at --spp, then one run at the count it predicts (error ∝ 1/√spp).
    #[arg(long, value_name = "REL")]
    pub error: Option<f64>,
    /// Radiosity options (`svetlo radiosity`'s key=value list, e.g. 'element-size=0.1').
    #[arg(long, default_value = "")]
    pub radiosity: String,
    /// Samples per point (path) or photons per grid point (light).
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Report the daylight factor (%): E over the unobstructed horizontal illuminance of the
    /// scene's sky (its infinite lights, e.g. <emitter type="cie_sky">) on a plane facing +Z.
    #[arg(long)]
    pub daylight_factor: bool,
    /// False-colour scale of PREFIX.png, 'lo:hi' in lx (default: 0 to Emax).
    #[arg(long, value_name = "LO:HI")]
    pub scale: Option<String>,
    /// Logarithmic false-colour scale.
    #[arg(long)]
    pub log: bool,
    /// Pixels per grid cell in PREFIX.png.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub pixels: u32,
    /// Output prefix: writes PREFIX.csv, PREFIX.json and PREFIX.png (plan view in false
    /// colour, u to the right and v up, iso-lux lines at the legend's steps).
    #[arg(short, long, default_value = "grid")]
    pub output: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

/// The largest standard error (or bound) relative to its point's value (points at 0 lx skipped).
pub fn worst_relative_error(g: &IlluminanceGrid) -> f64 {
    g.std_err.iter().zip(&g.lux).map(|(s, e)| if *e > 0.0 { s / e } else { 0.0 }).fold(0.0, f64::max)
}

pub fn summary(g: &IlluminanceGrid) -> String {
    let u = g.unit;
    let worst = worst_relative_error(g);
    format!(
        "{}: Emin {:.2} {u}, Eavg {:.2} {u}, Emax {:.2} {u}, U0 {:.3}, Emin/Emax {:.3}; largest relative {} {:.2} %",
        g.method,
        g.min(),
        g.mean(),
        g.max(),
        g.uniformity(),
        g.min() / g.max().max(1e-300),
        if g.method == "radiosity" { "discretisation bound" } else { "standard error" },
        100.0 * worst
    )
}

/// The grid by the estimator named `integrator` (path, light, radiosity); `spp` samples per
/// point (path) or photons per grid point (light); `radiosity` the radiosity options.
pub fn compute(
    scene: &svetlo::scene::Scene,
    plane: &WorkPlane,
    integrator: &str,
    spp: u32,
    radiosity: &str,
    settings: &RenderSettings,
) -> Result<IlluminanceGrid> {
    Ok(match integrator {
        "path" => gather(scene, plane, spp.max(2), settings),
        "light" => {
            let (nu, nv) = plane.dims();
            light_trace(scene, plane, spp as u64 * (nu * nv) as u64, settings)
        }
        "radiosity" => {
            let opts = svetlo::radiosity::RadiosityOptions::parse(radiosity).map_err(|e| crate::Usage(format!("--radiosity: {e}")))?;
            svetlo::photometry::illuminance::radiosity(scene, plane, &opts, settings).context("radiosity")?
        }
        other => bail!(crate::Usage(format!("--integrator: '{other}' is not an illuminance estimator (path, light, radiosity)"))),
    })
}

pub fn run(a: &IlluminanceArgs) -> Result<ExitCode> {
    let plane = WorkPlane::parse(&a.plane, a.spacing).map_err(|e| crate::Usage(format!("--plane: {e}")))?;
    let scale = a.scale.as_deref().map(|s| Scale::parse(s, a.log)).transpose().map_err(|e| crate::Usage(format!("--scale: {e}")))?;
    let scene = crate::load_scene(&a.scene, None, &a.define)?;
    let settings = RenderSettings { seed: a.seed, ..RenderSettings::from_scene(&scene) };
    let mut grid = compute(&scene, &plane, &a.integrator, a.spp, &a.radiosity, &settings)?;
    if let Some(target) = a.error {
        if !(target > 0.0 && target < 1.0) {
            bail!(crate::Usage(format!("--error must be within (0, 1), got {target}")));
        }
        if a.integrator == "radiosity" {
            bail!(crate::Usage("--error: radiosity reports a discretisation bound, not a standard error; refine with --radiosity element-size=".into()));
        }
        let worst = worst_relative_error(&grid);
        if worst > target {
            let need = (a.spp as f64 * (worst / target).powi(2) * 1.2).ceil().min(u32::MAX as f64) as u32;
            println!("pilot at {} samples: largest relative error {:.2} %; running {need}", a.spp, 100.0 * worst);
            grid = compute(&scene, &plane, &a.integrator, need, &a.radiosity, &RenderSettings { seed: settings.seed ^ 0x9e37_79b9, ..settings.clone() })?;
        }
    }
    let grid = if a.daylight_factor {
        let e_out = svetlo::photometry::sky::unobstructed_illuminance(&scene, glam::Vec3::Z);
        if e_out <= 0.0 {
            bail!(crate::Usage("--daylight-factor: the scene has no sky (no environment, constant or directional light lights a horizontal plane)".into()));
        }
        println!("unobstructed horizontal illuminance outdoors: {e_out:.1} lx");
        grid.daylight_factor(e_out)
    } else {
        grid
    };
    let csv = a.output.with_extension("csv");
    let json = a.output.with_extension("json");
    std::fs::write(&csv, grid.to_csv()).with_context(|| format!("cannot write {}", csv.display()))?;
    std::fs::write(&json, grid.to_json()).with_context(|| format!("cannot write {}", json.display()))?;
    let png = a.output.with_extension("png");
    let (nu, nv) = plane.dims();
    let sc = scale.unwrap_or_else(|| Scale::auto(&grid.lux, a.log));
    svetlo::io::write_png(&png, &grid_picture(&grid.lux, nu, nv, a.pixels as usize, &sc, if grid.unit == "%" { "%" } else { "lx" }))?;
    println!("{}", summary(&grid));
    println!("wrote {}, {} and {}", csv.display(), json.display(), png.display());
    Ok(ExitCode::SUCCESS)
}
