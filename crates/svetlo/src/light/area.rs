//! Area lights: a shape with an emitting material, Mitsuba's `area`. Emission is one-sided,
//! on the front of the geometric normal, and Lambertian (radiance independent of direction).
//!
//! Sampling from a reference point (`sample_li`):
//! * meshes: a point uniform by area (triangle by area, then uniform in the triangle),
//!   converted to solid angle by dist² / (|cos θ_light| A);
//! * spheres seen from outside: uniform in the cone of directions the sphere subtends
//!   (every sample lands on the visible cap); from inside: uniform by area, as meshes.

use super::{EmissionSample, LightSample};
use crate::geometry::{Geometry, Ray, Sphere};
use crate::math::{safe_sqrt, warp, Frame, INV_PI, PI};
use crate::sampling::Distribution1D;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// Emitting shape: one-sided (front of the geometric normal), as Mitsuba's `area`.
#[derive(Clone, Debug)]
pub struct AreaLight {
    pub shape: u32,
    pub geometry: Arc<Geometry>,
    pub radiance: Texture,
    /// Triangle selection by area (meshes only).
    pub tri_distribution: Option<Distribution1D>,
    pub area: f32,
    /// 1 / area (0 without area): the density of every point sample.
    inv_area: f32,
    /// Per triangle, the frame of the geometric normal on the side the shading normals face,
    /// when that normal is the same over the whole triangle (all vertex normals on one side):
    /// light sampling then needs no interpolation, and emission sampling no frame of its own
    /// (`Frame::from_normal` of that normal, so the same bits). `None` falls back to
    /// `TriangleMesh::surface` at the point.
    tri_frames: Vec<Option<Frame>>,
    /// Per triangle, its first vertex and two edges (p0, p1 - p0, p2 - p0): sampling a point
    /// reads one record instead of three indexed positions.
    tri_edges: Vec<[Vec3; 3]>,
}

/// The geometric normal of triangle `t` as `TriangleMesh::surface` orients it, if that is the
/// same at every point of the triangle: no shading normals, or all three on one side.
pub(crate) fn constant_normal(m: &crate::geometry::TriangleMesh, t: usize) -> Option<Vec3> {
    let [p0, p1, p2] = m.vertices(t);
    let ng = (p1 - p0).cross(p2 - p0).normalize_or_zero();
    if m.normals.is_empty() {
        return Some(ng);
    }
    let sides = m.indices[t].map(|i| ng.dot(m.normals[i as usize]));
    if sides.iter().all(|&d| d > 0.0) {
        Some(ng)
    } else if sides.iter().all(|&d| d < 0.0) {
        Some(-ng)
    } else {
        None
    }
}

/// Spheres and the points they are sampled from, lane by lane (structure of arrays), for
/// [`AreaLight::sample_constant_spheres`]; `u` the light sample's numbers.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SphereLanes<const N: usize> {
    pub center: [[f32; N]; 3],
    pub radius: [f32; N],
    pub flip: [bool; N],
    pub p_ref: [[f32; N]; 3],
    pub u: [[f32; N]; 2],
}

impl<const N: usize> Default for SphereLanes<N> {
    fn default() -> Self {
        SphereLanes { center: [[0.0; N]; 3], radius: [0.0; N], flip: [false; N], p_ref: [[0.0; N]; 3], u: [[0.0; N]; 2] }
    }
}

/// [`AreaLight::sample_constant_spheres`]' results, lane by lane: `inside` where
/// [`AreaLight::sample_constant_sphere`] says None (the point is sampled by area), else
/// `found` where it gives a sample, and that sample's direction, point, normal and density.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SphereSamples<const N: usize> {
    pub inside: [bool; N],
    pub found: [bool; N],
    pub wi: [[f32; N]; 3],
    pub p: [[f32; N]; 3],
    pub n: [[f32; N]; 3],
    pub pdf: [f32; N],
}

/// The cone of directions a sphere subtends from an outside point.
struct SphereCone {
    /// Unit vector from the sphere's center toward the reference point.
    axis: Vec3,
    /// sin θ_max = radius / distance, and the reciprocals of it and of its square.
    inv_sin_max: f32,
    inv_sin2_max: f32,
    /// 1 - cos θ_max, computed without cancellation for small cones.
    one_minus_cos_max: f32,
}

impl SphereCone {
    /// None when `p_ref` is inside the sphere (or on it): area sampling is used there.
    #[inline]
    fn new(s: &Sphere, p_ref: Vec3) -> Option<Self> {
        let dc = p_ref - s.center;
        let dist2 = dc.length_squared();
        let r2 = s.radius * s.radius;
        let one_minus_cos_max = Self::one_minus_cos_max(dist2, r2)?;
        let dist = dist2.sqrt();
        let inv_sin_max = dist / s.radius;
        Some(SphereCone { axis: dc * (1.0 / dist), inv_sin_max, inv_sin2_max: inv_sin_max * inv_sin_max, one_minus_cos_max })
    }

    /// 1 - cos θ_max at squared distance `dist2` from a sphere of squared radius `r2`; None
    /// inside (or on) the sphere. [`Self::new`] and [`AreaLight::pdf_li`] share it, so
    /// their densities agree to the bit.
    #[inline]
    fn one_minus_cos_max(dist2: f32, r2: f32) -> Option<f32> {
        if dist2 <= r2 * (1.0 + 1e-5) {
            return None;
        }
        let sin2_max = r2 / dist2;
        Some(sin2_max / (1.0 + safe_sqrt(1.0 - sin2_max)))
    }

    #[inline]
    fn pdf_of(one_minus_cos_max: f32) -> f32 {
        1.0 / (2.0 * PI * one_minus_cos_max)
    }
}

impl AreaLight {
    pub fn new(shape: u32, geometry: Arc<Geometry>, radiance: Texture) -> Self {
        let (tri_distribution, area, tri_frames, tri_edges) = match &*geometry {
            Geometry::Mesh(m) => {
                let areas: Vec<f32> = (0..m.triangle_count()).map(|t| m.triangle_area(t)).collect();
                let area = areas.iter().sum();
                let frames = (0..m.triangle_count()).map(|t| constant_normal(m, t).map(Frame::from_normal)).collect();
                let edges = (0..m.triangle_count())
                    .map(|t| {
                        let [p0, p1, p2] = m.vertices(t);
                        [p0, p1 - p0, p2 - p0]
                    })
                    .collect();
                (Some(Distribution1D::new(&areas)), area, frames, edges)
            }
            Geometry::Sphere(s) => (None, s.area(), Vec::new(), Vec::new()),
            // Refused as emitters by the scene builder; no area to sample.
            Geometry::SdfGrid(_) => (None, 0.0, Vec::new(), Vec::new()),
        };
        let inv_area = if area > 0.0 { 1.0 / area } else { 0.0 };
        AreaLight { shape, geometry, radiance, tri_distribution, area, inv_area, tri_frames, tri_edges }
    }

    /// Radiance leaving point with normal `n` and uv toward direction `w`.
    #[inline]
    pub fn l(&self, n: Vec3, uv: Vec2, w: Vec3) -> Rgb {
        if n.dot(w) <= 0.0 {
            Rgb::BLACK
        } else {
            self.radiance.eval(uv)
        }
    }

    /// Uniform point on the surface by area: (point, geometric normal, uv, pdf_area).
    /// Returns a zero pdf for a shape without area.
    pub fn sample_point(&self, u: Vec2) -> (Vec3, Vec3, Vec2, f32) {
        let (p, n, _, uv, pdf) = self.sample_point_framed(u);
        (p, n, uv, pdf)
    }

    /// [`Self::sample_point`], with the normal's frame where the triangle has one precomputed.
    #[inline(always)]
    fn sample_point_framed(&self, u: Vec2) -> (Vec3, Vec3, Option<&Frame>, Vec2, f32) {
        let pdf = self.inv_area;
        match (&*self.geometry, &self.tri_distribution) {
            (Geometry::Mesh(m), Some(dist)) if !dist.is_empty() => {
                let (t, _, ur) = dist.sample_discrete(u.x);
                let b = warp::square_to_uniform_triangle(Vec2::new(ur, u.y));
                let Some([p0, e1, e2]) = self.tri_edges.get(t) else { return (Vec3::ZERO, Vec3::Z, None, Vec2::ZERO, 0.0) };
                let p = *p0 + *e1 * b.x + *e2 * b.y;
                match self.tri_frames.get(t) {
                    // A constant texture needs no uv.
                    Some(Some(frame)) if self.radiance.is_constant() => (p, frame.n, Some(frame), Vec2::ZERO, pdf),
                    _ => {
                        let (ng, _ns, uv, _) = m.surface(t, b.x, b.y);
                        (p, ng, None, uv, pdf)
                    }
                }
            }
            (Geometry::Sphere(s), _) => {
                let d = warp::square_to_uniform_sphere(u);
                let p = s.center + d * s.radius;
                let (n, uv, _) = s.surface(p);
                (p, n, None, uv, pdf)
            }
            _ => (Vec3::ZERO, Vec3::Z, None, Vec2::ZERO, 0.0),
        }
    }

    pub fn sample_li(&self, p_ref: Vec3, u: Vec2) -> Option<LightSample> {
        if let Geometry::Sphere(s) = &*self.geometry {
            if let Some(cone) = SphereCone::new(s, p_ref) {
                return self.sample_sphere_cone(s, &cone, p_ref, u);
            }
        }
        let (p, n, uv, pdf_area) = self.sample_point(u);
        if pdf_area <= 0.0 {
            return None;
        }
        let d = p - p_ref;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let cos_l = n.dot(-wi);
        if cos_l <= 0.0 {
            return None; // the back of a one-sided emitter
        }
        let pdf = pdf_area * dist2 / cos_l;
        Some(LightSample { wi, li: self.radiance.eval(uv), pdf, p, n, infinite: false })
    }

    /// Uniform direction in the cone; the point is where that direction first meets the
    /// sphere, found from the angle at the sphere's center (no ray intersection, so no
    /// misses at grazing angles).
    fn sample_sphere_cone(&self, s: &Sphere, cone: &SphereCone, p_ref: Vec3, u: Vec2) -> Option<LightSample> {
        let (p, n_out, wi) = Self::cone_point(s, cone, p_ref, u)?;
        // A constant radiance needs no uv (its two inverse trigonometric functions), and the
        // normal is the unit vector the point was made from.
        let (n, uv) = if self.radiance.is_constant() {
            (if s.flip_normals { -n_out } else { n_out }, Vec2::ZERO)
        } else {
            let (n, uv, _) = s.surface(p);
            (n, uv)
        };
        if n.dot(-wi) <= 0.0 {
            return None; // an inward-facing sphere seen from outside emits nothing toward us
        }
        Some(LightSample { wi, li: self.radiance.eval(uv), pdf: SphereCone::pdf_of(cone.one_minus_cos_max), p, n, infinite: false })
    }

    /// The cone sample's point on the sphere, its outward normal and the unit direction to it
    /// (None where the point is the reference point).
    #[inline(always)]
    fn cone_point(s: &Sphere, cone: &SphereCone, p_ref: Vec3, u: Vec2) -> Option<(Vec3, Vec3, Vec3)> {
        let one_minus_cos = u.y * cone.one_minus_cos_max;
        let cos_t = 1.0 - one_minus_cos;
        let sin2_t = one_minus_cos * (2.0 - one_minus_cos);
        // Angle α at the center between the axis and the hit point:
        // cos α = sin²θ / sin θ_max + cos θ sqrt(1 - sin²θ / sin²θ_max).
        let cos_a = (sin2_t * cone.inv_sin_max + cos_t * safe_sqrt(1.0 - sin2_t * cone.inv_sin2_max)).min(1.0);
        let sin_a = safe_sqrt(1.0 - cos_a * cos_a);
        let (sin_phi, cos_phi) = warp::sin_cos_2pi(u.x);
        let frame = Frame::from_normal(cone.axis);
        let n_out = frame.to_world(Vec3::new(sin_a * cos_phi, sin_a * sin_phi, cos_a));
        let p = s.center + n_out * s.radius;
        let d = p - p_ref;
        let dist = d.length();
        if dist == 0.0 {
            return None;
        }
        Some((p, n_out, d / dist))
    }

    /// [`Self::sample_li`] of a sphere of constant radiance `s`: None where `p_ref` is inside
    /// it (sampled by area there), else the light sample's direction, point, normal and
    /// density, or None where `sample_li` gives none. The same operations, so the same bits:
    /// the tests' link between `sample_li` and [`Self::sample_constant_spheres`].
    #[cfg(test)]
    pub(crate) fn sample_constant_sphere(s: &Sphere, p_ref: Vec3, u: Vec2) -> Option<Option<(Vec3, Vec3, Vec3, f32)>> {
        let cone = SphereCone::new(s, p_ref)?;
        Some(Self::cone_point(s, &cone, p_ref, u).and_then(|(p, n_out, wi)| {
            let n = if s.flip_normals { -n_out } else { n_out };
            if n.dot(-wi) <= 0.0 {
                return None;
            }
            Some((wi, p, n, SphereCone::pdf_of(cone.one_minus_cos_max)))
        }))
    }

    /// [`Self::sample_constant_sphere`] for `N` lanes at once, each with its own sphere: the
    /// same operations lane by lane, without branches, so that the lanes run as vector lanes
    /// (the square roots and divisions of one lane's chain wait on each other; eight lanes'
    /// chains side by side fill the wait). The same bits.
    #[inline(always)]
    pub(crate) fn sample_constant_spheres<const N: usize>(q: &SphereLanes<N>) -> SphereSamples<N> {
        let mut o = SphereSamples { inside: [false; N], found: [false; N], wi: [[0.0; N]; 3], p: [[0.0; N]; 3], n: [[0.0; N]; 3], pdf: [0.0; N] };
        for l in 0..N {
            let c = Vec3::new(q.center[0][l], q.center[1][l], q.center[2][l]);
            let r = q.radius[l];
            let p_ref = Vec3::new(q.p_ref[0][l], q.p_ref[1][l], q.p_ref[2][l]);
            // `SphereCone::new`, computed whether or not the point is outside.
            let dc = p_ref - c;
            let dist2 = dc.length_squared();
            let r2 = r * r;
            let inside = dist2 <= r2 * (1.0 + 1e-5);
            let sin2_max = r2 / dist2;
            let one_minus_cos_max = sin2_max / (1.0 + safe_sqrt(1.0 - sin2_max));
            let dist = dist2.sqrt();
            let inv_sin_max = dist / r;
            let axis = dc * (1.0 / dist);
            let inv_sin2_max = inv_sin_max * inv_sin_max;
            // `cone_point`.
            let one_minus_cos = q.u[1][l] * one_minus_cos_max;
            let cos_t = 1.0 - one_minus_cos;
            let sin2_t = one_minus_cos * (2.0 - one_minus_cos);
            let cos_a = (sin2_t * inv_sin_max + cos_t * safe_sqrt(1.0 - sin2_t * inv_sin2_max)).min(1.0);
            let sin_a = safe_sqrt(1.0 - cos_a * cos_a);
            let (sin_phi, cos_phi) = warp::sin_cos_2pi(q.u[0][l]);
            let n_out = Frame::from_normal(axis).to_world(Vec3::new(sin_a * cos_phi, sin_a * sin_phi, cos_a));
            let p = c + n_out * r;
            let d = p - p_ref;
            let len = d.length();
            let wi = d / len;
            // `sample_constant_sphere`'s tests.
            let n = if q.flip[l] { -n_out } else { n_out };
            o.inside[l] = inside;
            // It refuses a facing `<= 0` only (a NaN one passes).
            let facing = n.dot(-wi);
            o.found[l] = !inside && len != 0.0 && (facing > 0.0 || facing.is_nan());
            for k in 0..3 {
                o.wi[k][l] = wi[k];
                o.p[k][l] = p[k];
                o.n[k][l] = n[k];
            }
            o.pdf[l] = SphereCone::pdf_of(one_minus_cos_max);
        }
        o
    }

    /// Solid-angle density of `sample_li` choosing the point `p` (normal `n`) from `p_ref`.
    pub fn pdf_li(&self, p_ref: Vec3, p: Vec3, n: Vec3) -> f32 {
        if let Geometry::Sphere(s) = &*self.geometry {
            if let Some(omc) = SphereCone::one_minus_cos_max((p_ref - s.center).length_squared(), s.radius * s.radius) {
                return SphereCone::pdf_of(omc);
            }
        }
        if self.area <= 0.0 {
            return 0.0;
        }
        let d = p - p_ref;
        let dist2 = d.length_squared();
        let cos_l = n.dot(d).abs() / dist2.sqrt();
        if cos_l <= 0.0 || !cos_l.is_finite() {
            return 0.0;
        }
        dist2 / (cos_l * self.area)
    }

    /// Emitted power Φ = π A · mean radiance (one-sided Lambertian emitter), luminance.
    pub fn power(&self) -> f32 {
        PI * self.area * self.radiance.mean().luminance().max(0.0)
    }

    /// A ray leaving the light: origin uniform by area, direction cosine-weighted about the
    /// geometric normal (proportional to the emitted radiance's projected solid angle).
    pub fn sample_le(&self, u_pos: Vec2, u_dir: Vec2, time: f32) -> Option<EmissionSample> {
        let (p, n, frame, uv, pdf_pos) = self.sample_point_framed(u_pos);
        if pdf_pos <= 0.0 {
            return None;
        }
        let local = warp::square_to_cosine_hemisphere(u_dir);
        let pdf_dir = warp::square_to_cosine_hemisphere_pdf(local);
        if pdf_dir <= 0.0 {
            return None;
        }
        let d = match frame {
            Some(f) => f.to_world(local),
            None => Frame::from_normal(n).to_world(local),
        };
        let mut ray = Ray::new(crate::geometry::ray::offset_ray_origin(p, n, d), d);
        ray.time = time;
        Some(EmissionSample { ray, le: self.radiance.eval(uv), pdf_pos, pdf_dir, n })
    }

    /// What `sample_le`'s framed case (a mesh of constant radiance, a triangle with its
    /// frame) takes from `u_pos` before its arithmetic: the triangle (first vertex, two
    /// edges), its frame, and the triangle choice's remapped number; None in other cases.
    /// For `emit8`, which does the arithmetic of eight samples at once.
    #[inline]
    pub(crate) fn framed_triangle(&self, u_pos: Vec2) -> Option<(&[Vec3; 3], &Frame, f32)> {
        let (Geometry::Mesh(_), Some(dist)) = (&*self.geometry, &self.tri_distribution) else { return None };
        if dist.is_empty() || !self.radiance.is_constant() || self.inv_area <= 0.0 {
            return None;
        }
        let (t, _, ur) = dist.sample_discrete(u_pos.x);
        let tri = self.tri_edges.get(t)?;
        let frame = self.tri_frames.get(t)?.as_ref()?;
        Some((tri, frame, ur))
    }

    /// The emission sample of `sample_le`'s framed case from its ray, its frame's normal
    /// and its direction's density (what `emit8` computed).
    #[inline]
    pub(crate) fn framed_emission(&self, ray: Ray, n: Vec3, pdf_dir: f32) -> EmissionSample {
        EmissionSample { ray, le: self.radiance.eval(Vec2::ZERO), pdf_pos: self.inv_area, pdf_dir, n }
    }

    /// Densities of `sample_le` for a ray leaving the light at `ray.o` with normal `n`:
    /// (per unit area, per unit solid angle).
    pub fn pdf_le(&self, ray: &Ray, n: Vec3) -> (f32, f32) {
        (self.inv_area, n.dot(ray.d).max(0.0) * INV_PI)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::rng::Pcg32;

    /// Emission samples of a mesh light leave along `Frame::from_normal` of the sampled
    /// point's normal, bit for bit, whether that frame is precomputed (flat triangles, vertex
    /// normals on either side) or built at the point (normals across the triangle's plane),
    /// with the density 1 / area.
    #[test]
    fn mesh_emission_frames_are_the_normals_frames() {
        use crate::geometry::TriangleMesh;
        let mut rng = Pcg32::new(5, 11);
        let positions = vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 0.1, 0.0), Vec3::new(0.3, 1.7, 0.2), Vec3::new(-1.0, 0.5, 0.9)];
        let indices = vec![[0, 1, 2], [0, 2, 3]];
        let up = Vec3::new(0.1, -0.2, 1.0).normalize();
        let normals = [Vec::new(), vec![-up; 4], vec![up, up, up, -up]];
        let mut framed = 0;
        for normals in normals {
            let mesh = TriangleMesh { positions: positions.clone(), normals, uvs: Vec::new(), indices: indices.clone() };
            let light = AreaLight::new(0, Arc::new(Geometry::Mesh(mesh)), Texture::Constant(Rgb::splat(1.0)));
            framed += light.tri_frames.iter().flatten().count();
            for _ in 0..2000 {
                let (u_pos, u_dir) = (Vec2::new(rng.next_f32(), rng.next_f32()), Vec2::new(rng.next_f32(), rng.next_f32()));
                let es = light.sample_le(u_pos, u_dir, 0.0).expect("a sample");
                let (p, n, _, pdf) = light.sample_point(u_pos);
                let d = Frame::from_normal(n).to_world(warp::square_to_cosine_hemisphere(u_dir));
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                assert_eq!((bits(es.ray.d), bits(es.n)), (bits(d), bits(n)));
                assert_eq!(bits(es.ray.o), bits(crate::geometry::ray::offset_ray_origin(p, n, d)));
                assert_eq!((es.pdf_pos.to_bits(), pdf.to_bits()), ((1.0 / light.area).to_bits(), (1.0 / light.area).to_bits()));
            }
        }
        // Flat triangles, both with their normal and flipped; the mixed one builds its frame.
        assert_eq!(framed, 5);
    }

    /// Case `i` of the sphere-sample tests, from the numbers `f(lo, hi)`: a sphere (tiny or
    /// not, inward-facing or not), a reference point inside, on (within rounding), just
    /// outside or far from it, and the light sample's numbers (their ends and the quadrant
    /// boundaries, or random).
    fn sphere_case(i: usize, f: &mut impl FnMut(f32, f32) -> f32) -> (Sphere, Vec3, Vec2) {
        let us = [0.0f32, 0.25, 0.5, 0.75, 1.0 - f32::EPSILON, 0.124_999_99, 1e-9];
        let center = Vec3::new(f(-5.0, 5.0), f(-5.0, 5.0), f(-5.0, 5.0));
        let radius = if i.is_multiple_of(11) { 1e-3 } else { f(0.01, 2.0) };
        let sphere = Sphere { center, radius, flip_normals: i.is_multiple_of(5) };
        let dir = warp::square_to_uniform_sphere(Vec2::new(f(0.0, 1.0), f(0.0, 1.0)));
        let dist = match i % 4 {
            0 => radius * f(0.0, 1.0),
            1 => radius * (1.0 + f(-1e-5, 1e-5)),
            2 => radius * (1.0 + f(0.0, 1e-3)),
            _ => radius * f(1.0, 1e4),
        };
        let u = if i.is_multiple_of(3) { Vec2::new(us[i % us.len()], us[(i / 7) % us.len()]) } else { Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) };
        (sphere, center + dir * dist, u)
    }

    /// `sample_constant_sphere` (the path kernel's sphere light sample) gives
    /// `AreaLight::sample_li`'s bits (direction, point, normal, density, and None where it
    /// refuses), or says the point takes area sampling: reference points outside, on and
    /// inside spheres, near and far, inward-facing spheres, the numbers' ends and quadrant
    /// boundaries.
    #[test]
    fn constant_sphere_sample_is_sample_li() {
        let mut rng = Pcg32::new(3, 7);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let (mut cones, mut refused, mut inside) = (0, 0, 0);
        for i in 0..40_000usize {
            let (sphere, p_ref, u) = sphere_case(i, &mut f);
            let le = Rgb::new(2.0, 1.0, 0.5);
            let light = AreaLight::new(0, Arc::new(Geometry::Sphere(sphere)), Texture::Constant(le));
            let Some(fast) = AreaLight::sample_constant_sphere(&sphere, p_ref, u) else {
                assert!(SphereCone::new(&sphere, p_ref).is_none(), "{sphere:?} from {p_ref}: not sampled by its cone");
                inside += 1;
                continue;
            };
            cones += 1;
            let scalar = light.sample_li(p_ref, u);
            assert_eq!(fast.is_some(), scalar.is_some(), "{sphere:?} from {p_ref} u {u}");
            let (Some((wi, p, n, pdf)), Some(s)) = (fast, scalar) else {
                refused += 1;
                continue;
            };
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!((bits(wi), bits(p), bits(n), pdf.to_bits()), (bits(s.wi), bits(s.p), bits(s.n), s.pdf.to_bits()), "{sphere:?} from {p_ref} u {u}");
            assert_eq!(s.li, le);
        }
        // Every outcome was exercised.
        assert!(cones > 20_000 && refused > 100 && inside > 5_000, "{cones} cone samples, {refused} refused, {inside} inside");
    }

    /// `sample_constant_spheres` compiled as the path kernel's AVX2 build compiles it.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn spheres_avx2(q: &SphereLanes<8>) -> SphereSamples<8> {
        AreaLight::sample_constant_spheres(q)
    }

    /// `sample_constant_spheres` (eight lanes, a sphere each; as the baseline build and as the
    /// AVX2 one compile it) gives `sample_constant_sphere`'s outcome and bits lane by lane:
    /// points inside, on, just outside and far from the spheres, inward-facing spheres, the
    /// numbers' ends and quadrant boundaries.
    #[test]
    fn constant_spheres_are_the_single_samples() {
        let mut rng = Pcg32::new(5, 11);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let (mut found, mut refused, mut inside) = (0, 0, 0);
        for batch in 0..5_000usize {
            let mut q = SphereLanes::<8>::default();
            let mut lanes = [(Sphere { center: Vec3::ZERO, radius: 1.0, flip_normals: false }, Vec3::ZERO, Vec2::ZERO); 8];
            for (l, lane) in lanes.iter_mut().enumerate() {
                let (sphere, p_ref, u) = sphere_case(batch * 8 + l, &mut f);
                let (center, radius) = (sphere.center, sphere.radius);
                for k in 0..3 {
                    q.center[k][l] = center[k];
                    q.p_ref[k][l] = p_ref[k];
                }
                q.radius[l] = radius;
                q.flip[l] = sphere.flip_normals;
                q.u[0][l] = u.x;
                q.u[1][l] = u.y;
                *lane = (sphere, p_ref, u);
            }
            let o = AreaLight::sample_constant_spheres(&q);
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() {
                // SAFETY: the CPU has AVX2.
                let v = unsafe { spheres_avx2(&q) };
                let bits = |o: &SphereSamples<8>| (o.inside, o.found, [o.wi, o.p, o.n].map(|a| a.map(|r| r.map(f32::to_bits))), o.pdf.map(f32::to_bits));
                assert_eq!(bits(&v), bits(&o), "batch {batch}: the AVX2 build differs");
            }
            for (l, &(sphere, p_ref, u)) in lanes.iter().enumerate() {
                let one = AreaLight::sample_constant_sphere(&sphere, p_ref, u);
                assert_eq!(o.inside[l], one.is_none(), "{sphere:?} from {p_ref} u {u}");
                match one {
                    None => inside += 1,
                    Some(None) => {
                        assert!(!o.found[l], "{sphere:?} from {p_ref} u {u}: found");
                        refused += 1;
                    }
                    Some(Some((wi, p, n, pdf))) => {
                        assert!(o.found[l], "{sphere:?} from {p_ref} u {u}: not found");
                        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                        let lane = |a: &[[f32; 8]; 3]| Vec3::new(a[0][l], a[1][l], a[2][l]);
                        assert_eq!(
                            (bits(lane(&o.wi)), bits(lane(&o.p)), bits(lane(&o.n)), o.pdf[l].to_bits()),
                            (bits(wi), bits(p), bits(n), pdf.to_bits()),
                            "{sphere:?} from {p_ref} u {u}"
                        );
                        found += 1;
                    }
                }
            }
        }
        assert!(found > 15_000 && refused > 1_000 && inside > 15_000, "{found} found, {refused} refused, {inside} inside");
    }
}
