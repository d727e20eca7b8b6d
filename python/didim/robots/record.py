"""A robot's record (:class:`RobotRecording`): the references, the controllers' forces and the measured positions of
every joint, sampled together, with one controller per joint; read from CSV, Parquet or HDF5
(:func:`didim.load_record` with ``robot=``), the controllers from a ``{"type": "joints", "joints": [...]}`` file
(:func:`load_joint_controllers`)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, List, Optional, Tuple

import numpy as np

from .._errors import DataError
from ..controllers import Controller, _spec, controller_from_dict


def load_joint_controllers(path) -> Tuple[Controller, ...]:
    """One controller per joint from a JSON or TOML file ``{"type": "joints", "joints": [c_1, ..., c_n]}`` whose
    entries are single-axis controllers (:func:`didim.load_controller`'s form), in the robot's joint order."""
    p, spec = _spec(path)
    if not isinstance(spec, dict) or spec.get("type") != "joints" or not isinstance(spec.get("joints"), list):
        raise DataError(f"{p}: a robot's controller file is {{\"type\": \"joints\", \"joints\": [one controller per "
                        f"joint]}}, got type {spec.get('type') if isinstance(spec, dict) else type(spec).__name__!r}")
    if not spec["joints"]:
        raise DataError(f"{p}: \"joints\" is empty: give one controller per joint")
    return tuple(controller_from_dict(c, f"{p}: joint {i + 1}") for i, c in enumerate(spec["joints"]))


def load_joint_drives(path) -> Tuple[Tuple[int, ...], Tuple[float, ...]]:
    """Each joint's actuation delay (samples) and force lag (s) from the entries of a robot's controller file
    (``"delay"``, ``"force_lag"``; 0 where absent): the drive between the controller's command and the force on the
    joint, which the closed loop simulates and the least squares regress on (:func:`applied_force`)."""
    from .. import _checks

    p, spec = _spec(path)
    entries = spec.get("joints") if isinstance(spec, dict) and isinstance(spec.get("joints"), list) else []
    delay, lag = [], []
    for i, e in enumerate(entries):
        e = e if isinstance(e, dict) else {}
        delay.append(_checks.whole(f"{p}: joint {i + 1}'s delay", e.get("delay", 0), hint=" (samples)"))
        lag.append(_checks.real(f"{p}: joint {i + 1}'s force_lag", e.get("force_lag", 0.0), "s", lo=0.0,
                                lo_open=False))
    return tuple(delay), tuple(lag)


def applied_force(force: np.ndarray, delay: Tuple[int, ...], force_lag: Tuple[float, ...], dt: float) -> np.ndarray:
    """The force each joint's plant receives, as its mean over each sample period, when the drive logs the commands
    ``force`` (samples × joints): the command of ``delay`` samples earlier (the first one before the record: the
    drive held it), through a first-order lag of ``force_lag`` s started at it, as the robot's closed loop applies
    them (the core's arithmetic, one axis's too). The least squares regress on it: the simulated states answer it,
    not the logged command."""
    from .. import _core

    out = np.array(force, dtype=float)
    for j in range(out.shape[1]):
        d = delay[j] if j < len(delay) else 0
        lag = force_lag[j] if j < len(force_lag) else 0.0
        if d or lag > 0:
            out[:, j] = _core.applied_force(np.ascontiguousarray(out[:, j]), int(d), float(lag), dt,
                                            held=float(out[0, j]))
    return out


@dataclass(frozen=True)
class RobotRecording:
    """A record of an n-joint robot: sample period ``dt`` (s), references ``qr``, forces ``force`` (the controllers'
    commands, N·m or N) and measured positions ``qm`` (rad or m), each (N, n) in ``joint_names``' order; the
    ``controllers`` (one per joint) and each joint's encoder step (``encoder_step``, 0 where unknown)."""

    dt: float
    qr: np.ndarray
    force: np.ndarray
    qm: np.ndarray
    joint_names: Tuple[str, ...]
    controllers: Tuple[Controller, ...]
    encoder_step: Tuple[float, ...]
    name: str = ""
    #: "revolute" or "prismatic" per joint (the units: rad and N·m, or m and N).
    joint_kinds: Tuple[str, ...] = ()
    #: The units each joint was logged in (:class:`didim.units.Units`; the arrays hold SI), empty when SI.
    units: Tuple = ()
    #: Where each joint's controller comes from when nobody described it (the fit's summary), else empty.
    controller_origin: Tuple[str, ...] = ()
    #: A known force each joint's drive adds to its controller's command before saturation (a feedforward), (N, n)
    #: like ``force``; None for none (the logged force includes it).
    u_ext: Optional[np.ndarray] = None
    #: Each joint's actuation delay (samples) and force lag (s) between its command and the force on the joint;
    #: empty for none.
    delay: Tuple[int, ...] = ()
    force_lag: Tuple[float, ...] = ()
    #: The references before the first sample, for a log that begins in motion, as one axis's
    #: (:attr:`didim.Recording.lead_in`): ``"auto"`` (default) reconstructs each joint's back to the rest it left where
    #: its reference begins in the acceleration from rest (:func:`didim.recording.reconstruct_lead_in`), ``None`` for
    #: none (the loop starts at rest on the first reference sample), or the samples themselves ((L, n), oldest first,
    #: at ``dt``). The loop runs through them from rest, each controller's integrator holding the model's static
    #: torque; nothing is compared there. :attr:`qr_lead` is the one in use.
    lead_in: Any = "auto"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise DataError(f"the sample period must be finite and > 0 s, got {self.dt}")
        n = len(self.joint_names)
        for key in ("qr", "force", "qm", "u_ext"):
            if getattr(self, key) is None and key == "u_ext":
                continue
            a = np.ascontiguousarray(np.asarray(getattr(self, key), dtype=float))
            if a.ndim != 2 or a.shape[1] != n or (key == "u_ext" and a.shape != self.force.shape):
                raise DataError(f"{key} must be (samples, {n}) for joints {', '.join(self.joint_names)}"
                                f"{' like force' if key == 'u_ext' else ''}, got {a.shape}")
            bad = np.argwhere(~np.isfinite(a))
            if len(bad):
                k, j = bad[0]
                raise DataError(f"{key} of joint {self.joint_names[j]} is not finite at sample {k}")
            a.setflags(write=False)
            object.__setattr__(self, key, a)
        if not (len(self.qr) == len(self.force) == len(self.qm)):
            raise DataError("qr, force and qm must have the same number of samples")
        for key in ("delay", "force_lag"):
            got = tuple(getattr(self, key))
            if got and len(got) != n:
                raise DataError(f"{key} needs one value per joint ({n}), got {len(got)}")
            object.__setattr__(self, key, got)
        if any(d < 0 or d >= max(len(self.qr), 1) or int(d) != d for d in self.delay):
            raise DataError(f"each joint's delay must be a whole number of samples, >= 0 and shorter than the record "
                            f"({len(self.qr)} samples), got {self.delay}")
        if any(not (math.isfinite(x) and x >= 0) for x in self.force_lag):
            raise DataError(f"each joint's force lag must be finite and >= 0 s, got {self.force_lag}")
        if not self.joint_kinds:
            object.__setattr__(self, "joint_kinds", ("revolute",) * n)
        if len(self.controllers) != n:
            raise DataError(f"{len(self.controllers)} controllers for {n} joints: give one per joint")
        for c in self.controllers:
            c.transfer_function(self.dt)  # the same sample period, or a DataError saying so
        lead = self.lead_in
        if isinstance(lead, str):
            if lead not in ("auto", "none"):
                raise DataError(f"lead_in must be 'auto', None (or 'none') or the references before the first sample "
                                f"(L, {n}), got {lead!r}")
        elif lead is not None:
            lead = np.asarray(lead, dtype=float)
            if lead.ndim != 2 or lead.shape[1] != n or not np.all(np.isfinite(lead)) or lead.shape[0] >= len(self.qr):
                raise DataError(f"lead_in must be finite references (L, {n}) before the first sample, fewer than the "
                                f"record's {len(self.qr)} samples, got shape {lead.shape}")
            object.__setattr__(self, "lead_in", lead)

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self.qr)

    @property
    def ndof(self) -> int:
        return len(self.joint_names)

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n) * self.dt

    def joint(self, j: int, controller: Optional[Controller] = None):
        """Joint ``j`` (an index or a name) as a one-axis :class:`didim.Recording`: its reference, force and measured
        position with its controller (or ``controller``) and encoder step, in rad and N·m (or m and N), from rest
        on its first sample as the robot's loop starts. Every one-axis method that reads one joint's log (the
        controller check, the controller fitted from the log) takes it."""
        from ..recording import Recording
        from ..units import Units

        if isinstance(j, str):
            if j not in self.joint_names:
                raise DataError(f"no joint {j!r} in the record: its joints are {', '.join(self.joint_names)}")
            j = self.joint_names.index(j)
        rotary = self.joint_kinds[j] != "prismatic"
        return Recording(dt=self.dt, qr=self.qr[:, j], force=self.force[:, j], qm=self.qm[:, j],
                         u_ext=None if self.u_ext is None else self.u_ext[:, j],
                         controller=controller if controller is not None else self.controllers[j],
                         position_resolution=self.encoder_step[j] or None,
                         name=f"{self.name or 'record'}, joint {self.joint_names[j]}", lead_in=None,
                         units=Units("rad", "N*m") if rotary else Units("m", "N"))

    @functools.cached_property
    def qr_lead(self) -> np.ndarray:
        """The references before the first sample that the loop runs through from rest ((L, n), oldest first; L = 0
        for none): the given ones, or with ``lead_in="auto"`` each joint's reconstructed back to the rest it left as
        one axis's (:func:`didim.recording.reconstruct_lead_in`) when every joint whose reference moves at the first
        samples has one, the longest setting L and the shorter ones held at rest before theirs. A joint that moves
        without one (a log cut in its cruise or its deceleration: how long it cruised is not in the log) leaves the
        record without a lead-in, as one axis's: holding it still through the others' lead-in and then moving it
        would start it further from its state than the record's first sample does."""
        if isinstance(self.lead_in, np.ndarray):
            return self.lead_in
        n = self.ndof
        if self.lead_in != "auto":
            return np.zeros((0, n))
        from ..recording import LEAD_FIT_SAMPLES, reconstruct_lead_in

        leads = [reconstruct_lead_in(self.qr[:, j], self.dt, self.qm[:, j], self.encoder_step[j] or None)
                 for j in range(n)]
        head = self.qr[:min(LEAD_FIT_SAMPLES, self.n)]
        moving = np.ptp(head, axis=0) > np.maximum(np.asarray(self.encoder_step, dtype=float), 0.0)
        if any(m and not len(x) for m, x in zip(moving, leads)):
            return np.zeros((0, n))
        size = max(len(x) for x in leads)
        out = np.empty((size, n))
        for j, x in enumerate(leads):
            start = x[0] if len(x) else self.qr[0, j]
            out[:, j] = np.concatenate([np.full(size - len(x), start), x])
        out.setflags(write=False)
        return out

    def lead_in_signals(self) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """The references and the known feedforward the loop runs on: :attr:`qr_lead` then ``qr``, and ``u_ext`` held
        at its first value through the lead-in. The record's own arrays when it has no lead-in."""
        lead = self.qr_lead
        if not len(lead):
            return self.qr, self.u_ext
        u = None if self.u_ext is None else np.concatenate([np.repeat(self.u_ext[:1], len(lead), axis=0), self.u_ext])
        return np.ascontiguousarray(np.concatenate([lead, self.qr])), u

    def lead_in_note(self) -> str:
        """One sentence on the record's lead-in for a result's notes ("" without one)."""
        if not len(self.qr_lead):
            return ""
        return (f"the record begins in motion: simulated from rest {1e3 * len(self.qr_lead) * self.dt:.0f} ms before its "
                "first sample, through its references' lead-in (to start at the first sample: lead_in=None, on the "
                "command line --lead-in none)")

    def applied_force(self) -> np.ndarray:
        """The force the joints receive (:func:`applied_force`): the logged one without delay nor lag."""
        if not any(self.delay) and not any(self.force_lag):
            return self.force
        return applied_force(self.force, self.delay, self.force_lag, self.dt)

    def core_controllers(self) -> List[Tuple[str, List[float]]]:
        """The controllers as the core takes them: (kind, gains) per joint."""
        return [(c.kind, list(c.gains)) for c in self.controllers]

    def __repr__(self) -> str:
        return (f"RobotRecording({self.name!r}: {self.n} samples at {1 / self.dt:g} Hz, {self.n * self.dt:g} s, joints "
                f"{', '.join(self.joint_names)})")


__all__ = ["RobotRecording", "load_joint_controllers", "load_joint_drives", "applied_force"]
