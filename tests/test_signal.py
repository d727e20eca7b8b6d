"""Zero-phase filtering and parallel decimation against scipy (the reference implementation)."""

import numpy as np
import pytest
import scipy.signal as sg

import didim
from didim import _core
from didim.signal import Decimation, default_factor, lowpass


def signal(n=3001, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    return np.sin(2 * np.pi * 1.3 * t) + 0.3 * np.sin(2 * np.pi * 47 * t) + 0.2 * t + 0.05 * rng.standard_normal(n)


def rel(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


def iir_tolerance(b, a, passes=2):
    """How far two correct implementations of a (b, a) IIR filter may differ, relative to the signal's scale.

    Each step of the recursion rounds its sums, an error of about eps·(Σ|b|·|x| + Σ|a|·|y|); the recursion 1/A(z)
    amplifies such errors by at most the ℓ1 norm of its impulse response. Forward and backward passes add up, and two
    implementations (didim's and scipy's, each with the CPU's own kernels) may err in opposite directions. For the
    order-8 Chebyshev of MATLAB's decimate by 10 (poles near the unit circle) ‖1/A‖₁ is 2.4e6, so the two differ by
    up to ~1e-7 — on some CPUs by 8e-9 — where a well-conditioned Butterworth stays below 1e-12.
    """
    imp = np.zeros(200_000)
    imp[0] = 1.0
    gain = np.sum(np.abs(sg.lfilter([1.0], a, imp)))
    return 2 * passes * np.finfo(float).eps * (np.sum(np.abs(b)) + np.sum(np.abs(a))) * gain


@pytest.mark.parametrize("order, cutoff, factor", [(4, 60.0, 6), (4, 5.0, 80), (2, 100.0, 3), (6, 20.0, 10)])
def test_butterworth_sos_decimation_matches_scipy_sosfiltfilt(order, cutoff, factor):
    x = signal()
    w = np.column_stack([x, x**2, np.cos(x)])
    dec = Decimation.lowpass(cutoff, 1000.0, order=order, factor=factor)
    yd, wd = dec.apply(x, w)
    sos = sg.butter(order, cutoff / 500.0, output="sos")
    ref = sg.sosfiltfilt(sos, x)[::factor]
    assert rel(yd, ref) < 1e-10
    for j in range(3):
        assert rel(wd[:, j], sg.sosfiltfilt(sos, w[:, j])[::factor]) < 1e-10


@pytest.mark.parametrize("order, cutoff, factor", [(4, 60.0, 6), (4, 100.0, 2), (3, 30.0, 10)])
def test_butterworth_ba_decimation_matches_scipy_filtfilt(order, cutoff, factor):
    x = signal()
    dec = Decimation.lowpass(cutoff, 1000.0, order=order, factor=factor, form="ba")
    b, a = sg.butter(order, cutoff / 500.0)
    assert rel(dec(x), sg.filtfilt(b, a, x)[::factor]) < iir_tolerance(b, a)


@pytest.mark.parametrize("n, r", [(1237, 10), (24792, 10), (500, 3)])
def test_matlab_decimate_convention(n, r):
    x = signal(n)
    b, a = sg.cheby1(8, 0.05, 0.8 / r)
    y = sg.filtfilt(b, a, x, padtype="odd", padlen=3 * (max(len(a), len(b)) - 1))
    nout = -(-n // r)
    nbeg = r - (r * nout - n)
    ref = y[nbeg - 1 :: r]
    got = Decimation.matlab(r)(x)
    assert got.shape == ref.shape
    assert rel(got, ref) < iir_tolerance(b, a)


def test_lowpass_paddings_match_scipy_and_matlab_filtfilt():
    x = signal()
    b, a = sg.butter(4, 0.2)
    assert rel(lowpass(x, 100.0, 1000.0), sg.filtfilt(b, a, x)) < iir_tolerance(b, a)
    assert rel(lowpass(x, 100.0, 1000.0, padding="matlab"), sg.filtfilt(b, a, x, padlen=12)) < iir_tolerance(b, a)


def test_filter_designs_match_scipy():
    for order, wn in [(4, 0.2), (8, 0.01), (2, 0.9)]:
        b, a = _core.butter(order, wn)
        bs, as_ = sg.butter(order, wn)
        np.testing.assert_allclose(b, bs, rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(a, as_, rtol=1e-12)
    b, a = _core.cheby1(8, 0.05, 0.08)
    bs, as_ = sg.cheby1(8, 0.05, 0.08)
    np.testing.assert_allclose(b, bs, rtol=1e-12)
    np.testing.assert_allclose(a, as_, rtol=1e-12)


@pytest.mark.parametrize("k", [1, 3, 4, 6, 9])
def test_decimating_columns_together_is_decimating_each_alone(k):
    """Decimation.columns (one pass of the filter, four columns a lane group) against one call per column, bit for
    bit (each lane does exactly the one-column arithmetic), and against scipy within its rounding."""
    x = signal()
    cols = np.column_stack([x * (j + 1) + np.cos(j * x) for j in range(k)])
    dec = Decimation.lowpass(20.0, 1000.0)
    together = dec.columns(cols)
    assert together.shape == (len(dec(x)), k)
    for j in range(k):
        assert np.array_equal(together[:, j], dec(np.ascontiguousarray(cols[:, j])))
    sos = sg.butter(4, 20.0 / 500.0, output="sos")
    assert rel(together, sg.sosfiltfilt(sos, cols, axis=0)[::dec.factor]) < 1e-10
    assert dec.columns(np.asfortranarray(cols)).tobytes() == together.tobytes()
    assert dec.columns(cols[:, :0]).shape == (len(dec(x)), 0)


def test_default_factor_follows_matlabs_cutoff_relation():
    assert default_factor(1000.0, 5.0) == 80
    assert default_factor(1000.0, 60.0) == 6
    assert default_factor(1000.0, 40.0) == 10


def test_decimation_errors_say_what_to_fix():
    with pytest.raises(didim.DataError, match="Nyquist"):
        Decimation.lowpass(600.0, 1000.0)
    with pytest.raises(didim.DataError, match="(?i)short"):
        Decimation.lowpass(5.0, 1000.0)(np.ones(10))
    with pytest.raises(didim.DataError, match="(?i)finite|nan"):
        x = signal()
        x[7] = np.nan
        Decimation.lowpass(60.0, 1000.0)(x)


def test_core_lfilter_is_scipys_with_and_without_an_initial_state():
    """The core's causal filter (what the controllers' replay runs on, without importing scipy.signal) against
    scipy's: a stable Butterworth and an integrating PI law, from rest and from a given state. The outputs are sums
    of a few hundred products of order-1 terms (the integrator's a ramp): a relative 1e-12 of the output's scale."""
    from scipy.signal import butter, lfilter

    from didim import _core

    rng = np.random.default_rng(3)
    x = rng.standard_normal(2000)
    b, a = butter(4, 0.1)
    pi_b, pi_a = [1.2, -1.0], [1.0, -1.0]  # a PI's discrete law: an integrator
    for num, den in ((b, a), (pi_b, pi_a)):
        zi = rng.standard_normal(max(len(num), len(den)) - 1)
        for state in (None, zi):
            want = lfilter(num, den, x) if state is None else lfilter(num, den, x, zi=state)[0]
            got = _core.lfilter(list(num), list(den), x, zi=None if state is None else list(state))
            assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))
    with pytest.raises(ValueError, match="a\\[0\\] non-zero"):
        _core.lfilter([1.0], [0.0, 1.0], x)


@pytest.mark.parametrize("kind, f_hz", [("butter", 20.0), ("butter", 60.0), ("butter", 79.0), ("butter", 110.0),
                                        ("matlab", 30.0), ("matlab", 45.0)])
def test_decimation_gain_is_the_share_of_a_sine_the_filter_passes(kind, f_hz):
    """Decimation.gain against the filter itself: a sine at f_hz through scipy's zero-phase filter of the same design,
    its amplitude in the middle of the record (away from the ends' transients) over the input's."""
    fs = 1000.0
    dec = Decimation.lowpass(60.0, fs) if kind == "butter" else Decimation.matlab(10)
    t = np.arange(20000) / fs
    x = np.sin(2 * np.pi * f_hz * t)
    if kind == "butter":
        y = sg.sosfiltfilt(sg.butter(4, 60.0 / (fs / 2), output="sos"), x)
    else:
        y = sg.filtfilt(*sg.cheby1(8, 0.05, 0.8 / 10), x)
    mid = slice(5000, 15000)
    got = np.sqrt(2 * np.mean(y[mid] ** 2))
    assert dec.gain(f_hz, fs) == pytest.approx(got, rel=1e-3, abs=1e-6)
