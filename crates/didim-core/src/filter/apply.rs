//! Applying a filter: causal (`lfilter`, `sosfilt` and their steady states) and zero-phase (`filtfilt`, `sosfiltfilt`).

use super::*;
use super::{lanes, Prepared};

/// Filters `x` with `tf` (direct form II transposed), like
/// `scipy.signal.lfilter(tf.b, tf.a, x, zi=zi)` (returns `y` only).
///
/// Coefficients are normalised by `a[0]`; `b` and `a` are zero-padded to the
/// same length `n`, and the state has `n - 1` entries. `zi` is the initial
/// state (e.g. `lfilter_zi(tf)` scaled by `x[0]`); `None` means zero.
/// Surplus `zi` entries are ignored and missing ones taken as zero. A
/// malformed `tf` (empty `b` or `a`, `a[0] == 0`) yields all-NaN output; use
/// [`filtfilt`] for validated filtering.
pub fn lfilter(tf: &Tf, x: &[f64], zi: Option<&[f64]>) -> Vec<f64> {
    // an impulse response (a controller's free response) decays through subnormal numbers: 5 times the cost
    #[cfg(target_arch = "x86_64")]
    let _flush = FlushSubnormals::on();
    match normalized_ba(&tf.b, &tf.a) {
        Some((b, a)) => lfilter_norm(&b, &a, x, zi),
        None => vec![f64::NAN; x.len()],
    }
}

/// Steady-state initial state of [`lfilter`] for a unit step input, like
/// `scipy.signal.lfilter_zi(tf.b, tf.a)`: scale it by `x[0]` to start a
/// filter "as if the signal had always been `x[0]`" (used by [`filtfilt`]).
///
/// Length `max(len(a), len(b)) - 1` (after dropping leading zeros of `a`); the
/// coefficients normalised by `a[0]`, as in scipy. Returns NaNs if the filter
/// has no steady state (a pole at `z = 1`) or is malformed.
pub fn lfilter_zi(tf: &Tf) -> Vec<f64> {
    lfilter_zi_checked(&tf.b, &tf.a)
        .unwrap_or_else(|_| vec![f64::NAN; tf.b.len().max(tf.a.len()).saturating_sub(1)])
}

/// Filters `x` through the cascade `sos`, like `scipy.signal.sosfilt(sos, x,
/// zi=zi)` (returns `y` only). `zi` holds the two states of each section
/// (`sosfilt_zi(sos)` scaled by `x[0]` for a steady start); `None` means zero,
/// missing sections are zero. Sections with `a0 != 1` are normalised by `a0`;
/// a section with `a0 == 0` makes the output NaN. No sections: `y = x`.
pub fn sosfilt(sos: &Sos, x: &[f64], zi: Option<&[[f64; 2]]>) -> Vec<f64> {
    #[cfg(target_arch = "x86_64")]
    let _flush = FlushSubnormals::on();
    match normalized_sos(sos) {
        Some(s) => sosfilt_norm(&s, x, zi),
        None => vec![f64::NAN; x.len()],
    }
}

/// Steady-state initial states of [`sosfilt`] for a unit step, like
/// `scipy.signal.sosfilt_zi(sos)`: each section's [`lfilter_zi`] scaled by
/// the DC gain of the sections before it. NaN if a section has a pole at
/// `z = 1` or is malformed.
pub fn sosfilt_zi(sos: &Sos) -> Vec<[f64; 2]> {
    sosfilt_zi_checked(sos).unwrap_or_else(|_| vec![[f64::NAN; 2]; sos.0.len()])
}

/// `b`, `a` zero-padded to the same length and divided by `a[0]` (scipy's
/// `_linear_filter`). `None` if empty or `a[0] == 0`.
pub(super) fn normalized_ba(b: &[f64], a: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
    let a0 = *a.first()?;
    if b.is_empty() || a0 == 0.0 {
        return None;
    }
    let n = a.len().max(b.len());
    let mut bb = vec![0.0; n];
    let mut aa = vec![0.0; n];
    bb[..b.len()].copy_from_slice(b);
    aa[..a.len()].copy_from_slice(a);
    if a0 != 1.0 {
        for v in bb.iter_mut().chain(aa.iter_mut()) {
            *v /= a0;
        }
    }
    Some((bb, aa))
}

/// Direct form II transposed with the exact operation order of scipy's C
/// `_linear_filter`; `b`, `a` of equal length with `a[0] == 1`.
pub(super) fn lfilter_norm(b: &[f64], a: &[f64], x: &[f64], zi: Option<&[f64]>) -> Vec<f64> {
    let n = b.len().min(a.len());
    let mut z = vec![0.0; n.saturating_sub(1)];
    if let Some(zi) = zi {
        for (d, s) in z.iter_mut().zip(zi) {
            *d = *s;
        }
    }
    let mut y = Vec::with_capacity(x.len());
    if n <= 1 {
        let b0 = b.first().copied().unwrap_or(f64::NAN);
        y.extend(x.iter().map(|&xn| xn * b0));
        return y;
    }
    let last = n - 2;
    for &xn in x {
        let yn = z[0] + b[0] * xn;
        for i in 0..last {
            z[i] = z[i + 1] + xn * b[i + 1] - yn * a[i + 1];
        }
        z[last] = xn * b[last + 1] - yn * a[last + 1];
        y.push(yn);
    }
    y
}

pub(super) fn lfilter_zi_checked(b: &[f64], a: &[f64]) -> Result<Vec<f64>> {
    let first = a
        .iter()
        .position(|&v| v != 0.0)
        .unwrap_or(a.len().saturating_sub(1));
    let a = a.get(first..).unwrap_or(&[]);
    let (b, a) = normalized_ba(b, a).ok_or_else(|| {
        invalid!("filter coefficients are malformed: b and a must be non-empty with a[0] != 0")
    })?;
    let n = a.len();
    let m = n - 1;
    if m == 0 {
        return Ok(Vec::new());
    }
    // I - companion(a).T, column-major, exactly as numpy forms it.
    let mut mat = vec![0.0; m * m];
    for r in 0..m {
        mat[r] = if r == 0 { 1.0 - (-a[1]) } else { 0.0 - (-a[r + 1]) };
        if r >= 1 {
            mat[r * m + r] = 1.0;
        }
        if r + 1 < m {
            mat[(r + 1) * m + r] = -1.0;
        }
    }
    let rhs: Vec<f64> = (0..m).map(|i| b[i + 1] - a[i + 1] * b[0]).collect();
    solve(mat, m, &rhs).ok_or_else(|| {
        invalid!(
            "the filter has a pole at z = 1 (sum(a) = 0): it has no steady state, so lfilter_zi/filtfilt cannot initialise it; check the coefficients"
        )
    })
}

/// Sections divided by their `a0`; `None` if some `a0 == 0`.
pub(super) fn normalized_sos(sos: &Sos) -> Option<Vec<[f64; 6]>> {
    sos.0
        .iter()
        .map(|s| {
            let a0 = s[3];
            if a0 == 0.0 {
                None
            } else if a0 == 1.0 {
                Some(*s)
            } else {
                Some(s.map(|v| v / a0))
            }
        })
        .collect()
}

/// scipy's Cython `_sosfilt` loop.
pub(super) fn sosfilt_norm(sos: &[[f64; 6]], x: &[f64], zi: Option<&[[f64; 2]]>) -> Vec<f64> {
    let mut z = vec![[0.0; 2]; sos.len()];
    if let Some(zi) = zi {
        for (d, s) in z.iter_mut().zip(zi) {
            *d = *s;
        }
    }
    let mut y = Vec::with_capacity(x.len());
    for &xn in x {
        let mut cur = xn;
        for (s, zs) in sos.iter().zip(z.iter_mut()) {
            let new = s[0] * cur + zs[0];
            zs[0] = s[1] * cur - s[4] * new + zs[1];
            zs[1] = s[2] * cur - s[5] * new;
            cur = new;
        }
        y.push(cur);
    }
    y
}

pub(super) fn sosfilt_zi_checked(sos: &Sos) -> Result<Vec<[f64; 2]>> {
    let mut out = Vec::with_capacity(sos.0.len());
    let mut scale = 1.0;
    for s in &sos.0 {
        let zi = lfilter_zi_checked(&s[..3], &s[3..])?;
        out.push([
            scale * zi.first().copied().unwrap_or(0.0),
            scale * zi.get(1).copied().unwrap_or(0.0),
        ]);
        scale *= (s[0] + s[1] + s[2]) / (s[3] + s[4] + s[5]);
    }
    Ok(out)
}

// ---------------------------------------------------------------------------
// Zero-phase filtering
// ---------------------------------------------------------------------------

/// Zero-phase filtering of `x` with `tf` (forward and backward passes), exactly
/// `scipy.signal.filtfilt(tf.b, tf.a, x, padtype='odd', padlen=padlen)`:
/// `x` is extended at both ends by `padlen` samples of odd reflection
/// (`2*x[0] - x[padlen..0]`, `2*x[n-1] - x[n-2..]`), each pass starts from
/// the steady state [`lfilter_zi`] scaled by its first input, and the
/// extension is cut off again. The result has the length of `x`, no phase
/// shift and the squared magnitude response of `tf` (paper section III).
///
/// `padlen = None` is scipy's default `3 * max(len(a), len(b))`; MATLAB's
/// `filtfilt` uses `3 * (max(len(a), len(b)) - 1)`: pass `Some(that)` to
/// reproduce it. Errors (`InvalidInput`) if `x.len() <= padlen` (record too
/// short for this filter), if `x` has a non-finite value, if `tf` is
/// malformed or has a pole at `z = 1`, or if the output overflows (an unstable
/// filter, or a gain or signal too large for `f64`): the result is always finite. See the module documentation on the
/// conditioning of high-order ba filters at low cutoffs.
pub fn filtfilt(tf: &Tf, x: &[f64], padlen: Option<usize>) -> Result<Vec<f64>> {
    validate_tf(tf)?;
    let ntaps = tf.a.len().max(tf.b.len());
    let edge = padlen.unwrap_or(ntaps.saturating_mul(3));
    check_record(
        x,
        edge,
        "x",
        &format!("len(a) = {}, len(b) = {}", tf.a.len(), tf.b.len()),
    )?;
    let zi = lfilter_zi_checked(&tf.b, &tf.a)?;
    let (b, a) = normalized_ba(&tf.b, &tf.a).ok_or_else(|| invalid!("filter coefficients are malformed"))?;
    finite_output(lanes::filtfilt_one(&Prepared::Ba { b, a, zi }, x, edge), "x")
}

/// The filtered signal, or an error when it is not finite: the filter is unstable or its gain (after dividing by
/// `a[0]`) is so large, or the signal so large, that the passes overflow. Never returns NaN silently.
pub(super) fn finite_output(y: Vec<f64>, name: &str) -> Result<Vec<f64>> {
    match y.iter().position(|v| !v.is_finite()) {
        None => Ok(y),
        Some(i) => Err(invalid!(
            "filtering {name} overflowed (non-finite output at index {i}): the filter is unstable, or its gain or the \
             signal is too large for f64; check the coefficients (a[0] normalises them) and rescale the signal"
        )),
    }
}

/// Zero-phase filtering through second-order sections, exactly
/// `scipy.signal.sosfiltfilt(sos, x, padtype='odd', padlen=padlen)`: the
/// same scheme as [`filtfilt`] with [`sosfilt`] and [`sosfilt_zi`].
///
/// `padlen = None` is scipy's default `3 * ntaps` with
/// `ntaps = 2 * n_sections + 1 - min(#{b2 == 0}, #{a2 == 0})` (so `3 * (N + 1)`
/// for an order-`N` design). Errors like [`filtfilt`] (too short record,
/// non-finite `x`, malformed `sos`: no section, non-finite coefficient or
/// `a0 == 0`, a section with a pole at `z = 1`). Paper section III.
pub fn sosfiltfilt(sos: &Sos, x: &[f64], padlen: Option<usize>) -> Result<Vec<f64>> {
    let norm = validate_sos(sos)?;
    let edge = padlen.unwrap_or_else(|| sos_default_padlen(&norm));
    check_record(x, edge, "x", &format!("{} second-order sections", norm.len()))?;
    let zi = sosfilt_zi_checked(sos)?;
    finite_output(
        lanes::filtfilt_one(&Prepared::Sos { sos: norm, zi }, x, edge),
        "x",
    )
}

pub(super) fn sos_default_padlen(sos: &[[f64; 6]]) -> usize {
    let zb = sos.iter().filter(|s| s[2] == 0.0).count();
    let za = sos.iter().filter(|s| s[5] == 0.0).count();
    let ntaps = (2 * sos.len() + 1).saturating_sub(zb.min(za));
    3 * ntaps
}

pub(super) fn validate_tf(tf: &Tf) -> Result<()> {
    if tf.b.is_empty() || tf.a.is_empty() {
        return Err(invalid!(
            "filter tf is malformed: b has {} and a has {} coefficients, both need at least one",
            tf.b.len(),
            tf.a.len()
        ));
    }
    if let Some(i) = tf.b.iter().position(|v| !v.is_finite()) {
        return Err(invalid!("filter tf.b[{i}] = {} is not finite", tf.b[i]));
    }
    if let Some(i) = tf.a.iter().position(|v| !v.is_finite()) {
        return Err(invalid!("filter tf.a[{i}] = {} is not finite", tf.a[i]));
    }
    if tf.a[0] == 0.0 {
        return Err(invalid!(
            "filter tf.a[0] is 0; the leading denominator coefficient must be non-zero (normally 1)"
        ));
    }
    Ok(())
}

pub(super) fn validate_sos(sos: &Sos) -> Result<Vec<[f64; 6]>> {
    if sos.0.is_empty() {
        return Err(invalid!(
            "sos has no sections; design one with butter_sos or cheby1_sos"
        ));
    }
    for (i, s) in sos.0.iter().enumerate() {
        if let Some(j) = s.iter().position(|v| !v.is_finite()) {
            return Err(invalid!(
                "sos section {i} coefficient {j} = {} is not finite",
                s[j]
            ));
        }
        if s[3] == 0.0 {
            return Err(invalid!(
                "sos section {i} has a0 = 0; each row must be [b0, b1, b2, 1, a1, a2]"
            ));
        }
    }
    normalized_sos(sos).ok_or_else(|| invalid!("sos has a section with a0 = 0"))
}

/// Length and finiteness checks of a record to be filtered with padding `edge`.
pub(super) fn check_record(x: &[f64], edge: usize, name: &str, filter: &str) -> Result<()> {
    if x.len() <= edge {
        return Err(invalid!(
            "{name} has {} samples, but the record is too short for this filter ({filter}): zero-phase filtering pads {edge} samples at each end and needs more than {edge} samples; use a longer record, a lower order or a smaller padlen",
            x.len()
        ));
    }
    // an infinite or NaN value has every exponent bit set: an OR over the samples, which the compiler vectorizes
    // (`position`'s early exit is a branch per sample, 2 % of the EMPS doctor's time); the index only on failure
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    if x.iter()
        .fold(0u64, |acc, v| acc | u64::from(v.to_bits() & EXPONENT == EXPONENT))
        == 0
    {
        return Ok(());
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(invalid!(
            "{name} has a non-finite value at index {i} ({}); remove or interpolate non-finite samples before filtering",
            x[i]
        ));
    }
    Ok(())
}

// The one-column reference of the zero-phase filters: what the kernels of `lanes` compute,
// lane by lane, in the same operation order (the tests compare them bit for bit).

/// scipy's `odd_ext(x, n)`.
#[cfg(test)]
pub(super) fn odd_ext(x: &[f64], n: usize) -> Vec<f64> {
    let len = x.len();
    if n == 0 || len == 0 {
        return x.to_vec();
    }
    let (first, last) = (x[0], x[len - 1]);
    let mut ext = Vec::with_capacity(len + 2 * n);
    ext.extend((1..=n).rev().map(|i| 2.0 * first - x[i]));
    ext.extend_from_slice(x);
    ext.extend((1..=n).map(|i| 2.0 * last - x[len - 1 - i]));
    ext
}

/// Forward-backward pass; `b`, `a` normalised, `x.len() > edge`.
#[cfg(test)]
pub(super) fn filtfilt_core(b: &[f64], a: &[f64], zi: &[f64], x: &[f64], edge: usize) -> Vec<f64> {
    let ext = odd_ext(x, edge);
    let x0 = ext.first().copied().unwrap_or(0.0);
    let z: Vec<f64> = zi.iter().map(|v| v * x0).collect();
    let mut y = lfilter_norm(b, a, &ext, Some(&z));
    let y0 = y.last().copied().unwrap_or(0.0);
    y.reverse();
    let z: Vec<f64> = zi.iter().map(|v| v * y0).collect();
    let mut y = lfilter_norm(b, a, &y, Some(&z));
    y.reverse();
    y.get(edge..y.len() - edge)
        .map(<[f64]>::to_vec)
        .unwrap_or_default()
}

/// Forward-backward pass through sections; `x.len() > edge`.
#[cfg(test)]
pub(super) fn sosfiltfilt_core(sos: &[[f64; 6]], zi: &[[f64; 2]], x: &[f64], edge: usize) -> Vec<f64> {
    let ext = odd_ext(x, edge);
    let x0 = ext.first().copied().unwrap_or(0.0);
    let z: Vec<[f64; 2]> = zi.iter().map(|v| [v[0] * x0, v[1] * x0]).collect();
    let mut y = sosfilt_norm(sos, &ext, Some(&z));
    let y0 = y.last().copied().unwrap_or(0.0);
    y.reverse();
    let z: Vec<[f64; 2]> = zi.iter().map(|v| [v[0] * y0, v[1] * y0]).collect();
    let mut y = sosfilt_norm(sos, &y, Some(&z));
    y.reverse();
    y.get(edge..y.len() - edge)
        .map(<[f64]>::to_vec)
        .unwrap_or_default()
}
