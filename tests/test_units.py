"""Any axis, any units: declared units are converted once (positions, encoder step, controller, force), every printed
unit follows the axis, and a record whose positions are scaled (controller coefficients scaled back: the same
physics) gives the same parameters after conversion, the same doctor findings and the same work, because every speed,
length and tolerance didim derives comes from the record (its speed scale, stroke, encoder step)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import warnings

import numpy as np
import pytest

import didim
from didim.controllers import in_units
from didim.methods.friction_law import QUARTER
from didim.units import parse

from conftest import TRUTHBENCH_DIR

AXES = os.path.join(TRUTHBENCH_DIR, "axes")
needs_axes = pytest.mark.skipif(not os.path.isdir(AXES), reason="truthbench/axes records not found")

#: The scales of the issue: m to mm-like (1e-3), rad to deg, rad to rev, rad to 2^17 counts per revolution.
SCALES = (1e-3, 180 / math.pi, 1 / (2 * math.pi), 2**17 / (2 * math.pi))


def _scaled(rec: didim.Recording, s: float) -> didim.Recording:
    """The same record with its positions times ``s`` and its controller acting on them (coefficients / s)."""
    return dataclasses.replace(rec, qr=rec.qr * s, qm=rec.qm * s, lead_in="auto",
                               position_resolution=None if rec.position_resolution is None else rec.position_resolution * s,
                               controller=in_units(rec.controller, rec.dt, s, 1.0))


@pytest.fixture(scope="module")
def wrist() -> didim.Recording:
    """8 s of the truthbench's robot wrist joint (rad, N·m, 1 kHz, 2^20-count-like encoder, PI cascade), no effect."""
    rec = didim.load_record(os.path.join(AXES, "null_wrist_pic_train.csv"), units="rad")
    n = 8000
    return dataclasses.replace(rec, qr=rec.qr[:n], force=rec.force[:n], qm=rec.qm[:n])


def test_unit_texts_parse_and_convert():
    assert parse("deg").position_factor == pytest.approx(math.pi / 180, rel=1e-15)
    assert parse("deg").rotary and parse("deg").force == "N*m"
    u = parse("counts/rev=1048576")
    assert u.rotary and u.position_factor == pytest.approx(2 * math.pi / 2**20, rel=1e-15)
    assert parse("counts/m=2e6").position_factor == pytest.approx(5e-7, rel=1e-15) and not parse("counts/m=2e6").rotary
    v = parse("mm,V=2.5")
    assert v.position_factor == 1e-3 and v.force_factor == 2.5
    for bad, says in (("furlong", "not a position unit"), ("deg,N", "torque"), ("counts", "counts per")):
        with pytest.raises(didim.DataError, match=says):
            parse(bad)


@needs_axes
def test_declared_units_give_the_si_record_and_its_encoder_step():
    """The spindle's record in deg and in encoder counts, declared, is the rad record to rounding: positions, the
    encoder step (2π/2^20 rad, detected from positions that are no round decimal) and the controller's command."""
    base = didim.load_record(os.path.join(AXES, "null_spindle_pic_train.csv"), units="rad")
    assert base.position_resolution == pytest.approx(2 * math.pi / 2**20, rel=1e-9)
    for f, u in (("null_spindle_pic_deg_train.csv", "deg"), ("null_spindle_pic_counts_train.csv", "counts/rev=1048576")):
        rec = didim.load_record(os.path.join(AXES, f), units=u)
        assert rec.axis == "rotary"
        # the files print 12 significant digits: positions agree to that
        assert np.max(np.abs(rec.qm - base.qm)) <= 1e-9 * np.max(np.abs(base.qm))
        assert rec.position_resolution == pytest.approx(base.position_resolution, rel=1e-9)
        c, c0 = rec.controller.command(rec.qr, rec.qm), base.controller.command(base.qr, base.qm)
        assert np.max(np.abs(c - c0)) <= 1e-6 * np.max(np.abs(c0))


@needs_axes
def test_a_stroke_no_axis_has_is_refused_with_the_unit_to_declare(tmp_path):
    with pytest.raises(didim.DataError, match="another unit than m, mm on a linear axis"):
        didim.load_record(os.path.join(AXES, "null_belt_pid_mm_train.csv"))
    rec = didim.load_record(os.path.join(AXES, "null_belt_pid_mm_train.csv"), units="mm")
    assert rec.stroke == pytest.approx(0.6573, rel=1e-3)
    # the same from the header and from the controller file
    src = os.path.join(AXES, "null_belt_pid_mm_train.csv")
    lines = open(src).read().splitlines()
    csv = tmp_path / "belt.csv"
    csv.write_text("\n".join(["t,qr[mm],force[N],qm[mm]"] + lines[1:200]) + "\n")
    assert didim.load_record(csv, controller=src.replace(".csv", "_controller.json")).qm[0] == pytest.approx(
        rec.qm[0], rel=1e-12)
    spec = json.load(open(src.replace(".csv", "_controller.json")))
    spec["units"] = "mm"
    (tmp_path / "b_controller.json").write_text(json.dumps(spec))
    csv2 = tmp_path / "b.csv"
    csv2.write_text("\n".join(lines[:200]) + "\n")
    assert didim.load_record(csv2).qm[0] == pytest.approx(rec.qm[0], rel=1e-12)


@needs_axes
def test_a_rotary_result_prints_rotary_units(wrist):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r = didim.identify(wrist, "rigid", "didim")
    assert r.units == {"M": "kg·m²", "Fv": "N·m·s/rad", "Fc": "N·m"}
    assert "M (kg·m²)" in r.summary()
    assert didim.IdentificationResult.from_dict(r.to_dict()).units == r.units  # a saved result keeps them


@needs_axes
@pytest.mark.parametrize("s", SCALES)
def test_rigid_didim_gives_the_same_parameters_in_any_unit(wrist, s):
    """Scaling the positions by s (controller scaled back, units not declared) scales M and Fv by 1/s and leaves Fc:
    the same identified parameters after conversion, to 1e-6 (the records agree to rounding), in the same number of
    iterations and simulations, with the Coulomb smoothing speed scaled by s (it is a fraction of the speed scale)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        r0 = didim.identify(wrist, "rigid", "didim")
        r = didim.identify(_scaled(wrist, s), "rigid", "didim")
    assert r.iterations == r0.iterations and r.simulations == r0.simulations
    assert r.params["M"] * s == pytest.approx(r0.params["M"], rel=1e-6)
    assert r.params["Fv"] * s == pytest.approx(r0.params["Fv"], rel=1e-6)
    assert r.params["Fc"] == pytest.approx(r0.params["Fc"], rel=1e-6)
    assert r.structure.coulomb_eps / s == pytest.approx(r0.structure.coulomb_eps, rel=1e-12)
    # the full-rate force error runs through the encoder quantizer, where a rounding difference of the scaled positions
    # can flip one count somewhere: a count flip moves the error by far less than 1e-3 of itself on 8000 samples
    assert r.force_error == pytest.approx(r0.force_error, rel=1e-3)


@needs_axes
@pytest.mark.parametrize("s", (1e-3, 180 / math.pi, 2**17 / (2 * math.pi)))
def test_the_doctor_gives_the_same_findings_and_law_in_any_unit(wrist, s):
    """Same fitted friction law (its shape, and its smoothing speed scaled), same findings, same errors."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", didim.DidimWarning)
        d0 = didim.doctor(wrist, "rigid")
        d = didim.doctor(_scaled(wrist, s), "rigid")
    assert [f.effect for f in d.findings] == [f.effect for f in d0.findings]
    law, law0 = d.final_result.structure, d0.final_result.structure
    assert law.coulomb_law == law0.coulomb_law
    # the smoothing speed is searched on grids of factors on the record's speed scale (the same in any unit), then
    # moved to a parabola's vertex between the fine grid's points (QUARTER apart in log ε), on simulations through the
    # encoder quantizer, where the scaled positions' rounding flips a count here and there: the vertex may move by a
    # fraction of the grid's step, and the final error by as much as that law's difference (a few 1e-3 of itself)
    assert math.log(law.coulomb_eps / s / law0.coulomb_eps) == pytest.approx(0.0, abs=QUARTER / 2)
    assert d.fit["valid_force_after"] == pytest.approx(d0.fit["valid_force_after"], rel=5e-3)


def test_a_findings_details_carry_the_axis_units():
    """The doctor's details lines (each finding's params) in the record's units: N·m and rad/s on a rotary axis."""
    from didim.doctor.effects import params_text

    s, f = {"Fs": -5e-4, "vs": 0.15}, {"f_n_flex": 30.0, "M1": 2e-3, "K12": 40.0}
    assert params_text("stribeck", s, "rotary") == "Fs = -0.0005 N·m, vs = 0.15 rad/s"
    assert params_text("flexibility", f, "rotary") == "f_n_flex = 30 Hz, M1 = 0.002 kg·m², K12 = 40 N·m/rad"
    assert params_text("stribeck", s, "linear") == "Fs = -0.0005 N, vs = 0.15 m/s"
    assert params_text("flexibility", f, "linear") == "f_n_flex = 30 Hz, M1 = 0.002 kg, K12 = 40 N/m"
    # each effect carries the units of what it reports: every quantity its findings name has one, or none on purpose
    from didim.doctor.effects import REGISTRY

    assert REGISTRY["gravity"].units["angle_offset"] == "m"  # rad on a rotary axis
    assert params_text("unnamed", {"x": 1.0}, "linear") == "x = 1"
