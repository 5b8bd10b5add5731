//! The eight-wide path tracer (`path`, integrator/path_simd.rs) against the scalar one
//! (`path:simd=false`): same random numbers in the same order, so the images agree pixel by
//! pixel up to float rounding (a path meeting a shared edge may take the other triangle and
//! go its own way: a few pixels may differ by noise). The Z-test against Mitsuba is
//! `references.rs`'s `cbox_rgb_measured`, which renders through `path` and so through the kernel.

mod common;

use common::scenes::shared;
use std::path::{Path, PathBuf};
use svetlo::film::Image;
use svetlo::integrator::path_simd::SimdKernel;
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::io::load_scene;
use svetlo::scene::Scene;

fn repo_scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name)
}

fn load(path: &Path, defaults: &[(&str, &str)], size: u32) -> Scene {
    let defaults: Vec<(String, String)> = defaults.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    let mut scene = load_scene(path, &defaults).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    scene.camera.width = size;
    scene.camera.height = size;
    scene
}

fn render(scene: &Scene, name: &str, settings: &RenderSettings) -> Image {
    svetlo::methods::by_name(name).expect("integrator").render(scene, settings, &Progress::new()).expect("render").image()
}

fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Renders with the kernel and with the scalar tracer and compares pixel channels: at least
/// 99 % within 1e-4 relative (most are bit-identical), and the image means within 1 %.
fn compare(scene: &Scene, settings: &RenderSettings, what: &str) {
    compare_within(scene, settings, what, 0.99);
}

/// [`compare`] with at least `close_share` of the packet tracer's pixel channels within 1e-4
/// (the single-ray kernel is still the scalar tracer bit for bit).
fn compare_within(scene: &Scene, settings: &RenderSettings, what: &str, close_share: f64) {
    assert!(SimdKernel::new(scene, settings).is_some(), "{what}: the scene should qualify for the kernel");
    if !avx2() {
        eprintln!("SKIPPED {what}: no AVX2, the kernel falls back to the scalar tracer");
        return;
    }
    let a = render(scene, "path", settings);
    let b = render(scene, "path:simd=false", settings);
    let (mut close, mut exact, mut n) = (0usize, 0usize, 0usize);
    for (pa, pb) in a.data.iter().zip(&b.data) {
        for c in 0..3 {
            let (x, y) = (pa[c], pb[c]);
            n += 1;
            exact += (x == y) as usize;
            close += ((x - y).abs() <= 1e-4 * x.abs().max(y.abs()).max(1e-3)) as usize;
        }
    }
    // The AVX2-only build of the kernel (the one CPUs without AVX-512 run) gives the same image.
    let mut k = SimdKernel::new(scene, settings).expect("kernel");
    let wide = k.uses_avx512();
    k.set_avx512(false);
    let c = k.render(scene, settings, &Progress::new()).expect("render").image();
    assert!(c.data == a.data, "{what}: the AVX2 build of the kernel differs from the default build (AVX-512: {wide})");
    // One ray at a time through the scene's BVH (large scenes): the scalar tracer's hits, so
    // its image bit for bit.
    k.use_single_rays(scene);
    let d = k.render(scene, settings, &Progress::new()).expect("render").image();
    assert!(d.data == b.data, "{what}: the kernel tracing single rays differs from the scalar tracer");
    let (ma, mb) = (a.mean(), b.mean());
    println!("{what}: {exact}/{n} channels bit-identical, {close} within 1e-4; means {ma:?} vs {mb:?}");
    assert!(close as f64 >= close_share * n as f64, "{what}: only {close} of {n} pixel channels agree");
    assert!(exact > 0, "{what}: no channel is bit-identical: the kernel does not follow the scalar tracer");
    for c in 0..3 {
        assert!((ma[c] - mb[c]).abs() <= 0.01 * mb[c].abs().max(1e-3), "{what}: means differ in channel {c}: {ma:?} vs {mb:?}");
    }
}

#[test]
fn cornell_box_matches_scalar() {
    let scene = load(&repo_scene("cornell-box.xml"), &[], 48);
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 8;
    s.seed = 3;
    compare(&scene, &s, "cornell-box");
    // Short paths, hidden emitters, Russian roulette from the first bounce.
    s.max_depth = 2;
    s.hide_emitters = true;
    compare(&scene, &s, "cornell-box depth 2, hidden emitters");
    s.max_depth = -1;
    s.hide_emitters = false;
    s.rr_depth = 1;
    compare(&scene, &s, "cornell-box unbounded depth, rr from 1");
    // Camera rays and emission only: every step's paths all end at their first vertex (the
    // packets skip the shading step and start eight camera samples at once).
    s.max_depth = 1;
    compare(&scene, &s, "cornell-box depth 1");
}

#[test]
fn sobol_sampler_matches_scalar() {
    // Each lane draws from its own copy of the scalar tracer's Sobol sampler, in its order.
    let scene = load(&repo_scene("cornell-box.xml"), &[], 48);
    let mut s = RenderSettings::from_scene(&scene);
    s.sampler = svetlo::sampling::SamplerKind::Sobol;
    s.spp = 8;
    s.seed = 5;
    compare(&scene, &s, "cornell-box, sobol");
    s.rr_depth = 1;
    s.max_depth = 4;
    compare(&scene, &s, "cornell-box, sobol, depth 4, rr from 1");
    s.max_depth = 1;
    compare(&scene, &s, "cornell-box, sobol, depth 1");
}

#[test]
fn cbox_rgb_matches_scalar() {
    let Some(root) = shared() else { return };
    let scene = load(&root.join("mitsuba-data/scenes/cbox/cbox-rgb.xml"), &[], 64);
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 8;
    s.max_depth = 6;
    compare(&scene, &s, "cbox-rgb");
}

/// Lambertian materials with textures: each lane evaluates its hit's texture as the scalar
/// tracer's `Material::bsdf` does (checkerboards over the walls' uvs, a different one on the
/// back of the two-sided ones): the same image as the scalar tracer's, with either sampler.
#[test]
fn textured_diffuse_matches_scalar() {
    use svetlo::bsdf::Material;
    use svetlo::spectrum::Rgb;
    use svetlo::texture::Texture;
    fn checker(c: Rgb, k: f32, scale: f32) -> Texture {
        Texture::Checkerboard { color0: c, color1: c * k, to_uv: glam::Affine2::from_scale(glam::Vec2::splat(scale)) }
    }
    fn texturize(m: &Material, k: f32) -> Material {
        match m {
            Material::Diffuse { reflectance: Texture::Constant(c) } => Material::Diffuse { reflectance: checker(*c, k, 5.0) },
            Material::TwoSided { front, back } => Material::TwoSided { front: Box::new(texturize(front, k)), back: Box::new(texturize(back, 0.1)) },
            m => m.clone(),
        }
    }
    let mut scene = load(&repo_scene("cornell-box.xml"), &[], 48);
    scene.materials = scene.materials.iter().map(|m| texturize(m, 0.35)).collect();
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 8;
    s.seed = 11;
    compare(&scene, &s, "cornell-box, checkerboard walls");
    s.sampler = svetlo::sampling::SamplerKind::Sobol;
    compare(&scene, &s, "cornell-box, checkerboard walls, sobol");
    // The texture matters: the kernel's image is not the untextured one.
    let plain = load(&repo_scene("cornell-box.xml"), &[], 48);
    let a = render(&scene, "path", &s);
    let b = render(&plain, "path", &s);
    assert!(a.mean()[1] < 0.9 * b.mean()[1], "the checkerboards darken the box: {:?} vs {:?}", a.mean(), b.mean());
}

/// Lambertian materials with bitmaps large enough that the kernel asks for their texels
/// ahead of shading and keeps the uvs it computed for that (`prefetch_texels`; 640x480
/// texels of random 8-bit codes, another bitmap on the back of the two-sided walls; the
/// second material keeps its constant, so the textured meshes are not one run of the
/// kernel's triangles): the scalar tracer's image.
#[test]
fn large_bitmaps_match_scalar() {
    use svetlo::bsdf::Material;
    use svetlo::texture::{Bitmap, FilterMode, Texture, WrapMode};
    let mut rng = svetlo::sampling::rng::Pcg32::new(5, 7);
    let table: &'static [f32; 256] = Box::leak(Box::new(std::array::from_fn(|i| i as f32 / 255.0)));
    let mut bitmap = |scale: f32| {
        let (w, h) = (640, 480);
        let codes: Vec<[u8; 4]> = (0..w * h).map(|_| rng.next_u32().to_le_bytes()).collect();
        Texture::Bitmap {
            image: std::sync::Arc::new(Bitmap::from_8bit(w, h, codes, table)),
            filter: FilterMode::Bilinear,
            wrap: WrapMode::Repeat,
            to_uv: glam::Affine2::from_scale(glam::Vec2::splat(scale)),
        }
    };
    let (front, back) = (bitmap(1.0), bitmap(3.0));
    let mut scene = load(&repo_scene("cornell-box.xml"), &[], 48);
    scene.materials = scene
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| match m {
            _ if i == 1 => m.clone(),
            Material::Diffuse { reflectance: Texture::Constant(_) } => Material::Diffuse { reflectance: front.clone() },
            Material::TwoSided { .. } => Material::TwoSided {
                front: Box::new(Material::Diffuse { reflectance: front.clone() }),
                back: Box::new(Material::Diffuse { reflectance: back.clone() }),
            },
            m => m.clone(),
        })
        .collect();
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 8;
    s.seed = 13;
    compare(&scene, &s, "cornell-box, large bitmaps");
}

#[test]
fn same_image_for_any_thread_count() {
    if !avx2() {
        eprintln!("SKIPPED: no AVX2");
        return;
    }
    let scene = load(&repo_scene("cornell-box.xml"), &[], 40);
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let mut s = RenderSettings::from_scene(&scene);
        s.sampler = sampler;
        s.spp = 4;
        s.threads = 1;
        let a = render(&scene, "path", &s);
        s.threads = 3;
        let b = render(&scene, "path", &s);
        assert!(a.data == b.data, "the kernel's image depends on the thread count ({sampler:?})");
    }
}

/// Moving shapes (a ball flying, a box spinning and growing): each lane's rays at its camera
/// ray's time, the static shapes as packets and the moving ones lane by lane after them (or
/// all through the scene's own queries, as `compare` also checks), so the image is the scalar
/// tracer's bit for bit.
#[test]
fn motion_blur_matches_scalar() {
    let scene = load(&repo_scene("motion-blur.xml"), &[], 40);
    assert!(!scene.moving.is_empty(), "motion-blur.xml has moving shapes");
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let mut s = RenderSettings::from_scene(&scene);
        s.sampler = sampler;
        s.spp = 6;
        s.seed = 11;
        s.max_depth = 5;
        let k = SimdKernel::new(&scene, &s).expect("a scene with moving shapes qualifies");
        assert!(k.uses_packets(), "the static shapes of a scene with moving ones go as packets");
        compare_exact(&scene, &s, &format!("motion-blur ({sampler:?})"));
    }
}

/// A ray epsilon (Tungsten's references): every ray through the scene's queries, which skip
/// the epsilon; the scalar tracer's image bit for bit.
#[test]
fn ray_epsilon_matches_scalar() {
    let mut scene = load(&repo_scene("cornell-box.xml"), &[], 40);
    scene.settings.ray_epsilon = 5e-4;
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 6;
    s.seed = 4;
    compare_exact(&scene, &s, "cornell-box, ray epsilon 5e-4");
    // The epsilon matters: without it the image differs.
    let mut plain = scene.clone();
    plain.settings.ray_epsilon = 0.0;
    assert!(render(&plain, "path", &s).data != render(&scene, "path", &s).data, "the epsilon should change the image");
}

/// [`compare`] for a kernel that traces through the scene's queries: the scalar tracer's
/// image bit for bit, whatever the thread count.
fn compare_exact(scene: &Scene, settings: &RenderSettings, what: &str) {
    compare(scene, settings, what);
    if !avx2() {
        return;
    }
    let a = render(scene, "path", settings);
    let b = render(scene, "path:simd=false", settings);
    assert!(a.data == b.data, "{what}: the kernel's image differs from the scalar tracer's");
    let mut s = settings.clone();
    s.threads = 3;
    assert!(render(scene, "path", &s).data == a.data, "{what}: the kernel's image depends on the thread count");
}

#[test]
fn out_of_scope_scenes_fall_back() {
    // Two environments (a lane adds what its escaped ray sees as one): the scalar tracer's.
    let dir = std::env::temp_dir().join(format!("svetlo-simd-scope-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("two-envs.xml");
    let env = r#"<emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>"#;
    std::fs::write(&path, std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap().replace("</scene>", &format!("{env}{env}</scene>"))).unwrap();
    let scene = load(&path, &[], 16);
    assert_eq!(scene.environment_lights.len(), 2);
    assert!(SimdKernel::new(&scene, &RenderSettings::from_scene(&scene)).is_none(), "two environments should take the scalar tracer");
    // Spheres (a mirror and a glass one; caustic.xml's glass sphere): the kernel, packets
    // (a few spheres are tested on every lane beside the packet tree's triangles).
    for name in ["caustic.xml", "cornell-spheres.xml"] {
        let scene = load(&repo_scene(name), &[], 16);
        let k = SimdKernel::new(&scene, &RenderSettings::from_scene(&scene)).unwrap_or_else(|| panic!("{name} should qualify"));
        assert!(k.uses_packets(), "{name}: a few spheres go with the packets");
    }
    assert!(svetlo::methods::by_name("path:simd=maybe").is_err());
    assert!(svetlo::methods::by_name("path:fast=true").is_err());
}

/// A bumpy floor of 2 x `n` x `n` triangles under a quad light (a Lambertian material, or
/// where `mask`, a mask around it), 40 x 40 pixels.
fn bumpy_floor(n: u32, mask: bool) -> Scene {
    use glam::{Mat4, Vec3};
    use svetlo::bsdf::Material;
    use svetlo::camera::Camera;
    use svetlo::geometry::{shapes, Geometry, TriangleMesh};
    use svetlo::scene::SceneBuilder;
    use svetlo::spectrum::Rgb;
    use svetlo::texture::Texture;
    let mut floor = TriangleMesh::default();
    for j in 0..=n {
        for i in 0..=n {
            let (x, z) = (i as f32 / n as f32 * 4.0 - 2.0, j as f32 / n as f32 * 4.0 - 2.0);
            floor.positions.push(Vec3::new(x, 0.05 * (7.0 * x).sin() * (5.0 * z).cos(), z));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let v = |a: u32, b: u32| (j + b) * (n + 1) + i + a;
            floor.indices.push([v(0, 0), v(0, 1), v(1, 0)]);
            floor.indices.push([v(1, 0), v(0, 1), v(1, 1)]);
        }
    }
    let mut b = SceneBuilder::new();
    let diffuse = Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.7)) };
    let white = b.add_material(if mask { Material::Mask { opacity: Texture::Constant(Rgb::splat(0.5)), inner: Box::new(diffuse) } } else { diffuse });
    b.add_shape(Geometry::Mesh(floor), white, None, "floor").expect("floor");
    // The rectangle faces +z; turned to face down, 1.5 above the floor.
    let mut lamp = shapes::rectangle();
    let to_lamp = Mat4::from_translation(Vec3::new(0.0, 1.5, 0.0)) * Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2) * Mat4::from_scale(Vec3::splat(0.5));
    for p in &mut lamp.positions {
        *p = to_lamp.transform_point3(*p);
    }
    b.add_shape(Geometry::Mesh(lamp), white, Some(Texture::Constant(Rgb::splat(8.0))), "lamp").expect("lamp");
    let to_world = svetlo::io::mitsuba::look_at(Vec3::new(0.0, 2.0, -3.0), Vec3::ZERO, Vec3::Y).expect("camera");
    b.set_camera(Camera::pinhole(to_world, 50.0, 40, 40));
    b.build().expect("scene")
}

/// Past 20 000 triangles (a floor of 24 200) the kernel still traces packets, but checks their
/// ties, so that its image is the one of single rays, the scalar tracer's, bit for bit; past
/// 40 000 (a floor of 51 200) it traces single rays through the scene's BVH (packets of
/// incoherent rays pay for the union of eight walks there). Both take the kernel with a
/// material other than a Lambertian one too (see
/// `a_large_packet_scene_takes_the_kernel_on_its_first_render` and
/// `a_single_ray_scene_takes_the_kernel_on_its_first_render`).
#[test]
fn large_scenes_keep_the_single_ray_image() {
    for (n, packets) in [(110u32, true), (160, false)] {
        let scene = bumpy_floor(n, false);
        let mut s = RenderSettings::from_scene(&scene);
        s.spp = 4;
        s.max_depth = 4;
        let what = format!("a floor of {} triangles", 2 * n * n);
        let k = SimdKernel::new(&scene, &s).expect("the scene qualifies");
        assert_eq!(k.uses_packets(), packets, "{what}: packets");
        assert!(render(&scene, "path", &s).mean().max_component() > 0.0, "the lamp lights the floor");
        compare(&scene, &s, &what);
        if avx2() {
            assert!(render(&scene, "path", &s).data == render(&scene, "path:simd=false", &s).data, "{what}: not the scalar tracer's image");
        }
        // Not Lambertian there: the kernel all the same, packets or single rays as without.
        let masked = SimdKernel::new(&bumpy_floor(n, true), &s).unwrap_or_else(|| panic!("{what} with a mask: the kernel"));
        assert_eq!(masked.uses_packets(), packets, "{what} with a mask: packets");
    }
    let small = load(&repo_scene("cornell-box.xml"), &[], 16);
    assert!(SimdKernel::new(&small, &RenderSettings::from_scene(&small)).expect("qualifies").uses_packets(), "the Cornell box should trace packets");
}

/// AOVs and `--lpe` in the kernel's lanes: each lane steps its path's automata as the scalar
/// tracer's camera walk does (custom labels, counted repetition, the vertex form, a restricted
/// beauty), so every layer and the beauty equal the scalar tracer's: bit for bit when the
/// kernel traces single rays (the scalar tracer's hits), up to the packet tracer's rounding
/// otherwise; and whatever the thread count.
#[test]
fn aovs_in_lanes_match_scalar() {
    use std::sync::Arc;
    use svetlo::lpe::AovSet;
    if !avx2() {
        eprintln!("SKIPPED: no AVX2, the kernel falls back to the scalar tracer");
        return;
    }
    let scene = load(&repo_scene("cornell-box.xml"), &[], 40);
    let list: Vec<(String, String)> = [
        ("emit", "C L"),
        ("direct", "C D L"),
        ("indirect", "C D .+ L"),
        ("floor", "C 'floor' L"),
        ("via_floor", "C .* 'floor' .* L"),
        ("two", "C .{2} L"),
        ("refl", "C <R.> <R.>+ L"),
        ("lecture", "L D* E"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    for (beauty, sampler) in [(None, svetlo::sampling::SamplerKind::Independent), (Some("C D{1,2} L"), svetlo::sampling::SamplerKind::Sobol)] {
        let mut set = AovSet::compile(&list, beauty).expect("expressions");
        assert!(set.bind(&scene).is_empty());
        let mut s = RenderSettings::from_scene(&scene);
        s.sampler = sampler;
        s.spp = 6;
        s.seed = 9;
        s.max_depth = 5;
        s.lpe = Some(Arc::new(set));
        let what = format!("AOVs, beauty {beauty:?}, {sampler:?}");
        let mut k = SimdKernel::new(&scene, &s).expect("the scene qualifies with AOVs");
        k.use_single_rays(&scene);
        let single = k.render(&scene, &s, &Progress::new()).expect("render");
        let packets = svetlo::methods::by_name("path").unwrap().render(&scene, &s, &Progress::new()).expect("render");
        let scalar = svetlo::methods::by_name("path:simd=false").unwrap().render(&scene, &s, &Progress::new()).expect("render");
        assert_eq!(single.layer_names(), scalar.layer_names());
        assert!(single.image().data == scalar.image().data, "{what}: beauty differs from the scalar tracer's");
        let mut lit = 0;
        for (name, img) in scalar.layer_images() {
            let a = single.layer(&name).expect("layer");
            assert!(a.data == img.data, "{what}: layer {name} differs from the scalar tracer's");
            let b = packets.layer(&name).expect("layer");
            let close =
                b.data.iter().zip(&img.data).filter(|(x, y)| (0..3).all(|c| (x[c] - y[c]).abs() <= 1e-4 * x[c].abs().max(y[c].abs()).max(1e-3))).count();
            assert!(close as f64 >= 0.99 * img.data.len() as f64, "{what}: packets: layer {name} only {close} pixels agree");
            lit += (img.mean().max_component() > 0.0) as usize;
        }
        // Every layer but the one-bounce vertex form's partner classes sees light.
        assert!(lit >= 7, "{what}: only {lit} layers are lit");
        if beauty.is_some() {
            // The restricted beauty is not the whole image.
            let full = svetlo::methods::by_name("path").unwrap().render(&scene, &RenderSettings { lpe: None, ..s.clone() }, &Progress::new()).expect("render");
            assert!(packets.image().mean()[1] < 0.95 * full.image().mean()[1], "{what}: --lpe did not restrict the beauty");
        }
        let mut s3 = s.clone();
        s3.threads = 3;
        let t3 = svetlo::methods::by_name("path").unwrap().render(&scene, &s3, &Progress::new()).expect("render");
        for (name, img) in packets.layer_images() {
            assert!(t3.layer(&name).expect("layer").data == img.data, "{what}: layer {name} depends on the thread count");
        }
    }
}

/// Lights other than constant mesh lights: each lane samples them through their own
/// `Light::sample_li` (point, spot, directional, a constant environment, an environment map)
/// and an escaped ray adds the environment under the scalar tracer's MIS weight, so the image
/// and the layers equal the scalar tracer's (bit for bit with single rays).
#[test]
fn every_light_type_matches_scalar() {
    use std::sync::Arc;
    use svetlo::film::Image;
    use svetlo::lpe::AovSet;
    use svetlo::spectrum::Rgb;
    let dir = std::env::temp_dir().join(format!("svetlo-simd-lights-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A small environment map with a bright patch.
    let env: Vec<Rgb> = (0..32).map(|i| if i == 9 { Rgb::new(40.0, 30.0, 20.0) } else { Rgb::new(0.2 + 0.01 * i as f32, 0.3, 0.4) }).collect();
    svetlo::io::image_io::write_exr(&dir.join("env.exr"), &Image::new(8, 4, env)).unwrap();
    let base = std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap();
    let emitters = [
        ("point", r#"<emitter type="point"><point name="position" x="0.3" y="1.6" z="0.4"/><rgb name="intensity" value="3, 2.5, 2"/></emitter>"#),
        (
            "spot",
            r#"<emitter type="spot"><transform name="to_world"><lookat origin="-0.5, 1.8, 0.5" target="0, 0, -0.2" up="0, 0, 1"/></transform><rgb name="intensity" value="6"/><float name="cutoff_angle" value="30"/></emitter>"#,
        ),
        ("directional", r#"<emitter type="directional"><vector name="direction" x="0.1" y="-0.3" z="-1"/><rgb name="irradiance" value="1.5"/></emitter>"#),
        ("constant", r#"<emitter type="constant"><rgb name="radiance" value="0.4, 0.5, 0.6"/></emitter>"#),
        ("envmap", r#"<emitter type="envmap"><string name="filename" value="env.exr"/></emitter>"#),
    ];
    for (name, xml) in emitters {
        let path = dir.join(format!("{name}.xml"));
        std::fs::write(&path, base.replace("</scene>", &format!("{xml}\n</scene>"))).unwrap();
        let scene = load(&path, &[], 32);
        for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
            let mut s = RenderSettings::from_scene(&scene);
            s.sampler = sampler;
            s.spp = 4;
            s.seed = 17;
            s.max_depth = 5;
            compare(&scene, &s, &format!("cornell-box with a {name} light, {sampler:?}"));
        }
        // The paths' events: the environment as B, the other lights as L.
        let list: Vec<(String, String)> =
            [("bg", "C B"), ("bg_bounce", "C .+ B"), ("direct", "C D L"), ("all", "C .* [LB]")].iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
        let mut set = AovSet::compile(&list, None).unwrap();
        assert!(set.bind(&scene).is_empty());
        let mut s = RenderSettings::from_scene(&scene);
        s.spp = 4;
        s.max_depth = 5;
        s.lpe = Some(Arc::new(set));
        if !avx2() {
            continue;
        }
        let mut k = SimdKernel::new(&scene, &s).expect("qualifies");
        k.use_single_rays(&scene);
        let a = k.render(&scene, &s, &Progress::new()).expect("render");
        let b = svetlo::methods::by_name("path:simd=false").unwrap().render(&scene, &s, &Progress::new()).expect("render");
        for (layer, img) in b.layer_images() {
            assert!(a.layer(&layer).expect("layer").data == img.data, "{name}: layer {layer} differs from the scalar tracer's");
        }
        let background = name == "constant" || name == "envmap";
        let seen = |l: &str| b.layer(l).unwrap().mean().max_component() > 0.0;
        assert_eq!(seen("bg") || seen("bg_bounce"), background, "{name}: the environment's light (B) in the layers");
        // Every light lights the box: more than the ceiling light alone.
        let plain = load(&repo_scene("cornell-box.xml"), &[], 32);
        let lit = render(&scene, "path", &RenderSettings { lpe: None, ..s.clone() }).mean().max_component();
        let unlit = render(&plain, "path", &RenderSettings { lpe: None, ..s.clone() }).mean().max_component();
        assert!(lit > unlit * 1.01, "{name}: {lit} vs {unlit} without it");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Puts the material `id` on the shape `shape` of the Cornell box's XML (in place of its first
/// `<ref id="white"/>`).
fn with_material(xml: &str, shape: &str, id: &str) -> String {
    let at = xml.find(&format!(r#"id="{shape}""#)).unwrap_or_else(|| panic!("no shape {shape}"));
    let r = at + xml[at..].find(r#"<ref id="white"/>"#).unwrap_or_else(|| panic!("{shape} has no white"));
    format!("{}<ref id=\"{id}\"/>{}", &xml[..r], &xml[r + r#"<ref id="white"/>"#.len()..])
}

/// Every BSDF svetlo reads renders in the kernel (lane by lane through its scalar code) to the
/// scalar tracer's image, bit for bit with single rays, for both samplers; the layers of
/// glossy, singular and transmitting paths too. The boxes and the back wall wear the BSDF; a
/// point light (delta: no MIS) and a constant environment (seen through the open side) join
/// the ceiling light, so that emitters are met after delta, glossy and diffuse bounces alike.
#[test]
fn every_bsdf_matches_scalar() {
    use std::sync::Arc;
    use svetlo::lpe::AovSet;
    let dir = std::env::temp_dir().join(format!("svetlo-simd-bsdfs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap();
    let diffuse = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.5, 0.7"/></bsdf>"#;
    let bsdfs: Vec<(&str, String)> = [
        ("conductor", r#"<bsdf type="conductor"><string name="material" value="Au"/></bsdf>"#.to_string()),
        ("roughconductor", r#"<bsdf type="roughconductor"><string name="material" value="Cu"/><float name="alpha" value="0.2"/></bsdf>"#.into()),
        (
            "ggx roughconductor",
            r#"<bsdf type="roughconductor"><string name="distribution" value="ggx"/><string name="material" value="Au"/><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf>"#.into(),
        ),
        (
            "anisotropic roughconductor",
            r#"<bsdf type="roughconductor"><string name="distribution" value="beckmann"/><float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.3"/></bsdf>"#.into(),
        ),
        ("dielectric", r#"<bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>"#.into()),
        ("roughdielectric", r#"<bsdf type="roughdielectric"><float name="alpha" value="0.15"/><float name="int_ior" value="1.5"/></bsdf>"#.into()),
        ("thindielectric", r#"<bsdf type="thindielectric"><float name="int_ior" value="1.5"/></bsdf>"#.into()),
        ("glass", r#"<bsdf type="glass"/>"#.into()),
        ("plastic", r#"<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.2, 0.4, 0.6"/></bsdf>"#.into()),
        ("roughplastic", r#"<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.6, 0.3, 0.2"/><float name="alpha" value="0.1"/></bsdf>"#.into()),
        (
            "ggx roughplastic",
            r#"<bsdf type="roughplastic"><string name="distribution" value="ggx"/><rgb name="diffuse_reflectance" value="0.2, 0.5, 0.3"/><float name="alpha" value="0.25"/><boolean name="nonlinear" value="true"/></bsdf>"#.into(),
        ),
        ("phong", r#"<bsdf type="phong"><float name="exponent" value="20"/></bsdf>"#.into()),
        ("blinnphong", r#"<bsdf type="blinnphong"><float name="exponent" value="40"/></bsdf>"#.into()),
        ("cooktorrance", r#"<bsdf type="cooktorrance"><float name="alpha" value="0.2"/></bsdf>"#.into()),
        ("roughdiffuse", r#"<bsdf type="roughdiffuse"><float name="alpha" value="0.4"/></bsdf>"#.into()),
        ("ward", r#"<bsdf type="ward"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf>"#.into()),
        ("twosided conductor", r#"<bsdf type="twosided"><bsdf type="roughconductor"><float name="alpha" value="0.1"/></bsdf></bsdf>"#.into()),
        ("twosided diffuse and conductor", format!(r#"<bsdf type="twosided">{diffuse}<bsdf type="conductor"/></bsdf>"#)),
        ("mask", format!(r#"<bsdf type="mask"><float name="opacity" value="0.4"/>{diffuse}</bsdf>"#)),
        ("blendbsdf", format!(r#"<bsdf type="blendbsdf"><float name="weight" value="0.3"/><bsdf type="conductor"/>{diffuse}</bsdf>"#)),
        (
            "principled",
            r#"<bsdf type="principled"><rgb name="base_color" value="0.8, 0.3, 0.2"/><float name="metallic" value="0.3"/><float name="roughness" value="0.4"/><float name="spec_trans" value="0.3"/></bsdf>"#.into(),
        ),
        ("principledthin", r#"<bsdf type="principledthin"><rgb name="base_color" value="0.2, 0.6, 0.3"/><float name="roughness" value="0.3"/></bsdf>"#.into()),
        (
            "bumpmap",
            r#"<bsdf type="bumpmap"><texture type="checkerboard"><rgb name="color0" value="0"/><rgb name="color1" value="1"/></texture><float name="scale" value="0.05"/><bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf></bsdf>"#.into(),
        ),
    ]
    .into_iter()
    .collect();
    let lights = r#"<emitter type="point"><point name="position" x="0.3" y="1.6" z="0.4"/><rgb name="intensity" value="3, 2.5, 2"/></emitter>
        <emitter type="constant"><rgb name="radiance" value="0.3, 0.4, 0.5"/></emitter>"#;
    for (name, bsdf) in &bsdfs {
        let mut xml = base.replace("<!-- A rectangle", &format!("{}\n    <!-- A rectangle", bsdf.replacen("<bsdf ", r#"<bsdf id="test" "#, 1)));
        for shape in ["back", "short-box", "tall-box"] {
            xml = with_material(&xml, shape, "test");
        }
        let path = dir.join(format!("{}.xml", name.replace(' ', "_")));
        std::fs::write(&path, xml.replace("</scene>", &format!("{lights}\n</scene>"))).unwrap();
        let scene = load(&path, &[], 24);
        for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
            let mut s = RenderSettings::from_scene(&scene);
            s.sampler = sampler;
            s.spp = 4;
            s.seed = 23;
            s.max_depth = 7;
            s.rr_depth = 3;
            // `compare` checks that the kernel takes the scene (no fallback to the scalar tracer).
            // Scenes whose paths cross surfaces (dielectrics, masks, principled with
            // transmission) trace packets too; where a path inside a box meets its bottom and
            // the floor at once, the tie takes the scene BVH's triangle: the scalar tracer's
            // image bit for bit (without, the packet images came out 0.2-0.3 % darker).
            let crosses = ["dielectric", "roughdielectric", "thindielectric", "glass", "mask", "principled", "principledthin"].contains(name);
            let k = SimdKernel::new(&scene, &s).expect("kernel");
            assert!(k.uses_packets(), "{name}: a small scene traces packets");
            compare(&scene, &s, &format!("cornell-box of {name}, {sampler:?}"));
            if crosses && avx2() {
                let (a, b) = (render(&scene, "path", &s), render(&scene, "path:simd=false", &s));
                assert!(a.data == b.data, "{name}: the packet image is the scalar tracer's bit for bit");
            }
        }
        if !["conductor", "roughdielectric", "dielectric", "mask", "blendbsdf"].contains(name) || !avx2() {
            continue;
        }
        // The paths' events at the BSDF: glossy, singular, transmitted, and a mask's none.
        let list: Vec<(String, String)> =
            [("glossy", "C .* G .* [LB]"), ("singular", "C S .* [LB]"), ("transmitted", "C .* <T.> .* [LB]"), ("direct", "C . [LB]"), ("all", "C .* [LB]")]
                .iter()
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect();
        let mut set = AovSet::compile(&list, None).expect("expressions");
        assert!(set.bind(&scene).is_empty());
        let mut s = RenderSettings::from_scene(&scene);
        s.spp = 4;
        s.max_depth = 7;
        s.lpe = Some(Arc::new(set));
        let mut k = SimdKernel::new(&scene, &s).expect("qualifies with AOVs");
        k.use_single_rays(&scene);
        let a = k.render(&scene, &s, &Progress::new()).expect("render");
        let b = svetlo::methods::by_name("path:simd=false").unwrap().render(&scene, &s, &Progress::new()).expect("render");
        assert!(a.image().data == b.image().data, "{name}: the beauty with AOVs differs from the scalar tracer's");
        for (layer, img) in b.layer_images() {
            assert!(a.layer(&layer).expect("layer").data == img.data, "{name}: layer {layer} differs from the scalar tracer's");
        }
        let seen = |l: &str| b.layer(l).unwrap().mean().max_component() > 0.0;
        match *name {
            "conductor" => assert!(seen("singular") && !seen("glossy") && !seen("transmitted"), "{name}: its layers"),
            "dielectric" => assert!(seen("singular") && seen("transmitted"), "{name}: its layers"),
            "roughdielectric" => assert!(seen("glossy") && seen("transmitted") && !seen("singular"), "{name}: its layers"),
            _ => assert!(seen("all") && seen("direct"), "{name}: its layers"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A normal or bump map over a Lambertian material is a lane case of the kernel (its
/// perturbed frame and shadowing term per lane, no `Bsdf` built): bsdf_spheres' bump- and
/// normal-mapped spheres (32k triangles: packets that check ties, an area light and an
/// environment) render the scalar tracer's image bit for bit on 1 and 2 threads, and a
/// Cornell box whose boxes and back wall wear the maps (diffuse bounces, emitters met after
/// them) agrees with it as `compare` asks, bit for bit with single rays, for both samplers.
#[test]
fn detail_over_lambertian_matches_scalar() {
    let Some(root) = shared() else { return };
    let spheres = root.join("mitsuba-data/tests/scenes/bsdf_spheres");
    for name in ["bumpmap", "normalmap"] {
        let scene = load(&spheres.join(format!("test_{name}_path.xml")), &[], 24);
        kernel_renders_scalar_image(&scene, name);
    }
    let tiles = root.join("mitsuba-data/common/textures/floor_tiles_bumpmap.png");
    let diffuse = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.5, 0.7"/></bsdf>"#;
    let maps = [
        (
            "normalmap",
            format!(
                r#"<bsdf type="normalmap"><texture name="normalmap" type="checkerboard"><rgb name="color0" value="0.8, 0.3, 0.7"/><rgb name="color1" value="0.2, 0.6, 0.9"/></texture>{diffuse}</bsdf>"#
            ),
        ),
        (
            "bumpmap",
            format!(
                r#"<bsdf type="bumpmap"><texture type="bitmap"><boolean name="raw" value="true"/><string name="filename" value="{}"/></texture><float name="scale" value="0.5"/>{diffuse}</bsdf>"#,
                tiles.display()
            ),
        ),
    ];
    let dir = std::env::temp_dir().join(format!("svetlo-simd-detail-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bsdf) in &maps {
        compare_cornell_box_wearing(&dir, name, bsdf, "{} over diffuse");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `scene` (3 spp, seed 5) qualifies for the kernel, and where it runs (AVX2) its image is the
/// scalar tracer's bit for bit on 1 and 2 threads.
fn kernel_renders_scalar_image(scene: &Scene, name: &str) {
    let s = RenderSettings { spp: 3, seed: 5, ..RenderSettings::from_scene(scene) };
    assert!(SimdKernel::new(scene, &s).is_some(), "{name}: the scene should qualify for the kernel");
    if !avx2() {
        return;
    }
    let want = render(scene, "path:simd=false", &s);
    assert!(want.mean().max_component() > 0.0, "{name}: lit");
    for threads in [1, 2] {
        let t = RenderSettings { threads, ..s.clone() };
        assert!(render(scene, "path", &t).data == want.data, "{name}, {threads} threads: not the scalar tracer's image");
    }
}

/// A Cornell box whose back wall and boxes wear `bsdf` (a `<bsdf>` element), written to
/// `dir`: the kernel agrees with the scalar tracer as `compare` asks (bit for bit with single
/// rays), for both samplers. `label` goes around the name in the message (`{}` its place).
fn compare_cornell_box_wearing(dir: &Path, name: &str, bsdf: &str, label: &str) {
    let base = std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap();
    let mut xml = base.replace("<!-- A rectangle", &format!("{}\n    <!-- A rectangle", bsdf.replacen("<bsdf ", r#"<bsdf id="test" "#, 1)));
    for shape in ["back", "short-box", "tall-box"] {
        xml = with_material(&xml, shape, "test");
    }
    let path = dir.join(format!("{}.xml", name.replace(' ', "_")));
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], 24);
    let what = label.replace("{}", name);
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let s = RenderSettings { sampler, spp: 4, seed: 29, max_depth: 6, rr_depth: 3, ..RenderSettings::from_scene(&scene) };
        compare(&scene, &s, &format!("cornell-box of {what}, {sampler:?}"));
    }
}

/// Rough conductors under normal and bump maps, and one of textured roughness, in the kernel
/// (`conductor_scatter`: the perturbed frame per lane, the conductor lanes in it, no `Bsdf`
/// built): bsdf_spheres' normal-mapped GGX spheres (constant and bitmap maps), the same
/// bitmap map over a Beckmann conductor, and the checkerboard-roughness Beckmann sphere
/// render the scalar tracer's image bit for bit on 1 and 2 threads; a Cornell box whose boxes
/// and back wall wear a bump-mapped Beckmann and a normal-mapped GGX conductor agrees with it
/// as `compare` asks, bit for bit with single rays, for both samplers.
#[test]
fn conductors_with_detail_or_textures_match_scalar() {
    let Some(root) = shared() else { return };
    let spheres = root.join("mitsuba-data/tests/scenes/bsdf_spheres");
    let dir = std::env::temp_dir().join(format!("svetlo-simd-conductors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The bitmap normal map over a Beckmann conductor: the GGX scene's XML with its paths made absolute.
    let ggx = std::fs::read_to_string(spheres.join("test_normalmap_roughconductor_path.xml")).unwrap();
    let beckmann = ggx
        .replace(r#"value="ggx""#, r#"value="beckmann""#)
        .replace(r#"value="../../../common""#, &format!(r#"value="{}""#, root.join("mitsuba-data/common").display()))
        .replace(r#"filename="fragments/"#, &format!(r#"filename="{}/fragments/"#, spheres.display()));
    assert!(beckmann.contains("beckmann"), "the scene names its distribution");
    let beckmann_path = dir.join("normalmap_beckmann.xml");
    std::fs::write(&beckmann_path, beckmann).unwrap();
    let names = ["normalmap_identity_roughconductor", "normalmap_roughconductor", "textured_roughconductor"];
    let paths = names.iter().map(|n| spheres.join(format!("test_{n}_path.xml"))).chain([beckmann_path]);
    for path in paths {
        let name = path.display().to_string();
        let scene = load(&path, &[], 24);
        kernel_renders_scalar_image(&scene, &name);
    }
    let tiles = root.join("mitsuba-data/common/textures/floor_tiles_bumpmap.png");
    let conductor = |d: &str| {
        format!(
            r#"<bsdf type="roughconductor"><string name="material" value="Cu"/><string name="distribution" value="{d}"/><float name="alpha" value="0.2"/></bsdf>"#
        )
    };
    let maps = [
        (
            "bumpmap over beckmann",
            format!(
                r#"<bsdf type="bumpmap"><texture type="bitmap"><boolean name="raw" value="true"/><string name="filename" value="{}"/></texture><float name="scale" value="0.5"/>{}</bsdf>"#,
                tiles.display(),
                conductor("beckmann")
            ),
        ),
        (
            "normalmap over ggx",
            format!(
                r#"<bsdf type="normalmap"><texture name="normalmap" type="checkerboard"><rgb name="color0" value="0.8, 0.3, 0.7"/><rgb name="color1" value="0.2, 0.6, 0.9"/></texture>{}</bsdf>"#,
                conductor("ggx")
            ),
        ),
    ];
    for (name, bsdf) in &maps {
        compare_cornell_box_wearing(&dir, name, bsdf, "{}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Textured `principled` and `principledthin` materials are a lane case of the kernel (the
/// model built in a lane's slot, no `Bsdf`; kept for the MIS weight at an emitter): bsdf_spheres'
/// three principled scenes (an area light and an environment) render the scalar tracer's image
/// bit for bit on 1 and 2 threads, and a Cornell box whose boxes and back wall are textured
/// principled (thin) materials (principled bounces, emitters met after them) agrees with it as
/// `compare` asks, bit for bit with single rays, for both samplers.
#[test]
fn principled_matches_scalar() {
    let Some(root) = shared() else { return };
    let spheres = root.join("mitsuba-data/tests/scenes/bsdf_spheres");
    for name in ["texturedprincipled1", "texturedprincipled2", "texturedprincipledthin"] {
        let scene = load(&spheres.join(format!("test_{name}_path.xml")), &[], 24);
        kernel_renders_scalar_image(&scene, name);
    }
    let checker = |name: &str, a: f32, b: f32| {
        format!(
            r#"<texture name="{name}" type="checkerboard"><transform name="to_uv"><scale x="4" y="4"/></transform><float name="color0" value="{a}"/><float name="color1" value="{b}"/></texture>"#
        )
    };
    let full = format!(
        r#"<bsdf type="principled"><rgb name="base_color" value="0.3, 0.6, 0.8"/><float name="roughness" value="0.3"/>{}{}{}{}<float name="spec_trans" value="0.2"/></bsdf>"#,
        checker("anisotropic", 0.1, 0.7),
        checker("metallic", 0.6, 0.1),
        checker("clearcoat", 0.8, 0.2),
        checker("sheen", 0.2, 0.9)
    );
    let thin = format!(
        r#"<bsdf type="principledthin"><rgb name="base_color" value="0.7, 0.2, 0.1"/>{}{}{}<float name="eta" value="1.33"/></bsdf>"#,
        checker("spec_trans", 0.2, 0.7),
        checker("diff_trans", 0.4, 1.4),
        checker("sheen", 0.1, 0.8)
    );
    let dir = std::env::temp_dir().join(format!("svetlo-simd-principled-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bsdf) in [("principled", &full), ("principledthin", &thin)] {
        compare_cornell_box_wearing(&dir, name, bsdf, "textured {}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A textured emitter in the kernel: sampled through its own `Light::sample_li`, its radiance
/// looked up where a path hits it (`AreaLight::l`), so the image and an emission layer equal
/// the scalar tracer's (bit for bit with single rays), with a glossy box that reflects it.
#[test]
fn textured_emitter_matches_scalar() {
    use std::sync::Arc;
    use svetlo::lpe::AovSet;
    let dir = std::env::temp_dir().join(format!("svetlo-simd-textured-light-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap();
    let textured = r#"<emitter type="area"><texture type="checkerboard" name="radiance"><rgb name="color0" value="17, 12, 4"/><rgb name="color1" value="3, 6, 9"/></texture></emitter>"#;
    let constant = r#"<emitter type="area">
            <rgb name="radiance" value="17, 12, 4"/>
        </emitter>"#;
    assert!(base.contains(constant), "the Cornell box's light");
    let glossy = r#"<bsdf type="roughconductor" id="test"><float name="alpha" value="0.1"/></bsdf>
    <!-- A rectangle"#;
    let xml = with_material(&base.replace(constant, textured).replacen("<!-- A rectangle", glossy, 1), "tall-box", "test");
    let path = dir.join("textured-light.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], 32);
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let mut s = RenderSettings::from_scene(&scene);
        s.sampler = sampler;
        s.spp = 4;
        s.max_depth = 5;
        compare(&scene, &s, &format!("cornell-box with a textured light, {sampler:?}"));
    }
    let plain = load(&repo_scene("cornell-box.xml"), &[], 32);
    let s = RenderSettings { spp: 4, max_depth: 5, ..RenderSettings::from_scene(&scene) };
    let (a, b) = (render(&scene, "path", &s).mean(), render(&plain, "path", &s).mean());
    assert!((a[2] - b[2]).abs() > 0.01 * b[2], "the texture changes the light: {a:?} vs {b:?}");
    if !avx2() {
        return;
    }
    let list: Vec<(String, String)> = [("emit", "C L"), ("glossy", "C G L"), ("all", "C .* L")].iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    let mut set = AovSet::compile(&list, None).expect("expressions");
    assert!(set.bind(&scene).is_empty());
    let s = RenderSettings { lpe: Some(Arc::new(set)), ..s };
    let mut k = SimdKernel::new(&scene, &s).expect("qualifies");
    k.use_single_rays(&scene);
    let a = k.render(&scene, &s, &Progress::new()).expect("render");
    let b = svetlo::methods::by_name("path:simd=false").unwrap().render(&scene, &s, &Progress::new()).expect("render");
    for (layer, img) in b.layer_images() {
        assert!(img.mean().max_component() > 0.0, "layer {layer} is lit");
        assert!(a.layer(&layer).expect("layer").data == img.data, "layer {layer} differs from the scalar tracer's");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The Cornell box with its tall box of glass (`dielectric`, IOR 1.5), written to `dir`; its
/// bottom lies on the floor, as in the repository's scene; `lift` raises the box.
fn glass_box_scene(dir: &Path, lift: f32, size: u32) -> Scene {
    std::fs::create_dir_all(dir).unwrap();
    let base = std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap();
    let bsdf = r#"<bsdf type="dielectric" id="glass"><float name="int_ior" value="1.5"/></bsdf>"#;
    let at = r#"<translate x="-0.335" y="0.6" z="-0.29"/>"#;
    assert!(base.contains(at), "the tall box's placement");
    let xml = with_material(&base.replace("<!-- A rectangle", &format!("{bsdf}\n    <!-- A rectangle")), "tall-box", "glass")
        .replace(at, &format!(r#"<translate x="-0.335" y="{}" z="-0.29"/>"#, 0.6 + lift));
    let path = dir.join(format!("glass-box-{lift}.xml"));
    std::fs::write(&path, xml).unwrap();
    load(&path, &[], size)
}

/// Rays from points of the glass box's faces, into the box and out of it, through the packet
/// tracer's tree and the scene's BVH: they disagree only where two triangles are hit at the
/// same distance (the box's bottom lies on the floor: a ray inside the glass going down meets
/// both), and `PacketBvh::intersect_ties` flags every such lane, which the kernel then traces
/// through the scene's BVH. With the box lifted off the floor no ray disagrees.
#[test]
fn glass_box_rays_agree_with_scene_bvh() {
    use glam::Vec3;
    use svetlo::accel::packet::{PacketBvh, Rays8, LANES};
    use svetlo::geometry::ray::offset_ray_origin;
    use svetlo::geometry::{Geometry, Ray};
    let dir = std::env::temp_dir().join(format!("svetlo-simd-glass-rays-{}", std::process::id()));
    for (lift, resting) in [(0.0, true), (1e-3, false)] {
        let scene = glass_box_scene(&dir, lift, 16);
        // The kernel's numbering: each shape's triangles in turn.
        let mut tris = Vec::new();
        let mut first = Vec::new();
        let mut tall = 0..0;
        for s in &scene.shapes {
            first.push(tris.len() as u32);
            let Geometry::Mesh(m) = &*s.geometry else { panic!("{}: not a mesh", s.name) };
            if s.name == "tall-box" {
                tall = tris.len()..tris.len() + m.triangle_count();
            }
            tris.extend((0..m.triangle_count()).map(|t| m.vertices(t)));
        }
        assert_eq!(tall.len(), 12, "the tall box's triangles");
        let bvh = PacketBvh::build(&tris);
        let mut rng = svetlo::sampling::Pcg32::new(3, 7);
        let (mut rays, mut differ, mut flagged, mut inward) = (0u32, 0u32, 0u32, 0u32);
        for _ in 0..20_000 {
            let mut r = Rays8::default();
            for l in 0..LANES {
                let [p0, p1, p2] = tris[tall.start + (rng.next_u32() % 12) as usize];
                let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let p = p0 + (p1 - p0) * u + (p2 - p0) * v;
                let ng = (p1 - p0).cross(p2 - p0).normalize();
                let d = loop {
                    let d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
                    let len = d.length();
                    if len > 1e-3 && len <= 1.0 {
                        break d / len;
                    }
                };
                // Off the face to the side the ray leaves by, as the tracers spawn their rays.
                let o = offset_ray_origin(p, ng, d);
                inward += (d.dot(ng) < 0.0) as u32;
                for k in 0..3 {
                    r.o[k][l] = o[k];
                    r.d[k][l] = d[k];
                }
                r.t_max[l] = f32::INFINITY;
            }
            let (h, ties) = bvh.intersect_ties(&r, 0xff);
            let blocked = bvh.occluded(&Rays8 { t_max: [1.0; LANES], ..r }, 0xff);
            for l in 0..LANES {
                rays += 1;
                let ray = Ray::new(Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]), Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]));
                let want = scene.accel.intersect(&ray);
                let want_prim = want.map_or(u32::MAX, |w| first[w.shape as usize] + w.prim);
                let tied = ties & (1 << l) != 0;
                flagged += tied as u32;
                if want_prim != h.prim[l] {
                    differ += 1;
                    assert!(tied, "lift {lift}: the trees disagree ({} vs {want_prim}) on a lane not flagged: {ray:?}", h.prim[l]);
                    // A tie: the same distance up to the test's rounding.
                    let t = want.map_or(f32::INFINITY, |w| w.t);
                    assert!((h.t[l] - t).abs() <= 1e-6 * t, "lift {lift}: not a tie: {} vs {t}", h.t[l]);
                } else if want_prim != u32::MAX {
                    let w = want.unwrap();
                    assert_eq!((h.t[l], h.b1[l], h.b2[l]), (w.t, w.b1, w.b2), "lift {lift}: the same triangle, other numbers");
                }
                let short = Ray { t_max: 1.0, ..ray };
                assert_eq!(blocked & (1 << l) != 0, scene.accel.occluded(&short), "lift {lift}: occlusion of {short:?}");
            }
        }
        println!("lift {lift}: {rays} rays ({inward} into the box), {differ} hit another triangle than the scene's BVH, {flagged} flagged as ties");
        assert!(inward > rays / 3, "rays into the box and out of it");
        if resting {
            // The bottom on the floor: some rays inside meet both; the packet tree's order kept
            // the floor (the difference that darkened the glass box's image).
            assert!(differ > 10, "lift {lift}: {differ} disagreements: the coplanar faces should tie");
        } else {
            assert_eq!(differ, 0, "lift {lift}: the trees disagree without coplanar faces");
        }
        // Flagged: the lanes inside the box that go down onto its bottom (with the floor
        // beneath it), and few others.
        if resting {
            assert!(flagged >= differ && flagged < rays / 10, "lift {lift}: {flagged} of {rays} lanes flagged");
        } else {
            assert!(flagged < rays / 1000, "lift {lift}: {flagged} of {rays} lanes flagged without coplanar faces");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The Cornell box with a glass box traced as packets (ties traced again through the scene's
/// BVH): the scalar tracer's image bit for bit, for both samplers. (Before the ties were
/// resolved its mean came out 0.2-0.3 % below the scalar tracer's.)
#[test]
fn glass_box_packets_match_scalar() {
    if !avx2() {
        eprintln!("SKIPPED: no AVX2, the kernel falls back to the scalar tracer");
        return;
    }
    let dir = std::env::temp_dir().join(format!("svetlo-simd-glass-image-{}", std::process::id()));
    let scene = glass_box_scene(&dir, 0.0, 48);
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let mut s = RenderSettings::from_scene(&scene);
        s.sampler = sampler;
        s.spp = 32;
        s.seed = 29;
        let k = SimdKernel::new(&scene, &s).expect("the scene qualifies");
        assert!(k.uses_packets(), "a small scene with glass traces packets");
        let a = k.render(&scene, &s, &Progress::new()).expect("render").image();
        let b = render(&scene, "path:simd=false", &s);
        let (ma, mb) = (a.mean(), b.mean());
        let exact = a.data.iter().zip(&b.data).filter(|(x, y)| x == y).count();
        println!("glass box, {sampler:?}: {exact}/{} pixels bit-identical; means {ma:?} vs {mb:?}", a.data.len());
        assert!(a.data == b.data, "{sampler:?}: the packet image differs from the scalar tracer's: means {ma:?} vs {mb:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Spheres in the kernel: met by packets (`PacketSpheres`, every sphere on every lane after
/// the packet tree's triangles; unsure lanes through the scene's BVH), shaded from the
/// scene's own surface record of the hit (a diffuse, a checkerboard-textured, a bump-mapped
/// rough conductor, the mirror, the glass and a black emitting sphere), the emitting sphere
/// sampled through its `sample_li` (the cone it subtends) and weighted by its `pdf_li`
/// where a path hits it, beside the mesh light: the image, and layers that tell the sphere
/// light's and the mesh light's paths apart, are the scalar tracer's bit for bit, with either
/// sampler and any thread count.
#[test]
fn spheres_match_scalar() {
    use std::sync::Arc;
    use svetlo::lpe::AovSet;
    let dir = std::env::temp_dir().join(format!("svetlo-simd-spheres-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(repo_scene("cornell-spheres.xml")).unwrap();
    let spheres = r#"<shape type="sphere" id="matte"><point name="center" x="0.55" y="1.2" z="-0.5"/><float name="radius" value="0.25"/>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.6, 0.7"/></bsdf></shape>
        <shape type="sphere" id="checked"><point name="center" x="-0.6" y="1.25" z="0.3"/><float name="radius" value="0.2"/>
            <bsdf type="twosided"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.1, 0.2, 0.8"/><rgb name="color1" value="0.9, 0.8, 0.1"/></texture></bsdf></bsdf></shape>
        <shape type="sphere" id="bumpy"><point name="center" x="-0.05" y="0.2" z="0.55"/><float name="radius" value="0.2"/>
            <bsdf type="bumpmap"><texture type="checkerboard"><rgb name="color0" value="0"/><rgb name="color1" value="1"/></texture><float name="scale" value="0.05"/>
                <bsdf type="roughconductor"><string name="material" value="Cu"/><float name="alpha" value="0.15"/></bsdf></bsdf></shape>
        <shape type="sphere" id="orb"><point name="center" x="0.1" y="1.45" z="0.1"/><float name="radius" value="0.12"/>
            <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
            <emitter type="area"><rgb name="radiance" value="6, 9, 14"/></emitter></shape>
"#;
    let path = dir.join("spheres.xml");
    std::fs::write(&path, base.replace("</scene>", &format!("{spheres}\n</scene>"))).unwrap();
    let scene = load(&path, &[], 32);
    assert_eq!(scene.shapes.iter().filter(|s| matches!(&*s.geometry, svetlo::geometry::Geometry::Sphere(_))).count(), 6, "six analytic spheres");
    assert_eq!(scene.lights.len(), 2, "the mesh light and the sphere light");
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let mut s = RenderSettings::from_scene(&scene);
        s.sampler = sampler;
        s.spp = 4;
        s.seed = 29;
        s.max_depth = 6;
        s.rr_depth = 3;
        let k = SimdKernel::new(&scene, &s).expect("a scene of spheres qualifies");
        assert!(k.uses_packets(), "six spheres go with the packets");
        // A sphere light: several packets a tile, their lanes' layers and sums kept apart.
        assert!(k.packets_a_tile() > 1, "a sphere light steps several packets a tile");
        // The kernel (both builds, single rays) against the scalar tracer: the same bits, at any thread count.
        compare_exact(&scene, &s, &format!("cornell-spheres with more spheres, {sampler:?}"));
    }
    if !avx2() {
        let _ = std::fs::remove_dir_all(&dir);
        return;
    }
    // The paths' events on spheres: each light's emission found and sampled, the glossy bumpy
    // sphere, the textured one, and the singular mirror and glass.
    let list: Vec<(String, String)> = [
        ("orb", "C .* 'orb'"),
        ("orb_direct", "C D 'orb'"),
        ("lamp", "C .* 'light'"),
        ("glossy", "C .* G .* L"),
        ("checked", "C .* 'checked' .* L"),
        ("singular", "C S .* L"),
        ("all", "C .* L"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    let mut set = AovSet::compile(&list, None).expect("expressions");
    assert!(set.bind(&scene).is_empty());
    let s = RenderSettings { spp: 4, max_depth: 6, lpe: Some(Arc::new(set)), ..RenderSettings::from_scene(&scene) };
    let k = SimdKernel::new(&scene, &s).expect("qualifies with AOVs");
    assert!(k.packets_a_tile() > 1, "the AOV layers of several packets a tile");
    let a = k.render(&scene, &s, &Progress::new()).expect("render");
    let b = svetlo::methods::by_name("path:simd=false").unwrap().render(&scene, &s, &Progress::new()).expect("render");
    let t3 = k.render(&scene, &RenderSettings { threads: 3, ..s.clone() }, &Progress::new()).expect("render");
    assert!(a.image().data == b.image().data, "the beauty with AOVs differs from the scalar tracer's");
    assert_eq!(a.layer_names(), b.layer_names());
    for (layer, img) in b.layer_images() {
        assert!(img.mean().max_component() > 0.0, "layer {layer} is lit");
        assert!(a.layer(&layer).expect("layer").data == img.data, "layer {layer} differs from the scalar tracer's");
        assert!(t3.layer(&layer).expect("layer").data == img.data, "layer {layer} depends on the thread count");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An SDF grid (Mitsuba's various_shapes test scene: a voxel torus among meshed shapes under
/// a constant environment) in the kernel: the scene's surface record of a grid hit, so the
/// scalar tracer's image bit for bit.
#[test]
fn sdf_grid_matches_scalar() {
    let Some(root) = shared() else { return };
    let scene = load(&root.join("mitsuba-data/tests/scenes/various_shapes/test_various_shapes_path.xml"), &[], 48);
    assert!(scene.shapes.iter().any(|s| matches!(&*s.geometry, svetlo::geometry::Geometry::SdfGrid(_))), "the scene has an SDF grid");
    let s = RenderSettings { spp: 4, max_depth: 4, seed: 31, ..RenderSettings::from_scene(&scene) };
    assert!(!SimdKernel::new(&scene, &s).expect("qualifies").uses_packets(), "a grid is met through the scene's BVH");
    compare(&scene, &s, "various_shapes with an SDF grid");
    if avx2() {
        assert!(render(&scene, "path", &s).data == render(&scene, "path:simd=false", &s).data, "the kernel's image differs from the scalar tracer's");
    }
}

/// The Cornell box with spheres cut by its triangles and by each other: a sphere light sunk
/// into the short box's top, a sphere half in the back wall, one touching the tall box's
/// side and the floor, two overlapping ones (a rough conductor and a diffuse one).
fn sphere_box_scene(dir: &Path, size: u32, extra_spheres: usize) -> Scene {
    std::fs::create_dir_all(dir).unwrap();
    let base = std::fs::read_to_string(repo_scene("cornell-box.xml")).unwrap();
    let sphere = |id: &str, c: [f32; 3], r: f32, inner: &str| {
        format!(
            r#"<shape type="sphere" id="{id}"><point name="center" x="{}" y="{}" z="{}"/><float name="radius" value="{r}"/>{inner}</shape>"#,
            c[0], c[1], c[2]
        )
    };
    let diffuse = |c: &str| format!(r#"<bsdf type="diffuse"><rgb name="reflectance" value="{c}"/></bsdf>"#);
    let mut xml = [
        // The short box's top is at y = 0.6, its center at (0.33, 0.37).
        sphere(
            "sunk-light",
            [0.33, 0.6, 0.37],
            0.12,
            r#"<bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf><emitter type="area"><rgb name="radiance" value="12, 10, 6"/></emitter>"#,
        ),
        sphere("in-wall", [0.5, 1.3, -1.0], 0.3, &diffuse("0.2, 0.5, 0.8")),
        // The tall box's corner region: its faces lie within 0.3 * sqrt(2) of (-0.335, -0.29).
        sphere("on-floor", [-0.72, 0.2, 0.25], 0.2, &diffuse("0.8, 0.6, 0.2")),
        sphere("rough", [-0.3, 1.5, 0.3], 0.22, r#"<bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.2"/></bsdf>"#),
        sphere("overlap", [-0.1, 1.55, 0.45], 0.18, &diffuse("0.3, 0.8, 0.3")),
    ]
    .join("\n");
    for i in 0..extra_spheres {
        xml += &sphere(&format!("bead{i}"), [-0.9 + 0.1 * i as f32, 1.9, 0.8], 0.04, &diffuse("0.5, 0.5, 0.5"));
    }
    let path = dir.join(format!("sphere-box-{extra_spheres}.xml"));
    std::fs::write(&path, base.replace("</scene>", &format!("{xml}\n</scene>"))).unwrap();
    load(&path, &[], size)
}

/// Rays from points on the spheres and the boxes of `sphere_box_scene`, traced as the
/// kernel does (packet tree with its tie check, then `PacketSpheres`), against the scene's
/// BVH: every lane not flagged (tied triangle, unsure sphere) has the scene BVH's shape,
/// primitive, distance and barycentrics bit for bit, and its occlusion; few are flagged.
#[test]
fn sphere_packet_rays_agree_with_scene_bvh() {
    use glam::Vec3;
    use svetlo::accel::packet::{PacketBvh, PacketSpheres, Rays8, LANES};
    use svetlo::geometry::ray::offset_ray_origin;
    use svetlo::geometry::{Geometry, Ray};
    let dir = std::env::temp_dir().join(format!("svetlo-simd-sphere-rays-{}", std::process::id()));
    let scene = sphere_box_scene(&dir, 16, 0);
    let (mut tris, mut tri_shape, mut spheres, mut sphere_shape) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, s) in scene.shapes.iter().enumerate() {
        match &*s.geometry {
            Geometry::Mesh(m) => {
                tris.extend((0..m.triangle_count()).map(|t| m.vertices(t)));
                tri_shape.extend((0..m.triangle_count()).map(|t| (i as u32, t as u32)));
            }
            Geometry::Sphere(sp) => {
                spheres.push(*sp);
                sphere_shape.push(i as u32);
            }
            Geometry::SdfGrid(_) => panic!("no grids here"),
        }
    }
    assert_eq!(spheres.len(), 5);
    let bvh = PacketBvh::build(&tris);
    let packed = PacketSpheres::new(&spheres);
    let mut rng = svetlo::sampling::Pcg32::new(41, 3);
    let (mut rays, mut flagged, mut sphere_hits, mut blocked_n, mut unsure_n) = (0u32, 0u32, 0u32, 0u32, 0u32);
    for _ in 0..20_000 {
        let mut r = Rays8::default();
        for l in 0..LANES {
            let dir = loop {
                let d = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE;
                let len = d.length();
                if len > 1e-3 && len <= 1.0 {
                    break d / len;
                }
            };
            // A point on a sphere or a triangle, the ray leaving its surface as the tracers spawn them.
            let (p, ng) = if l % 2 == 0 {
                let s = spheres[(rng.next_u32() as usize) % spheres.len()];
                let n = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - Vec3::ONE).normalize_or(Vec3::Y);
                (s.center + n * s.radius, n)
            } else {
                let [p0, p1, p2] = tris[(rng.next_u32() as usize) % tris.len()];
                let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                (p0 + (p1 - p0) * u + (p2 - p0) * v, (p1 - p0).cross(p2 - p0).normalize())
            };
            let o = offset_ray_origin(p, ng, dir);
            for k in 0..3 {
                r.o[k][l] = o[k];
                r.d[k][l] = dir[k];
            }
            r.t_max[l] = if l % 3 == 0 { 0.5 + rng.next_f32() } else { f32::INFINITY };
        }
        let (mut h, tied) = bvh.intersect_ties(&r, 0xff);
        let (ids, unsure) = packed.nearest(&r, !tied, &mut h.t);
        let tri_blocked = bvh.occluded(&r, 0xff);
        let (sph_blocked, occ_unsure) = packed.occluded(&r, !tri_blocked);
        for l in 0..LANES {
            rays += 1;
            let ray = Ray::with_max(Vec3::new(r.o[0][l], r.o[1][l], r.o[2][l]), Vec3::new(r.d[0][l], r.d[1][l], r.d[2][l]), r.t_max[l]);
            let blocked = tri_blocked & (1 << l) != 0 || sph_blocked & (1 << l) != 0;
            blocked_n += blocked as u32;
            if occ_unsure & (1 << l) == 0 {
                assert_eq!(blocked, scene.accel.occluded(&ray), "occlusion of {ray:?}");
            }
            unsure_n += (unsure & (1 << l) != 0) as u32;
            if (tied | unsure) & (1 << l) != 0 {
                flagged += 1;
                continue;
            }
            let want = scene.accel.intersect(&ray);
            let got = if ids[l] != u32::MAX {
                sphere_hits += 1;
                Some((sphere_shape[ids[l] as usize], 0, h.t[l], 0.0, 0.0))
            } else if h.prim[l] != u32::MAX {
                let (shape, prim) = tri_shape[h.prim[l] as usize];
                Some((shape, prim, h.t[l], h.b1[l], h.b2[l]))
            } else {
                None
            };
            let want = want.map(|w| (w.shape, w.prim, w.t, w.b1, w.b2));
            assert_eq!(
                got.map(|g| (g.0, g.1, g.2.to_bits(), g.3.to_bits(), g.4.to_bits())),
                want.map(|w| (w.0, w.1, w.2.to_bits(), w.3.to_bits(), w.4.to_bits())),
                "{ray:?}"
            );
        }
    }
    println!("{rays} rays, {sphere_hits} on spheres, {blocked_n} blocked, {flagged} flagged ({unsure_n} by the spheres)");
    assert!(sphere_hits > rays / 10 && blocked_n > rays / 10, "the rays meet spheres and are blocked");
    // Most flagged lanes are triangle ties: rays inside a box meet its bottom on the floor.
    assert!(flagged < rays / 20 && unsure_n < rays / 200, "{flagged} of {rays} lanes flagged ({unsure_n} by the spheres)");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `sphere_box_scene` in the kernel, packets with the spheres tested on their lanes: the
/// scalar tracer's image bit for bit with either sampler and one or three threads. With more
/// than 16 spheres the kernel traces single rays (and is still the scalar tracer's image).
#[test]
fn sphere_box_packets_match_scalar() {
    if !avx2() {
        eprintln!("SKIPPED: no AVX2, the kernel falls back to the scalar tracer");
        return;
    }
    let dir = std::env::temp_dir().join(format!("svetlo-simd-sphere-box-{}", std::process::id()));
    for (extra, packets) in [(0, true), (12, false)] {
        let scene = sphere_box_scene(&dir, 40, extra);
        for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
            let mut s = RenderSettings::from_scene(&scene);
            s.sampler = sampler;
            s.spp = if packets { 16 } else { 4 };
            s.seed = 5;
            s.max_depth = 5;
            let k = SimdKernel::new(&scene, &s).expect("the scene qualifies");
            assert_eq!(k.uses_packets(), packets, "{} spheres", 5 + extra);
            let b = render(&scene, "path:simd=false", &s);
            for threads in [1, 3] {
                let a = k.render(&scene, &RenderSettings { threads, ..s.clone() }, &Progress::new()).expect("render").image();
                let exact = a.data.iter().zip(&b.data).filter(|(x, y)| x == y).count();
                assert!(a.data == b.data, "{sampler:?}, {threads} threads, {} spheres: {exact}/{} channels bit-identical", 5 + extra, a.data.len());
            }
            assert!(b.mean().max_component() > 0.0);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bitterli's veach-mis (sphere lights over rough conductor plates), the scene the sphere
/// packets are for: packets, and the scalar tracer's image bit for bit.
#[test]
fn veach_mis_packets_match_scalar() {
    let Some(root) = shared() else { return };
    if !avx2() {
        return;
    }
    let scene = load(&root.join("bitterli/veach-mis/mitsuba3/scene.xml"), &[("resx", "64"), ("resy", "36")], 48);
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 8;
    s.seed = 3;
    let k = SimdKernel::new(&scene, &s).expect("veach-mis qualifies");
    assert!(k.uses_packets(), "veach-mis traces packets");
    for sampler in [svetlo::sampling::SamplerKind::Independent, svetlo::sampling::SamplerKind::Sobol] {
        let s = RenderSettings { sampler, ..s.clone() };
        assert!(render(&scene, "path", &s).data == render(&scene, "path:simd=false", &s).data, "{sampler:?}: veach-mis differs from the scalar tracer");
    }
}

/// The packet tree and the unpacked triangles are kept with the scene (`Scene::packet_tree`,
/// `Scene::kernel_geometry`): a second render, and a render of a clone, take them and give
/// the first render's image bit for bit.
#[test]
fn renders_after_the_first_keep_the_image() {
    let scene = load(&repo_scene("cornell-box.xml"), &[], 32);
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 4;
    s.seed = 5;
    let a = render(&scene, "path", &s);
    assert!(render(&scene, "path", &s).data == a.data, "the second render differs");
    assert!(render(&scene.clone(), "path", &s).data == a.data, "the clone's render differs");
}

/// A large scene with a material other than a Lambertian one whose rays go as packets takes
/// the kernel on its first render (it took the scalar tracer until the kernel shaded rough
/// dielectrics, plastics and conductors in lanes: its set-up had cost more than it gained),
/// with the scalar tracer's image bit for bit (the packets check ties), whatever the thread
/// count; a second render takes the kept set-up and gives the same image.
#[test]
fn a_large_packet_scene_takes_the_kernel_on_its_first_render() {
    if !avx2() {
        eprintln!("SKIPPED: no AVX2, the kernel falls back to the scalar tracer");
        return;
    }
    // 24 200 triangles under a mask (packets that check ties; a BSDF shaded by its scalar code).
    let n = 110u32;
    let scene = bumpy_floor(n, true);
    let s = RenderSettings { spp: 4, max_depth: 4, seed: 11, ..RenderSettings::from_scene(&scene) };
    let what = format!("a masked floor of {} triangles", 2 * n * n);
    let want = render(&scene, "path:simd=false", &s);
    assert!(want.mean().max_component() > 0.0, "the lamp lights the floor");
    let k = SimdKernel::new(&scene, &s).unwrap_or_else(|| panic!("{what}: the first render should take the kernel"));
    assert!(k.uses_packets(), "{what}: packets");
    for threads in [1, 2, 3] {
        let t = RenderSettings { threads, ..s.clone() };
        assert!(k.render(&scene, &t, &Progress::new()).expect("render").image().data == want.data, "{what}, {threads} threads: not the scalar tracer's image");
    }
    assert!(render(&scene, "path", &s).data == want.data, "{what}: a second render differs");
}

/// A large scene that traces single rays takes the kernel on its first render whatever its
/// materials: at few camera samples a triangle its hits read their triangles from the mesh,
/// at many it unpacks them (and later renders take those); the scalar tracer's image bit for
/// bit either way, whatever the thread count.
#[test]
fn a_single_ray_scene_takes_the_kernel_on_its_first_render() {
    if !avx2() {
        eprintln!("SKIPPED: no AVX2, the kernel falls back to the scalar tracer");
        return;
    }
    // 51 200 triangles under a mask (a material the kernel shades through its scalar BSDF).
    let scene = bumpy_floor(160, true);
    let s = RenderSettings { spp: 4, max_depth: 4, seed: 11, ..RenderSettings::from_scene(&scene) };
    let want = render(&scene, "path:simd=false", &s);
    assert!(want.mean().max_component() > 0.0, "the lamp lights the floor");
    let k = SimdKernel::new(&scene, &s).expect("the first render takes the kernel");
    assert!(!k.uses_packets() && !k.unpacks_triangles(), "4 spp of 40x40 pixels on 51 200 triangles: single rays, triangles read at the hits");
    for threads in [1, 2, 3] {
        let t = RenderSettings { threads, ..s.clone() };
        assert!(k.render(&scene, &t, &Progress::new()).expect("render").image().data == want.data, "triangles read at the hits, {threads} threads");
    }
    // 100 spp: more than three camera samples a triangle.
    let many = RenderSettings { spp: 100, ..s.clone() };
    let k = SimdKernel::new(&scene, &many).expect("the kernel");
    assert!(k.unpacks_triangles(), "100 spp of 40x40 pixels on 51 200 triangles: unpacked");
    assert!(k.render(&scene, &s, &Progress::new()).expect("render").image().data == want.data, "unpacked triangles");
    assert!(SimdKernel::new(&scene, &s).expect("the kernel").unpacks_triangles(), "a later render takes the kept unpacked triangles");
    assert!(render(&scene, "path", &s).data == want.data, "a render after the unpacking");
}

/// Mitsuba's projector tests in small: a 2000-unit square (two triangles) lit by a point
/// light 1 unit above, seen through a 170° lens. Shadow rays leave the floor with an offset
/// below the watertight test's rounding at that scale; the packet tree (one leaf) met the
/// floor again on ~1 % of them where the scene's BVH rejects them by the floor's flat box,
/// and the kernel's image was a third darker in places. Now the scalar tracer's bit for bit.
#[test]
fn vast_floor_matches_scalar() {
    let dir = std::env::temp_dir().join(format!("svetlo-simd-floor-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let xml = r#"<scene version="2.1.0">
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective"><float name="fov" value="170"/>
        <transform name="to_world"><lookat origin="0, 0, 1" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film>
    </sensor>
    <shape type="rectangle"><bsdf type="diffuse"><rgb name="reflectance" value="1"/></bsdf>
        <transform name="to_world"><scale value="1000"/></transform></shape>
    <emitter type="point"><point name="position" x="0" y="0" z="1"/><rgb name="intensity" value="1"/></emitter>
</scene>"#;
    let path = dir.join("floor.xml");
    std::fs::write(&path, xml).unwrap();
    let scene = load(&path, &[], 32);
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = 8;
    s.seed = 3;
    compare_exact(&scene, &s, "a vast floor under a point light");
}

/// A clone shares what the kernel keeps of the scene, but a clone given another mesh (or
/// another material) renders as a scene built with it: the kept triangles and tree are
/// rebuilt, the materials never kept.
#[test]
fn a_clone_with_another_mesh_or_material_is_not_given_the_kept_set_up() {
    let s = RenderSettings { spp: 4, seed: 9, ..RenderSettings::from_scene(&bumpy_floor(10, false)) };
    let (a, b) = (bumpy_floor(10, false), bumpy_floor(12, false));
    let first = render(&a, "path", &s);
    assert!(first.data != render(&b, "path", &s).data, "the floors should give different images");
    // `a`'s lamp and light, `b`'s floor (and the BVH over it).
    let mut c = a.clone();
    c.shapes[0] = b.shapes[0].clone();
    c.accel = b.accel.clone();
    c.bounds = b.bounds;
    assert!(render(&c, "path", &s).data == render(&b, "path", &s).data, "the clone with another floor took the kept one");
    let grey = svetlo::bsdf::Material::Diffuse { reflectance: svetlo::texture::Texture::Constant(svetlo::spectrum::Rgb::splat(0.3)) };
    let mut d = a.clone();
    d.materials[0] = grey.clone();
    let mut fresh = bumpy_floor(10, false);
    fresh.materials[0] = grey;
    assert!(render(&d, "path", &s).data == render(&fresh, "path", &s).data, "the clone with another material took the kept one");
    assert!(render(&a, "path", &s).data == first.data, "the first scene's image changed");
}
