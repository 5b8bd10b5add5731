//! What a renderer derives from a scene's geometry alone (the path kernel's packet tree, its
//! unpacked triangles), kept for the renders of the scene that follow: the path kernel built
//! both at every render call (on bsdf_spheres' textured sphere, 32k triangles at 128 spp, a
//! sixth and then 3 % of the render call's instructions).

use crate::geometry::Geometry;
use std::sync::{Arc, Mutex, Weak};

/// The last value built for a scene, shared by the scene's clones (a render at another
/// resolution). Keyed by the geometry it was built from, by allocation, each with a tag of
/// the caller's (what the allocation stands for: a shape's index, a light's): a shape given
/// another mesh, or a mesh changed through `Arc::make_mut` (a new allocation while the key
/// refers to the old one), is another key, so a scene whose public fields change between
/// renders never gets a stale value (the value must depend on nothing else that may change).
/// The key's weak references keep the allocations (not the meshes) alive, so no other mesh
/// can take a keyed address.
pub struct GeometryCache<T>(Arc<Mutex<Option<Entry<T>>>>);

struct Entry<T> {
    key: Vec<(u32, Weak<Geometry>)>,
    value: Arc<T>,
}

impl<T> Default for GeometryCache<T> {
    fn default() -> Self {
        GeometryCache(Arc::new(Mutex::new(None)))
    }
}

/// A clone shares the entry.
impl<T> Clone for GeometryCache<T> {
    fn clone(&self) -> Self {
        GeometryCache(self.0.clone())
    }
}

impl<T> GeometryCache<T> {
    /// The value built from `key` (tagged allocations, in this order): the kept one when it
    /// was built from the same, else `build()`'s, kept in its place. The lock is not held
    /// while building (a build may join rayon tasks; two renders racing on a new key both
    /// build).
    pub fn get_or_build(&self, key: &[(u32, &Arc<Geometry>)], build: impl FnOnce() -> T) -> Arc<T> {
        if let Some(value) = self.get(key) {
            return value;
        }
        let value = Arc::new(build());
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) =
            Some(Entry { key: key.iter().map(|&(t, m)| (t, Arc::downgrade(m))).collect(), value: value.clone() });
        value
    }

    /// The kept value when it was built from `key`, else None (nothing is built).
    pub fn get(&self, key: &[(u32, &Arc<Geometry>)]) -> Option<Arc<T>> {
        let same =
            |e: &Entry<T>| e.key.len() == key.len() && e.key.iter().zip(key).all(|((ta, w), (tb, m))| ta == tb && std::ptr::eq(w.as_ptr(), Arc::as_ptr(m)));
        self.0.lock().unwrap_or_else(|e| e.into_inner()).as_ref().filter(|e| same(e)).map(|e| e.value.clone())
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

    #[test]
    fn kept_for_the_same_meshes_rebuilt_for_others() {
        let cache = GeometryCache::<u32>::default();
        let (a, b) = (mesh(0.0), mesh(1.0));
        let builds = std::cell::Cell::new(0);
        let get = |key: &[(u32, &Arc<Geometry>)]| {
            cache.get_or_build(key, || {
                builds.set(builds.get() + 1);
                builds.get()
            })
        };
        let first = get(&[(0, &a), (1, &b)]);
        assert!(Arc::ptr_eq(&first, &get(&[(0, &a), (1, &b)])), "the same meshes: the kept value");
        assert_eq!(builds.get(), 1);
        // Another order, a subset, an equal mesh in another allocation, another tag: each a
        // new key.
        get(&[(0, &b), (1, &a)]);
        get(&[(0, &a)]);
        get(&[(0, &mesh(0.0)), (1, &b)]);
        get(&[(0, &a), (2, &b)]);
        assert_eq!(builds.get(), 5);
        // A clone of the cache (a cloned scene) shares the entry.
        let kept = get(&[(0, &a), (1, &b)]);
        assert!(Arc::ptr_eq(&kept, &cache.clone().get_or_build(&[(0, &a), (1, &b)], || panic!("rebuilt for a clone"))));
    }

    #[test]
    fn get_answers_without_building() {
        let cache = GeometryCache::<u32>::default();
        let (a, b) = (mesh(0.0), mesh(1.0));
        assert!(cache.get(&[(0, &a)]).is_none(), "an empty cache holds nothing");
        let built = cache.get_or_build(&[(0, &a)], || 7);
        assert!(cache.get(&[(0, &a)]).is_some_and(|v| Arc::ptr_eq(&v, &built)), "the kept value");
        assert!(cache.get(&[(0, &b)]).is_none() && cache.get(&[(1, &a)]).is_none() && cache.get(&[(0, &a), (1, &b)]).is_none(), "another key");
        // Asking about another key keeps the entry.
        assert_eq!(cache.get(&[(0, &a)]).as_deref(), Some(&7));
    }

    #[test]
    fn a_mesh_changed_through_make_mut_is_a_new_key() {
        let cache = GeometryCache::<u32>::default();
        let mut a = mesh(0.0);
        cache.get_or_build(&[(0, &a)], || 1);
        if let Geometry::Mesh(m) = Arc::make_mut(&mut a) {
            m.positions[2].z = 5.0;
        }
        assert_eq!(*cache.get_or_build(&[(0, &a)], || 2), 2, "the changed mesh took the old value");
    }
}
