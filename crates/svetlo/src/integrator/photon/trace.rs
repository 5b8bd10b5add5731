//! Photon tracing: the light subpaths of `path` (importance transport, shading-normal
//! correction, Russian roulette, max_depth as everywhere), read as photons: every vertex on
//! a surface with a non-specular lobe is a landing, carrying the walk's throughput, which is
//! the flux `Le |n·d| / (pmf pdf_pos pdf_dir)` times the adjoint scattering weights.

use crate::bsdf::LobeFlags;
use crate::lpe::{AovSet, LightTracker};
use crate::path::{light_subpath, PathConfig, Vertex};
use crate::sampling::{IndependentSampler, Sampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec3;
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
    /// Geometric and shading normals there.
    pub ng: Vec3,
    pub ns: Vec3,
    /// Reflectance of the side it arrived on, where that side is purely Lambertian.
    pub albedo: Option<Rgb>,
    /// With AOVs: the reverse automata's state for the events of the photon's path before
    /// this landing (the light and every bounce), which the lookup completes.
    pub light_state: u32,
}

/// Position `sampler` at photon path `index` of pass `tag`: its numbers are a function of
/// (seed, tag, index) only, so that photon maps do not depend on the thread count.
fn start_photon(sampler: &mut IndependentSampler, tag: u64, index: u64) {
    sampler.start_pixel_sample(index as u32, (index >> 32) as u32 ^ (tag >> 32) as u32, tag as u32);
}

/// Trace one photon path (the light subpath of `cfg`), calling `visit` at every
/// non-specular landing; `visit` returns false to stop reading the path there. With AOVs
/// (`aovs` not empty), landings carry their path's events as a reverse automaton state.
pub(crate) fn trace_photon(
    scene: &Scene,
    cfg: &PathConfig,
    aovs: &AovSet,
    sampler: &mut dyn Sampler,
    path: &mut Vec<Vertex>,
    visit: &mut impl FnMut(&Deposit) -> bool,
) {
    let cam = &scene.camera;
    let time = cam.shutter_open + sampler.next_1d() * (cam.shutter_close - cam.shutter_open);
    light_subpath(scene, cfg, time, sampler, path);
    let Some(first) = path.first() else { return };
    let mut events = (!aovs.is_empty()).then(|| LightTracker::light(aovs, aovs.endpoint_event(scene, first)));
    let mut all_specular = true;
    for (segments, v) in path.iter().enumerate().skip(1) {
        let Some(bsdf) = v.bsdf.as_ref().filter(|_| v.on_surface()) else { break };
        let flags = bsdf.flags();
        if flags.has_non_specular() {
            let d = Deposit {
                p: v.p,
                wi: v.wo,
                power: v.beta,
                segments: segments as u32,
                caustic: all_specular && segments >= 2,
                surface: flags,
                ng: v.ng,
                ns: v.shading.n,
                albedo: super::map::lambertian_albedo(bsdf, v.shading.to_local(v.wo)),
                light_state: events.map_or(0, |t| t.state()),
            };
            if !visit(&d) {
                break;
            }
        }
        all_specular &= v.delta;
        // The event of scattering here, as the walk sampled it, for the landings after.
        if let Some(t) = &mut events {
            if let Some(e) = aovs.sampled_event(v) {
                t.push(e);
            }
        }
    }
}

/// Trace photon paths `range` of pass `tag` in parallel and collect what `keep` makes of
/// each landing (given the path's index), in path order: the result depends on neither the
/// thread count nor how a pass's paths are cut into ranges (ranges traced apart, on other
/// machines, and concatenated in order are the whole pass's photons).
pub(crate) fn trace_photons<T: Send>(
    scene: &Scene,
    seed: u64,
    tag: u64,
    range: std::ops::Range<u64>,
    cfg: &PathConfig,
    aovs: &AovSet,
    keep: impl Fn(u64, &Deposit) -> (Option<T>, bool) + Sync,
) -> Vec<T> {
    const CHUNK: u64 = 4096;
    let chunks = (range.end.saturating_sub(range.start)).div_ceil(CHUNK);
    // usize: a u64 range is not an indexed parallel iterator (no `with_max_len`).
    let parts: Vec<Vec<T>> = (0..chunks as usize)
        .into_par_iter()
        .with_max_len(1) // a chunk a task: see `splat::render_chunked`
        .map(|c| {
            let c = c as u64;
            let mut out = Vec::new();
            let mut sampler = IndependentSampler::new(1, seed);
            let mut path = Vec::new();
            for i in range.start + c * CHUNK..(range.start + (c + 1) * CHUNK).min(range.end) {
                start_photon(&mut sampler, tag, i);
                trace_photon(scene, cfg, aovs, &mut sampler, &mut path, &mut |d| {
                    let (v, go_on) = keep(i, d);
                    out.extend(v);
                    go_on
                });
            }
            out
        })
        .collect();
    parts.into_iter().flatten().collect()
}
