"""The friction law through zero speed on a robot whose law has a long tail (atan): DIDIM estimates its smoothing
speed with the parameters, on an independent plant (a Python RK4 loop over Pinocchio's `aba`, noise inside the
loop, an 18-bit encoder, the data folder's cascades). With ε chosen by the closed loop alone, ε a few percent off
left Fv 5 % off on a Panda (docs/robots.md): the two trade where the law's tail is long."""

import math

import numpy as np
import pytest

import didim

pin = pytest.importorskip("pinocchio")


class _Filter:
    """One joint's controller as a plain filter (transposed direct form over the common denominator)."""

    def __init__(self, tf):
        b_r, a_r, b_y, a_y = (np.array(x, float) for x in (tf.b_r, tf.a_r, tf.b_y, tf.a_y))
        if not np.array_equal(a_r, a_y):
            b_r, b_y, a_r = np.convolve(b_r, a_y), np.convolve(b_y, a_r), np.convolve(a_r, a_y)
        m = max(len(b_r), len(b_y), len(a_r))
        pad = lambda x: np.concatenate([x, np.zeros(m - len(x))]) / a_r[0]  # noqa: E731
        self.nr, self.ny, self.den = pad(b_r), pad(b_y), pad(a_r)
        self.z = np.zeros(m)
        self.sat, self.gain = tf.saturation, tf.gain

    def step(self, qr, qm, u0):
        u = self.nr[0] * qr - self.ny[0] * qm + self.z[0]
        for i in range(len(self.z) - 1):
            self.z[i] = self.nr[i + 1] * qr - self.ny[i + 1] * qm - self.den[i + 1] * u + self.z[i + 1]
        return self.gain * max(-self.sat, min(self.sat, u + u0 / self.gain))


def _plant(model, Ia, Fv, Fc, vs, controllers, qr, dt, step, noise):
    """RK4 (2 substeps) over pin.aba with atan friction, the torque (plus noise) held over each sample."""
    data = model.createData()
    model.armature = np.asarray(Ia, float)
    laws = [_Filter(c) for c in controllers]
    n, h = model.nv, dt / 2
    q, v = qr[0].copy(), np.zeros(n)
    u0 = pin.computeGeneralizedGravity(model, data, qr[0])
    force, qm_log = np.empty_like(qr), np.empty_like(qr)

    def acc(q, v, u):
        return pin.aba(model, data, q, v, u - Fv * v - Fc * (2 / math.pi) * np.arctan(v / vs))

    for k in range(len(qr)):
        qm = np.round(q / step) * step
        u = np.array([laws[j].step(qr[k, j] - qr[0, j], qm[j] - qr[0, j], u0[j]) for j in range(n)])
        force[k], qm_log[k] = u, qm
        ud = u + noise[k]
        for _ in range(2):
            k1 = acc(q, v, ud)
            k2 = acc(q + 0.5 * h * v, v + 0.5 * h * k1, ud)
            k3 = acc(q + 0.5 * h * (v + 0.5 * h * k1), v + 0.5 * h * k2, ud)
            k4 = acc(q + h * (v + 0.5 * h * k2), v + h * k3, ud)
            q = q + h / 6 * (v + 2 * (v + 0.5 * h * k1) + 2 * (v + 0.5 * h * k2) + (v + h * k3))
            v = v + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return force, qm_log


def test_didim_estimates_the_smoothing_speed_of_a_long_tailed_law(robots_dir, tmp_path):
    urdf = robots_dir / "pendulum_cad.urdf"
    robot = didim.Robot.from_urdf(urdf)
    model = pin.buildModelFromUrdf(str(urdf))
    ctl = didim.robots.load_joint_controllers(robots_dir / "pendulum_controller.json")
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
    force, qm = _plant(model, Ia, Fv, Fc, vs, ctl, qr, dt, step, noise)
    cols = {"t": t} | {f"qr_{j + 1}": qr[:, j] for j in range(n)} | {f"force_{j + 1}": force[:, j] for j in range(n)} \
        | {f"qm_{j + 1}": qm[:, j] for j in range(n)}
    path = tmp_path / "pendulum_atan.csv"
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    rec = didim.load_record(path, robot=robot, controller=robots_dir / "pendulum_controller.json")
    res = didim.identify(rec, robot, "didim", offset=False)
    # didim's atan law is (2/π)·atan(π/2 · v/ε): the plant's atan(v/vs) is ε = vs·π/2
    assert res.law[0] == "atan"
    assert res.law[1] == pytest.approx(vs * math.pi / 2, rel=0.03)
    for j, name in enumerate(robot.joint_names):
        assert res.params[f"Fv_{name}"] == pytest.approx(Fv[j], rel=0.03), name
        assert res.params[f"Fc_{name}"] == pytest.approx(Fc[j], rel=0.02), name
