//! A balanced kd-tree over points (photons, visible points), Jensen's layout: the items are
//! reordered in place so that each subrange's median (on the axis of its largest extent)
//! sits at the middle index, its left subtree before it and its right subtree after it.
//! No pointers: a node is an index, its children the middles of the two halves.
//!
//! Queries: every item within a radius (`for_each_in_radius`), and the k nearest within a
//! maximum radius (`k_nearest`), both with a filter so that callers can skip items (photons
//! of the wrong path length) without a second pass.

use glam::Vec3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// What the tree stores must say where it is.
pub trait KdPoint {
    fn position(&self) -> Vec3;
}

impl KdPoint for Vec3 {
    fn position(&self) -> Vec3 {
        *self
    }
}

pub struct KdTree<T> {
    items: Vec<T>,
    /// Split axis of the node at each index (0, 1, 2).
    axes: Vec<u8>,
}

/// Subranges smaller than this are built on one thread.
const PARALLEL_MIN: usize = 16_384;

fn split_axis<T: KdPoint>(items: &[T]) -> usize {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for it in items {
        let p = it.position();
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let e = hi - lo;
    if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    }
}

fn build<T: KdPoint + Send>(items: &mut [T], axes: &mut [u8]) {
    let n = items.len();
    if n <= 1 {
        if n == 1 {
            axes[0] = 0;
        }
        return;
    }
    let axis = split_axis(items);
    let mid = n / 2;
    items.select_nth_unstable_by(mid, |a, b| a.position()[axis].total_cmp(&b.position()[axis]));
    axes[mid] = axis as u8;
    let (li, rest) = items.split_at_mut(mid);
    let (la, rest_a) = axes.split_at_mut(mid);
    let (ri, ra) = (&mut rest[1..], &mut rest_a[1..]);
    if n >= PARALLEL_MIN {
        rayon::join(|| build(li, la), || build(ri, ra));
    } else {
        build(li, la);
        build(ri, ra);
    }
}

/// A candidate of the k-nearest search, ordered by distance (then index, for determinism).
#[derive(Clone, Copy, Debug)]
struct Candidate {
    d2: f32,
    index: u32,
}

impl PartialEq for Candidate {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Candidate {
    fn cmp(&self, o: &Self) -> Ordering {
        self.d2.total_cmp(&o.d2).then(self.index.cmp(&o.index))
    }
}

impl<T: KdPoint + Send> KdTree<T> {
    /// Build over `items` (reordered). O(n log n), subtrees in parallel above a size.
    pub fn new(mut items: Vec<T>) -> Self {
        let mut axes = vec![0u8; items.len()];
        build(&mut items, &mut axes);
        KdTree { items, axes }
    }
}

impl<T: KdPoint> KdTree<T> {
    pub fn len(&self) -> usize {
        self.items.len()
    }
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
    /// The items in the tree's order (indices returned by queries point here).
    pub fn items(&self) -> &[T] {
        &self.items
    }

    /// Call `f(item, squared distance)` for every item within `radius` of `p`.
    pub fn for_each_in_radius(&self, p: Vec3, radius: f32, mut f: impl FnMut(&T, f32)) {
        if !self.items.is_empty() {
            self.radius_rec(0, self.items.len(), p, radius * radius, &mut f);
        }
    }

    fn radius_rec(&self, lo: usize, hi: usize, p: Vec3, r2: f32, f: &mut impl FnMut(&T, f32)) {
        if lo >= hi {
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let it = &self.items[mid];
        let q = it.position();
        let d2 = (q - p).length_squared();
        if d2 <= r2 {
            f(it, d2);
        }
        let axis = self.axes[mid] as usize;
        let delta = p[axis] - q[axis];
        // Items equal to the median on the axis may be on either side: visit both then.
        if delta <= 0.0 || delta * delta <= r2 {
            self.radius_rec(lo, mid, p, r2, f);
        }
        if delta >= 0.0 || delta * delta <= r2 {
            self.radius_rec(mid + 1, hi, p, r2, f);
        }
    }

    /// The (at most) `k` nearest items within `max_radius` of `p` that `accept` lets through,
    /// as (index into `items()`, squared distance), nearest first. Ties break by index.
    pub fn k_nearest(&self, p: Vec3, k: usize, max_radius: f32, accept: impl Fn(&T) -> bool) -> Vec<(usize, f32)> {
        let mut heap: BinaryHeap<Candidate> = BinaryHeap::with_capacity(k + 1);
        if k > 0 && !self.items.is_empty() {
            let mut r2 = max_radius * max_radius;
            self.knn_rec(0, self.items.len(), p, k, &mut r2, &mut heap, &accept);
        }
        let mut v: Vec<(usize, f32)> = heap.into_iter().map(|c| (c.index as usize, c.d2)).collect();
        v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        v
    }

    #[allow(clippy::too_many_arguments)]
    fn knn_rec(&self, lo: usize, hi: usize, p: Vec3, k: usize, r2: &mut f32, heap: &mut BinaryHeap<Candidate>, accept: &impl Fn(&T) -> bool) {
        if lo >= hi {
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let it = &self.items[mid];
        let q = it.position();
        let axis = self.axes[mid] as usize;
        let delta = p[axis] - q[axis];
        // Near side first, so that the search radius shrinks early.
        let (near, far) = if delta <= 0.0 { ((lo, mid), (mid + 1, hi)) } else { ((mid + 1, hi), (lo, mid)) };
        self.knn_rec(near.0, near.1, p, k, r2, heap, accept);
        let d2 = (q - p).length_squared();
        if d2 <= *r2 && accept(it) {
            let c = Candidate { d2, index: mid as u32 };
            if heap.len() < k {
                heap.push(c);
            } else if heap.peek().is_some_and(|w| c < *w) {
                heap.pop();
                heap.push(c);
            }
            if heap.len() == k {
                *r2 = heap.peek().map_or(*r2, |w| w.d2);
            }
        }
        // Equal coordinates may lie on either side of the median.
        if delta * delta <= *r2 {
            self.knn_rec(far.0, far.1, p, k, r2, heap, accept);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    fn random_points(n: usize, seed: u64, clustered: bool) -> Vec<Vec3> {
        let mut rng = Pcg32::new(seed, 1);
        (0..n)
            .map(|i| {
                let mut p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                if clustered {
                    // Points on a plane, duplicates and a dense clump: the layouts photons take.
                    match i % 4 {
                        0 => p.z = 0.25,
                        1 => p = (p * 1e-3) + Vec3::splat(0.5),
                        2 => p.x = (p.x * 8.0).floor() / 8.0,
                        _ => {}
                    }
                }
                p
            })
            .collect()
    }

    #[test]
    fn radius_query_equals_brute_force() {
        for (seed, clustered) in [(1, false), (2, true)] {
            let pts = random_points(5_000, seed, clustered);
            let tree = KdTree::new(pts.clone());
            let mut rng = Pcg32::new(seed + 100, 3);
            for _ in 0..200 {
                let q = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 1.2 - Vec3::splat(0.1);
                let r = 0.2 * rng.next_f32();
                let mut got: Vec<[u32; 3]> = Vec::new();
                tree.for_each_in_radius(q, r, |p, d2| {
                    assert!((d2 - (*p - q).length_squared()).abs() <= 1e-6);
                    got.push(p.to_array().map(f32::to_bits));
                });
                let mut want: Vec<[u32; 3]> = pts.iter().filter(|p| (**p - q).length_squared() <= r * r).map(|p| p.to_array().map(f32::to_bits)).collect();
                got.sort_unstable();
                want.sort_unstable();
                assert_eq!(got, want, "query {q:?} radius {r}");
            }
        }
    }

    #[test]
    fn k_nearest_equals_brute_force() {
        for (seed, clustered) in [(3, false), (4, true)] {
            let pts = random_points(4_000, seed, clustered);
            let tree = KdTree::new(pts.clone());
            let mut rng = Pcg32::new(seed + 200, 5);
            for qi in 0..200 {
                let q = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let k = 1 + (qi % 60);
                let max_r = if qi % 3 == 0 { 0.05 } else { f32::INFINITY };
                // A filter that drops about a third of the points.
                let accept = |p: &Vec3| (p.x * 1000.0) as i64 % 3 != 0;
                let got = tree.k_nearest(q, k, max_r, accept);
                let mut want: Vec<f32> = pts.iter().filter(|p| accept(p)).map(|p| (*p - q).length_squared()).filter(|&d2| d2 <= max_r * max_r).collect();
                want.sort_by(f32::total_cmp);
                want.truncate(k);
                let got_d: Vec<f32> = got.iter().map(|&(_, d2)| d2).collect();
                assert_eq!(got_d, want, "query {q:?} k {k} max {max_r}");
                for &(i, d2) in &got {
                    assert!(accept(&tree.items()[i]));
                    assert_eq!((tree.items()[i] - q).length_squared(), d2);
                }
            }
        }
    }

    #[test]
    fn tree_is_balanced_and_ordered() {
        let pts = random_points(50_000, 9, true);
        let tree = KdTree::new(pts.clone());
        assert_eq!(tree.len(), pts.len());
        // Every node separates its halves on its axis.
        fn check(t: &KdTree<Vec3>, lo: usize, hi: usize, depth: usize, max_depth: &mut usize) {
            if lo >= hi {
                return;
            }
            *max_depth = (*max_depth).max(depth);
            let mid = lo + (hi - lo) / 2;
            let a = t.axes[mid] as usize;
            let v = t.items[mid][a];
            assert!(t.items[lo..mid].iter().all(|p| p[a] <= v));
            assert!(t.items[mid + 1..hi].iter().all(|p| p[a] >= v));
            check(t, lo, mid, depth + 1, max_depth);
            check(t, mid + 1, hi, depth + 1, max_depth);
        }
        let mut d = 0;
        check(&tree, 0, tree.len(), 1, &mut d);
        assert_eq!(d, (tree.len() as f64 + 1.0).log2().ceil() as usize);
        let empty: KdTree<Vec3> = KdTree::new(Vec::new());
        assert!(empty.k_nearest(Vec3::ZERO, 5, 1.0, |_| true).is_empty());
    }
}
