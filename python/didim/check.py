"""The controller against the log: before any fit, the described controller's law applied to the logged reference and
motor position must give the logged force.

DIDIM simulates the closed loop, so everything rests on the controller. A described controller that is not the one
that ran the axis (the feedforward forgotten, an integral time typed in ms, a gain in the wrong unit) still gives a
fit, with biased parameters and invented effects. The log holds the evidence: ``u = C_r(z)·qr − C_y(z)·qm`` on the
logged signals is the logged command, to rounding, when the description is right (0.0 % on the truthbench's drive
records, at most 0.3 % on the EMPS). :func:`check_controller` measures that mismatch on the samples where the drive
does not saturate (the law's unknown state at the first sample taken out), says where it lives (during moves, at rest,
around reversals), and, when it is too large, tries the usual mistakes and names the one that explains the log. Too
large is beyond rounding (``ROUNDING_LEVEL``) and beyond ``NOISE_MARGIN`` times what the best linear law fitted from
the same log reaches (:func:`didim.fit_controller`): what that law misses is noise, which no description explains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ._errors import DataError
from .controller_fit import CHECK_TOLERANCE, fit_controller, free_responses, mismatch
from .controllers import TransferFunction

#: A mismatch below this share is rounding (the logged force's digits, a command logged in drive units): no law is
#: fitted to judge it.
ROUNDING_LEVEL = 0.005
#: Above it, the described law must replay the log within this factor of the best linear law fitted from the same
#: log (:func:`didim.fit_controller`): what that law misses is noise (a force measured rather than commanded, or with
#: noise added), which no description can explain either.
NOISE_MARGIN = 1.5
#: Samples within this share of the saturation are left out (the law's output is clipped there).
SATURATION_MARGIN = 0.999
#: The factors tried on a gain or a time constant given in another unit: ms for s, rad/s for Hz (2π), and back.
UNIT_FACTORS = (1e-3, 1e3, 2 * math.pi, 1 / (2 * math.pi))


@dataclass
class ControllerCheck:
    """The described controller against the log: ``mismatch`` = ‖F − F_law‖/‖F‖ on the ``samples`` where the drive
    does not saturate; ``passed`` when it is within ``tolerance``; ``where`` the share of the mismatch's energy during
    moves, at rest and around reversals; ``likely`` the mistake that explains the log (in words) and
    ``likely_mismatch`` the mismatch with it corrected, when one does."""

    mismatch: float
    tolerance: float
    samples: int
    where: Dict[str, float] = field(default_factory=dict)
    likely: Optional[str] = None
    likely_mismatch: float = float("nan")
    tried: List[Tuple[str, float]] = field(default_factory=list)
    #: The mismatch of the best linear law fitted from the log (what noise explains), when one was fitted.
    best_linear: float = float("nan")
    #: The share of the mismatch's energy that the described law's own mistakes cannot explain
    #: (:func:`_exogenous_share`), when it was measured.
    exogenous: float = float("nan")
    #: The share of the force (RMS) that the drive added to the law's command, when the law replays the log but for
    #: an input it does not make (a dither, an injected excitation): the described law is then right.
    disturbance: float = float("nan")

    @property
    def passed(self) -> bool:
        return bool(self.mismatch <= self.tolerance or math.isfinite(self.disturbance))

    def summary(self) -> str:
        noise = (f": what the best linear law fitted from the log reaches ({100 * self.best_linear:.3g} %) times "
                 f"{NOISE_MARGIN:g}, or the rounding level {100 * ROUNDING_LEVEL:g} %, whichever is larger"
                 if math.isfinite(self.best_linear) and self.tolerance < CHECK_TOLERANCE else "")
        head = (f"controller check: its law on the logged qr and qm gives the logged force within "
                f"{100 * self.mismatch:.3g} % (RMS, {self.samples} unsaturated samples; at most "
                f"{100 * self.tolerance:.3g} % is accepted{noise})")
        if math.isfinite(self.disturbance):
            return (f"controller check: its law on the logged qr and qm gives the logged force within "
                    f"{100 * self.mismatch:.3g} % (RMS, {self.samples} unsaturated samples), more than a linear law "
                    f"fitted from the log ({100 * self.best_linear:.3g} %), but {100 * self.exogenous:.0f} % of the "
                    "difference is not of the law's making (no gain, delay, lag or feedforward of it explains it): the "
                    f"drive added an input to its command, {100 * self.disturbance:.3g} % of the force (a dither or an "
                    "injected excitation); the law is accepted. Give that input as u_ext if it is known")
        if self.passed:
            return head
        where = ", ".join(f"{100 * v:.0f} % {k}" for k, v in self.where.items() if v >= 0.005)
        return head.replace("within", "only within") + f"; the mismatch lives {where}; " + self.cause()

    def cause(self, joints: Sequence["ControllerCheck"] = ()) -> str:
        """What likely went wrong, for this check and the ``joints`` whose checks name the same cause (their figures
        beside this one's)."""
        every = [self, *joints]
        if self.likely:
            fixed = [c.likely_mismatch for c in every if math.isfinite(c.likely_mismatch)]
            return f"likely: {self.likely}" + (" (corrected, the law gives the log within " + ", ".join(
                f"{100 * m:.3g} %" for m in fixed) + ")" if fixed else "")
        fitted = [c.best_linear for c in every if math.isfinite(c.best_linear)]
        return ("none of the usual mistakes (feedforward missing or doubled, a time constant or gain in another unit, "
                "the force gain, the sign, a sample of delay) explains it: check that this is the controller that ran "
                "the axis and that the force is its command, not a measured current"
                + (" (a linear law fitted from the log replays it within " + ", ".join(
                    f"{100 * m:.3g} %" for m in fitted) + ": didim controller fit)" if fitted else ""))

    def to_dict(self) -> Dict[str, Any]:
        return {"mismatch": self.mismatch, "tolerance": self.tolerance, "passed": self.passed,
                "best_linear": self.best_linear, "exogenous": self.exogenous, "disturbance": self.disturbance,
                "samples": self.samples, "where": dict(self.where), "likely": self.likely,
                "likely_mismatch": self.likely_mismatch}


#: A mismatch of a described law is taken for an input the drive added to its command (a dither, an excitation)
#: when more than this share of its energy lies outside what the law's own mistakes would make
#: (:func:`_exogenous_share`): at least 1 − 1/NOISE_MARGIN² of it, the share a fitted law must explain to refuse.
EXOGENOUS_SHARE = 1 - 1 / NOISE_MARGIN**2


def _exogenous_share(f: np.ndarray, c: np.ndarray, rec, keep: np.ndarray) -> float:
    """The share of the mismatch ``f − c``'s energy (on ``keep``) that no mistake of the described law explains: the
    least squares of the mismatch on the law's own command ``c`` (a gain), shifted by one and two samples either way
    (a delay, a lag), and on the reference's speed, acceleration and jerk (a feedforward's gain or filter). A wrong
    description's mismatch is made of these; an input the drive added to its command is not (it does not follow the
    reference, and the command's answer to it is a small part of the command)."""
    e = (f - c)[keep]
    ee = float(e @ e)
    if ee <= 0:
        return 0.0
    dt = rec.dt
    v = np.gradient(rec.qr, dt)
    a = np.gradient(v, dt)
    cols = [c, np.r_[c[:1], c[:-1]], np.r_[c[:2], c[:-2]], np.r_[c[1:], c[-1:]], np.r_[c[2:], c[-2:]],
            v, a, np.gradient(a, dt), np.ones_like(c)]
    x = np.column_stack(cols)[keep]
    scale = np.linalg.norm(x, axis=0)
    x = x[:, scale > 0] / scale[scale > 0]
    beta, *_ = np.linalg.lstsq(x, e, rcond=None)
    r = e - x @ beta
    return float(r @ r) / ee


def _law(tf: TransferFunction, rec) -> np.ndarray:
    """The law's command on the log; a known external input at the gain the log shows (its gain is the input's
    matter, which :meth:`Recording.diagnose` reports, not the controller's)."""
    u_ext = rec.u_ext
    if u_ext is not None:
        g, _ = rec.u_ext_gain()
        u_ext = u_ext * g if math.isfinite(g) else u_ext
    with np.errstate(all="ignore"):
        return tf.command(rec.qr, rec.qm, u_ext)


def _variants(tf: TransferFunction) -> List[Tuple[str, TransferFunction]]:
    """The usual mistakes of a description, each as (what it was, the controller with it corrected)."""
    out: List[Tuple[str, TransferFunction]] = []
    if tf.design is None:
        return out
    d = dict(tf.design)

    def build(**change) -> Optional[TransferFunction]:
        try:
            return TransferFunction.cascade(**{**d, **change})
        except (DataError, ValueError, ZeroDivisionError):
            return None

    if d["kff"] == 0:
        out.append(("the velocity feedforward is missing from the description (kff = 0; the log says kff = 1)",
                    build(kff=1.0)))
    else:
        out.append((f"the velocity feedforward is in the description (kff = {d['kff']:g}) but not in the drive",
                    build(kff=0.0)))
        if d["kff"] != 1.0:
            out.append((f"the velocity feedforward is {d['kff']:g}, the drive's is 1", build(kff=1.0)))
    for name, unit in (("ti", "s"), ("f_lp", "Hz"), ("kv", ""), ("kp", "1/s")):
        v = d.get(name)
        if v is None:
            continue
        for k in UNIT_FACTORS:
            what = {1e-3: f"in thousandths (given {v:g}, the log says {v * k:g}: ms for s?)",
                    1e3: f"in thousands (given {v:g}, the log says {v * k:g}: s for ms?)",
                    2 * math.pi: f"in the wrong unit by 2π (given {v:g}, the log says {v * k:g}: Hz for rad/s?)",
                    1 / (2 * math.pi): f"in the wrong unit by 2π (given {v:g}, the log says {v * k:g}: rad/s for "
                                       "Hz?)"}[k]
            out.append((f"{name} {what}", build(**{name: v * k})))
    return [(w, c) for w, c in out if c is not None]


#: A pole of the law this much outside the unit circle (in |z|) is unstable, not the rounding of an integrator's.
UNSTABLE_POLE = 1e-6


def _unstable(tf: TransferFunction) -> Optional[str]:
    """The law's denominator whose pole lies outside the unit circle, in words, or None: its command grows without
    bound from any input (a sign typed wrong in a_y or a_r)."""
    for name in ("a_y", "a_r"):
        den = np.asarray(getattr(tf, name), dtype=float)
        poles = np.roots(den) if len(den) > 1 else np.array([])
        if poles.size and float(np.max(np.abs(poles))) > 1 + UNSTABLE_POLE:
            return (f"the controller's denominator {name} = {list(map(float, den))} has a pole at |z| = "
                    f"{float(np.max(np.abs(poles))):.4g}, outside the unit circle: its law is unstable; check {name}'s "
                    "coefficients (in ascending powers of 1/z) and their signs")
    return None


def _position_mistakes(tf: TransferFunction, rec) -> List[Tuple[str, np.ndarray]]:
    """The law's command under the mistakes that change how the positions enter it, each (what, command): the
    controller in the other angle unit than the record (degrees and radians mixed) and the reference's sign
    reversed."""
    u_ext = rec.u_ext
    out = []
    with np.errstate(all="ignore"):
        for k, what in ((math.pi / 180, "the controller acts on positions in deg while the record's are in rad (or the "
                                         "controller's coefficients are per rad and the record was declared in deg)"),
                        (180 / math.pi, "the controller acts on positions in rad while the record's are in deg (or the "
                                        "controller's coefficients are per deg and the record was declared in rad)")):
            out.append((what + ": give the controller in the record's units", tf.command(rec.qr * k, rec.qm * k, u_ext)))
        out.append(("the reference's sign is reversed against the measured position (qr logged with the other sign: "
                    "negate it)", tf.command(-rec.qr, rec.qm, u_ext)))
    return out


def _saturated_cause(tf: TransferFunction, rec, f: np.ndarray) -> str:
    """What likely makes the law's command saturate on almost every sample: an unstable denominator, or a mistake of
    :func:`_position_mistakes` under which the law replays the log (on the samples it then leaves unsaturated);
    else the saturation and gain to check."""
    unstable = _unstable(tf)
    if unstable:
        return "likely: " + unstable
    limit = tf.force_limit
    best = None
    for what, alt in _position_mistakes(tf, rec):
        keep = np.isfinite(alt) & (np.abs(alt) < SATURATION_MARGIN * limit if math.isfinite(limit) else True)
        keep[:2] = False
        if np.count_nonzero(keep) < 0.5 * rec.n:
            continue
        m = mismatch(tf, f, alt, keep)
        if m <= CHECK_TOLERANCE and (best is None or m < best[1]):
            best = (what, m)
    if best is not None:
        return f"likely: {best[0]} (corrected, the law gives the log within {100 * best[1]:.3g} %)"
    return "check the saturation and gain"


def check_controller(rec) -> Union[ControllerCheck, "RobotControllerCheck"]:
    """The recording's controller against its log (see the module's text). Tries the usual mistakes only when the
    description fails: the cascade's settings (feedforward, ti, f_lp, kv, kp in another unit) when the controller was
    built by :meth:`TransferFunction.cascade` or from a ``"cascade"`` file, and for any controller the force gain (a
    least-squares factor), the sign and one or two samples of delay between the command and the log. A robot's
    record: each joint's controller against its own log (:func:`check_robot_controllers`)."""
    if rec.has_joint_columns:
        return check_robot_controllers(rec)
    tf = rec.controller.transfer_function(rec.dt)
    f = np.asarray(rec.force, dtype=float)
    if not np.any(f) and np.ptp(rec.qr) > 0:  # a loop that moves commands a force: this column holds none
        raise DataError(f"{rec.name or 'record'}: the logged force is zero on every sample while the reference moves: "
                        "the force column holds no command (not logged, or another column); check the force column "
                        "and its scale")
    c = _law(tf, rec)
    limit = tf.force_limit
    keep = np.ones(rec.n, bool) if not math.isfinite(limit) else np.abs(c) < SATURATION_MARGIN * limit
    keep[:2] = False  # the law's first samples take the first position for the earlier ones
    if np.count_nonzero(keep) < max(3, 0.05 * rec.n):
        raise DataError(f"{rec.name or 'record'}: the controller's command is at its saturation on almost every sample: "
                        f"the controller cannot be checked against the log; {_saturated_cause(tf, rec, f)}")
    out = ControllerCheck(mismatch(tf, f, c, keep), CHECK_TOLERANCE, int(np.count_nonzero(keep)))
    if out.mismatch > ROUNDING_LEVEL:
        # what noise explains: the best linear law fitted from this log replays it only so well
        try:
            out.best_linear = fit_controller(rec, tolerance=math.inf).error
        except DataError:
            pass  # too short or never moving: the absolute tolerance judges
        else:
            out.tolerance = max(NOISE_MARGIN * out.best_linear, ROUNDING_LEVEL)
    if not out.passed and out.mismatch <= CHECK_TOLERANCE:
        out.exogenous = _exogenous_share(f, c, rec, keep)
        if out.exogenous > EXOGENOUS_SHARE:
            out.disturbance = out.mismatch  # the law is right; the log carries a command it did not make
    if out.passed:
        return out
    # where the mismatch lives
    v = np.gradient(rec.qr, rec.dt)
    vmax = float(np.max(np.abs(v))) or 1.0
    moving = np.abs(v) > 0.05 * vmax
    sign = np.sign(np.where(moving, v, 0.0))
    idx = np.flatnonzero(sign)
    rev = np.zeros(rec.n, bool)
    if idx.size > 1:
        flips = idx[1:][np.diff(sign[idx]) != 0]
        w = max(1, int(round(0.05 / rec.dt)))
        for k in flips:
            rev[max(0, k - w):k + w] = True
    e2 = (f - c) ** 2 * keep
    tot = float(np.sum(e2)) or 1.0
    out.where = {"during moves": float(np.sum(e2[moving & ~rev]) / tot), "at rest": float(np.sum(e2[~moving & ~rev]) / tot),
                 "around reversals": float(np.sum(e2[rev]) / tot)}
    # the usual mistakes
    cands: List[Tuple[str, np.ndarray]] = [(what, _law(alt, rec)) for what, alt in _variants(tf)]
    tol = max(out.tolerance, ROUNDING_LEVEL)
    # the factor by least squares beside the law's free responses (its state at the first sample, which the
    # comparison takes out too): a joint that holds a weight starts its integrator at the logged force, not at the
    # law's rest, and the plain ratio f·c/c·c was biased by that offset (a robot's gravity-loaded joints with their
    # gains 10 times too large were refused without the factor named)
    cc = float(np.dot(c[keep], c[keep]))
    if cc > 0:
        free = free_responses(tf, rec.n)[keep]
        cols = np.column_stack([c[keep], free]) if free.shape[1] and np.all(np.isfinite(free)) else c[keep][:, None]
        with np.errstate(all="ignore"):
            a = float(np.linalg.lstsq(cols, f[keep], rcond=None)[0][0]) if np.all(np.isfinite(cols)) else math.nan
        a = a if math.isfinite(a) else float(np.dot(f[keep], c[keep]) / cc)
        if a < 0 and abs(abs(a) - 1) < 0.05:
            cands.append(("the force's sign is reversed against the command (a motor wired or logged the other way)",
                          a * c))
        elif a != 0:
            unit = next((u for k, u in ((2 * math.pi, "2π: a gain per rad/s given for per m/s, or Hz for rad/s?"),
                                         (1 / (2 * math.pi), "1/2π: a gain per m/s given for per rad/s?"),
                                         (1e3, "1000: a unit prefix, m for mm or ms for s?"),
                                         (1e-3, "1/1000: a unit prefix, mm for m or s for ms?"))
                         if abs(a / k - 1) < 0.01), None)
            scale = (f"the velocity-loop gain kv ({dict(tf.design)['kv']:g} → {dict(tf.design)['kv'] * a:.4g}) or the "
                     f"force gain ({tf.gain:.4g} → {tf.gain * a:.4g})" if tf.design is not None
                     else f"the force gain ({tf.gain:.4g} → {tf.gain * a:.4g})")
            cands.append((f"the command's scale is off by a factor {a:.4g}{f' ({unit})' if unit else ''}: {scale}, or "
                          f"a force logged in other units (force_scale {1 / a:.4g})", a * c))
    cands += _position_mistakes(tf, rec)
    unstable = _unstable(tf)
    with np.errstate(all="ignore"):
        cands.append(("the reference and the measured position are swapped (qr read as qm and qm as qr: check the "
                      "columns' names or the mapping)", tf.command(rec.qm, rec.qr, rec.u_ext)))
    for lag in (1, 2):
        cands.append((f"the logged force is {lag} sample{'s' if lag > 1 else ''} late against the logged positions "
                      "(a delay in the drive's log, or the positions logged early)", np.r_[np.full(lag, c[0]), c[:-lag]]))
        cands.append((f"the description has {lag} sample{'s' if lag > 1 else ''} of delay that the log does not (a "
                      "computation delay written into the controller that the drive does not have, or the force "
                      "logged early)", np.r_[c[lag:], np.full(lag, c[-1])]))
    out.tried = [(what, mismatch(tf, f, alt, keep)) for what, alt in cands]
    best = min(out.tried, key=lambda t: t[1]) if out.tried else None
    if best is not None and best[1] <= tol:
        out.likely, out.likely_mismatch = best
    elif unstable:
        out.likely, out.likely_mismatch = unstable, math.nan
    return out


@dataclass
class RobotControllerCheck:
    """Each joint's controller against its log (:func:`check_controller` on the joint as one axis), and, where a
    joint's controller fails and another joint's replays its log, the swap that explains it."""

    joints: Dict[str, ControllerCheck]
    swapped: List[Tuple[str, str]] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.joints.values())

    @property
    def mismatch(self) -> float:
        return max(c.mismatch for c in self.joints.values())

    def failed(self) -> List[str]:
        return [j for j, c in self.joints.items() if not c.passed]

    def summary(self) -> str:
        if self.passed:
            return (f"controller check: each joint's law on its logged qr and qm gives its logged force within "
                    f"{100 * self.mismatch:.3g} % at most (" + ", ".join(f"{j} {100 * c.mismatch:.2g} %"
                                                                        for j, c in self.joints.items()) + ")")
        parts = []
        for a, b in self.swapped:
            parts.append(f"joints {a} and {b}: each one's controller gives the other's log: the two controllers are "
                         "swapped in the file (its entries are in the robot's joint order)")
        named = {j for pair in self.swapped for j in pair}
        # the joints that fail for the same likely cause in one line each (six joints' sentences in a row made a
        # line of thousands of characters)
        groups: Dict[str, List[str]] = {}
        for j in self.failed():
            if j not in named:
                groups.setdefault(self.joints[j].likely, []).append(j)
        for js in groups.values():
            if len(js) == 1:
                parts.append(f"joint {js[0]}: " + self.joints[js[0]].summary())
                continue
            checks = [self.joints[j] for j in js]
            parts.append(f"joints {', '.join(js)}: each one's law on its logged qr and qm gives its logged force only "
                         "within " + ", ".join(f"{100 * c.mismatch:.3g} %" for c in checks) + " (RMS; at most "
                         + ", ".join(dict.fromkeys(f"{100 * c.tolerance:.3g} %" for c in checks)) + " accepted); "
                         + checks[0].cause(checks[1:]))
        return "".join(f";\n  {p}" if i else p for i, p in enumerate(parts))

    def to_dict(self) -> Dict[str, Any]:
        return {"passed": self.passed, "mismatch": self.mismatch, "swapped": [list(p) for p in self.swapped],
                "joints": {j: c.to_dict() for j, c in self.joints.items()}}


def check_robot_controllers(rec) -> RobotControllerCheck:
    """:func:`check_controller` on each joint of a robot's record (:meth:`didim.Recording.joint`); a joint whose
    controller fails is tried with the other joints' controllers, and two joints that replay each other's logs are
    named as swapped."""
    if not rec.has_joint_columns:
        raise DataError(f"{rec.name or 'record'} is one axis's: check its controller with check_controller(rec)")
    n = len(rec.joint_names)
    out = RobotControllerCheck({rec.joint_names[j]: check_controller(rec.joint(j)) for j in range(n)})
    bad = [j for j in range(n) if not out.joints[rec.joint_names[j]].passed]
    fits = {}
    for j in bad:
        for i in bad:
            if i != j:
                try:
                    fits[j, i] = check_controller(rec.joint(j, rec.controllers[i])).passed
                except DataError:
                    fits[j, i] = False
    for j in bad:
        for i in bad:
            if i > j and fits.get((j, i)) and fits.get((i, j)):
                out.swapped.append((rec.joint_names[j], rec.joint_names[i]))
    return out


#: What to do when the described controller does not give the logged force: refuse (a DataError, exit 2 from the
#: command line), warn (a DidimWarning) and go on, or not check at all.
CHECK_MODES = ("error", "warn", "off")


def enforce(rec, mode: str = "error"):
    """:func:`check_controller` on ``rec`` (or, on a robot's record, :func:`check_robot_controllers`) as ``mode`` asks
    (``CHECK_MODES``); the check, or None when "off"."""
    import warnings

    from . import _checks
    from ._errors import DidimWarning

    _checks.one_of("controller_check", mode, CHECK_MODES)
    if mode == "off":
        return None
    robot = rec.has_joint_columns
    chk = check_controller(rec)
    if not chk.passed:
        what = (f"the described controller of joint{'s' if len(chk.failed()) > 1 else ''} {', '.join(chk.failed())} "
                "does not give the logged force" if robot else "the described controller does not give the logged force")
        text = (f"{rec.name or 'record'}: {what}: {chk.summary()}. "
                "didim simulates the closed loop with this controller, so a fit or a simulation with it would be "
                "wrong; correct the description (Python: controller=..., CLI: --controller FILE)")
        if mode == "error":
            raise DataError(text + ", or go on anyway with controller_check='warn' (CLI: --controller-check warn)")
        warnings.warn(text, DidimWarning, stacklevel=3)
    return chk


__all__ = ["ControllerCheck", "RobotControllerCheck", "check_controller", "check_robot_controllers", "enforce", "CHECK_TOLERANCE", "CHECK_MODES"]
