"""Recordings of a position-controlled plant, one axis or a robot's joints: the one data type, validated on
construction (the file formats are in :mod:`didim.formats.loaders`)."""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import warnings
from dataclasses import dataclass
from typing import List, Optional, Tuple, Union

import numpy as np

from . import _checks
from ._errors import DataError
from .controllers import PD, Controller, EmpsCascade, TransferFunction
from .units import SI, Units, parse as parse_units

#: Relative tolerance on the sample-time jitter accepted by :func:`load_mat` (the EMPS logs ±2.5e-8 s on 1e-3 s).
TIME_JITTER_RTOL = 1e-3


def _number(name: str, x, unit: str) -> float:
    """A real number from a Python or numpy scalar, or a DataError naming it."""
    if isinstance(x, (bool, np.bool_)) or isinstance(x, (complex, np.complexfloating)):
        raise DataError(f"{name} must be a real number ({unit}), got {x!r}")
    try:
        return float(x)
    except (TypeError, ValueError):
        raise DataError(f"{name} must be a real number ({unit}), got {x!r}") from None


def _signal(name: str, x, n: Optional[int] = None) -> np.ndarray:
    if x is None:
        raise DataError(f"{name} is missing (None): give one value per sample")
    if np.iscomplexobj(x):
        raise DataError(f"{name} has complex values: a signal must be real (take the real part or the magnitude first)")
    if isinstance(x, np.ndarray) and x.dtype.kind not in "biuf":
        raise DataError(f"{name} must be an array of real numbers, got an array of {x.dtype} (text or objects): "
                        "convert the column to numbers first")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # e.g. numpy's ComplexWarning for complex objects in an object array
            a = np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError, Warning) as e:
        raise DataError(f"{name} must be an array of real numbers: {e}") from None
    a = np.squeeze(a) if a.ndim > 1 and sum(s > 1 for s in a.shape) <= 1 else a
    if a.ndim != 1:
        raise DataError(f"{name} must be a 1-D signal (one value per sample), got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise DataError(f"{name} has {a.shape[0]} samples but the reference has {n}: all signals must have the same length")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise DataError(f"{name} has {bad.size} non-finite value(s), the first at sample {bad[0]}: clean or cut the record")
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _joint_signals(name: str, x, joints: Tuple[str, ...], n: Optional[int] = None,
                   absent: bool = False) -> np.ndarray:
    """A robot's signal: (samples, joints) real numbers, finite, or a DataError naming the joint and the sample.
    ``absent``: a joint's column may be all NaN (a signal some joints do not have: link-side encoders on the first
    axes only)."""
    ndof = len(joints)
    if isinstance(x, np.ndarray) and x.dtype.kind not in "biufc":
        raise DataError(f"{name} must be an array of real numbers, got an array of {x.dtype} (text or objects)")
    a = _checks.real_array(name, x, ndims=None)
    if a.ndim != 2 or a.shape[1] != ndof:
        raise DataError(f"{name} must be (samples, {ndof}) for joints {', '.join(joints)}, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise DataError(f"{name} has {a.shape[0]} samples but the reference has {n}: all signals must have the same length")
    bad = np.argwhere(~np.isfinite(a) & ~(absent & np.all(np.isnan(a), axis=0)))
    if len(bad):
        k, j = bad[0]
        raise DataError(f"{name} of joint {joints[j]} is not finite at sample {k}: clean or cut the record")
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def applied_force(force: np.ndarray, delay: Tuple[int, ...], force_lag: Tuple[float, ...], dt: float) -> np.ndarray:
    """The force each joint's plant receives, as its mean over each sample period, when the drive logs the commands
    ``force`` (samples × joints): the command of ``delay`` samples earlier (the first one before the record: the
    drive held it), through a first-order lag of ``force_lag`` s started at it, as the closed loop applies them (the
    core's arithmetic). The least squares regress on it: the simulated states answer it, not the logged command."""
    from . import _core

    out = np.array(force, dtype=float)
    cols = out if out.ndim == 2 else out[:, None]
    for j in range(cols.shape[1]):
        d = delay[j] if j < len(delay) else 0
        lag = force_lag[j] if j < len(force_lag) else 0.0
        if d or lag > 0:
            cols[:, j] = _core.applied_force(np.ascontiguousarray(cols[:, j]), int(d), float(lag), dt,
                                             held=float(cols[0, j]))
    return out


#: Sample periods didim accepts (s): a drive logs between 10 MHz and 0.1 Hz; outside, the time unit is wrong.
DT_RANGE = (1e-7, 10.0)

#: Samples at the head of the reference that a parabola is fitted to, to tell whether the log began in motion.
LEAD_FIT_SAMPLES = 8
#: The parabola must fit those samples within this share of the distance they cover (a smooth move, not a step or
#: noise), or no lead-in is reconstructed.
LEAD_FIT_RTOL = 0.02
#: A lead-in is reconstructed when the fitted acceleration at the head has the velocity's sign and at least this share
#: of the reference's typical acceleration (a log cut in the acceleration from rest).
LEAD_ACCEL_SHARE = 0.1
#: Percentile of the reference's acceleration magnitude taken as its typical acceleration (m/s²), over windows of
#: :data:`LEAD_ACCEL_WINDOW_S`.
LEAD_ACCEL_PERCENTILE = 99.0
LEAD_ACCEL_WINDOW_S = 0.01
#: The axis must lag the moving reference at the first sample by more than this many encoder steps for a lead-in.
LEAD_LAG_STEPS = 2.0
#: The longest lead-in reconstructed (s); a longer one, or one longer than the record, is not guessed.
LEAD_MAX_S = 2.0


#: A given lead-in must join the record's first reference sample within this many of the largest steps of the
#: reference at the join (the lead-in's last and the record's first).
LEAD_JOIN_STEPS = 3.0


def _check_join(lead: np.ndarray, qr: np.ndarray, where: str = "", unit: str = "m") -> None:
    """A given lead-in ends where the record's reference begins (the samples just before it, in the same unit);
    ``where`` names the joint ("joint j2's ")."""
    steps = [abs(qr[1] - qr[0])] + ([abs(lead[-1] - lead[-2])] if lead.size > 1 else [])
    scale = max(float(np.max(np.abs(qr))), float(np.ptp(qr)), 1e-12)
    tol = LEAD_JOIN_STEPS * max(steps) + 1e-9 * scale
    if not abs(lead[-1] - qr[0]) <= tol:
        raise DataError(f"{where}lead_in ends at {lead[-1]:.6g} {unit} but the reference's first sample is "
                        f"{qr[0]:.6g} {unit}: give the reference's samples just before the first one (oldest first, "
                        f"in {unit}, at the record's dt), so that the simulation runs through them into the record")


def reconstruct_lead_in(qr: np.ndarray, dt: float, qm: Optional[np.ndarray] = None,
                        resolution: Optional[float] = None) -> np.ndarray:
    """The reference before the first sample of a log that begins in motion, back to the rest it left (m, oldest
    first; empty when the reference begins at rest or its head is not a smooth move, or when the measured position
    ``qm`` shows the axis did not come from there).

    A parabola fitted to the first :data:`LEAD_FIT_SAMPLES` samples gives the reference's velocity ``v0`` and
    acceleration ``a0`` there. When the reference was accelerating (``a0`` of the sign of ``v0`` and at least
    :data:`LEAD_ACCEL_SHARE` of its typical acceleration), it is extrapolated back with ``a0`` to zero velocity,
    ``v0/a0`` earlier. A log cut in a cruise or a deceleration gets none: how long the axis cruised, which sets its
    state at the first sample, is not in the log (the fits then leave out the samples the simulation takes to join
    it, see :func:`didim.simulation.settling_samples`). With the measured position ``qm``, the lead-in is
    kept only when the axis lags the moving reference at the first sample by more than :data:`LEAD_LAG_STEPS`
    encoder steps (``resolution``; without one, a millionth of the reference's stroke): the loop was running before
    the log. An axis that sits on the reference at the first sample (a simulation started there, at rest) gets none.
    On the EMPS records (13.5 mm/s and 0.84 m/s² at the first sample, the axis 0.1 mm behind) this gives 16 samples
    back to rest at 0.000 mm, 7.7 µm from the first measured position: the logs begin 16 ms after the move did.
    """
    with np.errstate(all="ignore"):  # absurd magnitudes give no lead-in, not warnings
        lead = _lead_in(np.asarray(qr, dtype=float), float(dt), qm, resolution)
    return lead if np.all(np.isfinite(lead)) else np.zeros(0)


def _lead_in(qr: np.ndarray, dt: float, qm: Optional[np.ndarray], resolution: Optional[float]) -> np.ndarray:
    n = qr.shape[0]
    m = min(LEAD_FIT_SAMPLES, n)
    empty = np.zeros(0)
    if m < 4:
        return empty
    head = qr[:m] - qr[0]
    span = float(np.max(np.abs(head)))
    scale = max(1.0, float(np.max(np.abs(qr))))
    if span <= 1e-12 * scale:
        return empty  # at rest
    k = np.arange(m, dtype=float)
    basis = np.stack([k * k, k, np.ones(m)], axis=1)
    c = np.linalg.lstsq(basis, head, rcond=None)[0]
    if float(np.sqrt(np.mean((head - basis @ c) ** 2))) > LEAD_FIT_RTOL * span:
        return empty  # a step or noise at the head: nothing smooth to extrapolate
    v0, a0 = c[1] / dt, 2.0 * c[0] / dt**2
    if v0 == 0.0:
        return empty
    s = max(1, int(round(LEAD_ACCEL_WINDOW_S / dt)))
    acc = (qr[2 * s:] - 2.0 * qr[s:-s] + qr[:-2 * s]) / (s * dt) ** 2 if n > 2 * s else np.zeros(0)
    a_typ = float(np.percentile(np.abs(acc), LEAD_ACCEL_PERCENTILE)) if acc.size else 0.0
    if not (v0 * a0 > 0 and abs(a0) >= LEAD_ACCEL_SHARE * a_typ):
        return empty  # a log cut in a cruise or a deceleration: its history is not in its head
    back = v0 / a0  # s back to rest
    lead = math.ceil(back / dt - 1e-9)
    if lead < 1 or lead * dt > LEAD_MAX_S or lead > n:
        return empty
    tt = np.maximum(np.arange(-lead, 0) * dt, -back)
    q = qr[0] + v0 * tt + 0.5 * a0 * tt**2
    if qm is not None:
        step = resolution if resolution else 1e-6 * max(float(np.ptp(qr)), 1e-12)
        if not math.copysign(1.0, v0) * (qr[0] - qm[0]) > LEAD_LAG_STEPS * step:
            return empty  # the axis does not lag the reference: the loop starts with the log
    return q


@dataclass(frozen=True)
class Recording:
    """A record of a position-controlled plant of one or several joints, validated on construction; SI units on the
    load side (m and N, or rad and N·m).

    One axis holds 1-D signals (one value per sample); a robot holds (samples, joints) arrays in ``joint_names``'
    order, and then each per-joint field (``controller``, ``position_resolution``, ``units``, ``controller_origin``)
    holds one entry per joint. Every method that reads one joint's log takes :meth:`joint`.

    Attributes:
        dt: sample period (s).
        qr: position reference fed to the controller (m or rad).
        force: measured motor force (N or N·m), e.g. ``gtau·vir`` on the EMPS; a robot's controllers' commands.
        qm: measured motor position (m or rad).
        controller: the controller that ran the axis (:class:`TransferFunction`, :class:`EmpsCascade` or :class:`PD`;
            :func:`didim.load_controller` reads one from a file), or a robot's, one per joint
            (:func:`didim.load_joint_controllers`). Required.
        ql: measured load position (m or rad) when the plant has a second encoder, else None; a robot's link-side
            positions (samples, joints), all NaN in the columns of joints without a link-side encoder. They check a
            model's deflection (:func:`didim.simulate`'s ``deflection_error_per_joint``); no method fits on them.
        u_ext: known external force added to the command (N or N·m), e.g. the EMPS pulses or a robot's feedforward,
            else None.
        position_resolution: resolution of the motor encoder (m or rad), used to quantize the simulated measurement,
            or None; per joint for a robot (None or 0 where unknown).
        name: a label for reports.
        lead_in: the reference before the first sample, for a log that begins in motion: ``"auto"`` (default)
            reconstructs it back to rest when the reference begins moving (:func:`reconstruct_lead_in`), ``None``
            for none (the simulation starts at rest on the first reference sample, as in the paper), or the samples
            themselves (oldest first, at ``dt``, e.g. from a pre-trigger buffer; (L, joints) for a robot). The
            simulation runs through it from rest, with ``u_ext`` held at its first value; nothing is compared there.
            :attr:`qr_lead` is the one in use.
        units: the units the record was logged in (:class:`didim.units.Units`, per joint for a robot); the arrays
            hold SI, converted by the loaders. It says whether an axis is linear or rotary (:attr:`axis`), for every
            unit didim prints.
        controller_origin: where the controller comes from when nobody described it (the fit's summary,
            :func:`didim.fit_controller`; per joint for a robot), else empty.
        joint_names: a robot's joints, in the columns' order (``("axis",)`` for one axis).
        joint_kinds: ``"revolute"`` or ``"prismatic"`` per joint (rad and N·m, or m and N).
        delay, force_lag: each joint's actuation delay (samples) and force lag (s) between its command and the force
            on the joint, read from a robot's controller file; empty for none.
    """

    dt: float
    qr: np.ndarray
    force: np.ndarray
    qm: np.ndarray
    controller: Union[Controller, Tuple[Controller, ...], None] = None
    ql: Optional[np.ndarray] = None
    u_ext: Optional[np.ndarray] = None
    position_resolution: Union[float, Tuple[Optional[float], ...], None] = None
    name: str = ""
    lead_in: Union[str, None, np.ndarray] = "auto"
    units: Union[Units, Tuple[Units, ...]] = SI
    controller_origin: Union[str, Tuple[str, ...]] = ""
    joint_names: Tuple[str, ...] = ()
    joint_kinds: Tuple[str, ...] = ()
    delay: Tuple[int, ...] = ()
    force_lag: Tuple[float, ...] = ()

    def __post_init__(self) -> None:
        dt = _number("sample period dt", self.dt, "s")
        if not (math.isfinite(dt) and dt > 0):
            raise DataError(f"sample period dt must be a finite number of seconds > 0, got {self.dt}")
        object.__setattr__(self, "dt", dt)
        names = self.joint_names
        if isinstance(names, str) or not isinstance(names, (tuple, list)):
            raise DataError(f"joint_names must be a tuple of names, one per column, got {names!r}")
        raw = self.qr
        shape = np.shape(raw) if isinstance(raw, (np.ndarray, list, tuple)) else ()
        columns = len(shape) == 2 and (bool(names) and tuple(names) != ("axis",) or shape[1] > 1)
        if columns:
            ndof = shape[1]
            names = tuple(str(x) for x in names) or tuple(str(j + 1) for j in range(ndof))
            if len(names) != ndof:
                raise DataError(f"joint_names has {len(names)} names for the record's {ndof} joint columns")
            if len(set(names)) != ndof:
                twice = sorted({x for x in names if names.count(x) > 1})
                raise DataError(f"joint {twice[0]!r} appears twice in joint_names: each joint needs its own name")
        else:
            ndof, names = 1, tuple(str(x) for x in names) or ("axis",)
            if len(names) != 1:
                raise DataError(f"joint_names has {len(names)} names for a record of one axis (1-D signals)")
        object.__setattr__(self, "joint_names", names)

        def sig(label: str, x, n: Optional[int] = None, absent: bool = False) -> np.ndarray:
            return _joint_signals(label, x, names, n, absent) if columns else _signal(label, x, n)

        qr = sig("qr (position reference)", raw)
        n = qr.shape[0]
        if n < 3:
            raise DataError(f"the record has {n} samples; at least 3 are needed")
        if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
            raise DataError(
                f"sample period dt = {dt:g} s is outside {DT_RANGE[0]:g}-{DT_RANGE[1]:g} s (drives log between "
                f"{1 / DT_RANGE[1]:g} Hz and {1e-6 / DT_RANGE[0]:g} MHz): check the time column's unit (ns, us or ms "
                "read as seconds?) or the dt you gave")
        object.__setattr__(self, "qr", qr)
        object.__setattr__(self, "force", sig("force", self.force, n))
        object.__setattr__(self, "qm", sig("qm (motor position)", self.qm, n))
        if self.ql is not None:
            object.__setattr__(self, "ql", sig("ql (load position)", self.ql, n, absent=True))
        if self.u_ext is not None:
            object.__setattr__(self, "u_ext", sig("u_ext (external force)", self.u_ext, n))

        ctrls = self.controller if columns else (self.controller,)
        if self.controller is None:
            raise DataError("the recording has no controller: didim simulates the closed loop, so it needs the law that "
                            "ran the axis; give controller=didim.EmpsCascade() for the EMPS, didim.PD(kp, kd), "
                            "didim.TransferFunction(...) or .cascade(...), or didim.load_controller('controller.json') "
                            "(on the command line: --controller FILE)" + (
                                "; a robot takes one per joint: didim.load_joint_controllers('joints.json')"
                                if columns else ""))
        if columns and not isinstance(ctrls, (tuple, list)):
            raise DataError(f"a robot's record takes one controller per joint ({ndof}: {', '.join(names)}), as a "
                            f"tuple, got one {type(ctrls).__name__}; read them with "
                            "didim.load_joint_controllers('joints.json')")
        if len(ctrls) != ndof:
            raise DataError(f"{len(ctrls)} controllers for {ndof} joints ({', '.join(names)}): give one per joint")
        for j, c in enumerate(ctrls):
            if not isinstance(c, (EmpsCascade, PD, TransferFunction)):
                raise DataError(("controller" if not columns else f"joint {names[j]}'s controller")
                                + " must be a didim.TransferFunction, EmpsCascade or PD, got " + type(c).__name__
                                + ("; read a controller file with didim.load_controller(path)"
                                   if isinstance(c, (str, bytes, os.PathLike)) else ""))
            c.transfer_function(dt)  # a transfer function designed for another sample period is refused
        if columns:
            object.__setattr__(self, "controller", tuple(ctrls))

        res = self.position_resolution
        if columns:
            res = (None,) * ndof if res is None else res
            if not isinstance(res, (tuple, list, np.ndarray)) or len(res) != ndof:
                raise DataError(f"position_resolution needs one encoder step per joint ({ndof}; None or 0 where "
                                f"unknown), got {res!r}")
            steps = []
            for j, r in enumerate(res):
                r = 0.0 if r is None else _number(f"joint {names[j]}'s position_resolution", r, "m or rad")
                if not (math.isfinite(r) and r >= 0):
                    raise DataError(f"joint {names[j]}'s position_resolution must be a finite step >= 0 (0 for "
                                    f"unknown), got {r}")
                steps.append(r)
            object.__setattr__(self, "position_resolution", tuple(steps))
        elif res is not None:
            r = _number("position_resolution", res, "m")
            if not (math.isfinite(r) and r > 0):
                raise DataError(f"position_resolution must be a finite length > 0 m (or None), got {r}")
            object.__setattr__(self, "position_resolution", r)
        if not isinstance(self.name, str):
            raise DataError(f"name must be a string, got {type(self.name).__name__}")

        kinds = tuple(self.joint_kinds)
        if columns:
            kinds = kinds or ("revolute",) * ndof
            if len(kinds) != ndof or any(k not in ("revolute", "prismatic") for k in kinds):
                raise DataError(f"joint_kinds needs 'revolute' or 'prismatic' for each of the {ndof} joints, got "
                                f"{kinds!r}")
            units = self.units
            if isinstance(units, (tuple, list)) and units:
                if len(units) != ndof:
                    raise DataError(f"units needs one entry per joint ({ndof}), got {len(units)}")
                units = tuple(u if isinstance(u, Units) else (parse_units(u) or SI) for u in units)
            else:
                units = tuple(Units("m", "N") if k == "prismatic" else Units("rad", "N*m") for k in kinds)
            object.__setattr__(self, "units", units)
            origin = self.controller_origin
            origin = tuple(origin) if isinstance(origin, (tuple, list)) else ((origin,) if origin else ())
            object.__setattr__(self, "controller_origin", origin)
        else:
            if not isinstance(self.units, Units):
                object.__setattr__(self, "units", parse_units(self.units) or SI)
            kinds = kinds or ("prismatic" if self.units.axis == "linear" else "revolute",)
            if len(kinds) != 1:
                raise DataError(f"joint_kinds has {len(kinds)} entries for a record of one axis")
        object.__setattr__(self, "joint_kinds", kinds)

        for key in ("delay", "force_lag"):
            got = tuple(getattr(self, key))
            if got and len(got) != ndof:
                raise DataError(f"{key} needs one value per joint ({ndof}), got {len(got)}")
            object.__setattr__(self, key, got)
        if any(d < 0 or d >= n or int(d) != d for d in self.delay):
            raise DataError(f"each joint's delay must be a whole number of samples, >= 0 and shorter than the record "
                            f"({n} samples), got {self.delay}")
        if any(not (math.isfinite(x) and x >= 0) for x in self.force_lag):
            raise DataError(f"each joint's force lag must be finite and >= 0 s, got {self.force_lag}")

        lead = self.lead_in
        if isinstance(lead, str):
            if lead not in ("auto", "none"):
                raise DataError(f"lead_in must be 'auto', None (or 'none') or the reference's samples before the "
                                f"first one, got {lead!r}")
        elif lead is not None:
            lead = sig("lead_in (the reference before the first sample)", lead)
            if lead.shape[0] >= n:
                raise DataError(f"lead_in has {lead.shape[0]} samples, not fewer than the record's {n}: give only "
                                "the stretch before the log, from rest")
            if lead.shape[0]:
                for j in range(ndof):
                    _check_join(lead[:, j] if columns else lead, qr[:, j] if columns else qr,
                                f"joint {names[j]}'s " if columns else "",
                                "rad" if self.joint_units[j].rotary else "m")
            object.__setattr__(self, "lead_in", lead)

    @classmethod
    def from_time(cls, t, qr, force, qm, *, dt: Optional[float] = None, **kw) -> "Recording":
        """A recording from its time stamps ``t`` (s): checks that time increases with a constant step (within
        :data:`TIME_JITTER_RTOL`) and, when ``dt`` is given, that the step is ``dt``. Other keywords as the
        constructor (controller, ql, u_ext, position_resolution, name)."""
        t = _signal("time t", t)
        step = _time_step(t, "")
        if dt is not None:
            _check_expected_dt(step, dt, "")
        return cls(dt=step, qr=qr, force=force, qm=qm, **kw)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.qr.shape[0])

    @property
    def ndof(self) -> int:
        """Number of joints (1 for one axis)."""
        return len(self.joint_names)

    @property
    def has_joint_columns(self) -> bool:
        """True for a robot's record ((samples, joints) arrays), False for one axis's 1-D signals."""
        return self.qr.ndim == 2

    @property
    def controllers(self) -> Tuple[Controller, ...]:
        """The controller of each joint."""
        return self.controller if self.has_joint_columns else (self.controller,)  # type: ignore[return-value]

    @property
    def encoder_step(self) -> Tuple[float, ...]:
        """Each joint's encoder step (m or rad; 0 where unknown)."""
        r = self.position_resolution
        return tuple(r) if self.has_joint_columns else (float(r or 0.0),)  # type: ignore[arg-type]

    @property
    def joint_units(self) -> Tuple[Units, ...]:
        """The units each joint was logged in."""
        return self.units if self.has_joint_columns else (self.units,)  # type: ignore[return-value]

    def column(self, x: Optional[np.ndarray], j: int) -> Optional[np.ndarray]:
        """Joint ``j``'s samples of a signal of this record (``x`` itself for one axis; None stays None)."""
        if x is None or not self.has_joint_columns:
            return x
        return x[:, j]

    def joint(self, j, controller: Optional[Controller] = None) -> "Recording":
        """Joint ``j`` (an index or a name) as a one-axis record: its reference, force and measured position with its
        controller (or ``controller``) and encoder step, in its units, from rest on its first sample as the robot's
        loop starts. Every one-axis method that reads one joint's log (the controller check, the controller fitted
        from the log) takes it. One axis's own record for one axis (with ``controller`` when given)."""
        if isinstance(j, str):
            if j not in self.joint_names:
                raise DataError(f"no joint {j!r} in the record: its joints are {', '.join(self.joint_names)}")
            j = self.joint_names.index(j)
        if not self.has_joint_columns:
            return self if controller is None else dataclasses.replace(self, controller=controller)
        rotary = self.joint_kinds[j] != "prismatic"
        return Recording(dt=self.dt, qr=self.qr[:, j], force=self.force[:, j], qm=self.qm[:, j],
                         ql=None if self.ql is None or np.all(np.isnan(self.ql[:, j])) else self.column(self.ql, j), u_ext=self.column(self.u_ext, j),
                         controller=controller if controller is not None else self.controllers[j],
                         position_resolution=self.encoder_step[j] or None,
                         name=f"{self.name or 'record'}, joint {self.joint_names[j]}", lead_in=None,
                         units=Units("rad", "N*m") if rotary else Units("m", "N"), joint_names=(self.joint_names[j],))

    @functools.cached_property
    def t(self) -> np.ndarray:
        """Time of each sample (s), from 0 (read-only; computed once, as the recording cannot change)."""
        t = np.arange(self.n) * self.dt
        t.setflags(write=False)
        return t

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("t", None)  # the cached time vector: rebuilt on demand, not shipped to worker processes
        state.pop("qr_lead", None)
        return state

    @functools.cached_property
    def qr_lead(self) -> np.ndarray:
        """The reference before the first sample that the simulation runs through from rest (oldest first, (L,) or
        (L, joints); L = 0 for none; read-only, computed once): the given one, or with ``lead_in="auto"`` each
        joint's reconstructed back to the rest it left (:func:`reconstruct_lead_in`) when every joint whose
        reference moves at the first samples has one, the longest setting L and the shorter ones held at rest before
        theirs. A joint that moves without one (a log cut in its cruise or its deceleration: how long it cruised is
        not in the log) leaves the record without a lead-in: holding it still through the others' lead-in and then
        moving it would start it further from its state than the record's first sample does."""
        cols = self.has_joint_columns
        if isinstance(self.lead_in, np.ndarray):
            lead = self.lead_in
        elif self.lead_in != "auto":
            lead = np.zeros((0, self.ndof) if cols else 0)
        else:
            qr, qm = (self.qr, self.qm) if cols else (self.qr[:, None], self.qm[:, None])
            steps = self.encoder_step
            leads = [reconstruct_lead_in(qr[:, j], self.dt, qm[:, j], steps[j] or None) for j in range(self.ndof)]
            head = qr[:min(LEAD_FIT_SAMPLES, self.n)]
            moving = np.ptp(head, axis=0) > np.asarray(steps, dtype=float)
            if any(m and not len(x) for m, x in zip(moving, leads)):
                size = 0
            else:
                size = max(len(x) for x in leads)
            lead = np.empty((size, self.ndof))
            for j, x in enumerate(leads):
                if size:
                    lead[:, j] = np.concatenate([np.full(size - len(x), x[0] if len(x) else qr[0, j]), x])
            lead = lead if cols else lead[:, 0]
        lead = np.ascontiguousarray(lead, dtype=float)
        lead.setflags(write=False)
        return lead

    def lead_in_signals(self) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """The reference and the known external input the simulation runs on: :attr:`qr_lead` then ``qr``, and
        ``u_ext`` held at its first value through the lead-in (a bias stays on; pulses that begin with the log begin
        at zero). The record's own arrays when it has no lead-in."""
        lead = self.qr_lead
        if not len(lead):
            return self.qr, self.u_ext
        u = None if self.u_ext is None else np.concatenate([np.repeat(self.u_ext[:1], len(lead), axis=0), self.u_ext])
        return np.ascontiguousarray(np.concatenate([lead, self.qr])), u

    def lead_in_note(self) -> str:
        """One sentence on the record's lead-in for a result's notes or a command's output ("" without one)."""
        if not len(self.qr_lead):
            return ""
        return (f"the record begins in motion: simulated from rest {1e3 * len(self.qr_lead) * self.dt:.0f} ms before "
                "its first sample, through its reference's lead-in (to start at the first sample, as the paper: "
                "lead_in=None, on the command line --lead-in none)")

    def applied_force(self) -> np.ndarray:
        """The force the joints receive (:func:`applied_force`): the logged one without delay nor lag."""
        if not any(self.delay) and not any(self.force_lag):
            return self.force
        return applied_force(self.force, self.delay, self.force_lag, self.dt)

    def core_controllers(self) -> List[Tuple[str, List[float]]]:
        """The controllers as the core takes them: (kind, gains) per joint."""
        return [(c.kind, list(c.gains)) for c in self.controllers]

    def _one_axis(self, what: str) -> None:
        if self.has_joint_columns:
            raise DataError(f"{what} reads one axis's log: take it on one joint, record.joint(name)")

    @property
    def fs(self) -> float:
        """Sampling frequency (Hz)."""
        return 1.0 / self.dt

    @property
    def axis(self) -> str:
        """``"linear"`` (positions in m, force in N) or ``"rotary"`` (rad, N·m)."""
        return self.units.axis

    @functools.cached_property
    def speed_scale(self) -> float:
        """The record's speed scale (m/s or rad/s): the largest speed of the reference between two samples (of the
        motor position when the reference does not move). Every speed didim derives (the Coulomb smoothing, the
        Stribeck speeds it tries) is a fraction of it, so that a record gives the same answer in any unit."""
        self._one_axis("the record's speed scale")
        for x in (self.qr, self.qm):
            v = float(np.max(np.abs(np.diff(x)))) / self.dt
            if math.isfinite(v) and v > 0:
                return v
        return 1.0 / self.dt  # a record that never moves: excitation checks refuse it before any fit

    @functools.cached_property
    def stroke(self) -> float:
        """The span of the reference (m or rad), or of the motor position when the reference does not move."""
        self._one_axis("the stroke")
        for x in (self.qr, self.qm):
            s = float(np.ptp(x))
            if math.isfinite(s) and s > 0:
                return s
        return 1.0

    @property
    def force_limit(self) -> float:
        """The controller's saturation of the command in N (``gtau·vsat`` or ``tau_max``), ``inf`` for none."""
        self._one_axis("the force limit")
        return self.controller.force_limit

    def implied_command(self) -> np.ndarray:
        """The force (N) the controller computes from the logged reference and motor position (and ``u_ext``), per
        sample, with the controller's saturation: the evidence :meth:`diagnose` compares the measured force with.
        The two samples before the start take the first position."""
        self._one_axis("the implied command")
        return self.controller.transfer_function(self.dt).command(self.qr, self.qm, self.u_ext)

    def u_ext_gain(self) -> Tuple[float, float]:
        """The gain with which the known external input ``u_ext`` enters the logged force, and its standard error: the
        least-squares slope of the force minus the controller's command from the logged reference and motor position
        (without ``u_ext``) on ``u_ext`` (with a constant, for a controller state the log began with), on the samples
        the command does not saturate. 1 when ``u_ext`` is what the drive applied; (nan, nan) without ``u_ext`` or
        when it is zero. On DATA_EMPS_PULSES, with ``gtau·pulses_N``: 1.0138 ± 4e-5 (the pulses enter ``vir`` 1.4 %
        larger than ``pulses_N``)."""
        self._one_axis("the gain of u_ext")
        nan = (math.nan, math.nan)
        if self.u_ext is None:
            return nan
        with np.errstate(all="ignore"):
            c0 = self.controller.transfer_function(self.dt).command(self.qr, self.qm, None)
            y, x = (self.force - c0)[2:], self.u_ext[2:]
            ok = np.isfinite(y) & np.isfinite(x)
            limit = self.force_limit
            if math.isfinite(limit) and limit > 0:
                ok &= np.abs(self.force[2:]) < (1 - SATURATION_RTOL) * limit
            x, y = x[ok], y[ok]
            if len(x) < 3:
                return nan
            xc, yc = x - x.mean(), y - y.mean()
            sxx = float(xc @ xc)
            if not sxx > 0 or not math.isfinite(sxx):
                return nan
            g = float(xc @ yc) / sxx
            e = yc - g * xc
            se = math.sqrt(float(e @ e) / max(len(x) - 2, 1) / sxx)
        return (g, se) if math.isfinite(g) else nan

    def diagnose(self) -> List[str]:
        """Things in the record that look wrong but need not be, each as a sentence with the evidence and what to
        check: a command that saturates for long stretches (the loop is open there), and a force whose scale does not
        match what the controller gains and the tracking error imply (volts instead of newtons, gtau applied twice,
        wrong gains). :func:`didim.identify` issues them as :class:`didim.DidimWarning`. A robot's: each joint's,
        naming it."""
        if self.has_joint_columns:
            return [f"joint {j}: {m}" for j in self.joint_names for m in self.joint(j).diagnose()]
        out: List[str] = []
        n = self.n
        force = self.force
        limit = self.force_limit
        with np.errstate(all="ignore"):
            if math.isfinite(limit) and limit > 0:
                mag = np.abs(force)
                sat = (mag >= (1 - SATURATION_RTOL) * limit) & (mag <= (1 + SATURATION_OVER_RTOL) * limit)
                total = int(np.count_nonzero(sat))
                longest, start = _longest_run(sat)
                if longest * self.dt >= SATURATION_WARN_S or total >= SATURATION_WARN_FRACTION * n:
                    out.append(
                        f"the command is at the controller's limit ±{limit:.4g} N on {total} samples "
                        f"({100 * total / n:.1f} % of the record), the longest stretch {longest} samples "
                        f"({longest * self.dt:.3g} s) from t = {start * self.dt:.4g} s: the loop is open while saturated, "
                        "so the closed-loop simulation and the identification rely on the saturation level being right; "
                        "check the limit (vsat, tau_max) or use a gentler reference"
                    )
                over = np.abs(force) > (1 + SATURATION_OVER_RTOL) * limit
                if np.any(over):
                    k = int(np.flatnonzero(over)[0])
                    out.append(
                        f"the force exceeds the controller's saturation ±{limit:.4g} N on {int(np.count_nonzero(over))} "
                        f"samples (first at sample {k}: {force[k]:.4g} N): check the saturation (vsat, tau_max), gtau, "
                        "and the force units"
                    )
            f, c = force[2:], self.implied_command()[2:]
            fr, cr = _rms(f), _rms(c)
            if fr > 0 and cr > 0 and math.isfinite(fr) and math.isfinite(cr):
                fs, cs = f / fr, c / cr
                corr = float(np.mean(fs * cs))
                ratio = corr * fr / cr  # least-squares scale of the force on the implied command
                if math.isfinite(ratio) and corr > SCALE_MIN_CORRELATION:
                    ctrl = self.controller
                    evidence = (
                        f"its RMS is {fr:.4g} against the {cr:.4g} N RMS that the controller ({_describe(ctrl)}) and the "
                        f"tracking error qr − qm imply (least-squares ratio {ratio:.4g}, correlation {corr:.3f})"
                    )
                    gtau = getattr(ctrl, "gtau", None)
                    if gtau is not None and abs(math.log(gtau)) > math.log(2) and abs(ratio * gtau - 1) < SCALE_RTOL:
                        out.append(
                            f"the force looks like volts, not newtons: {evidence}, about 1/gtau = {1 / gtau:.4g}; "
                            f"multiply the drive command by gtau = {gtau:.10g} N/V (load_mat does so for the EMPS layout)"
                        )
                    elif gtau is not None and abs(math.log(gtau)) > math.log(2) and abs(ratio / gtau - 1) < SCALE_RTOL:
                        out.append(
                            f"the force looks multiplied by gtau twice: {evidence}, about gtau = {gtau:.4g}; "
                            "the drive command was probably already in newtons"
                        )
                    elif not (1 / SCALE_FACTOR_WARN < ratio < SCALE_FACTOR_WARN):
                        out.append(
                            f"the force does not have the scale the controller implies: {evidence}; check that it is in N "
                            "on the load side and that the controller and its gains are the axis's (a force logged in "
                            f"other units, volts or amperes, takes force_scale = {1 / ratio:.4g}; CLI: --force-scale)"
                        )
        g, se = self.u_ext_gain()
        if math.isfinite(g) and abs(g - 1) > U_EXT_GAIN_RTOL and abs(g - 1) > 5 * se:
            out.append(
                f"the external input u_ext enters the logged force with gain {g:.5g} ± {se:.2g}, not 1 (least squares of "
                "the force minus the controller's command from qr and qm on u_ext): the simulation applies u_ext as "
                f"given, so scale it by {g:.5g} if the log is right (load_mat does so for the EMPS pulses), or check its "
                "units and the controller"
            )
        return out

    def __repr__(self) -> str:
        extra = [k for k in ("ql", "u_ext") if getattr(self, k) is not None]
        if self.has_joint_columns:
            return (f"Recording({self.name or 'unnamed'}: {self.n} samples at {self.fs:g} Hz, {self.n * self.dt:g} s, "
                    f"joints {', '.join(self.joint_names)}" + (f", with {', '.join(extra)}" if extra else "")
                    + (f", lead-in {1e3 * len(self.qr_lead) * self.dt:g} ms" if len(self.qr_lead) else "") + ")")
        with np.errstate(over="ignore"):  # a force of 1e200 N has an RMS of inf here, not a warning
            rms = float(np.sqrt(np.mean(self.force**2)))
        return (
            f"Recording({self.name or 'unnamed'}: {self.n} samples at {self.fs:g} Hz, {self.n * self.dt:g} s, "
            f"force RMS {rms:.4g} N, stroke {np.ptp(self.qr):.4g} m"
            + (f", with {', '.join(extra)}" if extra else "")
            + (f", lead-in {1e3 * self.qr_lead.size * self.dt:g} ms" if self.qr_lead.size else "")
            + ")"
        )


#: :meth:`Recording.diagnose` reports a gain of ``u_ext`` in the logged force further than this from 1 (and 5 σ).
U_EXT_GAIN_RTOL = 0.005
#: Relative margin below the saturation at which a sample counts as saturated (:meth:`Recording.diagnose`).
SATURATION_RTOL = 0.01
#: Relative margin above the saturation beyond which the force is reported as exceeding it.
SATURATION_OVER_RTOL = 0.05
#: A saturated stretch this long (s) is reported ...
SATURATION_WARN_S = 0.05
#: ... and so is a record saturated on this fraction of its samples.
SATURATION_WARN_FRACTION = 0.02
#: The force-scale check needs at least this correlation between the force and the implied command ...
SCALE_MIN_CORRELATION = 0.5
#: ... and reports a force more than this factor off the implied command (either way) ...
SCALE_FACTOR_WARN = 2.0
#: ... or within this relative distance of 1/gtau (volts) or gtau (gtau applied twice).
SCALE_RTOL = 0.3


def _rms(x: np.ndarray) -> float:
    with np.errstate(all="ignore"):
        m = float(np.max(np.abs(x))) if x.size else 0.0
        if m == 0 or not math.isfinite(m):
            return m
        return m * float(np.sqrt(np.mean((x / m) ** 2)))


def _longest_run(mask: np.ndarray):
    """Length and start of the longest run of True in ``mask`` (0, 0 for none)."""
    if not mask.any():
        return 0, 0
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    i = int(np.argmax(ends - starts))
    return int(ends[i] - starts[i]), int(starts[i])


def _describe(c: Controller) -> str:
    return c.describe()


def _time_step(t: np.ndarray, where: str) -> float:
    """The constant sample period of time stamps ``t``, or a DataError saying where they are not uniform."""
    n = t.shape[0]
    if n < 3:
        raise DataError(f"{where}the record has {n} samples; at least 3 are needed")
    steps = np.diff(t)
    if not np.all(steps > 0):
        k = int(np.flatnonzero(~(steps > 0))[0])
        raise DataError(
            f"{where}time t is not increasing (t[{k + 1}] = {t[k + 1]:.9g} <= t[{k}] = {t[k]:.9g}): sort the record and "
            "remove repeated samples"
        )
    dt = float((t[-1] - t[0]) / (n - 1))
    worst = int(np.argmax(np.abs(steps - dt)))
    if not (math.isfinite(dt) and dt > 0) or abs(steps[worst] - dt) > TIME_JITTER_RTOL * dt:
        raise DataError(
            f"{where}time t is not uniform: step {steps[worst]:.6g} s at sample {worst} against the mean {dt:.6g} s; "
            "resample the record to a constant period"
        )
    return dt


def _check_expected_dt(step: float, dt, where: str) -> None:
    dt = _number("dt", dt, "s")
    if not (math.isfinite(dt) and dt > 0) or abs(step - dt) > TIME_JITTER_RTOL * dt:
        raise DataError(
            f"{where}the sample period dt = {dt!r} s does not match the data, whose time t has a step of {step:.6g} s "
            f"({1 / step:.6g} Hz): give the record's own period or resample it"
        )


__all__ = ["Recording", "TIME_JITTER_RTOL", "applied_force"]
