//! The classic local illumination model shared by `whitted` and `zbuffer`: every light acts
//! as a point (or direction). Point, spot and directional lights are themselves; an area
//! light is replaced by one point: the area-weighted centroid of a mesh emitter, radiating
//! the intensity I(w) = L Σ_t max(0, A_t n_t · w) of its triangles (exact in the far field,
//! and for a planar emitter L A cos θ), or for a sphere the point nearest the shaded point
//! with intensity L π r². Environment lights have no position: they are seen as background
//! only. Light path class L(D|G)E at each shaded point, no indirect light.

use crate::bsdf::{Bsdf, TransportMode};
use crate::geometry::Geometry;
use crate::light::Light;
use crate::math::Frame;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// An area light reduced to a point.
#[derive(Clone, Debug)]
enum AreaProxy {
    Mesh { centre: Vec3, radiance: Rgb, vector_areas: Vec<Vec3> },
    Sphere { centre: Vec3, radius: f32, radiance: Rgb },
}

/// One light as the local model sees it from a point.
#[derive(Clone, Copy, Debug)]
pub struct PointLightSample {
    /// Unit direction toward the light.
    pub wi: Vec3,
    /// Irradiance-producing radiance term: intensity / r² (or irradiance for directional lights).
    pub li: Rgb,
    /// Where the light is (for shadow rays and shadow maps); `None` for directions.
    pub p: Option<Vec3>,
}

/// The lights of a scene as points, precomputed once per render.
#[derive(Clone, Debug)]
pub struct LocalLights {
    areas: Vec<Option<AreaProxy>>,
    /// The common lights in a form [`LocalLights::sample`] evaluates without dispatch.
    quick: Vec<Quick>,
}

/// A point light or a planar mesh emitter's proxy (one vector area), copied out of the
/// scene so that sampling it is a few products; `Other` goes the general way.
#[derive(Clone, Copy, Debug)]
enum Quick {
    Point { position: Vec3, intensity: Rgb },
    Planar { centre: Vec3, radiance: Rgb, vector_area: Vec3 },
    Other,
}

impl LocalLights {
    pub fn new(scene: &Scene) -> Self {
        let areas: Vec<Option<AreaProxy>> = scene
            .lights
            .iter()
            .map(|l| match l {
                Light::Area(a) => Some(match &*a.geometry {
                    Geometry::SdfGrid(_) => return None,
                    Geometry::Sphere(s) => AreaProxy::Sphere { centre: s.center, radius: s.radius, radiance: a.radiance.mean() },
                    Geometry::Mesh(m) => {
                        let mut centre = Vec3::ZERO;
                        let mut total = 0.0;
                        let mut vector_areas = Vec::with_capacity(m.triangle_count());
                        for t in 0..m.triangle_count() {
                            let [p0, p1, p2] = m.vertices(t);
                            let va = 0.5 * (p1 - p0).cross(p2 - p0);
                            let area = va.length();
                            centre += (p0 + p1 + p2) / 3.0 * area;
                            total += area;
                            vector_areas.push(va);
                        }
                        // A planar emitter needs one vector area, not one per triangle.
                        let sum: Vec3 = vector_areas.iter().copied().sum();
                        if (sum.length() - total).abs() <= 1e-4 * total {
                            vector_areas = vec![sum];
                        }
                        AreaProxy::Mesh { centre: if total > 0.0 { centre / total } else { centre }, radiance: a.radiance.mean(), vector_areas }
                    }
                }),
                _ => None,
            })
            .collect();
        let quick = scene
            .lights
            .iter()
            .zip(&areas)
            .map(|(l, a)| match (l, a) {
                (Light::Point { position, intensity }, _) => Quick::Point { position: *position, intensity: *intensity },
                (_, Some(AreaProxy::Mesh { centre, radiance, vector_areas })) if vector_areas.len() == 1 => {
                    Quick::Planar { centre: *centre, radiance: *radiance, vector_area: vector_areas[0] }
                }
                _ => Quick::Other,
            })
            .collect();
        LocalLights { areas, quick }
    }

    /// Light `i` seen from `p` as a point or a direction; `None` when it sends nothing toward
    /// `p` (or has no position, as environment lights).
    #[inline(always)]
    pub fn sample(&self, scene: &Scene, i: usize, p: Vec3) -> Option<PointLightSample> {
        // The same arithmetic as `Light::sample_li` and the mesh proxy below, in order.
        match self.quick[i] {
            Quick::Point { position, intensity } => {
                let d = position - p;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                Some(PointLightSample { wi: d / dist2.sqrt(), li: intensity / dist2, p: Some(position) })
            }
            Quick::Planar { centre, radiance, vector_area } => {
                let d = centre - p;
                let r2 = d.length_squared();
                if r2 <= 0.0 {
                    return None;
                }
                let wi = d / r2.sqrt();
                let projected = vector_area.dot(-wi).max(0.0);
                if projected <= 0.0 {
                    return None;
                }
                Some(PointLightSample { wi, li: radiance * (projected / r2), p: Some(centre) })
            }
            Quick::Other => self.sample_general(scene, i, p),
        }
    }

    #[inline(never)]
    fn sample_general(&self, scene: &Scene, i: usize, p: Vec3) -> Option<PointLightSample> {
        let light = &scene.lights[i];
        match light {
            Light::Point { .. } | Light::Spot { .. } | Light::Luminaire(_) | Light::Projector(_) | Light::Goniometric(_) => {
                let ls = light.sample_li(p, Vec2::splat(0.5), &scene.bounds)?;
                Some(PointLightSample { wi: ls.wi, li: ls.li, p: Some(ls.p) })
            }
            Light::Directional { .. } => {
                let ls = light.sample_li(p, Vec2::splat(0.5), &scene.bounds)?;
                Some(PointLightSample { wi: ls.wi, li: ls.li, p: None })
            }
            Light::Area(_) => match self.areas[i].as_ref()? {
                AreaProxy::Mesh { centre, radiance, vector_areas } => {
                    let d = *centre - p;
                    let r2 = d.length_squared();
                    if r2 <= 0.0 {
                        return None;
                    }
                    let wi = d / r2.sqrt();
                    let projected: f32 = vector_areas.iter().map(|va| va.dot(-wi).max(0.0)).sum();
                    if projected <= 0.0 {
                        return None;
                    }
                    Some(PointLightSample { wi, li: *radiance * (projected / r2), p: Some(*centre) })
                }
                AreaProxy::Sphere { centre, radius, radiance } => {
                    let d = *centre - p;
                    let dist = d.length();
                    if dist <= *radius {
                        return None;
                    }
                    let wi = d / dist;
                    let target = *centre - wi * *radius;
                    Some(PointLightSample { wi, li: *radiance * (crate::math::PI * radius * radius / (dist * dist)), p: Some(target) })
                }
            },
            Light::Constant { .. } | Light::EnvMap(_) => None,
        }
    }

    /// Σ over lights of f(wo, wi) L |cos θi|, with a shadow ray to each light when `shadows`
    /// (seeing the scene at `time`).
    /// `wo` is in the shading frame `frame`; `p`, `ng` in world space.
    #[allow(clippy::too_many_arguments)]
    pub fn shade(&self, scene: &Scene, p: Vec3, ng: Vec3, frame: &Frame, wo: Vec3, bsdf: &Bsdf, shadows: bool, time: f32) -> Rgb {
        let mut l = Rgb::BLACK;
        self.shade_each(scene, p, ng, frame, wo, bsdf, shadows, time, |_, c, _| l += c);
        l
    }

    /// [`Self::shade`] light by light: `each(light, contribution, transmission)`, where
    /// `transmission` says the light lies behind the surface (for the path's events).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn shade_each(
        &self,
        scene: &Scene,
        p: Vec3,
        ng: Vec3,
        frame: &Frame,
        wo: Vec3,
        bsdf: &Bsdf,
        shadows: bool,
        time: f32,
        mut each: impl FnMut(usize, Rgb, bool),
    ) {
        for i in 0..scene.lights.len() {
            let Some(s) = self.sample(scene, i, p) else { continue };
            let wi = frame.to_local(s.wi);
            let f = bsdf.eval(wo, wi, TransportMode::Radiance);
            if f.is_black() {
                continue;
            }
            if shadows {
                let blocked = match s.p {
                    Some(q) => scene.occluded_at(p, ng, q, time),
                    None => scene.occluded_dir_at(p, ng, s.wi, time),
                };
                if blocked {
                    continue;
                }
            }
            each(i, f * s.li * wi.z.abs(), wi.z * wo.z < 0.0);
        }
    }
}
