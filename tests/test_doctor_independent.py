"""The doctor on records from the independent rigid plant of `benches/doctor_independent.py` (plain RK4, a rational
Coulomb law, force noise inside the loop): the concealed effect named, no wrong name, and on a record with nothing
concealed nothing named but the friction law's shape through zero speed (the plant's Coulomb law is not didim's)."""

import pytest

from conftest import bench_module


@pytest.fixture(scope="module")
def bench():
    return bench_module("doctor_independent")


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


def test_a_ripple_moved_along_the_stroke_in_the_held_out_record_is_said_so(bench):
    """The validation record is 'homed' a quarter period (5 mm of the 20 mm ripple) away: the ripple fitted on the
    training record makes the held-out fit worse and is not confirmed; the doctor says that the held-out record shows
    the same period shifted along the stroke (the shift, 5 mm, within the resolution of a 2 N ripple in 0.5 N of
    noise: a few degrees, 1 mm allowed), instead of only refusing it."""
    import re
    import warnings

    import didim

    train, valid = bench.records("position_ripple", 1, valid_ripple_shift=0.005)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        d = didim.doctor(train, "rigid", valid)
    assert "position_ripple" not in [f.effect for f in d.findings]
    notes = [f.note for f in d.rejected if f.effect == "position_ripple" and f.note]
    assert notes, [(f.effect, f.evidence) for f in d.rejected]
    m = re.search(r"same period \(([\d.]+) mm.*shifted by ([\d.]+) mm", notes[-1])
    assert m, notes[-1]
    assert abs(float(m.group(1)) - 20.0) < 0.5 and abs(float(m.group(2)) - 5.0) < 1.0, notes[-1]
    assert "not confirmed" in d.summary() and "shifted by" in d.summary()

