//! Binary BVH built by binned SAH, flattened depth-first. Triangles are stored
//! by value in leaf order so that traversal touches memory in sequence.

use super::PrimHit;
use crate::geometry::triangle::WatertightRay;
use crate::geometry::{Aabb, Geometry, Ray, Sphere};
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first primitive; interior: index of the second child (the first follows the node).
    offset: u32,
    /// Leaf: primitive count (> 0); interior: 0.
    count: u16,
    axis: u16,
}

#[derive(Clone, Copy, Debug)]
enum Prim {
    Triangle { p0: Vec3, p1: Vec3, p2: Vec3 },
    Sphere(Sphere),
}

#[derive(Clone, Copy, Debug)]
struct PrimRef {
    shape: u32,
    prim: u32,
}

pub struct Accel {
    nodes: Vec<Node>,
    prims: Vec<Prim>,
    refs: Vec<PrimRef>,
}

const BINS: usize = 16;
const MAX_LEAF: usize = 4;

impl Accel {
    pub fn build(shapes: &[&Geometry]) -> Accel {
        let mut prims = Vec::new();
        let mut refs = Vec::new();
        for (si, g) in shapes.iter().enumerate() {
            match g {
                Geometry::Mesh(m) => {
                    for t in 0..m.triangle_count() {
                        let [p0, p1, p2] = m.vertices(t);
                        prims.push(Prim::Triangle { p0, p1, p2 });
                        refs.push(PrimRef { shape: si as u32, prim: t as u32 });
                    }
                }
                Geometry::Sphere(s) => {
                    prims.push(Prim::Sphere(*s));
                    refs.push(PrimRef { shape: si as u32, prim: 0 });
                }
            }
        }
        let bounds: Vec<Aabb> = prims.iter().map(prim_bounds).collect();
        let centroids: Vec<Vec3> = bounds.iter().map(|b| b.center()).collect();
        let mut order: Vec<u32> = (0..prims.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * prims.len().max(1));
        if !prims.is_empty() {
            build_rec(&bounds, &centroids, &mut order, 0, &mut nodes);
        }
        let prims = order.iter().map(|&i| prims[i as usize]).collect();
        let refs = order.iter().map(|&i| refs[i as usize]).collect();
        Accel { nodes, prims, refs }
    }

    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map(|n| n.bounds).unwrap_or(Aabb::EMPTY)
    }

    pub fn intersect(&self, ray: &Ray) -> Option<PrimHit> {
        self.traverse(ray, false)
    }

    pub fn occluded(&self, ray: &Ray) -> bool {
        self.traverse(ray, true).is_some()
    }

    #[inline]
    fn traverse(&self, ray: &Ray, any: bool) -> Option<PrimHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv_d = ray.d.recip();
        let neg = [inv_d.x < 0.0, inv_d.y < 0.0, inv_d.z < 0.0];
        let wray = WatertightRay::new(ray.o, ray.d);
        let mut t_max = ray.t_max;
        let mut best: Option<(u32, f32, f32, f32)> = None;
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut ni = 0u32;
        loop {
            let node = &self.nodes[ni as usize];
            if node.bounds.intersect(ray.o, inv_d, t_max).is_some() {
                if node.count > 0 {
                    let start = node.offset as usize;
                    for i in start..start + node.count as usize {
                        let hit = match &self.prims[i] {
                            Prim::Triangle { p0, p1, p2 } => wray.intersect(*p0, *p1, *p2, t_max),
                            Prim::Sphere(s) => s.intersect(ray.o, ray.d, t_max).map(|t| (t, 0.0, 0.0)),
                        };
                        if let Some((t, b1, b2)) = hit {
                            t_max = t;
                            best = Some((i as u32, t, b1, b2));
                            if any {
                                break;
                            }
                        }
                    }
                    if any && best.is_some() {
                        break;
                    }
                } else {
                    // Visit the near child first.
                    if neg[node.axis as usize] {
                        stack[sp] = ni + 1;
                        ni = node.offset;
                    } else {
                        stack[sp] = node.offset;
                        ni += 1;
                    }
                    sp += 1;
                    continue;
                }
            }
            if sp == 0 {
                break;
            }
            sp -= 1;
            ni = stack[sp];
        }
        best.map(|(i, t, b1, b2)| {
            let r = self.refs[i as usize];
            PrimHit { t, shape: r.shape, prim: r.prim, b1, b2 }
        })
    }
}

fn prim_bounds(p: &Prim) -> Aabb {
    match p {
        Prim::Triangle { p0, p1, p2 } => Aabb::from_points(&[*p0, *p1, *p2]),
        Prim::Sphere(s) => s.bounds(),
    }
}

fn build_rec(bounds: &[Aabb], centroids: &[Vec3], order: &mut [u32], first: usize, nodes: &mut Vec<Node>) -> usize {
    let idx = nodes.len();
    let bb = order.iter().fold(Aabb::EMPTY, |b, &i| b.union(bounds[i as usize]));
    nodes.push(Node { bounds: bb, offset: first as u32, count: order.len() as u16, axis: 0 });
    if order.len() <= MAX_LEAF {
        return idx;
    }
    let cb = order.iter().fold(Aabb::EMPTY, |b, &i| b.grow(centroids[i as usize]));
    let ext = cb.extent();
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    let mut mid = order.len() / 2;
    if ext[axis] > 0.0 {
        // Binned SAH along the widest centroid axis.
        let scale = BINS as f32 / ext[axis];
        let bin_of = |i: u32| (((centroids[i as usize][axis] - cb.min[axis]) * scale) as usize).min(BINS - 1);
        let mut bin_b = [Aabb::EMPTY; BINS];
        let mut bin_n = [0usize; BINS];
        for &i in order.iter() {
            let b = bin_of(i);
            bin_b[b] = bin_b[b].union(bounds[i as usize]);
            bin_n[b] += 1;
        }
        let mut best = (f32::INFINITY, 0usize);
        let mut right_area = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut n_right = [0usize; BINS];
        let mut n = 0;
        for b in (1..BINS).rev() {
            acc = acc.union(bin_b[b]);
            n += bin_n[b];
            right_area[b] = acc.surface_area();
            n_right[b] = n;
        }
        let mut acc = Aabb::EMPTY;
        let mut n_left = 0;
        for split in 1..BINS {
            acc = acc.union(bin_b[split - 1]);
            n_left += bin_n[split - 1];
            if n_left == 0 || n_right[split] == 0 {
                continue;
            }
            let cost = acc.surface_area() * n_left as f32 + right_area[split] * n_right[split] as f32;
            if cost < best.0 {
                best = (cost, split);
            }
        }
        let leaf_cost = bb.surface_area() * order.len() as f32;
        if order.len() <= 16 && best.0 >= leaf_cost {
            return idx;
        }
        if best.0.is_finite() {
            let split = best.1;
            let mut l = 0;
            for k in 0..order.len() {
                if bin_of(order[k]) < split {
                    order.swap(k, l);
                    l += 1;
                }
            }
            mid = l;
        } else {
            order.sort_by(|&a, &b| centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis]));
        }
    } else if order.len() <= 16 {
        return idx;
    }
    if mid == 0 || mid == order.len() {
        mid = order.len() / 2;
    }
    nodes[idx].count = 0;
    nodes[idx].axis = axis as u16;
    let (left, right) = order.split_at_mut(mid);
    build_rec(bounds, centroids, left, first, nodes);
    let r = build_rec(bounds, centroids, right, first + mid, nodes);
    nodes[idx].offset = r as u32;
    idx
}
