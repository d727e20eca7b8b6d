"""Simulated recordings with a known truth: reference trajectories, noise, encoder quantization, the controller.

Used by the tests, the demo and the doctor's proof. The measured force is the simulated command plus coloured
measurement noise; the measured positions are the simulated ones quantized by the encoder resolution (the simulated
controller already sees quantized positions).
"""

from __future__ import annotations

import math
from typing import Dict, Optional, Union

import numpy as np

from . import _checks
from ._errors import DataError
from .controllers import Controller, EmpsCascade
from .model import Model
from .recording import Recording
from .simulation import DEFAULT_COULOMB_EPS, simulate

#: The paper's Table 3 IDIM-LS values (EMPS without payload), used as the truth of the demo.
TABLE3_TRUTH = dict(M1=68.0, Fv1=104.0, Fc1=10.0, M2=38.0, Fv2=96.5, Fc2=9.5, K12=8.8e5)
#: Table 4 (with the 10 kg payload).
TABLE4_TRUTH = dict(M1=69.0, Fv1=110.0, Fc1=10.5, M2=46.5, Fv2=98.2, Fc2=8.68, K12=8.6e5)
#: The EMPS benchmark's rigid IDIM-LS values.
EMPS_RIGID = dict(M=95.1089, Fv=203.5034, Fc=20.3935, OF=-3.1648)


def _smooth_move(distance: float, v_max: float, a_max: float, dt: float) -> np.ndarray:
    """Positions of a trapezoidal-velocity move of ``distance`` (m) from rest to rest."""
    d = abs(distance)
    if d == 0:
        return np.zeros(1)
    t_acc = v_max / a_max
    if a_max * t_acc**2 > d:  # triangular profile
        t_acc = math.sqrt(d / a_max)
        v_max = a_max * t_acc
    t_flat = (d - a_max * t_acc**2) / v_max
    T = 2 * t_acc + t_flat
    t = np.arange(0.0, T + dt, dt)
    q = np.where(
        t < t_acc,
        0.5 * a_max * t**2,
        np.where(
            t < t_acc + t_flat,
            0.5 * a_max * t_acc**2 + v_max * (t - t_acc),
            d - 0.5 * a_max * np.clip(T - t, 0, None) ** 2,
        ),
    )
    return np.sign(distance) * np.minimum(q, d)


def trapezoid(*, dt: float = 1e-3, stroke: float = 0.2, speeds=(0.042, 0.083, 0.125), a_max: float = 0.83,
              dwell_s: float = 0.3) -> np.ndarray:
    """Back-and-forth trapezoidal-velocity moves over ``stroke`` (m) at each speed (m/s), with rests of ``dwell_s``."""
    parts = [np.zeros(int(dwell_s / dt))]
    pos = 0.0
    for v in speeds:
        for target in (stroke, 0.0):
            m = pos + _smooth_move(target - pos, v, a_max, dt)
            parts += [m, np.full(int(dwell_s / dt), m[-1])]
            pos = m[-1]
    return np.concatenate(parts)


def chirp(*, dt: float = 1e-3, duration_s: float = 6.0, f0: float = 2.0, f1: float = 40.0, accel: float = 1.5,
          center: float = 0.1) -> np.ndarray:
    """A position chirp around ``center`` (m) from ``f0`` to ``f1`` Hz (linear sweep) of constant acceleration amplitude
    ``accel`` (m/s²), faded in and out over half a second; excites the flexible mode."""
    t = np.arange(0.0, duration_s, dt)
    f = f0 + (f1 - f0) * t / duration_s
    phase = 2 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t**2 / duration_s)
    amp = accel / (2 * math.pi * f) ** 2
    fade = np.clip(np.minimum(t, duration_s - t) / 0.5, 0, 1)
    return center + fade * amp * np.sin(phase)


def trapezoid_chirp(*, dt: float = 1e-3, stroke: float = 0.2, chirp_f1: float = 40.0, **kw) -> np.ndarray:
    """Section VI.A's excitation: trapezoidal velocity moves (inertia, friction) followed by a chirp (flexibility)."""
    tr = trapezoid(dt=dt, stroke=stroke)
    ramp = tr[-1] + _smooth_move(stroke / 2 - tr[-1], 0.05, 0.83, dt)
    ch = chirp(dt=dt, center=stroke / 2, f1=chirp_f1, **kw)
    back = ch[-1] + _smooth_move(-ch[-1], 0.083, 0.83, dt)
    return np.concatenate([tr, ramp, ch, back, np.zeros(int(0.3 / dt))])


def trapezoid_moving_chirp(*, dt: float = 1e-3, stroke: float = 0.2, speed: float = 0.03, amplitude: float = 25e-6,
                           f0: float = 2.0, f1: float = 40.0) -> np.ndarray:
    """The paper's "trapezoidal velocity signal coupled with a chirp": trapezoidal moves (inertia, friction), then a
    slow move across the stroke at ``speed`` (m/s) with a chirp of ``amplitude`` (m) from ``f0`` to ``f1`` Hz on top,
    so the axis keeps moving in one direction while the flexible mode is excited (the load's Coulomb friction then
    acts as a constant force instead of reversing twice per period). ``amplitude · 2π f1`` must stay below ``speed``."""
    if amplitude * 2 * math.pi * f1 >= speed:
        raise DataError(f"the chirp's velocity amplitude {amplitude * 2 * math.pi * f1:.3g} m/s reaches the move's speed "
                        f"{speed:g} m/s: the axis would reverse; lower amplitude or f1, or raise speed")
    tr = trapezoid(dt=dt, stroke=stroke)
    start, end = 0.1 * stroke, 0.9 * stroke
    to_start = tr[-1] + _smooth_move(start - tr[-1], 0.083, 0.83, dt)
    move = start + _smooth_move(end - start, speed, 0.83, dt)
    t = np.arange(len(move)) * dt
    dur = t[-1]
    phase = 2 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t**2 / dur)
    fade = np.clip(np.minimum(t, dur - t) / 0.5, 0, 1)
    back = end + _smooth_move(-end, 0.083, 0.83, dt)
    return np.concatenate([tr, to_start, move + fade * amplitude * np.sin(phase), back, np.zeros(int(0.3 / dt))])


def emps_like(*, n: int = 24841, dt: float = 1e-3) -> np.ndarray:
    """A reference shaped like the EMPS record's: bang-bang acceleration (0.83 m/s²), plateaus at 0.042, 0.083 and
    0.125 m/s, strokes within 0 .. 0.246 m, ``n`` samples."""
    speeds = [0.125, 0.083, 0.042, 0.125, 0.083, 0.042]
    parts = [np.zeros(int(0.3 / dt))]
    pos, i = 0.0, 0
    while sum(len(p) for p in parts) < n:
        v = speeds[i % len(speeds)]
        target = 0.24 if pos < 0.12 else 0.005
        m = pos + _smooth_move(target - pos, v, 0.83, dt)
        parts += [m, np.full(int(0.25 / dt), m[-1])]
        pos, i = m[-1], i + 1
    return np.concatenate(parts)[:n]


def pulses(n: int, dt: float, amplitude: float, *, period_s: float = 1.0, first_s: float = 0.344) -> np.ndarray:
    """A square wave of ``amplitude`` (N), on for half of each ``period_s`` from ``first_s`` on (like the EMPS pulses)."""
    t = np.arange(n) * dt - first_s
    return np.where((t >= 0) & ((t % period_s) < period_s / 2), amplitude, 0.0)


def make_recording(
    truth: Dict[str, float],
    model: Union[str, Model] = "flexible",
    qr: Optional[np.ndarray] = None,
    *,
    dt: float = 1e-3,
    controller: Optional[Controller] = None,
    u_ext: Optional[np.ndarray] = None,
    force_noise: float = 1.0,
    noise_corr: float = 0.5,
    quantization: Optional[float] = 5e-8,
    load_encoder: bool = False,
    seed: int = 0,
    substeps: int = 10,
    coulomb_eps: float = DEFAULT_COULOMB_EPS,
    name: str = "simulated",
) -> Recording:
    """A recording of ``truth`` (a parameter dict of the ``model``) tracking ``qr`` (default :func:`trapezoid_chirp`)
    under ``controller`` (default the EMPS cascade), with force noise of ``force_noise`` N RMS (AR(1) correlation
    ``noise_corr``), positions quantized to ``quantization`` m and, with ``load_encoder``, a load position ``ql``."""
    from scipy.signal import lfilter

    if qr is None:
        qr = trapezoid_chirp(dt=dt)
    qr = _checks.real_array("qr (position reference)", qr)
    quantization = quantization or None  # 0 means no quantization, like None
    controller = controller or EmpsCascade()
    plan = Recording(dt=dt, qr=qr, force=np.zeros(len(qr)), qm=qr, controller=controller, u_ext=u_ext,
                     position_resolution=quantization, name=name)
    noise_corr = _checks.real("noise correlation noise_corr", noise_corr, lo=0.0, lo_open=False, hi=1.0)
    force_noise = _checks.real("force_noise", force_noise, "N", lo=0.0, lo_open=False, hint=" (RMS of the noise)")
    # a didim.Model carries its own friction law; a kind gets coulomb_eps
    sim = simulate(plan, truth, model, substeps=substeps, **({} if isinstance(model, Model) else
                                                              dict(coulomb_eps=coulomb_eps)))
    try:
        rng = np.random.default_rng(seed)
    except (TypeError, ValueError) as e:
        raise DataError(f"seed must be a whole number >= 0, got {seed!r} ({e})") from None
    white = rng.standard_normal(len(qr)) * force_noise * math.sqrt(1 - noise_corr**2)
    noise = lfilter([1.0], [1.0, -noise_corr], white)

    def quant(x):
        return np.round(x / quantization) * quantization if quantization else x

    return Recording(
        dt=dt, qr=qr, force=sim.force + noise, qm=quant(sim.q1), controller=controller,
        ql=quant(sim.q12) if (load_encoder and sim.q12 is not None) else None, u_ext=u_ext,
        position_resolution=quantization, name=name,
    )


__all__ = ["trapezoid", "chirp", "trapezoid_chirp", "trapezoid_moving_chirp", "emps_like", "pulses", "make_recording", "TABLE3_TRUTH",
           "TABLE4_TRUTH", "EMPS_RIGID"]
