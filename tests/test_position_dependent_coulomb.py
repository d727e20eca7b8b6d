"""Position-dependent Coulomb friction, Fc·(1 + a·sin(2π q/P)) against the motion, as one model term (the core's
`CoulombRipple` basis, `coulomb_ripple_sin`/`_cos` in Python): simulated, differentiated, identified by DIDIM and
OE-LM, and named by the doctor on a record from an independent simulator."""

import warnings

import numpy as np
import pytest

import didim
from conftest import resolved
from didim import scenarios as sc
from didim.methods.identification import didim_iterate
from didim.methods.oe import check_sensitivities, oe_lm

P = 0.05
TERMS = [didim.Term("Aq_sin", "coulomb_ripple_sin", P), didim.Term("Aq_cos", "coulomb_ripple_cos", P)]
TRUTH = dict(M=95.0, Fv=200.0, Fc=20.0, Aq_sin=6.0, Aq_cos=-2.0)


@pytest.fixture(scope="module")
def record():
    qr = sc.emps_like(n=15000)
    plan = didim.Recording(dt=1e-3, qr=qr, force=np.zeros(len(qr)), qm=qr, controller=didim.EmpsCascade())
    sim = didim.simulate(plan, TRUTH, "rigid", terms=TERMS, quantization=0.0)
    noise = np.random.default_rng(3).standard_normal(len(qr)) * 0.5
    return didim.Recording(dt=1e-3, qr=qr, force=sim.force + noise, qm=sim.q1, controller=didim.EmpsCascade())


def test_the_term_is_the_coulomb_friction_modulated_along_the_stroke(record):
    sim = didim.simulate(record, TRUTH, "rigid", terms=TERMS, quantization=0.0)
    w = didim.Model("rigid", terms=TERMS).core().regressor(sim.q, sim.qd, sim.qdd)
    sign = didim.coulomb_sign(sim.qd1)
    np.testing.assert_allclose(w[0, :, 3], sign * np.sin(2 * np.pi * sim.q1 / P), atol=1e-12)
    np.testing.assert_allclose(w[0, :, 4], sign * np.cos(2 * np.pi * sim.q1 / P), atol=1e-12)


def test_its_sensitivities_match_central_differences(record):
    err = check_sensitivities(record, TRUTH, "rigid", terms=TERMS, integrator="rk4", quantization=0.0)
    assert max(err.values()) < 1e-3, err


@pytest.mark.parametrize("method", ["didim", "oe-lm"])
def test_didim_and_oe_lm_recover_it(record, method):
    start = dict(M=80.0, Fv=150.0, Fc=15.0, Aq_sin=0.0, Aq_cos=0.0)
    if method == "didim":
        r = didim_iterate(record, "rigid", start, terms=TERMS, cutoff_hz=20.0)
    else:
        r = oe_lm(record, "rigid", {k: (v if v else 0.5) for k, v in start.items()}, terms=TERMS, cutoff_hz=20.0)
    assert r.converged, r.message
    for k in ("M", "Fv", "Fc"):
        assert r.params[k] == pytest.approx(TRUTH[k], rel=0.02), k
    for k in ("Aq_sin", "Aq_cos"):
        assert r.params[k] == pytest.approx(TRUTH[k], abs=0.3), k
    assert didim.simulate(record, r).relative_error(record) == pytest.approx(
        didim.simulate(record, r.all_params, "rigid", terms=TERMS).relative_error(record), rel=1e-12)


def test_the_doctor_names_it_on_an_independent_record(truthbench):
    load, truth = truthbench
    entry = truth["doctor/poscoulomb_emps"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        d = didim.doctor(load("doctor/poscoulomb_emps_train"), "rigid", load("doctor/poscoulomb_emps_valid"))
    named = [f for f in d.findings if f.effect != "unnamed"]
    assert [f.effect for f in named] == ["position_dependent_coulomb"], d.summary()
    f = named[0]
    assert f.params["period"] == pytest.approx(entry["params"]["Fcq_p"], rel=0.05)
    assert f.params["relative_amplitude"] == pytest.approx(entry["params"]["Fcq_a"], rel=0.2)


@pytest.mark.parametrize("method", ["idim-ls", "didim", "oe-nm", "oe-lm"])
def test_every_method_identifies_it_given_as_a_model_and_its_result_reproduces_its_error(record, method):
    """The term as part of a didim.Model, through identify with every method: the amplitudes within a few percent of
    the truth (0.5 N noise; IDIM-LS differentiates noisy positions) and the result simulates its own force error."""
    m = didim.Model("rigid", terms=tuple(TERMS))
    kw = dict(apM=90.0) if method != "idim-ls" else dict(coulomb_eps=didim.DEFAULT_COULOMB_EPS)
    if method == "oe-nm":
        kw.update(initial={**TRUTH, "M": 90.0, "Fv": 180.0, "Fc": 18.0, "Aq_sin": 4.0, "Aq_cos": -1.0}, max_iter=600)
        del kw["apM"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r = didim.identify(record, m, method, **kw)
    assert r.structure == resolved(m, record, kw.get("coulomb_eps")), method
    amp, amp_true = np.hypot(r.params["Aq_sin"], r.params["Aq_cos"]), np.hypot(TRUTH["Aq_sin"], TRUTH["Aq_cos"])
    assert amp == pytest.approx(amp_true, rel=0.05), (method, r.params)
    assert r.params["Fc"] == pytest.approx(TRUTH["Fc"], rel=0.05), (method, r.params)
    assert didim.simulate(record, r).relative_error(record) == pytest.approx(r.force_error, rel=1e-9)
