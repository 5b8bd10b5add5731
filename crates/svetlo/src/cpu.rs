//! The vector instruction sets this CPU runs, detected at run time (std caches the answers):
//! the eight-lane steps are compiled once per set from one source and pick their copy here.

/// AVX: the BVH build's bin unions and partition.
#[inline]
pub fn avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// AVX2: the eight-wide paths (ray packets, the kernels' eight-lane steps).
#[inline]
pub fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// FMA: the rough conductors' copies (glibc's `expf` as vector lanes, `math::expf`).
#[inline]
pub fn fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// AVX2 with AVX-512F, VL and DQ: the eight-lane steps' 32-register copies (DQ: the path
/// kernel's 64-bit multiplies).
#[inline]
pub fn avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx2()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("avx512dq")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}
