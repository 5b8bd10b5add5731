//! `svetlo info SCENE.xml`: what the loader made of a scene, and what it warned about.

use crate::parse_define;
use anyhow::Result;
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
    /// Scene file (Mitsuba XML, or pbrt-v4 `.pbrt` / `.pbrt.gz`), or a luminaire file (.ies,
    /// .ldt) for its photometric summary.
    pub scene: PathBuf,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
    /// Scene format (default: from the extension, `.pbrt` and `.pbrt.gz` are pbrt-v4).
    #[arg(long, value_enum)]
    pub format: Option<crate::FormatArg>,
    /// Also compile a light path expression: its automaton's size and the event symbols it
    /// uses against those the scene can produce.
    #[arg(long, value_name = "EXPR")]
    pub lpe: Option<String>,
}

/// Shapes listed one by one up to this many; beyond, only the totals.
const MAX_LISTED_SHAPES: usize = 40;

pub fn material_kind(m: &Material) -> String {
    m.kind_name()
}

pub fn light_kind(l: &Light) -> &'static str {
    l.kind_name()
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
    let (mut tris, mut meshes, mut spheres, mut grids) = (0usize, 0usize, 0usize, 0usize);
    for s in &scene.shapes {
        match &*s.geometry {
            Geometry::Mesh(m) => {
                meshes += 1;
                tris += m.triangle_count();
            }
            Geometry::Sphere(_) => spheres += 1,
            Geometry::SdfGrid(_) => grids += 1,
        }
    }
    let grids = if grids > 0 { format!(", {grids} SDF grids") } else { String::new() };
    let _ = writeln!(o, "shapes      {} ({meshes} meshes with {tris} triangles, {spheres} spheres{grids})", scene.shapes.len());
    for (i, s) in scene.shapes.iter().enumerate().take(MAX_LISTED_SHAPES) {
        let geo = match &*s.geometry {
            Geometry::Mesh(m) => format!("mesh, {} triangles", m.triangle_count()),
            Geometry::Sphere(sp) => format!("sphere, center {}, radius {}", v3(sp.center), sp.radius),
            Geometry::SdfGrid(g) => format!("sdfgrid, {}x{}x{} samples, {} occupied voxels", g.res[0], g.res[1], g.res[2], g.voxel_count()),
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
    // A closed stdout (`svetlo info s.xml | head -1`) is not an error.
    use std::io::Write as _;
    // Luminaire files (IES LM-63, EULUMDAT) get their photometric summary.
    let ext = a.scene.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    if matches!(ext.as_deref(), Some("ies" | "ldt")) {
        let p = svetlo::photometry::load(&a.scene).map_err(|e| anyhow::Error::new(crate::SceneError(e)).context("cannot read the luminaire file"))?;
        let _ = write!(std::io::stdout(), "{}", p.summary());
        return Ok(ExitCode::SUCCESS);
    }
    // Mitsuba scenes: every unsupported plugin first, whether or not the scene then loads.
    if matches!(ext.as_deref(), Some("xml")) && !matches!(a.format, Some(crate::FormatArg::Pbrt)) {
        if let Ok(list) = svetlo::io::mitsuba::unsupported_plugins(&a.scene, &a.define) {
            let _ = write!(std::io::stdout(), "{}", describe_unsupported(&list));
        }
    }
    let scene = crate::load_scene(&a.scene, a.format, &a.define)?;
    let _ = write!(std::io::stdout(), "{}", describe(&scene));
    if svetlo::methods::by_name(&scene.settings.integrator).is_err() {
        let _ =
            writeln!(std::io::stdout(), "note        integrator '{}' is not one of svetlo's methods: give --integrator to render", scene.settings.integrator);
    }
    if let Some(e) = &a.lpe {
        let _ = write!(std::io::stdout(), "{}", describe_lpe(&scene, e).map_err(|e| crate::Usage(format!("light path expression: {e}")))?);
    }
    Ok(ExitCode::SUCCESS)
}

/// The `unsupported` section of `svetlo info`: one line per plugin, file:line first.
pub fn describe_unsupported(list: &[svetlo::io::mitsuba::Unsupported]) -> String {
    let mut o = String::new();
    if list.is_empty() {
        let _ = writeln!(o, "unsupported none");
    } else {
        let _ = writeln!(o, "unsupported {}", list.len());
        for u in list {
            let _ = writeln!(o, "  {u}");
        }
    }
    o
}

/// The event symbols a scene can produce: C, L or B by its lights, and per material the
/// scattering events its lobes make (as path vertices label them).
pub fn scene_symbols(scene: &Scene) -> Vec<&'static str> {
    use svetlo::bsdf::LobeFlags;
    use svetlo::lpe::Event;
    let mut out = vec!["C"];
    if scene.lights.iter().any(|l| !matches!(l, Light::Constant { .. } | Light::EnvMap(_))) {
        out.push("L");
    }
    if !scene.environment_lights.is_empty() {
        out.push("B");
    }
    for m in &scene.materials {
        let f = m.bsdf(glam::Vec2::ZERO).flags();
        for t in [false, true] {
            let side = if t { LobeFlags::TRANSMISSION } else { LobeFlags::REFLECTION };
            if !f.intersects(side) {
                continue;
            }
            let mut evs = Vec::new();
            if f.intersects(LobeFlags::SPECULAR) {
                evs.push(Event::scatter(f, true, t, 0));
            }
            if f.has_non_specular() {
                evs.push(Event::scatter(f, false, t, 0));
            }
            for e in evs {
                if !out.contains(&e.symbol()) {
                    out.push(e.symbol());
                }
            }
        }
    }
    out
}

fn describe_lpe(scene: &Scene, expr: &str) -> std::result::Result<String, svetlo::lpe::LpeError> {
    let mut set = svetlo::lpe::AovSet::compile(&[("lpe".into(), expr.into())], None)?;
    let warnings = set.bind(scene);
    let l = &set.expressions()[0];
    let (states, rev, classes) = l.size();
    let have = scene_symbols(scene);
    let used = l.useful_symbols();
    let mut s = String::new();
    let order = if l.light_first { "light first, reversed" } else { "camera first" };
    let _ = writeln!(s, "lpe         '{expr}' ({order})");
    let _ = writeln!(s, "automaton   {states} states (minimised), reverse {rev} states, {classes} event classes");
    let _ = writeln!(s, "expression  uses {}", used.join(" "));
    let _ = writeln!(s, "scene       produces {}", have.join(" "));
    let missing: Vec<&str> = used.iter().copied().filter(|u| !have.contains(u)).collect();
    if !missing.is_empty() {
        let _ = writeln!(s, "note        the scene produces no {} events", missing.join(" "));
    }
    for w in warnings {
        let _ = writeln!(s, "warning     {w}");
    }
    Ok(s)
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
