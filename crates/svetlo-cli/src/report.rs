//! `svetlo report SCENE --plane ... [--observer 'eye=.. dir=..'] -o report.html`: one
//! self-contained HTML page (images embedded as data URIs, no external resources) with a
//! false-colour plan and the Emin/Eavg/Emax/U0 table of each work plane, the UGR of each
//! observer, and the luminaires with their flux and power: what a designer hands a client.

use crate::glare::{check_view, parse_vec3};
use crate::parse_define;
use anyhow::{Context, Result};
use clap::Args;
use glam::Vec3;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::integrator::RenderSettings;
use svetlo::light::Light;
use svetlo::photometry::false_colour::{grid_picture, Scale};
use svetlo::photometry::illuminance::WorkPlane;

#[derive(Args, Debug)]
pub struct ReportArgs {
    /// Scene file (Mitsuba XML).
    pub scene: PathBuf,
    /// A work plane 'origin=x,y,z u=x,y,z v=x,y,z' (repeatable).
    #[arg(long, required = true)]
    pub plane: Vec<String>,
    /// Grid spacing in scene units.
    #[arg(long, default_value_t = 0.25)]
    pub spacing: f32,
    /// Illuminance estimator: path, light or radiosity.
    #[arg(long, default_value = "path")]
    pub integrator: String,
    /// Samples per point (path) or photons per grid point (light).
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Radiosity options (with --integrator radiosity).
    #[arg(long, default_value = "")]
    pub radiosity: String,
    /// An observer for UGR: 'eye=x,y,z dir=x,y,z' (repeatable; up is +Z).
    #[arg(long)]
    pub observer: Vec<String>,
    /// Output page.
    #[arg(short, long, default_value = "report.html")]
    pub output: PathBuf,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

fn parse_observer(s: &str) -> Result<(Vec3, Vec3)> {
    let (mut eye, mut dir) = (None, None);
    for part in s.split_whitespace() {
        let (k, v) = part.split_once('=').ok_or_else(|| crate::Usage(format!("--observer: expected key=x,y,z, got '{part}'")))?;
        let p = parse_vec3(v).map_err(|e| crate::Usage(format!("--observer: {e}")))?;
        match k {
            "eye" => eye = Some(p),
            "dir" => dir = Some(p),
            _ => anyhow::bail!(crate::Usage(format!("--observer: unknown key '{k}' (eye, dir)"))),
        }
    }
    match (eye, dir) {
        (Some(e), Some(d)) => {
            check_view(d, Vec3::Z)?;
            Ok((e, d))
        }
        _ => anyhow::bail!(crate::Usage(format!("--observer '{s}': needs eye= and dir="))),
    }
}

/// Standard base64 (RFC 4648) for the embedded images.
pub fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = ((c[0] as u32) << 16) | ((*c.get(1).unwrap_or(&0) as u32) << 8) | (*c.get(2).unwrap_or(&0) as u32);
        for k in 0..4 {
            if k <= c.len() {
                s.push(T[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

pub fn run(a: &ReportArgs) -> Result<ExitCode> {
    let planes: Vec<WorkPlane> = a
        .plane
        .iter()
        .map(|p| WorkPlane::parse(p, a.spacing).map_err(|e| anyhow::Error::new(crate::Usage(format!("--plane '{p}': {e}")))))
        .collect::<Result<_>>()?;
    let observers: Vec<(Vec3, Vec3)> = a.observer.iter().map(|o| parse_observer(o)).collect::<Result<_>>()?;
    let scene = crate::load_scene(&a.scene, None, &a.define)?;
    let settings = RenderSettings { seed: a.seed, ..RenderSettings::from_scene(&scene) };
    let mut html = String::from(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>svetlo lighting report</title>\n<style>body{font-family:sans-serif;margin:2em;max-width:60em}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #999;padding:0.25em 0.6em;text-align:right}th{background:#eee}img{image-rendering:pixelated;border:1px solid #999}</style></head><body>\n",
    );
    html += &format!("<h1>Lighting report: {}</h1>\n", escape(&a.scene.display().to_string()));
    html += &format!(
        "<p>Illuminance by {} ({}), grid spacing {} m. Photometric units from radiometric RGB by 683 lm/W and the Rec.709 luminance weights.</p>\n",
        escape(&a.integrator),
        if a.integrator == "radiosity" { "± discretisation bound".to_string() } else { format!("{} samples per point, ± standard error", a.spp) },
        a.spacing
    );
    html += "<h2>Work planes</h2>\n<table><tr><th>plane</th><th>points</th><th>E<sub>min</sub> (lx)</th><th>E<sub>avg</sub> (lx)</th><th>E<sub>max</sub> (lx)</th><th>U<sub>0</sub> = E<sub>min</sub>/E<sub>avg</sub></th><th>E<sub>min</sub>/E<sub>max</sub></th><th>largest relative error</th></tr>\n";
    let mut pictures = String::new();
    for (k, plane) in planes.iter().enumerate() {
        let g = crate::illuminance::compute(&scene, plane, &a.integrator, a.spp, &a.radiosity, &settings)?;
        let (nu, nv) = plane.dims();
        let worst = g.std_err.iter().zip(&g.lux).map(|(s, e)| if *e > 0.0 { s / e } else { 0.0 }).fold(0.0, f64::max);
        html += &format!(
            "<tr><td>{}</td><td>{nu} × {nv}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.3}</td><td>{:.3}</td><td>{:.2} %</td></tr>\n",
            k + 1,
            g.min(),
            g.mean(),
            g.max(),
            g.uniformity(),
            g.min() / g.max().max(1e-300),
            100.0 * worst
        );
        let px = (480 / nu.max(nv)).clamp(2, 64);
        let img = grid_picture(&g.lux, nu, nv, px, &Scale::auto(&g.lux, false), "lx");
        let png = svetlo::io::image_io::encode_png(&img).context("cannot encode the plan")?;
        pictures += &format!(
            "<h3>Plane {}: {}</h3>\n<p>Plan view (u to the right, v up), iso-lux lines at the legend's steps.</p>\n<img alt=\"plane {}\" src=\"data:image/png;base64,{}\">\n",
            k + 1,
            escape(&a.plane[k]),
            k + 1,
            base64(&png)
        );
    }
    html += "</table>\n";
    html += &pictures;
    if !observers.is_empty() {
        html += "<h2>Glare (CIE 117 UGR)</h2>\n<table><tr><th>observer</th><th>eye</th><th>view</th><th>UGR</th><th>background L<sub>b</sub> (cd/m²)</th><th>luminaires rated</th></tr>\n";
        for (k, (eye, dir)) in observers.iter().enumerate() {
            let gl = svetlo::photometry::glare::ugr(&scene, *eye, *dir, Vec3::Z, 4096, &settings);
            let u = gl.ugr.map_or("–".to_string(), |u| format!("{u:.1}"));
            html += &format!(
                "<tr><td>{}</td><td>{:.2}, {:.2}, {:.2}</td><td>{:.2}, {:.2}, {:.2}</td><td>{u}</td><td>{:.2} ± {:.2}</td><td>{}</td></tr>\n",
                k + 1,
                eye.x,
                eye.y,
                eye.z,
                dir.x,
                dir.y,
                dir.z,
                gl.background,
                gl.background_se,
                gl.sources.len()
            );
        }
        html += "</table>\n";
    }
    html += "<h2>Luminaires</h2>\n<table><tr><th>#</th><th>file</th><th>position (m)</th><th>flux (lm)</th><th>power (W)</th><th>efficacy (lm/W)</th></tr>\n";
    let (mut total_lm, mut total_w) = (0.0, 0.0);
    let mut n = 0;
    for l in &scene.lights {
        let Light::Luminaire(lum) = l else { continue };
        n += 1;
        let lm = lum.flux_lm();
        total_lm += lm;
        let (w, eff) = match lum.input_watts {
            Some(w) if w > 0.0 => {
                total_w += w;
                (format!("{w:.1}"), format!("{:.0}", lm / w))
            }
            _ => ("–".into(), "–".into()),
        };
        let p = lum.position;
        html += &format!(
            "<tr><td>{n}</td><td style=\"text-align:left\">{}</td><td>{:.2}, {:.2}, {:.2}</td><td>{lm:.0}</td><td>{w}</td><td>{eff}</td></tr>\n",
            escape(&lum.name),
            p.x,
            p.y,
            p.z
        );
    }
    html += &format!(
        "<tr><th colspan=\"3\">total ({n})</th><th>{total_lm:.0}</th><th>{}</th><th></th></tr>\n</table>\n",
        if total_w > 0.0 { format!("{total_w:.1}") } else { "–".into() }
    );
    html += "</body></html>\n";
    std::fs::write(&a.output, html).with_context(|| format!("cannot write {}", a.output.display()))?;
    println!("wrote {}", a.output.display());
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (i, o) in [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("fooba", "Zm9vYmE="), ("foobar", "Zm9vYmFy")] {
            assert_eq!(super::base64(i.as_bytes()), o);
        }
    }
}
