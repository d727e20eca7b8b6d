"""The first-order force lag (a current loop's bandwidth) against an independent closed loop: the same EMPS cascade
written out in Python, the plant and the lag as one ODE integrated by SciPy between samples."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import didim
from conftest import resolved


def _independent(rec: didim.Recording, M: float, Fv: float, lag: float) -> np.ndarray:
    """Commanded force of the EMPS cascade (vir = kv·(kp·(qr − q) − (q_k − q_{k−2})/(2 dt)), saturated, × gtau) on
    M q̈ = f − Fv q̇ with T ḟ = τ − f (f = τ when lag = 0), DOP853 at rtol 1e-11 over each sample period."""
    c, dt, qr = rec.controller, rec.dt, rec.qr
    x = np.array([qr[0], 0.0, 0.0])
    past = [qr[0], qr[0]]
    out = np.empty(rec.n)
    for k in range(rec.n):
        v_hat = (x[0] - past[-2]) / (2 * dt)
        tau = c.gtau * float(np.clip(c.kv * (c.kp * (qr[k] - x[0]) - v_hat), -c.vsat, c.vsat))
        out[k] = tau
        past.append(x[0])
        if k == 0:
            x[2] = tau  # at rest, the applied force has settled on the first command
        if k + 1 == rec.n:
            break
        if lag > 0:
            def rhs(t, s):
                return [s[1], (s[2] - Fv * s[1]) / M, (tau - s[2]) / lag]
        else:
            def rhs(t, s):
                return [s[1], (tau - Fv * s[1]) / M, 0.0]
        x = solve_ivp(rhs, (0.0, dt), x, rtol=1e-11, atol=1e-14, method="DOP853").y[:, -1]
    return out


@pytest.fixture(scope="module")
def short_emps(emps):
    n = 2500
    return didim.Recording(dt=emps.dt, qr=emps.qr[:n], force=emps.force[:n], qm=emps.qm[:n], controller=emps.controller,
                           lead_in=None)  # the independent ODE below starts at rest on the first reference sample


def test_the_force_lag_matches_an_independent_ode_of_plant_and_lag(short_emps):
    M, Fv, lag = 95.0, 200.0, 3e-4
    params = dict(M=M, Fv=Fv, Fc=0.0)
    rel = lambda a, b: float(np.linalg.norm(a - b) / np.linalg.norm(b))  # noqa: E731
    ref0, ref = _independent(short_emps, M, Fv, 0.0), _independent(short_emps, M, Fv, lag)
    # without the lag the two closed loops are the same computation (exact for this linear plant): to rounding
    assert rel(didim.simulate(short_emps, params, tol=1e-12).force, ref0) < 1e-9
    effect = rel(ref, ref0)  # what the lag changes in the commanded force (2 % here)
    assert effect > 1e-2
    for integrator in ("exponential", "rk4"):
        sim = didim.simulate(short_emps, params, force_lag=lag, integrator=integrator, tol=1e-12, substeps=50).force
        # the plant sees the lagged force's mean over each period: within 5 % of the lag's own effect
        assert rel(sim, ref) < 0.05 * effect, integrator


def test_a_model_carries_its_force_lag_and_didim_fits_through_it(short_emps):
    truth = dict(M=95.0, Fv=200.0, Fc=20.0)
    m = didim.Model("rigid", force_lag=3e-4)
    sim = didim.simulate(short_emps, truth, m)
    rec = didim.Recording(dt=short_emps.dt, qr=short_emps.qr, force=sim.force, qm=sim.q[0],
                          controller=short_emps.controller)
    r = didim.identify(rec, m, "didim", apM=80.0)
    assert r.structure == resolved(m, rec) and r.converged
    for k, v in truth.items():
        assert r.params[k] == pytest.approx(v, rel=5e-3), k
    assert didim.Model.from_dict(m.to_dict()).force_lag == 3e-4


def test_oe_lm_fits_through_a_force_lag(short_emps):
    """OE-LM's exact sensitivities follow the command through the lag (the core's test checks them against central
    differences): on a record simulated with a 0.3 ms lag, the truth within 0.5 % from a start 10-20 % off."""
    truth = dict(M=95.0, Fv=200.0, Fc=20.0)
    m = didim.Model("rigid", force_lag=3e-4)
    sim = didim.simulate(short_emps, truth, m)
    rec = didim.Recording(dt=short_emps.dt, qr=short_emps.qr, force=sim.force, qm=sim.q[0],
                          controller=short_emps.controller)
    r = didim.identify(rec, m, "oe-lm", initial=dict(M=80.0, Fv=230.0, Fc=17.0))
    assert r.converged and r.structure.force_lag == 3e-4
    for k, v in truth.items():
        assert r.params[k] == pytest.approx(v, rel=5e-3), k
    with pytest.raises(didim.DataError, match="force_lag must be a finite number >= 0 s"):
        didim.simulate(short_emps, dict(M=95.0, Fv=200.0, Fc=20.0), force_lag=-1e-3)


@pytest.mark.parametrize("lag", [2e-4, 1e-3, 5e-2])
def test_force_lag_mean_is_the_mean_of_the_exact_lag_over_each_period(lag):
    """The applied force of a loop with a lag (what DIDIM regresses, computed by the core as its simulator applies the
    lag) against the lag's exact solution under held commands, integrated over each period: f(t) = τ + (f₀ − τ)·e^(−t/T),
    its mean T/dt·(1 − e^(−dt/T))·(f₀ − τ) + τ."""
    from scipy.integrate import quad

    import didim
    from didim.simulation import problem

    dt = 1e-3
    tau = np.random.default_rng(1).standard_normal(200) * 50
    rec = didim.Recording(dt, np.linspace(0, 0.1, 200), tau, np.linspace(0, 0.1, 200),
                          controller=didim.PD(kp=1e3, kd=50.0, tau_max=1e3))
    pb = problem(rec, didim.Model("rigid", force_lag=lag))
    f0, expected = tau[0], np.empty_like(tau)
    for k, t in enumerate(tau):
        expected[k] = quad(lambda s: t + (f0 - t) * np.exp(-s / lag), 0, dt, epsabs=0, epsrel=1e-10)[0] / dt
        f0 = t + (f0 - t) * np.exp(-dt / lag)
    # the quadrature's relative 1e-10 on forces of up to 200 N: 2e-8 N
    np.testing.assert_allclose(pb.applied_force(tau), expected, rtol=0, atol=2e-8)
    # with a delay too: the command of two samples earlier (0 before the first) through the same lag
    delayed = problem(rec, didim.Model("rigid", force_lag=lag, delay=2)).applied_force(tau)
    np.testing.assert_allclose(delayed[2:], problem(rec, didim.Model("rigid", force_lag=lag)).applied_force(
        np.r_[0.0, 0.0, tau[:-2]])[2:], rtol=0, atol=1e-12)


def test_the_late_force_search_goes_past_one_period_and_stops_where_the_fit_stops_moving():
    """doctor.effects.delay_search, every plant's: force lags are searched upward past one sample period (a 3 ms
    lag at 1 kHz: held-out Panda e8), whole-sample delays too when the best lag is a period or longer, the better
    kept; a search ends where the fit rises by 10 % or has not improved over DELAY_PATIENCE sizes (a record with no
    late force fits every size alike and used to refit them all)."""
    import math

    from didim.doctor.effects import DELAY_PATIENCE, LAG_PERIODS, delay_search

    dt = 1e-3
    seen = []

    def bowl(best_periods, floor):
        def fit(x):
            periods = x / dt if isinstance(x, float) else x
            seen.append(x)
            return floor + math.log(periods / best_periods) ** 2, True, x
        return fit

    # a lag of 3 periods, and delays no better: the lag, found past one period
    kind, size, _ = delay_search(bowl(3.0, 1.0), bowl(3.0, 1.5), dt)
    assert kind == "force_lag" and size == pytest.approx(3 * dt)
    assert max(x for x in seen if isinstance(x, float)) <= 6.75 * dt  # stopped past the minimum
    assert any(isinstance(x, int) for x in seen)  # delays tried: the best lag is a period or longer
    # a whole-sample delay that fits better than every lag is kept
    seen.clear()
    kind, size, _ = delay_search(bowl(2.0, 1.0), bowl(2.0, 0.5), dt)
    assert (kind, size) == ("delay", 2)
    # a short lag: no delays tried
    seen.clear()
    kind, size, _ = delay_search(bowl(0.3, 1.0), bowl(1.0, 0.0), dt)
    assert kind == "force_lag" and size == pytest.approx(0.3 * dt)
    assert not any(isinstance(x, int) for x in seen)
    # no late force: every size fits alike, and the search stops after DELAY_PATIENCE sizes that do not improve it
    seen.clear()
    kind, size, _ = delay_search(lambda x: (seen.append(x), (1.0, True, x))[1], bowl(1.0, 0.5), dt)
    assert (kind, size) == ("force_lag", LAG_PERIODS[0] * dt) and len(seen) == 1 + DELAY_PATIENCE
    # each kind's best is polished before the two are compared (a robot refits it from the base's own start): a lag
    # whose search fit (1.0) loses to a delay's (0.5) wins once polished to 0.4; the polish sees each best once
    seen.clear()
    polished = []

    def polish(kind, size, err, kept):
        polished.append((kind, size, err))
        return (0.4, ("polished", kept)) if kind == "force_lag" else (err, kept)

    kind, size, kept = delay_search(bowl(3.0, 1.0), bowl(3.0, 0.5), dt, polish=polish)
    assert (kind, kept) == ("force_lag", ("polished", size)) and size == pytest.approx(3 * dt)
    assert [(k, e) for k, _, e in polished] == [("force_lag", 1.0), ("delay", 0.5)]
    assert delay_search(bowl(3.0, 1.0), bowl(3.0, 0.5), dt)[0] == "delay"  # without it, the delay
    # a short lag: no delays tried, nothing to compare, nothing polished
    polished.clear()
    assert delay_search(bowl(0.3, 1.0), bowl(1.0, 0.0), dt, polish=polish)[0] == "force_lag" and not polished
