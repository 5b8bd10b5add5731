//! Illuminance (lux) on a work plane by two independent estimators:
//! * gathering: at each grid point, E = Σ over delta lights of I cos γ / r² (visible) plus
//!   π × the mean radiance the path tracer returns along cosine-distributed rays (which sees
//!   area lights and every interreflection) — an estimate at the point, with its standard
//!   error over samples;
//! * light tracing: photons from the lights (chosen by power) walk the scene by BSDF
//!   sampling in importance mode; every segment that crosses the plane's rectangle from the
//!   side its normal faces deposits its flux on the cell it crosses. The plane is virtual
//!   (it blocks nothing). An estimate of the cell's mean illuminance, with the standard
//!   error from independent batches;
//! * radiosity: E = the delta lights' direct irradiance (shadow rays) + Σ_j B_j F(x → j) V(x, j)
//!   over the solved elements j (B the exitance, F Lambert's point-to-polygon form factor,
//!   V the unblocked fraction of shadow rays to points of j); its error bound is the change
//!   from a solve at twice the element size (constant elements converge in O(h)).
//!
//! Luminous quantities from radiometric RGB by 683 lm/W and the Rec.709 weights.

use super::LM_PER_W;
use crate::bsdf::TransportMode;
use crate::geometry::Ray;
use crate::integrator::path::PathTracer;
use crate::integrator::{PixelEstimator, RenderSettings};
use crate::light::Light;
use crate::radiosity::RadiosityOptions;
use crate::sampling::{IndependentSampler, Sampler};
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A rectangle `origin + s u + t v` (s, t in [0, 1]) sampled at cell centres `spacing`
/// apart; E is measured on the side of the normal u × v.
#[derive(Clone, Copy, Debug)]
pub struct WorkPlane {
    pub origin: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub spacing: f32,
}

impl WorkPlane {
    pub fn normal(&self) -> Vec3 {
        self.u.cross(self.v).normalize_or_zero()
    }

    /// Cells along u and v (at least one each).
    pub fn dims(&self) -> (usize, usize) {
        let n = |l: f32| ((l / self.spacing).round() as usize).max(1);
        (n(self.u.length()), n(self.v.length()))
    }

    /// Centre of cell (i, j).
    pub fn point(&self, i: usize, j: usize) -> Vec3 {
        let (nu, nv) = self.dims();
        self.origin + self.u * ((i as f32 + 0.5) / nu as f32) + self.v * ((j as f32 + 0.5) / nv as f32)
    }

    /// Parse `origin=x,y,z u=x,y,z v=x,y,z`.
    pub fn parse(s: &str, spacing: f32) -> Result<WorkPlane, String> {
        let mut o = None;
        let (mut u, mut v) = (None, None);
        for part in s.split_whitespace() {
            let (k, val) = part.split_once('=').ok_or_else(|| format!("expected key=x,y,z, got '{part}'"))?;
            let xs: Vec<f32> = val.split(',').map(|x| x.trim().parse::<f32>().map_err(|_| format!("'{val}' is not x,y,z"))).collect::<Result<_, _>>()?;
            if xs.len() != 3 || xs.iter().any(|x| !x.is_finite()) {
                return Err(format!("'{val}' is not three numbers"));
            }
            let p = Vec3::new(xs[0], xs[1], xs[2]);
            match k {
                "origin" => o = Some(p),
                "u" => u = Some(p),
                "v" => v = Some(p),
                _ => return Err(format!("unknown plane key '{k}' (origin, u, v)")),
            }
        }
        let (Some(origin), Some(u), Some(v)) = (o, u, v) else { return Err("the plane needs origin=, u= and v=".into()) };
        if !(spacing > 0.0 && spacing.is_finite()) {
            return Err(format!("spacing must be positive, got {spacing}"));
        }
        let p = WorkPlane { origin, u, v, spacing };
        if p.normal() == Vec3::ZERO {
            return Err("u and v must span a plane".into());
        }
        let (nu, nv) = p.dims();
        if nu * nv > 4_000_000 {
            return Err(format!("{nu} x {nv} grid points is too many"));
        }
        Ok(p)
    }
}

/// Lux per grid point (u outer index i, v inner j: `values[i * nv + j]`) with standard errors.
#[derive(Clone, Debug)]
pub struct IlluminanceGrid {
    pub plane: WorkPlane,
    pub lux: Vec<f64>,
    pub std_err: Vec<f64>,
    pub method: &'static str,
    /// "lx", or "%" for a daylight-factor grid.
    pub unit: &'static str,
}

impl IlluminanceGrid {
    pub fn min(&self) -> f64 {
        self.lux.iter().copied().fold(f64::INFINITY, f64::min)
    }
    pub fn max(&self) -> f64 {
        self.lux.iter().copied().fold(0.0, f64::max)
    }
    pub fn mean(&self) -> f64 {
        self.lux.iter().sum::<f64>() / self.lux.len() as f64
    }
    /// Uniformity U0 = Emin / Eavg.
    pub fn uniformity(&self) -> f64 {
        self.min() / self.mean()
    }

    /// The daylight factor DF = 100 E / E_out (%), E_out the unobstructed horizontal
    /// illuminance outdoors under the same sky ([`super::sky::unobstructed_illuminance`]).
    pub fn daylight_factor(mut self, e_out: f64) -> IlluminanceGrid {
        let k = if e_out > 0.0 { 100.0 / e_out } else { 0.0 };
        self.lux.iter_mut().chain(self.std_err.iter_mut()).for_each(|x| *x *= k);
        self.unit = "%";
        self
    }

    pub fn to_csv(&self) -> String {
        let (nu, nv) = self.plane.dims();
        let mut s = format!("i,j,x,y,z,{},std_err\n", if self.unit == "%" { "daylight_factor_percent" } else { "lux" });
        for i in 0..nu {
            for j in 0..nv {
                let p = self.plane.point(i, j);
                let k = i * nv + j;
                s += &format!("{i},{j},{},{},{},{:.4},{:.4}\n", p.x, p.y, p.z, self.lux[k], self.std_err[k]);
            }
        }
        s
    }

    pub fn to_json(&self) -> String {
        let (nu, nv) = self.plane.dims();
        let list = |v: &[f64]| v.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>().join(",");
        format!(
            "{{\"method\":\"{}\",\"unit\":\"{}\",\"nu\":{nu},\"nv\":{nv},\"spacing\":{},\"e_min\":{:.4},\"e_avg\":{:.4},\"e_max\":{:.4},\"u0\":{:.5},\"e_min_over_e_max\":{:.5},\"lux\":[{}],\"std_err\":[{}]}}\n",
            self.method,
            self.unit,
            self.plane.spacing,
            self.min(),
            self.mean(),
            self.max(),
            self.uniformity(),
            self.min() / self.max().max(1e-300),
            list(&self.lux),
            list(&self.std_err)
        )
    }
}

/// Gathering estimator with `spp` samples per point.
pub fn gather(scene: &Scene, plane: &WorkPlane, spp: u32, settings: &RenderSettings) -> IlluminanceGrid {
    let (nu, nv) = plane.dims();
    let n = plane.normal();
    let frame = crate::math::Frame::from_normal(n);
    let res: Vec<(f64, f64)> = (0..nu * nv)
        .into_par_iter()
        .with_max_len(1) // a point a task: see `splat::render_chunked`
        .map(|k| {
            let (i, j) = (k / nv, k % nv);
            let p = plane.point(i, j);
            let mut sampler = IndependentSampler::new(spp, settings.seed);
            let (mut s, mut s2) = (0.0f64, 0.0f64);
            for si in 0..spp {
                sampler.start_pixel_sample(i as u32, j as u32, si);
                let mut e = 0.0f64;
                for light in scene.lights.iter().filter(|l| l.is_delta()) {
                    e += delta_irradiance(scene, light, p, n, sampler.next_2d());
                }
                let w = frame.to_world(crate::math::warp::square_to_cosine_hemisphere(sampler.next_2d()));
                let ray = Ray::new(crate::geometry::ray::offset_ray_origin(p, n, w), w);
                e += std::f64::consts::PI * PathTracer.li(scene, &ray, &mut sampler, settings).luminance() as f64;
                let e = e * LM_PER_W;
                s += e;
                s2 += e * e;
            }
            let m = s / spp as f64;
            (m, ((s2 / spp as f64 - m * m).max(0.0) / spp as f64).sqrt())
        })
        .collect();
    IlluminanceGrid { plane: *plane, lux: res.iter().map(|r| r.0).collect(), std_err: res.iter().map(|r| r.1).collect(), method: "gathering", unit: "lx" }
}

/// Illuminance (lx) at `p` facing `n` from everything but the delta lights (area lights,
/// skies, interreflection), by `spp` cosine-distributed rays through the path tracer: the
/// mean and its standard error. Glare ratings take the background luminance from it.
pub fn indirect_illuminance(scene: &Scene, p: Vec3, n: Vec3, spp: u32, settings: &RenderSettings) -> (f64, f64) {
    let frame = crate::math::Frame::from_normal(n);
    let mut sampler = IndependentSampler::new(spp, settings.seed ^ 0x91a2e);
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for si in 0..spp {
        sampler.start_pixel_sample(0, 0, si);
        let w = frame.to_world(crate::math::warp::square_to_cosine_hemisphere(sampler.next_2d()));
        let ray = Ray::new(crate::geometry::ray::offset_ray_origin(p, n, w), w);
        let e = std::f64::consts::PI * PathTracer.li(scene, &ray, &mut sampler, settings).luminance() as f64 * LM_PER_W;
        s += e;
        s2 += e * e;
    }
    let m = s / spp.max(1) as f64;
    (m, ((s2 / spp.max(1) as f64 - m * m).max(0.0) / spp.max(1) as f64).sqrt())
}

/// Irradiance (W/m², luminance) at `p` (normal `n`) from one delta light, shadow-tested;
/// `u` picks the point of a spread luminaire's opening.
fn delta_irradiance(scene: &Scene, light: &Light, p: Vec3, n: Vec3, u: Vec2) -> f64 {
    let Some(ls) = light.sample_li(p, u, &scene.bounds) else { return 0.0 };
    let cos = n.dot(ls.wi);
    if cos <= 0.0 || ls.pdf <= 0.0 {
        return 0.0;
    }
    let blocked = if ls.infinite { scene.occluded_dir(p, n, ls.wi) } else { scene.occluded_between(p, n, ls.p, ls.n, 0.0) };
    if blocked {
        0.0
    } else {
        (ls.li.luminance() * cos / ls.pdf) as f64
    }
}

/// Radiosity estimator: solve with `opts` and again at twice the element size; lux at each
/// grid point from the finer solution, `std_err` holding the discretisation bound
/// |E_h − E_2h| (the plane is virtual: it blocks nothing and is not meshed).
pub fn radiosity(scene: &Scene, plane: &WorkPlane, opts: &RadiosityOptions, settings: &RenderSettings) -> crate::error::Result<IlluminanceGrid> {
    let fine = crate::radiosity::solve(scene, opts, settings.max_depth)?;
    let h = opts.mesh.max_edge.unwrap_or(scene.bounds.radius.max(1e-6) / 5.0);
    let mut coarse_opts = opts.clone();
    coarse_opts.mesh.max_edge = Some(2.0 * h);
    let coarse = crate::radiosity::solve(scene, &coarse_opts, settings.max_depth)?;
    let (nu, nv) = plane.dims();
    let n = plane.normal();
    let delta: Vec<&Light> = scene.lights.iter().filter(|l| l.is_delta()).collect();
    let res: Vec<(f64, f64)> = (0..nu * nv)
        .into_par_iter()
        .with_max_len(1) // a point a task: see `splat::render_chunked`
        .map(|k| {
            let p = plane.point(k / nv, k % nv);
            // A 2 × 2 stratification of a spread opening (one point for the others).
            let us = [Vec2::new(0.25, 0.25), Vec2::new(0.75, 0.25), Vec2::new(0.25, 0.75), Vec2::new(0.75, 0.75)];
            let direct: f64 = delta.iter().map(|l| us.iter().map(|u| delta_irradiance(scene, l, p, n, *u)).sum::<f64>() / 4.0).sum();
            let ef = direct + gathered_from_elements(scene, &fine, p, n);
            let ec = direct + gathered_from_elements(scene, &coarse, p, n);
            (ef * LM_PER_W, (ef - ec).abs() * LM_PER_W)
        })
        .collect();
    Ok(IlluminanceGrid { plane: *plane, lux: res.iter().map(|r| r.0).collect(), std_err: res.iter().map(|r| r.1).collect(), method: "radiosity", unit: "lx" })
}

/// Σ_j B_j F(p → j) V(p, j) (luminance, W/m²) over the elements whose front faces `p`.
fn gathered_from_elements(scene: &Scene, solved: &crate::radiosity::Solved, p: Vec3, n: Vec3) -> f64 {
    use crate::radiosity::form_factor::analytic::{point_to_polygon, triangle_points};
    let mut e = 0.0;
    for (el, b) in solved.mesh.elements.iter().zip(&solved.b) {
        let b = b.luminance() as f64;
        if b <= 0.0 || el.normal.dot(p - el.centroid) <= 0.0 {
            continue;
        }
        let f = point_to_polygon(p, n, &el.p);
        if f <= 0.0 {
            continue;
        }
        let targets = triangle_points(&el.p, 2);
        let seen = targets.iter().filter(|y| !scene.occluded(p, n, **y)).count();
        e += b * f * seen as f64 / targets.len() as f64;
    }
    e
}

/// Light-tracing estimator: `photons` paths in `BATCHES` independent batches.
pub fn light_trace(scene: &Scene, plane: &WorkPlane, photons: u64, settings: &RenderSettings) -> IlluminanceGrid {
    const BATCHES: usize = 16;
    let (nu, nv) = plane.dims();
    let n = plane.normal();
    let cell_area = (plane.u.cross(plane.v).length() / (nu * nv) as f32) as f64;
    let per_batch = (photons / BATCHES as u64).max(1);
    let batches: Vec<Vec<f64>> = (0..BATCHES)
        .into_par_iter()
        .with_max_len(1)
        .map(|b| {
            let mut grid = vec![0.0f64; nu * nv];
            let mut sampler = IndependentSampler::new(1, settings.seed ^ 0x5eed_0000);
            for k in 0..per_batch {
                sampler.start_pixel_sample(b as u32, (k >> 32) as u32, k as u32);
                trace_photon(scene, plane, n, &mut sampler, settings, &mut grid);
            }
            // Flux per photon-sum → lux: Σ Φ / (N A).
            grid.iter().map(|x| x * LM_PER_W / (per_batch as f64 * cell_area)).collect()
        })
        .collect();
    let mut lux = vec![0.0; nu * nv];
    let mut se = vec![0.0; nu * nv];
    for k in 0..nu * nv {
        let m = batches.iter().map(|g| g[k]).sum::<f64>() / BATCHES as f64;
        let var = batches.iter().map(|g| (g[k] - m).powi(2)).sum::<f64>() / (BATCHES - 1) as f64;
        lux[k] = m;
        se[k] = (var / BATCHES as f64).sqrt();
    }
    IlluminanceGrid { plane: *plane, lux, std_err: se, method: "light tracing", unit: "lx" }
}

/// Where segment o + t d (0 < t < t_max) crosses the plane from its front: the cell.
fn crossing(plane: &WorkPlane, n: Vec3, o: Vec3, d: Vec3, t_max: f32) -> Option<usize> {
    let dn = d.dot(n);
    if dn >= 0.0 {
        return None;
    }
    let t = (plane.origin - o).dot(n) / dn;
    if !(t > 0.0 && t < t_max) {
        return None;
    }
    let q = o + d * t - plane.origin;
    let (uu, vv) = (plane.u.length_squared(), plane.v.length_squared());
    let (s, r) = (q.dot(plane.u) / uu, q.dot(plane.v) / vv);
    if !(0.0..1.0).contains(&s) || !(0.0..1.0).contains(&r) {
        return None;
    }
    let (nu, nv) = plane.dims();
    let i = ((s * nu as f32) as usize).min(nu - 1);
    let j = ((r * nv as f32) as usize).min(nv - 1);
    Some(i * nv + j)
}

fn trace_photon(scene: &Scene, plane: &WorkPlane, n: Vec3, sampler: &mut IndependentSampler, settings: &RenderSettings, grid: &mut [f64]) {
    if scene.lights.is_empty() {
        return;
    }
    let (li, pmf, _) = scene.light_distribution.sample_discrete(sampler.next_1d());
    if pmf <= 0.0 {
        return;
    }
    let light = &scene.lights[li];
    let Some(es) = light.sample_le(sampler.next_2d(), sampler.next_2d(), 0.0, &scene.bounds) else { return };
    let denom = pmf * es.pdf_pos * es.pdf_dir;
    if denom <= 0.0 {
        return;
    }
    let mut beta = es.le * (es.n.dot(es.ray.d).abs() / denom);
    let mut ray = es.ray;
    let max_bounces = if settings.max_depth < 0 { 64 } else { settings.max_depth.max(1) as usize };
    for _ in 0..max_bounces {
        let hit = scene.intersect(&ray);
        let t_max = hit.as_ref().map_or(f32::INFINITY, |h| (h.p - ray.o).length());
        if let Some(c) = crossing(plane, n, ray.o, ray.d, t_max) {
            grid[c] += beta.luminance() as f64;
        }
        let Some(si) = hit else { return };
        let bsdf = scene.material(&si).bsdf(si.uv);
        let wo = si.to_local(si.wo);
        let Some(bs) = bsdf.sample(wo, sampler.next_1d(), sampler.next_2d(), TransportMode::Importance) else { return };
        if bs.pdf <= 0.0 {
            return;
        }
        // The throughput stays RGB (the luminance of a product is not the product of the
        // luminances on coloured walls); only the deposit is luminance.
        beta *= bs.weight();
        if beta.is_black() {
            return;
        }
        ray = si.spawn_ray(si.to_world(bs.wi));
    }
}
