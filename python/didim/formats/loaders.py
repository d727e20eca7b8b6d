"""Records from the files drives log: CSV, Parquet, HDF5 (and the EMPS MAT layout), one entry point.

Columns (SI units on the load side): ``t`` (s), ``qr`` (position reference, m), ``force`` (motor force, N), ``qm``
(motor position, m); optional ``ql`` (load position, m) and ``u_ext`` (known external force added to the command, N).
Other names are mapped with ``columns={"force": "F_motor", ...}``; a force logged in another unit (V, A, % of rated)
is brought to N with ``force_scale``. The controller that ran the axis is required: ``controller=`` or, when it is
not given, a controller file beside the record (``NAME_controller.json`` or ``.toml``).
"""

from __future__ import annotations

import math
import os
import re
import warnings
from dataclasses import replace
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _checks
from .._errors import DataError
from ._io import beside, check_input
from ..controllers import (Controller, EmpsCascade, controller_file_units, in_units, load_controller,
                          load_joint_controllers, load_joint_drives)
from ..robots.chain import Robot
from ..recording import Recording, _check_expected_dt, _number, _signal, _time_step
from ..units import SI, Units, check_stroke, from_header, other_readings, parse as parse_units

#: The columns of a record: required, then optional.
REQUIRED = ("t", "qr", "force", "qm")
OPTIONAL = ("ql", "u_ext")
#: File extensions and their readers.
EXTENSIONS = {".csv": "CSV", ".txt": "CSV", ".parquet": "Parquet", ".pq": "Parquet", ".h5": "HDF5", ".hdf5": "HDF5",
              ".mat": "MAT"}

PathLike = Union[str, "os.PathLike[str]"]


def parse_columns(text: Optional[str]) -> Dict[str, str]:
    """``"force=F_motor,qm=enc"`` → ``{"force": "F_motor", "qm": "enc"}`` (the CLI's ``--columns``)."""
    if not text:
        return {}
    out: Dict[str, str] = {}
    for part in text.split(","):
        key, sep, value = part.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise DataError(f"--columns: {part!r} is not KEY=NAME; e.g. --columns force=F_motor,qm=encoder")
        out[key] = value
    return out


def detect_resolution(qm: np.ndarray) -> Optional[float]:
    """The encoder resolution (in qm's unit) when every motor position is a whole number of one step, else None.

    The step is the largest whole fraction (1/1 … 1/20) of the smallest non-zero change between samples of which
    every change is a multiple, refined by least squares over all the changes (a step of 2π/2^20 rad or its
    degrees is no round decimal, and text files round the positions' last digits); the positions must then lie on
    one grid of that step within 1e-3 of a step."""
    d = np.diff(qm)
    d = d[d != 0]
    if d.size < 10 or not np.all(np.isfinite(qm)):
        return None
    smallest = float(np.min(np.abs(d)))
    for parts in range(1, 21):
        for step in (float(f"{smallest / parts:.6g}"), smallest / parts):  # a rounded decimal step first: 5e-8
            if not (math.isfinite(step) and step > 0):
                continue  # a change below the smallest float's resolution: no step to try
            few = d[np.abs(d) <= 20 * step]  # small changes first: the step's error grows with the count
            if not few.size:
                continue
            n = np.round(few / step)
            if np.max(np.abs(few / step - n)) > 1e-2:
                continue
            refined = float(np.dot(few, n) / np.dot(n, n))
            n = np.round(d / refined)
            if np.max(np.abs(d / refined - n)) > 1e-2:
                continue
            refined = float(np.dot(d, n) / np.dot(n, n))
            for s in (step, refined):
                k = qm / s
                if np.max(np.abs(k)) > 2**52:
                    return None
                frac = k - np.round(k)
                frac = frac - np.median(frac)  # one grid, maybe offset from zero
                if np.max(np.abs(frac - np.round(frac))) <= 1e-3:
                    return s
    return None


def _from_columns(get: Callable[[str], Optional[np.ndarray]], available: List[str], where: str, *,
                  controller: Optional[Controller], columns: Optional[Mapping[str, str]], force_scale: float,
                  dt: Optional[float], position_resolution: Union[None, float, str], name: str,
                  units: Union[None, str, Units] = None, file_units: Optional[Units] = None) -> Recording:
    if columns is not None and (not isinstance(columns, Mapping)
                                or not all(isinstance(k, str) and isinstance(v, str) for k, v in columns.items())):
        raise DataError(f"columns must map didim's names to the file's, e.g. {{'force': 'F_motor'}}, got {columns!r}"
                        " (on the command line: --columns force=F_motor)")
    columns = dict(columns or {})
    plain, header_units = from_header(available)  # "qm[deg]" is column qm, in degrees
    if plain != list(available):
        raw_get, by_plain = get, dict(zip(plain, available))
        get, available = (lambda c: raw_get(by_plain[c])), plain
    declared = parse_units(units, force_scale=None if force_scale == 1.0 else force_scale)
    if declared is not None and header_units is not None and declared != header_units:
        raise DataError(f"{where}: units={units!r} but the header says {header_units.describe()}: give one")
    u = declared or header_units or file_units or SI
    unknown = sorted(set(columns) - set(REQUIRED) - set(OPTIONAL))
    if unknown:
        raise DataError(f"{where}: unknown key(s) {', '.join(unknown)} in the column map; the keys are "
                        f"{', '.join(REQUIRED + OPTIONAL)}")
    scale = _checks.real("force_scale", force_scale, hint=" (N per unit of the logged force)")
    if scale == 0:
        raise DataError("force_scale must not be zero (N per unit of the logged force)")
    signals: Dict[str, Optional[np.ndarray]] = {}
    for key in REQUIRED + OPTIONAL:
        col = columns.get(key, key)
        if key == "t" and col not in available and dt is not None and "t" not in columns:
            signals["t"] = None  # no time column: the period is given
            continue
        a = get(col) if col in available else None
        if a is None and key in REQUIRED:
            hint = " (or give dt)" if key == "t" else ""
            if key != "t" and f"{key}_1" in available:
                hint += (f"; the file has {key}_1, {key}_2, …: a robot's record, read with its URDF (Python: "
                         "load_record(path, robot=...), CLI: --urdf URDF)")
            raise DataError(f"{where}: no column {col!r} for {key}{hint}; the file has {', '.join(available) or 'none'}. "
                            f"A record needs columns {', '.join(REQUIRED)} (optional {', '.join(OPTIONAL)}); map other "
                            "names with columns={'force': 'YOUR_NAME', ...} (CLI: --columns force=YOUR_NAME)")
        if a is not None:
            a = np.asarray(a)
            if a.dtype.kind not in "iuf":
                raise DataError(f"{where}: column {col!r} ({key}) must hold numbers, got {a.dtype}")
            a = a.astype(float).ravel()
        signals[key] = a
    if scale != 1.0 and u.force_factor != 1.0 and u.force_factor != scale:
        raise DataError(f"{where}: force_scale={scale:g} and units ({u.describe()}) both scale the force: give one")
    ff = u.force_factor if u.force_factor != 1.0 else float(scale)
    force = signals["force"] * ff  # type: ignore[operator]
    k = u.position_factor
    check_stroke(signals["qr"], u, where)
    qm = signals["qm"]
    assert qm is not None
    if position_resolution == "auto":
        res = detect_resolution(qm) if np.all(np.isfinite(qm)) else None  # on the logged grid, then in SI
        res = None if res is None else res * k
    elif position_resolution is None:
        res = None
    else:
        res = _checks.real("position_resolution", position_resolution, "m", lo=0.0, lo_open=False,
                           hint=" (the encoder step, in SI: m or rad; None for none, 'auto' to detect it)")
    origin = ""
    if controller is None:  # nobody described it: the linear law that ran the axis, from the log itself
        from ..controller_fit import fit_controller

        t = signals["t"]
        period = dt if dt is not None else _time_step(t, f"{where}: ")
        try:
            cf = fit_controller(dict(dt=period, qr=signals["qr"] * k, qm=qm * k, force=force,
                                     u_ext=None if signals["u_ext"] is None else signals["u_ext"] * ff, name=where))
        except DataError as e:
            raise DataError(f"{e}. No controller was given (controller=..., CLI: --controller FILE, or "
                            "NAME_controller.json beside the record), so didim tried to fit one from the log") from None
        controller, origin = cf.controller, cf.summary()
        k_in = 1.0  # fitted on SI positions and force already
    else:
        k_in = None
    if k_in is None:
        try:
            controller = in_units(controller, dt if dt is not None else _time_step(signals["t"], f"{where}: "), k, ff)
        except DataError as e:
            raise DataError(f"{where}: {e}") from None

    def si(x):
        return None if x is None else x * k

    kw = dict(qr=si(signals["qr"]), force=force, qm=si(qm), controller=controller, ql=si(signals["ql"]),
              u_ext=None if signals["u_ext"] is None else signals["u_ext"] * ff, position_resolution=res, name=name,
              units=u, controller_origin=origin)
    try:
        if signals["t"] is None:
            return Recording(dt=dt, **kw)  # type: ignore[arg-type]
        return Recording.from_time(signals["t"], dt=dt, **kw)  # type: ignore[arg-type]
    except DataError as e:
        raise DataError(f"{where}: {e}") from None


def _csv(path: str):
    import csv

    skip = 1  # the header's line, after the comment lines ("# exported by ...") a logger may write above it
    with open(path, newline="", encoding="utf-8-sig") as f:
        head = f.readline()
        while head.lstrip().startswith("#"):
            head, skip = f.readline(), skip + 1
    if not head.strip():
        raise DataError(f"{path}: the file is empty or its first line is blank; a CSV record starts with a header "
                        f"line naming its columns ({', '.join(REQUIRED)})")
    delim = max([",", ";", "\t"], key=head.count)
    if head.count(delim) == 0:
        delim = None  # whitespace-separated
    names = [c.strip().strip('"') for c in (next(csv.reader([head], delimiter=delim)) if delim else head.split())]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": said below, as a DataError
            data = np.loadtxt(path, delimiter=delim, skiprows=skip, ndmin=2, encoding="utf-8-sig")
    except ValueError as e:
        msg = str(e).rstrip(". ")
        empty = ("an empty field is a missing value: fill it or cut the record (pandas writes NaN as an empty field "
                 "unless to_csv(na_rep='nan')); " if "string ''" in msg else "")
        raise DataError(f"{path}: not a numeric CSV table under its header ({msg}; numpy counts rows from 0 under the "
                        f"header and columns from 1); {empty}every row must hold {len(names)} numbers") from None
    if data.size == 0:
        raise DataError(f"{path}: the header names its columns ({', '.join(names)}) but no row of samples follows")
    if data.shape[1] != len(names):
        raise DataError(f"{path}: the header names {len(names)} columns but the rows hold {data.shape[1]}")
    twice = sorted({c for c in names if names.count(c) > 1})
    if twice:
        raise DataError(f"{path}: column(s) {', '.join(twice)} appear more than once in the header: which one is meant "
                        "is ambiguous; rename one")
    return (lambda c: data[:, names.index(c)]), names


def _parquet(path: str):
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise DataError(f"{path}: reading Parquet needs pyarrow: pip install pyarrow (or pip install 'didim[io]')") \
            from None
    try:
        table = pq.read_table(path)
    except Exception as e:  # pyarrow raises its own types for corrupt files
        raise DataError(f"{path}: not a readable Parquet file ({type(e).__name__}: {e})") from None
    names = list(table.column_names)
    return (lambda c: table.column(c).to_numpy()), names


def _hdf5(path: str):
    try:
        import h5py
    except ImportError:
        raise DataError(f"{path}: reading HDF5 needs h5py: pip install h5py (or pip install 'didim[io]')") from None
    try:
        f = h5py.File(path, "r")
    except Exception as e:
        raise DataError(f"{path}: not a readable HDF5 file ({type(e).__name__}: {e})") from None
    with f:
        names: List[str] = []
        f.visititems(lambda n, obj: names.append(n) if isinstance(obj, h5py.Dataset) else None)
        data = {n: np.asarray(f[n][()]) for n in names}
    return (lambda c: data[c]), names


def load_record(path: PathLike, *, controller: Union[None, Controller, PathLike] = None,
                columns: Optional[Mapping[str, str]] = None, force_scale: float = 1.0, dt: Optional[float] = None,
                position_resolution: Union[None, float, str] = "auto", name: Optional[str] = None,
                pulses_gain: Union[float, str] = "log", lead_in: Union[str, None, np.ndarray] = "auto",
                units: Union[None, str, Units] = None, beside_controller: bool = True,
                robot: Optional["Robot"] = None, **unknown) -> Recording:
    """A record from a CSV, Parquet, HDF5 or MAT file, the format chosen by the extension.

    With ``robot`` (a :class:`didim.Robot` or a URDF's path): a robot's record (a :class:`didim.Recording` with joint columns),
    columns ``t, qr_1..qr_n, force_1..force_n, qm_1..qm_n`` in the robot's joint order (or ``qr_<joint name>``…),
    in rad (m) and N·m (N) unless ``units`` (``"deg"``, ``"deg,mm"``, one per joint), the header or the controllers'
    file says otherwise (:func:`load_robot_record`), the controller a ``{"type": "joints", ...}`` file (by default
    ``NAME_controller.json`` beside it).

    CSV: a header line naming the columns, then one row of numbers per sample (comma, semicolon, tab or spaces).
    Parquet: one column per signal. HDF5: one dataset per signal (``columns`` may name ``group/dataset``). MAT: the
    EMPS layout (:func:`didim.load_mat`), whose controller comes from the file unless ``controller`` is given.

    ``controller``: the controller that ran the axis, or the path of its file; when None, ``NAME_controller.json`` (or ``.toml``) beside the
    file is read if it exists. ``columns``: map from didim's names (t, qr, force, qm, ql, u_ext) to the file's.
    An option it does not take is refused by name (``joints``: a robot's are picked with its URDF,
    ``didim.Robot.from_urdf(path, joints=[...])``).
    ``force_scale``: N per unit of the logged force. ``dt``: the expected period (s), checked against ``t``, or the
    period when the file has no time column. ``position_resolution``: the motor encoder's step (m), ``'auto'`` to
    detect it from ``qm`` (positions on a grid), or None. ``pulses_gain``: MAT files, see :func:`didim.load_mat`.
    ``lead_in``: the reference before the first sample, see :class:`didim.Recording` (``"auto"``: reconstructed when
    the log begins in the acceleration from rest; None: the simulation starts at rest on the first sample).
    ``units``: what the positions and force are logged in (:mod:`didim.units`: ``"mm"``, ``"deg"``, ``"rad,N*m"``,
    ``"counts/rev=1048576"``, ``"mm,V=2.5"``); also read from the CSV header (``qm[deg]``) or the controller file's
    ``"units"``; SI (m, N) when none says. The record is converted to SI (m or rad, N or N·m) with its controller,
    and remembers whether its axis is linear or rotary for every unit it prints. Without a controller (given, or a
    file beside the record unless ``beside_controller=False``), the controller is fitted from the log
    (:func:`didim.fit_controller`) and ``Recording.controller_origin`` says so.
    """
    if "joints" in unknown:
        raise DataError("load_record takes no joints=: a robot's actuated joints are picked when its URDF is read, "
                        "robot=didim.Robot.from_urdf(path, joints=[...]) (CLI: --joints), and the record's columns "
                        "follow them")
    if unknown:
        _checks.known_options([load_record], unknown, "load_record")
    if robot is not None:
        if isinstance(robot, (str, os.PathLike)):
            robot = Robot.from_urdf(robot)  # the URDF's path
        if not (isinstance(robot, Robot) or hasattr(robot, "joint_names") and hasattr(robot, "joint_kinds")):
            raise DataError(f"robot must be a didim.Robot (didim.Robot.from_urdf(path)) or a URDF's path, got "
                            f"{type(robot).__name__}")
        if columns is not None or force_scale != 1.0:
            raise DataError("a robot record has columns t, qr_1..qr_n, force_1.., qm_1.. (or qr_<joint name>..); "
                            "columns and force_scale apply to one axis's record: declare a drive unit with its scale "
                            "in units (e.g. units='deg,A=2.5')")
        return load_robot_record(path, robot, controller=controller, name=name, units=units,
                                 beside_controller=beside_controller, lead_in=lead_in)
    rec = _load_record(path, controller, columns, force_scale, dt, position_resolution, name, pulses_gain, units,
                       beside_controller)
    if isinstance(lead_in, str) and lead_in == "auto":
        return rec
    import dataclasses

    return dataclasses.replace(rec, lead_in=lead_in)


def _load_record(path, controller, columns, force_scale, dt, position_resolution, name, pulses_gain,
                 units=None, beside_controller=True) -> Recording:
    p = check_input(path, "record")
    ext = os.path.splitext(p)[1].lower()
    if ext not in EXTENSIONS:
        raise DataError(f"{p}: unknown record format {ext or '(no extension)'!r}: didim reads "
                        f"{', '.join(sorted(EXTENSIONS))} (CSV, Parquet, HDF5, MATLAB in the EMPS layout)")
    if os.path.getsize(p) == 0:
        raise DataError(f"{p}: the file is empty (0 bytes)")
    file_units = None
    if isinstance(controller, (str, os.PathLike)):  # a controller file (JSON or TOML)
        file_units = controller_file_units(controller)
        controller = load_controller(controller)
    if controller is None and beside_controller:
        side = beside(p)
        if side is not None:
            file_units = controller_file_units(side)
            controller = load_controller(side)
    label = name if name is not None else os.path.splitext(os.path.basename(p))[0]
    if ext == ".mat":
        res = None if position_resolution == "auto" else position_resolution
        rec = load_mat(p, position_resolution=res, name=label, dt=dt, pulses_gain=pulses_gain)  # type: ignore[arg-type]
        if controller is not None:
            import dataclasses

            rec = dataclasses.replace(rec, controller=controller)
        if units is not None and parse_units(units) != SI:
            raise DataError(f"{p}: the EMPS MAT layout is in SI (m, N); units={units!r} does not apply")
        return rec
    try:
        get, names = {"CSV": _csv, "Parquet": _parquet, "HDF5": _hdf5}[EXTENSIONS[ext]](p)
    except PermissionError as e:
        raise DataError(f"{p}: cannot be read ({e.strerror or e}): check its permissions") from None
    except UnicodeDecodeError:
        raise DataError(f"{p}: not a text file: a {EXTENSIONS[ext]} record was expected from its extension") from None
    return _from_columns(get, names, p, controller=controller, columns=columns, force_scale=force_scale, dt=dt,
                         position_resolution=position_resolution, name=label, units=units, file_units=file_units)


# ---------------------------------------------------------------------------------------------------- robots


def _encoder_step(qm: np.ndarray) -> float:
    step = detect_resolution(qm) if np.all(np.isfinite(qm)) else None
    return float(step) if step else 0.0


def _link_columns(available: Sequence[str], names: Sequence[str], where: str) -> Dict[int, str]:
    """The file's link-side position columns, ``ql_<i>`` or ``ql_<joint name>``, of the joints that have one (a
    robot with link-side encoders on its first axes only): joint index to column."""
    found: Dict[int, str] = {}
    for j, name in enumerate(names):
        got = [c for c in (f"ql_{j + 1}", f"ql_{name}") if c in available]
        if len(set(got)) > 1:
            raise DataError(f"{where}: both ql_{j + 1} and ql_{name} are in the file: keep one (which one holds joint "
                            f"{name}'s link-side position would be a guess)")
        if got:
            found[j] = got[0]
    stray = [c for c in available if c.startswith("ql_") and c not in found.values()]
    if stray:
        raise DataError(f"{where}: column {stray[0]} names no joint of the robot ({', '.join(names)}): link-side "
                        f"positions are ql_1..ql_{len(names)} or ql_<joint name>")
    return found


def _columns(available: Sequence[str], names: Sequence[str], key: str, where: str) -> List[str]:
    """The file's columns of signal ``key`` for each joint: ``key_1 … key_n`` or ``key_<joint name>``."""
    forms = ([f"{key}_{i + 1}" for i in range(len(names))], [f"{key}_{j}" for j in names])
    complete = [form for form in forms if all(c in available for c in form)]
    if len(complete) == 2 and complete[0] != complete[1]:
        raise DataError(f"{where}: both {key}_1 … {key}_{len(names)} and {key}_<joint name> columns are in the file: "
                        f"keep one form (which one holds each joint's {key} would be a guess)")
    for form in complete:
        return form
    # the form the file comes closest to says which columns it lacks
    closest = max(forms, key=lambda f: sum(c in available for c in f))
    lacking = [c for c in closest if c not in available]
    raise DataError(f"{where}: no columns {key}_1 … {key}_{len(names)} (or {key}_<joint name>) for the robot's "
                    f"{len(names)} joints ({', '.join(names)}): {', '.join(lacking)} missing; the file has "
                    f"{', '.join(available)}. Rename the file's header to those names (a robot's record takes no "
                    "column map)")


#: A robot's positions are read to this many binary digits below its encoder step (or below its reference's span
#: where no encoder is seen): what a conversion of units moves (their last digits) is gone, so the same record in
#: degrees and in radians is the same numbers in SI (the closed loop's encoder turns a difference in the last digit
#: into whole counts some seconds later, and DIDIM's estimate by 1e-5).
READING_BITS = 24


def _reading_grid(step: float, qr: np.ndarray) -> float:
    """The dyadic grid a joint's positions are read on: 2^-READING_BITS of its encoder step, or of its reference's
    span (2^-40 of it) without one."""
    scale = step if step > 0 else float(np.ptp(qr)) * 2.0**-16
    if not (math.isfinite(scale) and scale > 0):
        return 0.0
    return 2.0 ** (math.floor(math.log2(scale)) - READING_BITS)


def _canonical(x, grid: float):
    """``x`` on the dyadic ``grid`` (unchanged when the grid is 0)."""
    if not grid:
        return x
    return np.round(np.asarray(x) / grid) * grid if np.ndim(x) else float(round(x / grid) * grid)


#: A reference beyond a joint's URDF limits by more than this share of their range is in other units than the
#: URDF's (degrees read as radians, mm as m).
LIMIT_MARGIN = 0.1


#: A jump of a revolute joint's position between two samples within this share of a whole turn (2π, in SI) is an
#: encoder's wrap, when it also exceeds :data:`WRAP_JUMP_RATIO` times the joint's largest step that is not one.
WRAP_TURN_RTOL = 0.05
WRAP_JUMP_RATIO = 20.0


#: The units a robot record's time column may declare in its header (``t[ms]``), in seconds.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}


def _check_wraps(p, names, kinds, signals, dt: float) -> None:
    """Refuses a revolute joint's position that jumps by a whole turn between two samples, once or at every turn (an
    encoder that wraps at ±π or 0..2π, logged as is): the closed loop would read it as a turn in one sample period,
    and the dynamics as positions in another unit. Jumps of more than half a turn within :data:`WRAP_TURN_RTOL` of a
    whole number of turns are wraps when each exceeds :data:`WRAP_JUMP_RATIO` times the joint's largest other step."""
    for key in ("qm", "qr"):
        for j, kind in enumerate(kinds):
            if kind == "prismatic":
                continue
            d = np.diff(signals[key][:, j])
            if d.size < 2 or not np.all(np.isfinite(d)):
                continue  # a non-finite value is refused by the record's own check, naming its sample
            turns = np.abs(d) / (2 * math.pi)
            wraps = (np.abs(d) > math.pi) & (np.abs(turns - np.round(turns)) <= WRAP_TURN_RTOL)
            if not np.any(wraps) or np.all(wraps):
                continue
            rest = float(np.max(np.abs(d[~wraps])))
            if np.all(np.abs(d[wraps]) > WRAP_JUMP_RATIO * rest):
                k = int(np.flatnonzero(wraps)[0])
                raise DataError(f"{p}: joint {names[j]}'s {key} jumps by {d[k]:.4g} rad between samples {k} and "
                                f"{k + 1}, a whole turn: its encoder wraps at one turn (at t = {(k + 1) * dt:.6g} s"
                                + (f", {int(np.sum(wraps))} times in the record" if np.sum(wraps) > 1 else "")
                                + "); unwrap the positions (numpy.unwrap) before identifying")


def _check_limits(p, robot, qr: np.ndarray, declared: bool) -> None:
    """Refuses a reference that leaves a joint's URDF limits by more than :data:`LIMIT_MARGIN` of their range: the
    URDF sets the scale of its joints' positions (rad, m), and a record in degrees or mm leaves it."""
    limits = getattr(robot, "limits", None)
    if limits is None:
        return
    for j, (lo, hi, *_rest) in enumerate(limits):
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            continue
        m = LIMIT_MARGIN * (hi - lo)
        a, b = float(np.min(qr[:, j])), float(np.max(qr[:, j]))
        if a < lo - m or b > hi + m:
            prismatic = robot.joint_kinds[j] == "prismatic"
            unit = "m" if prismatic else "rad"
            hint = ("the positions are in another unit than declared" if declared else
                    f"the positions are in another unit than {unit}: declare it (units='{'mm' if prismatic else 'deg'}', "
                    f"CLI: --units {'mm' if prismatic else 'deg'}, a header such as qr_{j + 1}[{'mm' if prismatic else 'deg'}], "
                    "or \"units\" in the controllers' file)")
            raise DataError(f"{p}: joint {robot.joint_names[j]}'s reference spans {a:.4g} to {b:.4g} {unit}, beyond "
                            f"its URDF limits {lo:.4g} to {hi:.4g} {unit}: {hint}, or the record is another robot's")


#: A record's positions are refused as in the wrong unit when the URDF's dynamics explain its force this many times
#: better with them in the other unit (rad for deg, deg for rad, m for mm, mm for m). Measured on seven arms (the data
#: folder's and held-out ones): the right angle unit leaves 4-9 % of the force unexplained, the wrong one at least 2.7
#: times that; the held-out arm's quill in mm read as m, 360 % against 4 % (its position hardly enters the others'
#: torques, so a quill in m declared in mm fits alike, 3.53 % against 3.52 %, and passes).
UNITS_RATIO = 2.0
def _refuse_if_no_unit_fits(p, rec, robot, read, here: float, there: float, other: str) -> None:
    """Refuses a record that fits the URDF's dynamics in no unit of position (the better reading ``other`` still leaves
    more than FIT_WELL unexplained): the URDF's or the record's fault, said by :func:`urdf_mismatch`."""
    from ..methods.robot import FIT_WELL, urdf_mismatch

    if here > UNITS_RATIO * there and there > FIT_WELL:
        raise DataError(f"{p}: no unit of position makes the record fit the URDF's dynamics (read in {read} they "
                        f"leave {100 * here:.0f} % of the force unexplained, in {other} at best {100 * there:.0f} %; "
                        f"a right URDF leaves under {100 * FIT_WELL:.0f} %): " + urdf_mismatch(rec, robot))


def _check_position_units(p, robot, rec: Recording) -> None:
    """Refuses a record whose positions fit the URDF's dynamics :data:`UNITS_RATIO` times better in another unit
    (:data:`didim.units.READINGS`) than in the one they were read in, for the revolute joints (rad, degrees or revolutions) and
    the prismatic ones (m, mm or µm) each as a group (a record in rad declared in degrees, in degrees or revolutions
    declared in nothing, a quill in m declared in mm): :func:`didim.methods.robot.urdf_residual`. The unit is named
    only when it brings the URDF's share under :data:`didim.methods.robot.FIT_WELL`; otherwise no unit fits, and
    the refusal says why it may be (:func:`didim.methods.robot.urdf_mismatch`). The limits catch a reference beyond
    the URDF's range; this catches the rest, in either direction."""
    from ..methods.robot import unit_readings

    if not hasattr(robot, "rnea"):  # joints known by number only (no dynamics)
        return
    for kind, joints, read_as, here, there, other in unit_readings(rec, robot):
        if len(read_as) > 1:  # joints of one kind declared in several units: each declaration judged on its joint
            _check_joint_units(p, robot, rec, joints)
            continue
        if not other:
            continue  # counts: no other reading
        read = next(iter(read_as))
        _refuse_if_no_unit_fits(p, rec, robot, read, here, there, other)
        if here > UNITS_RATIO * there:
            raise DataError(f"{p}: read in {read}, the {kind} joints' positions leave the URDF's dynamics "
                            f"{100 * here:.0f} % of the force unexplained, read in {other} {100 * there:.0f} %: the "
                            f"record is probably in {other}; declare its units (units='{other}', CLI: --units "
                            f"{other}, a header such as qr_{joints[0] + 1}[{other}], or \"units\" in the controllers' "
                            "file), or "
                            "check that the URDF is this robot's")


def _check_urdf_scale(p, robot, rec: Recording) -> None:
    """Refuses a URDF whose inverse dynamics are not finite on the record's own motion (a mass of 1e300 kg): no fit
    or check can read them."""
    from ..methods.robot import urdf_residual

    if hasattr(robot, "rnea") and not math.isfinite(urdf_residual(rec, robot)):
        raise DataError(f"{p}: the URDF's inverse dynamics are not finite on this record's motion (they overflow): a "
                        f"mass, length or inertia of {robot.source or 'the URDF'} is far out of scale; check its "
                        "numbers")


def _check_time_unit(p, robot, rec: Recording, read: str) -> None:
    """Refuses a record whose time column fits the URDF's dynamics :data:`UNITS_RATIO` times better in another unit
    of :data:`TIME_UNITS` than in the one it was read in (a time in ms read as s: a 1 s sample period, the
    accelerations a millionth of the true ones, every controller fitted from the log and every inertia a million
    times off): the same test as the positions' (:func:`_check_position_units`), the speeds divided by the factor and
    the accelerations by its square, and the drives' own inertia left out (it would take up a joint's share of
    accelerations read a factor off)."""
    from ..methods.robot import urdf_residual
    from ..recording import DT_RANGE

    if not hasattr(robot, "rnea"):  # joints known by number only (no dynamics)
        return
    tried = [(urdf_residual(rec, robot, time_factor=f / TIME_UNITS[read], drive_inertia=False), unit,
              rec.dt * f / TIME_UNITS[read])
             for unit, f in TIME_UNITS.items() if f != TIME_UNITS[read]
             and DT_RANGE[0] <= rec.dt * f / TIME_UNITS[read] <= DT_RANGE[1]]
    if not tried:
        return
    there, unit, dt = min(tried)
    here = urdf_residual(rec, robot, drive_inertia=False)
    if here > UNITS_RATIO * there:
        raise DataError(f"{p}: read in {read}, the time column t (a sample period of {rec.dt:g} s) leaves the URDF's "
                        f"dynamics {100 * here:.0f} % of the force unexplained, read in {unit} ({dt:g} s) "
                        f"{100 * there:.0f} %: its time is probably in {unit}; declare it in the header (t[{unit}]) "
                        "or convert it to s, or check that the URDF is this robot's")


def _check_force_scale(p, robot, rec: Recording) -> None:
    """A drive unit declared with its scale (``"A=2.5"``: N·m per unit) on a force already in N·m multiplies every
    parameter by it (the URDF's masses 2.5 times): refused when the force read without the scale fits the URDF's
    dynamics :data:`UNITS_RATIO` times better than with it."""
    from ..methods.robot import urdf_residual

    scales = np.array([u.force_factor for u in rec.units]) if rec.units else np.ones(rec.ndof)
    if not hasattr(robot, "rnea") or np.all(scales == 1.0):  # joints known by number only, or no scale declared
        return
    here = urdf_residual(rec, robot)
    there = urdf_residual(replace(rec, force=rec.force / scales,
                                  u_ext=None if rec.u_ext is None else rec.u_ext / scales), robot)
    if here > UNITS_RATIO * there:
        raise DataError(f"{p}: the force read with its declared drive scale ({', '.join(f'{s:g}' for s in scales)} "
                        f"N·m or N per unit) leaves the URDF's dynamics {100 * here:.0f} % of it unexplained, read as "
                        f"it is {100 * there:.0f} %: the force is probably already in N·m (or N); leave the drive unit "
                        "out of the declared units")


def _check_joint_units(p, robot, rec: Recording, joints: List[int]) -> None:
    """:func:`_check_position_units` for joints of one kind declared in several units: each joint's positions read
    in the other unit alone, the rest as declared (a joints file declaring one joint in degrees on a record in rad)."""
    from ..methods.robot import urdf_residual

    here = urdf_residual(rec, robot)
    for j in joints:
        tried = []
        for other, factor in other_readings(rec.units[j].position):
            factors = np.ones(rec.ndof)
            factors[j] = factor
            tried.append((urdf_residual(rec, robot, factors=factors), other))
        if not tried:
            continue
        read = rec.units[j].position
        there, other = min(tried)
        _refuse_if_no_unit_fits(p, rec, robot, read, here, there, other)
        if here > UNITS_RATIO * there:
            raise DataError(f"{p}: joint {rec.joint_names[j]} is read in {read}, where its positions leave the URDF's "
                            f"dynamics {100 * here:.0f} % of the force unexplained, read in {other} "
                            f"{100 * there:.0f} %: it is probably in {other}; correct its declared units (the "
                            "controllers' file's \"units\", the header or units=...)")


def _robot_file_units(path, kinds) -> Optional[list]:
    """The units a robot's controller file declares: ``"units"`` beside ``"joints"`` (all joints) and in each joint's
    entry (that joint), per joint (None when it declares none)."""
    from ..controllers import _spec
    from ..units import for_joints

    where, spec = _spec(path)
    if not isinstance(spec, dict):
        return None
    where = f"{where}"
    whole = for_joints(spec.get("units"), kinds, f"{where}: \"units\"")
    entries = spec.get("joints") if isinstance(spec.get("joints"), list) else []
    each = [e.get("units") if isinstance(e, dict) else None for e in entries]
    if len(each) != len(kinds) or all(e is None for e in each):
        return whole
    per = for_joints(each, kinds, f"{where}: the joints' \"units\"")
    assert per is not None
    out = []
    for j, u in enumerate(per):
        if each[j] is None:
            out.append(whole[j] if whole is not None else u)
        elif whole is not None and whole[j] != u:
            raise DataError(f"{where}: joint {j + 1} is declared in {u.describe()} in its entry and in "
                            f"{whole[j].describe()} beside \"joints\": give one")
        else:
            out.append(u)
    return out


def _joints_logged(available: Sequence[str], names: Sequence[str]) -> Optional[int]:
    """The number of joints a robot record's numbered columns were logged for, when it is not the robot's: more
    (a qr_, force_, qm_ or u_ext_ column numbered beyond the robot's joints: the highest number), or fewer (qr_, force_
    and qm_ all numbered 1..k alike for k below the joints, and no column named after a joint); None otherwise (a
    header to rename is left to :func:`_columns`' message, which names the columns missing)."""
    beyond = [int(c.split("_")[-1]) for c in available
              if re.fullmatch(r"(qr|force|qm|u_ext)_\d+", c) and int(c.split("_")[-1]) > len(names)]
    if beyond:
        return max(beyond)
    logged = {key: next(k for k in range(len(names) + 1) if f"{key}_{k + 1}" not in available)
              for key in ("qr", "force", "qm")}
    if len(set(logged.values())) == 1 and 0 < logged["qr"] < len(names) \
            and not any(f"qr_{j}" in available for j in names):
        return logged["qr"]
    return None


def load_robot_record(path, robot: "Robot", *, controller: Any = None, name: Optional[str] = None,
                      units: Any = None, beside_controller: bool = True, lead_in: Any = "auto",
                      table: Optional[Tuple[Callable[[str], np.ndarray], List[str]]] = None) -> Recording:
    """A robot record from a CSV, Parquet or HDF5 file with columns ``t, qr_1..qr_n, force_1..force_n, qm_1..qm_n``
    in ``robot``'s joint order (or ``qr_<joint name>``…), positions in rad (prismatic joints: m), forces in N·m (N),
    unless the record declares other units: ``units`` (``"deg"``, ``"deg,mm"``, one per joint:
    :func:`didim.units.for_joints`), a header suffix (``qr_1[deg]``), or ``"units"`` in the controllers' file (for
    all joints, or in a joint's entry); declarations that disagree are refused. Positions, encoder steps and the
    controllers are converted to SI once. ``controller``: the joints' controllers (a sequence, one per joint) or
    the path of their file; by default ``NAME_controller.json`` beside the record (unless ``beside_controller`` is
    False), and without one each joint's linear law is fitted from its log (:func:`didim.fit_controller`;
    ``Recording.controller_origin`` says so). ``table``: the columns already read (a column getter and the
    columns' names: :func:`from_dataframe`), ``path`` then only names them."""
    from ..units import for_joints

    if table is None:
        p = check_input(path, "robot record")
        ext = os.path.splitext(p)[1].lower()
        kind = EXTENSIONS.get(ext)
        if kind not in ("CSV", "Parquet", "HDF5"):
            raise DataError(f"{p}: a robot record is a CSV, Parquet or HDF5 file, got {ext or 'no extension'!r}")
        if os.path.getsize(p) == 0:
            raise DataError(f"{p}: the file is empty (0 bytes)")
    else:
        p, beside_controller = str(path), False
    if controller is None and beside_controller:
        controller = beside(p)  # NAME_controller.json beside the record, if there is one
    kinds = list(robot.joint_kinds)
    declared = []  # (where, per-joint units)
    delay: Tuple[int, ...] = ()
    force_lag: Tuple[float, ...] = ()
    # a joints file, by its path or its content (a mapping {"type": "joints", "joints": [...]})
    as_file = isinstance(controller, (str, os.PathLike)) or (isinstance(controller, Mapping)
                                                              and controller.get("type") == "joints")
    controller_file = (controller if not isinstance(controller, Mapping) else "the controllers' mapping") \
        if as_file else None
    if as_file:
        file_units = _robot_file_units(controller, kinds)
        if file_units is not None:
            declared.append((f"the controller file {controller_file}", file_units))
        delay, force_lag = load_joint_drives(controller)
        controller = load_joint_controllers(controller)
    if controller is not None and not isinstance(controller, (list, tuple)):
        raise DataError(f"{p}: a robot's record takes one controller per joint ({len(kinds)}: "
                        f"{', '.join(robot.joint_names)}): give a joints file (its path, or its content as a "
                        "mapping {\"type\": \"joints\", \"joints\": [...]}) or a list of controllers, got one "
                        f"{type(controller).__name__}")
    controllers = tuple(controller) if controller is not None else None
    arg_units = for_joints(units, kinds, "units")
    if arg_units is not None:
        declared.append(("units=" + (units if isinstance(units, str) else "..."), arg_units))
    try:
        get, available = table if table is not None else {"CSV": _csv, "Parquet": _parquet, "HDF5": _hdf5}[kind](p)
    except UnicodeDecodeError:
        raise DataError(f"{p}: not a text file: a {kind} record was expected from its extension") from None
    names = robot.joint_names
    # a header's "[unit]" suffixes: qr_1[deg] is column qr_1 in degrees
    suffix: Dict[str, str] = {}
    plain = []
    for c in available:
        m = re.fullmatch(r"\s*(.*?)\s*\[(.+)\]\s*", c)
        plain.append(m.group(1) if m else c)
        if m:
            suffix[m.group(1)] = m.group(2).strip()
    if plain != list(available):
        twice = sorted({c for c in plain if plain.count(c) > 1})
        if twice:
            raise DataError(f"{p}: column(s) {', '.join(twice)} appear more than once in the header (with different "
                            "units): rename one")
        raw_get, by_plain = get, dict(zip(plain, available))
        get, available = (lambda c: raw_get(by_plain[c])), plain
    if "t" not in available:
        raise DataError(f"{p}: no time column t; the file has {', '.join(available)}")
    t_unit = suffix.get("t", "s")
    if t_unit not in TIME_UNITS:
        raise DataError(f"{p}: the time column's unit [{t_unit}] is not one didim reads: give it in "
                        f"{', '.join(TIME_UNITS)} (t[ms], for instance)")
    dt = _time_step(np.asarray(get("t"), dtype=float) * TIME_UNITS[t_unit], f"{p}: ")
    k = _joints_logged(available, names)
    if k is not None:
        # another robot's record (or the robot another's), not a header to rename
        fewer = k < len(names)
        raise DataError(f"{p}: the record has columns for {k} joint{'s' if k != 1 else ''} (qr_1..qr_{k}, force_…, "
                        f"qm_…) but the robot has {len(names)} "
                        f"({', '.join(names)}): "
                        + ("is this the robot's record (or the result's robot this record's)? Give the record of the "
                           "robot, or the robot (URDF, --joints) of the record" if fewer else
                           "the URDF (or the controller file) is another robot's, or --joints picks fewer joints "
                           "than were logged"))
    cols = {key: _columns(available, names, key, p) for key in ("qr", "force", "qm")}
    # a feedforward the drives add to the commands: u_ext_1..u_ext_n (or u_ext_<joint name>), every joint's or none
    if any(c.startswith("u_ext_") for c in available):
        cols["u_ext"] = _columns(available, names, "u_ext", p)
    signals = {key: np.column_stack([np.asarray(get(c), dtype=float).ravel() for c in cols[key]]) for key in cols}
    # link-side encoders (ql_1..ql_n or ql_<joint name>) on some joints or all: a joint without one reads NaN
    ql = _link_columns(available, names, p)
    if ql:
        signals["ql"] = np.column_stack([np.asarray(get(ql[j]), dtype=float).ravel() if j in ql
                                         else np.full(len(signals["qr"]), np.nan) for j in range(len(names))])
        for j, c in ql.items():
            cols.setdefault("ql", [None] * len(names))[j] = c
    if any(c in suffix for key in cols for c in cols[key]):
        head = []
        for j in range(len(names)):
            pos = {suffix[c] for c in (cols["qr"][j], cols["qm"][j], *cols.get("ql", [None] * len(names))[j:j + 1])
                   if c in suffix}
            if len(pos) > 1:
                raise DataError(f"{p}: joint {names[j]}'s positions are in several units ({', '.join(sorted(pos))})")
            forces = {suffix[cols[key][j]] for key in ("force", "u_ext") if key in cols and cols[key][j] in suffix}
            if len(forces) > 1:
                raise DataError(f"{p}: joint {names[j]}'s force and u_ext are in different units "
                                f"({', '.join(sorted(forces))}): give them in one")
            force = forces.pop() if forces else None
            text = ",".join([*pos] + ([force] if force and force not in ("N", "N*m", "N·m", "Nm") else []))
            head.append(text or None)
        declared.append(("the header", for_joints(head, kinds, f"{p}: the header")))
    u = None
    for where, got in declared:
        if u is None:
            u, first = got, where
            continue
        for j in range(len(names)):
            if got[j] != u[j]:
                raise DataError(f"{p}: joint {names[j]} is in {u[j].describe()} by {first} but in "
                                f"{got[j].describe()} by {where}: declare its units once")
    origin: Tuple[str, ...] = ()
    if controllers is None:  # nobody described them: each joint's linear law from its own log, in SI
        from ..controller_fit import fit_controller

        fits = []
        for j in range(len(names)):
            k, ff = (u[j].position_factor, u[j].force_factor) if u is not None else (1.0, 1.0)
            try:
                fits.append(fit_controller(dict(dt=dt, qr=signals["qr"][:, j] * k, qm=signals["qm"][:, j] * k,
                                                 force=signals["force"][:, j] * ff, name=f"{p}: joint {names[j]}")))
            except DataError as e:
                raise DataError(f"{e}. No controller was given (controller=..., CLI: --controller FILE, or "
                                f"{os.path.splitext(p)[0]}_controller.json beside the record), so didim tried to fit "
                                "each joint's from the log") from None
        controllers = tuple(f.controller for f in fits)
        origin = tuple(f"joint {j}: {f.summary()}" for j, f in zip(names, fits))
        converted = True
    else:
        converted = False
    if len(controllers) != len(names):
        where = f"{controller_file}: " if controller_file is not None else ""
        raise DataError(f"{where}{len(controllers)} controllers for the {len(names)} joints of the robot of {p} "
                        f"({', '.join(names)}): give one per joint, in the URDF's order (is it another robot's "
                        "controller file?)")
    if u is not None:
        for j in range(len(names)):
            k, ff = u[j].position_factor, u[j].force_factor
            for key, factor in (("qr", k), ("qm", k), ("ql", k), ("force", ff), ("u_ext", ff)):
                if key in signals:
                    signals[key][:, j] *= factor
            if converted:
                continue  # fitted on SI signals already
            try:
                controllers = controllers[:j] + (in_units(controllers[j], dt, k, ff),) + controllers[j + 1:]
            except DataError as e:
                raise DataError(f"{p}: joint {names[j]}: {e}") from None
    _check_wraps(p, names, kinds, signals, dt)
    _check_limits(p, robot, signals["qr"], u is not None)
    steps = []
    for j in range(len(names)):
        step = _encoder_step(signals["qm"][:, j])
        grid = _reading_grid(step, signals["qr"][:, j])
        steps.append(_canonical(step, grid))
        for key in ("qr", "qm"):
            signals[key][:, j] = _canonical(signals[key][:, j], grid)
    steps = tuple(steps)
    label = name if name is not None else os.path.splitext(os.path.basename(p))[0]
    try:
        rec = Recording(dt=dt, joint_names=tuple(names), controller=controllers, position_resolution=steps, name=label,
                             joint_kinds=tuple(kinds), **signals, delay=delay, force_lag=force_lag,
                             units=tuple(u) if u is not None else (), controller_origin=origin,
                             lead_in=lead_in)
    except DataError as e:
        raise DataError(f"{p}: {e}") from None
    from ..methods.robot import MIN_SAMPLES, STATE_FILTER_ORDER

    if rec.n < MIN_SAMPLES:
        raise DataError(f"{p}: the record has {rec.n} samples ({rec.n * dt:.4g} s): a robot's states are filtered "
                        f"without phase (a {STATE_FILTER_ORDER}th-order low-pass padded with {MIN_SAMPLES - 1} samples "
                        f"at each end), which needs at least {MIN_SAMPLES} samples, and a fit a motion that excites "
                        "every joint: log a longer record")
    _check_urdf_scale(p, robot, rec)
    _check_time_unit(p, robot, rec, t_unit)
    _check_position_units(p, robot, rec)
    _check_force_scale(p, robot, rec)
    return rec


def from_dataframe(df, *, controller: Any, columns: Optional[Mapping[str, str]] = None,
                   force_scale: float = 1.0, dt: Optional[float] = None,
                   position_resolution: Union[None, float, str] = "auto", name: str = "",
                   units: Any = None, robot: Optional["Robot"] = None) -> Recording:
    """A record from a pandas DataFrame (or any mapping of column name to array), as :func:`load_record`: one axis's,
    or with ``robot`` a robot's (columns ``t, qr_1..qr_n, force_1..force_n, qm_1..qm_n``, as
    :func:`load_robot_record` reads them from a file; ``controller`` one per joint or a joints file).

    A DataFrame whose index is the time may be passed with ``df.reset_index()`` or ``dt=`` (one axis)."""
    try:
        names = [str(c) for c in df.columns] if hasattr(df, "columns") else [str(c) for c in df.keys()]
    except Exception:
        raise DataError(f"from_dataframe needs a pandas DataFrame or a mapping of columns, got {type(df).__name__}") \
            from None

    def get(c: str) -> np.ndarray:
        col = df[c]
        return col.to_numpy() if hasattr(col, "to_numpy") else np.asarray(col)

    if robot is not None:
        given = [k for k, v in (("columns", columns), ("force_scale", force_scale != 1.0), ("dt", dt),
                                ("position_resolution", position_resolution != "auto")) if v]
        if given:
            raise DataError(f"from_dataframe: {', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to one "
                            "axis's record; a robot's has a time column t and its joints' columns qr_1.., force_1.., "
                            "qm_1.. (units: units=...)")
        return load_robot_record(name or "DataFrame", robot, controller=controller, name=name or None, units=units,
                                 table=(get, names))
    return _from_columns(get, names, name or "DataFrame", controller=controller, columns=columns,
                         force_scale=force_scale, dt=dt, position_resolution=position_resolution, name=name,
                         units=units)


# ---------------------------------------------------------------------------------------------------- MAT (EMPS)

#: :func:`load_mat` takes the pulses' gain from the log only within this distance of 1: further, the log and the
#: pulses disagree on more than a calibration, and the record is loaded with gain 1 (``diagnose`` then says so).
PULSES_GAIN_RANGE = 0.2


def _scalar(d: dict, key: str, path: str) -> float:
    a = np.asarray(d[key])
    if a.size != 1 or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise DataError(f"{path}: variable {key!r} must be a single number, got shape {a.shape} of {a.dtype}")
    v = float(a.ravel()[0])
    if not math.isfinite(v):
        raise DataError(f"{path}: variable {key!r} is not finite ({v})")
    return v


def load_mat(
    path, *, position_resolution: Optional[float] = None, name: Optional[str] = None, dt: Optional[float] = None,
    pulses_gain: Union[float, str] = "log", lead_in: Union[str, None, np.ndarray] = "auto",
) -> Recording:
    """Loads a record in the EMPS benchmark layout (MATLAB v4/v5/v7 ``.mat``; not v7.3, which is HDF5).

    Variables: ``t`` (s), ``qm`` (m), ``qg`` (the reference, m), ``vir`` (the drive command, V), ``gtau`` (N/V),
    ``kp`` (1/s), ``kv`` (V/(m/s)); optional ``pulses_N``, the disturbance injected at the drive input (in V,
    despite its name; ``vir`` already contains it, so the measured force is ``gtau·vir`` and the known external
    force ``gtau·pulses_N``), optional ``ql``, the load position of an axis with a second encoder, and optional
    ``vsat`` (V, 10 by default, the EMPS drive's limit). ``dt`` (s), when given, is the sample period the caller
    expects: a file whose time step differs is refused.

    ``pulses_gain``: the pulses enter ``vir`` with a gain of their own (DATA_EMPS_PULSES: ``vir`` = the controller's
    output + 1.0138·``pulses_N``, to 0.005 V RMS), and the axis gets ``gtau·vir``: the known external force is
    ``pulses_gain·gtau·pulses_N``. ``"log"`` (default) takes the gain from the log (:meth:`Recording.u_ext_gain`),
    kept at 1 when the log cannot tell it from 1 (within 5 σ) or when it is more than 20 % from 1 (which
    ``diagnose`` then reports); a number sets it (1: the benchmark's ``pulses_N`` as it is). Ignored for a file
    without ``pulses_N``. With the gain of the log, the benchmark's published model simulates DATA_EMPS_PULSES to
    5.13 % instead of 5.26 % (from rest on the first sample, ``lead_in=None``: 6.03 % instead of 6.14 %).

    ``lead_in``: see :class:`Recording` (``"auto"``: both EMPS records begin 16 ms into the move and get one; None:
    the simulation starts at rest on the first sample, as the paper).

    Raises :class:`DataError` naming the file and the problem: missing, unreadable or truncated file, not a MAT
    file, missing variable, wrong shape or type, time not increasing or not uniform, a period other than ``dt``.
    The file is only read.
    """
    from scipy.io import loadmat, whosmat

    from ._io import check_input

    path = check_input(path, "MAT file")
    try:
        with open(path, "rb") as f:
            head = f.read(128)
    except OSError as e:
        raise DataError(f"{path}: cannot be read ({e.strerror or e}): check its permissions") from None
    size = os.path.getsize(path)
    if size == 0:
        raise DataError(f"{path}: the file is empty (0 bytes): copy it again from its source")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns on odd headers before failing or succeeding
            # only the variables a record needs are decompressed, after their sizes are read from their headers: an
            # unused variable (or a decompression bomb) is never expanded
            source = _mat5_needed(path, MAT_VARIABLES, MAX_MAT_SAMPLES)
            d = loadmat(source if source is not None else path, variable_names=list(MAT_VARIABLES))
    except PermissionError as e:
        raise DataError(f"{path}: cannot be read ({e.strerror or e}): check its permissions") from None
    except NotImplementedError:
        raise DataError(
            f"{path}: MATLAB v7.3 (HDF5) files are not supported: save it with save(..., '-v7') in MATLAB, or read "
            "it with h5py and build a didim.Recording"
        ) from None
    except DataError:  # a variable's header says it is too large: the file is readable, the record too long
        raise
    except Exception as e:  # scipy raises several types for corrupt files
        if head.startswith(b"MATLAB") or head[:4] in _MAT4_HEADS:
            raise DataError(
                f"{path}: truncated or corrupt MAT file ({size} bytes; {type(e).__name__}: {e}): copy it again from "
                "its source"
            ) from None
        raise DataError(f"{path}: not a readable MATLAB .mat file ({type(e).__name__}: {e})") from None
    required = ("t", "qm", "qg", "vir", "gtau", "kp", "kv")
    missing = [k for k in required if k not in d]
    if missing:
        present = sorted(k for k in d if not k.startswith("__"))
        if size < 50_000_000:  # name the file's other variables (scipy decompresses them to list them)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    present = sorted(name for name, _, _ in whosmat(path))
            except Exception:
                pass
        hint = "; the file holds no variable at all: is it truncated?" if not present else ""
        raise DataError(
            f"{path}: missing variable(s) {', '.join(missing)}; the EMPS layout needs {', '.join(required)} "
            f"(found: {', '.join(present) or 'none'}){hint}"
        )

    def vec(key: str) -> np.ndarray:
        a = np.asarray(d[key])
        if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
            raise DataError(f"{path}: variable {key!r} must be real numbers, got {_kind(d[key])}")
        if a.ndim != 2 or min(a.shape) != 1:
            raise DataError(f"{path}: variable {key!r} must be a vector (N x 1), got shape {a.shape}")
        return a.astype(float).ravel()

    try:
        t = _signal(f"{path}: t", vec("t"))
        n = t.shape[0]
        step = _time_step(t, f"{path}: ")
        if dt is not None:
            _check_expected_dt(step, dt, f"{path}: ")
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
        rec = Recording(
            dt=step,
            qr=_signal(f"{path}: qg", vec("qg"), n),
            force=force,
            qm=_signal(f"{path}: qm", vec("qm"), n),
            controller=ctrl,
            ql=ql,
            u_ext=u_ext,
            position_resolution=position_resolution,
            name=name if name is not None else os.path.splitext(os.path.basename(path))[0],
            lead_in=lead_in,
        )
        if u_ext is None:
            return rec
        if isinstance(pulses_gain, str):
            if pulses_gain != "log":
                raise DataError(f"pulses_gain must be 'log' or a number, got {pulses_gain!r}")
            g, se = rec.u_ext_gain()  # 1 where the log cannot tell it from 1
            gain = g if math.isfinite(g) and 5 * se < abs(g - 1) <= PULSES_GAIN_RANGE else 1.0
        else:
            gain = _number("pulses_gain", pulses_gain, "a ratio")
            if not (math.isfinite(gain) and gain > 0):
                raise DataError(f"pulses_gain must be a finite number > 0 (or 'log'), got {pulses_gain!r}")
        return rec if gain == 1.0 else replace(rec, u_ext=gain * u_ext)
    except DataError as e:
        msg = str(e)
        raise DataError(msg if msg.startswith(path) else f"{path}: {msg}") from None


#: The variables of the EMPS layout that load_mat reads (the others are never decompressed).
MAT_VARIABLES = ("t", "qm", "qg", "vir", "gtau", "kp", "kv", "vsat", "pulses_N", "ql")
#: Most samples of a record read from a MAT file (each signal then takes up to 400 MB in memory).
MAX_MAT_SAMPLES = 50_000_000


def _mat5_needed(path: str, names, max_values: int):
    """A MATLAB v5 file reduced to the variables ``names`` (an in-memory copy of their raw, still compressed records
    behind the file's header), after checking from each variable's header that it holds at most ``max_values``
    values; None for another format (v4, which has no compression, is read as it is). Only the first bytes of each
    compressed variable are decompressed, to read its name and dimensions."""
    import io
    import struct
    import zlib

    with open(path, "rb") as f:
        raw = f.read()
    if len(raw) < 128 or not raw.startswith(b"MATLAB 5.0") or raw[126:128] not in (b"IM", b"MI"):
        return None
    e = "<" if raw[126:128] == b"IM" else ">"
    keep = [raw[:128]]
    pos = 128
    while pos + 8 <= len(raw):
        mdtype, count = struct.unpack(e + "II", raw[pos:pos + 8])
        end = pos + 8 + count
        if count == 0 or end > len(raw):
            return None  # truncated or odd: scipy reads it and says what is wrong
        if mdtype == 15:  # miCOMPRESSED: decompress a bounded prefix only
            head = zlib.decompressobj().decompress(raw[pos + 8:end], 4096)
        elif mdtype == 14:  # miMATRIX
            head = raw[pos:pos + 4096]
        else:
            return None
        info = _mat5_header(head, e)
        if info is None:
            return None
        name, dims = info
        if name in names:
            size = int(np.prod(dims, dtype=np.int64)) if dims else 1
            if size > max_values:
                raise DataError(f"{path}: variable {name!r} has {size} values (shape {tuple(dims)}); didim reads records "
                                f"of at most {max_values} samples: split the record")
            keep.append(raw[pos:end])
        pos = end + ((-count) % 8 if mdtype == 14 else 0)
    return io.BytesIO(b"".join(keep))


def _mat5_header(head: bytes, e: str):
    """(name, dims) of a v5 miMATRIX element from its first bytes, or None."""
    import struct

    if len(head) < 40:
        return None
    mdtype, _ = struct.unpack(e + "II", head[:8])
    if mdtype != 14:
        return None
    p = 8 + 16  # array flags: an 8-byte tag and 8 bytes
    dtype, count = struct.unpack(e + "II", head[p:p + 8])
    if dtype != 5 or count % 4 or p + 8 + count > len(head):  # dimensions: miINT32
        return None
    dims = list(struct.unpack(e + f"{count // 4}i", head[p + 8:p + 8 + count]))
    p += 8 + count + ((-count) % 8)
    if p + 8 > len(head):
        return None
    first = struct.unpack(e + "I", head[p:p + 4])[0]
    if first >> 16:  # small data element: type and length packed in the tag, name in its last 4 bytes
        n = first >> 16  # the byte count is the upper half in either byte order (as scipy reads it)
        name = head[p + 4:p + 4 + n]
    else:
        n = struct.unpack(e + "I", head[p + 4:p + 8])[0]
        name = head[p + 8:p + 8 + n]
    return name.decode("latin-1"), dims


#: First bytes of MATLAB v4 files (no text header): the type code of a double matrix, either byte order.
_MAT4_HEADS = (b"\x00\x00\x00\x00", b"\xe8\x03\x00\x00", b"\x00\x00\x03\xe8")


def _kind(a) -> str:
    if hasattr(a, "tocsc"):
        return "a sparse matrix (save it with full(...) in MATLAB)"
    a = np.asarray(a)
    if a.dtype.kind == "U":
        return "text"
    if a.dtype.kind == "O":
        return "a cell array"
    if a.dtype.names:
        return "a struct"
    return str(a.dtype)


__all__ = ["load_record", "load_mat", "from_dataframe", "detect_resolution", "parse_columns", "REQUIRED", "OPTIONAL"]
