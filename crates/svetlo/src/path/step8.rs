//! The scattering half of eight lockstep walks' step ([`Walk::scatter`]) as one eight-lane
//! vector step, for the lanes whose vertex is Lambertian (as `walk::lambertian_sample`
//! takes it): the cosine sample, the shading-normal correction, the next ray and Russian
//! roulette, over plain arrays. The same operations in the same order as the scalar step,
//! branches as selects, so each lane's numbers are its scalar step's bit for bit (a test
//! compares them). Other lanes scatter alone. The vertices' densities (`pdf_fwd`,
//! `pdf_rev`) are left out: the lockstep walks are light tracing's, which weighs no
//! strategy against another and reads none of them.
//!
//! As the path kernel's `shade8` (integrator/path_simd.rs): the arrays are plain (no
//! `Option` field in a struct the loop reads), no `bool` array is read or written under a
//! condition (AVX2 and AVX-512F have no masked byte loads and stores, and LLVM then leaves
//! the loop scalar), and the loop is called through `#[inline(never)]` copies per
//! instruction set (inlined into its caller it stayed scalar code).

use super::walk::Walk;
use super::{Event, Vertex};
use crate::accel::packet::{Rays8, LANES};
use crate::bsdf::{BsdfModel, LobeFlags, TransportMode};
use crate::geometry::Ray;
use crate::math::lane::{cosine_hemisphere, dot3, offset3};
use crate::math::INV_PI;
use crate::spectrum::Rgb;
use glam::{Vec2, Vec3};

/// What [`step8`] reads of a lane's vertex (plain arrays only, see the module's doc).
#[derive(Clone, Default)]
struct VertexNums {
    p: [[f32; LANES]; 3],
    ng: [[f32; LANES]; 3],
    fs: [[f32; LANES]; 3],
    ft: [[f32; LANES]; 3],
    fnn: [[f32; LANES]; 3],
    /// Toward the previous vertex (-d of the ray traced).
    wo: [[f32; LANES]; 3],
    /// The diffuse reflectances of the two sides (the back's read only where `has_back`).
    front: [[f32; LANES]; 3],
    back: [[f32; LANES]; 3],
    has_back: [bool; LANES],
    opacity: [f32; LANES],
    u: [[f32; LANES]; 2],
    u_rr: [f32; LANES],
    /// Russian roulette at this vertex (its segments reach the walk's `rr_depth`).
    rr: [bool; LANES],
    /// The walks' state before the step.
    beta: [[f32; LANES]; 3],
    scatter: [[f32; LANES]; 3],
    eta_scale: [f32; LANES],
}

/// What [`step8`] writes per lane.
#[derive(Clone, Default)]
struct StepOut {
    /// A direction was sampled: the vertex's event is set, and the walk's state below is
    /// its new one.
    sampled: [bool; LANES],
    /// The walk goes on (its next ray in the lane of the step's rays).
    cont: [bool; LANES],
    beta: [[f32; LANES]; 3],
    scatter: [[f32; LANES]; 3],
}

/// The lockstep walks' Lambertian lanes of one step: gathered lane by lane
/// ([`Self::gather`]), stepped together ([`Self::run`]), handed back lane by lane
/// ([`Self::finish`]).
pub(crate) struct WalkLanes {
    v: VertexNums,
    o: StepOut,
    /// Lanes gathered since the last run.
    lanes: u8,
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    avx512: bool,
}

impl Default for WalkLanes {
    fn default() -> Self {
        WalkLanes { v: VertexNums::default(), o: StepOut::default(), lanes: 0, avx512: crate::cpu::avx512() }
    }
}

impl WalkLanes {
    /// Lane `l`'s walk after [`Walk::arrive_unsettled`] (Some(true)) with the vertex's
    /// draws, as [`Walk::scatter`] would take them: into the lanes where the vertex is
    /// Lambertian (true), else nothing (false: the caller scatters it alone).
    #[inline(always)]
    pub fn gather(&mut self, l: usize, walk: &Walk, path: &[Vertex], uc: f32, u: Vec2, u_rr: f32) -> bool {
        let n = path.len();
        let v = &path[n - 1];
        let Some(bsdf) = v.bsdf.as_ref() else { return false };
        // `lambertian_sample`'s cases: a diffuse front, no surface detail, no mask's
        // pass-through, a diffuse back or none (importance transport: the light walks).
        let BsdfModel::Diffuse(front) = &bsdf.front else { return false };
        let back = match &bsdf.back {
            None => None,
            Some(BsdfModel::Diffuse(b)) => Some(b.reflectance),
            Some(_) => return false,
        };
        if bsdf.detail.is_some() || (bsdf.opacity < 1.0 && uc >= bsdf.opacity) || walk.mode != TransportMode::Importance {
            return false;
        }
        let x = &mut self.v;
        let put = |a: &mut [[f32; LANES]; 3], w: Vec3| {
            a[0][l] = w.x;
            a[1][l] = w.y;
            a[2][l] = w.z;
        };
        put(&mut x.p, v.p);
        put(&mut x.ng, v.ng);
        put(&mut x.fs, v.shading.s);
        put(&mut x.ft, v.shading.t);
        put(&mut x.fnn, v.shading.n);
        put(&mut x.wo, -walk.ray.d);
        let rgb = |c: Rgb| Vec3::new(c.r, c.g, c.b);
        put(&mut x.front, rgb(front.reflectance));
        put(&mut x.back, rgb(back.unwrap_or(Rgb::BLACK)));
        x.has_back[l] = back.is_some();
        x.opacity[l] = bsdf.opacity;
        x.u[0][l] = u.x;
        x.u[1][l] = u.y;
        x.u_rr[l] = u_rr;
        x.rr[l] = (n - 1) as i32 >= walk.rr_depth;
        put(&mut x.beta, rgb(walk.beta));
        put(&mut x.scatter, rgb(walk.scatter));
        x.eta_scale[l] = walk.eta_scale;
        self.lanes |= 1 << l;
        true
    }

    /// The gathered lanes' step; every lane of `rays` is written (those not gathered are
    /// for their owners to set again).
    #[inline]
    pub fn run(&mut self, rays: &mut Rays8) {
        if self.lanes == 0 {
            return;
        }
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: `cpu::avx512()` checked the CPU; the lockstep walks run only where packets
            // do, which need AVX2.
            if self.avx512 {
                return unsafe { step8_avx512(&self.v, &mut self.o, rays) };
            }
            if crate::cpu::avx2() {
                return unsafe { step8_avx2(&self.v, &mut self.o, rays) };
            }
        }
        step8(&self.v, &mut self.o, rays)
    }

    /// Whether lane `l` was gathered since the last [`Self::clear`].
    #[inline]
    pub fn has(&self, l: usize) -> bool {
        self.lanes & (1 << l) != 0
    }

    /// After [`Self::run`]: gathered lane `l`'s step into its walk and path, as
    /// [`Walk::scatter`] leaves them but for the densities; returns whether the walk goes on
    /// (with its next ray the one `run` put in lane `l`).
    #[inline(always)]
    pub fn finish(&self, l: usize, walk: &mut Walk, path: &mut [Vertex], rays: &Rays8) -> bool {
        debug_assert!(self.has(l));
        let o = &self.o;
        if !o.sampled[l] {
            return false;
        }
        let n = path.len();
        path[n - 1].event = Event::from_lobe(LobeFlags::DIFFUSE_REFLECTION);
        let mut ray = Ray::new(Vec3::new(rays.o[0][l], rays.o[1][l], rays.o[2][l]), Vec3::new(rays.d[0][l], rays.d[1][l], rays.d[2][l]));
        ray.time = walk.ray.time;
        walk.ray = ray;
        walk.beta = Rgb::new(o.beta[0][l], o.beta[1][l], o.beta[2][l]);
        walk.scatter = Rgb::new(o.scatter[0][l], o.scatter[1][l], o.scatter[2][l]);
        o.cont[l]
    }

    /// Empties the lanes for the next step.
    #[inline]
    pub fn clear(&mut self) {
        self.lanes = 0;
    }
}

/// [`Walk::scatter`] at a Lambertian vertex for eight lanes, its densities left out:
/// `lambertian_sample`, the weight and its shading correction (importance transport), the
/// offset ray, Russian roulette.
/// Failures and comparisons keep the scalar step's sense on NaN (`!(x <= 0)`, not `x > 0`).
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn step8(v: &VertexNums, o: &mut StepOut, rays: &mut Rays8) {
    for l in 0..LANES {
        let g = |a: &[[f32; LANES]; 3]| [a[0][l], a[1][l], a[2][l]];
        let (p, ng, fs, ft, fnn, wo) = (g(&v.p), g(&v.ng), g(&v.fs), g(&v.ft), g(&v.fnn), g(&v.wo));
        let (has_back, rr) = (v.has_back[l], v.rr[l]);
        let opacity = v.opacity[l];
        // `Bsdf::side`: the front from above, else the back with wo mirrored.
        let zo = dot3(wo, fnn);
        let front_side = zo >= 0.0;
        let zm = if front_side { zo } else { -zo };
        let refl = if front_side { g(&v.front) } else { g(&v.back) };
        let wim = cosine_hemisphere(v.u[0][l], v.u[1][l]);
        let pdf = wim[2].max(0.0) * INV_PI;
        let wz = if front_side { wim[2] } else { -wim[2] };
        let f = [(refl[0] * INV_PI) * opacity, (refl[1] * INV_PI) * opacity, (refl[2] * INV_PI) * opacity];
        let bpdf = pdf * opacity;
        let f_black = (f[0] == 0.0) & (f[1] == 0.0) & (f[2] == 0.0);
        let sampled = (front_side | has_back) & !(zm <= 0.0) & !(pdf <= 0.0) & !(bpdf <= 0.0) & !f_black;
        let s = wz.abs() / bpdf;
        let wi =
            [(fs[0] * wim[0] + ft[0] * wim[1]) + fnn[0] * wz, (fs[1] * wim[0] + ft[1] * wim[1]) + fnn[1] * wz, (fs[2] * wim[0] + ft[2] * wim[1]) + fnn[2] * wz];
        // `shading_correction` in importance transport.
        let num = dot3(wo, fnn).abs() * dot3(wi, ng).abs();
        let den = dot3(wo, ng).abs() * dot3(wi, fnn).abs();
        let sc = if den == 0.0 { 0.0 } else { num / den };
        let w = [(f[0] * s) * sc, (f[1] * s) * sc, (f[2] * s) * sc];
        let origin = offset3(p, ng, wi);
        for k in 0..3 {
            rays.o[k][l] = origin[k];
            rays.d[k][l] = wi[k];
        }
        rays.t_max[l] = f32::INFINITY;
        let (beta, scatter) = (g(&v.beta), g(&v.scatter));
        let mut nb = [beta[0] * w[0], beta[1] * w[1], beta[2] * w[2]];
        let mut ns = [scatter[0] * w[0], scatter[1] * w[1], scatter[2] * w[2]];
        // Russian roulette on the scattering throughput.
        let eta = v.eta_scale[l];
        let q = (ns[0] * eta).max(ns[1] * eta).max(ns[2] * eta).min(0.95);
        let survive = !(v.u_rr[l] >= q);
        if rr & survive {
            nb = [nb[0] / q, nb[1] / q, nb[2] / q];
            ns = [ns[0] / q, ns[1] / q, ns[2] / q];
        }
        let black = (nb[0] == 0.0) & (nb[1] == 0.0) & (nb[2] == 0.0);
        for k in 0..3 {
            o.beta[k][l] = nb[k];
            o.scatter[k][l] = ns[k];
        }
        o.sampled[l] = sampled;
        o.cont[l] = sampled & (!rr | survive) & !black;
    }
}

/// [`step8`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline(never)]
unsafe fn step8_avx2(v: &VertexNums, o: &mut StepOut, rays: &mut Rays8) {
    step8(v, o, rays)
}

/// [`step8`] compiled for AVX-512VL (the same 256-bit code, 32 vector registers).
///
/// # Safety
/// The CPU must support AVX2, AVX-512F and AVX-512VL.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
#[inline(never)]
unsafe fn step8_avx512(v: &VertexNums, o: &mut StepOut, rays: &mut Rays8) {
    step8(v, o, rays)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::diffuse::Diffuse;
    use crate::bsdf::Bsdf;
    use crate::math::warp::square_to_uniform_sphere;
    use crate::math::Frame;
    use crate::path::VertexKind;
    use crate::sampling::Pcg32;

    /// A random two-vertex path ending at a Lambertian surface (one- or two-sided, masked or
    /// not, black sides, shading normals off the geometric one, a previous vertex on a
    /// surface, at a point, at infinity or at the same point) and the walk that arrived there.
    fn lane(rng: &mut Pcg32) -> (Walk, Vec<Vertex>, [f32; 4]) {
        let mut f = || rng.next_f32();
        let dir = |a: f32, b: f32| square_to_uniform_sphere(Vec2::new(a, b));
        let diffuse = |r: Rgb| BsdfModel::Diffuse(Diffuse { reflectance: r });
        let ng = dir(f(), f());
        let ns = if f() < 0.5 { ng } else { (ng + 0.4 * dir(f(), f())).normalize() };
        let front = if f() < 0.1 { Rgb::BLACK } else { Rgb::new(f(), f(), 0.5 * f()) };
        let back = (f() < 0.5).then(|| diffuse(Rgb::new(f(), 0.0, f())));
        let opacity = if f() < 0.3 { f() } else { 1.0 };
        let p = Vec3::new(f() - 0.5, 3.0 * f(), f() * 20.0 - 10.0);
        let d = dir(f(), f());
        let mut prev = Vertex::light_point(0, p - d * (0.1 + f()), if f() < 0.3 { Vec3::ZERO } else { dir(f(), f()) }, Rgb::WHITE, Rgb::WHITE, 1.0);
        match (f() * 10.0) as u32 {
            0 => {
                prev.infinite = true;
                prev.wo = -d;
            }
            1 => prev.p = p,
            _ => {}
        }
        let mut v = prev.clone();
        v.kind = VertexKind::Surface;
        (v.p, v.ng, v.shading, v.wo, v.infinite) = (p, ng, Frame::from_normal(ns), -d, false);
        v.bsdf = Some(Bsdf { front: diffuse(front), back, opacity, detail: None });
        let mut ray = Ray::new(p - d, d);
        ray.time = f();
        let mut w = Walk::new(ray, Rgb::new(f(), 2.0 * f(), f()), f(), 8, if f() < 0.5 { 1 } else { 5 }, TransportMode::Importance);
        w.scatter = Rgb::new(f(), f(), 0.1 * f());
        let u = match (f() * 8.0) as u32 {
            0 => [0.5, 0.5],
            1 => [0.0, f()],
            _ => [f(), f()],
        };
        (w, vec![prev, v], [f(), u[0], u[1], f()])
    }

    /// The step's outputs as bits (every lane).
    fn out_bits(o: &StepOut, rays: &Rays8) -> Vec<u32> {
        let mut b: Vec<u32> = rays.t_max.iter().map(|x| x.to_bits()).collect();
        for a in [&o.beta, &o.scatter, &rays.o, &rays.d] {
            b.extend(a.iter().flatten().map(|x| x.to_bits()));
        }
        b.extend(o.sampled.iter().chain(&o.cont).map(|&x| u32::from(x)));
        b
    }

    /// The plain build of the step and its AVX2 copy give what `run` gave (the AVX-512VL
    /// copy where the CPU has it), bit for bit.
    fn same_as_every_copy(lanes: &WalkLanes, rays: &Rays8) {
        let want = out_bits(&lanes.o, rays);
        let (mut o, mut r) = (StepOut::default(), Rays8::default());
        step8(&lanes.v, &mut o, &mut r);
        assert_eq!(out_bits(&o, &r), want, "plain");
        #[cfg(target_arch = "x86_64")]
        if crate::cpu::avx2() {
            // SAFETY: the CPU has AVX2.
            unsafe { step8_avx2(&lanes.v, &mut o, &mut r) };
            assert_eq!(out_bits(&o, &r), want, "avx2");
        }
    }

    /// Eight lanes stepped together leave each walk and path as `Walk::scatter` does, bit
    /// for bit, but for the densities, and go on where they do; vertices it does not cover
    /// are refused.
    #[test]
    fn step8_is_the_scalar_scatter() {
        let mut rng = Pcg32::new(3, 9);
        let mut lanes = WalkLanes::default();
        let mut seen = [0usize; 3];
        for round in 0..3000 {
            let cases: Vec<_> = (0..LANES).map(|_| lane(&mut rng)).collect();
            let mut rays = Rays8::default();
            let mut got: Vec<_> = cases.iter().map(|(w, p, _)| (w.clone(), p.clone())).collect();
            let mut gathered = [false; LANES];
            for (l, ((w, path), (_, _, u))) in got.iter().zip(&cases).enumerate() {
                gathered[l] = lanes.gather(l, w, path, u[0], Vec2::new(u[1], u[2]), u[3]);
            }
            lanes.run(&mut rays);
            same_as_every_copy(&lanes, &rays);
            for (l, (w, path, u)) in cases.iter().enumerate() {
                let (mut want_w, mut want_p) = (w.clone(), path.clone());
                let want = want_w.scatter(u[0], Vec2::new(u[1], u[2]), u[3], &mut want_p);
                if !gathered[l] {
                    // Only a mask's pass-through is left to the scalar step.
                    let o = path[1].bsdf.as_ref().map_or(1.0, |b| b.opacity);
                    assert!(o < 1.0 && u[0] >= o, "round {round} lane {l}");
                    seen[2] += 1;
                    continue;
                }
                let (gw, gp) = &mut got[l];
                let goes = lanes.finish(l, gw, gp, &rays);
                assert_eq!(goes, want, "round {round} lane {l}");
                assert_eq!(
                    format!("{:?}", (&gw.ray, gw.beta, gw.scatter)),
                    format!("{:?}", (&want_w.ray, want_w.beta, want_w.scatter)),
                    "round {round} lane {l}"
                );
                let bits = |v: &Vertex| (v.event, v.delta);
                assert_eq!((bits(&gp[0]), bits(&gp[1])), (bits(&want_p[0]), bits(&want_p[1])), "round {round} lane {l}");
                if goes {
                    let r = &want_w.ray;
                    for k in 0..3 {
                        assert_eq!((rays.o[k][l].to_bits(), rays.d[k][l].to_bits()), (r.o[k].to_bits(), r.d[k].to_bits()));
                    }
                }
                seen[usize::from(goes)] += 1;
            }
            lanes.clear();
        }
        // Walks that end (failed samples, roulette, black) and that go on, and pass-throughs.
        assert!(seen.iter().all(|&n| n > 500), "{seen:?}");
    }
}
