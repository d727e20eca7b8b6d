"""The friction law through zero speed as part of the model: every shape of the core's Coulomb sign feeds the
simulator and the regressor alike, a result carries its law, and the doctor fits the law of records from an
independent simulator (tanh Coulomb friction) instead of naming its shape as an effect."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

import didim
from didim.simulation import COULOMB_LAWS, default_coulomb_eps

from conftest import TRUTHBENCH_DIR

AXES = os.path.join(TRUTHBENCH_DIR, "axes")
needs_axes = pytest.mark.skipif(not os.path.isdir(AXES), reason="truthbench/axes records not found")
TABLE3 = dict(M1=68.0, Fv1=104.0, Fc1=10.0, M2=38.0, Fv2=96.5, Fc2=9.5, K12=8.8e5)


@pytest.mark.parametrize("law", COULOMB_LAWS)
def test_the_simulated_states_satisfy_the_idm_with_every_law(emps, law):
    """The regressor with the same law reproduces the simulated force to rounding (both read the core's one law)."""
    eps = default_coulomb_eps(emps)
    sim = didim.simulate(emps, TABLE3, didim.Model("flexible", coulomb_law=law))
    w = didim.Model("flexible", coulomb_eps=eps, coulomb_law=law).core().regressor(sim.q, sim.qd, sim.qdd)
    chi = np.array(list(TABLE3.values()))
    np.testing.assert_allclose(w[0] @ chi, sim.force, atol=1e-7 * np.abs(sim.force).max())
    np.testing.assert_allclose(w[1] @ chi, 0.0, atol=1e-6)


def test_a_result_carries_its_law_and_reproduces_its_error(emps):
    m = didim.Model("rigid", offset=True, coulomb_law="tanh")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r = didim.identify(emps, m, "didim")
    assert r.structure.coulomb_law == "tanh" and r.structure.coulomb_eps == pytest.approx(default_coulomb_eps(emps))
    back = didim.IdentificationResult.from_dict(r.to_dict())
    assert back.structure == r.structure
    assert didim.simulate(emps, back).relative_error(emps) == pytest.approx(r.force_error, rel=1e-12)
    with pytest.raises(didim.DataError, match="coulomb_law"):
        didim.Model("rigid", coulomb_law="linear")


@needs_axes
@pytest.mark.parametrize("name,speed", [("null_portal_notch", 3e-4), ("null_belt_pid", 1.5e-4)])
def test_the_doctor_fits_the_plants_law_and_names_nothing(name, speed):
    """The independent simulator's plant has Coulomb friction Fc·tanh(v/veps): the doctor fits the tanh law with its
    veps within 10 % and names nothing. With didim's algebraic law at 1e-4 m/s these records showed "a low-speed
    friction deficit" (3 of the 4 false alarms the issue measured)."""
    train = didim.load_record(os.path.join(AXES, f"{name}_train.csv"))
    valid = didim.load_record(os.path.join(AXES, f"{name}_valid.csv"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        d = didim.doctor(train, "rigid", valid)
    law = d.final_result.structure
    assert law.coulomb_law == "tanh" and law.coulomb_eps == pytest.approx(speed, rel=0.1), law
    assert d.findings == [], d.summary()
    assert "friction law through zero speed (fitted in closed loop): tanh" in d.summary()


def test_on_a_coarse_encoder_the_band_error_says_what_the_fit_explains():
    """A 1 µm encoder under the EMPS cascade: the velocity loop amplifies every count flip, so even the true parameters
    miss the full-rate force by far more than the noise; below the fit's band (5 Hz for rigid DIDIM) the error is
    the noise's share, and the summary says which is which."""
    from didim import scenarios

    rec = scenarios.make_recording(scenarios.EMPS_RIGID, "rigid", scenarios.emps_like(), quantization=1e-6, seed=3,
                                   force_noise=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r = didim.identify(rec, "rigid", "didim", offset=True)
    for k, v in scenarios.EMPS_RIGID.items():  # the parameters are right (OF within 2 %)...
        assert r.params[k] == pytest.approx(v, rel=0.02), (k, r.params)
    # ... yet the full rate misses by 11 %: count flips the parameters' last digits decorrelate; below 5 Hz, 0.2 %
    assert r.force_error > 10 * r.force_error_band, (r.force_error, r.force_error_band)
    assert "the band the fit used" in r.summary() and "encoder-count chatter" in r.summary()
