"""Logs that begin while the axis moves: the simulation starts at rest on the reference, the recorded axis elsewhere.
The samples before the two join (`didim.simulation.settling_samples`) are left out of the DIDIM regression, so the fit
is the fit of the same axis logged from rest; with `start="keep"` (the paper's regression on every sample) it is not.
Records from the independent plant of `benches/doctor_independent.py` (plain RK4, rational Coulomb law, in-loop
noise), so that the simulator that fits is not the one that made the data."""

import importlib.util
import pathlib
import warnings

import numpy as np
import pytest

import didim
from didim.simulation import settling_samples

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benches" / "doctor_independent.py"


@pytest.fixture(scope="module")
def plant():
    spec = importlib.util.spec_from_file_location("doctor_independent", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _late(rec, i0, name="late log"):
    return didim.Recording(dt=rec.dt, qr=rec.qr[i0:], force=rec.force[i0:], qm=rec.qm[i0:], controller=rec.controller,
                           position_resolution=rec.position_resolution, name=name)


def test_settling_samples_on_known_gaps():
    dt = 1e-3
    t = np.arange(2000) * dt
    q = np.zeros_like(t)
    # a start 100 µm away decaying as a closed loop of 10 ms time constant, then 0.5 µm of tracking noise
    rng = np.random.default_rng(0)
    noise = 5e-7 * rng.standard_normal(len(t))
    qm = q + 1e-4 * np.exp(-t / 0.01) + noise
    k = settling_samples(qm, q, dt)
    # the gap meets 5 × its 90th percentile (≈ 4.1 µm) at t = 10 ms · ln(100 / 4.1) ≈ 32 ms; noise moves it by a few
    assert 25 <= k <= 40, k
    assert settling_samples(q + noise, q, dt) == 0  # starts on the reference
    assert settling_samples(q + 2e-8, q, dt, resolution=5e-8) == 0  # within two encoder steps
    assert settling_samples(q + 1e-4, q, dt) == 0  # never joins: nothing to leave out


def test_a_log_cut_while_moving_fits_as_the_whole_log(plant):
    train, _ = plant.records(None, 1)
    moving = np.flatnonzero(np.abs(np.diff(train.qr)) > 1e-5)
    i0 = int(moving[moving > 3000][0]) + 200  # 83 mm/s, 0.54 mm behind the reference
    late = _late(train, i0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        whole = didim.identify(train, "rigid")
        auto = didim.identify(late, "rigid")
        keep = didim.identify(late, "rigid", start="keep")
    # truth of the plant: M 95 kg, Fv 200 N/(m/s), Fc 20 N; the whole log fits M within 0.5 %
    assert abs(whole.params["M"] / plant.M - 1) < 0.005, whole.params
    for k in ("M", "Fv", "Fc"):  # the cut log as the whole one, within 3 σ-sized differences (0.5 %)
        assert abs(auto.params[k] / whole.params[k] - 1) < 0.005, (k, auto.params, whole.params)
    assert keep.params["M"] < 0.9 * plant.M, keep.params  # the start biases the paper's regression (80 kg)


def test_start_option_is_checked(plant):
    train, _ = plant.records(None, 1)
    with pytest.raises(didim.DataError, match="start must be 'auto' or 'keep'"):
        didim.identify(train, "rigid", start="later")
