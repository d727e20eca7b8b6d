"""The doctor's entry for robots (``didim doctor REC --urdf U``, ``didim.doctor(rec, robot, validate=...)``): the base
model fitted by DIDIM on the training record (each joint's controller checked against its log first), simulated in
closed loop on the training and the validation record, and per joint where simulation and record differ: how large
the difference is on each record, and where it lives (slow or moving, each direction; speed bands; stretches of the
joint's stroke; the stretch of time that holds most of it). Which physics a joint misses (its effects, adopted and
shown on held-out data) is the robot doctor's next step: the ``findings`` list stays empty here, and the summary says
so rather than guess."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional

import numpy as np

from .._errors import DataError
from ..recording import Recording

#: Bands of each joint's speed (shares of its top reference speed) and of its stroke the residual is reported in.
SPEED_EDGES = (0.0, 0.05, 0.25, 0.5, 1.0)
STROKE_BINS = 5
#: The stretch of time whose residual energy is reported (a share of the record).
TIME_WINDOW = 0.1


@dataclass
class JointMismatch:
    """Where one joint's simulated force differs from its record: ``error`` (‖τ − τ_sim‖/‖τ‖) on the training record
    and on the validation record, the residual's energy shares (``shares``: slow, forward, backward), its RMS per speed
    band and per stretch of the stroke (relative to the joint's force RMS), and the stretch of time holding most of
    it."""

    joint: str
    error_train: float
    error_valid: float
    shares: Dict[str, float]
    speed_bands: List[Dict[str, float]]
    stroke_bins: List[Dict[str, float]]
    worst_time: Dict[str, float]
    unit: str

    def sentence(self) -> str:
        s = self.shares
        band = max(self.speed_bands, key=lambda b: b["rms"]) if self.speed_bands else None
        where = max(self.stroke_bins, key=lambda b: b["rms"]) if self.stroke_bins else None
        out = (f"{self.joint}: force error {100 * self.error_train:.2f} % on the training record"
               + (f", {100 * self.error_valid:.2f} % on the validation record" if math.isfinite(self.error_valid) else "")
               + f"; the residual lives {100 * s['slow']:.0f} % below 5 % of the top speed, {100 * s['forward']:.0f} % "
               f"moving forward, {100 * s['backward']:.0f} % backward")
        if band is not None:
            out += (f"; largest between {band['from']:.3g} and {band['to']:.3g} {self.unit}/s "
                    f"({100 * band['rms']:.2g} % of the joint's force RMS)")
        if where is not None:
            out += f", and between {where['from']:.4g} and {where['to']:.4g} {self.unit} of its stroke"
        w = self.worst_time
        out += f"; {100 * w['share']:.0f} % of it in {w['from']:.2f}–{w['to']:.2f} s"
        return out


@dataclass
class RobotDiagnosis:
    """The robot doctor's report: the base result, each joint's mismatch (worst first on the held-out record), the
    controller checks, and the findings (none named yet for robots: see the module's text)."""

    base: Any
    joints: List[JointMismatch]
    record: str
    validate: str
    elapsed_s: float
    findings: List[Dict[str, Any]] = field(default_factory=list)
    ambiguities: List[Dict[str, Any]] = field(default_factory=list)
    notes: List[str] = field(default_factory=list)

    def summary(self) -> str:
        b = self.base
        lines = [f"doctor on {self.record} ({b.robot.ndof}-joint robot {b.robot.name}), held out: {self.validate}",
                 f"base model: {b.method}, closed-loop force error {100 * b.force_error:.2f} % on the training record "
                 f"({'converged' if b.converged else 'NOT converged'}, {b.iterations} iterations); friction law "
                 f"{b.law[0] if b.law else 'default'}",
                 "where simulation and record differ, per joint (worst on the held-out record first):"]
        lines += [f"  {m.sentence()}" for m in self.joints]
        lines.append("findings: none named: the robot doctor locates the mismatch per joint; naming and adopting "
                     "each joint's missing physics (friction law's shape, Stribeck, elasticity, a spring, delay) is "
                     "not in this version")
        lines += [f"note: {n}" for n in self.notes]
        lines.append(f"({self.elapsed_s:.1f} s)")
        return "\n".join(lines)

    @property
    def final_result(self):
        """The model the doctor ends with (the base model: no effect is adopted on robots yet)."""
        return self.base

    def to_dict(self) -> Dict[str, Any]:
        from ..formats._io import jsonable

        return jsonable({"kind": "robot", "record": self.record, "validate": self.validate,
                         "findings": self.findings, "ambiguities": self.ambiguities,
                         "joints": [dict(m.__dict__) for m in self.joints], "base": self.base.to_dict(),
                         "notes": self.notes, "elapsed_s": self.elapsed_s})

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    def to_html(self) -> str:
        import html

        rows = "".join(f"<li>{html.escape(m.sentence())}</li>" for m in self.joints)
        return (f"<!doctype html><meta charset='utf-8'><title>didim doctor: {html.escape(self.record)}</title>"
                f"<h1>didim doctor: {html.escape(self.record)}</h1><pre>{html.escape(self.summary())}</pre>"
                f"<h2>Per joint</h2><ul>{rows}</ul>")


def _mismatch(joint: str, unit: str, rec, sim, err_train: float, err_valid: float, vmax: float) -> JointMismatch:
    """One joint's residual on ``rec`` (the record it is judged on) against ``sim``'s force."""
    j = list(rec.joint_names).index(joint)
    f, fs = rec.force[:, j], sim["force"][:, j]
    r = f - fs
    e2 = r ** 2
    tot = float(np.sum(e2)) or 1.0
    v = np.gradient(rec.qr[:, j], rec.dt)
    slow = np.abs(v) <= 0.05 * vmax
    shares = {"slow": float(np.sum(e2[slow]) / tot), "forward": float(np.sum(e2[~slow & (v > 0)]) / tot),
              "backward": float(np.sum(e2[~slow & (v < 0)]) / tot)}
    scale = float(np.sqrt(np.mean(f ** 2))) or 1.0
    bands = []
    for lo, hi in zip(SPEED_EDGES[:-1], SPEED_EDGES[1:]):
        m = (np.abs(v) >= lo * vmax) & (np.abs(v) <= hi * vmax)
        if np.any(m):
            bands.append({"from": lo * vmax, "to": hi * vmax, "rms": float(np.sqrt(np.mean(e2[m]))) / scale,
                          "samples": int(np.count_nonzero(m))})
    q = rec.qm[:, j]
    edges = np.linspace(float(np.min(q)), float(np.max(q)), STROKE_BINS + 1)
    strokes = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (q >= lo) & (q <= hi)
        if np.any(m):
            strokes.append({"from": float(lo), "to": float(hi), "rms": float(np.sqrt(np.mean(e2[m]))) / scale,
                            "samples": int(np.count_nonzero(m))})
    w = max(1, int(round(TIME_WINDOW * rec.n)))
    c = np.concatenate([[0.0], np.cumsum(e2)])
    k = int(np.argmax(c[w:] - c[:-w]))
    worst = {"from": k * rec.dt, "to": (k + w) * rec.dt, "share": float((c[k + w] - c[k]) / tot)}
    return JointMismatch(joint, err_train, err_valid, shares, bands, strokes, worst, unit)


def doctor_robot(recording, robot, validate=None, *, progress: Optional[Callable[[str], None]] = None,
                 controller_check: str = "error", offset: Optional[bool] = None) -> RobotDiagnosis:
    """:func:`didim.doctor` of a robot's record with its :class:`didim.Robot` (see the module's text)."""
    from ..api import identify
    from ..check import enforce
    from ..methods.robot import force_errors, simulate_robot, top_speeds

    if validate is not None and not (isinstance(validate, Recording) and validate.has_joint_columns):
        raise DataError(f"validate must be a robot's record like the training one, got {type(validate).__name__}")
    if validate is not None and list(validate.joint_names) != list(recording.joint_names):
        raise DataError("the validation record's joints are not the training record's")
    if validate is recording or (validate is not None and validate.name == recording.name
                                 and np.array_equal(validate.force, recording.force)):
        raise DataError("the validation record is the training record: give another run of the robot")
    t0 = time.perf_counter()
    if validate is not None:
        enforce(validate, controller_check)
    base = identify(recording, robot, "didim", offset=offset, progress=progress, controller_check=controller_check)
    sim_t = simulate_robot(recording, base)
    _, per_t = force_errors(recording, sim_t["force"])
    if validate is not None:
        sim_v = simulate_robot(validate, base)
        _, per_v = force_errors(validate, sim_v["force"])
        judged, sim_j = validate, sim_v
    else:
        per_v = {j: math.nan for j in recording.joint_names}
        judged, sim_j = recording, sim_t
    vmax = top_speeds(judged)
    joints = [_mismatch(jn, "m" if kind == "prismatic" else "rad", judged, sim_j, per_t[jn], per_v[jn], float(vmax[i]))
              for i, (jn, kind) in enumerate(zip(robot.joint_names, robot.joint_kinds))]
    joints.sort(key=lambda m: -(m.error_valid if math.isfinite(m.error_valid) else m.error_train))
    notes = [] if validate is not None else ["no validation record: the mismatch is located on the training record, "
                                             "which the fit has seen; give --validate for a held-out judgement"]
    return RobotDiagnosis(base=base, joints=joints, record=recording.name,
                          validate=validate.name if validate is not None else "(none)",
                          elapsed_s=time.perf_counter() - t0, notes=notes)


__all__ = ["RobotDiagnosis", "JointMismatch", "doctor_robot"]
