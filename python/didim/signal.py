"""Zero-phase filtering, numerical differentiation and parallel decimation (paper section III), on the Rust core."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from . import _checks, _core
from ._errors import DataError

#: Padding conventions of the zero-phase filters: scipy's default (3·max(len(a), len(b))) or MATLAB's (3·(nfilt − 1)).
PADDINGS = ("scipy", "matlab")


def _padlen(padding: str, order: int) -> Optional[int]:
    if padding == "scipy":
        return None
    if padding == "matlab":
        return 3 * order  # nfilt = order + 1 coefficients
    raise DataError(f"padding must be one of {', '.join(PADDINGS)}, got {padding!r}")


def lowpass(x, cutoff_hz: float, fs_hz: float, *, order: int = 4, padding: str = "scipy") -> np.ndarray:
    """Zero-phase Butterworth low-pass (forward and backward, odd padding), ``filtfilt(*butter(order, wn), x)``.

    ``padding="matlab"`` reproduces MATLAB's ``filtfilt`` (pad length 3·order instead of scipy's 3·(order + 1)).
    """
    x = np.ascontiguousarray(_checks.real_array("the signal to filter", x))
    order = _checks.whole("order", order, lo=1, hi=20)
    wn = _wn(cutoff_hz, fs_hz)
    b, a = _core.butter(order, wn)
    return _core.filtfilt(b, a, x, padlen=_padlen(padding, int(order)))


def _wn(cutoff_hz: float, fs_hz: float) -> float:
    fs_hz = _checks.real("sampling frequency", fs_hz, "Hz")
    cutoff_hz = _checks.real("cutoff", cutoff_hz, "Hz")
    if not (math.isfinite(fs_hz) and fs_hz > 0):
        raise DataError(f"sampling frequency must be > 0 Hz, got {fs_hz}")
    if not (math.isfinite(cutoff_hz) and 0 < cutoff_hz < fs_hz / 2):
        raise DataError(
            f"cutoff {cutoff_hz:g} Hz must lie between 0 and the Nyquist frequency {fs_hz / 2:g} Hz: lower the cutoff"
        )
    return cutoff_hz / (fs_hz / 2)


def welch(x, fs: float, nperseg: int) -> Tuple[np.ndarray, np.ndarray]:
    """Welch's power spectral density of a 1-D signal (unit²/Hz): Hann-windowed segments of ``nperseg`` samples
    overlapping by half, each with its mean removed, one-sided; SciPy's ``scipy.signal.welch`` with its defaults
    (the doctor's only use of ``scipy.signal``, whose import costs more than a doctor's round). Returns (f, psd)."""
    x = np.asarray(x, float)
    nperseg = int(min(nperseg, len(x)))
    if nperseg < 1:
        raise DataError("welch needs at least one sample")
    step = nperseg - nperseg // 2
    starts = np.arange(0, len(x) - nperseg + 1, step)
    win = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(nperseg) / nperseg)  # periodic Hann
    seg = x[starts[:, None] + np.arange(nperseg)]
    seg = (seg - seg.mean(axis=1, keepdims=True)) * win
    pxx = np.abs(np.fft.rfft(seg, axis=1)) ** 2 / (fs * float(win @ win))
    pxx[:, 1:(nperseg + 1) // 2] *= 2  # one-sided: the negative frequencies' power, not at 0 Hz nor at Nyquist
    return np.fft.rfftfreq(nperseg, 1 / fs), pxx.mean(axis=0)


def diffcent(x, dt: float) -> np.ndarray:
    """Central difference ``(x[k+1] − x[k−1]) / (2·dt)``, one-sided at both ends (the EMPS benchmark's ``diffcent``)."""
    x = _checks.real_array("the signal to differentiate", x, (1, 2))
    dt = _checks.real("sample period dt", dt, "s", lo=0.0)
    if x.shape[-1] < 2:
        raise DataError("differentiation needs at least 2 samples")
    d = np.empty_like(x)
    d[..., 1:-1] = (x[..., 2:] - x[..., :-2]) / 2
    d[..., 0] = x[..., 1] - x[..., 0]
    d[..., -1] = x[..., -1] - x[..., -2]
    return d / dt


def default_factor(fs_hz: float, cutoff_hz: float) -> int:
    """Down-sampling factor that keeps ``cutoff_hz`` at 80 % of the new Nyquist frequency (MATLAB's ``decimate`` relation)."""
    _wn(cutoff_hz, fs_hz)
    return int(_core.default_factor(fs_hz, cutoff_hz))


@dataclass(frozen=True)
class Decimation:
    """Parallel decimation (paper section III): one zero-phase low-pass and down-sampling by ``factor``,
    applied alike to Y and to every column of W.

    Build it with :meth:`lowpass` (Butterworth of ``order`` at ``cutoff_hz``, second-order sections, then one sample
    in ``factor`` from the first) or :meth:`matlab` (MATLAB's ``decimate(x, r)``: Chebyshev I of order 8, 0.05 dB,
    cutoff 0.8·fs/(2r), MATLAB's padding and sample alignment; the EMPS benchmark's IDIM-LS recipe).
    """

    factor: int
    kind: str = "butter"
    cutoff_hz: Optional[float] = None
    fs_hz: Optional[float] = None
    order: int = 4
    form: str = "sos"

    @classmethod
    def lowpass(cls, cutoff_hz: float, fs_hz: float, *, order: int = 4, factor: Optional[int] = None, form: str = "sos"):
        """Butterworth decimation; ``factor`` defaults to :func:`default_factor` (80 for 5 Hz at 1 kHz, 6 for 60 Hz)."""
        _wn(cutoff_hz, fs_hz)
        if factor is None:
            factor = default_factor(fs_hz, cutoff_hz)
        factor = _checks.whole("decimation factor", factor, lo=1, hi=2**31 - 1, hint=" (keep one sample in factor)")
        order = _checks.whole("order", order, lo=1, hi=20)
        _checks.one_of("form", form, ("sos", "ba"))
        return cls(factor=factor, kind="butter", cutoff_hz=float(cutoff_hz), fs_hz=float(fs_hz), order=order, form=form)

    @classmethod
    def matlab(cls, factor: int):
        """MATLAB's ``decimate(x, factor)`` convention."""
        factor = _checks.whole("decimation factor", factor, lo=1, hi=2**31 - 1, hint=" (keep one sample in factor)")
        return cls(factor=factor, kind="matlab", order=8, form="ba")

    @property
    def core(self) -> "_core.Decimation":
        """The design held by the Rust core (made once per instance)."""
        d = self.__dict__.get("_core_decimator")
        if d is None:
            d = _core.Decimation(
                self.factor, kind=self.kind, order=self.order, cutoff_hz=self.cutoff_hz, fs_hz=self.fs_hz, form=self.form
            )
            object.__setattr__(self, "_core_decimator", d)
        return d

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_core_decimator", "_leak_ends")}

    def __setstate__(self, state):
        self.__dict__.update(state)

    def apply(self, y, w=None) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """Decimates ``y`` (n,) and, when given, every column of ``w`` (n, p) in parallel; returns (y_dec, w_dec).

        The columns go through the filter four at a time (eight with second-order sections on a processor with
        AVX-512), interleaved, each with exactly the one-column arithmetic.
        """
        y = np.ascontiguousarray(_checks.real_array("y", y))
        if w is not None:
            w = _checks.real_array("w", w, (1, 2))
            if w.ndim == 1:
                w = w[:, None]
        return self.core.apply(y, w)

    def gain(self, f_hz: float, fs_hz: Optional[float] = None) -> float:
        """The share of a sinusoid's amplitude at ``f_hz`` that the zero-phase filter passes (forward and backward:
        |H|², 1/2 at a Butterworth's cutoff), before the down-sampling: the core's own filter's response.
        ``fs_hz``: the record's rate, needed for :meth:`matlab` (whose cutoff follows the rate); a Butterworth
        decimation knows its own."""
        fs = self.fs_hz if fs_hz is None else float(fs_hz)
        if fs is None:
            raise DataError("the gain of a MATLAB-style decimation needs the record's sampling frequency (fs_hz)")
        return float(self.core.gain(float(f_hz) / (fs / 2)))

    def __call__(self, x) -> np.ndarray:
        """Decimates one signal."""
        return self.apply(x)[0]

    def columns(self, x) -> np.ndarray:
        """Decimates every column of ``x`` (n, k) in one pass of the filter, four (or eight, see :meth:`apply`)
        columns at a time: each column as :meth:`__call__` gives it, bit for bit, at about a quarter of the cost of
        ``k`` calls (a robot's per-joint Coulomb and friction-law columns, the doctors' candidate columns)."""
        x = _checks.real_array("x", x, (2,))
        if x.shape[1] == 0:
            return np.zeros((len(self(np.zeros(x.shape[0]))), 0))
        yd, wd = self.apply(np.ascontiguousarray(x[:, 0]), x[:, 1:] if x.shape[1] > 1 else None)
        return yd[:, None] if wd is None else np.column_stack([yd, wd])

    def leak_end(self, n: int, k: int, leak: float) -> int:
        """The first decimated row of a record of ``n`` samples from which on the decimated indicator of its first
        ``k`` samples stays below ``leak`` (0 when it never reaches it): how far a disturbance of the first ``k``
        samples reaches through the filter. Kept per ``(n, k, leak)``: a doctor asks for the same few ``k`` with each
        refit (on the EMPS doctor 106 such decimations took 1.2 s of its 6.8 s, when the filter still computed the
        subnormal numbers its state passes through after the indicator; the core flushes them now)."""
        cache = self.__dict__.setdefault("_leak_ends", {})
        key = (int(n), int(k), float(leak))
        if key not in cache:
            ind = np.zeros(int(n))
            ind[:int(k)] = 1.0
            heavy = np.flatnonzero(np.abs(self(ind)) >= leak)
            cache[key] = int(heavy[-1]) + 1 if heavy.size else 0
        return cache[key]

    def describe(self) -> str:
        if self.kind == "matlab":
            return f"MATLAB decimate, factor {self.factor}"
        return f"Butterworth order {self.order} at {self.cutoff_hz:g} Hz, zero phase, factor {self.factor}"


def decimation_matches(dec, fs: float) -> None:
    """A Butterworth decimation designed for another sampling frequency than the record's is refused."""
    if not isinstance(dec, Decimation):
        raise DataError(f"decimation must be a didim.Decimation (e.g. Decimation.lowpass(5.0, recording.fs)), got "
                        f"{type(dec).__name__}")
    if dec.fs_hz is not None and abs(dec.fs_hz - fs) > 1e-9 * fs:
        raise DataError(
            f"the decimation was designed for a sampling frequency of {dec.fs_hz:g} Hz, but the record's sample "
            f"period gives {fs:g} Hz: build it with Decimation.lowpass(cutoff_hz, recording.fs)"
        )


__all__ = ["lowpass", "diffcent", "default_factor", "Decimation", "PADDINGS", "decimation_matches"]
