//! What the processor can do, asked once: whether the kernels built for AVX2 and FMA run
//! ([`wide_simd`]). The closed loop ([`crate::sim::driver::simd`]), the filters, the trajectory
//! regressor, the sine kernel and the robot chain each compile their inner loops twice, for the
//! baseline x86-64 and for AVX2 with FMA, the same IEEE operations in either, and ask here which
//! to run. The filters have a third build, eight columns to an AVX-512 register
//! ([`wide512`]), where the processor has it.

/// Whether the AVX2 and FMA builds run: the processor has both, and the environment variable
/// `DIDIM_BASELINE_SIMD` is not set (to compare the two builds).
#[cfg(target_arch = "x86_64")]
pub(crate) fn wide_simd() -> bool {
    static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WIDE.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::env::var_os("DIDIM_BASELINE_SIMD").is_none()
    })
}

/// Whether the filters' eight-lane AVX-512 build runs: [`wide_simd`] holds, the processor has
/// AVX-512F, and `DIDIM_NO_AVX512` is not set (to compare with the four-lane build).
#[cfg(target_arch = "x86_64")]
pub(crate) fn wide512() -> bool {
    static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WIDE.get_or_init(|| {
        wide_simd()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::env::var_os("DIDIM_NO_AVX512").is_none()
    })
}
