//! The scene's accelerator: an 8-wide BVH over triangles (stored by value, four to a
//! SIMD block, in leaf order) and a second, small one over analytic spheres. A ray
//! walks both; the nearer hit wins.

use super::build::{build_wide, LeafParams};
use super::tri4::{Tri4, TriRay};
use super::wide::{leaf_code, leaf_range, prefetch, traverse, BoxRay, Node};
use super::PrimHit;
use crate::geometry::{Aabb, Geometry, Ray, Sphere};
use glam::Vec3;

pub struct Accel {
    tri_nodes: Vec<Node>,
    tris: Vec<Tri4>,
    /// (first triangle id, shape) per mesh, by first id: triangle ids number all meshes' triangles in turn.
    meshes: Vec<(u32, u32)>,
    sph_nodes: Vec<Node>,
    spheres: Vec<Sphere>,
    /// Shape index of each sphere of `spheres`.
    sph_shapes: Vec<u32>,
    bounds: Aabb,
    /// The CPU has AVX: node tests take all eight children at once.
    pub(super) avx: bool,
}

const TRI_LEAF: LeafParams = LeafParams { group: 4, max_leaf: 16, traversal_cost: 0.3 };
const SPHERE_LEAF: LeafParams = LeafParams { group: 1, max_leaf: 4, traversal_cost: 1.0 };

impl Accel {
    pub fn build(shapes: &[&Geometry]) -> Accel {
        let mut tri_v: Vec<[Vec3; 3]> = Vec::new();
        let mut meshes = Vec::new();
        let mut sph = Vec::new();
        let mut sph_r = Vec::new();
        for (si, g) in shapes.iter().enumerate() {
            match g {
                Geometry::Mesh(m) => {
                    if m.triangle_count() > 0 {
                        meshes.push((tri_v.len() as u32, si as u32));
                    }
                    tri_v.extend((0..m.triangle_count()).map(|t| m.vertices(t)));
                }
                Geometry::Sphere(s) => {
                    sph.push(*s);
                    sph_r.push(si as u32);
                }
            }
        }

        let tri_bounds: Vec<Aabb> = tri_v.iter().map(|t| Aabb::from_points(t)).collect();
        assert!(tri_v.len() < u32::MAX as usize, "too many triangles");
        let mut tris = Vec::with_capacity(tri_v.len() / 3);
        let (tri_nodes, _) = build_wide(&tri_bounds, TRI_LEAF, |prims| {
            let start = tris.len();
            for chunk in prims.chunks(4) {
                let lanes: Vec<([Vec3; 3], u32)> = chunk.iter().map(|&i| (tri_v[i as usize], i)).collect();
                tris.push(Tri4::new(&lanes));
            }
            leaf_code(start, tris.len() - start)
        });

        let sph_bounds: Vec<Aabb> = sph.iter().map(|s| s.bounds()).collect();
        let mut spheres = Vec::with_capacity(sph.len());
        let mut sph_shapes = Vec::with_capacity(sph.len());
        let (sph_nodes, _) = build_wide(&sph_bounds, SPHERE_LEAF, |prims| {
            let start = spheres.len();
            for &i in prims {
                spheres.push(sph[i as usize]);
                sph_shapes.push(sph_r[i as usize]);
            }
            leaf_code(start, prims.len())
        });

        let mut bounds = Aabb::EMPTY;
        for n in [&tri_nodes, &sph_nodes] {
            if let Some(root) = n.first() {
                bounds = bounds.union(root.bounds());
            }
        }
        Accel { tri_nodes, tris, meshes, sph_nodes, spheres, sph_shapes, bounds, avx: has_avx() }
    }

    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    pub fn intersect(&self, ray: &Ray) -> Option<PrimHit> {
        self.trace::<false>(ray)
    }

    pub fn occluded(&self, ray: &Ray) -> bool {
        self.trace::<true>(ray).is_some()
    }

    #[inline(always)]
    fn trace<const ANY: bool>(&self, ray: &Ray) -> Option<PrimHit> {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only when the CPU reports AVX.
            return unsafe { self.trace_avx::<ANY>(ray) };
        }
        self.trace_with::<ANY, false>(ray)
    }

    /// # Safety
    /// The CPU must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn trace_avx<const ANY: bool>(&self, ray: &Ray) -> Option<PrimHit> {
        self.trace_with::<ANY, true>(ray)
    }

    #[inline(always)]
    fn trace_with<const ANY: bool, const AVX: bool>(&self, ray: &Ray) -> Option<PrimHit> {
        let bray = BoxRay::new(ray.o, ray.d);
        let mut t_max = ray.t_max;
        let mut best: Option<PrimHit> = None;
        if !self.tri_nodes.is_empty() {
            let tray = TriRay::new(ray.o, ray.d);
            let mut hit: Option<(u32, f32, f32)> = None;
            let prefetch_leaf = |code| {
                let (start, count) = leaf_range(code);
                prefetch(self.tris.as_ptr().wrapping_add(start), count * std::mem::size_of::<Tri4>());
            };
            traverse::<ANY, AVX>(&self.tri_nodes, &bray, &mut t_max, prefetch_leaf, |code, t_max| {
                let (start, count) = leaf_range(code);
                let mut found = false;
                for block in &self.tris[start..start + count] {
                    if let Some((lane, t, b1, b2)) = block.intersect(&tray, *t_max) {
                        *t_max = t;
                        hit = Some((block.ids[lane], b1, b2));
                        found = true;
                        if ANY {
                            break;
                        }
                    }
                }
                found
            });
            if let Some((id, b1, b2)) = hit {
                let (first, shape) = self.meshes[self.meshes.partition_point(|m| m.0 <= id) - 1];
                best = Some(PrimHit { t: t_max, shape, prim: id - first, b1, b2 });
                if ANY {
                    return best;
                }
            }
        }
        if !self.sph_nodes.is_empty() {
            let mut hit = None;
            traverse::<ANY, AVX>(
                &self.sph_nodes,
                &bray,
                &mut t_max,
                |_| {},
                |code, t_max| {
                    let (start, count) = leaf_range(code);
                    let mut found = false;
                    for i in start..start + count {
                        if let Some(t) = self.spheres[i].intersect(ray.o, ray.d, *t_max) {
                            *t_max = t;
                            hit = Some(i);
                            found = true;
                            if ANY {
                                break;
                            }
                        }
                    }
                    found
                },
            );
            if let Some(i) = hit {
                best = Some(PrimHit { t: t_max, shape: self.sph_shapes[i], prim: 0, b1: 0.0, b2: 0.0 });
            }
        }
        best
    }
}

fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx") && std::env::var_os("SVETLO_NO_AVX").is_none()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
