//! The scene: shapes, materials, lights, camera and the accelerator, immutable once built.

mod builder;

pub use builder::SceneBuilder;

use crate::accel::Accel;
use crate::bsdf::Material;
use crate::camera::Camera;
use crate::film::Filter;
use crate::geometry::{Geometry, Ray, SurfaceInteraction};
use crate::light::{Light, SceneBounds};
use crate::math::Frame;
use crate::sampling::{Distribution1D, SamplerKind};
use glam::Vec3;
use std::sync::Arc;

#[derive(Clone, Debug)]
pub struct Shape {
    pub geometry: Arc<Geometry>,
    pub material: u32,
    /// Index into `Scene::lights` when the shape emits.
    pub light: Option<u32>,
    /// The scene file's id or a generated name, for messages.
    pub name: String,
}

/// Render settings a scene file carries (Mitsuba `<integrator>`, `<sampler>`, `<film>`).
/// The CLI may override each.
#[derive(Clone, Debug)]
pub struct SceneSettings {
    pub integrator: String,
    pub max_depth: i32,
    pub rr_depth: i32,
    pub spp: u32,
    pub sampler: SamplerKind,
    pub seed: u64,
    pub filter: Filter,
    pub hide_emitters: bool,
    pub light_selection: LightSelection,
}

/// How next-event estimation picks a light.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightSelection {
    /// Every light alike (Mitsuba 3's choice).
    Uniform,
    /// In proportion to emitted power.
    Power,
    /// Half power, half uniform.
    #[default]
    Mixed,
}

impl Default for SceneSettings {
    fn default() -> Self {
        SceneSettings {
            integrator: "path".into(),
            max_depth: -1,
            rr_depth: 5,
            spp: 16,
            sampler: SamplerKind::Independent,
            seed: 0,
            filter: Filter::default(),
            hide_emitters: false,
            light_selection: LightSelection::Mixed,
        }
    }
}

pub struct Scene {
    pub shapes: Vec<Shape>,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    /// Light selection by emitted power.
    pub light_distribution: Distribution1D,
    /// Indices of the infinite lights that rays escaping the scene see (constant, envmap).
    pub environment_lights: Vec<u32>,
    pub camera: Camera,
    pub accel: Accel,
    pub bounds: SceneBounds,
    pub settings: SceneSettings,
    /// Everything the loader ignored or adapted, for `svetlo info` and the log.
    pub warnings: Vec<String>,
}

impl Scene {
    /// Closest surface along the ray.
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        let hit = self.accel.intersect(ray)?;
        let shape = &self.shapes[hit.shape as usize];
        let p_ray = ray.at(hit.t);
        let (p, ng, ns, uv, dpdu) = match &*shape.geometry {
            Geometry::Mesh(m) => {
                let [p0, p1, p2] = m.vertices(hit.prim as usize);
                // Barycentric position is more accurate than o + t d far from the origin.
                let p = p0 * (1.0 - hit.b1 - hit.b2) + p1 * hit.b1 + p2 * hit.b2;
                let (ng, ns, uv, dpdu) = m.surface(hit.prim as usize, hit.b1, hit.b2);
                (p, ng, ns, uv, dpdu)
            }
            Geometry::Sphere(s) => {
                // Reproject onto the sphere to remove the error of t.
                let d = p_ray - s.center;
                let p = s.center + d * (s.radius / d.length());
                let (n, uv, dpdu) = s.surface(p);
                (p, n, n, uv, dpdu)
            }
        };
        Some(SurfaceInteraction { p, t: hit.t, ng, shading: Frame::from_normal_tangent(ns, dpdu), uv, shape: hit.shape, prim: hit.prim, wo: -ray.d })
    }

    /// Is the straight segment between two points blocked? `p0` is offset off its surface with
    /// normal `n0`; the far end stops short of `p1` so that the target surface does not count.
    pub fn occluded(&self, p0: Vec3, n0: Vec3, p1: Vec3) -> bool {
        let d = p1 - p0;
        let o = crate::geometry::ray::offset_ray_origin(p0, n0, d);
        let d = p1 - o;
        let dist = d.length();
        if dist == 0.0 {
            return false;
        }
        let ray = Ray::with_max(o, d / dist, dist * (1.0 - crate::geometry::ray::SHADOW_EPSILON));
        self.accel.occluded(&ray)
    }

    /// Is anything in the way from `p0` (normal `n0`) toward direction `w`, to infinity?
    pub fn occluded_dir(&self, p0: Vec3, n0: Vec3, w: Vec3) -> bool {
        let o = crate::geometry::ray::offset_ray_origin(p0, n0, w);
        self.accel.occluded(&Ray::new(o, w))
    }

    /// The area light of the shape hit, if it emits.
    pub fn area_light(&self, si: &SurfaceInteraction) -> Option<(u32, &crate::light::AreaLight)> {
        let li = self.shapes[si.shape as usize].light?;
        match &self.lights[li as usize] {
            Light::Area(a) => Some((li, a)),
            _ => None,
        }
    }

    pub fn material(&self, si: &SurfaceInteraction) -> &Material {
        &self.materials[self.shapes[si.shape as usize].material as usize]
    }

    /// Probability that light selection picks light `i`.
    pub fn light_pmf(&self, i: u32) -> f32 {
        self.light_distribution.pmf(i as usize)
    }
}
