"""The doctor on records from the independent rigid plant of `benches/doctor_independent.py` (plain RK4, a rational
Coulomb law, force noise inside the loop): the concealed effect named, no wrong name, and on a record with nothing
concealed nothing named but the friction law's shape through zero speed (the plant's Coulomb law is not didim's)."""

import importlib.util
import pathlib

import pytest

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benches" / "doctor_independent.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("doctor_independent", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_nothing_concealed_nothing_named_but_the_friction_law_shape(bench):
    r = bench.diagnose(None, 1)
    assert r["named"] == [] and not r["false_alarm"], r
    assert set(r["shape"]) <= {"stribeck"}, r


def test_a_one_sample_delay_is_named_and_the_low_speed_term_chosen_again(bench):
    """Before the delay is modelled a low-speed term at 4.4 mm/s stands in for part of it (a `stribeck` name: wrong);
    once the delay is modelled its speed is chosen again, 0.18 mm/s: the friction law's shape, as on the null record."""
    r = bench.diagnose("delay", 1)
    assert "delay" in r["named"] and not r["wrong"], r
    assert r["valid_after"] < 0.5 * r["valid_before"], r


@pytest.mark.parametrize("effect", ["asymmetric_friction", "position_ripple"])
def test_friction_asymmetry_and_a_ripple_are_named(bench, effect):
    r = bench.diagnose(effect, 2)
    assert r["right"] and not r["wrong"], r
