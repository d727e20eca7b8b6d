"""The fast paths: the exponential integrator against a fine RK4 on the real EMPS reference, batched simulation,
the core objectives against their Python definitions, and the interleaved decimation against scipy."""

import numpy as np
import pytest
import scipy.signal as ss

import didim
from didim.simulation import default_coulomb_eps
from didim import scenarios as sc
from didim.methods.identification import didim_rigid, nelder_mead_simplex, prefetch
from didim.signal import Decimation

TABLE3 = np.array([68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5])
EMPS_REF = dict(M=95.1089, Fv=203.5034, Fc=20.3935, OF=-3.1648)


def rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def emps_plain(emps):
    """The EMPS record without its encoder quantizer (a quantized loop turns any integration difference into whole
    encoder counts, so accuracy is compared without it)."""
    return didim.Recording(dt=emps.dt, qr=emps.qr, force=emps.force, qm=emps.qm, controller=emps.controller)


@pytest.mark.parametrize("model, params", [("flexible", TABLE3), ("rigid", EMPS_REF)])
def test_exponential_integrator_matches_rk4_with_a_ten_times_smaller_step_on_the_emps_reference(emps_plain, model, params):
    fine = didim.simulate(emps_plain, params, model, integrator="rk4", substeps=100)
    fast = didim.simulate(emps_plain, params, model)  # the default
    assert rel(fast.force, fine.force) < 1e-4
    assert np.max(np.abs(fast.q - fine.q)) < 2e-8  # m, against a 0.25 m stroke
    rk4 = didim.simulate(emps_plain, params, model, integrator="rk4")
    assert rel(rk4.force, fine.force) < 1e-6  # the reference itself is converged


def test_with_the_encoder_quantizer_both_integrators_agree_to_the_quantization_level(emps):
    q = didim.Recording(dt=emps.dt, qr=emps.qr, force=emps.force, qm=emps.qm, controller=emps.controller,
                        position_resolution=5e-8)
    fine = didim.simulate(q, TABLE3, "flexible", integrator="rk4", substeps=100)
    for integrator in ("exponential", "rk4"):
        s = didim.simulate(q, TABLE3, "flexible", integrator=integrator)
        assert rel(s.force, fine.force) < 5e-3, integrator
        assert np.max(np.abs(s.q1 - fine.q1)) < 2e-7


def test_simulated_states_satisfy_the_idm_with_both_integrators(emps):
    for integrator in ("exponential", "rk4"):
        sim = didim.simulate(emps, TABLE3, "flexible", integrator=integrator)
        w = didim.Model("flexible", coulomb_eps=default_coulomb_eps(emps)).core().regressor(sim.q, sim.qd, sim.qdd)
        np.testing.assert_allclose(w[0] @ TABLE3, sim.force, atol=1e-7 * np.abs(sim.force).max())
        np.testing.assert_allclose(w[1] @ TABLE3, 0.0, atol=1e-6)


def test_bad_integrator_options_are_data_errors(emps):
    with pytest.raises(didim.DataError, match="integrator"):
        didim.simulate(emps, EMPS_REF, integrator="euler")
    with pytest.raises(didim.DataError, match="tol"):
        didim.simulate(emps, EMPS_REF, tol=0.0)


def test_simulate_batch_equals_single_simulations_in_order_and_isolates_failures(emps):
    sets = [TABLE3 * (1 + 0.1 * i) for i in range(5)]
    sets[3] = TABLE3 * np.array([1, 1, 1, 1, 1, 1, -1])  # a negative stiffness is refused
    b = didim.simulate_batch(emps, sets, "flexible", states=True)
    assert len(b) == 5 and list(b.ok) == [True, True, True, False, True]
    assert "stiffness K12" in b.errors[3] and np.isnan(b.force[3]).all()
    for i in (0, 1, 2, 4):
        s = didim.simulate(emps, sets[i], "flexible")
        np.testing.assert_array_equal(b.force[i], s.force)
        np.testing.assert_array_equal(b.q[i], s.q)
        np.testing.assert_array_equal(b.qdd[i], s.qdd)
        np.testing.assert_array_equal(b[i].q1, s.q1)
    errs = b.relative_errors(emps)
    assert np.isnan(errs[3]) and errs[0] == pytest.approx(b[0].relative_error(emps))
    with pytest.raises(didim.DidimError, match="member 3"):
        b[3]
    with pytest.raises(didim.DataError, match="2-D"):
        didim.simulate_batch(emps, TABLE3, "flexible")
    mapped = didim.simulate_batch(emps, [EMPS_REF, dict(EMPS_REF, M=80.0)])
    assert mapped.names == ["M", "Fv", "Fc", "OF"] and mapped.force.shape == (2, emps.n)
    # a loop that diverges is reported, not raised
    stiff = didim.Recording(dt=emps.dt, qr=emps.qr, force=emps.force, qm=emps.qm, controller=didim.PD(1e6, 1e4))
    d = didim.simulate_batch(stiff, [dict(M=0.01, Fv=0.0, Fc=0.0), dict(M=95.0, Fv=200.0, Fc=20.0)])
    assert "diverged at sample" in d.errors[0] and d.errors[1] is None


def test_core_objectives_equal_their_python_definitions(emps):
    dec = Decimation.lowpass(60.0, emps.fs)
    pb = didim.simulation.problem(emps, "flexible")
    yd = dec(emps.force)
    sim = didim.simulate(emps, TABLE3, "flexible")
    e = yd - dec(sim.force)
    assert pb.squared_error(TABLE3, yd, dec.core) == pytest.approx(float(e @ e), rel=1e-12)
    costs, errors = pb.squared_error_batch(np.array([TABLE3, 1.1 * TABLE3]), yd, dec.core)
    assert costs[0] == pytest.approx(float(e @ e), rel=1e-12) and errors == [None, None]
    # DIDIM's system: both rows of eq. (4), frozen Fv2 and Fc2 moved to the targets
    free = [0, 1, 2, 3, 6]
    y, w, force_dec = pb.didim_system(TABLE3, emps.force, free, dec.core)
    wr = didim.Model("flexible", coulomb_eps=default_coulomb_eps(emps)).core().regressor(sim.q, sim.qd, sim.qdd)
    frozen = [4, 5]
    rows = [(emps.force - wr[0][:, frozen] @ TABLE3[frozen], wr[0][:, free]),
            (-wr[1][:, frozen] @ TABLE3[frozen], wr[1][:, free])]
    parts = [dec.apply(a, b) for a, b in rows]
    np.testing.assert_allclose(y, np.concatenate([p[0] for p in parts]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(w, np.vstack([p[1] for p in parts]), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(force_dec, dec(sim.force))
    # with the simulated motor position, from the same simulation (DIDIM's start row without simulating χ⁰ twice)
    y_q, w_q, f_q, q = pb.didim_system(TABLE3, emps.force, free, dec.core, with_q=True)
    np.testing.assert_array_equal(q, pb.simulate(TABLE3)["q"][0])
    for a, b in ((y_q, y), (w_q, w), (f_q, force_dec)):
        np.testing.assert_array_equal(a, b)
    # the exact-sensitivity linearization
    r, jac = pb.linearize(TABLE3, emps.force, [0, 6], dec.core)
    s = pb.simulate_sensitivity(TABLE3)
    r2, j2 = dec.apply(emps.force - s["force"], s["dforce"][[0, 6]].T)
    np.testing.assert_array_equal(r, r2)
    np.testing.assert_allclose(jac, j2, rtol=1e-12, atol=0)


@pytest.mark.parametrize("kind", ["butter-sos", "butter-ba", "matlab"])
def test_interleaved_decimation_equals_one_column_at_a_time_and_scipy(kind):
    rng = np.random.default_rng(0)
    n = 5000
    y = np.cumsum(rng.standard_normal(n))
    w = np.column_stack([np.cumsum(rng.standard_normal(n)) for _ in range(7)])
    if kind == "matlab":
        dec = Decimation.matlab(10)
    else:
        dec = Decimation.lowpass(60.0, 1000.0, form=kind.split("-")[1])
    yd, wd = dec.apply(y, w)
    np.testing.assert_array_equal(yd, dec(y))
    for j in range(7):
        np.testing.assert_array_equal(wd[:, j], dec(w[:, j]))
    if kind == "butter-sos":
        ref = ss.sosfiltfilt(ss.butter(4, 60.0 / 500.0, output="sos"), np.column_stack([y, w]), axis=0)[::dec.factor]
        np.testing.assert_allclose(np.column_stack([yd, wd]), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_prefetched_nelder_mead_takes_the_same_path_as_plain_scipy():
    from scipy.optimize import minimize

    def rosen(x):
        return float((1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2 + (x[2] - 1) ** 2)

    x0 = np.array([-1.2, 1.0, 0.0])
    plain = minimize(rosen, x0, method="Nelder-Mead", options=dict(maxiter=200))
    sim = nelder_mead_simplex(x0)
    calls = []
    fast = minimize(prefetch(lambda x: calls.append(1) or rosen(x), lambda xs: [rosen(x) for x in xs], sim), x0,
                    method="Nelder-Mead", options=dict(maxiter=200, initial_simplex=sim))
    np.testing.assert_array_equal(plain.x, fast.x)
    assert plain.nfev == fast.nfev == len(calls) + len(sim)


def test_identification_results_do_not_depend_on_the_integrator(emps):
    a = didim_rigid(emps, 78.0, offset=True)
    b = didim_rigid(emps, 78.0, offset=True, integrator="rk4")
    for name in a.params:
        assert a.params[name] == pytest.approx(b.params[name], rel=2e-4, abs=1e-3), name
    truth = dict(sc.TABLE3_TRUTH)
    rec = sc.make_recording(truth, "flexible", force_noise=1.0, seed=12)
    ga = didim.identify(rec, "flexible", "oe-gn", apM=78.0)
    gb = didim.identify(rec, "flexible", "oe-gn", apM=78.0, integrator="rk4")
    for name in ga.params:  # the integrator moves the estimate by much less than its uncertainty
        assert abs(ga.params[name] - gb.params[name]) < 0.5 * ga.std[name], name


def test_exact_sensitivities_agree_with_central_differences_from_one_batch(emps_plain):
    from didim.methods.oe import check_sensitivities

    err = check_sensitivities(emps_plain, TABLE3, "flexible")
    assert max(err.values()) < 1e-3, err
    err = check_sensitivities(emps_plain, EMPS_REF, "rigid", output="position")
    assert max(err.values()) < 1e-3, err


def test_step_2_grid_start_finds_the_mode_from_a_start_where_nelder_mead_alone_fails():
    from didim.methods.identification import fit_flexible_mode

    rec = sc.make_recording(dict(sc.TABLE3_TRUTH, Fv1=200.5, Fc1=19.5, Fv2=0.0, Fc2=0.0), "flexible", force_noise=1.0,
                            seed=0)
    r1 = didim_rigid(rec, 78.0)
    f_true = np.sqrt(38 / 38 * 8.8e5 / 38) / (2 * np.pi)
    plain = fit_flexible_mode(rec, r1, lambda0=0.55, f0=5.0, grid_start=False)
    assert abs(plain.params["f_n_flex"] / f_true - 1) > 0.1  # the paper's step 2 from 5 Hz ends elsewhere
    grid = fit_flexible_mode(rec, r1, lambda0=0.55, f0=5.0, grid_start=True)
    assert grid.params["f_n_flex"] == pytest.approx(f_true, rel=0.01)
    assert grid.params["lambda"] == pytest.approx(68 / 106, abs=0.01)
    assert grid.initial == {"lambda": 0.55, "f_n_flex": 5.0} and grid.simulations > 41  # the 40-point grid and more
