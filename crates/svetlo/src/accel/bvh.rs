//! The scene's accelerator: an 8-wide BVH over triangles (stored by value, eight to a
//! SIMD block, in leaf order), a second, small one over analytic spheres and a third over
//! the occupied voxels of SDF grids. A ray walks all three; the nearest hit wins.

use super::build::{build_wide, LeafParams};
use super::packet::Rays8;
use super::pages::{PagedSlice, PagedVec};
use super::tri4::{intersect_half, TriRay};
#[cfg(target_arch = "x86_64")]
use super::tri8::TriRay8;
use super::tri8::{Hit, Tri8, LANES, NO_TRI};
use super::wide::{leaf_code, leaf_range, traverse, BoxRay, Node};
use super::PrimHit;
use crate::geometry::triangle::WatertightRay;
use crate::geometry::{Aabb, Geometry, Ray, SdfGrid, Sphere, TriangleMesh};
use glam::Vec3;

#[derive(Clone)]
pub struct Accel {
    tri_nodes: PagedSlice<Node>,
    tris: PagedSlice<Tri8>,
    /// (first triangle id, shape) per mesh, by first id: triangle ids number all meshes' triangles in turn.
    pub(super) meshes: Vec<(u32, u32)>,
    /// Index into `meshes` of each triangle id, when there are more than [`MESH_SEARCH_MAX`]
    /// meshes (else empty: the hit's mesh is searched for in `meshes`).
    pub(super) tri_mesh: PagedSlice<u32>,
    sph_nodes: PagedSlice<Node>,
    spheres: PagedSlice<Sphere>,
    /// Shape index of each sphere of `spheres`.
    sph_shapes: Vec<u32>,
    sdf_nodes: PagedSlice<Node>,
    /// The SDF grids (their samples shared with the scene's) and the shape of each.
    grids: Vec<(SdfGrid, u32)>,
    /// (grid, voxel) of each voxel primitive, in leaf order.
    voxels: Vec<(u32, u32)>,
    bounds: Aabb,
    /// The hierarchy is larger than the caches: traversal prefetches what it pushes.
    pub(super) prefetch: bool,
    /// The CPU has AVX (and POPCNT): node tests take all eight children at once.
    pub(super) avx: bool,
    /// With `avx`, the CPU has AVX-512F and VL too: the interleaved walks take their copy
    /// compiled with them (`trace_lanes_avx512`).
    pub(super) avx512: bool,
    /// The hierarchy is large enough for alike rays to be walked as one (`accel/coherent.rs`).
    pub(super) coherent: bool,
}

/// Traversal cost 0.15 of a block test: cbox-rgb's rays cost 2% fewer instructions than at
/// 0.3 (its shadow rays 11% fewer), no change measurable on the 1M-triangle bench mesh; lower
/// values change nothing more there.
const TRI_LEAF: LeafParams = LeafParams { group: LANES, max_leaf: 16, traversal_cost: 0.15 };
/// Hierarchies smaller than this (about an L2 cache) are not prefetched: in cache, the
/// prefetch instructions cost more than they save.
const PREFETCH_MIN_BYTES: usize = 1 << 20;
/// Hierarchies smaller than this walk alike rays interleaved rather than as one: the
/// bsdf_spheres scenes (a few megabytes) took 1.04-1.07 the render CPU as one (their rays'
/// walks hit the caches, and the interleaved walks overlap what latency is left), and so did
/// its ten-sphere grid (325k triangles, 16-32 MB: in a 32 MB L3, and ~140 triangles a
/// pixel, so a pixel's rays part at the leaves): test_envmap 1.07, test_arealight 1.03;
/// the 1M-mesh (60 MB) 0.86 at depth 1.
const COHERENT_MIN_BYTES: usize = 32 << 20;
/// Up to this many meshes, a hit's mesh is found by a binary search of `Accel::meshes`
/// (in L1) rather than read from `tri_mesh`, a load at a random place of a megabytes-long
/// array: that load was 5-6 % of the closest-hit samples on the 1M-triangle bench scene
/// (three meshes). Past it, the search's steps would miss the caches themselves.
pub(super) const MESH_SEARCH_MAX: usize = 64;
const SPHERE_LEAF: LeafParams = LeafParams { group: 1, max_leaf: 4, traversal_cost: 1.0 };
/// A voxel test (a cubic's root) costs several box tests: small leaves.
const VOXEL_LEAF: LeafParams = LeafParams { group: 1, max_leaf: 2, traversal_cost: 0.3 };

impl Accel {
    pub fn build(shapes: &[&Geometry]) -> Accel {
        let mut tri_count = 0usize;
        // (first triangle id, mesh) of each mesh with triangles, beside `meshes`: the build reads
        // the triangles from the meshes (an array of them all would be tens of megabytes more to
        // fault in and fill, for one pass of bounds and one of leaf packing).
        let mut tri_src: Vec<(u32, &TriangleMesh)> = Vec::new();
        let mut meshes = Vec::new();
        let mut sph = Vec::new();
        let mut sph_r = Vec::new();
        let mut grids = Vec::new();
        for (si, g) in shapes.iter().enumerate() {
            match g {
                Geometry::Mesh(m) => {
                    if m.triangle_count() > 0 {
                        meshes.push((tri_count as u32, si as u32));
                        tri_src.push((tri_count as u32, m));
                    }
                    tri_count += m.triangle_count();
                }
                Geometry::Sphere(s) => {
                    sph.push(*s);
                    sph_r.push(si as u32);
                }
                Geometry::SdfGrid(g) => grids.push(((**g).clone(), si as u32)),
            }
        }
        assert!(tri_count < u32::MAX as usize, "too many triangles");

        let tri_mesh: Vec<u32> = if meshes.len() > MESH_SEARCH_MAX {
            let mut v = Vec::with_capacity(tri_count);
            for (k, &(first, _)) in meshes.iter().enumerate() {
                let end = meshes.get(k + 1).map_or(tri_count, |m| m.0 as usize);
                v.extend(std::iter::repeat_n(k as u32, end - first as usize));
            }
            v
        } else {
            Vec::new()
        };
        // The vertices of triangle `id`: its mesh found by a search of the few meshes.
        let triangle = |id: u32| {
            let (first, m) = tri_src[tri_src.partition_point(|&(first, _)| first <= id) - 1];
            m.vertices((id - first) as usize)
        };
        // The leaves' triangles in leaf order, and each block's run of them (start, length):
        // the blocks are packed once the tree is built, on all threads (packing them leaf by
        // leaf, reading the meshes' vertices, was a tenth of a 1M-triangle build, on one thread).
        let mut leaf_tris: Vec<u32> = Vec::with_capacity(tri_count);
        let mut blocks: Vec<(u32, u32)> = Vec::with_capacity(tri_count / 3);
        let (tri_nodes, _) = build_wide(
            tri_count,
            |i| Aabb::from_points(&triangle(i as u32)),
            TRI_LEAF,
            |prims| {
                let (start, first) = (blocks.len(), leaf_tris.len());
                // One copy per leaf, not a `memcpy` call per block (this pass runs on one thread).
                leaf_tris.extend_from_slice(prims);
                for (k, chunk) in prims.chunks(LANES).enumerate() {
                    blocks.push(((first + k * LANES) as u32, chunk.len() as u32));
                }
                leaf_code(start, blocks.len() - start)
            },
        );
        let mut tris = PagedVec::with_capacity(blocks.len());
        tris.extend_par(blocks.len(), |b| {
            let (start, len) = blocks[b];
            // On the stack: a block is packed per eight triangles.
            let mut lanes = [([Vec3::ZERO; 3], 0u32); LANES];
            for (lane, &i) in lanes.iter_mut().zip(&leaf_tris[start as usize..(start + len) as usize]) {
                *lane = (triangle(i), i);
            }
            Tri8::new(&lanes[..len as usize])
        });

        let sph_bounds: Vec<Aabb> = sph.iter().map(|s| s.bounds()).collect();
        let mut spheres = Vec::with_capacity(sph.len());
        let mut sph_shapes = Vec::with_capacity(sph.len());
        let (sph_nodes, _) = build_wide(
            sph_bounds.len(),
            |i| sph_bounds[i],
            SPHERE_LEAF,
            |prims| {
                let start = spheres.len();
                for &i in prims {
                    spheres.push(sph[i as usize]);
                    sph_shapes.push(sph_r[i as usize]);
                }
                leaf_code(start, prims.len())
            },
        );

        let mut vox: Vec<(u32, u32)> = Vec::new();
        let mut vox_bounds = Vec::new();
        for (gi, (g, _)) in grids.iter().enumerate() {
            for k in 0..g.voxel_count() {
                vox.push((gi as u32, k as u32));
                vox_bounds.push(g.voxel_bounds(k));
            }
        }
        let mut voxels = Vec::with_capacity(vox.len());
        let (sdf_nodes, _) = build_wide(
            vox_bounds.len(),
            |i| vox_bounds[i],
            VOXEL_LEAF,
            |prims| {
                let start = voxels.len();
                voxels.extend(prims.iter().map(|&i| vox[i as usize]));
                leaf_code(start, prims.len())
            },
        );

        let mut bounds = Aabb::EMPTY;
        for n in [&tri_nodes, &sph_nodes, &sdf_nodes] {
            if let Some(root) = n.first() {
                bounds = bounds.union(root.bounds());
            }
        }
        let bytes = std::mem::size_of_val(&tri_nodes[..])
            + std::mem::size_of_val(&tris[..])
            + std::mem::size_of_val(&sph_nodes[..])
            + std::mem::size_of_val(&spheres[..])
            + std::mem::size_of_val(&sdf_nodes[..]);
        let prefetch = bytes > PREFETCH_MIN_BYTES;
        let coherent = bytes > COHERENT_MIN_BYTES;
        let (tri_nodes, tris, sph_nodes, spheres, sdf_nodes) =
            (tri_nodes.into_slice(), tris.into_slice(), sph_nodes.into_slice(), PagedSlice::new(spheres), sdf_nodes.into_slice());
        // Read once per closest hit, at a random place: on huge pages too.
        let tri_mesh = PagedSlice::new(tri_mesh);
        let avx = has_avx();
        let avx512 = avx && crate::cpu::avx512();
        Accel { tri_nodes, tris, meshes, tri_mesh, sph_nodes, spheres, sph_shapes, sdf_nodes, grids, voxels, bounds, prefetch, avx, avx512, coherent }
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
            // SAFETY: `avx` is set only when the CPU reports AVX and POPCNT.
            return unsafe { self.trace_avx::<ANY>(ray) };
        }
        self.trace_sse::<ANY>(ray)
    }

    /// Out of line, so that `intersect` and `occluded` stay small wrappers around the AVX
    /// path (this one's stack frame would otherwise be set up on every call).
    #[inline(never)]
    fn trace_sse<const ANY: bool>(&self, ray: &Ray) -> Option<PrimHit> {
        let w = WatertightRay::new(ray.o, ray.d);
        self.trace_with::<ANY, false, _>(ray, &TriRay::new(&w), &w)
    }

    /// # Safety
    /// The CPU must support AVX and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn trace_avx<const ANY: bool>(&self, ray: &Ray) -> Option<PrimHit> {
        let w = WatertightRay::new(ray.o, ray.d);
        // SAFETY: this function runs only on CPUs with AVX (see `trace`).
        let tray = unsafe { TriRay8::new(&w) };
        self.trace_with::<ANY, true, _>(ray, &tray, &w)
    }

    /// With `ANY`, returns `Some` (with no meaningful content) at the first hit found.
    #[inline(always)]
    fn trace_with<const ANY: bool, const AVX: bool, K: TriKernel>(&self, ray: &Ray, tray: &K, w: &WatertightRay) -> Option<PrimHit> {
        let bray = BoxRay::new(ray.o, ray.d);
        let mut t_max = ray.t_max;
        let mut hit = None;
        let tris_at = |code| self.tris_at(code);
        let any_hit = traverse::<ANY, AVX>(&self.tri_nodes, &bray, &mut t_max, self.prefetch, tris_at, |code, t_max| {
            self.tri_leaf::<ANY, K>(code, t_max, tray, w, &mut hit)
        });
        if ANY && any_hit {
            return Some(PrimHit { t: t_max, shape: 0, prim: 0, b1: 0.0, b2: 0.0 });
        }
        self.trace_others::<ANY, AVX>(ray, &bray, t_max, hit)
    }

    /// Where a leaf's first triangle block starts: the walks ask for that block only (a
    /// constant length, so no loop), as further blocks are often not reached.
    #[inline(always)]
    fn tris_at(&self, code: u32) -> *const u8 {
        self.tris.as_ptr().wrapping_add(leaf_range(code).0) as *const u8
    }

    /// Tests the ray against the triangle blocks of leaf `code`. Closest hit: records the
    /// nearest one in `hit` (block, lane, b1, b2) and lowers `t_max` to it. With `ANY`,
    /// whether any block is hit. Returns whether the leaf held a hit.
    #[inline(always)]
    fn tri_leaf<const ANY: bool, K: TriKernel>(&self, code: u32, t_max: &mut f32, tray: &K, w: &WatertightRay, hit: &mut Option<TriHit>) -> bool {
        let (start, count) = leaf_range(code);
        debug_assert!(start + count <= self.tris.len());
        // SAFETY: a leaf code of this tree names a run of its blocks (`Accel::build`), so the range
        // lies inside `tris` (unchecked: as the node index in `Walk::step`).
        let blocks = unsafe { self.tris.get_unchecked(start..start + count) };
        if ANY {
            // Any hit ends the walk: no nearest lane, no barycentrics. A loop, not `any`: in
            // the interleaved walk `any` stayed out of line, and its AVX intrinsics with it.
            for block in blocks {
                if tray.occludes(block, w, *t_max) {
                    return true;
                }
            }
            return false;
        }
        let mut found = false;
        for (i, block) in blocks.iter().enumerate() {
            if let Some((lane, t, b1, b2)) = tray.test(block, w, *t_max) {
                *t_max = t;
                *hit = Some((start + i, lane, b1, b2));
                found = true;
            }
        }
        found
    }

    /// The rest of a trace once the triangles are walked (`t_max` lowered to their nearest
    /// hit `tri`, if any): the spheres' and the SDF grids' hierarchies, the nearest hit.
    /// With `ANY` (no triangle hit), `Some` at the first hit.
    #[inline(always)]
    fn trace_others<const ANY: bool, const AVX: bool>(&self, ray: &Ray, bray: &BoxRay, mut t_max: f32, tri: Option<TriHit>) -> Option<PrimHit> {
        let mut best = tri.map(|hit| self.tri_hit(t_max, hit));
        if let Some(i) = nearest_prim::<ANY, AVX, _>(&self.sph_nodes, bray, &mut t_max, self.prefetch, &self.spheres, |s, t| s.intersect(ray.o, ray.d, t)) {
            if ANY {
                return Some(PrimHit { t: t_max, shape: 0, prim: 0, b1: 0.0, b2: 0.0 });
            }
            best = Some(PrimHit { t: t_max, shape: self.sph_shapes[i], prim: 0, b1: 0.0, b2: 0.0 });
        }
        let voxel = |&(g, k): &(u32, u32), t| self.grids[g as usize].0.intersect_voxel(k as usize, ray.o, ray.d, t);
        if let Some(i) = nearest_prim::<ANY, AVX, _>(&self.sdf_nodes, bray, &mut t_max, self.prefetch, &self.voxels, voxel) {
            let (g, k) = self.voxels[i];
            // prim: the voxel's number in its grid (`SdfGrid::normals_at`).
            best = Some(PrimHit { t: t_max, shape: self.grids[g as usize].1, prim: k, b1: 0.0, b2: 0.0 });
        }
        best
    }
}

/// Where a caller reads first after a closest hit (its triangle's record for shading): the
/// interleaved walks ask for a hit's record as they find it, so that it arrives while they
/// go on (read after the walks, it was a miss at a random place of a large array per hit).
pub struct HitRecords {
    /// Per mesh of the tree (`Accel::meshes`), the address of its first triangle's record;
    /// 0 for none. Addresses, never read: only prefetched, which cannot fault.
    base: Vec<usize>,
    /// Bytes from one triangle's record to the next, and a record's.
    stride: usize,
    size: usize,
}

impl HitRecords {
    /// None asked for.
    pub const NONE: HitRecords = HitRecords { base: Vec::new(), stride: 0, size: 0 };
}

/// The rays of [`Accel::intersect_lanes`] and [`Accel::occluded_lanes`].
pub const RAY_LANES: usize = 8;

/// Eight rays as the lane walks read them: an array of rays, or rows of lanes (`Rays8`, as
/// the path kernel keeps them: no array of rays built for a walk that makes rows again).
/// (Rows alone, arrays converted at `intersect_lanes`, with the walks no longer generic,
/// cost bsdf_spheres' test_envmap and test_arealight 1.08-1.09 of the render time in the
/// kernel, which passes rows either way: the walks' code generation, not the conversion.)
pub trait LaneRays {
    /// Lane `l`'s ray (its time unread by the walks).
    fn ray(&self, l: usize) -> Ray;
    /// The rays as rows, where they are kept so.
    #[inline(always)]
    fn rows(&self) -> Option<&Rays8> {
        None
    }
}

impl LaneRays for [Ray; RAY_LANES] {
    #[inline(always)]
    fn ray(&self, l: usize) -> Ray {
        self[l]
    }
}

impl LaneRays for Rays8 {
    #[inline(always)]
    fn ray(&self, l: usize) -> Ray {
        Ray::with_max(Vec3::new(self.o[0][l], self.o[1][l], self.o[2][l]), Vec3::new(self.d[0][l], self.d[1][l], self.d[2][l]), self.t_max[l])
    }
    #[inline(always)]
    fn rows(&self) -> Option<&Rays8> {
        Some(self)
    }
}

/// A triangle hit found by the walk: (block, lane, b1, b2).
type TriHit = (usize, usize, f32, f32);

impl Accel {
    /// The closest hit of each ray `rays[l]` whose bit `l` is set in `active` (`None` for
    /// the others): what [`Accel::intersect`] gives each, bit for bit. In a hierarchy larger
    /// than the caches, the rays' walks of the triangles take turns node by node, each
    /// prefetching its next node or leaf, so that the rays wait on memory together rather
    /// than one after the other.
    pub fn intersect_lanes(&self, rays: &[Ray; RAY_LANES], active: u8) -> [Option<PrimHit>; RAY_LANES] {
        self.intersect_lanes_asking(rays, active, &HitRecords::NONE)
    }

    /// [`Accel::intersect_lanes`], the hits' `records` asked for as the walks find them.
    pub fn intersect_lanes_asking(&self, rays: &[Ray; RAY_LANES], active: u8, records: &HitRecords) -> [Option<PrimHit>; RAY_LANES] {
        let mut hits = [None; RAY_LANES];
        self.intersect_lanes_with(rays, active, records, |l, hit| hits[l] = hit);
        hits
    }

    /// [`Accel::intersect_lanes_asking`] of rays of either form, each active lane's hit
    /// handed to `done(lane, hit)` (no array of hits for the caller to copy out).
    #[inline(always)]
    pub fn intersect_lanes_with(&self, rays: &impl LaneRays, active: u8, records: &HitRecords, mut done: impl FnMut(usize, Option<PrimHit>)) {
        #[cfg(target_arch = "x86_64")]
        if self.avx && self.prefetch && !self.tri_nodes.is_empty() {
            // SAFETY: `avx` is set only when the CPU reports AVX and POPCNT.
            unsafe {
                if self.coherent && active.count_ones() >= COHERENT_MIN {
                    self.trace_coherent_avx(rays, active, records, done)
                } else {
                    self.trace_lanes::<false>(rays, active, records, done)
                }
            };
            return;
        }
        for l in (0..RAY_LANES).filter(|&l| active & (1 << l) != 0) {
            done(l, self.intersect(&rays.ray(l)));
        }
    }

    /// The mask of the rays of `active` (as in [`Accel::intersect_lanes`]) that something blocks.
    pub fn occluded_lanes(&self, rays: &[Ray; RAY_LANES], active: u8) -> u8 {
        self.occluded_lanes_of(rays, active)
    }

    /// [`Accel::occluded_lanes`] of rays of either form.
    #[inline(always)]
    pub fn occluded_lanes_of(&self, rays: &impl LaneRays, active: u8) -> u8 {
        #[cfg(target_arch = "x86_64")]
        if self.avx && self.prefetch && !self.tri_nodes.is_empty() {
            let mut blocked = 0;
            // SAFETY: `avx` is set only when the CPU reports AVX and POPCNT.
            unsafe { self.trace_lanes::<true>(rays, active, &HitRecords::NONE, |l, hit| blocked |= (hit.is_some() as u8) << l) };
            return blocked;
        }
        (0..RAY_LANES).filter(|&l| active & (1 << l) != 0 && self.occluded(&rays.ray(l))).fold(0, |m, l| m | 1 << l)
    }

    /// [`Accel::trace_lanes_body`] in the copy for this CPU.
    ///
    /// # Safety
    /// The CPU must support AVX and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn trace_lanes<const ANY: bool>(&self, rays: &impl LaneRays, active: u8, records: &HitRecords, done: impl FnMut(usize, Option<PrimHit>)) {
        // SAFETY: the caller's contract; `avx512` is set only where the CPU has AVX-512F and VL too.
        unsafe {
            if self.avx512 {
                self.trace_lanes_avx512::<ANY>(rays, active, records, done)
            } else {
                self.trace_lanes_avx::<ANY>(rays, active, records, done)
            }
        }
    }

    /// # Safety
    /// The CPU must support AVX and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn trace_lanes_avx<const ANY: bool>(&self, rays: &impl LaneRays, active: u8, records: &HitRecords, done: impl FnMut(usize, Option<PrimHit>)) {
        // SAFETY: this function runs only on CPUs with AVX and POPCNT.
        unsafe { self.trace_lanes_body::<ANY, false>(rays, active, records, done) }
    }

    /// The same walks compiled with AVX-512VL: the same operations (no FMA is enabled, so no
    /// rounding changes), with 32 vector registers where AVX has 16, so that a lane's ray
    /// stays in registers through a leaf's blocks instead of being copied to the stack at
    /// every leaf.
    ///
    /// # Safety
    /// The CPU must support AVX2, POPCNT, AVX-512F and AVX-512VL.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,popcnt,avx512f,avx512vl")]
    unsafe fn trace_lanes_avx512<const ANY: bool>(&self, rays: &impl LaneRays, active: u8, records: &HitRecords, done: impl FnMut(usize, Option<PrimHit>)) {
        // SAFETY: this function runs only on CPUs with these sets.
        unsafe { self.trace_lanes_body::<ANY, true>(rays, active, records, done) }
    }

    /// `trace` of each active lane, the triangle walks interleaved (see `intersect_lanes`):
    /// each lane takes the steps its own walk would, so its hit is the same. Each active
    /// lane's hit goes to `done(lane, hit)`: not into an array returned whole, whose copy
    /// out read each lane's fields, just stored one by one, with wide loads (a
    /// store-forwarding stall, 22 % of the occlusion walk's samples on bsdf_spheres).
    ///
    /// `COPY` only tells the two copies apart: each then has closures of its own, inlined into
    /// it, where closures shared by both stayed out of line, compiled without AVX (the
    /// intrinsics in them became calls: three times the render's time).
    ///
    /// # Safety
    /// The CPU must support AVX and POPCNT, and the caller must be compiled with them.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn trace_lanes_body<const ANY: bool, const COPY: bool>(
        &self,
        rays: &impl LaneRays,
        active: u8,
        records: &HitRecords,
        mut done: impl FnMut(usize, Option<PrimHit>),
    ) {
        use super::wide::{Walk, WalkStack};
        use std::mem::MaybeUninit;
        struct Lane {
            bray: BoxRay,
            tray: TriRay8,
            w: WatertightRay,
            t_max: f32,
            hit: Option<TriHit>,
            walk: Walk,
        }
        let mut stacks: [WalkStack; RAY_LANES] = [const { Walk::stack() }; RAY_LANES];
        // Set up in place, active lanes only (an array built whole was copied, 2.5 KB a call).
        let mut lanes: [MaybeUninit<Lane>; RAY_LANES] = [const { MaybeUninit::uninit() }; RAY_LANES];
        let mut set_up = active;
        while set_up != 0 {
            let l = set_up.trailing_zeros() as usize & (RAY_LANES - 1);
            set_up &= set_up - 1;
            let r = rays.ray(l);
            let w = WatertightRay::new(r.o, r.d);
            // SAFETY: this function runs only on CPUs with AVX.
            let tray = unsafe { TriRay8::new(&w) };
            lanes[l].write(Lane { bray: BoxRay::new(r.o, r.d), tray, w, t_max: r.t_max, hit: None, walk: Walk::new() });
        }
        let nodes = &self.tri_nodes[..];
        let tris_at = |code| self.tris_at(code);
        // Entries asked for at their pop (see `Walk::step`) where the tree fits the last-level
        // cache: on bsdf_spheres' four spheres (128k triangles) the render ran 2 % fewer
        // instructions in the same time; the 1M-triangle mesh (in memory) took 1.01-1.02.
        let lazy = !self.coherent;
        let mut live = active;
        while live != 0 {
            let mut turn = live;
            while turn != 0 {
                let l = turn.trailing_zeros() as usize & (RAY_LANES - 1);
                turn &= turn - 1;
                // SAFETY: `live` is a subset of `active`, whose lanes were all written above.
                let lane = unsafe { lanes[l].assume_init_mut() };
                let mut leaf = |code, t_max: &mut f32| {
                    let found = self.tri_leaf::<ANY, TriRay8>(code, t_max, &lane.tray, &lane.w, &mut lane.hit);
                    if let (false, true, Some((block, tri, _, _))) = (ANY, found, lane.hit) {
                        self.ask_record(records, block, tri);
                    }
                    found
                };
                // A lane keeps the turn while its next entry was asked for steps ago (likely in cache).
                loop {
                    if !lane.walk.step::<ANY, true>(&mut stacks[l], nodes, &lane.bray, &mut lane.t_max, true, true, lazy, &tris_at, &mut leaf) {
                        live &= !(1 << l);
                        break;
                    }
                    if lane.walk.fresh() {
                        break;
                    }
                }
            }
        }
        // The spheres' and grids' trees, where the scene has any (as `trace_coherent_avx`): the
        // calls for two empty trees were a fifth of a ray's set-up and finish (~45 of ~200
        // instructions, the 1M-triangle mesh).
        let others = !self.sph_nodes.is_empty() || !self.sdf_nodes.is_empty();
        let mut finish = active;
        while finish != 0 {
            let l = finish.trailing_zeros() as usize & (RAY_LANES - 1);
            finish &= finish - 1;
            // SAFETY: lane l is active, so it was written above.
            let lane = unsafe { lanes[l].assume_init_ref() };
            let hit = if ANY && lane.walk.found() {
                Some(PrimHit { t: lane.t_max, shape: 0, prim: 0, b1: 0.0, b2: 0.0 })
            } else if others {
                self.trace_others::<ANY, true>(&rays.ray(l), &lane.bray, lane.t_max, lane.hit)
            } else {
                // What `trace_others` gives with both trees empty (an occlusion walk records no hit).
                lane.hit.map(|h| self.tri_hit(lane.t_max, h))
            };
            done(l, hit);
        }
    }
}

/// Fewest rays worth a coherent walk (`accel/coherent.rs`).
#[cfg(target_arch = "x86_64")]
const COHERENT_MIN: u32 = 4;

impl Accel {
    /// [`Accel::trace_lanes`] for closest hits, the rays walked as one where they are
    /// alike (one octant, near directions and origins: `accel/coherent.rs`), else interleaved. Each ray's hit is
    /// the one its single walk finds, bit for bit: a ray whose nearest hit may tie with
    /// another, or that met a triangle on an edge, is walked again alone.
    ///
    /// # Safety
    /// The CPU must support AVX and POPCNT.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn trace_coherent_avx(&self, rays: &impl LaneRays, active: u8, records: &HitRecords, mut done: impl FnMut(usize, Option<PrimHit>)) {
        use super::coherent::{walk, Coherent, TIE};
        // SAFETY: this function runs only on CPUs with AVX.
        let b = self.bounds;
        let Some(c) = (unsafe { Coherent::new(rays, active, (b.max - b.min).max_element()) }) else {
            // SAFETY: as above.
            return unsafe { self.trace_lanes::<false>(rays, active, records, done) };
        };
        // SAFETY: as above.
        let f = unsafe { walk(&self.tri_nodes, &self.tris, &c, active, self.prefetch, |code| self.tris_at(code)) };
        // The spheres' and grids' trees, where the scene has any, ray by ray.
        let others = !self.sph_nodes.is_empty() || !self.sdf_nodes.is_empty();
        let mut again = f.again as u8 & active;
        let mut finish = active & !again;
        while finish != 0 {
            let l = finish.trailing_zeros() as usize & (RAY_LANES - 1);
            finish &= finish - 1;
            let r = rays.ray(l);
            let hit = (f.slot[l] >= 0).then(|| (f.slot[l] as usize / LANES, f.slot[l] as usize % LANES, f.b1[l], f.b2[l]));
            if hit.is_some() && f.rival[l] <= f.t[l] * (1.0 + TIE) {
                again |= 1 << l;
                continue;
            }
            let t = if hit.is_some() { f.t[l] } else { r.t_max };
            done(l, if others { self.trace_others::<false, true>(&r, &BoxRay::new(r.o, r.d), t, hit) } else { hit.map(|h| self.tri_hit(t, h)) });
        }
        if again != 0 {
            // SAFETY: as above.
            unsafe { self.trace_lanes::<false>(rays, again, records, done) };
        }
    }

    /// `records` of the triangle in `block`'s `lane` (see [`HitRecords`]), where the tree has
    /// few meshes (else finding the triangle's mesh would be a miss of its own).
    #[inline(always)]
    fn ask_record(&self, records: &HitRecords, block: usize, lane: usize) {
        if records.base.is_empty() || !self.tri_mesh.is_empty() {
            return;
        }
        let id = self.tris[block].ids[lane & (LANES - 1)];
        let k = self.mesh_of(id);
        if let (Some(&base), Some(&(first, _))) = (records.base.get(k), self.meshes.get(k)) {
            if base != 0 {
                // + 63: a record that starts inside a line may reach a line further.
                super::wide::prefetch((base as *const u8).wrapping_add((id - first) as usize * records.stride), records.size + 63);
            }
        }
    }

    /// [`HitRecords`] of `size` bytes every `stride` bytes, each mesh's first at
    /// `first(shape)` (the shape's index among those the tree was built from; None: not asked for).
    pub fn hit_records(&self, stride: usize, size: usize, first: impl Fn(u32) -> Option<*const u8>) -> HitRecords {
        let base = self.meshes.iter().map(|&(_, shape)| first(shape).map_or(0, |p| p as usize)).collect();
        HitRecords { base, stride, size }
    }

    /// The closest hit of a triangle hit `(block, lane, b1, b2)` at `t`.
    #[inline(always)]
    fn tri_hit(&self, t: f32, (b, lane, b1, b2): TriHit) -> PrimHit {
        let id = self.tris[b].ids[lane];
        let (first, shape) = self.meshes[self.mesh_of(id)];
        PrimHit { t, shape, prim: id - first, b1, b2 }
    }
}

impl Accel {
    /// Index into `meshes` of the mesh that holds triangle `id`.
    #[inline(always)]
    pub(super) fn mesh_of(&self, id: u32) -> usize {
        if self.tri_mesh.is_empty() {
            // The last mesh whose first id is at most `id` (the first one's is 0). A few
            // meshes: the branch-free search of a slice in L1.
            self.meshes.partition_point(|&(first, _)| first <= id).saturating_sub(1)
        } else {
            self.tri_mesh[id as usize] as usize
        }
    }
}

/// The nearest primitive of `prims` (with `ANY`, any) that a ray meets in the leaves of
/// `nodes`, `intersect(prim, t_max)` giving its distance: its index, with `t_max` set to it.
#[inline(always)]
fn nearest_prim<const ANY: bool, const AVX: bool, P>(
    nodes: &[Node],
    bray: &BoxRay,
    t_max: &mut f32,
    prefetch: bool,
    prims: &[P],
    intersect: impl Fn(&P, f32) -> Option<f32>,
) -> Option<usize> {
    let mut hit = None;
    traverse::<ANY, AVX>(
        nodes,
        bray,
        t_max,
        prefetch,
        |code| prims.as_ptr().wrapping_add(leaf_range(code).0) as *const u8,
        |code, t_max| {
            let (start, count) = leaf_range(code);
            let mut found = false;
            for (i, p) in prims[start..start + count].iter().enumerate() {
                if let Some(t) = intersect(p, *t_max) {
                    *t_max = t;
                    hit = Some(start + i);
                    found = true;
                    if ANY {
                        break;
                    }
                }
            }
            found
        },
    );
    hit
}

/// The triangle block test of one ray, by instruction set.
pub(super) trait TriKernel {
    /// Nearest hit of the block in `(0, t_max]`: (lane, t, b1, b2).
    fn test(&self, block: &Tri8, w: &WatertightRay, t_max: f32) -> Option<Hit>;

    /// Whether the block has any hit in `(0, t_max]` (`test(..).is_some()`).
    #[inline(always)]
    fn occludes(&self, block: &Tri8, w: &WatertightRay, t_max: f32) -> bool {
        self.test(block, w, t_max).is_some()
    }
}

impl TriKernel for TriRay {
    #[inline(always)]
    fn test(&self, block: &Tri8, w: &WatertightRay, t_max: f32) -> Option<Hit> {
        let lo = intersect_half(block, 0, self, w, t_max);
        if block.ids[4] == NO_TRI {
            return lo;
        }
        // The upper half wins only when strictly nearer: on a tie the lowest lane wins, as with AVX.
        match intersect_half(block, 1, self, w, lo.map_or(t_max, |h| h.1)) {
            Some(hi) if lo.is_none_or(|l| hi.1 < l.1) => Some(hi),
            _ => lo,
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl TriKernel for TriRay8 {
    #[inline(always)]
    fn test(&self, block: &Tri8, w: &WatertightRay, t_max: f32) -> Option<Hit> {
        // SAFETY: a TriRay8 exists only on CPUs with AVX (its constructor's contract), and it is
        // used only inside `trace_avx`, which is compiled with AVX enabled.
        unsafe { block.intersect_avx(self, w, t_max) }
    }

    #[inline(always)]
    fn occludes(&self, block: &Tri8, w: &WatertightRay, t_max: f32) -> bool {
        // SAFETY: as in `test`.
        unsafe { block.occludes_avx(self, w, t_max) }
    }
}

fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        // POPCNT comes with every AVX CPU; the walk's sorted pushes count with it.
        std::is_x86_feature_detected!("avx") && std::is_x86_feature_detected!("popcnt") && std::env::var_os("SVETLO_NO_AVX").is_none()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
