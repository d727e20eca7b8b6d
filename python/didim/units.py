"""The units a record is logged in, and the words and labels of every number didim prints for it.

didim computes in SI on the load side: metres or radians, newtons or newton-metres. A record logged in other units
declares them (:class:`Units`: ``load_record(path, units="deg")``, ``--units deg``, a CSV header ``qm[deg]``, or
``"units"`` in the controller file); the loaders convert positions, the encoder step and the controller's
coefficients to SI once, and the record remembers whether its axis is linear or rotary, so that every parameter,
speed and length is printed with the axis's units (kg·m², N·m·s/rad, rad/s for a rotary axis).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Tuple, Union

from ._errors import DataError

#: Position units: SI per unit, and whether the axis is rotary. ``counts`` needs ``counts_per`` (per m or per rev).
POSITION_UNITS: Dict[str, tuple] = {
    "m": (1.0, False), "mm": (1e-3, False), "um": (1e-6, False), "µm": (1e-6, False), "μm": (1e-6, False),
    "rad": (1.0, True), "deg": (math.pi / 180.0, True), "rev": (2.0 * math.pi, True),
}
#: Force units: SI per unit and whether it is a torque. A drive unit (V, A, %, or any other name) needs a scale.
FORCE_UNITS: Dict[str, tuple] = {"N": (1.0, False), "N*m": (1.0, True), "N·m": (1.0, True), "Nm": (1.0, True),
                                 "kN": (1e3, False)}
#: A linear stroke beyond this many metres is no machine axis: the positions are in another unit (mm read as m).
MAX_LINEAR_STROKE_M = 50.0

#: The units of position the dynamics can tell apart, an angle in rad, degrees or revolutions, a length in m, mm or
#: µm (:data:`POSITION_UNITS`): a robot's record read in one of them is tried in each other of its kind
#: (the loader checks them, :mod:`didim.formats.loaders`; :func:`didim.methods.robot.units_hint` names one in a failed
#: fit).
READINGS = ("rad", "deg", "rev", "m", "mm", "um")


def other_readings(read: str) -> List[Tuple[str, float]]:
    """The other readings of positions read in ``read`` (one of :data:`READINGS`), each with the factor that takes
    the positions read in ``read`` to them (both in SI): rad for deg is π/180, rev for rad 2π. Empty for a unit
    without one (counts, whose count per turn only the user knows)."""
    if read not in READINGS:
        return []
    si, rotary = POSITION_UNITS[read]
    return [(x, POSITION_UNITS[x][0] / si) for x in READINGS if x != read and POSITION_UNITS[x][1] == rotary]


#: The SI unit of a linear axis's quantity and its rotary counterpart (load side).
ROTARY = {"kg": "kg·m²", "N/(m/s)": "N·m·s/rad", "N/m": "N·m/rad", "N": "N·m", "m": "rad", "m/s": "rad/s",
          "m/s²": "rad/s²", "N/(m/s)²": "N·m·s²/rad²"}


@dataclass(frozen=True)
class Units:
    """The units of a record: ``position`` (m, mm, um, rad, deg, rev, or counts with ``counts_per`` counts per m or,
    with ``per="rev"``, per revolution) and ``force`` (N, N*m, or a drive unit such as V or A with ``force_scale``
    N or N·m per unit, and ``torque`` saying which). SI (m, N) by default."""

    position: str = "m"
    force: str = "N"
    counts_per: Optional[float] = None
    per: str = "m"
    force_scale: float = 1.0
    torque: Optional[bool] = None

    def __post_init__(self) -> None:
        if self.position == "counts":
            if self.counts_per is None or not (isinstance(self.counts_per, (int, float)) and math.isfinite(self.counts_per)
                                               and self.counts_per > 0):
                raise DataError("positions in encoder counts need the number of counts per m or per revolution: "
                                "units='counts/rev=1048576' or 'counts/m=2e6' (Python: Units('counts', counts_per=..., "
                                "per='rev'))")
            if self.per not in ("m", "rev"):
                raise DataError(f"counts are per 'm' or per 'rev', got {self.per!r}")
        elif self.position not in POSITION_UNITS:
            raise DataError(f"unknown position unit {self.position!r}: use one of {', '.join(_POSITION_NAMES)}, or "
                            "counts/rev=N or counts/m=N for an encoder's counts")
        if self.force not in FORCE_UNITS:
            if not (isinstance(self.force_scale, (int, float)) and math.isfinite(self.force_scale) and self.force_scale > 0):
                raise DataError(f"a force logged in {self.force!r} needs its scale (N or N·m per {self.force}): "
                                f"units='...,{self.force}=2.5' or force_scale=2.5")
        torque = FORCE_UNITS[self.force][1] if self.force in FORCE_UNITS else self.torque
        if torque is not None and bool(torque) != self.rotary:
            what = "a torque" if torque else "a force"
            raise DataError(f"the force is {what} ({self.force}) but the positions are {self.position}: a "
                            f"{'rotary' if self.rotary else 'linear'} axis's effort is "
                            f"{'a torque (N*m)' if self.rotary else 'a force (N)'}")

    @property
    def rotary(self) -> bool:
        """True when the positions are angles (rad, deg, rev, counts per rev)."""
        if self.position == "counts":
            return self.per == "rev"
        return POSITION_UNITS[self.position][1]

    @property
    def axis(self) -> str:
        return "rotary" if self.rotary else "linear"

    @property
    def position_factor(self) -> float:
        """SI (m or rad) per unit of the logged positions."""
        if self.position == "counts":
            assert self.counts_per is not None
            return (2.0 * math.pi if self.per == "rev" else 1.0) / self.counts_per
        return POSITION_UNITS[self.position][0]

    @property
    def force_factor(self) -> float:
        """N (or N·m) per unit of the logged force."""
        return FORCE_UNITS[self.force][0] if self.force in FORCE_UNITS else float(self.force_scale)

    @property
    def is_si(self) -> bool:
        return self.position_factor == 1.0 and self.force_factor == 1.0

    def describe(self) -> str:
        pos = (f"counts ({self.counts_per:g} per {self.per})" if self.position == "counts" else self.position)
        force = self.force if self.force in FORCE_UNITS else f"{self.force} ({self.force_scale:g} {'N·m' if self.rotary else 'N'} each)"
        return f"positions in {pos}, force in {force}"

    def to_dict(self) -> Dict[str, Any]:
        d: Dict[str, Any] = {"position": self.position, "force": self.force}
        if self.position == "counts":
            d.update(counts_per=self.counts_per, per=self.per)
        if self.force not in FORCE_UNITS:
            d["force_scale"] = self.force_scale
        return d


_POSITION_NAMES = ("m", "mm", "um", "rad", "deg", "rev")
SI = Units()


def parse(spec: Union[None, str, Mapping[str, Any], Units], *, force_scale: Optional[float] = None) -> Optional[Units]:
    """Units from their text (``"deg"``, ``"rad,N*m"``, ``"counts/rev=1048576"``, ``"mm,V=2.5"``), a mapping (a
    controller file's ``"units"``) or a :class:`Units`; None stays None (not declared)."""
    if spec is None or isinstance(spec, Units):
        return spec
    if isinstance(spec, Mapping):
        known = {"position", "force", "counts_per", "per", "force_scale"}
        extra = set(spec) - known
        if extra:
            raise DataError(f"unknown units field(s) {', '.join(sorted(extra))}: the fields are {', '.join(sorted(known))}")
        return Units(**{k: spec[k] for k in spec})
    if not isinstance(spec, str):
        raise DataError(f"units must be text such as 'deg' or 'rad,N*m', got {type(spec).__name__}")
    pos, force, counts, per, scale = "m", None, None, "m", 1.0
    for part in (p.strip() for p in spec.split(",") if p.strip()):
        m = re.fullmatch(r"counts\s*/\s*(m|rev)\s*=\s*([0-9.eE+-]+)", part)
        if m:
            pos, per, counts = "counts", m.group(1), _number(m.group(2), part)
            continue
        name, eq, value = part.partition("=")
        name = name.strip()
        if name == "counts":
            Units("counts")  # says what is missing
        if name in POSITION_UNITS:
            pos = name
        elif name in FORCE_UNITS and not eq:
            force = name
        elif eq:  # a drive unit with its scale
            force, scale = name, _number(value, part)
        else:
            raise DataError(f"units {spec!r}: {part!r} is not a position unit ({', '.join(_POSITION_NAMES)}, "
                            "counts/rev=N, counts/m=N) nor a force unit (N, N*m, or a drive unit with its scale as "
                            "V=2.5)")
    rotary = pos == "counts" and per == "rev" or (pos in POSITION_UNITS and POSITION_UNITS[pos][1])
    if force is None:
        force = "N*m" if rotary else "N"
        if force_scale is not None and force_scale != 1.0:
            force, scale = "drive unit", float(force_scale)
    return Units(pos, force, counts, per, scale, torque=rotary if force not in FORCE_UNITS else None)


def from_header(names) -> tuple:
    """The column names without their ``[unit]`` suffixes, and the position and force units they declare (None
    when none does). Positions must agree: ``qr[deg]`` with ``qm[rad]`` is refused."""
    plain, pos, force = [], set(), set()
    for n in names:
        m = re.fullmatch(r"\s*(.*?)\s*\[(.+)\]\s*", n)
        if not m:
            plain.append(n)
            continue
        plain.append(m.group(1))
        (force if m.group(1).lower() in ("force", "tau", "torque", "u_ext") else pos).add(m.group(2).strip())
    if len(pos) > 1:
        raise DataError(f"the header gives the positions in several units ({', '.join(sorted(pos))}); didim needs them "
                        "in one")
    if len(force) > 1:
        raise DataError(f"the header gives the forces in several units ({', '.join(sorted(force))})")
    text = ",".join([*pos, *force])
    return plain, (parse(text) if text else None)


def _number(text: str, where: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise DataError(f"units: {where!r} needs a number after '='") from None
    if not (math.isfinite(x) and x > 0):
        raise DataError(f"units: {where!r} needs a finite number > 0")
    return x


def label(si_unit: str, axis: str) -> str:
    """The unit of a quantity whose linear-axis SI unit is ``si_unit``, on a ``"linear"`` or ``"rotary"`` axis."""
    if axis != "rotary":
        return si_unit
    return ROTARY.get(si_unit, si_unit)


def length(x: float, axis: str) -> str:
    """A position or distance with its unit: mm on a linear axis, rad (and degrees) on a rotary one."""
    if axis == "rotary":
        return f"{_g(x)} rad ({_g(math.degrees(x))}°)"
    return f"{_g(1e3 * x)} mm"


def speed(v: float, axis: str) -> str:
    """A speed with its unit: mm/s on a linear axis, rad/s on a rotary one."""
    if axis == "rotary":
        return f"{_g(v)} rad/s"
    return f"{_g(1e3 * v)} mm/s"


def force(f: float, axis: str) -> str:
    return f"{_g(f)} {'N·m' if axis == 'rotary' else 'N'}"


def force_unit(axis: str) -> str:
    """N on a linear axis, N·m on a rotary one."""
    return "N·m" if axis == "rotary" else "N"


def plot_length(axis: str) -> tuple:
    """The factor and unit a plot shows positions in: mm on a linear axis, rad on a rotary one."""
    return (1.0, "rad") if axis == "rotary" else (1e3, "mm")


def _g(x: float) -> str:
    return f"{x:.4g}"


def check_stroke(qr, units: Units, where: str) -> None:
    """Refuses positions declared in metres whose stroke no machine axis has (400 "m": millimetres read as m)."""
    import numpy as np

    if units.rotary:
        return
    stroke = float(np.ptp(qr)) * units.position_factor
    if stroke > MAX_LINEAR_STROKE_M:
        guess = "mm" if stroke / 1e3 <= MAX_LINEAR_STROKE_M else "um"
        raise DataError(f"{where}: the reference spans {stroke:.4g} m, more than any machine axis "
                        f"({MAX_LINEAR_STROKE_M:g} m): the positions are in another unit than {units.position}, "
                        f"{guess} on a linear axis, or rad, deg, rev or encoder counts on a rotary one; declare it, "
                        f"e.g. units='{guess}', units='rad' or units='deg' (CLI: --units {guess}, or a CSV header such "
                        f"as qm[{guess}])")


def _kind_unit(u: Units, kind: str) -> bool:
    """Whether the units ``u`` apply to a joint of ``kind`` ("revolute" or "prismatic")."""
    return u.rotary == (kind != "prismatic")


def for_joints(spec, kinds, where: str = "units") -> Optional[list]:
    """Each joint's :class:`Units` from a robot's declaration, or None when ``spec`` declares none. ``spec`` is text
    naming at most one angle unit and one length unit, which apply to the revolute and the prismatic joints
    (``"deg"``: revolute joints in degrees, prismatic ones in m; ``"deg,mm"``; a drive unit with its scale, e.g.
    ``"deg,A=2.5"``, scales every joint's force), a sequence with one declaration per joint (text, a mapping or a
    :class:`Units`, None for SI), a mapping (a controller file's ``"units"``) or a :class:`Units`. A unit that fits
    no joint (``"mm"`` on an arm of revolute joints) or two units of one kind (``"deg,rad"``) are refused."""
    n = len(kinds)
    si = [Units("rad", "N*m") if k != "prismatic" else Units("m", "N") for k in kinds]
    if spec is None:
        return None
    if isinstance(spec, (list, tuple)):
        if len(spec) != n:
            raise DataError(f"{where}: {len(spec)} declarations for {n} joints: give one per joint (None for SI)")
        out = []
        for j, (sp, kind) in enumerate(zip(spec, kinds)):
            u = parse(sp) if sp is not None else None
            if u is None:
                out.append(si[j])
                continue
            if not _kind_unit(u, kind):
                raise DataError(f"{where}: joint {j + 1} is {kind} but is declared in {u.position} "
                                f"({'an angle' if u.rotary else 'a length'}): give "
                                f"{'rad, deg or rev' if kind != 'prismatic' else 'm, mm or um'}")
            out.append(u)
        return out
    if isinstance(spec, (Mapping, Units)):
        u = parse(spec)
        assert u is not None
        parts = [u]
    elif isinstance(spec, str):
        parts = []
        for text in (p.strip() for p in spec.split(",") if p.strip()):
            name = text.partition("=")[0].strip()
            if name in POSITION_UNITS or name.startswith("counts"):
                parts.append(parse(text))
            elif name in FORCE_UNITS:
                raise DataError(f"{where}: a robot's forces are N·m on revolute joints and N on prismatic ones; "
                                f"{text!r} names one of them: leave it out, or give a drive unit with its scale "
                                "(A=2.5)")
            else:
                try:
                    parts.append(("force", parse(f"m,{text}")))
                except DataError:  # neither a position unit nor a drive's: say so of what the user wrote
                    raise DataError(f"{where}: {text!r} is not a unit didim knows: a position unit (rad, deg, rev, "
                                    "m, mm, um, counts/...) or a drive unit with its scale (A=2.5)") from None
    else:
        raise DataError(f"{where}: units must be text such as 'deg' or 'deg,mm', or one per joint, got "
                        f"{type(spec).__name__}")
    rot = [p for p in parts if isinstance(p, Units) and p.rotary]
    lin = [p for p in parts if isinstance(p, Units) and not p.rotary]
    drive = [p[1] for p in parts if isinstance(p, tuple)]
    for kind, found in (("angle", rot), ("length", lin)):
        if len({(u.position, u.counts_per) for u in found}) > 1:
            raise DataError(f"{where}: several {kind} units ({', '.join(u.position for u in found)}): one declaration "
                            f"gives one {kind} unit to every joint of its kind; where the joints differ, declare them "
                            "per joint: \"units\" in each joint's entry of the controllers' file, a header such as "
                            "qr_1[deg], or in Python units=[...] with one per joint")
    if len(drive) > 1:
        raise DataError(f"{where}: several force units; give one drive unit with its scale")
    for kind, found, word in (("revolute", rot, "angle"), ("prismatic", lin, "length")):
        if found and kind not in kinds:
            raise DataError(f"{where}: {found[0].position} is a{'n' if word == 'angle' else ''} {word} unit but the "
                            f"robot has no {kind} joint (its joints are {', '.join(kinds)})")
    out = []
    for j, kind in enumerate(kinds):
        pos = (rot if kind != "prismatic" else lin)
        base = pos[0] if pos else si[j]
        if drive:
            base = Units(base.position, drive[0].force, base.counts_per, base.per, drive[0].force_scale,
                         torque=kind != "prismatic")
        out.append(base)
    return out


__all__ = ["Units", "SI", "parse", "for_joints", "from_header", "label", "length", "speed", "force", "force_unit", "plot_length",
           "check_stroke"]
