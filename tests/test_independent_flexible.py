"""Three-step DIDIM on flexible records from a plant written apart from didim's simulator (benches/independent_flexible.py:
plain RK4, a rational Coulomb law, force noise inside the loop), with truths the truthbench does not hold: other
masses, a 40 Hz mode, a light load. Tolerances as the issue's: 5 % on M1, M2, K12 and the totals with load friction,
2 % on every identified parameter with all friction on the motor, ΔM2 within 1.5 kg for 10 kg."""

import importlib.util
import pathlib

import pytest

import didim

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benches" / "independent_flexible.py"


@pytest.fixture(scope="module")
def plant(truthbench):
    spec = importlib.util.spec_from_file_location("independent_flexible", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    from conftest import TRUTHBENCH_DIR

    mod.TRUTHBENCH = TRUTHBENCH_DIR  # the paper-like references come from there (the fixture skips without it)
    return mod


@pytest.mark.parametrize("label", ["heavy motor, 40 Hz, moving", "light load, 30 Hz, at rest"])
def test_three_step_didim_with_load_friction_on_an_independent_plant(plant, label):
    i, (_, t, ref) = next((i, c) for i, c in enumerate(plant.CASES) if c[0] == label)
    r = didim.identify(plant.recording(plant.reference(ref), t, seed=100 + i), "flexible", "didim")
    assert r.converged, r.message
    e = plant.errors(r, t)
    for k in ("M1", "M2", "K12", "M1+M2", "Fv1+Fv2", "Fc1+Fc2"):
        assert abs(e[k]) < 5.0, (k, e)


def test_three_step_didim_with_motor_friction_only_on_an_independent_plant(plant):
    i, (_, t, ref) = next((i, c) for i, c in enumerate(plant.CASES) if c[0].startswith("motor friction only, 35 Hz"))
    r = didim.identify(plant.recording(plant.reference(ref), t, seed=100 + i), "flexible", "didim")
    assert r.converged and r.options["variant"] == "paper", r.message
    e = plant.errors(r, t)
    for k in ("M1", "M2", "K12", "Fv1", "Fc1"):
        assert abs(e[k]) < 2.0, (k, e)


def test_three_step_didim_sees_a_10_kg_payload_on_an_independent_plant(plant):
    t = plant.truth(60.0, 20.0, 30.0, 0.5)
    heavy = dict(t, M2=t["M2"] + 10.0)  # the same coupling: the mode moves down with the payload
    qr = plant.reference("moving")
    m2 = [didim.identify(plant.recording(qr, p, seed=7), "flexible", "didim").params["M2"] for p in (t, heavy)]
    assert abs((m2[1] - m2[0]) - 10.0) < 1.5, m2


def test_a_mass_split_sliding_in_step_3_is_named_in_the_message():
    from types import SimpleNamespace

    from didim.methods.identification import _mass_split_drift

    def run(m2s):
        hist = [SimpleNamespace(params={"M2": m, "K12": 1e6 * m / 30.0}) for m in m2s]
        return _mass_split_drift(SimpleNamespace(history=hist, params={"M2": m2s[0]}))

    slide = run([30.0 - 0.3 * k for k in range(30)])  # the ratio (the mode) holds, the split drifts by 15 %
    assert "sliding together" in slide and "lowest output error" in slide
    assert run([30.0 + 0.01 * (-1) ** k for k in range(30)]) == ""  # wandering in place is no drift
    assert run([30.0] * 3) == ""  # too few iterations to tell
