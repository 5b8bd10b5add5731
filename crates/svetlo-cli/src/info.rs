//! `svetlo info SCENE.xml`: what the loader made of a scene, and what it warned about.

use crate::parse_define;
use anyhow::{Context, Result};
use clap::Args;
use glam::Vec3;
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use svetlo::bsdf::Material;
use svetlo::camera::Projection;
use svetlo::geometry::Geometry;
use svetlo::light::Light;
use svetlo::scene::Scene;

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// Scene file (Mitsuba XML), or a luminaire file (.ies, .ldt) for its photometric summary.
    pub scene: PathBuf,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

/// Shapes listed one by one up to this many; beyond, only the totals.
const MAX_LISTED_SHAPES: usize = 40;

pub fn material_kind(m: &Material) -> String {
    let rough = |r: &Option<_>, smooth: &str, rough: &str| if r.is_some() { rough.to_string() } else { smooth.to_string() };
    match m {
        Material::Diffuse { .. } => "diffuse".into(),
        Material::Conductor { roughness, .. } => rough(roughness, "conductor", "roughconductor"),
        Material::Dielectric { roughness, .. } => rough(roughness, "dielectric", "roughdielectric"),
        Material::ThinDielectric { .. } => "thindielectric".into(),
        Material::Plastic { roughness, .. } => rough(roughness, "plastic", "roughplastic"),
        Material::Phong { .. } => "phong".into(),
        Material::BlinnPhong { .. } => "blinnphong".into(),
        Material::CookTorrance { .. } => "cooktorrance".into(),
        Material::OrenNayar { .. } => "roughdiffuse".into(),
        Material::Ward { .. } => "ward".into(),
        Material::TwoSided { front, .. } => format!("twosided({})", material_kind(front)),
        Material::Mask { inner, .. } => format!("mask({})", material_kind(inner)),
        Material::Null => "null".into(),
    }
}

pub fn light_kind(l: &Light) -> &'static str {
    match l {
        Light::Area(_) => "area",
        Light::Point { .. } => "point",
        Light::Spot { .. } => "spot",
        Light::Directional { .. } => "directional",
        Light::Constant { .. } => "constant",
        Light::EnvMap(_) => "envmap",
        Light::Luminaire(_) => "luminaire",
    }
}

fn counts<I: IntoIterator<Item = String>>(items: I) -> String {
    let mut m: BTreeMap<String, usize> = BTreeMap::new();
    for k in items {
        *m.entry(k).or_default() += 1;
    }
    m.iter().map(|(k, n)| format!("{n} {k}")).collect::<Vec<_>>().join(", ")
}

fn v3(v: Vec3) -> String {
    format!("({:.4}, {:.4}, {:.4})", v.x, v.y, v.z)
}

/// The description `svetlo info` prints.
pub fn describe(scene: &Scene) -> String {
    let mut o = String::new();
    let (mut tris, mut meshes, mut spheres) = (0usize, 0usize, 0usize);
    for s in &scene.shapes {
        match &*s.geometry {
            Geometry::Mesh(m) => {
                meshes += 1;
                tris += m.triangle_count();
            }
            Geometry::Sphere(_) => spheres += 1,
        }
    }
    let _ = writeln!(o, "shapes      {} ({meshes} meshes with {tris} triangles, {spheres} spheres)", scene.shapes.len());
    for (i, s) in scene.shapes.iter().enumerate().take(MAX_LISTED_SHAPES) {
        let geo = match &*s.geometry {
            Geometry::Mesh(m) => format!("mesh, {} triangles", m.triangle_count()),
            Geometry::Sphere(sp) => format!("sphere, center {}, radius {}", v3(sp.center), sp.radius),
        };
        let mat = scene.materials.get(s.material as usize).map(material_kind).unwrap_or_else(|| "?".into());
        let emits = if s.light.is_some() { ", emitter" } else { "" };
        let _ = writeln!(o, "  {i:>4} {:<20} {geo}, {mat}{emits}", s.name);
    }
    if scene.shapes.len() > MAX_LISTED_SHAPES {
        let _ = writeln!(o, "  ... {} more", scene.shapes.len() - MAX_LISTED_SHAPES);
    }
    let _ = writeln!(o, "materials   {}: {}", scene.materials.len(), counts(scene.materials.iter().map(material_kind)));
    let _ = writeln!(o, "lights      {}: {}", scene.lights.len(), counts(scene.lights.iter().map(|l| light_kind(l).to_string())));
    let c = &scene.camera;
    let kind = match c.projection {
        Projection::Perspective { fov_x_deg, aperture_radius, focus_distance } if aperture_radius > 0.0 => {
            format!("thin lens, fov {fov_x_deg:.3} deg (x), aperture radius {aperture_radius}, focus distance {focus_distance}")
        }
        Projection::Perspective { fov_x_deg, .. } => format!("perspective, fov {fov_x_deg:.3} deg (x)"),
        Projection::Orthographic => "orthographic".into(),
    };
    let _ = writeln!(o, "camera      {kind}, {}x{}", c.width, c.height);
    let _ = writeln!(
        o,
        "            position {}, looking {}, clip [{}, {}]",
        v3(c.to_world.transform_point3(Vec3::ZERO)),
        v3(c.to_world.transform_vector3(Vec3::Z).normalize_or_zero()),
        c.near_clip,
        c.far_clip
    );
    let s = &scene.settings;
    let _ = writeln!(
        o,
        "settings    integrator {}, spp {}, max_depth {}, rr_depth {}, sampler {:?}, seed {}, filter {:?}{}",
        s.integrator,
        s.spp,
        s.max_depth,
        s.rr_depth,
        s.sampler,
        s.seed,
        s.filter,
        if s.hide_emitters { ", emitters hidden" } else { "" }
    );
    let _ = writeln!(o, "bounds      center {}, radius {}", v3(scene.bounds.center), scene.bounds.radius);
    if scene.warnings.is_empty() {
        let _ = writeln!(o, "warnings    none");
    } else {
        let _ = writeln!(o, "warnings    {}", scene.warnings.len());
        for w in &scene.warnings {
            let _ = writeln!(o, "  {w}");
        }
    }
    o
}

pub fn run(a: &InfoArgs) -> Result<ExitCode> {
    // Luminaire files (IES LM-63, EULUMDAT) get their photometric summary.
    let ext = a.scene.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    if matches!(ext.as_deref(), Some("ies" | "ldt")) {
        let p = svetlo::photometry::load(&a.scene).context("cannot read the luminaire file")?;
        print!("{}", p.summary());
        return Ok(ExitCode::SUCCESS);
    }
    let scene = svetlo::io::load_scene(&a.scene, &a.define).context("cannot load the scene")?;
    print!("{}", describe(&scene));
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn describes_a_scene() {
        let scene = crate::render::tests::tiny_scene();
        let d = describe(&scene);
        assert!(d.contains("shapes      1 (0 meshes with 0 triangles, 1 spheres)"), "{d}");
        assert!(d.contains("materials   1: 1 diffuse"), "{d}");
        assert!(d.contains("lights      1: 1 point"), "{d}");
        assert!(d.contains("perspective, fov 40.000 deg (x), 32x24"), "{d}");
        assert!(d.contains("integrator path, spp 3"), "{d}");
        assert!(d.contains("warnings    none"), "{d}");
    }
}
