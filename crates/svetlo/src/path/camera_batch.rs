//! A light subpath's camera connections (strategies (s, 1)) eight at a time: what
//! [`camera_connection`](super::camera_connection) gives for each vertex, bit for bit, with
//! the connections of Lambertian surface vertices to a pinhole computed in the lanes of
//! AVX registers (light tracing makes one per vertex; the scalar arithmetic of the lens
//! sample, the BSDF value and the shadow ray was most of its cost).
//!
//! Each lane does the scalar code's operations in its order (IEEE multiplications,
//! divisions, square roots and comparisons give the same bits in a lane as alone); what a
//! vertex alone decides (which side of its BSDF is seen, its constants) is done per vertex
//! before. Other vertices (the light's own, other BSDFs, a thin lens) take the scalar path.
//! Lanes may hold several paths' vertices (`stage_lazy` one at a time, `run` when full): the
//! light tracer fills all eight so.

use super::connect::{camera_connectible, camera_connection_at, camera_strategy_exists};
use super::{PathConfig, Vertex, VertexKind};
use crate::accel::packet::Rays8;
use crate::bsdf::BsdfModel;
use crate::camera::Pinhole;
use crate::geometry::ray::SHADOW_EPSILON;
use crate::geometry::Ray;
use crate::math::INV_PI;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

const LANES: usize = 8;

/// The camera's constants for batched connections: Some for a pinhole on a CPU with AVX2.
#[derive(Clone, Copy, Debug)]
pub struct CameraBatch {
    pinhole: Pinhole,
}

impl CameraBatch {
    pub fn new(cfg: &PathConfig) -> Option<CameraBatch> {
        if !cfg.camera_connectible || !crate::cpu::avx2() {
            return None;
        }
        cfg.lens.as_ref()?.pinhole().map(|pinhole| CameraBatch { pinhole })
    }

    /// `camera_connection(scene, cfg, light, s, sampler)` for s = 1..=light.len(), in
    /// order, each that exists given to `emit` as (contribution, raster, shadow ray): one
    /// path's [`Self::stage_lazy`] (the owed draws paid after each strategy, or, `lazy`, at
    /// the end) and [`Self::run`]. `scratch` holds the lanes (none staged); one per caller
    /// serves all its paths.
    #[allow(clippy::too_many_arguments)]
    pub fn connections<S: Sampler + ?Sized>(
        &self,
        scene: &Scene,
        cfg: &PathConfig,
        light: &[Vertex],
        sampler: &mut S,
        scratch: &mut BatchScratch,
        lazy: bool,
        mut emit: impl FnMut(Rgb, Vec2, Option<Ray>),
    ) {
        // The strategies staged since the last run, in order.
        let mut staged: [Staged; LANES] = [Staged::None; LANES];
        let mut k = 0;
        let mut owed = 0;
        for s in 1..=light.len() {
            staged[k] = self.stage_lazy(scene, cfg, light, s, sampler, &mut owed, scratch);
            if !lazy {
                pay_lens_draws(sampler, &mut owed);
            }
            k += 1;
            if k == LANES || s == light.len() || scratch.is_full() {
                if scratch.lanes.n > 0 {
                    self.run(scratch);
                }
                for st in &staged[..k] {
                    match *st {
                        Staged::None | Staged::Scalar(None) => {}
                        Staged::Scalar(Some((l, raster, ray))) => emit(l, raster, ray),
                        Staged::Lane(i) => {
                            if scratch.valid(i) {
                                emit(scratch.l(i), scratch.raster(i), scratch.ray(i));
                            }
                        }
                    }
                }
                scratch.clear();
                k = 0;
            }
        }
        pay_lens_draws(sampler, &mut owed);
    }

    /// Strategy (s, 1) of `light` as `camera_connection` begins it (its checks; its lens
    /// sample counted in `owed`, for `pay_lens_draws` to draw): none, computed here, or put
    /// in the next lane of `scratch` for [`Self::run`] (which the caller runs before staging
    /// into a full one). Lanes may hold the strategies of several paths: each lane is alone.
    /// A caller that draws nothing more from `sampler` after the path's connections (the
    /// light tracer's lanes: a lane's next sample restarts its sampler) leaves the lens
    /// samples that the lanes do not read (a pinhole's) owed, drawn only where a scalar
    /// connection needs the draw after them; any other pays them after each strategy.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn stage_lazy<S: Sampler + ?Sized>(
        &self,
        scene: &Scene,
        cfg: &PathConfig,
        light: &[Vertex],
        s: usize,
        sampler: &mut S,
        owed: &mut u32,
        scratch: &mut BatchScratch,
    ) -> Staged {
        debug_assert!(!scratch.is_full());
        if !camera_strategy_exists(cfg, light, s) {
            return Staged::None;
        }
        *owed += 1;
        let qs = &light[s - 1];
        if !camera_connectible(scene, cfg, qs, s) {
            return Staged::None;
        }
        match scratch.lanes.push(scene, qs, s) {
            Some(lane) => Staged::Lane(lane),
            None => {
                *owed -= 1;
                pay_lens_draws(sampler, owed);
                let u = sampler.next_2d();
                Staged::Scalar(camera_connection_at(scene, cfg, qs, s, u).map(|c| (c.l, c.raster, c.shadow)))
            }
        }
    }

    /// The connections of the staged lanes (read with `BatchScratch::valid` and the rest
    /// until [`BatchScratch::clear`]).
    pub fn run(&self, scratch: &mut BatchScratch) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `new` made a batch only where the CPU has AVX2 (which includes AVX).
        unsafe {
            kernel(&self.pinhole, &scratch.lanes, &mut scratch.out)
        };
    }
}

/// The lens samples owed by [`CameraBatch::stage_lazy`], drawn and dropped.
#[inline]
fn pay_lens_draws<S: Sampler + ?Sized>(sampler: &mut S, owed: &mut u32) {
    for _ in 0..*owed {
        sampler.next_2d();
    }
    *owed = 0;
}

/// Where [`CameraBatch::stage_lazy`] put a strategy.
#[derive(Clone, Copy, Debug)]
pub enum Staged {
    /// No connection (the strategy does not exist, or its vertex cannot see the camera).
    None,
    /// Computed alone: None, or (contribution, raster, shadow ray).
    Scalar(Option<(Rgb, Vec2, Option<Ray>)>),
    /// In this lane of the scratch.
    Lane(usize),
}

/// The lane buffers of [`CameraBatch::stage_lazy`] and [`CameraBatch::run`], kept by the caller
/// from path to path: clearing a fresh pair per path cost about 1 % of light tracing. Lanes
/// at and above `Lanes::n` keep an earlier batch's numbers, which the kernel computes and
/// masks off.
#[derive(Default)]
pub struct BatchScratch {
    lanes: Lanes,
    out: Out,
}

impl BatchScratch {
    /// Whether every lane is staged (run them before staging more).
    #[inline]
    pub fn is_full(&self) -> bool {
        self.lanes.n == LANES
    }
    /// How many lanes are staged.
    #[inline]
    pub fn staged(&self) -> usize {
        self.lanes.n
    }
    /// Empties the lanes (after their results are read).
    #[inline]
    pub fn clear(&mut self) {
        self.lanes.n = 0;
    }
    /// The lanes whose connection exists and whose contribution is finite (after `run`): those
    /// a splat keeps (`SampleOut::splat`'s test; a lane's contribution is never black).
    #[inline]
    pub fn splatted(&self) -> u8 {
        self.out.valid & self.out.finite
    }
    /// Whether lane `i`'s connection exists (after `run`).
    #[inline]
    pub fn valid(&self, i: usize) -> bool {
        self.out.valid & (1 << i) != 0
    }
    #[inline]
    pub fn l(&self, i: usize) -> Rgb {
        Rgb::new(self.out.l[0][i], self.out.l[1][i], self.out.l[2][i])
    }
    #[inline]
    pub fn raster(&self, i: usize) -> Vec2 {
        Vec2::new(self.out.raster[0][i], self.out.raster[1][i])
    }
    /// Lane `i`'s shadow ray, None where the segment has no length.
    pub fn ray(&self, i: usize) -> Option<Ray> {
        if self.out.has_ray & (1 << i) == 0 {
            return None;
        }
        let r = &self.out.rays;
        let v = |a: &[[f32; LANES]; 3]| Vec3::new(a[0][i], a[1][i], a[2][i]);
        let mut ray = Ray::with_max(v(&r.o), v(&r.d), r.t_max[i]);
        ray.time = self.lanes.time[i];
        Some(ray)
    }
    /// The lanes' shadow rays as a packet, and the mask of the lanes whose connection exists
    /// and has a ray that can be blocked, t_max > 0 or NaN, as `ShadowedSplats` tests them
    /// (the packet's other lanes hold anything).
    #[inline]
    pub fn shadow_rays(&self) -> (&Rays8, u8) {
        (&self.out.rays, self.out.tested)
    }
}

/// The vertices of one batch, one lane each (structure of arrays).
#[derive(Default)]
struct Lanes {
    n: usize,
    p: [[f32; LANES]; 3],
    ng: [[f32; LANES]; 3],
    ns: [[f32; LANES]; 3],
    /// `wo · ns`, `|wo · ng|` (`shading_correction`'s factors of wo).
    zo: [f32; LANES],
    wo_ng: [f32; LANES],
    /// The local z of wo on the side that is seen (`Bsdf::side`: wo's own, or mirrored).
    side_zo: [f32; LANES],
    /// Whether wi's local z is mirrored too (the back side): -0 or 0.
    flip: [f32; LANES],
    /// A light's endpoint (all bits set) rather than a Lambertian surface (0).
    emitter: [f32; LANES],
    /// The BSDF's value where both directions are above the side seen, and where not.
    f_lit: [[f32; LANES]; 3],
    f_dark: [[f32; LANES]; 3],
    beta: [[f32; LANES]; 3],
    time: [f32; LANES],
}

impl Lanes {
    /// `qs` (the subpath's `s`-th vertex) in the next lane if the lanes' arithmetic is its
    /// connection's: a finite vertex on a surface that is an area light's endpoint (s = 1,
    /// `le_dir`) or whose BSDF is Lambertian (`lambertian_eval`); None otherwise.
    fn push(&mut self, scene: &Scene, qs: &Vertex, s: usize) -> Option<usize> {
        if qs.infinite || !qs.on_surface() {
            return None;
        }
        let n = qs.shading.n;
        let dark = Rgb::BLACK;
        let (zo, side_zo, flip, lit, dark, emitter) = if s == 1 {
            // `le_dir` of a light's endpoint on an area light: its radiance toward the side its
            // normal faces (the BSDF's entries are not read).
            if qs.kind == VertexKind::Surface || !qs.is_area_light(scene) {
                return None;
            }
            (0.0, 0.0, false, qs.le, dark, true)
        } else {
            let (zo, side_zo, flip, lit, dark) = Self::lambertian(qs)?;
            (zo, side_zo, flip, lit, dark, false)
        };
        let i = self.n;
        for k in 0..3 {
            self.p[k][i] = qs.p[k];
            self.ng[k][i] = qs.ng[k];
            self.ns[k][i] = n[k];
            self.beta[k][i] = qs.beta[k];
        }
        for (k, (l, d)) in [(lit.r, dark.r), (lit.g, dark.g), (lit.b, dark.b)].into_iter().enumerate() {
            self.f_lit[k][i] = l;
            self.f_dark[k][i] = d;
        }
        self.zo[i] = zo;
        self.wo_ng[i] = if emitter { 0.0 } else { qs.wo.dot(qs.ng).abs() };
        self.side_zo[i] = side_zo;
        self.flip[i] = if flip { -0.0 } else { 0.0 };
        self.emitter[i] = if emitter { f32::from_bits(u32::MAX) } else { 0.0 };
        self.time[i] = qs.time;
        self.n += 1;
        Some(i)
    }

    /// A Lambertian vertex's `zo` (wo · ns), the side's z of wo, whether wi is mirrored, and
    /// `lambertian_eval`'s values where both are above the side and where not.
    fn lambertian(qs: &Vertex) -> Option<(f32, f32, bool, Rgb, Rgb)> {
        let bsdf = qs.bsdf.as_ref()?;
        if bsdf.detail.is_some() {
            return None;
        }
        let BsdfModel::Diffuse(front) = &bsdf.front else { return None };
        let zo = qs.wo.dot(qs.shading.n);
        let dark = Rgb::BLACK;
        let (side_zo, flip, lit, dark) = if zo >= 0.0 {
            (zo, false, front.reflectance * INV_PI * bsdf.opacity, dark * bsdf.opacity)
        } else {
            match &bsdf.back {
                // Black whatever wi is, not scaled by the opacity.
                None => (-1.0, false, dark, dark),
                Some(BsdfModel::Diffuse(back)) => (-zo, true, back.reflectance * INV_PI * bsdf.opacity, dark * bsdf.opacity),
                Some(_) => return None,
            }
        };
        Some((zo, side_zo, flip, lit, dark))
    }
}

/// The lanes' connections: a mask of those that exist, their contribution, raster position
/// and shadow ray (`has_ray`: a segment of some length), the rays laid out as a packet.
#[derive(Default)]
struct Out {
    valid: u8,
    /// The contribution is finite in every channel.
    finite: u8,
    has_ray: u8,
    /// Valid, with a ray of positive (or NaN) length.
    tested: u8,
    l: [[f32; LANES]; 3],
    raster: [[f32; LANES]; 2],
    rays: Rays8,
}

/// `camera_connection_at` for a pinhole in every lane below `lanes.n`: `sample_lens`,
/// `direction_to_point`, `f_dir` through `lambertian_eval` and `shading_correction`, the
/// contribution, `shadow_ray_to_lens`; each line names the scalar code it follows.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn kernel(k: &Pinhole, v: &Lanes, out: &mut Out) {
    use std::arch::x86_64::*;
    let ld = |a: &[f32; LANES]| _mm256_loadu_ps(a.as_ptr());
    let set = |x: f32| _mm256_set1_ps(x);
    let (add, sub, mul, div) = (|a, b| _mm256_add_ps(a, b), |a, b| _mm256_sub_ps(a, b), |a, b| _mm256_mul_ps(a, b), |a, b| _mm256_div_ps(a, b));
    // glam's dot: x·x' + y·y' + z·z', left to right.
    let dot = |a: [__m256; 3], b: [__m256; 3]| add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]));
    let abs = |a| _mm256_andnot_ps(set(-0.0), a);
    let and = |a, b| _mm256_and_ps(a, b);
    let p = [ld(&v.p[0]), ld(&v.p[1]), ld(&v.p[2])];

    // sample_lens: p = to_camera.transform_point3(p_ref) (glam: ((x c0 + y c1) + z c2) + c3).
    let m = k.to_camera;
    let col = |c: glam::Vec4| [set(c.x), set(c.y), set(c.z)];
    let (c0, c1, c2, c3) = (col(m.x_axis), col(m.y_axis), col(m.z_axis), col(m.w_axis));
    let pc: [__m256; 3] = std::array::from_fn(|j| add(c3[j], add(mul(c2[j], p[2]), add(mul(c1[j], p[1]), mul(c0[j], p[0])))));
    // !(p.z < near || p.z > far)
    let mut ok = and(_mm256_cmp_ps::<_CMP_NLT_UQ>(pc[2], set(k.near_clip)), _mm256_cmp_ps::<_CMP_NGT_UQ>(pc[2], set(k.far_clip)));
    // to_ref = p - 0 (the pinhole's lens point), dist2 != 0, d = to_ref / sqrt(dist2).
    let zero = _mm256_setzero_ps();
    let to_ref = [sub(pc[0], zero), sub(pc[1], zero), sub(pc[2], zero)];
    let dist2 = dot(to_ref, to_ref);
    ok = and(ok, _mm256_cmp_ps::<_CMP_NEQ_UQ>(dist2, zero));
    let len = _mm256_sqrt_ps(dist2);
    let d = [div(to_ref[0], len), div(to_ref[1], len), div(to_ref[2], len)];
    // we_local: !(cos_t <= 0); q = d.xy / cos_t; ndc = 0.5 (1 - q / half); raster = ndc size.
    let cos_t = d[2];
    ok = and(ok, _mm256_cmp_ps::<_CMP_NLE_UQ>(cos_t, zero));
    let one = set(1.0);
    let ndc_x = mul(set(0.5), sub(one, div(div(d[0], cos_t), set(k.half.x))));
    let ndc_y = mul(set(0.5), sub(one, div(div(d[1], cos_t), set(k.half.y))));
    let rx = mul(ndc_x, set(k.size.x));
    let ry = mul(ndc_y, set(k.size.y));
    let inside = and(
        and(_mm256_cmp_ps::<_CMP_GE_OQ>(rx, zero), _mm256_cmp_ps::<_CMP_GE_OQ>(ry, zero)),
        and(_mm256_cmp_ps::<_CMP_LT_OQ>(rx, set(k.size.x)), _mm256_cmp_ps::<_CMP_LT_OQ>(ry, set(k.size.y))),
    );
    ok = and(ok, inside);
    let cos2 = mul(cos_t, cos_t);
    let we = div(one, mul(mul(set(k.areas), cos2), cos2));
    let pdf = div(dist2, mul(d[2], set(k.lens_area)));
    // camera_connection: !(pdf <= 0 || we <= 0); beta_cam = we / pdf.
    ok = and(ok, and(_mm256_cmp_ps::<_CMP_NLE_UQ>(pdf, zero), _mm256_cmp_ps::<_CMP_NLE_UQ>(we, zero)));
    let beta_cam = div(we, pdf);
    // direction_to_point(center): dv = center - p, d2, w = dv / sqrt(d2); d2 == 0: w = 0 and
    // f black (below: f = 0 and |ns·w| = 0).
    let center = [set(k.center.x), set(k.center.y), set(k.center.z)];
    let dv = [sub(center[0], p[0]), sub(center[1], p[1]), sub(center[2], p[2])];
    let d2 = dot(dv, dv);
    let coincident = _mm256_cmp_ps::<_CMP_EQ_OQ>(d2, zero);
    let dl = _mm256_sqrt_ps(d2);
    let w = [div(dv[0], dl), div(dv[1], dl), div(dv[2], dl)];
    // f_dir: lambertian_eval's value by the side's z of wi (lit: !(zo <= 0 || zi <= 0)),
    // times shading_correction (num |wo·ns| |wi·ng|, den |wo·ng| |wi·ns|; den == 0: 0).
    let ns = [ld(&v.ns[0]), ld(&v.ns[1]), ld(&v.ns[2])];
    let ng = [ld(&v.ng[0]), ld(&v.ng[1]), ld(&v.ng[2])];
    let zi = dot(w, ns);
    let side_zi = _mm256_xor_ps(zi, ld(&v.flip));
    let lit = and(_mm256_cmp_ps::<_CMP_NLE_UQ>(ld(&v.side_zo), zero), _mm256_cmp_ps::<_CMP_NLE_UQ>(side_zi, zero));
    let num = mul(abs(ld(&v.zo)), abs(dot(w, ng)));
    let den = mul(ld(&v.wo_ng), abs(zi));
    let corr = _mm256_blendv_ps(div(num, den), zero, _mm256_cmp_ps::<_CMP_EQ_OQ>(den, zero));
    // l = beta f beta_cam |ns·w|, per channel left to right; not black.
    let cos = _mm256_blendv_ps(abs(zi), zero, coincident);
    let mut black = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
    let mut l_finite = black;
    // le_dir of a light's endpoint: its radiance where ng·w > 0, else black.
    let emitter = ld(&v.emitter);
    let lit_emitter = _mm256_cmp_ps::<_CMP_GT_OQ>(dot(w, ng), zero);
    for c in 0..3 {
        let f = mul(_mm256_blendv_ps(ld(&v.f_dark[c]), ld(&v.f_lit[c]), lit), corr);
        let f_emitter = _mm256_blendv_ps(ld(&v.f_dark[c]), ld(&v.f_lit[c]), lit_emitter);
        let f = _mm256_blendv_ps(f, f_emitter, emitter);
        let f = _mm256_blendv_ps(f, zero, coincident);
        let l = mul(mul(mul(ld(&v.beta[c]), f), beta_cam), cos);
        black = and(black, _mm256_cmp_ps::<_CMP_EQ_OQ>(l, zero));
        l_finite = and(l_finite, _mm256_cmp_ps::<_CMP_LT_OQ>(abs(l), set(f32::INFINITY)));
        _mm256_storeu_ps(out.l[c].as_mut_ptr(), l);
    }
    ok = _mm256_andnot_ps(black, ok);
    _mm256_storeu_ps(out.raster[0].as_mut_ptr(), rx);
    _mm256_storeu_ps(out.raster[1].as_mut_ptr(), ry);
    // shadow_ray_to_lens(p, ng, center): offset_ray_origin(p, ng, dv): mag = max(max(|x|,
    // |y|), |z|) then f32::max with 1 (vmaxps takes its second operand on NaN, as both do).
    let mag = _mm256_max_ps(_mm256_max_ps(_mm256_max_ps(abs(p[0]), abs(p[1])), abs(p[2])), one);
    let eps = mul(mag, set(2e-6));
    let above = _mm256_cmp_ps::<_CMP_GE_OQ>(dot(dv, ng), zero);
    let o: [__m256; 3] = std::array::from_fn(|j| {
        let off = mul(ng[j], eps);
        _mm256_blendv_ps(sub(p[j], off), add(p[j], off), above)
    });
    // q = center + 0 where (-dv)·0 >= 0, else center - 0.
    let neg = |a| _mm256_xor_ps(a, set(-0.0));
    let finite = _mm256_cmp_ps::<_CMP_GE_OQ>(dot([neg(dv[0]), neg(dv[1]), neg(dv[2])], [zero; 3]), zero);
    let q: [__m256; 3] = std::array::from_fn(|j| _mm256_blendv_ps(sub(center[j], zero), add(center[j], zero), finite));
    let seg = [sub(q[0], o[0]), sub(q[1], o[1]), sub(q[2], o[2])];
    let dist = _mm256_sqrt_ps(dot(seg, seg));
    let has_ray = _mm256_cmp_ps::<_CMP_NEQ_UQ>(dist, zero);
    for j in 0..3 {
        _mm256_storeu_ps(out.rays.o[j].as_mut_ptr(), o[j]);
        _mm256_storeu_ps(out.rays.d[j].as_mut_ptr(), div(seg[j], dist));
    }
    let t_max = mul(dist, set(1.0 - SHADOW_EPSILON));
    _mm256_storeu_ps(out.rays.t_max.as_mut_ptr(), t_max);
    let lanes = (1u32 << v.n) - 1;
    out.valid = (_mm256_movemask_ps(ok) as u32 & lanes) as u8;
    out.has_ray = (_mm256_movemask_ps(has_ray) as u32 & lanes) as u8;
    out.finite = (_mm256_movemask_ps(l_finite) as u32 & lanes) as u8;
    // The rays a packet tests: `ShadowedSplats::push`'s, !(t_max <= 0).
    let tested = _mm256_and_ps(_mm256_and_ps(ok, has_ray), _mm256_cmp_ps::<_CMP_NLE_UQ>(t_max, zero));
    out.tested = (_mm256_movemask_ps(tested) as u32 & lanes) as u8;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::oren_nayar::OrenNayar;
    use crate::bsdf::{diffuse::Diffuse, Bsdf, Material};
    use crate::camera::{Camera, Projection};
    use crate::geometry::{Geometry, Sphere};
    use crate::light::Light;
    use crate::math::warp::square_to_uniform_sphere;
    use crate::math::Frame;
    use crate::path::{camera_connection, VertexKind};
    use crate::sampling::{IndependentSampler, Pcg32};
    use crate::scene::SceneBuilder;
    use crate::texture::Texture;

    fn scene() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.5)) });
        let glow = Some(Texture::Constant(Rgb::splat(2.0)));
        b.add_shape(Geometry::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 40.0), radius: 1.0, flip_normals: false }), m, glow, "ball").unwrap();
        b.set_camera(Camera {
            to_world: crate::io::mitsuba::look_at(Vec3::new(0.5, -0.25, -1.0), Vec3::new(0.0, 0.3, 4.0), Vec3::Y).expect("a frame"),
            projection: Projection::Perspective { fov_x_deg: 60.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: 40,
            height: 30,
            near_clip: 0.01,
            far_clip: 100.0,
            shutter_open: 0.0,
            shutter_close: 0.0,
        });
        b.build().unwrap()
    }

    /// A light subpath of `n` vertices: the light, then random surface vertices (Lambertian
    /// one- and two-sided, masked, rough, specular), some behind the camera or off the film.
    fn subpath(rng: &mut Pcg32, light: u32, n: usize) -> Vec<Vertex> {
        let mut dir = || square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        // The light's endpoint: on the area light (a random point and normal), or without
        // a normal now and then.
        let (a, b) = (dir(), dir());
        let n_light = if n.is_multiple_of(4) { Vec3::ZERO } else { b };
        let mut path =
            vec![Vertex::light_point(light, Vec3::new(4.0 * a.x, 4.0 * a.y, 4.0 + 4.0 * a.z), n_light, Rgb::new(3.0, 2.0, 1.0), Rgb::splat(1.5), 1.0)];
        let diffuse = |r: f32| BsdfModel::Diffuse(Diffuse { reflectance: Rgb::new(r, 0.7 * r, 0.2) });
        let rough = BsdfModel::OrenNayar(OrenNayar { reflectance: Rgb::splat(0.5), sigma: 0.3 });
        for i in 1..n {
            let (a, b, c, e) = (dir(), dir(), dir(), dir());
            let p = Vec3::new(6.0 * a.x, 5.0 * a.y, 3.0 + 6.0 * a.z);
            let ns = b;
            // A geometric normal near the shading one (sometimes the same).
            let ng = if i % 3 == 0 { ns } else { (ns + 0.3 * c).normalize() };
            let bsdf = match i % 5 {
                0 => Bsdf { front: diffuse(0.8), back: None, opacity: 1.0, detail: None },
                1 => Bsdf { front: diffuse(0.6), back: Some(diffuse(0.3)), opacity: 1.0, detail: None },
                2 => Bsdf { front: diffuse(0.9), back: Some(diffuse(0.4)), opacity: 0.7, detail: None },
                3 => Bsdf { front: rough.clone(), back: None, opacity: 1.0, detail: None },
                _ => Bsdf { front: diffuse(0.5), back: Some(rough.clone()), opacity: 1.0, detail: None },
            };
            let lobes = bsdf.flags();
            let beta = Rgb::new(1.0 + e.x, 1.5 + e.y, 0.5 + e.z);
            path.push(Vertex {
                kind: VertexKind::Surface,
                p,
                ng,
                shading: Frame::from_normal(ns),
                wo: c,
                bsdf: Some(bsdf),
                lobes,
                beta,
                time: 0.25,
                ..Vertex::camera(Vec3::ZERO, Vec2::ZERO, Rgb::BLACK)
            });
        }
        path
    }

    /// The batched connections are `camera_connection`'s, bit for bit and in order, for
    /// subpaths shorter and longer than a batch.
    #[test]
    fn batched_connections_are_camera_connections() {
        let scene = scene();
        let cfg = PathConfig::new(&scene, -1, 5, false);
        let Some(batch) = CameraBatch::new(&cfg) else { return };
        let bits = |(l, r, ray): (Rgb, Vec2, Option<Ray>)| {
            let ray = ray.map(|r| (r.o.to_array().map(f32::to_bits), r.d.to_array().map(f32::to_bits), r.t_max.to_bits(), r.time.to_bits()));
            ([l.r, l.g, l.b].map(f32::to_bits), r.to_array().map(f32::to_bits), ray)
        };
        let light = scene.lights.iter().position(|l| matches!(l, Light::Area(_))).expect("an area light") as u32;
        let mut rng = Pcg32::new(3, 9);
        // One scratch for all paths, as the light tracer keeps it: a longer path's lanes
        // stay behind in a shorter one's batch.
        let mut scratch = BatchScratch::default();
        let (mut total, mut lambertian, mut emitted, mut non_finite) = (0, 0, 0, 0);
        for k in 0..3000 {
            let path = subpath(&mut rng, light, 1 + k % 13);
            let mut a = IndependentSampler::new(1, k as u64);
            let mut b = a.clone();
            let want: Vec<_> =
                (1..=path.len()).filter_map(|s| camera_connection(&scene, &cfg, &path, s, &mut a)).map(|c| bits((c.l, c.raster, c.shadow))).collect();
            let mut c = b.clone();
            let mut got = Vec::new();
            batch.connections(&scene, &cfg, &path, &mut b, &mut scratch, false, |l, r, ray| got.push(bits((l, r, ray))));
            assert_eq!(got, want, "path {k}");
            let mut lazy = Vec::new();
            batch.connections(&scene, &cfg, &path, &mut c, &mut scratch, true, |l, r, ray| lazy.push(bits((l, r, ray))));
            assert_eq!(lazy, want, "path {k}: lens draws owed");
            let next = a.next_1d().to_bits();
            assert_eq!(next, b.next_1d().to_bits(), "the same sampler dimensions");
            assert_eq!(next, c.next_1d().to_bits(), "the same sampler dimensions, owed draws paid");
            // `splatted` is `valid` and a finite contribution, lane by lane; every fifth path's
            // light vertices carry a non-finite or huge throughput (a NaN or an infinity).
            let mut odd = path.clone();
            if k % 5 == 0 {
                for (j, v) in odd.iter_mut().enumerate() {
                    v.beta = match j % 3 {
                        0 => Rgb::new(f32::NAN, 1.0, 1.0),
                        1 => Rgb::new(1.0, f32::INFINITY, 1.0),
                        _ => v.beta * 1e38,
                    };
                }
            }
            let mut owed = 0;
            let mut d = b.clone();
            for s in 1..=odd.len() {
                if scratch.is_full() {
                    break;
                }
                batch.stage_lazy(&scene, &cfg, &odd, s, &mut d, &mut owed, &mut scratch);
            }
            if scratch.staged() > 0 {
                batch.run(&mut scratch);
                let want: u8 = (0..scratch.staged()).filter(|&i| scratch.valid(i) && scratch.l(i).is_finite()).fold(0, |m, i| m | 1 << i);
                assert_eq!(scratch.splatted(), want, "path {k}: the splatted lanes");
                non_finite += (0..scratch.staged()).filter(|&i| scratch.valid(i) && !scratch.l(i).is_finite()).count();
                scratch.clear();
            }
            total += want.len();
            emitted += usize::from(camera_connection(&scene, &cfg, &path, 1, &mut IndependentSampler::new(1, k as u64)).is_some());
            lambertian += path.iter().skip(1).filter(|v| matches!(v.bsdf.as_ref().map(|b| &b.front), Some(BsdfModel::Diffuse(_)))).count();
        }
        assert!(total > 1500 && lambertian > 10_000 && emitted > 300 && non_finite > 100, "{total} {lambertian} {emitted} {non_finite}");
    }
}
