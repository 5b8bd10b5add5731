//! Monte Carlo form factors by ray casting, area to area: rays leave uniformly distributed
//! points of element i in cosine-distributed directions; the fraction that first hits element
//! j estimates F_ij (the cosine density is exactly the kernel cos θ_i / π, and the uniform
//! origin does the area average). Visibility is part of the estimate, the row sums to the
//! fraction of rays that hit anything (1 in a closed scene, up to rays lost at cracks), and
//! each F_ij is binomial with variance F_ij (1 − F_ij) / N.
//!
//! Rays that meet a surface with only specular (delta) lobes (mirror, smooth glass: no
//! elements, black in the diffuse system) are continued by sampling its BSDF, carrying the
//! mean of the sampled weight, up to 16 bounces: F_ij then includes the paths from i to j via
//! specular reflection and refraction (the extended form factors of Wallace, Cohen & Greenberg
//! and Sillion & Puech), so that the diffuse solution receives the light such surfaces redirect
//! and the row sums stay the fraction of the power that reaches a diffuse surface.

use super::super::mesh::RadiosityMesh;
use crate::bsdf::TransportMode;
use crate::geometry::ray::offset_ray_origin;
use crate::geometry::Ray;
use crate::math::{warp, Frame};
use crate::sampling::rng::{hash_seed, Pcg32};
use crate::scene::Scene;
use glam::Vec2;

/// Specular bounces followed at most by one ray.
const MAX_SPECULAR: u32 = 16;

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
        let mut ray = Ray::new(offset_ray_origin(p, e.normal, d), d);
        let mut weight = w;
        for _ in 0..=MAX_SPECULAR {
            let Some(h) = scene.intersect_prim(&ray) else { break };
            if let Some(j) = mesh.element_at(&h, ray.at(h.t), ray.d) {
                if j as usize != i {
                    hits.push((j, weight));
                }
                break;
            }
            // No element: absorbed, unless the surface is purely specular.
            let shape = &scene.shapes[h.shape as usize];
            if scene.materials[shape.material as usize].bsdf(Vec2::splat(0.5)).flags().has_non_specular() {
                break;
            }
            let Some(si) = scene.intersect(&ray) else { break };
            let bsdf = scene.bsdf(&si);
            let Some(bs) = bsdf.sample(si.to_local(si.wo), rng.next_f32(), Vec2::new(rng.next_f32(), rng.next_f32()), TransportMode::Radiance) else { break };
            if bs.pdf <= 0.0 {
                break;
            }
            weight *= bs.weight().mean();
            if weight <= 0.0 {
                break;
            }
            ray = si.spawn_ray(si.to_world(bs.wi));
        }
    }
    super::merge(hits)
}
