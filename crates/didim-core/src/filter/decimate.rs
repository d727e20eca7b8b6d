//! Parallel decimation: the [`Decimation`] of `Y` and `W` and the default factor.

use super::*;

/// Which sample the decimation keeps first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Alignment {
    /// `x[0], x[r], x[2r], …` (scipy slicing `[::r]`).
    First,
    /// MATLAB's `decimate`: the last sample is kept, first kept (1-based)
    /// `nbeg = r - (r*nout - n)` with `nout = ceil(n/r)`.
    Last,
}

/// Filter state precomputed for repeated application.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Prepared {
    Identity,
    Ba { b: Vec<f64>, a: Vec<f64>, zi: Vec<f64> },
    Sos { sos: Vec<[f64; 6]>, zi: Vec<[f64; 2]> },
}

/// Zero-phase low-pass filter followed by downsampling by an integer factor:
/// the "parallel decimation" of paper section III, applied identically to the
/// measured force `Y` and to every column of the regressor `W`
/// ([`Decimation::apply_parallel`]) so that `Y = W·θ` still holds after it.
#[derive(Debug, Clone, PartialEq)]
pub struct Decimation {
    filter: Option<ZeroPhase>,
    pub(super) prepared: Prepared,
    factor: usize,
    order: usize,
    padlen: usize,
    alignment: Alignment,
}

impl Decimation {
    /// Butterworth low-pass of `order` (1..=20) at `cutoff_hz` for a sampling
    /// frequency `fs_hz` (both in Hz, `0 < cutoff_hz < fs_hz / 2`), applied with
    /// zero phase, then keep `x[0], x[r], x[2r], …` with `r = factor ≥ 1`:
    /// `scipy.signal.sosfiltfilt(butter(order, cutoff/(fs/2), output='sos'),
    /// x)[::r]` for `form = Sos`, `scipy.signal.filtfilt(*butter(order, wn),
    /// x)[::r]` for `form = Ba` (scipy's default padding in both cases).
    ///
    /// The cutoff should be below the new Nyquist frequency `fs_hz / (2 r)`
    /// (MATLAB's choice is `0.8 fs / (2 r)`, see [`default_factor`]),
    /// otherwise the decimated signals alias; this is not checked. Prefer
    /// `Sos` (see the module documentation). Paper section III.
    pub fn butterworth(
        order: usize,
        cutoff_hz: f64,
        fs_hz: f64,
        factor: usize,
        form: FilterForm,
    ) -> Result<Self> {
        if !(fs_hz.is_finite() && fs_hz > 0.0) {
            return Err(invalid!(
                "sampling frequency fs_hz must be finite and positive, got {fs_hz}"
            ));
        }
        if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < fs_hz / 2.0) {
            return Err(invalid!(
                "cutoff_hz must satisfy 0 < cutoff_hz < fs_hz / 2 = {} Hz (Nyquist), got {cutoff_hz}; choose a cutoff below the Nyquist frequency (e.g. 0.8 * fs_hz / (2 * factor))",
                fs_hz / 2.0
            ));
        }
        check_factor(factor)?;
        if order == 0 || order > MAX_ORDER {
            return Err(invalid!(
                "filter order must be between 1 and {MAX_ORDER}, got {order}; choose an order in that range (4 is typical)"
            ));
        }
        let wn = cutoff_hz / (fs_hz / 2.0);
        let filter = match form {
            FilterForm::Ba => ZeroPhase::Ba(butter(order, wn)?),
            FilterForm::Sos => ZeroPhase::Sos(butter_sos(order, wn)?),
        };
        Self::from_filter(filter, factor, order, None, Alignment::First)
    }

    /// MATLAB's `decimate(x, r)` (default IIR mode) for `r = factor ≥ 1`:
    /// Chebyshev type I low-pass, order 8, 0.05 dB ripple, passband edge
    /// `0.8/r` (normalised to Nyquist), ba form, zero-phase with MATLAB's
    /// `filtfilt` padding `3*(nfilt - 1)` (`nfilt = order + 1`), then keep every
    /// `r`-th sample so that the last one is kept: `nout = ceil(n/r)` samples
    /// starting at (1-based) `nbeg = r - (r*nout - n)`.
    ///
    /// Like MATLAB, the order is reduced by one while the design's magnitude at
    /// `0.8/r` differs from −0.05 dB by more than 1e-6 dB (or `b` is all zeros,
    /// or the magnitude is not finite). The check measures the rounding damage
    /// of the ba coefficients, so it only fails for large factors (order 8 is
    /// kept up to `r = 17`; e.g. 7 for `r = 18`, 6 for `r = 25`, 4 for
    /// `r = 100`) and its outcome there is not monotonic in `r`. The magnitude
    /// is evaluated accurately; MATLAB's plain evaluation is itself noisy at
    /// the 1e-6 dB level for `r ≥ 15`, so MATLAB may settle on a neighbouring
    /// order for such factors. `factor = 1` returns the input unchanged, as
    /// MATLAB does. Errors if no order passes. The ba form is ill-conditioned
    /// for large `r` (module documentation): for `r` beyond about 10 prefer
    /// [`Decimation::butterworth`] with [`FilterForm::Sos`] or decimating in
    /// stages. Paper section III.
    pub fn matlab(factor: usize) -> Result<Self> {
        check_factor(factor)?;
        if factor == 1 {
            return Ok(Self {
                filter: None,
                prepared: Prepared::Identity,
                factor,
                order: 0,
                padlen: 0,
                alignment: Alignment::Last,
            });
        }
        const RIPPLE: f64 = 0.05;
        let wn = 0.8 / factor as f64;
        let mut order = 8;
        let mut tf = cheby1(order, RIPPLE, wn);
        loop {
            let ok = match &tf {
                Ok(t) => {
                    let dev = (mag_db(t, wn) + RIPPLE).abs();
                    t.b.iter().any(|&v| v != 0.0) && dev <= 1e-6
                }
                Err(_) => false,
            };
            if ok {
                break;
            }
            order -= 1;
            if order == 0 {
                return Err(invalid!(
                    "decimation factor {factor} is too large for MATLAB's decimate filter (no Chebyshev order passes its accuracy check at 0.8/{factor}); decimate in several stages or use Decimation::butterworth with FilterForm::Sos"
                ));
            }
            tf = cheby1(order, RIPPLE, wn);
        }
        let tf = tf?;
        let padlen = 3 * (tf.a.len().max(tf.b.len()) - 1);
        Self::from_filter(ZeroPhase::Ba(tf), factor, order, Some(padlen), Alignment::Last)
    }

    pub(super) fn from_filter(
        filter: ZeroPhase,
        factor: usize,
        order: usize,
        padlen: Option<usize>,
        alignment: Alignment,
    ) -> Result<Self> {
        let (prepared, default_padlen) = match &filter {
            ZeroPhase::Ba(tf) => {
                validate_tf(tf)?;
                let zi = lfilter_zi_checked(&tf.b, &tf.a)?;
                let (b, a) = normalized_ba(&tf.b, &tf.a)
                    .ok_or_else(|| invalid!("filter coefficients are malformed"))?;
                let pl = 3 * tf.a.len().max(tf.b.len());
                (Prepared::Ba { b, a, zi }, pl)
            }
            ZeroPhase::Sos(sos) => {
                let norm = validate_sos(sos)?;
                let zi = sosfilt_zi_checked(sos)?;
                let pl = sos_default_padlen(&norm);
                (Prepared::Sos { sos: norm, zi }, pl)
            }
        };
        Ok(Self {
            filter: Some(filter),
            prepared,
            factor,
            order,
            padlen: padlen.unwrap_or(default_padlen),
            alignment,
        })
    }

    /// The decimation factor `r` (keep one sample in `r`).
    pub fn factor(&self) -> usize {
        self.factor
    }

    /// The share of a sinusoid's amplitude at `f_rel` (its frequency over the
    /// Nyquist frequency, clamped to `0..=1`) that the zero-phase filter passes
    /// before the down-sampling (1 for the identity).
    pub fn gain(&self, f_rel: f64) -> f64 {
        self.filter
            .as_ref()
            .map_or(1.0, |f| f.power_gain(PI * f_rel.clamp(0.0, 1.0)))
    }

    /// The zero-phase filter, `None` for the identity (`Decimation::matlab(1)`).
    pub fn filter(&self) -> Option<&ZeroPhase> {
        self.filter.as_ref()
    }

    /// Order of the low-pass filter (after MATLAB's reduction for
    /// [`Decimation::matlab`]; 0 for the identity).
    pub fn order(&self) -> usize {
        self.order
    }

    /// Samples of odd extension added at each end before filtering.
    pub fn padlen(&self) -> usize {
        self.padlen
    }

    /// Number of samples [`Decimation::apply`] returns for an input of `n`
    /// samples: `ceil(n / r)`.
    pub fn output_len(&self, n: usize) -> usize {
        n.div_ceil(self.factor)
    }

    /// Shortest record this decimator accepts: `padlen + 1` samples (the
    /// zero-phase filter needs more samples than its padding), 1 for the
    /// identity.
    pub fn min_input_len(&self) -> usize {
        self.padlen + 1
    }

    /// Filters `x` (uniformly sampled at the design's `fs`) with zero phase and
    /// keeps one sample in `r` (see the constructors for which ones). Errors
    /// (`InvalidInput`) if `x` is shorter than [`Decimation::min_input_len`] or
    /// has a non-finite value. Paper section III.
    pub fn apply(&self, x: &[f64]) -> Result<Vec<f64>> {
        self.apply_named(x, "x")
    }

    pub(super) fn apply_named(&self, x: &[f64], name: &str) -> Result<Vec<f64>> {
        let desc = match &self.prepared {
            Prepared::Identity => {
                if x.is_empty() {
                    return Err(invalid!("{name} is empty; the decimator needs at least 1 sample"));
                }
                check_record(x, 0, name, "identity")?;
                return Ok(x.to_vec());
            }
            Prepared::Ba { .. } => format!("order-{} ba filter, padlen {}", self.order, self.padlen),
            Prepared::Sos { .. } => format!("order-{} sos filter, padlen {}", self.order, self.padlen),
        };
        check_record(x, self.padlen, name, &desc)?;
        let start = self.start_index(x.len());
        let out = lanes::filtfilt_slice(
            &self.prepared,
            1,
            x.len(),
            |_, i| x[i],
            self.padlen,
            start,
            self.factor,
        )
        .pop()
        .unwrap_or_default();
        finite_output(out, name)
    }

    /// Parallel decimation of paper section III: the same filter and slicing
    /// applied to `y` (length `n`) and to each of the `ncols` columns of `w`,
    /// stored column-major (`w[j*n + i]` is row `i` of column `j`, so
    /// `w.len() == n * ncols`). Columns are processed in parallel with rayon;
    /// every column gives bit-for-bit the result of [`Decimation::apply`].
    ///
    /// Returns `(y_dec, w_dec)` with `w_dec` column-major
    /// (`output_len(n)` rows, `ncols` columns). Errors (`InvalidInput`, naming
    /// `y` or the column of `w`) on mismatched lengths, too-short records or
    /// non-finite values.
    pub fn apply_parallel(&self, y: &[f64], w: &[f64], ncols: usize) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = y.len();
        check_matrix(w, n, ncols, "column-major")?;
        let mut cols: Vec<&[f64]> = Vec::with_capacity(ncols + 1);
        cols.push(y);
        if n > 0 {
            cols.extend(w.chunks(n));
        }
        let mut out = self.apply_columns(&cols, y_or_column)?;
        let yd = out.remove(0);
        Ok((yd, out.concat()))
    }

    /// [`Decimation::apply_parallel`] with `w` stored row-major (`w[i*ncols + j]` is row `i`
    /// of column `j`, a C-ordered `n × ncols` array): the columns are read in place, without
    /// a transposed copy. The same result, bit for bit, and the same errors; `w_dec` is
    /// column-major as there.
    pub fn apply_parallel_rows(&self, y: &[f64], w: &[f64], ncols: usize) -> Result<(Vec<f64>, Vec<f64>)> {
        let n = y.len();
        check_matrix(w, n, ncols, "row-major")?;
        let column = |j: usize| -> Vec<f64> { w.iter().skip(j).step_by(ncols.max(1)).copied().collect() };
        self.check_column(y, &y_or_column(0))?;
        if w.iter().any(|v| !v.is_finite()) {
            // the first column (in column order) with a non-finite value is named, as apply_parallel does
            for j in 0..ncols {
                self.check_column(&column(j), &y_or_column(j + 1))?;
            }
        }
        let at = |j: usize, i: usize| if j == 0 { y[i] } else { w[i * ncols + (j - 1)] };
        let mut out = self.decimate(ncols + 1, n, at);
        let yd = out.remove(0);
        let wd = out.concat();
        // never NaN silently: an overflowing pass is an error naming the column
        let m = yd.len();
        let yd = finite_output(yd, "y")?;
        if let Some(j) = wd.iter().position(|v| !v.is_finite()).map(|i| i / m.max(1)) {
            finite_output(wd[j * m..(j + 1) * m].to_vec(), &y_or_column(j + 1))?;
        }
        Ok((yd, wd))
    }

    /// Decimates equal-length columns alike, [`lanes::width`] columns at a time through
    /// the filter (column-interleaved, bit-for-bit the result of [`Decimation::apply`]),
    /// the groups in parallel with rayon. `name(j)` names column `j` in errors.
    pub fn apply_columns(&self, cols: &[&[f64]], name: impl Fn(usize) -> String) -> Result<Vec<Vec<f64>>> {
        let Some(n) = cols.first().map(|c| c.len()) else {
            return Ok(Vec::new());
        };
        for (j, c) in cols.iter().enumerate() {
            if c.len() != n {
                return Err(invalid!(
                    "{} has {} samples but the first column has {n}; all columns must have the same length",
                    name(j),
                    c.len()
                ));
            }
            self.check_column(c, &name(j))?;
        }
        // never NaN silently: an overflowing pass is an error naming the column
        self.decimate(cols.len(), n, |j, i| cols[j][i])
            .into_iter()
            .enumerate()
            .map(|(j, c)| finite_output(c, &name(j)))
            .collect()
    }

    /// Decimates `ncols` columns of `n` samples that `fill(j, column)` writes (over a column of
    /// `n` zeros), [`lanes::width`] at a time, the groups in parallel with rayon: a group's
    /// full-rate columns exist only while it is filtered. Bit for bit what
    /// [`Decimation::apply_columns`] gives on the filled columns, with its errors (`name(j)` names
    /// column `j`).
    pub fn apply_filled(
        &self,
        ncols: usize,
        n: usize,
        fill: impl Fn(usize, &mut [f64]) + Sync,
        name: impl Fn(usize) -> String + Sync,
    ) -> Result<Vec<Vec<f64>>> {
        let edge = match self.prepared {
            Prepared::Identity => 0,
            _ => self.padlen,
        };
        let (start, r, width) = (self.start_index(n), self.factor, lanes::width(&self.prepared));
        let group = |g: usize| -> Result<Vec<Vec<f64>>> {
            let j0 = g * width;
            let k = width.min(ncols - j0);
            let mut buf = vec![0.0; k * n];
            for c in 0..k {
                let col = &mut buf[c * n..(c + 1) * n];
                fill(j0 + c, col);
                self.check_column(col, &name(j0 + c))?;
            }
            lanes::filtfilt_slice(&self.prepared, k, n, |c, i| buf[c * n + i], edge, start, r)
                .into_iter()
                .enumerate()
                .map(|(c, out)| finite_output(out, &name(j0 + c)))
                .collect()
        };
        match ncols.div_ceil(width) {
            0 => Ok(Vec::new()),
            1 => group(0),
            groups => Ok((0..groups)
                .into_par_iter()
                .map(group)
                .collect::<Result<Vec<_>>>()?
                .into_iter()
                .flatten()
                .collect()),
        }
    }

    /// Length and finiteness of one column (`check_record` with this decimator's padding).
    fn check_column(&self, c: &[f64], name: &str) -> Result<()> {
        match &self.prepared {
            Prepared::Identity => {
                if c.is_empty() {
                    return Err(invalid!("{name} is empty; the decimator needs at least 1 sample"));
                }
                check_record(c, 0, name, "identity")
            }
            Prepared::Ba { .. } => check_record(
                c,
                self.padlen,
                name,
                &format!("order-{} ba filter, padlen {}", self.order, self.padlen),
            ),
            Prepared::Sos { .. } => check_record(
                c,
                self.padlen,
                name,
                &format!("order-{} sos filter, padlen {}", self.order, self.padlen),
            ),
        }
    }

    /// The decimated columns `0..ncols` of `n` validated samples, column `j`'s sample `i`
    /// being `at(j, i)`: groups of [`lanes::width`] columns in parallel.
    fn decimate(&self, ncols: usize, n: usize, at: impl Fn(usize, usize) -> f64 + Sync) -> Vec<Vec<f64>> {
        let edge = match self.prepared {
            Prepared::Identity => 0,
            _ => self.padlen,
        };
        let start = self.start_index(n);
        let (r, width) = (self.factor, lanes::width(&self.prepared));
        let at = &at;
        let group = |g: usize| {
            let j0 = g * width;
            let k = width.min(ncols - j0);
            lanes::filtfilt_slice(&self.prepared, k, n, |c, i| at(j0 + c, i), edge, start, r)
        };
        match ncols.div_ceil(width) {
            // one group (up to four or eight columns) on this thread: handing it to the pool would add a
            // thread hand-off to a fraction of a millisecond of filtering
            1 => group(0),
            groups => (0..groups)
                .into_par_iter()
                .map(group)
                .collect::<Vec<_>>()
                .into_iter()
                .flatten()
                .collect(),
        }
    }

    /// First kept sample of a filtered record of `n` samples.
    pub(super) fn start_index(&self, n: usize) -> usize {
        match self.alignment {
            Alignment::First => 0,
            // MATLAB: nbeg (1-based) = r - (r*nout - n), i.e. the last sample
            // n - 1 is kept and the first is (n - 1) - (nout - 1) r.
            Alignment::Last => {
                let skipped = self.output_len(n).saturating_sub(1).saturating_mul(self.factor);
                n.saturating_sub(1).saturating_sub(skipped)
            }
        }
    }
}

/// Names `y` (column 0) and the columns of `w` in the errors of the parallel decimation.
fn y_or_column(j: usize) -> String {
    if j == 0 {
        "y".into()
    } else {
        format!("w column {}", j - 1)
    }
}

/// `w` holds `n × ncols` values.
fn check_matrix(w: &[f64], n: usize, ncols: usize, layout: &str) -> Result<()> {
    let expected = n
        .checked_mul(ncols)
        .ok_or_else(|| invalid!("w: n = {n} rows times ncols = {ncols} columns overflows; check ncols"))?;
    if w.len() != expected {
        return Err(invalid!(
            "w has {} values but y has n = {n} samples and ncols = {ncols}: w must be the {layout} n x ncols regressor ({expected} values); check ncols and that y and the columns of w have the same length",
            w.len()
        ));
    }
    Ok(())
}

pub(super) fn check_factor(factor: usize) -> Result<()> {
    if factor == 0 {
        return Err(invalid!(
            "decimation factor must be at least 1, got 0; use 1 to filter without downsampling, or default_factor(fs_hz, cutoff_hz)"
        ));
    }
    Ok(())
}

/// MATLAB's `filtmag_db(b, a, f)`: `20 log10 |B(z) / A(z)|` at `z = e^{-iπf}`,
/// `B(z) = Σ b_k z^k`. The polynomials are evaluated with a compensated
/// (double-double) Horner scheme: near the crowded poles of a high-order ba
/// design the plain sum has rounding noise of up to ~1e-5 dB, as large as the
/// 1e-6 dB threshold the value is compared with; this way the decision reflects
/// the designed coefficients.
pub(super) fn mag_db(tf: &Tf, f: f64) -> f64 {
    let w = PI * f;
    let (zr, zi) = (w.cos(), -w.sin());
    let eval = |c: &[f64]| {
        let (mut sr, mut si) = (Dd::ZERO, Dd::ZERO);
        for &v in c.iter().rev() {
            let re = sr.mul(zr).sub(si.mul(zi)).add(Dd::from(v));
            let im = sr.mul(zi).add(si.mul(zr));
            (sr, si) = (re, im);
        }
        sr.value().hypot(si.value())
    };
    20.0 * (eval(&tf.b) / eval(&tf.a)).log10()
}

/// Decimation factor for a low-pass `cutoff_hz` at sampling rate `fs_hz`,
/// from MATLAB's relation `cutoff = 0.8 · fs / (2 r)`: `floor(0.4 · fs /
/// cutoff)`, at least 1 (paper section III). Ratios within 1e-12 (relative)
/// below an integer count as that integer, so `(1000, 40)` gives exactly 10.
/// Non-finite or non-positive inputs give 1.
pub fn default_factor(fs_hz: f64, cutoff_hz: f64) -> usize {
    let q = (2.0 * fs_hz) / (5.0 * cutoff_hz);
    if !(q.is_finite() && q >= 1.0 && fs_hz > 0.0 && cutoff_hz > 0.0) {
        return 1;
    }
    ((q * (1.0 + 1e-12)).floor() as usize).max(1)
}
