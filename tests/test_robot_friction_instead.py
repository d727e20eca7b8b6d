"""A friction effect on a robot's joint must be separable from that joint's friction fitted otherwise. DIDIM's fixed
point is not the output-error optimum when the loop is noisy: on clean Panda records of the independent Pinocchio loop
(benches/robot_doctor_sweep.py) it ended at 1.1-1.6 times each joint's floor, and a small low-speed term took part of
that difference and was "confirmed" on held-out data (4 of 13 clean pairs with a finding). The doctor now compares the
model without and with the term, each with the joint's own parameters fitted to its output error
(``methods.robot.polish_joint``). The pair here (seed 38) carries a direction-dependent Coulomb friction on joint 6,
and the doctor had also "confirmed" a Stribeck deficit on joint 3."""

import numpy as np
import pytest

import didim
from didim.methods.robot import polish_joint, simulate_robot

from conftest import robot_doctor_case


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    return robot_doctor_case("test_friction_instead", dict(robot="panda", seed=38, effect=dict(
        kind="asymmetric", joint=5, plus=0.8, minus=1.2), want="asymmetric_friction"),
        tmp_path_factory.mktemp("test_friction_instead"))


def test_polish_joint_fits_that_joint_alone_and_lowers_its_output_error(panda):
    cad, truth, rec, val = panda
    res = didim.identify(rec, cad, "didim")
    j = 2
    jn = cad.joint_names[j]
    pol = polish_joint(rec, res, j)
    own = {f"Fv_{jn}", f"Fc_{jn}", f"OF_{jn}", f"Ia_{jn}"}
    # every other parameter and every other joint's smoothing speed held, bit for bit
    assert all(pol.params[k] == v for k, v in res.params.items() if k not in own)
    assert pol.law[0] == res.law[0]
    assert all(a == b for i, (a, b) in enumerate(zip(pol.law[1], res.law[1])) if i != j)
    # the output error of that joint, which it minimises (its loop without the encoders' rounding, smooth in the
    # parameters), does not rise: a least squares from DIDIM's point
    def error(r):
        f = simulate_robot(rec, r, quantize=False)["force"][:, j]
        return np.linalg.norm(rec.force[:, j] - f) / np.linalg.norm(rec.force[:, j])

    assert error(pol) <= error(res) * (1 + 1e-9), (error(res), error(pol))
    # and on the held-out record it stays at the truth's floor, where DIDIM already is (measured: 1.745 % -> 1.768 %
    # with OE-LM's exact sensitivities, 1.734 % with forward differences, of a floor of 1.718 %: a few tenths of a
    # percent either way, the held-out noise of 4 parameters fitted on the training record); from farther above the
    # floor it comes nearer (an earlier DIDIM's 2.02 % -> 1.77 %)
    floor = truth["records"]["valid"]["floor_per_joint"][j]
    before = didim.simulate(val, res).relative_error_per_joint(val)[jn]
    after = didim.simulate(val, pol).relative_error_per_joint(val)[jn]
    assert after < 1.05 * floor, (before, after, floor)
    if before > 1.05 * floor:
        assert after < before, (before, after, floor)


def test_a_friction_term_the_joints_own_friction_explains_is_not_confirmed(panda):
    cad, truth, rec, val = panda
    d = didim.doctor(rec, cad, val)
    named = [(f.effect, f.joint) for f in d.findings]
    assert named == [("asymmetric_friction", "panda_joint6")], named
    asym = d.findings[0]
    # the concealed effect stands the comparison at the joint's output-error optimum (measured 1.68 -> 1.16 %)
    assert asym.fit["valid_polished_with"] < 0.8 * asym.fit["valid_polished_without"], asym.fit
    stribeck = [f for f in d.rejected if f.effect == "stribeck" and f.joint == "panda_joint3"]
    if stribeck:  # tried: rejected by the comparison, with its numbers, or before it by the term's own share
        ev = stribeck[0].evidence
        assert "fitted otherwise explains it" in ev or "the refit's other changes, not the term" in ev, ev
        if "valid_polished_with" in stribeck[0].fit:
            assert stribeck[0].fit["valid_polished_with"] > 0.95 * stribeck[0].fit["valid_polished_without"]
        else:  # the term's own torque on the held-out record is a small share of the joint's residual
            assert stribeck[0].fit["term_share"] < 0.05, stribeck[0].fit
