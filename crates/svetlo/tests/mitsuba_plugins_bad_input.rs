//! Bad input to the Mitsuba plugins of issue #20 (projector, normal and bump maps, blends,
//! mesh attributes): typed errors that name
//! the file and the line of the offending element, never a panic.

use std::path::Path;
use svetlo::io::load_scene_from_str;

const SENSOR: &str = r#"<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film></sensor>"#;

/// Load `body` (placed on line 3 of a scene) and return the error's text.
fn error_of(body: &str) -> String {
    let text = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>");
    match load_scene_from_str(&text, Path::new("/nowhere/bad.xml"), &[]) {
        Ok(_) => panic!("loaded:\n{body}"),
        Err(e) => e.to_string(),
    }
}

fn assert_names_line(body: &str, words: &str) {
    let e = error_of(body);
    assert!(e.contains("bad.xml:3"), "no file:line in '{e}'");
    assert!(e.contains(words), "'{e}' does not say '{words}'");
}

#[test]
fn projector_bad_input() {
    assert_names_line(r#"<emitter type="projector"><float name="scale" value="-1"/></emitter>"#, "scale");
    assert_names_line(r#"<emitter type="projector"><float name="fov" value="180"/></emitter>"#, "fov");
    assert_names_line(r#"<emitter type="projector"><float name="fov" value="0"/></emitter>"#, "fov");
    assert_names_line(r#"<emitter type="projector"><float name="fov" value="40"/><string name="fov_axis" value="z"/></emitter>"#, "fov_axis");
    assert_names_line(r#"<emitter type="projector"><transform name="to_world"><scale x="0"/></transform></emitter>"#, "degenerate");
    let e = error_of(r#"<emitter type="projector"><texture type="bitmap" name="irradiance"><string name="filename" value="missing.png"/></texture></emitter>"#);
    assert!(e.contains("missing.png"), "{e}");
}

#[test]
fn projector_loads() {
    let text = format!("<scene version=\"3.0.0\">\n{SENSOR}\n<emitter type=\"projector\"><float name=\"fov\" value=\"60\"/><rgb name=\"irradiance\" value=\"0.5\"/></emitter>\n</scene>");
    let s = load_scene_from_str(&text, Path::new("/nowhere/ok.xml"), &[]).expect("loads");
    assert!(matches!(s.lights.as_slice(), [svetlo::light::Light::Projector(_)]));
}

const DIFFUSE: &str = r#"<bsdf type="diffuse"/>"#;
/// A shape that uses the BSDF `a` (unused BSDFs are not built).
const USE: &str = r#"<shape type="sphere"><ref id="a"/></shape>"#;

#[test]
fn surface_detail_bad_input() {
    assert_names_line(&format!(r#"<bsdf type="normalmap" id="a">{DIFFUSE}</bsdf>{USE}"#), "needs a texture named 'normalmap'");
    assert_names_line(&format!(r#"<bsdf type="normalmap" id="a"><rgb name="normalmap" value="0.5"/>{DIFFUSE}</bsdf>{USE}"#), "must be a texture");
    // Not a normal map: no direction at all, or values a normal map cannot hold.
    let flat = r#"<texture type="rawconstant" name="normalmap"><vector name="value" value="0.5, 0.5, 0.5"/></texture>"#;
    let e = error_of(&format!("<bsdf type=\"normalmap\" id=\"a\">\n{flat}{DIFFUSE}</bsdf>{USE}"));
    assert!(e.contains("bad.xml:4") && e.contains("not a normal map"), "{e}");
    let big = r#"<texture type="rawconstant" name="normalmap"><vector name="value" value="0.5, 2, 1"/></texture>"#;
    assert!(error_of(&format!("<bsdf type=\"normalmap\" id=\"a\">\n{big}{DIFFUSE}</bsdf>{USE}")).contains("not a normal map"));
    assert_names_line(&format!(r#"<bsdf type="normalmap" id="a"/>{USE}"#), "exactly one nested bsdf");
    assert_names_line(&format!(r#"<bsdf type="bumpmap" id="a">{DIFFUSE}</bsdf>{USE}"#), "nested height texture");
    let height = r#"<texture type="checkerboard"/>"#;
    assert_names_line(&format!(r#"<bsdf type="bumpmap" id="a"><float name="scale" value="inf"/>{height}{DIFFUSE}</bsdf>{USE}"#), "scale");
}

#[test]
fn blend_bad_input() {
    assert_names_line(&format!(r#"<bsdf type="blendbsdf" id="a">{DIFFUSE}</bsdf>{USE}"#), "exactly two nested bsdfs");
    assert_names_line(&format!(r#"<bsdf type="blendbsdf" id="a"><float name="weight" value="1.5"/>{DIFFUSE}{DIFFUSE}</bsdf>{USE}"#), "weight");
}

/// A two-triangle PLY with a per-vertex colour and a per-face weight.
fn attribute_ply(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("attr.ply");
    let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float color_0\nproperty float color_1\nproperty float color_2\n\
                element face 1\nproperty list uchar int vertex_indices\nproperty float weight_0\nend_header\n\
                0 0 0 1 0 0\n1 0 0 0 1 0\n1 1 0 0 0 1\n0 1 0 1 1 1\n4 0 1 2 3 0.25\n";
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn mesh_attribute_bad_input_and_values() {
    assert_names_line(
        r#"<texture type="mesh_attribute" id="t"/><bsdf type="diffuse" id="b"><ref name="reflectance" id="t"/></bsdf><shape type="sphere"><ref id="b"/></shape>"#,
        "needs a 'name'",
    );
    assert_names_line(
        r#"<texture type="mesh_attribute" id="t"><string name="name" value="color"/></texture><bsdf type="diffuse" id="b"><ref name="reflectance" id="t"/></bsdf><shape type="sphere"><ref id="b"/></shape>"#,
        "vertex_ or face_",
    );
    let e = error_of(
        r#"<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance"><string name="name" value="vertex_color"/></texture></bsdf><shape type="sphere"><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance"><string name="name" value="vertex_color"/></texture></bsdf></shape>"#,
    );
    assert!(e.contains("need a mesh"), "{e}");
    let dir = std::env::temp_dir().join(format!("svetlo-attr-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ply = attribute_ply(&dir);
    let shape = |name: &str| {
        format!(
            "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"ply\"><string name=\"filename\" value=\"{}\"/><bsdf type=\"diffuse\"><texture type=\"mesh_attribute\" name=\"reflectance\"><string name=\"name\" value=\"{name}\"/></texture></bsdf></shape>\n</scene>",
            ply.display()
        )
    };
    // An attribute the mesh does not have: the error lists those it has.
    let e = load_scene_from_str(&shape("face_color"), &dir.join("s.xml"), &[]).err().expect("missing attribute").to_string();
    assert!(e.contains("s.xml:3") && e.contains("face_color") && e.contains("vertex_color, face_weight"), "{e}");
    // The values as the file gives them: per vertex (interpolated), per face (on both triangles of the quad).
    for (name, want) in [("vertex_color", None), ("face_weight", Some(0.25f32))] {
        let s = load_scene_from_str(&shape(name), &dir.join("s.xml"), &[]).expect("loads");
        let m = &s.materials[s.shapes[0].material as usize];
        for prim in 0..2u32 {
            for bary in [glam::Vec2::ZERO, glam::Vec2::new(1.0, 0.0), glam::Vec2::new(0.25, 0.5)] {
                let p = svetlo::texture::TexPoint { uv: glam::Vec2::ZERO, prim, bary, ..Default::default() };
                let svetlo::bsdf::Material::Diffuse { reflectance } = m else { panic!("{m:?}") };
                let got = reflectance.eval(p);
                match want {
                    Some(w) => assert_eq!(got, svetlo::Rgb::splat(w)),
                    None => {
                        // Fan (0, 1, 2), (0, 2, 3) with colours red, green, blue, white.
                        let cols = [svetlo::Rgb::new(1.0, 0.0, 0.0), svetlo::Rgb::new(0.0, 1.0, 0.0), svetlo::Rgb::new(0.0, 0.0, 1.0), svetlo::Rgb::WHITE];
                        let tri = if prim == 0 { [0, 1, 2] } else { [0, 2, 3] };
                        let w = cols[tri[0]] * (1.0 - bary.x - bary.y) + cols[tri[1]] * bary.x + cols[tri[2]] * bary.y;
                        assert!((got - w).max_component().abs() < 1e-6, "{prim} {bary}: {got:?} vs {w:?}");
                    }
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A `.vol` file in a fresh temporary folder: (folder, file name).
fn vol_file(name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("svetlo-sdf-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(name), bytes).unwrap();
    dir
}

/// A sphere of radius 0.3 about the unit cube's centre on an n³ grid.
fn sphere_vol(n: usize) -> Vec<u8> {
    let mut v = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = glam::Vec3::new(x as f32, y as f32, z as f32) / (n - 1) as f32 - glam::Vec3::splat(0.5);
                v.push(p.length() - 0.3);
            }
        }
    }
    svetlo::io::vol::encode_vol([n, n, n], &v)
}

fn sdf_scene(dir: &Path, shape: &str) -> svetlo::error::Result<svetlo::scene::Scene> {
    let text = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{shape}\n</scene>");
    load_scene_from_str(&text, &dir.join("s.xml"), &[])
}

/// The error loading `shape` gives.
fn sdf_error(dir: &Path, shape: &str) -> String {
    match sdf_scene(dir, shape) {
        Ok(_) => panic!("loaded:\n{shape}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn sdfgrid_bad_input() {
    let empty = vol_file("empty.vol", b"");
    let e = sdf_error(&empty, r#"<shape type="sdfgrid"><string name="filename" value="empty.vol"/></shape>"#);
    assert!(e.contains("empty.vol") && e.contains("no 'VOL'"), "{e}");
    // All samples positive: no surface.
    let dir = vol_file("far.vol", &svetlo::io::vol::encode_vol([3, 3, 3], &[1.0; 27]));
    let e = sdf_error(&dir, r#"<shape type="sdfgrid"><string name="filename" value="far.vol"/></shape>"#);
    assert!(e.contains("far.vol") && e.contains("no voxel"), "{e}");
    let mut nan = svetlo::io::vol::encode_vol([2, 2, 2], &[-1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]);
    let at = nan.len() - 4;
    nan[at..].copy_from_slice(&f32::NAN.to_le_bytes());
    let dir = vol_file("nan.vol", &nan);
    let e = sdf_error(&dir, r#"<shape type="sdfgrid"><string name="filename" value="nan.vol"/></shape>"#);
    assert!(e.contains("nan.vol") && e.contains("not finite"), "{e}");
    let dir = vol_file("ok.vol", &sphere_vol(5));
    let two = [&sphere_vol(5)[..20], &2i32.to_le_bytes(), &sphere_vol(5)[24..]].concat();
    std::fs::write(dir.join("two.vol"), two).unwrap();
    let e = sdf_error(&dir, r#"<shape type="sdfgrid"><string name="filename" value="two.vol"/></shape>"#);
    assert!(e.contains("two.vol"), "{e}");
    for (body, words) in [
        (r#"<shape type="sdfgrid"/>"#, "needs a 'filename'"),
        (r#"<shape type="sdfgrid"><string name="filename" value="missing.vol"/></shape>"#, "missing.vol"),
        (r#"<shape type="sdfgrid"><string name="filename" value="ok.vol"/><string name="normals" value="flat"/></shape>"#, "normals"),
        (r#"<shape type="sdfgrid"><string name="filename" value="ok.vol"/><emitter type="area"/></shape>"#, "cannot be an area emitter"),
    ] {
        let e = sdf_error(&dir, body);
        assert!(e.contains("s.xml:3") && e.contains(words), "'{e}' does not say '{words}'");
    }
    let s = sdf_scene(&dir, r#"<shape type="sdfgrid"><string name="filename" value="ok.vol"/></shape>"#).expect("loads");
    assert!(matches!(&*s.shapes[0].geometry, svetlo::geometry::Geometry::SdfGrid(_)));
}

/// An SDF grid of a sphere, seen by camera rays, matches the analytic sphere it samples: the
/// same pixels covered (but for those the silhouette crosses) and the same normals within the
/// interpolation error; placed by an instance, as Mitsuba's test scene places its torus.
#[test]
fn sdfgrid_sphere_matches_the_analytic_sphere() {
    let n = 33;
    let dir = vol_file("sphere.vol", &sphere_vol(n));
    // The grid's cube [0,1]³ centred at the origin and scaled by 2: a sphere of radius 0.6.
    let place = r#"<transform name="to_world"><translate value="-0.5, -0.5, -0.5"/><scale value="2"/><rotate y="1" angle="30"/></transform>"#;
    let grid = sdf_scene(
        &dir,
        &format!(r#"<shape type="shapegroup" id="g"><shape type="sdfgrid"><string name="filename" value="sphere.vol"/></shape></shape><shape type="instance"><ref id="g"/>{place}</shape>"#),
    )
    .expect("loads");
    let sphere = sdf_scene(&dir, r#"<shape type="sphere"><float name="radius" value="0.6"/></shape>"#).expect("loads");
    let voxel = 2.0 / (n - 1) as f32;
    let (mut both, mut disagree) = (0, 0);
    for i in 0..64 {
        for j in 0..64 {
            let o = glam::Vec3::new(-1.0 + (i as f32 + 0.5) / 32.0, -1.0 + (j as f32 + 0.5) / 32.0, -5.0);
            let ray = svetlo::geometry::Ray::new(o, glam::Vec3::Z);
            let r = (o.x * o.x + o.y * o.y).sqrt();
            match (grid.intersect(&ray), sphere.intersect(&ray)) {
                (Some(a), Some(b)) => {
                    both += 1;
                    assert!((a.p - b.p).length() < voxel, "hit {} vs {}", a.p, b.p);
                    // Normals err by at most about h/r (h the voxel, r the radius) where the
                    // surface is not grazing.
                    if r < 0.5 {
                        assert!(a.shading.n.dot(b.ng) > (voxel / 0.6).cos(), "normal {} vs {}", a.shading.n, b.ng);
                        assert!(a.ng.dot(b.ng) > (voxel / 0.6).cos(), "normal {} vs {}", a.ng, b.ng);
                    }
                }
                (None, None) => {}
                _ => {
                    disagree += 1;
                    assert!((r - 0.6).abs() < voxel, "hit and miss disagree at r = {r}");
                }
            }
        }
    }
    assert!(both > 1000, "{both} pixels hit");
    assert!(disagree < 40, "{disagree} silhouette pixels disagree");
}

/// Bitmap normal maps: a float one with no direction (every texel 0.5) or a texel outside
/// [0, 1] is refused with its line, as the constant ones above; an 8-bit one (its values
/// checked through its code table, not a decoded copy) loads.
#[test]
fn bitmap_normal_maps() {
    use svetlo::spectrum::Rgb;
    let dir = std::env::temp_dir().join(format!("svetlo-normalmap-bitmaps-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, texels: Vec<Rgb>| {
        let path = dir.join(name);
        svetlo::io::image_io::write_exr(&path, &svetlo::film::Image::new(4, 2, texels)).unwrap();
        path
    };
    let bitmap = |path: &Path| {
        format!(r#"<texture type="bitmap" name="normalmap"><boolean name="raw" value="true"/><string name="filename" value="{}"/></texture>"#, path.display())
    };
    let flat = write("flat.exr", vec![Rgb::splat(0.5); 8]);
    let e = error_of(&format!("<bsdf type=\"normalmap\" id=\"a\">\n{}{DIFFUSE}</bsdf>{USE}", bitmap(&flat)));
    assert!(e.contains("bad.xml:4") && e.contains("no direction"), "{e}");
    let mut texels = vec![Rgb::new(0.5, 0.5, 1.0); 8];
    texels[5] = Rgb::new(0.5, 1.5, 1.0);
    let big = write("big.exr", texels);
    let e = error_of(&format!("<bsdf type=\"normalmap\" id=\"a\">\n{}{DIFFUSE}</bsdf>{USE}", bitmap(&big)));
    assert!(e.contains("bad.xml:4") && e.contains("texel 5") && e.contains("outside [0, 1]"), "{e}");
    // An 8-bit map (PNG) loads.
    let png = dir.join("up.png");
    svetlo::io::image_io::write_image(&png, &svetlo::film::Image::new(4, 2, vec![Rgb::new(0.5, 0.5, 1.0); 8])).unwrap();
    let text = format!("<scene version=\"3.0.0\">\n{SENSOR}\n<bsdf type=\"normalmap\" id=\"a\">{}{DIFFUSE}</bsdf>{USE}\n</scene>", bitmap(&png));
    load_scene_from_str(&text, Path::new("/nowhere/ok.xml"), &[]).expect("an 8-bit normal map loads");
    let _ = std::fs::remove_dir_all(&dir);
}
