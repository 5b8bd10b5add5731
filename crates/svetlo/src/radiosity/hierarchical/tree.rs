//! The quadtrees of hierarchical radiosity: every input triangle (one side) is a root, split at
//! its edge midpoints into four congruent children as refinement asks. After d splits the
//! nodes at depth d are exactly the sub-triangles of the regular 2^d × 2^d split that
//! [`crate::radiosity::mesh`] makes, which is how a solution is shown on a conforming mesh.

use crate::spectrum::Rgb;
use glam::Vec3;

/// Values at the corners of the four children of a triangle with corner values `v` (linear
/// interpolation; the same order as [`Node::child_corners`]). Also splits positions.
pub fn split_corners<T: Copy + std::ops::Add<Output = T> + std::ops::Mul<f32, Output = T>>(v: [T; 3]) -> [[T; 3]; 4] {
    let [a, b, c] = v;
    let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
    [[a, ab, ca], [ab, b, bc], [ca, bc, c], [bc, ca, ab]]
}

/// One node of a quadtree: a triangle with its radiosity and importance.
#[derive(Clone, Debug)]
pub struct Node {
    pub p: [Vec3; 3],
    pub normal: Vec3,
    pub centroid: Vec3,
    pub area: f32,
    pub root: u32,
    pub depth: u8,
    /// Index of the first of four consecutive children; 0 for a leaf (a root is never a child).
    pub children: u32,
    /// Radiosity: at a leaf E + ρ (gathered here and above); inside, the area-weighted mean of the children.
    pub b: Rgb,
    /// Σ F B over the links this node gathers from (irradiance / π, before ρ), as values at
    /// the three corners of a linear function over the node (links are linear in the receiver).
    pub gathered: [Rgb; 3],
    /// Importance per unit area (response of the image to a unit radiosity here), and its gathered part.
    pub w: f32,
    pub w_gathered: f32,
}

impl Node {
    pub fn new(p: [Vec3; 3], normal: Vec3, root: u32, depth: u8) -> Self {
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        Node {
            p,
            normal,
            centroid: (p[0] + p[1] + p[2]) / 3.0,
            area,
            root,
            depth,
            children: 0,
            b: Rgb::BLACK,
            gathered: [Rgb::BLACK; 3],
            w: 0.0,
            w_gathered: 0.0,
        }
    }

    pub fn is_leaf(&self) -> bool {
        self.children == 0
    }

    pub fn radius(&self) -> f32 {
        self.p.iter().map(|v| (*v - self.centroid).length()).fold(0.0, f32::max)
    }

    /// The four children's corners: three at the corners, the inverted one in the middle.
    pub fn child_corners(&self) -> [[Vec3; 3]; 4] {
        split_corners(self.p)
    }

    /// Which child holds point `x` (in the node's plane): by its barycentrics, a corner child
    /// when one weight reaches 1/2, the middle one otherwise.
    pub fn child_of(&self, x: Vec3) -> u32 {
        let [b0, b1, b2] = self.barycentric(x);
        if b0 >= 0.5 {
            0
        } else if b1 >= 0.5 {
            1
        } else if b2 >= 0.5 {
            2
        } else {
            3
        }
    }

    /// Barycentric weights of the corners at point `x` (projected onto the node's plane).
    pub fn barycentric(&self, x: Vec3) -> [f32; 3] {
        let (e1, e2, q) = (self.p[1] - self.p[0], self.p[2] - self.p[0], x - self.p[0]);
        let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (q1, q2) = (q.dot(e1), q.dot(e2));
        let det = (d11 * d22 - d12 * d12).max(1e-30);
        let b1 = (d22 * q1 - d12 * q2) / det;
        let b2 = (d11 * q2 - d12 * q1) / det;
        [1.0 - b1 - b2, b1, b2]
    }

    /// Can any of `other`'s corners be in front of this node (so light may pass from one to the other)?
    pub fn faces(&self, other: &Node) -> bool {
        let eps = 1e-6 * self.radius().max(other.radius());
        other.p.iter().any(|v| self.normal.dot(*v - self.centroid) > eps)
    }
}

/// The nodes of every quadtree in one arena; roots first, in the order of the root mesh's elements.
#[derive(Clone, Debug, Default)]
pub struct Forest {
    pub nodes: Vec<Node>,
    pub roots: usize,
}

impl Forest {
    /// Split node `n` into four (no-op when it has children); children start with its radiosity and importance.
    pub fn split(&mut self, n: u32) -> u32 {
        let node = &self.nodes[n as usize];
        if !node.is_leaf() {
            return node.children;
        }
        let first = self.nodes.len() as u32;
        let (normal, root, depth, b, w) = (node.normal, node.root, node.depth + 1, node.b, node.w);
        for c in node.child_corners() {
            let mut child = Node::new(c, normal, root, depth);
            child.b = b;
            child.w = w;
            self.nodes.push(child);
        }
        self.nodes[n as usize].children = first;
        first
    }

    /// The deepest node at most `depth` deep on the path from root `r` to the point `x`.
    pub fn find(&self, r: u32, x: Vec3, depth: u8) -> u32 {
        let mut n = r;
        loop {
            let node = &self.nodes[n as usize];
            if node.is_leaf() || node.depth >= depth {
                return n;
            }
            n = node.children + node.child_of(x);
        }
    }

    pub fn leaves(&self) -> usize {
        self.nodes.iter().filter(|n| n.is_leaf()).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn children_tile_the_parent_and_point_location_agrees() {
        let mut f = Forest { nodes: vec![Node::new([Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.3, 1.5, 0.0)], Vec3::Z, 0, 0)], roots: 1 };
        let c = f.split(0);
        let s: f32 = (0..4).map(|k| f.nodes[(c + k) as usize].area).sum();
        assert!((s - f.nodes[0].area).abs() < 1e-5 * s);
        for k in 0..4 {
            let x = f.nodes[(c + k) as usize].centroid;
            assert_eq!(f.nodes[0].child_of(x), k);
            assert_eq!(f.find(0, x, 5), c + k);
            assert_eq!(f.find(0, x, 0), 0);
        }
    }
}
