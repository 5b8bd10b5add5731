//! Photon methods: Jensen's photon mapping (`jensen.rs`) and stochastic progressive photon
//! mapping (`sppm.rs`), over photon tracing (`trace.rs`), photon maps in a kd-tree
//! (`map.rs`) and a camera walk that hands diffuse vertices to the photons (`camera.rs`).
//!
//! Options follow `radiosity:key=value,...`: `photon:photons=200000,k=64,gather=16` and
//! `sppm:photons=100000,radius=0.05,alpha=0.667`.

mod camera;
pub mod jensen;
pub mod map;
pub mod sppm;
mod trace;

pub use jensen::{PhotonMapper, PhotonOptions};
pub use map::{Kernel, Lookup};
pub use sppm::{Sppm, SppmOptions, SppmRows};

use crate::error::{Error, Result};
use crate::scene::Scene;
use glam::Vec2;

/// Parse `key=value,...` into pairs, with a typed error naming the method.
pub(crate) fn parse_pairs<'a>(method: &str, params: &'a str) -> Result<Vec<(&'a str, &'a str)>> {
    params
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|kv| kv.split_once('=').map(|(k, v)| (k.trim(), v.trim())).ok_or_else(|| Error::Settings(format!("{method}: expected key=value, got '{kv}'"))))
        .collect()
}

pub(crate) fn parse_count(method: &str, k: &str, v: &str) -> Result<u64> {
    v.replace('_', "").parse::<u64>().map_err(|_| Error::Settings(format!("{method}: {k} needs a whole number, got '{v}'")))
}

/// A positive finite number.
pub(crate) fn parse_positive(method: &str, k: &str, v: &str) -> Result<f32> {
    match v.parse::<f32>() {
        Ok(x) if x > 0.0 && x.is_finite() => Ok(x),
        _ => Err(Error::Settings(format!("{method}: {k} needs a positive number, got '{v}'"))),
    }
}

/// Photon path segments that can still contribute to a camera path of `max_depth`: the
/// camera side has at least one segment (-1: unbounded).
pub(crate) fn photon_max_segments(max_depth: i32) -> i32 {
    if max_depth < 0 {
        -1
    } else {
        (max_depth - 1).max(0)
    }
}

/// Photon segments a camera vertex at `depth` may take (the whole path within max_depth).
#[inline]
pub(crate) fn segments_left(max_depth: i32, depth: i32) -> i32 {
    if max_depth < 0 {
        i32::MAX
    } else {
        max_depth - depth
    }
}

/// Width of one pixel, in scene units, at the distance of the scene's center from the camera
/// (at least half the scene's radius, for cameras inside it): the scale of the default
/// lookup radii.
pub(crate) fn pixel_footprint(scene: &Scene) -> f32 {
    let cam = &scene.camera;
    let c = Vec2::new(cam.width as f32 * 0.5, cam.height as f32 * 0.5);
    let r0 = cam.generate_ray(c, Vec2::splat(0.5), 0.0);
    let r1 = cam.generate_ray(c + Vec2::X, Vec2::splat(0.5), 0.0);
    let t = (scene.bounds.center - r0.o).dot(r0.d).max(0.5 * scene.bounds.radius);
    let f = (r0.at(t) - r1.at(t)).length();
    if f > 0.0 && f.is_finite() {
        f
    } else {
        scene.bounds.radius * 2.0 / cam.width.max(1) as f32
    }
}
