"""The model-mismatch doctor: statistics, the CI-sized concealed-effect benchmark, reports and the CLI."""

import importlib.util
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import lfilter

import didim
from didim.stats import diebold_mariano, holm, wald_added

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benches" / "doctor_benchmark.py"


def load_bench():
    spec = importlib.util.spec_from_file_location("doctor_benchmark", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_added_regressor_test_keeps_its_size_on_coloured_noise():
    rng = np.random.default_rng(7)
    n = 1200
    idx = np.minimum((np.arange(n) * 10) // n, 9)
    x = np.zeros((n, 10))
    x[np.arange(n), idx] = 1.0  # persistent regressors: the hard case for HAC tests
    p = np.array([wald_added(lfilter([1.0], [1.0, -0.6], rng.standard_normal(n)), x).p_value for _ in range(300)])
    assert np.mean(p < 0.05) < 0.09  # nominal 5 %; 300 draws
    assert np.mean(p < 0.01) < 0.03


def test_added_regressor_test_detects_a_real_effect():
    rng = np.random.default_rng(8)
    n = 1200
    x = np.sin(np.arange(n) / 7.0)
    r = lfilter([1.0], [1.0, -0.6], rng.standard_normal(n)) + 0.6 * x
    t = wald_added(r, x)
    assert t.p_value < 1e-6 and t.beta[0] == pytest.approx(0.6, abs=0.1)


def test_the_statistics_written_without_scipy_signal_equal_scipys():
    """welch, the AR prewhitening and the distributions' tails are SciPy's (its signal and stats modules cost more
    to import than a doctor's round): equal to rounding, on signals of several lengths and segment sizes."""
    import scipy.signal as ss
    import scipy.stats as st

    from didim.signal import welch
    from didim.stats import ar_fit, prewhiten

    rng = np.random.default_rng(11)
    for n, nperseg, fs in ((5000, 512, 166.7), (24841, 1024, 1000.0), (300, 512, 100.0), (1001, 63, 1.0)):
        x = np.cumsum(rng.standard_normal(n))
        f, pxx = welch(x, fs, nperseg)
        f_ref, pxx_ref = ss.welch(x, fs=fs, nperseg=min(nperseg, n))
        np.testing.assert_allclose(f, f_ref, rtol=1e-12)
        np.testing.assert_allclose(pxx, pxx_ref, rtol=1e-9, atol=1e-12 * pxx_ref.max())
    x = lfilter([1.0], [1.0, -0.6, 0.2], rng.standard_normal(3000))
    a = ar_fit(x)
    np.testing.assert_allclose(a, [1.0, -0.6, 0.2], atol=0.06)  # Yule-Walker on 3000 samples: ±2/√n per coefficient
    cols = np.column_stack([x, rng.standard_normal(3000)])
    np.testing.assert_allclose(prewhiten(a, cols)[0], lfilter(a, [1.0], cols, axis=0)[len(a) - 1:], atol=1e-12)
    t = wald_added(x, rng.standard_normal((3000, 2)), a)
    assert t.p_value == pytest.approx(st.f.sf(t.statistic / 2, 2, 3000 - (len(a) - 1) - 2), rel=1e-9)
    stat, p, _ = diebold_mariano(x, 0.97 * x + 0.05 * rng.standard_normal(3000))
    assert p == pytest.approx(st.norm.sf(stat), rel=1e-9, abs=1e-300)


def test_the_grouped_wald_tests_equal_the_one_by_one_tests():
    """wald_groups (the normal equations of each group of columns, all groups at once) against wald_whitened (an SVD
    least-squares solve per group) on groups of 1, 2, 3 and 26 columns: an effect's sine and cosine, pure noise, a
    pair 0.9999 correlated (condition 2·10⁴), a column of zeros and a pair correlated beyond the grouped solve's
    limit (both through wald_whitened). The tolerance is the rounding of the normal equations, ε·cond(XᵀX)."""
    from didim.stats import wald_groups, wald_whitened

    rng = np.random.default_rng(5)
    n = 3000
    t = np.arange(n)
    r = rng.standard_normal(n) + 0.3 * np.sin(t / 9.0)
    near = rng.standard_normal(n)
    groups = [np.column_stack([np.sin(t / 9.0), np.cos(t / 9.0)]), rng.standard_normal((n, 1)),
              np.column_stack([near, near + 0.014 * rng.standard_normal(n)]), rng.standard_normal((n, 3)),
              rng.standard_normal((n, 26)), np.column_stack([rng.standard_normal(n), np.zeros(n)]),
              np.column_stack([near, near + 1e-6 * rng.standard_normal(n)]), 1e-3 * rng.standard_normal((n, 2))]
    x = np.column_stack(groups)
    got = wald_groups(r, x, [g.shape[1] for g in groups])
    for g, t_got in zip(groups, got):
        want = wald_whitened(r, g)
        scaled = g / np.maximum(np.linalg.norm(g, axis=0), 1e-300)
        cond = np.linalg.cond(scaled.T @ scaled) if np.all(np.any(g != 0, axis=0)) else 1.0
        tol = max(1e-12, 50 * np.finfo(float).eps * cond)
        assert t_got.dof == want.dof
        assert t_got.statistic == pytest.approx(want.statistic, rel=tol)
        assert t_got.p_value == pytest.approx(want.p_value, rel=10 * tol * max(1.0, want.statistic), abs=1e-300)
        assert t_got.explained == pytest.approx(want.explained, rel=tol, abs=1e-15)
        np.testing.assert_allclose(t_got.beta, want.beta, rtol=tol, atol=tol * np.max(np.abs(want.beta)))
        np.testing.assert_allclose(t_got.cov, want.cov, rtol=tol, atol=tol * np.max(np.abs(want.cov)))
    assert got[0].p_value < 1e-20 and got[1].p_value > 1e-4
    with pytest.raises(ValueError, match="groups of 3 columns for"):
        wald_groups(r, x, [1, 2])


def test_the_held_out_test_on_absolute_errors_sees_through_spikes():
    """The doctor's held-out test (HELDOUT_LOSS): on errors with a few large spikes (a closed loop's starts and
    reversals), a model 30 % better on every sample is significant on the absolute errors and not on the squares; with
    no improvement, the absolute errors' test keeps its size (300 draws)."""
    from didim.doctor.finding import HELDOUT_LOSS

    rng = np.random.default_rng(12)
    n = 3000

    def errors():
        base = lfilter([1.0], [1.0, -0.5], rng.standard_normal(n))
        spikes = np.zeros(n)
        spikes[rng.choice(n, 12, replace=False)] = 60 * rng.standard_normal(12)
        return base, spikes

    base, spikes = errors()
    _, p_abs, _ = diebold_mariano(base + spikes, 0.7 * base + spikes, HELDOUT_LOSS)
    _, p_sq, _ = diebold_mariano(base + spikes, 0.7 * base + spikes, "squared")
    assert HELDOUT_LOSS == "absolute" and p_abs < 1e-6 and p_sq > 1e3 * p_abs
    p = []
    for _ in range(300):
        (b0, s0), (b1, _) = errors(), errors()
        p.append(diebold_mariano(b0 + s0, b1 + s0, HELDOUT_LOSS)[1])
    assert np.mean(np.array(p) < 0.05) < 0.09


def test_holm_and_diebold_mariano():
    np.testing.assert_allclose(holm([0.01, 0.04, 0.03]), [0.03, 0.06, 0.06])
    rng = np.random.default_rng(9)
    e = rng.standard_normal(2000)
    _, p_same, _ = diebold_mariano(e, e + 0.01 * rng.standard_normal(2000))
    _, p_better, gain = diebold_mariano(e + 0.5, e)
    assert p_same > 0.01 and p_better < 1e-6 and gain > 0.1


@pytest.fixture(scope="module")
def bench():
    return load_bench()


@pytest.mark.parametrize("effect, level", [("offset", 5.6), ("asymmetric_friction", 5.6), ("position_ripple", 8.0), ("delay", 3)])
def test_doctor_names_and_recovers_a_concealed_effect(bench, effect, level):
    r = bench.run_one((effect, level, "emps", bench.TEST_SEED0))
    assert r["named"] == effect, r
    tol = 0.5 if effect == "delay" else 0.05  # samples, or relative error of the hidden parameter
    assert r["param_error"] is not None and r["param_error"] <= tol, r
    assert r["fit"]["valid_after"] < 0.5 * r["fit"]["valid_before"]
    assert r["fit"]["valid_after"] < 0.03  # down to the noise floor (2 N on ~55 N RMS)


@pytest.mark.parametrize("seed", [0, 1])
def test_doctor_finds_nothing_when_nothing_is_hidden(bench, seed):
    r = bench.run_one(("none", 0, "emps", bench.TEST_SEED0 + 10 + seed))
    assert r["named"] == "none", r


def test_doctor_finds_a_hidden_flexible_mode_and_its_frequency(bench):
    rec, h, enr = bench.make("flexibility", 25.0, "emps", bench.TEST_SEED0)
    d = didim.doctor(rec, "rigid", apM=80.0)
    named = [f.effect for f in d.findings]
    assert named and named[0] == "flexibility", d.summary()
    assert d.findings[0].params["f_n_flex"] == pytest.approx(25.0, rel=0.03)


def test_an_effect_a_fitted_friction_law_partly_stands_in_for_is_still_named(bench):
    """A 45 Hz mode (effect-to-noise ratio 0.57) behind the generator's algebraic law at 0.1 mm/s: the law fitted
    before any effect softened to 0.18 mm/s and took a part of the mode's force at the reversals, and the mode then
    failed the held-out test (2.96 % -> 2.65 %, p = 0.057). Adopted from didim's default law as well, it is named, at
    its frequency, and the law comes back to the generator's."""
    rec, h, enr = bench.make("flexibility", 45.0, "emps", bench.TEST_SEED0 + 1)
    d = didim.doctor(rec, "rigid", apM=80.0)
    named = [f.effect for f in d.findings]
    assert named and named[0] == "flexibility", d.summary()
    assert d.findings[0].params["f_n_flex"] == pytest.approx(45.0, rel=0.1)
    law = d.final_result.structure
    assert law.coulomb_law == "algebraic" and law.coulomb_eps == pytest.approx(1e-4, rel=0.5), law


def test_diagnosis_json_and_html_contract(bench, tmp_path):
    rec, _, _ = bench.make("offset", 5.6, "emps", bench.TEST_SEED0 + 1)
    d = didim.doctor(rec, "rigid", apM=80.0)
    j = json.loads(d.to_json())
    assert j["findings"] and j["findings"][0]["effect"] == "offset" and "OF" in j["findings"][0]["params"]
    for k in ("train_before", "train_after", "valid_before", "valid_after"):
        assert 0 < j["fit"][k] < 1
    h = d.to_html()
    assert h.count("data:image/png;base64,") >= 2 and "offset" in h and "<html" in h


def test_doctor_cli_on_the_real_emps_records(emps_path, emps_pulses_path, tmp_path):
    out, page = tmp_path / "d.json", tmp_path / "d.html"
    p = subprocess.run([sys.executable, "-m", "didim", "doctor", str(emps_path), "--validate", str(emps_pulses_path),
                        "--apm", "78", "--json", str(out), "--html", str(page), "--quiet"],
                       capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    d = json.loads(out.read_text())
    assert set(d["fit"]) >= {"train_before", "train_after", "valid_before", "valid_after"}
    from didim.doctor import EFFECTS
    assert all(f["effect"] in EFFECTS for f in d["findings"])
    assert d["fit"]["valid_after"] <= d["fit"]["valid_before"]
    assert page.stat().st_size > 50_000
    # the target on the real EMPS: the final model's closed-loop force error on DATA_EMPS_PULSES at most 4.5 %
    # (3.27 % measured), below the benchmark's published model's through the same simulator (5.13 %)
    published = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "OF": -3.1648}
    valid = didim.load_mat(emps_pulses_path)
    pub = float(np.linalg.norm(valid.force - didim.simulate(valid, published).force) / np.linalg.norm(valid.force))
    assert d["fit"]["valid_force_after"] <= 0.045 and d["fit"]["valid_force_after"] < pub - 0.01, (d["fit"], pub)
    assert [x["samples"] for x in d["locate"]["lead_in"]] == [16, 16], d["locate"]["lead_in"]
    # the mode step 2 finds lies far above the band (106-111 Hz): the adoption stops there, as the three steps do,
    # instead of fitting a stiff loop to a mode the record does not show (56.9 % held-out error, 1.3 s per refit)
    flex = [x for x in d["rejected"] if x["effect"] == "flexibility"]
    assert flex and all("step 2 finds no mode" in x["evidence"] for x in flex), flex
    # each try says its round, the ones not adopted too (a new user saw two "flexibility" lines, one without it)
    assert all(isinstance(x["where"].get("round"), int) for x in d["rejected"]), [x["where"] for x in d["rejected"]]
    html = page.read_text()
    lead = html.index("<b>Lead-in.</b>")
    assert html.count("<b>Lead-in.</b>") == 2 and "data:image/png" in html[lead:lead + 2000]  # its figure follows


def test_no_flexible_base_on_a_record_that_does_not_show_the_mode(emps):
    """DATA_EMPS shows no flexible mode in its band (step 2's best mode lies above the 60 Hz cutoff): a flexible base
    fitted there anyway predicted DATA_EMPS_PULSES with a 313 % force error and the doctor went on from it. Now it
    says there is no flexible base and which model to diagnose instead."""
    from didim.doctor import BaseFitError

    with pytest.raises(BaseFitError, match="no flexible base fit on DATA_EMPS: this record cannot support a flexible "
                                           r"identification.*model='rigid'"):
        didim.doctor(emps, "flexible")


def test_doctor_finds_load_friction_missing_from_a_flexible_model():
    # a validation run of its own (another noise draw): the load-friction fit must not see the held-out samples, and
    # on this record the friction split needs the chirp at its end, which an in-record holdout would hold out
    truth = didim.scenarios.TABLE3_TRUTH
    rec = didim.scenarios.make_recording(truth, "flexible", force_noise=1.0, seed=105)
    val = didim.scenarios.make_recording(truth, "flexible", force_noise=1.0, seed=106)
    d = didim.doctor(rec, "flexible", validate=val, apM=78.0)
    named = [f.effect for f in d.findings]
    assert named[:1] == ["load_friction"], d.summary()
    f = d.findings[0]
    assert f.params["Fv2"] == pytest.approx(truth["Fv2"], rel=0.1)
    assert f.params["Fc2"] == pytest.approx(truth["Fc2"], rel=0.1)
    assert d.fit["valid_after"] < 0.3 * d.fit["valid_before"]
    # judged against the model without it refitted by the same optimiser (which alone moves M1, M2, K12)
    assert "same optimiser" in f.evidence
    assert f.fit["valid_before"] < 0.9 * d.fit["valid_before"]


def test_fits_that_take_a_whole_record_see_only_the_training_samples():
    from didim.doctor.fit import Data
    from didim.signal import Decimation

    rec = didim.scenarios.make_recording(didim.scenarios.TABLE3_TRUTH, "flexible", force_noise=1.0, seed=105)
    data = Data(rec, None, Decimation.lowpass(40.0, rec.fs), 0.3)
    tr = data.train_record()
    assert tr.n == data.n_train == round(0.7 * rec.n)
    np.testing.assert_array_equal(tr.force, rec.force[: data.n_train])
    assert Data(rec, rec, Decimation.lowpass(40.0, rec.fs), 0.3).train_record() is rec


def _unnamed_setup(seed):
    from didim.doctor.fit import Data
    from didim.signal import Decimation

    truth = dict(M=95.0, Fv=200.0, Fc=20.0)
    rec = didim.scenarios.make_recording(truth, "rigid", force_noise=0.5, seed=seed)
    data = Data(rec, None, Decimation.lowpass(40.0, rec.fs), 0.3)
    sim = didim.simulate(rec, truth, "rigid")
    m = data.m_train
    v, q = data.dec(sim.qd[0])[:m], data.dec(sim.q[0])[:m]
    noise = lfilter([1.0], [1.0, -0.9], np.random.default_rng(seed).standard_normal(m)) * 0.3  # coloured, 0.7 N RMS
    return data, sim, v, q, noise


def test_unnamed_finds_friction_that_varies_along_the_stroke_in_one_direction_only():
    # a 3 N friction excess over a third of the stroke, only while moving forward: no candidate's shape, and a pooled
    # position view mixes it with the backward passes; an AR fitted on the residual itself whitened such smooth
    # structure away
    from didim.doctor import _unnamed

    data, sim, v, q, noise = _unnamed_setup(3)
    lo, hi = np.percentile(q, [20, 50])
    bump = np.where((v > 0.02 * np.abs(v).max()) & (q > lo) & (q < hi), -3.0, 0.0)
    f = _unnamed(data, bump + noise, sim, np.zeros((len(q), 0)), 0.01)
    assert f is not None and f.where["view"] == "position, moving forward", f
    assert f.where["mean_residual_N"] < -1.5  # the bin it names carries the excess


def test_unnamed_stays_silent_on_coloured_noise():
    from didim.doctor import _unnamed

    alarms = 0
    for seed in range(10):
        data, sim, v, q, noise = _unnamed_setup(seed)
        alarms += _unnamed(data, noise, sim, np.zeros((len(q), 0)), 0.01) is not None
    assert alarms <= 1  # 4 views at a family-wise 1 %: about 0.1 expected in 10


def test_validating_on_the_training_record_is_refused():
    rec = didim.scenarios.make_recording(dict(M=95.0, Fv=200.0, Fc=20.0), "rigid", force_noise=0.5, seed=1)
    same = didim.Recording(dt=rec.dt, qr=rec.qr.copy(), force=rec.force.copy(), qm=rec.qm, controller=rec.controller,
                           name="a copy under another name")
    with pytest.raises(didim.DataError, match="validation record is the training record"):
        didim.doctor(rec, "rigid", validate=same)


def test_the_summary_gives_the_final_model_in_words_with_units(emps_path, emps_pulses_path):
    d = didim.doctor(didim.load_mat(emps_path), "rigid", validate=didim.load_mat(emps_pulses_path))
    f = next(x for x in d.findings if x.effect == "asymmetric_friction")
    p = d.final_state.params  # refitted after the later findings: the words give these values, not the first fit's
    fwd, bwd = p["Fv"] + p["dFv"], p["Fv"] - p["dFv"]
    assert f"viscous friction {fwd:.4g} N/(m/s) forward, {bwd:.4g} N/(m/s) backward" in f.words
    assert f"Coulomb friction {p['Fc'] + p['dFc']:.4g} N forward" in f.words
    assert f.words in d.summary() and "details" in d.summary() and "dFv = " in d.summary()
    assert " N/(m/s)," in d.summary().split("details")[1]  # the details carry units too


def test_a_force_lag_accepted_before_flexibility_survives_its_adoption():
    """Issue 28: the flexibility's adoption rebuilt the doctor's state field by field and dropped a force lag (and the
    friction law) accepted before it. The state it returns is the one it was given, made flexible."""
    from didim.doctor.effects import _flexibility_adopt
    from didim.doctor.fit import Data, State
    from didim.signal import Decimation

    truth = didim.scenarios.TABLE3_TRUTH
    plan = didim.scenarios.make_recording(truth, "flexible", force_noise=0.0, seed=3)
    sim = didim.simulate(plan, truth, "flexible", force_lag=4e-4)
    rng = np.random.default_rng(3)
    rec = didim.Recording(dt=plan.dt, qr=plan.qr, force=sim.force + rng.standard_normal(plan.n), qm=sim.q1,
                          controller=plan.controller, lead_in=None)
    rigid = didim.identify(rec, "rigid", "didim", force_lag=4e-4)
    state = State(didim.Model("rigid", force_lag=4e-4, coulomb_eps=2e-4, coulomb_law="tanh"), dict(rigid.params), {})
    data = Data(rec, None, Decimation.lowpass(40.0, rec.fs), 0.3)
    st, r, params, _ = _flexibility_adopt(None, state, data, None)
    assert st.kind == "flexible" and r.model == "flexible"
    assert (st.model.force_lag, st.model.coulomb_eps, st.model.coulomb_law) == (4e-4, 2e-4, "tanh")
    assert r.structure.force_lag == 4e-4
    # the blocked-motor mode, as the doctor states it
    assert params["f_n_flex"] == pytest.approx(np.sqrt(truth["K12"] / truth["M2"]) / (2 * np.pi), rel=0.05)


def test_the_fit_plot_simulates_a_doctor_result_with_its_own_structure(bench):
    """plot_fit guessed the model from the parameter names ("OF" in params, "K12" in params) and failed on a result
    with extra terms; it simulates the result as it is (its terms, delay, force lag and friction law)."""
    from didim.plots import plot_fit

    rec, _, _ = bench.make("asymmetric_friction", 5.6, "emps", bench.TEST_SEED0 + 2)
    d = didim.doctor(rec, "rigid", apM=80.0)
    assert d.final_result.structure.terms, d.summary()
    fig = plot_fit(rec, d.final_result)
    err = didim.simulate(rec, d.final_result).relative_error(rec)
    assert f"{100 * err:.2f} %" in fig.axes[0].get_title()
    assert err < 0.5 * d.fit["train_force_before"]
