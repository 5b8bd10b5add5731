//! Radiosity on awkward input (issue 3, "bad input"): non-planar polygons, degenerate and
//! sliver triangles, zero reflectance, scenes with no diffuse surface. Each either solves with
//! every solver (finite, non-negative radiosity) or fails with a typed error that says why;
//! none panics.

use glam::{Mat4, Vec3};
use svetlo::bsdf::Material;
use svetlo::camera::Camera;
use svetlo::geometry::{Geometry, TriangleMesh};
use svetlo::radiosity::{solve, RadiosityOptions};
use svetlo::scene::{Scene, SceneBuilder};
use svetlo::texture::Texture;
use svetlo::Rgb;

const SOLVERS: [&str; 9] = ["auto", "jacobi", "gauss-seidel", "southwell", "progressive", "ssg", "two-level", "hierarchical", "progressive,omega=adaptive"];

fn camera() -> Camera {
    // Inside the box, at its centre.
    Camera::pinhole(Mat4::IDENTITY, 60.0, 8, 8)
}

fn mesh(positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> TriangleMesh {
    TriangleMesh { positions, normals: vec![], uvs: vec![], indices }
}

/// An axis-aligned square facing `normal` (inwards for a box), centred at `c`, half-size 1.
fn square(c: Vec3, normal: Vec3) -> TriangleMesh {
    let (t, b) = normal.any_orthonormal_pair();
    let p = [c - t - b, c + t - b, c + t + b, c - t + b];
    let m = mesh(p.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
    // Wind so that the front (the side of (b − a) × (c − a)) faces `normal`.
    if (p[1] - p[0]).cross(p[2] - p[0]).dot(normal) > 0.0 {
        m
    } else {
        mesh(p.to_vec(), vec![[0, 2, 1], [0, 3, 2]])
    }
}

/// A closed 2×2×2 box, walls of one material and the ceiling of another, plus extra shapes;
/// the ceiling emits.
fn box_scene(wall: Material, light: Material, extra: Vec<(TriangleMesh, Material)>) -> Result<Scene, svetlo::Error> {
    let mut b = SceneBuilder::new();
    let mw = b.add_material(wall);
    let ml = b.add_material(light);
    let faces = [(Vec3::Y, -Vec3::Y), (-Vec3::Y, Vec3::Y), (Vec3::X, -Vec3::X), (-Vec3::X, Vec3::X), (Vec3::Z, -Vec3::Z), (-Vec3::Z, Vec3::Z)];
    for (k, (c, n)) in faces.into_iter().enumerate() {
        let (m, e) = if k == 0 { (ml, Some(Texture::Constant(Rgb::splat(1.0)))) } else { (mw, None) };
        b.add_shape(Geometry::Mesh(square(c, n)), m, e, &format!("wall{k}"))?;
    }
    for (k, (s, m)) in extra.into_iter().enumerate() {
        let id = b.add_material(m);
        b.add_shape(Geometry::Mesh(s), id, None, &format!("extra{k}"))?;
    }
    b.set_camera(camera());
    b.build()
}

fn grey(rho: f32) -> Material {
    Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(rho)) }
}

fn mirror() -> Material {
    Material::Conductor { eta: Rgb::splat(0.0), k: Rgb::splat(1.0), specular_reflectance: Texture::Constant(Rgb::splat(1.0)), roughness: None }
}

/// Solve with every solver; each must succeed with finite, non-negative radiosity.
fn solves_everywhere(scene: &Scene, what: &str) -> Vec<Vec<Rgb>> {
    SOLVERS
        .iter()
        .map(|s| {
            let opts = RadiosityOptions::parse(&format!("solver={s},element-size=0.5,tolerance=1e-4")).expect("options");
            let sol = solve(scene, &opts, -1).unwrap_or_else(|e| panic!("{what}, {s}: {e}"));
            for b in &sol.b {
                assert!(b.r.is_finite() && b.g.is_finite() && b.b.is_finite(), "{what}, {s}: {b:?}");
                assert!(b.r >= 0.0 && b.g >= 0.0 && b.b >= 0.0, "{what}, {s}: {b:?}");
            }
            sol.b
        })
        .collect()
}

/// A non-planar quadrilateral (one corner lifted off the plane of the others): the scene's
/// triangle meshes are planar per triangle, so it becomes two planar patches (the loaders
/// triangulate polygons as fans) and solves like any other surface.
#[test]
fn non_planar_polygons_solve_as_triangles() {
    let quad =
        mesh(vec![Vec3::new(-0.5, -0.9, -0.5), Vec3::new(0.5, -0.9, -0.5), Vec3::new(0.5, -0.5, 0.5), Vec3::new(-0.5, -0.9, 0.5)], vec![[0, 2, 1], [0, 3, 2]]);
    let scene = box_scene(grey(0.5), grey(0.5), vec![(quad, grey(0.8))]).expect("scene");
    solves_everywhere(&scene, "non-planar quad");
}

/// Zero-area triangles are dropped when the scene is built (with a warning), a shape of only
/// zero-area triangles is a typed error, and a sliver (area 1e-9 of its neighbours) solves
/// without dividing by its tiny area into infinities.
#[test]
fn degenerate_and_sliver_triangles() {
    let degenerate = mesh(vec![Vec3::ZERO, Vec3::X * 0.5, Vec3::X], vec![[0, 1, 2]]);
    let err = box_scene(grey(0.5), grey(0.5), vec![(degenerate.clone(), grey(0.5))]).err().expect("a shape of only zero-area triangles is an error");
    assert!(err.to_string().contains("non-zero area"), "{err}");

    let mut mixed = square(Vec3::new(0.0, -0.5, 0.0), Vec3::Y);
    mixed.positions.extend([Vec3::new(-0.2, -0.4, 0.0), Vec3::new(0.0, -0.4, 0.0), Vec3::new(0.2, -0.4, 0.0)]);
    mixed.indices.push([4, 5, 6]);
    let sliver = mesh(vec![Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.0, 1e-9, 0.0)], vec![[0, 1, 2]]);
    let scene = box_scene(grey(0.5), grey(0.5), vec![(mixed, grey(0.5)), (sliver, grey(0.9))]).expect("scene");
    assert!(scene.warnings.iter().any(|w| w.contains("zero-area")), "{:?}", scene.warnings);
    solves_everywhere(&scene, "sliver");
}

/// ρ = 0 everywhere: only the light has elements (the black walls absorb), so B = E exactly;
/// with nothing emitting either, there is nothing to mesh and the error says so.
#[test]
fn zero_reflectance() {
    let scene = box_scene(grey(0.0), grey(0.0), vec![]).expect("scene");
    for (s, b) in SOLVERS.iter().zip(solves_everywhere(&scene, "black box")) {
        assert!(!b.is_empty(), "{s}");
        for x in b {
            assert!((x.r - std::f32::consts::PI).abs() < 1e-4, "{s}: B = {x:?}, expected E = π");
        }
    }
    let mut b = SceneBuilder::new();
    let m = b.add_material(grey(0.0));
    b.add_shape(Geometry::Mesh(square(Vec3::ZERO, Vec3::Z)), m, None, "black").expect("shape");
    b.set_camera(camera());
    let scene = b.build().expect("scene");
    for s in SOLVERS {
        let opts = RadiosityOptions::parse(&format!("solver={s}")).expect("options");
        let err = solve(&scene, &opts, -1).err().unwrap_or_else(|| panic!("{s}: black scene without light solved"));
        assert!(err.to_string().contains("no diffuse or emitting surface"), "{s}: {err}");
    }
}

/// Only specular surfaces (and a light): the mirrors take no part in the radiosity system and
/// absorb what reaches them; the light keeps B = E. Without the light: a typed error.
#[test]
fn no_diffuse_surface() {
    let scene = box_scene(mirror(), grey(0.0), vec![]).expect("scene");
    for (s, b) in SOLVERS.iter().zip(solves_everywhere(&scene, "mirror box")) {
        for x in b {
            assert!((x.r - std::f32::consts::PI).abs() < 1e-4, "{s}: B = {x:?}");
        }
    }
    let mut b = SceneBuilder::new();
    let m = b.add_material(mirror());
    b.add_shape(Geometry::Mesh(square(Vec3::ZERO, Vec3::Z)), m, None, "mirror").expect("shape");
    b.set_camera(camera());
    let scene = b.build().expect("scene");
    let err = solve(&scene, &RadiosityOptions::default(), -1).err().expect("no diffuse surface is an error");
    assert!(err.to_string().contains("no diffuse or emitting surface"), "{err}");
    // The integrator says the same through the render entry point.
    let integ = svetlo::methods::by_name("radiosity").expect("integrator");
    let settings = svetlo::integrator::RenderSettings::from_scene(&scene);
    assert!(integ.render(&scene, &settings, &svetlo::integrator::Progress::new()).is_err());
}
