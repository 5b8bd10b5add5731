//! Hierarchical radiosity against the full matrix: the furnace, the Cornell box (per-shape
//! radiosity and images), link counts, and importance.

use svetlo::film::Filter;
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::radiosity::{RadiosityOptions, Solved};
use svetlo::scene::Scene;
use svetlo::Rgb;

fn shared() -> Option<std::path::PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("SKIPPED: {} not found", p.display());
        None
    }
}

fn cornell_scene(res: u32) -> Option<(Scene, svetlo::film::Image)> {
    let dir = shared()?.join("bitterli/cornell-box");
    let defaults = [("resx", res.to_string()), ("resy", res.to_string())].map(|(a, b)| (a.to_string(), b));
    let scene = svetlo::io::load_scene(&dir.join("mitsuba3/scene_v3.xml"), &defaults).expect("scene");
    let reference = svetlo::io::read_image(&dir.join("TungstenRender_box4x4_256x256.pfm")).expect("reference");
    Some((scene, reference))
}

type ShapeMeans = Vec<(String, Rgb, f64)>;

/// Area-weighted mean radiosity of every shape (both sides of two-sided ones: the outer side of the walls is dark).
fn shape_means(scene: &Scene, s: &Solved) -> ShapeMeans {
    let mut sum = vec![(Rgb::BLACK, 0.0f64); scene.shapes.len()];
    for (e, b) in s.mesh.elements.iter().zip(&s.b) {
        sum[e.shape as usize].0 += *b * e.area;
        sum[e.shape as usize].1 += e.area as f64;
    }
    sum.iter().enumerate().filter(|(_, (_, a))| *a > 0.0).map(|(k, (b, a))| (scene.shapes[k].name.clone(), *b * (1.0 / *a as f32), *a)).collect()
}

fn image(scene: &Scene, s: &Solved, opts: &RadiosityOptions) -> svetlo::film::Image {
    let settings = RenderSettings { spp: 4, filter: Filter::Box, ..RenderSettings::from_scene(scene) };
    let view = s.view(opts.shading);
    svetlo::integrator::render_pixels(scene, &settings, &Progress::new(), &view).expect("render").image()
}

/// Compare option sets on the Cornell box (the first is the baseline):
/// `HR_OPTS='element-size=0.5;solver=hierarchical,epsilon=0.01' cargo test --release --test radiosity_hierarchical -- --ignored explore --nocapture`.
#[test]
#[ignore]
fn explore() {
    let Some((scene, reference)) = cornell_scene(256) else { return };
    let args: Vec<String> = std::env::var("HR_OPTS").unwrap_or_default().split(';').map(String::from).collect();
    let mut base: Option<(ShapeMeans, svetlo::film::Image)> = None;
    for a in args.into_iter().filter(|s| !s.is_empty()) {
        let opts = RadiosityOptions::parse(&a).expect("opts");
        let t = std::time::Instant::now();
        let s = svetlo::radiosity::solve(&scene, &opts, -1).expect("solve");
        let secs = t.elapsed().as_secs_f64();
        let img = image(&scene, &s, &opts);
        let e = svetlo::film::compare::rel_mse(&img, &reference).expect("relmse");
        let means = shape_means(&scene, &s);
        println!(
            "{a}: {} elements, links {:?}, relMSE {e:.3e}, {secs:.2} s, steps {}",
            s.mesh.elements.len(),
            s.hierarchy.as_ref().map(|h| (h.links, h.leaves, h.passes)),
            s.history.len()
        );
        if let Some((bm, bi)) = &base {
            let d = svetlo::film::compare::rel_mse(&img, bi).expect("relmse");
            println!("  vs full matrix image relMSE {d:.3e}");
            for ((n, m, _), (_, r, _)) in means.iter().zip(bm) {
                println!("  {n:20} {:.4} {:.4} {:.4}   ratio {:.3}", m.r, m.g, m.b, m.luminance() / r.luminance());
            }
        } else {
            base = Some((means, img));
        }
    }
}

fn camera() -> svetlo::camera::Camera {
    use svetlo::camera::Camera;
    Camera::pinhole(glam::Mat4::IDENTITY, 60.0, 8, 8)
}

/// Closed unit box of one-sided inward quads, all grey ρ, all emitting Le.
fn furnace(rho: f32, le: f32) -> Scene {
    box_scene(rho, Some(le), false)
}

/// The unit box; with `light`, a small emitting square under the ceiling (walls then dark).
fn box_scene(rho: f32, wall_emission: Option<f32>, light: bool) -> Scene {
    use glam::Vec3;
    use svetlo::bsdf::Material;
    use svetlo::geometry::{Geometry, TriangleMesh};
    use svetlo::texture::Texture;
    let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let quads = [
        [c(0., 0., 0.), c(1., 0., 0.), c(1., 1., 0.), c(0., 1., 0.)],
        [c(0., 0., 1.), c(0., 1., 1.), c(1., 1., 1.), c(1., 0., 1.)],
        [c(0., 0., 0.), c(0., 1., 0.), c(0., 1., 1.), c(0., 0., 1.)],
        [c(1., 0., 0.), c(1., 0., 1.), c(1., 1., 1.), c(1., 1., 0.)],
        [c(0., 0., 0.), c(0., 0., 1.), c(1., 0., 1.), c(1., 0., 0.)],
        [c(0., 1., 0.), c(1., 1., 0.), c(1., 1., 1.), c(0., 1., 1.)],
    ];
    let mut b = svetlo::scene::SceneBuilder::new();
    let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(rho)) });
    for (k, q) in quads.iter().enumerate() {
        let mesh = TriangleMesh { positions: q.to_vec(), normals: vec![], uvs: vec![], indices: vec![[0, 1, 2], [0, 2, 3]] };
        b.add_shape(Geometry::Mesh(mesh), m, wall_emission.map(|le| Texture::Constant(Rgb::splat(le))), &format!("f{k}")).expect("shape");
    }
    if light {
        let black = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::BLACK) });
        let q = vec![c(0.4, 0.4, 0.99), c(0.4, 0.6, 0.99), c(0.6, 0.6, 0.99), c(0.6, 0.4, 0.99)];
        let mesh = TriangleMesh { positions: q, normals: vec![], uvs: vec![], indices: vec![[0, 1, 2], [0, 2, 3]] };
        b.add_shape(Geometry::Mesh(mesh), black, Some(Texture::Constant(Rgb::splat(10.0))), "light").expect("light");
    }
    b.set_camera(camera());
    b.build().expect("scene")
}

#[test]
fn furnace_gives_e_over_one_minus_rho() {
    let (rho, le) = (0.6f32, 1.0f32);
    let scene = furnace(rho, le);
    let exact = std::f32::consts::PI * le / (1.0 - rho);
    for o in ["refine=f,epsilon=0.01,min-area=0.004", "refine=bf,epsilon=0.02,min-area=0.004"] {
        let opts = RadiosityOptions::parse(&format!("solver=hierarchical,tolerance=1e-6,{o}")).expect("opts");
        let s = svetlo::radiosity::solve(&scene, &opts, -1).expect("solve");
        let h = s.hierarchy.as_ref().expect("stats");
        let (lo, hi) = s.b.iter().fold((f32::MAX, f32::MIN), |(a, c), b| (a.min(b.g / exact), c.max(b.g / exact)));
        println!("furnace {o}: {} links, {} leaves, B/exact in [{lo:.5}, {hi:.5}]", h.links, h.leaves);
        assert!(s.converged);
        assert!(lo > 0.97 && hi < 1.03, "{o}: [{lo}, {hi}]");
    }
}

/// A bounded max_depth keeps exactly max_depth − 1 diffuse bounces (Jacobi sweeps from E):
/// in the furnace B = E (1 + ρ + ρ²) for max_depth 3, within the closure error (2 %).
#[test]
fn max_depth_truncates_the_bounces() {
    let (rho, le) = (0.6f32, 1.0f32);
    let scene = furnace(rho, le);
    let opts = RadiosityOptions::parse("solver=hierarchical,refine=f,epsilon=0.01,min-area=0.004").expect("opts");
    let s = svetlo::radiosity::solve(&scene, &opts, 3).expect("solve");
    let exact = std::f32::consts::PI * le * (1.0 + rho + rho * rho);
    let (lo, hi) = s.b.iter().fold((f32::MAX, f32::MIN), |(a, c), b| (a.min(b.g / exact), c.max(b.g / exact)));
    println!("max_depth 3: {} sweeps, B/exact in [{lo:.4}, {hi:.4}]", s.history.len());
    assert_eq!(s.history.len(), 2);
    assert!(lo > 0.98 && hi < 1.02, "[{lo}, {hi}]");
}

/// Refined everywhere to one depth, the hierarchy is the regular mesh with every pair linked:
/// it must then solve the same system as the full matrix on that mesh, element by element, up
/// to the two quadratures of the form factors (16 or 1 points and 2×2 shadow rays for the
/// matrix, 9 points fitted linearly for the links). Power-weighted they differ by 0.9 %
/// (bound 2 %); element by element by < 3 % except on the ceiling around the light, 1 cm below
/// it, where the matrix judges the visibility of far elements from the centroid alone (two
/// elements whose centroid is above the light differ by 22 %; bound there 30 %).
#[test]
fn refined_everywhere_it_is_the_full_matrix() {
    use svetlo::radiosity::mesh::MeshOptions;
    let scene = box_scene(0.7, None, true);
    // Walls: two triangles of area 1/2, split twice (area 1/32 ≥ 0.03); the light's triangles (0.02) stay whole.
    let opts = RadiosityOptions::parse("solver=hierarchical,refine=f,epsilon=1e-9,min-area=0.03,tolerance=1e-6").expect("opts");
    let h = svetlo::radiosity::solve(&scene, &opts, -1).expect("hierarchical");
    let mut full = RadiosityOptions::parse("solver=gauss-seidel,tolerance=1e-6").expect("opts");
    full.mesh = MeshOptions { shape_splits: vec![4, 4, 4, 4, 4, 4, 1], ..Default::default() };
    let f = svetlo::radiosity::solve(&scene, &full, -1).expect("full");
    assert_eq!(h.mesh.elements.len(), f.mesh.elements.len());
    let (mut worst, mut sum, mut norm) = (0.0f32, 0.0f64, 0.0f64);
    for ((a, b), e) in h.b.iter().zip(&f.b).zip(&f.mesh.elements) {
        if e.reflectance.is_black() {
            continue;
        }
        let d = (a.g - b.g).abs() / b.g;
        let above_light = e.centroid.z > 0.99 && (0.3..0.7).contains(&e.centroid.x) && (0.3..0.7).contains(&e.centroid.y);
        assert!(d < if above_light { 0.3 } else { 0.03 }, "{:?}: {} vs {}", e.centroid, a.g, b.g);
        worst = worst.max(d);
        sum += (e.area * (a.g - b.g).abs()) as f64;
        norm += (e.area * b.g) as f64;
    }
    println!("{} elements: worst relative difference {worst:.3e}, power-weighted {:.3e}", f.mesh.elements.len(), sum / norm);
    assert!(sum / norm < 0.02);
}

/// Links carry F as a linear function over the receiver, so a leaf inherits its ancestors'
/// links to first order: the fraction of each leaf's hemisphere its links cover stays near 1.
/// Refined everywhere (links only between leaves) the 9-point quadrature of the contour
/// integral closes to rounding.
#[test]
fn closure_in_a_closed_box() {
    use svetlo::radiosity::hierarchical::*;
    let scene = furnace(0.6, 1.0);
    for (rule, eps, min_area, tol) in [
        (Rule::F, 1e-9, 0.03, 1e-5),
        // Measured: F rule ε = 0.01 gives [0.988, 1.021], ε = 0.002 [0.993, 1.012] (constant links: [0.89, 1.24]).
        (Rule::F, 0.01, 0.004, 0.03),
        (Rule::F, 0.002, 0.001, 0.02),
    ] {
        let opts = HierarchicalOptions { rule, epsilon: eps, min_area: Some(min_area), ..Default::default() };
        let mut h = Hierarchy::new(&scene, &Default::default(), opts).expect("h");
        h.refine_roots();
        h.compute_pending();
        let c = h.closure();
        let (lo, hi) = c.iter().fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x.1), b.max(x.1)));
        println!("ε {eps}, min area {min_area}: {} leaves, {} links, closure [{lo:.5}, {hi:.5}]", c.len(), h.link_count());
        assert!(lo > 1.0 - tol && hi < 1.0 + tol, "ε {eps}: [{lo}, {hi}]");
    }
}

fn solve_cornell(scene: &Scene, options: &str) -> (Solved, RadiosityOptions) {
    let opts = RadiosityOptions::parse(options).expect("options");
    (svetlo::radiosity::solve(scene, &opts, -1).expect("solve"), opts)
}

/// Hierarchical against the full matrix (Gauss-Seidel) on the Cornell box at the same element
/// size (0.5; the hierarchy's smallest elements are an eighth of that squared). The full matrix
/// at 0.5 is itself 3.1e-3 (relMSE) from the full matrix at 0.25, and its per-shape means up
/// to 7.5 % brighter (short box); the hierarchical image must be closer to it than that, each
/// shape's mean within 10 %, and it must be at least as close to the Tungsten reference as the
/// full matrix's bound (1.5e-2). Measured: 1.6e-3, shapes 0.92-1.00, 8.8e-3 against Tungsten
/// (full matrix 1.05e-2). An earlier attempt (not this code) was 15-19 % too bright on the boxes
/// (relMSE 6.6e-2); constant links under an oracle on the size of F make that kind of error
/// (up to +24 % near contacts in the furnace, see `closure_in_a_closed_box`).
#[test]
fn cornell_box_matches_the_full_matrix() {
    let Some((scene, reference)) = cornell_scene(256) else { return };
    let (full, fo) = solve_cornell(&scene, "solver=gauss-seidel,element-size=0.5,tolerance=1e-4");
    let (hier, ho) = solve_cornell(&scene, "solver=hierarchical,element-size=0.5,tolerance=1e-4");
    let (fi, hi) = (image(&scene, &full, &fo), image(&scene, &hier, &ho));
    let against_full = svetlo::film::compare::rel_mse(&hi, &fi).expect("relmse");
    let (eh, ef) = (svetlo::film::compare::rel_mse(&hi, &reference).expect("relmse"), svetlo::film::compare::rel_mse(&fi, &reference).expect("relmse"));
    let h = hier.hierarchy.as_ref().expect("stats");
    println!("hierarchical: {} links, {} leaves; relMSE vs full matrix {against_full:.3e}; vs Tungsten {eh:.3e} (full matrix {ef:.3e})", h.links, h.leaves);
    assert!(hier.converged);
    assert!(against_full < 3.1e-3, "{against_full}");
    assert!(eh < 1.5e-2, "{eh}");
    for ((n, m, _), (_, r, _)) in shape_means(&scene, &hier).iter().zip(&shape_means(&scene, &full)) {
        let ratio = m.luminance() / r.luminance();
        println!("  {n:12} hierarchical / full {ratio:.3}");
        assert!((ratio - 1.0).abs() < 0.10, "{n}: {ratio}");
    }
}

/// Importance (Smits' BFV): with the camera zoomed onto the middle of the Cornell box, the
/// links that only light what the camera cannot see (nor what lights what it sees) stay
/// coarse: far fewer links, and with a smaller ε the visible image converges to BF's.
#[test]
fn importance_refines_less_where_the_camera_does_not_look() {
    let Some((mut scene, _)) = cornell_scene(128) else { return };
    if let svetlo::camera::Projection::Perspective { fov_x_deg, .. } = &mut scene.camera.projection {
        *fov_x_deg /= 4.0;
    }
    let mut res = vec![];
    let mut bf_image = None;
    for (imp, eps) in [("false", 0.005), ("true", 0.005), ("true", 0.001)] {
        let (s, o) = solve_cornell(&scene, &format!("solver=hierarchical,element-size=0.5,tolerance=1e-4,epsilon={eps},importance={imp}"));
        let img = image(&scene, &s, &o);
        let e = bf_image.as_ref().map(|b| svetlo::film::compare::rel_mse(&img, b).expect("relmse")).unwrap_or(0.0);
        bf_image.get_or_insert(img);
        let h = s.hierarchy.expect("stats");
        println!("importance={imp} ε={eps}: {} links, {} leaves, relMSE against BF {e:.3e}", h.links, h.leaves);
        res.push((h.links, e));
    }
    // Measured: BF 90k links; BFV 6.7k links at the same ε (relMSE 8.6e-4 from BF's image) and
    // 25k at ε / 5 (9.3e-5). The bound 5e-4 is a tenth of the discretisation difference between
    // either and the full matrix at this element size in this view (5e-3).
    assert!((res[2].0 as f64) < 0.5 * res[0].0 as f64, "{res:?}");
    assert!(res[2].1 < 5e-4 && res[2].1 < res[1].1, "{res:?}");
}

#[test]
fn bad_hierarchical_options_are_errors() {
    let scene = furnace(0.5, 1.0);
    for o in ["epsilon=-1", "epsilon=0", "min-area=0", "min-area=-2", "epsilon=nan"] {
        let opts = RadiosityOptions::parse(&format!("solver=hierarchical,{o}")).expect("parses");
        assert!(svetlo::radiosity::solve(&scene, &opts, -1).is_err(), "{o}");
    }
    for o in ["refine=q", "importance=maybe", "hybrid=1x", "gather=-1"] {
        assert!(RadiosityOptions::parse(o).is_err(), "{o}");
    }
}
