"""Coulomb friction that varies along the stroke differently in each direction, as cubic B-spline terms per direction
(the core's `CoulombSpline` basis, `coulomb_spline_fwd`/`_bwd`): the regressor, the sensitivities, identification by
DIDIM, and the doctor naming it on records from the plant of `benches/doctor_independent.py`, independent of didim's
simulator (plain RK4, a rational Coulomb law, a Gaussian and a tanh-shaped friction profile that no B-spline reproduces
exactly, force noise inside the loop, a 5e-8 m encoder)."""

import warnings

import numpy as np
import pytest

import didim
from didim import scenarios as sc
from didim.doctor.effects import spline_profile
from didim.methods.identification import didim_iterate
from didim.methods.oe import check_sensitivities

from conftest import bench_module

plant = bench_module("doctor_independent")  # the independent plant; its "position_dependent_coulomb" has the profiles below
QUANT = plant.QUANT
M, FV = plant.M, plant.FV


def friction_forward(q):
    """Coulomb level moving forward (N): a tight zone, 5 N more around 70 mm (the plant's law)."""
    return 21.0 + 5.0 * np.exp(-(((q - 0.07) / 0.025) ** 2))


def friction_backward(q):
    """Coulomb level moving backward (N): 4 N less beyond about 160 mm (the plant's law)."""
    return 18.0 - 2.0 * (1 + np.tanh((q - 0.16) / 0.02))


def record(qr, seed, name):
    force, qm = plant.simulate(qr, "position_dependent_coulomb", seed=seed)
    return didim.Recording(dt=1e-3, qr=qr, force=force, qm=qm, controller=didim.EmpsCascade(),
                           position_resolution=QUANT, name=name)


@pytest.fixture(scope="module")
def records():
    train = record(sc.emps_like(n=20000), 1, "independent profile (training)")
    valid = record(sc.trapezoid(stroke=0.24, speeds=(0.06, 0.1, 0.03)), 2, "independent profile (validation)")
    return train, valid


def _splines(lo=0.0, hi=0.24, intervals=6):
    w = (hi - lo) / intervals
    return [didim.Term(f"F{d[0]}{j + 1}", f"coulomb_spline_{d}", lo + j * w, width=w)
            for d in ("fwd", "bwd") for j in range(-1, intervals + 2)]


def _bspline(u):
    a = np.abs(u)
    return np.where(a < 1, 2 / 3 - a**2 + a**3 / 2, np.where(a < 2, (2 - a) ** 3 / 6, 0.0))


def test_the_terms_are_bsplines_times_the_sign_of_one_direction():
    rec = didim.Recording(dt=1e-3, qr=sc.emps_like(n=6000), force=np.zeros(6000), qm=sc.emps_like(n=6000),
                          controller=didim.EmpsCascade())
    terms = _splines()[:3] + _splines()[9:12]
    p = {"M": M, "Fv": FV, "Fc": 20.0, **{t.name: 1.0 for t in terms}}
    sim = didim.simulate(rec, p, "rigid", terms=terms)
    w = didim.Model("rigid", terms=terms).core().regressor(sim.q, sim.qd, sim.qdd)
    s = didim.coulomb_sign(sim.qd1)
    for i, t in enumerate(terms):
        side = s * (1 + s) / 2 if t.hypers["side"] > 0 else s * (1 - s) / 2  # 1|0 forward, 0|-1 backward
        np.testing.assert_allclose(w[0, :, 3 + i], _bspline((sim.q1 - t.hypers["center"]) / t.hypers["width"]) * side, atol=1e-12)
    # the whole set of one direction sums to its side of the sign along the stroke (a partition of unity)
    full = _splines()
    wf = didim.Model("rigid", terms=full).core().regressor(sim.q, sim.qd, sim.qdd)[0, :, 3:]
    inside = (sim.q1 > 0.0) & (sim.q1 < 0.24)
    np.testing.assert_allclose(wf[inside, :9].sum(axis=1), (s * (1 + s) / 2)[inside], atol=1e-12)
    np.testing.assert_allclose(wf[inside, 9:].sum(axis=1), (s * (1 - s) / 2)[inside], atol=1e-12)


def test_a_profile_held_within_its_stroke_keeps_its_end_values_beyond_it():
    """With ``lo < hi`` each knot's B-spline reads the position held within [lo, hi] (the doctor's profiles: the stroke
    of the training record), so a profile carries its end values on where the record goes further; inside, the terms
    are the plain ones. Regressor columns against the B-spline written here, on a move past both ends."""
    qr = sc.emps_like(n=6000)
    rec = didim.Recording(dt=1e-3, qr=qr, force=np.zeros(6000), qm=qr, controller=didim.EmpsCascade())
    lo, hi = 0.05, 0.15
    plain = _splines()
    held = [didim.Term(t.name, t.kind, t.hypers["center"], width=t.hypers["width"], side=t.hypers["side"], lo=lo, hi=hi)
            for t in plain]
    p = {"M": M, "Fv": FV, "Fc": 20.0}
    sim = didim.simulate(rec, p, "rigid")
    assert sim.q1.min() < lo and sim.q1.max() > hi
    s = didim.coulomb_sign(sim.qd1)
    w_held = didim.Model("rigid", terms=held).core().regressor(sim.q, sim.qd, sim.qdd)[0, :, 3:]
    w_plain = didim.Model("rigid", terms=plain).core().regressor(sim.q, sim.qd, sim.qdd)[0, :, 3:]
    inside = (sim.q1 >= lo) & (sim.q1 <= hi)
    np.testing.assert_array_equal(w_held[inside], w_plain[inside])
    for i, t in enumerate(held):
        side = s * (1 + s) / 2 if t.hypers["side"] > 0 else s * (1 - s) / 2
        want = _bspline((np.clip(sim.q1, lo, hi) - t.hypers["center"]) / t.hypers["width"]) * side
        np.testing.assert_allclose(w_held[:, i], want, atol=1e-12)
    # saved and read back with its stroke; a stroke with lo > hi is refused, naming it
    again = didim.Model.from_dict(didim.Model("rigid", terms=held).to_dict())
    assert again.terms[0].hypers["lo"] == lo and again.terms[0].hypers["hi"] == hi
    with pytest.raises(didim.DataError, match="lo <= hi"):
        didim.Term("x", "coulomb_spline", 0.1, width=0.05, lo=0.2, hi=0.1)


def test_its_sensitivities_match_central_differences():
    qr = sc.emps_like(n=6000)
    rec = didim.Recording(dt=1e-3, qr=qr, force=np.zeros(len(qr)), qm=qr, controller=didim.EmpsCascade())
    terms = _splines(intervals=3)
    p = {"M": M, "Fv": FV, "Fc": 20.0, **{t.name: (2.0 if t.kind.endswith("fwd") else -1.5) for t in terms}}
    # a relative step of 1e-4: these parameters are a few newtons, and the default 1e-6 (2e-6 N) moves the force by
    # little more than its rounding over a record (the central differences then disagree by 2e-3, the exact
    # sensitivities do not change)
    for integrator in ("rk4", "exponential"):
        err = check_sensitivities(rec, p, "rigid", terms=terms, integrator=integrator, quantization=0.0, rel_step=1e-4)
        assert max(err.values()) < 1e-3, (integrator, err)
    # held within a stroke the record passes both ends of (the slope 0 beyond them)
    held = [didim.Term(t.name, t.kind, t.hypers["center"], width=t.hypers["width"], side=t.hypers["side"], lo=0.05,
                       hi=0.15) for t in terms]
    err = check_sensitivities(rec, p, "rigid", terms=held, quantization=0.0, rel_step=1e-4)
    assert max(err.values()) < 1e-3, err


def test_didim_recovers_both_profiles_from_the_independent_plant(records):
    """Given the structure (direction-dependent Coulomb friction and splines per direction, the last knot of each
    left out as the doctor does), DIDIM recovers the two profiles: their shape along the stroke (mean removed) within
    0.6 N RMS of the truth's, whose variation is 1.3-1.7 N RMS; the masses and viscous friction within 2 %."""
    train, valid = records
    terms = [didim.Term("dFc", "abs_coulomb")] + [t for t in _splines() if t.name not in ("Ff8", "Fb8")]
    start = {"M": 80.0, "Fv": 150.0, "Fc": 15.0, **{t.name: 0.0 for t in terms}}
    r = didim_iterate(train, "rigid", start, terms=terms, cutoff_hz=20.0)
    assert r.converged, r.message
    assert r.params["M"] == pytest.approx(M, rel=0.02)
    assert r.params["Fv"] == pytest.approx(FV, rel=0.02)
    from didim.doctor.fit import State

    st = State(didim.Model("rigid", terms=terms), dict(r.params), {})
    prof = spline_profile(st)
    q = prof["q"]
    fc, dfc = r.params["Fc"], r.params["dFc"]
    for side, truth, sign in (("fwd", friction_forward, 1), ("bwd", friction_backward, -1)):
        fitted = fc + sign * dfc + prof[side]  # the level against the motion along the stroke
        covered = (q > 0.01) & (q < 0.23)  # where the training moves at speed in both directions
        dev = (fitted - truth(q))[covered]
        shape_truth = truth(q)[covered] - np.mean(truth(q)[covered])
        assert np.sqrt(np.mean((dev - dev.mean()) ** 2)) < 0.6, side
        assert np.sqrt(np.mean(shape_truth ** 2)) > 1.2
        assert abs(dev.mean()) < 1.0, side  # the level too, within 1 N
    # the validation record is better explained with the profiles than without
    without = didim_iterate(train, "rigid", {"M": 80.0, "Fv": 150.0, "Fc": 15.0, "dFc": 0.0},
                            terms=terms[:1], cutoff_hz=20.0)
    assert didim.simulate(valid, r).relative_error(valid) < 0.8 * didim.simulate(valid, without).relative_error(valid)


def test_the_doctor_names_the_profile_and_where_it_lies(records):
    """The doctor names the profile, says where it departs most in each direction and gives the mean level per
    direction (the profile per direction carries the direction-dependent level, so direction-dependent friction may be
    taken out again once it is modelled). The plant's rational Coulomb law differs from didim's through zero speed,
    which the doctor may add as a Stribeck-shaped term; nothing else may be named."""
    train, valid = records
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        d = didim.doctor(train, "rigid", valid)
    named = [f.effect for f in d.findings if f.effect != "unnamed"]
    assert "position_dependent_coulomb" in named, d.summary()
    assert set(named) <= {"position_dependent_coulomb", "asymmetric_friction", "stribeck"}, d.summary()
    f = next(f for f in d.findings if f.effect == "position_dependent_coulomb")
    assert "spacing" in f.params, f.params  # the per-direction profile, not the periodic law
    p = final = {**f.params, **_final_summary(d)}
    # forward: the tight zone at 70 mm (+5 N at its centre); backward: the drop of 4 N beyond 160 mm
    assert p["peak_forward_at"] == pytest.approx(0.07, abs=0.02), final
    assert 2.0 < p["peak_forward"] < 5.0, final
    assert p["peak_backward"] < -1.5 and p["peak_backward_at"] > 0.15, final
    q = np.linspace(0.0, 0.24, 241)
    assert p["level_forward"] == pytest.approx(np.mean(friction_forward(q)), abs=1.0), final
    assert p["level_backward"] == pytest.approx(np.mean(friction_backward(q)), abs=1.0), final
    assert "moving forward" in f.words and "mm" in f.words
    assert d.fit["valid_force_after"] < 0.5 * d.fit["valid_force_before"]


def _final_summary(d):
    from didim.doctor.effects import _spline_summary

    return _spline_summary(d.final_state)


def test_identify_with_profile_terms_converges_on_the_emps_with_the_default_options(emps):
    """A user's model with a few profile terms, identified with the defaults: the spline knots near the ends of the
    stroke live where the axis reverses, so the default keeps the reversals in the regression (excluding them, the
    samples left out changed with each iterate and DIDIM alternated between two points for 200 iterations)."""
    w = 0.05
    terms = [didim.Term("Sf_a", "coulomb_spline_fwd", 0.05, width=w), didim.Term("Sf_b", "coulomb_spline_fwd", 0.10, width=w),
             didim.Term("Sb_a", "coulomb_spline_bwd", 0.15, width=w), didim.Term("Sb_b", "coulomb_spline_bwd", 0.20, width=w)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r = didim.identify(emps, didim.Model("rigid", offset=True, terms=terms), "didim")
        base = didim.identify(emps, didim.Model("rigid", offset=True), "didim", reversals="keep")
    assert r.converged, r.message
    # the rigid parameters stay where the base model (same regression samples) has them, and the profile does not
    # make the closed-loop fit worse than it (5.81 % against 5.96 % measured)
    for k in ("M", "Fv", "Fc"):
        assert r.params[k] == pytest.approx(base.params[k], rel=0.05), k
    assert r.force_error <= base.force_error * 1.01


def test_a_full_set_of_knots_is_refused_with_what_to_leave_out(emps):
    """Every knot of both directions beside Fc: the splines of a direction sum to its side of the sign, so the
    regressor is rank-deficient; the error says which knot to leave out, not only to excite the axis more."""
    terms = [didim.Term("dFc", "abs_coulomb")] + _splines(lo=0.0, hi=0.24, intervals=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        with pytest.raises(didim.IdentifiabilityError, match="leave one knot of each direction out"):
            didim.identify(emps, didim.Model("rigid", terms=terms), "didim")


def test_terms_say_what_is_wrong_with_their_width():
    with pytest.raises(didim.DataError, match="needs its width .m.: e.g. didim.Term"):
        didim.Term("a", "coulomb_spline_fwd", 0.1)
    with pytest.raises(didim.DataError, match="knot spacing width > 0 m, got 0.1 and -0.02"):
        didim.Term("a", "coulomb_spline_bwd", 0.1, width=-0.02)
    with pytest.raises(didim.DataError, match="only spline terms have a width"):
        didim.Term("a", "stribeck", 0.01, width=0.05)
    # the older name is the kind with its side fixed, and the hyper-parameters are named
    t = didim.Term("a", "coulomb_spline_fwd", 0.1, width=0.05)
    assert t == didim.Term("a", "coulomb_spline", center=0.1, width=0.05, side=1)
    assert t.spec() == ("a", "coulomb_spline", "motor", [("center", 0.1), ("width", 0.05), ("side", 1.0), ("lo", 0.0),
                                                           ("hi", 0.0)])
