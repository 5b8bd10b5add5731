//! Veach's mutations on `MPath`s, each with the ratio of its transition densities
//! T(y→x) / T(x→y) in the area-product measure (delta vertices as Dirac coefficients, see
//! `space.rs`).
//!
//! - **Bidirectional**: delete the vertices strictly between x_{a-1} and x_{a+kd-1} (kd
//!   segments; a = 0 deletes the light end too), regenerate ka segments: ka − 1 new vertices,
//!   s of them by a light-side walk from x_{a-1}, the rest by a camera-side walk from
//!   x_{a+kd-1}, joined by a deterministic connection between two non-delta vertices. The
//!   walks scatter off specular surfaces like BDPT's, and the kept end each walk leaves from
//!   takes the lobe it chose. T sums over the ka ways to split the new vertices (the exact
//!   density of producing y with this deletion), times the choice probabilities of kd, the
//!   deletion's position and ka; the reverse move deletes the new vertices and regenerates
//!   the old ones. kd ~ Veach's (0.25, 0.5, 2^-kd) on 1..=k+1; ka within 4 of kd (weight
//!   2^-|ka-kd|), never the identity (kd = ka = 1), within max_depth.
//! - **Lens perturbation** ((L|D)DS*E): move the film position by an offset of radius
//!   between 0.1 pixel and 10 % of the image (Veach's exponential kernel: log-uniform) in a
//!   uniform direction, retrace the camera ray through the same delta lobes (reflection stays
//!   reflection, refraction refraction) to the first non-delta vertex, reconnect it to the
//!   fixed one before it. Symmetric on the film, so the ratio is that of the camera-side
//!   densities of the moved vertices when the lobes are followed, not chosen: the camera's
//!   area density of x_{k-1} times the geometric conversions after each delta vertex.
//! - **Caustic perturbation** ((L|D)S*DE): turn the direction leaving the last non-delta
//!   vertex before the camera's D by an angle between 1e-4 and 0.1 rad (log-uniform),
//!   follow the same lobes (light side) to the D vertex, reconnect it to the camera.
//!   Symmetric in solid angle, so the ratio is that of the light-side densities of the moved
//!   vertices (conversions, with 1/|J| of each refraction).
//! - **Multi-chain perturbation** ((L|D)(DS*)+DS*E with a specular chain before the first
//!   D): the lens perturbation for the first chain; then at each following D vertex the
//!   direction toward the next chain is the old one turned by an angle of the size the camera
//!   ray turned (log-uniform in [θ/2, 2θ], θ the angle between old and new camera rays: the
//!   same in both directions of the move, so the kernel is symmetric), followed through its
//!   chain; the last D is reconnected to the fixed vertex before it. Each turn is drawn
//!   afresh: one angle shared by all chains would confine the proposals to a manifold of
//!   lower dimension than the paths, where no density ratio exists.

use super::space::{MPath, Space};
use crate::bsdf::TransportMode;
use crate::math::Frame;
use crate::path::Vertex;
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

/// Join a light side and a reversed camera side by a connection: both ends become non-delta
/// vertices and must see each other. None when they cannot be joined.
fn join(sp: &Space, mut light: Vec<Vertex>, mut eye: Vec<Vertex>) -> Option<MPath> {
    if let (Some(l), Some(e)) = (light.last_mut(), eye.last_mut()) {
        l.delta = false;
        e.delta = false;
        if !sp.visible(l, e) {
            return None;
        }
    }
    light.extend(eye.into_iter().rev());
    sp.finish(light)
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
    let mut light = x.v[..a].to_vec();
    let mut eye: Vec<Vertex> = x.v[kept_eye..].iter().rev().cloned().collect();
    if !sp.walk_light(&mut light, s, rng) || !sp.walk_eye(&mut eye, m - s, rng) {
        return None;
    }
    let y = join(sp, light, eye)?;
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

/// A new vertex where `hit` is, marked like `like` (delta with its lobe, or not).
fn marked(mut hit: Vertex, like: &Vertex) -> Vertex {
    hit.delta = like.delta;
    hit.event = like.event;
    hit
}

/// Index of the first non-delta vertex seen from the camera (x0, a light, never is delta).
fn first_diffuse_from_camera(x: &MPath) -> usize {
    (0..x.k()).rev().find(|&i| !x.v[i].delta).unwrap_or(0)
}

/// Whether `v`, reached at the end of a followed chain, is the kind of vertex `like` is: a
/// non-delta scatterer, or (index 0) an area emitter.
fn lands(sp: &Space, v: &Vertex, index: usize) -> bool {
    if index == 0 {
        sp.is_area_emitter(v)
    } else {
        Space::scatters(v)
    }
}

/// Follow x's delta vertices from y[i] (already placed) toward the light, camera-side, while
/// x.v[i] is delta: fills y[i-1], ... and returns the index of the first non-delta vertex.
fn follow_to_light(sp: &Space, x: &MPath, y: &mut [Vertex], mut i: usize) -> Option<usize> {
    while x.v[i].delta {
        if i == 0 {
            return None;
        }
        let next = sp.follow(&y[i], &y[i + 1], TransportMode::Radiance)?;
        y[i - 1] = marked(next, &x.v[i - 1]);
        i -= 1;
    }
    lands(sp, &y[i], i).then_some(i)
}

/// The lens part shared by the lens and multi-chain perturbations: a perturbed film
/// position, x_{k-1} .. x_j (j the first non-delta vertex from the camera) retraced through
/// the same lobes. Returns the new vertices in a copy of x, j, and the angle between the old
/// and the new camera rays.
fn retrace_eye(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(Vec<Vertex>, usize, f64)> {
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
    let mut y = x.v.clone();
    y[k - 1] = marked(Vertex::surface(sp.scene, &si, Rgb::WHITE), &x.v[k - 1]);
    let j = follow_to_light(sp, x, &mut y, k - 1)?;
    let (d0, d1) = ((x.v[k - 1].p - sp.cam_pos).normalize_or_zero(), (y[k - 1].p - sp.cam_pos).normalize_or_zero());
    let theta = f64::from(d0.dot(d1).clamp(-1.0, 1.0)).acos();
    Some((y, j, theta))
}

/// T(y→x)/T(x→y) of a move that re-made vertices lo..k-1 from the camera side, following
/// delta lobes with symmetric kernels.
fn eye_ratio(sp: &Space, x: &MPath, y: &MPath, lo: usize) -> Option<f64> {
    let k = x.k();
    let (mut px, mut py) = (1.0, 1.0);
    for i in lo..k {
        px *= sp.pe_follow(&x.v, i);
        py *= sp.pe_follow(&y.v, i);
    }
    (py > 0.0 && py.is_finite()).then_some(px / py)
}

/// Lens perturbation ((L|D)DS*E): a new film position near the old one, the camera's
/// specular chain retraced, its D vertex reconnected to the fixed vertex before it.
pub fn lens(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let j = first_diffuse_from_camera(x);
    if j >= 1 && x.v[j - 1].delta {
        return None; // a chain before the D vertex: the multi-chain perturbation's
    }
    let (y, j, _) = retrace_eye(sp, x, rng)?;
    if j >= 1 && !sp.visible(&y[j - 1], &y[j]) {
        return None;
    }
    let y = sp.finish(y)?;
    let ratio = eye_ratio(sp, x, &y, j)?;
    Some((y, ratio))
}

/// A direction turned away from `w` by `theta` at azimuth `phi`.
fn turn(w: Vec3, theta: f64, phi: f64) -> Vec3 {
    let (st, ct) = (theta.sin(), theta.cos());
    let local = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
    Frame::from_normal(w).to_world(local).normalize()
}

/// Multi-chain perturbation: the lens perturbation of the first chain, then each following
/// chain re-aimed from its moved D vertex by a fresh turn of about the camera ray's.
pub fn multi_chain(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let j0 = first_diffuse_from_camera(x);
    if j0 == 0 || !x.v[j0 - 1].delta {
        return None; // one chain: the lens perturbation's
    }
    let (mut y, mut d, theta_lens) = retrace_eye(sp, x, rng)?;
    if theta_lens <= 0.0 || !theta_lens.is_finite() {
        return None;
    }
    while d >= 1 && x.v[d - 1].delta {
        let wx = sp.pivot_dir(&x.v[d], &x.v[d - 1]);
        if wx == Vec3::ZERO {
            return None;
        }
        let theta = log_uniform(rng.next_f64(), 0.5 * theta_lens, 2.0 * theta_lens).min(std::f64::consts::FRAC_PI_2);
        let phi = std::f64::consts::TAU * rng.next_f64();
        let hit = sp.trace(&y[d], turn(wx, theta, phi))?;
        y[d - 1] = marked(hit, &x.v[d - 1]);
        d = follow_to_light(sp, x, &mut y, d - 1)?;
    }
    if d >= 1 && !sp.visible(&y[d - 1], &y[d]) {
        return None;
    }
    let y = sp.finish(y)?;
    let ratio = eye_ratio(sp, x, &y, d)?;
    Some((y, ratio))
}

/// Caustic perturbation ((L|D)S*DE): the direction leaving the last non-delta vertex
/// before the D vertex seen by the camera turned slightly, the chain followed, the camera
/// reconnected.
pub fn caustic(sp: &Space, x: &MPath, rng: &mut Pcg32) -> Option<(MPath, f64)> {
    let k = x.k();
    if k < 2 || x.v[k - 1].delta {
        return None;
    }
    let j = (0..k - 1).rev().find(|&i| !x.v[i].delta)?;
    let w = sp.pivot_dir(&x.v[j], &x.v[j + 1]);
    if w == Vec3::ZERO {
        return None;
    }
    let theta = log_uniform(rng.next_f64(), 1e-4, 0.1);
    let phi = std::f64::consts::TAU * rng.next_f64();
    let mut y = x.v.clone();
    y[j + 1] = marked(sp.trace(&x.v[j], turn(w, theta, phi))?, &x.v[j + 1]);
    for i in j + 1..k - 1 {
        let next = sp.follow(&y[i], &y[i - 1], TransportMode::Importance)?;
        y[i + 1] = marked(next, &x.v[i + 1]);
    }
    if !Space::scatters(&y[k - 1]) {
        return None;
    }
    let y = sp.finish(y)?;
    if !sp.visible(&y.v[k - 1], &y.v[k]) {
        return None;
    }
    let (mut px, mut py) = (1.0, 1.0);
    for i in j + 1..k {
        px *= sp.pl_follow(&x.v, i);
        py *= sp.pl_follow(&y.v, i);
    }
    if py.is_nan() || py <= 0.0 {
        return None;
    }
    Some((y, px / py))
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
    let mut light = Vec::new();
    let mut eye = vec![Vertex::camera(sp.cam_pos, Vec2::ZERO, Rgb::WHITE)];
    if !sp.walk_light(&mut light, s, rng) || !sp.walk_eye(&mut eye, k - s, rng) {
        return None;
    }
    let y = join(sp, light, eye)?;
    let p = p_length(k, sp) * sp.regen_density(&y.v, 0, k);
    (p > 0.0).then_some((y, p))
}
