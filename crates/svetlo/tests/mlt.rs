//! Metropolis light transport: the chain machinery against a target with a known answer, and
//! both MLTs against the path tracer's references on measured scenes.
//!
//! - A synthetic primary-sample target with an analytic image: many short renders with
//!   different seeds, each pixel's mean against the exact value (t-statistics from the spread
//!   between renders). A wrong acceptance ratio fails it (checked: the same test with a
//!   mutation that lies about its transition ratio must fail).
//! - `cbox-rgb` and `bsdf_spheres/test_arealight_path`, block-averaged to a few pixels so the
//!   chains converge in seconds: the image mean within its confidence (chain spread and the
//!   bootstrap's error in b) of the reference's, and the relMSE falling as mutations grow.

mod common;

use common::scenes::shared;
use glam::Vec2;
use svetlo::film::compare::rel_mse;
use svetlo::film::Image;
use svetlo::integrator::metropolis::pss::PssSampler;
use svetlo::integrator::metropolis::{self, ChainSettings, ChainStats, Contribution, MetropolisTarget, Proposal};
use svetlo::integrator::mlt::{Mlt, MltOptions};
use svetlo::integrator::pssmlt::{PssTargetKind, Pssmlt, PssmltOptions};
use svetlo::integrator::{Progress, RenderSettings};
use svetlo::io::{load_scene, read_image};
use svetlo::sampling::{Pcg32, Sampler};
use svetlo::Rgb;

const W: u32 = 8;
const H: u32 = 6;

/// Rectangles [x0, x1] x [y0, y1] of the unit square and their values; g is their sum.
const RECTS: [([f64; 4], f64); 3] = [([0.0, 0.3, 0.0, 0.85], 3.0), ([0.0, 1.0, 0.0, 0.85], 1.0), ([0.62, 0.71, 0.4, 0.52], 20.0)];

fn g(x: f64, y: f64) -> f64 {
    RECTS.iter().filter(|(r, _)| x >= r[0] && x < r[1] && y >= r[2] && y < r[3]).map(|(_, v)| v).sum()
}

/// The exact image: pixel j is npix times the integral of g over its cell, in every channel.
fn exact() -> Vec<f64> {
    let mut out = Vec::new();
    for py in 0..H {
        for px in 0..W {
            let (cx0, cx1) = (px as f64 / W as f64, (px + 1) as f64 / W as f64);
            let (cy0, cy1) = (py as f64 / H as f64, (py + 1) as f64 / H as f64);
            let mut s = 0.0;
            for (r, v) in RECTS {
                let ox = (r[1].min(cx1) - r[0].max(cx0)).max(0.0);
                let oy = (r[3].min(cy1) - r[2].max(cy0)).max(0.0);
                s += v * ox * oy;
            }
            out.push(s * (W * H) as f64);
        }
    }
    out
}

/// L(u) = (g k, g 2[u3 < 0.5], g) with k = 2 u2: channel means g, g, g, but the chain must get
/// the extra coordinates' distribution right.
struct Synthetic {
    large_step: f32,
    /// Lie about the transition ratio of small steps (a broken Metropolis-Hastings ratio).
    lie: f64,
}

impl Synthetic {
    fn eval(&self, s: &mut PssSampler, out: &mut Contribution) {
        s.start_stream(0);
        let u = s.next_2d();
        let k = 2.0 * s.next_1d();
        let c = if s.next_1d() < 0.5 { 2.0 } else { 0.0 };
        let gv = g(u.x as f64, u.y as f64) as f32;
        out.push(Vec2::new(u.x * W as f32, u.y * H as f32), Rgb::new(gv * k, gv * c, gv));
    }
}

impl MetropolisTarget for Synthetic {
    type State = PssSampler;
    fn mutation_names(&self) -> Vec<&'static str> {
        vec!["small", "large"]
    }
    fn bootstrap(&self, rng: Pcg32, weights: &mut Vec<f32>) {
        let mut s = PssSampler::new(rng, 0.05, self.large_step, 1);
        let mut c = Contribution::default();
        self.eval(&mut s, &mut c);
        weights.push(c.f());
    }
    fn start(&self, rng: Pcg32, _k: usize, chain_rng: Pcg32, out: &mut Contribution) -> Option<PssSampler> {
        let mut s = PssSampler::new(rng, 0.05, self.large_step, 1);
        self.eval(&mut s, out);
        s.set_rng(chain_rng);
        Some(s)
    }
    fn propose(&self, s: &mut PssSampler, out: &mut Contribution) -> Proposal {
        s.start_iteration();
        self.eval(s, out);
        let large = s.is_large_step();
        Proposal { kind: usize::from(large), t_ratio: if large { 1.0 } else { self.lie } }
    }
    fn accept(&self, s: &mut PssSampler) {
        s.accept();
    }
    fn reject(&self, s: &mut PssSampler) {
        s.reject();
    }
}

/// Sum over pixel channels of squared t-statistics of `renders` renders against `exact`, the
/// largest |t|, and the number of cells.
fn t_statistics(target: &Synthetic, renders: u64, spp: u32) -> (f64, f64, usize) {
    let truth = exact();
    let n = (W * H) as usize;
    let mut s1 = vec![[0.0f64; 3]; n];
    let mut s2 = vec![[0.0f64; 3]; n];
    for r in 0..renders {
        let settings = RenderSettings { spp, seed: 1000 + r, threads: 2, ..Default::default() };
        let cfg = ChainSettings { chains: 16, bootstrap: 4000 };
        let (film, _) = metropolis::run(target, W, H, &settings, &cfg, &Progress::new()).expect("render");
        let img = film.image();
        for (j, p) in img.data.iter().enumerate() {
            for k in 0..3 {
                s1[j][k] += p[k] as f64;
                s2[j][k] += (p[k] as f64).powi(2);
            }
        }
    }
    let rn = renders as f64;
    let (mut sum, mut max, mut cells) = (0.0, 0.0f64, 0);
    for j in 0..n {
        for k in 0..3 {
            let m = s1[j][k] / rn;
            let var = ((s2[j][k] - rn * m * m) / (rn - 1.0)).max(0.0);
            if truth[j] == 0.0 {
                assert!(m.abs() < 1e-9, "pixel {j} should be black, mean {m}");
                continue;
            }
            let t = (m - truth[j]) / (var / rn).sqrt().max(1e-12);
            sum += t * t;
            max = max.max(t.abs());
            cells += 1;
        }
    }
    (sum, max, cells)
}

/// Student-t with nu degrees of freedom: E[t^2] = nu/(nu-2), Var[t^2] = 2 nu^2 (nu-1) /
/// ((nu-2)^2 (nu-4)); the sum over cells is tested at 4 standard deviations, and no cell may
/// exceed |t| = 6.
fn t_sum_ok(sum: f64, max: f64, cells: usize, renders: u64) -> bool {
    let nu = (renders - 1) as f64;
    let mean = nu / (nu - 2.0);
    let var = 2.0 * nu * nu * (nu - 1.0) / ((nu - 2.0).powi(2) * (nu - 4.0));
    let bound = cells as f64 * mean + 4.0 * (cells as f64 * var).sqrt();
    println!("sum t^2 = {sum:.1} (bound {bound:.1}, {cells} cells), max |t| = {max:.2}");
    sum <= bound && max <= 6.0
}

#[test]
fn synthetic_target_converges_to_its_integral() {
    let renders = 40;
    for large in [0.0, 0.3, 1.0] {
        let (sum, max, cells) = t_statistics(&Synthetic { large_step: large, lie: 1.0 }, renders, 400);
        assert!(t_sum_ok(sum, max, cells, renders), "large-step probability {large}: the chains do not reproduce the exact image");
    }
}

/// The same test must fail when the acceptance uses a wrong transition ratio: it has the
/// power to see a broken Metropolis-Hastings step.
#[test]
fn synthetic_target_detects_a_wrong_acceptance_ratio() {
    let renders = 40;
    let (sum, max, cells) = t_statistics(&Synthetic { large_step: 0.3, lie: 0.5 }, renders, 400);
    assert!(!t_sum_ok(sum, max, cells, renders), "a transition ratio off by 2 went unnoticed");
}

/// Average `img` over `f` x `f` blocks.
fn block_average(img: &Image, f: usize) -> Image {
    let (w, h) = (img.width / f, img.height / f);
    let mut data = vec![Rgb::BLACK; w * h];
    for y in 0..h * f {
        for x in 0..w * f {
            data[(y / f) * w + x / f] += img.get(x, y) / (f * f) as f32;
        }
    }
    Image::new(w, h, data)
}

/// Which Metropolis integrator a test runs.
#[derive(Clone)]
enum Method {
    Pss(PssmltOptions),
    Veach(MltOptions),
}

/// What a test render gives: the image and the chains' statistics.
struct Rendered {
    img: Image,
    stats: ChainStats,
}

/// Render a shared scene at `res` x `res` pixels and `spp` mutations per pixel.
fn mlt_render(scene_path: &std::path::Path, res: u32, spp: u32, seed: u64, method: &Method) -> Rendered {
    let mut scene = load_scene(scene_path, &[]).unwrap_or_else(|e| panic!("{}: {e}", scene_path.display()));
    scene.camera.width = res;
    scene.camera.height = res;
    let mut settings = RenderSettings::from_scene(&scene);
    settings.spp = spp;
    settings.seed = seed;
    let (film, stats) = match method {
        Method::Pss(o) => Pssmlt::new(o.clone()).render_with_stats(&scene, &settings, &Progress::new()).expect("render"),
        Method::Veach(o) => Mlt::new(o.clone()).render_with_stats(&scene, &settings, &Progress::new()).expect("render"),
    };
    Rendered { img: film.image(), stats }
}

/// Mean within confidence and relMSE falling with mutations, against a reference
/// block-averaged by `f` to `res` pixels.
fn check_against_reference(scene_path: &std::path::Path, reference: &Image, f: usize, spp: [u32; 2], max_ratio: f64, method: Method) {
    let reference = block_average(reference, f);
    let res = reference.width as u32;
    let mut errs = Vec::new();
    for (i, &n) in spp.iter().enumerate() {
        let Rendered { img, stats } = mlt_render(scene_path, res, n, 7, &method);
        let (mean, se) = stats.image_mean().expect("chains");
        let rm = reference.mean();
        // The relMSE of the image's shape: scaled to the reference's mean luminance, so that
        // the bootstrap's error in b (the same for both renders: same seed) does not floor it;
        // the mean test below checks b.
        let scale = rm.luminance() / img.mean().luminance();
        let shaped = Image::new(img.width, img.height, img.data.iter().map(|p| *p * scale).collect());
        let e = rel_mse(&shaped, &reference).expect("relmse");
        print!("{}: {n} mutations/pixel, shape relMSE {e:.3e}, b {:.4e} ± {:.1e}; {}", scene_path.display(), stats.b, stats.b_stderr, stats.report());
        for k in 0..3 {
            let z = (mean[k] - rm[k] as f64) / se[k];
            println!("  channel {k}: mean {:.5} ± {:.5} vs reference {:.5} (z = {z:.2})", mean[k], se[k], rm[k]);
            if i == spp.len() - 1 {
                assert!(z.abs() < 4.0, "channel {k}: image mean {} differs from the reference {} by {z:.1} standard errors", mean[k], rm[k]);
            }
        }
        errs.push(e);
    }
    // 8x the mutations: relMSE should fall ~8x when unbiased; a bias (a wrong target density
    // from a wrong acceptance ratio or splat weight) stalls it.
    let ratio = errs[1] / errs[0];
    println!("relMSE ratio {ratio:.3} for {}x the mutations", spp[1] / spp[0]);
    assert!(ratio < max_ratio, "relMSE fell only by {ratio:.3} ({:.3e} -> {:.3e})", errs[0], errs[1]);
}

#[test]
fn pssmlt_cbox_rgb() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/scenes/cbox");
    let reference = read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    for target in [PssTargetKind::Bdpt, PssTargetKind::Path] {
        let opts = PssmltOptions { chain: ChainSettings { chains: 64, bootstrap: 40_000 }, target, ..Default::default() };
        check_against_reference(&dir.join("cbox-rgb.xml"), &reference, 16, [32, 256], 0.35, Method::Pss(opts));
    }
}

#[test]
fn pssmlt_bsdf_spheres_arealight() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/tests/scenes/bsdf_spheres");
    let reference = read_image(&dir.join("refs/test_arealight_ref_rgb.exr")).expect("reference");
    let opts = PssmltOptions { chain: ChainSettings { chains: 64, bootstrap: 200_000 }, ..Default::default() };
    // Rare bright paths (the light seen in the glass and metal spheres) make this image's
    // relMSE noisier from seed to seed: seen between 0.11 and 0.44 for 8x; a bias stalls it at 1.
    check_against_reference(&dir.join("test_arealight_path.xml"), &reference, 4, [256, 2048], 0.6, Method::Pss(opts));
}

#[test]
fn mlt_cbox_rgb() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/scenes/cbox");
    let reference = read_image(&dir.join("refs/cbox-rgb_mitsuba3.9.1_llvm_ad_rgb_4096spp.exr")).expect("reference");
    let opts = MltOptions { chain: ChainSettings { chains: 64, bootstrap: 40_000 }, ..Default::default() };
    check_against_reference(&dir.join("cbox-rgb.xml"), &reference, 16, [32, 256], 0.35, Method::Veach(opts));
}

/// Glass, metal and plastic spheres: the chains carry the specular paths too.
#[test]
fn mlt_bsdf_spheres_arealight() {
    let Some(root) = shared() else { return };
    let dir = root.join("mitsuba-data/tests/scenes/bsdf_spheres");
    let reference = read_image(&dir.join("refs/test_arealight_ref_rgb.exr")).expect("reference");
    let opts = MltOptions { chain: ChainSettings { chains: 64, bootstrap: 200_000 }, ..Default::default() };
    check_against_reference(&dir.join("test_arealight_path.xml"), &reference, 4, [256, 2048], 0.6, Method::Veach(opts));
}

/// A project scene at 8x8 pixels and `max_depth` segments at most.
fn tiny(name: &str, max_depth: &str) -> svetlo::scene::Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(name);
    let defaults: Vec<(String, String)> = [("res", "8"), ("max_depth", max_depth)].iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    load_scene(&path, &defaults).unwrap_or_else(|e| panic!("scenes/{name}: {e}"))
}

/// The Cornell box, three segments at most.
fn tiny_box() -> svetlo::scene::Scene {
    tiny("cornell-box.xml", "3")
}

/// The Cornell box with a mirror and a glass sphere, five segments at most: paths through
/// the glass (LSSDE caustics, LDSSE refraction), the mirror (LDSE, and LSDSE: a caustic seen
/// in the mirror, two specular chains).
fn tiny_spheres() -> svetlo::scene::Scene {
    tiny("cornell-spheres.xml", "4")
}

/// Light through mirrors only (`scenes/mirror-box.xml`), four segments at most: the floor lit
/// through the mirror ceiling (LSDE) and seen in the back mirror (LSDSE, two chains).
fn tiny_mirror_box() -> svetlo::scene::Scene {
    tiny("mirror-box.xml", "4")
}

/// Sum of squared t-statistics of `renders` Veach-MLT chain renders of `scene` (mutation
/// weights `weights`, acceptance ratios raised to `power`, `spp` mutations per pixel) against
/// a path-traced reference with its own standard error, the largest |t|, and the cell count.
fn mlt_stationary(scene: &svetlo::scene::Scene, weights: [f64; 4], power: [f64; 4], renders: u64, spp: u32) -> (f64, f64, usize) {
    use svetlo::film::Filter;
    use svetlo::integrator::mlt::Target;
    let mut settings = RenderSettings::from_scene(scene);
    settings.filter = Filter::Box;
    settings.threads = 2;
    // Reference: the path tracer, and its standard error from the per-sample variance.
    let mut pt = settings.clone();
    pt.spp = 8192;
    pt.seed = 99;
    let film = svetlo::methods::by_name("path").expect("path").render(scene, &pt, &Progress::new()).expect("path tracer");
    let (reference, var) = (film.image(), film.variance_image());
    let n = reference.data.len();
    let (mut s1, mut s2) = (vec![[0.0f64; 3]; n], vec![[0.0f64; 3]; n]);
    for r in 0..renders {
        let mut s = settings.clone();
        s.spp = spp;
        s.seed = 500 + r;
        let mut target = Target::new(scene, &s, weights).expect("target");
        target.ratio_power = power;
        let cfg = ChainSettings { chains: 16, bootstrap: 5000 };
        let (film, _) = metropolis::run(&target, scene.camera.width, scene.camera.height, &s, &cfg, &Progress::new()).expect("mlt");
        for (j, p) in film.image().data.iter().enumerate() {
            for k in 0..3 {
                s1[j][k] += p[k] as f64;
                s2[j][k] += (p[k] as f64).powi(2);
            }
        }
    }
    let rn = renders as f64;
    let (mut sum, mut max, mut cells) = (0.0, 0.0f64, 0);
    for j in 0..n {
        for k in 0..3 {
            let m = s1[j][k] / rn;
            let v_mlt = ((s2[j][k] - rn * m * m) / (rn - 1.0)).max(0.0) / rn;
            let v_ref = var.data[j][k] as f64 / pt.spp as f64;
            if v_mlt + v_ref == 0.0 {
                continue;
            }
            let t = (m - reference.data[j][k] as f64) / (v_mlt + v_ref).sqrt();
            sum += t * t;
            max = max.max(t.abs());
            cells += 1;
        }
    }
    (sum, max, cells)
}

/// Mutation mixes that let one mutation dominate (the bidirectional mutation keeps a small
/// share where a perturbation dominates, for ergodicity).
const DOMINANT: [(&str, [f64; 4]); 4] =
    [("bidirectional", [1.0, 0.0, 0.0, 0.0]), ("lens", [0.1, 0.9, 0.0, 0.0]), ("caustic", [0.1, 0.0, 0.9, 0.0]), ("multi-chain", [0.1, 0.0, 0.0, 0.9])];

/// On the specular scene the perturbations share the proposals equally with the bidirectional
/// mutation: they cannot leave a path's class (the number and kind of its specular chains),
/// and with 10 % of bidirectional mutations the chains of these short renders do not spread
/// over the classes in time (the images converge to the path tracer's as the chains grow; a
/// test of this size needs the faster mixing).
const DOMINANT_SPECULAR: [(&str, [f64; 4]); 4] =
    [("bidirectional", [1.0, 0.0, 0.0, 0.0]), ("lens", [0.5, 0.5, 0.0, 0.0]), ("caustic", [0.5, 0.0, 0.5, 0.0]), ("multi-chain", [0.5, 0.0, 0.0, 0.5])];

/// Detailed balance of each mutation, seen through the chain's stationary distribution:
/// chains dominated by one mutation must reproduce the path tracer's image pixel by pixel
/// (a wrong T(y→x)/T(x→y) moves the stationary distribution away from f).
#[test]
fn mlt_each_mutation_keeps_f_stationary() {
    let scene = tiny_box();
    // 2048 mutations per pixel: at 512 the dark cells of the box (a few chain visits per
    // render, in runs) have skewed per-render estimates, and the t-test fails there on some
    // seeds for every mutation (seen on 2 of 7 seeds); at 2048 all 7 seeds tried pass.
    for (name, w) in &DOMINANT[..3] {
        let (sum, max, cells) = mlt_stationary(&scene, *w, [1.0; 4], 16, 2048);
        print!("{name}: ");
        assert!(t_sum_ok(sum, max, cells, 16), "{name}: the chain's image departs from the path tracer's");
    }
}

/// The same with a mirror and a glass sphere, all mutations at their default shares: the
/// chains over paths with specular vertices (no other estimator adds to them) reproduce the
/// path tracer's image.
#[test]
fn mlt_specular_scene_keeps_f_stationary() {
    let (sum, max, cells) = mlt_stationary(&tiny_spheres(), MltOptions::default().weights, [1.0; 4], 16, 4096);
    print!("default mix (specular scene): ");
    assert!(t_sum_ok(sum, max, cells, 16), "the chain's image departs from the path tracer's on the specular scene");
}

/// Each mutation through specular chains (lens through the glass and in the mirror, caustics
/// from the light through the glass and off the mirror, multi-chain for the light of the mirror
/// ceiling seen in the mirror wall of the mirror box) keeps f stationary. Ignored by default (about a minute): run with `-- --ignored`.
#[test]
#[ignore]
fn mlt_specular_mutations_keep_f_stationary() {
    let scene = tiny_spheres();
    for (name, w) in &DOMINANT_SPECULAR {
        let (sum, max, cells) = mlt_stationary(&scene, *w, [1.0; 4], 16, 4096);
        print!("{name} (specular scene): ");
        assert!(t_sum_ok(sum, max, cells, 16), "{name}: the chain's image departs from the path tracer's on the specular scene");
    }
    // Where two-chain paths (LSDSE) light much of the image; only camera-side walks that hit
    // the light through both mirrors make them otherwise, so the chains need long runs.
    let (sum, max, cells) = mlt_stationary(&tiny_mirror_box(), DOMINANT_SPECULAR[3].1, [1.0; 4], 16, 32768);
    print!("multi-chain (mirror box): ");
    assert!(t_sum_ok(sum, max, cells, 16), "multi-chain: the chain's image departs from the path tracer's on the mirror box");
}

/// The same tests see a wrong acceptance ratio (T(x→y)/T(y→x) in place of T(y→x)/T(x→y)) in
/// each mutation, on the box, the spheres and (multi-chain) the mirror box. Ignored by
/// default (about two minutes): run with `-- --ignored`.
#[test]
#[ignore]
fn mlt_stationarity_test_detects_wrong_ratios() {
    for (scene, label, spp, mixes) in [(tiny_box(), "box", 512, &DOMINANT), (tiny_spheres(), "specular", 4096, &DOMINANT_SPECULAR)] {
        for (i, (name, w)) in mixes.iter().enumerate() {
            if i == 3 {
                // No specular chains in the plain box; on the spheres scene the paths with two
                // chains carry too little of the image: the mirror box below.
                continue;
            }
            let mut p = [1.0; 4];
            p[i] = -1.0;
            let (sum, max, cells) = mlt_stationary(&scene, *w, p, 16, spp);
            print!("{name} on {label} (ratio upside down): ");
            assert!(!t_sum_ok(sum, max, cells, 16), "{name} on {label}: an inverted transition ratio went unnoticed");
        }
    }
    let mut p = [1.0; 4];
    p[3] = -1.0;
    let (sum, max, cells) = mlt_stationary(&tiny_mirror_box(), DOMINANT_SPECULAR[3].1, p, 16, 16384);
    print!("multi-chain on the mirror box (ratio upside down): ");
    assert!(!t_sum_ok(sum, max, cells, 16), "multi-chain: an inverted transition ratio went unnoticed");
}

/// `scenes/caustic.xml` (a glass sphere focusing a small light onto the floor: LSSDE paths):
/// the chains alone carry the caustic. Eight MLT renders against eight BDPT renders, block by
/// block (4x4 blocks of 6x6 pixels, the caustic among them), a two-sample t-test per block.
#[test]
fn mlt_caustic_scene_matches_bdpt() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/caustic.xml");
    let defaults: Vec<(String, String)> = [("res", "24"), ("max_depth", "6")].iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    let scene = load_scene(&path, &defaults).expect("scenes/caustic.xml");
    let renders = 8u64;
    let blocks = |img: &Image| block_average(img, 6).data;
    let stats = |name: &str, spp: u32| {
        let (mut s1, mut s2) = (vec![[0.0f64; 3]; 16], vec![[0.0f64; 3]; 16]);
        for r in 0..renders {
            let mut s = RenderSettings::from_scene(&scene);
            s.spp = spp;
            s.seed = 40 + r;
            s.threads = 2;
            let img = if name == "mlt" {
                let o = MltOptions { chain: ChainSettings { chains: 64, bootstrap: 20_000 }, ..Default::default() };
                Mlt::new(o).render_with_stats(&scene, &s, &Progress::new()).expect("mlt").0.image()
            } else {
                svetlo::methods::by_name(name).expect(name).render(&scene, &s, &Progress::new()).expect(name).image()
            };
            for (j, p) in blocks(&img).iter().enumerate() {
                for k in 0..3 {
                    s1[j][k] += p[k] as f64;
                    s2[j][k] += (p[k] as f64).powi(2);
                }
            }
        }
        let n = renders as f64;
        let mean: Vec<[f64; 3]> = s1.iter().map(|v| v.map(|x| x / n)).collect();
        let var: Vec<[f64; 3]> = (0..16).map(|j| std::array::from_fn(|k| ((s2[j][k] - n * mean[j][k].powi(2)) / (n - 1.0)).max(0.0) / n)).collect();
        (mean, var)
    };
    let (m_mlt, v_mlt) = stats("mlt", 128);
    let (m_bdpt, v_bdpt) = stats("bdpt", 32);
    let (mut sum, mut max, mut cells) = (0.0, 0.0f64, 0);
    let brightest = (0..16).max_by(|&a, &b| m_bdpt[a][0].total_cmp(&m_bdpt[b][0])).expect("blocks");
    for j in 0..16 {
        for k in 0..3 {
            let se = (v_mlt[j][k] + v_bdpt[j][k]).sqrt();
            if se == 0.0 {
                continue;
            }
            let t = (m_mlt[j][k] - m_bdpt[j][k]) / se;
            sum += t * t;
            max = max.max(t.abs());
            cells += 1;
        }
    }
    println!(
        "caustic block {brightest}: mlt {:.4} ± {:.4}, bdpt {:.4} ± {:.4}",
        m_mlt[brightest][0],
        v_mlt[brightest][0].sqrt(),
        m_bdpt[brightest][0],
        v_bdpt[brightest][0].sqrt()
    );
    assert!(t_sum_ok(sum, max, cells, renders), "MLT departs from BDPT on the caustic scene");
}

/// The image depends on the seed, not on the number of threads.
#[test]
fn deterministic_for_any_thread_count() {
    let target = Synthetic { large_step: 0.3, lie: 1.0 };
    let cfg = ChainSettings { chains: 8, bootstrap: 500 };
    let img = |threads: usize| {
        let settings = RenderSettings { spp: 64, seed: 3, threads, ..Default::default() };
        metropolis::run(&target, W, H, &settings, &cfg, &Progress::new()).expect("render").0.image().data
    };
    assert_eq!(img(1), img(3));
}
