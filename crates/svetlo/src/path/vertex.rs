//! One vertex of a path, and the densities and throughputs between two vertices.

use crate::bsdf::diffuse::Diffuse;
use crate::bsdf::{Bsdf, BsdfModel, BsdfSample, LobeFlags, Material, TransportMode};
use crate::camera::LensConnector;
use crate::geometry::SurfaceInteraction;
use crate::light::Light;
use crate::math::{warp, Frame, INV_PI, PI};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::mem::MaybeUninit;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexKind {
    /// The lens (or pinhole).
    Camera,
    /// A light's endpoint: a point on an emitter, a point or spot light, or a direction at
    /// infinity (environment, directional, or a camera ray that escaped the scene).
    Light,
    /// A surface the walk scattered on (it may also emit: a camera path that hit an emitter).
    Surface,
}

/// What happened at a vertex, for light path expressions: E camera, L light, D diffuse,
/// G glossy, S specular, N null (a mask let the path through), each a reflection or a
/// transmission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventKind {
    Camera,
    Light,
    Diffuse,
    Glossy,
    Specular,
    Null,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Event {
    pub kind: EventKind,
    pub transmission: bool,
}

impl Event {
    pub const CAMERA: Event = Event { kind: EventKind::Camera, transmission: false };
    pub const LIGHT: Event = Event { kind: EventKind::Light, transmission: false };

    /// The event of a sampled lobe.
    pub fn from_lobe(l: LobeFlags) -> Event {
        let kind = if l.is_null() {
            EventKind::Null
        } else if l.contains(LobeFlags::SPECULAR) {
            EventKind::Specular
        } else if l.contains(LobeFlags::GLOSSY) {
            EventKind::Glossy
        } else {
            EventKind::Diffuse
        };
        Event { kind, transmission: l.contains(LobeFlags::TRANSMISSION) }
    }

    /// The event of a connection through a BSDF: its non-specular part, glossy if it has one.
    pub fn connection(flags: LobeFlags, transmission: bool) -> Event {
        let kind = if flags.contains(LobeFlags::GLOSSY) { EventKind::Glossy } else { EventKind::Diffuse };
        Event { kind, transmission }
    }

    /// One letter: E, L, D, G, S or N.
    pub fn symbol(self) -> char {
        match self.kind {
            EventKind::Camera => 'E',
            EventKind::Light => 'L',
            EventKind::Diffuse => 'D',
            EventKind::Glossy => 'G',
            EventKind::Specular => 'S',
            EventKind::Null => 'N',
        }
    }
}

#[derive(Clone, Debug)]
pub struct Vertex {
    pub kind: VertexKind,
    pub p: Vec3,
    /// Geometric normal; zero where the vertex is not on a surface (camera, point lights,
    /// directions at infinity): densities convert to it without a cosine.
    pub ng: Vec3,
    /// Shading frame (surfaces; the geometric one for area-light endpoints).
    pub shading: Frame,
    pub uv: Vec2,
    /// Surfaces: unit direction toward the previous vertex of the walk. Vertices at
    /// infinity: the unit direction from the scene toward the light.
    pub wo: Vec3,
    pub bsdf: Option<Bsdf>,
    /// The BSDF's lobes (`bsdf.flags()`, NONE without one), looked up once per vertex:
    /// connections and path events ask for them per strategy.
    pub lobes: LobeFlags,
    /// The light of a light endpoint, or the emitter of a surface; None for a camera ray
    /// that escaped (all environment lights together).
    pub light: Option<u32>,
    /// Light endpoints sampled from the light: radiance (area) or intensity (point, spot)
    /// at the origin.
    pub le: Rgb,
    pub infinite: bool,
    pub beta: Rgb,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    pub delta: bool,
    pub event: Event,
    /// Surfaces: the scene shape (for light path expressions' labels).
    pub shape: u32,
    /// Camera vertices: where on the film.
    pub raster: Vec2,
    /// The path's time in the shutter interval (the camera ray's): connections test
    /// visibility against moving shapes at this time.
    pub time: f32,
}

#[inline]
fn remap_nan(x: f32) -> f32 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

/// The factor that makes scattering with shading normals adjoint (Veach §5.3): in
/// importance transport f(wo, wi) |wi·ns| must become f |wo·ns| |wi·ng| / |wo·ng|.
#[inline]
pub(crate) fn shading_correction(ng: Vec3, ns: Vec3, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
    if mode == TransportMode::Radiance {
        return 1.0;
    }
    let num = wo.dot(ns).abs() * wi.dot(ng).abs();
    let den = wo.dot(ng).abs() * wi.dot(ns).abs();
    if den == 0.0 {
        0.0
    } else {
        num / den
    }
}

/// `bsdf.eval(to_local(wo), to_local(wi), mode)` in the shading frame of normal `n`, bit
/// for bit, where the BSDF is Lambertian on both sides (diffuse front, diffuse or no back,
/// no surface detail): its value reads only the two local z components (`to_local`'s
/// `dot(n)`), so the frame's other four dot products and the model dispatch are skipped
/// (light tracing evaluates a BSDF per camera connection). None for other BSDFs.
#[inline]
pub(crate) fn lambertian_eval(bsdf: &Bsdf, n: Vec3, wo: Vec3, wi: Vec3, mode: TransportMode) -> Option<Rgb> {
    let BsdfModel::Diffuse(front) = &bsdf.front else { return None };
    if bsdf.detail.is_some() {
        return None;
    }
    let (zo, zi) = (wo.dot(n), wi.dot(n));
    // `Bsdf::side`: the front from above (a diffuse front does not handle its back side),
    // the back with both directions mirrored, or black (not scaled by the opacity).
    let z = |z: f32| Vec3::new(0.0, 0.0, z);
    let f = if zo >= 0.0 {
        front.eval(z(zo), z(zi), mode)
    } else {
        match &bsdf.back {
            None => return Some(Rgb::BLACK),
            Some(BsdfModel::Diffuse(back)) => back.eval(z(-zo), z(-zi), mode),
            Some(_) => return None,
        }
    };
    Some(f * bsdf.opacity)
}

/// `Bsdf::pdf(a, b, mode)` of a Lambertian BSDF (as in [`lambertian_eval`]) from the local
/// z components alone, bit for bit: the diffuse density reads nothing else. None where the
/// back side is asked for and is not diffuse.
#[inline]
fn lambertian_pdf(bsdf: &Bsdf, za: f32, zb: f32) -> Option<f32> {
    let cos_pdf = |za: f32, zb: f32| if za <= 0.0 || zb <= 0.0 { 0.0 } else { warp::square_to_cosine_hemisphere_pdf(Vec3::new(0.0, 0.0, zb)) };
    if za >= 0.0 {
        return Some(cos_pdf(za, zb) * bsdf.opacity);
    }
    match &bsdf.back {
        None => Some(0.0),
        Some(BsdfModel::Diffuse(_)) => Some(cos_pdf(-za, -zb) * bsdf.opacity),
        Some(_) => None,
    }
}

/// `bsdf.pdf(a, b, mode)` from the local z components `za`, `zb` alone (`to_local`'s
/// `dot(n)`), bit for bit, for a Lambertian BSDF (as in [`lambertian_eval`]): BDPT's MIS
/// weight asks two or four per connection. None for other BSDFs.
#[inline]
fn lambertian_pdf_of(bsdf: &Bsdf, za: f32, zb: f32) -> Option<f32> {
    if !matches!(bsdf.front, BsdfModel::Diffuse(_)) || bsdf.detail.is_some() {
        return None;
    }
    lambertian_pdf(bsdf, za, zb)
}

/// `bsdf.sample(to_local(wo), uc, u, mode)` in `frame` and the reverse density
/// `bsdf.pdf(s.wi, to_local(wo), ..)`, bit for bit and with the same draws, for a Lambertian
/// BSDF (as in [`lambertian_eval`]; a mask's pass-through excepted): only the local z of
/// `wo` is read, and no model dispatch. The walk samples one per light-path vertex.
/// None: not such a BSDF (use the generic route); Some(None): the sample fails.
#[inline]
pub(crate) fn lambertian_sample(bsdf: &Bsdf, frame: &Frame, wo: Vec3, uc: f32, u: Vec2) -> Option<Option<(BsdfSample, f32)>> {
    let BsdfModel::Diffuse(front) = &bsdf.front else { return None };
    if bsdf.detail.is_some() || (bsdf.opacity < 1.0 && uc >= bsdf.opacity) {
        return None;
    }
    let zo = wo.dot(frame.n);
    // `Bsdf::side`, then `Diffuse::sample` on that side with wo mirrored to +z.
    let (model, flipped) = if zo >= 0.0 {
        (front, false)
    } else {
        match &bsdf.back {
            None => return Some(None),
            Some(BsdfModel::Diffuse(back)) => (back, true),
            Some(_) => return None,
        }
    };
    let zm = if flipped { -zo } else { zo };
    if zm <= 0.0 {
        return Some(None);
    }
    let mut wi = warp::square_to_cosine_hemisphere(u);
    let pdf = warp::square_to_cosine_hemisphere_pdf(wi);
    if pdf <= 0.0 {
        return Some(None);
    }
    if flipped {
        wi.z = -wi.z;
    }
    let pdf_rev = lambertian_pdf(bsdf, wi.z, zo)?;
    let s = BsdfSample { wi, f: model.reflectance * INV_PI * bsdf.opacity, pdf: pdf * bsdf.opacity, lobe: LobeFlags::DIFFUSE_REFLECTION, eta: 1.0 };
    Some(Some((s, pdf_rev)))
}

impl Vertex {
    fn blank(kind: VertexKind) -> Self {
        Vertex {
            kind,
            p: Vec3::ZERO,
            ng: Vec3::ZERO,
            shading: Frame::from_normal(Vec3::Z),
            uv: Vec2::ZERO,
            wo: Vec3::ZERO,
            bsdf: None,
            lobes: LobeFlags::NONE,
            light: None,
            le: Rgb::BLACK,
            infinite: false,
            beta: Rgb::BLACK,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            delta: false,
            event: if kind == VertexKind::Camera { Event::CAMERA } else { Event::LIGHT },
            shape: 0,
            raster: Vec2::ZERO,
            time: 0.0,
        }
    }

    /// The camera at lens point `p` (world), seeing raster position `raster`.
    pub fn camera(p: Vec3, raster: Vec2, beta: Rgb) -> Self {
        Vertex { p, raster, beta, ..Self::blank(VertexKind::Camera) }
    }

    /// A light endpoint at `p` (normal `n`, zero for point lights) of light `light`.
    pub fn light_point(light: u32, p: Vec3, n: Vec3, le: Rgb, beta: Rgb, pdf_fwd: f32) -> Self {
        let shading = if n == Vec3::ZERO { Frame::from_normal(Vec3::Z) } else { Frame::from_normal(n) };
        Vertex { p, ng: n, shading, light: Some(light), le, beta, pdf_fwd, ..Self::blank(VertexKind::Light) }
    }

    /// A light endpoint at infinity: light arrives from direction `toward_light`.
    pub fn light_infinite(light: Option<u32>, p: Vec3, toward_light: Vec3, beta: Rgb, pdf_fwd: f32) -> Self {
        Vertex { p, wo: toward_light, light, infinite: true, beta, pdf_fwd, ..Self::blank(VertexKind::Light) }
    }

    /// A surface hit with its BSDF; `pdf_fwd` is set by the walk.
    pub fn surface(scene: &Scene, si: &SurfaceInteraction, beta: Rgb) -> Self {
        Self::at_surface(si, scene.bsdf(si), scene.area_light(si).map(|(i, _)| i), beta, 0.0)
    }

    /// The surface vertex at `si` with its BSDF and area light (of [`Self::surface`] and
    /// [`Self::write_surface`]).
    #[inline(always)]
    fn at_surface(si: &SurfaceInteraction, bsdf: Bsdf, light: Option<u32>, beta: Rgb, pdf_fwd: f32) -> Self {
        let lobes = bsdf.flags();
        Vertex {
            p: si.p,
            ng: si.ng,
            shading: si.shading,
            uv: si.uv,
            wo: si.wo,
            bsdf: Some(bsdf),
            lobes,
            light,
            beta,
            pdf_fwd,
            time: si.time,
            shape: si.shape,
            ..Self::blank(VertexKind::Surface)
        }
    }

    /// `path.push(Vertex { pdf_fwd, ..Vertex::surface(scene, si, beta) })`, the vertex
    /// written where it lands: pushed by value it went through two stack copies (a vertex
    /// with its BSDF is a few hundred bytes; the walk pushes one per bounce).
    #[inline]
    pub(crate) fn push_surface(path: &mut Vec<Vertex>, scene: &Scene, si: &SurfaceInteraction, beta: Rgb, pdf_fwd: f32) {
        push_written(path, |dst| Self::write_surface(dst, scene, si, beta, pdf_fwd));
    }

    /// [`Self::surface`] into `dst`. Not inlined: a destination that nothing else can
    /// reach is what lets the compiler build the vertex in it rather than copy it there.
    /// A plain diffuse material's BSDF (`Scene::bsdf`'s, the same value) is built here too:
    /// returned by `Scene::bsdf` it was copied in whole, though only its model's colour and
    /// tags are set.
    #[inline(never)]
    fn write_surface<'a>(dst: &'a mut MaybeUninit<Vertex>, scene: &Scene, si: &SurfaceInteraction, beta: Rgb, pdf_fwd: f32) -> &'a mut Vertex {
        let light = scene.area_light(si).map(|(i, _)| i);
        let vertex = |bsdf: Bsdf| Self::at_surface(si, bsdf, light, beta, pdf_fwd);
        match scene.material(si) {
            Material::Diffuse { reflectance } if !scene.shapes[si.shape as usize].detail => {
                // A constant without the texture point: its copy read the hit record back in
                // wider words than they were just stored with (a store-forwarding stall a hit).
                let reflectance = match reflectance {
                    crate::texture::Texture::Constant(c) => *c,
                    t => t.eval(si.tex_point()),
                }
                .clamp(0.0, 1.0);
                dst.write(vertex(Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance }))))
            }
            _ => dst.write(vertex(scene.bsdf(si))),
        }
    }

    /// [`Self::write_surface`] at a surface known to be constant diffuse without surface
    /// detail, of (clamped) `reflectance` and area `light` (`ShadowPackets::diffuse`), without
    /// looking up the shape, its material and its light. The BSDF is written black and its
    /// reflectance set after: built whole, its model went through the stack in 8-byte words
    /// across its 4-byte fields, a store-forwarding stall.
    #[inline(always)]
    pub(crate) fn write_diffuse_surface<'a>(
        dst: &'a mut MaybeUninit<Vertex>,
        si: &SurfaceInteraction,
        reflectance: Rgb,
        light: Option<u32>,
        beta: Rgb,
        pdf_fwd: f32,
    ) -> &'a mut Vertex {
        let v = dst.write(Self::at_surface(si, Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: Rgb::BLACK })), light, beta, pdf_fwd));
        if let Some(Bsdf { front: BsdfModel::Diffuse(d), .. }) = &mut v.bsdf {
            d.reflectance = reflectance;
        }
        v
    }

    /// `path.push(Vertex::light_point(..))`, written where it lands (as
    /// [`Self::push_surface`]; a light subpath starts with one).
    #[inline]
    pub(crate) fn push_light_point(path: &mut Vec<Vertex>, light: u32, p: Vec3, n: Vec3, le: Rgb, beta: Rgb, pdf_fwd: f32) {
        push_written(path, |dst| Self::write_light_point(dst, light, p, n, le, beta, pdf_fwd));
    }

    #[inline(never)]
    fn write_light_point(dst: &mut MaybeUninit<Vertex>, light: u32, p: Vec3, n: Vec3, le: Rgb, beta: Rgb, pdf_fwd: f32) -> &mut Vertex {
        dst.write(Self::light_point(light, p, n, le, beta, pdf_fwd))
    }

    #[inline]
    pub fn on_surface(&self) -> bool {
        self.ng != Vec3::ZERO
    }

    /// Whether light leaves this vertex by emission (a light endpoint or an emitting surface).
    pub fn is_light(&self) -> bool {
        self.kind == VertexKind::Light || (self.kind == VertexKind::Surface && self.light.is_some())
    }

    /// A light whose position or direction is a delta: no strategy can hit it.
    pub fn is_delta_light(&self, scene: &Scene) -> bool {
        self.kind == VertexKind::Light && self.light.is_some_and(|i| scene.lights[i as usize].is_delta())
    }

    /// An emitting area (a surface that a camera path can hit, and that can be connected to
    /// the camera directly).
    pub fn is_area_light(&self, scene: &Scene) -> bool {
        !self.infinite && self.light.is_some_and(|i| matches!(scene.lights[i as usize], Light::Area(_)))
    }

    /// Whether a deterministic connection can end here.
    pub fn connectible(&self, scene: &Scene) -> bool {
        match self.kind {
            VertexKind::Camera => true,
            VertexKind::Light => !self.light.is_some_and(|i| matches!(scene.lights[i as usize], Light::Directional { .. })),
            VertexKind::Surface => self.lobes.has_non_specular(),
        }
    }

    /// Unit direction from this vertex to `other` and the squared distance (1 for a vertex at
    /// infinity, whose densities stay per unit solid angle).
    #[inline]
    pub fn direction_to(&self, other: &Vertex) -> (Vec3, f32) {
        if other.infinite {
            return (other.wo, 1.0);
        }
        self.direction_to_point(other.p)
    }

    /// [`Self::direction_to`] a finite point `p` (a lens point that has no vertex of its own).
    #[inline]
    pub fn direction_to_point(&self, p: Vec3) -> (Vec3, f32) {
        if self.infinite {
            return (-self.wo, 1.0);
        }
        let d = p - self.p;
        let d2 = d.length_squared();
        if d2 == 0.0 {
            return (Vec3::ZERO, 0.0);
        }
        (d / d2.sqrt(), d2)
    }

    /// Both unit directions between two finite vertices (a to b, b to a) and the squared
    /// distance, with one square root: each is bit for bit what `direction_to` gives.
    #[inline]
    pub(crate) fn directions_between(a: &Vertex, b: &Vertex) -> (Vec3, Vec3, f32) {
        debug_assert!(!a.infinite && !b.infinite);
        let d = b.p - a.p;
        let d2 = d.length_squared();
        if d2 == 0.0 {
            return (Vec3::ZERO, Vec3::ZERO, 0.0);
        }
        let len = d2.sqrt();
        // a - b rather than -(b - a): a zero component keeps the sign direction_to gives it.
        (d / len, (a.p - b.p) / len, d2)
    }

    /// Convert a solid-angle density at this vertex into an area density at `next`.
    pub fn convert_density(&self, pdf: f32, next: &Vertex) -> f32 {
        if next.infinite {
            return pdf;
        }
        let (w, d2) = self.direction_to(next);
        Self::convert_density_dir(pdf, next, w, d2)
    }

    /// [`Self::convert_density`] to a finite vertex that is not built yet: at `p`, with
    /// geometric normal `ng` (zero off surfaces).
    #[inline]
    pub(crate) fn convert_density_to_point(&self, pdf: f32, p: Vec3, ng: Vec3) -> f32 {
        let (w, d2) = self.direction_to_point(p);
        Self::area_density(pdf, ng, w, d2)
    }

    /// [`Self::convert_density`] with the direction toward `next` and the squared distance
    /// (`direction_to(next)`) already at hand.
    #[inline]
    fn convert_density_dir(pdf: f32, next: &Vertex, w: Vec3, d2: f32) -> f32 {
        if next.infinite {
            return pdf;
        }
        Self::area_density(pdf, next.ng, w, d2)
    }

    /// A solid-angle density as an area density at a finite point with normal `ng` (zero:
    /// not on a surface, no cosine), `w` and `d2` the direction and squared distance to it.
    #[inline]
    fn area_density(pdf: f32, ng: Vec3, w: Vec3, d2: f32) -> f32 {
        if d2 == 0.0 {
            return 0.0;
        }
        let mut pdf = pdf / d2;
        if ng != Vec3::ZERO {
            pdf *= ng.dot(w).abs();
        }
        remap_nan(pdf)
    }

    /// BSDF toward `next` (world direction), with the shading-normal correction of
    /// importance transport. Zero for vertices without a BSDF.
    pub fn f(&self, next: &Vertex, mode: TransportMode) -> Rgb {
        if self.bsdf.is_none() {
            return Rgb::BLACK;
        }
        let (wi, d2) = self.direction_to(next);
        if d2 == 0.0 {
            return Rgb::BLACK;
        }
        self.f_dir(wi, mode)
    }

    /// [`Self::f`] toward the unit world direction `wi` (non-zero: `direction_to` of a
    /// distinct vertex), for connections that have it at hand.
    #[inline]
    pub fn f_dir(&self, wi: Vec3, mode: TransportMode) -> Rgb {
        let Some(bsdf) = &self.bsdf else { return Rgb::BLACK };
        let f = match lambertian_eval(bsdf, self.shading.n, self.wo, wi, mode) {
            Some(f) => f,
            None => bsdf.eval(self.shading.to_local(self.wo), self.shading.to_local(wi), mode),
        };
        f * shading_correction(self.ng, self.shading.n, self.wo, wi, mode)
    }

    /// |cos| between the shading normal and the direction to `other` (1 off surfaces).
    pub fn abs_cos_to(&self, other: &Vertex) -> f32 {
        if !self.on_surface() {
            return 1.0;
        }
        self.abs_cos_dir(self.direction_to(other).0)
    }

    /// [`Self::abs_cos_to`] with the direction at hand.
    #[inline]
    pub fn abs_cos_dir(&self, w: Vec3) -> f32 {
        if !self.on_surface() {
            return 1.0;
        }
        self.shading.n.dot(w).abs()
    }

    /// Emission from this vertex toward `toward`: radiance of an area light or an environment,
    /// intensity of a point or spot light.
    pub fn le(&self, scene: &Scene, toward: &Vertex) -> Rgb {
        if self.infinite {
            // A camera ray escaped: all environment lights (toward is the last surface).
            return scene.environment_lights.iter().fold(Rgb::BLACK, |acc, &i| acc + scene.lights[i as usize].le_escaped(self.wo));
        }
        if self.light.is_none() {
            return Rgb::BLACK;
        }
        let (w, d2) = self.direction_to(toward);
        if d2 == 0.0 {
            return Rgb::BLACK;
        }
        self.le_dir(scene, w)
    }

    /// [`Self::le`] of a finite vertex toward the unit direction `w` (non-zero).
    #[inline]
    pub fn le_dir(&self, scene: &Scene, w: Vec3) -> Rgb {
        let Some(li) = self.light else { return Rgb::BLACK };
        match &scene.lights[li as usize] {
            Light::Area(a) => {
                if self.kind == VertexKind::Surface {
                    a.l(self.ng, self.uv, w)
                } else if self.ng.dot(w) > 0.0 {
                    self.le
                } else {
                    Rgb::BLACK
                }
            }
            l @ (Light::Spot { .. } | Light::Luminaire(_)) => l.spot_intensity(w),
            Light::Projector(pr) => pr.intensity(w),
            Light::Goniometric(g) => g.eval(w),
            Light::Point { .. } => self.le,
            _ => Rgb::BLACK,
        }
    }

    /// Area density at `next` of a walk at this vertex that arrived from `prev` and samples
    /// `next` (`mode`: the direction of that walk). Light endpoints sample by emission.
    pub fn pdf(&self, scene: &Scene, prev: Option<&Vertex>, next: &Vertex, mode: TransportMode) -> f32 {
        if self.kind == VertexKind::Camera {
            return self.pdf_with_lens(scene, scene.camera.lens_connector().as_ref(), prev, next, mode);
        }
        self.pdf_with_lens(scene, None, prev, next, mode)
    }

    /// [`Self::pdf`] with the camera's constants computed beforehand (`PathConfig::lens`;
    /// only camera vertices read it), for the connections that ask per sample.
    pub fn pdf_with_lens(&self, scene: &Scene, lens: Option<&LensConnector>, prev: Option<&Vertex>, next: &Vertex, mode: TransportMode) -> f32 {
        if self.kind == VertexKind::Light {
            return self.pdf_light(scene, next);
        }
        let (wn, d2) = self.direction_to(next);
        if d2 == 0.0 {
            return 0.0;
        }
        let pdf = match self.kind {
            VertexKind::Camera => lens.map_or(0.0, |l| l.pdf_we(&crate::geometry::Ray::new(self.p, wn)).1),
            _ => {
                let (Some(bsdf), Some(prev)) = (&self.bsdf, prev) else { return 0.0 };
                let (wp, dp2) = self.direction_to(prev);
                if dp2 == 0.0 {
                    return 0.0;
                }
                match lambertian_pdf_of(bsdf, wp.dot(self.shading.n), wn.dot(self.shading.n)) {
                    Some(p) => p,
                    None => bsdf.pdf(self.shading.to_local(wp), self.shading.to_local(wn), mode),
                }
            }
        };
        Self::convert_density_dir(pdf, next, wn, d2)
    }

    /// `(self.pdf_with_lens(.., Some(a), b, to_b), self.pdf_with_lens(.., Some(b), a, to_a))`,
    /// bit for bit, with the two directions and their local frames computed once for both
    /// at a surface (the MIS weight asks both at each end of a connection).
    #[allow(clippy::too_many_arguments)]
    pub fn pdf_pair(&self, scene: &Scene, lens: Option<&LensConnector>, a: &Vertex, b: &Vertex, to_b: TransportMode, to_a: TransportMode) -> (f32, f32) {
        if self.kind != VertexKind::Surface {
            return (self.pdf_with_lens(scene, lens, Some(a), b, to_b), self.pdf_with_lens(scene, lens, Some(b), a, to_a));
        }
        let (wa, da2) = self.direction_to(a);
        let (wb, db2) = self.direction_to(b);
        let Some(bsdf) = &self.bsdf else { return (0.0, 0.0) };
        if da2 == 0.0 || db2 == 0.0 {
            return (0.0, 0.0);
        }
        let (za, zb) = (wa.dot(self.shading.n), wb.dot(self.shading.n));
        let (pab, pba) = match (lambertian_pdf_of(bsdf, za, zb), lambertian_pdf_of(bsdf, zb, za)) {
            (Some(ab), Some(ba)) => (ab, ba),
            _ => {
                let (la, lb) = (self.shading.to_local(wa), self.shading.to_local(wb));
                (bsdf.pdf(la, lb, to_b), bsdf.pdf(lb, la, to_a))
            }
        };
        (Self::convert_density_dir(pab, b, wb, db2), Self::convert_density_dir(pba, a, wa, da2))
    }

    /// Area density at `v` of a ray leaving this light vertex toward it (emission's
    /// directional density; for lights at infinity the density of the entry disk).
    pub fn pdf_light(&self, scene: &Scene, v: &Vertex) -> f32 {
        let (w, d2) = self.direction_to(v);
        if d2 == 0.0 {
            return 0.0;
        }
        let mut pdf = if self.infinite {
            1.0 / (PI * scene.bounds.radius * scene.bounds.radius)
        } else {
            let Some(li) = self.light else { return 0.0 };
            scene.lights[li as usize].pdf_le(&crate::geometry::Ray::new(self.p, w), self.ng, &scene.bounds).1 / d2
        };
        if v.on_surface() {
            pdf *= v.ng.dot(w).abs();
        }
        remap_nan(pdf)
    }

    /// Density with which a light subpath starts at this vertex (light choice times the
    /// origin's density; for infinite lights the direction toward `v`, per unit solid angle).
    pub fn pdf_light_origin(&self, scene: &Scene, v: &Vertex) -> f32 {
        if self.infinite {
            let (w, _) = self.direction_to(v);
            return infinite_light_density(scene, w);
        }
        let Some(li) = self.light else { return 0.0 };
        let (w, d2) = self.direction_to(v);
        if d2 == 0.0 {
            return 0.0;
        }
        let (pdf_pos, _) = scene.lights[li as usize].pdf_le(&crate::geometry::Ray::new(self.p, w), self.ng, &scene.bounds);
        scene.light_pmf(li) * pdf_pos
    }
}

/// `path.push(v)` for the vertex `write` puts in the path's next slot (and hands back,
/// which only writing it can do), so that it is built there rather than copied there.
#[inline]
pub(crate) fn push_written(path: &mut Vec<Vertex>, write: impl for<'a> FnOnce(&'a mut MaybeUninit<Vertex>) -> &'a mut Vertex) {
    path.reserve(1);
    let len = path.len();
    let slot = &mut path.spare_capacity_mut()[0];
    let at = slot.as_ptr();
    let written: *const Vertex = write(slot);
    // A reference to the slot as a `Vertex` exists only once the slot is written (one
    // comparison a vertex keeps this sound whatever `write` does).
    assert!(std::ptr::eq(written, at), "push_written: the write did not return the slot");
    // SAFETY: `write` returned the element at `len` as a `&mut Vertex` (checked above), so it
    // is initialised, and `reserve` made room for it.
    unsafe { path.set_len(len + 1) };
}

/// Solid-angle density with which light selection and environment sampling produce light
/// travelling in direction `d` (summed over the environment lights).
pub(crate) fn infinite_light_density(scene: &Scene, d: Vec3) -> f32 {
    scene.environment_lights.iter().map(|&i| scene.light_pmf(i) * scene.lights[i as usize].pdf_li_escaped(-d)).sum()
}

/// The geometric term between two surface vertices with shading cosines, zero when blocked.
/// `w_ab`, `w_ba`, `d2`: [`Vertex::directions_between`] of the two (finite) vertices.
#[inline]
pub(crate) fn geometry_term(scene: &Scene, a: &Vertex, b: &Vertex, w_ab: Vec3, w_ba: Vec3, d2: f32) -> f32 {
    if d2 == 0.0 {
        return 0.0;
    }
    let g = a.abs_cos_dir(w_ab) * b.abs_cos_dir(w_ba) / d2;
    if g == 0.0 || scene.occluded_between(a.p, a.ng, b.p, b.ng, a.time) {
        return 0.0;
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::detail::Detail;
    use crate::bsdf::diffuse::Diffuse;
    use crate::bsdf::oren_nayar::OrenNayar;
    use crate::math::warp::square_to_uniform_sphere;
    use crate::sampling::Pcg32;

    fn diffuse(r: f32) -> BsdfModel {
        BsdfModel::Diffuse(Diffuse { reflectance: Rgb::new(r, 0.5 * r, 0.25) })
    }

    /// The BSDFs the Lambertian shortcuts cover: one- and two-sided diffuse, opaque and masked.
    fn lambertian_bsdfs() -> Vec<Bsdf> {
        let mut bsdfs = Vec::new();
        for back in [None, Some(diffuse(0.3))] {
            for opacity in [1.0, 0.6] {
                bsdfs.push(Bsdf { front: diffuse(0.8), back: back.clone(), opacity, detail: None });
            }
        }
        bsdfs
    }

    /// BSDFs the Lambertian shortcuts must refuse: a rough diffuse one, a diffuse front with a
    /// rough back, a diffuse one with a normal map.
    fn not_lambertian_bsdfs() -> [Bsdf; 3] {
        let rough = BsdfModel::OrenNayar(OrenNayar { reflectance: Rgb::splat(0.5), sigma: 0.3 });
        [
            Bsdf { front: rough.clone(), back: None, opacity: 1.0, detail: None },
            Bsdf { front: diffuse(0.5), back: Some(rough), opacity: 1.0, detail: None },
            Bsdf { front: diffuse(0.5), back: None, opacity: 1.0, detail: Some(Detail::new(Vec3::new(0.1, 0.0, 1.0), true)) },
        ]
    }

    /// `lambertian_eval` is the BSDF's own `eval` in the local frame, bit for bit: one- and
    /// two-sided diffuse BSDFs, masks, directions on both sides and in the tangent plane
    /// (signed zeros); None for the BSDFs it does not cover.
    #[test]
    fn lambertian_eval_is_bsdf_eval() {
        let bsdfs = lambertian_bsdfs();
        let mut rng = Pcg32::new(11, 5);
        let dir = |rng: &mut Pcg32| square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let bits = |c: Rgb| [c.r, c.g, c.b].map(f32::to_bits);
        let mut lit = [0usize; 2];
        for _ in 0..2000 {
            let frame = Frame::from_normal(dir(&mut rng));
            let (mut wo, mut wi) = (dir(&mut rng), dir(&mut rng));
            // Some directions exactly in the tangent plane (a local z of ±0).
            if rng.next_f32() < 0.1 {
                wo = frame.s;
            }
            if rng.next_f32() < 0.1 {
                wi = -frame.t;
            }
            for (k, b) in bsdfs.iter().enumerate() {
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let want = b.eval(frame.to_local(wo), frame.to_local(wi), mode);
                    let got = lambertian_eval(b, frame.n, wo, wi, mode).expect("a Lambertian BSDF");
                    assert_eq!(bits(got), bits(want), "bsdf {k} wo {wo} wi {wi}");
                    lit[usize::from(b.back.is_some())] += usize::from(!got.is_black());
                }
            }
        }
        // Both sides scatter where there is a back.
        assert!(lit[0] > 1000 && lit[1] > 2 * lit[0] - 400, "{lit:?}");
        let others = not_lambertian_bsdfs();
        // (From below, so that the second one's back is asked for.)
        for b in &others {
            assert!(lambertian_eval(b, Vec3::Z, -Vec3::Z, Vec3::Z, TransportMode::Radiance).is_none());
        }
    }

    /// `lambertian_pdf_of` (the MIS weight's densities) is the BSDF's own `pdf` in the local
    /// frame, bit for bit: one- and two-sided diffuse BSDFs, masks, both sides, tangent
    /// directions; None for the BSDFs it does not cover.
    #[test]
    fn lambertian_pdf_is_bsdf_pdf() {
        let bsdfs = lambertian_bsdfs();
        let mut rng = Pcg32::new(13, 7);
        let dir = |rng: &mut Pcg32| square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let mut positive = 0;
        for _ in 0..2000 {
            let frame = Frame::from_normal(dir(&mut rng));
            let (mut wa, mut wb) = (dir(&mut rng), dir(&mut rng));
            if rng.next_f32() < 0.1 {
                wa = -frame.s;
            }
            if rng.next_f32() < 0.1 {
                wb = frame.t;
            }
            for (k, b) in bsdfs.iter().enumerate() {
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let want = b.pdf(frame.to_local(wa), frame.to_local(wb), mode);
                    let got = lambertian_pdf_of(b, wa.dot(frame.n), wb.dot(frame.n)).expect("a Lambertian BSDF");
                    assert_eq!(got.to_bits(), want.to_bits(), "bsdf {k} wa {wa} wb {wb}");
                    positive += usize::from(got > 0.0);
                }
            }
        }
        assert!(positive > 4000, "{positive}");
        let others = not_lambertian_bsdfs();
        // (From below, so that the second one's back is asked for.)
        for b in &others {
            assert!(lambertian_pdf_of(b, -1.0, -0.5).is_none());
        }
    }

    /// `lambertian_sample` is the BSDF's own `sample` in the local frame and its reverse
    /// `pdf`, bit for bit (the walk's generic route), with the same draws: one- and two-sided
    /// diffuse BSDFs, masks, both sides, tangent directions; Some(None) where `sample` fails;
    /// None for a mask's pass-through and for the BSDFs it does not cover.
    #[test]
    fn lambertian_sample_is_bsdf_sample() {
        let bsdfs = lambertian_bsdfs();
        let mut rng = Pcg32::new(7, 3);
        let dir = |rng: &mut Pcg32| square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let bits = |c: Rgb| [c.r, c.g, c.b].map(f32::to_bits);
        let vbits = |v: Vec3| v.to_array().map(f32::to_bits);
        let flip = |m| if m == TransportMode::Radiance { TransportMode::Importance } else { TransportMode::Radiance };
        let mut seen = [0usize; 3];
        for _ in 0..3000 {
            let frame = Frame::from_normal(dir(&mut rng));
            let mut wo = dir(&mut rng);
            if rng.next_f32() < 0.1 {
                wo = frame.t;
            }
            let uc = rng.next_f32();
            let u = match rng.next_u32() % 8 {
                0 => Vec2::ZERO,
                1 => Vec2::new(0.5, 0.5),
                _ => Vec2::new(rng.next_f32(), rng.next_f32()),
            };
            for (k, b) in bsdfs.iter().enumerate() {
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let wl = frame.to_local(wo);
                    let want = b.sample(wl, uc, u, mode);
                    let Some(got) = lambertian_sample(b, &frame, wo, uc, u) else {
                        // Only a mask's pass-through goes the generic way.
                        assert!(b.opacity < 1.0 && uc >= b.opacity, "bsdf {k}");
                        seen[2] += 1;
                        continue;
                    };
                    match (got, want) {
                        (None, None) => seen[0] += 1,
                        (Some((g, rev)), Some(w)) => {
                            assert_eq!(vbits(g.wi), vbits(w.wi), "bsdf {k} wo {wo} u {u}");
                            assert_eq!(bits(g.f), bits(w.f));
                            assert_eq!((g.pdf.to_bits(), g.lobe, g.eta.to_bits()), (w.pdf.to_bits(), w.lobe, w.eta.to_bits()));
                            assert_eq!(rev.to_bits(), b.pdf(w.wi, wl, flip(mode)).to_bits(), "bsdf {k} wo {wo} u {u}");
                            seen[1] += 1;
                        }
                        (g, w) => panic!("bsdf {k} wo {wo}: {:?} vs {:?}", g.map(|s| s.0.wi), w.map(|s| s.wi)),
                    }
                }
            }
        }
        // Samples on both sides, failures (the back of one-sided BSDFs), pass-throughs.
        assert!(seen.iter().all(|&n| n > 1000), "{seen:?}");
        let others = not_lambertian_bsdfs();
        let frame = Frame::from_normal(Vec3::Z);
        for b in &others {
            assert!(lambertian_sample(b, &frame, -Vec3::Z, 0.5, Vec2::splat(0.3)).is_none());
        }
    }
}
