//! Link refinement: the oracle, the split decision, and the form factor a link carries.

use super::{Hierarchy, Link, Rule};
use crate::radiosity::form_factor::analytic::{point_to_polygon, triangle_points};
use rayon::prelude::*;

/// Deepest quadtree level (a guard; `min_area` stops refinement long before).
const MAX_DEPTH: u8 = 24;

impl Hierarchy<'_> {
    /// Can node `n` be split without making elements smaller than `min_area`?
    fn splittable(&self, n: u32) -> bool {
        let node = &self.forest.nodes[n as usize];
        node.area * 0.25 >= self.min_area && node.depth < MAX_DEPTH
    }

    fn split(&mut self, n: u32) -> u32 {
        let c = self.forest.split(n);
        self.links.resize_with(self.forest.nodes.len(), Vec::new);
        c
    }

    /// How much the point-to-polygon form factor varies over each node: (over p toward q, over q
    /// toward p), from the centroid and the (slightly pulled in) corners, counting only points in
    /// front of the other node. A link applies one averaged F to every point of its receiver and
    /// all its descendants, so its error is this variation, not the size of F: many small links
    /// kept at a coarse level while the receiver was split for a near source all err the same
    /// way (near a corner the far surfaces fill less of the hemisphere than on average), and an
    /// oracle on the size of F leaves such leaves 10-25 % too bright in a furnace.
    pub fn estimate(&self, p: u32, q: u32) -> (f32, f32) {
        let (np, nq) = (&self.forest.nodes[p as usize], &self.forest.nodes[q as usize]);
        let variation = |a: &super::Node, b: &super::Node| {
            let pts = [a.centroid, a.p[0] * 0.9 + a.centroid * 0.1, a.p[1] * 0.9 + a.centroid * 0.1, a.p[2] * 0.9 + a.centroid * 0.1];
            let (mut lo, mut hi) = (f64::MAX, 0.0f64);
            for x in pts {
                let f = if b.normal.dot(x - b.centroid) > 0.0 { point_to_polygon(x, a.normal, &b.p) } else { 0.0 };
                lo = lo.min(f);
                hi = hi.max(f);
            }
            (hi - lo) as f32
        };
        (variation(np, nq), variation(nq, np))
    }

    /// The oracle's error for the link p ← q from the variations (over p, over q).
    fn error(&self, p: u32, q: u32, vp: f32, vq: f32) -> f64 {
        let v = vp.max(vq) as f64;
        match self.opts.rule {
            Rule::F => v,
            Rule::BF => {
                let transfer = (self.rho(p) * self.forest.nodes[q as usize].b).luminance() as f64 * v / self.b_ref;
                if self.opts.importance {
                    transfer * (self.forest.nodes[p as usize].w / self.w_mean) as f64
                } else {
                    transfer
                }
            }
        }
    }

    /// Link p ← q, or split the node over which F varies more and refine its children
    /// (`split` forces the split at this level: a partially visible link found too coarse).
    fn refine(&mut self, p: u32, q: u32, est: Option<(f32, f32)>, split: bool) {
        let (vp, vq) = est.unwrap_or_else(|| self.estimate(p, q));
        let (sp, sq) = (self.splittable(p), self.splittable(q));
        if (!sp && !sq) || (!split && self.error(p, q, vp, vq) <= self.opts.epsilon) {
            self.pending.push((p, q, vp, vq));
            return;
        }
        if sq && (vq > vp || !sp) {
            let c = self.split(q);
            for k in c..c + 4 {
                if self.faces_both(p, k) {
                    self.refine(p, k, None, false);
                }
            }
        } else {
            let c = self.split(p);
            for k in c..c + 4 {
                if self.faces_both(k, q) {
                    self.refine(k, q, None, false);
                }
            }
        }
    }

    fn faces_both(&self, a: u32, b: u32) -> bool {
        let (na, nb) = (&self.forest.nodes[a as usize], &self.forest.nodes[b as usize]);
        na.faces(nb) && nb.faces(na)
    }

    /// Refine every pair of roots that face each other and can exchange light (the receiver
    /// reflects, the source emits or reflects).
    pub fn refine_roots(&mut self) {
        let n = self.forest.roots as u32;
        for p in 0..n {
            if self.rho(p).is_black() {
                continue;
            }
            for q in 0..n {
                if p != q && !(self.rho(q).is_black() && self.emission(q).is_black()) && self.faces_both(p, q) {
                    self.refine(p, q, None, false);
                }
            }
        }
    }

    /// Refine the existing links again with the current radiosity and importance; returns how
    /// many links were replaced.
    pub fn rerefine(&mut self) -> usize {
        let mut changed = 0;
        for p in 0..self.forest.nodes.len() as u32 {
            let old = std::mem::take(&mut self.links[p as usize]);
            for l in old {
                let can = self.splittable(p) || self.splittable(l.src);
                // f_est bounds the error of the link's F (see `compute_pending`).
                if can && self.error(p, l.src, l.f_est, l.f_est) > self.opts.epsilon {
                    changed += 1;
                    self.refine(p, l.src, None, true);
                    continue;
                }
                self.links[p as usize].push(l);
            }
        }
        changed
    }

    /// Form factors of the links made since the last call (in parallel); links through which
    /// no light passes (every sample blocked or behind the source) are dropped.
    pub fn compute_pending(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        let fs: Vec<([f32; 3], bool)> = pending.par_iter().map(|&(p, q, _, _)| self.link_form_factor(p, q)).collect();
        self.stats.form_factors += pending.len() as u64;
        for ((p, q, vp, vq), (f, partial)) in pending.into_iter().zip(fs) {
            if f.iter().any(|&x| x != 0.0) {
                // A partially visible link may be off by as much as its whole F (the shadow
                // boundary can fall anywhere in it), not just by the variation of the unoccluded F.
                let mean = (f[0] + f[1] + f[2]) / 3.0;
                let f_est = if partial { vp.max(vq).max(mean) } else { vp.max(vq) };
                self.links[p as usize].push(Link { src: q, f, f_est });
            }
        }
    }

    /// F_pq with visibility as a linear function over p (corner values): the contour integral
    /// from the 9 midpoints of p's 3 × 3 split to q, each times one shadow ray to a point of q's
    /// 3 × 3 split (strata paired by a permutation), fitted by least squares. The fit's mean is
    /// the 9 points' mean (they are symmetric about the centroid), i.e. the area-averaged F.
    /// Points behind q's plane receive nothing from its front.
    /// Also says whether the link is partially visible (some of its rays blocked, some not).
    pub fn link_form_factor(&self, p: u32, q: u32) -> ([f32; 3], bool) {
        let (np, nq) = (&self.forest.nodes[p as usize], &self.forest.nodes[q as usize]);
        let targets = triangle_points(&nq.p, 3);
        let mut m = glam::DMat3::ZERO;
        let mut rhs = glam::DVec3::ZERO;
        let (mut open, mut blocked) = (0, 0);
        for (k, (u, v)) in midpoints3().into_iter().enumerate() {
            let x = np.p[0] + (np.p[1] - np.p[0]) * u + (np.p[2] - np.p[0]) * v;
            let mut f = 0.0;
            if nq.normal.dot(x - nq.centroid) > 0.0 {
                f = point_to_polygon(x, np.normal, &nq.p);
                if f > 0.0 {
                    if self.scene.occluded(x, np.normal, targets[(4 * k + 1) % targets.len()]) {
                        f = 0.0;
                        blocked += 1;
                    } else {
                        open += 1;
                    }
                }
            }
            let a = glam::DVec3::new(1.0, u as f64, v as f64);
            m += glam::DMat3::from_cols(a * a.x, a * a.y, a * a.z);
            rhs += a * f;
        }
        let c = m.inverse() * rhs;
        ([c.x as f32, (c.x + c.y) as f32, (c.x + c.z) as f32], open > 0 && blocked > 0)
    }
}

/// Barycentrics (weights of corners 1 and 2) of the midpoints of a triangle's 3 × 3 split.
fn midpoints3() -> [(f32, f32); 9] {
    let mut out = [(0.0, 0.0); 9];
    let mut n = 0;
    for j in 0..3 {
        for i in 0..3 - j {
            let (fi, fj) = (i as f32, j as f32);
            out[n] = ((fi + 1.0 / 3.0) / 3.0, (fj + 1.0 / 3.0) / 3.0);
            n += 1;
            if i + j + 1 < 3 {
                out[n] = ((fi + 2.0 / 3.0) / 3.0, (fj + 2.0 / 3.0) / 3.0);
                n += 1;
            }
        }
    }
    out
}
