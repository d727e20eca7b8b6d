"""The held-out elastic robots of benches/elastic_robots.py (issue 39's "robots of other kinds"): their plant, a Python
loop over Pinocchio written apart from didim, and didim's elastic closed loop are the same plant. The truth's
parameters in didim's loop replay each record to its truth floor (the noise inside the loop, which didim's loop does
not have) and the link side to the deflection the record logs: on a belt-driven prismatic lift under gravity (K in
N/m, 1 µm encoder, exponential friction law, P + PI cascade, 1 kHz) and on the UR10 (PID, 500 Hz, tanh law), each
with two elastic joints. What didim identifies from these records is measured in docs/elastic_robots.md
(`python benches/elastic_robots.py --held-out`), the three-step DIDIM's failure on the vertical lift among it: not a
test here, because since step 2 starts inside its bounds its search on that stiff 12 s loop runs for more than 15
minutes before it fails."""

import numpy as np
import pytest

import didim
from didim.methods.robot import deflection_errors, force_errors

from conftest import bench_module

pytest.importorskip("pinocchio")


@pytest.mark.parametrize("name", ["lift", "ur10"])
def test_the_truth_in_didims_loop_replays_a_held_out_elastic_robots_record_to_its_floor(name, tmp_path):
    """2 s of training record: the truth's force in didim's loop within 3 % of the record's truth floor (measured
    0.284 % against 0.284 % on the lift, 0.521 % against 0.523 % on the UR10 over the full records), and each elastic
    joint's deflection within 3 % RMS of the logged one (the noise moves the link: the floor of the deflection)."""
    bench = bench_module("elastic_robots")
    cad, truth, records, _ = bench.held_out_robot(name, tmp_path, seconds=(2.0, 1.0))
    rec, floor, _ = records["train"]
    assert rec.ql is not None
    sim = bench.replay_truth(rec, cad, truth)
    err, _ = force_errors(rec, sim["force"])
    assert err == pytest.approx(floor, rel=0.03)
    elastic = [cad.joint_names[j] for j in np.flatnonzero(truth["elastic"])]
    defl = deflection_errors(rec, sim, didim.Model(robot=cad, elastic=elastic))
    assert sorted(defl) == sorted(elastic)
    assert max(defl.values()) < 0.03, defl


@pytest.fixture(scope="module")
def ur10_shared(tmp_path_factory):
    """The UR10 under PID with every elastic joint's harmonics up to 1.4 times the highest mode (21 Hz), 16 s."""
    bench = bench_module("elastic_robots")
    return bench.held_out_robot("ur10_shared", tmp_path_factory.mktemp("ur10_shared"), seconds=(16.0, 1.0))


def test_a_rigid_step_that_cannot_start_on_an_elastic_record_does_not_blame_a_right_urdf(ur10_shared):
    """The UR10 under PID with every elastic joint's harmonics up to 1.4 times the highest mode: whatever rigid DIDIM
    says when it cannot start, the URDF is the robot's (the truth built on it replays the record to its floor). It
    said "the URDF probably does not describe this record's robot"; below another robot's share of the force
    unexplained it now names elastic joints as the other cause."""
    cad, truth, records, _ = ur10_shared
    rec = records["train"][0]
    try:
        didim.identify(rec, cad, "didim")
    except didim.SimulationError as e:
        assert "URDF probably does not describe" not in str(e)


def test_step_2_splits_a_vertical_lift_without_changing_the_weight_it_holds(tmp_path):
    """Step 2's split of a rigid estimate into rotor and link (eqs. (23)-(27)) keeps a joint's total inertia and moves
    the rotor's share into its own body. On a vertical prismatic joint that body's mass is the weight the joint holds,
    which the rigid step fixes from the static force (the lift: 17.2 kg, while the motor sees 10.5 kg through the
    belt above its mode), and every split of that total needed a negative mass: none of step 2's grid could be
    simulated. Such a joint keeps its chain (its static torques those of the rigid step, to rounding) and takes its
    rotor from λ: Ia = λ/(1 − λ) M_jj, positive at every λ; the revolute shoulder keeps its total. (λ, f, ζ) come back
    from the split's θ."""
    from didim.methods.robot import ELASTIC_GRID_LAMBDA, _ElasticSplit, _model_of

    bench = bench_module("elastic_robots")
    cad, truth, records, _ = bench.held_out_robot("lift", tmp_path, seconds=(3.0, 1.0))
    rec = records["train"][0]
    rigid = didim.identify(rec, cad, "idim-ls")
    model = didim.Model(robot=cad, elastic=["lift", "shoulder"])
    split = _ElasticSplit.of_rigid(rec, rigid, model)
    assert split.holds == [True, False]
    q = split.qmid[None]
    zero = np.zeros_like(q)
    chain0 = cad.with_inertial_params(split.pi1[cad.ndof:])
    g0 = chain0.rnea(q, zero, zero)[0]
    total = split.total[1]
    for lam in ELASTIC_GRID_LAMBDA:
        x = np.array([[lam, 14.0, 0.03], [lam, 19.0, 0.02]])
        theta = split.theta(x)
        chain, d = _model_of(model, split.base, theta)
        g = chain.rnea(q, zero, zero)[0]
        assert np.allclose(g[0], g0[0], rtol=1e-9, atol=0), (lam, g, g0)
        m = chain.mass_matrix(split.qmid)
        ia = d["armature"]
        assert ia[0] == pytest.approx(lam / (1 - lam) * m[0, 0], rel=1e-9)
        assert ia[0] > 0
        assert ia[1] + m[1, 1] == pytest.approx(total, rel=1e-9)
        assert np.allclose(split.x_of(theta), x, rtol=1e-9, atol=1e-12)


def test_three_step_didim_identifies_the_held_out_ur10_and_predicts_its_validation_record(tmp_path):
    """The held-out UR10 under PID (500 Hz, tanh law, shoulder lift 7 Hz and wrist 1 21 Hz elastic), from the motor
    side, against issue 39's done-when: each elastic joint's K, rotor and Fv within 5 %, its mode within 3 % of the
    truth's locked-rotor mode, the validation record within 1.2 times its truth floor.

    Step 3's motor rows used to carry the springs, and its link rows, which hold exactly on the simulated states,
    pinned the link side's parameters to step 1's rigid fit: the shoulder lift's offset came out 1.84 N·m for 0.62,
    its link's first moment 0.032 for −0.106, wrist 1's K +4.3 % (+8.3 % the session before), and the validation
    record at 1.507 times its floor. With the link's equation in the motor rows (methods.robot._model_columns),
    measured on one core: the validation at 1.03 times its floor, K −0.05 % and −0.33 %, the modes within 0.2 %."""
    import math

    import pinocchio as pin

    from didim.methods.robot import simulate_robot

    bench = bench_module("elastic_robots")
    cad, t, records, _ = bench.held_out_robot("ur10", tmp_path, seconds=(16.0, 8.0))
    rec = records["train"][0]
    val, floor, _ = records["valid"]
    joints = list(cad.joint_names)
    elastic = [joints[j] for j in np.flatnonzero(t["elastic"])]
    res = didim.identify(rec, cad, "didim", elastic=elastic)
    assert "no_mode" not in res.options, res.message
    t["model"].armature = np.zeros(cad.ndof)
    for j in elastic:
        i = joints.index(j)
        qmid = np.array([res.options["modes"].get(n, {"q_mid": np.nan})["q_mid"] for n in joints])
        qmid = np.where(np.isnan(qmid), 0.5 * (rec.qm.min(axis=0) + rec.qm.max(axis=0)), qmid)
        f_true = math.sqrt(t["K"][i] / pin.crba(t["model"], t["model"].createData(), qmid)[i, i]) / (2 * math.pi)
        assert res.options["modes"][j]["f_n_flex"] == pytest.approx(f_true, rel=0.03), j
        for p, truth in (("K", t["K"][i]), ("Ia", t["Ia"][i]), ("Fv", t["Fv"][i])):
            assert res.params[f"{p}_{j}"] == pytest.approx(truth, rel=0.05), (p, j)
    err, _ = force_errors(val, simulate_robot(val, res)["force"])
    assert err < 1.2 * floor, (err, floor)


def test_a_joint_the_rigid_steps_split_shows_no_mode_of_is_split_again_from_the_others_elastic_model(ur10_shared):
    """The rigid step, below 1.25 Hz, sees little of wrist 1's inertia beside its gravity and friction: it put the
    wrist's total 16 % above the truth's, its link (12 % of the total) twice the truth's, and step 2 from that split
    found the rigid wrist better than any mode ("no mode of wrist_1_joint"). The three steps now fit the model with
    the shoulder lift elastic first and split the wrist from it (its total within 5 %): the wrist's mode within 3 %
    of the truth's locked-rotor mode (measured −1.3 %: 20.96 against 21.23 Hz), the shoulder lift's K within 1 %
    (−0.12 %)."""
    import math

    cad, truth, records, _ = ur10_shared
    rec = records["train"][0]
    said = []
    r = didim.identify(rec, cad, "didim", elastic=["shoulder_lift_joint", "wrist_1_joint"], progress=said.append)
    assert not r.options.get("no_mode"), r.message
    assert any("step 2 again from that model's split" in s for s in said)
    j = cad.joint_names.index("wrist_1_joint")
    # the truth's locked-rotor mode at the method's mid-stroke pose (the truth's chain there)
    m = r.options["modes"]["wrist_1_joint"]
    q = 0.5 * (rec.qm.min(axis=0) + rec.qm.max(axis=0))  # the split's mid-stroke pose
    mjj = cad.with_inertial_params(truth["pi"]).mass_matrix(q)[j, j]
    f_truth = math.sqrt(truth["K"][j] / mjj) / (2 * math.pi)
    assert m["f_n_flex"] == pytest.approx(f_truth, rel=0.03), (m, f_truth)
    k = cad.joint_names.index("shoulder_lift_joint")
    assert r.params["K_shoulder_lift_joint"] == pytest.approx(truth["K"][k], rel=0.01)
