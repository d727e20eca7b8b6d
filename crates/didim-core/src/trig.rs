//! Sine and cosine of the model's angles and periodic terms: the robot chain's joint rotations
//! ([`crate::robot`]), a force periodic in position and gravity on one axis ([`crate::model`]), one
//! kernel for the scalar calls of the simulators, the regressors and the sensitivities, and for the
//! whole columns the doctor tests ([`sin_into`]): the same operations in the same order, so a column
//! equals, bit for bit, what [`sin_cos`] gives sample by sample.
//!
//! The argument is reduced by `k = round(x·2/π)` against π/2 in two parts (fdlibm's `pio2_1`, 33
//! bits, so `k·pio2_1` is exact while |x| ≤ 2²⁰ rad, and `pio2_1t`), and the reduced argument in
//! [−π/4, π/4] goes through fdlibm's `__kernel_sin` and `__kernel_cos` polynomials (their
//! coefficients, evaluated by Horner's rule). Against the C library's `sin` and `cos` the error is at
//! most half an ulp of max(1, |value|) on the test's 216 000 arguments up to [`REDUCED_LIMIT`] (an
//! absolute error near the zeros, where the reduced argument's own rounding sets it); beyond, and
//! for NaN, the standard library computes.
//!
//! Why not `f64::sin_cos`: it calls the C library's `sin` and `cos` one at a time (two reductions,
//! no vector registers). A robot's ABA takes a sine and a cosine per joint and step; the doctor's
//! position-periodic candidates are 160 columns of the whole record per grid (on the EMPS record,
//! 9 % of a doctor run was glibc's `sin`). Here the loop has no branch and no call, and
//! [`sin_into`]'s AVX2 build runs it four samples at a time.

// fdlibm's constants as it prints them (more digits than a double holds; each rounds to its double)
#![allow(clippy::excessive_precision)]

/// Above this |x| the reduction's `k·pio2_1` is no longer exact: the standard library computes.
pub const REDUCED_LIMIT: f64 = 1_048_576.0; // 2²⁰

/// 1.5·2⁵²: added to an integer-valued double of magnitude below 2⁵¹, it puts the integer in the
/// low bits of the sum (two's complement residue for a negative one).
const ROUNDER: f64 = 6_755_399_441_055_744.0;
// π/2's first 33 bits and the rest (fdlibm's pio2_1, pio2_1t)
const PIO2_1: f64 = 1.570_796_326_734_125_6;
const PIO2_1T: f64 = 6.077_100_506_506_192e-11;
// __kernel_sin's and __kernel_cos's coefficients
const S: [f64; 6] = [
    -1.666_666_666_666_663_2e-1,
    8.333_333_333_322_49e-3,
    -1.984_126_982_985_795e-4,
    2.755_731_370_707_006_8e-6,
    -2.505_076_025_340_686_3e-8,
    1.589_690_995_211_55e-10,
];
const C: [f64; 6] = [
    4.166_666_666_666_660_2e-2,
    -1.388_888_888_887_411e-3,
    2.480_158_728_947_673e-5,
    -2.755_731_435_139_066_3e-7,
    2.087_572_321_298_175e-9,
    -1.135_964_755_778_819_5e-11,
];

/// `(sin x, cos x)` for |x| ≤ [`REDUCED_LIMIT`], branch-free (the caller checks the range).
#[inline(always)]
fn reduced(x: f64) -> (f64, f64) {
    let k = (x * std::f64::consts::FRAC_2_PI).round();
    let r = (x - k * PIO2_1) - k * PIO2_1T;
    let z = r * r;
    let sp = S[0] + z * (S[1] + z * (S[2] + z * (S[3] + z * (S[4] + z * S[5]))));
    let sin = r + r * z * sp;
    let cp = z * (C[0] + z * (C[1] + z * (C[2] + z * (C[3] + z * (C[4] + z * C[5])))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    let cos = w + (((1.0 - w) - hz) + z * cp);
    // the quadrant k mod 4 from the low bits, without a conversion to an integer register: odd
    // ones swap, the upper two negate
    let q = (k + ROUNDER).to_bits();
    let (s, c) = if q & 1 == 0 { (sin, cos) } else { (cos, -sin) };
    let flip = if q & 2 == 0 { 1.0 } else { -1.0 };
    (flip * s, flip * c)
}

/// `(sin x, cos x)`.
#[inline(always)]
pub fn sin_cos(x: f64) -> (f64, f64) {
    if x.abs() > REDUCED_LIMIT || x.is_nan() {
        return x.sin_cos();
    }
    reduced(x)
}

/// `sin x`.
#[inline(always)]
pub fn sin(x: f64) -> f64 {
    sin_cos(x).0
}

/// `out[k] = sin(w·x[k] + phase)` for every sample, each the bits of `sin(w * x[k] + phase)`;
/// compiled for the processor as [`crate::sim::driver::simd`] is (AVX2 and FMA where it has
/// both, four samples a register; the same IEEE operations in both builds).
pub fn sin_into(out: &mut [f64], x: &[f64], w: f64, phase: f64) {
    assert_eq!(
        out.len(),
        x.len(),
        "sin_into: {} outputs for {} samples",
        out.len(),
        x.len()
    );
    #[cfg(target_arch = "x86_64")]
    let _flush = crate::filter::FlushSubnormals::on();
    /// # Safety
    /// The processor must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn wide(out: &mut [f64], x: &[f64], w: f64, phase: f64) -> bool {
        sin_loop(out, x, w, phase)
    }
    #[cfg(target_arch = "x86_64")]
    let beyond = if crate::cpu::wide_simd() {
        // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
        unsafe { wide(out, x, w, phase) }
    } else {
        sin_loop(out, x, w, phase)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let beyond = sin_loop(out, x, w, phase);
    if beyond {
        // the rare arguments beyond the reduction's range (and NaN), as sin_cos takes them
        for (o, &xk) in out.iter_mut().zip(x) {
            *o = sin(w * xk + phase);
        }
    }
}

/// The branch-free loop of [`sin_into`]; whether an argument lay beyond [`REDUCED_LIMIT`].
#[inline(always)]
fn sin_loop(out: &mut [f64], x: &[f64], w: f64, phase: f64) -> bool {
    let mut beyond = false;
    for (o, &xk) in out.iter_mut().zip(x) {
        let a = w * xk + phase;
        beyond |= a.abs() > REDUCED_LIMIT || a.is_nan();
        *o = reduced(a).0;
    }
    beyond
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The error of `got` against the C library's value, in units of the larger of its ulp and
    /// the ulp of 1 (an absolute error for the small values near a zero of the function, where
    /// the reduced argument's own rounding sets it).
    fn ulps(got: f64, want: f64) -> f64 {
        let unit = f64::EPSILON * want.abs().max(1.0);
        (got - want).abs() / unit
    }

    fn arguments() -> Vec<f64> {
        // deterministic spread: small, multiples of π/2 and their neighbours, large
        let mut xs = vec![0.0, -0.0, 1e-300, 1e-8, -1e-8, 0.5, -0.785, 0.786, 1.0, 3.0, -7.5];
        for k in -2000..=2000 {
            let x = k as f64 * std::f64::consts::FRAC_PI_2;
            xs.extend([x, f64::from_bits(x.to_bits() + 1), x + 1e-9, x - 3e-7]);
        }
        let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..200_000 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (s >> 11) as f64 / (1u64 << 53) as f64;
            let scale = [1.0, 10.0, 1e3, 1e5, 8e5][(s & 7) as usize % 5];
            xs.push((2.0 * u - 1.0) * scale);
        }
        xs
    }

    #[test]
    fn sin_and_cos_are_within_two_ulps_of_one_of_the_c_library() {
        let mut worst = (0.0f64, 0.0f64);
        for x in arguments() {
            let (s, c) = sin_cos(x);
            worst.0 = worst.0.max(ulps(s, x.sin()));
            worst.1 = worst.1.max(ulps(c, x.cos()));
        }
        eprintln!(
            "worst errors against the C library: sin {:.2}, cos {:.2} ulps",
            worst.0, worst.1
        );
        assert!(worst.0 <= 2.0 && worst.1 <= 2.0, "worst errors {worst:?} ulps");
    }

    #[test]
    fn beyond_the_reduction_and_at_special_values_the_library_computes() {
        for x in [1.1e6, -3.3e7, 1e300, f64::MAX] {
            assert_eq!(sin_cos(x), x.sin_cos());
        }
        assert!(sin(f64::NAN).is_nan() && sin(f64::INFINITY).is_nan());
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
    }

    #[test]
    fn a_column_is_the_scalar_sine_bit_for_bit() {
        // (not subnormal arguments: `simd` flushes them to zero, as it does in every loop it runs)
        let normal = |x: &f64| *x == 0.0 || x.abs() >= f64::MIN_POSITIVE;
        let x: Vec<f64> = arguments()
            .into_iter()
            .filter(normal)
            .take(50_001)
            .chain([2e6, f64::NAN])
            .collect();
        for (w, phase) in [(1.0, 0.0), (2513.27, 0.3), (-0.7, -1.1), (1e4, 0.0)] {
            let mut out = vec![0.0; x.len()];
            sin_into(&mut out, &x, w, phase);
            for (o, &xk) in out.iter().zip(&x) {
                let want = sin(w * xk + phase);
                assert!(
                    o.to_bits() == want.to_bits() || (o.is_nan() && want.is_nan()),
                    "x {xk}: {o} vs {want}"
                );
            }
        }
    }
}
