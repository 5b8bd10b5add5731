//! Connecting the first s vertices of a light subpath to the first t of a camera subpath:
//! the path's unweighted contribution and its MIS weight.
//!
//! * s = 0: the camera subpath itself ends on an emitter;
//! * t = 1: the light subpath's end is connected to a fresh point on the lens
//!   (`Camera::sample_wi`); the result lands at its own film position (a splat);
//! * s = 1: a fresh point on a light (`Light::sample_li`, next-event estimation);
//! * otherwise the two ends are joined by a shadow ray.
//!
//! Sampler dimensions: t = 1 uses two (the lens), s = 1 three (light choice, point).

use super::vertex::geometry_term;
use super::{mis_weight, PathConfig, Vertex, VertexKind};
use crate::bsdf::TransportMode;
use crate::geometry::Ray;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::Vec2;

/// One strategy's estimate for one pair of subpaths.
#[derive(Clone, Copy, Debug)]
pub struct Connection {
    /// Unweighted contribution (in the film's pixel units; splats are divided by the
    /// number of light paths per pixel).
    pub l: Rgb,
    /// Power-heuristic weight (1 when not asked for).
    pub weight: f32,
    /// Film position for t = 1 (a splat); None: the camera subpath's own pixel.
    pub raster: Option<Vec2>,
    /// The vertex the strategy sampled (t = 1: the lens point; s = 1: the light point) and,
    /// for s = 1, its light: what light path expressions need of it.
    pub sampled_p: glam::Vec3,
    pub sampled_light: Option<u32>,
}

/// Strategy (s, t) on the subpaths `light` and `camera`; None when it contributes nothing.
/// `weighted`: compute the MIS weight (pure light tracing does not need it; it may then pass
/// an empty camera subpath for t = 1).
#[allow(clippy::too_many_arguments)]
pub fn connect(
    scene: &Scene,
    cfg: &PathConfig,
    light: &[Vertex],
    camera: &[Vertex],
    s: usize,
    t: usize,
    sampler: &mut dyn Sampler,
    weighted: bool,
) -> Option<Connection> {
    if t == 0 || s > light.len() || (t > camera.len() && t != 1) || s + t < 2 || !cfg.allows(s + t) {
        return None;
    }
    if s + t == 2 && cfg.hide_emitters {
        return None;
    }
    // A camera path that escaped can only be used as a whole.
    if s > 0 && t >= 2 && camera[t - 1].kind == VertexKind::Light {
        return None;
    }
    // The vertex the strategy sampled, built only when the MIS weight reads it; its position
    // and light are reported either way.
    let mut sampled: Option<Vertex> = None;
    let mut sampled_p = glam::Vec3::ZERO;
    let mut sampled_light = None;
    let mut raster = None;
    let l = if s == 0 {
        let pt = &camera[t - 1];
        if !pt.is_light() {
            return None;
        }
        pt.beta * pt.le(scene, &camera[t - 2])
    } else if t == 1 {
        let c = camera_connection(scene, cfg, light, s, sampler)?;
        if c.shadow.is_some_and(|ray| scene.occluded_ray(&ray)) {
            return None;
        }
        raster = Some(c.raster);
        sampled_p = c.p_lens;
        if weighted {
            let mut cam = Vertex::camera(c.p_lens, c.raster, c.beta_cam);
            cam.time = light[s - 1].time;
            sampled = Some(cam);
        }
        c.l
    } else if s == 1 {
        let u_light = sampler.next_1d();
        let u = sampler.next_2d();
        let pt = &camera[t - 1];
        if !pt.connectible(scene) || scene.lights.is_empty() {
            return None;
        }
        let (li, pmf, _) = scene.light_distribution.sample_discrete(u_light);
        if pmf <= 0.0 {
            return None;
        }
        let ls = scene.lights[li].sample_li(pt.p, u, &scene.bounds)?;
        if ls.pdf <= 0.0 || ls.li.is_black() {
            return None;
        }
        let beta = ls.li / (pmf * ls.pdf);
        let mut v = if ls.infinite {
            Vertex::light_infinite(Some(li as u32), ls.p, ls.wi, beta, 0.0)
        } else {
            Vertex::light_point(li as u32, ls.p, ls.n, ls.li, beta, 0.0)
        };
        v.pdf_fwd = v.pdf_light_origin(scene, pt);
        v.time = pt.time;
        // The direction toward the light point once, for the BSDF and the cosine.
        let (w, d2) = pt.direction_to(&v);
        let f = if d2 == 0.0 { Rgb::BLACK } else { pt.f_dir(w, TransportMode::Radiance) };
        let l = pt.beta * f * v.beta * pt.abs_cos_dir(w);
        if l.is_black() {
            return None;
        }
        let blocked = if ls.infinite { scene.occluded_dir_at(pt.p, pt.ng, ls.wi, pt.time) } else { scene.occluded_between(pt.p, pt.ng, ls.p, ls.n, pt.time) };
        if blocked {
            return None;
        }
        (sampled_p, sampled_light) = (v.p, v.light);
        sampled = Some(v);
        l
    } else {
        let (qs, pt) = (&light[s - 1], &camera[t - 1]);
        if !qs.connectible(scene) || !pt.connectible(scene) {
            return None;
        }
        // Both are finite surface vertices: their directions once, for both BSDFs and G.
        let (w_qp, w_pq, d2) = Vertex::directions_between(qs, pt);
        if d2 == 0.0 || qs.bsdf.is_none() || pt.bsdf.is_none() {
            return None;
        }
        let l = qs.beta * qs.f_dir(w_qp, TransportMode::Importance) * pt.f_dir(w_pq, TransportMode::Radiance) * pt.beta;
        if l.is_black() {
            return None;
        }
        let g = geometry_term(scene, qs, pt, w_qp, w_pq, d2);
        if g == 0.0 {
            return None;
        }
        l * g
    };
    if l.is_black() || !l.is_finite() {
        return None;
    }
    let weight = if weighted { mis_weight(scene, cfg, light, camera, sampled.as_ref(), s, t) } else { 1.0 };
    Some(Connection { l, weight, raster, sampled_p, sampled_light })
}

/// Strategy t = 1 before its shadow ray: what lands on the film if the segment from the
/// light subpath's end to the lens is clear.
#[derive(Clone, Copy, Debug)]
pub struct CameraConnection {
    /// Unweighted contribution (not black; possibly not finite).
    pub l: Rgb,
    pub raster: Vec2,
    pub p_lens: glam::Vec3,
    /// The camera vertex's throughput (importance over its density).
    pub beta_cam: Rgb,
    /// The segment to test (None: it has no length and nothing can block it).
    pub shadow: Option<Ray>,
}

/// Strategy (s, 1) without its visibility test, so that light tracing can test the shadow
/// rays of several connections at once; `connect` is this and the test. Uses two sampler
/// dimensions (the lens) whenever `s` is in range.
// Inlined: BDPT's `connect` otherwise pays a call and the record's copy per t = 1 strategy.
#[inline(always)]
pub fn camera_connection<S: Sampler + ?Sized>(scene: &Scene, cfg: &PathConfig, light: &[Vertex], s: usize, sampler: &mut S) -> Option<CameraConnection> {
    if !camera_strategy_exists(cfg, light, s) {
        return None;
    }
    let u = sampler.next_2d();
    let qs = &light[s - 1];
    if !camera_connectible(scene, cfg, qs, s) {
        return None;
    }
    camera_connection_at(scene, cfg, qs, s, u)
}

/// Whether strategy (s, 1) exists for `light` (it then draws its lens sample).
#[inline(always)]
pub(crate) fn camera_strategy_exists(cfg: &PathConfig, light: &[Vertex], s: usize) -> bool {
    s >= 1 && s <= light.len() && cfg.allows(s + 1) && !(s == 1 && cfg.hide_emitters)
}

/// Whether the light subpath's vertex `qs` (its `s`-th) can be connected to the camera.
#[inline(always)]
pub(crate) fn camera_connectible(scene: &Scene, cfg: &PathConfig, qs: &Vertex, s: usize) -> bool {
    cfg.camera_connectible && qs.connectible(scene) && (s != 1 || qs.is_area_light(scene))
}

/// [`camera_connection`] after its checks, with its lens sample `u` drawn.
#[inline(always)]
pub(crate) fn camera_connection_at(scene: &Scene, cfg: &PathConfig, qs: &Vertex, s: usize, u: Vec2) -> Option<CameraConnection> {
    let cs = cfg.lens.as_ref()?.sample_lens(qs.p, u)?;
    if cs.pdf <= 0.0 || cs.we <= 0.0 {
        return None;
    }
    let beta_cam = Rgb::splat(cs.we / cs.pdf);
    // The direction toward the lens once for emission or BSDF and the cosine (what
    // `le`, `f` and `abs_cos_to` of a camera vertex there would each compute).
    let (w, d2) = qs.direction_to_point(cs.p_lens);
    let f = if d2 == 0.0 {
        Rgb::BLACK
    } else if s == 1 {
        qs.le_dir(scene, w)
    } else {
        qs.f_dir(w, TransportMode::Importance)
    };
    let l = qs.beta * f * beta_cam * qs.abs_cos_dir(w);
    // Non-finite values are left to the callers' own checks (`connect`'s, the splat's).
    if l.is_black() {
        return None;
    }
    let shadow = shadow_ray_to_lens(scene, qs.p, qs.ng, cs.p_lens, qs.time);
    Some(CameraConnection { l, raster: cs.raster, p_lens: cs.p_lens, beta_cam, shadow })
}

/// `scene.shadow_ray(p, ng, p_lens, Vec3::ZERO, time)` bit for bit: the lens end has no
/// normal, so its offset is `p_lens + 0` (which only turns -0.0 into 0.0) and the
/// magnitude its size would scale is not needed (one connection per light vertex).
#[inline]
pub(crate) fn shadow_ray_to_lens(scene: &Scene, p: glam::Vec3, ng: glam::Vec3, p_lens: glam::Vec3, time: f32) -> Option<Ray> {
    use crate::geometry::ray::{offset_ray_origin, SHADOW_EPSILON};
    if !p_lens.is_finite() {
        // (A zero normal times a non-finite magnitude is NaN there.)
        return scene.shadow_ray(p, ng, p_lens, glam::Vec3::ZERO, time);
    }
    let d = p_lens - p;
    let o = offset_ray_origin(p, ng, d);
    // `offset_ray_origin(p_lens, 0, -d)`: a dot product with zero is ±0 (taking +0) unless
    // `d` is not finite (NaN: taking -0).
    let q = if (-d).dot(glam::Vec3::ZERO) >= 0.0 { p_lens + glam::Vec3::ZERO } else { p_lens - glam::Vec3::ZERO };
    let d = q - o;
    let dist = d.length();
    if dist == 0.0 {
        return None;
    }
    let mut ray = Ray::with_max(o, d / dist, dist * (1.0 - SHADOW_EPSILON));
    ray.time = time;
    Some(ray)
}

/// Strategy (s, 1) of [`connect`] with its MIS weight, without the visibility test: the
/// weighted contribution, where it lands, and the segment that must be clear for it (None:
/// nothing can block it). `connect(.., s, 1, .., true)` is this, then the test; the same
/// sampler dimensions either way (BDPT tests these shadow rays as packets).
#[inline]
pub fn weighted_camera_connection(
    scene: &Scene,
    cfg: &PathConfig,
    light: &[Vertex],
    camera: &[Vertex],
    s: usize,
    sampler: &mut dyn Sampler,
) -> Option<(Rgb, Vec2, Option<Ray>)> {
    let c = camera_connection(scene, cfg, light, s, sampler)?;
    if c.l.is_black() || !c.l.is_finite() {
        return None;
    }
    let mut cam = Vertex::camera(c.p_lens, c.raster, c.beta_cam);
    cam.time = light[s - 1].time;
    let weight = mis_weight(scene, cfg, light, camera, Some(&cam), s, 1);
    Some((c.l * weight, c.raster, c.shadow))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Material;
    use crate::camera::{Camera, Projection};
    use crate::geometry::{Geometry, Sphere};
    use crate::light::Light;
    use crate::sampling::Pcg32;
    use crate::scene::SceneBuilder;
    use crate::texture::Texture;
    use glam::{Mat4, Vec3};

    /// `shadow_ray_to_lens` is `Scene::shadow_ray` toward a point without a normal, bit for
    /// bit: random points, signed zeros, points on the lens and non-finite ones.
    #[test]
    fn shadow_ray_to_lens_is_scene_shadow_ray() {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.5)) });
        b.add_shape(Geometry::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 4.0), radius: 1.0, flip_normals: false }), m, None, "ball").unwrap();
        b.add_light(Light::Point { position: Vec3::ZERO, intensity: Rgb::splat(1.0) });
        b.set_camera(Camera {
            to_world: Mat4::IDENTITY,
            projection: Projection::Perspective { fov_x_deg: 50.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: 8,
            height: 8,
            near_clip: 0.01,
            far_clip: 100.0,
            shutter_open: 0.0,
            shutter_close: 0.0,
        });
        let scene = b.build().unwrap();
        let bits = |r: Option<Ray>| r.map(|r| (r.o.to_array().map(f32::to_bits), r.d.to_array().map(f32::to_bits), r.t_max.to_bits(), r.time.to_bits()));
        let mut rng = Pcg32::new(7, 3);
        let mut u = || (rng.next_f32() - 0.5) * 20.0;
        let mut points: Vec<Vec3> = vec![Vec3::ZERO, Vec3::new(-0.0, 0.0, -0.0), Vec3::new(-0.0, -0.0, -0.0), Vec3::new(1.0, -0.0, 3.0)];
        points.extend([Vec3::new(f32::INFINITY, 0.0, 1.0), Vec3::new(f32::NAN, 1.0, 0.0), Vec3::new(1e30, -1e30, 2.0)]);
        points.extend((0..400).map(|_| Vec3::new(u(), u(), u())));
        let normals = [Vec3::Z, -Vec3::X, Vec3::ZERO, Vec3::new(0.6, 0.0, -0.8)];
        let mut some = 0;
        for (i, &p) in points.iter().enumerate() {
            for &p_lens in points.iter().skip(i % 5).step_by(37) {
                for ng in normals {
                    let want = scene.shadow_ray(p, ng, p_lens, Vec3::ZERO, 0.25);
                    let got = shadow_ray_to_lens(&scene, p, ng, p_lens, 0.25);
                    assert_eq!(bits(got), bits(want), "p {p} ng {ng} p_lens {p_lens}");
                    some += got.is_some() as usize;
                }
            }
        }
        assert!(some > 1000, "{some}");
    }
}
