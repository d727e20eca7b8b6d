//! What the processor can do, asked once: whether the kernels built for AVX2 and FMA run
//! ([`wide_simd`]). The closed loop ([`crate::sim::driver::simd`]), the filters, the trajectory
//! regressor, the sine kernel and the robot chain each compile their inner loops twice, for the
//! baseline x86-64 and for AVX2 with FMA, the same IEEE operations in either, and ask here which
//! to run.

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
