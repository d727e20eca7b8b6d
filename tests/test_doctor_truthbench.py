"""The doctor on records from an independent simulator (../shared/data/truthbench/doctor/): the cases that broke it
before (a flexible base it could not fit, a delay hidden behind flexibility, a clean low-noise record where a
statistically detectable but practically irrelevant Stribeck term was named). The full run over all 25 pairs is
benches/doctor_truthbench.py."""

import warnings

import pytest

import didim


def _diagnose(truthbench, name):
    load, truth = truthbench
    entry = truth[f"doctor/{name}"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        d = didim.doctor(load(f"doctor/{name}_train"), entry["model"], load(f"doctor/{name}_valid"))
    return d, entry


@pytest.mark.parametrize("name", ["backlash_trap", "delay1_slow", "flex_delay_chirp", "null_lownoise", "null_flex_trap",
                                  "coupling_damping_multisine"])
def test_the_doctor_names_what_is_concealed_and_nothing_else(truthbench, name):
    d, entry = _diagnose(truthbench, name)
    named = {f.effect for f in d.findings if f.effect != "unnamed"}
    assert named == set(entry["effects"]), d.summary()
    if not entry["effects"]:  # nothing concealed: no finding of any kind, `unnamed` included
        assert not d.findings, d.summary()
    if named:  # every accepted effect matters: the held-out error drops by more than the practical threshold
        from didim.doctor import MIN_HELDOUT_GAIN

        assert d.fit["valid_after"] < (1 - MIN_HELDOUT_GAIN) * d.fit["valid_before"]


def test_the_doctor_recovers_the_coupling_damping(truthbench):
    d, entry = _diagnose(truthbench, "coupling_damping_multisine")
    (f,) = [f for f in d.findings if f.effect == "coupling_damping"]
    assert f.params["C12"] == pytest.approx(entry["params"]["Cdamp"], rel=0.15)
