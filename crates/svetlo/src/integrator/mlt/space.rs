//! Veach's path space for Metropolis: a path x0 ... xk from a light (x0) to the camera (xk)
//! as `path::Vertex`es, its measurement contribution f in the area-product measure, and the
//! densities with which the bidirectional samplers produce its vertices.
//!
//! The chains live on paths whose light end is on an area light, whose camera is a pinhole,
//! and whose every scattering vertex scatters by a non-delta lobe; the rest of path space
//! (anything through a specular lobe) is rendered by the complement estimator of `mod.rs`.
//!
//! f(x) = Le(x0→x1) · Π_{i=1}^{k-1} fs(x_{i+1}←x_i←x_{i-1}) |ns_i·ω_{i→i-1}|
//!        · Π_{i=0}^{k-2} |ng_i·ω| / |x_i − x_{i+1}|² · c(x_{k-1})
//! with the shading-normal convention of the path tracer (radiance transport), and
//! c(x_{k-1}) the camera's area density of x_{k-1} for a uniform film sample (its We makes
//! the path tracer's camera-ray weight 1), so that f / p is exactly what the path tracer
//! and BDPT estimate.

use crate::bsdf::TransportMode;
use crate::geometry::Ray;
use crate::light::Light;
use crate::math::{warp, Frame};
use crate::path::{Vertex, VertexKind};
use crate::sampling::Pcg32;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// A light-to-camera path.
#[derive(Clone, Debug, Default)]
pub struct MPath {
    pub v: Vec<Vertex>,
}

impl MPath {
    /// Number of segments k.
    pub fn k(&self) -> usize {
        self.v.len() - 1
    }
    pub fn raster(&self) -> Vec2 {
        self.v.last().map(|c| c.raster).unwrap_or_default()
    }
}

/// What the space needs to know about the render.
#[derive(Clone, Copy)]
pub struct Space<'a> {
    pub scene: &'a Scene,
    pub cam_pos: Vec3,
    /// Most segments (max_depth), or usize::MAX.
    pub max_k: usize,
    /// Fewest segments (2 when emitters seen directly are hidden).
    pub min_k: usize,
}

#[inline]
fn dir(a: &Vertex, b: &Vertex) -> (Vec3, f32) {
    let d = b.p - a.p;
    let d2 = d.length_squared();
    if d2 == 0.0 || !d2.is_finite() {
        (Vec3::ZERO, 0.0)
    } else {
        (d / d2.sqrt(), d2)
    }
}

impl<'a> Space<'a> {
    pub fn new(scene: &'a Scene, max_depth: i32, hide_emitters: bool) -> Self {
        Space {
            scene,
            cam_pos: scene.camera.to_world.transform_point3(Vec3::ZERO),
            max_k: if max_depth < 0 { usize::MAX } else { max_depth as usize },
            min_k: if hide_emitters { 2 } else { 1 },
        }
    }

    /// Whether `v` may be a path's light end: a point on an area light.
    pub fn is_area_emitter(&self, v: &Vertex) -> bool {
        !v.infinite && v.light.is_some_and(|i| matches!(self.scene.lights[i as usize], Light::Area(_)))
    }

    /// Whether `v` can scatter in this space: a surface with a non-delta lobe.
    pub fn scatters(v: &Vertex) -> bool {
        v.kind == VertexKind::Surface && v.bsdf.as_ref().is_some_and(|b| b.flags().has_non_specular())
    }

    /// The camera vertex seeing `x` (the last scattering vertex), with its raster position;
    /// None off the film.
    pub fn camera_vertex(&self, x: &Vertex) -> Option<Vertex> {
        let (w, d2) = (x.p - self.cam_pos, (x.p - self.cam_pos).length_squared());
        if d2 == 0.0 {
            return None;
        }
        let ray = Ray::new(self.cam_pos, w / d2.sqrt());
        let (_, raster) = self.scene.camera.we(&ray)?;
        let (cw, ch) = (self.scene.camera.width as f32, self.scene.camera.height as f32);
        if !(raster.x >= 0.0 && raster.y >= 0.0 && raster.x < cw && raster.y < ch) {
            return None;
        }
        Some(Vertex::camera(self.cam_pos, raster, Rgb::WHITE))
    }

    /// BSDF at path vertex i toward the camera side (i+1) from the light side (i-1).
    fn fs(&self, p: &[Vertex], i: usize) -> Rgb {
        let v = &p[i];
        let Some(b) = &v.bsdf else { return Rgb::BLACK };
        let (we, _) = dir(v, &p[i + 1]);
        let (wl, _) = dir(v, &p[i - 1]);
        b.eval(v.shading.to_local(we), v.shading.to_local(wl), TransportMode::Radiance)
    }

    /// The measurement contribution f(x) (visibility of the segments is the caller's: walks
    /// trace them, connections test them).
    pub fn contribution(&self, x: &MPath) -> Rgb {
        let p = &x.v;
        let k = x.k();
        if k < self.min_k || k > self.max_k || !self.is_area_emitter(&p[0]) {
            return Rgb::BLACK;
        }
        let mut f = p[0].le(self.scene, &p[1]);
        for i in 1..k {
            if !Self::scatters(&p[i]) {
                return Rgb::BLACK;
            }
            let (wl, _) = dir(&p[i], &p[i - 1]);
            f *= self.fs(p, i) * p[i].shading.n.dot(wl).abs();
        }
        for i in 0..k - 1 {
            let (w, d2) = dir(&p[i], &p[i + 1]);
            if d2 == 0.0 {
                return Rgb::BLACK;
            }
            f *= p[i].ng.dot(w).abs() / d2;
        }
        let c = self.pe(p, k - 1);
        f * c as f32
    }

    /// Area density (f64) at p[i] of a light-side walk that made it from p[i-1] (and p[i-2]).
    pub fn pl(&self, p: &[Vertex], i: usize) -> f64 {
        let s = self.scene;
        let d = match i {
            0 => p[0].pdf_light_origin(s, &p[1]),
            1 => p[0].pdf_light(s, &p[1]),
            _ => p[i - 1].pdf(s, Some(&p[i - 2]), &p[i], TransportMode::Importance),
        };
        d as f64
    }

    /// Area density at p[i] of a camera-side walk that made it from p[i+1] (and p[i+2]).
    pub fn pe(&self, p: &[Vertex], i: usize) -> f64 {
        let k = p.len() - 1;
        let d = if i + 1 == k {
            p[k].pdf(self.scene, None, &p[i], TransportMode::Radiance)
        } else {
            p[i + 1].pdf(self.scene, Some(&p[i + 2]), &p[i], TransportMode::Radiance)
        };
        d as f64
    }

    /// Density with which vertices n0..n0+m-1 of `p` are regenerated between the kept ends,
    /// summed over the m + 1 ways to split them between a light-side and a camera-side walk
    /// (each chosen with probability 1/(m+1)). 1 when m = 0 (a bare connection).
    pub fn regen_density(&self, p: &[Vertex], n0: usize, m: usize) -> f64 {
        if m == 0 {
            return 1.0;
        }
        let pl: Vec<f64> = (n0..n0 + m).map(|i| self.pl(p, i)).collect();
        let pe: Vec<f64> = (n0..n0 + m).map(|i| self.pe(p, i)).collect();
        let mut sum = 0.0;
        for s in 0..=m {
            let prod: f64 = pl[..s].iter().product::<f64>() * pe[s..].iter().product::<f64>();
            sum += prod;
        }
        sum / (m + 1) as f64
    }

    /// Trace from `from` along `w` to a new surface vertex.
    fn trace(&self, from: &Vertex, w: Vec3) -> Option<Vertex> {
        let o = if from.kind == VertexKind::Camera { from.p } else { crate::geometry::ray::offset_ray_origin(from.p, from.ng, w) };
        let si = self.scene.intersect(&Ray::new(o, w))?;
        Some(Vertex::surface(self.scene, &si, Rgb::WHITE))
    }

    /// Grow `count` vertices from the light side after `prefix` (empty: start on a light),
    /// appending to `out`. False when the walk dies (escape, delta lobe, no light).
    pub fn walk_light(&self, prefix: &[Vertex], count: usize, rng: &mut Pcg32, out: &mut Vec<Vertex>) -> bool {
        let s = self.scene;
        let mut chain: Vec<Vertex> = prefix.iter().rev().take(2).rev().cloned().collect();
        for _ in 0..count {
            let n = chain.len();
            let next = if n == 0 {
                let (li, pmf, _) = s.light_distribution.sample_discrete(rng.next_f32());
                if pmf <= 0.0 || !matches!(s.lights[li], Light::Area(_)) {
                    return false;
                }
                let (u1, u2) = (Vec2::new(rng.next_f32(), rng.next_f32()), Vec2::new(rng.next_f32(), rng.next_f32()));
                let Some(es) = s.lights[li].sample_le(u1, u2, 0.0, &s.bounds) else { return false };
                Vertex::light_point(li as u32, es.ray.o, es.n, es.le, Rgb::WHITE, 0.0)
            } else if n == 1 && prefix.len() <= 1 {
                // Leave the light end by its emission (cosine about the normal).
                let v = &chain[0];
                let local = warp::square_to_cosine_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                let w = Frame::from_normal(v.ng).to_world(local);
                let Some(nv) = self.trace(v, w) else { return false };
                nv
            } else {
                let Some(nv) = self.scatter(&chain[n - 1], &chain[n - 2], TransportMode::Importance, rng) else { return false };
                nv
            };
            out.push(next.clone());
            chain.push(next);
            if chain.len() > 2 {
                chain.remove(0);
            }
        }
        true
    }

    /// The next vertex after `v` (reached from `prev`) by sampling its BSDF in `mode`; None
    /// where the walk ends (no BSDF, a specular lobe the chains do not hold, nothing hit).
    fn scatter(&self, v: &Vertex, prev: &Vertex, mode: TransportMode, rng: &mut Pcg32) -> Option<Vertex> {
        let b = v.bsdf.as_ref()?;
        let (wp, _) = dir(v, prev);
        let bs = b.sample(v.shading.to_local(wp), rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()), mode)?;
        if bs.lobe.is_specular() || bs.pdf <= 0.0 {
            return None;
        }
        self.trace(v, v.shading.to_world(bs.wi))
    }

    /// Grow `count` vertices from the camera side before `suffix` (`suffix[0]` the vertex
    /// next to the new ones, `suffix[1]` its neighbour toward the camera; the camera alone
    /// samples a uniform film position), appending them to `out` in walk order.
    pub fn walk_eye(&self, suffix: &[Vertex], count: usize, rng: &mut Pcg32, out: &mut Vec<Vertex>) -> bool {
        let cam = &self.scene.camera;
        let mut chain: Vec<Vertex> = suffix.iter().take(2).rev().cloned().collect(); // [.., toward camera, current]
        for _ in 0..count {
            let n = chain.len();
            let v = &chain[n - 1];
            let next = if v.kind == VertexKind::Camera {
                let raster = Vec2::new(rng.next_f32() * cam.width as f32, rng.next_f32() * cam.height as f32);
                // The camera's own ray (from the near plane), as the path tracer's.
                let ray = cam.generate_ray(raster, Vec2::splat(0.5), 0.0);
                let Some(si) = self.scene.intersect(&ray) else { return false };
                Vertex::surface(self.scene, &si, Rgb::WHITE)
            } else {
                let Some(nv) = self.scatter(v, &chain[n - 2], TransportMode::Radiance, rng) else { return false };
                nv
            };
            out.push(next.clone());
            chain.push(next);
            if chain.len() > 2 {
                chain.remove(0);
            }
        }
        true
    }

    /// Whether the segment a–b is unblocked.
    pub fn visible(&self, a: &Vertex, b: &Vertex) -> bool {
        if a.kind == VertexKind::Camera {
            return !self.scene.occluded(b.p, b.ng, a.p);
        }
        if b.kind == VertexKind::Camera {
            return !self.scene.occluded(a.p, a.ng, b.p);
        }
        !self.scene.occluded(a.p, a.ng, b.p)
    }

    /// Check the structure of a path: area emitter at 0, scattering vertices inside, the
    /// camera at the end with the raster position of x_{k-1}.
    pub fn finish(&self, v: Vec<Vertex>) -> Option<MPath> {
        let k = v.len().checked_sub(1)?;
        if k < self.min_k || k > self.max_k || !self.is_area_emitter(&v[0]) || v[1..k].iter().any(|x| !Self::scatters(x)) {
            return None;
        }
        let mut v = v;
        let cam = self.camera_vertex(&v[k - 1])?;
        v[k] = cam;
        Some(MPath { v })
    }
}
