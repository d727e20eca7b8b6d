//! Zero-phase low-pass filtering and parallel decimation (paper section III).
//!
//! DIDIM estimates the parameters from the motor force and the states sampled
//! at the controller rate. Before the least-squares step the measured force
//! `Y` and every column of the regressor `W` are low-pass filtered *with the
//! same filter* and resampled ("parallel decimation", paper section III): a
//! zero-phase (forward-backward) low-pass filter removes the high-frequency
//! content without phase shift, then one sample in `r` is kept. Filtering `Y`
//! and `W` identically keeps the linear relation `Y = W·θ` intact.
//!
//! This module provides, with the conventions of `scipy.signal`:
//!
//! - filter design: [`butter`], [`cheby1`] (transfer function, "ba" form) and
//!   [`butter_sos`], [`cheby1_sos`] (second-order sections), built like scipy:
//!   analog prototype → prewarping → low-pass scaling → bilinear transform →
//!   polynomial expansion (ba) or conjugate-pole pairing (sos);
//! - causal filtering: [`lfilter`], [`lfilter_zi`], [`sosfilt`], [`sosfilt_zi`];
//! - zero-phase filtering: [`filtfilt`], [`sosfiltfilt`] (odd extension at both
//!   ends, steady-state initial conditions, forward then backward pass);
//! - decimation: [`Decimation`] (Butterworth with scipy's conventions, or
//!   MATLAB's `decimate(x, r)`), [`Decimation::apply_parallel`] for `Y` and `W`,
//!   and [`default_factor`].
//!
//! # Which form: ba or sos
//!
//! The ba (transfer-function) form of a high-order filter with a low
//! normalised cutoff is numerically ill-conditioned: its poles crowd near
//! `z = 1`, the denominator sums to a tiny number (`Σa = Π(1 − p_i)`), and the
//! output reacts to the last bit of the coefficients. Relative change of the
//! [`filtfilt`] output of a Butterworth design when its ba coefficients move
//! by one ulp (measured on the test signal):
//!
//! | order | wn = 0.2 | 0.1   | 0.05  | 0.02  | 0.01  |
//! |-------|----------|-------|-------|-------|-------|
//! | 2     | 3e-15    | 1e-14 | 6e-14 | 3e-13 | 1e-12 |
//! | 4     | 2e-14    | 5e-13 | 6e-12 | 2e-10 | 3e-9  |
//! | 6     | 2e-13    | 1e-11 | 1e-9  | 2e-7  | 1e-5  |
//! | 8     | 1e-12    | 4e-10 | 7e-8  | 1e-4  | 4e-2  |
//!
//! MATLAB's `decimate` filter (Chebyshev I order 8 at `wn = 0.8/r`) is at 3e-8
//! for `r = 10` and 2.4e-7 for `r = 13`. Rounding inside the filter is
//! amplified the same way, so different implementations agree only to that
//! level, and beyond about 1e-6 the ba filter is no longer the designed one.
//! Prefer [`FilterForm::Sos`] / [`sosfiltfilt`] (a cascade of biquads keeps
//! full accuracy) unless the goal is to reproduce a ba-form result of scipy or
//! MATLAB; it is needed for orders of 6 or more below `wn ≈ 0.1` (decimation
//! factors above about 8 with MATLAB's cutoff `0.8/r`) and for order 4 below
//! `wn ≈ 0.02`.
//!
//! # Reproducing scipy and MATLAB
//!
//! The designs follow scipy's operation order, so on glibc platforms the
//! coefficients agree with scipy to the last bit (scipy's own results can
//! differ by an ulp between machines, e.g. when numpy uses SVML for `tan`).
//! The filters and [`lfilter_zi`]'s steady-state solve (an LU with partial
//! pivoting, as LAPACK's but in another operation order) agree with scipy to
//! the conditioning above: to rounding for sos and well-conditioned ba
//! filters, to the ill-conditioned ba filter's sensitivity otherwise. The
//! tests derive their tolerances from it.
//! MATLAB's `filtfilt` is the same algorithm with a padding of
//! `3*(max(len(a), len(b)) - 1)` samples (pass it explicitly) and a different
//! but equivalent steady-state solve.

use crate::error::{invalid, Error, Result};
use rayon::prelude::*;
use std::f64::consts::PI;

mod apply;
mod decimate;
mod design;
mod lanes;
mod numeric;
#[cfg(test)]
mod tests;

mod flush;

pub use apply::*;
pub use decimate::*;
pub use design::*;
#[cfg(target_arch = "x86_64")]
pub(crate) use flush::FlushSubnormals;
use numeric::*;

/// Highest filter order accepted by the design functions.
pub const MAX_ORDER: usize = 20;

/// Digital filter in transfer-function ("ba") form,
/// `H(z) = (b[0] + b[1] z⁻¹ + …) / (a[0] + a[1] z⁻¹ + …)`.
///
/// The designs of this module return `a[0] == 1`. The filtering functions
/// accept any `a[0] != 0` and normalise by it, like scipy.
#[derive(Debug, Clone, PartialEq)]
pub struct Tf {
    /// Numerator coefficients, in increasing powers of `z⁻¹`.
    pub b: Vec<f64>,
    /// Denominator coefficients, in increasing powers of `z⁻¹`; `a[0] == 1`.
    pub a: Vec<f64>,
}

/// Digital filter as a cascade of second-order sections, one row per section
/// `[b0, b1, b2, a0, a1, a2]` with `a0 == 1` (scipy's `sos` layout). A
/// first-order section has `b2 == a2 == 0`.
#[derive(Debug, Clone, PartialEq)]
pub struct Sos(pub Vec<[f64; 6]>);

impl Sos {
    /// The sections, in filtering order.
    pub fn sections(&self) -> &[[f64; 6]] {
        &self.0
    }

    /// Number of sections.
    pub fn n_sections(&self) -> usize {
        self.0.len()
    }
}

/// Representation used for a zero-phase filter of a [`Decimation`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterForm {
    /// Transfer function, filtered with [`filtfilt`] (ill-conditioned at low
    /// cutoffs, see the module documentation).
    Ba,
    /// Second-order sections, filtered with [`sosfiltfilt`] (recommended).
    Sos,
}

/// A zero-phase low-pass filter: the filter and the function that applies it
/// ([`filtfilt`] for `Ba`, [`sosfiltfilt`] for `Sos`).
#[derive(Debug, Clone, PartialEq)]
pub enum ZeroPhase {
    /// Transfer function, applied with [`filtfilt`].
    Ba(Tf),
    /// Second-order sections, applied with [`sosfiltfilt`].
    Sos(Sos),
}

/// `|P(e^{-jω})|²` of the polynomial `p[0] + p[1] z⁻¹ + …` at `ω` (rad per sample).
fn poly_power(p: &[f64], w: f64) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    for (k, c) in p.iter().enumerate() {
        let x = -(k as f64) * w;
        re += c * x.cos();
        im += c * x.sin();
    }
    re * re + im * im
}

impl ZeroPhase {
    /// The share of a sinusoid's amplitude at `w` (rad per sample, `0 ≤ w ≤ π`)
    /// that the filter passes applied forward and backward: `|H(e^{jω})|²`.
    pub fn power_gain(&self, w: f64) -> f64 {
        match self {
            ZeroPhase::Ba(tf) => poly_power(&tf.b, w) / poly_power(&tf.a, w),
            ZeroPhase::Sos(sos) => sos
                .sections()
                .iter()
                .map(|s| poly_power(&s[..3], w) / poly_power(&s[3..], w))
                .product(),
        }
    }
}
