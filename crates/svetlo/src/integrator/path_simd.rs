//! The path tracer of `path.rs`, eight paths at a time: the same estimator (next-event
//! estimation and BSDF sampling combined by the power heuristic, Russian roulette, Mitsuba's
//! `max_depth`), with the rays of eight paths traced as one packet (`accel::packet`: the
//! triangles through the packet BVH, up to 16 analytic spheres tested on every lane), or, in
//! scenes of more than 40 000 triangles, more spheres or SDF grids, one by one through the
//! scene's BVH (`Tracer`). Per vertex, `gather` does each lane's branchy part (emission
//! found, random numbers, light and triangle choice) and `shade8` the arithmetic of all
//! eight lanes on the paths' state kept as structure of arrays (compiled to AVX2 vector
//! code; an AVX-512VL build of the same code has 32 registers where the CPU has them).
//!
//! Scope: scenes of triangle meshes, analytic spheres and SDF grids, with any material svetlo
//! reads, static or with moving shapes. Where shapes move (motion blur), the packets hold the
//! static shapes and the moving ones are tried after them lane by lane at each path's time,
//! as `Scene::closest` tries them after its BVH (scenes/motion-blur.xml: the scalar tracer's
//! image bit for bit in 0.56 of its CPU time); with a ray epsilon every lane's ray goes one by
//! one through the scene's own queries (`Tracer::Scene`). A hit on a shape that is not a mesh
//! comes as the scene's own surface record (`Scene::interaction`, as the scalar tracer's
//! `Scene::intersect` makes it: `other_hit`), and is shaded from it as a triangle's hit is.
//! (Two-sided) Lambertian materials of constant or textured reflectance (any texture:
//! bitmaps, procedural, mesh attributes; evaluated per lane where the path hits) are shaded
//! as eight-lane arithmetic, on any shape; a normal or bump map over a one-sided Lambertian
//! one by `detail_scatter` (the map per lane, no `Bsdf` built), a one-sided rough conductor
//! under a map or of textured parameters by `conductor_scatter` (the conductor and the
//! perturbed frame per lane, the conductor lanes in that frame, no `Bsdf` built); every other
//! one (conductors, dielectrics, plastics, the classic models, principled, blends, masks, maps
//! over other models) lane by lane through its scalar `Bsdf`
//! (`scalar_light_sample` in `gather`, `scalar_scatter` once every lane's sphere-light
//! sample is in: the same calls and random numbers as `path.rs`), its results selected into
//! `shade8`'s lanes. A shape whose material has no texture and no surface detail keeps its
//! `Bsdf`, built once (`ShapeData::uniform`; its lanes neither rebuild nor copy it), and
//! the value and density toward the light sample come with the BSDF's own sample from one
//! call (`Bsdf::eval_pdf_and_sample`: a rough model's half vector, D and G1 computed once;
//! a rough conductor's Λ(wo) once for both; a Beckmann one's visible normal, value, density
//! and sample for all lanes at once before, by `conductor_samples`, the same bits). Large
//! scenes that trace single rays read the triangles their rays hit from the meshes (unpacking
//! them all only where a render takes several camera samples a triangle).
//! Lights: area lights of constant radiance on meshes
//! (sampled by the kernel's own unpacked copy), and every other light the scalar tracer
//! takes (textured area lights, sphere lights, point, spot, directional, one constant or
//! bitmap environment), each lane sampling it through its own `Light::sample_li` (a
//! sphere's: the cone it subtends; those of constant radiance for all lanes at once, after
//! `gather`, by `AreaLight::sample_constant_spheres`, the same bits), looking a textured or sphere
//! emitter's radiance and density (`AreaLight::l`, `pdf_li`) up where its path hits it and
//! seeing the environment where its ray escapes;
//! either sampler (Sobol's scrambles for all lanes at once: [`LaneSampler`]); AOVs and
//! `--lpe` (each lane steps its path's automata as the scalar tracer does: see
//! [`LaneLayers`]). `SimdPathTracer` checks that (`SimdKernel::new`) and otherwise, or
//! without AVX2, runs the scalar tracer.
//!
//! Each lane draws its random numbers from its own copy of the scalar tracer's sampler, in
//! the same order, and the samples of a tile are added to the film in the scalar order, so
//! that the image equals the scalar tracer's up to float rounding (paths that meet a shared
//! edge may pick the other triangle); tracing single rays, bit for bit. Where a ray meets two
//! triangles at one distance, the tree that tests the one last keeps it (the test accepts
//! t up to t_max within its rounding), so the packet tree and the scene's BVH may keep
//! different ones. In scenes whose paths cross surfaces (`may_cross`: dielectrics, masks,
//! principled, ...) that is systematic: a path inside a glass box resting on the floor meets
//! the box's bottom and the floor at once, and packets kept the floor where the scene's BVH
//! kept the glass (a Cornell box with a glass box came out 0.2-0.3 % darker; lifted 1e-4 off
//! the floor, it was the single-ray image bit for bit). There the packet walk flags the lanes
//! whose nearest hit has another triangle's within 1e-5 (`PacketBvh::intersect_ties`) and
//! traces them again through the scene's BVH: the packet image is the scalar tracer's bit for
//! bit, in 0.81 of the CPU time single rays took on a Cornell box with a glass box (0.60 of
//! the scalar tracer's). Opaque scenes skip the check: their ties are shared edges and faces
//! hidden inside closed objects; but large ones (more than 20 000 triangles, which traced
//! single rays before) keep it, and with it their single-ray image bit for bit. Scenes with spheres (which traced single rays, bit for bit)
//! keep the check, and test their spheres after the triangles on all lanes with
//! `Sphere::intersect`'s f64 operations (`PacketSpheres`), as the scene's BVH tests them after
//! its triangles; the lanes it cannot vouch for (two spheres at one f32 distance, a hit within
//! rounding of a sphere's box) are traced again singly: Bitterli's veach-mis (three sphere
//! lights, rough conductor plates) is the single-ray image bit for bit in 0.80 of its CPU time
//! (0.85 of its instructions).

use super::path::{bsdf_pdf_toward, PathTracer};
use super::{camera_sample, render_tiles, Integrator, Progress, RenderSettings};
use crate::accel::packet::{Hits8, PacketBvh, PacketSpheres, Rays8, LANES};
use crate::accel::HitRecords;
use crate::bsdf::conductor::{rough_conductor_ggx_lanes, rough_conductor_lanes, RoughConductor, RoughConductorLanes};
use crate::bsdf::detail::{bump_map_normal, normal_map_normal, Detail};
use crate::bsdf::detail_lanes::{detail_frame, detail_lambert_lanes, tan2, DetailLambertLanes};
use crate::bsdf::dielectric::{rough_dielectric_lanes, RoughDielectric, RoughDielectricLanes};
use crate::bsdf::diffuse::Diffuse;
use crate::bsdf::lane_samples::LaneSamples;
use crate::bsdf::material::Roughness;
use crate::bsdf::plastic::{rough_plastic_ggx_lanes, rough_plastic_lanes, RoughPlastic, RoughPlasticLanes};
use crate::bsdf::principled::{PrincipledAt, PrincipledMaterial};
use crate::bsdf::{Bsdf, BsdfModel, BsdfSample, LobeFlags, Material, MicrofacetKind, TransportMode};
use crate::camera::{RayGenerator, RayLanes};
use crate::error::{Error, Result};
use crate::film::{Film, FilmTile};
use crate::geometry::mesh::TriangleFrame;
use crate::geometry::ray::SHADOW_EPSILON;
use crate::geometry::Ray;
use crate::geometry::{Geometry, Sphere, SurfaceInteraction, TriangleShading};
use crate::light::area::{SphereLanes, SphereSamples};
use crate::light::envmap::EnvCells;
use crate::light::{AreaLight, EnvMap, Light, LightSample};
use crate::lpe::{AovSet, ForwardView, LayerMask, MAX_LAYERS};
use crate::math::lane::{cosine_hemisphere, dot3, lanes_of, offset3};
use crate::math::{warp, Frame, INV_PI};
use crate::sampling::{power_heuristic, Distribution1D, IndependentSampler, Sampler, SamplerKind, SobolSampler};
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::texture::{TexPoint, Texture};
use glam::{Vec2, Vec3};
use std::sync::Arc;

/// `path`: the eight-wide kernel when the scene qualifies and the CPU has AVX2, else the
/// scalar [`PathTracer`]. `path:simd=false` always runs the scalar one.
#[derive(Clone, Copy, Debug)]
pub struct SimdPathTracer {
    pub simd: bool,
}

impl Default for SimdPathTracer {
    fn default() -> Self {
        SimdPathTracer { simd: true }
    }
}

impl SimdPathTracer {
    /// Options `key=value,...`: `simd=true|false`.
    pub fn parse(opts: &str) -> Result<Self> {
        let mut t = SimdPathTracer::default();
        for kv in opts.split(',').filter(|s| !s.is_empty()) {
            match kv.split_once('=') {
                Some(("simd", v)) => t.simd = v.parse().map_err(|_| Error::Settings(format!("path: simd must be true or false, got '{v}'")))?,
                _ => return Err(Error::Settings(format!("path: unknown option '{kv}' (available: simd=true|false)"))),
            }
        }
        Ok(t)
    }
}

impl SimdPathTracer {
    /// Whether a render asks the eight-wide kernel first (it may still decline the scene).
    fn tries_kernel(&self, settings: &RenderSettings) -> bool {
        self.simd && lanes_route(settings) && crate::cpu::avx2()
    }
}

/// Whether the lanes can step the AOVs' product automaton (built when the set is bound to the
/// scene); a set too large for one takes the scalar tracer's automaton-by-automaton steps.
fn lanes_route(settings: &RenderSettings) -> bool {
    settings.aovs().is_empty() || settings.aovs().forward_view().is_some()
}

impl Integrator for SimdPathTracer {
    fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        if self.simd && !lanes_route(settings) {
            eprintln!("note: these light path expressions take the scalar path tracer (their product automaton is too large for the eight-wide kernel)");
        }
        if self.tries_kernel(settings) {
            if let Some(k) = SimdKernel::new(scene, settings) {
                return k.render(scene, settings, progress);
            }
        }
        PathTracer.render(scene, settings, progress)
    }

    /// The kernel's set-up, made and dropped: its geometry (the packet tree, the unpacked
    /// triangles) stays with the scene for the render.
    fn prepare(&self, scene: &Scene, settings: &RenderSettings) {
        if self.tries_kernel(settings) {
            drop(SimdKernel::new(scene, settings));
        }
    }
}

/// What the packet tree is built from: the static meshes, in the kernel's order. The tree
/// depends on the corners alone: the meshes untagged.
fn packet_tree_key(scene: &Scene) -> Vec<(u32, &Arc<Geometry>)> {
    kernel_order(scene)
        .take_while(|&si| !scene.moving.iter().any(|mv| mv.shape as usize == si))
        .map(|si| (0, &scene.shapes[si].geometry))
        .filter(|(_, g)| matches!(&***g, Geometry::Mesh(_)))
        .collect()
}

/// A triangle as shading sees it.
#[derive(Clone, Copy, Debug)]
struct Tri {
    p: [Vec3; 3],
    shading: TriangleFrame,
    shape: u32,
    /// Its index in its mesh (for uvs and mesh-attribute textures).
    local: u32,
}

/// A Lambertian reflectance: constant, or a texture evaluated where the path hits.
#[derive(Clone, Debug)]
enum Albedo {
    Constant(Rgb),
    Textured(Texture),
}

impl Albedo {
    /// Its value where it is constant (black where textured: never asked there).
    #[inline(always)]
    fn constant(&self) -> Rgb {
        match self {
            Albedo::Constant(c) => *c,
            Albedo::Textured(_) => Rgb::BLACK,
        }
    }

    /// As `Material::bsdf` evaluates it (clamped to [0, 1]).
    #[inline(always)]
    fn at(&self, tp: &TexPoint) -> Rgb {
        match self {
            Albedo::Constant(c) => *c,
            Albedo::Textured(t) => t.eval_inline(tp).clamp(0.0, 1.0),
        }
    }

    /// Whether its lookups land anywhere in a bitmap too large to stay cached (a texel a
    /// lookup: see [`PREFETCH_TEXELS_MIN`]).
    fn large_bitmap(&self) -> bool {
        matches!(self, Albedo::Textured(Texture::Bitmap { image, .. }) if image.width * image.height >= PREFETCH_TEXELS_MIN)
    }

    /// Asks for the texels a lookup at `uv` will read (a hint: changes no value).
    #[inline(always)]
    fn prefetch(&self, uv: Vec2) {
        if let Albedo::Textured(t) = self {
            t.prefetch(uv);
        }
    }
}

/// Bitmaps of at least this many texels (1 MiB of 8-bit ones, about an L2 cache) have the
/// texels of the lanes' hits asked for before shading (`SimdKernel::prefetch_texels`).
const PREFETCH_TEXELS_MIN: usize = 1 << 18;

/// A shape's material and emission.
#[derive(Clone, Debug)]
struct ShapeData {
    /// Whether its lanes take the scalar `Bsdf` (any material but a plain Lambertian one, or
    /// a normal or bump map); then `front` and `back` are unused, but where `detail` is set.
    scalar_bsdf: bool,
    front: Albedo,
    /// Reflectance seen from the back (two-sided); None: black there.
    back: Option<Albedo>,
    /// Whether either side is textured (then the hit's uv is needed).
    textured: bool,
    /// Light index and radiance when the shape emits.
    /// (None: a textured emitter, its radiance looked up at the hit by `AreaLight::l`).
    light: Option<(u32, Option<Rgb>)>,
    /// A scalar BSDF that is the same at every point (no texture, no surface detail: what
    /// `Scene::bsdf` gives at any hit), built once instead of at each hit of a lane.
    uniform: Option<Bsdf>,
    /// Its lobes (looked up once: they cost two model dispatches a hit).
    uniform_flags: LobeFlags,
    /// Whether its shading or emission reads the hit's uv (a texture, a textured emitter, a
    /// BSDF built per hit); where not, a hit on a shape that is not a mesh comes without
    /// (`other_hit`: a sphere's uv costs an atan2 and an acos).
    reads_uv: bool,
    /// Whether a side's reflectance is a large bitmap, whose texels are asked for ahead.
    prefetch_texels: bool,
    /// A normal or bump map over a one-sided Lambertian `front`: its lanes keep `scalar_bsdf`
    /// for `shade8` but are shaded by `detail_scatter`, without a `Bsdf`.
    detail: Option<DetailMap>,
    /// A one-sided rough conductor shaded by `conductor_scatter`, no `Bsdf` built: under a
    /// normal or bump map, or of textured parameters (its lanes keep `scalar_bsdf`).
    conductor: Option<KernelConductor>,
    /// Its `KernelConductor::fixed` where that has a normal map (a fixed one without is a
    /// uniform `Bsdf`).
    conductor_fixed: Option<(RoughConductor, Vec3)>,
    /// A textured `principled` or `principledthin` material (no surface detail): its lanes
    /// keep `scalar_bsdf` but build its model in a slot of their own (`principled_scatter`),
    /// no `Bsdf`.
    principled: bool,
}

/// A [`ShapeData::conductor`]: `Material::Conductor`'s parameters (its textures evaluated per
/// lane, as `Material::bsdf` evaluates them) and the map over it, if any.
#[derive(Clone, Debug)]
struct KernelConductor {
    eta: Rgb,
    k: Rgb,
    specular_reflectance: Texture,
    roughness: Roughness,
    map: Option<DetailMap>,
    /// The conductor and the map's perturbed normal (`Detail::n`) where neither depends on
    /// the hit (constant textures, no map or a constant normal map): made once, the hit's
    /// texture point not made (a mesh's uv was ~1 % of an identity normal map's time).
    fixed: Option<(RoughConductor, Option<Vec3>)>,
}

impl KernelConductor {
    /// Where material `m` (of a shape with surface detail: `detail`) is a rough conductor under
    /// a normal or bump map, or a rough conductor of textured parameters without one.
    fn of(m: &Material, detail: bool) -> Option<KernelConductor> {
        let (map, inner) = match m {
            Material::NormalMap { normals, inner } if detail => (Some(DetailMap::Normal(normals.clone())), &**inner),
            Material::BumpMap { height, scale, inner } if detail => (Some(DetailMap::Bump { height: height.clone(), scale: *scale }), &**inner),
            m if !detail => (None, m),
            _ => return None,
        };
        // A uniform one without a map keeps its `Bsdf` (`ShapeData::uniform`).
        if map.is_none() && inner.is_uniform() {
            return None;
        }
        match inner {
            Material::Conductor { eta, k, specular_reflectance, roughness: Some(r) } => {
                let mut c = KernelConductor { eta: *eta, k: *k, specular_reflectance: specular_reflectance.clone(), roughness: r.clone(), map, fixed: None };
                let constant = |t: &Texture| matches!(t, Texture::Constant(_));
                let n = match &c.map {
                    None => Some(None),
                    Some(DetailMap::Normal(t)) if constant(t) => Some(Some(Detail::new(normal_map_normal(t.eval(TexPoint::default())), true).n)),
                    Some(_) => None,
                };
                if let Some(n) = n.filter(|_| constant(&c.specular_reflectance) && constant(&c.roughness.alpha_u) && constant(&c.roughness.alpha_v)) {
                    c.fixed = Some((c.at(TexPoint::default()), n));
                }
                Some(c)
            }
            _ => None,
        }
    }

    /// The conductor at `tp` (as `Material::bsdf` builds it).
    #[inline(always)]
    fn at(&self, tp: TexPoint) -> RoughConductor {
        RoughConductor { distribution: self.roughness.at(tp), eta: self.eta, k: self.k, specular_reflectance: self.specular_reflectance.eval(tp) }
    }
}

/// The map of a [`ShapeData::detail`] (`Material::NormalMap`, `Material::BumpMap`).
#[derive(Clone, Debug)]
enum DetailMap {
    Normal(Texture),
    Bump { height: Texture, scale: f32 },
}

impl DetailMap {
    /// Whether its lookups land anywhere in a bitmap too large to stay cached (see
    /// [`PREFETCH_TEXELS_MIN`]).
    fn large_bitmap(&self) -> bool {
        let (DetailMap::Normal(t) | DetailMap::Bump { height: t, .. }) = self;
        matches!(t, Texture::Bitmap { image, .. } if image.width * image.height >= PREFETCH_TEXELS_MIN)
    }

    /// Asks for the texels a lookup at `uv` will read (a hint: changes no value).
    #[inline(always)]
    fn prefetch(&self, uv: Vec2) {
        let (DetailMap::Normal(t) | DetailMap::Bump { height: t, .. }) = self;
        t.prefetch(uv);
    }
}

/// The perturbed normal (unnormalised, in the shading frame `frame`) of `map` at `tp` on
/// `shape`, as `Material::bsdf_with_detail` finds it.
#[inline(always)]
fn detail_normal(scene: &Scene, map: &DetailMap, shape: u32, tp: TexPoint, frame: &Frame, ng: Vec3) -> Vec3 {
    match map {
        DetailMap::Normal(t) => normal_map_normal(t.eval(tp)),
        DetailMap::Bump { height, scale } => {
            let (dpdu, dpdv) = scene.dp_duv_at(shape, tp.prim, tp.p, frame);
            bump_map_normal(height.eval_f32_grad(tp) * *scale, frame, ng, dpdu, dpdv)
        }
    }
}

/// The normal or bump map of a shape's detail route (`ShapeData::detail`) or conductor route
/// (`ShapeData::conductor`), if any.
fn map_of<'a>(detail: &'a Option<DetailMap>, conductor: &'a Option<KernelConductor>) -> Option<&'a DetailMap> {
    detail.as_ref().or_else(|| conductor.as_ref().and_then(|c| c.map.as_ref()))
}

/// The detail map and Lambertian reflectance of a normal or bump map over a one-sided
/// Lambertian material (what `Material::bsdf_with_detail` builds there).
fn detail_lambert(m: &Material) -> Option<(DetailMap, Albedo)> {
    match m {
        Material::NormalMap { normals, inner } => Some((DetailMap::Normal(normals.clone()), diffuse_albedo(inner)?)),
        Material::BumpMap { height, scale, inner } => Some((DetailMap::Bump { height: height.clone(), scale: *scale }, diffuse_albedo(inner)?)),
        _ => None,
    }
}

/// A mesh area light as `AreaLight::sample_li` samples it, unpacked: its triangles' vertices
/// and the normals it gives sampled points.
struct MeshLight {
    /// 1 / area (0 for a light without area).
    pdf_area: f32,
    tri_distribution: Distribution1D,
    /// Its mesh's triangles (from [`KernelGeometry::light_tris`]).
    tris: Arc<[LightTri]>,
    radiance: Rgb,
}

/// A mesh light's triangle: first vertex and edges (p0, p1 - p0, p2 - p0) and the sampled
/// point's normal: constant over the triangle, or the geometric normal of
/// `TriangleMesh::surface`.
type LightTri = ([Vec3; 3], std::result::Result<Vec3, TriangleShading>);

/// What the kernel unpacks from the scene's geometry alone, kept with the scene
/// (`Scene::kernel_geometry`) for its next renders: unpacking every triangle cost ~22M
/// instructions a render on bsdf_spheres' textured sphere (32k triangles; the render call
/// ~850M at 128 spp).
pub(crate) struct KernelGeometry {
    /// Every mesh's triangles, the shapes in [`kernel_order`]; empty where they are read from
    /// the meshes at each hit instead (`unpacked` false, see [`Self::triangle`]).
    tris: Vec<Tri>,
    /// Whether `tris` holds the triangles.
    unpacked: bool,
    /// How many triangles the meshes have: the kernel's indices below it name one.
    triangles: u32,
    /// Each mesh's first index of the kernel's and its shape, in [`kernel_order`].
    meshes: Vec<(u32, u32)>,
    /// How many of `tris` are the static shapes' (the packet tree holds those, a prefix).
    static_triangles: usize,
    /// Per light of the scene: a mesh area light's triangles, else None.
    light_tris: Vec<Option<Arc<[LightTri]>>>,
}

/// [`KernelGeometry`]'s key tags: a static shape's index as it is, a moving shape's and a
/// light's with these bits, and every entry's with [`ON_DEMAND_TAG`] where the triangles are
/// not unpacked (no scene has 2^29 shapes or lights).
const MOVING_TAG: u32 = 1 << 31;
const LIGHT_TAG: u32 = 1 << 30;
const ON_DEMAND_TAG: u32 = 1 << 29;

/// Triangle records of at least this many bytes in all are prefetched before shading (see
/// [`KernelGeometry::prefetch_hits`]); below it (about an L2 cache) they are likely cached.
const PREFETCH_HITS_MIN_BYTES: usize = 1 << 20;

impl KernelGeometry {
    /// Asks for the records of the lanes' hit triangles ahead of shading them. In a large mesh
    /// each is a miss at a random place of a large array (a third of the shading's samples on
    /// the 1M-triangle bench scene); shading takes the lanes one after the other, each long
    /// enough that a lane's miss waited alone. Asked for together, the misses overlap.
    #[inline(always)]
    fn prefetch_hits(&self, prim: &[u32; LANES], active: u8) {
        if std::mem::size_of_val(&self.tris[..]) < PREFETCH_HITS_MIN_BYTES {
            return;
        }
        for (l, &p) in prim.iter().enumerate() {
            if active & (1 << l) != 0 {
                if let Some(tri) = self.tris.get(p as usize) {
                    // + 63: a record that starts inside a line may reach two lines on.
                    crate::accel::prefetch(tri as *const Tri, std::mem::size_of::<Tri>() + 63);
                }
            }
        }
    }

    /// Where the triangles are read from the meshes at each hit ([`Self::read`]), asks for
    /// what reading the lanes' hit triangles loads: their indices first, all lanes', then
    /// (once the first has come) the corners, vertex normals and flat entries they lead to.
    /// In a large mesh each is a miss at a random place; read lane after lane, a hit waited
    /// for its indices, then for its corners (`TriangleMesh::shading` 6.7 % of a 16 spp
    /// render of the 1M-triangle bench scene).
    #[inline(always)]
    fn prefetch_reads(&self, scene: &Scene, prim: &[u32; LANES], active: u8) {
        // Below this many bytes of indices, the meshes are likely cached.
        if self.unpacked || (self.triangles as usize) * std::mem::size_of::<[u32; 3]>() < PREFETCH_HITS_MIN_BYTES {
            return;
        }
        let mesh = |p: u32| {
            let (si, t) = self.mesh_of(p)?;
            let s = &scene.shapes[si];
            match &*s.geometry {
                Geometry::Mesh(m) => Some((s, m, t)),
                _ => None,
            }
        };
        // An element's first and last byte: one line, or the two it straddles.
        #[inline(always)]
        fn ask<T>(p: *const T) {
            crate::accel::prefetch(p, 1);
            crate::accel::prefetch((p as *const u8).wrapping_add(std::mem::size_of::<T>() - 1), 1);
        }
        // Each lane's mesh found once (a search of the mesh starts), used by both passes.
        let hit: [_; LANES] = std::array::from_fn(|l| if active & (1 << l) != 0 { mesh(prim[l]) } else { None });
        for &(_, m, t) in hit.iter().flatten() {
            ask(m.indices.as_ptr().wrapping_add(t));
        }
        for &(s, m, t) in hit.iter().flatten() {
            let Some(idx) = m.indices.get(t) else { continue };
            for &i in idx {
                ask(m.positions.as_ptr().wrapping_add(i as usize));
                if !m.normals.is_empty() {
                    ask(m.normals.as_ptr().wrapping_add(i as usize));
                }
            }
            if !s.flat.is_empty() {
                ask(s.flat.as_ptr().wrapping_add(t));
            }
        }
    }

    /// The kept one when the scene's meshes and lights have the same geometry, else unpacked
    /// and kept. It depends on the shapes' geometry, their order ([`kernel_order`]: which
    /// ones move) and the lights' geometry only (the shapes' `flat` tables are the meshes'),
    /// which the key holds. `unpack`: with every triangle unpacked (the packet tree needs
    /// them); else the triangles are read from the meshes where rays hit them, unless the
    /// kept one has them unpacked.
    fn of(scene: &Scene, unpack: bool) -> Arc<KernelGeometry> {
        let mut key = KernelGeometry::key(scene);
        if !unpack {
            if let Some(kept) = scene.kernel_geometry.get(&key) {
                return kept;
            }
            key.iter_mut().for_each(|(tag, _)| *tag |= ON_DEMAND_TAG);
        }
        scene.kernel_geometry.get_or_build(&key, || KernelGeometry::unpack(scene, unpack))
    }

    /// The geometry it is unpacked from, tagged (the key of `Scene::kernel_geometry`).
    fn key(scene: &Scene) -> Vec<(u32, &Arc<Geometry>)> {
        let moving = |si: usize| scene.moving.iter().any(|mv| mv.shape as usize == si);
        let mut key: Vec<(u32, &Arc<Geometry>)> = kernel_order(scene)
            .filter(|&si| matches!(&*scene.shapes[si].geometry, Geometry::Mesh(_)))
            .map(|si| (si as u32 | if moving(si) { MOVING_TAG } else { 0 }, &scene.shapes[si].geometry))
            .collect();
        key.extend(scene.lights.iter().enumerate().filter_map(|(li, l)| match l {
            Light::Area(a) if matches!(&*a.geometry, Geometry::Mesh(_)) => Some((li as u32 | LIGHT_TAG, &a.geometry)),
            _ => None,
        }));
        key
    }

    /// The mesh lights' triangles, and the meshes' too where `unpack_tris`.
    fn unpack(scene: &Scene, unpack_tris: bool) -> KernelGeometry {
        let triangles: usize = scene.shapes.iter().map(|s| if let Geometry::Mesh(m) = &*s.geometry { m.triangle_count() } else { 0 }).sum();
        // Written once into a vector of the final size: with a million triangles this
        // unpacking is a visible part of the render's time, its page faults as much as the
        // writes. (On huge pages it cost 0.13-0.39 s instead of 0.18-0.20 s on mesh1m: the
        // kernel's compaction for them, in the render call.)
        let mut tris = Vec::with_capacity(if unpack_tris { triangles } else { 0 });
        let mut meshes = Vec::new();
        let mut n = 0usize;
        // Plain loops: `extend` over a `flat_map` took 70 more instructions a triangle.
        // Static shapes' first: the packet tree holds those (`kernel_order`).
        let mut static_triangles = None;
        for si in kernel_order(scene) {
            let s = &scene.shapes[si];
            if static_triangles.is_none() && scene.moving.iter().any(|mv| mv.shape as usize == si) {
                static_triangles = Some(n);
            }
            let Geometry::Mesh(m) = &*s.geometry else { continue };
            meshes.push((n as u32, si as u32));
            n += m.triangle_count();
            if unpack_tris {
                for t in 0..m.triangle_count() {
                    tris.push(Tri::of(s, m, si, t));
                }
            }
        }
        let light_tris = scene
            .lights
            .iter()
            .map(|l| match l {
                Light::Area(a) => match &*a.geometry {
                    Geometry::Mesh(m) => Some(
                        (0..m.triangle_count())
                            .map(|t| {
                                let [p0, p1, p2] = m.vertices(t);
                                ([p0, p1 - p0, p2 - p0], crate::light::area::constant_normal(m, t).ok_or_else(|| m.shading(t)))
                            })
                            .collect(),
                    ),
                    _ => None,
                },
                _ => None,
            })
            .collect();
        KernelGeometry { static_triangles: static_triangles.unwrap_or(n), tris, unpacked: unpack_tris, triangles: n as u32, meshes, light_tris }
    }

    /// The meshes of the shapes `keep` takes, as (first triangle of the kernel's, count, shape).
    fn texel_meshes(&self, keep: impl Fn(u32) -> bool) -> Vec<(u32, u32, u32)> {
        let end = |k: usize| self.meshes.get(k + 1).map_or(self.triangles, |&(f, _)| f);
        self.meshes.iter().enumerate().filter(|&(_, &(_, si))| keep(si)).map(|(k, &(f, si))| (f, end(k) - f, si)).collect()
    }

    /// Whether `prim` (a lane's hit) names a triangle of the kernel's.
    #[inline(always)]
    fn is_triangle(&self, prim: u32) -> bool {
        prim < self.triangles
    }

    /// The shape whose mesh holds the kernel's triangle `prim`, and the triangle's index in
    /// it; None where `prim` names no triangle.
    #[inline(always)]
    fn mesh_of(&self, prim: u32) -> Option<(usize, usize)> {
        if !self.is_triangle(prim) {
            return None;
        }
        // The last mesh that starts at or before `prim` (the first starts at 0).
        let (first, si) = self.meshes[self.meshes.partition_point(|&(f, _)| f <= prim) - 1];
        Some((si as usize, (prim - first) as usize))
    }

    /// The kernel's triangle `prim` where the triangles are unpacked; else None (and where it
    /// names none: a ray that escaped, or hit a shape that is not a mesh).
    #[inline(always)]
    fn unpacked_triangle(&self, prim: u32) -> Option<&Tri> {
        self.tris.get(prim as usize)
    }

    /// The kernel's triangle `prim` read from its mesh (None where it names none). Scenes
    /// that trace single rays need no packet tree, and their rays may hit few of the
    /// triangles: reading those costs less than unpacking all (bsdf_spheres' grid: 325k
    /// triangles, ~300 instructions each, a sixth of a 128 spp render call). Out of line: the
    /// kernel's loop stays that of unpacked triangles.
    #[inline(never)]
    fn read(&self, scene: &Scene, prim: u32) -> Option<Tri> {
        let (si, t) = self.mesh_of(prim)?;
        let s = &scene.shapes[si];
        let Geometry::Mesh(m) = &*s.geometry else { return None };
        Some(Tri::of(s, m, si, t))
    }
}

impl Tri {
    /// Triangle `t` of shape `si` (`s`, of mesh `m`).
    #[inline(always)]
    fn of(s: &crate::scene::Shape, m: &crate::geometry::TriangleMesh, si: usize, t: usize) -> Tri {
        let shading = TriangleFrame::new(s.flat.get(t).copied().flatten(), m, t);
        Tri { p: m.vertices(t), shading, shape: si as u32, local: t as u32 }
    }
}

/// Scenes with more triangles than this are large: their packets check ties. (They took the
/// kernel on a first render only with Lambertian materials until the kernel had lanes for
/// rough dielectrics, plastics and conductors; on bsdf_spheres' single sphere, 32k triangles,
/// the kernel then took 0.50-0.80 of the scalar tracer's render CPU and 0.65-0.90 of its
/// whole process at 128 spp, the same bits.)
const LARGE_TRIANGLES: usize = 20_000;
/// Scenes with more triangles than this trace one ray at a time (see [`Tracer`]). Between
/// [`LARGE_TRIANGLES`] and this, packets still won: bsdf_spheres' textured sphere (32k
/// triangles, depth 2: a lane's eight camera rays share a pixel, its shadow and bounce rays
/// leave a patch of the sphere) took 0.86 of the single rays' instructions, that sphere on a
/// floor at depth 6 0.95; with a second sphere (64k triangles) packets took 1.10 of them.
const PACKET_MAX_TRIANGLES: usize = 40_000;
/// Scenes that trace single rays unpack their triangles only when their render takes more
/// camera samples than this per triangle (see [`SimdKernel::new`]).
const UNPACK_SAMPLES_PER_TRIANGLE: u64 = 3;
/// Scenes with more analytic spheres than this trace one ray at a time: a packet tests every
/// sphere on every lane, where the scene's BVH walks a hierarchy of them.
const PACKET_MAX_SPHERES: usize = 16;

/// How the kernel traces its eight rays.
enum Tracer {
    /// As one packet through a BVH of the kernel's own: wins while the eight walks share
    /// most of their nodes (scenes up to [`PACKET_MAX_TRIANGLES`]). With `ties` (the kernel's index of each shape's
    /// first triangle), the lanes whose nearest hit ties with another triangle's are traced
    /// again through the scene's BVH, so that they take the triangle the scalar tracer takes
    /// (see [`SimdKernel::new`]). `spheres`: the scene's analytic spheres, tested on all
    /// lanes after the triangles (as the scene's BVH does), with the scene shape of each;
    /// a lane the spheres leave unsure is traced again through the scene's BVH (then `ties`
    /// is always there).
    Packets { bvh: Arc<PacketBvh>, ties: Option<Vec<u32>>, spheres: Option<Box<(PacketSpheres, Vec<u32>)>> },
    /// One by one through the scene's wide BVH: in a large scene eight incoherent rays share
    /// few nodes, and a packet pays for the union of their walks; the only way to shapes
    /// other than meshes. `first`: the kernel's index of each shape's first triangle
    /// ([`NOT_MESH`] for a shape of no triangles of the kernel's).
    Single { first: Vec<u32>, records: HitRecords },
    /// One by one through the scene's own queries (`Scene::closest`, `occluded_ray`), each
    /// lane's ray at its path's time: scenes with a ray epsilon, and scenes with moving shapes
    /// that would trace single rays. `first` as in `Single`.
    Scene { first: Vec<u32> },
}

/// `Tracer::Single`'s `first` of a shape that is not a mesh (sphere, SDF grid).
const NOT_MESH: u32 = u32::MAX;

/// `Hits8::prim` of a lane whose ray hit a shape that is not a mesh; its shape and primitive
/// are then in the lane's [`OtherHits`] entry.
const OTHER: u32 = u32::MAX - 1;

/// Per lane, a hit on a shape that is not a mesh: its (shape, primitive), and its surface
/// record where the tracer made it already (a moving shape's, in the pose of the ray's time).
struct OtherHits {
    prim: [(u32, u32); LANES],
    record: [Option<SurfaceInteraction>; LANES],
}

impl Default for OtherHits {
    fn default() -> Self {
        OtherHits { prim: [(0, 0); LANES], record: [None; LANES] }
    }
}

impl Tracer {
    /// The lanes' closest hits (lane `l`'s ray at time `time[l]`); a hit on a shape that is
    /// not a mesh has `prim` [`OTHER`] and its shape and primitive (or record) in `others`.
    /// Packets meet the static shapes; moving ones (in scenes that have them) are tried after
    /// them lane by lane, as `Scene::closest` tries them after the scene's BVH.
    fn intersect(&self, scene: &Scene, rays: &Rays8, time: &[f32; LANES], active: u8, others: &mut OtherHits) -> Hits8 {
        if let Tracer::Scene { first } = self {
            return scene_hits(scene, rays, time, active, first, others);
        }
        let mut h = self.static_hits(scene, rays, active, others);
        if !scene.moving.is_empty() {
            for l in (0..LANES).filter(|l| active & (1 << l) != 0) {
                let ray = timed_ray(rays, time, l);
                if let Some((hit, moving)) = scene.closest_moving(&ray, h.t[l]) {
                    (h.t[l], h.prim[l], h.b1[l], h.b2[l]) = (hit.t, OTHER, hit.b1, hit.b2);
                    others.record[l] = Some(scene.closest_interaction(&hit, Some(&moving), &ray));
                }
            }
        }
        h
    }

    /// [`Self::intersect`] on the static shapes (every tracer but `Scene`).
    fn static_hits(&self, scene: &Scene, rays: &Rays8, active: u8, others: &mut OtherHits) -> Hits8 {
        // The lanes to trace through the scene's BVH: a packet's tied ones, or all.
        let (mut h, lanes, first) = match self {
            Tracer::Packets { bvh, ties: None, .. } => return bvh.intersect(rays, active),
            Tracer::Packets { bvh, ties: Some(first), spheres: None } => {
                let (h, tied) = bvh.intersect_ties(rays, active);
                (h, tied, first)
            }
            Tracer::Packets { bvh, ties: Some(first), spheres: Some(sp) } => {
                let (spheres, shapes) = &**sp;
                let (mut h, tied) = bvh.intersect_ties(rays, active);
                // The tied lanes go to the scene's BVH whole: no need to test their spheres.
                let (ids, unsure) = spheres.nearest(rays, active & !tied, &mut h.t);
                for l in (0..LANES).filter(|&l| ids[l] != u32::MAX) {
                    others.prim[l] = (shapes[ids[l] as usize], 0);
                    (h.prim[l], h.b1[l], h.b2[l]) = (OTHER, 0.0, 0.0);
                }
                (h, tied | unsure, first)
            }
            Tracer::Single { first, .. } | Tracer::Scene { first } => {
                (Hits8 { t: rays.t_max, prim: [u32::MAX; LANES], b1: [0.0; LANES], b2: [0.0; LANES] }, active, first)
            }
        };
        if lanes == 0 {
            return h;
        }
        let records = if let Tracer::Single { records, .. } = self { records } else { &HitRecords::NONE };
        // The walks read the lanes' rows and write each lane's hit here as they finish it.
        scene.accel.intersect_lanes_with(rays, lanes, records, |l, hit| {
            let l = l & (LANES - 1);
            let Some(hit) = hit else {
                (h.t[l], h.prim[l], h.b1[l], h.b2[l]) = (rays.t_max[l], u32::MAX, 0.0, 0.0);
                return;
            };
            // The BVH's shape ids index the static shapes where some move.
            let shape = scene.static_shapes.get(hit.shape as usize).copied().unwrap_or(hit.shape);
            h.prim[l] = match first[shape as usize] {
                NOT_MESH => {
                    others.prim[l] = (shape, hit.prim);
                    OTHER
                }
                f => f + hit.prim,
            };
            (h.t[l], h.b1[l], h.b2[l]) = (hit.t, hit.b1, hit.b2);
        });
        h
    }

    /// Mask of the active lanes whose ray is blocked (lane `l`'s at time `time[l]`): by a
    /// static shape, else (in scenes that have them) by a moving one, as `Scene::occluded_ray`.
    fn occluded(&self, scene: &Scene, rays: &Rays8, time: &[f32; LANES], active: u8) -> u8 {
        let blocked = self.occluded_static(scene, rays, time, active);
        if scene.moving.is_empty() || matches!(self, Tracer::Scene { .. }) {
            return blocked;
        }
        (0..LANES).filter(|&l| (active & !blocked) & (1 << l) != 0 && rays.t_max[l] > 0.0).fold(blocked, |m, l| {
            if scene.occluded_moving(&timed_ray(rays, time, l)) {
                m | 1 << l
            } else {
                m
            }
        })
    }

    /// [`Self::occluded`] by the static shapes (by every shape with `Scene`).
    fn occluded_static(&self, scene: &Scene, rays: &Rays8, time: &[f32; LANES], active: u8) -> u8 {
        match self {
            Tracer::Packets { bvh, spheres: None, .. } => bvh.occluded(rays, active),
            Tracer::Packets { bvh, spheres: Some(sp), .. } => {
                let spheres = &sp.0;
                let blocked = bvh.occluded(rays, active);
                let (hit, unsure) = spheres.occluded(rays, active & !blocked);
                let again = if unsure != 0 { scene.accel.occluded_lanes_of(rays, unsure) } else { 0 };
                blocked | (hit & !unsure) | again
            }
            Tracer::Single { .. } => scene.accel.occluded_lanes_of(rays, active),
            Tracer::Scene { .. } => {
                (0..LANES).filter(|&l| active & (1 << l) != 0).fold(0, |m, l| if scene.occluded_ray(&timed_ray(rays, time, l)) { m | 1 << l } else { m })
            }
        }
    }
}

/// [`Tracer::Scene`]'s closest hits: each active lane's through `Scene::closest` at its time.
/// A static mesh's hit names the kernel's triangle; any other comes with the scene's record.
#[inline(never)]
fn scene_hits(scene: &Scene, rays: &Rays8, time: &[f32; LANES], active: u8, first: &[u32], others: &mut OtherHits) -> Hits8 {
    let mut h = Hits8 { t: rays.t_max, prim: [u32::MAX; LANES], b1: [0.0; LANES], b2: [0.0; LANES] };
    for l in (0..LANES).filter(|l| active & (1 << l) != 0) {
        let ray = timed_ray(rays, time, l);
        let Some((hit, moving)) = scene.closest(&ray) else { continue };
        (h.t[l], h.b1[l], h.b2[l]) = (hit.t, hit.b1, hit.b2);
        h.prim[l] = match (first[hit.shape as usize], &moving) {
            (f, None) if f != NOT_MESH => f + hit.prim,
            _ => {
                others.record[l] = Some(scene.closest_interaction(&hit, moving.as_ref(), &ray));
                OTHER
            }
        };
    }
    h
}

/// The scene's shapes in the order the kernel keeps their triangles: the static ones, then
/// the moving ones (so that the packet tree holds the static triangles, a prefix).
fn kernel_order(scene: &Scene) -> impl Iterator<Item = usize> + '_ {
    let mut moves = vec![false; scene.shapes.len()];
    for mv in &scene.moving {
        if let Some(m) = moves.get_mut(mv.shape as usize) {
            *m = true;
        }
    }
    let (fixed, moving): (Vec<usize>, Vec<usize>) = (0..scene.shapes.len()).partition(|&i| !moves[i]);
    fixed.into_iter().chain(moving)
}

/// The kernel's index of each shape's first triangle.
fn first_triangles(scene: &Scene) -> Vec<u32> {
    let mut first = vec![NOT_MESH; scene.shapes.len()];
    let mut n = 0u32;
    for si in kernel_order(scene) {
        if let Geometry::Mesh(m) = &*scene.shapes[si].geometry {
            first[si] = n;
            n += m.triangle_count() as u32;
        }
    }
    first
}

fn single_tracer(scene: &Scene, geometry: &KernelGeometry) -> Tracer {
    let first = first_triangles(scene);
    // What shading reads first at a hit (the unpacked record, else the mesh's index row),
    // asked for by the walks as they find it; as `KernelGeometry::prefetch_hits`, not below
    // an L2 cache's worth of records.
    let records = if geometry.unpacked {
        if std::mem::size_of_val(&geometry.tris[..]) < PREFETCH_HITS_MIN_BYTES {
            HitRecords::NONE
        } else {
            let shape_first = |shape: u32| {
                let si = scene.static_shapes.get(shape as usize).copied().unwrap_or(shape);
                first.get(si as usize).filter(|&&f| f != NOT_MESH).map(|&f| geometry.tris.as_ptr().wrapping_add(f as usize) as *const u8)
            };
            scene.accel.hit_records(std::mem::size_of::<Tri>(), std::mem::size_of::<Tri>(), shape_first)
        }
    } else if (geometry.triangles as usize) * std::mem::size_of::<[u32; 3]>() < PREFETCH_HITS_MIN_BYTES {
        HitRecords::NONE
    } else {
        let rows = |shape: u32| {
            let si = scene.static_shapes.get(shape as usize).copied().unwrap_or(shape);
            match scene.shapes.get(si as usize).map(|s| &*s.geometry) {
                Some(Geometry::Mesh(m)) => Some(m.indices.as_ptr() as *const u8),
                _ => None,
            }
        };
        scene.accel.hit_records(std::mem::size_of::<[u32; 3]>(), std::mem::size_of::<[u32; 3]>(), rows)
    };
    Tracer::Single { first, records }
}

fn lane_ray(rays: &Rays8, l: usize) -> Ray {
    Ray::with_max(Vec3::new(rays.o[0][l], rays.o[1][l], rays.o[2][l]), Vec3::new(rays.d[0][l], rays.d[1][l], rays.d[2][l]), rays.t_max[l])
}

fn timed_ray(rays: &Rays8, time: &[f32; LANES], l: usize) -> Ray {
    Ray { time: time[l], ..lane_ray(rays, l) }
}

/// Everything the kernel needs of a qualifying scene.
pub struct SimdKernel {
    tracer: Tracer,
    /// The unpacked triangles and mesh lights, shared with the scene's next renders.
    geometry: Arc<KernelGeometry>,
    shapes: Vec<ShapeData>,
    /// Per light of the scene: a mesh area light unpacked, or None for a light the lanes
    /// sample through its own `Light::sample_li` (point, spot, directional, environment).
    lights: Vec<Option<MeshLight>>,
    /// Per light of the scene: a sphere area light of constant radiance, which the lanes
    /// sample without `Light::sample_li`'s dispatch, all lanes at once (`sphere_samples`).
    sphere_lights: Vec<Option<(Sphere, Rgb)>>,
    /// The scene's light that is a large environment map (`EnvMap::large`), which the lanes
    /// sample all at once (`env_samples`).
    env_light: Option<usize>,
    /// Whether some shape's texels are asked for ahead of shading (`prefetch_texels`; with
    /// the triangles unpacked, whose uvs it reads).
    prefetch_texels: bool,
    /// The kernel's triangles of those shapes, as (first, count, shape) per mesh: a lane's
    /// hit is tested against these ranges, not searched for among all meshes.
    texel_meshes: Vec<(u32, u32, u32)>,
    /// Run the AVX-512VL build of the kernel (detected at run time; tests may clear it).
    avx512: bool,
    /// Packets a tile steps in phase: [`PACKETS`] where lane groups of rough plastics,
    /// conductors or dielectrics are filled, [`CHAIN_PACKETS`] where Beckmann normals or
    /// sphere-light samples (latency chains for a few lanes a step) are drawn, else one (the second
    /// packet's longer drain at a tile's end and its bookkeeping cost 2 % more instructions
    /// on cbox-rgb, for nothing to overlap).
    packets: usize,
    /// Whether some shape may have a Beckmann rough plastic (`plastic_samples`).
    plastics: bool,
    /// Whether some shape may have a GGX rough plastic (`ggx_plastic_samples`).
    ggx_plastics: bool,
    /// Whether some shape may have a GGX rough conductor (`ggx_conductor_samples`).
    ggx_conductors: bool,
    /// Whether some shape may have a Beckmann rough dielectric (`dielectric_samples`).
    dielectrics: bool,
    /// Whether some shape emits (`detail_scatter` then keeps its lane's `Bsdf` for MIS).
    emitters: bool,
    /// Whether some shape is a rough conductor of the conductor route (`conductor_scatter`).
    conductor_route: bool,
}

/// The reflectance of a diffuse model (a constant one clamped as `Material::bsdf` does).
/// The albedos of a material the kernel shades itself (Lambertian, on one side or two).
fn lambert_sides(m: &Material) -> Option<(Albedo, Option<Albedo>)> {
    match m {
        Material::TwoSided { front, back } => diffuse_albedo(front).zip(diffuse_albedo(back).map(Some)),
        m => diffuse_albedo(m).map(|f| (f, None)),
    }
}

fn diffuse_albedo(m: &Material) -> Option<Albedo> {
    match m {
        Material::Diffuse { reflectance: Texture::Constant(c) } => Some(Albedo::Constant(c.clamp(0.0, 1.0))),
        Material::Diffuse { reflectance } => Some(Albedo::Textured(reflectance.clone())),
        _ => None,
    }
}

fn area_of(scene: &Scene, li: u32) -> Option<&AreaLight> {
    match scene.lights.get(li as usize)? {
        Light::Area(a) => Some(a),
        _ => None,
    }
}

impl SimdKernel {
    /// The kernel's data, or None when the scene or the settings are out of its scope.
    pub fn new(scene: &Scene, settings: &RenderSettings) -> Option<SimdKernel> {
        // One environment at most: a lane adds what its escaped ray sees as one contribution.
        if scene.environment_lights.len() > 1 {
            return None;
        }
        let triangles: usize = scene.shapes.iter().map(|s| if let Geometry::Mesh(m) = &*s.geometry { m.triangle_count() } else { 0 }).sum();
        let large = triangles > LARGE_TRIANGLES;
        // The packet BVH holds triangles only: a few spheres are tested on all lanes beside it
        // (`PacketSpheres`), other shapes (SDF grids) are met through the scene's BVH.
        // (Moving spheres are met with the other moving shapes, after the packets.)
        let spheres: Vec<(crate::geometry::Sphere, u32)> = scene
            .shapes
            .iter()
            .enumerate()
            .filter(|(i, _)| !scene.moving.iter().any(|mv| mv.shape as usize == *i))
            .filter_map(|(i, s)| if let Geometry::Sphere(sp) = &*s.geometry { Some((*sp, i as u32)) } else { None })
            .collect();
        let grids = scene.shapes.iter().any(|s| matches!(&*s.geometry, Geometry::SdfGrid(_)));
        let single_rays = triangles > PACKET_MAX_TRIANGLES || grids || spheres.len() > PACKET_MAX_SPHERES;
        // Whether rays go one by one (through the scene's BVH or its own queries): then no
        // packet tree is built.
        let scene_rays = single_rays || scene.settings.ray_epsilon > 0.0;
        // Whether the triangles are unpacked: for the packet tree, and where rays may hit
        // triangles several times over. A triangle read from its mesh where a ray hit it
        // cost about a cache miss more than an unpacked one (its index, then its corners),
        // ~55 ns; unpacking ~200 ns a triangle. On the 1M-triangle sphere on a floor (depth
        // 6, 64 spp, 256², 4 camera samples a triangle) reading took 1.05 the time of
        // unpacking; on bsdf_spheres' grid (depth 2, a quarter of the camera rays hit
        // anything, 128 spp: 0.9 camera samples a triangle) 0.83 (environment map) and 0.94
        // (area light), and about the same as unpacking at 1024 spp (7 a triangle).
        let camera_samples = scene.camera.width as u64 * scene.camera.height as u64 * settings.spp as u64;
        let unpack = !scene_rays || camera_samples > UNPACK_SAMPLES_PER_TRIANGLE * triangles as u64;
        // The mesh lights' (light, 1 / area, distribution, radiance); their triangles come
        // with the rest of the geometry once the scene is in scope.
        let mut mesh_lights = Vec::with_capacity(scene.lights.len());
        for l in &scene.lights {
            let Light::Area(a) = l else {
                mesh_lights.push(None);
                continue;
            };
            // A textured emitter, or one of a shape that is not a mesh (a sphere's samples the
            // cone it subtends), is sampled through its own `sample_li`, as the other lights.
            if !matches!(a.radiance, Texture::Constant(_)) || !matches!(&*a.geometry, Geometry::Mesh(_)) {
                mesh_lights.push(None);
                continue;
            }
            let (Texture::Constant(radiance), Some(dist)) = (&a.radiance, &a.tri_distribution) else { return None };
            if dist.is_empty() {
                return None;
            }
            let pdf_area = if a.area > 0.0 { 1.0 / a.area } else { 0.0 };
            mesh_lights.push(Some((pdf_area, dist, *radiance)));
        }
        // Where paths cross surfaces (dielectrics, masks), a path inside an object meets faces
        // that lie on another surface (a glass box's bottom on the floor) at the same distance:
        // a tie, which each tree breaks by its own order of tests. Packets kept the floor where
        // the scene's BVH kept the glass: a Cornell box with a glass box came out 0.2-0.3 %
        // darker. There the tied lanes take the scene BVH's hit (`Tracer`); elsewhere ties are
        // shared edges and faces hidden inside opaque objects, and the walk skips the check.
        let crossing = scene.materials.iter().any(Material::may_cross);
        let mut shapes = Vec::with_capacity(scene.shapes.len());
        for s in &scene.shapes {
            let mat = scene.materials.get(s.material as usize)?;
            let lambert = lambert_sides(mat);
            // Any other material (or surface detail) by its own scalar code, lane by lane.
            // (A detail over a Lambertian one: `detail_scatter`.)
            let detail = if s.detail { detail_lambert(mat) } else { None };
            // (A rough conductor under a map or of textured parameters: `conductor_scatter`.)
            let conductor = if detail.is_none() { KernelConductor::of(mat, s.detail) } else { None };
            let (scalar_bsdf, (front, back), detail) = match (lambert, detail) {
                (Some(fb), _) if !s.detail => (false, fb, None),
                (_, Some((map, front))) => (true, (front, None), Some(map)),
                _ => (true, (Albedo::Constant(Rgb::BLACK), None), None),
            };
            let textured = detail.is_none() && (matches!(front, Albedo::Textured(_)) || matches!(back, Some(Albedo::Textured(_))));
            let light = match s.light {
                Some(li) => {
                    let a = area_of(scene, li)?;
                    let le = match a.radiance {
                        Texture::Constant(le) => Some(le),
                        _ => None,
                    };
                    Some((li, le))
                }
                None => None,
            };
            let uniform = (scalar_bsdf && !s.detail && conductor.is_none() && mat.is_uniform()).then(|| mat.bsdf(TexPoint::default()));
            let uniform_flags = uniform.as_ref().map_or(LobeFlags::NONE, Bsdf::flags);
            let reads_uv = textured || matches!(light, Some((_, None))) || (scalar_bsdf && uniform.is_none());
            let prefetch_texels = if scalar_bsdf {
                // A normal or bump map's texels (its lanes' `gather` reads them).
                map_of(&detail, &conductor).is_some_and(DetailMap::large_bitmap)
            } else {
                front.large_bitmap() || back.as_ref().is_some_and(Albedo::large_bitmap)
            };
            let principled = scalar_bsdf && !s.detail && uniform.is_none() && matches!(mat, Material::Principled(_));
            shapes.push(ShapeData {
                scalar_bsdf,
                front,
                back,
                textured,
                light,
                uniform,
                uniform_flags,
                reads_uv,
                prefetch_texels,
                detail,
                conductor_fixed: conductor.as_ref().and_then(|c| c.fixed).and_then(|(c, n)| Some((c, n?))),
                conductor,
                principled,
            });
        }
        // The meshes' triangles (other shapes' hits come as the scene's surface records:
        // `other_hit`), the ones of the scene's last render if its geometry is the same.
        let geometry = KernelGeometry::of(scene, unpack);
        let lights = mesh_lights
            .into_iter()
            .zip(&geometry.light_tris)
            .map(|(ml, tris)| {
                let ((pdf_area, dist, radiance), tris) = ml.zip(tris.clone())?;
                Some(MeshLight { pdf_area, tri_distribution: dist.clone(), tris, radiance })
            })
            .collect();
        // Only the packet tree needs the corners apart (single rays use the scene's BVH): the
        // tree over the static meshes, the one of the scene's last render if it has the same.
        let packet_tree = || {
            let verts = || geometry.tris[..geometry.static_triangles].iter().map(|t| t.p).collect::<Vec<_>>();
            scene.packet_tree.get_or_build(&packet_tree_key(scene), || PacketBvh::build(&verts()))
        };
        let tracer = if scene.settings.ray_epsilon > 0.0 || (single_rays && !scene.moving.is_empty()) {
            Tracer::Scene { first: first_triangles(scene) }
        } else if single_rays {
            single_tracer(scene, &geometry)
        } else if spheres.is_empty() {
            // A large scene's tied lanes go to the scene's BVH too: its image stays the one of
            // single rays (which these scenes traced before), bit for bit.
            Tracer::Packets { bvh: packet_tree(), ties: (crossing || large).then(|| first_triangles(scene)), spheres: None }
        } else {
            // Scenes with spheres took single rays, the scalar tracer's image bit for bit: they
            // keep it with the tie check on their triangles (shared edges, which opaque
            // mesh scenes leave to the packet tree) and the spheres' unsure lanes retraced.
            let (geo, shapes): (Vec<_>, Vec<_>) = spheres.into_iter().unzip();
            Tracer::Packets { bvh: packet_tree(), ties: Some(first_triangles(scene)), spheres: Some(Box::new((PacketSpheres::new(&geo), shapes))) }
        };
        let sphere_lights: Vec<_> = scene
            .lights
            .iter()
            .map(|l| match l {
                Light::Area(a) => match (&*a.geometry, &a.radiance) {
                    (Geometry::Sphere(s), Texture::Constant(le)) => Some((*s, *le)),
                    _ => None,
                },
                _ => None,
            })
            .collect();
        let env_light = scene.lights.iter().position(|l| matches!(l, Light::EnvMap(env) if env.large()));
        let prefetch_texels = geometry.unpacked && shapes.iter().any(|s| s.prefetch_texels);
        let texel_meshes = if prefetch_texels { geometry.texel_meshes(|si| shapes[si as usize].prefetch_texels) } else { Vec::new() };
        let chains =
            sphere_lights.iter().any(Option::is_some) || shapes.iter().any(|s| s.uniform.as_ref().is_some_and(|b| b.beckmann_conductor(Vec3::Z).is_some()));
        // A shape whose BSDF is built per hit may be a plastic too.
        let plastics = shapes
            .iter()
            .any(|s| s.scalar_bsdf && s.detail.is_none() && s.conductor.is_none() && s.uniform.as_ref().is_none_or(|b| b.beckmann_plastic(Vec3::Z).is_some()));
        let ggx_plastics = shapes
            .iter()
            .any(|s| s.scalar_bsdf && s.detail.is_none() && s.conductor.is_none() && s.uniform.as_ref().is_none_or(|b| b.ggx_plastic(Vec3::Z).is_some()));
        let ggx_conductors = shapes
            .iter()
            .any(|s| s.scalar_bsdf && s.detail.is_none() && s.conductor.is_none() && s.uniform.as_ref().is_none_or(|b| b.ggx_conductor(Vec3::Z).is_some()));
        let dielectrics = shapes.iter().any(|s| {
            s.scalar_bsdf && s.detail.is_none() && s.conductor.is_none() && s.uniform.as_ref().is_none_or(|b| b.beckmann_dielectric(Vec3::Z).is_some())
        });
        // The lane groups (`group_samples`) take the lanes of all packets: with one packet a GGX
        // plastic group ran ~2.9 lanes on bsdf_spheres' four plastics (128k triangles), with
        // three 5.7 (render Ir -1.9 % at 8 spp), four a little more (-0.5 % more); veach-mis's
        // Beckmann conductors took -1.0 % with four (three before, for their chains). Shapes whose
        // BSDF is built per hit (textures) are not counted: those scenes were not measured so.
        // The conductor route (`conductor_scatter`) pools its lanes across the packets too:
        // with one packet it ran ~3.8 lanes a call, with four ~6.4 (bsdf_spheres).
        let conductor_route = shapes.iter().any(|s| s.conductor.is_some());
        let groups = conductor_route
            || shapes.iter().any(|s| {
                s.scalar_bsdf
                    && s.detail.is_none()
                    && s.uniform.as_ref().is_some_and(|b| {
                        b.ggx_plastic(Vec3::Z).is_some()
                            || b.beckmann_plastic(Vec3::Z).is_some()
                            || b.ggx_conductor(Vec3::Z).is_some()
                            || b.beckmann_dielectric(Vec3::Z).is_some()
                            || b.beckmann_conductor(Vec3::Z).is_some()
                    })
            });
        let packets = if groups {
            PACKETS
        } else if chains {
            CHAIN_PACKETS
        } else {
            1
        };
        // Whether a path may hit an emitting shape (where a detail lane's `Bsdf` is kept for MIS).
        let emitters = shapes.iter().any(|s| s.light.is_some());
        Some(SimdKernel {
            tracer,
            geometry,
            shapes,
            lights,
            sphere_lights,
            env_light,
            prefetch_texels,
            texel_meshes,
            avx512: crate::cpu::avx512(),
            packets,
            plastics,
            ggx_plastics,
            ggx_conductors,
            dielectrics,
            emitters,
            conductor_route,
        })
    }

    /// How many packets of eight paths a tile steps in phase (more than one where the
    /// kernel draws Beckmann normals or sphere-light samples).
    pub fn packets_a_tile(&self) -> usize {
        self.packets
    }

    /// Whether rays go as packets (else one by one through the scene's BVH).
    pub fn uses_packets(&self) -> bool {
        matches!(self.tracer, Tracer::Packets { .. })
    }

    /// Traces one ray at a time through the scene's BVH whatever the scene's size (for
    /// comparisons; `scene` must be the one the kernel was made for).
    pub fn use_single_rays(&mut self, scene: &Scene) {
        self.tracer = if scene.moving.is_empty() && scene.settings.ray_epsilon <= 0.0 {
            single_tracer(scene, &self.geometry)
        } else {
            Tracer::Scene { first: first_triangles(scene) }
        };
    }

    /// Whether the meshes' triangles are unpacked (else each hit reads its triangle from the
    /// mesh).
    pub fn unpacks_triangles(&self) -> bool {
        self.geometry.unpacked
    }

    /// Whether the AVX-512VL build of the kernel runs.
    pub fn uses_avx512(&self) -> bool {
        self.avx512
    }

    /// Chooses the AVX-512VL build (when the CPU has it) or the AVX2 one.
    pub fn set_avx512(&mut self, on: bool) {
        self.avx512 = on && crate::cpu::avx512();
    }

    pub fn render(&self, scene: &Scene, settings: &RenderSettings, progress: &Progress) -> Result<Film> {
        let events = LaneEvents::new(scene, settings.aovs());
        let events = &events;
        // Without a product automaton the lanes cannot route: AOVs are then refused here.
        let routes = settings.aovs().is_empty() || events.view.is_some();
        render_tiles(scene, settings, progress, routes, &|tile: &mut FilmTile, rect: [u32; 4], s0: u32, n: u32| match settings.sampler {
            // One build of the kernel per sampler: each lane's draws inline.
            SamplerKind::Independent => {
                self.render_tile_on_cpu(scene, settings, events, tile, rect, s0, n, IndependentSampler::new(settings.spp, settings.seed))
            }
            SamplerKind::Sobol => self.render_tile_on_cpu(scene, settings, events, tile, rect, s0, n, SobolSampler::new(settings.spp, settings.seed)),
        })
    }

    /// `render_tile` in the build for this CPU.
    #[allow(clippy::too_many_arguments)]
    fn render_tile_on_cpu<S: LaneSampler>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        tile: &mut FilmTile,
        rect: [u32; 4],
        s0: u32,
        n: u32,
        sampler: S,
    ) {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: `avx2()` detects AVX2 at run time, and
            // `avx512` only where AVX-512F and VL were.
            return unsafe {
                if self.avx512 {
                    self.render_tile_avx512(scene, settings, events, tile, rect, s0, n, sampler)
                } else {
                    self.render_tile_avx2(scene, settings, events, tile, rect, s0, n, sampler)
                }
            };
        }
        self.render_tile(scene, settings, events, tile, rect, s0, n, sampler)
    }

    /// `render_tile` compiled for AVX2 (the lanes' scalar shading too: VEX code, no FMA
    /// contraction, so the same results).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn render_tile_avx2<S: LaneSampler>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        tile: &mut FilmTile,
        rect: [u32; 4],
        s0: u32,
        n: u32,
        sampler: S,
    ) {
        self.render_tile(scene, settings, events, tile, rect, s0, n, sampler)
    }

    /// `render_tile` compiled for AVX-512VL: the same 256-bit code with 32 vector registers
    /// instead of 16 (fewer spills in the eight-lane arithmetic); with DQ, the samplers' PCG
    /// steps multiply 64 bits in one instruction (vpmullq) rather than three 32-bit ones.
    ///
    /// # Safety
    /// The CPU must support AVX2, AVX-512F, AVX-512VL and AVX-512DQ.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f,avx512vl,avx512dq")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn render_tile_avx512<S: LaneSampler>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        tile: &mut FilmTile,
        rect: [u32; 4],
        s0: u32,
        n: u32,
        sampler: S,
    ) {
        self.render_tile(scene, settings, events, tile, rect, s0, n, sampler)
    }

    /// Samples `s0..s0 + n` of every pixel of `rect` (the tile's own pixels; the film tile
    /// extends past them by the filter radius), up to [`PACKETS`] packets of eight paths stepped in
    /// phase; a lane whose path ends takes the next camera sample; each lane draws from its
    /// own copy of `sampler`. (Which lane runs which sample does not change its numbers: each
    /// path's sampler restarts at its pixel sample, and its result goes to its job's slot.)
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn render_tile<S: LaneSampler>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        tile: &mut FilmTile,
        rect: [u32; 4],
        s0: u32,
        n: u32,
        sampler: S,
    ) {
        let [x0, y0, x1, y1] = rect;
        let w = x1 - x0;
        let jobs = (w * (y1 - y0) * n) as usize;
        let mut jobs_at = JobCursor { at: (x0, y0, s0), next: 0, rect, s0, n };
        // Every job's slot is written when its path ends, before the film reads it: the
        // worker's slots of earlier tiles serve as they are.
        let mut slots = RESULTS.take();
        if slots.len() < jobs {
            slots.resize(jobs, (Vec2::ZERO, Rgb::BLACK));
        }
        let results = &mut slots[..jobs];
        let aovs = settings.aovs();
        let mut layers = LaneLayers::new(events, aovs, jobs);
        let cam = scene.camera.ray_generator();
        let pinhole = cam.is_pinhole();
        // The tile's packets, each written in place (an array from `array::from_fn` copied
        // each packet, 13 KB, two to four times once the principled slots were added).
        let mut all: Vec<Packet<S>> = Vec::with_capacity(self.packets);
        for _ in 0..self.packets {
            all.push(Packet::new(sampler.clone()));
        }
        let packets = &mut all[..];
        // Camera samples started eight at a time for lanes that fall idle a few a step.
        let mut ahead = CameraAhead::new(sampler.clone());
        let env_map = scene.environment_lights.first().and_then(|&ei| match &scene.lights[ei as usize] {
            Light::EnvMap(env) => Some(&**env),
            _ => None,
        });
        loop {
            for (pk, p) in packets.iter_mut().enumerate() {
                // The lanes that take the next jobs, in lane order: the idle ones, at the
                // tile's end the first of them.
                let left = jobs - jobs_at.next + ahead.len();
                let mut fill = !p.active;
                if left < LANES {
                    let (mut idle, mut first) = (fill, 0u8);
                    for _ in 0..left {
                        first |= idle & idle.wrapping_neg();
                        idle &= idle.wrapping_sub(1);
                    }
                    fill = first;
                }
                if fill == 0 {
                    continue;
                }
                if pinhole && fill == u8::MAX && ahead.len() == 0 {
                    // A whole packet (every step at depth 1): its samplers started, their
                    // numbers drawn side by side, then their rays all eight at once
                    // (`pinhole_lanes`, as `direct`'s: the same bits), each row written whole.
                    let (job, film, r) = jobs_at.camera_eight(&cam, &mut p.st.sampler);
                    p.st.start_lanes(fill, &job, &film, &r.time);
                    for (l, &j) in job.iter().enumerate() {
                        layers.start(pk, l, j);
                    }
                    let rays = &mut p.rays;
                    (rays.o, rays.d, rays.t_max) = (r.o, r.d, r.t_max);
                    p.active = fill;
                    continue;
                }
                while fill != 0 {
                    let l = fill.trailing_zeros() as usize;
                    fill &= fill - 1;
                    if pinhole && ahead.len() == 0 && jobs - jobs_at.next >= LANES {
                        ahead.refill(&mut jobs_at, &cam);
                    }
                    let (job, raster, time) = if let Some(i) = ahead.take() {
                        // The next started sample: its sampler goes on in the lane.
                        p.st.sampler[l].clone_from(&ahead.sampler[i]);
                        let r = &ahead.rays;
                        let (o, d) = (Vec3::new(r.o[0][i], r.o[1][i], r.o[2][i]), Vec3::new(r.d[0][i], r.d[1][i], r.d[2][i]));
                        set_ray(&mut p.rays, l, o, d, r.t_max[i]);
                        (ahead.job[i], Vec2::new(ahead.film[0][i], ahead.film[1][i]), r.time[i])
                    } else {
                        // The tile's last few, or a camera other than a pinhole: one by one.
                        let (x, y, s, job) = jobs_at.take();
                        let (raster, ray) = camera_sample(&cam, &mut p.st.sampler[l], x, y, s);
                        set_ray(&mut p.rays, l, ray.o, ray.d, ray.t_max);
                        (job, raster, ray.time)
                    };
                    p.st.start(l, job, raster, time);
                    layers.start(pk, l, job);
                    p.active |= 1 << l;
                }
            }
            if packets.iter().all(|p| p.active == 0) {
                break;
            }
            for p in packets.iter_mut().filter(|p| p.active != 0) {
                self.trace_and_gather_on_cpu(scene, settings, env_map, p);
            }
            // The sphere lights' and the environment map's samples of all lanes of all packets,
            // then the Beckmann conductors' values toward them and samples (eight lanes a group
            // across the packets): the packets' latency chains side by side. Every packet's
            // sphere arithmetic comes before any packet's lane-by-lane results, whose branches
            // wait on it (lanes not pending compute on what earlier steps left, unread; written
            // in place: `array::from_fn` kept its closure out of line and copied the samples).
            let mut spheres = [None; PACKETS];
            for (o, p) in spheres.iter_mut().zip(packets.iter()) {
                if p.v.sphere_pending != 0 {
                    *o = Some(AreaLight::sample_constant_spheres(&p.v.sphere_q));
                }
            }
            for (p, o) in packets.iter_mut().zip(&spheres) {
                if let Some(o) = o {
                    self.sphere_results(scene, &mut p.v, o);
                }
            }
            for p in packets.iter_mut() {
                self.env_samples(scene, &mut p.v);
            }
            self.conductor_samples(events, packets);
            if self.ggx_conductors {
                self.ggx_conductor_samples(events, packets);
            }
            if self.plastics {
                self.plastic_samples(events, packets);
            }
            if self.ggx_plastics {
                self.ggx_plastic_samples(events, packets);
            }
            if self.dielectrics {
                self.dielectric_samples(events, packets);
            }
            if self.conductor_route {
                self.conductor_scatter(events, packets, layers.on());
            }
            for (pk, p) in packets.iter_mut().enumerate().filter(|(_, p)| p.active != 0) {
                if p.go == 0 && !layers.on() {
                    // No path goes on (every step at depth 1): the shading step's outputs are
                    // read for `go` lanes only, so the ended ones just hand over their sums.
                    p.finish_ends(results);
                } else {
                    self.scatter_and_shade_on_cpu(scene, settings, events, pk, p, &mut layers, results);
                }
            }
        }
        if events.view.is_some() {
            tile.add_samples_touched(results.iter().enumerate().map(|(j, &(raster, l))| {
                let (aov, touched) = layers.row(j);
                (raster, l, aov, touched)
            }));
        } else {
            tile.add_samples(results);
        }
        RESULTS.set(slots);
    }

    /// [`Self::trace_and_gather`] out of line in this CPU's build. (Inlined into the loop over
    /// the packets, every field of the packet was addressed from the packet's index, the
    /// pointers spilled, and `gather` ran 1.7x its time.)
    #[inline(always)]
    fn trace_and_gather_on_cpu<S: LaneSampler>(&self, scene: &Scene, settings: &RenderSettings, env_map: Option<&EnvMap>, p: &mut Packet<S>) {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: `avx2()` detects AVX2 at run time, and `avx512` is set only where
            // AVX-512F and VL were.
            return unsafe {
                if self.avx512 {
                    self.trace_and_gather_avx512(scene, settings, env_map, p)
                } else {
                    self.trace_and_gather_avx2(scene, settings, env_map, p)
                }
            };
        }
        self.trace_and_gather(scene, settings, env_map, p)
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    unsafe fn trace_and_gather_avx2<S: LaneSampler>(&self, scene: &Scene, settings: &RenderSettings, env_map: Option<&EnvMap>, p: &mut Packet<S>) {
        self.trace_and_gather(scene, settings, env_map, p)
    }

    /// # Safety
    /// The CPU must support AVX2, AVX-512F, AVX-512VL and AVX-512DQ.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f,avx512vl,avx512dq")]
    #[inline(never)]
    unsafe fn trace_and_gather_avx512<S: LaneSampler>(&self, scene: &Scene, settings: &RenderSettings, env_map: Option<&EnvMap>, p: &mut Packet<S>) {
        self.trace_and_gather(scene, settings, env_map, p)
    }

    /// A packet's step up to the sphere samples: its rays traced (lanes of `active`) and each
    /// lane's `gather` into `v`; sets the lanes whose paths go on and those that end there.
    #[inline(always)]
    fn trace_and_gather<S: LaneSampler>(&self, scene: &Scene, settings: &RenderSettings, env_map: Option<&EnvMap>, p: &mut Packet<S>) {
        let Packet { st, rays, others, v, active, .. } = p;
        let (active, rays) = (*active, &*rays);
        // A large environment map's grid points of all lanes' rays (eight at once), and
        // their texels asked for before the walk: bounce rays off a convex object escape
        // in all directions, and each lookup in `gather` had waited on memory; now the
        // walk hides the wait (the lanes whose rays hit something ask in vain).
        let env_ahead = env_map.filter(|env| env.large());
        if let Some(env) = env_ahead {
            v.env_grid = env.dirs_to_grid(&rays.d);
            v.env_cells = env.cells_of(&v.env_grid);
            for l in (0..LANES).filter(|l| active & (1 << l) != 0) {
                env.prefetch_in(&v.env_cells, l);
            }
        }
        let hits = self.tracer.intersect(scene, rays, &st.time, active, others);
        self.geometry.prefetch_hits(&hits.prim, active);
        self.geometry.prefetch_reads(scene, &hits.prim, active);
        if self.prefetch_texels {
            self.prefetch_texels(scene, &hits, active, &mut v.uv_ahead);
        }
        // The environment map's grid points of the escaped lanes (those `gather` finds
        // no hit for), all eight at once.
        if let Some(env) = env_map.filter(|_| env_ahead.is_none()) {
            if (0..LANES).any(|l| active & (1 << l) != 0 && hits.prim[l] != OTHER && !self.geometry.is_triangle(hits.prim[l])) {
                v.env_grid = env.dirs_to_grid(&rays.d);
                v.env_cells = env.cells_of(&v.env_grid);
            }
        }
        // Every lane's numbers for this vertex, where the sampler draws them for all lanes
        // at once (a lane that ends before it needs them, or is idle, restarts its sampler
        // with its next camera sample: all eight step, no per-lane write-back test); none at
        // max depth 1, where every path ends at its first vertex. (Asking each lane's depth
        // instead cost Bitterli's box 1.02.)
        let draws = if S::BATCHED && settings.depth_allows(2) { S::vertex_draws(&mut st.sampler, u8::MAX) } else { [[0.0; LANES]; 7] };
        let (mut go, mut ends) = (0u8, 0u8);
        v.late_texels = 0;
        for l in 0..LANES {
            if active & (1 << l) == 0 {
                continue;
            }
            let d = Vec3::new(rays.d[0][l], rays.d[1][l], rays.d[2][l]);
            let other = if hits.prim[l] == OTHER {
                Some(others.record[l].take().unwrap_or_else(|| other_hit(scene, &self.shapes, rays, &hits, others, l)))
            } else {
                None
            };
            if self.gather(scene, settings, st, &draws, l, hits.prim[l], hits.b1[l], hits.b2[l], d, other.as_ref(), v) {
                go |= 1 << l;
            } else {
                ends |= 1 << l;
            }
        }
        if v.late_texels != 0 {
            self.late_texels(v);
        }
        (p.go, p.ends) = (go, ends);
    }

    /// The reflectances `gather` left to look up (`Soa::late_texels`): by now the texels
    /// `prefetch_texels` asked for have come, where a lookup inside `gather` waited on its
    /// own (about a tenth of `trace_and_gather`'s time on the textured sphere).
    #[inline(always)]
    fn late_texels(&self, v: &mut Soa) {
        for l in lanes_of(v.late_texels as u32) {
            let front = self.shapes[v.shape[l] as usize].front.at(&TexPoint::from(v.uv_ahead[l]));
            // As `gather` picks the side (the back is black).
            let fs = v.late_front[l];
            put_rgb(&mut v.num.refl, l, Rgb::new(sel(fs, front.r, 0.0), sel(fs, front.g, 0.0), sel(fs, front.b, 0.0)));
        }
    }

    /// [`Self::scatter_and_shade`] out of line in this CPU's build (as `trace_and_gather_on_cpu`).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn scatter_and_shade_on_cpu<S>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        pk: usize,
        p: &mut Packet<S>,
        layers: &mut LaneLayers,
        results: &mut [(Vec2, Rgb)],
    ) {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: `avx2()` detects AVX2 at run time, and `avx512` is set only where
            // AVX-512F and VL were.
            return unsafe {
                if self.avx512 {
                    self.scatter_and_shade_avx512(scene, settings, events, pk, p, layers, results)
                } else {
                    self.scatter_and_shade_avx2(scene, settings, events, pk, p, layers, results)
                }
            };
        }
        self.scatter_and_shade(scene, settings, events, pk, p, layers, results)
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn scatter_and_shade_avx2<S>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        pk: usize,
        p: &mut Packet<S>,
        layers: &mut LaneLayers,
        results: &mut [(Vec2, Rgb)],
    ) {
        self.scatter_and_shade(scene, settings, events, pk, p, layers, results)
    }

    /// # Safety
    /// The CPU must support AVX2, AVX-512F and AVX-512VL.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f,avx512vl")]
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn scatter_and_shade_avx512<S>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        pk: usize,
        p: &mut Packet<S>,
        layers: &mut LaneLayers,
        results: &mut [(Vec2, Rgb)],
    ) {
        self.scatter_and_shade(scene, settings, events, pk, p, layers, results)
    }

    /// The rest of a packet's step once its sphere samples and Beckmann conductors are in:
    /// the scalar BSDFs' scattering, `shade8`, the shadow rays, the light samples that count;
    /// the samples that end go to their jobs' slots of `results`, and leave `active`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn scatter_and_shade<S>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        events: &LaneEvents,
        pk: usize,
        p: &mut Packet<S>,
        layers: &mut LaneLayers,
        results: &mut [(Vec2, Rgb)],
    ) {
        let Packet { st, rays, shadow, v, o, active, go, ends, .. } = p;
        let (active, go, mut ends) = (*active, *go, *ends);
        let mut lanes = std::mem::take(&mut v.scatter_lanes);
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            self.scalar_scatter(events, st, l, v);
        }
        let mut lanes = std::mem::take(&mut v.princ_lanes);
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            self.principled_scatter(events, st, l, v);
        }
        if v.detail_lanes != 0 {
            self.detail_scatter(events, st, v);
        }
        // (`v.cond_lanes` were taken by `conductor_scatter` across the packets.)
        // Writes every lane's next ray, shadow ray and state; only `go` lanes' count.
        self.shade8_on_cpu(v, settings.rr_depth, st, rays, shadow, o);
        // The `go` lanes' light samples that count now (1) or once their shadow ray is clear
        // (2), and those whose path ends: masks from whole rows (a branch per lane on each
        // mispredicted where the lanes differ).
        // (`nee` is 0, 1 or 2 a lane: a byte's bit 0 says 1, its bit 1 says 2. Compared as
        // bytes, its two masks took about 90 instructions.)
        debug_assert!(o.nee.iter().all(|&n| n <= 2));
        let (nee, ones) = (u64::from_le_bytes(o.nee), u64::from_le_bytes([1; LANES]));
        let counted = go & byte_lanes(nee & ones);
        let smask = go & byte_lanes((nee >> 1) & ones);
        ends |= go & !lane_bits(&o.cont);
        let clear = smask & !self.tracer.occluded(scene, shadow, &st.time, smask);
        if layers.on() {
            layers.route(pk, v, o, active, counted | clear, go & !ends);
        }
        // The light samples that count (a lane's at most: `counted` and `clear` are apart),
        // all lanes at once as selects: lane-by-lane adds, stored a float at a time, were
        // read back below as one wide load that waited on them (store forwarding).
        // (Both read whole first: read lane by lane, LLVM made the selects branches.)
        let adds = counted | clear;
        let (mut sum, c) = (st.l, o.c);
        for k in 0..3 {
            for l in 0..LANES {
                sum[k][l] = if adds & (1 << l) != 0 { sum[k][l] + c[k][l] } else { sum[k][l] };
            }
        }
        st.l = sum;
        let mut done = ends;
        while done != 0 {
            let l = done.trailing_zeros() as usize;
            done &= done - 1;
            let beauty = Rgb::new(st.l[0][l], st.l[1][l], st.l[2][l]);
            results[st.job[l]] = (st.raster[l], layers.finish(pk, l, beauty));
        }
        p.active &= !ends;
    }

    /// [`shade8`] in its own function of this CPU's build. Inlined into the tile loop, its
    /// loop stayed scalar code (a branch per lane at most selects: `cosine_hemisphere`'s
    /// major axis, `offset3`'s side are coin tosses); in a function of its own it compiles to
    /// eight-lane code with no branch. (`#[inline(never)]`: inlined back, it is scalar again.)
    #[inline(always)]
    fn shade8_on_cpu<S>(&self, v: &Soa, rr_depth: i32, st: &mut Paths<S>, rays: &mut Rays8, shadow: &mut Rays8, o: &mut Out) {
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: `avx2()` detects AVX2 at run time, and `avx512` is set only where
            // AVX-512F and VL were.
            return unsafe {
                if self.avx512 {
                    shade8_avx512(&v.num, rr_depth, &mut st.num, rays, shadow, o)
                } else {
                    shade8_avx2(&v.num, rr_depth, &mut st.num, rays, shadow, o)
                }
            };
        }
        shade8(&v.num, rr_depth, &mut st.num, rays, shadow, o)
    }

    /// The per-lane part of one vertex (as `shade`): emission found, the depth test, the
    /// random numbers, the light and its triangle chosen, and at a material other than a
    /// Lambertian one its scalar BSDF's value toward the light sample and its own sample; the
    /// arithmetic is left in `v` for `shade8`. The hit: triangle `prim` of the kernel's at
    /// (b1, b2), or where `prim` is [`OTHER`], the scene's record `other` of a shape that is
    /// not a mesh. False when the path ends here.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn gather<S: LaneSampler>(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        st: &mut Paths<S>,
        draws: &[[f32; LANES]; 7],
        l: usize,
        prim: u32,
        b1: f32,
        b2: f32,
        d: Vec3,
        other: Option<&SurfaceInteraction>,
        v: &mut Soa,
    ) -> bool {
        st.num.depth[l] += 1;
        let depth = st.num.depth[l];
        v.emitted[l] = false;
        let read;
        let tri = match self.geometry.unpacked_triangle(prim) {
            None if !self.geometry.unpacked => {
                read = self.geometry.read(scene, prim);
                read.as_ref()
            }
            tri => tri,
        };
        let (hit, shape, p, ng, frame) = match (tri, other) {
            (Some(tri), _) => {
                let p = tri.p[0] * (1.0 - b1 - b2) + tri.p[1] * b1 + tri.p[2] * b2;
                let (ng, frame) = tri.shading.at(b1, b2);
                (Hit::Tri(tri), tri.shape, p, ng, frame)
            }
            (None, Some(si)) => (Hit::Other(si), si.shape, si.p, si.ng, si.shading),
            (None, None) => {
                self.escaped(scene, settings, st, l, d, v);
                return false;
            }
        };
        let sh = &self.shapes[shape as usize];
        v.shape[l] = shape;
        let wo_w = -d;
        if let Some((li, le)) = sh.light {
            let hide = depth == 1 && settings.hide_emitters;
            let le = match le {
                Some(le) => {
                    if ng.dot(wo_w) <= 0.0 {
                        Rgb::BLACK
                    } else {
                        le
                    }
                }
                None => area_of(scene, li).map_or(Rgb::BLACK, |a| a.l(ng, self.hit_uv(scene, &hit, b1, b2), wo_w)),
            };
            if !le.is_black() && !hide {
                let w = if st.num.prev_specular[l] {
                    1.0
                } else {
                    let prev_p = Vec3::new(st.num.prev_p[0][l], st.num.prev_p[1][l], st.num.prev_p[2][l]);
                    let pdf_li = area_of(scene, li).map_or(0.0, |a| a.pdf_li(prev_p, p, ng));
                    let pdf_bsdf = match &st.prev_bsdf[l] {
                        // A principled vertex's `Bsdf` (`Scene::bsdf`'s), built only here.
                        Some(pb) if self.shapes[pb.shape as usize].principled => match st.prev_princ.get(l) {
                            Some(Some(m)) => bsdf_pdf_toward(&Bsdf::new(m.into_model()), &pb.frame, pb.wo, prev_p, p).unwrap_or(st.num.prev_pdf[l]),
                            _ => st.num.prev_pdf[l],
                        },
                        Some(pb) => match self.shapes[pb.shape as usize].uniform.as_ref().or(st.prev_own[l].as_ref()) {
                            Some(bsdf) => bsdf_pdf_toward(bsdf, &pb.frame, pb.wo, prev_p, p).unwrap_or(st.num.prev_pdf[l]),
                            // Never: a shape without a uniform BSDF left its own in `prev_own`.
                            None => st.num.prev_pdf[l],
                        },
                        None => {
                            // The diffuse BSDF's density toward the hit point, as the scalar
                            // tracer's `bsdf_pdf_toward` (the same operations).
                            let prev_n = Vec3::new(st.num.prev_n[0][l], st.num.prev_n[1][l], st.num.prev_n[2][l]);
                            let dp = p - prev_p;
                            let len = dp.length();
                            if len > 0.0 && len.is_finite() {
                                (dp / len).dot(prev_n).max(0.0) * INV_PI
                            } else {
                                st.num.prev_pdf[l]
                            }
                        }
                    };
                    power_heuristic(1.0, pdf_bsdf, 1.0, scene.light_pmf(li) * pdf_li)
                };
                let beta = Rgb::new(st.num.beta[0][l], st.num.beta[1][l], st.num.beta[2][l]);
                st.add(l, beta * le * w);
                v.emitted[l] = true;
                put_rgb(&mut v.emit, l, beta * le * w);
            }
        }
        if !settings.depth_allows(depth + 1) {
            return false;
        }
        // All of the vertex's numbers, in the scalar order (u_rr is drawn even where the path
        // ends before it: the lane's sampler restarts with its next camera sample).
        let (u_light, u_l2, uc, u, u_rr) = if S::BATCHED {
            (draws[0][l], Vec2::new(draws[1][l], draws[2][l]), draws[3][l], Vec2::new(draws[4][l], draws[5][l]), draws[6][l])
        } else {
            let sampler = &mut st.sampler[l];
            let u_light = sampler.next_1d();
            let u_l2 = sampler.next_2d();
            // Only a scalar BSDF takes the lobe number (a Lambertian lane only steps past it).
            let uc = if sh.scalar_bsdf {
                sampler.next_1d()
            } else {
                sampler.next_1d();
                0.0
            };
            (u_light, u_l2, uc, sampler.next_2d(), sampler.next_1d())
        };
        v.num.u_rr[l] = u_rr;
        let put = |a: &mut [[f32; LANES]; 3], x: Vec3| {
            a[0][l] = x.x;
            a[1][l] = x.y;
            a[2][l] = x.z;
        };
        let putc = |a: &mut [[f32; LANES]; 3], x: Rgb| put_rgb(a, l, x);
        put(&mut v.num.p, p);
        put(&mut v.num.ng, ng);
        put(&mut v.num.fs, frame.s);
        put(&mut v.num.ft, frame.t);
        put(&mut v.num.fnn, frame.n);
        put(&mut v.num.wo, wo_w);
        v.num.scalar_bsdf[l] = sh.scalar_bsdf;
        let late = sh.prefetch_texels && self.prefetch_texels && sh.back.is_none() && matches!(hit, Hit::Tri(_));
        if !sh.scalar_bsdf && late {
            // A large bitmap's reflectance: looked up once every lane is gathered (`late_texels`).
            v.late_front[l] = dot3(wo_w.to_array(), frame.n.to_array()) >= 0.0;
            v.late_texels |= 1 << l;
            v.num.has_back[l] = false;
            v.num.u[0][l] = u.x;
            v.num.u[1][l] = u.y;
            if st.prev_bsdf[l].is_some() {
                st.prev_bsdf[l] = None;
            }
        } else if !sh.scalar_bsdf {
            let (front, back) = if sh.textured {
                // The hit's texture point, as `Scene::interaction` gives it (`SurfaceInteraction::tex_point`).
                let tp = self.tex_point_ahead(scene, sh, v, l, &hit, b1, b2, p, ng);
                (sh.front.at(&tp), sh.back.as_ref().map_or(Rgb::BLACK, |b| b.at(&tp)))
            } else {
                // Constant on both sides. (No texture point made: copying one that was just
                // stored field by field stalled on store forwarding, 1-2 % of veach-mis.)
                (sh.front.constant(), sh.back.as_ref().map_or(Rgb::BLACK, Albedo::constant))
            };
            // The reflectance of the side the path sees (`shade8`'s test of wo's cosine with
            // the shading normal, the same operations), picked here: both sides handed over
            // and picked in `shade8`, LLVM read the side's array per lane there and the
            // AVX-512 copy gathered them (three `vgatherqps`, 7 % of its time). (Both sides
            // evaluated, then selected: a branch on the side mispredicted in the Cornell box.)
            let front_side = dot3(wo_w.to_array(), frame.n.to_array()) >= 0.0;
            let refl = Rgb::new(sel(front_side, front.r, back.r), sel(front_side, front.g, back.g), sel(front_side, front.b, back.b));
            putc(&mut v.num.refl, refl);
            v.num.has_back[l] = sh.back.is_some();
            v.num.u[0][l] = u.x;
            v.num.u[1][l] = u.y;
            if st.prev_bsdf[l].is_some() {
                st.prev_bsdf[l] = None;
            }
        }
        if !sh.scalar_bsdf {
            self.light_sample(scene, l, v, p, u_light, u_l2);
        } else if let Some(map) = &sh.detail {
            // A detail over a Lambertian: its perturbed normal and reflectance, as
            // `Scene::bsdf` builds them, for `detail_scatter`.
            let tp = self.tex_point_ahead(scene, sh, v, l, &hit, b1, b2, p, ng);
            put(&mut v.detail_n, Detail::new(detail_normal(scene, map, shape, tp, &frame, ng), true).n);
            putc(&mut v.num.refl, sh.front.at(&tp));
            v.flags[l] = LobeFlags::DIFFUSE_REFLECTION;
            self.light_sample(scene, l, v, p, u_light, u_l2);
            (v.scatter_u[1][l], v.scatter_u[2][l]) = (u.x, u.y);
            v.detail_lanes |= 1 << l;
        } else if let Some((cond, n)) = sh.conductor_fixed {
            // The same of a conductor route's shape whose conductor and normal do not depend
            // on the hit (`KernelConductor::fixed`): no texture point made.
            put(&mut v.detail_n, n);
            v.cond_detail |= 1 << l;
            v.cond[l] = Some(cond);
            v.flags[l] = LobeFlags::GLOSSY_REFLECTION;
            self.light_sample(scene, l, v, p, u_light, u_l2);
            (v.scatter_u[1][l], v.scatter_u[2][l]) = (u.x, u.y);
            v.cond_lanes |= 1 << l;
        } else if let Some(c) = &sh.conductor {
            // A rough conductor under a map or of textured parameters: the conductor and the
            // perturbed normal, as `Scene::bsdf` builds them, for `conductor_scatter`.
            let tp = self.tex_point_ahead(scene, sh, v, l, &hit, b1, b2, p, ng);
            if let Some(map) = &c.map {
                put(&mut v.detail_n, Detail::new(detail_normal(scene, map, shape, tp, &frame, ng), true).n);
                v.cond_detail |= 1 << l;
            } else {
                v.cond_detail &= !(1 << l);
            }
            v.cond[l] = Some(c.at(tp));
            v.flags[l] = LobeFlags::GLOSSY_REFLECTION;
            self.light_sample(scene, l, v, p, u_light, u_l2);
            (v.scatter_u[1][l], v.scatter_u[2][l]) = (u.x, u.y);
            v.cond_lanes |= 1 << l;
        } else if let Some(pm) = sh.principled.then(|| principled_material(scene, shape)).flatten() {
            let tp = self.tex_point(scene, &hit, b1, b2, p, ng);
            self.principled_light_sample(scene, l, v, pm, tp, u_light, u_l2);
            (v.scatter_u[0][l], v.scatter_u[1][l], v.scatter_u[2][l]) = (uc, u.x, u.y);
            v.princ_lanes |= 1 << l;
        } else {
            // The hit's record only where `Scene::bsdf` builds the hit's own BSDF from it:
            // the rest of the vertex is in `v.num` (a record per lane, built and copied into
            // `Soa` and read back, had been most of a scalar lane's `gather`).
            let si = sh.uniform.is_none().then(|| match hit {
                Hit::Tri(tri) => SurfaceInteraction {
                    p,
                    t: 0.0,
                    ng,
                    shading: frame,
                    uv: self.uv(scene, tri, b1, b2),
                    shape: tri.shape,
                    prim: tri.local,
                    bary: Vec2::new(b1, b2),
                    wo: wo_w,
                    time: st.time[l],
                },
                Hit::Other(si) => *si,
            });
            self.scalar_light_sample(scene, l, v, shape, p, si.as_ref(), u_light, u_l2);
            (v.scatter_u[0][l], v.scatter_u[1][l], v.scatter_u[2][l]) = (uc, u.x, u.y);
            v.scatter_lanes |= 1 << l;
        }
        true
    }

    /// The texture point of a hit at `p` (geometric normal `ng`), as `Scene::interaction`
    /// gives it (`SurfaceInteraction::tex_point`).
    #[inline(always)]
    fn tex_point(&self, scene: &Scene, hit: &Hit, b1: f32, b2: f32, p: Vec3, ng: Vec3) -> TexPoint {
        match hit {
            Hit::Tri(tri) => TexPoint { uv: self.uv(scene, tri, b1, b2), prim: tri.local, bary: Vec2::new(b1, b2), p, n: ng },
            Hit::Other(si) => si.tex_point(),
        }
    }

    /// As [`Self::tex_point`], taking the uv `prefetch_texels` computed for lane `l` where it
    /// did (the same value) for a shape of `sh`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn tex_point_ahead(&self, scene: &Scene, sh: &ShapeData, v: &Soa, l: usize, hit: &Hit, b1: f32, b2: f32, p: Vec3, ng: Vec3) -> TexPoint {
        match hit {
            // (With `prefetch_texels` every triangle hit is an unpacked one, whose uv it took.)
            Hit::Tri(tri) if sh.prefetch_texels && self.prefetch_texels => TexPoint { uv: v.uv_ahead[l], prim: tri.local, bary: Vec2::new(b1, b2), p, n: ng },
            _ => self.tex_point(scene, hit, b1, b2, p, ng),
        }
    }

    /// Lane `l`'s vertex of a BSDF of lobes `flags` at `p`: its light sample where a lobe is not
    /// specular (`light_sample`), else none.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn scalar_vertex_light(&self, scene: &Scene, l: usize, v: &mut Soa, p: Vec3, flags: LobeFlags, u_light: f32, u_l2: Vec2) {
        if flags.has_non_specular() {
            self.light_sample(scene, l, v, p, u_light, u_l2);
        } else {
            v.num.nee_ok[l] = false;
        }
        v.flags[l] = flags;
    }

    /// Lane `l`'s light sample from `p` (as `path::light_sample_unshadowed` up to the BSDF): the light
    /// chosen by `u_light`, its point by `u_l2`; `nee_ok` where it counts so far.
    #[inline(always)]
    fn light_sample(&self, scene: &Scene, l: usize, v: &mut Soa, p: Vec3, u_light: f32, u_l2: Vec2) {
        let put = |a: &mut [[f32; LANES]; 3], x: Vec3| {
            a[0][l] = x.x;
            a[1][l] = x.y;
            a[2][l] = x.z;
        };
        let putc = |a: &mut [[f32; LANES]; 3], x: Rgb| put_rgb(a, l, x);
        v.num.nee_ok[l] = false;
        v.num.generic[l] = false;
        if scene.lights.is_empty() {
            return;
        }
        let (li, pmf, _) = scene.light_distribution.sample_discrete(u_light);
        v.num.pmf[l] = pmf;
        v.light[l] = li as u32;
        match self.lights.get(li) {
            // Any other light by its own sampling (`path::light_sample_unshadowed`'s first tests).
            Some(None) if pmf > 0.0 => {
                // A sphere of constant radiance: with the other lanes' (`sphere_samples`), its
                // operands written into their lanes here (a pass over all lanes that looked
                // each light up again, a branch per lane, cost more than its instructions).
                if let Some((sp, le)) = &self.sphere_lights[li] {
                    v.sphere_pending |= 1 << l;
                    let q = &mut v.sphere_q;
                    for k in 0..3 {
                        q.center[k][l] = sp.center[k];
                        q.p_ref[k][l] = p[k];
                    }
                    q.radius[l] = sp.radius;
                    q.flip[l] = sp.flip_normals;
                    q.u[0][l] = u_l2.x;
                    q.u[1][l] = u_l2.y;
                    v.sphere_le[l] = *le;
                    return;
                }
                if self.env_light == Some(li) {
                    v.env_pending |= 1 << l;
                    v.env_p[l] = p;
                    v.env_u[l] = u_l2;
                    return;
                }
                // A point light inline (through `sample_li`'s dispatch, out of line, its few
                // operations had cost a call and a wait on the point passed in memory).
                if let Light::Point { position, intensity } = &scene.lights[li] {
                    Self::take_light_sample(l, v, crate::light::point_sample_li(*position, *intensity, p), true);
                    return;
                }
                Self::generic_light_sample(scene, l, v, li, p, u_l2);
            }
            // A mesh light: its point, as `MeshLight::sample_li` up to the distance test.
            Some(Some(ml)) if pmf > 0.0 && ml.pdf_area > 0.0 && !ml.radiance.is_black() => {
                let (t, _, ur) = ml.tri_distribution.sample_discrete(u_l2.x);
                let b = warp::square_to_uniform_triangle(Vec2::new(ur, u_l2.y));
                let ([p0, e1, e2], n) = ml.tris[t];
                let n = match n {
                    Ok(n) => n,
                    Err(s) => s.normals_at(b.x, b.y).0,
                };
                put(&mut v.num.lp, p0 + e1 * b.x + e2 * b.y);
                put(&mut v.num.ln, n);
                putc(&mut v.num.lrad, ml.radiance);
                v.num.pdf_area[l] = ml.pdf_area;
                v.num.infinite[l] = false;
                v.num.delta[l] = false;
                v.num.nee_ok[l] = true;
            }
            _ => {}
        }
    }

    /// Lane `l`'s light sample from `p` of light `li` by its own `Light::sample_li`
    /// (`path::light_sample_unshadowed`'s first tests).
    fn generic_light_sample(scene: &Scene, l: usize, v: &mut Soa, li: usize, p: Vec3, u_l2: Vec2) {
        let light = &scene.lights[li];
        Self::take_light_sample(l, v, light.sample_li(p, u_l2, &scene.bounds), light.is_delta());
    }

    /// Lane `l`'s light sample `ls` of a light (`delta`: of a delta light) where it counts.
    #[inline(always)]
    fn take_light_sample(l: usize, v: &mut Soa, ls: Option<LightSample>, delta: bool) {
        if let Some(ls) = ls.filter(|ls| ls.pdf > 0.0 && !ls.li.is_black()) {
            for k in 0..3 {
                v.num.lp[k][l] = ls.p[k];
                v.num.ln[k][l] = ls.n[k];
                v.num.gwi[k][l] = ls.wi[k];
            }
            put_rgb(&mut v.num.lrad, l, ls.li);
            v.num.gpdf[l] = ls.pdf;
            v.num.infinite[l] = ls.infinite;
            v.num.delta[l] = delta;
            v.num.generic[l] = true;
            v.num.nee_ok[l] = true;
        }
    }

    /// The light samples `light_sample` left to the large environment map (`env_pending`
    /// lanes), all lanes' at once: as `generic_light_sample` takes them, drawn stage by stage
    /// across the lanes so that their misses in the map's tables overlap
    /// (`EnvMap::sample_points`: 11 % of test_envmap's samples had been the map's sampling,
    /// most of it waiting on memory).
    #[inline(always)]
    fn env_samples(&self, scene: &Scene, v: &mut Soa) {
        let pending = v.env_pending;
        let Some(li) = self.env_light.filter(|_| pending != 0) else { return };
        v.env_pending = 0;
        let light = &scene.lights[li];
        let Light::EnvMap(env) = light else { return };
        // (`sample_li` returns None before it samples a map it cannot sample.)
        if !env.samples() {
            return;
        }
        let g = env.sample_points(&v.env_u, pending as u32);
        // The points' directions, all lanes' at once (vector code; unused lanes' unread).
        let (d, sin_t) = env.grid_to_dirs(&g);
        let mut lanes = pending;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let dir = (Vec3::new(d[0][l], d[1][l], d[2][l]), sin_t[l]);
            let ls = Light::sample_li_env_at(env, v.env_p[l], g[l], dir, &scene.bounds);
            Self::take_light_sample(l, v, ls, light.is_delta());
        }
    }

    /// The light samples `light_sample` left to a sphere of constant radiance (`sphere_pending`
    /// lanes) into `v`: `o`, all lanes' at once as `sample_li` samples the cone the sphere
    /// subtends (`AreaLight::sample_constant_spheres`, the bits of `sample_constant_sphere`),
    /// or where the point is inside the sphere, its sample by area through `sample_li`.
    #[inline(always)]
    fn sphere_results(&self, scene: &Scene, v: &mut Soa, o: &SphereSamples<LANES>) {
        let pending = v.sphere_pending;
        v.sphere_pending = 0;
        let mut lanes = pending;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let (li, le) = (v.light[l] as usize, v.sphere_le[l]);
            if o.inside[l] {
                let q = &v.sphere_q;
                let (p, u) = (Vec3::new(q.p_ref[0][l], q.p_ref[1][l], q.p_ref[2][l]), Vec2::new(q.u[0][l], q.u[1][l]));
                Self::generic_light_sample(scene, l, v, li, p, u);
                continue;
            }
            let taken = o.found[l] && o.pdf[l] > 0.0 && !le.is_black();
            if !taken {
                continue;
            }
            for k in 0..3 {
                v.num.lp[k][l] = o.p[k][l];
                v.num.ln[k][l] = o.n[k][l];
                v.num.gwi[k][l] = o.wi[k][l];
            }
            put_rgb(&mut v.num.lrad, l, le);
            v.num.gpdf[l] = o.pdf[l];
            v.num.infinite[l] = false;
            v.num.delta[l] = false;
            v.num.generic[l] = true;
            v.num.nee_ok[l] = true;
        }
    }

    /// Asks for the texels the lanes' hits on large bitmaps will read. Such lookups land
    /// anywhere in the image (bsdf_spheres' textured sphere: 2048x1571 texels, ~1800 a
    /// pixel), and each lane's waited alone inside `gather`; asked for together, the
    /// misses overlap. The uvs go to `uv_ahead` for `gather`.
    #[inline(never)]
    fn prefetch_texels(&self, scene: &Scene, hits: &Hits8, active: u8, uv_ahead: &mut [Vec2; LANES]) {
        for &(first, count, si) in &self.texel_meshes {
            // The lanes whose hit is on this mesh (all eight compared at once; a miss's
            // `u32::MAX` is out of every range), and the hit's index there from the kernel's
            // index alone (`self.uv` of the unpacked triangle, the same value): the
            // triangle's record, just asked for by `prefetch_hits`, is not waited on here
            // (3 % of the grid's render, most of its lanes on shapes without such a bitmap).
            let on = (0..LANES).fold(0u8, |m, l| m | (u8::from(hits.prim[l].wrapping_sub(first) < count) << l)) & active;
            if on == 0 {
                continue;
            }
            let sh = &self.shapes[si as usize];
            let Geometry::Mesh(m) = &*scene.shapes[si as usize].geometry else { continue };
            let map = map_of(&sh.detail, &sh.conductor);
            for l in lanes_of(on as u32) {
                let uv = m.uv((hits.prim[l] - first) as usize, hits.b1[l], hits.b2[l]);
                uv_ahead[l] = uv;
                if let Some(map) = map {
                    map.prefetch(uv);
                    continue;
                }
                sh.front.prefetch(uv);
                if let Some(b) = &sh.back {
                    b.prefetch(uv);
                }
            }
        }
    }

    /// The uv of a hit: on a triangle at barycentrics (b1, b2), or the scene's record's.
    #[inline(always)]
    fn hit_uv(&self, scene: &Scene, hit: &Hit, b1: f32, b2: f32) -> Vec2 {
        match hit {
            Hit::Tri(tri) => self.uv(scene, tri, b1, b2),
            Hit::Other(si) => si.uv,
        }
    }

    /// The uv of a hit on `tri` at barycentrics (b1, b2).
    #[inline(always)]
    fn uv(&self, scene: &Scene, tri: &Tri, b1: f32, b2: f32) -> Vec2 {
        match &*scene.shapes[tri.shape as usize].geometry {
            Geometry::Mesh(m) => m.uv(tri.local as usize, b1, b2),
            _ => Vec2::ZERO,
        }
    }

    /// The Beckmann rough conductors' (`Bsdf::beckmann_conductor`) values and densities
    /// toward their light samples and their own samples, all packets' lanes at once, eight a
    /// group (`rough_conductor_lanes`: the visible normal, then both directions' D, G1,
    /// densities and Fresnel term as vector code, the bits of `Bsdf::eval_pdf_and_sample`),
    /// written where `scalar_scatter` writes a lane's results; such lanes leave
    /// `scatter_lanes`. (About one lane in eight holds such a vertex a step: one group for all
    /// packets runs one chain where each packet ran its own.)
    #[inline(always)]
    fn conductor_samples<S>(&self, events: &LaneEvents, packets: &mut [Packet<S>]) {
        self.group_samples::<S, RoughConductorStep>(events, packets);
    }

    /// The Beckmann rough plastics' (`Bsdf::beckmann_plastic`) values and densities toward
    /// their light samples and their own samples, as [`Self::conductor_samples`] does a
    /// conductor's (`rough_plastic_lanes`: the lobe, the visible normal or cosine direction,
    /// then both directions' D, G1, densities, Fresnel term and coating transmittances).
    /// (Out of line: inlined, it changed how LLVM compiled the tile loop around it.)
    #[inline(never)]
    fn plastic_samples<S>(&self, events: &LaneEvents, packets: &mut [Packet<S>]) {
        if packets.iter().fold(0, |a, p| a | p.v.scatter_lanes) == 0 {
            return;
        }
        self.group_samples::<S, RoughPlasticStep>(events, packets);
    }

    /// The GGX rough conductors' (`Bsdf::ggx_conductor`), as [`Self::plastic_samples`] does the
    /// plastics' (`rough_conductor_ggx_lanes`: visible normals in closed form).
    #[inline(never)]
    fn ggx_conductor_samples<S>(&self, events: &LaneEvents, packets: &mut [Packet<S>]) {
        if packets.iter().fold(0, |a, p| a | p.v.scatter_lanes) == 0 {
            return;
        }
        self.group_samples::<S, GgxConductorStep>(events, packets);
    }

    /// The GGX rough plastics' (`Bsdf::ggx_plastic`), as [`Self::plastic_samples`] does the
    /// Beckmann ones' (`rough_plastic_ggx_lanes`: visible normals in closed form).
    #[inline(never)]
    fn ggx_plastic_samples<S>(&self, events: &LaneEvents, packets: &mut [Packet<S>]) {
        if packets.iter().fold(0, |a, p| a | p.v.scatter_lanes) == 0 {
            return;
        }
        self.group_samples::<S, GgxPlasticStep>(events, packets);
    }

    /// The Beckmann rough dielectrics' (`Bsdf::beckmann_dielectric`) values and densities
    /// toward their light samples and their own samples, as [`Self::plastic_samples`] does a
    /// plastic's (`rough_dielectric_lanes`: the visible normal, the lobe by its Fresnel term,
    /// then both directions' half vector, D, G1, densities and values).
    #[inline(never)]
    fn dielectric_samples<S>(&self, events: &LaneEvents, packets: &mut [Packet<S>]) {
        if packets.iter().fold(0, |a, p| a | p.v.scatter_lanes) == 0 {
            return;
        }
        self.group_samples::<S, RoughDielectricStep>(events, packets);
    }

    /// The scalar-BSDF lanes of all packets whose BSDF is model `M`'s, evaluated and sampled
    /// eight a group by `M`'s vector step and written as `scalar_scatter` writes a lane's.
    #[inline(always)]
    fn group_samples<S, M: LaneStep>(&self, events: &LaneEvents, packets: &mut [Packet<S>]) {
        // Made at the first such lane (most steps of most scenes have none).
        let mut group: Option<M::Group> = None;
        let mut slot = [GroupSlot::default(); LANES];
        let mut used = 0usize;
        for pk in 0..packets.len() {
            let mut lanes = packets[pk].v.scatter_lanes;
            while lanes != 0 {
                let l = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let Packet { st, v, .. } = &mut packets[pk];
                if !M::takes(v.flags[l]) {
                    continue;
                }
                let shape = v.shape[l];
                let Some(bsdf) = v.own[l].as_ref().or(self.shapes[shape as usize].uniform.as_ref()) else { continue };
                let frame = v.num.frame(l);
                let wo = frame.to_local(lane3(&v.num.wo, l));
                let Some((m, flipped)) = M::model(bsdf, wo) else { continue };
                let side = |w: Vec3| if flipped { Vec3::new(w.x, w.y, -w.z) } else { w };
                let wi = nee_dir(v, l, &frame);
                let q = group.get_or_insert_with(M::Group::default);
                M::set(q, used, m, side(wo), wi.map(side), [v.scatter_u[0][l], v.scatter_u[1][l], v.scatter_u[2][l]]);
                slot[used] = GroupSlot { pk, l, flipped, opacity: bsdf.opacity, lit: wi.is_some() };
                take_lane(events, st, v, l, PrevBsdf { shape, frame, wo }, wi);
                used += 1;
                if used == LANES {
                    self.finish_group::<S, M>(events, q, &slot[..used], packets);
                    used = 0;
                }
            }
        }
        if let Some(q) = group.as_ref().filter(|_| used > 0) {
            self.finish_group::<S, M>(events, q, &slot[..used], packets);
        }
    }

    /// One group of [`Self::group_samples`]: lanes `slot` of `q`, each finished as its BSDF
    /// finishes them and written into its packet's `v` (as `scalar_scatter`). (The group's
    /// other lanes hold earlier lanes' values: the lanes are independent.)
    #[inline(always)]
    fn finish_group<S, M: LaneStep>(&self, events: &LaneEvents, q: &M::Group, slot: &[GroupSlot], packets: &mut [Packet<S>]) {
        let out = M::run(self.avx512, q, slot.len());
        for (i, c) in slot.iter().enumerate() {
            let (nee, s) = M::lane(&out, i, c.lit);
            put_lane(events, c, packets, nee, s);
        }
    }

    /// The first part of lane `l`'s vertex at `p` on `shape` of a scalar BSDF: the BSDF (the
    /// shape's uniform one, or the hit's own, as `Scene::bsdf` makes it from the hit's record
    /// `si`, kept in `v.own`), its lobes, and the light sample (numbers `u_light`, `u_l2`)
    /// unless it has delta lobes only (a sphere light's comes with the other lanes'). Out of
    /// line: the Lambertian lanes' `gather` stays small.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn scalar_light_sample(&self, scene: &Scene, l: usize, v: &mut Soa, shape: u32, p: Vec3, si: Option<&SurfaceInteraction>, u_light: f32, u_l2: Vec2) {
        let sh = &self.shapes[shape as usize];
        // `v.own[l]` is None here (`scalar_scatter` took it) and stays so with a uniform
        // BSDF: moving a None in and out copied the whole `Option<Bsdf>` (memcpy) each hit.
        let flags = match si {
            Some(si) => {
                let own = scene.bsdf(si);
                let flags = own.flags();
                v.own[l] = Some(own);
                flags
            }
            None => sh.uniform_flags,
        };
        self.scalar_vertex_light(scene, l, v, p, flags, u_light, u_l2);
    }

    /// The rest of lane `l`'s vertex of a scalar BSDF (`scalar_light_sample` took the light
    /// sample; the vertex in `v.num`, its numbers in `v.scatter_u`): the BSDF's value and
    /// density toward it (as `path::light_sample_unshadowed`), its own sample (as
    /// `camera_walk`), and the events of both, into `v` for `shade8`; the lane's next MIS
    /// vertex and radiance scale into `st`.
    #[inline(never)]
    fn scalar_scatter<S>(&self, events: &LaneEvents, st: &mut Paths<S>, l: usize, v: &mut Soa) {
        let (uc, ux, uy) = (v.scatter_u[0][l], v.scatter_u[1][l], v.scatter_u[2][l]);
        let shape = v.shape[l];
        // The shape's uniform BSDF, or this hit's own (moved into `prev_own` at the end).
        let uniform = self.shapes[shape as usize].uniform.as_ref();
        let own = if v.own[l].is_some() { v.own[l].take() } else { None };
        let Some(bsdf) = own.as_ref().or(uniform) else { unreachable!("a shape without a uniform BSDF builds its own") };
        let flags = v.flags[l];
        let frame = v.num.frame(l);
        // The outgoing direction, local, and the light's direction as `shade8` finds it; the
        // value and density toward it, and the BSDF's own sample, from one call (a Beckmann
        // conductor's lanes come not here: `conductor_samples` wrote theirs).
        let wo = frame.to_local(lane3(&v.num.wo, l));
        let wi = nee_dir(v, l, &frame);
        let result = bsdf.eval_pdf_and_sample(wo, wi, uc, Vec2::new(ux, uy), TransportMode::Radiance);
        let Some(bs) = put_scatter(events, st, v, l, flags, wo, wi, result) else { return };
        if !bs.lobe.is_specular() {
            st.prev_bsdf[l] = Some(PrevBsdf { shape, frame, wo });
            if own.is_some() {
                st.prev_own[l] = own;
            }
        }
    }

    /// [`Self::scalar_light_sample`] of a lane of a principled shape (`ShapeData::principled`):
    /// its model at `tp` built into `v.princ` (`Scene::bsdf` builds it boxed, in a `Bsdf`).
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn principled_light_sample(&self, scene: &Scene, l: usize, v: &mut Soa, pm: &PrincipledMaterial, tp: TexPoint, u_light: f32, u_l2: Vec2) {
        let m = pm.at(tp);
        let flags = m.flags();
        if v.princ.len() < LANES {
            v.princ.resize(LANES, None);
        }
        v.princ[l] = Some(m);
        self.scalar_vertex_light(scene, l, v, tp.p, flags, u_light, u_l2);
    }

    /// [`Self::scalar_scatter`] of a lane of a principled shape, by its model in `v.princ`
    /// (`PrincipledAt::eval_pdf_and_sample`: the bits of its `Bsdf`'s), kept in
    /// `Paths::prev_princ` where a path may meet an emitting shape (for the MIS weight there).
    #[inline(never)]
    fn principled_scatter<S>(&self, events: &LaneEvents, st: &mut Paths<S>, l: usize, v: &mut Soa) {
        let (uc, ux, uy) = (v.scatter_u[0][l], v.scatter_u[1][l], v.scatter_u[2][l]);
        let shape = v.shape[l];
        let frame = v.num.frame(l);
        let wo = frame.to_local(lane3(&v.num.wo, l));
        let wi = nee_dir(v, l, &frame);
        st.prev_bsdf[l] = None;
        let Some(m) = v.princ.get(l).and_then(Option::as_ref) else {
            // Never: `gather` built the lane's model.
            v.num.nee_ok[l] = false;
            v.num.bmoved[l] = false;
            return;
        };
        let result = m.eval_pdf_and_sample(wo, wi, uc, Vec2::new(ux, uy), TransportMode::Radiance);
        let Some(bs) = put_scatter(events, st, v, l, v.flags[l], wo, wi, result) else { return };
        if !bs.lobe.is_specular() {
            st.prev_bsdf[l] = Some(PrevBsdf { shape, frame, wo });
            if self.emitters {
                if st.prev_princ.len() < LANES {
                    st.prev_princ.resize(LANES, None);
                }
                st.prev_princ[l] = v.princ[l];
            }
        }
    }

    /// [`Self::scalar_scatter`] of the lanes of a detail over a Lambertian
    /// (`ShapeData::detail`: the perturbed normals in `v.detail_n`, the reflectances in
    /// `v.num.refl`), all at once by `detail_lambert_lanes` (the bits of
    /// `Bsdf::detail_lambert`), the `Bsdf` built only where a path may meet an emitting shape
    /// (for the MIS weight there).
    #[inline(never)]
    fn detail_scatter<S>(&self, events: &LaneEvents, st: &mut Paths<S>, v: &mut Soa) {
        let lanes = std::mem::take(&mut v.detail_lanes);
        let mut q = DetailLambertLanes::<LANES>::default();
        let mut frames = [Frame { s: Vec3::X, t: Vec3::Y, n: Vec3::Z }; LANES];
        for l in lanes_of(lanes.into()) {
            let frame = v.num.frame(l);
            let wo = frame.to_local(lane3(&v.num.wo, l));
            let wi = nee_dir(v, l, &frame);
            for c in 0..3 {
                q.wo[c][l] = wo[c];
                q.wi[c][l] = wi.unwrap_or(Vec3::ZERO)[c];
            }
            q.lit[l] = wi.is_some();
            frames[l] = frame;
        }
        (q.n, q.refl, q.u) = (v.detail_n, v.num.refl, [v.scatter_u[1], v.scatter_u[2]]);
        let out = detail_lanes_on_cpu(self.avx512, &q);
        for l in lanes_of(lanes.into()) {
            let wo = Vec3::new(q.wo[0][l], q.wo[1][l], q.wo[2][l]);
            let wi = q.lit[l].then(|| Vec3::new(q.wi[0][l], q.wi[1][l], q.wi[2][l]));
            let result = out.lane(l, q.lit[l], LobeFlags::DIFFUSE_REFLECTION);
            if put_scatter(events, st, v, l, LobeFlags::DIFFUSE_REFLECTION, wo, wi, result).is_none() {
                continue;
            }
            st.prev_bsdf[l] = Some(PrevBsdf { shape: v.shape[l], frame: frames[l], wo });
            if self.emitters {
                let d = Detail { n: lane3(&v.detail_n, l), shadowing: true };
                let refl = Rgb::new(v.num.refl[0][l], v.num.refl[1][l], v.num.refl[2][l]);
                st.prev_own[l] = Some(Bsdf { detail: Some(d), ..Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: refl })) });
            }
        }
    }

    /// The lanes of rough conductors under a map or of textured parameters
    /// (`ShapeData::conductor`: the conductor in `v.cond`, the perturbed normal in
    /// `v.detail_n` where `v.cond_detail`) of the packets that `scatter_and_shade` runs for
    /// (`layers`: whether AOV layers are on), eight at a time across the packets by
    /// [`conductor_slots`] (a packet has about four such lanes a step), each written
    /// as [`Self::scalar_scatter`] writes a lane's: the bits of the `Bsdf` `Scene::bsdf`
    /// builds, which is built only where a path may meet an emitting shape (for the MIS
    /// weight there). (The lanes are independent: a lane's bits do not depend on its slot or
    /// its neighbours.) Out of line: in the tile loop, it cost scenes without such lanes ~2 %.
    #[inline(never)]
    fn conductor_scatter<S>(&self, events: &LaneEvents, packets: &mut [Packet<S>], layers: bool) {
        let mut q = ConductorSlots::default();
        let mut at = [(0usize, 0usize); LANES];
        let mut frames = [Frame::from_normal(Vec3::Z); LANES];
        let mut used = 0usize;
        for pk in 0..packets.len() {
            // As the tile loop picks the packets it scatters.
            let p = &packets[pk];
            if p.active == 0 || p.v.cond_lanes == 0 || (p.go == 0 && !layers) {
                continue;
            }
            let lanes = std::mem::take(&mut packets[pk].v.cond_lanes);
            for l in lanes_of(u32::from(lanes)) {
                let v = &packets[pk].v;
                let Some(c) = v.cond[l] else { continue };
                let frame = v.num.frame(l);
                let wo = frame.to_local(lane3(&v.num.wo, l));
                let wi = nee_dir(v, l, &frame);
                let d = (v.cond_detail & (1 << l) != 0).then(|| Detail { n: lane3(&v.detail_n, l), shadowing: true });
                q.set(used, c, d, wo, wi, Vec2::new(v.scatter_u[1][l], v.scatter_u[2][l]));
                (at[used], frames[used]) = ((pk, l), frame);
                used += 1;
                if used == LANES {
                    self.put_conductors(events, &q, &at, &frames, packets);
                    used = 0;
                }
            }
        }
        if used > 0 {
            // (The slots past `used` hold the previous group's lanes: not run again.)
            self.put_conductors(events, &q, &at[..used], &frames[..used], packets);
        }
    }

    /// One group of [`Self::conductor_scatter`]: slots `q` (slot `i` lane `at[i]` of its
    /// packet, shading frame `frames[i]`), run and written into their packets.
    #[inline(always)]
    fn put_conductors<S>(&self, events: &LaneEvents, q: &ConductorSlots, at: &[(usize, usize)], frames: &[Frame], packets: &mut [Packet<S>]) {
        let out = conductor_slots(self.avx512, q, at.len());
        for (i, (&(pk, l), &frame)) in at.iter().zip(frames).enumerate() {
            let Packet { st, v, .. } = &mut packets[pk];
            let (wo, lit) = (lane3(&q.wo, i), q.lit[i]);
            let wi = lit.then(|| lane3(&q.wi, i));
            if put_scatter(events, st, v, l, LobeFlags::GLOSSY_REFLECTION, wo, wi, out.lane(i, lit, LobeFlags::GLOSSY_REFLECTION)).is_none() {
                continue;
            }
            st.prev_bsdf[l] = Some(PrevBsdf { shape: v.shape[l], frame, wo });
            if self.emitters {
                st.prev_own[l] = Some(Bsdf { detail: q.detail_of(i), ..Bsdf::new(BsdfModel::RoughConductor(q.c[i])) });
            }
        }
    }

    /// Lane `l`'s ray along `d` left the scene: what the environment adds there, weighted
    /// against the previous vertex's BSDF sample as the scalar tracer weighs it.
    #[inline(always)]
    fn escaped<S: Sampler>(&self, scene: &Scene, settings: &RenderSettings, st: &mut Paths<S>, l: usize, d: Vec3, v: &mut Soa) {
        if st.num.depth[l] == 1 && settings.hide_emitters {
            return;
        }
        let Some(&ei) = scene.environment_lights.first() else { return };
        let light = &scene.lights[ei as usize];
        // An environment map locates the direction once for its radiance and its density
        // (render_tile located the escaped lanes' directions together).
        let (le, pdf_light) = match light {
            Light::EnvMap(env) => env.eval_pdf_in(&v.env_cells, l, v.env_grid[2][l], !st.num.prev_specular[l]),
            _ => light.le_pdf_escaped(d, !st.num.prev_specular[l]),
        };
        if le.is_black() {
            return;
        }
        let w = if st.num.prev_specular[l] { 1.0 } else { power_heuristic(1.0, st.num.prev_pdf[l], 1.0, scene.light_pmf(ei) * pdf_light) };
        let beta = Rgb::new(st.num.beta[0][l], st.num.beta[1][l], st.num.beta[2][l]);
        st.add(l, beta * le * w);
        v.emitted[l] = true;
        v.shape[l] = ESCAPED;
        put_rgb(&mut v.emit, l, beta * le * w);
    }
}

/// A lane of [`conductor_detail_lanes`] (tests): an opaque one-sided rough conductor `c` under surface
/// detail `d` (None: none) seen from `wo` (local), its light sample toward `wi` where it has
/// one, the sample's numbers `u`.
#[cfg(test)]
#[derive(Clone, Copy, Debug)]
struct ConductorLane {
    c: RoughConductor,
    d: Option<Detail>,
    wo: Vec3,
    wi: Option<Vec3>,
    u: Vec2,
}

/// A lane's (value, density) toward its light sample and its own sample.
type LaneResult = (Option<(Rgb, f32)>, Option<BsdfSample>);

/// Up to eight lanes of [`conductor_slots`], slot by slot as lane rows: slot `i` an opaque
/// one-sided rough conductor `c[i]`, under a detail where `detail[i]` (its unit normal `n`,
/// with the shadowing term where `shadowing`), seen from `wo` (local), its light sample
/// toward `wi` where `lit`, the sample's numbers `u`.
#[derive(Clone, Copy, Debug)]
struct ConductorSlots {
    c: [RoughConductor; LANES],
    detail: [bool; LANES],
    shadowing: [bool; LANES],
    n: [[f32; LANES]; 3],
    wo: [[f32; LANES]; 3],
    wi: [[f32; LANES]; 3],
    lit: [bool; LANES],
    u: [[f32; LANES]; 2],
}

impl Default for ConductorSlots {
    fn default() -> Self {
        let c = RoughConductor {
            distribution: crate::bsdf::microfacet::Microfacet::new(MicrofacetKind::Ggx, 1.0, 1.0),
            eta: Rgb::splat(1.0),
            k: Rgb::BLACK,
            specular_reflectance: Rgb::splat(1.0),
        };
        ConductorSlots {
            c: [c; LANES],
            detail: [false; LANES],
            shadowing: [false; LANES],
            n: [[0.0; LANES], [0.0; LANES], [1.0; LANES]],
            wo: [[0.0; LANES], [0.0; LANES], [1.0; LANES]],
            wi: [[0.0; LANES], [0.0; LANES], [-1.0; LANES]],
            lit: [false; LANES],
            u: [[0.5; LANES]; 2],
        }
    }
}

impl ConductorSlots {
    /// Slot `i`: conductor `c` under detail `d` from `wo`, light sample toward `wi`, numbers `u`.
    #[inline(always)]
    fn set(&mut self, i: usize, c: RoughConductor, d: Option<Detail>, wo: Vec3, wi: Option<Vec3>, u: Vec2) {
        self.c[i] = c;
        self.detail[i] = d.is_some();
        self.shadowing[i] = d.is_some_and(|d| d.shadowing);
        let n = d.map_or(Vec3::Z, |d| d.n);
        let w = wi.unwrap_or(Vec3::NEG_Z);
        for k in 0..3 {
            (self.n[k][i], self.wo[k][i], self.wi[k][i]) = (n[k], wo[k], w[k]);
        }
        self.lit[i] = wi.is_some();
        (self.u[0][i], self.u[1][i]) = (u.x, u.y);
    }

    /// Slot `i`'s detail, if any.
    #[inline(always)]
    fn detail_of(&self, i: usize) -> Option<Detail> {
        self.detail[i].then(|| Detail { n: lane3(&self.n, i), shadowing: self.shadowing[i] })
    }
}

/// `Bsdf::eval_pdf_and_sample` (radiance) of the first `used` slots' `Bsdf`s (the conductor,
/// under its detail), the same bits, read back by `LaneSamples::lane` (`nee`: the slot's
/// `lit`): the perturbed frames and the directions in them (as `Bsdf::eval_detail` and
/// `sample_detail` make them) as lane arithmetic over all slots, the slots whose `wo` lies
/// above the conductor there through its distribution's conductor lanes
/// (`rough_conductor_ggx_lanes`, `rough_conductor_lanes`) together, the others black (the
/// back of a one-sided model), then the detail's factor and frame applied as `eval_detail`,
/// `pdf_detail` and `detail_sample_out` apply them, as lane arithmetic again (per lane, in
/// `Bsdf::finish_detail`, it had been most of the route's time outside the conductor lanes).
#[inline(always)]
fn conductor_slots(avx512: bool, q: &ConductorSlots, used: usize) -> LaneSamples<LANES> {
    // `Detail::frame(wo)` and `to_local` (as `detail_lambert_lanes`); slots without detail
    // keep their directions.
    let used = used.min(LANES);
    // Without detail (textured conductors) both passes are skipped.
    let any_detail = q.detail[..used].contains(&true);
    let (mut fs, mut ft, mut fnn) = ([[0.0f32; LANES]; 3], [[0.0f32; LANES]; 3], [[0.0f32; LANES]; 3]);
    let (mut pwo, mut pwi) = (q.wo, q.wi);
    for l in (0..LANES).filter(|_| any_detail) {
        let n = [q.n[0][l], q.n[1][l], q.n[2][l]];
        let wo = [q.wo[0][l], q.wo[1][l], q.wo[2][l]];
        let wi = [q.wi[0][l], q.wi[1][l], q.wi[2][l]];
        let (nn, s, t) = detail_frame(n, wo);
        let d = q.detail[l];
        let lo = [dot3(wo, s), dot3(wo, t), dot3(wo, nn)];
        let li = [dot3(wi, s), dot3(wi, t), dot3(wi, nn)];
        for c in 0..3 {
            pwo[c][l] = if d { lo[c] } else { wo[c] };
            pwi[c][l] = if d { li[c] } else { wi[c] };
            (fs[c][l], ft[c][l], fnn[c][l]) = (s[c], t[c], nn[c]);
        }
    }
    let mut o = LaneSamples::<LANES>::empty(true);
    for kind in [MicrofacetKind::Ggx, MicrofacetKind::Beckmann] {
        let mut g = RoughConductorLanes::<LANES>::default();
        let (mut at, mut n) = ([0usize; LANES], 0usize);
        for l in 0..used {
            if q.c[l].distribution.kind != kind || pwo[2][l] <= 0.0 || pwo[2][l].is_nan() {
                continue;
            }
            g.set(n, &q.c[l], lane3(&pwo, l), q.lit[l].then(|| lane3(&pwi, l)), Vec2::new(q.u[0][l], q.u[1][l]));
            at[n] = l;
            n += 1;
        }
        if n == 0 {
            continue;
        }
        let r = if kind == MicrofacetKind::Ggx { GgxConductorStep::run(avx512, &g, n) } else { RoughConductorStep::run(avx512, &g, n) };
        if n == used {
            // Every slot, in order.
            o = r;
            break;
        }
        for (i, &l) in at[..n].iter().enumerate() {
            for c in 0..3 {
                (o.nee_f[c][l], o.wi[c][l], o.f[c][l]) = (r.nee_f[c][i], r.wi[c][i], r.f[c][i]);
            }
            (o.nee_pdf[l], o.sampled[l], o.pdf[l]) = (r.nee_pdf[i], r.sampled[i], r.pdf[i]);
        }
    }
    // `Bsdf::detail_factor` toward the light sample and the sample (turned back to the
    // shading frame as `detail_sample_out` turns it).
    for l in (0..LANES).filter(|_| any_detail) {
        let d = q.detail[l];
        let alpha2 = (0.125 * tan2(q.n[2][l])).min(1.0);
        // Selects, no early return: with one, this pass ran as scalar code (perf: ~9 % of
        // `conductor_scatter` on this closure).
        let shadowing = |z: f32| {
            let g = 2.0 / (1.0 + (1.0 + alpha2 * tan2(z)).sqrt());
            let g = if g.is_finite() { g } else { 0.0 };
            if q.shadowing[l] {
                g
            } else {
                1.0
            }
        };
        let (wz, pwz) = (q.wi[2][l], pwi[2][l]);
        let through = wz * pwz > 0.0;
        let k = pwz.abs() / wz.abs() * shadowing(wz);
        for c in 0..3 {
            let v = o.nee_f[c][l];
            o.nee_f[c][l] = if !d {
                v
            } else if through {
                v * k
            } else {
                0.0
            };
        }
        o.nee_pdf[l] = if !d || through { o.nee_pdf[l] } else { 0.0 };
        let pw = [o.wi[0][l], o.wi[1][l], o.wi[2][l]];
        let w: [f32; 3] = std::array::from_fn(|c| fs[c][l] * pw[0] + ft[c][l] * pw[1] + fnn[c][l] * pw[2]);
        let through = w[2] * pw[2] > 0.0;
        let k = pw[2].abs() / w[2].abs() * shadowing(w[2]);
        for c in 0..3 {
            o.wi[c][l] = if d { w[c] } else { pw[c] };
            o.f[c][l] = if d { o.f[c][l] * k } else { o.f[c][l] };
        }
        o.sampled[l] = o.sampled[l] && (!d || through);
    }
    o
}

/// [`conductor_slots`] of the lanes that are there (the tests' form).
#[cfg(test)]
fn conductor_detail_lanes(avx512: bool, lanes: &[Option<ConductorLane>; LANES]) -> [LaneResult; LANES] {
    let mut q = ConductorSlots::default();
    let mut at = [0usize; LANES];
    let mut used = 0usize;
    for (l, x) in lanes.iter().enumerate() {
        let Some(x) = x else { continue };
        q.set(used, x.c, x.d, x.wo, x.wi, x.u);
        at[used] = l;
        used += 1;
    }
    let o = conductor_slots(avx512, &q, used);
    let mut out: [LaneResult; LANES] = [(None, None); LANES];
    for (i, &l) in at[..used].iter().enumerate() {
        out[l] = o.lane(i, q.lit[i], LobeFlags::GLOSSY_REFLECTION);
    }
    out
}

/// Lane `l`'s direction toward its light sample from its vertex (`v.num.p`, shading frame
/// `frame`), local, where it has one (as `shade8` finds it; a mesh light's as
/// `AreaLight::sample_li`).
#[inline(always)]
fn nee_dir(v: &Soa, l: usize, frame: &Frame) -> Option<Vec3> {
    v.num.nee_ok[l].then(|| {
        let wi_w = if v.num.generic[l] {
            lane3(&v.num.gwi, l)
        } else {
            let d = lane3(&v.num.lp, l) - lane3(&v.num.p, l);
            d / d.length_squared().sqrt()
        };
        frame.to_local(wi_w)
    })
}

/// The `principled` or `principledthin` material of `shape`, if it is one.
#[inline(always)]
fn principled_material(scene: &Scene, shape: u32) -> Option<&PrincipledMaterial> {
    let s = scene.shapes.get(shape as usize)?;
    match scene.materials.get(s.material as usize)? {
        Material::Principled(pm) => Some(pm.as_ref()),
        _ => None,
    }
}

/// Lane `l` of a row of vectors.
#[inline(always)]
fn lane3(a: &[[f32; LANES]; 3], l: usize) -> Vec3 {
    Vec3::new(a[0][l], a[1][l], a[2][l])
}

/// Lane `l`'s scalar BSDF's value `f` and density `pdf` toward its light sample, for
/// `shade8` (a delta light takes no MIS weight, nor the density).
#[inline(always)]
fn put_light_value(v: &mut Soa, l: usize, f: Rgb, pdf: f32) {
    v.num.nee_ok[l] = !f.is_black();
    put_rgb(&mut v.num.bf, l, f);
    v.num.bpdf_nee[l] = if v.num.delta[l] { 0.0 } else { pdf };
}

/// Lane `l`'s BSDF results seen from `wo` (local): its value and density toward the light
/// sample `wi`, where the lane has one, and its own sample, with their events (`flags`: the
/// BSDF's lobes), into `v` for `shade8`; a transmitted sample's η² into the path's scale.
/// The sample where it moves the path (the caller keeps the vertex for MIS); the lane's
/// previous MIS vertex is cleared.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn put_scatter<S>(
    events: &LaneEvents,
    st: &mut Paths<S>,
    v: &mut Soa,
    l: usize,
    flags: LobeFlags,
    wo: Vec3,
    wi: Option<Vec3>,
    (nee, bs): LaneResult,
) -> Option<BsdfSample> {
    if let (Some(wi), Some((f, pdf))) = (wi, nee) {
        put_light_value(v, l, f, pdf);
        if let Some(view) = events.view {
            v.class_nee[l] = view.class(events.aovs.scatter_event(v.shape[l], flags, None, wi.z * wo.z < 0.0));
        }
    }
    let bs = bs.filter(|bs| bs.pdf > 0.0 && !bs.f.is_black());
    v.num.bmoved[l] = bs.is_some();
    st.prev_bsdf[l] = None;
    let bs = bs?;
    put_sample(events, v, l, flags, &bs);
    if bs.lobe.contains(LobeFlags::TRANSMISSION) {
        st.num.eta_scale[l] *= bs.eta * bs.eta;
    }
    Some(bs)
}

/// Lane `l`'s scalar BSDF's own sample `bs` (which moves the path), for `shade8`, and its
/// event (`flags`: the BSDF's lobes).
#[inline(always)]
fn put_sample(events: &LaneEvents, v: &mut Soa, l: usize, flags: LobeFlags, bs: &BsdfSample) {
    for k in 0..3 {
        v.num.bwi[k][l] = bs.wi[k];
    }
    put_rgb(&mut v.num.bweight, l, bs.weight());
    v.num.bpdf[l] = bs.pdf;
    v.num.bspecular[l] = bs.lobe.is_specular();
    if let Some(view) = events.view {
        // A null interaction (a mask let the path through) is no event.
        let transmission = bs.lobe.contains(LobeFlags::TRANSMISSION);
        v.class_step[l] = (!bs.lobe.is_null()).then(|| view.class(events.aovs.scatter_event(v.shape[l], flags, Some(bs.lobe), transmission)));
    }
}

/// A lane taken by a vector BSDF step (`conductor_samples`, `plastic_samples`): what
/// `scalar_scatter` writes that does not wait on the values, so the lane leaves
/// `scatter_lanes`. The vertex `kept` for the MIS weight of the emitter its sample reaches
/// (taken back in [`put_lane`] where the lane does not move; its own BSDF, if any, goes with
/// it as `scalar_scatter` moves it), and the light sample's event toward `wi`.
#[inline(always)]
fn take_lane<S>(events: &LaneEvents, st: &mut Paths<S>, v: &mut Soa, l: usize, kept: PrevBsdf, wi: Option<Vec3>) {
    if let (Some(view), Some(wi)) = (events.view, wi) {
        v.class_nee[l] = view.class(events.aovs.scatter_event(v.shape[l], v.flags[l], None, wi.z * kept.wo.z < 0.0));
    }
    st.prev_bsdf[l] = Some(kept);
    if v.own[l].is_some() {
        st.prev_own[l] = v.own[l].take();
    }
    v.scatter_lanes &= !(1 << l);
}

/// The values of slot `c`'s lane from its vector step, on the model's side, finished as its
/// BSDF finishes them (`Bsdf::finish_conductor`) and written where `scalar_scatter` writes
/// a lane's: the light sample's value and density `nee`, the lane's own sample `s`.
#[inline(always)]
fn put_lane<S>(events: &LaneEvents, c: &GroupSlot, packets: &mut [Packet<S>], nee: Option<(Rgb, f32)>, s: Option<BsdfSample>) {
    let Packet { st, v, .. } = &mut packets[c.pk];
    let l = c.l;
    let (nee, s) = Bsdf::finish_conductor(c.opacity, c.flipped, nee, s);
    if let Some((f, pdf)) = nee {
        put_light_value(v, l, f, pdf);
    }
    let bs = s.filter(|bs| bs.pdf > 0.0 && !bs.f.is_black());
    v.num.bmoved[l] = bs.is_some();
    match bs {
        // (Never of a delta lobe: the vertex `take_lane` kept stays.)
        Some(bs) => {
            put_sample(events, v, l, v.flags[l], &bs);
            if bs.lobe.contains(LobeFlags::TRANSMISSION) {
                st.num.eta_scale[l] *= bs.eta * bs.eta;
            }
        }
        None => st.prev_bsdf[l] = None,
    }
}

/// A BSDF model whose lanes the path kernel evaluates and samples eight at a time
/// ([`SimdKernel::group_samples`]): each lane's value and density toward its light sample
/// and its own sample, the bits of `Bsdf::eval_pdf_and_sample`, on the model's side.
trait LaneStep {
    type Model;
    /// The inputs of up to eight lanes.
    type Group: Default;
    /// Whether a lane of these lobes may be the model's (a cheap test before `model`).
    fn takes(_flags: LobeFlags) -> bool {
        true
    }
    /// The model, where `bsdf` toward `wo` is one, and whether directions are mirrored to its side.
    fn model(bsdf: &Bsdf, wo: Vec3) -> Option<(&Self::Model, bool)>;
    /// Group lane `i`: directions on the model's side, the vertex's three numbers (lobe, direction).
    fn set(q: &mut Self::Group, i: usize, m: &Self::Model, wo: Vec3, wi: Option<Vec3>, u: [f32; 3]);
    /// The vector step, portable code.
    const PORTABLE: fn(&Self::Group, usize) -> LaneSamples<LANES>;
    /// Its copies for AVX2 with FMA and for AVX-512VL (made by `vector_step_copies!`).
    #[cfg(target_arch = "x86_64")]
    const COPIES: Copies<Self::Group, LaneSamples<LANES>>;
    /// The first `used` lanes' results, by this CPU's build of the step: its AVX-512 copy
    /// where the kernel runs AVX-512 (`avx512`), its AVX2 copy where the CPU has AVX2 and
    /// FMA, else the portable code.
    #[inline(always)]
    fn run(avx512: bool, q: &Self::Group, used: usize) -> LaneSamples<LANES> {
        run_vector_step(
            avx512,
            Self::PORTABLE,
            #[cfg(target_arch = "x86_64")]
            Self::COPIES,
            q,
            used,
        )
    }
    /// The model's lobe besides the glossy reflection (the conductor has none: its own).
    const OTHER_LOBE: LobeFlags;
    /// Lane `i`'s light-sample value and density (where it has a light sample: `lit`) and own sample.
    #[inline(always)]
    fn lane(out: &LaneSamples<LANES>, i: usize, lit: bool) -> (Option<(Rgb, f32)>, Option<BsdfSample>) {
        out.lane(i, lit, Self::OTHER_LOBE)
    }
}

/// A vector step's copies for AVX2 and AVX-512 (`conductor8_avx2`, ...): each needs its
/// instruction set, so calling one is unsafe.
#[cfg(target_arch = "x86_64")]
type Copies<Q, O> = (unsafe fn(&Q, usize) -> O, unsafe fn(&Q, usize) -> O);

/// The first `used` lanes' results of a vector step by this CPU's build: its AVX-512 copy
/// where the kernel runs AVX-512 (`avx512`), its AVX2 copy where the CPU has AVX2 and FMA,
/// else its portable code.
#[inline(always)]
fn run_vector_step<Q>(
    avx512: bool,
    portable: fn(&Q, usize) -> LaneSamples<LANES>,
    #[cfg(target_arch = "x86_64")] copies: Copies<Q, LaneSamples<LANES>>,
    q: &Q,
    used: usize,
) -> LaneSamples<LANES> {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::avx2() && crate::cpu::fma() {
        let (avx2_copy, avx512_copy) = copies;
        // SAFETY: `avx2()` and `fma()` detect AVX2 and FMA at run time, and the kernel's
        // `avx512` is set only where AVX-512F and VL were.
        return unsafe {
            if avx512 {
                avx512_copy(q, used)
            } else {
                avx2_copy(q, used)
            }
        };
    }
    portable(q, used)
}

/// Beckmann rough conductors (`conductor8`).
struct RoughConductorStep;

impl LaneStep for RoughConductorStep {
    type Model = RoughConductor;
    type Group = RoughConductorLanes<LANES>;
    #[inline(always)]
    fn model(bsdf: &Bsdf, wo: Vec3) -> Option<(&RoughConductor, bool)> {
        bsdf.beckmann_conductor(wo)
    }
    #[inline(always)]
    fn set(q: &mut Self::Group, i: usize, m: &RoughConductor, wo: Vec3, wi: Option<Vec3>, u: [f32; 3]) {
        q.set(i, m, wo, wi, Vec2::new(u[1], u[2]));
    }
    const PORTABLE: fn(&Self::Group, usize) -> LaneSamples<LANES> = rough_conductor_lanes;
    #[cfg(target_arch = "x86_64")]
    const COPIES: Copies<Self::Group, LaneSamples<LANES>> = (conductor8_avx2, conductor8_avx512);
    const OTHER_LOBE: LobeFlags = LobeFlags::GLOSSY_REFLECTION;
}

/// Beckmann rough plastics (`plastic8`).
struct RoughPlasticStep;

impl LaneStep for RoughPlasticStep {
    type Model = RoughPlastic;
    type Group = RoughPlasticLanes<LANES>;
    /// A plastic without a mask has these lobes (with a back of other lobes it is left to
    /// `scalar_scatter`): most scalar lanes are other models.
    #[inline(always)]
    fn takes(flags: LobeFlags) -> bool {
        flags == LobeFlags::GLOSSY_REFLECTION | LobeFlags::DIFFUSE_REFLECTION
    }
    #[inline(always)]
    fn model(bsdf: &Bsdf, wo: Vec3) -> Option<(&RoughPlastic, bool)> {
        bsdf.beckmann_plastic(wo)
    }
    #[inline(always)]
    fn set(q: &mut Self::Group, i: usize, m: &RoughPlastic, wo: Vec3, wi: Option<Vec3>, u: [f32; 3]) {
        q.set(i, m, wo, wi, u[0], Vec2::new(u[1], u[2]));
    }
    const PORTABLE: fn(&Self::Group, usize) -> LaneSamples<LANES> = rough_plastic_lanes;
    #[cfg(target_arch = "x86_64")]
    const COPIES: Copies<Self::Group, LaneSamples<LANES>> = (plastic8_avx2, plastic8_avx512);
    const OTHER_LOBE: LobeFlags = LobeFlags::DIFFUSE_REFLECTION;
}

/// GGX rough conductors (`conductor_ggx8`).
struct GgxConductorStep;

impl LaneStep for GgxConductorStep {
    type Model = RoughConductor;
    type Group = RoughConductorLanes<LANES>;
    #[inline(always)]
    fn model(bsdf: &Bsdf, wo: Vec3) -> Option<(&RoughConductor, bool)> {
        bsdf.ggx_conductor(wo)
    }
    #[inline(always)]
    fn set(q: &mut Self::Group, i: usize, m: &RoughConductor, wo: Vec3, wi: Option<Vec3>, u: [f32; 3]) {
        RoughConductorStep::set(q, i, m, wo, wi, u);
    }
    const PORTABLE: fn(&Self::Group, usize) -> LaneSamples<LANES> = rough_conductor_ggx_lanes;
    #[cfg(target_arch = "x86_64")]
    const COPIES: Copies<Self::Group, LaneSamples<LANES>> = (conductor_ggx8_avx2, conductor_ggx8_avx512);
    const OTHER_LOBE: LobeFlags = LobeFlags::GLOSSY_REFLECTION;
}

/// GGX rough plastics (`plastic_ggx8`).
struct GgxPlasticStep;

impl LaneStep for GgxPlasticStep {
    type Model = RoughPlastic;
    type Group = RoughPlasticLanes<LANES>;
    #[inline(always)]
    fn takes(flags: LobeFlags) -> bool {
        RoughPlasticStep::takes(flags)
    }
    #[inline(always)]
    fn model(bsdf: &Bsdf, wo: Vec3) -> Option<(&RoughPlastic, bool)> {
        bsdf.ggx_plastic(wo)
    }
    #[inline(always)]
    fn set(q: &mut Self::Group, i: usize, m: &RoughPlastic, wo: Vec3, wi: Option<Vec3>, u: [f32; 3]) {
        RoughPlasticStep::set(q, i, m, wo, wi, u);
    }
    const PORTABLE: fn(&Self::Group, usize) -> LaneSamples<LANES> = rough_plastic_ggx_lanes;
    #[cfg(target_arch = "x86_64")]
    const COPIES: Copies<Self::Group, LaneSamples<LANES>> = (plastic_ggx8_avx2, plastic_ggx8_avx512);
    const OTHER_LOBE: LobeFlags = LobeFlags::DIFFUSE_REFLECTION;
}

/// Beckmann rough dielectrics (`dielectric8`).
struct RoughDielectricStep;

impl LaneStep for RoughDielectricStep {
    type Model = RoughDielectric;
    type Group = RoughDielectricLanes<LANES>;
    /// A dielectric without a mask has these lobes.
    #[inline(always)]
    fn takes(flags: LobeFlags) -> bool {
        flags == LobeFlags::GLOSSY_REFLECTION | LobeFlags::GLOSSY_TRANSMISSION
    }
    #[inline(always)]
    fn model(bsdf: &Bsdf, wo: Vec3) -> Option<(&RoughDielectric, bool)> {
        bsdf.beckmann_dielectric(wo)
    }
    #[inline(always)]
    fn set(q: &mut Self::Group, i: usize, m: &RoughDielectric, wo: Vec3, wi: Option<Vec3>, u: [f32; 3]) {
        q.set(i, m, wo, wi, u[0], Vec2::new(u[1], u[2]));
    }
    const PORTABLE: fn(&Self::Group, usize) -> LaneSamples<LANES> = rough_dielectric_lanes;
    #[cfg(target_arch = "x86_64")]
    const COPIES: Copies<Self::Group, LaneSamples<LANES>> = (dielectric8_avx2, dielectric8_avx512);
    const OTHER_LOBE: LobeFlags = LobeFlags::GLOSSY_TRANSMISSION;
}

/// A lane of a vector BSDF step's group (`SimdKernel::conductor_samples`,
/// `plastic_samples`): its packet and lane, whether its directions were mirrored to the model's side, its BSDF's opacity, and
/// whether it has a light sample.
#[derive(Clone, Copy, Default)]
struct GroupSlot {
    pk: usize,
    l: usize,
    flipped: bool,
    opacity: f32,
    lit: bool,
}

/// Where a lane's ray hit: a triangle of the kernel's, or a shape that is not a mesh (the
/// scene's surface record of the hit, as the scalar tracer's `Scene::intersect` makes it).
enum Hit<'a> {
    Tri(&'a Tri),
    Other(&'a SurfaceInteraction),
}

/// Lane `l`'s hit on a shape that is not a mesh, as the scalar tracer's `Scene::intersect`
/// records it (the same ray: the same point, normal and uv; the uv left zero where the
/// shape's `ShapeData::reads_uv` is not set). Out of line: mesh scenes never call it.
#[inline(never)]
fn other_hit(scene: &Scene, shapes: &[ShapeData], rays: &Rays8, hits: &Hits8, others: &OtherHits, l: usize) -> SurfaceInteraction {
    let (shape, prim) = others.prim[l];
    let (hit, ray) = (crate::accel::PrimHit { t: hits.t[l], shape, prim, b1: hits.b1[l], b2: hits.b2[l] }, lane_ray(rays, l));
    if shapes[shape as usize].reads_uv {
        scene.interaction(&hit, &ray)
    } else {
        scene.interaction_without_uv(&hit, &ray)
    }
}

/// `Soa::shape` of a lane whose ray left the scene.
const ESCAPED: u32 = u32::MAX;

/// What `shade8` reads of a vertex's lanes: plain arrays, apart from `Soa`'s `Option`s.
/// (`shade8` takes this alone: with a pointer to a struct that also holds `Option` fields,
/// LLVM left its loop scalar.)
#[derive(Clone, Default)]
struct VertexNums {
    p: [[f32; LANES]; 3],
    ng: [[f32; LANES]; 3],
    fs: [[f32; LANES]; 3],
    ft: [[f32; LANES]; 3],
    fnn: [[f32; LANES]; 3],
    /// Toward the previous vertex (world).
    wo: [[f32; LANES]; 3],
    /// The reflectance of the side `wo` is on (black: a back without a material).
    refl: [[f32; LANES]; 3],
    has_back: [bool; LANES],
    /// The BSDF sample's square point (cosine-warped in `shade8`).
    u: [[f32; LANES]; 2],
    u_rr: [f32; LANES],
    nee_ok: [bool; LANES],
    /// The light sample came from `Light::sample_li` (direction `gwi`, density `gpdf` in
    /// solid angle, radiance in `lrad`, point and normal in `lp`, `ln`), not a mesh light.
    generic: [bool; LANES],
    gwi: [[f32; LANES]; 3],
    gpdf: [f32; LANES],
    /// Its shadow ray runs to infinity (along `gwi`); a delta light takes no MIS weight.
    infinite: [bool; LANES],
    delta: [bool; LANES],
    lp: [[f32; LANES]; 3],
    ln: [[f32; LANES]; 3],
    lrad: [[f32; LANES]; 3],
    pmf: [f32; LANES],
    pdf_area: [f32; LANES],
    /// The lane's material took the scalar `Bsdf` (`SimdKernel::scalar_scatter`): its value
    /// `bf` and density `bpdf_nee` toward the light sample, and its own sample (taken when
    /// `bmoved`): local direction `bwi`, weight f |cos| / pdf `bweight`, density `bpdf`,
    /// whether of a delta lobe.
    scalar_bsdf: [bool; LANES],
    bf: [[f32; LANES]; 3],
    bpdf_nee: [f32; LANES],
    bmoved: [bool; LANES],
    bwi: [[f32; LANES]; 3],
    bweight: [[f32; LANES]; 3],
    bpdf: [f32; LANES],
    bspecular: [bool; LANES],
}

/// One vertex of eight paths, structure of arrays: what `gather` collected.
#[derive(Default)]
struct Soa {
    /// What `shade8` reads.
    num: VertexNums,
    /// The hit's uv where `prefetch_texels` computed it (a shape whose `prefetch_texels` is set).
    uv_ahead: [Vec2; LANES],
    /// Lanes whose reflectance (a large bitmap's, at `uv_ahead`; no back) is looked up after
    /// every lane's `gather` (`SimdKernel::late_texels`), and whether `wo` is on its front.
    late_texels: u8,
    late_front: [bool; LANES],
    /// The scene shape hit, the light sampled, and the emission found at the hit when
    /// `emitted` (for the paths' events).
    shape: [u32; LANES],
    light: [u32; LANES],
    emitted: [bool; LANES],
    emit: [[f32; LANES]; 3],
    /// With AOVs, at a scalar BSDF: the event classes of the light sample and of the BSDF
    /// sample (None: a null interaction, no event).
    class_nee: [u32; LANES],
    class_step: [Option<u32>; LANES],
    /// Lanes whose light is a sphere of constant radiance: the sphere, the point it is seen
    /// from and the sample's numbers in `sphere_q`, its radiance in `sphere_le`; sampled all
    /// at once after `gather` (`SimdKernel::sphere_samples`).
    sphere_pending: u8,
    sphere_q: SphereLanes<LANES>,
    sphere_le: [Rgb; LANES],
    /// Lanes whose light is the large environment map: the point it is seen from and the
    /// sample's numbers, sampled all at once after `gather` (`SimdKernel::env_samples`).
    env_pending: u8,
    env_p: [Vec3; LANES],
    env_u: [Vec2; LANES],
    /// Lanes of a scalar BSDF: the vertex's lobe number and the sample's square point (the
    /// vertex itself is in `num`), its own BSDF (None: the shape's uniform one) and lobes,
    /// for `scalar_scatter` once the sphere samples are in.
    scatter_u: [[f32; LANES]; 3],
    /// The lanes that wait on `scalar_scatter` (a Beckmann conductor's lane leaves in
    /// `conductor_samples`).
    scatter_lanes: u8,
    /// The lanes of a detail over a Lambertian (`detail_scatter`), and their perturbed
    /// normals (original shading frame).
    detail_lanes: u8,
    detail_n: [[f32; LANES]; 3],
    /// The lanes of a `ShapeData::conductor` (`conductor_scatter`), their conductors, and
    /// those under a map (their perturbed normals in `detail_n`).
    cond_lanes: u8,
    cond: [Option<RoughConductor>; LANES],
    cond_detail: u8,
    own: [Option<Bsdf>; LANES],
    /// The lanes of a principled shape (`principled_scatter`), and their models (`LANES`
    /// slots from the first such lane: the packets, made per tile, stay small without).
    princ_lanes: u8,
    princ: Vec<Option<PrincipledAt>>,
    flags: [LobeFlags; LANES],
    /// The rays' grid points (u, v) and sin θ in the environment map (`EnvMap::dirs_to_grid`),
    /// set when some lane escaped.
    env_grid: [[f32; LANES]; 3],
    /// Their cells in its grid (`EnvMap::cells_of`).
    env_cells: EnvCells<LANES>,
}

impl VertexNums {
    /// Lane `l`'s shading frame.
    #[inline(always)]
    fn frame(&self, l: usize) -> Frame {
        Frame { s: lane3(&self.fs, l), t: lane3(&self.ft, l), n: lane3(&self.fnn, l) }
    }
}

/// A camera-path vertex of a scalar BSDF that scattered by a non-delta lobe, kept for the
/// MIS weight of the emitter its sample reaches (as `path.rs`'s `ScatterPoint`). Its BSDF:
/// the shape's uniform one (`ShapeData::uniform`), else the one it built (`Paths::prev_own`).
#[derive(Clone, Copy)]
struct PrevBsdf {
    shape: u32,
    frame: Frame,
    /// Toward the vertex before it, local frame.
    wo: Vec3,
}

/// The events of the kernel's paths as classes of the AOVs' product automaton (the scene's
/// labels bound): a diffuse reflection at each shape, reaching each shape's or light's emission.
struct LaneEvents<'a> {
    /// None without AOVs (or without a product automaton: then the scalar tracer renders).
    view: Option<ForwardView<'a>>,
    /// For the events of scalar BSDFs, found per vertex.
    aovs: &'a AovSet,
    /// Per scene shape: the diffuse reflection there (sampled or toward a light sample alike:
    /// a Lambertian reflection is never singular, and a light sample it counts lies on its side).
    scatter: Vec<u32>,
    /// Per scene shape: its emission found by a path.
    light: Vec<u32>,
    /// The environment seen by an escaped ray.
    background: u32,
    /// Per scene light: its emission reached by a light sample.
    emitter: Vec<u32>,
    /// The lookups of all lanes at once by AVX2 gathers (the CPU has AVX2 and every table
    /// is indexable by 32-bit offsets).
    gathers: bool,
}

impl<'a> LaneEvents<'a> {
    fn new(scene: &Scene, aovs: &'a AovSet) -> LaneEvents<'a> {
        let Some(view) = aovs.forward_view().filter(|_| !aovs.is_empty()) else {
            return LaneEvents { view: None, aovs, scatter: Vec::new(), light: Vec::new(), background: 0, emitter: Vec::new(), gathers: false };
        };
        let shapes = 0..scene.shapes.len() as u32;
        let mut e = LaneEvents {
            view: Some(view),
            aovs,
            scatter: shapes.clone().map(|s| view.class(aovs.scatter_event(s, crate::bsdf::LobeFlags::DIFFUSE_REFLECTION, None, false))).collect(),
            light: shapes.map(|s| view.class(aovs.light_event(Some(s)))).collect(),
            background: view.class(crate::lpe::Event::BACKGROUND),
            emitter: scene.lights.iter().map(|l| view.class(aovs.emitter_event(l))).collect(),
            gathers: false,
        };
        let (table, ends, _) = view.tables();
        // (A scene without lights has no light samples to route: it keeps the scalar lookups.)
        let fits = |t: &[u32]| (1..=i32::MAX as usize).contains(&t.len());
        e.gathers = cfg!(target_arch = "x86_64") && crate::cpu::avx2() && [table, ends, &e.scatter, &e.light, &e.emitter].into_iter().all(fits);
        e
    }

    /// The automaton's lookups of one vertex of the lanes' paths: per lane the layers of the
    /// emission found (lanes `emitted`; the environment where the ray escaped), the layers
    /// of its light sample after the reflection there (lanes `nee`), and `q` stepped over the
    /// reflection the path takes (lanes `goes_on`). The reflection is the shape's diffuse
    /// one, or in the lanes of `own` that lane's own event classes.
    #[inline(always)]
    fn lookups(&self, q: &mut [u32; LANES], shape: &[u32; LANES], light: &[u32; LANES], own: &Reflection, masks: [u8; 3]) -> [[LayerMask; LANES]; 2] {
        #[cfg(target_arch = "x86_64")]
        if self.gathers {
            // SAFETY: `gathers` is set only where the CPU has AVX2.
            return unsafe { self.lookups_avx2(q, shape, light, own, masks) };
        }
        self.lookups_scalar(q, shape, light, own, masks)
    }

    /// [`Self::lookups`] lane by lane (without AVX2, and the reference of the gathers).
    fn lookups_scalar(
        &self,
        q: &mut [u32; LANES],
        shape: &[u32; LANES],
        light: &[u32; LANES],
        own: &Reflection,
        [emitted, nee, goes_on]: [u8; 3],
    ) -> [[LayerMask; LANES]; 2] {
        let (mut emit, mut lit) = ([0; LANES], [0; LANES]);
        let Some(view) = self.view else { return [emit, lit] };
        for l in 0..LANES {
            let bit = 1u8 << l;
            if emitted & bit != 0 {
                let class = if shape[l] == ESCAPED { self.background } else { self.light[shape[l] as usize] };
                emit[l] = view.ends(q[l], class);
            }
            if (nee | goes_on) & bit != 0 {
                let (at_nee, at_step) = if own.lanes & bit != 0 {
                    (own.nee[l], own.step[l])
                } else {
                    let c = self.scatter[shape[l] as usize];
                    (c, c)
                };
                if nee & bit != 0 {
                    lit[l] = view.ends(view.step(q[l], at_nee), self.emitter[light[l] as usize]);
                }
                if goes_on & bit != 0 {
                    q[l] = view.step(q[l], at_step);
                }
            }
        }
        [emit, lit]
    }

    /// [`Self::lookups_scalar`] for all lanes at once: each table read is one masked gather.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn lookups_avx2(
        &self,
        q: &mut [u32; LANES],
        shape: &[u32; LANES],
        light: &[u32; LANES],
        own: &Reflection,
        [emitted, nee, goes_on]: [u8; 3],
    ) -> [[LayerMask; LANES]; 2] {
        use std::arch::x86_64::*;
        let Some(view) = self.view else { return [[0; LANES]; 2] };
        let (table, ends, classes) = view.tables();
        let q0 = load8(q);
        let sh = load8(shape);
        let escaped = _mm256_cmpeq_epi32(sh, _mm256_set1_epi32(ESCAPED as i32));
        let row = |q: __m256i| _mm256_mullo_epi32(q, _mm256_set1_epi32(classes as i32));
        let em = lane_mask8(emitted);
        let hit_class = gather8(&self.light, sh, _mm256_andnot_si256(escaped, em));
        let emit_class = _mm256_blendv_epi8(hit_class, _mm256_set1_epi32(self.background as i32), escaped);
        let emit = gather8(ends, _mm256_add_epi32(row(q0), emit_class), em);
        let own_m = lane_mask8(own.lanes);
        let (lit_m, step_m) = (lane_mask8(nee), lane_mask8(goes_on));
        let reflects = lane_mask8(nee | goes_on);
        let diffuse = gather8(&self.scatter, sh, _mm256_andnot_si256(own_m, reflects));
        // The state after the reflection: one step for both the light sample and the path's
        // next vertex, unless a lane's own BSDF gives them different event classes.
        let (q_nee, qs) = if own.lanes == 0 {
            let qs = gather8(table, _mm256_add_epi32(row(q0), diffuse), reflects);
            (qs, qs)
        } else {
            let at_nee = _mm256_blendv_epi8(diffuse, load8(&own.nee), own_m);
            let at_step = _mm256_blendv_epi8(diffuse, load8(&own.step), own_m);
            (gather8(table, _mm256_add_epi32(row(q0), at_nee), lit_m), gather8(table, _mm256_add_epi32(row(q0), at_step), step_m))
        };
        let lit = gather8(ends, _mm256_add_epi32(row(q_nee), gather8(&self.emitter, load8(light), lit_m)), lit_m);
        store8(q, _mm256_blendv_epi8(q0, qs, step_m));
        let (mut e, mut n) = ([0; LANES], [0; LANES]);
        store8(&mut e, emit);
        store8(&mut n, lit);
        [e, n]
    }
}

/// The lanes whose flag is set, as a bit mask: each flag is one byte, 0 or 1, and one
/// multiplication moves byte `l`'s bit to bit `l` of the top byte (no carries: the bits differ).
#[inline(always)]
fn lane_bits(flags: &[bool; LANES]) -> u8 {
    byte_lanes(u64::from_le_bytes(flags.map(u8::from)))
}

/// [`lane_bits`] of eight bytes as one word, each byte 0 or 1.
#[inline(always)]
fn byte_lanes(bytes: u64) -> u8 {
    (bytes.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u8
}

/// The lanes whose vertex took a scalar BSDF, with the event classes of their light sample
/// and of the reflection their path takes (elsewhere the shape's diffuse reflection).
struct Reflection {
    lanes: u8,
    nee: [u32; LANES],
    step: [u32; LANES],
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn load8(a: &[u32; LANES]) -> std::arch::x86_64::__m256i {
    // SAFETY: eight u32 are 32 readable bytes (unaligned load).
    unsafe { std::arch::x86_64::_mm256_loadu_si256(a.as_ptr().cast()) }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn store8(a: &mut [u32; LANES], v: std::arch::x86_64::__m256i) {
    // SAFETY: eight u32 are 32 writable bytes (unaligned store).
    unsafe { std::arch::x86_64::_mm256_storeu_si256(a.as_mut_ptr().cast(), v) }
}

/// All ones in the lanes of bit mask `m`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn lane_mask8(m: u8) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(m as i32), bits), bits)
}

/// `t[idx]` in the lanes of `mask` (all ones), 0 in the others. Indices are clamped into `t`
/// (non-empty, at most `i32::MAX` entries), so no lane reads outside it.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gather8(t: &[u32], idx: std::arch::x86_64::__m256i, mask: std::arch::x86_64::__m256i) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    let idx = _mm256_min_epu32(idx, _mm256_set1_epi32(t.len().saturating_sub(1) as i32));
    // SAFETY: every index is within `t` (clamped above; `t.len() - 1` fits the i32 index).
    unsafe { _mm256_mask_i32gather_epi32::<4>(_mm256_setzero_si256(), t.as_ptr().cast(), idx, mask) }
}

/// With AOVs or `--lpe`: each lane's state of the AOVs' product automaton along its path (as
/// the scalar tracer's `camera_walk` steps its tracker), and per job of the tile a row that
/// sums what its sample adds to each layer, in place and in the order of its `LayerSample`
/// (only the layers a contribution reaches are added to), kept until the samples go to the
/// film in the scalar order. Without, each method is one untaken branch.
struct LaneLayers<'a> {
    events: &'a LaneEvents<'a>,
    /// AOVs of the render; a row holds them, then the restricted beauty.
    n: usize,
    /// The beauty's bit where the beauty is restricted (`--lpe`), else 0: then the beauty is
    /// the path's radiance and needs no row of its own.
    beauty_bit: LayerMask,
    /// Per packet and lane: its automaton state and its job (its row).
    q: [[u32; LANES]; PACKETS],
    job: [[usize; LANES]; PACKETS],
    /// Per job: its `n` layers and the restricted beauty (stride `n + 1`), and which of the
    /// layers its paths touched.
    rows: Vec<Rgb>,
    row_touched: Vec<u32>,
}

impl<'a> LaneLayers<'a> {
    /// Rows for `jobs` samples, all black.
    fn new(events: &'a LaneEvents<'a>, aovs: &AovSet, jobs: usize) -> Self {
        let on = events.view.is_some();
        let n = aovs.aov_count().min(MAX_LAYERS);
        LaneLayers {
            events,
            n,
            beauty_bit: if aovs.restricts_beauty() { crate::lpe::aov::BEAUTY } else { 0 },
            q: [[0; LANES]; PACKETS],
            job: [[0; LANES]; PACKETS],
            rows: if on { vec![Rgb::BLACK; jobs * (n + 1)] } else { Vec::new() },
            row_touched: if on { vec![0; jobs] } else { Vec::new() },
        }
    }

    /// Lane `l` of packet `pk` starts a camera sample, job `job`.
    #[inline(always)]
    fn start(&mut self, pk: usize, l: usize, job: usize) {
        if let Some(view) = self.events.view {
            self.q[pk][l] = view.camera();
            self.job[pk][l] = job;
        }
    }

    /// Adds `c` to the layers of `mask` in the row of packet `pk`'s lane `l` (as `LayerSample::add`).
    #[inline(always)]
    fn add(&mut self, mask: LayerMask, pk: usize, l: usize, c: Rgb) {
        let (job, n) = (self.job[pk][l], self.n);
        let Some(row) = self.rows.get_mut(job * (n + 1)..(job + 1) * (n + 1)) else { return };
        if mask & self.beauty_bit != 0 {
            row[n] += c;
        }
        let mut m = mask & !crate::lpe::aov::BEAUTY;
        if let Some(t) = self.row_touched.get_mut(job) {
            *t |= m;
        }
        while m != 0 {
            if let Some(a) = row[..n].get_mut(m.trailing_zeros() as usize) {
                *a += c;
            }
            m &= m - 1;
        }
    }

    fn on(&self) -> bool {
        self.events.view.is_some()
    }

    /// One vertex of the lanes' paths, in the scalar tracer's order: the emission found at
    /// the hit (lanes of `active` whose `v.emitted`), the light samples that count (`nee`;
    /// diffuse there, then the light), and the diffuse scattering of the paths that go on.
    #[inline(always)]
    fn route(&mut self, pk: usize, v: &Soa, o: &Out, active: u8, nee: u8, goes_on: u8) {
        if self.events.view.is_none() {
            return;
        }
        let emitted = lane_bits(&v.emitted) & active;
        // A scalar BSDF's events are the lane's own (`SimdKernel::scalar_scatter`); a null
        // interaction (a mask let the path through) is no event, so its state stays.
        let mut own = Reflection { lanes: lane_bits(&v.num.scalar_bsdf) & active, nee: [0; LANES], step: [0; LANES] };
        let mut steps = goes_on & active;
        let mut lanes = own.lanes;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            own.nee[l] = v.class_nee[l];
            match v.class_step[l] {
                Some(c) => own.step[l] = c,
                None => steps &= !(1 << l),
            }
        }
        let [emit, lit] = self.events.lookups(&mut self.q[pk], &v.shape, &v.light, &own, [emitted, nee & active, steps]);
        let mut lanes = emitted | (nee & active);
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            if emitted & (1 << l) != 0 {
                self.add(emit[l], pk, l, Rgb::new(v.emit[0][l], v.emit[1][l], v.emit[2][l]));
            }
            if nee & (1 << l) != 0 {
                let c = o.contribution(l);
                if !c.is_black() {
                    self.add(lit[l], pk, l, c);
                }
            }
        }
    }

    /// Packet `pk`'s lane `l`'s sample is done with radiance `beauty`: what the beauty takes
    /// (all of it, or the paths of `--lpe`).
    #[inline(always)]
    fn finish(&self, pk: usize, l: usize, beauty: Rgb) -> Rgb {
        if self.beauty_bit == 0 || self.events.view.is_none() {
            return beauty;
        }
        let j = (self.job[pk][l] + 1) * (self.n + 1) - 1;
        self.rows.get(j).copied().unwrap_or(beauty)
    }

    /// Job `job`'s layers and which of them its paths touched.
    #[inline]
    fn row(&self, job: usize) -> (&[Rgb], u32) {
        let s = self.n + 1;
        (self.rows.get(job * s..job * s + self.n).unwrap_or(&[]), self.row_touched.get(job).copied().unwrap_or(0))
    }
}

/// What `shade8` decided per lane.
#[derive(Default)]
struct Out {
    /// 0: no light sample, 1: counts without a shadow ray, 2: counts when the shadow ray is clear.
    nee: [u8; LANES],
    /// The light sample's contribution.
    c: [[f32; LANES]; 3],
    /// The path continues along its next ray.
    cont: [bool; LANES],
}

impl Out {
    fn contribution(&self, l: usize) -> Rgb {
        Rgb::new(self.c[0][l], self.c[1][l], self.c[2][l])
    }
}

/// `a` where `c`, else `b` (both evaluated: a select in vector code).
#[inline(always)]
fn sel(c: bool, a: f32, b: f32) -> f32 {
    if c {
        a
    } else {
        b
    }
}

/// The arithmetic of one vertex for eight lanes (`shade`'s light sample, BSDF sample and
/// Russian roulette), branch-free per lane so that it compiles to vector code; the same
/// operations in the same order as the scalar tracer. No `bool` array may be read or
/// written under a condition (`a || v.flag[l]`, `x[l] = if c { y } else { x[l] }`): AVX2 and
/// AVX-512F have no masked byte loads and stores, and LLVM then keeps the whole loop scalar,
/// silently (veach-mis and cbox-rgb took 1.3-1.5x the time).
#[inline(always)]
fn shade8(v: &VertexNums, rr_depth: i32, st: &mut PathNums, rays: &mut Rays8, shadow: &mut Rays8, o: &mut Out) {
    for l in 0..LANES {
        let g = |a: &[[f32; LANES]; 3]| [a[0][l], a[1][l], a[2][l]];
        let (p, ng, fs, ft, fnn) = (g(&v.p), g(&v.ng), g(&v.fs), g(&v.ft), g(&v.fnn));
        let wo_w = g(&v.wo);
        let wo = [dot3(wo_w, fs), dot3(wo_w, ft), dot3(wo_w, fnn)];
        let front_side = wo[2] >= 0.0;
        // `|`, not `||`: a load under a condition is a masked byte load, which AVX2 and
        // AVX-512F lack, and LLVM left the whole loop scalar code.
        let side_ok = front_side | v.has_back[l];
        let flip = if front_side { 1.0f32 } else { -1.0 };
        let refl = g(&v.refl);
        let f = [refl[0] * INV_PI, refl[1] * INV_PI, refl[2] * INV_PI];
        let f_black = f[0] == 0.0 && f[1] == 0.0 && f[2] == 0.0;
        let wo_up = wo[2] * flip > 0.0;
        let beta = g(&st.beta);
        // Light sample.
        let lp = g(&v.lp);
        let dl = [lp[0] - p[0], lp[1] - p[1], lp[2] - p[2]];
        let dist2 = dot3(dl, dl);
        let r = dist2.sqrt();
        let ln = g(&v.ln);
        // A mesh light's direction and density from its point, as `AreaLight::sample_li`;
        // any other light's as its `sample_li` gave them.
        let generic = v.generic[l];
        let gwi = g(&v.gwi);
        let wi_w = [sel(generic, gwi[0], dl[0] / r), sel(generic, gwi[1], dl[1] / r), sel(generic, gwi[2], dl[2] / r)];
        let cos_l = dot3(ln, [-wi_w[0], -wi_w[1], -wi_w[2]]);
        let pdf = sel(generic, v.gpdf[l], v.pdf_area[l] * dist2 / cos_l);
        let wi = [dot3(wi_w, fs), dot3(wi_w, ft), dot3(wi_w, fnn)];
        let sampled = generic | (dist2 != 0.0 && cos_l > 0.0 && pdf > 0.0);
        // A scalar BSDF's lane: its value and density as `gather` found them (a black value
        // already cleared `nee_ok`).
        let sb = v.scalar_bsdf[l];
        let lambert_ok = side_ok & wo_up & (wi[2] * flip > 0.0) & !f_black;
        let nee = v.nee_ok[l] && sampled && (sb | lambert_ok);
        let pdf_light = v.pmf[l] * pdf;
        let bsdf_pdf = sel(sb, v.bpdf_nee[l], (wi[2] * flip).max(0.0) * INV_PI);
        let (f2, g2) = (pdf_light * pdf_light, bsdf_pdf * bsdf_pdf);
        let w = if v.delta[l] | pdf_light.is_infinite() {
            1.0
        } else if f2 + g2 == 0.0 {
            0.0
        } else {
            f2 / (f2 + g2)
        };
        let s = wi[2].abs() * w / pdf_light;
        let li = g(&v.lrad);
        let bf = g(&v.bf);
        for k in 0..3 {
            o.c[k][l] = beta[k] * ((sel(sb, bf[k], f[k]) * li[k]) * s);
        }
        // Both ends off their surfaces, as `Scene::occluded_between`; toward a light at
        // infinity from the offset point along the direction, as `Scene::occluded_dir_at`.
        let inf = v.infinite[l];
        let so = offset3(p, ng, [sel(inf, wi_w[0], dl[0]), sel(inf, wi_w[1], dl[1]), sel(inf, wi_w[2], dl[2])]);
        let q = offset3(lp, ln, [-dl[0], -dl[1], -dl[2]]);
        let d2 = [q[0] - so[0], q[1] - so[1], q[2] - so[2]];
        let dist = dot3(d2, d2).sqrt();
        for k in 0..3 {
            shadow.o[k][l] = so[k];
            shadow.d[k][l] = sel(inf, wi_w[k], d2[k] / dist);
        }
        shadow.t_max[l] = sel(inf, f32::INFINITY, dist * (1.0 - SHADOW_EPSILON));
        o.nee[l] = if !nee {
            0
        } else if (dist == 0.0) & !inf {
            1
        } else {
            2
        };
        // BSDF sample.
        let wim = cosine_hemisphere(v.u[0][l], v.u[1][l]);
        let lpdf = wim[2].max(0.0) * INV_PI;
        let lwi = [wim[0], wim[1], wim[2] * flip];
        let sc = lwi[2].abs() / lpdf;
        // Or the scalar BSDF's sample, by selects (a branch here makes the loop scalar code).
        let (bwi, bw) = (g(&v.bwi), g(&v.bweight));
        let wi = [sel(sb, bwi[0], lwi[0]), sel(sb, bwi[1], lwi[1]), sel(sb, bwi[2], lwi[2])];
        let bpdf = sel(sb, v.bpdf[l], lpdf);
        let moved = (sb & v.bmoved[l]) | (!sb & side_ok & wo_up & (lpdf > 0.0) & !f_black);
        let mut nb = [beta[0] * sel(sb, bw[0], f[0] * sc), beta[1] * sel(sb, bw[1], f[1] * sc), beta[2] * sel(sb, bw[2], f[2] * sc)];
        let dir = [
            (fs[0] * wi[0] + ft[0] * wi[1]) + fnn[0] * wi[2],
            (fs[1] * wi[0] + ft[1] * wi[1]) + fnn[1] * wi[2],
            (fs[2] * wi[0] + ft[2] * wi[1]) + fnn[2] * wi[2],
        ];
        let no = offset3(p, ng, dir);
        let mut cont = moved;
        // Loads ahead of the branches: one inside a branch keeps it a branch.
        let (eta, specular) = (st.eta_scale[l], sb & v.bspecular[l]);
        if st.depth[l] >= rr_depth {
            let q = (nb[0] * eta).max(nb[1] * eta).max(nb[2] * eta).min(0.95);
            let survive = v.u_rr[l] < q;
            cont &= survive;
            if survive {
                nb = [nb[0] / q, nb[1] / q, nb[2] / q];
            }
        }
        cont &= !(nb[0] == 0.0 && nb[1] == 0.0 && nb[2] == 0.0);
        // A BSDF sample taken becomes the previous vertex of the next one (for MIS).
        for k in 0..3 {
            st.beta[k][l] = if moved { nb[k] } else { beta[k] };
            st.prev_p[k][l] = if moved { p[k] } else { st.prev_p[k][l] };
            st.prev_n[k][l] = if moved { fnn[k] * flip } else { st.prev_n[k][l] };
            rays.o[k][l] = no[k];
            rays.d[k][l] = dir[k];
        }
        rays.t_max[l] = f32::INFINITY;
        st.prev_pdf[l] = if moved { bpdf } else { st.prev_pdf[l] };
        // As logic, stored always: `if moved` became a store under a condition, a masked byte
        // store (as above).
        st.prev_specular[l] = (moved & specular) | (!moved & st.prev_specular[l]);
        o.cont[l] = cont;
    }
}

/// [`shade8`] compiled for AVX2 (see [`SimdKernel::shade8_on_cpu`]).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline(never)]
unsafe fn shade8_avx2(v: &VertexNums, rr_depth: i32, st: &mut PathNums, rays: &mut Rays8, shadow: &mut Rays8, o: &mut Out) {
    shade8(v, rr_depth, st, rays, shadow, o)
}

/// [`shade8`] compiled for AVX-512VL (the same 256-bit code, 32 vector registers).
///
/// # Safety
/// The CPU must support AVX2, AVX-512F and AVX-512VL.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
#[inline(never)]
unsafe fn shade8_avx512(v: &VertexNums, rr_depth: i32, st: &mut PathNums, rays: &mut Rays8, shadow: &mut Rays8, o: &mut Out) {
    shade8(v, rr_depth, st, rays, shadow, o)
}

/// A vector BSDF step's two copies: `$avx2` compiled for AVX2 with FMA (glibc's expf as
/// vector lanes) and `$avx512` for AVX-512VL, of `$step` over the kernel's eight lanes (see
/// [`LaneStep::COPIES`]; `kernel_code.rs` checks both are vector code).
macro_rules! vector_step_copies {
    ($step:ident($group:ty) -> $out:ty, $avx2:ident, $avx512:ident) => {
        #[doc = concat!("[`", stringify!($step), "`] of the kernel's eight lanes compiled for AVX2.")]
        ///
        /// # Safety
        /// The CPU must support AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        #[inline(never)]
        unsafe fn $avx2(q: &$group, used: usize) -> $out {
            $step(q, used)
        }

        #[doc = concat!("[`", stringify!($step), "`] compiled for AVX-512VL.")]
        ///
        /// # Safety
        /// The CPU must support AVX2, FMA, AVX-512F and AVX-512VL.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
        #[inline(never)]
        unsafe fn $avx512(q: &$group, used: usize) -> $out {
            $step(q, used)
        }
    };
}

vector_step_copies!(rough_conductor_lanes(RoughConductorLanes<LANES>) -> LaneSamples<LANES>, conductor8_avx2, conductor8_avx512);
vector_step_copies!(rough_plastic_lanes(RoughPlasticLanes<LANES>) -> LaneSamples<LANES>, plastic8_avx2, plastic8_avx512);
vector_step_copies!(rough_conductor_ggx_lanes(RoughConductorLanes<LANES>) -> LaneSamples<LANES>, conductor_ggx8_avx2, conductor_ggx8_avx512);
vector_step_copies!(rough_plastic_ggx_lanes(RoughPlasticLanes<LANES>) -> LaneSamples<LANES>, plastic_ggx8_avx2, plastic_ggx8_avx512);
vector_step_copies!(rough_dielectric_lanes(RoughDielectricLanes<LANES>) -> LaneSamples<LANES>, dielectric8_avx2, dielectric8_avx512);

/// [`detail_lambert_lanes`] as a vector step (all eight lanes computed, `used` or not).
#[inline(always)]
fn detail_step(q: &DetailLambertLanes<LANES>, _used: usize) -> LaneSamples<LANES> {
    detail_lambert_lanes(q)
}

vector_step_copies!(detail_step(DetailLambertLanes<LANES>) -> LaneSamples<LANES>, detail8_avx2, detail8_avx512);

/// [`detail_step`] by this CPU's build.
#[inline(always)]
fn detail_lanes_on_cpu(avx512: bool, q: &DetailLambertLanes<LANES>) -> LaneSamples<LANES> {
    run_vector_step(
        avx512,
        detail_step,
        #[cfg(target_arch = "x86_64")]
        (detail8_avx2, detail8_avx512),
        q,
        LANES,
    )
}

/// A sampler of the kernel's lanes: one vertex's numbers for all of them at once, in the
/// scalar tracer's order per vertex (light choice, light point, BSDF lobe, BSDF direction,
/// Russian roulette: 1, 2, 1, 2 and 1 dimensions), each lane from its own sampler.
pub(crate) trait LaneSampler: Sampler + Clone {
    /// Whether the kernel takes a vertex's numbers from [`Self::vertex_draws`] (both samplers
    /// do: their steps vectorise) or lane by lane inside `gather`.
    const BATCHED: bool = false;
    /// Rows: light choice, light point (2), lobe, direction (2), roulette; lanes of `lanes` only.
    #[inline(always)]
    fn vertex_draws(s: &mut [Self; LANES], lanes: u8) -> [[f32; LANES]; 7] {
        let mut d = [[0.0; LANES]; 7];
        for (l, s) in s.iter_mut().enumerate().filter(|(l, _)| lanes & (1 << l) != 0) {
            d[0][l] = s.next_1d();
            let a = s.next_2d();
            (d[1][l], d[2][l]) = (a.x, a.y);
            d[3][l] = s.next_1d();
            let b = s.next_2d();
            (d[4][l], d[5][l]) = (b.x, b.y);
            d[6][l] = s.next_1d();
        }
        d
    }
    /// A camera sample's numbers (`camera_sample`'s order: film point (2), lens point (2),
    /// time) of the lanes of `lanes`, each sampler started at its pixel sample.
    #[inline(always)]
    fn camera_draws(s: &mut [Self; LANES], lanes: u8) -> [[f32; LANES]; 5] {
        let mut d = [[0.0; LANES]; 5];
        for (l, s) in s.iter_mut().enumerate().filter(|(l, _)| lanes & (1 << l) != 0) {
            let (a, b) = (s.next_2d(), s.next_2d());
            (d[0][l], d[1][l], d[2][l], d[3][l]) = (a.x, a.y, b.x, b.y);
            d[4][l] = s.next_1d();
        }
        d
    }
}

impl LaneSampler for IndependentSampler {
    const BATCHED: bool = true;
    /// The eight lanes' PCG steps side by side (`IndependentSampler::draws8`); a Lambertian
    /// lane's lobe number is drawn and not read, as lane by lane.
    #[inline(always)]
    fn vertex_draws(s: &mut [Self; LANES], lanes: u8) -> [[f32; LANES]; 7] {
        IndependentSampler::draws8::<7>(s, lanes)
    }
    #[inline(always)]
    fn camera_draws(s: &mut [Self; LANES], lanes: u8) -> [[f32; LANES]; 5] {
        IndependentSampler::draws8::<5>(s, lanes)
    }
}

impl LaneSampler for SobolSampler {
    const BATCHED: bool = true;
    /// The Owen scrambles of the eight lanes side by side (`SobolSampler::vertex_draws8`).
    #[inline(always)]
    fn vertex_draws(s: &mut [Self; LANES], lanes: u8) -> [[f32; LANES]; 7] {
        SobolSampler::vertex_draws8(s, lanes)
    }
}

/// The lanes' numbers `shade8` reads and writes (see [`VertexNums`]).
#[derive(Clone)]
struct PathNums {
    beta: [[f32; LANES]; 3],
    depth: [i32; LANES],
    prev_specular: [bool; LANES],
    prev_pdf: [f32; LANES],
    prev_p: [[f32; LANES]; 3],
    /// The previous vertex's shading normal on the side its sample left by.
    prev_n: [[f32; LANES]; 3],
    /// The radiance scale of the refractions so far (for Russian roulette, as `camera_walk`).
    eta_scale: [f32; LANES],
}

/// The eight paths in flight: each lane's sampler and film sample, and the state that
/// `shade8` reads and updates, as structure of arrays.
struct Paths<S> {
    /// What `shade8` reads and writes.
    num: PathNums,
    sampler: [S; LANES],
    job: [usize; LANES],
    raster: [Vec2; LANES],
    /// Radiance gathered so far.
    l: [[f32; LANES]; 3],
    /// The previous vertex's BSDF where it was a scalar one (None: Lambertian).
    prev_bsdf: [Option<PrevBsdf>; LANES],
    /// The BSDF that vertex built where its shape has no uniform one (kept apart: a large
    /// `Option<Bsdf>` inside `PrevBsdf` was copied whole, memcpy, at every scalar vertex;
    /// stale where the shape has a uniform one, and then not read).
    prev_own: [Option<Bsdf>; LANES],
    /// The model of that vertex where its shape is a principled one (`ShapeData::principled`;
    /// `LANES` slots from the first, as `Soa::princ`).
    prev_princ: Vec<Option<PrincipledAt>>,
    /// The camera ray's time (every ray of the path sees the scene then).
    time: [f32; LANES],
}

impl<S: Clone> Paths<S> {
    fn new(sampler: S) -> Paths<S> {
        Paths {
            sampler: std::array::from_fn(|_| sampler.clone()),
            job: [0; LANES],
            raster: [Vec2::ZERO; LANES],
            l: [[0.0; LANES]; 3],
            num: PathNums {
                beta: [[1.0; LANES]; 3],
                depth: [0; LANES],
                prev_specular: [true; LANES],
                prev_pdf: [0.0; LANES],
                prev_p: [[0.0; LANES]; 3],
                prev_n: [[0.0; LANES]; 3],
                eta_scale: [1.0; LANES],
            },
            prev_bsdf: [None; LANES],
            prev_own: std::array::from_fn(|_| None),
            prev_princ: Vec::new(),
            time: [0.0; LANES],
        }
    }
}

impl<S> Paths<S> {
    /// Lane `l` starts camera sample `job` at `raster`, its camera ray at `time`.
    fn start(&mut self, l: usize, job: usize, raster: Vec2, time: f32) {
        self.job[l] = job;
        self.raster[l] = raster;
        self.time[l] = time;
        for k in 0..3 {
            self.l[k][l] = 0.0;
            self.num.beta[k][l] = 1.0;
            self.num.prev_p[k][l] = 0.0;
            self.num.prev_n[k][l] = 0.0;
        }
        self.num.depth[l] = 0;
        self.num.prev_specular[l] = true;
        self.num.prev_pdf[l] = 0.0;
        // `prev_bsdf` is read only after a non-delta sample, and `gather` sets it at each vertex.
        self.num.eta_scale[l] = 1.0;
    }

    /// [`Self::start`] of the lanes of `lanes` (jobs `job`, raster positions `raster`, times
    /// `time`), every row written whole with selects: lane-by-lane stores had been a
    /// tenth of the tile loop's samples at depth 1.
    #[inline(always)]
    fn start_lanes(&mut self, lanes: u8, job: &[usize; LANES], raster: &[[f32; LANES]; 2], time: &[f32; LANES]) {
        self.job = pick(lanes, job, &self.job);
        let old = self.raster;
        self.raster = std::array::from_fn(|l| if lanes & (1 << l) != 0 { Vec2::new(raster[0][l], raster[1][l]) } else { old[l] });
        self.time = pick(lanes, time, &self.time);
        let n = &mut self.num;
        self.l = pick_rows(lanes, &[[0.0; LANES]; 3], &self.l);
        n.beta = pick_rows(lanes, &[[1.0; LANES]; 3], &n.beta);
        n.prev_p = pick_rows(lanes, &[[0.0; LANES]; 3], &n.prev_p);
        n.prev_n = pick_rows(lanes, &[[0.0; LANES]; 3], &n.prev_n);
        n.depth = pick(lanes, &[0; LANES], &n.depth);
        n.prev_specular = pick(lanes, &[true; LANES], &n.prev_specular);
        n.prev_pdf = pick(lanes, &[0.0; LANES], &n.prev_pdf);
        n.eta_scale = pick(lanes, &[1.0; LANES], &n.eta_scale);
    }

    /// Adds `c` to lane `l`'s radiance (as `Rgb`'s `+=`).
    #[inline(always)]
    fn add(&mut self, l: usize, c: Rgb) {
        self.l[0][l] += c.r;
        self.l[1][l] += c.g;
        self.l[2][l] += c.b;
    }
}

/// A tile's next job (camera sample) and its pixel and sample, stepped with it (pixels in
/// rows, samples innermost; two integer divisions a job had cost 3 % at depth 1).
struct JobCursor {
    at: (u32, u32, u32),
    next: usize,
    rect: [u32; 4],
    s0: u32,
    n: u32,
}

impl JobCursor {
    /// The next job's pixel, sample and number.
    #[inline(always)]
    fn take(&mut self) -> (u32, u32, u32, usize) {
        let ((x, y, s), job) = (self.at, self.next);
        let [x0, _, x1, _] = self.rect;
        self.at = match (s + 1 < self.s0 + self.n, x + 1 < x1) {
            (true, _) => (x, y, s + 1),
            (false, true) => (x + 1, y, self.s0),
            (false, false) => (x0, y + 1, self.s0),
        };
        self.next += 1;
        (x, y, s, job)
    }

    /// The next eight jobs' camera samples in `samplers` (started, their numbers drawn side by
    /// side) and their rays made all eight at once (`pinhole_lanes`, as `direct`'s, from a
    /// pinhole): the jobs, film points and rays of `camera_sample`, the same bits.
    #[inline(always)]
    fn camera_eight<S: LaneSampler>(&mut self, cam: &RayGenerator<'_>, samplers: &mut [S; LANES]) -> ([usize; LANES], [[f32; LANES]; 2], RayLanes<LANES>) {
        let (mut film, mut job) = ([[0.0f32; LANES]; 2], [0usize; LANES]);
        for (l, sampler) in samplers.iter_mut().enumerate() {
            let (x, y, s, j) = self.take();
            sampler.start_pixel_sample(x, y, s);
            (film[0][l], film[1][l], job[l]) = (x as f32, y as f32, j);
        }
        let d = S::camera_draws(samplers, u8::MAX);
        for l in 0..LANES {
            film[0][l] += d[0][l];
            film[1][l] += d[1][l];
        }
        let r = cam.pinhole_lanes(&film, &d[4]);
        (job, film, r)
    }
}

/// Camera samples started ahead, eight at a time ([`JobCursor::camera_eight`]), for the
/// lanes that fall idle a few a step (paths of several bounces end at different steps),
/// handed out in job order: one by one, a lane's camera sample was a chain of its sampler's
/// steps, a square root and divisions (a sixth of veach-mis's tile loop). Each sample's
/// sampler goes on in the lane that takes it: the same numbers, rays and film order.
struct CameraAhead<S> {
    sampler: [S; LANES],
    job: [usize; LANES],
    film: [[f32; LANES]; 2],
    rays: RayLanes<LANES>,
    /// The next to hand out (`LANES`: none left).
    at: usize,
}

impl<S: LaneSampler> CameraAhead<S> {
    fn new(sampler: S) -> Self {
        let rays = RayLanes { o: [[0.0; LANES]; 3], d: [[0.0; LANES]; 3], t_max: [0.0; LANES], time: [0.0; LANES] };
        CameraAhead { sampler: std::array::from_fn(|_| sampler.clone()), job: [0; LANES], film: [[0.0; LANES]; 2], rays, at: LANES }
    }

    /// How many are left to hand out.
    #[inline(always)]
    fn len(&self) -> usize {
        LANES - self.at
    }

    /// The next eight jobs of `jobs`, from a pinhole `cam` (once all are handed out).
    #[inline(always)]
    fn refill(&mut self, jobs: &mut JobCursor, cam: &RayGenerator<'_>) {
        debug_assert_eq!(self.len(), 0);
        (self.job, self.film, self.rays) = jobs.camera_eight(cam, &mut self.sampler);
        self.at = 0;
    }

    /// The slot of the next one to hand out.
    #[inline(always)]
    fn take(&mut self) -> Option<usize> {
        let i = self.at;
        (i < LANES).then(|| {
            self.at += 1;
            i
        })
    }
}

thread_local! {
    /// Each worker's slots for its tile's finished samples, kept from tile to tile: a vector
    /// made for each tile (20 bytes a sample of a pass: 160 KiB at 32) came from the top
    /// of the heap, which the allocator trimmed at its free, and the next tile faulted its
    /// pages in again.
    static RESULTS: std::cell::Cell<Vec<(Vec2, Rgb)>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Packets of eight paths a tile steps in phase, at most: while one packet's latency chains
/// (camera rays, sphere samples, Beckmann normals) wait, the other's work fills the wait
/// ([`CHAIN_PACKETS`] of them); the lane groups of rough plastics, conductors and dielectrics
/// take the lanes of all packets, and four filled them fuller than three.
const PACKETS: usize = 4;
/// Packets of a tile where only latency chains call for more than one.
const CHAIN_PACKETS: usize = 3;

/// One packet's paths, rays and the scratch of its step.
struct Packet<S> {
    st: Paths<S>,
    rays: Rays8,
    shadow: Rays8,
    others: OtherHits,
    /// Lanes with a path; of those, the ones whose path goes on past `gather` (`go`) and
    /// the ones that end there (`ends`).
    active: u8,
    go: u8,
    ends: u8,
    /// Reused every step: lanes outside this step's mask hold stale values nobody reads.
    v: Soa,
    o: Out,
}

impl<S: Clone> Packet<S> {
    // Inlined: written in place into the tile's packets (out of line, copied there).
    #[inline(always)]
    fn new(sampler: S) -> Packet<S> {
        Packet {
            st: Paths::new(sampler),
            rays: Rays8::default(),
            shadow: Rays8::default(),
            others: OtherHits::default(),
            active: 0,
            go: 0,
            ends: 0,
            v: Soa::default(),
            o: Out::default(),
        }
    }
}

impl<S> Packet<S> {
    /// The lanes that ended at this step's vertex hand their radiance to their jobs' slots
    /// of `results` (as `scatter_and_shade` does with no AOVs) and leave `active`.
    #[inline(always)]
    fn finish_ends(&mut self, results: &mut [(Vec2, Rgb)]) {
        let st = &self.st;
        for l in lanes_of(self.ends as u32) {
            results[st.job[l]] = (st.raster[l], Rgb::new(st.l[0][l], st.l[1][l], st.l[2][l]));
        }
        self.active &= !self.ends;
    }
}

/// Lane `l` of a structure-of-arrays colour.
#[inline(always)]
fn put_rgb(a: &mut [[f32; LANES]; 3], l: usize, x: Rgb) {
    a[0][l] = x.r;
    a[1][l] = x.g;
    a[2][l] = x.b;
}

/// Lanes of `lanes` from `new`, the others from `old`.
#[inline(always)]
fn pick<T: Copy>(lanes: u8, new: &[T; LANES], old: &[T; LANES]) -> [T; LANES] {
    std::array::from_fn(|l| if lanes & (1 << l) != 0 { new[l] } else { old[l] })
}

/// [`pick`] of each row.
#[inline(always)]
fn pick_rows<T: Copy, const R: usize>(lanes: u8, new: &[[T; LANES]; R], old: &[[T; LANES]; R]) -> [[T; LANES]; R] {
    std::array::from_fn(|k| pick(lanes, &new[k], &old[k]))
}

#[inline(always)]
fn set_ray(r: &mut Rays8, l: usize, o: Vec3, d: Vec3, t_max: f32) {
    for a in 0..3 {
        r.o[a][l] = o[a];
        r.d[a][l] = d[a];
    }
    r.t_max[l] = t_max;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    /// `prepare` leaves the kernel's set-up with the scene (the render then takes the kept
    /// tree and triangles: the same allocations), and the image is the one of a scene
    /// rendered without it.
    #[test]
    fn prepare_keeps_the_set_up_with_the_scene() {
        if !crate::cpu::avx2() {
            eprintln!("SKIPPED: no AVX2");
            return;
        }
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
        let load = || crate::io::load_scene(&path, &[]).expect("the repository's Cornell box");
        let (prepared, plain) = (load(), load());
        let s = RenderSettings { spp: 2, seed: 3, ..RenderSettings::from_scene(&prepared) };
        let tracer = crate::methods::by_name("path").expect("path");
        assert!(prepared.packet_tree.get(&packet_tree_key(&prepared)).is_none());
        tracer.prepare(&prepared, &s);
        let tree = prepared.packet_tree.get(&packet_tree_key(&prepared)).expect("a packet tree kept by prepare");
        let tris = prepared.kernel_geometry.get(&KernelGeometry::key(&prepared)).expect("triangles kept by prepare");
        let k = SimdKernel::new(&prepared, &s).expect("the kernel");
        let Tracer::Packets { bvh, .. } = &k.tracer else { panic!("the Cornell box traces packets") };
        assert!(Arc::ptr_eq(bvh, &tree) && Arc::ptr_eq(&k.geometry, &tris), "the render built its set-up again");
        let progress = crate::integrator::Progress::new();
        let a = tracer.render(&prepared, &s, &progress).expect("render").image();
        let b = tracer.render(&plain, &s, &progress).expect("render").image();
        assert!(a.data == b.data, "the prepared scene's image differs");
    }

    /// Every combination of eight lane flags gives its bit mask.
    #[test]
    fn lane_bits_are_the_flags() {
        for m in 0..=255u8 {
            let flags: [bool; LANES] = std::array::from_fn(|l| m & (1 << l) != 0);
            assert_eq!(lane_bits(&flags), m);
        }
    }

    /// The light-sample masks from `nee`'s bits are its lanes equal to 1 and to 2, for
    /// every row of 0, 1 and 2.
    #[test]
    fn nee_masks_are_the_compares() {
        for code in 0..3u32.pow(LANES as u32) {
            let nee: [u8; LANES] = std::array::from_fn(|l| (code / 3u32.pow(l as u32) % 3) as u8);
            let (w, ones) = (u64::from_le_bytes(nee), u64::from_le_bytes([1; LANES]));
            assert_eq!(byte_lanes(w & ones), lane_bits(&nee.map(|n| n == 1)));
            assert_eq!(byte_lanes((w >> 1) & ones), lane_bits(&nee.map(|n| n == 2)));
        }
    }

    /// The lanes' gathered automaton lookups are the scalar ones, lane for lane, on random
    /// states, shapes (some escaped), lights and lane masks.
    #[test]
    fn gathered_lookups_are_the_scalar_ones() {
        if !crate::cpu::avx2() {
            eprintln!("SKIPPED: no AVX2");
            return;
        }
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.xml");
        let scene = crate::io::load_scene(&path, &[]).expect("the repository's Cornell box");
        let list: Vec<(String, String)> = [("a", "C D L"), ("b", "C D .+ L"), ("c", "C .* 'floor' .* L"), ("d", "C .{2} L"), ("e", "L D* E"), ("f", "C B")]
            .iter()
            .map(|(a, b)| (a.to_string(), b.to_string()))
            .collect();
        let mut set = AovSet::compile(&list, Some("C D{1,2} [LB]")).expect("expressions");
        assert!(set.bind(&scene).is_empty());
        let events = LaneEvents::new(&scene, &set);
        assert!(events.view.is_some(), "a product automaton");
        assert!(events.gathers, "AVX2 and small tables: the lanes gather");
        let states = set.product_states() as u32;
        let classes = events.view.map_or(1, |v| v.tables().2) as u32;
        let mut rng = Pcg32::new(7, 3);
        let mut pick = |n: u32| ((rng.next_f32() * n as f32) as u32).min(n - 1);
        let mut differ_from_start = 0;
        for _ in 0..2000 {
            let q: [u32; LANES] = std::array::from_fn(|_| pick(states));
            let shape: [u32; LANES] = std::array::from_fn(|_| if pick(5) == 0 { ESCAPED } else { pick(scene.shapes.len() as u32) });
            let light: [u32; LANES] = std::array::from_fn(|_| pick(scene.lights.len() as u32));
            let [emitted, nee, goes_on] = [pick(256) as u8, pick(256) as u8, pick(256) as u8];
            let hit: u8 = (0..LANES).fold(0, |m, l| m | ((shape[l] != ESCAPED) as u8) << l);
            let (nee, goes_on) = (nee & hit, goes_on & hit);
            // Some lanes with a scalar BSDF's own classes.
            let own = Reflection { lanes: pick(256) as u8 & hit, nee: std::array::from_fn(|_| pick(classes)), step: std::array::from_fn(|_| pick(classes)) };
            let (mut qa, mut qb) = (q, q);
            let a = events.lookups_scalar(&mut qa, &shape, &light, &own, [emitted, nee, goes_on]);
            // SAFETY: AVX2 was detected above.
            let b = unsafe { events.lookups_avx2(&mut qb, &shape, &light, &own, [emitted, nee, goes_on]) };
            assert_eq!(a, b, "layers for q {q:?}, shapes {shape:?}, lights {light:?}, masks {emitted:b} {nee:b} {goes_on:b}");
            assert_eq!(qa, qb, "stepped states");
            differ_from_start += (qa != q) as u32;
        }
        assert!(differ_from_start > 1000, "the walk steps states");
    }

    /// A lane's results as bits, to compare.
    #[allow(clippy::type_complexity)]
    fn lane_result_bits((nee, s): LaneResult) -> (Option<([u32; 3], u32)>, Option<([u32; 3], [u32; 3], u32, LobeFlags, u32)>) {
        let rgb = |c: Rgb| [c.r, c.g, c.b].map(f32::to_bits);
        (nee.map(|(c, p)| (rgb(c), p.to_bits())), s.map(|s| (s.wi.to_array().map(f32::to_bits), rgb(s.f), s.pdf.to_bits(), s.lobe, s.eta.to_bits())))
    }

    /// `KernelConductor::fixed`: made where the conductor's textures and its normal map are
    /// constant (the map's normal as `Detail::new` makes it, the conductor as `at` any point),
    /// not where the map, the roughness or the reflectance varies, nor under a bump map.
    #[test]
    fn fixed_conductors_are_those_of_constant_textures() {
        let checker = Texture::Checkerboard { color0: Rgb::splat(0.1), color1: Rgb::splat(0.3), to_uv: glam::Affine2::IDENTITY };
        let conductor = |alpha: Texture, refl: Texture| {
            Box::new(Material::Conductor {
                eta: Rgb::new(1.5, 0.9, 0.6),
                k: Rgb::new(3.0, 2.5, 2.0),
                specular_reflectance: refl,
                roughness: Some(Roughness { kind: MicrofacetKind::Ggx, alpha_u: alpha.clone(), alpha_v: Texture::Constant(Rgb::splat(0.05)) }),
            })
        };
        let constant = |c: f32| Texture::Constant(Rgb::splat(c));
        let texel = Rgb::new(0.7, 0.4, 0.9);
        let m = Material::NormalMap { normals: Texture::Constant(texel), inner: conductor(constant(0.25), constant(1.0)) };
        let c = KernelConductor::of(&m, true).unwrap();
        let tp = TexPoint { uv: Vec2::new(0.3, 0.8), ..TexPoint::default() };
        let (fixed, n) = c.fixed.unwrap();
        assert_eq!(format!("{fixed:?}"), format!("{:?}", c.at(tp)));
        assert_eq!(n.map(|n| n.to_array().map(f32::to_bits)), Some(Detail::new(normal_map_normal(texel), true).n.to_array().map(f32::to_bits)));
        for m in [
            Material::NormalMap { normals: checker.clone(), inner: conductor(constant(0.25), constant(1.0)) },
            Material::NormalMap { normals: Texture::Constant(texel), inner: conductor(checker.clone(), constant(1.0)) },
            Material::NormalMap { normals: Texture::Constant(texel), inner: conductor(constant(0.25), checker.clone()) },
            Material::BumpMap { height: constant(0.5), scale: 1.0, inner: conductor(constant(0.25), constant(1.0)) },
        ] {
            assert!(KernelConductor::of(&m, true).unwrap().fixed.is_none(), "{m:?}");
        }
        // Without a map: only textured ones take the route, never fixed.
        assert!(KernelConductor::of(&conductor(checker, constant(1.0)), false).unwrap().fixed.is_none());
    }

    /// The `avx512` arguments of `conductor_detail_lanes` this CPU can run.
    fn conductor_builds() -> Vec<bool> {
        let mut builds = vec![false];
        if crate::cpu::avx512() {
            builds.push(true);
        }
        builds
    }

    /// `conductor_detail_lanes` (rough conductors under normal or bump maps, or none; GGX and
    /// Beckmann lanes mixed; every build) gives the bits of the conductor's `Bsdf` with that
    /// detail, lane by lane. Enough lit lanes see the shadowing term below 1 and enough the
    /// mirrored normal (`wo` below the perturbed one) that a route dropping either, or the
    /// sample's turn back out of the perturbed frame, fails.
    #[test]
    fn conductor_detail_lanes_are_the_detail_bsdf() {
        use crate::bsdf::microfacet::Microfacet;
        let mut rng = Pcg32::new(7, 19);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let (bits, builds) = (lane_result_bits, conductor_builds());
        let (mut shadowed, mut mirrored, mut lit, mut sampled) = (0, 0, 0, 0);
        for batch in 0..6000usize {
            let mut lanes = [None; LANES];
            for (l, x) in lanes.iter_mut().enumerate() {
                let i = batch * LANES + l;
                if i % 11 == 3 {
                    continue;
                }
                let kind = if i.is_multiple_of(2) { MicrofacetKind::Ggx } else { MicrofacetKind::Beckmann };
                let c = RoughConductor {
                    distribution: Microfacet::new(kind, f(0.01, 0.6), f(0.01, 0.6)),
                    eta: Rgb::new(f(0.1, 3.0), f(0.1, 3.0), f(0.1, 3.0)),
                    k: Rgb::new(f(0.0, 5.0), f(0.0, 5.0), f(0.0, 5.0)),
                    specular_reflectance: Rgb::new(f(0.0, 1.0), f(0.0, 1.0), 1.0),
                };
                // Tilted normals (bump maps reach grazing ones), a flat one, or no detail.
                let d = match i % 5 {
                    0 => None,
                    1 => Some(Detail::new(normal_map_normal(Rgb::new(0.5, 0.5, 1.0)), true)),
                    _ => Some(Detail::new(Vec3::new(f(-1.0, 1.0), f(-1.0, 1.0), f(0.05, 1.0)), true)),
                };
                let dir = |z: f32, phi: f32| {
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                };
                let wo = dir(f(-0.2, 1.0), f(0.0, 6.3));
                let wi = (!i.is_multiple_of(4)).then(|| dir(f(-0.3, 1.0), f(0.0, 6.3)));
                *x = Some(ConductorLane { c, d, wo, wi, u: Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) });
            }
            let outs: Vec<_> = builds.iter().map(|&avx512| conductor_detail_lanes(avx512, &lanes)).collect();
            for (l, x) in lanes.iter().enumerate() {
                let Some(x) = x else { continue };
                let b = Bsdf { detail: x.d, ..Bsdf::new(BsdfModel::RoughConductor(x.c)) };
                let want = b.eval_pdf_and_sample(x.wo, x.wi, 0.5, x.u, TransportMode::Radiance);
                for out in &outs {
                    assert_eq!(bits(out[l]), bits(want), "{x:?}");
                }
                let Some(d) = x.d else { continue };
                let nee = want.0.filter(|(v, _)| !v.is_black());
                lit += usize::from(nee.is_some());
                sampled += usize::from(want.1.is_some());
                let lit_wi = nee.and(x.wi);
                if lit_wi.into_iter().chain(want.1.map(|s| s.wi)).any(|w| d.shadowing(w) < 0.99) {
                    shadowed += 1;
                }
                if (nee.is_some() || want.1.is_some()) && x.wo.z * x.wo.dot(d.n) <= 0.0 {
                    mirrored += 1;
                }
            }
        }
        assert!(lit > 5000 && sampled > 5000 && shadowed > 1000 && mirrored > 100, "lit {lit}, sampled {sampled}, shadowed {shadowed}, mirrored {mirrored}");
    }

    /// `conductor_scatter` pools the conductor lanes of several packets into one call of
    /// `conductor_detail_lanes`: a lane's bits are the same in any slot, whatever lanes
    /// share its call (sparse per-packet lanes against the same lanes packed, shifted and
    /// mixed with other packets', GGX and Beckmann, with and without detail).
    #[test]
    fn pooled_conductor_lanes_give_the_per_packet_bits() {
        use crate::bsdf::microfacet::Microfacet;
        let mut rng = Pcg32::new(11, 5);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let (bits, builds) = (lane_result_bits, conductor_builds());
        let dir = |z: f32, phi: f32| {
            let r = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        };
        let mut compared = 0;
        for batch in 0..1500usize {
            // Two packets' lanes, each on about half its lanes.
            let mut packets = [[None; LANES]; 2];
            for (pk, lanes) in packets.iter_mut().enumerate() {
                for (l, x) in lanes.iter_mut().enumerate() {
                    let i = (batch * 2 + pk) * LANES + l;
                    if f(0.0, 1.0) < 0.5 {
                        continue;
                    }
                    let kind = if f(0.0, 1.0) < 0.5 { MicrofacetKind::Ggx } else { MicrofacetKind::Beckmann };
                    let c = RoughConductor {
                        distribution: Microfacet::new(kind, f(0.01, 0.6), f(0.01, 0.6)),
                        eta: Rgb::new(f(0.1, 3.0), f(0.1, 3.0), f(0.1, 3.0)),
                        k: Rgb::new(f(0.0, 5.0), f(0.0, 5.0), f(0.0, 5.0)),
                        specular_reflectance: Rgb::new(f(0.0, 1.0), f(0.0, 1.0), 1.0),
                    };
                    let d = (!i.is_multiple_of(3)).then(|| Detail::new(Vec3::new(f(-1.0, 1.0), f(-1.0, 1.0), f(0.05, 1.0)), true));
                    let wo = dir(f(-0.2, 1.0), f(0.0, 6.3));
                    let wi = (!i.is_multiple_of(4)).then(|| dir(f(-0.3, 1.0), f(0.0, 6.3)));
                    *x = Some(ConductorLane { c, d, wo, wi, u: Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) });
                }
            }
            // Packed as `conductor_scatter` packs them: packet by packet, lane order, a call
            // per eight, the last call's slots past its lanes empty.
            let all: Vec<_> = packets.iter().flatten().flatten().copied().collect();
            for &avx512 in &builds {
                let per_packet = packets.map(|lanes| conductor_detail_lanes(avx512, &lanes));
                let mut pooled = Vec::new();
                for group in all.chunks(LANES) {
                    let mut input = [None; LANES];
                    for (i, x) in group.iter().enumerate() {
                        input[i] = Some(*x);
                    }
                    pooled.extend_from_slice(&conductor_detail_lanes(avx512, &input)[..group.len()]);
                }
                let want = packets.iter().zip(&per_packet).flat_map(|(lanes, out)| lanes.iter().zip(out).filter(|(x, _)| x.is_some()).map(|(_, r)| *r));
                assert_eq!(pooled.len(), all.len());
                for (got, want) in pooled.iter().zip(want) {
                    assert_eq!(bits(*got), bits(want));
                    compared += 1;
                }
            }
        }
        assert!(compared > 10000, "{compared}");
    }

    /// The kernel's rough-conductor lanes, Beckmann and GGX (the baseline build and the AVX2
    /// and AVX-512 copies it runs), give `RoughConductor::eval_pdf_and_sample`'s bits lane by lane, with 1 to 8
    /// lanes used: roughness from its floor to beyond 1, anisotropic, metals and
    /// dielectric-like IORs, incidence from normal to grazing, light directions on both sides
    /// and none, the numbers' ends.
    #[test]
    fn conductor_lanes_are_the_scalar_bsdf() {
        use crate::bsdf::MicrofacetKind;
        for (kind, seed) in [(MicrofacetKind::Beckmann, 9), (MicrofacetKind::Ggx, 10)] {
            conductor_lanes_of(kind, seed);
        }
    }

    fn conductor_lanes_of(kind: crate::bsdf::MicrofacetKind, seed: u64) {
        use crate::bsdf::conductor::RoughConductor;
        use crate::bsdf::microfacet::Microfacet;
        use crate::bsdf::MicrofacetKind;
        let ggx = kind == MicrofacetKind::Ggx;
        let step = |q: &RoughConductorLanes<LANES>, used: usize| if ggx { rough_conductor_ggx_lanes(q, used) } else { rough_conductor_lanes(q, used) };
        #[cfg(target_arch = "x86_64")]
        let copies: Copies<RoughConductorLanes<LANES>, LaneSamples<LANES>> = if ggx { GgxConductorStep::COPIES } else { RoughConductorStep::COPIES };
        let mut rng = Pcg32::new(31, seed);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let alphas = [1e-4f32, 1e-3, 0.01, 0.05, 0.1, 0.3, 1.0, 2.0];
        let us = [0.0f32, 1e-7, 0.5, 1.0 - 6e-8, 1.0];
        let cos_ts = [1.0f32, 0.999_999, 0.5, 1e-2, 1e-4, 1e-6];
        let bits = |(nee, s): (Option<(Rgb, f32)>, Option<BsdfSample>)| {
            let rgb = |c: Rgb| [c.r, c.g, c.b].map(f32::to_bits);
            (nee.map(|(c, p)| (rgb(c), p.to_bits())), s.map(|s| (s.wi.to_array().map(f32::to_bits), rgb(s.f), s.pdf.to_bits(), s.lobe, s.eta.to_bits())))
        };
        let (mut sampled, mut lit) = (0, 0);
        for batch in 0..20_000usize {
            let used = 1 + batch % LANES;
            let mut q = RoughConductorLanes::<LANES>::default();
            let mut lanes = Vec::new();
            for l in 0..used {
                let i = batch * LANES + l;
                let (au, av) = if i.is_multiple_of(3) { (alphas[i / 3 % 8], alphas[i / 24 % 8]) } else { (f(1e-4, 0.6), f(1e-4, 0.6)) };
                let (eta, k) = if i.is_multiple_of(4) {
                    (Rgb::splat(1.5), Rgb::BLACK)
                } else {
                    (Rgb::new(f(0.1, 3.0), f(0.1, 3.0), f(0.1, 3.0)), Rgb::new(f(0.0, 5.0), f(0.0, 5.0), f(0.0, 5.0)))
                };
                let c = RoughConductor { distribution: Microfacet::new(kind, au, av), eta, k, specular_reflectance: Rgb::new(f(0.0, 1.0), f(0.0, 1.0), 1.0) };
                let dir = |cos_t: f32, phi: f32| {
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
                };
                let wo = dir(if i.is_multiple_of(5) { cos_ts[i / 5 % cos_ts.len()] } else { f(1e-3, 1.0) }, f(0.0, 6.3));
                // Near the mirror direction (a smooth plate's lobe), anywhere, below, or none.
                let wi = match i % 4 {
                    0 => Some((Vec3::new(-wo.x, -wo.y, wo.z) + 0.05 * dir(f(-1.0, 1.0), f(0.0, 6.3))).normalize()),
                    1 => Some(dir(f(-1.0, 1.0), f(0.0, 6.3))),
                    2 => Some(dir(f(0.0, 1.0), f(0.0, 6.3))),
                    _ => None,
                };
                let u = if i.is_multiple_of(7) { Vec2::new(us[i / 7 % 5], us[i / 35 % 5]) } else { Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) };
                q.set(l, &c, wo, wi, u);
                lanes.push((c, wo, wi, u));
            }
            let mut outs = vec![step(&q, used)];
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() && crate::cpu::fma() {
                // SAFETY: AVX2 and FMA were detected, AVX-512 where `cpu::avx512()` says so.
                outs.push(unsafe { copies.0(&q, used) });
                if crate::cpu::avx512() {
                    outs.push(unsafe { copies.1(&q, used) });
                }
            }
            for (l, (c, wo, wi, u)) in lanes.iter().enumerate() {
                let want = c.eval_pdf_and_sample(*wo, *wi, *u);
                sampled += usize::from(want.1.is_some());
                lit += usize::from(want.0.is_some_and(|(f, _)| !f.is_black()));
                for (build, out) in outs.iter().enumerate() {
                    assert_eq!(bits(RoughConductorStep::lane(out, l, wi.is_some())), bits(want), "build {build}, {c:?} wo {wo} wi {wi:?} u {u}");
                }
            }
        }
        assert!(sampled > 40_000 && lit > 10_000, "{kind:?}: {sampled} samples, {lit} lit light samples");
    }

    /// The kernel's rough-plastic lanes, Beckmann and GGX (the baseline build and the AVX2
    /// and AVX-512 copies it runs), give `RoughPlastic::eval_pdf` and `sample`'s bits lane by
    /// lane, with 1 to 8 lanes used: several roughnesses, IORs (1 included), sampling weights
    /// (both lobes always, never, mixed), linear and nonlinear bases, incidence from normal
    /// to grazing, light directions on both sides and none, the numbers' ends.
    #[test]
    fn plastic_lanes_are_the_scalar_bsdf() {
        use crate::bsdf::MicrofacetKind;
        for (kind, seed) in [(MicrofacetKind::Beckmann, 5), (MicrofacetKind::Ggx, 6)] {
            plastic_lanes_of(kind, seed);
        }
    }

    fn plastic_lanes_of(kind: crate::bsdf::MicrofacetKind, seed: u64) {
        use crate::bsdf::plastic::RoughPlastic;
        use crate::bsdf::MicrofacetKind;
        let mut rng = Pcg32::new(37, seed);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let mut models = Vec::new();
        for (i, &alpha) in [1e-4f32, 0.01, 0.05, 0.1, 0.4, 1.0].iter().enumerate() {
            for (j, &eta) in [1.5f32, 1.0, 1.9].iter().enumerate() {
                let weight = [0.0f32, 1.0, 0.5, 0.667][(i + j) % 4];
                let diffuse = if (i + j).is_multiple_of(2) { Rgb::new(0.1, 0.27, 0.36) } else { Rgb::splat(0.5) };
                models.push(RoughPlastic::new(kind, alpha, diffuse, Rgb::new(1.0, 0.8, 0.6), eta, j == 2, weight));
            }
        }
        let ggx = kind == MicrofacetKind::Ggx;
        let step = |q: &RoughPlasticLanes<LANES>, used: usize| if ggx { rough_plastic_ggx_lanes(q, used) } else { rough_plastic_lanes(q, used) };
        #[cfg(target_arch = "x86_64")]
        let copies: Copies<RoughPlasticLanes<LANES>, LaneSamples<LANES>> = if ggx { GgxPlasticStep::COPIES } else { RoughPlasticStep::COPIES };
        let us = [0.0f32, 1e-7, 0.5, 1.0 - 6e-8, 1.0];
        let cos_ts = [1.0f32, 0.999_999, 0.5, 1e-2, 1e-4, 1e-6];
        let bits = |(nee, s): (Option<(Rgb, f32)>, Option<BsdfSample>)| {
            let rgb = |c: Rgb| [c.r, c.g, c.b].map(f32::to_bits);
            (nee.map(|(c, p)| (rgb(c), p.to_bits())), s.map(|s| (s.wi.to_array().map(f32::to_bits), rgb(s.f), s.pdf.to_bits(), s.lobe, s.eta.to_bits())))
        };
        let (mut glossy, mut diffuse, mut lit) = (0, 0, 0);
        for batch in 0..12_000usize {
            let used = 1 + batch % LANES;
            let mut q = RoughPlasticLanes::<LANES>::default();
            let mut lanes = Vec::new();
            for l in 0..used {
                let i = batch * LANES + l;
                let p = &models[(i * 7 + batch) % models.len()];
                let dir = |cos_t: f32, phi: f32| {
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
                };
                let wo = dir(if i.is_multiple_of(5) { cos_ts[i / 5 % cos_ts.len()] } else { f(1e-3, 1.0) }, f(0.0, 6.3));
                // Near the mirror direction (the glossy lobe), anywhere, above, or none.
                let wi = match i % 4 {
                    0 => Some((Vec3::new(-wo.x, -wo.y, wo.z) + 0.05 * dir(f(-1.0, 1.0), f(0.0, 6.3))).normalize()),
                    1 => Some(dir(f(-1.0, 1.0), f(0.0, 6.3))),
                    2 => Some(dir(f(0.0, 1.0), f(0.0, 6.3))),
                    _ => None,
                };
                let uc = if i.is_multiple_of(11) { us[i / 11 % 5] } else { f(0.0, 1.0) };
                let u = if i.is_multiple_of(7) { Vec2::new(us[i / 7 % 5], us[i / 35 % 5]) } else { Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) };
                q.set(l, p, wo, wi, uc, u);
                lanes.push((p, wo, wi, uc, u));
            }
            let mut outs = vec![step(&q, used)];
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() && crate::cpu::fma() {
                // SAFETY: AVX2 and FMA were detected, AVX-512 where `cpu::avx512()` says so.
                outs.push(unsafe { copies.0(&q, used) });
                if crate::cpu::avx512() {
                    outs.push(unsafe { copies.1(&q, used) });
                }
            }
            for (l, &(p, wo, wi, uc, u)) in lanes.iter().enumerate() {
                let want = (wi.map(|wi| p.eval_pdf(wo, wi)), p.sample(wo, uc, u, TransportMode::Radiance));
                match want.1.map(|s| s.lobe) {
                    Some(LobeFlags::GLOSSY_REFLECTION) => glossy += 1,
                    Some(_) => diffuse += 1,
                    None => {}
                }
                lit += usize::from(want.0.is_some_and(|(f, _)| !f.is_black()));
                for (build, out) in outs.iter().enumerate() {
                    assert_eq!(bits(RoughPlasticStep::lane(out, l, wi.is_some())), bits(want), "build {build}, {p:?} wo {wo} wi {wi:?} uc {uc} u {u}");
                }
            }
        }
        assert!(glossy > 10_000 && diffuse > 10_000 && lit > 10_000, "{kind:?}: {glossy} glossy and {diffuse} diffuse samples, {lit} lit light samples");
    }

    /// The kernel's rough-dielectric lanes (the baseline build and the AVX2 and AVX-512 copies
    /// it runs) give `RoughDielectric::eval_pdf` and `sample`'s bits (radiance mode) lane by
    /// lane, with 1 to 8 lanes used: roughness from its floor to beyond 1, anisotropic, IORs
    /// above and below 1 (and 1), both sides of the surface, incidence from normal to grazing
    /// (total internal reflection inside), light directions on both sides, near the mirror
    /// and refracted directions, and none, the numbers' ends.
    #[test]
    fn dielectric_lanes_are_the_scalar_bsdf() {
        use crate::bsdf::microfacet::Microfacet;
        use crate::bsdf::MicrofacetKind;
        let mut rng = Pcg32::new(41, 3);
        let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let alphas = [1e-4f32, 1e-3, 0.02, 0.05, 0.1, 0.3, 1.0, 2.0];
        let etas = [1.5168f32, 1.0, 1.33, 2.4, 1.0 / 1.5, 1.0001];
        let us = [0.0f32, 1e-7, 0.5, 1.0 - 6e-8, 1.0];
        let cos_ts = [1.0f32, 0.999_999, 0.5, 1e-2, 1e-4, 1e-6];
        let bits = |(nee, s): (Option<(Rgb, f32)>, Option<BsdfSample>)| {
            let rgb = |c: Rgb| [c.r, c.g, c.b].map(f32::to_bits);
            (nee.map(|(c, p)| (rgb(c), p.to_bits())), s.map(|s| (s.wi.to_array().map(f32::to_bits), rgb(s.f), s.pdf.to_bits(), s.lobe, s.eta.to_bits())))
        };
        let (mut reflected, mut refracted, mut lit, mut lit_through) = (0, 0, 0, 0);
        for batch in 0..20_000usize {
            let used = 1 + batch % LANES;
            let mut q = RoughDielectricLanes::<LANES>::default();
            let mut lanes = Vec::new();
            for l in 0..used {
                let i = batch * LANES + l;
                let (au, av) = if i.is_multiple_of(3) { (alphas[i / 3 % 8], alphas[i / 24 % 8]) } else { (f(1e-4, 0.6), f(1e-4, 0.6)) };
                let d = RoughDielectric {
                    distribution: Microfacet::new(MicrofacetKind::Beckmann, au, av),
                    eta: if i.is_multiple_of(2) { etas[i / 2 % etas.len()] } else { f(0.4, 2.5) },
                    specular_reflectance: Rgb::new(f(0.0, 1.0), 1.0, f(0.0, 1.0)),
                    specular_transmittance: Rgb::new(f(0.0, 1.0), f(0.0, 1.0), 1.0),
                };
                let dir = |cos_t: f32, phi: f32| {
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
                };
                let side = if i % 3 == 1 { -1.0 } else { 1.0 };
                let wo = dir(side * if i.is_multiple_of(5) { cos_ts[i / 5 % cos_ts.len()] } else { f(1e-3, 1.0) }, f(0.0, 6.3));
                // Near the mirror direction, near straight through (a smooth pane's lobes),
                // anywhere, or none.
                let wi = match i % 5 {
                    0 => Some((Vec3::new(-wo.x, -wo.y, wo.z) + 0.05 * dir(f(-1.0, 1.0), f(0.0, 6.3))).normalize()),
                    1 => Some((-wo + 0.05 * dir(f(-1.0, 1.0), f(0.0, 6.3))).normalize()),
                    2 | 3 => Some(dir(f(-1.0, 1.0), f(0.0, 6.3))),
                    _ => None,
                };
                let uc = if i.is_multiple_of(11) { us[i / 11 % 5] } else { f(0.0, 1.0) };
                let u = if i.is_multiple_of(7) { Vec2::new(us[i / 7 % 5], us[i / 35 % 5]) } else { Vec2::new(f(0.0, 1.0), f(0.0, 1.0)) };
                q.set(l, &d, wo, wi, uc, u);
                lanes.push((d, wo, wi, uc, u));
            }
            let mut outs = vec![rough_dielectric_lanes(&q, used)];
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() && crate::cpu::fma() {
                // SAFETY: AVX2 and FMA were detected, AVX-512 where `cpu::avx512()` says so.
                outs.push(unsafe { dielectric8_avx2(&q, used) });
                if crate::cpu::avx512() {
                    outs.push(unsafe { dielectric8_avx512(&q, used) });
                }
            }
            for (l, (d, wo, wi, uc, u)) in lanes.iter().enumerate() {
                let want = (wi.map(|wi| d.eval_pdf(*wo, wi, TransportMode::Radiance)), d.sample(*wo, *uc, *u, TransportMode::Radiance));
                match want.1.map(|s| s.lobe) {
                    Some(LobeFlags::GLOSSY_REFLECTION) => reflected += 1,
                    Some(_) => refracted += 1,
                    None => {}
                }
                let nee = want.0.filter(|(f, _)| !f.is_black()).zip(*wi);
                lit += usize::from(nee.is_some());
                lit_through += usize::from(nee.is_some_and(|(_, wi)| wi.z * wo.z < 0.0));
                for (build, out) in outs.iter().enumerate() {
                    assert_eq!(bits(RoughDielectricStep::lane(out, l, wi.is_some())), bits(want), "build {build}, {d:?} wo {wo} wi {wi:?} uc {uc} u {u}");
                }
            }
        }
        assert!(
            reflected > 10_000 && refracted > 10_000 && lit > 10_000 && lit_through > 3_000,
            "{reflected} reflected and {refracted} refracted samples, {lit} lit light samples ({lit_through} through)"
        );
    }

    /// `shade8` in its own AVX2 and AVX-512 builds (the kernel's) gives the portable
    /// build's outputs bit for bit, on random lanes (both sides, scalar BSDF lanes, lights
    /// at infinity, Russian roulette, zero directions).
    #[test]
    fn shade8_builds_agree() {
        #[cfg(target_arch = "x86_64")]
        {
            if !crate::cpu::avx2() {
                eprintln!("SKIPPED: no AVX2");
                return;
            }
            let mut rng = Pcg32::new(11, 5);
            let mut f = |lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
            let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
            for round in 0..500 {
                let mut v = VertexNums::default();
                let mut st = Paths::new(()).num;
                let rows =
                    |f: &mut dyn FnMut(f32, f32) -> f32, lo: f32, hi: f32| -> [[f32; LANES]; 3] { std::array::from_fn(|_| std::array::from_fn(|_| f(lo, hi))) };
                for a in [&mut v.p, &mut v.ng, &mut v.fs, &mut v.ft, &mut v.fnn, &mut v.wo, &mut v.gwi, &mut v.lp, &mut v.ln, &mut v.bwi] {
                    *a = rows(&mut f, -2.0, 2.0);
                }
                for a in [&mut v.refl, &mut v.lrad, &mut v.bf, &mut v.bweight, &mut st.beta] {
                    *a = rows(&mut f, 0.0, 1.0);
                }
                for a in [&mut v.u_rr, &mut v.gpdf, &mut v.pmf, &mut v.pdf_area, &mut v.bpdf_nee, &mut v.bpdf, &mut st.prev_pdf, &mut st.eta_scale] {
                    *a = std::array::from_fn(|_| f(0.0, 1.0));
                }
                // Some exact centres of the square (a zero direction in `cosine_hemisphere`).
                v.u = std::array::from_fn(|_| std::array::from_fn(|_| if f(0.0, 1.0) < 0.1 { 0.5 } else { f(0.0, 1.0) }));
                for a in [
                    &mut v.has_back,
                    &mut v.nee_ok,
                    &mut v.generic,
                    &mut v.infinite,
                    &mut v.delta,
                    &mut v.scalar_bsdf,
                    &mut v.bmoved,
                    &mut v.bspecular,
                    &mut st.prev_specular,
                ] {
                    *a = std::array::from_fn(|_| f(0.0, 1.0) < 0.5);
                }
                st.depth = std::array::from_fn(|_| f(0.0, 6.0) as i32);
                let run = |which: usize| {
                    let (mut st, mut rays, mut shadow, mut o) = (st.clone(), Rays8::default(), Rays8::default(), Out::default());
                    // SAFETY: AVX2 was detected above, AVX-512 where `cpu::avx512()` says so.
                    match which {
                        0 => shade8(&v, 3, &mut st, &mut rays, &mut shadow, &mut o),
                        1 => unsafe { shade8_avx2(&v, 3, &mut st, &mut rays, &mut shadow, &mut o) },
                        _ => unsafe { shade8_avx512(&v, 3, &mut st, &mut rays, &mut shadow, &mut o) },
                    }
                    (st, rays, shadow, o)
                };
                let want = run(0);
                for which in if crate::cpu::avx512() { 1..3 } else { 1..2 } {
                    let got = run(which);
                    let rows_of = |x: &(PathNums, Rays8, Rays8, Out)| -> Vec<[f32; LANES]> {
                        let (st, r, s, o) = x;
                        let mut v: Vec<[f32; LANES]> = [st.beta, st.prev_p, st.prev_n, r.o, r.d, s.o, s.d, o.c].concat();
                        v.extend([st.prev_pdf, r.t_max, s.t_max]);
                        v
                    };
                    for (a, b) in rows_of(&want).iter().zip(rows_of(&got).iter()) {
                        assert!(a.iter().zip(b).all(|(&a, &b)| same(a, b)), "round {round}, build {which}: {a:?} against {b:?}");
                    }
                    assert_eq!((want.0.prev_specular, want.3.nee, want.3.cont), (got.0.prev_specular, got.3.nee, got.3.cont), "round {round}, build {which}");
                }
            }
        }
    }
}
