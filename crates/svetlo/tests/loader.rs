//! The Mitsuba loader: the shared test scenes, the project's own scene, conventions
//! (transforms, look-at, fov axes, spectra) and bad input, which must give typed errors.

mod common;

use common::scenes::shared;
use glam::{Mat4, Vec3};
use std::path::{Path, PathBuf};
use svetlo::camera::Projection;
use svetlo::geometry::Geometry;
use svetlo::io::load_scene;
use svetlo::scene::Scene;
use svetlo::Error;

trait ErrOnly {
    fn err_only(self) -> Error;
}

impl ErrOnly for svetlo::Result<Scene> {
    /// The error of a load that must fail (a `Scene` has no Debug for `unwrap_err`).
    fn err_only(self) -> Error {
        match self {
            Ok(_) => panic!("expected an error, but the scene loaded"),
            Err(e) => e,
        }
    }
}

/// A fresh scratch folder for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("svetlo-loader-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/>
  <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="16"/></film></sensor>"#;

/// A scene with the standard sensor and `body`.
fn scene_xml(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>\n")
}

fn load_str(dir: &Path, body: &str) -> svetlo::Result<Scene> {
    let p = write(dir, "scene.xml", &scene_xml(body));
    load_scene(&p, &[])
}

fn mesh(s: &Scene, i: usize) -> &svetlo::geometry::TriangleMesh {
    match &*s.shapes[i].geometry {
        Geometry::Mesh(m) => m,
        _ => panic!("shape {i} is not a mesh"),
    }
}

enum Expect {
    /// shapes, lights, film width, height
    Ok(usize, usize, u32, u32),
    Err(&'static str),
}

/// Every Mitsuba scene of the shared set either loads (with the expected counts) or fails
/// with a typed error that says why.
#[test]
fn shared_scenes_load_or_fail_clearly() {
    let Some(root) = shared() else { return };
    use Expect::*;
    let t = "mitsuba-data/tests/scenes/";
    let cases: Vec<(String, Expect)> = vec![
        ("bitterli/cornell-box/mitsuba3/scene_v3.xml".into(), Ok(8, 1, 1024, 1024)),
        ("bitterli/veach-mis/mitsuba3/scene.xml".into(), Ok(9, 3, 1280, 720)),
        ("mitsuba-data/scenes/cbox/cbox-rgb.xml".into(), Ok(8, 1, 256, 256)),
        ("mitsuba-data/scenes/cbox/cbox-spectral.xml".into(), Ok(8, 1, 256, 256)),
        ("mitsuba-data/scenes/cbox/cbox.xml".into(), Ok(8, 1, 256, 256)),
        (format!("{t}bsdf_spheres/test_arealight_path.xml"), Ok(13, 1, 48, 48)),
        (format!("{t}bsdf_spheres/test_bumpmap_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_constant_path.xml"), Ok(12, 1, 48, 48)),
        (format!("{t}bsdf_spheres/test_envmap_path.xml"), Ok(12, 1, 48, 48)),
        (format!("{t}bsdf_spheres/test_normalmap_identity_roughconductor_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_normalmap_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_normalmap_roughconductor_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_pointlight_path.xml"), Ok(12, 1, 48, 48)),
        (format!("{t}bsdf_spheres/test_roughdielectric_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_roughplastic_linear_path.xml"), Ok(5, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_roughplastic_nonlinear_path.xml"), Ok(5, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_textured_diffuse_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_textured_roughconductor_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_texturedprincipled1_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_texturedprincipled2_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}bsdf_spheres/test_texturedprincipledthin_path.xml"), Ok(2, 3, 48, 48)),
        (format!("{t}floating_sphere/test_directional_direct.xml"), Ok(2, 1, 48, 48)),
        (format!("{t}infinite_mirrors/scene_path.xml"), Ok(3, 1, 32, 32)),
        (format!("{t}instancing/test_instancing_path.xml"), Ok(9, 1, 64, 64)),
        (format!("{t}mesh_attributes/test_mesh_attributes_1_face_direct.xml"), Ok(1, 1, 48, 48)),
        (format!("{t}mesh_attributes/test_mesh_attributes_3_face_direct.xml"), Ok(1, 1, 48, 48)),
        (format!("{t}mesh_attributes/test_mesh_attributes_3_vertex_direct.xml"), Ok(1, 1, 48, 48)),
        (format!("{t}orthographic_sensor/test_orthographic_path.xml"), Ok(1, 1, 200, 120)),
        (format!("{t}participating_media/test_homo_area_light_volpath.xml"), Err("participating media")),
        (format!("{t}participating_media/test_surf_area_light_volpath.xml"), Ok(4, 2, 48, 48)),
        (format!("{t}projector/test_projector_constant_direct.xml"), Ok(1, 1, 48, 48)),
        (format!("{t}projector/test_projector_textured_direct.xml"), Ok(1, 1, 48, 48)),
        (format!("{t}spot_light/test_spot_direct.xml"), Ok(1, 2, 48, 48)),
        (format!("{t}texture_interp/test_texture_interp_direct.xml"), Ok(6, 1, 128, 128)),
        (format!("{t}various_emitters/test_various_emitters_ptracer.xml"), Ok(6, 8, 512, 64)),
        (format!("{t}various_shapes/test_various_shapes_path.xml"), Ok(10, 1, 480, 480)),
        ("viewfactors/ovf-test-xmls/par-plates/par-plate-001.xml".into(), Err("not a Mitsuba scene")),
    ];
    for (rel, expect) in &cases {
        let path = root.join(rel);
        // `svetlo info`'s list of unsupported plugins agrees: a plugin that stops loading is
        // listed for every scene that fails on one, and none for a scene that loads.
        if let std::result::Result::Ok(listed) = svetlo::io::mitsuba::unsupported_plugins(&path, &[]) {
            let fatal = listed.iter().filter(|u| u.consequence == svetlo::io::mitsuba::Consequence::Error).count();
            match expect {
                Ok(..) => assert_eq!(fatal, 0, "{rel}: loads, but listed {listed:?}"),
                Err(msg) if msg.contains("not supported") || msg.contains("participating") => assert!(fatal > 0, "{rel}: fails on '{msg}', nothing listed"),
                Err(_) => {}
            }
        }
        let got = load_scene(&path, &[]);
        match (expect, got) {
            (Ok(ns, nl, w, h), std::result::Result::Ok(s)) => {
                assert_eq!((s.shapes.len(), s.lights.len(), s.camera.width, s.camera.height), (*ns, *nl, *w, *h), "{rel}");
                assert!(!s.materials.is_empty(), "{rel}");
            }
            (Err(msg), std::result::Result::Err(e)) => {
                let text = e.to_string();
                assert!(text.contains(msg), "{rel}: error '{text}' does not say '{msg}'");
                assert!(text.contains(&*path.file_name().unwrap().to_string_lossy()), "{rel}: error '{text}' does not name the file");
            }
            (Ok(..), std::result::Result::Err(e)) => panic!("{rel}: expected to load, got {e}"),
            (Err(msg), std::result::Result::Ok(_)) => panic!("{rel}: expected an error saying '{msg}', but it loaded"),
        }
    }
    // Every participating-media scene fails on its media, never with a panic.
    for e in std::fs::read_dir(root.join(format!("{t}participating_media"))).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "xml") {
            let _ = load_scene(&p, &[]);
        }
    }
}

/// What the scenes say, read back: settings, the Bitterli camera, spectra, forward references.
#[test]
fn shared_scene_details() {
    let Some(root) = shared() else { return };
    // cbox-rgb references its area emitter before defining it.
    let s = load_scene(&root.join("mitsuba-data/scenes/cbox/cbox-rgb.xml"), &[]).unwrap();
    assert_eq!((s.settings.integrator.as_str(), s.settings.max_depth, s.settings.spp), ("path", 6, 256));
    assert_eq!(s.settings.filter, svetlo::film::Filter::Box);
    assert_eq!(s.lights.iter().filter(|l| matches!(l, svetlo::light::Light::Area(_))).count(), 1);
    // fov 39.3077 along the smaller axis of a square film is also the horizontal fov.
    match s.camera.projection {
        Projection::Perspective { fov_x_deg, aperture_radius, .. } => {
            assert!((fov_x_deg - 39.3077).abs() < 1e-3);
            assert_eq!(aperture_radius, 0.0);
        }
        _ => panic!(),
    }
    // -D overrides <default>.
    let d = [("spp".to_string(), "7".to_string()), ("res".to_string(), "20".to_string())];
    let s = load_scene(&root.join("mitsuba-data/scenes/cbox/cbox-rgb.xml"), &d).unwrap();
    assert_eq!((s.settings.spp, s.camera.width), (7, 20));
    // veach-mis: three analytic sphere lights and a tent filter.
    let s = load_scene(&root.join("bitterli/veach-mis/mitsuba3/scene.xml"), &[]).unwrap();
    let spheres: Vec<f32> = s.shapes.iter().filter_map(|sh| if let Geometry::Sphere(sp) = &*sh.geometry { Some(sp.radius) } else { None }).collect();
    assert_eq!(spheres, vec![1.0, 0.5, 0.05]);
    assert!(matches!(s.settings.filter, svetlo::film::Filter::Tent { radius } if radius == 1.0));
    // The spectral cbox light "400:0, 500:8, 600:15.6, 700:18.4" is an illuminant: warm, red > green > blue.
    let s = load_scene(&root.join("mitsuba-data/scenes/cbox/cbox-spectral.xml"), &[]).unwrap();
    let svetlo::light::Light::Area(a) = &s.lights[0] else { panic!() };
    let c = a.radiance.mean();
    assert!(c.r > c.g && c.g > c.b && c.b > 0.0, "{c:?}");
    // moment wrapper, twosided mask, textures and named IORs: the arealight test loads 13 materials.
    let s = load_scene(&root.join("mitsuba-data/tests/scenes/bsdf_spheres/test_arealight_path.xml"), &[]).unwrap();
    assert_eq!(s.settings.max_depth, 2);
    assert!(s.materials.iter().any(|m| matches!(m, svetlo::bsdf::Material::Dielectric { eta, .. } if (eta - 2.419 / 1.000277).abs() < 1e-4)));
    assert!(s.materials.iter().any(|m| matches!(m, svetlo::bsdf::Material::Mask { inner, .. } if matches!(**inner, svetlo::bsdf::Material::TwoSided { .. }))));
}

/// The project's own Cornell box: loads with no external file, walls face the room.
#[test]
fn bundled_cornell_box() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let s = load_scene(&p, &[]).unwrap();
    assert_eq!((s.shapes.len(), s.lights.len(), s.camera.width, s.camera.height, s.settings.spp), (8, 1, 512, 512, 64));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let center = Vec3::new(0.0, 1.0, 0.0);
    for (i, sh) in s.shapes.iter().enumerate() {
        let m = mesh(&s, i);
        let (ng, _, _, _) = m.surface(0, 0.3, 0.3);
        let [a, b, c] = m.vertices(0);
        let p = (a + b + c) / 3.0;
        if ["floor", "ceiling", "back", "left", "right", "light"].contains(&sh.name.as_str()) {
            assert!(ng.dot(center - p) > 0.0, "{} faces away from the room", sh.name);
        }
    }
    // The room is [-1,1] x [0,2] x [-1,1].
    let b = s.accel.bounds();
    assert!((b.min - Vec3::new(-1.0, 0.0, -1.0)).abs().max_element() < 1e-5 && (b.max - Vec3::new(1.0, 2.0, 1.0)).abs().max_element() < 1e-5, "{b:?}");
}

/// A scene held in memory loads as its file does; errors and relative paths use `origin`.
#[test]
fn scene_from_memory() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
    let text = std::fs::read_to_string(&p).unwrap();
    let (a, b) = (load_scene(&p, &[]).unwrap(), svetlo::io::load_scene_from_str(&text, &p, &[]).unwrap());
    assert_eq!((a.shapes.len(), a.lights.len(), a.camera.width), (b.shapes.len(), b.lights.len(), b.camera.width));
    assert_eq!(a.accel.bounds(), b.accel.bounds());
    let e = svetlo::io::load_scene_from_str("<scene version=\"3.0.0\">\n  <shape type=\"obj\"/>\n</scene>", Path::new("/nowhere/dict.xml"), &[])
        .err()
        .expect("an error")
        .to_string();
    assert!(e.contains("dict.xml:2"), "{e}");
}

/// Transforms compose in file order (each operation applies after the previous ones).
#[test]
fn transform_composition_and_matrix() {
    let d = scratch("xf");
    let s = load_str(
        &d,
        r#"<shape type="rectangle"><transform name="to_world">
             <scale x="2" y="3"/><rotate z="1" angle="90"/><translate x="10" y="0" z="5"/>
           </transform></shape>
           <shape type="rectangle"><transform name="to_world">
             <matrix value="0 -3 0 10  2 0 0 0  0 0 1 5  0 0 0 1"/>
           </transform></shape>
           <emitter type="constant"/>"#,
    )
    .unwrap();
    let expect = Mat4::from_translation(Vec3::new(10.0, 0.0, 5.0)) * Mat4::from_rotation_z(90f32.to_radians()) * Mat4::from_scale(Vec3::new(2.0, 3.0, 1.0));
    let local = svetlo::geometry::shapes::rectangle();
    for i in 0..2 {
        let m = mesh(&s, i);
        for (p, q) in m.positions.iter().zip(&local.positions) {
            assert!((*p - expect.transform_point3(*q)).length() < 1e-5, "shape {i}: {p} vs {}", expect.transform_point3(*q));
        }
        // Normals follow the inverse transpose: still +z here.
        assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-5));
    }
}

/// lookat: +z toward the target, +y toward up, +x = up x dir; and the horizontal fov from each fov_axis.
#[test]
fn lookat_and_fov_axes() {
    let m = svetlo::io::mitsuba::look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 2.0, 10.0), Vec3::Y).unwrap();
    assert!((m.transform_point3(Vec3::ZERO) - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
    assert!((m.transform_vector3(Vec3::Z) - Vec3::Z).length() < 1e-6);
    assert!((m.transform_vector3(Vec3::X) - Vec3::X).length() < 1e-6);
    assert!(svetlo::io::mitsuba::look_at(Vec3::ZERO, Vec3::Y, Vec3::Y).is_none());

    use svetlo::io::mitsuba::fov_x_from_axis as fx;
    let half = |deg: f32| (0.5 * deg.to_radians()).tan();
    // Aspect 2: y-fov of 40 means tan(fx/2) = 2 tan(20 deg).
    assert!((half(fx(40.0, "y", 2.0).unwrap()) - 2.0 * half(40.0)).abs() < 1e-5);
    assert_eq!(fx(40.0, "x", 2.0), Some(40.0));
    assert_eq!(fx(40.0, "larger", 2.0), fx(40.0, "x", 2.0));
    assert_eq!(fx(40.0, "smaller", 2.0), fx(40.0, "y", 2.0));
    assert_eq!(fx(40.0, "smaller", 0.5), fx(40.0, "x", 0.5));
    // Diagonal: tan(fd/2)^2 = tan(fx/2)^2 + tan(fy/2)^2 with tan(fy/2) = tan(fx/2) / aspect.
    let tx = half(fx(60.0, "diagonal", 1.5).unwrap());
    assert!((tx * tx * (1.0 + 1.0 / 2.25) - half(60.0).powi(2)).abs() < 1e-5);
    assert_eq!(fx(40.0, "sideways", 1.0), None);

    // Through a file: Mitsuba 0.6 names (fovAxis, toWorld, lookAt, sampleCount).
    let d = scratch("fov");
    let p = write(
        &d,
        "old.xml",
        r##"<scene version="0.6.0">
  <integrator type="path"><integer name="maxDepth" value="4"/></integrator>
  <sensor type="perspective"><float name="fov" value="40"/><string name="fovAxis" value="y"/>
    <transform name="toWorld"><lookAt origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
    <sampler type="ldsampler"><integer name="sampleCount" value="9"/></sampler>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/></film></sensor>
  <shape type="sphere"><float name="radius" value="0.5"/>
    <bsdf type="dielectric"><string name="intIOR" value="water"/></bsdf></shape>
  <shape type="rectangle"><bsdf type="diffuse"><srgb name="reflectance" value="#808080"/></bsdf>
    <emitter type="area"><spectrum name="radiance" value="3"/></emitter></shape>
</scene>"##,
    );
    let s = load_scene(&p, &[]).unwrap();
    assert_eq!((s.settings.spp, s.settings.max_depth, s.settings.sampler), (9, 4, svetlo::sampling::SamplerKind::Sobol));
    let Projection::Perspective { fov_x_deg, .. } = s.camera.projection else { panic!() };
    assert!((half(fov_x_deg) - 2.0 * half(40.0)).abs() < 1e-5);
    assert!((s.camera.to_world.transform_vector3(Vec3::Z) + Vec3::Z).length() < 1e-6);
    assert!(matches!(s.materials[0], svetlo::bsdf::Material::Dielectric { eta, .. } if (eta - 1.333 / 1.000277).abs() < 1e-5));
    let svetlo::bsdf::Material::Diffuse { reflectance } = &s.materials[1] else { panic!() };
    assert!((reflectance.mean().r - svetlo::Rgb::srgb_to_linear(128.0 / 255.0)).abs() < 1e-6);
}

/// The OBJ and PLY versions of the same mesh give the same positions and normals; their uvs
/// differ by Mitsuba's OBJ-only v flip, and agree exactly with `flip_tex_coords` off.
#[test]
fn obj_and_ply_round_trip() {
    let Some(root) = shared() else { return };
    let base = root.join("mitsuba-data/tests");
    let d = scratch("objply");
    let body = |flip: &str| {
        format!(
            r#"<shape type="obj"><string name="filename" value="{}"/>{flip}</shape>
               <shape type="ply"><string name="filename" value="{}"/></shape><emitter type="constant"/>"#,
            base.join("obj/rectangle_normals_uv.obj").display(),
            base.join("ply/rectangle_normals_uv.ply").display()
        )
    };
    for (flip, flipped) in [("", true), (r#"<boolean name="flip_tex_coords" value="false"/>"#, false)] {
        let s = load_str(&d, &body(flip)).unwrap();
        let (o, p) = (mesh(&s, 0), mesh(&s, 1));
        // Vertices may be in another order: match them by position.
        assert_eq!(o.positions.len(), p.positions.len());
        assert_eq!(o.triangle_count(), p.triangle_count());
        for (i, q) in o.positions.iter().enumerate() {
            let j = p.positions.iter().position(|r| (*r - *q).length() < 1e-6).expect("same positions");
            assert!((o.normals[i] - p.normals[j]).length() < 1e-6);
            let (uo, up) = (o.uvs[i], p.uvs[j]);
            let want = if flipped { glam::Vec2::new(up.x, 1.0 - up.y) } else { up };
            assert!((uo - want).length() < 1e-6, "{uo} vs {want}");
        }
        assert!((o.area() - p.area()).abs() < 1e-5);
    }
}

/// A mesh file that several shapes name is read once and shared: each shape gets the file's
/// mesh under its own transform, and a shape that reads it with other options
/// (`flip_tex_coords`) gets its own reading.
#[test]
fn shapes_naming_one_mesh_file_each_get_it() {
    let d = scratch("sharedobj");
    write(&d, "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 0.25\nf 1/1 2/2 3/3 4/4\n");
    let shape = |t: &str, extra: &str| {
        format!(r#"<shape type="obj"><string name="filename" value="quad.obj"/>{extra}<transform name="to_world"><translate x="{t}"/></transform></shape>"#)
    };
    let body = format!("{}{}{}<emitter type=\"constant\"/>", shape("0", ""), shape("5", ""), shape("-3", r#"<boolean name="flip_tex_coords" value="false"/>"#));
    let s = load_str(&d, &body).unwrap();
    let (a, b, c) = (mesh(&s, 0), mesh(&s, 1), mesh(&s, 2));
    assert_eq!(a.triangle_count(), 2);
    assert_eq!((a.indices.clone(), a.uvs.clone()), (b.indices.clone(), b.uvs.clone()));
    for (p, q) in a.positions.iter().zip(&b.positions) {
        assert_eq!(*q, *p + glam::Vec3::new(5.0, 0.0, 0.0));
    }
    for (p, q) in a.positions.iter().zip(&c.positions) {
        assert_eq!(*q, *p + glam::Vec3::new(-3.0, 0.0, 0.0));
    }
    // OBJ flips v by default; the third shape asked for the file's own v.
    for (ua, uc) in a.uvs.iter().zip(&c.uvs) {
        assert_eq!(ua.y, 1.0 - uc.y);
    }
}

/// Binary and ASCII PLY give the same mesh, whatever the property types (double uvs,
/// unsigned indices), with an element the loader does not use between vertices and faces,
/// and a quad split into a fan.
#[test]
fn ply_binary_and_ascii_agree() {
    let d = scratch("plybin");
    let verts = [([0.0f32, 0.0, 0.0], [0.0f64, 0.0]), ([1.0, 0.0, 0.0], [1.0, 0.0]), ([1.0, 1.0, 0.5], [1.0, 1.0]), ([0.0, 1.0, 0.5], [0.0, 0.75])];
    let head = |format: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty double u\nproperty double v\n\
             element material 1\nproperty uchar red\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n"
        )
    };
    let mut ascii = head("ascii");
    let mut bin = head("binary_little_endian").into_bytes();
    for (p, uv) in &verts {
        ascii += &format!("{} {} {} {} {}\n", p[0], p[1], p[2], uv[0], uv[1]);
        p.iter().for_each(|x| bin.extend(x.to_le_bytes()));
        uv.iter().for_each(|x| bin.extend(x.to_le_bytes()));
    }
    ascii += "200\n4 0 1 2 3\n";
    bin.push(200);
    bin.push(4);
    [0u32, 1, 2, 3].iter().for_each(|i| bin.extend(i.to_le_bytes()));
    write(&d, "quad_ascii.ply", &ascii);
    std::fs::write(d.join("quad_bin.ply"), &bin).unwrap();
    let shape = |f: &str| format!(r#"<shape type="ply"><string name="filename" value="{f}"/></shape>"#);
    let s = load_str(&d, &format!("{}{}<emitter type=\"constant\"/>", shape("quad_ascii.ply"), shape("quad_bin.ply"))).unwrap();
    let (a, b) = (mesh(&s, 0), mesh(&s, 1));
    assert_eq!(a.positions, b.positions);
    assert_eq!(a.uvs, b.uvs);
    assert_eq!(a.indices, b.indices);
    assert_eq!(a.triangle_count(), 2);
    assert_eq!(a.uvs[3], glam::Vec2::new(0.0, 0.75));
}

fn assert_at(e: &Error, file: &str, line: u32, says: &str) {
    match e {
        Error::SceneAt { file: f, line: l, msg, .. } => {
            assert!(f.ends_with(file), "error names {} not {file}", f.display());
            assert_eq!(*l, line, "line of '{msg}'");
            assert!(msg.contains(says), "'{msg}' does not say '{says}'");
        }
        other => panic!("expected an error with a location, got {other:?}"),
    }
}

#[test]
fn bad_scene_files_give_located_errors() {
    let d = scratch("bad");
    // Malformed XML.
    let p = write(&d, "malformed.xml", "<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n</scene>\n");
    let e = load_scene(&p, &[]).err_only();
    assert!(matches!(&e, Error::SceneAt { line: 3, .. }), "{e:?}");

    // Line numbers below count from the first line of scene_xml: the sensor takes lines 2-3.
    let cases: &[(&str, u32, &str)] = &[
        (r#"<shape type="teapot"/>"#, 4, "unknown shape type 'teapot'"),
        (r#"<shape type="sphere"><bsdf type="velvet"/></shape>"#, 4, "unknown bsdf type 'velvet'"),
        (r#"<emitter type="laser"/>"#, 4, "unknown emitter type"),
        (r#"<shape type="obj"><string name="filename" value="nothere.obj"/></shape>"#, 4, "'nothere.obj' not found"),
        (
            r#"<shape type="sphere"><bsdf type="diffuse"><texture name="reflectance" type="bitmap">
                 <string name="filename" value="missing.png"/></texture></bsdf></shape>"#,
            5,
            "'missing.png' not found",
        ),
        (r#"<shape type="sphere"><float name="radius" value="abc"/></shape>"#, 4, "cannot read 'abc'"),
        (r#"<shape type="sphere"><float name="radius" value="$size"/></shape>"#, 4, "undefined parameter '$size'"),
        (r#"<shape type="sphere"><ref id="nothing"/></shape>"#, 4, "unknown id 'nothing'"),
        (r#"<shape type="sphere"><bsdf type="dielectric"><string name="int_ior" value="kryptonite"/></bsdf></shape>"#, 4, "unknown index of refraction"),
        (r#"<shape type="sphere"><bsdf type="conductor"><string name="material" value="Zz"/></bsdf></shape>"#, 4, "unknown conductor"),
        (r#"<shape type="rectangle"><transform name="to_world"><matrix value="1 2 3"/></transform></shape>"#, 4, "16 (or 9) values"),
    ];
    for (body, line, says) in cases {
        let e = load_str(&d, body).err_only();
        assert_at(&e, "scene.xml", *line, says);
    }
    // Sample counts: zero and negative.
    for n in ["0", "-4"] {
        let p = write(
            &d,
            "spp.xml",
            &format!(
                "<scene version=\"3.0.0\">\n<sensor type=\"perspective\">\n<sampler type=\"independent\">\n<integer name=\"sample_count\" value=\"{n}\"/></sampler></sensor></scene>"
            ),
        );
        assert_at(&load_scene(&p, &[]).err_only(), "spp.xml", 3, "sample_count must be a positive integer");
    }
    // No sensor at all.
    let p = write(&d, "nosensor.xml", "<scene version=\"3.0.0\"><emitter type=\"constant\"/></scene>");
    assert!(matches!(load_scene(&p, &[]).err_only(), Error::Scene { .. }));
    // A missing scene file is an I/O error naming it.
    assert!(matches!(load_scene(&d.join("absent.xml"), &[]).err_only(), Error::Io { file, .. } if file.ends_with("absent.xml")));
}

#[test]
fn include_cycle_is_an_error_not_a_hang() {
    let d = scratch("cycle");
    write(&d, "a.xml", "<scene version=\"3.0.0\"><include filename=\"b.xml\"/></scene>");
    write(&d, "b.xml", "<scene version=\"3.0.0\"><include filename=\"a.xml\"/></scene>");
    let e = load_scene(&d.join("a.xml"), &[]).err_only();
    assert!(e.to_string().contains("include cycle"), "{e}");
    // An include of itself, too.
    write(&d, "self.xml", "<scene version=\"3.0.0\"><include filename=\"self.xml\"/></scene>");
    assert!(load_scene(&d.join("self.xml"), &[]).err_only().to_string().contains("include cycle"));
    // Includes resolve relative to the including file, and share defaults and ids.
    std::fs::create_dir_all(d.join("sub")).unwrap();
    write(&d, "sub/part.xml", "<scene version=\"3.0.0\"><default name=\"r\" value=\"0.25\"/><bsdf type=\"diffuse\" id=\"m\"/></scene>");
    let p = write(
        &d,
        "main.xml",
        &scene_xml(
            r#"<include filename="sub/part.xml"/><shape type="sphere"><float name="radius" value="$r"/><ref id="m"/></shape><emitter type="constant"/>"#,
        ),
    );
    let s = load_scene(&p, &[]).unwrap();
    assert!(matches!(&*s.shapes[0].geometry, Geometry::Sphere(sp) if sp.radius == 0.25));
}

#[test]
fn bad_meshes_give_typed_errors() {
    let d = scratch("mesh");
    let shape = |f: &str| format!(r#"<shape type="{}"><string name="filename" value="{f}"/></shape>"#, &f[f.len() - 3..]);
    // NaN vertex in an OBJ.
    write(&d, "nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    match load_str(&d, &shape("nan.obj")).err_only() {
        Error::Mesh { file, msg } => assert!(file.ends_with("nan.obj") && msg.contains("non-finite"), "{msg}"),
        e => panic!("{e:?}"),
    }
    // Face index out of range in OBJ and PLY.
    write(&d, "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    match load_str(&d, &shape("range.obj")).err_only() {
        Error::Mesh { file, .. } => assert!(file.ends_with("range.obj")),
        e => panic!("{e:?}"),
    }
    let ply_head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    write(&d, "range.ply", &format!("{ply_head}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"));
    match load_str(&d, &shape("range.ply")).err_only() {
        Error::Mesh { file, msg } => assert!(file.ends_with("range.ply") && msg.contains("out of range"), "{msg}"),
        e => panic!("{e:?}"),
    }
    // Truncated PLY.
    write(&d, "short.ply", &format!("{ply_head}0 0 0\n1 0 0\n"));
    assert!(matches!(load_str(&d, &shape("short.ply")).err_only(), Error::Mesh { .. }));
    // Only zero-area triangles: an error naming the shape.
    write(&d, "flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
    let e = load_str(&d, &shape("flat.obj")).err_only();
    assert!(matches!(&e, Error::Invalid(m) if m.contains("obj#1") && m.contains("non-zero area")), "{e:?}");
    // A file that is not a serialized mesh: an error naming it.
    write(&d, "lonely.serialized", "not really");
    let e = load_str(&d, r#"<shape type="serialized"><string name="filename" value="lonely.serialized"/></shape>"#).err_only();
    assert!(matches!(&e, Error::Mesh { file, msg } if file.ends_with("lonely.serialized") && msg.contains("not a Mitsuba serialized mesh")), "{e:?}");
    // A good OBJ with a quad: fan-triangulated, normals computed, v flipped.
    write(&d, "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n");
    let s = load_str(&d, &format!("{}<emitter type=\"constant\"/>", shape("quad.obj"))).unwrap();
    let m = mesh(&s, 0);
    assert_eq!(m.triangle_count(), 2);
    assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    let i = m.positions.iter().position(|p| *p == Vec3::ZERO).unwrap();
    assert_eq!(m.uvs[i], glam::Vec2::new(0.0, 1.0));
}

/// Lights and sensors from a small file: positions, directions and defaults as Mitsuba has them.
#[test]
fn emitters_and_sensors() {
    let d = scratch("lights");
    let s = load_str(
        &d,
        r#"<emitter type="point"><point name="position" x="1" y="2" z="3"/><rgb name="intensity" value="5"/></emitter>
           <emitter type="point"><transform name="to_world"><translate x="-1"/></transform></emitter>
           <emitter type="spot"><transform name="to_world"><lookat origin="0,0,0" target="0,-1,0" up="0,0,1"/></transform></emitter>
           <emitter type="directional"><vector name="direction" value="0, 0, -2"/></emitter>
           <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
           <shape type="disk"><emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter></shape>"#,
    )
    .unwrap();
    use svetlo::light::Light;
    assert!(matches!(&s.lights[0], Light::Point { position, intensity } if *position == Vec3::new(1.0, 2.0, 3.0) && intensity.g == 5.0));
    assert!(matches!(&s.lights[1], Light::Point { position, .. } if *position == Vec3::new(-1.0, 0.0, 0.0)));
    match &s.lights[2] {
        Light::Spot { frame, cutoff_angle, beam_width, .. } => {
            assert!((frame.n - Vec3::new(0.0, -1.0, 0.0)).length() < 1e-6);
            assert!((cutoff_angle.to_degrees() - 20.0).abs() < 1e-4 && (beam_width.to_degrees() - 15.0).abs() < 1e-4);
        }
        l => panic!("{l:?}"),
    }
    assert!(matches!(&s.lights[3], Light::Directional { direction, .. } if (*direction + Vec3::Z).length() < 1e-6));
    assert!(matches!(&s.lights[4], Light::Constant { radiance } if radiance.r == 0.5));
    assert!(matches!(&s.lights[5], Light::Area(_)));
    // Default sensor values: 32x16 film, Mitsuba's near/far clip, default spp.
    assert_eq!((s.camera.width, s.camera.height, s.camera.near_clip, s.camera.far_clip), (32, 16, 1e-2, 1e4));
}
