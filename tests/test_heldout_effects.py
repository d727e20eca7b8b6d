"""The independent simulator's concealed effects (benches/heldout_robots.py ``closed_loop(effect=...)`` and
benches/elastic_robots.py ``pin_elastic_loop(backlash=...)``, used by benches/robot_doctor_heldout.py): each effect of
size zero is the plant without it, the force lag converges with the RK4 substeps, the load-dependent friction's
exact solve meets its equation, and a one-sample delay is the same plant fed the previous sample's torque."""

import math
import types

import numpy as np
import pytest

from conftest import bench_module

pin = pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """The 2-joint vertical arm of benches/heldout_robots.py with drives, PID controllers and a short reference."""
    h = bench_module("heldout_robots")
    path = tmp_path_factory.mktemp("arm") / "arm2.urdf"
    path.write_text(h._arm2_urdf())
    model = pin.buildModelFromUrdf(str(path))
    dt, N = 1e-3, 600
    Ia, Fv, Fc, off, eps = (np.array(x) for x in ([0.04, 0.03], [0.6, 0.4], [1.0, 0.8], [0.2, -0.1], [0.02, 0.02]))
    J = np.diag(pin.crba(model, model.createData(), np.array([0.4, -0.8]))) + Ia
    ctl = {"type": "joints", "joints": [h.pid_tf(J[j], dt, 4.0, 40.0, None, 1e6)[0] for j in range(2)]}
    t = np.arange(N) * dt
    qr = np.column_stack([0.4 + 0.3 * np.sin(2 * math.pi * t) ** 2, -0.8 + 0.4 * np.sin(3 * math.pi * t) ** 2])
    u0 = pin.computeGeneralizedGravity(model, model.createData(), qr[0]) + off
    return h, dict(model=model, Ia=Ia, Fv=Fv, Fc=Fc, off=off, law="atan", eps=eps, ctl_json=ctl, qr=qr, dt=dt,
                   substeps=4, steps=None, force0=u0)


def _run(h, a, effect=None, noise=None):
    return h.closed_loop(a["model"], a["Ia"], a["Fv"], a["Fc"], a["off"], a["law"], a["eps"], a["ctl_json"], a["qr"],
                         a["dt"], a["substeps"], a["steps"], a["force0"], noise, effect)["force"]


def test_effects_of_size_zero_are_the_rigid_plant(arm):
    h, a = arm
    rigid = _run(h, a)
    for eff in (dict(kind="stribeck", joint=0, dF=0.0, vst=0.05), dict(kind="spring", joint=1, k=0.0, phi=0.3, c=0.0),
                dict(kind="load", joint=0, mu=0.0), dict(kind="asymmetric", joint=1, Fc_plus=0.8, Fc_minus=0.8)):
        assert np.allclose(_run(h, a, eff), rigid, rtol=0, atol=1e-12), eff
    for eff in (dict(kind="stribeck", joint=0, dF=0.5, vst=0.05), dict(kind="spring", joint=1, k=1.0, phi=0.3, c=0.2),
                dict(kind="load", joint=0, mu=0.1), dict(kind="asymmetric", joint=1, Fc_plus=1.0, Fc_minus=0.6)):
        assert np.max(np.abs(_run(h, a, eff) - rigid)) > 1e-3, eff


def test_the_force_lag_converges_with_the_substeps(arm):
    """The lag's torque is solved exactly over the sample (u held), so the loop converges as RK4 does: the force with 4
    and with 16 substeps per sample agree far below the lag's own effect."""
    h, a = arm
    rigid = _run(h, a)
    lag = dict(kind="lag", T=3 * a["dt"])
    coarse, fine = _run(h, a, lag), _run(h, dict(a, substeps=16), lag)
    effect = np.max(np.abs(coarse - rigid))
    assert effect > 1e-3
    assert np.max(np.abs(coarse - fine)) < 1e-4 * effect


def test_a_one_sample_delay_feeds_the_previous_torque(arm):
    """With the delay, the plant's motion over sample k is the one the rigid plant makes under force[k - 1]: replaying
    the delayed loop's force shifted by one sample, open loop, through the rigid plant gives its states."""
    h, a = arm
    model = a["model"].copy()
    model.armature = a["Ia"].copy()
    data = model.createData()
    out = h.closed_loop(a["model"], a["Ia"], a["Fv"], a["Fc"], a["off"], a["law"], a["eps"], a["ctl_json"], a["qr"],
                        a["dt"], a["substeps"], None, a["force0"], None, dict(kind="delay"))
    applied = np.vstack([a["force0"], out["force"][:-1]])
    q, v = a["qr"][0].copy(), np.zeros(2)
    hs = a["dt"] / a["substeps"]
    shape = lambda x: (2 / math.pi) * np.arctan(math.pi / 2 * x)  # noqa: E731

    def f(q, v, u):
        return pin.aba(model, data, q, v, u - a["off"] - a["Fv"] * v - a["Fc"] * shape(v / a["eps"]))

    for k in range(len(applied) - 1):
        for _ in range(a["substeps"]):
            k1 = f(q, v, applied[k])
            k2 = f(q + hs / 2 * v, v + hs / 2 * k1, applied[k])
            k3 = f(q + hs / 2 * (v + hs / 2 * k1), v + hs / 2 * k2, applied[k])
            k4 = f(q + hs * (v + hs / 2 * k2), v + hs * k3, applied[k])
            q, v = (q + hs / 6 * (v + 2 * (v + hs / 2 * k1) + 2 * (v + hs / 2 * k2) + (v + hs * k3)),
                    v + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
        assert np.allclose(q, out["q"][k + 1], rtol=0, atol=1e-10), k


def test_load_dependent_friction_meets_its_equation(arm):
    """The exact solve: x = mu s(v) |tau_L,j|, (M + Ia) qdd + nle = tau - x e_j and tau_L = M qdd + nle (the links
    only), on random states, both signs of the load and of the speed."""
    h, a = arm
    m = a["model"].copy()
    m.armature = a["Ia"].copy()
    links = a["model"].copy()
    links.armature = np.zeros(2)
    rng = np.random.default_rng(3)
    for _ in range(50):
        q, v, tau = rng.normal(size=2), rng.normal(size=2), rng.normal(size=2) * 20
        for j in (0, 1):
            c = 0.3 * np.tanh(v[j] / 0.02)
            qdd = h.load_friction_acc(m, m.createData(), q, v, tau, a["Ia"], j, c)
            tau_l = pin.rnea(links, links.createData(), q, v, qdd)
            x = c * abs(tau_l[j])
            applied = tau.copy()
            applied[j] -= x
            assert np.allclose(pin.rnea(m, m.createData(), q, v, qdd), applied, rtol=0, atol=1e-10)


def test_backlash_of_width_zero_is_the_elastic_joint(arm):
    h, a = arm
    e = bench_module("elastic_robots")
    model = a["model"]
    ctl = [types.SimpleNamespace(**tf) for tf in a["ctl_json"]["joints"]]
    args = (a["Ia"], a["Fv"], a["Fc"], a["off"], lambda v: np.tanh(v / 0.02), np.array([400.0, 1.0]),
            np.array([0.5, 0.0]), [True, False], ctl, a["qr"], a["dt"], 4, 0.0, a["force0"])
    f_el, _ = e.pin_elastic_loop(model.copy(), *args)
    f_b0, _ = e.pin_elastic_loop(model.copy(), *args, backlash=[0.0, 0.0])
    assert np.allclose(f_b0, f_el, rtol=0, atol=1e-9 * np.max(np.abs(f_el)))
    f_b, _ = e.pin_elastic_loop(model.copy(), *args, backlash=[0.01, 0.0])
    assert np.max(np.abs(f_b - f_el)) > 1e-3
