//! Stochastic progressive photon mapping (Hachisuka & Jensen 2009).
//!
//! Each iteration: a camera pass finds, for every pixel, visible points (the diffuse vertices
//! of one camera path, see `camera.rs`; emission and NEE along it go straight into the
//! pixel), then a photon pass traces `photons` paths, and every visible point gathers the
//! photons within its radius. Per visible point (pixel and its n-th diffuse vertex) the
//! statistics N (photons), r (radius) and τ (flux) are updated as in the paper:
//! `N' = N + αM`, `r' = r sqrt(N' / (N + M))`, `τ' = (τ + Φ) r'² / r²`, and the pixel's
//! estimate is `Σ τ / (π r² · photons emitted so far)` plus the mean of the direct part.
//! Radii shrink to zero while the photons in them grow, so bias and variance both vanish.
//!
//! Photons of one segment are left out (NEE has direct light); depth as `photon`.
//! Iteration i's camera samples are sample i of each pixel and its photons are seeded by
//! (seed, i, photon index): the image is the same for any thread count. `--spp` is the number
//! of iterations; a time budget stops after a whole iteration.

use super::camera::camera_walk;
use super::map::{visible, Photon, SAME_ORIENTATION_COS};
use super::trace::trace_photons;
use super::{parse_count, parse_pairs, parse_positive, pixel_footprint, segments_left};
use crate::accel::KdTree;
use crate::bsdf::{Bsdf, LobeFlags, TransportMode};
use crate::error::{Error, Result};
use crate::film::{Film, Filter};
use crate::geometry::SurfaceInteraction;
use crate::integrator::{Integrator, Progress, RenderSettings};
use crate::math::PI;
use crate::path::PathConfig;
use crate::sampling::sampler::make_sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::Ordering;
use std::time::Instant;

#[derive(Clone, Debug, PartialEq)]
pub struct SppmOptions {
    /// Photon paths per iteration; None: four per pixel (on bench/photon's indirect-room one per
    /// pixel left SPPM variance-limited: relMSE 6.5e-4 against 3.9e-4 with four, at equal time).
    pub photons: Option<u64>,
    /// Initial gather radius (scene units); None: 2 pixel footprints.
    pub radius: Option<f32>,
    /// Fraction of new photons kept per iteration (Hachisuka's α).
    pub alpha: f32,
    /// Visible points per pixel: the first this many diffuse vertices of a camera path (more
    /// come only through delta lobes of diffuse-and-specular surfaces, such as plastic).
    pub max_visible: u32,
    /// Count only photons the visible point sees (`map::visible`): no light leaks through thin
    /// walls. Photons on surfaces facing another way are left out in any case.
    pub visibility: bool,
}

impl Default for SppmOptions {
    fn default() -> Self {
        SppmOptions { photons: None, radius: None, alpha: 2.0 / 3.0, max_visible: 3, visibility: true }
    }
}

impl SppmOptions {
    /// `photons=N,radius=R,alpha=A,visible=N,visibility=true|false`.
    pub fn parse(params: &str) -> Result<Self> {
        let m = "sppm";
        let mut o = SppmOptions::default();
        for (k, v) in parse_pairs(m, params)? {
            match k {
                "photons" => o.photons = Some(parse_count(m, k, v)?.max(1)),
                "radius" => o.radius = Some(parse_positive(m, k, v)?),
                "alpha" => {
                    let a = parse_positive(m, k, v)?;
                    if a >= 1.0 {
                        return Err(Error::Settings(format!("sppm: alpha must be in (0, 1), got {a}")));
                    }
                    o.alpha = a;
                }
                "visible" => o.max_visible = parse_count(m, k, v)?.clamp(1, 16) as u32,
                "visibility" => o.visibility = v.parse().map_err(|_| Error::Settings(format!("sppm: visibility is true or false, got '{v}'")))?,
                _ => return Err(Error::Settings(format!("sppm: unknown option '{k}' (photons, radius, alpha, visible, visibility)"))),
            }
        }
        Ok(o)
    }
}

#[derive(Clone, Debug, Default)]
pub struct Sppm {
    pub options: SppmOptions,
}

/// Where one camera path met a diffuse surface this iteration.
struct VisiblePoint {
    si: SurfaceInteraction,
    bsdf: Bsdf,
    wo: Vec3,
    beta: Rgb,
    depth: i32,
}

/// Progressive statistics of one visible-point slot (pixel, n-th diffuse vertex).
#[derive(Clone, Copy)]
struct Stats {
    r: f32,
    n: f32,
    tau: Rgb,
}

impl Sppm {
    /// One iteration's photons: on diffuse surfaces, at least two segments from the light.
    fn photon_pass(&self, scene: &Scene, settings: &RenderSettings, iteration: u64, count: u64) -> KdTree<Photon> {
        let cfg = PathConfig::new(scene, settings.max_depth, settings.rr_depth, settings.hide_emitters);
        let photons = trace_photons(scene, settings.seed, iteration, count, &cfg, |_, d| {
            let keep = (d.segments >= 2 && d.surface.intersects(LobeFlags::DIFFUSE)).then(|| Photon::from_deposit(d, 1.0));
            (keep, true)
        });
        KdTree::new(photons)
    }
}

impl Integrator for Sppm {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        settings.validate()?;
        settings.check_lpe_support("sppm", false)?;
        let o = &self.options;
        let start = Instant::now();
        let cam = &scene.camera.ray_generator();
        let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
        let slots = o.max_visible as usize;
        let per_iter = o.photons.unwrap_or(4 * (w * h) as u64).max(1);
        let r0 = o.radius.unwrap_or(2.0 * pixel_footprint(scene));
        let pool = rayon::ThreadPoolBuilder::new().num_threads(settings.threads).build().map_err(|e| Error::Settings(format!("thread pool: {e}")))?;
        let mut stats = vec![Stats { r: r0, n: 0.0, tau: Rgb::BLACK }; w * h * slots];
        // Sum over iterations of the camera-side part (emission, NEE).
        let mut direct = vec![Rgb::BLACK; w * h];
        let proto = make_sampler(settings.sampler, settings.spp, settings.seed);
        progress.total.store(settings.spp as u64 * (w * h) as u64, Ordering::Relaxed);
        let mut iterations = 0u32;
        let mut per_iteration_s = 0.0f64;
        while iterations < settings.spp {
            if progress.cancelled() {
                break;
            }
            if let Some(t) = settings.time_limit {
                // Start an iteration only if it should end within the budget.
                let el = start.elapsed().as_secs_f64();
                if el >= t.as_secs_f64() || (iterations > 0 && el + per_iteration_s > t.as_secs_f64()) {
                    break;
                }
            }
            let it = iterations;
            // Camera pass: rows in parallel, each pixel's visible points and direct part.
            let rows: Vec<Vec<(Rgb, Vec<Option<VisiblePoint>>)>> = pool.install(|| {
                (0..h)
                    .into_par_iter()
                    .map(|y| {
                        let mut sampler = proto.clone_box();
                        (0..w)
                            .map(|x| {
                                let (_, ray) = crate::integrator::camera_sample(cam, sampler.as_mut(), x as u32, y as u32, it);
                                let mut vps: Vec<Option<VisiblePoint>> = (0..slots).map(|_| None).collect();
                                let l = camera_walk(scene, &ray, sampler.as_mut(), settings, &mut |v, _| {
                                    if let Some(slot) = vps.get_mut(v.index as usize) {
                                        *slot = Some(VisiblePoint { si: *v.si, bsdf: v.bsdf.clone(), wo: v.wo, beta: v.beta, depth: v.depth });
                                    }
                                    Rgb::BLACK
                                });
                                (l, vps)
                            })
                            .collect()
                    })
                    .collect()
            });
            if progress.cancelled() {
                break;
            }
            let tree = pool.install(|| self.photon_pass(scene, settings, it as u64, per_iter));
            let alpha = o.alpha;
            let visibility = o.visibility;
            let max_depth = settings.max_depth;
            pool.install(|| {
                stats.par_chunks_mut(w * slots).zip(rows.par_iter()).for_each(|(srow, vrow)| {
                    for (x, (_, vps)) in vrow.iter().enumerate() {
                        for (s, vp) in vps.iter().enumerate() {
                            let Some(vp) = vp else { continue };
                            let st = &mut srow[x * slots + s];
                            let left = segments_left(max_depth, vp.depth);
                            let mut phi = Rgb::BLACK;
                            let mut m = 0u32;
                            // Lifted off the surface on the seen side, for the visibility test.
                            let n = if vp.si.wo.dot(vp.si.ng) >= 0.0 { vp.si.ng } else { -vp.si.ng };
                            tree.for_each_in_radius(vp.si.p, st.r, |ph, _| {
                                if (ph.segments as i32) > left {
                                    return;
                                }
                                let wi = vp.si.to_local(ph.wi);
                                let cos_g = ph.wi.dot(vp.si.ng).abs();
                                if cos_g <= 0.0 {
                                    return;
                                }
                                let f = vp.bsdf.eval(vp.wo, wi, TransportMode::Radiance);
                                if f.is_black() || ph.n.dot(n) <= SAME_ORIENTATION_COS || (visibility && !visible(scene, vp.si.p, n, ph.p, ph.n, vp.si.time)) {
                                    return;
                                }
                                phi += f * ph.power * (wi.z.abs() / cos_g);
                                m += 1;
                            });
                            if m > 0 {
                                let n_new = st.n + alpha * m as f32;
                                let ratio = n_new / (st.n + m as f32);
                                st.tau = (st.tau + vp.beta * phi) * ratio;
                                st.r *= ratio.sqrt();
                                st.n = n_new;
                            }
                        }
                    }
                });
            });
            for (y, row) in rows.iter().enumerate() {
                for (x, (l, _)) in row.iter().enumerate() {
                    direct[y * w + x] += if l.is_finite() { *l } else { Rgb::BLACK };
                }
            }
            iterations += 1;
            per_iteration_s = start.elapsed().as_secs_f64() / iterations as f64;
            progress.done.fetch_add((w * h) as u64, Ordering::Relaxed);
            if progress.wants_pass(iterations) {
                progress.pass_done(&develop(scene, &direct, &stats, slots, per_iter, iterations));
            }
        }
        Ok(develop(scene, &direct, &stats, slots, per_iter, iterations))
    }
}

/// The image after `iterations`: each pixel is its own measurement (box reconstruction).
fn develop(scene: &Scene, direct: &[Rgb], stats: &[Stats], slots: usize, per_iter: u64, iterations: u32) -> Film {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let mut film = Film::new(scene.camera.width, scene.camera.height, Filter::Box);
    if iterations > 0 {
        let emitted = per_iter as f64 * iterations as f64;
        for y in 0..h {
            for x in 0..w {
                let mut l = direct[y * w + x] / iterations as f32;
                for st in &stats[(y * w + x) * slots..(y * w + x + 1) * slots] {
                    if st.n > 0.0 {
                        l += st.tau / ((PI as f64 * st.r as f64 * st.r as f64 * emitted) as f32);
                    }
                }
                film.add_sample(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), l);
            }
        }
    }
    film.spp_done = iterations;
    film
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse() {
        let o = SppmOptions::parse("photons=5000,radius=0.25,alpha=0.5,visible=2").unwrap();
        assert_eq!(o, SppmOptions { photons: Some(5000), radius: Some(0.25), alpha: 0.5, max_visible: 2, visibility: true });
        assert!(!SppmOptions::parse("visibility=false").unwrap().visibility);
        assert_eq!(SppmOptions::parse("").unwrap(), SppmOptions::default());
        for bad in ["alpha=1", "alpha=0", "alpha=-1", "radius=inf", "photons=x", "k=3", "photons", "visibility=maybe"] {
            assert!(SppmOptions::parse(bad).is_err(), "{bad}");
        }
    }
}
