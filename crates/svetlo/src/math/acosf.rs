//! glibc's `acosf` as vector lanes: fdlibm's single-precision routine (the one glibc 2.36's
//! libm runs on x86-64), operation for operation, its three ranges computed in every lane and
//! the lane's own picked, so that a loop over many values vectorizes. The angle-weighted vertex
//! normals of a mesh without normals take three of them per triangle: the libm call per corner
//! was a tenth of a 1M-triangle scene's load. The same bits: every float of [-1, 1] (and a
//! million NaNs and values past 1) was checked against glibc 2.36's `acosf` once; the test sweeps every
//! seventh float of [-1, 1] and the special values against `f32::acos`.

const PI: f32 = f32::from_bits(0x4049_0fda);
const PIO2_HI: f32 = f32::from_bits(0x3fc9_0fda);
const PIO2_LO: f32 = f32::from_bits(0x33a2_2168);
const PS: [f32; 6] = [
    f32::from_bits(0x3e2a_aaab),
    f32::from_bits(0xbea6_b090),
    f32::from_bits(0x3e4e_0aa8),
    f32::from_bits(0xbd24_1146),
    f32::from_bits(0x3a4f_7f04),
    f32::from_bits(0x3811_ef08),
];
const QS: [f32; 4] = [f32::from_bits(0xc019_d139), f32::from_bits(0x4001_572d), f32::from_bits(0xbf30_3361), f32::from_bits(0x3d9d_c62e)];

/// acos(x) with libm's bits, branch-free (every range computed, one picked).
#[inline(always)]
pub(crate) fn acosf(x: f32) -> f32 {
    let ix = x.to_bits() & 0x7fff_ffff;
    // |x| < 0.5: the rational approximation in x^2; above, in (1 - |x|) / 2 (1 + x where x < 0).
    let z = if ix < 0x3f00_0000 { x * x } else { (1.0 - f32::from_bits(ix)) * 0.5 };
    let p = z * (PS[0] + z * (PS[1] + z * (PS[2] + z * (PS[3] + z * (PS[4] + z * PS[5])))));
    let q = 1.0 + z * (QS[0] + z * (QS[1] + z * (QS[2] + z * QS[3])));
    let r = p / q;
    let s = z.sqrt();
    // s with its low 12 bits cleared, and the rounding error of its square.
    let df = f32::from_bits(s.to_bits() & 0xffff_f000);
    let c = (z - df * df) / (s + df);
    let small = PIO2_HI - (x - (PIO2_LO - x * r));
    let negative = PI - 2.0 * (s + (r * s - PIO2_LO));
    let positive = 2.0 * (df + (r * s + c));
    let mid = if ix < 0x3f00_0000 {
        small
    } else if x < 0.0 {
        negative
    } else {
        positive
    };
    let tiny = PIO2_HI + PIO2_LO;
    let one = if x > 0.0 { 0.0 } else { PI + 2.0 * PIO2_LO };
    // |x| > 1: libm's wrapper gives the positive quiet NaN; a NaN goes through quieted (its
    // (x - x) / (x - x) is x + x there).
    let outside = if ix > 0x7f80_0000 { x + x } else { f32::NAN };
    if ix <= 0x3280_0000 {
        tiny
    } else if ix == 0x3f80_0000 {
        one
    } else if ix > 0x3f80_0000 {
        outside
    } else {
        mid
    }
}

/// Each value of `xs` replaced by its arc cosine ([`acosf`]), eight lanes at a time where the
/// CPU has AVX2.
pub(crate) fn acosf_in_place(xs: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::avx2() {
        // SAFETY: the CPU has AVX2.
        unsafe { acosf_avx2(xs) };
        return;
    }
    acosf_loop(xs);
}

#[inline(always)]
fn acosf_loop(xs: &mut [f32]) {
    for x in xs {
        *x = acosf(*x);
    }
}

/// The same loop compiled for AVX2 (no FMA: every product and sum rounds as libm's do).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn acosf_avx2(xs: &mut [f32]) {
    acosf_loop(xs);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every seventh float of [-1, 1], both signs, and the special values give libm's `acosf`
    /// bits, where the process's libm is glibc's fdlibm routine (x86-64 glibc before 2.41;
    /// elsewhere libm is another routine).
    #[test]
    fn acosf_is_glibc_acosf() {
        #[cfg(all(target_arch = "x86_64", target_os = "linux", target_env = "gnu"))]
        {
            let special = [1.0, -1.0, 0.5, -0.5, 1.5, -2.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, f32::MIN_POSITIVE, 2e-8, -2e-8];
            let every_seventh = (0..=0x3f80_0000u32).step_by(7).flat_map(|b| [f32::from_bits(b), f32::from_bits(b | 0x8000_0000)]);
            let mut all = special.into_iter().chain(every_seventh).peekable();
            let mut n = 0usize;
            while all.peek().is_some() {
                let mut xs: Vec<f32> = all.by_ref().take(1 << 16).collect();
                let want: Vec<u32> = xs.iter().map(|x| x.acos().to_bits()).collect();
                // The single value and the vector loop.
                for (x, w) in xs.iter().zip(&want) {
                    assert_eq!(acosf(*x).to_bits(), *w, "acos {x:e}");
                }
                acosf_in_place(&mut xs);
                for (x, w) in xs.iter().zip(&want) {
                    assert_eq!(x.to_bits(), *w, "the vector loop");
                }
                n += xs.len();
            }
            assert!(n > 300_000_000);
        }
    }
}
