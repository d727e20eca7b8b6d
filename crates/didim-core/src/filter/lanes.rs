//! Column-interleaved zero-phase filtering for the parallel decimation.
//!
//! A recursive filter is a chain of dependent multiply-adds per sample, so one column
//! runs at the latency of that chain, not at the machine's throughput. Here `LANES`
//! columns go through the filter together, sample by sample, each keeping its own state
//! in one lane of small arrays the compiler turns into vector instructions: the chains
//! of the columns overlap. Every lane performs exactly the operations, in the same order,
//! of the one-column code (`lfilter_norm`, `sosfilt_norm`, `filtfilt_core`,
//! `sosfiltfilt_core`), so each column's result is bit-for-bit the same.

use super::Prepared;

/// Columns filtered together.
pub(super) const LANES: usize = 4;

type Lane = [f64; LANES];

/// scipy's odd extension of up to `LANES` columns (each of length `n`), interleaved.
fn odd_ext_lanes(cols: &[&[f64]], edge: usize) -> Vec<Lane> {
    let n = cols[0].len();
    let mut ext = vec![[0.0; LANES]; n + 2 * edge];
    for (c, x) in cols.iter().enumerate() {
        let (first, last) = (x[0], x[n - 1]);
        for k in 0..edge {
            ext[k][c] = 2.0 * first - x[edge - k];
        }
        for (i, &v) in x.iter().enumerate() {
            ext[edge + i][c] = v;
        }
        for i in 1..=edge {
            ext[edge + n - 1 + i][c] = 2.0 * last - x[n - 1 - i];
        }
    }
    ext
}

/// In-place `sosfilt_norm` over `buf` (forward, or backward when `reverse`), initial
/// states `zi` scaled per lane by `x0`.
#[inline(always)]
fn sos_pass<const S: usize>(sos: &[[f64; 6]; S], zi: &[[f64; 2]; S], buf: &mut [Lane], reverse: bool) {
    let x0 = if reverse { buf[buf.len() - 1] } else { buf[0] };
    let mut z = [[[0.0; LANES]; 2]; S];
    for s in 0..S {
        for c in 0..LANES {
            z[s][0][c] = zi[s][0] * x0[c];
            z[s][1][c] = zi[s][1] * x0[c];
        }
    }
    let mut step = |x: &mut Lane| {
        let mut cur = *x;
        for s in 0..S {
            let c6 = &sos[s];
            let zs = &mut z[s];
            let mut new = [0.0; LANES];
            for c in 0..LANES {
                new[c] = c6[0] * cur[c] + zs[0][c];
                zs[0][c] = c6[1] * cur[c] - c6[4] * new[c] + zs[1][c];
                zs[1][c] = c6[2] * cur[c] - c6[5] * new[c];
            }
            cur = new;
        }
        *x = cur;
    };
    if reverse {
        buf.iter_mut().rev().for_each(&mut step);
    } else {
        buf.iter_mut().for_each(&mut step);
    }
}

/// The same for any number of sections (slices instead of arrays).
fn sos_pass_dyn(sos: &[[f64; 6]], zi: &[[f64; 2]], buf: &mut [Lane], reverse: bool) {
    let x0 = if reverse { buf[buf.len() - 1] } else { buf[0] };
    let mut z: Vec<[Lane; 2]> = zi
        .iter()
        .map(|v| {
            let mut s = [[0.0; LANES]; 2];
            for c in 0..LANES {
                s[0][c] = v[0] * x0[c];
                s[1][c] = v[1] * x0[c];
            }
            s
        })
        .collect();
    let mut step = |x: &mut Lane| {
        let mut cur = *x;
        for (c6, zs) in sos.iter().zip(z.iter_mut()) {
            let mut new = [0.0; LANES];
            for c in 0..LANES {
                new[c] = c6[0] * cur[c] + zs[0][c];
                zs[0][c] = c6[1] * cur[c] - c6[4] * new[c] + zs[1][c];
                zs[1][c] = c6[2] * cur[c] - c6[5] * new[c];
            }
            cur = new;
        }
        *x = cur;
    };
    if reverse {
        buf.iter_mut().rev().for_each(&mut step);
    } else {
        buf.iter_mut().for_each(&mut step);
    }
}

/// In-place `lfilter_norm` (direct form II transposed) with initial state `zi · x0`.
fn ba_pass(b: &[f64], a: &[f64], zi: &[f64], buf: &mut [Lane], reverse: bool) {
    let x0 = if reverse { buf[buf.len() - 1] } else { buf[0] };
    let n = b.len().min(a.len());
    if n <= 1 {
        let b0 = b.first().copied().unwrap_or(f64::NAN);
        for x in buf.iter_mut() {
            for c in 0..LANES {
                x[c] *= b0;
            }
        }
        return;
    }
    let mut z = vec![[0.0; LANES]; n - 1];
    for (d, v) in z.iter_mut().zip(zi) {
        for c in 0..LANES {
            d[c] = v * x0[c];
        }
    }
    let last = n - 2;
    let mut step = |x: &mut Lane| {
        let xn = *x;
        let mut yn = [0.0; LANES];
        for c in 0..LANES {
            yn[c] = z[0][c] + b[0] * xn[c];
        }
        for i in 0..last {
            let (lo, hi) = z.split_at_mut(i + 1);
            for c in 0..LANES {
                lo[i][c] = hi[0][c] + xn[c] * b[i + 1] - yn[c] * a[i + 1];
            }
        }
        for c in 0..LANES {
            z[last][c] = xn[c] * b[last + 1] - yn[c] * a[last + 1];
        }
        *x = yn;
    };
    if reverse {
        buf.iter_mut().rev().for_each(&mut step);
    } else {
        buf.iter_mut().for_each(&mut step);
    }
}

/// Zero-phase filtering of up to `LANES` equal-length columns (already validated, longer
/// than `edge`) and slicing `start, start + r, …` of each; the decimated columns.
pub(super) fn filtfilt_slice(
    prepared: &Prepared,
    cols: &[&[f64]],
    edge: usize,
    start: usize,
    r: usize,
) -> Vec<Vec<f64>> {
    debug_assert!(!cols.is_empty() && cols.len() <= LANES);
    let mut buf = odd_ext_lanes(cols, edge);
    match prepared {
        Prepared::Identity => {}
        Prepared::Sos { sos, zi } => match (sos.as_slice(), zi.as_slice()) {
            // The common designs get the sections unrolled.
            (s, z) if s.len() == 2 => {
                let (s, z): (&[[f64; 6]; 2], &[[f64; 2]; 2]) = (s.try_into().unwrap(), z.try_into().unwrap());
                sos_pass(s, z, &mut buf, false);
                sos_pass(s, z, &mut buf, true);
            }
            (s, z) if s.len() == 4 => {
                let (s, z): (&[[f64; 6]; 4], &[[f64; 2]; 4]) = (s.try_into().unwrap(), z.try_into().unwrap());
                sos_pass(s, z, &mut buf, false);
                sos_pass(s, z, &mut buf, true);
            }
            (s, z) => {
                sos_pass_dyn(s, z, &mut buf, false);
                sos_pass_dyn(s, z, &mut buf, true);
            }
        },
        Prepared::Ba { b, a, zi } => {
            ba_pass(b, a, zi, &mut buf, false);
            ba_pass(b, a, zi, &mut buf, true);
        }
    }
    let n = cols[0].len();
    let kept = &buf[edge..edge + n];
    (0..cols.len())
        .map(|c| kept.iter().skip(start).step_by(r).map(|x| x[c]).collect())
        .collect()
}
