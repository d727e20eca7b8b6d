"""Recordings of a position-controlled axis: the data type, validated on construction (the file formats are in
:mod:`didim.loaders`)."""

from __future__ import annotations

import functools
import math
import os
import warnings
from dataclasses import dataclass
from typing import List, Optional, Tuple, Union

import numpy as np

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


def _check_join(lead: np.ndarray, qr: np.ndarray) -> None:
    """A given lead-in ends where the record's reference begins (the samples just before it, in the same unit)."""
    steps = [abs(qr[1] - qr[0])] + ([abs(lead[-1] - lead[-2])] if lead.size > 1 else [])
    scale = max(float(np.max(np.abs(qr))), float(np.ptp(qr)), 1e-12)
    tol = LEAD_JOIN_STEPS * max(steps) + 1e-9 * scale
    if not abs(lead[-1] - qr[0]) <= tol:
        raise DataError(f"lead_in ends at {lead[-1]:.6g} m but the reference's first sample is {qr[0]:.6g} m: give the "
                        "reference's samples just before the first one (oldest first, in m, at the record's dt), so "
                        "that the simulation runs through them into the record")


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
    """A record of a position-controlled axis, validated on construction. SI units on the load side.

    Attributes:
        dt: sample period (s).
        qr: position reference fed to the controller (m).
        force: measured motor force (N), e.g. ``gtau·vir`` on the EMPS.
        qm: measured motor position (m).
        controller: the controller that ran the axis (:class:`TransferFunction`, :class:`EmpsCascade` or :class:`PD`;
            :func:`didim.load_controller` reads one from a file). Required.
        ql: measured load position (m) when the axis has a second encoder, else None.
        u_ext: known external force added to the command (N), e.g. the EMPS pulses, else None.
        position_resolution: resolution of the motor encoder (m), used to quantize the simulated measurement, or None.
        name: a label for reports.
        lead_in: the reference before the first sample, for a log that begins in motion: ``"auto"`` (default)
            reconstructs it back to rest when the reference begins moving (:func:`reconstruct_lead_in`), ``None``
            for none (the simulation starts at rest on the first reference sample, as in the paper), or the samples
            themselves (m, oldest first, at ``dt``, e.g. from a pre-trigger buffer). The simulation runs through it
            from rest, with ``u_ext`` held at its first value; nothing is compared there. :attr:`qr_lead` is the one
            in use.
        units: the units the record was logged in (:class:`didim.units.Units`); the arrays hold SI (m or rad, N or
            N·m), converted by the loaders. It says whether the axis is linear or rotary (:attr:`axis`), for every
            unit didim prints.
    """

    dt: float
    qr: np.ndarray
    force: np.ndarray
    qm: np.ndarray
    controller: Optional[Controller] = None
    ql: Optional[np.ndarray] = None
    u_ext: Optional[np.ndarray] = None
    position_resolution: Optional[float] = None
    name: str = ""
    lead_in: Union[str, None, np.ndarray] = "auto"
    units: Units = SI
    #: Where the controller comes from when nobody described it: the fit's summary (:func:`didim.fit_controller`),
    #: else empty.
    controller_origin: str = ""

    def __post_init__(self) -> None:
        dt = _number("sample period dt", self.dt, "s")
        if not (math.isfinite(dt) and dt > 0):
            raise DataError(f"sample period dt must be a finite number of seconds > 0, got {self.dt}")
        object.__setattr__(self, "dt", dt)
        qr = _signal("qr (position reference)", self.qr)
        n = qr.shape[0]
        if n < 3:
            raise DataError(f"the record has {n} samples; at least 3 are needed")
        if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
            raise DataError(
                f"sample period dt = {dt:g} s is outside {DT_RANGE[0]:g}-{DT_RANGE[1]:g} s (drives log between "
                f"{1 / DT_RANGE[1]:g} Hz and {1e-6 / DT_RANGE[0]:g} MHz): check the time column's unit (ns, us or ms "
                "read as seconds?) or the dt you gave")
        object.__setattr__(self, "qr", qr)
        object.__setattr__(self, "force", _signal("force", self.force, n))
        object.__setattr__(self, "qm", _signal("qm (motor position)", self.qm, n))
        if self.ql is not None:
            object.__setattr__(self, "ql", _signal("ql (load position)", self.ql, n))
        if self.u_ext is not None:
            object.__setattr__(self, "u_ext", _signal("u_ext (external force)", self.u_ext, n))
        if self.controller is None:
            raise DataError("the recording has no controller: didim simulates the closed loop, so it needs the law that "
                            "ran the axis; give controller=didim.EmpsCascade() for the EMPS, didim.PD(kp, kd), "
                            "didim.TransferFunction(...) or .cascade(...), or didim.load_controller('controller.json') "
                            "(on the command line: --controller FILE)")
        if not isinstance(self.controller, (EmpsCascade, PD, TransferFunction)):
            raise DataError("controller must be a didim.TransferFunction, EmpsCascade or PD, got "
                            f"{type(self.controller).__name__}"
                            + ("; read a controller file with didim.load_controller(path)"
                               if isinstance(self.controller, (str, bytes, os.PathLike)) else ""))
        self.controller.transfer_function(dt)  # a transfer function designed for another sample period is refused
        if self.position_resolution is not None:
            r = _number("position_resolution", self.position_resolution, "m")
            if not (math.isfinite(r) and r > 0):
                raise DataError(f"position_resolution must be a finite length > 0 m (or None), got {r}")
            object.__setattr__(self, "position_resolution", r)
        if not isinstance(self.name, str):
            raise DataError(f"name must be a string, got {type(self.name).__name__}")
        if not isinstance(self.units, Units):
            object.__setattr__(self, "units", parse_units(self.units) or SI)
        lead = self.lead_in
        if isinstance(lead, str):
            if lead not in ("auto", "none"):
                raise DataError(f"lead_in must be 'auto', None (or 'none') or the reference's samples before the "
                                f"first one, got {lead!r}")
        elif lead is not None:
            lead = _signal("lead_in (the reference before the first sample)", lead)
            if lead.shape[0] >= n:
                raise DataError(f"lead_in has {lead.shape[0]} samples, not fewer than the record's {n}: give only "
                                "the stretch before the log, from rest")
            if lead.size:
                _check_join(lead, qr)
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
        """The reference before the first sample that the simulation runs through from rest (m, oldest first; empty
        for none): :attr:`lead_in` resolved (read-only; computed once)."""
        if isinstance(self.lead_in, np.ndarray):
            lead = self.lead_in
        elif self.lead_in == "auto":
            lead = reconstruct_lead_in(self.qr, self.dt, self.qm, self.position_resolution)
        else:
            lead = np.zeros(0)
        lead = np.ascontiguousarray(lead, dtype=float)
        lead.setflags(write=False)
        return lead

    def lead_in_signals(self) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """The reference and the known external input the simulation runs on: :attr:`qr_lead` then ``qr``, and
        ``u_ext`` held at its first value through the lead-in (a bias stays on; pulses that begin with the log begin
        at zero). The record's own arrays when it has no lead-in."""
        lead = self.qr_lead
        if not lead.size:
            return self.qr, self.u_ext
        u = None if self.u_ext is None else np.concatenate([np.full(lead.size, self.u_ext[0]), self.u_ext])
        return np.concatenate([lead, self.qr]), u

    def lead_in_note(self) -> str:
        """One sentence on the record's lead-in for a result's notes or a command's output ("" without one)."""
        if not self.qr_lead.size:
            return ""
        return (f"the record begins in motion: simulated from rest {1e3 * self.qr_lead.size * self.dt:.0f} ms before "
                "its first sample, through its reference's lead-in (to start at the first sample, as the paper: "
                "lead_in=None, on the command line --lead-in none)")

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
        for x in (self.qr, self.qm):
            v = float(np.max(np.abs(np.diff(x)))) / self.dt
            if math.isfinite(v) and v > 0:
                return v
        return 1.0 / self.dt  # a record that never moves: excitation checks refuse it before any fit

    @functools.cached_property
    def stroke(self) -> float:
        """The span of the reference (m or rad), or of the motor position when the reference does not move."""
        for x in (self.qr, self.qm):
            s = float(np.ptp(x))
            if math.isfinite(s) and s > 0:
                return s
        return 1.0

    @property
    def force_limit(self) -> float:
        """The controller's saturation of the command in N (``gtau·vsat`` or ``tau_max``), ``inf`` for none."""
        return self.controller.force_limit

    def implied_command(self) -> np.ndarray:
        """The force (N) the controller computes from the logged reference and motor position (and ``u_ext``), per
        sample, with the controller's saturation: the evidence :meth:`diagnose` compares the measured force with.
        The two samples before the start take the first position."""
        return self.controller.transfer_function(self.dt).command(self.qr, self.qm, self.u_ext)

    def u_ext_gain(self) -> Tuple[float, float]:
        """The gain with which the known external input ``u_ext`` enters the logged force, and its standard error: the
        least-squares slope of the force minus the controller's command from the logged reference and motor position
        (without ``u_ext``) on ``u_ext`` (with a constant, for a controller state the log began with), on the samples
        the command does not saturate. 1 when ``u_ext`` is what the drive applied; (nan, nan) without ``u_ext`` or
        when it is zero. On DATA_EMPS_PULSES, with ``gtau·pulses_N``: 1.0138 ± 4e-5 (the pulses enter ``vir`` 1.4 %
        larger than ``pulses_N``)."""
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
        wrong gains). :func:`didim.identify` issues them as :class:`didim.DidimWarning`."""
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


__all__ = ["Recording", "TIME_JITTER_RTOL"]
