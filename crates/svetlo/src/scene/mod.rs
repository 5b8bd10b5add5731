//! The scene: shapes, materials, lights, camera and the accelerator, immutable once built.

mod builder;

pub use builder::SceneBuilder;

use crate::accel::Accel;
use crate::accel::PrimHit;
use crate::bsdf::Material;
use crate::camera::Camera;
use crate::film::Filter;
use crate::geometry::{Geometry, Motion, Ray, SurfaceInteraction};
use crate::light::{Light, SceneBounds};
use crate::math::Frame;
use crate::sampling::{Distribution1D, SamplerKind};
use glam::{Mat3, Mat4, Vec2, Vec3};
use std::sync::Arc;

#[derive(Clone, Debug)]
pub struct Shape {
    pub geometry: Arc<Geometry>,
    pub material: u32,
    /// Index into `Scene::lights` when the shape emits.
    pub light: Option<u32>,
    /// The scene file's id or a generated name, for messages.
    pub name: String,
    /// Animated to_world (motion blur); `geometry` is then its pose at the first keyframe.
    pub motion: Option<Arc<Motion>>,
    /// Per triangle of a mesh, its shading when constant over it (`TriangleMesh::flat_shading`),
    /// computed once so that a hit costs no normalisation; empty for other shapes and for
    /// meshes without a flat triangle (smooth-shaded ones: a hit interpolates, as for a None).
    pub flat: Vec<Option<(Vec3, Frame)>>,
    /// Whether the material has surface detail (normal or bump map): its BSDF then needs
    /// the partial derivatives (see [`Scene::bsdf`]).
    pub detail: bool,
}

impl Shape {
    pub fn new(geometry: Arc<Geometry>, material: u32, light: Option<u32>, name: String, motion: Option<Arc<Motion>>) -> Shape {
        let flat = match &*geometry {
            Geometry::Mesh(m) => {
                // The table starts at the first flat triangle: a smooth mesh allocates none.
                let mut flat = Vec::new();
                for t in 0..m.triangle_count() {
                    let f = m.flat_shading(t);
                    if f.is_some() && flat.is_empty() {
                        flat.reserve_exact(m.triangle_count());
                        flat.resize(t, None);
                    }
                    if f.is_some() || !flat.is_empty() {
                        flat.push(f);
                    }
                }
                flat
            }
            Geometry::Sphere(_) | Geometry::SdfGrid(_) => Vec::new(),
        };
        Shape { geometry, material, light, name, motion, flat, detail: false }
    }
}

/// A shape that moves during the shutter: its own accelerator over its reference pose, into
/// which rays are carried at their time.
#[derive(Clone)]
pub struct MovingShape {
    pub shape: u32,
    pub accel: Accel,
    pub motion: Arc<Motion>,
    /// World bounds over every time (the pose is held outside the keyframes).
    pub bounds: crate::geometry::Aabb,
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
    /// Hits closer than this to a ray's origin are skipped, on every ray (0: none, the
    /// default; origins are offset off their surfaces anyway). Tungsten skips 5e-4 scene
    /// units (its `DefaultEpsilon`), which drops light piped along thin walls: comparing
    /// with its references on such scenes needs the same (`--ray-epsilon`).
    pub ray_epsilon: f32,
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
            sampler: SamplerKind::default(),
            seed: 0,
            filter: Filter::default(),
            hide_emitters: false,
            light_selection: LightSelection::Mixed,
            ray_epsilon: 0.0,
        }
    }
}

/// Clone: a render at another resolution (Python's `render(width=...)`) takes a copy.
#[derive(Clone)]
pub struct Scene {
    pub shapes: Vec<Shape>,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    /// Light selection by emitted power.
    pub light_distribution: Distribution1D,
    /// Indices of the infinite lights that rays escaping the scene see (constant, envmap).
    pub environment_lights: Vec<u32>,
    pub camera: Camera,
    /// The accelerator over the static shapes.
    pub accel: Accel,
    /// Scene shape index of each shape of `accel` when some shapes move (empty: the identity).
    pub static_shapes: Vec<u32>,
    /// Shapes with an animated transform, intersected at each ray's time.
    pub moving: Vec<MovingShape>,
    pub bounds: SceneBounds,
    pub settings: SceneSettings,
    /// Everything the loader ignored or adapted, for `svetlo info` and the log.
    pub warnings: Vec<String>,
    /// The path kernel's packet tree, kept for the next render (keyed by the meshes).
    pub(crate) packet_tree: crate::accel::GeometryCache<crate::accel::packet::PacketBvh>,
    /// The path kernel's unpacked triangles and mesh lights, kept for the next render (keyed
    /// by the shapes' and lights' geometry).
    pub(crate) kernel_geometry: crate::accel::GeometryCache<crate::integrator::path_simd::KernelGeometry>,
}

impl Scene {
    /// Closest primitive along the ray, static or moving (shape ids index `shapes`).
    pub fn intersect_prim(&self, ray: &Ray) -> Option<PrimHit> {
        self.closest(ray).map(|(h, _)| h)
    }

    /// The closest hit; for a moving shape also the ray carried into its reference pose and
    /// the transform from that pose to the world at the ray's time.
    pub(crate) fn closest(&self, ray: &Ray) -> Option<(PrimHit, Option<(Ray, Mat4)>)> {
        let (ray, skip) = self.past_epsilon(ray);
        let ray = &ray;
        let mut best = self.accel.intersect(ray).map(|mut h| {
            if !self.static_shapes.is_empty() {
                h.shape = self.static_shapes[h.shape as usize];
            }
            (h, None)
        });
        if self.moving.is_empty() && skip == 0.0 {
            return best;
        }
        let t_max = best.as_ref().map_or(ray.t_max, |(h, _)| h.t);
        if let Some((h, mv)) = self.closest_moving(ray, t_max) {
            best = Some((h, Some(mv)));
        }
        if skip > 0.0 {
            // t from the caller's origin; a moving shape's local ray starts there too.
            best = best.map(|(mut h, mv)| {
                h.t += skip;
                (h, mv.map(|(local, m)| (Ray { o: local.o - local.d * skip, t_max: local.t_max + skip, ..local }, m)))
            });
        }
        best
    }

    /// The nearest hit on a moving shape (in its pose at the ray's time) closer than `t_max`,
    /// with the ray carried into the shape's reference pose and the transform back: the part
    /// of [`Self::closest`] after the static shapes' hit (`t_max`: its distance, or the ray's).
    pub(crate) fn closest_moving(&self, ray: &Ray, mut t_max: f32) -> Option<(PrimHit, (Ray, Mat4))> {
        let mut best = None;
        let inv_d = ray.d.recip();
        for mv in &self.moving {
            if mv.bounds.intersect(ray.o, inv_d, t_max).is_none() {
                continue;
            }
            let (local, m) = Self::to_reference(mv, ray, t_max);
            if let Some(mut h) = mv.accel.intersect(&local) {
                t_max = h.t;
                h.shape = mv.shape;
                best = Some((h, (local, m)));
            }
        }
        best
    }

    /// Whether a moving shape (in its pose at the ray's time) blocks `ray`: the part of
    /// [`Self::occluded_ray`] after the static shapes.
    pub(crate) fn occluded_moving(&self, ray: &Ray) -> bool {
        let inv_d = ray.d.recip();
        self.moving.iter().any(|mv| mv.bounds.intersect(ray.o, inv_d, ray.t_max).is_some() && mv.accel.occluded(&Self::to_reference(mv, ray, ray.t_max).0))
    }

    /// `ray` with its first `settings.ray_epsilon` cut off, and that length (t of a hit on
    /// the cut ray plus it is t on `ray`: the integrators' directions are unit vectors).
    #[inline]
    fn past_epsilon(&self, ray: &Ray) -> (Ray, f32) {
        let e = self.settings.ray_epsilon;
        if e > 0.0 {
            (Ray { o: ray.at(e), t_max: ray.t_max - e, ..*ray }, e)
        } else {
            (*ray, 0.0)
        }
    }

    /// `ray` in the reference pose of a moving shape (same parameter t), and the transform back.
    #[inline]
    fn to_reference(mv: &MovingShape, ray: &Ray, t_max: f32) -> (Ray, Mat4) {
        let m = mv.motion.relative(ray.time);
        let inv = m.inverse();
        (Ray { o: inv.transform_point3(ray.o), d: inv.transform_vector3(ray.d), t_max, time: ray.time }, m)
    }

    /// Closest surface along the ray.
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        if self.moving.is_empty() && self.settings.ray_epsilon <= 0.0 {
            // Static scenes (the common case): no pose transform to carry through `closest`.
            let mut hit = self.accel.intersect(ray)?;
            if !self.static_shapes.is_empty() {
                hit.shape = self.static_shapes[hit.shape as usize];
            }
            return Some(self.interaction(&hit, ray));
        }
        let (hit, moving) = self.closest(ray)?;
        Some(self.closest_interaction(&hit, moving.as_ref(), ray))
    }

    /// The surface record of a hit of [`Self::closest`] along `ray`: on a moving shape, made
    /// in its reference pose (`moving`: the ray there and the transform back) and carried to
    /// the world at the ray's time.
    pub(crate) fn closest_interaction(&self, hit: &PrimHit, moving: Option<&(Ray, Mat4)>, ray: &Ray) -> SurfaceInteraction {
        let Some((local, m)) = moving else { return self.interaction(hit, ray) };
        let si = self.interaction(hit, local);
        let lin = Mat3::from_mat4(*m);
        let normal = lin.inverse().transpose();
        let ng = (normal * si.ng).normalize();
        let ns = (normal * si.shading.n).normalize();
        let shading = Frame::from_normal_tangent(ns, lin * si.shading.s);
        SurfaceInteraction { p: m.transform_point3(si.p), ng, shading, wo: -ray.d, ..si }
    }

    /// The surface record of a primitive hit by `ray` (in the space the primitive is stored in).
    pub(crate) fn interaction(&self, hit: &PrimHit, ray: &Ray) -> SurfaceInteraction {
        self.interaction_with::<true>(hit, ray)
    }

    /// [`Self::interaction`] with the uv left zero, for a caller whose material and emission
    /// there read none: the rest bit for bit. (A sphere's uv is an atan2 and an acos.)
    pub(crate) fn interaction_without_uv(&self, hit: &PrimHit, ray: &Ray) -> SurfaceInteraction {
        self.interaction_with::<false>(hit, ray)
    }

    #[inline(always)]
    fn interaction_with<const UV: bool>(&self, hit: &PrimHit, ray: &Ray) -> SurfaceInteraction {
        let shape = &self.shapes[hit.shape as usize];
        let p_ray = ray.at(hit.t);
        let (p, ng, ns, uv, dpdu) = match &*shape.geometry {
            Geometry::Mesh(m) => {
                let [p0, p1, p2] = m.vertices(hit.prim as usize);
                // Barycentric position is more accurate than o + t d far from the origin.
                let p = p0 * (1.0 - hit.b1 - hit.b2) + p1 * hit.b1 + p2 * hit.b2;
                if let Some(Some((ng, shading))) = shape.flat.get(hit.prim as usize) {
                    let uv = if UV { m.uv(hit.prim as usize, hit.b1, hit.b2) } else { Vec2::ZERO };
                    let bary = Vec2::new(hit.b1, hit.b2);
                    return SurfaceInteraction {
                        p,
                        t: hit.t,
                        ng: *ng,
                        shading: *shading,
                        uv,
                        shape: hit.shape,
                        prim: hit.prim,
                        bary,
                        wo: -ray.d,
                        time: ray.time,
                    };
                }
                let (ng, ns, uv, dpdu) = m.surface(hit.prim as usize, hit.b1, hit.b2);
                (p, ng, ns, uv, dpdu)
            }
            Geometry::Sphere(s) => {
                // Reproject onto the sphere to remove the error of t.
                let d = p_ray - s.center;
                let p = s.center + d * (s.radius / d.length());
                let (n, uv, dpdu) = if UV {
                    s.surface(p)
                } else {
                    let (n, dpdu) = s.normal_and_dpdu(p);
                    (n, Vec2::ZERO, dpdu)
                };
                (p, n, n, uv, dpdu)
            }
            // As in Mitsuba: the point along the ray (not reprojected), no uvs.
            Geometry::SdfGrid(g) => {
                let (ng, ns) = g.normals_at(hit.prim as usize, p_ray);
                (p_ray, ng, ns, Vec2::ZERO, Vec3::ZERO)
            }
        };
        let bary = if matches!(&*shape.geometry, Geometry::Mesh(_)) { Vec2::new(hit.b1, hit.b2) } else { Vec2::ZERO };
        SurfaceInteraction {
            p,
            t: hit.t,
            ng,
            shading: Frame::from_normal_tangent(ns, dpdu),
            uv: if UV { uv } else { Vec2::ZERO },
            shape: hit.shape,
            prim: hit.prim,
            bary,
            wo: -ray.d,
            time: ray.time,
        }
    }

    /// Is anything in the way along `ray` up to its `t_max` (static or, at the ray's time,
    /// moving)? The test of every `occluded_*`, and of a ray of [`Self::shadow_ray`].
    pub fn occluded_ray(&self, ray: &Ray) -> bool {
        if self.moving.is_empty() && self.settings.ray_epsilon <= 0.0 {
            // Static scenes, as in `intersect`: no cut ray to copy, no moving shapes to try.
            if ray.t_max <= 0.0 {
                return false;
            }
            return self.accel.occluded(ray);
        }
        let (ray, _) = self.past_epsilon(ray);
        let ray = &ray;
        if ray.t_max <= 0.0 {
            return false;
        }
        self.accel.occluded(ray) || self.occluded_moving(ray)
    }

    /// Is the straight segment between two points blocked at time 0 (see [`Self::occluded_at`])?
    pub fn occluded(&self, p0: Vec3, n0: Vec3, p1: Vec3) -> bool {
        self.occluded_at(p0, n0, p1, 0.0)
    }

    /// Is the straight segment between two points blocked at `time`? `p0` is offset off its
    /// surface with normal `n0`; the far end stops short of `p1` so that the target surface
    /// does not count. For a target on a surface use [`Self::occluded_between`].
    pub fn occluded_at(&self, p0: Vec3, n0: Vec3, p1: Vec3, time: f32) -> bool {
        self.occluded_between(p0, n0, p1, Vec3::ZERO, time)
    }

    /// Is the segment between two surface points blocked at `time`? Both ends are offset off
    /// their surfaces (normals `n0`, `n1`; a zero normal leaves that end where it is) and the
    /// far end also stops short. Stopping short alone fails on grazing segments, such as a
    /// short chord inside a concave emitter: the target surface's hit is then uncertain by
    /// its rounding over the cosine, more than the margin, and inside an emitting sphere about
    /// one light sample in 70 000 was lost.
    pub fn occluded_between(&self, p0: Vec3, n0: Vec3, p1: Vec3, n1: Vec3, time: f32) -> bool {
        self.shadow_ray(p0, n0, p1, n1, time).is_some_and(|ray| self.occluded_ray(&ray))
    }

    /// The ray [`Self::occluded_between`] tests (None: the offset ends coincide and nothing
    /// can block), for callers that test several at once.
    #[inline]
    pub fn shadow_ray(&self, p0: Vec3, n0: Vec3, p1: Vec3, n1: Vec3, time: f32) -> Option<Ray> {
        let d = p1 - p0;
        let o = crate::geometry::ray::offset_ray_origin(p0, n0, d);
        let q = crate::geometry::ray::offset_ray_origin(p1, n1, -d);
        let d = q - o;
        let dist = d.length();
        if dist == 0.0 {
            return None;
        }
        let mut ray = Ray::with_max(o, d / dist, dist * (1.0 - crate::geometry::ray::SHADOW_EPSILON));
        ray.time = time;
        Some(ray)
    }

    /// Is anything in the way from `p0` (normal `n0`) toward direction `w`, to infinity, at time 0?
    pub fn occluded_dir(&self, p0: Vec3, n0: Vec3, w: Vec3) -> bool {
        self.occluded_dir_at(p0, n0, w, 0.0)
    }

    /// Is anything in the way from `p0` (normal `n0`) toward direction `w`, to infinity, at `time`?
    pub fn occluded_dir_at(&self, p0: Vec3, n0: Vec3, w: Vec3, time: f32) -> bool {
        self.occluded_ray(&self.dir_ray_at(p0, n0, w, time))
    }

    /// The ray [`Self::occluded_dir_at`] tests, for callers that test several at once.
    #[inline]
    pub fn dir_ray_at(&self, p0: Vec3, n0: Vec3, w: Vec3, time: f32) -> Ray {
        let o = crate::geometry::ray::offset_ray_origin(p0, n0, w);
        let mut ray = Ray::new(o, w);
        ray.time = time;
        ray
    }

    /// The BSDF at a hit: its material's, textures looked up at the point, with the
    /// perturbed frame of a normal or bump map.
    #[inline]
    pub fn bsdf(&self, si: &SurfaceInteraction) -> crate::bsdf::Bsdf {
        let m = self.material(si);
        if !self.shapes[si.shape as usize].detail {
            return m.bsdf(si.tex_point());
        }
        self.bsdf_with_detail(m, si)
    }

    /// [`Self::bsdf`] where the shape's material has surface detail (out of line: the
    /// common case stays small at its callers).
    #[inline(never)]
    fn bsdf_with_detail(&self, m: &Material, si: &SurfaceInteraction) -> crate::bsdf::Bsdf {
        let (dpdu, dpdv) = self.dp_duv(si);
        m.bsdf_with_detail(si.tex_point(), &crate::bsdf::material::ShadingGeometry { shading: si.shading, ng: si.ng, dpdu, dpdv })
    }

    /// (dp/du, dp/dv) at a hit, world space (a moving shape's in its reference pose).
    fn dp_duv(&self, si: &SurfaceInteraction) -> (Vec3, Vec3) {
        self.dp_duv_at(si.shape, si.prim, si.p, &si.shading)
    }

    /// [`Self::dp_duv`] of a hit on triangle `prim` of `shape` (its local index) at `p`, shading frame `shading`.
    #[inline]
    pub(crate) fn dp_duv_at(&self, shape: u32, prim: u32, p: Vec3, shading: &Frame) -> (Vec3, Vec3) {
        match &*self.shapes[shape as usize].geometry {
            Geometry::Mesh(m) => m.dp_duv(prim as usize),
            Geometry::Sphere(s) => s.dp_duv(p),
            // No uv parameterisation: the shading frame's axes stand in.
            Geometry::SdfGrid(_) => (shading.s, shading.t),
        }
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

    /// Choose lights for next-event estimation (and light tracing's emission) by `how` from
    /// now on.
    pub fn set_light_selection(&mut self, how: LightSelection) {
        self.settings.light_selection = how;
        self.light_distribution = builder::light_selection_distribution(&self.lights, &self.bounds, how);
    }

    /// Probability that light selection picks light `i`.
    pub fn light_pmf(&self, i: u32) -> f32 {
        self.light_distribution.pmf(i as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::TriangleMesh;

    /// A shape's table of flat triangles says for every triangle what `flat_shading` says
    /// (absent entries as None), and a smooth mesh keeps no table.
    #[test]
    fn flat_table_is_flat_shading() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.2), Vec3::new(0.0, 2.0, 0.5)];
        let indices = vec![[0, 1, 2], [1, 3, 2], [2, 3, 4], [0, 2, 4]];
        let n = Vec3::Z;
        let tilted = Vec3::new(0.1, 0.0, 1.0).normalize();
        for normals in [
            vec![],
            vec![n; 5],
            vec![n, tilted, n, n, n],
            vec![n, n, n, tilted, tilted],
            vec![tilted, n, n, n, n],
            (0..5).map(|i| Vec3::new(0.1 * i as f32, 0.0, 1.0).normalize()).collect(),
        ] {
            let m = TriangleMesh { positions: positions.clone(), normals: normals.clone(), uvs: vec![], indices: indices.clone() };
            let shape = Shape::new(Arc::new(Geometry::Mesh(m.clone())), 0, None, "m".into(), None);
            let any_flat = (0..4).any(|t| m.flat_shading(t).is_some());
            assert_eq!(shape.flat.is_empty(), !any_flat, "{normals:?}");
            for t in 0..4 {
                let (got, want) = (shape.flat.get(t).copied().flatten(), m.flat_shading(t));
                assert_eq!(format!("{got:?}"), format!("{want:?}"), "triangle {t}, normals {normals:?}");
            }
        }
    }
}
