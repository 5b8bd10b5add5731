//! Statistical tests of the lights: chi-square goodness of fit of `sample_li` against
//! `pdf_li` and of `sample_le` against `pdf_le`, pdfs integrating to one, and irradiance
//! against closed forms.
//!
//! Chi-square tests: directions are binned on a spherical cap (bins uniform in cos θ and φ
//! about an axis); expected counts integrate the pdf over each bin by a midpoint rule,
//! refined where the pdf's support has an edge. Failed samples and directions outside the
//! cap share one extra cell. Seeds are fixed; each test rejects at the Šidák level that
//! keeps the family-wise false-alarm probability of all `CHI2_TESTS` tests at 1 %.
//!
//! Monte Carlo estimates of irradiance must lie within 5 standard errors of the exact
//! value (a two-sided 5.7e-7 chance of failing for a correct estimator).

use glam::{Mat4, Vec2, Vec3};
use std::sync::Arc;
use svetlo::geometry::triangle::WatertightRay;
use svetlo::geometry::{Geometry, Ray, Sphere, TriangleMesh};
use svetlo::light::{AreaLight, EnvMap, Light, SceneBounds};
use svetlo::math::{Frame, PI};
use svetlo::sampling::stats::{chi_square_test, sidak_alpha};
use svetlo::sampling::Pcg32;
use svetlo::texture::{Bitmap, Texture};
use svetlo::Rgb;

/// Number of chi-square tests in this file (for the Šidák correction).
const CHI2_TESTS: usize = 21;
const SAMPLES: usize = 200_000;

fn alpha() -> f64 {
    sidak_alpha(0.01, CHI2_TESTS)
}

fn bounds() -> SceneBounds {
    SceneBounds { center: Vec3::new(0.2, 0.1, -0.3), radius: 5.0 }
}

fn u2(rng: &mut Pcg32) -> Vec2 {
    Vec2::new(rng.next_f32(), rng.next_f32())
}

// ---------------------------------------------------------------------------------------
// Binning of directions on a spherical cap.

struct Cap {
    frame: Frame,
    cos_min: f64,
    n_theta: usize,
    n_phi: usize,
}

impl Cap {
    fn new(axis: Vec3, half_angle: f64, n_theta: usize, n_phi: usize) -> Self {
        Cap { frame: Frame::from_normal(axis.normalize()), cos_min: half_angle.min(std::f64::consts::PI).cos(), n_theta, n_phi }
    }
    fn full_sphere(n_theta: usize, n_phi: usize) -> Self {
        Cap::new(Vec3::Z, std::f64::consts::PI, n_theta, n_phi)
    }
    fn cells(&self) -> usize {
        self.n_theta * self.n_phi + 1
    }
    /// Cell of a direction; the last cell is "outside the cap".
    fn cell(&self, w: Vec3) -> usize {
        let l = self.frame.to_local(w.normalize());
        let c = l.z as f64;
        if c < self.cos_min {
            return self.n_theta * self.n_phi;
        }
        let i = (((1.0 - c) / (1.0 - self.cos_min) * self.n_theta as f64) as usize).min(self.n_theta - 1);
        let mut phi = (l.y as f64).atan2(l.x as f64);
        if phi < 0.0 {
            phi += 2.0 * std::f64::consts::PI;
        }
        let j = ((phi / (2.0 * std::f64::consts::PI) * self.n_phi as f64) as usize).min(self.n_phi - 1);
        i * self.n_phi + j
    }
    fn dir(&self, c: f64, phi: f64) -> Vec3 {
        let s = (1.0 - c * c).max(0.0).sqrt();
        self.frame.to_world(Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32))
    }
    /// ∫ pdf dω over cell (i, j) by an m x m midpoint rule in (cos θ, φ).
    fn integrate_cell(&self, i: usize, j: usize, m: usize, pdf: &dyn Fn(Vec3) -> f64) -> (f64, bool) {
        let dc = (1.0 - self.cos_min) / self.n_theta as f64;
        let dp = 2.0 * std::f64::consts::PI / self.n_phi as f64;
        let (mut sum, mut zero, mut nonzero) = (0.0, false, false);
        for a in 0..m {
            let c = 1.0 - (i as f64 + (a as f64 + 0.5) / m as f64) * dc;
            for b in 0..m {
                let phi = (j as f64 + (b as f64 + 0.5) / m as f64) * dp;
                let v = pdf(self.dir(c, phi));
                if v > 0.0 {
                    nonzero = true;
                } else {
                    zero = true;
                }
                sum += v;
            }
        }
        (sum * dc * dp / (m * m) as f64, zero && nonzero)
    }
    /// Expected probability of each cell (the last one takes the rest, failures included).
    /// Cells where the pdf's support has an edge — mixed zero and non-zero samples in the
    /// cell or a neighbour that differs — are integrated much more finely.
    fn expected(&self, pdf: &dyn Fn(Vec3) -> f64) -> Vec<f64> {
        let (nt, np) = (self.n_theta, self.n_phi);
        let coarse: Vec<(f64, bool)> = (0..nt * np).map(|k| self.integrate_cell(k / np, k % np, 12, pdf)).collect();
        // 0: empty, 1: full, 2: mixed.
        let status = |i: usize, j: usize| {
            let (v, edge) = coarse[i * np + j];
            if edge {
                2
            } else if v > 0.0 {
                1
            } else {
                0
            }
        };
        let mut e = Vec::with_capacity(self.cells());
        for i in 0..nt {
            for j in 0..np {
                let st = status(i, j);
                let mut refine = st == 2;
                for di in [-1i64, 0, 1] {
                    for dj in [-1i64, 0, 1] {
                        let ii = i as i64 + di;
                        if ii < 0 || ii >= nt as i64 {
                            continue;
                        }
                        let jj = (j as i64 + dj).rem_euclid(np as i64) as usize;
                        refine |= status(ii as usize, jj) != st;
                    }
                }
                e.push(if refine { self.integrate_cell(i, j, 64, pdf).0 } else { coarse[i * np + j].0 });
            }
        }
        let inside: f64 = e.iter().sum();
        e.push((1.0 - inside).max(0.0));
        e
    }
}

/// Chi-square test of sampled directions (None = failed sample) against a density.
/// Returns the fraction of samples that succeeded.
fn chi2_directions(name: &str, cap: &Cap, samples: impl Iterator<Item = Option<Vec3>>, pdf: &dyn Fn(Vec3) -> f64) -> f64 {
    let mut observed = vec![0.0f64; cap.cells()];
    let (mut n, mut ok) = (0usize, 0usize);
    for s in samples {
        n += 1;
        match s {
            Some(w) => {
                ok += 1;
                observed[cap.cell(w)] += 1.0
            }
            None => observed[cap.cells() - 1] += 1.0,
        }
    }
    let expected: Vec<f64> = cap.expected(pdf).iter().map(|p| p * n as f64).collect();
    let r = chi_square_test(&observed, &expected, 5.0);
    let a = alpha();
    eprintln!("{name}: chi2 = {:.1}, dof = {}, p = {:.4} (alpha {a:.1e})", r.statistic, r.dof, r.p_value);
    if r.p_value <= a || std::env::var("CHI2_DEBUG").is_ok() {
        for (k, (o, e)) in observed.iter().zip(&expected).enumerate() {
            if (o - e).abs() > 4.0 * e.sqrt().max(1.0) {
                eprintln!("  cell {k}: observed {o}, expected {e:.2}");
            }
        }
    }
    assert!(r.p_value > a, "{name}: sampling does not match its pdf (chi2 {:.1}, dof {}, p {:.2e})", r.statistic, r.dof, r.p_value);
    ok as f64 / n as f64
}

// ---------------------------------------------------------------------------------------
// Geometry helpers.

fn mesh(positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> TriangleMesh {
    TriangleMesh { positions, normals: vec![], uvs: vec![], indices }
}

fn area_light(m: TriangleMesh, radiance: Rgb) -> (AreaLight, Light) {
    let a = AreaLight::new(0, Arc::new(Geometry::Mesh(m)), Texture::Constant(radiance));
    (a.clone(), Light::Area(a))
}

/// Density of `sample_li` over directions for a mesh light: the solid-angle densities of
/// all front-facing points along the direction (back-facing ones are never returned).
fn mesh_direction_pdf(light: &AreaLight, p_ref: Vec3, w: Vec3) -> f64 {
    let Geometry::Mesh(m) = &*light.geometry else { unreachable!() };
    let ray = WatertightRay::new(p_ref, w);
    let mut pdf = 0.0;
    for t in 0..m.triangle_count() {
        let [p0, p1, p2] = m.vertices(t);
        if let Some((tt, b1, b2)) = ray.intersect(p0, p1, p2, f32::INFINITY) {
            let (ng, _, _, _) = m.surface(t, b1, b2);
            if ng.dot(-w) > 0.0 {
                pdf += light.pdf_li(p_ref, p_ref + w * tt, ng) as f64;
            }
        }
    }
    pdf
}

fn sphere_light(center: Vec3, radius: f32, flip: bool, radiance: Rgb) -> (AreaLight, Sphere) {
    let s = Sphere { center, radius, flip_normals: flip };
    (AreaLight::new(0, Arc::new(Geometry::Sphere(s)), Texture::Constant(radiance)), s)
}

fn sphere_direction_pdf(light: &AreaLight, s: &Sphere, p_ref: Vec3, w: Vec3) -> f64 {
    match s.intersect(p_ref, w, f32::INFINITY) {
        Some(t) => {
            let p = p_ref + w * t;
            let (n, _, _) = s.surface(p);
            if n.dot(-w) > 0.0 {
                light.pdf_li(p_ref, p, n) as f64
            } else {
                0.0
            }
        }
        None => 0.0,
    }
}

fn max_angle_to(p_ref: Vec3, axis: Vec3, pts: &[Vec3]) -> f64 {
    pts.iter().map(|&p| ((p - p_ref).normalize().dot(axis.normalize()) as f64).clamp(-1.0, 1.0).acos()).fold(0.0, f64::max)
}

fn quad(p0: Vec3, e1: Vec3, e2: Vec3) -> TriangleMesh {
    mesh(vec![p0, p0 + e1, p0 + e1 + e2, p0 + e2], vec![[0, 1, 2], [0, 2, 3]])
}

fn cube(center: Vec3, h: f32) -> TriangleMesh {
    let mut pos = Vec::new();
    for i in 0..8 {
        pos.push(center + Vec3::new(if i & 1 == 0 { -h } else { h }, if i & 2 == 0 { -h } else { h }, if i & 4 == 0 { -h } else { h }));
    }
    // Outward-facing (counter-clockwise seen from outside) faces.
    let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let mut idx = Vec::new();
    for f in faces {
        idx.push([f[0], f[1], f[2]]);
        idx.push([f[0], f[2], f[3]]);
    }
    mesh(pos, idx)
}

fn test_envmap(to_world: Mat4) -> EnvMap {
    // 32 x 16 image: a dim gradient, a bright 3 x 2 spot, and a black band.
    let (w, h) = (32usize, 16usize);
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let mut c = Rgb::new(0.1 + 0.02 * x as f32, 0.2, 0.05 + 0.03 * y as f32);
            if (20..23).contains(&x) && (5..7).contains(&y) {
                c = Rgb::new(60.0, 40.0, 30.0);
            }
            if (8..10).contains(&x) {
                c = Rgb::BLACK;
            }
            data.push(c);
        }
    }
    EnvMap::new(Arc::new(Bitmap::new(w, h, data)), to_world, 1.5)
}

// ---------------------------------------------------------------------------------------
// sample_li against pdf_li.

fn chi2_mesh_light(name: &str, m: TriangleMesh, p_ref: Vec3, min_success: f64, seed: u64) {
    let pts = m.positions.clone();
    let (a, l) = area_light(m, Rgb::splat(1.0));
    let centroid = pts.iter().copied().sum::<Vec3>() / pts.len() as f32;
    let axis = centroid - p_ref;
    // Fine cells: the pdf of an obliquely seen polygon is steep, and the midpoint rule's
    // error must stay well below the sampling noise of 200k samples.
    let cap = Cap::new(axis, max_angle_to(p_ref, axis, &pts) + 0.05, 32, 64);
    let mut rng = Pcg32::new(seed, 1);
    let b = bounds();
    let samples = (0..SAMPLES).map(|_| {
        let s = l.sample_li(p_ref, u2(&mut rng), &b)?;
        // The returned pdf is the density of the returned direction.
        let pdf = mesh_direction_pdf(&a, p_ref, s.wi) as f32;
        assert!((s.pdf - pdf).abs() <= 2e-3 * pdf, "{name}: pdf {} vs {pdf}", s.pdf);
        Some(s.wi)
    });
    let ok = chi2_directions(name, &cap, samples, &|w| mesh_direction_pdf(&a, p_ref, w));
    assert!(ok >= min_success, "{name}: only {ok} of the samples succeeded");
}

#[test]
fn chi2_triangle_light() {
    let m = mesh(vec![Vec3::new(-1.0, 2.0, -0.5), Vec3::new(1.5, 2.2, 0.0), Vec3::new(0.0, 1.8, 1.5)], vec![[0, 1, 2]]);
    chi2_mesh_light("triangle", m, Vec3::new(0.3, 0.0, 0.2), 0.999, 1);
}

#[test]
fn chi2_quad_light() {
    // A quad facing down (-y), seen obliquely.
    let m = quad(Vec3::new(-1.0, 1.5, -1.0), Vec3::new(3.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0));
    chi2_mesh_light("quad", m, Vec3::new(2.5, 0.0, 0.5), 0.999, 2);
}

#[test]
fn chi2_mesh_light_cube() {
    // A closed mesh seen from a point that sees two of its faces: samples on the other
    // faces are turned away and fail (4 of 6 faces: success 1/3).
    chi2_mesh_light("cube mesh", cube(Vec3::new(0.5, 2.0, -0.3), 0.6), Vec3::new(-0.6, 0.0, 0.0), 0.3, 3);
}

fn chi2_sphere(name: &str, center: Vec3, radius: f32, flip: bool, p_ref: Vec3, seed: u64) {
    let (a, s) = sphere_light(center, radius, flip, Rgb::splat(2.0));
    let l = Light::Area(a.clone());
    let d = (center - p_ref).length();
    let cap = if d > radius { Cap::new(center - p_ref, ((radius / d) as f64).asin() * 1.05 + 1e-3, 16, 32) } else { Cap::full_sphere(24, 48) };
    let mut rng = Pcg32::new(seed, 2);
    let b = bounds();
    let samples = (0..SAMPLES).map(|_| {
        let ls = l.sample_li(p_ref, u2(&mut rng), &b)?;
        // The sample is on the sphere, its pdf is pdf_li's, and it is seen along wi.
        assert!(((ls.p - center).length() - radius).abs() < 1e-4 * radius.max(1.0));
        let (n, _, _) = s.surface(ls.p);
        let pdf = a.pdf_li(p_ref, ls.p, n);
        assert!((ls.pdf - pdf).abs() <= 1e-3 * pdf, "{name}: pdf {} vs pdf_li {pdf}", ls.pdf);
        assert!(((ls.p - p_ref).normalize() - ls.wi).length() < 1e-3);
        Some(ls.wi)
    });
    let ok = chi2_directions(name, &cap, samples, &|w| sphere_direction_pdf(&a, &s, p_ref, w));
    assert!(ok > 0.999, "{name}: only {ok} of the samples succeeded");
}

#[test]
fn chi2_sphere_light_near() {
    chi2_sphere("sphere, near", Vec3::new(0.0, 1.0, 0.5), 0.8, false, Vec3::new(0.1, 0.0, -0.2), 4);
}

#[test]
fn chi2_sphere_light_far() {
    chi2_sphere("sphere, far", Vec3::new(30.0, 40.0, -10.0), 0.5, false, Vec3::new(0.1, 0.0, -0.2), 5);
}

#[test]
fn chi2_sphere_light_from_inside() {
    // An inward-facing sphere lighting its interior: area sampling.
    chi2_sphere("sphere, inside", Vec3::new(0.0, 0.0, 0.0), 2.0, true, Vec3::new(0.7, -0.4, 0.9), 6);
}

#[test]
fn chi2_constant_light() {
    let l = Light::Constant { radiance: Rgb::splat(1.0) };
    let mut rng = Pcg32::new(7, 3);
    let b = bounds();
    let p = Vec3::new(0.3, 0.2, 0.1);
    let cap = Cap::full_sphere(16, 32);
    chi2_directions("constant", &cap, (0..SAMPLES).map(|_| l.sample_li(p, u2(&mut rng), &b).map(|s| s.wi)), &|w| l.pdf_li_escaped(w) as f64);
}

#[test]
fn chi2_envmap() {
    let env = test_envmap(Mat4::from_rotation_x(0.4) * Mat4::from_rotation_y(-1.1));
    let l = Light::EnvMap(Box::new(env));
    let mut rng = Pcg32::new(8, 4);
    let b = bounds();
    let p = Vec3::new(0.3, 0.2, 0.1);
    let cap = Cap::full_sphere(32, 64);
    let samples = (0..SAMPLES).map(|_| {
        let s = l.sample_li(p, u2(&mut rng), &b)?;
        let pdf = l.pdf_li_escaped(s.wi);
        assert!((s.pdf - pdf).abs() <= 2e-3 * pdf, "envmap: pdf {} vs pdf {pdf}", s.pdf);
        assert!((s.li - l.le_escaped(s.wi)).max_component().abs() < 1e-4 * s.li.max_component().max(1.0));
        Some(s.wi)
    });
    chi2_directions("envmap", &cap, samples, &|w| l.pdf_li_escaped(w) as f64);
}

// ---------------------------------------------------------------------------------------
// sample_le against pdf_le.

/// Chi-square of points on a unit square (u, v) against the uniform density.
fn chi2_uniform_square(name: &str, pts: &[Vec2], n: usize) {
    let mut observed = vec![0.0f64; n * n];
    for p in pts {
        let i = ((p.x.clamp(0.0, 0.999_999) * n as f32) as usize).min(n - 1);
        let j = ((p.y.clamp(0.0, 0.999_999) * n as f32) as usize).min(n - 1);
        observed[i * n + j] += 1.0;
    }
    let expected = vec![pts.len() as f64 / (n * n) as f64; n * n];
    let r = chi_square_test(&observed, &expected, 5.0);
    eprintln!("{name}: chi2 = {:.1}, dof = {}, p = {:.4}", r.statistic, r.dof, r.p_value);
    assert!(r.p_value > alpha(), "{name}: not uniform (p {:.2e})", r.p_value);
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

#[test]
fn chi2_sample_le_quad() {
    let (p0, e1, e2) = (Vec3::new(-1.0, 1.5, -1.0), Vec3::new(0.0, 0.0, 2.0), Vec3::new(3.0, 0.0, 0.0));
    let (a, l) = area_light(quad(p0, e1, e2), Rgb::new(1.0, 2.0, 3.0));
    let n_quad = e1.cross(e2).normalize();
    let b = bounds();
    let mut rng = Pcg32::new(9, 5);
    let mut pos = Vec::new();
    let mut dirs = Vec::new();
    let mut rim = 0;
    for _ in 0..SAMPLES {
        // u_dir.x = 0 exactly maps to the hemisphere's rim (cos = 0, density 0): no sample.
        let Some(es) = l.sample_le(u2(&mut rng), u2(&mut rng), 0.25, &b) else {
            rim += 1;
            continue;
        };
        assert!((es.n - n_quad).length() < 1e-5);
        assert_eq!(es.ray.time, 0.25);
        assert_eq!(es.le, Rgb::new(1.0, 2.0, 3.0));
        let (pp, pd) = l.pdf_le(&es.ray, es.n, &b);
        assert!(close(pp, es.pdf_pos, 1e-5) && close(pd, es.pdf_dir, 1e-4), "pdf_le {pp} {pd} vs {} {}", es.pdf_pos, es.pdf_dir);
        assert!(close(es.pdf_pos, 1.0 / a.area, 1e-5));
        let q = es.ray.o - p0;
        pos.push(Vec2::new(q.dot(e1) / e1.length_squared(), q.dot(e2) / e2.length_squared()));
        dirs.push(es.ray.d);
    }
    assert!(rim <= SAMPLES / 10_000, "{rim} of {SAMPLES} emission samples missing");
    chi2_uniform_square("sample_le quad positions", &pos, 10);
    let cap = Cap::new(n_quad, std::f64::consts::FRAC_PI_2, 12, 24);
    chi2_directions("sample_le quad directions", &cap, dirs.into_iter().map(Some), &|w| l.pdf_le(&Ray::new(Vec3::ZERO, w), n_quad, &b).1 as f64);
}

#[test]
fn chi2_sample_le_sphere() {
    let (a, _s) = sphere_light(Vec3::new(1.0, 0.0, 0.0), 0.5, false, Rgb::splat(1.0));
    let l = Light::Area(a);
    let b = bounds();
    let mut rng = Pcg32::new(10, 6);
    let (mut normals, mut local) = (Vec::new(), Vec::new());
    for _ in 0..SAMPLES {
        let es = l.sample_le(u2(&mut rng), u2(&mut rng), 0.5, &b).expect("sphere emits");
        let (pp, pd) = l.pdf_le(&es.ray, es.n, &b);
        assert!(close(pp, es.pdf_pos, 1e-5) && close(pd, es.pdf_dir, 1e-4));
        normals.push(Some(es.n));
        local.push(Some(Frame::from_normal(es.n).to_local(es.ray.d)));
    }
    let cap = Cap::full_sphere(12, 24);
    let inv_area = 1.0 / (4.0 * std::f64::consts::PI);
    chi2_directions("sample_le sphere positions", &cap, normals.into_iter(), &|_| inv_area);
    let hemi = Cap::new(Vec3::Z, std::f64::consts::FRAC_PI_2, 12, 24);
    chi2_directions("sample_le sphere directions", &hemi, local.into_iter(), &|w| (w.z.max(0.0) / PI) as f64);
}

#[test]
fn chi2_sample_le_point_and_spot() {
    let b = bounds();
    let point = Light::point(Vec3::new(0.0, 1.0, 0.0), Rgb::splat(3.0));
    let mut rng = Pcg32::new(11, 7);
    let dirs: Vec<Option<Vec3>> = (0..SAMPLES)
        .map(|_| {
            let es = point.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b).unwrap();
            assert_eq!(es.ray.o, Vec3::new(0.0, 1.0, 0.0));
            assert_eq!(es.pdf_pos, 1.0);
            Some(es.ray.d)
        })
        .collect();
    chi2_directions("sample_le point", &Cap::full_sphere(12, 24), dirs.into_iter(), &|w| point.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64);

    let to_world = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0)) * Mat4::from_rotation_x(2.0) * Mat4::from_rotation_z(0.3);
    let spot = Light::spot(&to_world, Rgb::splat(5.0), 30.0, Some(20.0));
    let axis = to_world.transform_vector3(Vec3::Z).normalize();
    let dirs: Vec<Option<Vec3>> = (0..SAMPLES)
        .map(|_| {
            let es = spot.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b).unwrap();
            assert!(close(es.le.r, 5.0 * spot.spot_falloff(es.ray.d), 1e-6));
            assert!(close(es.pdf_dir, spot.pdf_le(&es.ray, es.n, &b).1, 1e-4));
            Some(es.ray.d)
        })
        .collect();
    let cap = Cap::new(axis, 32f64.to_radians(), 12, 24);
    chi2_directions("sample_le spot", &cap, dirs.into_iter(), &|w| spot.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64);
}

/// The projector's emitted directions (uniform over its image plane, pdf 1 / (4 tan_x tan_y
/// cos³θ)) against `pdf_le`, with a textured image and an oblique, non-square frustum; the
/// emitted radiance is the intensity toward the sampled direction.
#[test]
fn chi2_sample_le_projector() {
    let b = bounds();
    let to_world = Mat4::from_translation(Vec3::new(-1.0, 0.5, 2.0)) * Mat4::from_rotation_y(0.7) * Mat4::from_rotation_x(-0.4);
    let image = Arc::new(Bitmap::new(2, 2, vec![Rgb::splat(0.2), Rgb::new(1.0, 0.5, 0.1), Rgb::splat(3.0), Rgb::BLACK]));
    let tex = Texture::Bitmap { image, filter: svetlo::texture::FilterMode::Nearest, wrap: svetlo::texture::WrapMode::Clamp, to_uv: glam::Affine2::IDENTITY };
    let pr = svetlo::light::Projector::new(&to_world, 50.0, 1.6, tex, 2.0).unwrap();
    let half = (pr.tan_x.hypot(pr.tan_y) as f64).atan();
    let light = Light::Projector(Box::new(pr.clone()));
    let axis = to_world.transform_vector3(Vec3::Z).normalize();
    let mut rng = Pcg32::new(21, 3);
    let dirs: Vec<Option<Vec3>> = (0..SAMPLES)
        .map(|_| {
            let es = light.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b)?;
            assert!((es.ray.o - pr.position).length() < 1e-5);
            assert!(close(es.pdf_dir, light.pdf_le(&es.ray, es.n, &b).1, 1e-4));
            let i = pr.intensity(es.ray.d);
            assert!(close(es.le.r, i.r, 1e-4) && close(es.le.g, i.g, 1e-4), "{:?} vs {i:?}", es.le);
            Some(es.ray.d)
        })
        .collect();
    let cap = Cap::new(axis, half + 0.05, 12, 24);
    chi2_directions("sample_le projector", &cap, dirs.into_iter(), &|w| light.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64);
}

/// Origins of rays from infinity: on the bounding sphere's disk, one radius behind the center.
fn disk_coords(b: &SceneBounds, ray: &Ray) -> Vec2 {
    let off = ray.o - b.center;
    assert!((off.dot(ray.d) + b.radius).abs() < 1e-3 * b.radius, "origin not on the entry disk");
    let l = Frame::from_normal(ray.d).to_local(off);
    let mut phi = l.y.atan2(l.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    // (r / R)² and φ / 2π are uniform for a uniform point on the disk.
    Vec2::new((l.x * l.x + l.y * l.y) / (b.radius * b.radius), phi / (2.0 * PI))
}

#[test]
fn chi2_sample_le_infinite_lights() {
    let b = bounds();
    let mut rng = Pcg32::new(12, 8);
    let env = Light::EnvMap(Box::new(test_envmap(Mat4::from_rotation_z(0.5))));
    let mut pts = Vec::new();
    let mut dirs = Vec::new();
    for _ in 0..SAMPLES {
        let es = env.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b).expect("envmap emits");
        let (pp, pd) = env.pdf_le(&es.ray, es.n, &b);
        assert!(close(pp, es.pdf_pos, 1e-5) && close(pd, es.pdf_dir, 2e-3), "envmap pdf_le {pp} {pd} vs {} {}", es.pdf_pos, es.pdf_dir);
        assert!(close(es.pdf_pos, 1.0 / (PI * b.radius * b.radius), 1e-5));
        pts.push(disk_coords(&b, &es.ray));
        dirs.push(Some(es.ray.d));
    }
    chi2_uniform_square("sample_le envmap origins", &pts, 10);
    chi2_directions("sample_le envmap directions", &Cap::full_sphere(24, 48), dirs.into_iter(), &|w| env.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64);

    let dir = Vec3::new(0.3, -1.0, 0.2).normalize();
    let sun = Light::Directional { direction: dir, irradiance: Rgb::splat(2.0) };
    let pts: Vec<Vec2> = (0..SAMPLES)
        .map(|_| {
            let es = sun.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b).unwrap();
            assert_eq!(es.ray.d, dir);
            assert_eq!(es.pdf_dir, 1.0);
            assert!(close(es.pdf_pos, sun.pdf_le(&es.ray, es.n, &b).0, 1e-6));
            disk_coords(&b, &es.ray)
        })
        .collect();
    chi2_uniform_square("sample_le directional origins", &pts, 10);
}

// ---------------------------------------------------------------------------------------
// Densities integrate to one.

fn integrate_sphere(pdf: &dyn Fn(Vec3) -> f64, n: usize) -> f64 {
    let cap = Cap::full_sphere(n, 2 * n);
    let mut s = 0.0;
    for i in 0..n {
        for j in 0..2 * n {
            s += cap.integrate_cell(i, j, 2, pdf).0;
        }
    }
    s
}

#[test]
fn pdfs_integrate_to_one() {
    let b = bounds();
    let p = Vec3::new(0.1, 0.0, -0.2);
    // Sphere light from outside (cone) and inside (area measure).
    let (a, s) = sphere_light(Vec3::new(0.0, 1.0, 0.5), 0.8, false, Rgb::splat(1.0));
    let v = integrate_sphere(&|w| sphere_direction_pdf(&a, &s, p, w), 400);
    assert!((v - 1.0).abs() < 5e-3, "sphere cone: {v}");
    let (a, s) = sphere_light(Vec3::ZERO, 2.0, true, Rgb::splat(1.0));
    let v = integrate_sphere(&|w| sphere_direction_pdf(&a, &s, Vec3::new(0.7, -0.4, 0.9), w), 200);
    assert!((v - 1.0).abs() < 2e-3, "sphere inside: {v}");
    // A triangle facing the point: all of its area is visible.
    let m = mesh(vec![Vec3::new(-1.0, 2.0, -0.5), Vec3::new(1.5, 2.2, 0.0), Vec3::new(0.0, 1.8, 1.5)], vec![[0, 1, 2]]);
    let (a, _) = area_light(m, Rgb::splat(1.0));
    let v = integrate_sphere(&|w| mesh_direction_pdf(&a, p, w), 600);
    assert!((v - 1.0).abs() < 5e-3, "triangle: {v}");
    // Environment map and constant.
    let env = Light::EnvMap(Box::new(test_envmap(Mat4::from_rotation_y(0.3))));
    let v = integrate_sphere(&|w| env.pdf_li_escaped(w) as f64, 400);
    assert!((v - 1.0).abs() < 2e-3, "envmap: {v}");
    // Emission directions: area (cosine), point (uniform), spot (cone).
    let (a, l) = area_light(quad(Vec3::ZERO, Vec3::X, Vec3::Y), Rgb::splat(1.0));
    let _ = a;
    let v = integrate_sphere(&|w| l.pdf_le(&Ray::new(Vec3::ZERO, w), Vec3::Z, &b).1 as f64, 200);
    assert!((v - 1.0).abs() < 2e-3, "area emission: {v}");
    let spot = Light::spot(&Mat4::from_rotation_x(0.5), Rgb::splat(1.0), 25.0, None);
    let v = integrate_sphere(&|w| spot.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64, 800);
    assert!((v - 1.0).abs() < 5e-3, "spot emission: {v}");
}

// ---------------------------------------------------------------------------------------
// Irradiance against closed forms.

/// Monte Carlo irradiance at `p` with normal `n` from one light: mean and standard error.
fn irradiance(light: &Light, p: Vec3, n: Vec3, samples: usize, seed: u64) -> (f64, f64) {
    let b = bounds();
    let mut rng = Pcg32::new(seed, 9);
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for _ in 0..samples {
        let x = match light.sample_li(p, u2(&mut rng), &b) {
            Some(ls) if ls.pdf > 0.0 => (ls.li.r * n.dot(ls.wi).max(0.0) / ls.pdf) as f64,
            _ => 0.0,
        };
        s += x;
        s2 += x * x;
    }
    let mean = s / samples as f64;
    (mean, ((s2 / samples as f64 - mean * mean) / samples as f64).max(0.0).sqrt())
}

#[test]
fn point_light_irradiance_is_inverse_square() {
    let l = Light::point(Vec3::new(0.0, 3.0, 0.0), Rgb::splat(12.0));
    let (e, _) = irradiance(&l, Vec3::ZERO, Vec3::Y, 4, 1);
    assert!((e - 12.0 / 9.0).abs() < 1e-5, "{e}");
    // Tilted receiver: E = I cos θ / r².
    let n = Vec3::new(1.0, 1.0, 0.0).normalize();
    let (e, _) = irradiance(&l, Vec3::ZERO, n, 4, 1);
    assert!((e - 12.0 / 9.0 * std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-5, "{e}");
}

#[test]
fn sphere_light_irradiance() {
    // A sphere of radiance L and radius r at distance d, facing: E = π L (r/d)².
    for &(r, d) in &[(0.5f32, 3.0f32), (1.0, 1.2), (0.1, 50.0)] {
        let (a, _) = sphere_light(Vec3::new(0.0, d, 0.0), r, false, Rgb::splat(2.0));
        let (e, se) = irradiance(&Light::Area(a), Vec3::ZERO, Vec3::Y, 100_000, 2);
        let exact = std::f64::consts::PI * 2.0 * (r as f64 / d as f64).powi(2);
        assert!((e - exact).abs() < 5.0 * se + 1e-6 * exact, "r={r} d={d}: {e} ± {se} vs {exact}");
    }
}

/// Irradiance from a Lambertian polygon of radiance `l` (Lambert's formula): E = L/2 Σ γ_i (n · u_i),
/// γ_i the angle each edge subtends and u_i the unit normal of the plane through it and p.
fn lambert_polygon(p: Vec3, n: Vec3, verts: &[Vec3], l: f64) -> f64 {
    let mut s = 0.0f64;
    for i in 0..verts.len() {
        let a = (verts[i] - p).as_dvec3().normalize();
        let b = (verts[(i + 1) % verts.len()] - p).as_dvec3().normalize();
        let c = a.cross(b);
        let gamma = a.dot(b).clamp(-1.0, 1.0).acos();
        s += gamma * n.as_dvec3().dot(c.normalize());
    }
    0.5 * l * s.abs()
}

#[test]
fn large_area_light_irradiance() {
    // A regular 96-gon of radius 2 at height 1, facing down, radiance 1.5.
    let (r, h, k) = (2.0f32, 1.0f32, 96usize);
    let mut pos = vec![Vec3::new(0.0, h, 0.0)];
    for i in 0..k {
        let t = 2.0 * PI * i as f32 / k as f32;
        pos.push(Vec3::new(r * t.cos(), h, r * t.sin()));
    }
    let idx: Vec<[u32; 3]> = (0..k as u32).map(|i| [0, 1 + i, 1 + (i + 1) % k as u32]).collect();
    let m = mesh(pos.clone(), idx);
    // Faces down (toward the receiver at the origin)?
    let (ng, _, _, _) = m.surface(0, 0.3, 0.3);
    assert!(ng.y < 0.0, "the polygon must face the receiver");
    let (_, light) = area_light(m, Rgb::splat(1.5));
    for (p, n) in [(Vec3::ZERO, Vec3::Y), (Vec3::new(0.7, 0.0, -0.4), Vec3::new(0.3, 1.0, 0.1).normalize())] {
        let exact = lambert_polygon(p, n, &pos[1..], 1.5);
        let (e, se) = irradiance(&light, p, n, 200_000, 3);
        assert!((e - exact).abs() < 5.0 * se, "at {p}: {e} ± {se} vs Lambert {exact}");
    }
    // The polygon approximates the disk: E = π L R² / (h² + R²), up to the area it misses.
    let disk = std::f64::consts::PI * 1.5 * (r * r) as f64 / (h * h + r * r) as f64;
    let polygon = lambert_polygon(Vec3::ZERO, Vec3::Y, &pos[1..], 1.5);
    assert!((polygon - disk).abs() < 2e-3 * disk, "polygon {polygon} vs disk {disk}");
}

#[test]
fn spot_profile_and_power_follow_mitsuba() {
    let spot = Light::spot(&Mat4::IDENTITY, Rgb::splat(2.0), 20.0, None);
    // Beam width defaults to 15 degrees: full inside, linear in angle to 0 at 20 degrees.
    let at = |deg: f32| spot.spot_falloff(Vec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos()));
    assert_eq!(at(0.0), 1.0);
    assert_eq!(at(14.9), 1.0);
    assert!((at(17.5) - 0.5).abs() < 1e-3, "{}", at(17.5));
    assert!((at(19.0) - 0.2).abs() < 1e-3, "{}", at(19.0));
    assert_eq!(at(20.5), 0.0);
    // Power = I ∫ profile dω: compare the closed form with a numerical integral.
    let n = 200_000;
    let mut s = 0.0f64;
    for i in 0..n {
        let t = (i as f64 + 0.5) / n as f64 * 0.4; // θ up to 0.4 rad > 20 degrees
        s += at(t.to_degrees() as f32) as f64 * t.sin() * 0.4 / n as f64;
    }
    let numeric = 2.0 * std::f64::consts::PI * s * 2.0 * Rgb::splat(1.0).luminance() as f64;
    let p = spot.power(&bounds()) as f64;
    assert!((p - numeric).abs() < 1e-3 * numeric, "power {p} vs {numeric}");
}

#[test]
fn envmap_pdf_is_consistent_with_radiance() {
    // A constant map: the luminance × sin θ density makes directions uniform (1/4π),
    // up to the interpolation of sin θ between rows (small away from the poles).
    let data = vec![Rgb::splat(0.7); 64 * 32];
    let env = EnvMap::new(Arc::new(Bitmap::new(64, 32, data)), Mat4::from_rotation_x(0.3), 2.0);
    let mut rng = Pcg32::new(5, 5);
    for _ in 0..1000 {
        let w = svetlo::math::warp::square_to_uniform_sphere(u2(&mut rng));
        assert!((env.eval(w).r - 1.4).abs() < 1e-5);
        let l = Mat4::from_rotation_x(-0.3).transform_vector3(w);
        if l.y.abs() < 0.95 {
            let pdf = env.pdf(w) * 4.0 * PI;
            assert!((pdf - 1.0).abs() < 0.02, "uniform map: 4π pdf = {pdf} at {l}");
        }
    }
    // A general map: wherever radiance has luminance, the pdf is positive.
    let env = test_envmap(Mat4::IDENTITY);
    for _ in 0..20_000 {
        let w = svetlo::math::warp::square_to_uniform_sphere(u2(&mut rng));
        if env.eval(w).luminance() > 0.0 && w.y.abs() < 0.999 {
            assert!(env.pdf(w) > 0.0, "radiance without density at {w}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// Luminaires from photometric files.

fn photometry_file(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/photometry").join(name)
}

/// A luminaire of an asymmetric real file where the shared folder has it (rab_3: 0-360°,
/// absolute photometry), else a small asymmetric EULUMDAT of our own.
fn test_luminaire(to_world: &Mat4, spread: bool) -> Light {
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/photometry/ies/rab_3.ies");
    let path = if shared.is_file() { shared } else { photometry_file("asymmetric_sym0.ldt") };
    let p = svetlo::photometry::load(&path).unwrap();
    let opening = spread.then_some(svetlo::photometry::Opening::Rectangle { length: 0.6, width: 0.3, height: 0.0 });
    Light::Luminaire(Box::new(svetlo::light::Luminaire::new(Arc::new(p.table), to_world, 1.0, Rgb::WHITE, opening)))
}

#[test]
fn chi2_sample_le_luminaires() {
    let b = bounds();
    let to_world = Mat4::from_translation(Vec3::new(0.5, -1.0, 2.0)) * Mat4::from_rotation_x(0.4) * Mat4::from_rotation_z(1.1);
    let mut rng = Pcg32::new(18, 3);
    for (name, file) in [
        ("sample_le luminaire (type C, asymmetric)", None),
        ("sample_le luminaire (type B)", Some("type_b.ies")),
        ("sample_le luminaire (type A)", Some("type_a_1986.ies")),
    ] {
        let l = match file {
            None => test_luminaire(&to_world, false),
            Some(f) => {
                let p = svetlo::photometry::load(&photometry_file(f)).unwrap();
                Light::Luminaire(Box::new(svetlo::light::Luminaire::new(Arc::new(p.table), &to_world, 1.0, Rgb::WHITE, None)))
            }
        };
        let Light::Luminaire(lum) = &l else { unreachable!() };
        let mut mismatched = 0usize;
        let dirs: Vec<Option<Vec3>> = (0..SAMPLES)
            .map(|_| {
                let es = l.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b)?;
                // Near the pole φ is ill-conditioned in f32: a neighbouring cell may answer.
                if !close(es.pdf_dir, l.pdf_le(&es.ray, es.n, &b).1, 1e-3) {
                    mismatched += 1;
                }
                assert!(close(es.le.g, lum.intensity(es.ray.d).g, 1e-6));
                Some(es.ray.d)
            })
            .collect();
        assert!(mismatched < SAMPLES / 1000, "{name}: {mismatched} samples' pdfs differ from pdf_le");
        // Bins: each of the table's cells split 2 x 2 in (φ, cos θ), where the density is
        // constant, so the expected counts are exact (pmf / 4).
        let (phi, theta) = lum.table.grid();
        let (np, nt) = (phi.len() - 1, theta.len() - 1);
        let mut observed = vec![0.0f64; np * nt * 4 + 1];
        let inv = |w: Vec3| Vec3::new(w.dot(lum.axes[0]), w.dot(lum.axes[1]), w.dot(lum.axes[2]));
        for d in dirs.iter() {
            let Some(d) = d else {
                observed[np * nt * 4] += 1.0;
                continue;
            };
            let (f, t) = lum.table.direction_angles(inv(*d));
            let i = phi.partition_point(|a| *a <= f).clamp(1, np) - 1;
            let j = theta.partition_point(|a| *a <= t).clamp(1, nt) - 1;
            let si = usize::from(f > 0.5 * (phi[i] + phi[i + 1]));
            let cm = 0.5 * (theta[j].cos() + theta[j + 1].cos());
            let sj = usize::from(t.cos() < cm);
            observed[((i * nt + j) * 2 + si) * 2 + sj] += 1.0;
        }
        let mut expected: Vec<f64> = (0..np * nt * 4).map(|k| lum.table.cell_probability(k / 4 / nt, (k / 4) % nt) * 0.25 * SAMPLES as f64).collect();
        expected.push(0.0);
        let r = chi_square_test(&observed, &expected, 5.0);
        eprintln!("{name}: chi2 = {:.1}, dof = {}, p = {:.4}", r.statistic, r.dof, r.p_value);
        assert!(r.p_value > alpha(), "{name}: sampling does not match its cells (p {:.2e})", r.p_value);
        let v = integrate_sphere(&|w| l.pdf_le(&Ray::new(Vec3::ZERO, w), w, &b).1 as f64, 400);
        assert!((v - 1.0).abs() < 5e-3, "{name}: pdf integrates to {v}");
    }
}

#[test]
fn luminaire_puts_its_file_flux_into_the_scene() {
    // The flux a light tracer emits, E[le |n.d| / (pdf_pos pdf_dir)] × 683 lm/W by Rec.709
    // luminance, is the file's integrated flux: within 5 standard errors of the estimate
    // (and the estimator's variance is small: the sampling follows the cells' flux).
    let b = bounds();
    let l = test_luminaire(&Mat4::from_rotation_y(0.7), true);
    let Light::Luminaire(lum) = &l else { unreachable!() };
    let want = lum.flux_lm();
    let mut rng = Pcg32::new(5, 5);
    let n = 100_000;
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for _ in 0..n {
        let x = match l.sample_le(u2(&mut rng), u2(&mut rng), 0.0, &b) {
            Some(es) => (es.le.luminance() / (es.pdf_pos * es.pdf_dir)) as f64 * 683.0,
            None => 0.0,
        };
        s += x;
        s2 += x * x;
    }
    let mean = s / n as f64;
    let se = ((s2 / n as f64 - mean * mean) / n as f64).sqrt();
    eprintln!("emitted {mean:.2} ± {se:.2} lm, file {want:.2} lm");
    assert!((mean - want).abs() < 5.0 * se + 1e-4 * want, "{mean} ± {se} against {want}");
    // Selection power is the same flux in W.
    assert!(close(l.power(&b) * 683.0, want as f32, 1e-4));
    // And the colour does not change it.
    let p = svetlo::photometry::load(&photometry_file("asymmetric_sym0.ldt")).unwrap();
    let want = p.flux();
    let red = svetlo::light::Luminaire::new(Arc::new(p.table), &Mat4::IDENTITY, 2.0, Rgb::new(1.0, 0.2, 0.1), None);
    assert!(((red.flux_lm() - 2.0 * want) / want).abs() < 1e-5);
}

#[test]
fn luminaire_frame_hangs_down_as_ies2rad() {
    // rab_7 (a downlight) or our quadrant file: intensity at the nadir, along the frame's −Z;
    // C90 along +Y. With an identity transform the beam points down a Z-up scene.
    let p = svetlo::photometry::load(&photometry_file("quadrant_sym4.ldt")).unwrap();
    let lum = svetlo::light::Luminaire::new(Arc::new(p.table), &Mat4::IDENTITY, 1.0, Rgb::WHITE, None);
    let c = |w: Vec3| lum.candela(w.normalize());
    assert!((c(Vec3::NEG_Z) - 100.0).abs() < 1e-3);
    assert!((c(Vec3::new(0.0, 1.0, -1.0)) - 300.0).abs() < 1e-2, "C90 toward +Y: {}", c(Vec3::new(0.0, 1.0, -1.0)));
    assert!((c(Vec3::new(1.0, 0.0, -1.0)) - 100.0).abs() < 1e-2, "C0 toward +X");
    assert_eq!(c(Vec3::Z), 0.0);
    // Point over a plane (CIE 171:2006 in spirit, test case 5.2: a point source over a
    // horizontal plane): E = I(γ) cos γ / d² at horizontal offset x and height h, with
    // cos γ = h/d; NEE from the light gives it exactly.
    let l = Light::Luminaire(Box::new(lum.clone()));
    let (h, x) = (2.5f32, 1.5f32);
    let mut rng = Pcg32::new(1, 1);
    let p0 = Vec3::new(0.0, x, -h);
    let ls = l.sample_li(p0, u2(&mut rng), &bounds()).unwrap();
    let e = (ls.li.luminance() * ls.wi.dot(Vec3::Z) / ls.pdf) as f64 * 683.0;
    let d2 = (h * h + x * x) as f64;
    let gamma = (x as f64).atan2(h as f64).to_degrees();
    // Quadrant file: C90 is 300 cd for γ ≤ 90°.
    let want = 300.0 * (h as f64 / d2.sqrt()) / d2;
    assert!((e - want).abs() < 1e-4 * want, "γ = {gamma:.1}°: {e} lx against {want}");
}
