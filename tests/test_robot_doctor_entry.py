"""The doctor's entry for robots (issue 36: the entry point; the robot effects are issue 40's): the base model by
DIDIM on the training record, and per joint where the simulation and the held-out record differ. On the data folder's
pendulum, whose plant the model holds (a clean record): no finding, each joint's held-out error near its truth
floor, the residual located in shares that add up."""

import json

import pytest

import didim
from didim.cli import main


def test_the_robot_doctor_locates_each_joints_mismatch_on_held_out_data(robots_dir, tmp_path, capsys):
    truth = json.loads((robots_dir / "truth.json").read_text())["robots"]["pendulum"]
    robot = didim.Robot.from_urdf(robots_dir / "pendulum_cad.urdf")
    ctl = robots_dir / "pendulum_controller.json"
    rec = didim.load_record(robots_dir / "pendulum_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(robots_dir / "pendulum_valid.csv", robot=robot, controller=ctl)
    d = didim.doctor(rec, robot, val)
    assert d.findings == []
    floors = dict(zip(truth["joint_names"], truth["records"]["valid"]["truth_floor_per_joint"]))
    for m in d.joints:
        assert m.error_valid <= 1.3 * floors[m.joint], m.joint
        assert sum(m.shares.values()) == pytest.approx(1.0, abs=1e-9)
        assert 0 <= m.worst_time["share"] <= 1
    assert d.joints[0].error_valid >= d.joints[-1].error_valid  # worst first
    with pytest.raises(didim.DataError, match="validation record is the training record"):
        didim.doctor(rec, robot, rec)
    out = tmp_path / "d.json"
    assert main(["doctor", str(robots_dir / "pendulum_train.csv"), "--urdf", str(robots_dir / "pendulum_cad.urdf"),
                 "--controller", str(ctl), "--validate", str(robots_dir / "pendulum_valid.csv"), "--json", str(out),
                 "--quiet"]) == 0
    got = json.loads(out.read_text())
    assert got["findings"] == [] and {j["joint"] for j in got["joints"]} == set(robot.joint_names)
    assert "where simulation and record differ, per joint" in capsys.readouterr().out


def test_a_robot_joints_stribeck_term_is_worded_as_one_axis_s():
    """One rule for every plant (``didim.doctor.effects.stribeck_physics``): a term against the joint's Coulomb
    friction is a low-speed deficit, else a Stribeck effect, read with the joint's own Fc (a deficit was worded
    "friction is higher at low speed"); a robot's wide law (ε near the Stribeck speeds) is not called its shape."""
    import types

    from didim.doctor.effects import REGISTRY, STRIBECK_DEFICIT
    from didim.doctor.robot import _physics

    res = types.SimpleNamespace(robot=types.SimpleNamespace(joint_names=["j1", "j2"]),
                                params={"Fc_j1": 2.0, "Fc_j2": -1.5}, law=("atan", (0.03, 0.02)))
    assert _physics("stribeck", {"Fs_j1": -0.1, "vs": 0.08}, res, 0) == STRIBECK_DEFICIT
    assert _physics("stribeck", {"Fs_j2": 0.1, "vs": 0.08}, res, 1) == STRIBECK_DEFICIT  # against a negative Fc
    assert _physics("stribeck", {"Fs_j1": 0.4, "vs": 0.05}, res, 0) == REGISTRY["stribeck"].physics
    assert _physics("stribeck") == REGISTRY["stribeck"].physics  # no fit given: the effect's sentence


def test_the_bodies_of_a_start_result_can_be_held_from_the_command_line(robots_dir, tmp_path, capsys):
    """``didim doctor ... --start RESULT.json --hold-bodies``: the start's bodies held in every fit, so that no free
    first moment can take a spring on a joint whose angle to gravity is its own. The pendulum swings in a vertical
    plane: its first joint is such a joint, said as a blind spot with free bodies, not with them held; the final
    model keeps the start's bodies."""
    urdf, ctl = robots_dir / "pendulum_cad.urdf", robots_dir / "pendulum_controller.json"
    train, valid = robots_dir / "pendulum_train.csv", robots_dir / "pendulum_valid.csv"
    base, out = tmp_path / "base.json", tmp_path / "d.json"
    common = ["--urdf", str(urdf), "--controller", str(ctl), "--quiet"]
    assert main(["identify", str(train), *common, "--method", "didim", "--json", str(base)]) == 0
    assert main(["doctor", str(train), *common, "--validate", str(valid), "--hold-bodies"]) == 2
    assert "--hold-bodies holds the bodies of the --start result: give --start" in capsys.readouterr().err
    assert main(["doctor", str(train), *common, "--validate", str(valid), "--json", str(out)]) == 0
    free = json.loads(out.read_text())
    blind = [a for a in free["ambiguities"] if a["effects"] == ["position_dependent_torque", "gravity"]]
    assert [a["joint"] for a in blind] == ["joint1"] and "--hold-bodies" in blind[0]["experiment"]
    result = tmp_path / "final.json"
    assert main(["doctor", str(train), *common, "--validate", str(valid), "--start", str(base), "--hold-bodies",
                 "--json", str(out), "--result", str(result)]) == 0
    held = json.loads(out.read_text())
    assert not [a for a in held["ambiguities"] if "gravity" in a["effects"]]
    start, final = didim.load_result(base), didim.load_result(result)
    for b in start.base.bodies_only:
        assert final.params[b] == start.params[b], b

