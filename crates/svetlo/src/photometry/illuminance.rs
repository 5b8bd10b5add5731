//! Illuminance (lux) on a work plane by two independent estimators:
//! * gathering: at each grid point, E = Σ over delta lights of I cos γ / r² (visible) plus
//!   π × the mean radiance the path tracer returns along cosine-distributed rays (which sees
//!   area lights and every interreflection) — an estimate at the point, with its standard
//!   error over samples;
//! * light tracing: photons from the lights (chosen by power) walk the scene by BSDF
//!   sampling in importance mode; every segment that crosses the plane's rectangle from the
//!   side its normal faces deposits its flux on the cell it crosses. The plane is virtual
//!   (it blocks nothing). An estimate of the cell's mean illuminance, with the standard
//!   error from independent batches.
//!
//! Luminous quantities from radiometric RGB by 683 lm/W and the Rec.709 weights.

use super::LM_PER_W;
use crate::bsdf::TransportMode;
use crate::geometry::Ray;
use crate::integrator::path::PathTracer;
use crate::integrator::{PixelEstimator, RenderSettings};
use crate::sampling::{IndependentSampler, Sampler};
use crate::scene::Scene;
use glam::Vec3;
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

    pub fn to_csv(&self) -> String {
        let (nu, nv) = self.plane.dims();
        let mut s = String::from("i,j,x,y,z,lux,std_err\n");
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
            "{{\"method\":\"{}\",\"nu\":{nu},\"nv\":{nv},\"spacing\":{},\"e_min\":{:.4},\"e_avg\":{:.4},\"e_max\":{:.4},\"u0\":{:.5},\"e_min_over_e_max\":{:.5},\"lux\":[{}],\"std_err\":[{}]}}\n",
            self.method,
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
        .map(|k| {
            let (i, j) = (k / nv, k % nv);
            let p = plane.point(i, j);
            let mut sampler = IndependentSampler::new(spp, settings.seed);
            let (mut s, mut s2) = (0.0f64, 0.0f64);
            for si in 0..spp {
                sampler.start_pixel_sample(i as u32, j as u32, si);
                let mut e = 0.0f64;
                for light in scene.lights.iter().filter(|l| l.is_delta()) {
                    let u = sampler.next_2d();
                    let Some(ls) = light.sample_li(p, u, &scene.bounds) else { continue };
                    let cos = n.dot(ls.wi);
                    if cos <= 0.0 {
                        continue;
                    }
                    let blocked = if ls.infinite { scene.occluded_dir(p, n, ls.wi) } else { scene.occluded(p, n, ls.p) };
                    if !blocked {
                        e += (ls.li.luminance() * cos / ls.pdf) as f64;
                    }
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
    IlluminanceGrid { plane: *plane, lux: res.iter().map(|r| r.0).collect(), std_err: res.iter().map(|r| r.1).collect(), method: "gathering" }
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
    IlluminanceGrid { plane: *plane, lux, std_err: se, method: "light tracing" }
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
    let mut beta = (es.le * es.n.dot(es.ray.d).abs() / denom).luminance() as f64;
    let mut ray = es.ray;
    let max_bounces = if settings.max_depth < 0 { 64 } else { settings.max_depth.max(1) as usize };
    for _ in 0..max_bounces {
        let hit = scene.intersect(&ray);
        let t_max = hit.as_ref().map_or(f32::INFINITY, |h| (h.p - ray.o).length());
        if let Some(c) = crossing(plane, n, ray.o, ray.d, t_max) {
            grid[c] += beta;
        }
        let Some(si) = hit else { return };
        let bsdf = scene.material(&si).bsdf(si.uv);
        let wo = si.to_local(si.wo);
        let Some(bs) = bsdf.sample(wo, sampler.next_1d(), sampler.next_2d(), TransportMode::Importance) else { return };
        if bs.pdf <= 0.0 {
            return;
        }
        // The throughput is carried as luminance: exact for grey materials (a coloured
        // interreflection would need the RGB of Φ, which a lux grid discards anyway).
        beta *= bs.weight().luminance() as f64;
        if beta <= 0.0 {
            return;
        }
        ray = si.spawn_ray(si.to_world(bs.wi));
    }
}
