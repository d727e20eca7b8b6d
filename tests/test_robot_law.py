"""The friction law through zero speed on a robot whose law has a long tail (atan): DIDIM estimates its smoothing
speed with the parameters, on an independent plant (a Python RK4 loop over Pinocchio's `aba`, noise inside the
loop, an 18-bit encoder, the data folder's cascades). With ε chosen by the closed loop alone, ε a few percent off
left Fv 5 % off on a Panda (docs/robots.md): the two trade where the law's tail is long."""

import math
import os
import pathlib
import sys

import numpy as np
import pytest

import didim

pin = pytest.importorskip("pinocchio")
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benches"))
_rayon = os.environ.get("RAYON_NUM_THREADS")
from robots import pin_loop  # noqa: E402  the benches' independent plant: RK4 over pin.aba, controllers in Python

# the bench pins rayon to one core for its timings; the tests keep the machine's default
if _rayon is None:
    os.environ.pop("RAYON_NUM_THREADS", None)


@pytest.fixture(scope="module")
def atan_record(robots_dir, tmp_path_factory):
    """The data folder's pendulum (2 joints) with an atan law (vs = 0.02 rad/s), 20 s at 1 kHz: the record, the
    robot and the truth (Fv, Fc, vs)."""
    tmp_path = tmp_path_factory.mktemp("atan")
    urdf = robots_dir / "pendulum_cad.urdf"
    robot = didim.Robot.from_urdf(urdf)
    model = pin.buildModelFromUrdf(str(urdf))
    ctl = didim.load_joint_controllers(robots_dir / "pendulum_controller.json")
    dt, seconds, n = 1e-3, 20.0, robot.ndof
    Ia, Fv, Fc, vs = np.array([0.05, 0.02]), np.array([0.8, 0.3]), np.array([1.5, 0.6]), 0.02
    t = np.arange(int(seconds / dt)) * dt
    rng = np.random.default_rng(3)
    qr = np.column_stack([sum(a * (1 - np.cos(2 * math.pi * 0.1 * (i + 1) * t)) / (i + 1)
                              for i, a in enumerate(rng.uniform(-1.0, 1.0, 4))) for _ in range(n)])
    rms = np.sqrt(np.mean(np.array([pin.rnea(model, model.createData(), qr[k], np.zeros(n), np.zeros(n))
                                    for k in range(0, len(qr), 100)]) ** 2, axis=0))
    noise = rng.normal(size=qr.shape) * 0.005 * rms
    step = 2 * math.pi / 2**18
    u0 = pin.computeGeneralizedGravity(model, model.createData(), qr[0])
    force, qm = pin_loop(model, Ia, Fv, Fc, np.zeros(n), lambda v: (2 / math.pi) * np.arctan(v / vs), ctl, qr, dt, 2,
                         step, u0, noise)
    cols = {"t": t} | {f"qr_{j + 1}": qr[:, j] for j in range(n)} | {f"force_{j + 1}": force[:, j] for j in range(n)} \
        | {f"qm_{j + 1}": qm[:, j] for j in range(n)}
    path = tmp_path / "pendulum_atan.csv"
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    rec = didim.load_record(path, robot=robot, controller=robots_dir / "pendulum_controller.json")
    return rec, robot, Fv, Fc, vs


def test_didim_estimates_the_smoothing_speed_of_a_long_tailed_law(atan_record):
    rec, robot, Fv, Fc, vs = atan_record
    res = didim.identify(rec, robot, "didim", offset=False)
    # didim's atan law is (2/π)·atan(π/2 · v/ε): the plant's atan(v/vs) is ε = vs·π/2
    assert res.law[0] == "atan"
    for j, eps in enumerate(res.law[1]):  # each joint's own ε (the plant's is the same on both)
        assert eps == pytest.approx(vs * math.pi / 2, rel=0.03), robot.joint_names[j]
    for j, name in enumerate(robot.joint_names):
        assert res.params[f"Fv_{name}"] == pytest.approx(Fv[j], rel=0.03), name
        assert res.params[f"Fc_{name}"] == pytest.approx(Fc[j], rel=0.02), name


def test_a_law_the_model_gives_is_held(atan_record):
    """methods.robot.didim holds the friction law of the model it is given (the doctor's searches over an effect's
    size hold the grown model's law, as one axis's do): the result carries that law to the last digit, and with the
    plant's own law the friction comes out as well as with the law fitted."""
    from didim.methods.robot import didim as robot_didim

    rec, robot, Fv, Fc, vs = atan_record
    law = ("atan", (vs * math.pi / 2,) * robot.ndof)
    said = []
    res = robot_didim(rec, didim.Model(robot=robot).with_law(law), progress=said.append)
    assert res.law == law
    assert any("friction law through zero speed, held" in s for s in said)
    assert not any("law through zero speed, in closed loop" in s or "by the inverse model" in s for s in said)
    for j, name in enumerate(robot.joint_names):
        assert res.params[f"Fv_{name}"] == pytest.approx(Fv[j], rel=0.03), name
        assert res.params[f"Fc_{name}"] == pytest.approx(Fc[j], rel=0.02), name
    with pytest.raises(didim.DataError, match="one smoothing speed per joint"):
        robot_didim(rec, didim.Model(robot=robot).with_law(("atan", (0.03,))))
