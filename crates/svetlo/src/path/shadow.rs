//! Shadow rays tested eight at a time through a packet BVH (`accel::packet`): the
//! connections of one light subpath to the camera all end at the lens, so their walks
//! share most nodes, and one packet walk costs less than their single-ray walks.
//!
//! A lane's answer should be the single ray's: the packet walk's watertight triangle test
//! is the scalar one operation for operation, over the same triangles and (0, t_max), only
//! through another tree (tests/bidir.rs compares them, at triangle edges too).

use crate::accel::packet::{PacketBvh, Rays8, LANES};
use crate::geometry::{Geometry, Ray};
use crate::scene::Scene;

/// Scenes with more triangles than this test shadow rays one at a time: eight rays then
/// share few nodes (the path kernel's bound).
const MAX_TRIANGLES: usize = 20_000;

/// A packet BVH over a scene's triangles for occlusion queries.
pub struct ShadowPackets {
    bvh: PacketBvh,
}

impl ShadowPackets {
    /// None where packets cannot answer for the scene's BVH or would not pay: moving shapes,
    /// a ray epsilon, shapes other than meshes, a large scene, or no eight-wide SIMD.
    pub fn new(scene: &Scene) -> Option<ShadowPackets> {
        if !scene.moving.is_empty() || scene.settings.ray_epsilon > 0.0 || !crate::accel::packet::avx2() {
            return None;
        }
        let mut tris = Vec::new();
        for s in &scene.shapes {
            let Geometry::Mesh(m) = &*s.geometry else { return None };
            if tris.len() + m.triangle_count() > MAX_TRIANGLES {
                return None;
            }
            tris.extend((0..m.triangle_count()).map(|t| m.vertices(t)));
        }
        let bvh = PacketBvh::build(&tris);
        bvh.simd().then_some(ShadowPackets { bvh })
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
        self.bvh.occluded(&r, active)
    }
}
