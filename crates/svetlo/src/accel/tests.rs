//! The accelerator against brute force: same closest hit (t bit for bit, same
//! primitive unless two primitives tie on t), same occlusion answer.

use super::{Accel, PrimHit, RAY_LANES};
use crate::geometry::triangle::WatertightRay;
use crate::geometry::{Geometry, Ray, SdfGrid, SdfNormals, Sphere, TriangleMesh};
use crate::sampling::rng::Pcg32;
use glam::Vec3;

/// Every primitive of every shape, in order, shrinking t_max at each hit.
fn brute(shapes: &[Geometry], ray: &Ray) -> Option<PrimHit> {
    let w = WatertightRay::new(ray.o, ray.d);
    let mut t_max = ray.t_max;
    let mut best = None;
    for (si, g) in shapes.iter().enumerate() {
        match g {
            Geometry::Mesh(m) => {
                for t in 0..m.triangle_count() {
                    let [p0, p1, p2] = m.vertices(t);
                    if let Some((th, b1, b2)) = w.intersect(p0, p1, p2, t_max) {
                        t_max = th;
                        best = Some(PrimHit { t: th, shape: si as u32, prim: t as u32, b1, b2 });
                    }
                }
            }
            Geometry::Sphere(s) => {
                if let Some(th) = s.intersect(ray.o, ray.d, t_max) {
                    t_max = th;
                    best = Some(PrimHit { t: th, shape: si as u32, prim: 0, b1: 0.0, b2: 0.0 });
                }
            }
            Geometry::SdfGrid(g) => {
                for k in 0..g.voxel_count() {
                    if let Some(th) = g.intersect_voxel(k, ray.o, ray.d, t_max) {
                        t_max = th;
                        best = Some(PrimHit { t: th, shape: si as u32, prim: k as u32, b1: 0.0, b2: 0.0 });
                    }
                }
            }
        }
    }
    best
}

/// The hit distance of one given primitive, for telling ties from errors.
fn prim_t(shapes: &[Geometry], ray: &Ray, shape: u32, prim: u32) -> Option<f32> {
    match &shapes[shape as usize] {
        Geometry::Mesh(m) => {
            let [p0, p1, p2] = m.vertices(prim as usize);
            WatertightRay::new(ray.o, ray.d).intersect(p0, p1, p2, ray.t_max).map(|h| h.0)
        }
        Geometry::Sphere(s) => s.intersect(ray.o, ray.d, ray.t_max),
        Geometry::SdfGrid(g) => g.intersect_voxel(prim as usize, ray.o, ray.d, ray.t_max),
    }
}

fn check(shapes: &[Geometry], accel: &Accel, ray: &Ray) {
    let want = brute(shapes, ray);
    let got = accel.intersect(ray);
    match (want, got) {
        (None, None) => {}
        (Some(w), Some(g)) => {
            if (w.shape, w.prim) == (g.shape, g.prim) {
                assert_eq!((w.t, w.b1, w.b2), (g.t, g.b1, g.b2), "same primitive, different hit for {ray:?}");
            } else {
                // Two primitives meeting the ray at one point (a shared edge or vertex): their t may
                // differ by rounding, and the scalar test's t_max cut is itself that fuzzy.
                assert!((w.t - g.t).abs() <= 1e-6 * w.t.abs().max(1e-3), "not a tie for {ray:?}: want {w:?}, got {g:?}");
                assert_eq!(prim_t(shapes, ray, g.shape, g.prim), Some(g.t), "reported t is not its primitive's for {ray:?}");
            }
        }
        _ => panic!("hit mismatch for {ray:?}: want {want:?}, got {got:?}"),
    }
    assert_eq!(accel.occluded(ray), want.is_some(), "occluded mismatch for {ray:?}");
}

fn v3(rng: &mut Pcg32) -> Vec3 {
    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
}

fn dir(rng: &mut Pcg32) -> Vec3 {
    let z = 1.0 - 2.0 * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Small random triangles in the unit cube, one triangle per mesh for half of them.
fn soup(rng: &mut Pcg32, n: usize) -> Vec<Geometry> {
    let mut big = TriangleMesh::default();
    let mut shapes = Vec::new();
    for i in 0..n {
        let c = v3(rng);
        let ps: Vec<Vec3> = (0..3).map(|_| c + (v3(rng) - 0.5) * 0.2).collect();
        if i % 2 == 0 {
            let k = big.positions.len() as u32;
            big.positions.extend(&ps);
            big.indices.push([k, k + 1, k + 2]);
        } else {
            shapes.push(Geometry::Mesh(TriangleMesh { positions: ps, indices: vec![[0, 1, 2]], ..Default::default() }));
        }
    }
    shapes.insert(0, Geometry::Mesh(big));
    shapes
}

/// A closed, bumpy sphere of shared vertices (n x 2n grid, poles included).
fn bumpy_sphere(n: usize, center: Vec3, radius: f32) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    for i in 0..=n {
        let theta = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..2 * n {
            let phi = std::f32::consts::PI * j as f32 / n as f32;
            let r = radius * (1.0 + 0.1 * (5.0 * theta).sin() * (7.0 * phi).cos());
            m.positions.push(center + r * Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
        }
    }
    let idx = |i: usize, j: usize| (i * 2 * n + j % (2 * n)) as u32;
    for i in 0..n {
        for j in 0..2 * n {
            m.indices.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            m.indices.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    m
}

fn scene_rays(rng: &mut Pcg32, n: usize) -> Vec<Ray> {
    let mut rays = Vec::new();
    for i in 0..n {
        // Origins in and around the unit cube: inside node boxes and outside all of them.
        let o = v3(rng) * 1.6 - 0.3;
        let mut d = dir(rng);
        // Every fourth ray is axis-parallel or lies in a coordinate plane (zero components, some -0.0).
        match i % 8 {
            1 => d = Vec3::new(0.0, 0.0, d.z.signum()),
            3 => d = Vec3::new(-0.0, d.y, d.z).normalize(),
            5 => d = Vec3::new(d.x.signum(), -0.0, 0.0),
            7 => d = Vec3::new(d.x, d.y, 0.0).normalize(),
            _ => {}
        }
        let t_max = if i % 3 == 0 { rng.next_f32() * 0.8 } else { f32::INFINITY };
        rays.push(Ray::with_max(o, d, t_max));
    }
    rays
}

/// Checks every ray against brute force, with the SIMD node and triangle tests this CPU
/// picks and with the 4-lane SSE ones (both must agree with brute force, so with each
/// other), the second time with the prefetching traversal that large scenes use.
fn run(shapes: &[Geometry], rays: &[Ray]) -> usize {
    let refs: Vec<&Geometry> = shapes.iter().collect();
    let mut accel = Accel::build(&refs);
    let mut hits = 0;
    for r in rays {
        check(shapes, &accel, r);
        hits += accel.intersect(r).is_some() as usize;
    }
    let prefetch = accel.prefetch;
    for interleaved in [true, false] {
        accel.prefetch = interleaved;
        check_lanes(&accel, rays);
    }
    // The interleaved walks as in a tree past the last-level cache too (`coherent`): the
    // farther children asked for when pushed, not when popped (`Walk::step`'s `lazy`).
    accel.prefetch = true;
    accel.coherent = !accel.coherent;
    check_lanes(&accel, rays);
    accel.coherent = !accel.coherent;
    if accel.avx512 {
        // The interleaved walks' AVX copy too (the AVX-512 one ran above).
        accel.avx512 = false;
        accel.prefetch = true;
        check_lanes(&accel, rays);
    }
    accel.avx = false;
    accel.prefetch = !prefetch;
    for r in rays {
        check(shapes, &accel, r);
    }
    check_lanes(&accel, rays);
    hits
}

/// The eight-ray queries give each active ray what the one-ray queries give it, bit for bit,
/// and nothing to the others: whole groups, single lanes and scattered masks. With AVX and
/// `prefetch`, the walks are the interleaved ones.
fn check_lanes(accel: &Accel, rays: &[Ray]) {
    let bits = |h: Option<PrimHit>| h.map(|h| (h.t.to_bits(), h.shape, h.prim, h.b1.to_bits(), h.b2.to_bits()));
    for (k, group) in rays.chunks(RAY_LANES).enumerate() {
        let mut eight = [group[0]; RAY_LANES];
        eight[..group.len()].copy_from_slice(group);
        let all = ((1u32 << group.len()) - 1) as u8;
        let active = all & [0xff, 0x01, 0x80, 0xa5, 0x5a, 0x3c][k % 6];
        let hits = accel.intersect_lanes(&eight, active);
        let blocked = accel.occluded_lanes(&eight, active);
        for l in 0..RAY_LANES {
            if active & (1 << l) != 0 {
                assert_eq!(bits(hits[l]), bits(accel.intersect(&eight[l])), "lane {l} of group {k}");
                assert_eq!(blocked & (1 << l) != 0, accel.occluded(&eight[l]), "occlusion of lane {l} of group {k}");
            } else {
                assert!(hits[l].is_none() && blocked & (1 << l) == 0, "inactive lane {l} of group {k}");
            }
        }
    }
}

#[test]
fn random_soup_matches_brute_force() {
    let mut rng = Pcg32::new(1, 7);
    let shapes = soup(&mut rng, 3000);
    let rays = scene_rays(&mut rng, 4000);
    let hits = run(&shapes, &rays);
    // Guard against a test that passes by never hitting.
    assert!(hits > rays.len() / 4 && hits < rays.len(), "{hits} hits");
}

#[test]
fn meshes_and_spheres_match_brute_force() {
    let mut rng = Pcg32::new(2, 7);
    let mut shapes = vec![Geometry::Mesh(bumpy_sphere(40, Vec3::new(0.3, 0.5, 0.5), 0.25)), Geometry::Mesh(bumpy_sphere(25, Vec3::new(0.75, 0.5, 0.4), 0.2))];
    for _ in 0..9 {
        shapes.push(Geometry::Sphere(Sphere { center: v3(&mut rng), radius: 0.02 + 0.1 * rng.next_f32(), flip_normals: false }));
    }
    // A sphere overlapping a mesh, so that the two hierarchies compete for the nearest hit.
    shapes.push(Geometry::Sphere(Sphere { center: Vec3::new(0.3, 0.5, 0.75), radius: 0.1, flip_normals: false }));
    let rays = scene_rays(&mut rng, 4000);
    let hits = run(&shapes, &rays);
    assert!(hits > rays.len() / 20, "{hits} hits");
}

/// A hit's mesh, searched for (up to `MESH_SEARCH_MAX` meshes) or read from the per-triangle
/// table (past it), is the mesh that holds the triangle, with empty meshes and spheres
/// (shapes without triangle ids) between the meshes.
#[test]
fn mesh_of_every_triangle_id() {
    let max = super::bvh::MESH_SEARCH_MAX;
    for n in [1, 2, 9, max - 1, max, max + 1, 5 * max] {
        let mut rng = Pcg32::new(n as u64, 3);
        let mut shapes = Vec::new();
        // Per triangle id: (shape, index in its mesh).
        let mut want = Vec::new();
        for _ in 0..n {
            if rng.next_f32() < 0.3 {
                shapes.push(Geometry::Mesh(TriangleMesh::default()));
            }
            if rng.next_f32() < 0.3 {
                shapes.push(Geometry::Sphere(Sphere { center: v3(&mut rng), radius: 0.05, flip_normals: false }));
            }
            let tris = 1 + (rng.next_f32() * 4.0) as usize;
            let mut m = TriangleMesh::default();
            for t in 0..tris {
                let c = v3(&mut rng);
                m.positions.extend((0..3).map(|_| c + (v3(&mut rng) - 0.5) * 0.1));
                m.indices.push([3 * t as u32, 3 * t as u32 + 1, 3 * t as u32 + 2]);
                want.push((shapes.len() as u32, t as u32));
            }
            shapes.push(Geometry::Mesh(m));
        }
        let refs: Vec<&Geometry> = shapes.iter().collect();
        let accel = Accel::build(&refs);
        assert_eq!(accel.tri_mesh.is_empty(), n <= max, "{n} meshes");
        for (id, &w) in want.iter().enumerate() {
            let (first, shape) = accel.meshes[accel.mesh_of(id as u32)];
            assert_eq!((shape, id as u32 - first), w, "triangle {id} of {n} meshes");
        }
    }
}

/// A torus-like SDF grid (two voxel hierarchies' worth of primitives) beside a mesh and a
/// sphere: the voxel hierarchy finds what testing every voxel finds.
#[test]
fn sdf_grids_match_brute_force() {
    let mut rng = Pcg32::new(4, 7);
    let n = 20;
    let mut values = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = Vec3::new(x as f32, y as f32, z as f32) / (n - 1) as f32 - Vec3::splat(0.5);
                let q = glam::Vec2::new(glam::Vec2::new(p.x, p.y).length() - 0.3, p.z);
                values.push(q.length() - 0.12);
            }
        }
    }
    let place = glam::Mat4::from_translation(Vec3::new(0.2, 0.25, 0.3)) * glam::Mat4::from_rotation_x(0.6) * glam::Mat4::from_scale(Vec3::splat(0.5));
    let grid = SdfGrid::new([n, n, n], values, place, SdfNormals::Smooth).unwrap();
    let shapes = vec![
        Geometry::SdfGrid(Box::new(grid)),
        Geometry::Mesh(bumpy_sphere(20, Vec3::new(0.75, 0.5, 0.4), 0.2)),
        Geometry::Sphere(Sphere { center: Vec3::new(0.45, 0.5, 0.55), radius: 0.1, flip_normals: false }),
    ];
    let rays = scene_rays(&mut rng, 3000);
    let hits = run(&shapes, &rays);
    assert!(hits > rays.len() / 30, "{hits} hits");
}

#[test]
fn spheres_only_and_empty_scene() {
    let mut rng = Pcg32::new(3, 7);
    let shapes: Vec<Geometry> = (0..40).map(|_| Geometry::Sphere(Sphere { center: v3(&mut rng), radius: 0.05, flip_normals: false })).collect();
    let rays = scene_rays(&mut rng, 2000);
    assert!(run(&shapes, &rays) > 0);

    let empty = Accel::build(&[]);
    assert!(empty.bounds().is_empty());
    for r in &rays[..100] {
        assert!(empty.intersect(r).is_none() && !empty.occluded(r));
    }
    // An empty mesh is no primitive either.
    let shapes = vec![Geometry::Mesh(TriangleMesh::default())];
    assert_eq!(run(&shapes, &rays[..100]), 0);
}

#[test]
fn rays_along_a_box_face_from_on_it() {
    // Triangles whose top edges lie in the plane y = 1 (the top face of their boxes), and rays
    // that start in that plane and run along it (d.y = +0 or -0): they meet the edges, so the
    // boxes must not be culled. (A zero direction component used to be clamped to a tiny one,
    // which put the far slab at t = 0 for an origin on the far plane.)
    let mut m = TriangleMesh::default();
    for k in 0..40u32 {
        let (x, z) = ((k % 8) as f32 * 0.5, 2.0 + (k / 8) as f32);
        m.positions.extend([Vec3::new(x - 0.2, 1.0, z), Vec3::new(x + 0.2, 1.0, z), Vec3::new(x, 0.0, z + 0.1)]);
        m.indices.push([3 * k, 3 * k + 1, 3 * k + 2]);
    }
    let shapes = vec![Geometry::Mesh(m)];
    let mut rays = Vec::new();
    for k in 0..8 {
        for (dy, dz) in [(0.0f32, 1.0f32), (-0.0, 1.0), (0.0, -1.0)] {
            let z0 = if dz > 0.0 { 0.0 } else { 20.0 };
            rays.push(Ray::new(Vec3::new(k as f32 * 0.5, 1.0, z0), Vec3::new(0.0, dy, dz)));
        }
    }
    let hits = run(&shapes, &rays);
    assert_eq!(hits, rays.len(), "a ray along the plane of the edges missed them");
}

#[test]
fn coincident_triangles_and_single_triangle() {
    // 200 copies of one triangle: every centroid equal, so no SAH split exists.
    let tri = [Vec3::new(0.0, 0.0, 0.5), Vec3::new(1.0, 0.0, 0.5), Vec3::new(0.0, 1.0, 0.5)];
    let mut m = TriangleMesh::default();
    for k in 0..200u32 {
        m.positions.extend(tri);
        m.indices.push([3 * k, 3 * k + 1, 3 * k + 2]);
    }
    let mut rng = Pcg32::new(4, 7);
    let rays = scene_rays(&mut rng, 1000);
    assert!(run(&[Geometry::Mesh(m)], &rays) > 0);
    let single = TriangleMesh { positions: tri.to_vec(), indices: vec![[0, 1, 2]], ..Default::default() };
    assert!(run(&[Geometry::Mesh(single)], &rays) > 0);
}

#[test]
fn no_cracks_between_leaves() {
    // A 64x64 grid of quads (two triangles each) at z = 0.5: rays aimed exactly at grid
    // vertices and edge points, from many directions, must all hit, whichever leaf holds which triangle.
    let n = 64;
    let mut m = TriangleMesh::default();
    for i in 0..=n {
        for j in 0..=n {
            m.positions.push(Vec3::new(i as f32 / n as f32, j as f32 / n as f32, 0.5));
        }
    }
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    for i in 0..n {
        for j in 0..n {
            m.indices.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            m.indices.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    let shapes = [Geometry::Mesh(m)];
    let mut accel = Accel::build(&[&shapes[0]]);
    // With the kernels this CPU picks, then with the SSE ones (4-lane node and triangle tests).
    for avx in [accel.avx, false] {
        accel.avx = avx;
        let mut rng = Pcg32::new(5, 7);
        for k in 0..20000 {
            let (i, j) = (1 + (rng.next_u32() % (n as u32 - 1)), 1 + (rng.next_u32() % (n as u32 - 1)));
            // A grid vertex, or a point on a horizontal, vertical or diagonal edge.
            let s = rng.next_f32();
            let target = match k % 4 {
                0 => Vec3::new(i as f32, j as f32, 0.0),
                1 => Vec3::new(i as f32 + s, j as f32, 0.0),
                2 => Vec3::new(i as f32, j as f32 + s, 0.0),
                _ => Vec3::new(i as f32 + s, j as f32 + s, 0.0),
            } / n as f32
                + Vec3::new(0.0, 0.0, 0.5);
            let mut d = dir(&mut rng);
            if k % 5 == 0 {
                d = Vec3::new(0.0, 0.0, if k % 2 == 0 { -1.0 } else { 1.0 });
            }
            if d.z.abs() < 0.05 {
                continue;
            }
            let ray = Ray::new(target - d * (0.3 + rng.next_f32()), d);
            assert!(accel.intersect(&ray).is_some(), "ray {k} slipped through (avx {avx}): {ray:?}");
            assert!(accel.occluded(&ray), "ray {k} not occluded (avx {avx}): {ray:?}");
            if k % 8 == 0 {
                check(&shapes, &accel, &ray);
            }
        }
    }
}

#[test]
fn accel_is_send_and_sync() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Accel>();
}

/// The nearest lane of a block by the scalar test, lane by lane (ties: the lowest lane).
fn scalar_block(tris: &[([Vec3; 3], u32)], w: &WatertightRay, t_max: f32) -> Option<(usize, f32, f32, f32)> {
    let mut best: Option<(usize, f32, f32, f32)> = None;
    for (lane, ([p0, p1, p2], _)) in tris.iter().enumerate() {
        if let Some((t, b1, b2)) = w.intersect(*p0, *p1, *p2, t_max) {
            if best.is_none_or(|b| t < b.1) {
                best = Some((lane, t, b1, b2));
            }
        }
    }
    best
}

#[test]
fn block_kernels_match_scalar_test_bit_for_bit() {
    use super::bvh::TriKernel;
    use super::tri4::TriRay;
    use super::tri8::Tri8;
    let mut rng = Pcg32::new(6, 7);
    // Vertices on a coarse grid and rays aimed at grid points, often along an axis: u, v or w is
    // then exactly zero in many lanes (the edge fallback), and equal distances tie.
    let grid = |rng: &mut Pcg32| (rng.next_u32() % 9) as f32 * 0.125;
    let gpt = |rng: &mut Pcg32| Vec3::new(grid(rng), grid(rng), grid(rng));
    let (mut hits, mut edge_cases) = (0, 0);
    for case in 0..20000u32 {
        let n = 1 + case as usize % 8;
        let mut tris: Vec<([Vec3; 3], u32)> = Vec::new();
        for k in 0..n {
            let mut t = [gpt(&mut rng), gpt(&mut rng), gpt(&mut rng)];
            if k > 0 && rng.next_f32() < 0.4 {
                // Share an edge with the previous triangle, reversed (a mesh neighbour), or copy it.
                let prev = tris[k - 1].0;
                t = if rng.next_f32() < 0.5 { [prev[1], prev[0], t[2]] } else { prev };
            }
            tris.push((t, 100 + k as u32));
        }
        let block = Tri8::new(&tris);
        let target = if rng.next_f32() < 0.5 { gpt(&mut rng) } else { v3(&mut rng) };
        let mut d = dir(&mut rng);
        match case % 4 {
            1 => d = Vec3::new(0.0, 0.0, if d.z < 0.0 { -1.0 } else { 1.0 }),
            2 => d = Vec3::new(d.x, 0.0, d.z).normalize(),
            _ => {}
        }
        let o = target - d * (0.5 + grid(&mut rng));
        let w = WatertightRay::new(o, d);
        let t_max = if case % 3 == 0 { 0.25 + rng.next_f32() } else { f32::INFINITY };
        let want = scalar_block(&tris, &w, t_max);
        hits += want.is_some() as usize;
        edge_cases += (0..n)
            .filter(|&l| {
                let [p0, p1, p2] = tris[l].0;
                let s = |p: Vec3| (p - o).to_array();
                let (a, b, c) = (s(p0), s(p1), s(p2));
                let xy = |q: [f32; 3]| (q[w.kx] - w.sx * q[w.kz], q[w.ky] - w.sy * q[w.kz]);
                let ((ax, ay), (bx, by), (cx, cy)) = (xy(a), xy(b), xy(c));
                cx * by - cy * bx == 0.0 || ax * cy - ay * cx == 0.0 || bx * ay - by * ax == 0.0
            })
            .count();
        let bits = |h: Option<(usize, f32, f32, f32)>| h.map(|(l, t, b1, b2)| (l, t.to_bits(), b1.to_bits(), b2.to_bits()));
        assert_eq!(bits(TriRay::new(&w).test(&block, &w, t_max)), bits(want), "SSE kernel, case {case}: {tris:?} {o:?} {d:?}");
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: AVX was just detected.
            let got = unsafe { avx_test(&block, &w, t_max) };
            assert_eq!(bits(got), bits(want), "AVX kernel, case {case}: {tris:?} {o:?} {d:?}");
        }
    }
    // Guard against a test that passes by never hitting, or never taking the edge path.
    assert!(hits > 2000 && edge_cases > 1000, "{hits} hits, {edge_cases} edge lanes");
}

/// # Safety
/// The CPU must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn avx_test(block: &super::tri8::Tri8, w: &WatertightRay, t_max: f32) -> Option<(usize, f32, f32, f32)> {
    use super::bvh::TriKernel;
    // SAFETY: the caller checked AVX.
    let r = unsafe { super::tri8::TriRay8::new(w) };
    r.test(block, w, t_max)
}

/// Groups of eight rays as a pinhole camera makes them (origins on its near plane along
/// the rays, directions within a small cone: what the coherent walk takes) give each ray
/// what its single walk gives, bit for bit: rays aimed at the meshes' shared vertices and
/// edges (several triangles tie there), at 40 copies of one triangle (exact ties), at points
/// just beside the surface (near misses), with finite and infinite t_max.
#[test]
fn coherent_walks_match_single_walks() {
    let mut rng = Pcg32::new(9, 7);
    let sphere = bumpy_sphere(60, Vec3::new(0.45, 0.5, 0.5), 0.3);
    let tri = [Vec3::new(0.7, 0.1, 0.2), Vec3::new(0.95, 0.1, 0.2), Vec3::new(0.7, 0.35, 0.2)];
    let mut copies = TriangleMesh::default();
    for k in 0..40u32 {
        copies.positions.extend(tri);
        copies.indices.push([3 * k, 3 * k + 1, 3 * k + 2]);
    }
    let mut shapes = soup(&mut rng, 400);
    shapes.push(Geometry::Mesh(sphere.clone()));
    shapes.push(Geometry::Mesh(copies));
    let refs: Vec<&Geometry> = shapes.iter().collect();
    let mut accel = Accel::build(&refs);
    // The walks of large scenes (the coherent and interleaved walks are for those only).
    accel.prefetch = true;
    accel.coherent = true;
    let bits = |h: Option<PrimHit>| h.map(|h| (h.t.to_bits(), h.shape, h.prim, h.b1.to_bits(), h.b2.to_bits()));
    let mut coherent = 0;
    for g in 0..1500 {
        let eye = v3(&mut rng) * 3.0 - 1.0;
        // Targets: a vertex of the sphere, the middle of one of its edges, the triangle copies, beside the sphere.
        let target = |rng: &mut Pcg32| -> Vec3 {
            let i = (rng.next_f32() * sphere.positions.len() as f32) as usize % sphere.positions.len();
            match g % 4 {
                0 => sphere.positions[i],
                1 => {
                    let [a, b, _] = sphere.indices[i % sphere.indices.len()];
                    (sphere.positions[a as usize] + sphere.positions[b as usize]) * 0.5
                }
                2 => (tri[0] + tri[1] + tri[2]) / 3.0 + (v3(rng) - 0.5) * 0.05,
                _ => sphere.positions[i] + (v3(rng) - 0.5) * 0.01,
            }
        };
        let base = target(&mut rng);
        // Up to a spread the walk takes as one (`coherent::DIR_SPREAD`), and a little past it.
        let spread = [0.0, 1e-4, 1e-3, 1e-2, 4e-2][g % 5];
        let mut eight = [Ray::new(Vec3::ZERO, Vec3::Z); RAY_LANES];
        for (k, ray) in eight.iter_mut().enumerate() {
            // Half of a group aims exactly at its point (a vertex, an edge, the copies), half beside it.
            let p = if k % 2 == 0 { base } else { base + (v3(&mut rng) - 0.5) * spread };
            // As a pinhole camera: the ray starts on the near plane, along its line from the eye.
            let v = p - eye;
            let o = eye + v * 0.01;
            *ray = if g % 3 == 0 { Ray::with_max(o, v.normalize(), v.length() * 0.999) } else { Ray::new(o, v.normalize()) };
        }
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: AVX is present.
            coherent += unsafe { super::coherent::Coherent::new(&eight, 0xff, 1.0) }.is_some() as usize;
        }
        // Beside the group as it is, the group with two or five of its rays unlike the rest
        // (a packet's bounce rays beside its camera rays: the alike ones still walk as one).
        let mut mixed = [eight; 3];
        for (m, unlike) in [(1, 0b0100_0010u8), (2, 0b1011_0001)] {
            for l in (0..RAY_LANES).filter(|l| unlike & (1 << l) != 0) {
                mixed[m][l] = Ray::new(v3(&mut rng) * 3.0 - 1.0, (v3(&mut rng) - 0.5).normalize_or(Vec3::X));
            }
        }
        for (m, eight) in mixed.iter().enumerate() {
            // The rays as rows too, as the path kernel keeps them.
            let mut rows = super::packet::Rays8::default();
            for (l, r) in eight.iter().enumerate() {
                for a in 0..3 {
                    (rows.o[a][l], rows.d[a][l]) = (r.o[a], r.d[a]);
                }
                rows.t_max[l] = r.t_max;
            }
            for active in [0xff, 0x7f, 0xf0, 0x3c] {
                let hits = accel.intersect_lanes(eight, active);
                let mut row_hits = [None; RAY_LANES];
                accel.intersect_lanes_with(&rows, active, &super::HitRecords::NONE, |l, hit| row_hits[l] = hit);
                let blocked = accel.occluded_lanes_of(&rows, active);
                for (l, ray) in eight.iter().enumerate() {
                    let want = if active & (1 << l) != 0 { bits(accel.intersect(ray)) } else { None };
                    assert_eq!(bits(hits[l]), want, "lane {l} of group {g}/{m} (active {active:#x})");
                    assert_eq!(bits(row_hits[l]), want, "rows: lane {l} of group {g}/{m} (active {active:#x})");
                    let occluded = active & (1 << l) != 0 && accel.occluded(ray);
                    assert_eq!(blocked & (1 << l) != 0, occluded, "rows: lane {l} of group {g}/{m} (active {active:#x})");
                }
            }
        }
        for ray in &eight[..2] {
            check(&shapes, &accel, ray);
        }
    }
    if std::is_x86_feature_detected!("avx") {
        assert!(coherent > 1000, "{coherent} groups walked as one");
    }
}

/// The order a node's pushes take (`wide::entries_below`, scalar and AVX) is the stable
/// insertion sort's by decreasing distance of the entries in slot order, ties included.
#[test]
fn sorted_pushes_match_the_insertion_sort() {
    use super::wide::{entries_below, WIDTH};
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,popcnt")]
    unsafe fn below_avx(tn: &[f32; WIDTH], hits: u32, k: usize) -> usize {
        entries_below::<true>(tn, hits, k)
    }
    let mut rng = Pcg32::new(7, 3);
    // Few distinct values (the signed zeros and infinity among them), so that ties are common.
    let values = [0.0, -0.0, 0.5, 0.5, 1.0, 2.0, f32::INFINITY];
    for _ in 0..20_000 {
        let tn: [f32; WIDTH] = std::array::from_fn(|_| values[(rng.next_f32() * values.len() as f32) as usize % values.len()]);
        let hits = (rng.next_f32() * 256.0) as u32 & 0xff;
        if hits.count_ones() < 3 {
            continue;
        }
        let mut want: Vec<(usize, f32)> = (0..WIDTH).filter(|&k| hits >> k & 1 != 0).map(|k| (k, tn[k])).collect();
        for i in 1..want.len() {
            let mut j = i;
            while j > 0 && want[j - 1].1 < want[j].1 {
                want.swap(j - 1, j);
                j -= 1;
            }
        }
        let mut got = vec![(WIDTH, 0.0); want.len()];
        for k in (0..WIDTH).filter(|&k| hits >> k & 1 != 0) {
            let at = entries_below::<false>(&tn, hits, k);
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx") && std::is_x86_feature_detected!("popcnt") {
                // SAFETY: AVX and POPCNT were detected just above.
                assert_eq!(unsafe { below_avx(&tn, hits, k) }, at, "{tn:?} {hits:#b} {k}");
            }
            got[at] = (k, tn[k]);
        }
        let slots = |v: &[(usize, f32)]| v.iter().map(|e| e.0).collect::<Vec<_>>();
        assert_eq!(slots(&got), slots(&want), "{tn:?} {hits:#b}");
    }
}
