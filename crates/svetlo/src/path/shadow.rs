//! Shadow rays tested eight at a time through a packet BVH (`accel::packet`): the
//! connections of one light subpath to the camera all end at the lens, so their walks
//! share most nodes, and one packet walk costs less than their single-ray walks.
//!
//! A lane's answer should be the single ray's: the packet walk's watertight triangle test
//! is the scalar one operation for operation, over the same triangles and (0, t_max), only
//! through another tree (tests/bidir.rs compares them, at triangle edges too).
//!
//! The same tree answers closest-hit queries ([`ShadowPackets::closest`]) for walks traced
//! in lockstep (light tracing's light subpaths). There a lane's nearest hit is the single
//! ray's, except where two triangles meet the ray at one distance (coplanar faces such as a
//! glass box's bottom on the floor, shared edges): each tree keeps the one it tests last,
//! so the packet walk flags those lanes (`PacketBvh::intersect_ties`) and they are traced
//! again through the scene's BVH, which makes every lane's surface record the one
//! `Scene::intersect` gives, bit for bit. Only in scenes where no path crosses a surface
//! ([`ShadowPackets::exact_closest`]): with glass the lockstep walk gave the single rays'
//! image (since `accel::packet`'s `HIT_SLACK` enters the flat box of a floor a few ulps
//! nearer than a glass box's bottom) but cost ~5% more CPU than `PacketShadows` (Mitsuba
//! cbox with dielectric boxes, 64², 256 spp).

use super::vertex::push_written;
use super::Vertex;
use crate::accel::packet::{Hits8, PacketBvh, Rays8, LANES};
use crate::bsdf::Material;
use crate::geometry::mesh::TriangleFrame;
use crate::geometry::{Geometry, Ray, SurfaceInteraction};
use crate::light::Light;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::mem::MaybeUninit;

/// Scenes with more triangles than this test shadow rays one at a time: eight rays then
/// share few nodes (the path kernel's bound).
const MAX_TRIANGLES: usize = 20_000;

/// A packet BVH over a scene's triangles for occlusion queries.
pub struct ShadowPackets {
    bvh: PacketBvh,
    /// Per triangle of the packet tree, what its hits' surface records need.
    tris: Vec<HitTriangle>,
    /// Whether closest hits are the scene BVH's (no material lets a path cross a surface).
    exact_closest: bool,
    /// Index in `tris` of each shape's first triangle.
    first: Vec<u32>,
}

/// A triangle's share of `Scene::interaction` for a mesh, gathered once (the packet tree
/// holds few triangles): a lane's hit then reads one entry instead of the shape, the mesh's
/// indices, positions, uvs and normals, and a smooth triangle's normal and dp/du are not
/// computed again at every hit.
struct HitTriangle {
    shape: u32,
    /// The triangle's index in its mesh.
    prim: u32,
    p: [Vec3; 3],
    /// The vertices' uvs (None: the mesh has none, uv = the barycentrics).
    uvs: Option<[Vec2; 3]>,
    shading: TriangleFrame,
    /// Where the shape's material is diffuse of constant reflectance without surface
    /// detail: the reflectance (clamped, as `Vertex::write_surface` takes it) and its area
    /// light, so that the lockstep walks' vertices skip the shape's and material's lookups.
    diffuse: Option<DiffuseSurface>,
}

/// A packet triangle's constant diffuse surface ([`ShadowPackets::diffuse`]).
#[derive(Clone, Copy, Debug)]
struct DiffuseSurface {
    reflectance: Rgb,
    light: Option<u32>,
}

/// A lane's hit on a triangle of constant diffuse material ([`ShadowPackets::diffuse`]).
pub(crate) struct DiffuseHit<'a> {
    tri: &'a HitTriangle,
    surface: &'a DiffuseSurface,
    /// The packet's hits and the lane's index (its distance and barycentrics read where the
    /// walk stored them: copied here, they were read back in a wider word).
    hits: &'a Hits8,
    l: usize,
}

impl DiffuseHit<'_> {
    /// `Vertex::push_surface(path, scene, &interaction, beta, 0.0)` for the hit's surface
    /// record along `ray`, without the scene's lookups of its shape, material and light,
    /// and without the record in memory: built by one call and read back by the next, its
    /// fields were loaded in wider words than they had just been stored with (a
    /// store-forwarding stall a vertex).
    #[inline]
    pub fn push(&self, ray: &Ray, beta: Rgb, path: &mut Vec<Vertex>) {
        push_written(path, |dst| self.write(dst, ray, beta));
    }

    #[inline(never)]
    fn write<'v>(&self, dst: &'v mut MaybeUninit<Vertex>, ray: &Ray, beta: Rgb) -> &'v mut Vertex {
        let (h, l) = (self.hits, self.l);
        let si = self.tri.interaction(h.t[l], h.b1[l], h.b2[l], ray);
        Vertex::write_diffuse_surface(dst, &si, self.surface.reflectance, self.surface.light, beta, 0.0)
    }
}

/// Closest hits of up to eight rays ([`ShadowPackets::closest`]).
pub struct ClosestHits {
    hits: Hits8,
    /// Lanes whose hit ties with another triangle's: traced again through the scene's BVH.
    tied: u8,
}

impl ShadowPackets {
    /// None where packets cannot answer for the scene's BVH or would not pay: moving shapes,
    /// a ray epsilon, shapes other than meshes, a large scene, or no eight-wide SIMD.
    pub fn new(scene: &Scene) -> Option<ShadowPackets> {
        if !scene.moving.is_empty() || scene.settings.ray_epsilon > 0.0 || !crate::cpu::avx2() {
            return None;
        }
        // (The scene's BVH then indexes `scene.shapes` itself, as the packet tree does.)
        if !scene.static_shapes.is_empty() {
            return None;
        }
        let mut tris = Vec::new();
        let mut first = Vec::with_capacity(scene.shapes.len());
        for (shape, s) in scene.shapes.iter().enumerate() {
            let Geometry::Mesh(m) = &*s.geometry else { return None };
            first.push(tris.len() as u32);
            if tris.len() + m.triangle_count() > MAX_TRIANGLES {
                return None;
            }
            let diffuse = match &scene.materials[s.material as usize] {
                Material::Diffuse { reflectance: Texture::Constant(c) } if !s.detail => {
                    let light = s.light.filter(|&li| matches!(scene.lights[li as usize], Light::Area(_)));
                    Some(DiffuseSurface { reflectance: c.clamp(0.0, 1.0), light })
                }
                _ => None,
            };
            tris.extend((0..m.triangle_count()).map(|t| {
                let shading = TriangleFrame::new(s.flat.get(t).copied().flatten(), m, t);
                let uvs = (!m.uvs.is_empty()).then(|| m.indices[t].map(|i| m.uvs[i as usize]));
                HitTriangle { shape: shape as u32, prim: t as u32, p: m.vertices(t), uvs, shading, diffuse }
            }));
        }
        let bvh = PacketBvh::build(&tris.iter().map(|t| t.p).collect::<Vec<_>>());
        let exact_closest = !scene.materials.iter().any(Material::may_cross);
        bvh.simd().then_some(ShadowPackets { bvh, tris, exact_closest, first })
    }

    /// Mask of the rays (at most eight, as `Scene::shadow_ray` makes them) that are blocked.
    pub fn occluded(&self, rays: &[Ray]) -> u8 {
        debug_assert!(rays.len() <= LANES);
        let mut r = Rays8::default();
        let mut active = 0u8;
        for (i, ray) in rays.iter().enumerate().take(LANES) {
            // A ray of no length is clear (as `Scene::occluded_ray` answers).
            if ray.t_max <= 0.0 {
                continue;
            }
            for k in 0..3 {
                r.o[k][i] = ray.o[k];
                r.d[k][i] = ray.d[k];
            }
            r.t_max[i] = ray.t_max;
            active |= 1 << i;
        }
        self.occluded_lanes(&r, active)
    }

    /// Mask of the lanes set in `active` whose ray is blocked (the other lanes are not
    /// read), for callers that fill a packet's lanes themselves.
    #[inline]
    pub fn occluded_lanes(&self, r: &Rays8, active: u8) -> u8 {
        self.bvh.occluded(r, active)
    }

    /// Whether [`Self::closest`] answers as `Scene::intersect` does, bit for bit: in scenes
    /// where no path passes through a surface (see the module's doc).
    pub fn exact_closest(&self) -> bool {
        self.exact_closest
    }

    /// Nearest hits of the rays of the lanes set in `active` (the others miss); the surface
    /// record of lane `l` is then [`Self::interaction`]`(scene, &hits, l, &rays[l])`.
    pub fn closest(&self, rays: &[Ray; LANES], active: u8) -> ClosestHits {
        let mut r = Rays8::default();
        for (i, ray) in rays.iter().enumerate() {
            set_lane(&mut r, i, ray);
        }
        self.closest_packet(&r, active)
    }

    /// [`Self::closest`] of rays the caller put in a packet's lanes ([`set_lane`]); lane `l`'s
    /// ray for [`Self::interaction`] is the one put in lane `l`.
    #[inline]
    pub fn closest_packet(&self, r: &Rays8, active: u8) -> ClosestHits {
        let (hits, tied) = self.bvh.intersect_ties(r, active);
        ClosestHits { hits, tied }
    }

    /// Lane `l`'s surface record as `scene.intersect(ray)` gives it (`ray`: the lane's ray
    /// given to [`Self::closest`]).
    #[inline(always)]
    pub fn interaction(&self, scene: &Scene, hits: &ClosestHits, l: usize, ray: &Ray) -> Option<SurfaceInteraction> {
        if hits.tied & (1 << l) != 0 {
            return scene.intersect(ray);
        }
        // A miss's prim is u32::MAX, past the table.
        let tri = self.tris.get(hits.hits.prim[l] as usize)?;
        Some(tri.interaction(hits.hits.t[l], hits.hits.b1[l], hits.hits.b2[l], ray))
    }

    /// Lane `l`'s hit where [`Self::interaction`] finds it on a triangle of constant diffuse
    /// material, for its vertex to be written at once ([`DiffuseHit::push`]); None: a miss,
    /// a tied lane, another material.
    #[inline(always)]
    pub(crate) fn diffuse<'a>(&'a self, hits: &'a ClosestHits, l: usize) -> Option<DiffuseHit<'a>> {
        if hits.tied & (1 << l) != 0 {
            return None;
        }
        let tri = self.tris.get(hits.hits.prim[l] as usize)?;
        let surface = tri.diffuse.as_ref()?;
        Some(DiffuseHit { tri, surface, hits: &hits.hits, l })
    }

    /// `scene.intersect(ray)`, bit for bit: the scene BVH's hit, its surface record from
    /// the triangle table (BDPT's walks: no walk through the mesh per hit).
    #[inline]
    pub fn intersect(&self, scene: &Scene, ray: &Ray) -> Option<SurfaceInteraction> {
        let h = scene.accel.intersect(ray)?;
        let tri = &self.tris[(self.first[h.shape as usize] + h.prim) as usize];
        Some(tri.interaction(h.t, h.b1, h.b2, ray))
    }
}

impl HitTriangle {
    /// The surface record of a hit at `t` with barycentrics `b1`, `b2` along `ray`:
    /// `Scene::interaction`'s mesh case, operation for operation.
    #[inline(always)]
    fn interaction(&self, t: f32, b1: f32, b2: f32, ray: &Ray) -> SurfaceInteraction {
        let [p0, p1, p2] = self.p;
        let p = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
        let uv = match self.uvs {
            None => Vec2::new(b1, b2),
            Some([t0, t1, t2]) => t0 * (1.0 - b1 - b2) + t1 * b1 + t2 * b2,
        };
        let (ng, shading) = self.shading.at(b1, b2);
        SurfaceInteraction { p, t, ng, shading, uv, shape: self.shape, prim: self.prim, bary: Vec2::new(b1, b2), wo: -ray.d, time: ray.time }
    }
}

/// `ray` into lane `l` of `r` (its time is not a packet's).
#[inline]
pub fn set_lane(r: &mut Rays8, l: usize, ray: &Ray) {
    for k in 0..3 {
        r.o[k][l] = ray.o[k];
        r.d[k][l] = ray.d[k];
    }
    r.t_max[l] = ray.t_max;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Material;
    use crate::camera::Camera;
    use crate::geometry::TriangleMesh;
    use crate::math::warp::square_to_uniform_sphere;
    use crate::sampling::Pcg32;
    use crate::scene::SceneBuilder;
    use crate::spectrum::Rgb;
    use crate::texture::Texture;

    /// A bumpy n×n grid of triangles over z = `z0` (two per cell), with or without uvs and
    /// vertex normals (`normals`: 0 none, 1 smooth, 2 equal per vertex row: flat and smooth
    /// triangles mixed).
    fn grid(z0: f32, n: u32, uvs: bool, normals: u32) -> TriangleMesh {
        let (mut positions, mut ns, mut ts, mut indices) = (vec![], vec![], vec![], vec![]);
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                positions.push(Vec3::new(x, y, z0 + 0.1 * (7.0 * x).sin() * (5.0 * y).cos()));
                ns.push(if normals == 1 {
                    Vec3::new(0.3 * (3.0 * x).sin(), 0.2 * y, 1.0).normalize()
                } else {
                    Vec3::new(0.0, 0.1 * j as f32, 1.0).normalize()
                });
                ts.push(Vec2::new(2.0 * x + 0.1 * y, y * y));
            }
        }
        for j in 0..n {
            for i in 0..n {
                let k = j * (n + 1) + i;
                indices.push([k, k + 1, k + n + 1]);
                indices.push([k + 1, k + n + 2, k + n + 1]);
            }
        }
        TriangleMesh { positions, normals: if normals == 0 { vec![] } else { ns }, uvs: if uvs { ts } else { vec![] }, indices }
    }

    /// A lane's surface record (`closest` then `interaction`), and `intersect`'s, is `Scene::intersect`'s whole,
    /// bit for bit (point, normals, shading frame, uv, indices, wo, time), on flat and smooth
    /// triangles of meshes with and without uvs.
    #[test]
    fn packet_interactions_are_scene_interactions() {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.5)) });
        for (k, (uvs, normals)) in [(false, 0), (true, 1), (false, 1), (true, 2), (true, 0)].into_iter().enumerate() {
            b.add_shape(Geometry::Mesh(grid(0.3 * k as f32, 6, uvs, normals)), m, None, &format!("grid {k}")).unwrap();
        }
        b.set_camera(Camera::pinhole(glam::Mat4::IDENTITY, 60.0, 8, 8));
        let scene = b.build().unwrap();
        let Some(packets) = ShadowPackets::new(&scene) else { return };
        assert!(packets.exact_closest());
        let mut rng = Pcg32::new(5, 17);
        let (mut hits, mut smooth, mut n) = (0, 0, 0);
        for round in 0..4000 {
            let rays: [Ray; LANES] = std::array::from_fn(|_| {
                let o = Vec3::new(rng.next_f32(), rng.next_f32(), -0.5 + 2.5 * rng.next_f32());
                let mut r = Ray::new(o, square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32())));
                r.time = rng.next_f32();
                r
            });
            let active = (rng.next_u32() & 0xff) as u8 | (round & 1) as u8;
            let h = packets.closest(&rays, active);
            for (l, r) in rays.iter().enumerate().filter(|(l, _)| active >> l & 1 == 1) {
                let want = scene.intersect(r);
                let got = packets.interaction(&scene, &h, l, r);
                assert_eq!(format!("{got:?}"), format!("{want:?}"), "round {round} lane {l}");
                let single = packets.intersect(&scene, r);
                assert_eq!(format!("{single:?}"), format!("{want:?}"), "round {round} lane {l}: intersect");
                if let Some(si) = want {
                    hits += 1;
                    smooth += usize::from(scene.shapes[si.shape as usize].flat.get(si.prim as usize).copied().flatten().is_none());
                }
                n += 1;
            }
        }
        assert!(hits > n / 4 && smooth > hits / 4 && smooth < hits * 3 / 4, "{n} rays, {hits} hits, {smooth} on smooth triangles");
    }

    /// A vertex written from a triangle's diffuse constants (`diffuse`, as the lockstep
    /// walks write theirs) is `Vertex::push_surface`'s of the lane's record, bit for bit:
    /// constant reflectances (clamped), an emitting one (its area light), and none for a
    /// textured reflectance.
    #[test]
    fn diffuse_vertices_are_surface_vertices() {
        let mut b = SceneBuilder::new();
        let plain = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::new(1.5, 0.25, -0.5)) });
        let checker = Texture::Checkerboard { color0: Rgb::splat(0.2), color1: Rgb::splat(0.7), to_uv: Default::default() };
        let textured = b.add_material(Material::Diffuse { reflectance: checker });
        for (k, (m, emits)) in [(plain, false), (textured, false), (plain, true)].into_iter().enumerate() {
            let emission = emits.then_some(Texture::Constant(Rgb::splat(3.0)));
            b.add_shape(Geometry::Mesh(grid(0.3 * k as f32, 4, k == 1, 1)), m, emission, &format!("grid {k}")).unwrap();
        }
        b.set_camera(Camera::pinhole(glam::Mat4::IDENTITY, 60.0, 8, 8));
        let scene = b.build().unwrap();
        let Some(packets) = ShadowPackets::new(&scene) else { return };
        let mut rng = Pcg32::new(7, 3);
        let mut seen = [0usize; 3];
        for round in 0..2000 {
            let rays: [Ray; LANES] = std::array::from_fn(|_| {
                let o = Vec3::new(rng.next_f32(), rng.next_f32(), -0.5 + 2.0 * rng.next_f32());
                Ray::new(o, square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32())))
            });
            let h = packets.closest(&rays, 0xff);
            for (l, r) in rays.iter().enumerate() {
                let Some(si) = packets.interaction(&scene, &h, l, r) else { continue };
                let beta = Rgb::new(rng.next_f32(), 1.0, 2.0);
                let mut want = vec![];
                crate::path::Vertex::push_surface(&mut want, &scene, &si, beta, 0.0);
                let Some(d) = packets.diffuse(&h, l) else {
                    assert!(si.shape == 1 || h.tied & (1 << l) != 0, "round {round} lane {l}");
                    seen[0] += 1;
                    continue;
                };
                let mut got = vec![];
                d.push(r, beta, &mut got);
                assert_eq!(format!("{got:?}"), format!("{want:?}"), "round {round} lane {l}");
                seen[1 + usize::from(si.shape == 2)] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 100), "{seen:?}");
    }
}
