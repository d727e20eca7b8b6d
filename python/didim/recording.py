"""Recordings of a position-controlled axis, and the loader of the EMPS benchmark's MAT files."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ._errors import DataError
from .controllers import PD, Controller, EmpsCascade

#: Relative tolerance on the sample-time jitter accepted by :func:`load_mat` (the EMPS logs ±2.5e-8 s on 1e-3 s).
TIME_JITTER_RTOL = 1e-3


def _signal(name: str, x, n: Optional[int] = None) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as e:
        raise DataError(f"{name} must be an array of numbers: {e}") from None
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


@dataclass(frozen=True)
class Recording:
    """A record of a position-controlled axis, validated on construction. SI units on the load side.

    Attributes:
        dt: sample period (s).
        qr: position reference fed to the controller (m).
        force: measured motor force (N), e.g. ``gtau·vir`` on the EMPS.
        qm: measured motor position (m).
        controller: the controller that ran the axis (:class:`EmpsCascade` or :class:`PD`).
        ql: measured load position (m) when the axis has a second encoder, else None.
        u_ext: known external force added to the command (N), e.g. the EMPS pulses, else None.
        position_resolution: resolution of the motor encoder (m), used to quantize the simulated measurement, or None.
        name: a label for reports.
    """

    dt: float
    qr: np.ndarray
    force: np.ndarray
    qm: np.ndarray
    controller: Controller = field(default_factory=EmpsCascade)
    ql: Optional[np.ndarray] = None
    u_ext: Optional[np.ndarray] = None
    position_resolution: Optional[float] = None
    name: str = ""

    def __post_init__(self) -> None:
        dt = float(self.dt)
        if not (math.isfinite(dt) and dt > 0):
            raise DataError(f"sample period dt must be a finite number of seconds > 0, got {self.dt}")
        object.__setattr__(self, "dt", dt)
        qr = _signal("qr (position reference)", self.qr)
        n = qr.shape[0]
        if n < 3:
            raise DataError(f"the record has {n} samples; at least 3 are needed")
        object.__setattr__(self, "qr", qr)
        object.__setattr__(self, "force", _signal("force", self.force, n))
        object.__setattr__(self, "qm", _signal("qm (motor position)", self.qm, n))
        if self.ql is not None:
            object.__setattr__(self, "ql", _signal("ql (load position)", self.ql, n))
        if self.u_ext is not None:
            object.__setattr__(self, "u_ext", _signal("u_ext (external force)", self.u_ext, n))
        if not isinstance(self.controller, (EmpsCascade, PD)):
            raise DataError(f"controller must be EmpsCascade or PD, got {type(self.controller).__name__}")
        if self.position_resolution is not None:
            r = float(self.position_resolution)
            if not (math.isfinite(r) and r > 0):
                raise DataError(f"position_resolution must be a finite length > 0 m (or None), got {r}")
            object.__setattr__(self, "position_resolution", r)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.qr.shape[0])

    @property
    def t(self) -> np.ndarray:
        """Time of each sample (s), from 0."""
        return np.arange(self.n) * self.dt

    @property
    def fs(self) -> float:
        """Sampling frequency (Hz)."""
        return 1.0 / self.dt

    def __repr__(self) -> str:
        extra = [k for k in ("ql", "u_ext") if getattr(self, k) is not None]
        return (
            f"Recording({self.name or 'unnamed'}: {self.n} samples at {self.fs:g} Hz, {self.n * self.dt:g} s, "
            f"force RMS {np.sqrt(np.mean(self.force**2)):.4g} N, stroke {np.ptp(self.qr):.4g} m"
            + (f", with {', '.join(extra)}" if extra else "")
            + ")"
        )


def _scalar(d: dict, key: str, path: str) -> float:
    a = np.asarray(d[key])
    if a.size != 1 or not np.issubdtype(a.dtype, np.number):
        raise DataError(f"{path}: variable {key!r} must be a single number, got shape {a.shape} of {a.dtype}")
    v = float(a.ravel()[0])
    if not math.isfinite(v):
        raise DataError(f"{path}: variable {key!r} is not finite ({v})")
    return v


def load_mat(path, *, position_resolution: Optional[float] = None, name: Optional[str] = None) -> Recording:
    """Loads a record in the EMPS benchmark layout (MATLAB v5 ``.mat``).

    Variables: ``t`` (s), ``qm`` (m), ``qg`` (the reference, m), ``vir`` (the drive command, V), ``gtau`` (N/V),
    ``kp`` (1/s), ``kv`` (V/(m/s)); optional ``pulses_N``, the disturbance injected at the drive input (in V,
    despite its name; ``vir`` already contains it, so the measured force is ``gtau·vir`` and the known external
    force ``gtau·pulses_N``), optional ``ql``, the load position of an axis with a second encoder, and optional
    ``vsat`` (V, 10 by default, the EMPS drive's limit).

    Raises :class:`DataError` naming the file and the problem: missing or unreadable file, not a MAT file,
    missing variable, wrong shape or type, non-uniform time.
    """
    from scipy.io import loadmat

    path = os.fspath(path)
    if not os.path.exists(path):
        raise DataError(f"{path}: no such file")
    try:
        d = loadmat(path)
    except Exception as e:  # scipy raises several types for corrupt files
        raise DataError(f"{path}: not a readable MATLAB .mat file ({type(e).__name__}: {e})") from None
    required = ("t", "qm", "qg", "vir", "gtau", "kp", "kv")
    missing = [k for k in required if k not in d]
    if missing:
        present = sorted(k for k in d if not k.startswith("__"))
        raise DataError(
            f"{path}: missing variable(s) {', '.join(missing)}; the EMPS layout needs {', '.join(required)} "
            f"(found: {', '.join(present) or 'none'})"
        )

    def vec(key: str) -> np.ndarray:
        a = np.asarray(d[key])
        if not np.issubdtype(a.dtype, np.number):
            raise DataError(f"{path}: variable {key!r} must be numeric, got {a.dtype}")
        if a.ndim != 2 or min(a.shape) != 1:
            raise DataError(f"{path}: variable {key!r} must be a vector (N x 1), got shape {a.shape}")
        return a.astype(float).ravel()

    try:
        t = _signal(f"{path}: t", vec("t"))
        n = t.shape[0]
        if n < 3:
            raise DataError(f"{path}: the record has {n} samples; at least 3 are needed")
        steps = np.diff(t)
        if not np.all(steps > 0):
            k = int(np.flatnonzero(steps <= 0)[0])
            raise DataError(f"{path}: time t is not increasing (t[{k + 1}] <= t[{k}])")
        dt = float((t[-1] - t[0]) / (n - 1))
        worst = int(np.argmax(np.abs(steps - dt)))
        if abs(steps[worst] - dt) > TIME_JITTER_RTOL * dt:
            raise DataError(
                f"{path}: time t is not uniform: step {steps[worst]:.6g} s at sample {worst} against the mean {dt:.6g} s; "
                "resample the record to a constant period"
            )
        gtau = _scalar(d, "gtau", path)
        ctrl = EmpsCascade(
            kp=_scalar(d, "kp", path),
            kv=_scalar(d, "kv", path),
            gtau=gtau,
            vsat=_scalar(d, "vsat", path) if "vsat" in d else 10.0,
        )
        force = gtau * _signal(f"{path}: vir", vec("vir"), n)
        u_ext = gtau * _signal(f"{path}: pulses_N", vec("pulses_N"), n) if "pulses_N" in d else None
        ql = _signal(f"{path}: ql", vec("ql"), n) if "ql" in d else None
        return Recording(
            dt=dt,
            qr=_signal(f"{path}: qg", vec("qg"), n),
            force=force,
            qm=_signal(f"{path}: qm", vec("qm"), n),
            controller=ctrl,
            ql=ql,
            u_ext=u_ext,
            position_resolution=position_resolution,
            name=name if name is not None else os.path.splitext(os.path.basename(path))[0],
        )
    except DataError as e:
        msg = str(e)
        raise DataError(msg if msg.startswith(path) else f"{path}: {msg}") from None


__all__ = ["Recording", "load_mat", "TIME_JITTER_RTOL"]
