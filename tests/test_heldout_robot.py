"""A robot nobody here identified before, from a simulator that is not didim's (benches/heldout_robots.py: Python RK4
over Pinocchio's aba, per-joint PID with a filtered derivative and velocity feedforward, the algebraic friction law
with a smoothing speed per joint in its own units, noise inside the loop, 2^18-count encoders and a 1 µm scale on the
quill): an arm with a prismatic quill between two revolute joints. Each joint's Fv and Fc within 5 % of the truth
with DIDIM, the validation record within 1.2 times its truth floor, the payload within 3 % (before the friction law
was per joint, one ε served m/s and rad/s at once: the quill's Fv came out 61 % off)."""

import json
import os

import numpy as np
import pytest

import didim
from didim.robots import payload
from didim.methods.robot import force_errors, simulate_robot

from conftest import bench_module

pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def rpr(tmp_path_factory):
    out = tmp_path_factory.mktemp("heldout")
    rayon = os.environ.get("RAYON_NUM_THREADS")
    bench_module("heldout_robots").main(["--out", str(out), "--only", "rpr", "--jobs", "1", "--no-substep-check"])
    if rayon is None:
        os.environ.pop("RAYON_NUM_THREADS", None)
    return out, json.loads((out / "truth.json").read_text())["robots"]["rpr"]


def _identified_within_bounds(out, truth, method):
    """``method`` on the arm's training record: each joint's friction within 5 % of the truth, the validation record
    simulated with the estimate within 1.2 times its truth floor. Returns the robot, its controllers and the result."""
    robot = didim.Robot.from_urdf(out / "rpr_cad.urdf")
    assert robot.joint_kinds == ["revolute", "prismatic", "revolute"]
    ctl = out / "rpr_controller.json"
    rec = didim.load_record(out / "rpr_train.csv", robot=robot, controller=ctl)
    res = didim.identify(rec, robot, method)
    for i, j in enumerate(robot.joint_names):
        assert res.params[f"Fv_{j}"] == pytest.approx(truth["Fv"][i], rel=0.05), j
        assert res.params[f"Fc_{j}"] == pytest.approx(truth["Fc"][i], rel=0.05), j
    val = didim.load_record(out / "rpr_valid.csv", robot=robot, controller=ctl)
    err, _ = force_errors(val, simulate_robot(val, res)["force"])
    assert err <= 1.2 * truth["records"]["valid"]["truth_floor_total"]
    return robot, ctl, res


def test_didim_identifies_an_arm_with_a_prismatic_joint_from_another_simulator(rpr):
    out, truth = rpr
    robot, ctl, res = _identified_within_bounds(out, truth, "didim")
    pay = payload(didim.load_record(out / "rpr_payload.csv", robot=robot, controller=ctl), res)
    assert pay.mass == pytest.approx(truth["payload"]["mass"], rel=0.03)


def test_idim_ls_identifies_the_arm_with_a_prismatic_joint_within_5_percent(rpr):
    """IDIM-LS on the measured positions (low-passed flat across the decimation's band, so that the force and the
    regressor are filtered alike): each joint's friction within 5 % of the truth, the validation within 1.2 times its
    floor with the closed loop's law (1.9 % and 1.31 times when the positions were low-passed at the decimation's
    own cutoff)."""
    out, truth = rpr
    _identified_within_bounds(out, truth, "idim-ls")


def test_a_quill_logged_in_mm_and_read_as_m_is_refused_by_the_urdfs_dynamics(rpr, tmp_path):
    """The prismatic joint's positions in mm, undeclared, on a URDF whose limits would not betray them: the URDF's
    dynamics explain the force far better read in mm, and the record is refused naming mm (declared, it loads)."""
    out, truth = rpr
    text = (out / "rpr_cad.urdf").read_text()
    assert 'lower="-0.15" upper="0.15"' in text
    urdf = tmp_path / "rpr_wide_limits.urdf"
    urdf.write_text(text.replace('lower="-0.15" upper="0.15"', 'lower="-1000" upper="1000"'))
    robot = didim.Robot.from_urdf(urdf)
    j = robot.joint_kinds.index("prismatic")
    head = (out / "rpr_train.csv").read_text().splitlines()[0].split(",")
    data = np.loadtxt(out / "rpr_train.csv", delimiter=",", skiprows=1)
    for i, c in enumerate(head):
        if c in (f"qr_{j + 1}", f"qm_{j + 1}"):
            data[:, i] *= 1000
    path = tmp_path / "rpr_mm.csv"
    np.savetxt(path, data, delimiter=",", header=",".join(head), comments="", fmt="%.17g")
    ctl = out / "rpr_controller.json"
    with pytest.raises(didim.DataError, match=r"prismatic joints.*probably in mm.*qr_2\[mm\]"):
        didim.load_record(path, robot=robot, controller=ctl)
    rec = didim.load_record(path, robot=robot, controller=ctl, units="mm")
    ref = didim.load_record(out / "rpr_train.csv", robot=robot, controller=ctl)
    np.testing.assert_allclose(rec.qm, ref.qm, rtol=1e-12, atol=1e-15)
