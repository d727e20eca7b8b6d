"""The gravity torque of a rotary joint, A·sin(q) + B·cos(q): a term of the core's table with named
hyper-parameters (angle_offset, phase), simulated as an independent plant integrates a pendulum, identified by DIDIM
and IDIM-LS."""

import math

import numpy as np
import pytest

import didim
from didim.units import Units

# a rotary joint: inertia (kg·m²), viscous (N·m·s/rad) and Coulomb (N·m) friction, and m·g·l = 2 N·m whose arm hangs
# at q = -0.4 rad (G sin(q + 0.4) = G cos 0.4 sin q + G sin 0.4 cos q)
J, FV, FC, MGL, DELTA = 0.05, 0.02, 0.3, 2.0, 0.4
TRUTH = {"M": J, "Fv": FV, "Fc": FC, "G_sin": MGL * math.cos(DELTA), "G_cos": MGL * math.sin(DELTA)}
GRAVITY = (didim.Term("G_sin", "gravity"), didim.Term("G_cos", "gravity", phase=math.pi / 2))
MODEL = didim.Model("rigid", terms=GRAVITY)
CONTROLLER = didim.PD(kp=800.0, kd=9.0, tau_max=40.0)  # about 20 Hz on 0.05 kg·m²


def _reference(dt=1e-3):
    """Rotary moves between -1.5 and 1.5 rad at several speeds, with rests."""
    from didim import scenarios

    return np.tile(scenarios.trapezoid(dt=dt, stroke=3.0, speeds=(0.8, 1.6, 3.0), a_max=20.0, dwell_s=0.3), 2) - 1.5


def _record(seed=0, model=MODEL, truth=TRUTH):
    from didim import scenarios

    rec = scenarios.make_recording(truth, model, _reference(), controller=CONTROLLER, force_noise=0.02,
                                   quantization=2 * math.pi / 2**16, seed=seed, name="pendulum")
    from dataclasses import replace

    return replace(rec, units=Units("rad", "N*m"))


def test_a_gravity_pair_simulates_a_pendulum_as_an_independent_plant_does():
    """didim's closed loop with the gravity terms against a plain SciPy solve_ivp plant, J q̈ = τ − Fv q̇ − Fc s(q̇) −
    m g l sin(q + δ), under the same PD held over each sample (its velocity the central difference over two samples,
    as didim.PD's; no quantization): the forces agree to the integrators' accuracy."""
    from scipy.integrate import solve_ivp

    dt, qr = 1e-3, _reference()[:3000]
    rec = didim.Recording(dt, qr, np.zeros(len(qr)), qr, controller=CONTROLLER, position_resolution=None)
    eps = 1e-3
    sim = didim.simulate(rec, TRUTH, didim.Model("rigid", terms=GRAVITY, coulomb_eps=eps), quantization=0.0)

    def rhs(_, x, tau):
        q, v = x
        return [v, (tau - FV * v - FC * v / math.sqrt(v * v + eps * eps) - MGL * math.sin(q + DELTA)) / J]

    x, past, forces = np.array([qr[0], 0.0]), [qr[0], qr[0]], []
    for k in range(len(qr)):
        q = x[0]
        v_hat = (q - past[0]) / (2 * dt)
        tau = float(np.clip(CONTROLLER.kp * (qr[k] - q) - CONTROLLER.kd * v_hat, -CONTROLLER.tau_max,
                            CONTROLLER.tau_max))
        forces.append(tau)
        past = [past[1], q]
        x = solve_ivp(rhs, (0, dt), x, args=(tau,), rtol=1e-10, atol=1e-12, method="LSODA").y[:, -1]
    forces = np.array(forces)
    # didim's adaptive exponential integrator works to a tolerance of 1e-6 of the stroke per step: the loop's force
    # follows to about that share of its scale
    assert np.linalg.norm(sim.force - forces) / np.linalg.norm(forces) < 2e-3


def test_didim_identifies_the_gravity_torque_of_a_rotary_joint():
    rec = _record()
    r = didim.identify(rec, MODEL, "didim")
    assert r.converged, r.message
    amplitude = math.hypot(r.params["G_sin"], r.params["G_cos"])
    assert amplitude == pytest.approx(MGL, rel=0.02)
    assert math.atan2(r.params["G_cos"], r.params["G_sin"]) == pytest.approx(DELTA, abs=0.02)
    for k in ("M", "Fv", "Fc"):
        assert r.params[k] == pytest.approx(TRUTH[k], rel=0.05), k
    assert r.units["G_sin"] == "N·m"
    # the angle offset as a named hyper-parameter: the same torque as G sin(q + δ) with one term
    one = didim.Model("rigid", terms=[didim.Term("G", "gravity", angle_offset=DELTA)])
    r1 = didim.identify(rec, one, "didim")
    assert r1.params["G"] == pytest.approx(MGL, rel=0.02)
    # IDIM-LS has the same regressor
    ls = didim.identify(rec, MODEL, "idim-ls")
    assert math.hypot(ls.params["G_sin"], ls.params["G_cos"]) == pytest.approx(MGL, rel=0.03)


def _independent_pendulum(mgl, seed=0):
    """A pendulum record from a plant of this test's own: RK4 on 8 substeps per sample, a tanh Coulomb law (didim's
    default is algebraic), torque noise inside the loop (the logged torque is the command), a 16-bit encoder, under
    the PD of ``CONTROLLER`` held over each sample."""
    rng = np.random.default_rng(seed)
    dt, qr = 1e-3, _reference()
    res, eps, h = 2 * math.pi / 2**16, 2e-3, 1e-3 / 8

    def acc(q, v, tau):
        return (tau - FV * v - FC * math.tanh(v / eps) - mgl * math.sin(q + DELTA)) / J

    q, v, past = qr[0], 0.0, [qr[0], qr[0]]
    tau_log, qm = np.empty(len(qr)), np.empty(len(qr))
    for k in range(len(qr)):
        qq = res * round(q / res)
        tau = min(max(CONTROLLER.kp * (qr[k] - qq) - CONTROLLER.kd * (qq - past[0]) / (2 * dt), -CONTROLLER.tau_max),
                  CONTROLLER.tau_max)
        tau_log[k], qm[k], past = tau, qq, [past[1], qq]
        tau_in = tau + 0.02 * rng.standard_normal()
        for _ in range(8):
            k1q, k1v = v, acc(q, v, tau_in)
            k2q, k2v = v + h / 2 * k1v, acc(q + h / 2 * k1q, v + h / 2 * k1v, tau_in)
            k3q, k3v = v + h / 2 * k2v, acc(q + h / 2 * k2q, v + h / 2 * k2v, tau_in)
            k4q, k4v = v + h * k3v, acc(q + h * k3q, v + h * k3v, tau_in)
            q, v = q + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q), v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return didim.Recording(dt, qr, tau_log, qm, controller=CONTROLLER, units=Units("rad", "N*m"), name="pendulum")


@pytest.mark.parametrize("mgl", [0.3, 2.0])
def test_the_doctor_names_gravity_on_an_independent_pendulum(mgl):
    """The doctor, told nothing of gravity, names it on a rotary joint of an independent plant: as large as the
    Coulomb friction, and 7 times larger (where the rigid model without it has no physical fit, so it is tried before
    the friction law), with its amplitude and the angle where the arm hangs."""
    d = didim.doctor(_independent_pendulum(mgl), "rigid")
    names = [f.effect for f in d.findings]
    assert "gravity" in names, d.summary()
    assert not set(names) - {"gravity", "unnamed"}, d.summary()
    g = d.final_params
    assert math.hypot(g["G_sin"], g["G_cos"]) == pytest.approx(mgl, rel=0.03)
    assert math.atan2(g["G_cos"], g["G_sin"]) == pytest.approx(DELTA, abs=0.03)
    for k in ("M", "Fv", "Fc"):
        assert g[k] == pytest.approx(TRUTH[k], rel=0.1), k
    assert "hangs" in next(f.words for f in d.findings if f.effect == "gravity")
