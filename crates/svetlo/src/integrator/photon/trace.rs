//! Photon tracing: random walks from the lights in importance mode, reporting every landing
//! on a surface that scatters non-specularly.
//!
//! Power: a path starts with the flux `Le |n·d| / (pmf pdf_pos pdf_dir)` and is multiplied at
//! each bounce by the adjoint BSDF weight, with the shading-normal correction of Veach (5.3)
//! so that flux crossing the geometric surface is what is carried. Russian roulette keeps
//! the power of a photon roughly constant (survival = the ratio of luminances, at most 1),
//! which is what density estimation wants; it changes no expectation, so the problem
//! solved is the one `path` solves.

use crate::bsdf::{positive_finite, LobeFlags, TransportMode};
use crate::sampling::rng::{hash_seed, Pcg32};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A photon arriving at a surface with a non-specular lobe.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Deposit {
    pub p: Vec3,
    /// World direction toward where the photon came from.
    pub wi: Vec3,
    /// Flux carried (per emitted path, before dividing by the number of paths).
    pub power: Rgb,
    /// Path segments from the light to here (1: direct).
    pub segments: u32,
    /// Every bounce before this one was specular (and there was at least one): L S+ here.
    pub caustic: bool,
    /// The lobes of the surface it landed on.
    pub surface: LobeFlags,
}

/// The random numbers of photon path `index` of pass `tag`: a function of (seed, tag, index)
/// only, so that photon maps do not depend on the thread count.
pub(crate) fn photon_rng(seed: u64, tag: u64, index: u64) -> Pcg32 {
    Pcg32::new(hash_seed(&[seed, tag, index]), tag)
}

/// Trace one photon path of at most `max_segments` segments (-1 unbounded), calling `visit`
/// at every non-specular landing; `visit` returns false to end the path there.
pub(crate) fn trace_photon(scene: &Scene, rng: &mut Pcg32, max_segments: i32, visit: &mut impl FnMut(&Deposit) -> bool) {
    if scene.lights.is_empty() || max_segments == 0 {
        return;
    }
    let (li, pmf, _) = scene.light_distribution.sample_discrete(rng.next_f32());
    if pmf <= 0.0 {
        return;
    }
    let u_pos = Vec2::new(rng.next_f32(), rng.next_f32());
    let u_dir = Vec2::new(rng.next_f32(), rng.next_f32());
    let cam = &scene.camera;
    let time = cam.shutter_open + rng.next_f32() * (cam.shutter_close - cam.shutter_open);
    let Some(es) = scene.lights[li].sample_le(u_pos, u_dir, time, &scene.bounds) else { return };
    let denom = pmf * es.pdf_pos * es.pdf_dir;
    if !positive_finite(denom) || es.le.is_black() {
        return;
    }
    let mut beta = es.le * (es.n.dot(es.ray.d).abs() / denom);
    let mut ray = es.ray;
    let mut segments = 0i32;
    let mut all_specular = true;
    loop {
        segments += 1;
        let Some(si) = scene.intersect(&ray) else { break };
        let bsdf = scene.material(&si).bsdf(si.uv);
        let flags = bsdf.flags();
        if flags.has_non_specular() {
            let d = Deposit { p: si.p, wi: si.wo, power: beta, segments: segments as u32, caustic: all_specular && segments >= 2, surface: flags };
            if !visit(&d) {
                break;
            }
        }
        if max_segments >= 0 && segments >= max_segments {
            break;
        }
        let wo = si.to_local(si.wo);
        let uc = rng.next_f32();
        let u = Vec2::new(rng.next_f32(), rng.next_f32());
        let Some(bs) = bsdf.sample(wo, uc, u, TransportMode::Importance) else { break };
        if !positive_finite(bs.pdf) || bs.f.is_black() {
            break;
        }
        let wi = si.to_world(bs.wi);
        // Adjoint shading-normal correction: |wo·ns| |wi·ng| / (|wo·ng| |wi·ns|).
        let (wo_ng, wi_ns) = (si.wo.dot(si.ng).abs(), bs.wi.z.abs());
        if wo_ng == 0.0 || wi_ns == 0.0 {
            break;
        }
        let corr = wo.z.abs() * wi.dot(si.ng).abs() / (wo_ng * wi_ns);
        let next = beta * bs.weight() * corr;
        all_specular &= bs.lobe.is_specular();
        let (lum, lum_next) = (beta.luminance(), next.luminance());
        let q = if lum > 0.0 { (lum_next / lum).min(1.0) } else { 0.0 };
        if !positive_finite(q) || rng.next_f32() >= q {
            break;
        }
        beta = next / q;
        ray = si.spawn_ray(wi);
    }
}

/// Trace photon paths `0..count` of pass `tag` in parallel and collect what `keep` makes of
/// each landing, in path order (so the result does not depend on the thread count).
pub(crate) fn trace_photons<T: Send>(
    scene: &Scene,
    seed: u64,
    tag: u64,
    count: u64,
    max_segments: i32,
    keep: impl Fn(&Deposit) -> (Option<T>, bool) + Sync,
) -> Vec<T> {
    const CHUNK: u64 = 4096;
    let chunks = count.div_ceil(CHUNK);
    let parts: Vec<Vec<T>> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut out = Vec::new();
            for i in c * CHUNK..((c + 1) * CHUNK).min(count) {
                let mut rng = photon_rng(seed, tag, i);
                trace_photon(scene, &mut rng, max_segments, &mut |d| {
                    let (v, go_on) = keep(d);
                    out.extend(v);
                    go_on
                });
            }
            out
        })
        .collect();
    parts.into_iter().flatten().collect()
}
