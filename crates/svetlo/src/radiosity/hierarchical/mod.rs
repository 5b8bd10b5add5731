//! Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991), with importance (Smits, Arvo &
//! Salesin 1992).
//!
//! Each input triangle is the root of a quadtree ([`tree`]). Every pair of roots that face
//! each other is *refined* ([`refine`]): a cheap bound on the form factor between the two
//! nodes (the largest point-to-polygon value over the receiver's centroid and corners) feeds an
//! oracle; when its error is above ε the node that looks larger from the other is split and the
//! children are refined, otherwise the pair is *linked*. A link carries the area-averaged
//! form factor from receiver to source, computed like the analytic matrix rows (contour
//! integral over 3 × 3 points of the receiver, each times a shadow ray to the source), so that
//! partial visibility is sampled per link.
//!
//! Solving alternates gathering and push-pull: every node sums F·B over its links; a pass down
//! each tree adds what the ancestors gathered, the leaves take B = E + ρ (sum), and a pass up
//! makes every inner node the area-weighted mean of its children. Emission is added once, at
//! the leaves. After the system converges the links are refined again with the current B
//! (the BF oracle needs it), and so on until no link changes.
//!
//! Oracles: the F rule refines while max(F_pq, F_qp) > ε; the BF rule while ρ_p B_q F_pq / B̄ > ε
//! (B̄ = emitted power / total area, so ε is a fraction of the scene's mean radiosity); with
//! importance (BFV) the BF error is weighted by the receiver's importance relative to the mean,
//! where importance is the adjoint solution driven by the camera (the fraction of the image
//! each node covers, per unit area), gathered over the same links in the other direction.

pub mod refine;
pub mod tree;

use super::mesh::{MeshOptions, RadiosityMesh};
use super::solver::{l1, Step};
use crate::error::{Error, Result};
use crate::geometry::Ray;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};
use std::time::Instant;
use tree::{Forest, Node};

/// Which oracle decides whether a link is fine enough.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rule {
    /// Form-factor estimate only.
    F,
    /// Radiosity transferred (ρ B F).
    BF,
}

/// Settings of the hierarchical solver.
#[derive(Clone, Debug)]
pub struct HierarchicalOptions {
    pub rule: Rule,
    /// Oracle threshold (F rule: a form factor; BF: a fraction of the mean radiosity).
    pub epsilon: f64,
    /// No element smaller than this (scene units²). None: an eighth of the square of the element size.
    pub min_area: Option<f32>,
    /// Weight the BF rule by importance from the camera (Smits' BFV).
    pub importance: bool,
    /// Refine-and-solve passes at most.
    pub max_passes: usize,
    /// Most elements of the display mesh.
    pub display_elements: usize,
}

impl Default for HierarchicalOptions {
    fn default() -> Self {
        HierarchicalOptions { rule: Rule::BF, epsilon: 0.02, min_area: None, importance: false, max_passes: 8, display_elements: 1 << 18 }
    }
}

/// A link: the receiver gathers F · B_src from `src`, F a linear function over the receiver
/// given by its corner values `f` (their mean is the area-averaged form factor); `f_est`
/// bounds the error of F for the oracle (the variation of the unoccluded F over either node,
/// or F itself when the link is partially visible).
#[derive(Clone, Copy, Debug)]
pub struct Link {
    pub src: u32,
    pub f: [f32; 3],
    pub f_est: f32,
}

impl Link {
    pub fn mean(&self) -> f32 {
        (self.f[0] + self.f[1] + self.f[2]) / 3.0
    }
}

#[inline]
fn add3(a: [Rgb; 3], b: [Rgb; 3]) -> [Rgb; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Mean of a linear function's corner values, negative parts clipped (extrapolated gradients of
/// noisy visibility may dip below zero at a corner).
#[inline]
fn mean3(a: [Rgb; 3]) -> Rgb {
    ((a[0] + a[1] + a[2]) * (1.0 / 3.0)).map(|x| x.max(0.0))
}

/// What the solve built.
#[derive(Clone, Debug, Default)]
pub struct Stats {
    pub links: usize,
    pub nodes: usize,
    pub leaves: usize,
    /// Link form factors computed, including links later refined away.
    pub form_factors: u64,
    pub passes: usize,
    pub memory: usize,
    pub refine_seconds: f64,
}

/// The hierarchy: quadtrees, links, and per-root emission and reflectance.
pub struct Hierarchy<'a> {
    pub scene: &'a Scene,
    pub roots: RadiosityMesh,
    pub forest: Forest,
    /// Links gathered by each node.
    pub links: Vec<Vec<Link>>,
    pub opts: HierarchicalOptions,
    pub min_area: f32,
    /// B̄: emitted power over total area (the BF rule's scale).
    pub b_ref: f64,
    /// Camera samples (root, point) for direct importance, and the number of rays cast.
    camera_hits: Vec<(u32, Vec3)>,
    camera_rays: usize,
    /// Mean importance over the camera's hits (the BFV rule's scale).
    pub w_mean: f32,
    pub stats: Stats,
    /// Links made since the last form-factor pass, waiting for their F.
    pending: Vec<(u32, u32, f32, f32)>,
}

impl<'a> Hierarchy<'a> {
    /// Roots from the scene (one per input triangle and side), no links yet.
    pub fn new(scene: &'a Scene, mesh: &MeshOptions, opts: HierarchicalOptions) -> Result<Self> {
        if !(opts.epsilon > 0.0 && opts.epsilon.is_finite()) {
            return Err(Error::Settings(format!("radiosity: hierarchical epsilon must be positive, got {}", opts.epsilon)));
        }
        let roots = RadiosityMesh::build(scene, &MeshOptions { max_edge: Some(f32::MAX), shape_splits: vec![], ..mesh.clone() })?;
        let h = mesh.max_edge.unwrap_or(scene.bounds.radius.max(1e-6) / 5.0);
        let min_area = opts.min_area.unwrap_or(h * h / 8.0);
        if !(min_area > 0.0 && min_area.is_finite()) {
            return Err(Error::Settings(format!("radiosity: hierarchical min-area must be positive, got {min_area}")));
        }
        let mut forest = Forest { nodes: Vec::with_capacity(roots.elements.len() * 4), roots: roots.elements.len() };
        for (i, e) in roots.elements.iter().enumerate() {
            let mut n = Node::new(e.p, e.normal, i as u32, 0);
            n.b = e.source();
            forest.nodes.push(n);
        }
        let area: f64 = roots.total_area();
        let power: f64 = roots.elements.iter().map(|e| e.area as f64 * e.source().luminance() as f64).sum();
        let b_ref = if power > 0.0 { power / area } else { 1.0 };
        let links = vec![vec![]; forest.nodes.len()];
        Ok(Hierarchy {
            scene,
            roots,
            forest,
            links,
            opts,
            min_area,
            b_ref,
            camera_hits: vec![],
            camera_rays: 0,
            w_mean: 1.0,
            stats: Stats::default(),
            pending: vec![],
        })
    }

    fn rho(&self, n: u32) -> Rgb {
        self.roots.elements[self.forest.nodes[n as usize].root as usize].reflectance
    }
    fn emission(&self, n: u32) -> Rgb {
        self.roots.elements[self.forest.nodes[n as usize].root as usize].source()
    }

    /// One Gauss-Seidel sweep: each tree gathers over its links (with the newest B) and is pushed and pulled.
    pub fn sweep(&mut self) {
        for r in 0..self.forest.roots as u32 {
            let mut stack = vec![r];
            while let Some(n) = stack.pop() {
                let g = self.gather(n);
                self.forest.nodes[n as usize].gathered = g;
                let c = self.forest.nodes[n as usize].children;
                if c != 0 {
                    stack.extend(c..c + 4);
                }
            }
            self.push_pull(r, [Rgb::BLACK; 3]);
        }
    }

    /// One Jacobi sweep (every node gathers from the previous B): k of them from E give exactly k bounces.
    pub fn jacobi_sweep(&mut self) {
        let g: Vec<[Rgb; 3]> = (0..self.forest.nodes.len() as u32).map(|n| self.gather(n)).collect();
        for (node, g) in self.forest.nodes.iter_mut().zip(g) {
            node.gathered = g;
        }
        for r in 0..self.forest.roots as u32 {
            self.push_pull(r, [Rgb::BLACK; 3]);
        }
    }

    /// B = E at every leaf (nothing gathered), area-weighted means above.
    pub fn reset_to_emission(&mut self) {
        for node in &mut self.forest.nodes {
            node.gathered = [Rgb::BLACK; 3];
        }
        for r in 0..self.forest.roots as u32 {
            self.push_pull(r, [Rgb::BLACK; 3]);
        }
    }

    #[inline]
    fn gather(&self, n: u32) -> [Rgb; 3] {
        let mut s = [Rgb::BLACK; 3];
        for l in &self.links[n as usize] {
            let b = self.forest.nodes[l.src as usize].b;
            for (sk, fk) in s.iter_mut().zip(l.f) {
                *sk += b * fk;
            }
        }
        s
    }

    /// Push what the ancestors gathered down to the leaves, pull area-weighted means up.
    fn push_pull(&mut self, n: u32, down: [Rgb; 3]) -> Rgb {
        let node = &self.forest.nodes[n as usize];
        let down = add3(down, node.gathered);
        let b = if node.is_leaf() {
            self.emission(n) + self.rho(n) * mean3(down)
        } else {
            let (c, area) = (node.children, node.area);
            let mut s = Rgb::BLACK;
            for (k, dk) in (c..c + 4).zip(tree::split_corners(down)) {
                let bk = self.push_pull(k, dk);
                s += bk * (self.forest.nodes[k as usize].area / area);
            }
            s
        };
        self.forest.nodes[n as usize].b = b;
        b
    }

    /// Relative residual of the hierarchical system, Σ_leaves A |E + ρ (gathered above) − B| / Σ A E,
    /// as the other solvers define it.
    pub fn residual(&self) -> f64 {
        use rayon::prelude::*;
        let g: Vec<[Rgb; 3]> = (0..self.forest.nodes.len() as u32).into_par_iter().map(|n| self.gather(n)).collect();
        let mut total = 0.0;
        let mut stack: Vec<(u32, [Rgb; 3])> = (0..self.forest.roots as u32).map(|r| (r, [Rgb::BLACK; 3])).collect();
        while let Some((n, down)) = stack.pop() {
            let node = &self.forest.nodes[n as usize];
            let down = add3(down, g[n as usize]);
            if node.is_leaf() {
                total += node.area as f64 * l1(self.emission(n) + self.rho(n) * mean3(down) - node.b);
            } else {
                stack.extend((node.children..node.children + 4).zip(tree::split_corners(down)));
            }
        }
        let power: f64 = self.roots.elements.iter().map(|e| e.area as f64 * l1(e.source())).sum();
        total / if power > 0.0 { power } else { 1.0 }
    }

    /// Cast a grid of camera rays and keep where they land on the roots (direct importance).
    pub fn sample_camera(&mut self) {
        let cam = &self.scene.camera;
        let (nx, ny) = (cam.width.clamp(1, 128), cam.height.clamp(1, 128));
        self.camera_hits.clear();
        for y in 0..ny {
            for x in 0..nx {
                let raster = Vec2::new((x as f32 + 0.5) * cam.width as f32 / nx as f32, (y as f32 + 0.5) * cam.height as f32 / ny as f32);
                let ray: Ray = cam.generate_ray(raster, Vec2::splat(0.5), 0.0);
                if let Some(hit) = self.scene.intersect_prim(&ray) {
                    let p = ray.at(hit.t);
                    if let Some(r) = self.roots.element_at(&hit, p, ray.d) {
                        self.camera_hits.push((r, p));
                    }
                }
            }
        }
        self.camera_rays = (nx * ny) as usize;
    }

    /// Solve for importance per unit area: w = r + Σ_links ρ_p F_qp w_p, the links read backwards
    /// (receiver p sends importance to source q, F_qp = F_pq A_p / A_q), by Jacobi sweeps.
    pub fn solve_importance(&mut self, sweeps: usize) {
        let nn = self.forest.nodes.len();
        let mut direct = vec![0.0f32; nn];
        let per_ray = 1.0 / self.camera_rays.max(1) as f32;
        for &(r, p) in &self.camera_hits {
            let leaf = self.forest.find(r, p, u8::MAX);
            direct[leaf as usize] += per_ray;
        }
        for (d, n) in direct.iter_mut().zip(&self.forest.nodes) {
            *d /= n.area.max(1e-30);
        }
        for _ in 0..sweeps {
            let mut g = vec![0.0f32; nn];
            for p in 0..nn {
                let np = &self.forest.nodes[p];
                let k = self.rho(p as u32).mean() * np.w * np.area;
                for l in &self.links[p] {
                    g[l.src as usize] += k * l.mean() / self.forest.nodes[l.src as usize].area;
                }
            }
            for (node, g) in self.forest.nodes.iter_mut().zip(g) {
                node.w_gathered = g;
            }
            for r in 0..self.forest.roots as u32 {
                self.push_pull_w(r, 0.0, &direct);
            }
        }
        // The scale of the BFV rule: the mean importance where the camera looks, so that what the
        // camera sees is refined about as the BF rule would, and the rest by how much it matters.
        let seen: f64 = self.camera_hits.iter().map(|&(r, p)| self.forest.nodes[self.forest.find(r, p, u8::MAX) as usize].w as f64).sum();
        self.w_mean = ((seen / self.camera_hits.len().max(1) as f64) as f32).max(1e-30);
    }

    fn push_pull_w(&mut self, n: u32, down: f32, direct: &[f32]) -> f32 {
        let node = &self.forest.nodes[n as usize];
        let down = down + node.w_gathered;
        let w = if node.is_leaf() {
            direct[n as usize] + down
        } else {
            let (c, area) = (node.children, node.area);
            (c..c + 4).map(|k| self.push_pull_w(k, down, direct) * (self.forest.nodes[k as usize].area / area)).sum()
        };
        self.forest.nodes[n as usize].w = w;
        w
    }

    /// For every leaf, Σ F over its own links and its ancestors': the fraction of its hemisphere
    /// the links account for (1 in a closed scene, up to the quadrature of the link form factors).
    pub fn closure(&self) -> Vec<(u32, f64)> {
        let mut out = vec![];
        let mut stack: Vec<(u32, [f32; 3])> = (0..self.forest.roots as u32).map(|r| (r, [0.0; 3])).collect();
        while let Some((n, above)) = stack.pop() {
            let mut s = above;
            for l in &self.links[n as usize] {
                for (sk, fk) in s.iter_mut().zip(l.f) {
                    *sk += fk;
                }
            }
            let node = &self.forest.nodes[n as usize];
            if node.is_leaf() {
                out.push((n, (s[0] + s[1] + s[2]) as f64 / 3.0));
            } else {
                stack.extend((node.children..node.children + 4).zip(tree::split_corners(s)));
            }
        }
        out
    }

    pub fn link_count(&self) -> usize {
        self.links.iter().map(Vec::len).sum()
    }

    fn update_stats(&mut self) {
        self.stats.links = self.link_count();
        self.stats.nodes = self.forest.nodes.len();
        self.stats.leaves = self.forest.leaves();
        self.stats.memory =
            self.forest.nodes.len() * (std::mem::size_of::<Node>() + std::mem::size_of::<Vec<Link>>()) + self.stats.links * std::mem::size_of::<Link>();
    }

    /// The display mesh: each shape split 2^d times per edge, d its deepest leaf (lowered while
    /// the mesh would exceed `display_elements`), every display element's radiosity, read
    /// from the node that covers it exactly (or the leaf above it), and Gouraud values at the
    /// display vertices (see [`Self::leaf_gouraud`]).
    pub fn display(&self, mesh: &MeshOptions) -> Result<(RadiosityMesh, Vec<Rgb>, Vec<Rgb>)> {
        let (display, splits) = self.display_mesh(mesh)?;
        let b = self.node_values(&display, &splits);
        let vertex_b = self.leaf_gouraud(&display, &b, &splits);
        Ok((display, b, vertex_b))
    }

    /// The display mesh (see [`Self::display`]) and its splits per shape.
    fn display_mesh(&self, mesh: &MeshOptions) -> Result<(RadiosityMesh, Vec<u32>)> {
        let shapes = self.scene.shapes.len();
        let mut depth = vec![0u8; shapes];
        let mut tris = vec![0usize; shapes];
        for e in &self.roots.elements {
            tris[e.shape as usize] += 1;
        }
        for n in &self.forest.nodes {
            let s = self.roots.elements[n.root as usize].shape as usize;
            depth[s] = depth[s].max(n.depth);
        }
        let count = |cap: u8| (0..shapes).map(|s| tris[s] << (2 * depth[s].min(cap) as usize)).sum::<usize>();
        let mut cap = depth.iter().copied().max().unwrap_or(0).min(12);
        while cap > 0 && count(cap) > self.opts.display_elements {
            cap -= 1;
        }
        let splits: Vec<u32> = depth.iter().map(|d| 1u32 << d.min(&cap)).collect();
        let display = RadiosityMesh::build(self.scene, &display_options(mesh, &splits))?;
        Ok((display, splits))
    }

    /// The radiosity of the node each display element lies in.
    fn node_values(&self, display: &RadiosityMesh, splits: &[u32]) -> Vec<Rgb> {
        display
            .elements
            .iter()
            .map(|e| {
                let d = splits[e.shape as usize].trailing_zeros() as u8;
                let n = self.forest.find(e.patch, e.centroid, d);
                self.forest.nodes[n as usize].b
            })
            .collect()
    }

    /// Gouraud over the leaves, not the (finer) display elements: a leaf's corners take the
    /// area-weighted mean of the display elements around them (so of the leaves that meet
    /// there), and every display vertex inside or on the edge of a leaf takes the linear
    /// interpolation of that leaf's corner values. A vertex on the boundary of leaves of
    /// different sizes (a T-vertex of the leaf mesh) takes the value of the largest, i.e. the
    /// interpolation along the long edge, so the two sides agree there and nothing cracks.
    fn leaf_gouraud(&self, display: &RadiosityMesh, b: &[Rgb], splits: &[u32]) -> Vec<Rgb> {
        use std::collections::HashMap;
        let fine = super::display::vertex_radiosity(display, b);
        let step = self.scene.bounds.radius.max(1e-6) * 1e-5;
        let key =
            |e: &super::mesh::Element, p: Vec3| (e.shape, e.back, [(p.x / step).round() as i64, (p.y / step).round() as i64, (p.z / step).round() as i64]);
        let mut at: HashMap<(u32, bool, [i64; 3]), u32> = HashMap::new();
        for e in &display.elements {
            for k in 0..3 {
                at.insert(key(e, e.p[k]), e.vertex[k]);
            }
        }
        let mut best: Vec<(f32, Rgb)> = vec![(-1.0, Rgb::BLACK); display.vertices.len()];
        for e in &display.elements {
            let d = splits[e.shape as usize].trailing_zeros() as u8;
            let node = &self.forest.nodes[self.forest.find(e.patch, e.centroid, d) as usize];
            let corners = node.p.map(|c| at.get(&key(e, c)).map(|&v| fine[v as usize]));
            for k in 0..3 {
                let v = e.vertex[k] as usize;
                let value = match corners {
                    [Some(c0), Some(c1), Some(c2)] if node.depth < d => {
                        let w = node.barycentric(e.p[k]);
                        c0 * w[0] + c1 * w[1] + c2 * w[2]
                    }
                    _ => fine[v],
                };
                if node.area > best[v].0 {
                    best[v] = (node.area, value);
                }
            }
        }
        best.into_iter().map(|(_, v)| v).collect()
    }
}

/// The display mesh's options: `mesh`'s, each shape split `splits` times per edge.
fn display_options(mesh: &MeshOptions, splits: &[u32]) -> MeshOptions {
    MeshOptions { shape_splits: splits.to_vec(), max_elements: usize::MAX, ..mesh.clone() }
}

/// Everything [`super::solve`] needs back.
pub struct Outcome {
    pub mesh: RadiosityMesh,
    /// What `mesh` was built from.
    pub mesh_options: MeshOptions,
    pub b: Vec<Rgb>,
    /// Gouraud values at the display mesh's vertices.
    pub vertex_b: Vec<Rgb>,
    /// Per display element, the light of exactly one diffuse bounce ρ F E (paths `L D E`) on
    /// the final links, for light path expressions.
    pub b_one: Vec<Rgb>,
    pub history: Vec<Step>,
    pub converged: bool,
    pub stats: Stats,
}

/// Refine, solve to `tolerance` (sweeps at most `max_sweeps` per pass), re-refine with the
/// new radiosity, until no link changes or `max_passes`. With `bounces`, the links are
/// refined once against E and exactly that many Jacobi sweeps are made.
pub fn solve(scene: &Scene, mesh: &MeshOptions, opts: &HierarchicalOptions, tolerance: f64, max_sweeps: usize, bounces: Option<usize>) -> Result<Outcome> {
    let t0 = Instant::now();
    let mut h = Hierarchy::new(scene, mesh, opts.clone())?;
    if opts.importance {
        h.sample_camera();
        h.solve_importance(1);
    }
    let mut refine_seconds = 0.0;
    let t = Instant::now();
    h.refine_roots();
    h.compute_pending();
    refine_seconds += t.elapsed().as_secs_f64();
    let mut history = vec![];
    let mut step = 0;
    let mut converged = false;
    if let Some(k) = bounces {
        // Exactly k bounces from E, then re-refine with that B (the BF rule refined only the
        // lights' links against E alone) and start again from E, until no link changes.
        for pass in 0..=opts.max_passes {
            h.stats.passes = pass + 1;
            h.reset_to_emission();
            for _ in 0..k {
                h.jacobi_sweep();
                step += 1;
                history.push(Step { step, residual: h.residual(), seconds: t0.elapsed().as_secs_f64(), rows: h.link_count() as u64 });
            }
            if pass == opts.max_passes {
                break;
            }
            let t = Instant::now();
            if opts.importance {
                h.solve_importance(8);
            }
            let changed = h.rerefine();
            h.compute_pending();
            refine_seconds += t.elapsed().as_secs_f64();
            if changed == 0 {
                break;
            }
        }
        converged = true;
    } else {
        for pass in 0..=opts.max_passes {
            h.stats.passes = pass + 1;
            converged = false;
            for _ in 0..max_sweeps {
                h.sweep();
                step += 1;
                let r = h.residual();
                history.push(Step { step, residual: r, seconds: t0.elapsed().as_secs_f64(), rows: h.link_count() as u64 });
                if r < tolerance {
                    converged = true;
                    break;
                }
            }
            if pass == opts.max_passes {
                break;
            }
            let t = Instant::now();
            if opts.importance {
                h.solve_importance(8);
            }
            let changed = h.rerefine();
            h.compute_pending();
            refine_seconds += t.elapsed().as_secs_f64();
            if changed == 0 {
                break;
            }
        }
    }
    h.update_stats();
    h.stats.refine_seconds = refine_seconds;
    let (display, splits) = h.display_mesh(mesh)?;
    let b = h.node_values(&display, &splits);
    let vertex_b = h.leaf_gouraud(&display, &b, &splits);
    // One Jacobi sweep from E on the same links is exactly one bounce.
    let b_one = if bounces == Some(0) {
        vec![Rgb::BLACK; b.len()]
    } else {
        h.reset_to_emission();
        let e = h.node_values(&display, &splits);
        h.jacobi_sweep();
        h.node_values(&display, &splits).iter().zip(&e).map(|(b1, e)| (*b1 - *e).map(|x| x.max(0.0))).collect()
    };
    Ok(Outcome { mesh: display, mesh_options: display_options(mesh, &splits), b, vertex_b, b_one, history, converged, stats: h.stats })
}
