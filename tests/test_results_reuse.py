"""A result carries its model structure and every parameter, frozen ones included: ``didim.simulate(rec, r)``
reproduces its own closed-loop force error, through a JSON file too, and ``didim simulate`` applies it to another
record (the paper's cross-test)."""

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

import didim
from conftest import resolved
from didim import scenarios as sc


@pytest.fixture(scope="module")
def flex_record():
    return sc.make_recording(sc.TABLE3_TRUTH, "flexible", sc.trapezoid_moving_chirp(), load_encoder=True, seed=5)


@pytest.fixture(scope="module")
def results(emps, flex_record):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        return {
            "idim-ls rigid": (emps, didim.identify(emps, "rigid", "idim-ls", offset=True)),
            "didim rigid": (emps, didim.identify(emps, "rigid", "didim", offset=True)),
            "oe-nm rigid": (emps, didim.identify(emps, "rigid", "oe-nm", max_iter=150)),
            "idim-ls flexible": (flex_record, didim.identify(flex_record, "flexible", "idim-ls")),
            "didim flexible": (flex_record, didim.identify(flex_record, "flexible", "didim")),
            "didim flexible (paper)": (flex_record, didim.identify(flex_record, "flexible", "didim", variant="paper")),
            "oe-lm flexible": (flex_record, didim.identify(flex_record, "flexible", "oe-lm")),
        }


@pytest.mark.parametrize("case", ["idim-ls rigid", "didim rigid", "oe-nm rigid", "idim-ls flexible", "didim flexible",
                                  "didim flexible (paper)", "oe-lm flexible"])
def test_simulating_a_result_reproduces_its_own_force_error(results, case, tmp_path):
    rec, r = results[case]
    assert r.structure is not None and set(r.all_params) == set(r.structure.param_names())
    assert 0 < r.force_error < 0.2
    assert didim.simulate(rec, r).relative_error(rec) == pytest.approx(r.force_error, rel=1e-9)
    r.save(tmp_path / "r.json")
    back = didim.load_result(tmp_path / "r.json")
    assert back.structure == r.structure and back.all_params == pytest.approx(r.all_params, rel=1e-15)
    assert didim.simulate(rec, back).relative_error(rec) == pytest.approx(r.force_error, rel=1e-9)


def test_a_flexible_didim_result_carries_its_frozen_load_friction(results):
    _, r = results["didim flexible (paper)"]
    assert r.frozen == {"Fv2": 0.0, "Fc2": 0.0}
    assert r.all_params["Fv2"] == 0.0 and list(r.all_params) == r.structure.param_names()


def test_simulate_batch_takes_results(results):
    rec, a = results["didim flexible"]
    _, b = results["oe-lm flexible"]
    batch = didim.simulate_batch(rec, [a, b])
    for i, r in enumerate((a, b)):
        np.testing.assert_allclose(batch.force[i], didim.simulate(rec, r).force, rtol=0, atol=1e-9 * np.abs(rec.force).max())
    with pytest.raises(didim.DataError, match="share one model structure"):
        didim.simulate_batch(rec, [a, results["idim-ls flexible"][1]])


def test_cli_simulate_applies_a_saved_result_to_another_record(results, emps_pulses_path, tmp_path):
    _, r = results["didim rigid"]
    r.save(tmp_path / "r.json")
    out = subprocess.run([sys.executable, "-m", "didim.cli", "simulate", str(emps_pulses_path), str(tmp_path / "r.json"),
                          "--json", str(tmp_path / "s.json")], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    got = json.loads((tmp_path / "s.json").read_text())
    pulses = didim.load_mat(emps_pulses_path)
    assert got["force_error"] == pytest.approx(didim.simulate(pulses, r).relative_error(pulses), rel=1e-12)
    assert 0.05 < got["force_error"] < 0.07  # the paper's cross-test: within a point of the training error
    assert f"{100 * got['force_error']:.2f} %" in out.stdout


def test_load_result_says_what_is_wrong(tmp_path):
    (tmp_path / "a.json").write_text("not json")
    with pytest.raises(didim.DataError, match="not a JSON result"):
        didim.load_result(tmp_path / "a.json")
    (tmp_path / "b.json").write_text(json.dumps({"x": 1}))
    with pytest.raises(didim.DataError, match="not a didim result"):
        didim.load_result(tmp_path / "b.json")
    with pytest.raises(didim.DataError, match="no such file"):
        didim.load_result(tmp_path / "missing.json")


def test_a_step_2_result_cannot_be_simulated_and_says_why(results):
    rec, r = results["didim flexible"]
    with pytest.raises(didim.DataError, match="no parameter set of a model"):
        didim.simulate(rec, r.steps["mode"])


def test_a_model_object_stands_for_its_kind_and_structure_everywhere(emps):
    """``didim.Model`` is accepted wherever a model kind is: simulate, simulate_batch, problem and identify take its
    structure (offset, delay, terms...) as if given one by one, and refuse the same field given twice."""
    p = dict(M=95.1089, Fv=203.5034, Fc=20.3935, OF=-3.1648)
    m = didim.Model("rigid", offset=True, delay=1)
    # the same computation either way: the structure is only spelled differently
    a = didim.simulate(emps, p, m)
    b = didim.simulate(emps, p, "rigid", delay=1)
    np.testing.assert_array_equal(a.force, b.force)
    batch = didim.simulate_batch(emps, [p, {**p, "Fc": 25.0}], m)
    np.testing.assert_array_equal(batch.force[0], a.force)
    assert not np.array_equal(batch.force[1], a.force)
    with pytest.raises(didim.DataError, match=r"carries its structure: leave delay out"):
        didim.simulate(emps, p, m, delay=2)
    with pytest.raises(didim.DataError, match=r"carries its structure: leave offset out"):
        didim.simulate(emps, {k: v for k, v in p.items() if k != "OF"}, didim.Model("rigid"), offset=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r1 = didim.identify(emps, didim.Model("rigid", offset=True), "didim")
        r2 = didim.identify(emps, "rigid", "didim", offset=True)
        assert r1.params == r2.params and r1.structure == resolved(didim.Model("rigid", offset=True), emps)
        # a delayed model: the result carries the delay, and its force error is that of its own closed loop
        r3 = didim.identify(emps, m, "didim")
    assert r3.structure == resolved(m, emps)
    assert r3.force_error == pytest.approx(didim.simulate(emps, r3).relative_error(emps), rel=1e-12)
    with pytest.raises(didim.DataError, match=r"idim-ls cannot identify .*does not support delay"):
        didim.identify(emps, m, "idim-ls")
    with pytest.raises(didim.DataError, match=r"carries its structure: leave delay out"):
        didim.identify(emps, m, "didim", delay=2)


def test_the_doctor_s_final_model_is_a_result_that_reproduces_its_own_errors(emps_path, emps_pulses_path, tmp_path):
    """The doctor's final model (its effects, force lag included) as a result: simulate reproduces the doctor's own
    full-rate errors on the training and the validation record, in Python and through ``didim simulate``."""
    out = subprocess.run([sys.executable, "-m", "didim.cli", "doctor", str(emps_path), "--validate",
                          str(emps_pulses_path), "--result", str(tmp_path / "m.json"), "--json", str(tmp_path / "d.json"),
                          "--quiet"], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    fit = json.loads((tmp_path / "d.json").read_text())["fit"]
    r = didim.load_result(tmp_path / "m.json")
    emps, pulses = didim.load_mat(emps_path), didim.load_mat(emps_pulses_path)
    assert r.structure.terms, "the EMPS doctor adds friction terms"
    assert didim.simulate(emps, r).relative_error(emps) == pytest.approx(fit["train_force_after"], rel=1e-9)
    assert didim.simulate(pulses, r).relative_error(pulses) == pytest.approx(fit["valid_force_after"], rel=1e-9)
    cli = subprocess.run([sys.executable, "-m", "didim.cli", "simulate", str(emps_pulses_path), str(tmp_path / "m.json"),
                          "--json", str(tmp_path / "s.json")], capture_output=True, text=True, timeout=300)
    assert cli.returncode == 0, cli.stderr
    assert json.loads((tmp_path / "s.json").read_text())["force_error"] == pytest.approx(fit["valid_force_after"],
                                                                                        rel=1e-9)
