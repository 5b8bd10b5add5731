//! Monte Carlo form factors by ray casting, area to area: rays leave uniformly distributed
//! points of element i in cosine-distributed directions; the fraction that first hits element
//! j estimates F_ij (the cosine density is exactly the kernel cos θ_i / π, and the uniform
//! origin does the area average). Visibility is part of the estimate, the row sums to the
//! fraction of rays that hit anything (1 in a closed scene, up to rays lost at cracks), and
//! each F_ij is binomial with variance F_ij (1 − F_ij) / N.

use super::super::mesh::RadiosityMesh;
use crate::geometry::ray::offset_ray_origin;
use crate::geometry::Ray;
use crate::math::{warp, Frame};
use crate::sampling::rng::{hash_seed, Pcg32};
use crate::scene::Scene;
use glam::Vec2;

/// Row i with `rays` rays (stratified over the square of directions, origins random).
pub fn row(scene: &Scene, mesh: &RadiosityMesh, i: usize, rays: u32, seed: u64) -> Vec<(u32, f32)> {
    let e = &mesh.elements[i];
    let frame = Frame::from_normal(e.normal);
    let mut rng = Pcg32::new(hash_seed(&[seed, i as u64]), 0x5ad1_0517);
    let side = (rays as f32).sqrt().ceil().max(1.0) as u32;
    let n = side * side;
    let w = 1.0 / n as f32;
    let mut hits = Vec::new();
    for s in 0..n {
        let u = Vec2::new(((s % side) as f32 + rng.next_f32()) / side as f32, ((s / side) as f32 + rng.next_f32()) / side as f32);
        let b = warp::square_to_uniform_triangle(Vec2::new(rng.next_f32(), rng.next_f32()));
        let p = e.point(b.x, b.y);
        let d = frame.to_world(warp::square_to_cosine_hemisphere(u));
        let ray = Ray::new(offset_ray_origin(p, e.normal, d), d);
        if let Some(h) = scene.intersect_prim(&ray) {
            if let Some(j) = mesh.element_at(&h, ray.at(h.t), d) {
                if j as usize != i {
                    hits.push((j, w));
                }
            }
        }
    }
    super::merge(hits)
}
