"""The doctor on robots (issue 40): on ../shared/data/robotdoctor (a rigid UR5 of an independent simulator, Pinocchio
and its own code, plus one concealed effect per record pair; truth.json says which), each effect is named on its
joint, adopted, and confirmed on the held-out record; the clean record gets no finding."""

import json
from pathlib import Path

import pytest

import didim

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "robotdoctor"
#: truth.json's effect names as the doctor names them
NAMES = {"stribeck": "stribeck", "flexible_joint": "flexibility", "delay": "delay", "force_lag": "delay",
         "asymmetric_coulomb": "asymmetric_friction", "spring_counterbalance": "position_dependent_torque",
         "load_dependent_friction": "load_dependent_friction", "backlash": "backlash"}


def _diagnose(key):
    if not (DATA / f"ur5_{key}_train.csv").exists():
        pytest.skip("../shared/data/robotdoctor is not here")
    robot = didim.Robot.from_urdf(DATA / "ur5_cad.urdf")
    ctl = DATA / "ur5_controller.json"
    rec = didim.load_record(DATA / f"ur5_{key}_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(DATA / f"ur5_{key}_valid.csv", robot=robot, controller=ctl)
    truth = json.loads((DATA / "truth.json").read_text())["records"][key]
    return robot, didim.doctor(rec, robot, val), truth


@pytest.mark.parametrize("key", ["d1", "d2", "d3", "d5"])
def test_each_concealed_effect_is_named_on_its_joint(key):
    robot, d, truth = _diagnose(key)
    want = NAMES[truth["effect"]]
    joint = None if truth["joint_1based"] == "all" else robot.joint_names[truth["joint_1based"] - 1]
    got = [(f.effect, f.joint) for f in d.findings]
    assert got and got[0] == (want, joint), d.summary()
    first = d.findings[0]
    # confirmed on the held-out record: the force error of the joints it acts on falls by 5 % of itself at least
    assert first.fit["valid_after"] < 0.95 * first.fit["valid_before"]
    assert first.statistic["dm_p_value"] < 0.01
    # nothing else named on another joint (at most one finding beyond the effect, none as large)
    assert len(d.findings) <= 2, d.summary()
    out = d.to_dict()
    assert out["findings"][0]["effect"] == want and out["findings"][0]["joint"] == joint


def test_the_clean_record_gets_no_finding():
    _, d, truth = _diagnose("d4")
    assert truth["effect"] == "none"
    assert d.findings == [], d.summary()
    # the one blind spot of a UR5 with free bodies: a spring A·sin(q + φ) on the shoulder lift (whose angle is its
    # links' angle to gravity, the shoulder pan's axis being vertical) is its links' gravity; the elbow's and wrists'
    # angles to gravity add the shoulder's, and a spring there stays testable
    blind = [a for a in d.ambiguities if a["effects"] == ["position_dependent_torque", "gravity"]]
    assert [a["joint"] for a in blind] == ["shoulder_lift_joint"], d.summary()
    assert blind[0]["shared_pct"] > 99.9999 and "frozen=" in blind[0]["experiment"]
    assert "ambiguous on shoulder_lift_joint: position_dependent_torque or gravity" in d.summary()


def test_held_bodies_leave_no_blind_spot():
    """With the bodies held (``frozen``) no first moment can take a spring: every joint's sinusoid keeps a part of
    its own beyond the model's columns, and no blind spot is said."""
    if not (DATA / "ur5_d4_train.csv").exists():
        pytest.skip("../shared/data/robotdoctor is not here")
    robot = didim.Robot.from_urdf(DATA / "ur5_cad.urdf")
    ctl = DATA / "ur5_controller.json"
    rec = didim.load_record(DATA / "ur5_d4_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(DATA / "ur5_d4_valid.csv", robot=robot, controller=ctl)
    base = didim.identify(rec, robot, "didim")
    d = didim.doctor(rec, robot, val, initial=base, frozen={b: base.params[b] for b in base.base.bodies_only})
    assert not [a for a in d.ambiguities if "gravity" in a["effects"]], d.summary()
    assert d.findings == [], d.summary()


def test_step_2_at_a_bound_is_no_mode():
    """Step 2's best split of a joint made elastic is no oscillating mode when the rotor's share is at a bound of its
    search, its damping ratio 1 or more, or its mode at the Nyquist frequency (robotdoctor's d5 searched a "mode" at
    λ = 0.001, 143 Hz, ζ = 2.8 for 10 minutes); a mode inside them passes. The verdict is the three steps' own
    (``didim_elastic`` stops there for every caller), which the doctor's adoption reports. Step 2's model damps a
    spring at most ELASTIC_ZETA_MAX of critical (the held-out UR10's wrist wandered to ζ ≈ 50 without it, 2 minutes a
    simulation), and a ratio at that cap is no mode either."""
    import numpy as np

    from didim.methods.robot import ELASTIC_ZETA_MAX, no_mode

    assert ELASTIC_ZETA_MAX == 1.0  # a damping ratio of 1: no oscillation

    dt = 1e-3
    assert no_mode(np.array([[0.11, 15.3, 0.02]]), ["elbow_joint"], dt) == {}  # d3's elbow: a mode
    for row, words in (([0.001, 143.0, 0.5], "λ = 0.001"), ([0.3, 143.0, 2.8], "damping ratio 2.8"),
                       ([0.3, 499.0, 0.1], "Nyquist"), ([0.999, 40.0, 0.1], "λ = 0.999"),
                       ([0.3, 40.0, 1.0], "damping ratio 1 ")):
        why = no_mode(np.array([[0.11, 15.3, 0.02], row]), ["shoulder_lift_joint", "elbow_joint"], dt)
        assert list(why) == ["elbow_joint"] and words in why["elbow_joint"], why


def test_a_start_is_a_robots(emps):
    """``initial`` (the base fit's start) is a robot doctor's: one axis's doctor refuses it by name, before any fit."""
    with pytest.raises(didim.DataError, match="initial is a robot's"):
        didim.doctor(emps, "rigid", initial={"M": 95.0})


def test_a_spring_that_bends_the_base_fit_is_named_on_its_joint(tmp_path):
    """benches/robot_doctor_heldout.py's e3, from an independent simulator (Python RK4 over Pinocchio): an RPR arm
    with a spring −2 sin(q + 0.4) + 0.3 N·m on its vertical base axis. The rigid base model, bent by it, misses
    base_yaw by 17 % on the training record and 56 % held out, so the spring's training fit does not predict the
    held-out residual, which the carry-over check once took for noise (a wrong joint then: the wrist). The refit in
    closed loop decides: the first finding is the spring on base_yaw, its amplitude within 15 % of the truth
    (2.18 N·m measured)."""
    pytest.importorskip("pinocchio")
    from conftest import bench_module

    t = bench_module("robot_doctor_heldout").make_case("e3", tmp_path)
    robot = didim.Robot.from_urdf(tmp_path / t["urdf"])
    ctl = tmp_path / t["controller"]
    rec = didim.load_record(tmp_path / "e3_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(tmp_path / "e3_valid.csv", robot=robot, controller=ctl)
    d = didim.doctor(rec, robot, val, max_findings=1)
    assert d.findings, d.summary()
    f = d.findings[0]
    assert (f.effect, f.joint) == ("position_dependent_torque", "base_yaw"), d.summary()
    assert f.params["amplitude"] == pytest.approx(t["parameters"]["k"], rel=0.15), f.params


def test_a_spring_the_held_bodies_cannot_take_is_named_with_its_size(tmp_path):
    """A spring −0.5 sin(q + 0.4) + 0.05 N·m on the held-out RPR arm's wrist (benches/robot_doctor_heldout.py's
    independent simulator, Python RK4 over Pinocchio), whose link's gravity is the same kind of sinusoid. The bodies
    are held at a fit of the same arm without the spring (``frozen``, as the KR300's published bodies), the base fit
    starting there: only the wrist's drive is free, and the spring is most of the wrist's residual (15 % of its
    force). The candidate's columns are tested beyond the model's free columns, and its coefficients for the
    carry-over check are fitted by feasible GLS under the alternative: with the whitening fitted on the residual
    itself they were −1.38, 1.47 where the spring's are 0.46, 0.19, the check said the fit did not carry over, and
    nothing was named. Named first on the wrist, amplitude within 10 % and phase within 0.1 rad (measured 0.500 N·m,
    0.400 rad)."""
    from conftest import robot_doctor_case

    spring = dict(robot="rpr", seed=13, effect=dict(kind="spring", joint=2, k=0.5, phi=0.4, c=0.05),
                  want="position_dependent_torque")
    robot, _, rec, val = robot_doctor_case("t_wrist_spring", spring, tmp_path)
    _, _, clean_rec, _ = robot_doctor_case("t_wrist_clean", dict(robot="rpr", seed=13, effect=None, want=None),
                                           tmp_path)
    clean = didim.identify(clean_rec, robot)
    held = {b: clean.params[b] for b in clean.base.bodies_only}
    d = didim.doctor(rec, robot, val, frozen=held, initial=clean, max_findings=1)
    assert d.findings, d.summary()
    f = d.findings[0]
    assert (f.effect, f.joint) == ("position_dependent_torque", "wrist"), d.summary()
    assert f.params["amplitude"] == pytest.approx(0.5, rel=0.10), f.params
    assert abs(f.params["phase_rad"] - 0.4) < 0.1, f.params


def test_a_stribeck_hump_is_named_at_the_speed_its_refits_choose(tmp_path):
    """benches/robot_doctor_sweep.py's n13 (the independent simulator's RPR arm, seed 53): a Stribeck hump of 0.6 Fc
    at 0.05 rad/s on the wrist, under a tanh law of 0.03 rad/s. The base's law, fitted without the hump, sharpened to
    0.0072 rad/s and took part of it, and the test chose 0.025 rad/s, where the refit could not fit the hump (its
    held-out error rose, 1.07 -> 1.09 %): nothing was named. The speed is now chosen by refits, as one axis's
    (effects.speed_search): named on the wrist, its speed within 20 % of the truth and the hump within 35 %
    (measured 0.0527 rad/s, 0.101 N·m against 0.132), the held-out error near the joint's floor (0.76 % against
    0.73 %; asserted below 0.85 %)."""
    from conftest import robot_doctor_case

    hump = dict(robot="rpr", seed=53, effect=dict(kind="stribeck", joint=2, dF_over_Fc=0.6, vst=0.05), want="stribeck")
    robot, t, rec, val = robot_doctor_case("t_wrist_hump", hump, tmp_path)
    d = didim.doctor(rec, robot, val, max_findings=1)
    assert d.findings, d.summary()
    f = d.findings[0]
    assert (f.effect, f.joint) == ("stribeck", "wrist"), d.summary()
    assert f.params["vs"] == pytest.approx(0.05, rel=0.2), f.params
    assert abs(f.params["Fs_wrist"]) == pytest.approx(t["parameters"]["dF"], rel=0.35), f.params
    assert f.fit["valid_after"] < 0.0085, f.fit


def test_a_candidate_tried_brings_its_look_alike_significant_or_not():
    """As for one axis (Effect.tried_with), a mode on a joint and a delay on every joint are tried together: a
    flexibility candidate brings the best-ranked delay not tried yet, whatever its training p-value (held-out e8: a
    3 ms force lag on every Panda joint ranked flexibility first, and the delay never came up); a look-alike already
    among the tries, or tried on this model, is not added again."""
    import numpy as np

    from didim.doctor.robot import _Candidate, _with_look_alikes

    def cand(effect, joint, p):
        c = _Candidate(effect, joint, {} if joint is None else {joint: np.zeros((3, 1))}, {})
        c.p_adj = p
        return c

    flex, asym, delay = cand("flexibility", 1, 1e-9), cand("asymmetric_friction", 0, 1e-5), cand("delay", None, 0.96)
    ranked = [flex, asym, cand("stribeck", 2, 0.5), delay]
    assert _with_look_alikes([flex, asym], ranked, set()) == [flex, asym, delay]
    assert _with_look_alikes([flex, delay], ranked, set()) == [flex, delay]
    assert _with_look_alikes([flex], ranked, {("delay", None)}) == [flex]
    assert _with_look_alikes([asym], ranked, set()) == [asym]
    # a delay brings the best-ranked mode not tried yet
    flex2 = cand("flexibility", 3, 0.2)
    assert _with_look_alikes([delay], [delay, flex2, flex], set()) == [delay, flex2]


def test_a_base_that_cannot_run_the_held_out_record_is_said_not_raised(robots_dir, monkeypatch):
    """A base model that fits the training poses but cannot be simulated on the validation record's (a body that is no
    physical arm there: the held-out Panda with backlash, e7, raised a SimulationError out of didim.doctor): the doctor
    says so in a note naming both records and what to do, names no effect (nothing can be judged on held-out data),
    and locates the mismatch on the training record."""
    from didim import SimulationError
    from didim.methods import robot as R

    robot = didim.Robot.from_urdf(robots_dir / "pendulum_cad.urdf")
    ctl = robots_dir / "pendulum_controller.json"
    rec = didim.load_record(robots_dir / "pendulum_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(robots_dir / "pendulum_valid.csv", robot=robot, controller=ctl)
    real = R.simulate_robot

    def fails_on_val(r, res, *a, **k):
        if r is val:
            raise SimulationError("the robot's closed loop cannot be simulated with these parameters: joint joint1: "
                                  "its articulated inertia is not positive (-0.1)")
        return real(r, res, *a, **k)

    monkeypatch.setattr(R, "simulate_robot", fails_on_val)
    d = didim.doctor(rec, robot, val)
    assert d.findings == [] and d.rounds == []
    note = " ".join(d.notes)
    assert "cannot be simulated on" in note and val.name in note and "frozen=" in note, d.notes
    assert d.validate == val.name and "cannot be simulated on the validation record" in d.summary()
    assert all(m.error_train > 0 for m in d.joints)


def _two_joints(axis_a: str, axis_b: str) -> str:
    return f"""<robot name="two">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0.02 0.05"/><mass value="5.0"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.2 0 0.03"/><mass value="2.0"/>
    <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial></link>
  <joint name="a" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.3"/>
    <axis xyz="{axis_a}"/><limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
  <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.4 0 0"/>
    <axis xyz="{axis_b}"/><limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
</robot>"""


@pytest.mark.parametrize("axes, want", [
    (("0 0 1", "0 1 0"), [False, True]),  # a vertical base, then a horizontal joint: its angle to gravity is its own
    (("0 1 0", "0 1 0"), [True, False]),  # a planar arm in the vertical plane: the elbow's angle adds the shoulder's
    (("1 0 0", "0 1 0"), [True, False]),  # a horizontal base turns the second axis against gravity
    (("0 0 1", "0 0 1"), [False, False]),  # vertical axes: gravity gives them no torque at all
])
def test_a_joint_whose_sinusoid_its_links_gravity_gives_is_found_from_the_kinematics(axes, want):
    """The blind spot's structure (``_gravity_like``): a torque A·sin(q + φ) on a joint is one its links' centres of
    mass can give it exactly when the joints before it turn about the vertical; found on random poses of the arm,
    whatever the record."""
    from didim.doctor.robot import _gravity_like

    robot = didim.Robot.from_urdf_string(_two_joints(*axes))
    assert [_gravity_like(robot, j) for j in range(robot.ndof)] == want

