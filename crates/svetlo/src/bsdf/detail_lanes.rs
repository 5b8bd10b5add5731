//! [`Bsdf::detail_lambert`](super::Bsdf::detail_lambert) of eight lanes at once: a one-sided
//! Lambertian under a normal or bump map (with the shadowing term), written as loops over
//! lane arrays with selects for branches, so that the path kernel's detail lanes compile to
//! vector code. Every operation is the scalar one's (IEEE basic operations and sqrt; the
//! cosine-weighted direction by `math::lane::cosine_hemisphere`), in its order: the same bits.

use super::lane_samples::LaneSamples;
use crate::math::lane::{cosine_hemisphere, dot3};
use crate::math::INV_PI;

/// The inputs of up to `N` lanes, in the shading frame: the perturbed unit normal `n`
/// (`Detail::n`, shadowing on), the reflectance, `wo`, the light sample `wi` where `lit`,
/// and the direction's two numbers `u`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct DetailLambertLanes<const N: usize> {
    pub n: [[f32; N]; 3],
    pub refl: [[f32; N]; 3],
    pub wo: [[f32; N]; 3],
    pub wi: [[f32; N]; 3],
    pub lit: [bool; N],
    pub u: [[f32; N]; 2],
}

impl<const N: usize> Default for DetailLambertLanes<N> {
    fn default() -> Self {
        DetailLambertLanes { n: [[0.0; N]; 3], refl: [[0.0; N]; 3], wo: [[0.0; N]; 3], wi: [[0.0; N]; 3], lit: [false; N], u: [[0.0; N]; 2] }
    }
}

/// `glam`'s `a.cross(b)`, operation for operation.
#[inline(always)]
pub(crate) fn cross3(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - b[1] * a[2], a[2] * b[0] - b[2] * a[0], a[0] * b[1] - b[0] * a[1]]
}

/// `Detail::frame(wo)` of a lane's detail normal `n`: its normal, mirrored where `wo` is below
/// it, and the frame's s and t (selects per component: whole arrays became branches).
#[inline(always)]
pub(crate) fn detail_frame(n: [f32; 3], wo: [f32; 3]) -> ([f32; 3], [f32; 3], [f32; 3]) {
    let flip = wo[2] * dot3(wo, n) <= 0.0;
    let nn = [if flip { -n[0] } else { n[0] }, if flip { -n[1] } else { n[1] }, n[2]];
    let s = [1.0 - nn[0] * nn[0], 0.0 - nn[1] * nn[0], 0.0 - nn[2] * nn[0]];
    let len2 = dot3(s, s);
    let len = len2.sqrt();
    let tilted = len2 > 1e-12;
    let s = [if tilted { s[0] / len } else { 0.0 }, if tilted { s[1] / len } else { 1.0 }, if tilted { s[2] / len } else { 0.0 }];
    (nn, s, cross3(nn, s))
}

/// `Detail::shadowing`'s `tan2` of a direction with this z.
#[inline(always)]
pub(crate) fn tan2(z: f32) -> f32 {
    (1.0 - z * z).max(0.0) / (z * z)
}

/// Each lane's (value, density) toward its light sample (where `lit`; read back by
/// `LaneSamples::lane` with `nee` = `lit`) and its own sample, as `Bsdf::detail_lambert` gives
/// them (lobe: the diffuse reflection, `LaneSamples::lane`'s `other`; eta 1). Lanes not used
/// compute garbage that no one reads.
#[inline(always)]
pub(crate) fn detail_lambert_lanes<const N: usize>(q: &DetailLambertLanes<N>) -> LaneSamples<N> {
    let mut o = LaneSamples::<N>::empty(false);
    for l in 0..N {
        let n = [q.n[0][l], q.n[1][l], q.n[2][l]];
        let wo = [q.wo[0][l], q.wo[1][l], q.wo[2][l]];
        let wi = [q.wi[0][l], q.wi[1][l], q.wi[2][l]];
        let refl = [q.refl[0][l], q.refl[1][l], q.refl[2][l]];
        let (nn, s, t) = detail_frame(n, wo);
        let pwo_z = dot3(wo, nn);
        // `Detail::shadowing` (of the unmirrored normal: the same z).
        let alpha2 = (0.125 * tan2(n[2])).min(1.0);
        let shadowing = |z: f32| {
            let g = 2.0 / (1.0 + (1.0 + alpha2 * tan2(z)).sqrt());
            if g.is_finite() {
                g
            } else {
                0.0
            }
        };
        let front = pwo_z >= 0.0;
        // The light sample: `Diffuse::eval` and `pdf` on the front (black behind), times
        // `detail_factor` where the detail lets the light through.
        let pwi_z = dot3(wi, nn);
        let through = wi[2] * pwi_z > 0.0;
        let k = pwi_z.abs() / wi[2].abs() * shadowing(wi[2]);
        let lambert = front && !(pwo_z <= 0.0 || pwi_z <= 0.0);
        let pdf = if lambert { pwi_z.max(0.0) * INV_PI } else { 0.0 };
        for (c, r) in refl.iter().enumerate() {
            let v = if lambert { r * INV_PI } else { 0.0 };
            o.nee_f[c][l] = if through { v * k } else { 0.0 };
        }
        o.nee_pdf[l] = if through { pdf } else { 0.0 };
        // The sample: `Diffuse::sample` from `pwo`, then `detail_sample_out`.
        let d = cosine_hemisphere(q.u[0][l], q.u[1][l]);
        let spdf = d[2].max(0.0) * INV_PI;
        let w = [s[0] * d[0] + t[0] * d[1] + nn[0] * d[2], s[1] * d[0] + t[1] * d[1] + nn[1] * d[2], s[2] * d[0] + t[2] * d[1] + nn[2] * d[2]];
        let through = w[2] * d[2] > 0.0;
        let k = d[2].abs() / w[2].abs() * shadowing(w[2]);
        // `front` and not `pwo_z <= 0` is `pwo_z > 0`; `spdf` is never NaN (z: a sqrt of a max).
        o.sampled[l] = pwo_z > 0.0 && spdf > 0.0 && through;
        for (c, r) in refl.iter().enumerate() {
            o.wi[c][l] = w[c];
            o.f[c][l] = r * INV_PI * k;
        }
        o.pdf[l] = spdf;
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::detail::Detail;
    use crate::bsdf::{Bsdf, BsdfSample, LobeFlags};
    use crate::sampling::rng::Pcg32;
    use crate::spectrum::Rgb;
    use glam::{Vec2, Vec3};

    /// `detail_lambert_lanes` compiled for AVX2 (as the path kernel's copy).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn lanes_avx2(q: &DetailLambertLanes<8>) -> LaneSamples<8> {
        detail_lambert_lanes(q)
    }

    /// `detail_lambert_lanes` compiled for AVX-512VL.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
    unsafe fn lanes_avx512(q: &DetailLambertLanes<8>) -> LaneSamples<8> {
        detail_lambert_lanes(q)
    }

    /// The lane routine (portable, AVX2 and AVX-512 builds) gives `Bsdf::detail_lambert`'s bits
    /// over many random lanes: tilted, grazing and flat normals, directions on both sides and
    /// grazing, lanes with and without a light sample, the numbers' ends; enough lanes see the
    /// detail block the light, a back-facing `wo`, and the shadowing term below 1.
    #[test]
    fn detail_lambert_lanes_are_detail_lambert() {
        let mut rng = Pcg32::new(17, 9);
        let f = |rng: &mut Pcg32, lo: f32, hi: f32| lo + (hi - lo) * rng.next_f32();
        let dir = |rng: &mut Pcg32, zlo: f32| {
            let z = f(rng, zlo, 1.0);
            let phi = f(rng, 0.0, 2.0 * crate::math::PI);
            let r = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        };
        let bits3 = |v: Vec3| v.to_array().map(f32::to_bits);
        let nee_bits = |n: Option<(Rgb, f32)>| n.map(|(f, pdf)| (f.r.to_bits(), f.g.to_bits(), f.b.to_bits(), pdf.to_bits()));
        let s_bits =
            |s: Option<BsdfSample>| s.map(|s| (bits3(s.wi), s.f.r.to_bits(), s.f.g.to_bits(), s.f.b.to_bits(), s.pdf.to_bits(), s.lobe, s.eta.to_bits()));
        let us = [0.0f32, 0.5, 1e-7, 1.0 - 6e-8, 0.25, 0.75];
        let (mut blocked, mut back, mut shadowed, mut sampled, mut unlit) = (0, 0, 0, 0, 0);
        for batch in 0..20_000usize {
            let mut q = DetailLambertLanes::<8>::default();
            let mut lanes = [(Detail { n: Vec3::Z, shadowing: true }, Rgb::BLACK, Vec3::Z, None, Vec2::ZERO); 8];
            for (l, lane) in lanes.iter_mut().enumerate() {
                let i = batch * 8 + l;
                // Normals mostly above the surface, some grazing or flat (as maps give them).
                let n = match i % 5 {
                    0 => Vec3::Z,
                    1 => Vec3::new(f(&mut rng, -1.0, 1.0), f(&mut rng, -1.0, 1.0), f(&mut rng, 0.0, 0.05)),
                    _ => dir(&mut rng, 0.0),
                };
                let d = Detail::new(n, true);
                let wo = if i % 11 == 0 { Vec3::new(f(&mut rng, -1.0, 1.0), f(&mut rng, -1.0, 1.0), 0.0).normalize() } else { dir(&mut rng, -1.0) };
                let wi = (i % 7 != 0).then(|| {
                    if i % 13 == 0 {
                        Vec3::new(f(&mut rng, -1.0, 1.0), f(&mut rng, -1.0, 1.0), 1e-4).normalize()
                    } else {
                        dir(&mut rng, -1.0)
                    }
                });
                let refl = Rgb::new(f(&mut rng, 0.0, 1.0), f(&mut rng, 0.0, 1.0), f(&mut rng, 0.0, 1.0));
                let u = if i % 3 == 0 { Vec2::new(us[i % us.len()], us[i / 3 % us.len()]) } else { Vec2::new(f(&mut rng, 0.0, 1.0), f(&mut rng, 0.0, 1.0)) };
                for c in 0..3 {
                    q.n[c][l] = d.n[c];
                    q.wo[c][l] = wo[c];
                    q.wi[c][l] = wi.unwrap_or(Vec3::ZERO)[c];
                }
                (q.refl[0][l], q.refl[1][l], q.refl[2][l]) = (refl.r, refl.g, refl.b);
                (q.u[0][l], q.u[1][l]) = (u.x, u.y);
                q.lit[l] = wi.is_some();
                *lane = (d, refl, wo, wi, u);
            }
            let mut outs = vec![detail_lambert_lanes(&q)];
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::avx2() && crate::cpu::fma() {
                // SAFETY: the CPU has AVX2 and FMA.
                outs.push(unsafe { lanes_avx2(&q) });
                if crate::cpu::avx512() {
                    // SAFETY: the CPU has AVX-512F and VL.
                    outs.push(unsafe { lanes_avx512(&q) });
                }
            }
            for (l, &(d, refl, wo, wi, u)) in lanes.iter().enumerate() {
                let (nee, s) = Bsdf::detail_lambert(&d, refl, wo, wi, u);
                for (b, out) in outs.iter().enumerate() {
                    let (nee_l, s_l) = out.lane(l, q.lit[l], LobeFlags::DIFFUSE_REFLECTION);
                    assert_eq!(nee_bits(nee_l), nee_bits(nee), "build {b}: {d:?} {wo} {wi:?}");
                    assert_eq!(s_bits(s_l), s_bits(s), "build {b}: {d:?} {wo} {u}");
                }
                let f = d.frame(wo);
                let pwo = f.to_local(wo);
                back += (pwo.z < 0.0) as usize;
                blocked += wi.is_some_and(|wi| wi.z * f.to_local(wi).z <= 0.0 && pwo.z > 0.0) as usize;
                shadowed += nee.is_some_and(|(f, _)| !f.is_black() && d.shadowing(wi.unwrap()) < 1.0) as usize;
                sampled += s.is_some() as usize;
                unlit += wi.is_none() as usize;
            }
        }
        assert!(blocked > 1000 && back > 1000 && shadowed > 1000 && sampled > 1000 && unlit > 1000, "{blocked} {back} {shadowed} {sampled} {unlit}");
    }
}
