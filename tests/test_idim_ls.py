"""IDIM-LS: the EMPS benchmark's published result, to the printed digits."""

import numpy as np
import pytest

import didim
from didim.methods.identification import idim_cross_test, idim_ls


def test_emps_golden_idim_ls_reproduces_the_published_values(emps):
    r = idim_ls(emps, offset=True, sigma="sample_std")  # the benchmark's recipe (defaults + its σ convention)
    published = {"M": (95.1089, 0.1085), "Fv": (203.5034, 1.1460), "Fc": (20.3935, 0.1012), "OF": (-3.1648, 0.0444)}
    for name, (value, sigma) in published.items():
        assert round(r.params[name], 4) == value, name
        assert round(r.std[name], 4) == sigma, name
    assert round(100 * r.relative_error, 4) == 4.0834


def test_emps_golden_cross_test_on_the_pulses_record(emps, emps_pulses):
    r = idim_ls(emps, offset=True, sigma="sample_std")
    assert round(100 * idim_cross_test(emps_pulses, r), 4) == 5.9824


def test_flexible_idim_ls_recovers_the_truth_on_noiseless_simulated_data():
    truth = didim.scenarios.TABLE3_TRUTH
    rec = didim.scenarios.make_recording(truth, "flexible", load_encoder=True, force_noise=0.0, quantization=None)
    r = idim_ls(rec, "flexible", lowpass_hz=200.0, zoh_align=True, coulomb_eps=didim.DEFAULT_COULOMB_EPS)
    for name in ("M1", "M2", "K12", "Fv1", "Fc1", "Fv2", "Fc2"):
        assert r.params[name] == pytest.approx(truth[name], rel=0.02), name
    # without aligning the held command, the half-sample lead biases the viscous friction by over 20 %
    biased = idim_ls(rec, "flexible", lowpass_hz=200.0, coulomb_eps=didim.DEFAULT_COULOMB_EPS)
    assert abs(biased.params["Fv1"] / truth["Fv1"] - 1) > 0.2


def test_flexible_idim_ls_needs_the_load_position(emps):
    with pytest.raises(didim.DataError, match="load position"):
        idim_ls(emps, "flexible")


def test_unexcited_record_raises_identifiability_error_naming_columns():
    n = 4000
    qr = 0.01 * np.arange(n) * 1e-3 + 0.001  # constant speed: q̈ ≡ 0 and sign(q̇) ≡ 1 = the offset column
    rec = didim.scenarios.make_recording(dict(M=10.0, Fv=50.0, Fc=5.0), "rigid", qr, force_noise=0.0, quantization=None)
    with pytest.raises(didim.IdentifiabilityError, match="Fc|OF"):
        idim_ls(rec, offset=True, border=200)
