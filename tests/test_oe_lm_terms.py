"""OE-LM honours extra model terms, the actuation delay and backlash: its exact sensitivities agree with central
differences, and it recovers the hidden parameters of a record simulated with them."""

import numpy as np
import pytest

import didim
from didim import scenarios as sc
from didim.methods.oe import check_sensitivities, oe_lm

ASYM = [didim.Term("dFv", "abs_viscous")]
TRUTH = dict(M=95.0, Fv=200.0, Fc=20.0, dFv=-30.0)


@pytest.fixture(scope="module")
def record():
    qr = sc.trapezoid()
    plan = didim.Recording(dt=1e-3, qr=qr, force=np.zeros(len(qr)), qm=qr, controller=didim.EmpsCascade())
    sim = didim.simulate(plan, TRUTH, "rigid", terms=ASYM, delay=2, quantization=0.0)
    noise = np.random.default_rng(7).standard_normal(len(qr)) * 0.5
    return didim.Recording(dt=1e-3, qr=qr, force=sim.force + noise, qm=sim.q1, controller=didim.EmpsCascade())


def test_oe_lm_sensitivities_with_a_term_and_a_delay_match_central_differences(record):
    err = check_sensitivities(record, TRUTH, "rigid", terms=ASYM, delay=2, quantization=0.0)
    assert max(err.values()) < 1e-3, err


def test_oe_lm_recovers_a_direction_dependent_friction_behind_a_delay(record):
    start = {k: 0.9 * v for k, v in TRUTH.items()}
    r = oe_lm(record, "rigid", start, terms=ASYM, delay=2, cutoff_hz=20.0)
    assert r.converged, r.message
    for k, v in TRUTH.items():
        assert r.params[k] == pytest.approx(v, rel=0.01), k
    assert r.structure.delay == 2 and r.structure.terms == tuple(ASYM)
    # the result reproduces itself with its terms and delay
    assert didim.simulate(record, r).force == pytest.approx(didim.simulate(record, r.all_params, "rigid", terms=ASYM, delay=2).force)


def test_oe_lm_sensitivities_with_backlash_match_central_differences():
    truth = dict(sc.TABLE3_TRUTH)
    rec = sc.make_recording(truth, "flexible", sc.trapezoid_moving_chirp(), force_noise=0.0, quantization=0.0, seed=1)
    err = check_sensitivities(rec, truth, "flexible", backlash_gap=2e-5, integrator="rk4", quantization=0.0)
    # the dead zone's edges are kinks of the coupling force: a central difference whose two simulations cross an
    # edge at different times errs by the kink's slope change times the step (seen: 1e-3 on M1, 1e-4 elsewhere),
    # while an error of the sensitivity equations would show at the 10 % level
    assert max(err.values()) < 3e-3, err


def test_coupling_damper_sensitivities_match_central_differences():
    """The damper between motor and load is an affine term: exact in both integrators' sensitivities. With the
    exponential integrator a step of 1e-4 keeps the central differences off the step-sequence switches."""
    truth = dict(sc.TABLE3_TRUTH, C12=300.0)
    rec = sc.make_recording(sc.TABLE3_TRUTH, "flexible", sc.trapezoid_moving_chirp(), force_noise=0.0, quantization=0.0,
                            seed=1)
    damper = [didim.Term("C12", "damper")]
    err = check_sensitivities(rec, truth, "flexible", terms=damper, integrator="rk4", quantization=0.0)
    assert max(err.values()) < 1e-3, err
    err = check_sensitivities(rec, truth, "flexible", terms=damper, quantization=0.0, rel_step=1e-4)
    assert max(err.values()) < 5e-3, err
