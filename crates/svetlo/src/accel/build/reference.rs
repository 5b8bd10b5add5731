//! The binned-SAH build as it was before the single-pass rewrite of the parent module,
//! kept for the tests: the new build must give the same tree, bit for bit.

use super::super::wide::{Node, EMPTY_CHILD, LEAF_BIT, WIDTH};
use super::{LeafParams, BINS, PARALLEL_MIN, SAH_MAX_DEPTH};
use crate::geometry::Aabb;
use glam::Vec3;

enum BNode {
    Leaf { start: u32, count: u32 },
    Inner { bounds: [Aabb; 2], children: Box<[BNode; 2]> },
}

struct Ctx<'a> {
    bounds: &'a [Aabb],
    centroids: &'a [Vec3],
    params: LeafParams,
}

/// The old [`super::build_wide`]: builds the wide tree over `bounds`. Returns the nodes (root first; none when
/// there is no primitive) and the primitive order the leaves refer to. `emit_leaf`
/// gets each leaf's slice of that order, in depth-first order, and returns its
/// child code (with `LEAF_BIT` set).
pub(super) fn build_wide_reference(bounds: &[Aabb], params: LeafParams, mut emit_leaf: impl FnMut(&[u32]) -> u32) -> (Vec<Node>, Vec<u32>) {
    let mut order: Vec<u32> = (0..bounds.len() as u32).collect();
    if bounds.is_empty() {
        return (Vec::new(), order);
    }
    let centroids: Vec<Vec3> = bounds.iter().map(|b| b.center()).collect();
    let ctx = Ctx { bounds, centroids: &centroids, params };
    let root_bounds = bounds.iter().fold(Aabb::EMPTY, |a, b| a.union(*b));
    let root = build_rec(&ctx, &mut order, 0, root_bounds, 0);
    let mut nodes = Vec::with_capacity(bounds.len() / 2 + 1);
    // The root is always an inner node, even over a single leaf, so that traversal starts uniformly.
    let (root_children, root_boxes) = match &root {
        BNode::Leaf { .. } => (vec![&root], vec![root_bounds]),
        BNode::Inner { .. } => collapse(&root),
    };
    nodes.push(Node::empty());
    fill_node(0, &root_children, &root_boxes, &order, &mut nodes, &mut emit_leaf);
    (nodes, order)
}

fn fill_node(idx: usize, children: &[&BNode], boxes: &[Aabb], order: &[u32], nodes: &mut Vec<Node>, emit_leaf: &mut impl FnMut(&[u32]) -> u32) {
    let mut codes = [EMPTY_CHILD; WIDTH];
    for (k, child) in children.iter().enumerate() {
        codes[k] = match child {
            BNode::Leaf { start, count } => {
                let code = emit_leaf(&order[*start as usize..(*start + *count) as usize]);
                debug_assert!(code & LEAF_BIT != 0);
                code
            }
            BNode::Inner { .. } => {
                let ci = nodes.len();
                nodes.push(Node::empty());
                let (gc, gb) = collapse(child);
                fill_node(ci, &gc, &gb, order, nodes, emit_leaf);
                ci as u32
            }
        };
    }
    nodes[idx] = Node::new(boxes, codes);
}

/// The up-to-WIDTH children of a binary inner node in the wide tree: open the
/// child of largest surface area until there are WIDTH (or only leaves remain).
fn collapse(node: &BNode) -> (Vec<&BNode>, Vec<Aabb>) {
    let BNode::Inner { bounds, children } = node else { unreachable!("collapse of a leaf") };
    let mut list: Vec<(&BNode, Aabb)> = vec![(&children[0], bounds[0]), (&children[1], bounds[1])];
    while list.len() < WIDTH {
        let best = list
            .iter()
            .enumerate()
            .filter(|(_, (n, _))| matches!(n, BNode::Inner { .. }))
            .max_by(|a, b| a.1 .1.surface_area().total_cmp(&b.1 .1.surface_area()))
            .map(|(i, _)| i);
        let Some(i) = best else { break };
        let (n, _) = list.swap_remove(i);
        if let BNode::Inner { bounds, children } = n {
            list.push((&children[0], bounds[0]));
            list.push((&children[1], bounds[1]));
        }
    }
    list.into_iter().unzip()
}

fn groups(n: usize, group: usize) -> f32 {
    n.div_ceil(group) as f32
}

fn build_rec(ctx: &Ctx, order: &mut [u32], first: usize, bb: Aabb, depth: usize) -> BNode {
    let n = order.len();
    let p = ctx.params;
    let leaf = BNode::Leaf { start: first as u32, count: n as u32 };
    if n <= 1 {
        return leaf;
    }
    let cb = order.iter().fold(Aabb::EMPTY, |b, &i| b.grow(ctx.centroids[i as usize]));
    let ext = cb.extent();
    let mut mid = n / 2;
    if depth >= SAH_MAX_DEPTH {
        if n <= p.max_leaf {
            return leaf;
        }
        let axis = ext.max_position();
        order.select_nth_unstable_by(mid, |&a, &b| ctx.centroids[a as usize][axis].total_cmp(&ctx.centroids[b as usize][axis]));
        return split_at(ctx, order, first, mid, depth);
    }
    let split = best_split(ctx, order, &cb);
    let leaf_cost = groups(n, p.group);
    match split {
        Some((cost, axis, bin)) => {
            // Costs are in units of parent area: traversal + sum of area ratio * groups.
            let split_cost = p.traversal_cost + cost / bb.surface_area().max(f32::MIN_POSITIVE);
            if n <= p.max_leaf && leaf_cost <= split_cost {
                return leaf;
            }
            let scale = BINS as f32 / ext[axis];
            let lo = cb.min[axis];
            let mut l = 0;
            for k in 0..n {
                let c = ctx.centroids[order[k] as usize][axis];
                if bin_index(c, lo, scale) < bin {
                    order.swap(k, l);
                    l += 1;
                }
            }
            if l > 0 && l < n {
                mid = l;
            }
        }
        None => {
            // All centroids coincide: nothing to gain from splitting but leaf size.
            if n <= p.max_leaf {
                return leaf;
            }
        }
    }
    split_at(ctx, order, first, mid, depth)
}

fn split_at(ctx: &Ctx, order: &mut [u32], first: usize, mid: usize, depth: usize) -> BNode {
    let n = order.len();
    let (left, right) = order.split_at_mut(mid);
    let lb = left.iter().fold(Aabb::EMPTY, |b, &i| b.union(ctx.bounds[i as usize]));
    let rb = right.iter().fold(Aabb::EMPTY, |b, &i| b.union(ctx.bounds[i as usize]));
    let (a, b) = if n >= PARALLEL_MIN {
        rayon::join(|| build_rec(ctx, left, first, lb, depth + 1), || build_rec(ctx, right, first + mid, rb, depth + 1))
    } else {
        (build_rec(ctx, left, first, lb, depth + 1), build_rec(ctx, right, first + mid, rb, depth + 1))
    };
    BNode::Inner { bounds: [lb, rb], children: Box::new([a, b]) }
}

#[inline]
fn bin_index(c: f32, lo: f32, scale: f32) -> usize {
    (((c - lo) * scale) as usize).min(BINS - 1)
}

/// Best binned SAH split over the three axes: (sum of area * groups, axis, first bin of the right side).
fn best_split(ctx: &Ctx, order: &[u32], cb: &Aabb) -> Option<(f32, usize, usize)> {
    let ext = cb.extent();
    let mut bin_b = [[Aabb::EMPTY; BINS]; 3];
    let mut bin_n = [[0u32; BINS]; 3];
    let scale = Vec3::select(ext.cmpgt(Vec3::ZERO), Vec3::splat(BINS as f32) / ext, Vec3::ZERO);
    for &i in order {
        let c = ctx.centroids[i as usize];
        let b = ctx.bounds[i as usize];
        for axis in 0..3 {
            let k = bin_index(c[axis], cb.min[axis], scale[axis]);
            bin_b[axis][k] = bin_b[axis][k].union(b);
            bin_n[axis][k] += 1;
        }
    }
    let g = ctx.params.group;
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if ext[axis] <= 0.0 {
            continue;
        }
        let mut right_cost = [0.0f32; BINS];
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
        for k in (1..BINS).rev() {
            acc = acc.union(bin_b[axis][k]);
            cnt += bin_n[axis][k] as usize;
            right_cost[k] = if cnt == 0 { f32::INFINITY } else { acc.surface_area() * groups(cnt, g) };
        }
        let (mut acc, mut cnt) = (Aabb::EMPTY, 0usize);
        for k in 1..BINS {
            acc = acc.union(bin_b[axis][k - 1]);
            cnt += bin_n[axis][k - 1] as usize;
            if cnt == 0 || !right_cost[k].is_finite() {
                continue;
            }
            let cost = acc.surface_area() * groups(cnt, g) + right_cost[k];
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, k));
            }
        }
    }
    best
}
