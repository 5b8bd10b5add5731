//! The packet tree of a scene's static meshes, kept for the renders of the scene that follow:
//! the path kernel's set-up built it at every render call (on bsdf_spheres' textured sphere,
//! 32k triangles at 128 spp, a sixth of the render call's instructions).

use super::packet::PacketBvh;
use crate::geometry::Geometry;
use std::sync::{Arc, Mutex, Weak};

/// The last packet tree built for a scene, shared by the scene's clones (a render at another
/// resolution). Keyed by the meshes it holds, by allocation: a shape given another mesh, or
/// a mesh changed through `Arc::make_mut` (a new allocation while the key refers to the old
/// one), is another key, so a scene whose public fields change between renders never gets a
/// stale tree. The key's weak references keep the allocations (not the meshes) alive, so
/// no other mesh can take a keyed address.
#[derive(Clone, Default)]
pub struct PacketTreeCache(Arc<Mutex<Option<Entry>>>);

struct Entry {
    meshes: Vec<Weak<Geometry>>,
    tree: Arc<PacketBvh>,
}

impl PacketTreeCache {
    /// The tree over `meshes` (in this order): the kept one when it was built over the same
    /// meshes, else `build()`'s, kept in its place. The lock is not held while building
    /// (the build joins rayon tasks; two renders racing on a new key both build).
    pub fn get_or_build(&self, meshes: &[&Arc<Geometry>], build: impl FnOnce() -> PacketBvh) -> Arc<PacketBvh> {
        let same = |e: &Entry| e.meshes.len() == meshes.len() && e.meshes.iter().zip(meshes).all(|(w, m)| std::ptr::eq(w.as_ptr(), Arc::as_ptr(m)));
        if let Some(e) = self.0.lock().unwrap_or_else(|e| e.into_inner()).as_ref().filter(|e| same(e)) {
            return e.tree.clone();
        }
        let tree = Arc::new(build());
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = Some(Entry { meshes: meshes.iter().map(|m| Arc::downgrade(m)).collect(), tree: tree.clone() });
        tree
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::TriangleMesh;
    use glam::Vec3;

    fn mesh(z: f32) -> Arc<Geometry> {
        Arc::new(Geometry::Mesh(TriangleMesh { positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 1.0, z)], indices: vec![[0, 1, 2]], ..Default::default() }))
    }

    fn tree() -> PacketBvh {
        PacketBvh::build(&[[Vec3::ZERO, Vec3::X, Vec3::Y]])
    }

    #[test]
    fn kept_for_the_same_meshes_rebuilt_for_others() {
        let cache = PacketTreeCache::default();
        let (a, b) = (mesh(0.0), mesh(1.0));
        let builds = std::cell::Cell::new(0);
        let get = |ms: &[&Arc<Geometry>]| {
            cache.get_or_build(ms, || {
                builds.set(builds.get() + 1);
                tree()
            })
        };
        let first = get(&[&a, &b]);
        assert!(Arc::ptr_eq(&first, &get(&[&a, &b])), "the same meshes: the kept tree");
        assert_eq!(builds.get(), 1);
        // Another order, a subset, an equal mesh in another allocation: each a new key.
        get(&[&b, &a]);
        get(&[&a]);
        get(&[&mesh(0.0), &b]);
        assert_eq!(builds.get(), 4);
        // A clone of the cache (a cloned scene) shares the entry.
        let kept = get(&[&a, &b]);
        assert!(Arc::ptr_eq(&kept, &cache.clone().get_or_build(&[&a, &b], || panic!("rebuilt for a clone"))));
    }

    #[test]
    fn a_mesh_changed_through_make_mut_is_a_new_key() {
        let cache = PacketTreeCache::default();
        let mut a = mesh(0.0);
        cache.get_or_build(&[&a], tree);
        if let Geometry::Mesh(m) = Arc::make_mut(&mut a) {
            m.positions[2].z = 5.0;
        }
        let mut rebuilt = false;
        cache.get_or_build(&[&a], || {
            rebuilt = true;
            tree()
        });
        assert!(rebuilt, "the changed mesh took the old tree");
    }
}
