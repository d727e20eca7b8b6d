"""didim against what a user would otherwise write, measured in one run on this machine; writes docs/benchmarks.md.

    RAYON_NUM_THREADS=1 python benches/compare.py [--quick] [--out docs/benchmarks.md]

One core unless said otherwise (the script sets RAYON_NUM_THREADS=1 for itself; the batch section also measures two
threads in a subprocess). Times are the best of several repetitions (the machine is shared; the load average is
printed), accuracies are against a reference integration with a ten times smaller step than the RK4 default (RK4 with
100 substeps per 1 ms sample, didim's own RK4 path). References:

- SciPy's ``solve_ivp`` closed loop, integrating the plant between samples with the held command (RK45);
- an RK4 loop with 10 substeps per sample JIT-compiled by numba (if installed) and the same loop in plain Python on a
  shortened record, extrapolated to the full length (labelled so);
- SciPy's ``sosfiltfilt``/``filtfilt`` on Y and a 7-column W in one call (axis 0), then slicing;
- NumPy's ``lstsq`` (LAPACK gelsd) on a DIDIM system;
- for the identifications, the paper's reported times (2 GHz dual core) and the same code with the RK4 simulator.
"""

from __future__ import annotations

import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pathlib  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.signal as ss  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
import didim  # noqa: E402
from didim import _core  # noqa: E402
from didim import scenarios as sc  # noqa: E402
from didim.formats._io import write_text  # noqa: E402
from didim.signal import Decimation  # noqa: E402

EMPS_DIR = pathlib.Path(os.environ.get("DIDIM_EMPS_DIR", ROOT.parent / "shared" / "data" / "emps"))
TRUTHBENCH = pathlib.Path(os.environ.get("DIDIM_TRUTHBENCH_DIR", ROOT.parent / "shared" / "data" / "truthbench"))
TABLE3 = dict(M1=68.0, Fv1=104.0, Fc1=10.0, M2=38.0, Fv2=96.5, Fc2=9.5, K12=8.8e5)
MOTOR_FRICTION = dict(TABLE3, Fv1=200.5, Fc1=19.5, Fv2=0.0, Fc2=0.0)
EPS = didim.DEFAULT_COULOMB_EPS


def best(f, repeat=5, budget_s=20.0):
    """Best wall time of up to ``repeat`` calls (fewer if the budget runs out), and the last result."""
    times, out = [], None
    t_start = time.perf_counter()
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
        if time.perf_counter() - t_start > budget_s:
            break
    return min(times), out


def rel(a, b):
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))


# --------------------------------------------------------------------------------------------------------------------
# Reference closed-loop simulators a user would write (EMPS cascade, flexible model, smooth Coulomb sign)
# --------------------------------------------------------------------------------------------------------------------


def controller(c, qr, qm, qm2, dt):
    vir = c.kv * (c.kp * (qr - qm) - (qm - qm2) / (2 * dt))
    return c.gtau * min(max(vir, -c.vsat), c.vsat)


def simulate_solve_ivp(rec, p, n, rtol=1e-8, atol=1e-12):
    M1, Fv1, Fc1, M2, Fv2, Fc2, K = (p[k] for k in ("M1", "Fv1", "Fc1", "M2", "Fv2", "Fc2", "K12"))

    def rhs(t, x, tau):
        q1, q12, v1, v12 = x
        spring = K * (q1 - q12)
        a1 = (tau - Fv1 * v1 - Fc1 * v1 / math.sqrt(v1 * v1 + EPS * EPS) - spring) / M1
        a2 = (-Fv2 * v12 - Fc2 * v12 / math.sqrt(v12 * v12 + EPS * EPS) + spring) / M2
        return [v1, v12, a1, a2]

    x = np.array([rec.qr[0], rec.qr[0], 0.0, 0.0])
    force = np.empty(n)
    qm1 = qm2 = x[0]
    for k in range(n):
        tau = controller(rec.controller, rec.qr[k], x[0], qm2, rec.dt)
        qm2, qm1 = qm1, x[0]
        force[k] = tau
        if k + 1 < n:
            x = solve_ivp(rhs, (0.0, rec.dt), x, args=(tau,), rtol=rtol, atol=atol).y[:, -1]
    return force


def rk4_python(qr, dt, gains, p, n, substeps=10):
    kp, kv, gtau, vsat = gains
    M1, Fv1, Fc1, M2, Fv2, Fc2, K = p
    q1 = q12 = qr[0]
    v1 = v12 = 0.0
    qm1 = qm2 = q1
    h = dt / substeps
    e2 = EPS * EPS
    force = [0.0] * n
    for k in range(n):
        vir = kv * (kp * (qr[k] - q1) - (q1 - qm2) / (2 * dt))
        tau = gtau * min(max(vir, -vsat), vsat)
        qm2, qm1 = qm1, q1
        force[k] = tau
        for _ in range(substeps):
            def acc(a, b, c, d):
                s = K * (a - b)
                return ((tau - Fv1 * c - Fc1 * c / math.sqrt(c * c + e2) - s) / M1,
                        (-Fv2 * d - Fc2 * d / math.sqrt(d * d + e2) + s) / M2)
            k1a, k1b = acc(q1, q12, v1, v12)
            k2a, k2b = acc(q1 + 0.5 * h * v1, q12 + 0.5 * h * v12, v1 + 0.5 * h * k1a, v12 + 0.5 * h * k1b)
            v2a, v2b = v1 + 0.5 * h * k1a, v12 + 0.5 * h * k1b
            k3a, k3b = acc(q1 + 0.5 * h * v2a, q12 + 0.5 * h * v2b, v1 + 0.5 * h * k2a, v12 + 0.5 * h * k2b)
            v3a, v3b = v1 + 0.5 * h * k2a, v12 + 0.5 * h * k2b
            k4a, k4b = acc(q1 + h * v3a, q12 + h * v3b, v1 + h * k3a, v12 + h * k3b)
            v4a, v4b = v1 + h * k3a, v12 + h * k3b
            q1 += h / 6 * (v1 + 2 * (v2a + v3a) + v4a)
            q12 += h / 6 * (v12 + 2 * (v2b + v3b) + v4b)
            v1 += h / 6 * (k1a + 2 * (k2a + k3a) + k4a)
            v12 += h / 6 * (k1b + 2 * (k2b + k3b) + k4b)
    return np.array(force)


def numba_rk4():
    try:
        import numba
    except ImportError:
        return None, None
    src_fn = rk4_python.__code__  # noqa: F841 (the JIT version below is the same loop, written for numba)

    @numba.njit(cache=False, fastmath=False)
    def rk4_numba(qr, dt, gains, p, n, substeps, quant=0.0):
        kp, kv, gtau, vsat = gains[0], gains[1], gains[2], gains[3]
        M1, Fv1, Fc1, M2, Fv2, Fc2, K = p[0], p[1], p[2], p[3], p[4], p[5], p[6]
        q1 = qr[0]
        q12 = qr[0]
        v1 = 0.0
        v12 = 0.0
        qm1 = q1 if quant == 0.0 else np.round(q1 / quant) * quant
        qm2 = qm1
        h = dt / substeps
        e2 = 1e-4 * 1e-4
        force = np.empty(n)
        for k in range(n):
            qm = q1 if quant == 0.0 else np.round(q1 / quant) * quant  # the encoder, as didim's quantizer
            vir = kv * (kp * (qr[k] - qm) - (qm - qm2) / (2 * dt))
            tau = gtau * min(max(vir, -vsat), vsat)
            qm2 = qm1
            qm1 = qm
            force[k] = tau
            for _ in range(substeps):
                s = K * (q1 - q12)
                k1a = (tau - Fv1 * v1 - Fc1 * v1 / math.sqrt(v1 * v1 + e2) - s) / M1
                k1b = (-Fv2 * v12 - Fc2 * v12 / math.sqrt(v12 * v12 + e2) + s) / M2
                v2a = v1 + 0.5 * h * k1a
                v2b = v12 + 0.5 * h * k1b
                s = K * ((q1 + 0.5 * h * v1) - (q12 + 0.5 * h * v12))
                k2a = (tau - Fv1 * v2a - Fc1 * v2a / math.sqrt(v2a * v2a + e2) - s) / M1
                k2b = (-Fv2 * v2b - Fc2 * v2b / math.sqrt(v2b * v2b + e2) + s) / M2
                v3a = v1 + 0.5 * h * k2a
                v3b = v12 + 0.5 * h * k2b
                s = K * ((q1 + 0.5 * h * v2a) - (q12 + 0.5 * h * v2b))
                k3a = (tau - Fv1 * v3a - Fc1 * v3a / math.sqrt(v3a * v3a + e2) - s) / M1
                k3b = (-Fv2 * v3b - Fc2 * v3b / math.sqrt(v3b * v3b + e2) + s) / M2
                v4a = v1 + h * k3a
                v4b = v12 + h * k3b
                s = K * ((q1 + h * v3a) - (q12 + h * v3b))
                k4a = (tau - Fv1 * v4a - Fc1 * v4a / math.sqrt(v4a * v4a + e2) - s) / M1
                k4b = (-Fv2 * v4b - Fc2 * v4b / math.sqrt(v4b * v4b + e2) + s) / M2
                q1 += h / 6 * (v1 + 2 * (v2a + v3a) + v4a)
                q12 += h / 6 * (v12 + 2 * (v2b + v3b) + v4b)
                v1 += h / 6 * (k1a + 2 * (k2a + k3a) + k4a)
                v12 += h / 6 * (k1b + 2 * (k2b + k3b) + k4b)
        return force

    return rk4_numba, numba.__version__


# --------------------------------------------------------------------------------------------------------------------


class Table:
    """Rows: what was timed, its time, what it is compared with and that time, and the speed-up of didim (the
    compared-with time over the row's time for a didim row; the row's time over didim's for a reference row)."""

    def __init__(self):
        self.rows = []

    def add(self, section, what, seconds, other=None, other_seconds=None, accuracy="", *, didim_row=True):
        speedup = None
        if other_seconds and seconds:
            speedup = other_seconds / seconds if didim_row else seconds / other_seconds
        self.rows.append((section, what, seconds, other, other_seconds, speedup, accuracy))
        r = f"didim {speedup:.1f}x faster ({other})" if speedup else ""
        print(f"  {what:<62} {fmt_t(seconds):>10}  {r:<50} {accuracy}", flush=True)

    def markdown(self) -> str:
        out = []
        section = None
        for sec, what, s, other, os_, speedup, acc in self.rows:
            if sec != section:
                out += ["", f"### {sec}", "", "| what | time | compared with | its time | didim speed-up | accuracy / note |",
                        "|---|---|---|---|---|---|"]
                section = sec
            out.append(f"| {what} | {fmt_t(s)} | {other or ''} | {fmt_t(os_) if os_ else ''} | "
                       f"{f'{speedup:.1f}×' if speedup else ''} | {acc} |")
        return "\n".join(out)


def fmt_t(s):
    if s is None:
        return ""
    if s < 1e-3:
        return f"{s * 1e6:.0f} µs"
    if s < 1:
        return f"{s * 1e3:.2f} ms"
    return f"{s:.2f} s"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer repetitions, shorter references")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    args = ap.parse_args()
    rep = 3 if args.quick else 7
    load0 = os.getloadavg()
    t_all = time.perf_counter()
    tab = Table()

    rec = didim.load_mat(EMPS_DIR / "DATA_EMPS.mat")
    # lead_in=None: every reference implementation below starts at rest on the first reference sample, as the paper
    plain = didim.Recording(dt=rec.dt, qr=rec.qr, force=rec.force, qm=rec.qm, controller=rec.controller, lead_in=None)
    n = plain.n
    p = np.array(list(TABLE3.values()))
    gains = np.array(rec.controller.gains)

    # ---------------------------------------------------------------- the real record, as loaded
    print("one closed-loop simulation of DATA_EMPS as loaded (encoder quantizer)", flush=True)
    numba_fn, numba_version = numba_rk4()
    quant = 5e-8  # the EMPS encoder's resolution (its README); load_mat does not set it by itself
    recq = dataclasses.replace(didim.load_mat(EMPS_DIR / "DATA_EMPS.mat", position_resolution=quant), lead_in=None)
    sec = (f"One closed-loop simulation of DATA_EMPS with its {quant:g} m encoder quantizer "
           "(`load_mat(path, position_resolution=5e-8)`, flexible model, one core): the headline case")
    ref_q = didim.simulate(recq, TABLE3, "flexible", integrator="rk4", substeps=100).force
    t_q, s_q = best(lambda: didim.simulate(recq, TABLE3, "flexible"), repeat=5 * rep)
    t_q_rk4, s_q_rk4 = best(lambda: didim.simulate(recq, TABLE3, "flexible", integrator="rk4"), repeat=rep)
    accq = lambda f: f"force ‖Δ‖/‖ref‖ = {rel(f, ref_q):.1e}"  # noqa: E731
    tab.add(sec, "didim.simulate(rec, params, 'flexible'), exponential integrator (default)", t_q,
            accuracy=accq(s_q.force) + " (in a quantized loop every integrator, numba's RK4 included, differs from "
            "the finer one by whole encoder counts; the accuracy without the quantizer is in the next section)")
    if numba_fn is not None:
        numba_fn(recq.qr, recq.dt, gains, p, n, 10, quant)  # compile
        t_nq, f_nq = best(lambda: numba_fn(recq.qr, recq.dt, gains, p, n, 10, quant), repeat=rep)
        tab.add(sec, f"numba {numba_version} JIT RK4 loop, 10 substeps, same quantizer", t_nq, "didim exponential",
                t_q, accq(f_nq) + " (target: didim ≥ 15× faster)", didim_row=False)
        tab.add(sec, "didim RK4, 10 substeps (integrator='rk4')", t_q_rk4, "numba RK4 loop, 10 substeps", t_nq,
                accq(s_q_rk4.force) + " (target: within 1.2× of numba)")

    # ---------------------------------------------------------------- one simulation
    print("one closed-loop simulation, flexible model, EMPS reference (24,841 samples)", flush=True)
    sec = "One closed-loop simulation (flexible model, 24,841-sample EMPS reference, one core)"
    ref = didim.simulate(plain, TABLE3, "flexible", integrator="rk4", substeps=100).force
    t_exp, s_exp = best(lambda: didim.simulate(plain, TABLE3, "flexible"), repeat=5 * rep)
    t_rk4, s_rk4 = best(lambda: didim.simulate(plain, TABLE3, "flexible", integrator="rk4"), repeat=rep)
    pb = didim.simulation.problem(plain, "flexible")
    t_core, _ = best(lambda: pb.simulate(p), repeat=5 * rep)
    t_numba = None
    if numba_fn is not None:
        t0 = time.perf_counter()
        f_numba = numba_fn(plain.qr, plain.dt, gains, p, n, 10)
        t_jit = time.perf_counter() - t0
        t_numba, f_numba = best(lambda: numba_fn(plain.qr, plain.dt, gains, p, n, 10), repeat=rep)
    n_ivp = n if not args.quick else 2000
    t_ivp, f_ivp = best(lambda: simulate_solve_ivp(plain, TABLE3, n_ivp), repeat=1, budget_s=0)
    t_ivp *= n / n_ivp
    n_py = 2500 if not args.quick else 500
    t_py, f_py = best(lambda: rk4_python(plain.qr, plain.dt, gains, p, n_py), repeat=1, budget_s=0)
    t_py_full = t_py * n / n_py
    acc = lambda f, m=n: f"force ‖Δ‖/‖ref‖ = {rel(f, ref[:m]):.1e}"  # noqa: E731
    tab.add(sec, "didim, exponential integrator (default), from Python", t_exp, accuracy=acc(s_exp.force))
    tab.add(sec, "didim, exponential integrator, core call only (Problem.simulate)", t_core)
    tab.add(sec, "didim, RK4 with 10 substeps (Rust, the previous default)", t_rk4, "didim exponential", t_exp,
            acc(s_rk4.force), didim_row=False)
    if t_numba is not None:
        tab.add(sec, f"numba {numba_version} JIT RK4 loop, 10 substeps", t_numba, "didim exponential", t_exp,
                acc(f_numba) + f" (JIT compile {t_jit:.1f} s not counted)", didim_row=False)
    tab.add(sec, "SciPy solve_ivp (RK45, rtol 1e-8, atol 1e-12) between samples"
            + (f" (first {n_ivp} samples, extrapolated)" if n_ivp < n else ""), t_ivp, "didim exponential", t_exp,
            acc(f_ivp, n_ivp), didim_row=False)
    tab.add(sec, f"plain Python RK4 loop, 10 substeps (first {n_py} samples, extrapolated ×{n / n_py:.2f})",
            t_py_full, "didim exponential", t_exp, acc(f_py, n_py), didim_row=False)

    # ---------------------------------------------------------------- the lead-in's cost
    print("the lead-in's cost: the record as loaded (through its lead-in) against the same from rest", flush=True)
    sec = (f"The default path through a lead-in (DATA_EMPS as loaded: {rec.qr_lead.size} lead-in samples) against "
           "the same simulation from rest on the first sample, one core (target: at most 1.10×)")
    rigid = dict(M=TABLE3["M1"] + TABLE3["M2"], Fv=TABLE3["Fv1"] + TABLE3["Fv2"], Fc=TABLE3["Fc1"] + TABLE3["Fc2"])
    for kind, params in (("rigid", rigid), ("flexible", TABLE3)):
        t_lead, _ = best(lambda: didim.simulate(rec, params, kind), repeat=10 * rep)
        t_rest, _ = best(lambda: didim.simulate(plain, params, kind), repeat=10 * rep)
        tab.add(sec, f"didim.simulate(rec, params, '{kind}') through the lead-in", t_lead, "from rest (lead_in=None)",
                t_rest, f"cost of the lead-in: {t_lead / t_rest:.2f}× (target ≤ 1.10×)", didim_row=False)

    # ---------------------------------------------------------------- sensitivities
    pb_exp = _core.Problem(_core.Model("flexible"), plain.qr, plain.dt, "emps", list(gains))
    pb_rk4 = _core.Problem(_core.Model("flexible"), plain.qr, plain.dt, "emps", list(gains), integrator="rk4")
    t_sens, _ = best(lambda: pb_exp.simulate_sensitivity(p), repeat=rep)
    t_sens_rk4, _ = best(lambda: pb_rk4.simulate_sensitivity(p), repeat=2)
    tab.add(sec, "didim forward sensitivities (7 parameters), exponential", t_sens, "same with RK4 10 substeps",
            t_sens_rk4)

    # ---------------------------------------------------------------- decimation
    print("decimation of Y and a 7-column W", flush=True)
    sec = "Decimation of Y and a 7-column W (24,841 samples, one core)"
    rng = np.random.default_rng(0)
    y = rec.force.copy()
    w = np.column_stack([np.cumsum(rng.standard_normal(n)) for _ in range(7)])
    x8 = np.column_stack([y, w])
    dec = Decimation.lowpass(60.0, rec.fs)  # Butterworth 4, sos, factor 6
    sos = ss.butter(4, 60.0 / 500.0, output="sos")
    t_d, (yd, wd) = best(lambda: dec.apply(y, w), repeat=10 * rep)
    t_s, xs = best(lambda: ss.sosfiltfilt(sos, x8, axis=0)[:: dec.factor], repeat=10 * rep)
    err = np.max(np.abs(np.column_stack([yd, wd]) - xs)) / np.max(np.abs(xs))
    tab.add(sec, "didim Decimation.lowpass(60 Hz) (Butterworth 4, sos, factor 6)", t_d, "SciPy sosfiltfilt(axis=0)[::6]",
            t_s, f"max diff {err:.1e} (relative)")
    decm = Decimation.matlab(10)
    b, a = ss.cheby1(8, 0.05, 0.8 / 10)
    pad = 3 * (max(len(a), len(b)) - 1)
    t_dm, (ydm, wdm) = best(lambda: decm.apply(y, w), repeat=10 * rep)
    start = (n - 1) - ((n + 9) // 10 - 1) * 10
    t_sm, xm = best(lambda: ss.filtfilt(b, a, x8, axis=0, padlen=pad)[start::10], repeat=10 * rep)
    err = np.max(np.abs(np.column_stack([ydm, wdm]) - xm)) / np.max(np.abs(xm))
    tab.add(sec, "didim Decimation.matlab(10) (Chebyshev I 8, ba)", t_dm, "SciPy filtfilt(axis=0)[start::10]", t_sm,
            f"max diff {err:.1e} (relative)")

    # ---------------------------------------------------------------- least squares
    print("least squares", flush=True)
    sec = "Least squares on a DIDIM system (flexible, 2 × 4,141 rows, 7 columns, one core)"
    sim = didim.simulate(rec, TABLE3, "flexible")
    pbf = didim.simulation.problem(rec, "flexible")
    ys, ws, _ = pbf.didim_system(p, rec.force, list(range(7)), dec.core)
    t_ls, sol = best(lambda: _core.lstsq(ws, ys), repeat=10 * rep)
    t_np, xnp = best(lambda: np.linalg.lstsq(ws, ys, rcond=None)[0], repeat=10 * rep)
    tab.add(sec, "didim lstsq (column-pivoted QR, σ, covariance, base parameters)", t_ls, "numpy.linalg.lstsq (gelsd)",
            t_np, f"max rel. diff {np.max(np.abs(sol['params'] - xnp) / np.abs(xnp)):.1e}")

    # ---------------------------------------------------------------- identification
    print("identifications", flush=True)
    sec = "Identification end to end from a loaded record (one core)"
    simrec = sc.make_recording(MOTOR_FRICTION, "flexible", qr=rec.qr.copy(), force_noise=1.0, seed=11,
                               name="flexible EMPS, real reference")
    table3rec = sc.make_recording(TABLE3, "flexible", qr=rec.qr.copy(), force_noise=1.0, seed=11)
    t_r, r_r = best(lambda: didim.identify(rec, "rigid", "didim", apM=78.0, offset=True), repeat=rep)
    tab.add(sec, f"rigid DIDIM on DATA_EMPS ({r_r.iterations} it., {r_r.simulations} sim.)", t_r, "paper (rigid DIDIM)",
            4.0)
    t_f, r_f = best(lambda: didim.identify(simrec, "flexible", "didim", apM=78.0), repeat=rep)
    t_f_rk4, _ = best(lambda: didim.identify(simrec, "flexible", "didim", apM=78.0, integrator="rk4"), repeat=1,
                      budget_s=0)
    conv = lambda r: "converged" if r.converged else "not converged"  # noqa: E731
    tab.add(sec, f"three-step DIDIM, simulated flexible EMPS ({r_f.simulations} sim.)", t_f, "paper (flexible DIDIM)",
            6.0, f"{conv(r_f)}; target ≤ 0.5 s")
    tab.add(sec, "same with the RK4 simulator", t_f_rk4, "three-step DIDIM, exponential", t_f, didim_row=False)
    t_fr, r_fr = best(lambda: didim.identify(rec, "flexible", "didim", apM=78.0, offset=True), repeat=rep)
    tab.add(sec, f"three-step DIDIM on DATA_EMPS ({r_fr.simulations} sim.)", t_fr, "paper (flexible DIDIM)", 6.0,
            ("flagged by didim: " + r_fr.message.split(";")[0] if not r_fr.converged else "converged")
            + "; target ≤ 0.5 s")
    t_gn, r_gn = best(lambda: didim.identify(table3rec, "flexible", "oe-gn", apM=78.0), repeat=rep)
    t_gn_rk4, _ = best(lambda: didim.identify(table3rec, "flexible", "oe-gn", apM=78.0, integrator="rk4"), repeat=1,
                       budget_s=0)
    tab.add(sec, f"exact-sensitivity OE (oe-lm), Table 3 truth ({r_gn.iterations} it., {r_gn.simulations} sim.)",
            t_gn, "same with the RK4 simulator", t_gn_rk4, f"{conv(r_gn)}; target ≤ 1 s")
    t_nm, r_nm = best(lambda: didim.identify(table3rec, "flexible", "oe-nm", apM=78.0), repeat=max(1, rep // 3))
    tab.add(sec, f"Nelder–Mead OE (oe-nm), Table 3 truth ({r_nm.iterations} it., {r_nm.simulations} sim.)", t_nm,
            "paper (Nelder–Mead OE, 9 min)", 540.0, f"{conv(r_nm)}; target ≤ 10 s")
    if not args.quick:
        t_nm_rk4, _ = best(lambda: didim.identify(table3rec, "flexible", "oe-nm", apM=78.0, integrator="rk4"),
                           repeat=1, budget_s=0)
        tab.add(sec, "same with the RK4 simulator", t_nm_rk4, "Nelder–Mead OE, exponential", t_nm, didim_row=False)

    # ---------------------------------------------------------------- three-step DIDIM on records from elsewhere
    print("three-step DIDIM on the truthbench paper-like records", flush=True)
    sec = ("Three-step DIDIM on the truthbench paper-like flexible records (independent simulator, one core; "
           "warm: the first call in a process also imports scipy.optimize, about 0.6 s)")
    truth = json.loads((TRUTHBENCH / "truth.json").read_text())
    for path in sorted((TRUTHBENCH / "flexible").glob("*.mat")):
        tb = didim.load_record(path)
        tp = dict(truth[f"flexible/{path.stem}"]["params"])
        tp["K12"] = tp.pop("K")
        t_tb, r_tb = best(lambda: didim.identify(tb, "flexible", "didim"), repeat=rep)
        errs = ", ".join(f"{k} {100 * (r_tb.params[k] / tp[k] - 1):+.1f} %" for k in ("M1", "M2", "K12"))
        tab.add(sec, f"{path.stem} ({r_tb.simulations} sim., variant {r_tb.options.get('variant')})", t_tb,
                "paper (flexible DIDIM)", 6.0, f"{conv(r_tb)}; {errs}; target ≤ 0.5 s")

    # ---------------------------------------------------------------- batch
    print("batch", flush=True)
    sec = "Batched simulation (32 flexible parameter sets, EMPS reference)"
    sets = p[None, :] * (1 + 0.02 * rng.standard_normal((32, 7)))
    t_loop, _ = best(lambda: [pb.simulate(x) for x in sets], repeat=rep)
    t_b1, _ = best(lambda: pb.simulate_batch(sets), repeat=rep)
    code = ("import time, numpy as np, didim; r=didim.load_mat(%r); "
            "d=didim.Recording(dt=r.dt, qr=r.qr, force=r.force, qm=r.qm, controller=r.controller, lead_in=None); "
            "pb=didim.simulation.problem(d,'flexible'); s=np.array(%r); pb.simulate_batch(s); t=[]\n"
            "for _ in range(%d):\n t0=time.perf_counter(); pb.simulate_batch(s); t.append(time.perf_counter()-t0)\n"
            "print(min(t))") % (str(EMPS_DIR / "DATA_EMPS.mat"), sets.tolist(), rep)
    env = dict(os.environ, RAYON_NUM_THREADS="2")
    t_b2 = float(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                check=True).stdout.strip())
    tab.add(sec, "simulate_batch, 1 thread", t_b1, "loop of Problem.simulate", t_loop)
    tab.add(sec, "simulate_batch, 2 threads (both cores)", t_b2, "simulate_batch, 1 thread", t_b1)

    load1 = os.getloadavg()
    header = [
        "# Benchmarks: didim against what a user would otherwise write",
        "",
        f"Measured by `RAYON_NUM_THREADS=1 python benches/compare.py` on {time.strftime('%Y-%m-%d %H:%M')}: "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores shared with other jobs (load average "
        f"{load0[0]:.1f} at the start, {load1[0]:.1f} at the end), Python {platform.python_version()}, NumPy "
        f"{np.__version__}, SciPy {scipy.__version__}" + (f", numba {numba_version}" if numba_version else "") +
        f". Whole run {time.perf_counter() - t_all:.0f} s. Times are the best of several repetitions; "
        "\"didim speed-up\" is the reference's time over didim's. Accuracy: the simulated force against RK4 with "
        "100 substeps (a step ten times smaller than RK4's default), with the record's encoder quantizer in the first "
        "section and none in the second.",
    ]
    write_text(args.out, "\n".join(header) + "\n" + tab.markdown() + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
