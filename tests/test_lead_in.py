"""Logs that begin in motion: `Recording.lead_in` reconstructs the reference back to the rest it left
(`didim.recording.reconstruct_lead_in`) and the simulation runs through that stretch before the log's first sample.
Records from the independent plant of `benches/doctor_independent.py` (plain RK4, rational Coulomb law, in-loop noise),
so that the simulator that fits is not the one that made the data, and the real EMPS."""

import dataclasses
import pickle
import warnings

import numpy as np
import pytest

import didim
from didim.recording import reconstruct_lead_in

from conftest import bench_module, cut_log

PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "OF": -3.1648}


@pytest.fixture(scope="module")
def plant():
    return bench_module("doctor_independent")


def _cut(rec, i0, name="cut log"):
    return cut_log(rec, i0, name)


def _start_of_move(rec):
    return int(np.flatnonzero(np.diff(rec.qr) != 0)[0])


def _head_error(rec, params, ms=60):
    """The force error (N RMS) of ``params`` over the first ``ms`` milliseconds of ``rec``."""
    k = int(round(ms * 1e-3 / rec.dt))
    r = rec.force[:k] - didim.simulate(rec, params).force[:k]
    return float(np.sqrt(np.mean(r**2)))


def test_the_emps_logs_begin_16_ms_after_the_move(emps, emps_pulses):
    """Both EMPS records begin with the reference at 13.5 mm/s under 0.84 m/s², the axis 0.1 mm behind: extrapolated
    back at that acceleration, the reference was at rest at 0 (within a nanometre) 16 samples earlier."""
    for rec in (emps, emps_pulses):
        lead = rec.qr_lead
        assert lead.size == 16 and abs(lead[0]) < 1e-9, lead[:3]
        assert np.all(np.diff(np.r_[lead, rec.qr[:3]]) > 0)  # it moves forward into the log, without a jump
        assert (rec.qr[1] - rec.qr[0]) / rec.dt == pytest.approx(0.0135, rel=0.03)
        assert not rec.qr_lead.flags.writeable


def test_the_lead_in_takes_the_start_artefact_out_of_the_published_models_error(emps_pulses):
    """The published model's force error over the first 60 ms of DATA_EMPS_PULSES: simulated from rest on the first
    reference sample (lead_in=None, the paper's start) the simulation lags a record that is already moving; through
    the lead-in it meets it. The residual there drops to a third at most, and the whole record's error with it."""
    none = dataclasses.replace(emps_pulses, lead_in=None)
    head_none, head_lead = _head_error(none, PUBLISHED), _head_error(emps_pulses, PUBLISHED)
    assert head_lead < head_none / 3, (head_none, head_lead)
    whole = [float(np.linalg.norm(r.force - didim.simulate(r, PUBLISHED).force) / np.linalg.norm(r.force))
             for r in (none, emps_pulses)]
    assert whole[1] < whole[0] - 0.005, whole


@pytest.mark.parametrize("ms", [8, 16, 40])
def test_a_log_cut_in_the_first_acceleration_is_led_in_from_where_it_began(plant, ms):
    """The independent plant's training record (at rest 0.3 s, then 0.83 m/s² from rest) with its first 0.3 s + ``ms``
    ms cut off: the reconstruction finds the rest ``ms`` ms back (within a sample) at the position the plant rested
    at (within 0.1 % of the distance moved, which a sample's rounding of the time back to rest allows), and the
    simulation of the plant's own parameters meets the log's first 60 ms three times closer than from rest on the
    first reference sample."""
    train, _ = plant.records(None, 1)
    i0 = _start_of_move(train) + ms
    cut = _cut(train, i0)
    lead = cut.qr_lead
    assert abs(lead.size - ms) <= 1, lead.size
    moved = cut.qr[0] - train.qr[0]
    assert abs(lead[0] - train.qr[0]) < 1e-3 * moved + 1e-12, (lead[0], train.qr[0])
    truth = {"M": plant.M, "Fv": plant.FV, "Fc": plant.FC}
    head_lead = _head_error(cut, truth)
    head_none = _head_error(dataclasses.replace(cut, lead_in=None), truth)
    assert head_lead < head_none / 3, (head_none, head_lead)


def test_a_log_cut_in_a_cruise_gets_no_lead_in(plant):
    """Cut 200 ms into a move at 83 mm/s (0.54 mm behind the reference): how long the axis cruised is not in the log,
    and a ramp from rest that ends at the first sample leaves 30 N RMS of transient over the first 50 ms (measured
    with a ramp at the reference's typical acceleration), which biased rigid DIDIM's M by 38 %. No lead-in: the fits
    leave out the samples the simulation takes to join the log (tests/test_late_start.py)."""
    train, _ = plant.records(None, 1)
    moving = np.flatnonzero(np.abs(np.diff(train.qr)) > 1e-5)
    cut = _cut(train, int(moving[moving > 3000][0]) + 200)
    assert cut.qr_lead.size == 0


def test_no_lead_in_where_the_log_begins_at_rest_or_on_the_reference(plant):
    train, _ = plant.records(None, 1)
    assert train.qr_lead.size == 0  # the reference rests for 0.3 s
    # a didim simulation started at rest on a moving reference (the truthbench's EMPS-like records): the axis sits on
    # the reference at the first sample, so the loop started with the log
    i0 = _start_of_move(train) + 16
    qr = train.qr[i0:]
    sim = didim.simulate(dataclasses.replace(_cut(train, i0), lead_in=None), {"M": 95.0, "Fv": 200.0, "Fc": 20.0})
    on = didim.Recording(dt=train.dt, qr=qr, force=sim.force, qm=sim.q[0], controller=train.controller,
                         position_resolution=train.position_resolution)
    assert on.qr_lead.size == 0
    # a step at the head: nothing smooth to extrapolate
    step = np.r_[0.0, np.full(train.n - 1, 0.01)]
    assert reconstruct_lead_in(step, train.dt, np.zeros(train.n), 5e-8).size == 0
    # the axis ahead of the reference, not behind it
    assert reconstruct_lead_in(qr, train.dt, qr + 1e-4, 5e-8).size == 0


def test_a_given_lead_in_is_used_and_checked(plant):
    train, _ = plant.records(None, 1)
    i0 = _start_of_move(train) + 16
    cut = _cut(train, i0)
    given = dataclasses.replace(cut, lead_in=train.qr[i0 - 100:i0])  # the true reference before the cut
    assert np.array_equal(given.qr_lead, train.qr[i0 - 100:i0])
    truth = {"M": plant.M, "Fv": plant.FV, "Fc": plant.FC}
    # the true history and the reconstructed one give the same simulation within the noise of the log
    assert np.max(np.abs(didim.simulate(given, truth).force - didim.simulate(cut, truth).force)) < 1.0
    assert dataclasses.replace(cut, lead_in="none").qr_lead.size == 0
    with pytest.raises(didim.DataError, match="lead_in must be 'auto', None"):
        dataclasses.replace(cut, lead_in="guess")
    with pytest.raises(didim.DataError, match="lead_in has 9 samples, not fewer than the record's 9"):
        didim.Recording(dt=1e-3, qr=np.zeros(9), force=np.zeros(9), qm=np.zeros(9), controller=didim.EmpsCascade(),
                        lead_in=np.zeros(9))
    with pytest.raises(didim.DataError, match="lead_in .* non-finite"):
        dataclasses.replace(cut, lead_in=np.array([0.0, np.nan]))
    again = pickle.loads(pickle.dumps(cut))
    assert np.array_equal(again.qr_lead, cut.qr_lead)


def test_a_simulation_that_diverges_in_the_lead_in_says_so(emps):
    rec = dataclasses.replace(emps, controller=didim.PD(1e6, 1e4))
    assert rec.qr_lead.size == 16
    with pytest.raises(didim.SimulationError, match=r"sample -\d+ \(t = -[\d.]+ s, in the lead-in before the record\)"):
        didim.simulate(rec, {"M": 0.01, "Fv": 0.0, "Fc": 0.0})


def test_three_step_didim_through_a_lead_in_on_an_independent_flexible_plant():
    """The independent two-mass plant of benches/independent_flexible.py (light load, 30 Hz, the chirp on a slow
    move; the reference rests 0.5 s, then accelerates at 0.8 m/s²) logged from 20 ms into the move: the lead-in goes
    back to where the reference rested (20 or 21 samples: a sample's rounding), and three-step DIDIM through it gives
    the truth within the whole log's tolerance (5 %), with a full-rate force error within 0.5 point of the whole
    log's (without the lead-in it is 2.7 points higher: the start)."""
    plant = bench_module("independent_flexible")
    if not (plant.TRUTHBENCH / "flexible").is_dir():  # the plant plays the truthbench's paper-like references
        pytest.skip(f"truthbench {plant.TRUTHBENCH} not available (set DIDIM_TRUTHBENCH_DIR)")
    _, t, ref = plant.CASES[0]
    rec = plant.recording(plant.reference(ref), t, seed=100)
    i0 = int(np.flatnonzero(np.diff(rec.qr) != 0)[0]) + 20
    cut = _cut(rec, i0)
    assert 20 <= cut.qr_lead.size <= 21 and abs(cut.qr_lead[0] - rec.qr[0]) < 1e-6, cut.qr_lead[:2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        whole = didim.identify(rec, "flexible", "didim")
        led = didim.identify(cut, "flexible", "didim")
    assert led.converged, led.message
    e = plant.errors(led, t)
    for k in ("M1", "M2", "K12", "M1+M2", "Fv1+Fv2", "Fc1+Fc2"):
        assert abs(e[k]) < 5.0, (k, e)
    assert led.force_error < whole.force_error + 0.005, (led.force_error, whole.force_error)


def test_the_command_line_and_load_record_take_the_lead_in(emps_pulses_path, tmp_path, capsys):
    from didim.cli import main

    assert didim.load_record(emps_pulses_path).qr_lead.size == 16
    none = didim.load_record(emps_pulses_path, lead_in=None)
    assert none.qr_lead.size == 0
    result = tmp_path / "published.json"
    didim.IdentificationResult(model="rigid", method="given", params=PUBLISHED, std={}, rel_std_pct={},
                               relative_error=float("nan"), iterations=0, simulations=0, elapsed_s=0.0,
                               options={"offset": True}).save(result)
    outs = []
    for extra in (["--quiet"], ["--lead-in", "none"]):
        assert main(["simulate", str(emps_pulses_path), str(result), *extra]) == 0
        outs.append(capsys.readouterr().out)
    expect = [f"{100 * np.linalg.norm(r.force - didim.simulate(r, PUBLISHED).force) / np.linalg.norm(r.force):.2f} %"
              for r in (didim.load_record(emps_pulses_path), none)]
    assert expect[0] != expect[1] and expect[0] in outs[0] and expect[1] in outs[1], (expect, outs)
    with pytest.raises(SystemExit) as e:  # argparse's usage error
        main(["simulate", str(emps_pulses_path), str(result), "--lead-in", "later"])
    assert e.value.code == 2 and "--lead-in" in capsys.readouterr().err


@pytest.mark.parametrize("ms", [10, 60])
def test_a_pi_cascade_log_cut_in_its_acceleration_fits_as_the_whole_log(ms):
    """The truthbench's drive record (an independent simulator, a PI velocity loop with feedforward and a low-pass,
    truth M 85 kg, Fv 180 N/(m/s), Fc 17 N; the reference rests 0.5 s, then accelerates at 1 m/s²) logged from ``ms``
    ms into the move. Through the lead-in the PI's integrator builds up as it did on the axis: rigid DIDIM gives the
    whole log's parameters within three standard errors (0.3–0.7 %) and its force error within 0.2 point (2.1 %).
    From rest on the first sample
    (lead_in=None) the error is 3.5 % at 10 ms and 32 % at 60 ms (2.7 % and 2.2 % after the start the fits leave
    out), with M 1.5 % low at 10 ms."""
    from conftest import TRUTHBENCH_DIR

    path = TRUTHBENCH_DIR / "drive" / "pi_cascade_train.csv"
    if not path.exists():
        pytest.skip(f"truthbench {TRUTHBENCH_DIR} not available (set DIDIM_TRUTHBENCH_DIR)")
    rec = didim.load_record(path)
    i0 = _start_of_move(rec) + ms
    cut = dataclasses.replace(rec, qr=rec.qr[i0:], force=rec.force[i0:], qm=rec.qm[i0:], name="cut")
    assert ms <= cut.qr_lead.size <= ms + 1 and abs(cut.qr_lead[0] - rec.qr[0]) < 1e-6, cut.qr_lead[:2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        whole = didim.identify(rec, "rigid")
        led = didim.identify(cut, "rigid")
    for k in ("M", "Fv", "Fc"):  # the two estimates share most of their data: 3 σ of one bounds their difference
        assert abs(led.params[k] - whole.params[k]) < 3 * whole.std[k], (k, led.params, whole.params, whole.std)
    assert abs(led.force_error - whole.force_error) < 0.002, (led.force_error, whole.force_error)


def test_a_lead_in_simulates_as_the_record_extended_by_it(plant):
    """The simulation through a lead-in is the simulation of the record extended by it (the reference's lead-in, the
    known external input held at its first value: here a 30 N bias), from its first sample on: the same operations,
    so the same numbers."""
    train, _ = plant.records(None, 1)
    i0 = _start_of_move(train) + 16
    cut = dataclasses.replace(_cut(train, i0), u_ext=np.full(train.n - i0, 30.0))
    lead = cut.qr_lead
    assert lead.size > 0
    extended = dataclasses.replace(cut, qr=np.r_[lead, cut.qr], force=np.r_[np.zeros(lead.size), cut.force],
                                   qm=np.r_[np.full(lead.size, cut.qm[0]), cut.qm],
                                   u_ext=np.full(train.n - i0 + lead.size, 30.0), lead_in=None)
    p = {"M": 95.0, "Fv": 200.0, "Fc": 20.0}
    for model, params in (("rigid", p), ("flexible", {"M1": 60.0, "Fv1": 100.0, "Fc1": 10.0, "M2": 35.0, "Fv2": 100.0,
                                                     "Fc2": 10.0, "K12": 8e5})):
        a = didim.simulate(cut, params, model)
        b = didim.simulate(extended, params, model)
        np.testing.assert_array_equal(a.force, b.force[lead.size:])
        np.testing.assert_array_equal(a.q, b.q[:, lead.size:])


def test_a_given_lead_in_must_join_the_reference(emps, emps_path):
    """A buffer in another unit, or not the samples just before the record, is refused with what to give."""
    with pytest.raises(didim.DataError, match=r"lead_in ends at 0.6 m but the reference's first sample is 0.000107822 m"):
        dataclasses.replace(emps, lead_in=np.array([0.5, 0.6]))
    ok = dataclasses.replace(emps, lead_in=emps.qr_lead.copy())  # the reconstructed one, given: accepted as it is
    assert np.array_equal(ok.qr_lead, emps.qr_lead)
    assert didim.load_mat(emps_path, lead_in=None).qr_lead.size == 0
    assert dataclasses.replace(emps, lead_in=np.array([])).qr_lead.size == 0  # an empty buffer: none
