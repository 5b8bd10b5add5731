//! Mitsuba 3's `sdfgrid` shape: a signed distance function sampled on a grid of
//! `nx × ny × nz` points spanning the unit cube of object space, placed by `to_world`.
//!
//! The surface is the zero set of the grid's trilinear interpolant. Each voxel whose eight
//! corner samples do not all share one strict sign is a primitive of its own (the
//! accelerator holds the tight box of its surface); along a ray the interpolant inside a
//! voxel is a cubic in t, whose first root is found by splitting the voxel span at the
//! cubic's turning points and refining the first bracketing piece by safeguarded Newton
//! steps (Hansson-Söderlund, Evans and Akenine-Möller, JCGT 11(3), 2022). Normals are
//! those Mitsuba computes: the geometric normal is the interpolant's gradient in the hit
//! voxel; the `smooth` shading normal blends the gradients of the eight voxels around the
//! nearest grid point by the position relative to their centres, so that it is continuous
//! across voxel faces (same paper). Mitsuba gives the shape no uvs (they are 0) and no
//! area: it cannot emit.

use super::Aabb;
use glam::{DMat3, DVec3, Mat3, Mat4, Vec3};
use std::sync::Arc;

/// How shading normals are computed (Mitsuba's `normals` parameter).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdfNormals {
    /// The gradient of the hit voxel's interpolant (equal to the geometric normal).
    Analytic,
    /// Blended over the eight voxels around the nearest grid point (Mitsuba's default).
    Smooth,
}

#[derive(Clone, Debug)]
pub struct SdfGrid {
    /// Samples along x, y, z (each at least 2).
    pub res: [usize; 3],
    /// Sample values, x fastest: index (z · ny + y) · nx + x.
    values: Arc<[f32]>,
    /// Lower-corner sample index of each voxel the surface may pass through.
    voxels: Arc<[u32]>,
    to_world: Mat4,
    /// Object to world in f64, and back (the root finder works in f64).
    lin: DMat3,
    offset: DVec3,
    inv_lin: DMat3,
    inv_offset: DVec3,
    /// Normals to world: the inverse transpose of the linear part.
    normal_to_world: Mat3,
    pub normals: SdfNormals,
}

impl SdfGrid {
    /// A grid of `res` samples (x fastest) placed by `to_world`. Errors (as text, for the
    /// caller to locate) for a grid under 2 samples along an axis, a value count that does
    /// not match, a value that is not finite, a singular transform, or a grid without any
    /// voxel the surface crosses.
    pub fn new(res: [usize; 3], values: Vec<f32>, to_world: Mat4, normals: SdfNormals) -> Result<SdfGrid, String> {
        if res.iter().any(|&n| n < 2) {
            return Err(format!("an SDF grid needs at least 2 samples along each axis, got {}x{}x{}", res[0], res[1], res[2]));
        }
        let count = res.iter().try_fold(1usize, |a, &n| a.checked_mul(n));
        if count != Some(values.len()) || values.len() > u32::MAX as usize {
            return Err(format!("{}x{}x{} grid with {} values", res[0], res[1], res[2], values.len()));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(format!("SDF value {} (sample {i}) is not finite", values[i]));
        }
        let [nx, ny, nz] = res;
        let mut voxels = Vec::new();
        for z in 0..nz - 1 {
            for y in 0..ny - 1 {
                for x in 0..nx - 1 {
                    let base = (z * ny + y) * nx + x;
                    let c = corners(&values, res, base);
                    // Occupied unless all corners are strictly positive or strictly negative.
                    if c.iter().any(|&v| v >= 0.0) && c.iter().any(|&v| v <= 0.0) {
                        voxels.push(base as u32);
                    }
                }
            }
        }
        if voxels.is_empty() {
            return Err("the SDF grid has no voxel the surface passes through (no sign change)".into());
        }
        Self::place(res, values.into(), voxels.into(), to_world, normals)
    }

    fn place(res: [usize; 3], values: Arc<[f32]>, voxels: Arc<[u32]>, to_world: Mat4, normals: SdfNormals) -> Result<SdfGrid, String> {
        let m = to_world.as_dmat4();
        let lin = DMat3::from_mat4(m);
        let det = lin.determinant();
        if !(det.is_finite() && det.abs() > 1e-30 && m.is_finite()) {
            return Err("to_world is singular or not finite".into());
        }
        let inv_lin = lin.inverse();
        let offset = m.w_axis.truncate();
        Ok(SdfGrid {
            res,
            values,
            voxels,
            to_world,
            lin,
            offset,
            inv_lin,
            inv_offset: -(inv_lin * offset),
            normal_to_world: Mat3::from_mat4(to_world).inverse().transpose(),
            normals,
        })
    }

    /// The grid placed by `m` after its own transform (instances); the samples are shared.
    pub fn transformed(&self, m: &Mat4) -> Result<SdfGrid, String> {
        Self::place(self.res, self.values.clone(), self.voxels.clone(), *m * self.to_world, self.normals)
    }

    pub fn to_world(&self) -> Mat4 {
        self.to_world
    }

    /// Number of primitives (occupied voxels).
    pub fn voxel_count(&self) -> usize {
        self.voxels.len()
    }

    /// The grid's samples, x fastest.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// World bounds of the whole unit cube.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for i in 0..8 {
            let c = Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, (i >> 2) as f32);
            b = b.grow(self.to_world.transform_point3(c));
        }
        b
    }

    fn voxel_pos(&self, base: usize) -> [usize; 3] {
        let [nx, ny, _] = self.res;
        [base % nx, (base / nx) % ny, base / (nx * ny)]
    }

    fn scale(&self) -> DVec3 {
        DVec3::new((self.res[0] - 1) as f64, (self.res[1] - 1) as f64, (self.res[2] - 1) as f64)
    }

    /// World box around the surface inside voxel `k`: the box (in voxel coordinates) of the
    /// corners on the surface and of the points where the interpolant crosses zero along an
    /// edge, transformed corner by corner (any affine `to_world`) and padded for rounding.
    pub fn voxel_bounds(&self, k: usize) -> Aabb {
        let base = self.voxels[k] as usize;
        let f = corners(&self.values, self.res, base);
        let corner = |i: usize| DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, (i >> 2) as f64);
        let (mut lo, mut hi) = (DVec3::splat(1.0), DVec3::ZERO);
        for (i, &fi) in f.iter().enumerate() {
            if fi == 0.0 {
                lo = lo.min(corner(i));
                hi = hi.max(corner(i));
            }
            for axis in 0..3 {
                if i & (1 << axis) != 0 {
                    continue;
                }
                let fj = f[i | (1 << axis)];
                if fi * fj <= 0.0 && fi != fj {
                    let mut p = corner(i);
                    p[axis] = (fi / (fi - fj)) as f64;
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
            }
        }
        // (Never empty for an occupied voxel, whose corners change sign along some edge or
        // touch zero; the whole voxel is the safe answer all the same.)
        if lo.cmpgt(hi).any() {
            lo = DVec3::ZERO;
            hi = DVec3::ONE;
        }
        let [x, y, z] = self.voxel_pos(base);
        let origin = DVec3::new(x as f64, y as f64, z as f64);
        let scale = self.scale();
        let mut b = Aabb::EMPTY;
        for i in 0..8 {
            let c = DVec3::new(if i & 1 == 0 { lo.x } else { hi.x }, if i & 2 == 0 { lo.y } else { hi.y }, if i & 4 == 0 { lo.z } else { hi.z });
            let w = self.lin * ((c + origin) / scale) + self.offset;
            b = b.grow(w.as_vec3());
        }
        let voxel = (self.lin * (DVec3::ONE / scale)).abs();
        let pad = voxel.as_vec3() * 1e-3 + b.min.abs().max(b.max.abs()) * (8.0 * f32::EPSILON);
        Aabb { min: b.min - pad, max: b.max + pad }
    }

    /// The first hit of `o + t d` with the surface inside voxel `k`, in `(0, t_max)`.
    pub fn intersect_voxel(&self, k: usize, o: Vec3, d: Vec3, t_max: f32) -> Option<f32> {
        let base = self.voxels[k] as usize;
        let [x, y, z] = self.voxel_pos(base);
        let scale = self.scale();
        // The ray in the voxel's coordinates, where the voxel is [0, 1]³; t is unchanged.
        let ov = (self.inv_lin * o.as_dvec3() + self.inv_offset) * scale - DVec3::new(x as f64, y as f64, z as f64);
        let dv = (self.inv_lin * d.as_dvec3()) * scale;
        // The whole span inside the voxel, whatever t_max: the root found must not depend on it
        // (the accelerator and a brute-force test then agree bit for bit).
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        // Which face the ray enters and leaves by (axis, coordinate 0 or 1).
        let (mut enter, mut exit) = (None, None);
        for a in 0..3 {
            if dv[a] == 0.0 {
                if !(0.0..=1.0).contains(&ov[a]) {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / dv[a];
            let (near_face, far_face) = if inv > 0.0 { (0.0, 1.0) } else { (1.0, 0.0) };
            let tn = (near_face - ov[a]) * inv;
            let tf = (far_face - ov[a]) * inv;
            if tn > t0 {
                t0 = tn;
                enter = Some((a, near_face));
            }
            if tf < t1 {
                t1 = tf;
                exit = Some((a, far_face));
            }
        }
        if t0.is_nan() || t1.is_nan() || t1 <= t0 || t0 >= t_max as f64 {
            return None;
        }
        let f = corners(&self.values, self.res, base).map(|v| v as f64);
        // The interpolant where the ray enters and leaves, with the crossed face's coordinate
        // snapped to 0 or 1: two voxels sharing the face then see the same value there, so
        // a surface grazing the face is not lost between them.
        let at = |t: f64, face: Option<(usize, f64)>| {
            let mut p = (ov + dv * t).clamp(DVec3::ZERO, DVec3::ONE);
            if let Some((a, c)) = face {
                p[a] = c;
            }
            trilerp(&f, p)
        };
        let (f0, f1) = (at(t0, enter), at(t1, exit));
        let cubic = Cubic::along(&f, ov + dv * t0, dv);
        let t = cubic.first_root(t1 - t0, f0, f1)? + t0;
        let t = t as f32;
        (t > 0.0 && t < t_max).then_some(t)
    }

    /// (geometric normal, shading normal) at world point `p` of voxel `k`.
    pub fn normals_at(&self, k: usize, p: Vec3) -> (Vec3, Vec3) {
        let base = self.voxels[k] as usize;
        let [x, y, z] = self.voxel_pos(base);
        let scale = self.scale();
        let local = self.inv_lin * p.as_dvec3() + self.inv_offset;
        let w = (local * scale - DVec3::new(x as f64, y as f64, z as f64)).clamp(DVec3::ZERO, DVec3::ONE);
        let f = corners(&self.values, self.res, base).map(|v| v as f64);
        let grad = trilerp_grad(&f, w) * scale;
        let ng = self.world_normal(grad);
        let ns = match self.normals {
            SdfNormals::Analytic => ng,
            SdfNormals::Smooth => {
                let n = self.world_normal(self.smooth_gradient(local));
                if n == Vec3::ZERO {
                    ng
                } else {
                    n
                }
            }
        };
        (ng, ns)
    }

    fn world_normal(&self, grad: DVec3) -> Vec3 {
        (self.normal_to_world * grad.as_vec3()).normalize_or_zero()
    }

    /// The grid sample at integer coordinates, clamped to the grid.
    fn sample(&self, q: [i64; 3]) -> f64 {
        let [nx, ny, nz] = self.res;
        let c = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
        self.values[(c(q[2], nz) * ny + c(q[1], ny)) * nx + c(q[0], nx)] as f64
    }

    /// The blend of the unit gradients of the eight voxels around the grid point nearest to
    /// `local` (object space), weighted by the position relative to their centres. A voxel's
    /// gradient along an axis is the difference of the grid's interpolant across the voxel
    /// at `local`'s position along the other two axes (zero past the grid's end, where the
    /// samples are clamped); voxels below the grid's start get no weight.
    fn smooth_gradient(&self, local: DVec3) -> DVec3 {
        let scale = self.scale();
        let sp = local * scale;
        let n = [self.res[0] as i64, self.res[1] as i64, self.res[2] as i64];
        let v: [i64; 3] = std::array::from_fn(|a| sp[a].round() as i64 - 1);
        // The cell holding the point, for the bilinear interpolation across the other axes.
        let cell: [i64; 3] = std::array::from_fn(|a| (sp[a].floor() as i64).clamp(0, n[a] - 2));
        let w: [f64; 3] = std::array::from_fn(|a| sp[a] - cell[a] as f64);
        // The interpolant on the sample plane `q` of axis `a`, at the point's other coordinates.
        let plane = |a: usize, q: i64| {
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let mut g = [0.0; 4];
            for (i, gi) in g.iter_mut().enumerate() {
                let mut idx = [0i64; 3];
                idx[a] = q;
                idx[b] = cell[b] + (i & 1) as i64;
                idx[c] = cell[c] + (i >> 1) as i64;
                *gi = self.sample(idx);
            }
            lerp(lerp(g[0], g[1], w[b]), lerp(g[2], g[3], w[b]), w[c])
        };
        // Per axis, the differences across the lower (index v) and upper (v + 1) voxels.
        let mut d = [[0.0; 3]; 2];
        for a in 0..3 {
            for (h, dh) in d.iter_mut().enumerate() {
                let q = v[a] + h as i64;
                dh[a] = (plane(a, q + 1) - plane(a, q)) * scale[a];
            }
        }
        let mut uvw: [f64; 3] = std::array::from_fn(|a| sp[a] - v[a] as f64 - 0.5);
        for a in 0..3 {
            if v[a] < 0 {
                uvw[a] = 1.0;
            }
        }
        let mut sum = DVec3::ZERO;
        for i in 0..8 {
            let hi = [i & 1 != 0, i & 2 != 0, i & 4 != 0];
            if (0..3).any(|a| !hi[a] && v[a] < 0) {
                continue;
            }
            let g = DVec3::new(d[hi[0] as usize][0], d[hi[1] as usize][1], d[hi[2] as usize][2]);
            let len = g.length();
            if len == 0.0 {
                continue;
            }
            let weight: f64 = (0..3).map(|a| if hi[a] { uvw[a] } else { 1.0 - uvw[a] }).product();
            sum += g * (weight / len);
        }
        sum
    }
}

/// The eight corner samples of the voxel with lower corner `base`, indexed x + 2y + 4z.
fn corners(values: &[f32], res: [usize; 3], base: usize) -> [f32; 8] {
    let [nx, ny, _] = res;
    std::array::from_fn(|i| values[base + (i & 1) + nx * (((i >> 1) & 1) + ny * (i >> 2))])
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    // Exact at t = 0 and t = 1 (the face-consistent values rely on it).
    (1.0 - t) * a + t * b
}

fn trilerp(f: &[f64; 8], p: DVec3) -> f64 {
    let bl = |o: usize| lerp(lerp(f[o], f[o + 1], p.x), lerp(f[o + 2], f[o + 3], p.x), p.y);
    lerp(bl(0), bl(4), p.z)
}

/// Gradient of the trilinear interpolant in voxel coordinates.
fn trilerp_grad(f: &[f64; 8], p: DVec3) -> DVec3 {
    let bl = |g: [f64; 4], u: f64, v: f64| lerp(lerp(g[0], g[1], u), lerp(g[2], g[3], u), v);
    DVec3::new(
        bl([f[1] - f[0], f[3] - f[2], f[5] - f[4], f[7] - f[6]], p.y, p.z),
        bl([f[2] - f[0], f[3] - f[1], f[6] - f[4], f[7] - f[5]], p.x, p.z),
        bl([f[4] - f[0], f[5] - f[1], f[6] - f[2], f[7] - f[3]], p.x, p.y),
    )
}

/// The trilinear interpolant along a ray: c0 + c1 t + c2 t² + c3 t³.
#[derive(Clone, Copy, Debug)]
struct Cubic([f64; 4]);

impl Cubic {
    /// The interpolant of corner values `f` along `o + t d` (voxel coordinates).
    fn along(f: &[f64; 8], o: DVec3, d: DVec3) -> Cubic {
        // f = a + b x + c y + e z + g xy + h xz + k yz + m xyz, each coordinate linear in t.
        let a = f[0];
        let b = f[1] - f[0];
        let c = f[2] - f[0];
        let e = f[4] - f[0];
        let g = f[3] - f[1] - f[2] + f[0];
        let h = f[5] - f[1] - f[4] + f[0];
        let k = f[6] - f[2] - f[4] + f[0];
        let m = f[7] - f[3] - f[5] - f[6] + f[1] + f[2] + f[4] - f[0];
        let lin = |u: usize| [o[u], d[u]];
        let mul2 = |p: [f64; 2], q: [f64; 2]| [p[0] * q[0], p[0] * q[1] + p[1] * q[0], p[1] * q[1]];
        let (x, y, z) = (lin(0), lin(1), lin(2));
        let (xy, xz, yz) = (mul2(x, y), mul2(x, z), mul2(y, z));
        let xyz = [xy[0] * z[0], xy[0] * z[1] + xy[1] * z[0], xy[1] * z[1] + xy[2] * z[0], xy[2] * z[1]];
        let mut c3 = [a, 0.0, 0.0, 0.0];
        for (coef, p) in [(b, &x[..]), (c, &y[..]), (e, &z[..]), (g, &xy[..]), (h, &xz[..]), (k, &yz[..]), (m, &xyz[..])] {
            for (ci, pi) in c3.iter_mut().zip(p) {
                *ci += coef * pi;
            }
        }
        Cubic(c3)
    }

    fn eval(&self, t: f64) -> f64 {
        let [c0, c1, c2, c3] = self.0;
        ((c3 * t + c2) * t + c1) * t + c0
    }

    fn deriv(&self, t: f64) -> f64 {
        let [_, c1, c2, c3] = self.0;
        (3.0 * c3 * t + 2.0 * c2) * t + c1
    }

    /// The first root in [0, t_end], given the values at the ends (which may differ from
    /// the polynomial's by rounding: they decide the bracket).
    fn first_root(&self, t_end: f64, f_beg: f64, f_end: f64) -> Option<f64> {
        let (mut lo, mut hi, mut f_lo, mut f_hi) = (0.0, t_end, f_beg, f_end);
        // Split at the turning points (roots of the derivative), in increasing order, keeping
        // the first piece that brackets a sign change.
        let [_, c1, c2, c3] = self.0;
        for r in quadratic_roots(3.0 * c3, 2.0 * c2, c1).into_iter().flatten() {
            if !(lo <= r && r <= hi) {
                continue;
            }
            let fr = self.eval(r);
            if f_lo * fr <= 0.0 {
                hi = r;
                f_hi = fr;
            } else {
                lo = r;
                f_lo = fr;
            }
        }
        if f_lo * f_hi > 0.0 {
            return None;
        }
        if f_lo == 0.0 {
            return Some(lo);
        }
        // Start at the secant estimate; Newton steps that leave the bracket bisect instead.
        let mut t = lo + (hi - lo) * (f_lo / (f_lo - f_hi));
        if !(t >= lo && t <= hi) {
            t = 0.5 * (lo + hi);
        }
        let tol = 1e-9 * t_end.max(1e-30);
        for _ in 0..64 {
            let ft = self.eval(t);
            if ft == 0.0 {
                return Some(t);
            }
            if ft * f_lo <= 0.0 {
                hi = t;
            } else {
                lo = t;
            }
            let next = t - ft / self.deriv(t);
            let next = if next > lo && next < hi { next } else { 0.5 * (lo + hi) };
            let done = (next - t).abs() <= tol;
            t = next;
            if done || hi - lo <= tol {
                break;
            }
        }
        Some(t)
    }
}

/// Real roots of a t² + b t + c, ascending (None where there are fewer).
fn quadratic_roots(a: f64, b: f64, c: f64) -> [Option<f64>; 2] {
    if a == 0.0 {
        return [(b != 0.0).then(|| -c / b), None];
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return [None, None];
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    [Some(r0.min(r1)), Some(r0.max(r1))]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere of radius `r` about the cube's centre, sampled on an n³ grid.
    fn sphere_grid(n: usize, r: f32) -> Vec<f32> {
        let mut v = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let p = Vec3::new(x as f32, y as f32, z as f32) / (n - 1) as f32 - Vec3::splat(0.5);
                    v.push(p.length() - r);
                }
            }
        }
        v
    }

    /// First hit over all voxels (brute force).
    fn trace(g: &SdfGrid, o: Vec3, d: Vec3) -> Option<(f32, usize)> {
        let mut best: Option<(f32, usize)> = None;
        for k in 0..g.voxel_count() {
            let t_max = best.map_or(f32::INFINITY, |b| b.0);
            if let Some(t) = g.intersect_voxel(k, o, d, t_max) {
                best = Some((t, k));
            }
        }
        best
    }

    #[test]
    fn quadratic_roots_are_sorted() {
        assert_eq!(quadratic_roots(1.0, -3.0, 2.0), [Some(1.0), Some(2.0)]);
        assert_eq!(quadratic_roots(1.0, 0.0, 1.0), [None, None]);
        assert_eq!(quadratic_roots(0.0, 2.0, -1.0), [Some(0.5), None]);
    }

    #[test]
    fn cubic_matches_trilinear_along_a_ray() {
        let f = [0.3, -0.2, 0.5, 0.1, -0.7, 0.4, 0.2, -0.1];
        let (o, d) = (DVec3::new(0.1, 0.2, 0.05), DVec3::new(0.3, 0.25, 0.4));
        let c = Cubic::along(&f, o, d);
        for i in 0..=10 {
            let t = i as f64 * 0.2;
            assert!((c.eval(t) - trilerp(&f, o + d * t)).abs() < 1e-12);
        }
    }

    /// Rays at a sampled sphere hit within a fraction of a voxel of the true sphere, with
    /// normals within a few degrees of the radial direction; rays that miss the sphere's
    /// silhouette by more than a voxel miss the grid.
    #[test]
    fn hits_a_sphere_grid_within_voxel_tolerance() {
        let n = 33;
        let r = 0.3;
        let voxel = 1.0 / (n - 1) as f32;
        // Placed by a rotation, a non-uniform scale and a shift: checked in object space.
        let to_world = Mat4::from_translation(Vec3::new(1.0, -2.0, 0.5)) * Mat4::from_rotation_y(0.7) * Mat4::from_scale(Vec3::new(2.0, 2.0, 2.0));
        for normals in [SdfNormals::Analytic, SdfNormals::Smooth] {
            let g = SdfGrid::new([n, n, n], sphere_grid(n, r), to_world, normals).unwrap();
            let to_obj = to_world.inverse();
            let centre = to_world.transform_point3(Vec3::splat(0.5));
            let mut rng = crate::sampling::Pcg32::new(7, 0);
            let (mut hits, mut worst_dist, mut worst_angle) = (0, 0.0f32, 0.0f32);
            for _ in 0..400 {
                // Aim at a random point of a disk around the centre, from a random direction.
                let dir = crate::math::warp::square_to_uniform_sphere(glam::Vec2::new(rng.next_f32(), rng.next_f32()));
                let frame = crate::math::Frame::from_normal(dir);
                let (a, b) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
                let aim = centre + (frame.s * a + frame.t * b) * 0.8;
                let o = aim - dir * 5.0;
                let off_axis = (frame.s * a + frame.t * b).length() * 0.8 / 2.0; // object units
                match trace(&g, o, dir) {
                    Some((t, k)) => {
                        hits += 1;
                        let p = o + dir * t;
                        let local = to_obj.transform_point3(p) - Vec3::splat(0.5);
                        worst_dist = worst_dist.max((local.length() - r).abs());
                        let (ng, ns) = g.normals_at(k, p);
                        let want = (g.normal_to_world * local).normalize();
                        worst_angle = worst_angle.max(ng.dot(want).clamp(-1.0, 1.0).acos()).max(ns.dot(want).clamp(-1.0, 1.0).acos());
                        assert!(off_axis < r + voxel, "hit at {off_axis} beyond the sphere");
                    }
                    None => assert!(off_axis > r - voxel, "missed at {off_axis} inside the sphere's silhouette"),
                }
            }
            assert!(hits > 100, "{hits} hits");
            // Trilinear interpolation errs by at most h²/8 (|f_xx| + |f_yy| + |f_zz|) in value, h the
            // voxel size; for |p| - r that sum is 2/|p|, with |p| > r - h over the voxels the
            // surface crosses. The gradient's direction errs by about h/r.
            assert!(worst_dist < voxel * voxel / (4.0 * (r - voxel)), "{normals:?}: distance error {worst_dist}");
            assert!(worst_angle < voxel / r, "{normals:?}: normal off by {} deg", worst_angle.to_degrees());
            eprintln!("{normals:?}: {hits} hits, distance error {worst_dist:.2e}, normal error {:.2} deg", worst_angle.to_degrees());
        }
    }

    /// Smooth normals are continuous across voxel faces; analytic ones jump.
    #[test]
    fn smooth_normals_are_continuous_across_voxels() {
        let n = 9;
        let g = SdfGrid::new([n, n, n], sphere_grid(n, 0.3), Mat4::IDENTITY, SdfNormals::Smooth).unwrap();
        // A ray along y at x, z near a voxel face (x = 5/8) hits two neighbouring voxels.
        let eps = 1e-4;
        let x = 5.0 / 8.0;
        let a = trace(&g, Vec3::new(x - eps, -1.0, 0.55), Vec3::Y).unwrap();
        let b = trace(&g, Vec3::new(x + eps, -1.0, 0.55), Vec3::Y).unwrap();
        assert_ne!(a.1, b.1, "the two rays should hit different voxels");
        let pa = Vec3::new(x - eps, -1.0, 0.55) + Vec3::Y * a.0;
        let pb = Vec3::new(x + eps, -1.0, 0.55) + Vec3::Y * b.0;
        let (nga, nsa) = g.normals_at(a.1, pa);
        let (ngb, nsb) = g.normals_at(b.1, pb);
        assert!(nsa.dot(nsb) > 0.99999, "smooth normals jump: {nsa} vs {nsb}");
        assert!(nga.dot(ngb) < nsa.dot(nsb), "analytic normals should jump more than smooth ones");
    }

    #[test]
    fn voxel_boxes_hold_their_hits() {
        let n = 17;
        let g = SdfGrid::new([n, n, n], sphere_grid(n, 0.35), Mat4::from_scale(Vec3::splat(3.0)), SdfNormals::Smooth).unwrap();
        let mut rng = crate::sampling::Pcg32::new(3, 1);
        for _ in 0..300 {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), -1.0) * Vec3::new(3.0, 3.0, 1.0);
            let d = (Vec3::new(1.5, 1.5, 1.5) + Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 0.0) * 2.0 - o).normalize();
            if let Some((t, k)) = trace(&g, o, d) {
                let b = g.voxel_bounds(k);
                let p = o + d * t;
                assert!(p.cmpge(b.min).all() && p.cmple(b.max).all(), "hit {p} outside its voxel box {b:?}");
            }
        }
    }

    #[test]
    fn bad_grids_are_refused() {
        assert!(SdfGrid::new([1, 2, 2], vec![0.0; 4], Mat4::IDENTITY, SdfNormals::Smooth).unwrap_err().contains("at least 2"));
        assert!(SdfGrid::new([2, 2, 2], vec![0.0; 7], Mat4::IDENTITY, SdfNormals::Smooth).is_err());
        assert!(SdfGrid::new([2, 2, 2], vec![1.0; 8], Mat4::IDENTITY, SdfNormals::Smooth).unwrap_err().contains("no voxel"));
        let mut v = vec![1.0; 8];
        v[3] = f32::NAN;
        assert!(SdfGrid::new([2, 2, 2], v, Mat4::IDENTITY, SdfNormals::Smooth).unwrap_err().contains("not finite"));
        assert!(SdfGrid::new([2, 2, 2], vec![-1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0], Mat4::ZERO, SdfNormals::Smooth).is_err());
    }
}
