"""The closed-loop simulator seen from Python, on the real EMPS record and on analytic cases."""

import numpy as np
import pytest

import didim
from didim.simulation import default_coulomb_eps

#: The EMPS benchmark's reference IDIM-LS parameters (Janot, Gautier, Brunot 2019).
EMPS_REF = dict(M=95.1089, Fv=203.5034, Fc=20.3935, OF=-3.1648)


def test_emps_reference_parameters_reproduce_the_measured_force_and_position(emps):
    sim = didim.simulate(emps, EMPS_REF)
    err = sim.relative_error(emps)
    assert err < 0.06, f"force relative error {err:.4f}"
    rms = np.sqrt(np.mean((sim.q1 - emps.qm) ** 2))
    assert rms < 5e-6, f"position RMS error {rms * 1e6:.2f} um"
    # the simulated command obeys the logged control law on the simulated positions
    c = emps.controller
    q = sim.q1
    vir = c.kv * (c.kp * (emps.qr[2:] - q[2:]) - (q[2:] - q[:-2]) / (2 * emps.dt))
    assert np.allclose(sim.force[2:], c.gtau * vir, rtol=0, atol=1e-9)


def test_emps_pulses_record_is_simulated_with_its_injected_input(emps_pulses):
    assert emps_pulses.u_ext is not None and np.ptp(emps_pulses.u_ext) > 150
    with_input = didim.simulate(emps_pulses, EMPS_REF).relative_error(emps_pulses)
    without = didim.Recording(
        dt=emps_pulses.dt, qr=emps_pulses.qr, force=emps_pulses.force, qm=emps_pulses.qm, controller=emps_pulses.controller
    )
    no_input = didim.simulate(without, EMPS_REF).relative_error(emps_pulses)
    assert with_input < 0.07
    assert no_input > 3 * with_input


def test_simulated_states_satisfy_the_inverse_dynamic_model(emps):
    params = dict(M1=68.0, Fv1=104.0, Fc1=10.0, M2=38.0, Fv2=96.5, Fc2=9.5, K12=8.8e5)
    sim = didim.simulate(emps, params, model="flexible")
    w = didim.Model("flexible", coulomb_eps=default_coulomb_eps(emps)).core().regressor(sim.q, sim.qd, sim.qdd)
    chi = np.array(list(params.values()))
    assert w.shape == (2, emps.n, 7)
    np.testing.assert_allclose(w[0] @ chi, sim.force, atol=1e-7 * np.abs(sim.force).max())
    np.testing.assert_allclose(w[1] @ chi, 0.0, atol=1e-6)


def test_frictionless_pd_axis_matches_the_exact_sampled_data_solution():
    dt, m, kp, kd = 1e-3, 10.0, 4.0e4, 600.0
    n = 2000
    qr = 0.05 * np.sin(np.linspace(0, 6 * np.pi, n)) + 0.02 * (np.arange(n) > 500)
    rec = didim.Recording(dt=dt, qr=qr, force=np.zeros(n), qm=qr, controller=didim.PD(kp, kd))
    sim = didim.simulate(rec, dict(M=m, Fv=0.0, Fc=0.0), coulomb_eps=0.0)
    # exact zero-order-hold discretization of m q'' = tau, iterated with the same digital PD
    q, v, hist = qr[0], 0.0, [qr[0], qr[0]]
    qs = []
    for k in range(n):
        tau = kp * (qr[k] - q) - kd * (q - hist[0]) / (2 * dt)
        hist = [hist[1], q]
        qs.append(q)
        q, v = q + dt * v + dt * dt / (2 * m) * tau, v + dt * tau / m
    np.testing.assert_allclose(sim.q1, qs, rtol=0, atol=1e-12)


def test_diverging_loop_raises_simulation_error_naming_the_sample(emps):
    with pytest.raises(didim.SimulationError, match=r"diverged at sample -?\d+"):
        rec = didim.Recording(dt=emps.dt, qr=emps.qr, force=emps.force, qm=emps.qm, controller=didim.PD(1e6, 1e4))
        didim.simulate(rec, dict(M=0.01, Fv=0.0, Fc=0.0))


@pytest.mark.parametrize(
    "params, match",
    [
        (dict(M=-1.0, Fv=1.0, Fc=1.0), "mass M"),
        (dict(M=1.0, Fv=1.0), "missing Fc"),
        (dict(M=1.0, Fv=1.0, Fc=1.0, X=2.0), "unknown X"),
        ([1.0, 2.0], "takes 3 parameters"),
    ],
)
def test_bad_parameters_raise_data_error(emps, params, match):
    with pytest.raises(didim.DataError, match=match):
        didim.simulate(emps, params)


def test_bad_options_raise_data_error(emps):
    with pytest.raises(didim.DataError, match="substeps"):
        didim.simulate(emps, EMPS_REF, substeps=0)
    with pytest.raises(didim.DataError, match="unknown model"):
        didim.simulate(emps, EMPS_REF, model="elastic")
    with pytest.raises(ValueError):  # DataError is a ValueError
        didim.simulate(emps, EMPS_REF, coulomb_eps=-1.0)
