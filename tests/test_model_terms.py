"""A model term says which degree of freedom it acts on, and every parameter's unit comes from its basis function in
the core (one definition for the simulator, the regressor and the units)."""

import json

import numpy as np
import pytest

import didim
from didim import _core
from didim.simulation import coulomb_sign


def test_a_load_side_term_reads_the_load_state_and_acts_on_the_load_row():
    rng = np.random.default_rng(3)
    n, vs = 400, 0.01
    q = np.cumsum(rng.normal(0, 1e-4, (2, n)), axis=1)
    qd = rng.normal(0, 0.02, (2, n))
    qdd = rng.normal(0, 1.0, (2, n))
    terms = [didim.Term("Fs1", "stribeck", vs), didim.Term("Fs2", "stribeck", vs, "load")]
    w = didim.Model("flexible", terms=terms).core().regressor(q, qd, qdd)
    names = didim.param_names("flexible", terms=terms)
    i1, i2 = names.index("Fs1"), names.index("Fs2")
    # the Stribeck basis sign(v)·exp(−(v/vs)²), written here from its definition with numpy
    expect = lambda v: coulomb_sign(v) * np.exp(-(v / vs) ** 2)  # noqa: E731
    np.testing.assert_allclose(w[0][:, i1], expect(qd[0]), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(w[1][:, i1], 0.0)
    np.testing.assert_allclose(w[1][:, i2], expect(qd[1]), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(w[0][:, i2], 0.0)


def test_units_come_from_the_basis_functions():
    m = didim.Model("flexible", offset=True, terms=(didim.Term("C12", "damper"), didim.Term("Fs2", "stribeck", 0.01, "load"),
                                                    didim.Term("Ar_sin", "ripple_sin", 0.02)), backlash_gap=1e-5)
    assert m.units() == {"M1": "kg", "Fv1": "N/(m/s)", "Fc1": "N", "M2": "kg", "Fv2": "N/(m/s)", "Fc2": "N",
                         "K12": "N/m", "OF": "N", "C12": "N/(m/s)", "Fs2": "N", "Ar_sin": "N"}


def test_a_term_s_dof_survives_saving_and_old_files_without_it_still_load(tmp_path):
    m = didim.Model("flexible", terms=(didim.Term("Fs2", "stribeck", 0.01, "load"),))
    back = didim.Model.from_dict(json.loads(json.dumps(m.to_dict())))
    assert back == m and back.terms[0].dof == "load"
    old = didim.Model.from_dict({"kind": "rigid", "terms": [["Fs", "stribeck", 0.01]]})
    assert old.terms[0].dof == "motor"


def test_a_term_on_a_dof_the_model_lacks_is_refused_by_name(emps):
    with pytest.raises(didim.DataError, match="term Fs2 refers to a degree of freedom outside this 1-dof model"):
        didim.simulate(emps, {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "Fs2": 1.0}, "rigid",
                       terms=[didim.Term("Fs2", "stribeck", 0.01, "load")])
    # a dof that is neither is a robot joint's name: one axis's model refuses it, naming the two it has
    with pytest.raises(didim.DataError, match="term Fs2's dof is 'joint': one axis's terms act on the 'motor' or the "
                                              "'load'"):
        didim.Model("rigid", terms=[didim.Term("Fs2", "stribeck", 0.01, "joint")])
    with pytest.raises(didim.DataError, match="a damper couples the motor and the load"):
        didim.Term("C12", "damper", 0.0, "load")
