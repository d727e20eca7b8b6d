"""The one-axis doctor on held-out axes of other kinds, from a simulator that is not didim's nor the truthbench's.

Issue 40 asks the one-axis doctor to name at least 17 of 18 concealed effects on held-out axes of other kinds (and
flag at most 1 of 8 clean records). ../shared/data/truthbench/axes is a sample of such records; this bench makes
more of them with its own closed loop, so that the count does not rest on one simulator's records:

- a plain RK4 loop (numba-compiled, 16 substeps a sample, zero-order hold on the force), in-loop force noise
  (white, low-passed to a first order at the axis's noise band), encoder rounding on the position the controller
  reads;
- five axes (a belt, a portal, a spindle, a robot wrist, a slow rotary table at 500 Hz), each with its own Coulomb
  law (tanh, arctangent, exponential, none of them didim's algebraic default) and smoothing speed;
- three controllers written here as the two-degree-of-freedom law ``u = C_r(z) qr - C_y(z) qm`` (Tustin
  discretization): a PID with a filtered derivative (``pid``), a P position loop around a PI velocity loop with
  velocity feedforward and a first-order command filter (``pic``), and the same with a notch on the command
  (``notch``); their gains are set from the axis's mass and a bandwidth, not tuned to the doctor;
- effects as the truthbench README defines them, with sizes relative to the axis (its Coulomb and viscous friction,
  stroke, top speed, sample period): asymmetric friction, a Stribeck hump, a friction zone along the stroke
  (``position_dependent_coulomb``), a periodic position ripple, an offset, a whole-sample delay and a first-order
  force lag (named ``delay``, as the issue says);
- training on moves at many speeds, validation on another draw of moves or on a multisine.

The records are written in the truthbench/axes layout (CSV ``t, qr, force, qm``, a ``*_controller.json`` beside
each, ``truth.json``), and the doctor is run on each pair as benches/doctor_axes.py runs it.

    python benches/axes_heldout.py --out /tmp/didim_axes_heldout [--seed 1] [--jobs 2] [--doc docs/doctor_axes_heldout.md]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from numba import njit
from scipy import signal

HERE = os.path.dirname(os.path.abspath(__file__))

#: axis: mass (kg or kg·m²), viscous, Coulomb friction, Coulomb law and its smoothing speed, sample rate, stroke,
#: top speed, encoder step, noise (force units, band in Hz), drive gain (force per controller unit) and saturation,
#: closed-loop bandwidth (Hz), position unit
AXES = {
    "belt": dict(M=6.0, Fv=25.0, Fc=5.0, law="tanh", veps=2e-4, fs=2000.0, stroke=(0.08, 0.75), vmax=0.7,
                 enc=1e-6, noise=0.25, noise_hz=60.0, gain=15.0, sat=12.0, bw=8.0, unit="m"),
    "portal": dict(M=320.0, Fv=500.0, Fc=110.0, law="atan", veps=2e-4, fs=1000.0, stroke=(0.1, 1.5), vmax=0.5,
                   enc=1e-6, noise=5.0, noise_hz=25.0, gain=200.0, sat=15.0, bw=4.0, unit="m"),
    "spindle": dict(M=8e-4, Fv=6e-4, Fc=0.03, law="exp", veps=3e-3, fs=4000.0, stroke=(0.0, 40.0), vmax=150.0,
                    enc=2 * math.pi / 2 ** 19, noise=0.002, noise_hz=120.0, gain=0.25, sat=30.0, bw=25.0, unit="rad"),
    "wrist": dict(M=1.5, Fv=4.0, Fc=2.5, law="tanh", veps=4e-4, fs=1000.0, stroke=(-1.8, 1.8), vmax=1.5,
                  enc=2e-7, noise=0.12, noise_hz=40.0, gain=1.0, sat=60.0, bw=6.0, unit="rad"),
    "table": dict(M=12.0, Fv=20.0, Fc=8.0, law="exp", veps=1e-3, fs=500.0, stroke=(-3.0, 3.0), vmax=1.0,
                  enc=2e-6, noise=0.8, noise_hz=20.0, gain=10.0, sat=40.0, bw=3.0, unit="rad"),
}
LAWS = {"tanh": 0, "atan": 1, "exp": 2}


def effect_params(effect: str, ax: dict, rng: np.random.Generator) -> dict:
    """The concealed effect's parameters, sized from the axis (a fraction of its friction, stroke, top speed)."""
    lo, hi = ax["stroke"]
    if effect == "asymmetric_friction":
        return dict(Fcn_extra=rng.uniform(0.2, 0.3) * ax["Fc"], Fvn_extra=rng.uniform(0.1, 0.2) * ax["Fv"])
    if effect == "stribeck":
        return dict(Fs_extra=rng.uniform(0.4, 0.6) * ax["Fc"], vs=rng.uniform(0.02, 0.04) * ax["vmax"])
    if effect == "position_dependent_coulomb":
        return dict(Fcb_a=rng.uniform(0.5, 0.7), Fcb_q0=lo + rng.uniform(0.3, 0.7) * (hi - lo),
                    Fcb_w=rng.uniform(0.08, 0.14) * (hi - lo))
    if effect == "position_ripple":
        return dict(rip_a=rng.uniform(0.15, 0.25) * ax["Fc"], rip_p=(hi - lo) / rng.uniform(15, 30),
                    rip_phi=rng.uniform(0, 2 * math.pi))
    if effect == "offset":
        return dict(OF=rng.choice([-1, 1]) * rng.uniform(0.25, 0.35) * ax["Fc"])
    if effect == "delay":
        return dict(delay_samples=int(rng.integers(1, 3)))
    if effect == "force_lag":
        return dict(tau_lag=rng.uniform(0.8, 1.5) / ax["fs"])
    if effect == "none":
        return {}
    raise ValueError(effect)


# ---------------------------------------------------------------------------------------------------------------
# controllers: continuous designs, Tustin-discretized, in the 2-DOF form the truthbench's files use


def _tustin(num, den, dt):
    b, a = signal.bilinear(num, den, 1 / dt)
    return (np.asarray(b, float) / a[0]).tolist(), (np.asarray(a, float) / a[0]).tolist()


def controller(kind: str, ax: dict) -> dict:
    """u = C_r qr − C_y qm as transfer functions in 1/z; gains from the axis's mass and bandwidth."""
    M, dt, g = ax["M"], 1 / ax["fs"], ax["gain"]
    w = 2 * math.pi * ax["bw"]
    P = np.polynomial.polynomial  # ascending powers of s; np.poly1d wants descending: reverse at the end
    if kind == "pid":  # triple pole at −w of M s² (friction left to the integrator), derivative filtered at 10 w
        kd, kp, ki = 3 * M * w / g, 3 * M * w ** 2 / g, M * w ** 3 / g
        wd = 10 * w
        # (kp + ki/s + kd s/(1+s/wd)) = (ki + (kp + ki/wd) s + (kp/wd + kd) s²) / (s (1 + s/wd))
        num = [ki, kp + ki / wd, kp / wd + kd]
        den = P.polymul([0, 1], [1, 1 / wd])
        b, a = _tustin(num[::-1], den[::-1], dt)
        return dict(b_r=b, a_r=a, b_y=b, a_y=a)
    # velocity loop PI (kv, wi), position P (kp_pos), velocity from a filtered derivative, feedforward of the
    # reference's speed through a first-order command filter
    kv, wi, kp_pos = 2 * M * w / g, w / 4, w / 3
    wdv, wf = 8 * w, 3 * w
    pi = [wi * kv, kv]  # kv (1 + wi/s) = kv (wi + s)/s
    # C_y = kv (s+wi)/s · (kp_pos + s/(1+s/wdv)) = kv (s+wi)(kp_pos (1+s/wdv) + s) / (s (1+s/wdv))
    inner_y = P.polyadd(P.polymul([kp_pos], [1, 1 / wdv]), [0, 1])
    num_y = P.polymul(pi, inner_y)
    den_y = P.polymul([0, 1], [1, 1 / wdv])
    # C_r = kv (s+wi)/s · (kp_pos + s) / (1 + s/wf)
    num_r = P.polymul(pi, [kp_pos, 1])
    den_r = P.polymul([0, 1], [1, 1 / wf])
    if kind == "notch":  # a notch on the command at 2.5 bandwidths, depth 0.1
        wn, z1, z2 = 2.5 * w, 0.05, 0.5
        num_r = P.polymul(num_r, [wn ** 2, 2 * z1 * wn, 1])
        den_r = P.polymul(den_r, [wn ** 2, 2 * z2 * wn, 1])
    br, ar = _tustin(num_r[::-1], den_r[::-1], dt)
    by, ay = _tustin(num_y[::-1], den_y[::-1], dt)
    return dict(b_r=br, a_r=ar, b_y=by, a_y=ay)


# ---------------------------------------------------------------------------------------------------------------
# references


def moves(ax: dict, T: float, rng: np.random.Generator) -> np.ndarray:
    """Point-to-point moves at speeds from 3 % to 100 % of the top speed (log-uniform), each 0.45-1.5 s at its
    speed, rests of 0.2-0.6 s between, the corners rounded by a 20 ms moving
    average."""
    dt = 1 / ax["fs"]
    lo, hi = ax["stroke"]
    amax = ax["vmax"] / 0.15
    q = [lo + 0.5 * (hi - lo)]
    pos = q[0]
    while len(q) * dt < T:
        v = ax["vmax"] * 10 ** rng.uniform(-1.5, 0)
        # a move of 0.45-1.5 s at its speed (a slow move across the whole stroke would take the record), within the
        # stroke, turning back at its ends
        span = min(0.9 * (hi - lo), v * 1.5) * rng.uniform(0.3, 1.0)
        way = rng.choice([-1, 1])
        if not lo + 0.05 * (hi - lo) <= pos + way * span <= hi - 0.05 * (hi - lo):
            way = -way
        target = float(np.clip(pos + way * span, lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo)))
        d = target - pos
        # trapezoid (or triangle)
        ta = v / amax
        if abs(d) < v * ta:
            v = math.sqrt(abs(d) * amax)
            ta = v / amax
        tc = abs(d) / v - ta
        n = int(math.ceil((2 * ta + tc) / dt))
        t = np.arange(1, n + 1) * dt
        s = np.where(t < ta, 0.5 * amax * t ** 2,
                     np.where(t < ta + tc, 0.5 * amax * ta ** 2 + v * (t - ta),
                              abs(d) - 0.5 * amax * np.maximum(2 * ta + tc - t, 0) ** 2))
        q.extend((pos + np.sign(d) * np.minimum(s, abs(d))).tolist())
        pos = target
        q.extend([pos] * int(rng.uniform(0.2, 0.6) / dt))
    q = np.asarray(q[: int(T / dt) + 1])
    k = max(1, int(0.02 / dt))
    pad = np.concatenate([np.full(k, q[0]), q, np.full(k, q[-1])])
    return np.convolve(pad, np.ones(k) / k, "same")[k:-k]


def multisine(ax: dict, T: float, rng: np.random.Generator) -> np.ndarray:
    """Six sines from 0.05 to 1.5 Hz at random phases, scaled to the stroke and the top speed."""
    dt = 1 / ax["fs"]
    lo, hi = ax["stroke"]
    t = np.arange(int(T / dt) + 1) * dt
    f = np.geomspace(0.05, 1.5, 6)
    x = sum(np.sin(2 * math.pi * fi * t + rng.uniform(0, 2 * math.pi)) / (1 + i) for i, fi in enumerate(f))
    x = x / np.max(np.abs(x))
    v = np.max(np.abs(np.gradient(x, dt)))
    amp = min(0.45 * (hi - lo), 0.8 * ax["vmax"] / v)
    ramp = np.clip(t / 1.0, 0, 1)
    return 0.5 * (lo + hi) + amp * x * ramp * ramp


# ---------------------------------------------------------------------------------------------------------------
# the closed loop


@njit
def _sgn(v, law, eps):
    x = v / eps
    if law == 0:
        return math.tanh(x)
    if law == 1:
        return 2 / math.pi * math.atan(x)
    return math.copysign(1 - math.exp(-abs(x)), x)


@njit
def _accel(q, v, F, p, law):
    # p: M, Fv, Fc, eps, Fcn, Fvn, Fs, vs, Fcb_a, Fcb_q0, Fcb_w, rip_a, rip_p, rip_phi, OF
    M, Fv, Fc, eps = p[0], p[1], p[2], p[3]
    s = _sgn(v, law, eps)
    neg = 0.5 * (1 - s)  # 1 moving backward, 0 forward, smooth through zero as the law
    fc = Fc * (1 + p[8] * math.exp(-((q - p[9]) / p[10]) ** 2)) if p[10] > 0 else Fc
    fric = Fv * v + fc * s + neg * (p[4] * s + p[5] * v)
    if p[6] != 0:
        fric += p[6] * math.exp(-(v / p[7]) ** 2) * s
    if p[11] != 0:
        fric += p[11] * math.sin(2 * math.pi * q / p[12] + p[13])
    fric += p[14]
    return (F - fric) / M


@njit
def _loop(qr, dt, p, law, br, ar, by, ay, gain, sat, enc, delay, tau, noise, sub):
    n = len(qr)
    force = np.zeros(n)
    qm = np.zeros(n)
    q, v, fa = qr[0], 0.0, 0.0
    nb_r, na_r, nb_y, na_y = len(br), len(ar), len(by), len(ay)
    xr = np.zeros(nb_r)
    yr = np.zeros(na_r)
    xy = np.zeros(nb_y)
    yy = np.zeros(na_y)
    # the filters at rest on the first reference: they run on the positions' departures from it, from zero states
    # (every controller here integrates, so no static gain is added back)
    x0 = qr[0]
    cmd = np.zeros(n + delay + 1)
    h = dt / sub
    for k in range(n):
        qm[k] = round(q / enc) * enc
        # u_r = C_r qr, u_y = C_y qm (direct form I)
        for i in range(nb_r - 1, 0, -1):
            xr[i] = xr[i - 1]
        xr[0] = qr[k] - x0
        for i in range(nb_y - 1, 0, -1):
            xy[i] = xy[i - 1]
        xy[0] = qm[k] - x0
        ur = 0.0
        for i in range(nb_r):
            ur += br[i] * xr[i]
        for i in range(1, na_r):
            ur -= ar[i] * yr[i - 1]
        uy = 0.0
        for i in range(nb_y):
            uy += by[i] * xy[i]
        for i in range(1, na_y):
            uy -= ay[i] * yy[i - 1]
        for i in range(na_r - 1, 0, -1):
            yr[i] = yr[i - 1]
        yr[0] = ur
        for i in range(na_y - 1, 0, -1):
            yy[i] = yy[i - 1]
        yy[0] = uy
        u = ur - uy
        if u > sat:
            u = sat
        if u < -sat:
            u = -sat
        force[k] = gain * u
        cmd[k + delay] = force[k]
        Fin = cmd[k] + noise[k]
        for _ in range(sub):  # RK4 on (q, v, fa): fa the applied force after the lag
            if tau > 0:
                f1 = (Fin - fa) / tau
                k1q, k1v = v, _accel(q, v, fa, p, law)
                fa2 = fa + 0.5 * h * f1
                f2 = (Fin - fa2) / tau
                k2q, k2v = v + 0.5 * h * k1v, _accel(q + 0.5 * h * k1q, v + 0.5 * h * k1v, fa2, p, law)
                fa3 = fa + 0.5 * h * f2
                f3 = (Fin - fa3) / tau
                k3q, k3v = v + 0.5 * h * k2v, _accel(q + 0.5 * h * k2q, v + 0.5 * h * k2v, fa3, p, law)
                fa4 = fa + h * f3
                f4 = (Fin - fa4) / tau
                k4q, k4v = v + h * k3v, _accel(q + h * k3q, v + h * k3v, fa4, p, law)
                fa += h / 6 * (f1 + 2 * f2 + 2 * f3 + f4)
            else:
                fa = Fin
                k1q, k1v = v, _accel(q, v, fa, p, law)
                k2q, k2v = v + 0.5 * h * k1v, _accel(q + 0.5 * h * k1q, v + 0.5 * h * k1v, fa, p, law)
                k3q, k3v = v + 0.5 * h * k2v, _accel(q + 0.5 * h * k2q, v + 0.5 * h * k2v, fa, p, law)
                k4q, k4v = v + h * k3v, _accel(q + h * k3q, v + h * k3v, fa, p, law)
            q += h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q)
            v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return force, qm


def simulate(ax: dict, ctrl: dict, prm: dict, qr: np.ndarray, rng: np.random.Generator):
    dt = 1 / ax["fs"]
    p = np.array([ax["M"], ax["Fv"], ax["Fc"], ax["veps"], prm.get("Fcn_extra", 0.0), prm.get("Fvn_extra", 0.0),
                  prm.get("Fs_extra", 0.0), prm.get("vs", 1.0), prm.get("Fcb_a", 0.0), prm.get("Fcb_q0", 0.0),
                  prm.get("Fcb_w", 0.0), prm.get("rip_a", 0.0), prm.get("rip_p", 1.0), prm.get("rip_phi", 0.0),
                  prm.get("OF", 0.0)])
    a = math.exp(-2 * math.pi * ax["noise_hz"] * dt)
    w = rng.standard_normal(len(qr)) * ax["noise"] * math.sqrt((1 - a * a))
    noise = signal.lfilter([1.0], [1.0, -a], w)
    arr = {k: np.asarray(ctrl[k], float) for k in ("b_r", "a_r", "b_y", "a_y")}
    return _loop(qr, dt, p, LAWS[ax["law"]], arr["b_r"], arr["a_r"], arr["b_y"], arr["a_y"], ax["gain"], ax["sat"],
                 ax["enc"], int(prm.get("delay_samples", 0)), float(prm.get("tau_lag", 0.0)), noise, 16)


#: the records: (effect, axis, controller, validation reference); every effect on axes and controllers the shared
#: sample does not pair it with, and a clean record of every axis
CASES = [
    ("asymmetric_friction", "belt", "pic", "moves"), ("asymmetric_friction", "portal", "notch", "multisine"),
    ("asymmetric_friction", "wrist", "pid", "moves"), ("asymmetric_friction", "table", "pic", "moves"),
    ("stribeck", "portal", "pid", "moves"), ("stribeck", "spindle", "pic", "moves"),
    ("stribeck", "wrist", "notch", "moves"), ("stribeck", "table", "pid", "moves"),
    ("position_dependent_coulomb", "portal", "pic", "moves"), ("position_dependent_coulomb", "wrist", "pid", "moves"),
    ("position_dependent_coulomb", "spindle", "notch", "moves"),
    ("position_ripple", "belt", "pid", "moves"), ("position_ripple", "wrist", "pic", "multisine"),
    ("offset", "spindle", "pid", "moves"), ("offset", "table", "notch", "moves"),
    ("delay", "belt", "notch", "moves"), ("delay", "table", "pic", "moves"),
    ("force_lag", "wrist", "pic", "moves"), ("force_lag", "belt", "pid", "multisine"),
    ("none", "belt", "notch", "moves"), ("none", "portal", "pid", "multisine"), ("none", "spindle", "pic", "moves"),
    ("none", "wrist", "notch", "moves"), ("none", "table", "pid", "moves"),
]
LENGTH_S = {"belt": 18.0, "portal": 30.0, "spindle": 12.0, "wrist": 24.0, "table": 40.0}


def make(out: str, seed: int) -> dict:
    axes_dir = os.path.join(out, "axes")
    os.makedirs(axes_dir, exist_ok=True)
    truth = {}
    for i, (effect, axis, kind, vref) in enumerate(CASES):
        ax = AXES[axis]
        rng = np.random.default_rng([seed, i])
        name = f"{'null' if effect == 'none' else effect}_{axis}_{kind}"
        prm = effect_params(effect, ax, rng)
        ctrl = controller(kind, ax)
        entry = dict(axis=axis, units={"q": ax["unit"], "force": "N" if ax["unit"] == "m" else "N*m"},
                     dt=1 / ax["fs"], controller=kind, model="rigid", effects=[] if effect == "none" else [effect],
                     params=dict(M1=ax["M"], Fv1=ax["Fv"], Fc1=ax["Fc"], veps=ax["veps"], law=ax["law"], **prm),
                     encoder=ax["enc"], noise_sigma=ax["noise"], noise_lp_hz=ax["noise_hz"], records={})
        for part, ref in (("train", "moves"), ("valid", vref)):
            T = LENGTH_S[axis]
            qr = moves(ax, T, rng) if ref == "moves" else multisine(ax, T, rng)
            force, qm = simulate(ax, ctrl, prm, qr, rng)
            if not np.all(np.isfinite(force)) or np.max(np.abs(qr - qm)) > 0.2 * (ax["stroke"][1] - ax["stroke"][0]):
                raise RuntimeError(f"{name} {part}: the loop is unstable (largest tracking error "
                                   f"{np.max(np.abs(qr - qm)):.3g})")
            f = f"{name}_{part}.csv"
            t = np.arange(len(qr)) / ax["fs"]
            np.savetxt(os.path.join(axes_dir, f), np.column_stack([t, qr, force, qm]), delimiter=",",
                       header="t,qr,force,qm", comments="", fmt="%.10g")
            with open(os.path.join(axes_dir, f"{name}_{part}_controller.json"), "w") as fh:
                json.dump(dict(type="transfer_function", dt=1 / ax["fs"], **ctrl, saturation=ax["sat"],
                               gain=ax["gain"]), fh, indent=1)
            entry["records"][part] = {"file": f, "reference": ref}
        truth[name] = entry
    with open(os.path.join(axes_dir, "truth.json"), "w") as fh:
        json.dump(truth, fh, indent=1)
    return truth


def _run(args):
    name, entry = args
    import doctor_axes  # noqa: E402 - reads DIDIM_TRUTHBENCH_DIR at import

    return name, doctor_axes.run_one(name, entry)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="/tmp/didim_axes_heldout", help="where the records go")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--doc", default=None, help="write the table to this markdown file")
    ap.add_argument("--only", default="", help="comma-separated record names")
    a = ap.parse_args()
    t0 = time.perf_counter()
    truth = make(a.out, a.seed)
    print(f"made {len(truth)} records in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    os.environ["DIDIM_TRUTHBENCH_DIR"] = a.out
    os.environ.setdefault("RAYON_NUM_THREADS", "1")
    sys.path.insert(0, HERE)
    names = [n for n in truth if not a.only or n in a.only.split(",")]
    res = {}
    with ProcessPoolExecutor(a.jobs) as ex:
        for name, r in ex.map(_run, [(n, truth[n]) for n in names]):
            res[name] = r
            print(f"{name:<42} {r['time_s']:5.1f} s truth {r['truth']} named "
                  f"{r.get('named', r.get('error'))}{' +unnamed' if r.get('unnamed') else ''}", file=sys.stderr,
                  flush=True)
    alias = {"force_lag": "delay"}
    eff = [n for n in res if res[n]["truth"]]
    nul = [n for n in res if not res[n]["truth"]]
    named = [n for n in eff if alias.get(truth[n]["effects"][0], truth[n]["effects"][0]) in res[n].get("named", [])]
    alarms = [n for n in nul if res[n].get("named") or res[n].get("unnamed") or not res[n]["ok"]]
    crashes = [n for n in res if not res[n]["ok"]]
    lines = [f"- concealed effects named: {len(named)} of {len(eff)}",
             f"- clean records with a finding: {len(alarms)} of {len(nul)}",
             f"- crashes: {len(crashes)}", "",
             "| record | law | truth | named | held-out error (first finding) | doctor (s) |", "|---|---|---|---|---|---:|"]
    for n, r in res.items():
        e = truth[n]
        lines.append(f"| {n} | {e['params']['law']} | {', '.join(r['truth']) or '—'} | "
                     f"{(', '.join(r.get('named', [])) + (' +unnamed' if r.get('unnamed') else '')) if r['ok'] else r['error']}"
                     f" | {r.get('heldout', '')} | {r['time_s']:.1f} |")
    print("\n".join(lines))
    if a.doc:
        with open(a.doc, "w", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")
        with open(os.path.splitext(a.doc)[0] + ".json", "w", encoding="utf-8") as fh:
            json.dump({k: {kk: vv for kk, vv in v.items() if kk != "trace"} for k, v in res.items()}, fh, indent=1,
                      default=float)


if __name__ == "__main__":
    main()
