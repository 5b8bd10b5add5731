//! Veach's mutations on `MPath`s, each with the ratio of its transition densities
//! T(y→x) / T(x→y) in the area-product measure.
//!
//! - **Bidirectional**: delete the vertices strictly between x_{a-1} and x_{a+kd-1} (kd
//!   segments; a = 0 deletes the light end too), regenerate ka segments: ka − 1 new vertices,
//!   s of them by a light-side walk from x_{a-1}, the rest by a camera-side walk from
//!   x_{a+kd-1}, joined by a deterministic connection. T sums over the ka ways to split the
//!   new vertices (the exact density of producing y with this deletion), times the choice
//!   probabilities of kd, the deletion's position and ka; the reverse move deletes the new
//!   vertices and regenerates the old ones. kd ~ Veach's (0.25, 0.5, 2^-kd) on 1..=k+1; ka
//!   within 4 of kd (weight 2^-|ka-kd|), never the identity (kd = ka = 1), within max_depth.
//! - **Lens perturbation** ((L|D)D E here): move the film position by an offset of radius
//!   between 0.1 pixel and 10 % of the image (log-uniform) in a uniform direction, retrace
//!   x_{k-1}, reconnect to x_{k-2}. Symmetric on the film, so T(y→x)/T(x→y) is the ratio of
//!   the camera's area densities c(x_{k-1}) / c(y_{k-1}).
//! - **Caustic perturbation** ((L|D)D E here): turn the direction x_{k-2}→x_{k-1} by an angle
//!   between 1e-4 and 0.1 rad (log-uniform), retrace, reconnect to the camera. Symmetric in
//!   solid angle at x_{k-2}, so the ratio is G(x_{k-2}, x_{k-1}) / G(x_{k-2}, y_{k-1}) with
//!   the receiving cosine only.
//!
//! The state space has no delta vertices (see `space.rs`), so the specular chains of the
//! multi-chain perturbation do not occur in it; that light is the complement's.

use super::space::{MPath, Space};
use crate::geometry::Ray;
use crate::math::Frame;
use crate::path::{Vertex, VertexKind};
use crate::sampling::Pcg32;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// Probability of deleting kd segments from a path of k (kd in 1..=k+1).
pub fn pd(kd: usize, k: usize) -> f64 {
    let w = |j: usize| match j {
        1 => 0.25,
        2 => 0.5,
        _ => 0.5f64.powi(j as i32),
    };
    if kd == 0 || kd > k + 1 {
        return 0.0;
    }
    w(kd) / (1..=k + 1).map(w).sum::<f64>()
}

/// Positions of a deletion of kd segments in a path of k.
pub fn n_pos(kd: usize, k: usize) -> usize {
    (k + 1 - kd) + usize::from(kd >= 2)
}

/// Range of ka for a deletion of kd segments from a path of k segments.
fn ka_range(kd: usize, k: usize, sp: &Space) -> (usize, usize) {
    let lo = 1.max(kd.saturating_sub(4)).max((sp.min_k + kd).saturating_sub(k));
    let hi = (kd + 4).min(sp.max_k.saturating_add(kd).saturating_sub(k));
    (lo, hi)
}

/// Probability of adding ka segments after deleting kd from a path of k.
pub fn pa(ka: usize, kd: usize, k: usize, sp: &Space) -> f64 {
    let (lo, hi) = ka_range(kd, k, sp);
    let ok = |j: usize| j >= lo && j <= hi && !(kd == 1 && j == 1);
    if !ok(ka) {
        return 0.0;
    }
    let w = |j: usize| 0.5f64.powi((j as i32 - kd as i32).abs());
    let z: f64 = (lo..=hi).filter(|&j| ok(j)).map(w).sum();
    if z > 0.0 {
        w(ka) / z
    } else {
        0.0
    }
}

fn pick(rng: &mut Pcg32, probs: impl Iterator<Item = (usize, f64)>) -> Option<usize> {
    let u = rng.next_f64();
    let mut acc = 0.0;
    let mut last = None;
    for (j, p) in probs {
        if p <= 0.0 {
            continue;
        }
        acc += p;
        last = Some(j);
        if u < acc {
            return Some(j);
        }
    }
    last
}

/// Assemble `prefix ++ light ++ reverse(eye) ++ suffix` (+ the camera).
fn assemble(prefix: &[Vertex], light: &[Vertex], eye: &[Vertex], suffix: &[Vertex]) -> Vec<Vertex> {
    let mut v = Vec::with_capacity(prefix.len() + light.len() + eye.len() + suffix.len());
    v.extend_from_slice(prefix);
    v.extend_from_slice(light);
    v.extend(eye.iter().rev().cloned());
    v.extend_from_slice(suffix);
    v
}

/// A bidirectional mutation of `x`: the proposal and T(y→x)/T(x→y).
pub fn bidirectional(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let k = x.k();
    let kd = pick(rng, (1..=k + 1).map(|j| (j, pd(j, k))))?;
    let npos = n_pos(kd, k);
    let i = ((rng.next_f64() * npos as f64) as usize).min(npos - 1);
    let a = if kd == 1 { i + 1 } else { i };
    let kept_eye = a + kd - 1; // index of the first kept vertex on the camera side
    let ka = pick(rng, (1..=kd + 4).map(|j| (j, pa(j, kd, k, sp))))?;
    let m = ka - 1;
    let s = ((rng.next_f64() * (m + 1) as f64) as usize).min(m);
    let prefix = &x.v[..a];
    let suffix = &x.v[kept_eye..];
    let mut light = Vec::new();
    let mut eye = Vec::new();
    if !sp.walk_light(prefix, s, rng, &mut light) || !sp.walk_eye(suffix, m - s, rng, &mut eye) {
        return None;
    }
    let v = assemble(prefix, &light, &eye, suffix);
    // The connection joins the light side's last vertex to the camera side's first.
    if a + s > 0 {
        let c = a + s - 1;
        if !sp.visible(&v[c], &v[c + 1]) {
            return None;
        }
    }
    let y = sp.finish(v)?;
    let k2 = y.k();
    let t_xy = pd(kd, k) / n_pos(kd, k) as f64 * pa(ka, kd, k, sp) * sp.regen_density(&y.v, a, m);
    let t_yx = pd(ka, k2) / n_pos(ka, k2) as f64 * pa(kd, ka, k2, sp) * sp.regen_density(&x.v, a, kd - 1);
    if t_xy.is_nan() || t_xy <= 0.0 {
        return None;
    }
    Some((y, t_yx / t_xy))
}

/// Log-uniform radius in [r1, r2].
fn log_uniform(u: f64, r1: f64, r2: f64) -> f64 {
    r2 * (-(r2 / r1).ln() * u).exp()
}

/// Lens perturbation: a new film position near the old one, x_{k-1} retraced.
pub fn lens(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let k = x.k();
    let cam = &sp.scene.camera;
    let (w, h) = (cam.width as f64, cam.height as f64);
    let r = log_uniform(rng.next_f64(), 0.1, 0.1 * (w * h).sqrt());
    let phi = std::f64::consts::TAU * rng.next_f64();
    let old = x.raster();
    let raster = Vec2::new((old.x as f64 + r * phi.cos()) as f32, (old.y as f64 + r * phi.sin()) as f32);
    if !(raster.x >= 0.0 && raster.y >= 0.0 && (raster.x as f64) < w && (raster.y as f64) < h) {
        return None;
    }
    let ray = cam.generate_ray(raster, Vec2::splat(0.5), 0.0);
    let si = sp.scene.intersect(&ray)?;
    let hit = Vertex::surface(sp.scene, &si, Rgb::WHITE);
    if k >= 2 && !sp.visible(&x.v[k - 2], &hit) {
        return None;
    }
    let mut v = x.v[..k - 1].to_vec();
    v.push(hit);
    v.push(x.v[k].clone());
    let y = sp.finish(v)?;
    let (px, py) = (sp.pe(&x.v, k - 1), sp.pe(&y.v, k - 1));
    if py.is_nan() || py <= 0.0 {
        return None;
    }
    Some((y, px / py))
}

/// |ng_b · ω| / r² of the segment a→b (the area density's receiving factor).
fn receive(a: &Vertex, b: &Vertex) -> f64 {
    let d = b.p - a.p;
    let d2 = d.length_squared();
    if d2 == 0.0 {
        return 0.0;
    }
    (b.ng.dot(d / d2.sqrt()).abs() / d2) as f64
}

/// Caustic perturbation: the direction leaving x_{k-2} turned slightly, the camera reconnected.
pub fn caustic(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let k = x.k();
    if k < 2 {
        return None;
    }
    let (from, old) = (&x.v[k - 2], &x.v[k - 1]);
    let w = (old.p - from.p).normalize_or_zero();
    if w == Vec3::ZERO {
        return None;
    }
    let theta = log_uniform(rng.next_f64(), 1e-4, 0.1);
    let phi = std::f64::consts::TAU * rng.next_f64();
    let (st, ct) = (theta.sin(), theta.cos());
    let local = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
    let wn = Frame::from_normal(w).to_world(local).normalize();
    let o = if from.kind == VertexKind::Camera { from.p } else { crate::geometry::ray::offset_ray_origin(from.p, from.ng, wn) };
    let si = sp.scene.intersect(&Ray::new(o, wn))?;
    let hit = Vertex::surface(sp.scene, &si, Rgb::WHITE);
    let mut v = x.v[..k - 1].to_vec();
    v.push(hit);
    v.push(x.v[k].clone());
    let y = sp.finish(v)?;
    if !sp.visible(&y.v[k - 1], &y.v[k]) {
        return None;
    }
    let (gx, gy) = (receive(from, old), receive(from, &y.v[k - 1]));
    if gy.is_nan() || gy <= 0.0 {
        return None;
    }
    Some((y, gx / gy))
}

/// Probability of a path length k (k >= min_k) for the independent sampler: geometric with
/// ratio 1/2; lengths beyond max_depth are drawn and discarded (zero-weight samples).
pub fn p_length(k: usize, sp: &Space) -> f64 {
    if k < sp.min_k || k > sp.max_k {
        return 0.0;
    }
    0.5f64.powi((k - sp.min_k + 1) as i32)
}

/// An independent path (the bootstrap's and the chains' seed sampler): a length, a split
/// of its k' free vertices between a light walk and a camera walk, a connection. Returns the
/// path and its density (summed over the splits).
pub fn independent(sp: &Space, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let mut k = sp.min_k;
    while rng.next_f64() >= 0.5 {
        k += 1;
        if k > 64 {
            return None;
        }
    }
    if k > sp.max_k {
        return None;
    }
    let s = ((rng.next_f64() * (k + 1) as f64) as usize).min(k);
    let camera = Vertex::camera(sp.cam_pos, Vec2::ZERO, Rgb::WHITE);
    let mut light = Vec::new();
    let mut eye = Vec::new();
    if !sp.walk_light(&[], s, rng, &mut light) || !sp.walk_eye(std::slice::from_ref(&camera), k - s, rng, &mut eye) {
        return None;
    }
    let v = assemble(&[], &light, &eye, std::slice::from_ref(&camera));
    if s > 0 && !sp.visible(&v[s - 1], &v[s]) {
        return None;
    }
    let y = sp.finish(v)?;
    let p = p_length(k, sp) * sp.regen_density(&y.v, 0, k);
    (p > 0.0).then_some((y, p))
}
