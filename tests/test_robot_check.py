"""Each joint's controller against its log, on robots as on one axis: the usual mistakes of a robot's controller file
(every gain 30 % off, one joint's gain ten times, two joints' controllers swapped, a sample of delay, a force that is
a current loop's output) are refused before any fit, naming the joint and, where one explains the log, the mistake;
the right file passes. On the data folder's records (an independent simulator: its controllers replay the force to
1e-12)."""

import json
import math

import numpy as np
import pytest
from scipy import signal

import didim
from didim.check import check_robot_controllers
from didim.cli import main


def _controllers(robots_dir, robot="pendulum"):
    return json.loads((robots_dir / f"{robot}_controller.json").read_text())


def _record(robots_dir, spec, robot="pendulum", force=None, tmp_path=None):
    bot = didim.Robot.from_urdf(robots_dir / f"{robot}_cad.urdf")
    ctl = didim.load_joint_controllers(_write(tmp_path / "ctl.json", spec))
    rec = didim.load_record(robots_dir / f"{robot}_train.csv", robot=bot, controller=ctl)
    if force is not None:
        import dataclasses

        rec = dataclasses.replace(rec, force=force(rec.force))
    return bot, rec


def _write(path, spec):
    path.write_text(json.dumps(spec))
    return path


def _scaled(entry, k):
    return {**entry, "b_r": [k * x for x in entry["b_r"]], "b_y": [k * x for x in entry["b_y"]]}


def test_the_right_controllers_pass_on_every_joint(robots_dir, tmp_path):
    _, rec = _record(robots_dir, _controllers(robots_dir, "ur5"), "ur5", tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    assert chk.passed
    assert chk.mismatch < 1e-6  # the files replay the force to 1e-12 (the data folder's README)
    assert len(chk.joints) == 6


def test_every_gain_30_percent_off_is_refused_naming_the_scale(robots_dir, tmp_path):
    spec = _controllers(robots_dir)
    spec["joints"] = [_scaled(c, 0.7) for c in spec["joints"]]
    bot, rec = _record(robots_dir, spec, tmp_path=tmp_path)
    with pytest.raises(didim.DataError) as e:
        didim.identify(rec, bot, "idim-ls")
    msg = str(e.value)
    assert "joint1" in msg and "joint2" in msg
    assert "scale is off by a factor 1.429" in msg  # the log is 1/0.7 of the law


def test_one_joint_gain_times_ten_is_refused_on_that_joint_only(robots_dir, tmp_path):
    spec = _controllers(robots_dir)
    spec["joints"][1] = _scaled(spec["joints"][1], 10.0)
    _, rec = _record(robots_dir, spec, tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    assert chk.failed() == ["joint2"]
    assert "factor 0.1" in chk.joints["joint2"].likely


@pytest.mark.parametrize("joints, k", [((1,), 10.0), ((1,), 0.7), (tuple(range(6)), 0.7)])
def test_a_gain_scale_is_named_on_the_joints_that_hold_a_weight_too(robots_dir, tmp_path, joints, k):
    # the UR5's shoulder and elbow start their integrators at the logged force (the weight they hold), not at the
    # law's rest: the factor is fitted beside the law's free responses, as the comparison takes them out (the plain
    # ratio f·c/c·c missed it: a joint's gains 10 times too large refused with "none of the usual mistakes")
    spec = _controllers(robots_dir, "ur5")
    for j in joints:
        spec["joints"][j] = _scaled(spec["joints"][j], k)
    _, rec = _record(robots_dir, spec, "ur5", tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    names = [rec.joint_names[j] for j in joints]
    assert chk.failed() == names
    for j in names:
        assert f"factor {1 / k:.4g}" in chk.joints[j].likely and chk.joints[j].likely_mismatch < 1e-6, j
    assert len(chk.summary()) < 1000  # the joints of one cause said once


def test_swapped_controllers_are_named_as_swapped(robots_dir, tmp_path):
    spec = _controllers(robots_dir, "ur5")
    spec["joints"][3], spec["joints"][4] = spec["joints"][4], spec["joints"][3]
    _, rec = _record(robots_dir, spec, "ur5", tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    assert chk.failed() == ["wrist_1_joint", "wrist_2_joint"]
    assert chk.swapped == [("wrist_1_joint", "wrist_2_joint")]
    assert "swapped" in chk.summary()


def test_a_sample_of_delay_is_named(robots_dir, tmp_path):
    # the force logged one sample late: the drive computed its command a sample after the positions it read
    spec = _controllers(robots_dir)
    _, rec = _record(robots_dir, spec, force=lambda f: np.vstack([f[:1], f[:-1]]), tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    assert chk.failed() == ["joint1", "joint2"]
    for c in chk.joints.values():
        assert "1 sample late" in c.likely
    # the joints with one cause are said once, on one line, each joint's figures beside
    text = chk.summary()
    assert "joints joint1, joint2:" in text and text.count("1 sample late") == 1
    assert len(max(text.splitlines(), key=len)) < 1000


def test_a_measured_current_is_refused_with_no_usual_mistake(robots_dir, tmp_path):
    # the force is the command through a 300 Hz current loop (a first-order lag), not the command itself
    b, a = signal.bilinear([2 * math.pi * 300], [1, 2 * math.pi * 300], fs=1000)
    spec = _controllers(robots_dir)
    _, rec = _record(robots_dir, spec, force=lambda f: signal.lfilter(b, a, f - f[0], axis=0) + f[0],
                     tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    assert not chk.passed
    assert "not a measured current" in chk.summary()


def test_the_command_line_refuses_with_exit_2_and_checks_a_joints_file(robots_dir, tmp_path, capsys):
    spec = _controllers(robots_dir)
    spec["joints"][0] = _scaled(spec["joints"][0], 10.0)
    bad = _write(tmp_path / "bad.json", spec)
    rec = str(robots_dir / "pendulum_train.csv")
    assert main(["controller", "check", rec, "--controller", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "joint 1" in err or "joints 1" in err
    ok = str(robots_dir / "pendulum_controller.json")
    assert main(["controller", "check", rec, "--controller", ok, "--urdf", str(robots_dir / "pendulum_cad.urdf")]) == 0
    assert main(["identify", rec, "--urdf", str(robots_dir / "pendulum_cad.urdf"), "--controller", str(bad),
                 "--method", "idim-ls"]) == 2
    assert "joint1" in capsys.readouterr().err


def test_without_a_controller_each_joints_law_is_fitted_from_its_log(robots_dir, tmp_path, capsys):
    import shutil

    shutil.copy(robots_dir / "pendulum_train.csv", tmp_path / "pendulum.csv")  # no controller file beside it
    robot = didim.Robot.from_urdf(robots_dir / "pendulum_cad.urdf")
    rec = didim.load_record(tmp_path / "pendulum.csv", robot=robot)
    assert len(rec.controller_origin) == 2 and "fitted from the log" in rec.controller_origin[0]
    chk = check_robot_controllers(rec)
    assert chk.passed and chk.mismatch < 1e-6  # the fitted laws replay the logged force (the true ones: 1e-12)
    known = didim.load_record(robots_dir / "pendulum_train.csv", robot=robot,
                              controller=robots_dir / "pendulum_controller.json")
    a, b = didim.identify(rec, robot, "idim-ls"), didim.identify(known, robot, "idim-ls")
    for k, v in b.params.items():  # the inverse model does not depend on the controller
        assert a.params[k] == pytest.approx(v, rel=1e-9, abs=1e-12), k
    assert any("no controller was described" in n for n in a.notes)
    out = tmp_path / "fitted.json"
    assert main(["controller", "fit", str(tmp_path / "pendulum.csv"), "--urdf", str(robots_dir / "pendulum_cad.urdf"),
                 "--json", str(out)]) == 0
    assert json.loads(out.read_text())["type"] == "joints"
    assert main(["controller", "check", str(tmp_path / "pendulum.csv"), "--controller", str(out)]) == 0


def test_a_sample_of_delay_in_the_description_is_named(robots_dir, tmp_path):
    spec = _controllers(robots_dir)
    c = spec["joints"][1]
    spec["joints"][1] = {**c, "b_r": [0.0] + c["b_r"], "b_y": [0.0] + c["b_y"]}  # a computation delay the drive lacks
    _, rec = _record(robots_dir, spec, tmp_path=tmp_path)
    chk = check_robot_controllers(rec)
    assert chk.failed() == ["joint2"]
    assert "description has 1 sample of delay" in chk.joints["joint2"].likely


def test_a_record_with_more_joints_than_the_robot_is_refused(robots_dir):
    robot = didim.Robot.from_urdf(robots_dir / "pendulum_cad.urdf")
    with pytest.raises(didim.DataError, match=r"columns for 6 joints .* the robot has 2"):
        didim.load_record(robots_dir / "ur5_train.csv", robot=robot, controller=robots_dir / "pendulum_controller.json")


def test_the_public_check_and_fit_take_a_robots_record_as_one_axis_s(robots_dir, tmp_path):
    """``didim.check_controller`` and ``didim.fit_controller`` serve every plant: on a robot's record each joint's
    controller is checked (or fitted) on its own log. The fitted laws replay each joint's logged force to 1e-6 (the
    files' true laws to 1e-9), and a joint with a gain ten times off is the one refused."""
    _, rec = _record(robots_dir, _controllers(robots_dir, "ur5"), "ur5", tmp_path=tmp_path)
    chk = didim.check_controller(rec)
    assert chk.passed and set(chk.joints) == set(rec.joint_names) and chk.mismatch < 1e-6
    fits = didim.fit_controller(rec)
    assert list(fits) == list(rec.joint_names)
    for name, f in fits.items():
        assert f.error < 1e-6, (name, f.summary())  # measured 5e-9 to 8e-8 (the written coefficients' rounding)
    assert len(fits.summary().splitlines()) == 6
    # the fitted laws as a joints file: read back, they pass the check on the same log
    again = didim.load_record(robots_dir / "ur5_train.csv", robot=didim.Robot.from_urdf(robots_dir / "ur5_cad.urdf"),
                              controller=fits.to_dict())
    assert didim.check_controller(again).mismatch < 1e-6
    spec = _controllers(robots_dir, "ur5")
    spec["joints"][2] = _scaled(spec["joints"][2], 10.0)
    _, bad = _record(robots_dir, spec, "ur5", tmp_path=tmp_path)
    assert didim.check_controller(bad).failed() == [bad.joint_names[2]]
    with pytest.raises(didim.DataError, match="one axis's"):
        check_robot_controllers(bad.joint(0))


def test_a_controller_file_named_for_the_robot_serves_each_of_its_records(robots_dir, tmp_path):
    """``NAME_controller.json`` beside a record, else the name cut at its last underscores (``ur5_valid.csv`` reads
    ``ur5_controller.json``, as the data folders keep one controller per robot): the same controllers as given by
    hand, none fitted from the log; a record whose prefixes name no file still has its laws fitted."""
    import shutil

    robot = didim.Robot.from_urdf(robots_dir / "pendulum_cad.urdf")
    shutil.copy(robots_dir / "pendulum_controller.json", tmp_path / "pendulum_controller.json")
    for name in ("pendulum_valid.csv", "pendulum_valid_2.csv"):
        shutil.copy(robots_dir / "pendulum_valid.csv", tmp_path / name)
        rec = didim.load_record(tmp_path / name, robot=robot)
        assert not rec.controller_origin, rec.controller_origin
        assert rec.controllers == didim.load_record(robots_dir / "pendulum_valid.csv", robot=robot,
                                                    controller=robots_dir / "pendulum_controller.json").controllers
    shutil.copy(robots_dir / "pendulum_valid.csv", tmp_path / "arm_valid.csv")
    assert len(didim.load_record(tmp_path / "arm_valid.csv", robot=robot).controller_origin) == 2
