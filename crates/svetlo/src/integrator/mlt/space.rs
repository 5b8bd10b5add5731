//! Veach's path space for Metropolis: a path x0 ... xk from a light (x0) to the camera (xk)
//! as `path::Vertex`es, its measurement contribution f in the area-product measure, and the
//! densities with which the bidirectional samplers produce its vertices.
//!
//! The chains live on every path whose light end is on an area light and whose camera is a
//! pinhole. A scattering vertex is either non-delta (its BSDF's non-delta part, evaluated by
//! `eval`) or delta (`Vertex::delta`, scattering by the specular or null lobe named by its
//! `event`): a mixed BSDF such as plastic makes two distinct kinds of vertex.
//!
//! f(x) = Le(x0→x1) · Π_{i=1}^{k-1} fs(x_{i+1}←x_i←x_{i-1}) |ns_i·ω_{i→i-1}|
//!        · Π_{i=0}^{k-2} |ng_i·ω| / |x_i − x_{i+1}|² · c(x_{k-1})
//! with the shading-normal convention of the path tracer (radiance transport), and
//! c(x_{k-1}) the camera's area density of x_{k-1} for a uniform film sample (its We makes
//! the path tracer's camera-ray weight 1), so that f / p is exactly what the path tracer
//! and BDPT estimate.
//!
//! **Delta vertices.** At a delta vertex fs |cos| is ρ δ, with ρ the lobe's weight (the
//! Fresnel factor, the radiance scaling of refraction) and δ a Dirac in the solid angle of
//! the direction toward the light, ω_in (the radiance form of the lobe). f and every density
//! of a path are kept as coefficients of the same product of such Diracs, which then cancel
//! in every ratio f/T (Veach §8.3, §10.3.5). A camera-side walk through a delta vertex
//! samples ω_in given ω_out with probability P_E (the lobe's choice): coefficient P_E. A
//! light-side walk samples ω_out given ω_in: its Dirac is in ω_out, δ_out = δ_in / |J| with
//! J = dω_out/dω_in = (η_in/η_out)² cos_in / cos_out (1 for reflection), so its coefficient is
//! P_L / |J|. The perturbations follow a lobe without choosing it: no P there. Connections
//! join two non-delta vertices only.

use crate::bsdf::{BsdfSample, LobeFlags, TransportMode};
use crate::camera::LensConnector;
use crate::geometry::Ray;
use crate::light::Light;
use crate::math::{warp, Frame};
use crate::path::{Event, EventKind, Vertex, VertexKind};
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
    /// The camera's connection constants, once (None: orthographic): a connection to the
    /// camera then costs no matrix inverse.
    pub lens: Option<LensConnector>,
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
            lens: scene.camera.lens_connector(),
            max_k: if max_depth < 0 { usize::MAX } else { max_depth as usize },
            min_k: if hide_emitters { 2 } else { 1 },
        }
    }

    /// Whether `v` may be a path's light end: a point on an area light.
    pub fn is_area_emitter(&self, v: &Vertex) -> bool {
        !v.infinite && v.light.is_some_and(|i| matches!(self.scene.lights[i as usize], Light::Area(_)))
    }

    /// Whether `v` can scatter in this space as it is marked: a surface with a non-delta
    /// lobe, or (marked delta) with the delta lobe of its event.
    pub fn scatters(v: &Vertex) -> bool {
        v.kind == VertexKind::Surface && if v.delta { v.lobes.contains(lobe_of(v.event)) } else { v.lobes.has_non_specular() }
    }

    /// The delta lobe of vertex p[i] followed from the neighbour `from` (i+1: radiance, from
    /// the camera side; i-1: importance, from the light side), checked against the path's
    /// other neighbour: its weight, choice probability and relative IOR.
    pub fn delta_lobe(&self, p: &[Vertex], i: usize, from_camera: bool) -> Option<BsdfSample> {
        let v = &p[i];
        let b = v.bsdf.as_ref()?;
        let (a, c) = if from_camera { (i + 1, i - 1) } else { (i - 1, i + 1) };
        let (wo, _) = dir(v, &p[a]);
        let (wi, _) = dir(v, &p[c]);
        let mode = if from_camera { TransportMode::Radiance } else { TransportMode::Importance };
        let s = b.sample_delta(v.shading.to_local(wo), lobe_of(v.event), mode)?;
        (v.shading.to_world(s.wi).dot(wi) > 0.999).then_some(s)
    }

    /// The camera vertex seeing `x` (the last scattering vertex), with its raster position;
    /// None off the film.
    pub fn camera_vertex(&self, x: &Vertex) -> Option<Vertex> {
        let (w, d2) = (x.p - self.cam_pos, (x.p - self.cam_pos).length_squared());
        if d2 == 0.0 {
            return None;
        }
        let ray = Ray::new(self.cam_pos, w / d2.sqrt());
        let (_, raster) = self.lens.as_ref()?.we(&ray)?;
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
            if p[i].delta {
                // ρ: the lobe's coefficient of δ_in.
                let Some(s) = self.delta_lobe(p, i, true) else { return Rgb::BLACK };
                f *= s.f * s.wi.z.abs();
            } else {
                let (wl, _) = dir(&p[i], &p[i - 1]);
                f *= self.fs(p, i) * p[i].shading.n.dot(wl).abs();
            }
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
            _ if p[i - 1].delta => {
                let Some(l) = self.delta_lobe(p, i - 1, false) else { return 0.0 };
                // 1/|J| = η_rel² cos_out / cos_in, η_rel = η_out/η_in (the sample's eta).
                let wo_z = p[i - 1].shading.n.dot(dir(&p[i - 1], &p[i - 2]).0).abs();
                if wo_z == 0.0 {
                    return 0.0;
                }
                let inv_j = l.eta * l.eta * l.wi.z.abs() / wo_z;
                l.pdf * inv_j * p[i - 1].convert_density(1.0, &p[i])
            }
            _ => p[i - 1].pdf(s, Some(&p[i - 2]), &p[i], TransportMode::Importance),
        };
        d as f64
    }

    /// Area density at p[i] of a camera-side walk that made it from p[i+1] (and p[i+2]).
    pub fn pe(&self, p: &[Vertex], i: usize) -> f64 {
        let k = p.len() - 1;
        let d = if i + 1 == k {
            p[k].pdf(self.scene, None, &p[i], TransportMode::Radiance)
        } else if p[i + 1].delta {
            let Some(l) = self.delta_lobe(p, i + 1, true) else { return 0.0 };
            l.pdf * p[i + 1].convert_density(1.0, &p[i])
        } else {
            p[i + 1].pdf(self.scene, Some(&p[i + 2]), &p[i], TransportMode::Radiance)
        };
        d as f64
    }

    /// Area density at p[i] of a walk from the camera side that follows the delta lobes
    /// without choosing them (the perturbations): the camera's density for i = k-1, the
    /// geometric conversion after a delta vertex, 0 after a non-delta one.
    pub fn pe_follow(&self, p: &[Vertex], i: usize) -> f64 {
        let k = p.len() - 1;
        if i + 1 == k {
            return self.pe(p, i);
        }
        f64::from(p[i + 1].convert_density(1.0, &p[i]))
    }

    /// The same from the light side: 1/|J| times the geometric conversion.
    pub fn pl_follow(&self, p: &[Vertex], i: usize) -> f64 {
        if i >= 2 && p[i - 1].delta {
            let Some(l) = self.delta_lobe(p, i - 1, false) else { return 0.0 };
            let wo_z = p[i - 1].shading.n.dot(dir(&p[i - 1], &p[i - 2]).0).abs();
            if wo_z == 0.0 {
                return 0.0;
            }
            return f64::from(l.eta * l.eta * l.wi.z.abs() / wo_z * p[i - 1].convert_density(1.0, &p[i]));
        }
        f64::from(p[i - 1].convert_density(1.0, &p[i]))
    }

    /// Density with which vertices n0..n0+m-1 of `p` are regenerated between the kept ends,
    /// summed over the m + 1 ways to split them between a light-side and a camera-side walk
    /// (each chosen with probability 1/(m+1)); a split whose connection would touch a delta
    /// vertex cannot make the path. For m = 0 (a bare connection): 1, or 0 if an end is delta.
    pub fn regen_density(&self, p: &[Vertex], n0: usize, m: usize) -> f64 {
        let joinable = |s: usize| n0 + s == 0 || (!p[n0 + s - 1].delta && !p[n0 + s].delta);
        if m == 0 {
            return if joinable(0) { 1.0 } else { 0.0 };
        }
        let pl: Vec<f64> = (n0..n0 + m).map(|i| self.pl(p, i)).collect();
        let pe: Vec<f64> = (n0..n0 + m).map(|i| self.pe(p, i)).collect();
        let mut sum = 0.0;
        for s in 0..=m {
            if joinable(s) {
                sum += pl[..s].iter().product::<f64>() * pe[s..].iter().product::<f64>();
            }
        }
        sum / (m + 1) as f64
    }

    /// Where rays leaving `from` toward `w` start (surfaces: offset off the surface).
    fn origin(from: &Vertex, w: Vec3) -> Vec3 {
        if from.kind == VertexKind::Camera {
            from.p
        } else {
            crate::geometry::ray::offset_ray_origin(from.p, from.ng, w)
        }
    }

    /// Trace from `from` along `w` to a new surface vertex.
    pub fn trace(&self, from: &Vertex, w: Vec3) -> Option<Vertex> {
        let si = self.scene.intersect(&Ray::new(Self::origin(from, w), w))?;
        Some(Vertex::surface(self.scene, &si, Rgb::WHITE))
    }

    /// The direction from where rays leaving `from` start to `to`. The angular perturbations
    /// turn this one: a ray traced along it from that origin lands on `to` exactly, so the
    /// angle between the old and the new direction is the same in both directions of a move
    /// (measured from `from.p` they would differ by the offset over the distance, which at
    /// Veach's smallest angles, 1e-4 rad, would break the kernel's symmetry).
    pub fn pivot_dir(&self, from: &Vertex, to: &Vertex) -> Vec3 {
        let o = Self::origin(from, to.p - from.p);
        (to.p - o).normalize_or_zero()
    }

    /// Extend `v` (the kept light side of a path, possibly empty: then start on a light) by
    /// `count` vertices of a light-side walk. The vertex each step scatters from is marked
    /// delta or not by the lobe it chose. False when the walk dies (escape, absorption).
    pub fn walk_light(&self, v: &mut Vec<Vertex>, count: usize, rng: &mut Pcg32) -> bool {
        let s = self.scene;
        for _ in 0..count {
            let n = v.len();
            let next = if n == 0 {
                let (li, pmf, _) = s.light_distribution.sample_discrete(rng.next_f32());
                if pmf <= 0.0 || !matches!(s.lights[li], Light::Area(_)) {
                    return false;
                }
                let (u1, u2) = (Vec2::new(rng.next_f32(), rng.next_f32()), Vec2::new(rng.next_f32(), rng.next_f32()));
                let Some(es) = s.lights[li].sample_le(u1, u2, 0.0, &s.bounds) else { return false };
                Vertex::light_point(li as u32, es.ray.o, es.n, es.le, Rgb::WHITE, 0.0)
            } else if n == 1 {
                // Leave the light end by its emission (cosine about the normal).
                let local = warp::square_to_cosine_hemisphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                let w = Frame::from_normal(v[0].ng).to_world(local);
                let Some(nv) = self.trace(&v[0], w) else { return false };
                nv
            } else {
                let (head, tail) = v.split_at_mut(n - 1);
                let Some(nv) = self.scatter(&mut tail[0], &head[n - 2], TransportMode::Importance, rng) else { return false };
                nv
            };
            v.push(next);
        }
        true
    }

    /// The next vertex after `v` (reached from `prev`) by sampling its BSDF in `mode`,
    /// marking `v` delta or not by the lobe chosen; None where the walk ends.
    fn scatter(&self, v: &mut Vertex, prev: &Vertex, mode: TransportMode, rng: &mut Pcg32) -> Option<Vertex> {
        let b = v.bsdf.as_ref()?;
        let (wp, _) = dir(v, prev);
        let bs = b.sample(v.shading.to_local(wp), rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()), mode)?;
        if bs.pdf <= 0.0 || bs.f.is_black() {
            return None;
        }
        v.delta = bs.lobe.is_specular();
        v.event = Event::from_lobe(bs.lobe);
        self.trace(v, v.shading.to_world(bs.wi))
    }

    /// Extend `r` (the kept camera side of a path in reverse order: the camera first) by
    /// `count` vertices of a camera-side walk; the camera alone samples a uniform film
    /// position. The vertex each step scatters from is marked delta or not.
    pub fn walk_eye(&self, r: &mut Vec<Vertex>, count: usize, rng: &mut Pcg32) -> bool {
        let cam = &self.scene.camera;
        for _ in 0..count {
            let n = r.len();
            let next = if r[n - 1].kind == VertexKind::Camera {
                let raster = Vec2::new(rng.next_f32() * cam.width as f32, rng.next_f32() * cam.height as f32);
                // The camera's own ray (from the near plane), as the path tracer's.
                let ray = cam.generate_ray(raster, Vec2::splat(0.5), 0.0);
                let Some(si) = self.scene.intersect(&ray) else { return false };
                Vertex::surface(self.scene, &si, Rgb::WHITE)
            } else {
                let (head, tail) = r.split_at_mut(n - 1);
                let Some(nv) = self.scatter(&mut tail[0], &head[n - 2], TransportMode::Radiance, rng) else { return false };
                nv
            };
            r.push(next);
        }
        true
    }

    /// Follow the delta lobe `v` is marked with from `prev` (light-side walks: importance,
    /// camera-side: radiance) to the next surface.
    pub fn follow(&self, v: &Vertex, prev: &Vertex, mode: TransportMode) -> Option<Vertex> {
        let b = v.bsdf.as_ref()?;
        let (wp, _) = dir(v, prev);
        let s = b.sample_delta(v.shading.to_local(wp), lobe_of(v.event), mode)?;
        self.trace(v, v.shading.to_world(s.wi))
    }

    /// Whether the segment a–b is unblocked.
    pub fn visible(&self, a: &Vertex, b: &Vertex) -> bool {
        // From the surface toward the camera's lens point.
        let (from, to) = if a.kind == VertexKind::Camera { (b, a) } else { (a, b) };
        !self.scene.occluded_between(from.p, from.ng, to.p, to.ng, 0.0)
    }

    /// Check the structure of a path: area emitter at 0, scattering vertices inside (as
    /// marked), the camera at the end with the raster position of x_{k-1}.
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

/// The lobe a delta vertex's event names.
pub fn lobe_of(e: Event) -> LobeFlags {
    match (e.kind, e.transmission) {
        (EventKind::Null, _) => LobeFlags::NULL_TRANSMISSION,
        (_, true) => LobeFlags::SPECULAR_TRANSMISSION,
        _ => LobeFlags::SPECULAR_REFLECTION,
    }
}
