#!/usr/bin/env python3
"""Reference vectors for didim-core's zero-phase filters and parallel decimation.

Writes ``filter_refs.txt`` (next to this script, or to the path given as the
first argument) with the scipy.signal results that the unit tests of
``crates/didim-core/src/filter.rs`` compare against (``include_str!``).

Run from anywhere:

    python3 crates/didim-core/tests/data/make_filter_refs.py

Requirements: numpy and scipy (generated with the versions printed in the
file header). The script is deterministic: the test signal is built from sines,
a ramp and a fixed 64-bit LCG, no random generator state is involved, and the
output is identical from run to run on the same installation.

File format (one record per line, ``#`` starts a comment line)::

    <name> <count> <v_1> ... <v_count>

Values are Python ``repr`` floats, so they parse back bit-exactly. Integers
(orders, lengths, flags) are stored as floats too. Records:

- ``x``: the test signal (1237 samples at 1 kHz: three sines, an offset, a ramp
  and a uniform pseudo-random part).
- ``butter.<i>.params`` = (order, wn) and ``cheby1.<i>.params`` = (order, rp_dB,
  wn): designs; ``.b``, ``.a`` = ``butter(order, wn)`` / ``cheby1(order, rp, wn)``
  in ba form, ``.sos`` = the ``output='sos'`` design flattened row by row,
  ``.zi`` = ``lfilter_zi(b, a)`` (``.zi_sensitivity``: its sensitivity, see
  below), ``.sos_zi`` = ``sosfilt_zi(sos)`` flattened.
- ``lfilter.<i>`` / ``sosfilt.<i>``: params = (kind, order, rp, wn, n, use_zi)
  with kind 0 = Butterworth, 1 = Chebyshev I (rp ignored for Butterworth);
  ``.y`` = ``lfilter(b, a, x[:n], zi=lfilter_zi(b, a)*x[0] if use_zi)`` (resp.
  ``sosfilt`` with ``sosfilt_zi``).
- ``filtfilt.<i>``: params = (kind, order, rp, wn, n, padlen, sensitivity) with
  padlen -1 meaning scipy's default; ``.y`` = ``filtfilt(b, a, x[:n],
  padtype='odd', padlen=...)``. ``sosfiltfilt.<i>``: same params, ``.y`` =
  ``sosfiltfilt(sos, x[:n], padlen=...)`` on scipy's own sos.
- ``dec_bw.<i>``: params = (order, cutoff_hz, fs_hz, factor, form, n,
  sensitivity) with form 0 = ba (``filtfilt(*butter(order, wn), x[:n])[::r]``)
  and 1 = sos (``sosfiltfilt(butter(order, wn, output='sos'), x[:n])[::r]``),
  wn = cutoff/(fs/2).
- ``dec_matlab.<i>``: params = (r, n, order, sensitivity); ``.y`` = MATLAB's
  ``decimate(x(1:n), r)`` convention: ``b, a = cheby1(order, 0.05, 0.8/r)``
  with MATLAB's order safeguard, ``y = filtfilt(b, a, x, padtype='odd',
  padlen=3*(max(len(a), len(b))-1))``, ``nout = ceil(n/r)``, ``nbeg = r -
  (r*nout - n)``, ``y[nbeg-1::r]``.
- ``matlab_order.r`` / ``matlab_order.order``: the order MATLAB's safeguard
  (reduce the order while the magnitude at 0.8/r is not -0.05 dB within 1e-6 dB)
  ends with, for a range of factors. The magnitude is evaluated exactly; MATLAB's
  own floating-point evaluation is noisy enough near the threshold (r >= 15) to
  end with a different order for some factors.

``sensitivity`` is the relative change of that output when the ba
coefficients are perturbed by one unit in the last place (largest of a few
deterministic sign patterns); it is 0 for sos outputs. Outputs of ba filters with
a large sensitivity (high order at a low normalised cutoff) are only reproducible
bit-for-bit: they depend on the last bit of every coefficient and on how
``lfilter_zi`` solves its (ill-conditioned) linear system, i.e. on the libm and
on the BLAS kernel numpy uses. ``filter.rs`` follows the operation order of
scipy on glibc x86-64 with OpenBLAS' SkylakeX kernels, where it matches them
exactly; on other platforms the tests use ``sensitivity`` to bound the error.
"""

import math
import os
import sys
from fractions import Fraction

import numpy as np
import scipy
from scipy import signal

N_SIGNAL = 1237
FS = 1000.0

BUTTER = [(1, 0.3), (2, 0.1), (3, 0.45), (4, 0.2), (5, 0.05), (6, 0.6), (7, 0.5),
          (8, 0.08), (9, 0.02), (12, 0.3), (20, 0.5)]
CHEBY1 = [(1, 0.5, 0.3), (2, 1.0, 0.2), (3, 0.5, 0.25), (4, 0.05, 0.4), (5, 1.0, 0.1),
          (6, 3.0, 0.5), (8, 0.05, 0.08), (8, 0.05, 0.8 / 3), (11, 0.1, 0.7)]
# (kind, order, rp, wn, n, use_zi)
LFILTER = [(0, 4, 0.0, 0.2, 200, 0), (1, 3, 0.5, 0.25, 200, 1), (1, 8, 0.05, 0.08, 200, 1)]
SOSFILT = [(0, 5, 0.0, 0.05, 200, 0), (0, 5, 0.0, 0.05, 200, 1), (1, 6, 3.0, 0.5, 150, 1)]
# (kind, order, rp, wn, n, padlen)   padlen -1 = scipy default
FILTFILT = [(0, 4, 0.0, 0.1, 500, -1), (0, 4, 0.0, 0.1, 500, 12),
            (1, 8, 0.05, 0.08, 800, 24), (1, 3, 0.5, 0.25, 200, -1),
            (0, 2, 0.0, 0.3, 150, 0), (0, 6, 0.0, 0.6, 100, 50), (0, 8, 0.0, 0.05, 500, -1)]
SOSFILTFILT = [(0, 4, 0.0, 0.1, 500, -1), (1, 8, 0.05, 0.08, 500, -1),
               (0, 5, 0.0, 0.05, 400, -1), (0, 9, 0.0, 0.02, 500, -1),
               (0, 3, 0.0, 0.45, 150, 10), (0, 7, 0.0, 0.5, 120, -1)]
# (order, cutoff_hz, fs_hz, factor, form, n)   form 0 = ba, 1 = sos
DEC_BW = [(4, 40.0, FS, 5, 1, N_SIGNAL), (4, 40.0, FS, 5, 0, N_SIGNAL),
          (6, 25.0, FS, 10, 1, N_SIGNAL), (6, 25.0, FS, 10, 0, N_SIGNAL),
          (3, 100.0, FS, 2, 1, 301), (2, 150.0, FS, 3, 0, 100)]
# (r, n)
DEC_MATLAB = [(10, N_SIGNAL), (4, 1001), (3, 500), (2, 77), (13, N_SIGNAL), (25, N_SIGNAL)]
MATLAB_ORDER_R = list(range(2, 61)) + [64, 80, 100, 128, 200, 256, 500, 1000]


def test_signal(n=N_SIGNAL, fs=FS):
    """Sines + offset + ramp + deterministic uniform noise in [-0.3, 0.3)."""
    state = 0x2545F4914F6CDD1D
    out = []
    for i in range(n):
        state = (6364136223846793005 * state + 1442695040888963407) % 2**64
        u = (state >> 11) / 2.0**53 * 2.0 - 1.0
        t = i / fs
        out.append(1.5 * math.sin(2 * math.pi * 3.1 * t)
                   + 0.7 * math.sin(2 * math.pi * 17.0 * t + 0.4)
                   + 0.25 * math.sin(2 * math.pi * 120.0 * t + 1.1)
                   + 0.8 + 2.0 * t + 0.3 * u)
    return np.array(out)


def design(kind, order, rp, wn, output):
    if kind == 0:
        return signal.butter(order, wn, output=output)
    return signal.cheby1(order, rp, wn, output=output)


def filtmag_db(b, a, f):
    """MATLAB's filtmag_db: 20 log10 |B(z)/A(z)| at z = exp(-1j*pi*f), B(z) = sum b_k z^k.

    Evaluated exactly (rational arithmetic on the double coefficients and on the
    double cos/sin of pi*f): the plain floating-point sum has rounding noise of up
    to ~1e-5 dB for high orders at low f, as large as the 1e-6 dB threshold below.
    """
    w = math.pi * f
    zr, zi = Fraction(math.cos(w)), Fraction(-math.sin(w))

    def ev(c):
        sr, si = Fraction(0), Fraction(0)
        for v in reversed([float(v) for v in c]):
            sr, si = sr * zr - si * zi + Fraction(v), sr * zi + si * zr
        return math.hypot(float(sr), float(si))

    num, den = ev(b), ev(a)
    if num == 0 or den == 0:
        return math.nan
    return 20 * math.log10(num / den)


def matlab_cheby(r):
    """MATLAB decimate's IIR design: cheby1(8, 0.05, 0.8/r) with its order safeguard."""
    rip, order = 0.05, 8
    b, a = signal.cheby1(order, rip, 0.8 / r)
    # MATLAB: while all(b==0) || abs(filtmag_db(b,a,.8/r)+rip) > 1e-6 (NaN counts as failure)
    while np.all(b == 0) or not abs(filtmag_db(b, a, 0.8 / r) + rip) <= 1e-6:
        order -= 1
        if order == 0:
            return 0, None, None
        b, a = signal.cheby1(order, rip, 0.8 / r)
    return order, b, a


def sensitivity(fun, b, a):
    """Relative output change for 1-ulp perturbations of b and a (a[0] kept at 1)."""
    ref = fun(b, a)
    scale = np.max(np.abs(ref))
    worst = 0.0
    for trial in range(4):
        sb = np.array([((7 * i + trial) % 3) - 1 for i in range(len(b))], dtype=float)
        sa = np.array([((5 * i + 2 * trial) % 3) - 1 for i in range(len(a))], dtype=float)
        sa[0] = 0.0
        b2 = b * (1.0 + sb * 2.0**-52)
        a2 = a * (1.0 + sa * 2.0**-52)
        worst = max(worst, float(np.max(np.abs(fun(b2, a2) - ref)) / scale))
    return worst


class Writer:
    def __init__(self):
        self.lines = []

    def comment(self, text):
        self.lines.append('# ' + text)

    def put(self, name, values):
        vals = [repr(float(v)) for v in np.ravel(np.asarray(values, dtype=float))]
        self.lines.append(f"{name} {len(vals)} {' '.join(vals)}".rstrip())


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    path = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, 'filter_refs.txt')
    x = test_signal()
    w = Writer()
    w.comment('Reference vectors for crates/didim-core/src/filter.rs; generated by '
              'make_filter_refs.py (see its docstring for the format). Do not edit.')
    w.comment(f'numpy {np.__version__}, scipy {scipy.__version__}, python '
              f'{sys.version.split()[0]}')
    w.put('x', x)

    for i, (order, wn) in enumerate(BUTTER):
        b, a = signal.butter(order, wn)
        sos = signal.butter(order, wn, output='sos')
        w.put(f'butter.{i}.params', [order, wn])
        w.put(f'butter.{i}.b', b)
        w.put(f'butter.{i}.a', a)
        w.put(f'butter.{i}.sos', sos)
        w.put(f'butter.{i}.zi', signal.lfilter_zi(b, a))
        w.put(f'butter.{i}.zi_sensitivity', [sensitivity(signal.lfilter_zi, b, a)])
        w.put(f'butter.{i}.sos_zi', signal.sosfilt_zi(sos))
    for i, (order, rp, wn) in enumerate(CHEBY1):
        b, a = signal.cheby1(order, rp, wn)
        sos = signal.cheby1(order, rp, wn, output='sos')
        w.put(f'cheby1.{i}.params', [order, rp, wn])
        w.put(f'cheby1.{i}.b', b)
        w.put(f'cheby1.{i}.a', a)
        w.put(f'cheby1.{i}.sos', sos)
        w.put(f'cheby1.{i}.zi', signal.lfilter_zi(b, a))
        w.put(f'cheby1.{i}.zi_sensitivity', [sensitivity(signal.lfilter_zi, b, a)])
        w.put(f'cheby1.{i}.sos_zi', signal.sosfilt_zi(sos))

    for i, (kind, order, rp, wn, n, use_zi) in enumerate(LFILTER):
        b, a = design(kind, order, rp, wn, 'ba')
        xs = x[:n]
        if use_zi:
            y, _ = signal.lfilter(b, a, xs, zi=signal.lfilter_zi(b, a) * xs[0])
        else:
            y = signal.lfilter(b, a, xs)
        w.put(f'lfilter.{i}.params', [kind, order, rp, wn, n, use_zi])
        w.put(f'lfilter.{i}.y', y)
    for i, (kind, order, rp, wn, n, use_zi) in enumerate(SOSFILT):
        sos = design(kind, order, rp, wn, 'sos')
        xs = x[:n]
        if use_zi:
            y, _ = signal.sosfilt(sos, xs, zi=signal.sosfilt_zi(sos) * xs[0])
        else:
            y = signal.sosfilt(sos, xs)
        w.put(f'sosfilt.{i}.params', [kind, order, rp, wn, n, use_zi])
        w.put(f'sosfilt.{i}.y', y)

    for i, (kind, order, rp, wn, n, padlen) in enumerate(FILTFILT):
        b, a = design(kind, order, rp, wn, 'ba')
        pl = None if padlen < 0 else padlen

        def run(bb, aa, xs=x[:n], pl=pl):
            return signal.filtfilt(bb, aa, xs, padtype='odd', padlen=pl)

        w.put(f'filtfilt.{i}.params', [kind, order, rp, wn, n, padlen, sensitivity(run, b, a)])
        w.put(f'filtfilt.{i}.y', run(b, a))
    for i, (kind, order, rp, wn, n, padlen) in enumerate(SOSFILTFILT):
        sos = design(kind, order, rp, wn, 'sos')
        pl = None if padlen < 0 else padlen
        w.put(f'sosfiltfilt.{i}.params', [kind, order, rp, wn, n, padlen, 0.0])
        w.put(f'sosfiltfilt.{i}.y', signal.sosfiltfilt(sos, x[:n], padtype='odd', padlen=pl))

    for i, (order, cutoff, fs, r, form, n) in enumerate(DEC_BW):
        wn = cutoff / (fs / 2)
        if form == 1:
            y = signal.sosfiltfilt(signal.butter(order, wn, output='sos'), x[:n])[::r]
            sens = 0.0
        else:
            b, a = signal.butter(order, wn)

            def run(bb, aa, xs=x[:n], r=r):
                return signal.filtfilt(bb, aa, xs)[::r]

            y = run(b, a)
            sens = sensitivity(run, b, a)
        w.put(f'dec_bw.{i}.params', [order, cutoff, fs, r, form, n, sens])
        w.put(f'dec_bw.{i}.y', y)

    for i, (r, n) in enumerate(DEC_MATLAB):
        order, b, a = matlab_cheby(r)
        nout = -(-n // r)
        nbeg = r - (r * nout - n)

        def run(bb, aa, xs=x[:n], nbeg=nbeg, r=r):
            y = signal.filtfilt(bb, aa, xs, padtype='odd',
                                padlen=3 * (max(len(aa), len(bb)) - 1))
            return y[nbeg - 1::r]

        w.put(f'dec_matlab.{i}.params', [r, n, order, sensitivity(run, b, a)])
        w.put(f'dec_matlab.{i}.y', run(b, a))

    w.put('matlab_order.r', MATLAB_ORDER_R)
    w.put('matlab_order.order', [matlab_cheby(r)[0] for r in MATLAB_ORDER_R])

    with open(path, 'w', encoding='ascii', newline='\n') as f:
        f.write('\n'.join(w.lines) + '\n')
    print(f'wrote {path} ({os.path.getsize(path)} bytes)')


if __name__ == '__main__':
    main()
