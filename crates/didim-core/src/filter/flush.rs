//! Subnormal numbers flushed to zero while a recursive filter runs.

/// Subnormal numbers read and written as zero by this thread's floating-point arithmetic
/// (x86-64's MXCSR flush-to-zero and denormals-are-zero) while it lives; the previous mode
/// comes back when it is dropped, also when a panic unwinds through it.
///
/// A recursive filter's state decays geometrically through a run of zeros (a regressor column
/// of local support: a friction spline along the stroke, an indicator, a Stribeck column at
/// speed) and passes through subnormal numbers on its way to zero, whose arithmetic costs
/// tens to a hundred times a normal number's: such columns took 27 times as long as columns of
/// random numbers (the EMPS doctor's friction profiles: 12 ms per DIDIM system of 23 columns,
/// 8 of them in the filter). Only numbers below 2.2e-308 change (to zero), and an output by a
/// few such numbers at most (a subnormal the reference carries into the backward pass), so
/// every output above 1e-250 is the same, bit for bit. Elsewhere than on x86-64 the passes
/// run without it: the same results, at the subnormals' cost. (Flushing the state by hand
/// every few samples, portable, took the state out of the registers: every pass ran 1.8 times
/// as slow.)
#[cfg(target_arch = "x86_64")]
pub(crate) struct FlushSubnormals(u32);

#[cfg(target_arch = "x86_64")]
impl FlushSubnormals {
    /// MXCSR's flush-to-zero (bit 15) and denormals-are-zero (bit 6).
    const FTZ_DAZ: u32 = 0x8040;

    pub(crate) fn on() -> Self {
        let mut old: u32 = 0;
        // SAFETY: `stmxcsr` stores the 32-bit MXCSR at the address of `old`, which is valid
        // for writes; `ldmxcsr` loads a value that differs from the current one only in the
        // FTZ and DAZ bits, which every x86-64 processor (SSE2) has.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut old, options(nostack, preserves_flags));
            let new = old | Self::FTZ_DAZ;
            std::arch::asm!("ldmxcsr [{}]", in(reg) &new, options(nostack, preserves_flags));
        }
        FlushSubnormals(old)
    }
}

#[cfg(target_arch = "x86_64")]
impl Drop for FlushSubnormals {
    fn drop(&mut self) {
        // SAFETY: restores the MXCSR value `on` read from this thread.
        unsafe { std::arch::asm!("ldmxcsr [{}]", in(reg) &self.0, options(nostack, preserves_flags)) };
    }
}
