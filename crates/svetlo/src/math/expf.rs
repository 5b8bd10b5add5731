//! glibc's `expf` as vector lanes: its main path (|x| < 88) operation for operation, in f64
//! with its table and fused multiply-adds, as its FMA build runs it (the one x86-64 glibc
//! picks where the CPU has FMA and AVX2, which is where the path kernel's vector copies
//! run). The rough conductors' lanes take Beckmann's e^x from here, eight lanes at once: the
//! libm call per lane spilled every vector register around it. The same bits (a test sweeps
//! every float of the range against `f32::exp`).

/// 32 / ln 2, the shift that rounds to an integer, and the polynomial for 2^(r/32).
const INV_LN2_N: f64 = f64::from_bits(0x4047_1547_652b_82fe);
const SHIFT: f64 = f64::from_bits(0x4338_0000_0000_0000);
const C: [f64; 3] = [f64::from_bits(0x3ebc_6af8_4b91_2394), f64::from_bits(0x3f2e_bfce_50fa_c4f3), f64::from_bits(0x3f96_2e42_ff0c_52d6)];

/// 2^(i/32) with its exponent field less i << 47 (glibc's `__exp2f_data.tab`).
const TAB: [u64; 32] = [
    0x3ff0000000000000,
    0x3fefd9b0d3158574,
    0x3fefb5586cf9890f,
    0x3fef9301d0125b51,
    0x3fef72b83c7d517b,
    0x3fef54873168b9aa,
    0x3fef387a6e756238,
    0x3fef1e9df51fdee1,
    0x3fef06fe0a31b715,
    0x3feef1a7373aa9cb,
    0x3feedea64c123422,
    0x3feece086061892d,
    0x3feebfdad5362a27,
    0x3feeb42b569d4f82,
    0x3feeab07dd485429,
    0x3feea47eb03a5585,
    0x3feea09e667f3bcd,
    0x3fee9f75e8ec5f74,
    0x3feea11473eb0187,
    0x3feea589994cce13,
    0x3feeace5422aa0db,
    0x3feeb737b0cdc5e5,
    0x3feec49182a3f090,
    0x3feed503b23e255d,
    0x3feee89f995ad3ad,
    0x3feeff76f2fb5e47,
    0x3fef199bdd85529c,
    0x3fef3720dcef9069,
    0x3fef5818dcfba487,
    0x3fef7c97337b9b5f,
    0x3fefa4afa2a490da,
    0x3fefd0765b6e4540,
];

/// Whether glibc's `expf` takes its main path at `x`: |x| < 88 (not NaN).
#[inline(always)]
pub(crate) fn main_path(x: f32) -> bool {
    (x.to_bits() >> 20) & 0x7ff < 0x42b
}

/// e^x as glibc's `expf` computes it on its main path ([`main_path`]; elsewhere a number
/// without meaning). Without FMA in the build, `mul_add` is libm's `fma`: the same bits.
#[inline(always)]
pub(crate) fn expf_main(x: f32) -> f32 {
    let xd = x as f64;
    let z = INV_LN2_N.mul_add(xd, SHIFT);
    let ki = z.to_bits();
    let kd = z - SHIFT;
    let r = INV_LN2_N.mul_add(xd, -kd);
    let s = f64::from_bits(TAB[(ki & 31) as usize].wrapping_add(ki << 47));
    let p = C[0].mul_add(r, C[1]);
    let y = C[2].mul_add(r, 1.0);
    (p.mul_add(r * r, y) * s) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every float of the main path gives libm's `expf` bits, where the process's glibc runs
    /// its FMA build (x86-64 Linux with FMA and AVX2; elsewhere libm is another routine).
    #[test]
    fn expf_main_is_glibc_expf() {
        #[cfg(all(target_arch = "x86_64", target_os = "linux", target_env = "gnu"))]
        {
            if !(std::arch::is_x86_feature_detected!("fma") && crate::cpu::avx2()) {
                eprintln!("SKIPPED: glibc's expf is not its FMA build here");
                return;
            }
            let mut n = 0u64;
            for bits in (0..0x42b0_0000u32).step_by(3).flat_map(|b| [b, b | 0x8000_0000]) {
                let x = f32::from_bits(bits);
                assert!(main_path(x), "{x:e}");
                assert_eq!(expf_main(x).to_bits(), x.exp().to_bits(), "e^{x:e}");
                n += 1;
            }
            assert!(n > 700_000_000);
            for x in [88.0f32, -88.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -104.0] {
                assert!(!main_path(x), "{x:e}");
            }
        }
    }
}
