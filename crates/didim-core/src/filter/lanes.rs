//! Column-interleaved zero-phase filtering: the kernels of every zero-phase filter of the
//! crate ([`super::filtfilt`], [`super::sosfiltfilt`], [`super::Decimation`]).
//!
//! A recursive filter is a chain of dependent multiply-adds per sample, so one column
//! runs at the latency of that chain, not at the machine's throughput. Here up to [`width`]
//! columns go through the filter together, sample by sample, each keeping its own state
//! in one lane of small arrays the compiler turns into vector instructions: the chains
//! of the columns overlap. Every lane performs exactly the operations, in the same order,
//! of the one-column reference (`lfilter_norm`, `sosfilt_norm` run forward and backward
//! over scipy's odd extension), so each column's result is bit-for-bit the same whatever
//! the number of lanes it shares a pass with.
//!
//! The filter's state lives in fixed-size arrays (the number of sections or taps and of
//! lanes are constants of each kernel), so that it stays in registers across samples; a
//! state behind a pointer, or a per-sample call, puts a store and a load on the chain and
//! ran the passes 2.7 times slower. A group of one or two columns runs on one or two lanes:
//! a lane of zeros costs the same instructions as a column.

use super::Prepared;

/// Columns filtered together: four (an AVX2 register), or eight where the processor has
/// AVX-512 ([`crate::cpu::wide512`]). The passes are bound by the latency of each section's
/// recurrence, not by arithmetic, so a group of eight costs about what a group of four does;
/// with AVX2's sixteen registers eight lanes spilled the states and ran slower (docs/speed.md
/// §14), AVX-512's thirty-two 8-wide registers hold them.
const LANES: usize = 4;
const LANES_512: usize = 8;

/// How many columns [`filtfilt_slice`] takes together with this filter on this processor:
/// eight for second-order sections on AVX-512, else four. (A transfer function of order 8,
/// MATLAB's `decimate`, ran its eight lanes slower than two groups of four: 1.74 against
/// 1.11 ms for eight EMPS columns.)
pub(super) fn width(prepared: &Prepared) -> usize {
    #[cfg(target_arch = "x86_64")]
    if matches!(prepared, Prepared::Sos { .. }) && crate::cpu::wide512() {
        return LANES_512;
    }
    let _ = prepared;
    LANES
}

/// Kernels are unrolled up to this many second-order sections (a Butterworth or Chebyshev
/// design of order 8); longer cascades run the general loop.
const MAX_FIXED_SECTIONS: usize = 4;

/// Zero-phase filtering of `k ≤ width(prepared)` equal-length columns of `n` samples (already
/// validated, `n > edge`), column `c`'s sample `i` being `at(c, i)`, then slicing
/// `start, start + r, …` of each: the decimated columns. `r = 1, start = 0` is the whole
/// filtered column.
pub(super) fn filtfilt_slice(
    prepared: &Prepared,
    k: usize,
    n: usize,
    at: impl Fn(usize, usize) -> f64,
    edge: usize,
    start: usize,
    r: usize,
) -> Vec<Vec<f64>> {
    debug_assert!((1..=width(prepared)).contains(&k) && n > edge && r >= 1);
    match k {
        1 => group::<1>(prepared, k, n, &at, edge, start, r),
        2 => group::<2>(prepared, k, n, &at, edge, start, r),
        3 | 4 => group::<LANES>(prepared, k, n, &at, edge, start, r),
        _ => group::<LANES_512>(prepared, k, n, &at, edge, start, r),
    }
}

/// One column filtered with zero phase (the whole column: the odd extension cut off again).
pub(super) fn filtfilt_one(prepared: &Prepared, x: &[f64], edge: usize) -> Vec<f64> {
    filtfilt_slice(prepared, 1, x.len(), |_, i| x[i], edge, 0, 1)
        .pop()
        .unwrap_or_default()
}

fn group<const L: usize>(
    prepared: &Prepared,
    k: usize,
    n: usize,
    at: &impl Fn(usize, usize) -> f64,
    edge: usize,
    start: usize,
    r: usize,
) -> Vec<Vec<f64>> {
    let mut buf = odd_ext_lanes::<L>(k, n, at, edge);
    filter_slice(prepared, &mut buf, k, edge, start, r)
}

/// Filters the odd extension `buf` of `k ≤ L` columns with zero phase, in place, and
/// slices `start, start + r, …` of each column's `buf.len() - 2 edge` samples.
fn filter_slice<const L: usize>(
    prepared: &Prepared,
    buf: &mut [[f64; L]],
    k: usize,
    edge: usize,
    start: usize,
    r: usize,
) -> Vec<Vec<f64>> {
    filter(prepared, buf);
    let kept = &buf[edge..buf.len() - edge];
    (0..k)
        .map(|c| kept.iter().skip(start).step_by(r).map(|x| x[c]).collect())
        .collect()
}

/// Forward and backward pass over `buf`, in place, compiled for the processor: eight lanes
/// in one AVX-512 register where it has AVX-512 ([`crate::cpu::wide512`]), four in one
/// AVX2 register where it has AVX2 and FMA ([`crate::cpu::wide_simd`]), else for the
/// baseline x86-64. Rust never fuses a multiply and an add by itself, so every build
/// computes the same IEEE operations in the same order and gives the same results.
fn filter<const L: usize>(prepared: &Prepared, buf: &mut [[f64; L]]) {
    #[cfg(target_arch = "x86_64")]
    let _flush = super::FlushSubnormals::on();
    /// # Safety
    /// The processor must support AVX-512F, AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    unsafe fn wide512<const L: usize>(prepared: &Prepared, buf: &mut [[f64; L]]) {
        filter_in_place(prepared, buf)
    }
    #[cfg(target_arch = "x86_64")]
    if L > LANES && crate::cpu::wide512() {
        // SAFETY: `wide512` has checked that this processor has AVX-512F, AVX2 and FMA.
        return unsafe { wide512(prepared, buf) };
    }
    /// # Safety
    /// The processor must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn wide<const L: usize>(prepared: &Prepared, buf: &mut [[f64; L]]) {
        filter_in_place(prepared, buf)
    }
    #[cfg(target_arch = "x86_64")]
    if crate::cpu::wide_simd() {
        // SAFETY: `wide_simd` has checked that this processor has AVX2 and FMA.
        return unsafe { wide(prepared, buf) };
    }
    filter_in_place(prepared, buf)
}

#[inline(always)]
fn filter_in_place<const L: usize>(prepared: &Prepared, buf: &mut [[f64; L]]) {
    match prepared {
        Prepared::Identity => {}
        Prepared::Sos { sos, zi } => sos_filtfilt(sos, zi, buf),
        Prepared::Ba { b, a, zi } => ba_filtfilt(b, a, zi, buf),
    }
}

/// scipy's odd extension of `k ≤ L` columns (each of length `n > edge`), interleaved; lanes
/// beyond `k` are zero.
fn odd_ext_lanes<const L: usize>(
    k: usize,
    n: usize,
    at: &impl Fn(usize, usize) -> f64,
    edge: usize,
) -> Vec<[f64; L]> {
    let first: [f64; L] = lane(k, |c| at(c, 0));
    let last: [f64; L] = lane(k, |c| at(c, n - 1));
    let mut ext = Vec::with_capacity(n + 2 * edge);
    ext.extend((0..edge).map(|j| lane(k, |c| 2.0 * first[c] - at(c, edge - j))));
    ext.extend((0..n).map(|i| lane(k, |c| at(c, i))));
    ext.extend((1..=edge).map(|i| lane(k, |c| 2.0 * last[c] - at(c, n - 1 - i))));
    ext
}

/// The first `k` lanes from `f`, the others zero.
#[inline(always)]
fn lane<const L: usize>(k: usize, f: impl Fn(usize) -> f64) -> [f64; L] {
    let mut v = [0.0; L];
    for (c, d) in v.iter_mut().enumerate().take(k) {
        *d = f(c);
    }
    v
}

// ---------------------------------------------------------------------------
// Second-order sections
// ---------------------------------------------------------------------------

/// Forward then backward pass through the sections, in place.
#[inline(always)]
fn sos_filtfilt<const L: usize>(sos: &[[f64; 6]], zi: &[[f64; 2]], buf: &mut [[f64; L]]) {
    #[inline(always)]
    fn fixed<const L: usize, const S: usize>(sos: &[[f64; 6]], zi: &[[f64; 2]], buf: &mut [[f64; L]]) {
        if let (Ok(s), Ok(z)) = (<&[[f64; 6]; S]>::try_from(sos), <&[[f64; 2]; S]>::try_from(zi)) {
            sos_pass::<L, S>(s, z, buf, false);
            sos_pass::<L, S>(s, z, buf, true);
        }
    }
    debug_assert_eq!(sos.len(), zi.len());
    const _: () = assert!(MAX_FIXED_SECTIONS == 4);
    match sos.len() {
        1 => fixed::<L, 1>(sos, zi, buf),
        2 => fixed::<L, 2>(sos, zi, buf),
        3 => fixed::<L, 3>(sos, zi, buf),
        4 => fixed::<L, 4>(sos, zi, buf),
        _ => {
            sos_pass_dyn(sos, zi, buf, false);
            sos_pass_dyn(sos, zi, buf, true);
        }
    }
}

/// One sample through the cascade (scipy's `_sosfilt` loop, per lane).
#[inline(always)]
fn sos_step<const L: usize>(c6: &[f64; 6], zs: &mut [[f64; L]; 2], cur: [f64; L]) -> [f64; L] {
    let mut new = [0.0; L];
    for c in 0..L {
        new[c] = c6[0] * cur[c] + zs[0][c];
        zs[0][c] = c6[1] * cur[c] - c6[4] * new[c] + zs[1][c];
        zs[1][c] = c6[2] * cur[c] - c6[5] * new[c];
    }
    new
}

/// Initial states `zi` scaled per lane by the pass's first input `x0`.
#[inline(always)]
fn sos_init<const L: usize>(zi: &[f64; 2], x0: &[f64; L]) -> [[f64; L]; 2] {
    let mut z = [[0.0; L]; 2];
    for c in 0..L {
        z[0][c] = zi[0] * x0[c];
        z[1][c] = zi[1] * x0[c];
    }
    z
}

/// In-place `sosfilt_norm` over `buf` (forward, or backward when `reverse`), the states in
/// registers.
#[inline(always)]
fn sos_pass<const L: usize, const S: usize>(
    sos: &[[f64; 6]; S],
    zi: &[[f64; 2]; S],
    buf: &mut [[f64; L]],
    reverse: bool,
) {
    let Some(&x0) = (if reverse { buf.last() } else { buf.first() }) else {
        return;
    };
    let mut z: [[[f64; L]; 2]; S] = std::array::from_fn(|s| sos_init(&zi[s], &x0));
    #[inline(always)]
    fn step<const L: usize, const S: usize>(
        sos: &[[f64; 6]; S],
        z: &mut [[[f64; L]; 2]; S],
        x: &mut [f64; L],
    ) {
        let mut cur = *x;
        for s in 0..S {
            cur = sos_step(&sos[s], &mut z[s], cur);
        }
        *x = cur;
    }
    if reverse {
        for x in buf.iter_mut().rev() {
            step(sos, &mut z, x);
        }
    } else {
        for x in buf.iter_mut() {
            step(sos, &mut z, x);
        }
    }
}

/// The same for any number of sections.
#[inline(always)]
fn sos_pass_dyn<const L: usize>(sos: &[[f64; 6]], zi: &[[f64; 2]], buf: &mut [[f64; L]], reverse: bool) {
    let Some(&x0) = (if reverse { buf.last() } else { buf.first() }) else {
        return;
    };
    let mut z: Vec<[[f64; L]; 2]> = zi.iter().map(|v| sos_init(v, &x0)).collect();
    #[inline(always)]
    fn step<const L: usize>(sos: &[[f64; 6]], z: &mut [[[f64; L]; 2]], x: &mut [f64; L]) {
        let mut cur = *x;
        for (c6, zs) in sos.iter().zip(z.iter_mut()) {
            cur = sos_step(c6, zs, cur);
        }
        *x = cur;
    }
    if reverse {
        for x in buf.iter_mut().rev() {
            step(sos, &mut z, x);
        }
    } else {
        for x in buf.iter_mut() {
            step(sos, &mut z, x);
        }
    }
}

// ---------------------------------------------------------------------------
// Transfer function (direct form II transposed)
// ---------------------------------------------------------------------------

/// Kernels are unrolled up to this many states (taps − 1: MATLAB's `decimate` filter of
/// order 8); longer filters run the general loop.
const MAX_FIXED_STATES: usize = 8;

/// Forward then backward pass of `lfilter_norm` (`b`, `a` normalised, of equal length), in
/// place.
#[inline(always)]
fn ba_filtfilt<const L: usize>(b: &[f64], a: &[f64], zi: &[f64], buf: &mut [[f64; L]]) {
    #[inline(always)]
    fn fixed<const L: usize, const M: usize>(b: &[f64], a: &[f64], zi: &[f64], buf: &mut [[f64; L]]) {
        ba_pass::<L, M>(b, a, zi, buf, false);
        ba_pass::<L, M>(b, a, zi, buf, true);
    }
    let n = b.len().min(a.len());
    if n <= 1 {
        let b0 = b.first().copied().unwrap_or(f64::NAN);
        for _ in 0..2 {
            for x in buf.iter_mut() {
                for v in x.iter_mut() {
                    *v *= b0;
                }
            }
        }
        return;
    }
    const _: () = assert!(MAX_FIXED_STATES == 8);
    match n - 1 {
        1 => fixed::<L, 1>(b, a, zi, buf),
        2 => fixed::<L, 2>(b, a, zi, buf),
        3 => fixed::<L, 3>(b, a, zi, buf),
        4 => fixed::<L, 4>(b, a, zi, buf),
        5 => fixed::<L, 5>(b, a, zi, buf),
        6 => fixed::<L, 6>(b, a, zi, buf),
        7 => fixed::<L, 7>(b, a, zi, buf),
        8 => fixed::<L, 8>(b, a, zi, buf),
        _ => {
            ba_pass_dyn(b, a, zi, buf, false);
            ba_pass_dyn(b, a, zi, buf, true);
        }
    }
}

/// In-place `lfilter_norm` with `M` states (`M + 1` coefficients in `b` and `a`) and initial
/// state `zi · x0` (missing `zi` entries zero), the states in registers.
#[inline(always)]
fn ba_pass<const L: usize, const M: usize>(
    b: &[f64],
    a: &[f64],
    zi: &[f64],
    buf: &mut [[f64; L]],
    reverse: bool,
) {
    let (Some(b), Some(a)) = (b.get(..=M), a.get(..=M)) else {
        return;
    };
    let Some(&x0) = (if reverse { buf.last() } else { buf.first() }) else {
        return;
    };
    let mut z = [[0.0; L]; M];
    for (d, v) in z.iter_mut().zip(zi) {
        for c in 0..L {
            d[c] = v * x0[c];
        }
    }
    #[inline(always)]
    fn step<const L: usize, const M: usize>(b: &[f64], a: &[f64], z: &mut [[f64; L]; M], x: &mut [f64; L]) {
        let xn = *x;
        let last = M - 1;
        let mut yn = [0.0; L];
        for c in 0..L {
            yn[c] = z[0][c] + b[0] * xn[c];
        }
        for i in 0..last {
            for c in 0..L {
                z[i][c] = z[i + 1][c] + xn[c] * b[i + 1] - yn[c] * a[i + 1];
            }
        }
        for c in 0..L {
            z[last][c] = xn[c] * b[last + 1] - yn[c] * a[last + 1];
        }
        *x = yn;
    }
    if reverse {
        for x in buf.iter_mut().rev() {
            step(b, a, &mut z, x);
        }
    } else {
        for x in buf.iter_mut() {
            step(b, a, &mut z, x);
        }
    }
}

/// The same for any number of states (at least one).
#[inline(always)]
fn ba_pass_dyn<const L: usize>(b: &[f64], a: &[f64], zi: &[f64], buf: &mut [[f64; L]], reverse: bool) {
    let Some(&x0) = (if reverse { buf.last() } else { buf.first() }) else {
        return;
    };
    let n = b.len().min(a.len());
    let mut z = vec![[0.0; L]; n - 1];
    for (d, v) in z.iter_mut().zip(zi) {
        for c in 0..L {
            d[c] = v * x0[c];
        }
    }
    #[inline(always)]
    fn step<const L: usize>(b: &[f64], a: &[f64], z: &mut [[f64; L]], x: &mut [f64; L]) {
        let xn = *x;
        let last = z.len() - 1;
        let mut yn = [0.0; L];
        for c in 0..L {
            yn[c] = z[0][c] + b[0] * xn[c];
        }
        for i in 0..last {
            let (lo, hi) = z.split_at_mut(i + 1);
            for c in 0..L {
                lo[i][c] = hi[0][c] + xn[c] * b[i + 1] - yn[c] * a[i + 1];
            }
        }
        for c in 0..L {
            z[last][c] = xn[c] * b[last + 1] - yn[c] * a[last + 1];
        }
        *x = yn;
    }
    if reverse {
        for x in buf.iter_mut().rev() {
            step(b, a, &mut z, x);
        }
    } else {
        for x in buf.iter_mut() {
            step(b, a, &mut z, x);
        }
    }
}
