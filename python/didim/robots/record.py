"""A robot's record (:class:`RobotRecording`): the references, the controllers' forces and the measured positions of
every joint, sampled together, with one controller per joint; read from CSV, Parquet or HDF5
(:func:`load_robot_record`), the controllers from a ``{"type": "joints", "joints": [...]}`` file
(:func:`load_joint_controllers`)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np

from .._errors import DataError
from ..controllers import Controller, _spec, controller_from_dict, in_units
from .chain import Robot


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

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise DataError(f"the sample period must be finite and > 0 s, got {self.dt}")
        n = len(self.joint_names)
        for key in ("qr", "force", "qm"):
            a = np.ascontiguousarray(np.asarray(getattr(self, key), dtype=float))
            if a.ndim != 2 or a.shape[1] != n:
                raise DataError(f"{key} must be (samples, {n}) for joints {', '.join(self.joint_names)}, got {a.shape}")
            bad = np.argwhere(~np.isfinite(a))
            if len(bad):
                k, j = bad[0]
                raise DataError(f"{key} of joint {self.joint_names[j]} is not finite at sample {k}")
            a.setflags(write=False)
            object.__setattr__(self, key, a)
        if not (len(self.qr) == len(self.force) == len(self.qm)):
            raise DataError("qr, force and qm must have the same number of samples")
        if len(self.controllers) != n:
            raise DataError(f"{len(self.controllers)} controllers for {n} joints: give one per joint")
        for c in self.controllers:
            c.transfer_function(self.dt)  # the same sample period, or a DataError saying so

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

    def core_controllers(self) -> List[Tuple[str, List[float]]]:
        """The controllers as the core takes them: (kind, gains) per joint."""
        return [(c.kind, list(c.gains)) for c in self.controllers]

    def __repr__(self) -> str:
        return (f"RobotRecording({self.name!r}: {self.n} samples at {1 / self.dt:g} Hz, {self.n * self.dt:g} s, joints "
                f"{', '.join(self.joint_names)})")


def _encoder_step(qm: np.ndarray) -> float:
    from ..loaders import detect_resolution

    step = detect_resolution(qm) if np.all(np.isfinite(qm)) else None
    return float(step) if step else 0.0


def _columns(available: Sequence[str], names: Sequence[str], key: str, where: str) -> List[str]:
    """The file's columns of signal ``key`` for each joint: ``key_1 … key_n`` or ``key_<joint name>``."""
    for form in ([f"{key}_{i + 1}" for i in range(len(names))], [f"{key}_{j}" for j in names]):
        if all(c in available for c in form):
            return form
    raise DataError(f"{where}: no columns {key}_1 … {key}_{len(names)} (or {key}_<joint name>) for the robot's "
                    f"{len(names)} joints ({', '.join(names)}); the file has {', '.join(available)}")


def load_robot_record(path, robot: Robot, *, controller: Any = None, name: Optional[str] = None) -> RobotRecording:
    """A robot record from a CSV, Parquet or HDF5 file with columns ``t, qr_1..qr_n, force_1..force_n, qm_1..qm_n``
    in ``robot``'s joint order (or ``qr_<joint name>``…), positions in rad (prismatic joints: m), forces in N·m (N).
    ``controller``: the joints' controllers (a sequence, one per joint) or the path of their file; by default
    ``NAME_controller.json`` beside the record."""
    from .._io import beside, check_input
    from ..loaders import EXTENSIONS, _csv, _hdf5, _parquet, _time_step

    p = check_input(path, "robot record")
    ext = os.path.splitext(p)[1].lower()
    kind = EXTENSIONS.get(ext)
    if kind not in ("CSV", "Parquet", "HDF5"):
        raise DataError(f"{p}: a robot record is a CSV, Parquet or HDF5 file, got {ext or 'no extension'!r}")
    if os.path.getsize(p) == 0:
        raise DataError(f"{p}: the file is empty (0 bytes)")
    if controller is None:
        side = beside(p)
        if side is None:
            raise DataError(f"{p}: no controller given and no {os.path.splitext(p)[0]}_controller.json beside it: give "
                            "the joints' controller file (CLI: --controller CTL.json)")
        controller = side
    if isinstance(controller, (str, os.PathLike)):
        controller = load_joint_controllers(controller)
    controllers = tuple(controller)
    try:
        get, available = {"CSV": _csv, "Parquet": _parquet, "HDF5": _hdf5}[kind](p)
    except UnicodeDecodeError:
        raise DataError(f"{p}: not a text file: a {kind} record was expected from its extension") from None
    names = robot.joint_names
    if "t" not in available:
        raise DataError(f"{p}: no time column t; the file has {', '.join(available)}")
    dt = _time_step(np.asarray(get("t"), dtype=float), f"{p}: ")
    signals = {key: np.column_stack([np.asarray(get(c), dtype=float).ravel() for c in _columns(available, names, key, p)])
               for key in ("qr", "force", "qm")}
    if len(controllers) != len(names):
        raise DataError(f"{p}: {len(controllers)} controllers for the robot's {len(names)} joints")
    controllers = tuple(in_units(c, dt, 1.0, 1.0) for c in controllers)
    steps = tuple(_encoder_step(signals["qm"][:, j]) for j in range(len(names)))
    label = name if name is not None else os.path.splitext(os.path.basename(p))[0]
    try:
        return RobotRecording(dt=dt, joint_names=tuple(names), controllers=controllers, encoder_step=steps, name=label,
                              **signals)
    except DataError as e:
        raise DataError(f"{p}: {e}") from None


__all__ = ["RobotRecording", "load_robot_record", "load_joint_controllers"]
