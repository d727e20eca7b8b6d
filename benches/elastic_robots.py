"""Elastic-joint robots, measured in one run (issue 39): didim's elastic closed loop against a Python loop over
Pinocchio's forward dynamics with the same integrator and plant (Spong's model), the three-step DIDIM and OE-LM on the
flexrobots records on one core, and the same on an elastic robot of this script's own making (its own plant: the
Python loop over Pinocchio, another friction law, another encoder and controllers), and on held-out elastic robots
of other kinds (``HELD_OUT``: a belt-driven prismatic axis, vertical and horizontal, with a SCARA shoulder; a UR10 under
PID at 500 Hz), against the truth and with a rigid model beside. Writes docs/elastic_robots.md (``--held-out``: only the
held-out robots' section, replaced in place).

    python benches/elastic_robots.py [--out docs/elastic_robots.md] [--quick] [--own-only] [--held-out [NAME,...]]

Needs pin (Pinocchio) and example-robot-data (pip install -e '.[test]') and ../shared/data/flexrobots.
"""

from __future__ import annotations

import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pathlib  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import types  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

import didim  # noqa: E402
from didim import _core  # noqa: E402
from didim.methods.robot import _model_of, deflection_errors, force_errors, simulate_robot, theta_of  # noqa: E402,E501

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from robots import Law, Panda, best_of, excitation, header, write_controllers, write_record  # noqa: E402
from heldout_robots import (PRIS_STEP, _ur_urdf, box_inertia, cascade_tf, friction_shape,  # noqa: E402
                            own_urdf, perturb_inertia, pid_tf)

ROOT = pathlib.Path(__file__).resolve().parents[1]
FLEX = pathlib.Path(os.environ.get("DIDIM_FLEXROBOTS_DIR", ROOT.parent / "shared" / "data" / "flexrobots"))


def pin_elastic_loop(model, Ia, Fv, Fc, offset, friction, K, D, elastic, controllers, qr, dt, substeps, step, force0,
                     noise=None, link=False, backlash=None):
    """The closed loop in Python over Pinocchio's aba: rigid joints with their rotor as armature and their friction
    at the link's speed; elastic joints (``elastic``, a mask) with their rotor, friction and the drive's torque on the
    motor side, whose position the encoder reads, and the spring K (θ − q) + D (θ̇ − q̇) on the link (N·m/rad, or N/m
    on a prismatic joint). RK4 with ``substeps`` per sample on (q, q̇, θ, θ̇), the torque (plus ``noise``) held over
    the sample; from rest at the first reference, the links where the springs hold gravity. ``step``: the encoders'
    step, one for every joint or one per joint (rad, m; 0: no rounding); ``friction(v)``: the Coulomb law's shape of
    the joints' speeds (a vector). Returns the force and the motor encoders, and with ``link`` the link positions q
    too. ``backlash`` (per joint, the total width b of a dead zone, rad or m; None: none): the elastic joints' motor
    and link coupled through it, K (x − clip(x, −b/2, b/2)) + D (θ̇ − q̇)·[|x| > b/2], x = θ − q."""
    data = model.createData()
    gap = 0.5 * np.broadcast_to(np.asarray(0.0 if backlash is None else backlash, float), (model.nv,))
    el = np.asarray(elastic, bool)
    Ia, Fv, Fc, offset, K, D = (np.asarray(x, float) for x in (Ia, Fv, Fc, offset, K, D))
    model.armature = np.where(el, 0.0, Ia)
    laws = [Law(c) for c in controllers]
    n, N = model.nv, len(qr)
    th = qr[0].copy()
    q = th.copy()
    for _ in range(100):  # K (θ − q) = g(q) on the elastic joints
        g = pin.computeGeneralizedGravity(model, data, q)
        q = np.where(el, th - g / np.where(el, K, 1.0) - np.sign(g) * gap, th)
    v, w = np.zeros(n), np.zeros(n)
    qr0 = qr[0]
    force, qm_log, ql_log = np.empty((N, n)), np.empty((N, n)), np.empty((N, n))
    h = dt / substeps
    step = np.broadcast_to(np.asarray(step, float), (n,))
    unit = np.where(step > 0, step, 1.0)

    def deriv(q, v, th, w, u):
        if backlash is None:
            spring = K * (th - q) + D * (w - v)
        else:
            x = th - q
            spring = K * (x - np.clip(x, -gap, gap)) + D * (w - v) * (np.abs(x) > gap)
        fr_link = Fv * v + Fc * friction(v) + offset
        fr_motor = Fv * w + Fc * friction(w) + offset
        tau = np.where(el, spring, u - fr_link)
        a = pin.aba(model, data, q, v, tau)
        b = np.where(el, (u - fr_motor - spring) / Ia, a)
        return a, b

    for k in range(N):
        pos = np.where(el, th, q)
        qm = np.where(step > 0, np.round(pos / unit) * unit, pos)
        u = np.array([laws[j].step(qr[k, j] - qr0[j], qm[j] - qr0[j], force0[j]) for j in range(n)])
        force[k], qm_log[k], ql_log[k] = u, qm, q
        ud = u + (noise[k] if noise is not None else 0.0)
        for _ in range(substeps):
            a1, b1 = deriv(q, v, th, w, ud)
            a2, b2 = deriv(q + 0.5 * h * v, v + 0.5 * h * a1, th + 0.5 * h * w, w + 0.5 * h * b1, ud)
            v2, w2 = v + 0.5 * h * a1, w + 0.5 * h * b1
            a3, b3 = deriv(q + 0.5 * h * v2, v + 0.5 * h * a2, th + 0.5 * h * w2, w + 0.5 * h * b2, ud)
            v3, w3 = v + 0.5 * h * a2, w + 0.5 * h * b2
            v4, w4 = v + h * a3, w + h * b3
            a4, b4 = deriv(q + h * v3, v4, th + h * w3, w4, ud)
            q = q + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
            th = th + h / 6 * (w + 2 * w2 + 2 * w3 + w4)
            v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
            w = w + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
            th = np.where(el, th, q)
            w = np.where(el, w, v)
    return (force, qm_log, ql_log) if link else (force, qm_log)


def speed(lines, seconds=10.0, substeps=10):
    """A 10 s elastic UR5 closed loop (joints 1-3 elastic) at 1 kHz: didim's core against the Python loop over
    Pinocchio, the same plant and RK4 substeps."""
    t = json.loads((FLEX / "truth.json").read_text())["robots"]["ur5flex"]
    robot = didim.Robot.from_urdf(FLEX / "ur5flex_cad.urdf")
    rec = didim.load_record(FLEX / "ur5flex_train.csv", robot=robot, controller=FLEX / "ur5flex_controller.json")
    m = int(round(seconds / rec.dt))
    qr = rec.qr[:m]
    pi = np.concatenate([t["links_truth"][j]["dyn10"] for j in t["joint_names"]])
    n = len(t["joint_names"])
    K = [k if f else math.inf for k, f in zip(t["K"], t["flexible"])]
    Dm = [d if f else 0.0 for d, f in zip(t["D"], t["flexible"])]

    def ours():
        return _core.simulate_robot(robot.with_inertial_params(pi)._core, t["Ia"], t["Fv"], t["Fc"], t["offset"],
                                    rec.core_controllers(), qr, rec.dt, quantization=list(rec.encoder_step),
                                    force0=list(rec.force[0]), substeps=substeps, coulomb_eps=[t["vs"]] * n,
                                    coulomb_law=[t["law"]] * n, stiffness=K, damping=Dm)

    model = pin.buildModelFromUrdf(str(FLEX / "ur5flex_cad.urdf"))
    for i in range(1, model.njoints):
        model.inertias[i] = pin.Inertia.FromDynamicParameters(np.asarray(pi[10 * (i - 1):10 * i]))
    vs = t["vs"]

    def theirs():
        return pin_elastic_loop(model, t["Ia"], t["Fv"], t["Fc"], t["offset"], lambda v: np.tanh(v / vs),
                                np.where(t["flexible"], t["K"], 1.0), Dm, t["flexible"], rec.controllers, qr, rec.dt,
                                substeps, rec.encoder_step[0], rec.force[0])

    t_ours, out = best_of(ours, 5)
    t_pin, (f_pin, _) = best_of(theirs, 2)
    agree = float(np.linalg.norm(out["force"] - f_pin) / np.linalg.norm(f_pin))
    # the same plants without the encoder's rounding, on the first 2 s: the arithmetic alone
    short = qr[:2000]
    exact = _core.simulate_robot(robot.with_inertial_params(pi)._core, t["Ia"], t["Fv"], t["Fc"], t["offset"],
                                 rec.core_controllers(), short, rec.dt, quantization=[0.0] * n,
                                 force0=list(rec.force[0]), substeps=substeps, coulomb_eps=[t["vs"]] * n,
                                 coulomb_law=[t["law"]] * n, stiffness=K, damping=Dm)["force"]
    f_exact, _ = pin_elastic_loop(model, t["Ia"], t["Fv"], t["Fc"], t["offset"], lambda v: np.tanh(v / vs),
                                  np.where(t["flexible"], t["K"], 1.0), Dm, t["flexible"], rec.controllers, short,
                                  rec.dt, substeps, 0.0, rec.force[0])
    agree_exact = float(np.linalg.norm(exact - f_exact) / np.linalg.norm(f_exact))
    lines += [f"## Speed: a {seconds:.0f} s elastic UR5 closed loop at 1 kHz (one core)", "",
              "Both loops: the flexrobots UR5 (joints 1-3 elastic) with its true parameters, its six controllers, RK4 "
              f"with {substeps} substeps per sample on (q, q̇, θ, θ̇), the 20-bit motor encoders, friction through tanh "
              "on the motor side; the Python loop calls Pinocchio's `aba` at each RK4 stage.", "",
              "| loop | time | |", "|---|---:|---:|",
              f"| didim (`_core.simulate_robot`, best of 5) | {1e3 * t_ours:.0f} ms | 1 |",
              f"| Python loop over `pinocchio.aba` {pin.__version__} (best of 2) | {t_pin:.2f} s | "
              f"{t_pin / t_ours:.1f}x slower |", "",
              f"The two loops' forces agree to {agree:.1e} (relative; the encoder's rounding flips where the "
              "arithmetic differs in the last digits, and the closed loop carries each flip on), and to "
              f"{agree_exact:.1e} without the encoders' rounding (the first 2 s).", ""]
    return t_ours, t_pin, agree


def truth_errors(res, t):
    """Each joint's relative error (%) of Ia, Fv, Fc, K, D against the truth (K, D on elastic joints)."""
    out = {}
    for p in ("Ia", "Fv", "Fc", "K", "D"):
        out[p] = [100 * (res.params[f"{p}_{j}"] / t[p][i] - 1) for i, j in enumerate(t["joint_names"])
                  if f"{p}_{j}" in res.params]
    return out


def with_link_columns(name, tmp):
    tr = np.genfromtxt(FLEX / f"{name}_train.csv", delimiter=",", names=True)
    lk = np.genfromtxt(FLEX / f"{name}_link_train.csv", delimiter=",", names=True)
    cols = list(tr.dtype.names)
    n = sum(c.startswith("qr_") for c in cols)
    out = pathlib.Path(tmp) / f"{name}_train.csv"
    np.savetxt(out, np.column_stack([tr[c] for c in cols] + [lk[f"q_{i + 1}"] for i in range(n)]), delimiter=",",
               header=",".join(cols + [f"ql_{i + 1}" for i in range(n)]), comments="", fmt="%.17g")
    return out


def flexrobots(lines):
    """The three-step DIDIM and OE-LM on the flexrobots records (one core)."""
    truth = json.loads((FLEX / "truth.json").read_text())["robots"]
    lines += ["## The flexrobots records (an independent simulator; one core)", "",
              "Identified from the training record's motor encoders and torques (`elastic` = the truth's elastic "
              "joints); the truth's values from truth.json; validation error over its truth floor; the deflection "
              "error against the link-side file (`ql_` columns, used to check, not to fit). Worst joint per "
              "parameter (%).", "",
              "| robot | method | time | Ia | Fv | Fc | K | D | modes (Hz, truth at the same q) | validation / floor | "
              "deflection RMS error |", "|---|---|---:|---:|---:|---:|---:|---:|---|---:|---|"]
    summary = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("arm2", "ur5flex"):
            t = truth[name]
            rob = didim.Robot.from_urdf(FLEX / f"{name}_cad.urdf")
            ctl = FLEX / f"{name}_controller.json"
            rec = didim.load_record(with_link_columns(name, tmp), robot=rob, controller=ctl)
            val = didim.load_record(FLEX / f"{name}_valid.csv", robot=rob, controller=ctl)
            el = [j for j, f in zip(t["joint_names"], t["flexible"]) if f]
            pi = np.concatenate([t["links_truth"][j]["dyn10"] for j in t["joint_names"]])
            start = None
            for method in ("didim", "oe-lm"):
                t0 = time.perf_counter()
                if method == "didim":
                    res = didim.identify(rec, rob, "didim", elastic=el)
                    start = res
                else:
                    from didim.methods.robot import oe_lm

                    res = oe_lm(rec, start.structure, start=start)
                elapsed = time.perf_counter() - t0 + (start.elapsed_s if method == "oe-lm" else 0.0)
                errs = truth_errors(res, t)
                qmid = np.array([res.options["modes"].get(j, {"q_mid": 0.0})["q_mid"] for j in t["joint_names"]])
                for j in t["joint_names"]:
                    if j not in res.options["modes"]:
                        qmid[t["joint_names"].index(j)] = 0.5 * (rec.qm[:, t["joint_names"].index(j)].min()
                                                                 + rec.qm[:, t["joint_names"].index(j)].max())
                mm = rob.with_inertial_params(pi).mass_matrix(qmid)
                modes = ", ".join(f"{res.options['modes'][j]['f_n_flex']:.2f} ({math.sqrt(t['K'][i] / mm[i, i]) / (2 * math.pi):.2f})"
                                  for i, j in enumerate(t["joint_names"]) if j in el)
                err, _ = force_errors(val, simulate_robot(val, res)["force"])
                ratio = err / t["records"]["valid"]["truth_floor_total"]
                defl = deflection_errors(rec, simulate_robot(rec, res), res.structure)
                worst = {p: max(abs(x) for x in v) for p, v in errs.items()}
                lines.append(f"| {name} | {method} | {elapsed:.1f} s | {worst['Ia']:.2f} | {worst['Fv']:.2f} | "
                             f"{worst['Fc']:.2f} | {worst['K']:.2f} | {worst['D']:.1f} | {modes} | {ratio:.3f} | "
                             + ", ".join(f"{100 * v:.1f} %" for v in defl.values()) + " |")
                summary[(name, method)] = (elapsed, worst, ratio, defl)
                print(f"{name} {method}: {elapsed:.1f} s, worst {worst}, valid/floor {ratio:.3f}", flush=True)
            rigid = start.options.get("rigid_force_error")
            lines.append(f"| {name} | (rigid model, step 1) | | | | | | | | training force error {100 * rigid:.1f} % | |")
    lines.append("")
    return summary


def with_mode_excitation(qr, elastic, top_hz, dt, rng, amplitude=0.02, count=6):
    """The reference with small high harmonics on the elastic joints, as the flexrobots generator adds them (six,
    log-spaced from 2 Hz to 1.4 times the highest mode, velocity amplitude ``amplitude`` rad/s each, random phases),
    faded in over the first second so that the move still starts at rest: without them a slow Fourier trajectory
    under a 3 Hz position loop leaves the modes unexcited, and the rigid model fits the record as well as the truth
    (2.94 % both on this Panda). ``top_hz``: the highest mode, or each joint's own (one per joint: each elastic
    joint's harmonics then end at 1.4 times its own mode)."""
    t = np.arange(len(qr)) * dt
    fade = np.where(t < 1.0, np.sin(0.5 * math.pi * np.minimum(t, 1.0)) ** 2, 1.0)
    out = qr.copy()
    top = np.broadcast_to(np.asarray(top_hz, float), (qr.shape[1],))
    for j in np.flatnonzero(elastic):
        for f in np.geomspace(2.0, 1.4 * top[j], count):
            w = 2 * math.pi * f
            out[:, j] += fade * amplitude / w * np.sin(w * t + rng.uniform(0, 2 * math.pi))
    return out


def own_robot(lines, seed=21, seconds=20.0):
    """An elastic robot of this script's own making: example-robot-data's Panda, 7 joints, joints 2 and 4 elastic, on
    the Python loop over Pinocchio (atan friction, 18-bit encoders, P + PI cascades, noise inside the loop)."""
    p = Panda(seed)
    joints, model, cad, n = p.joints, p.model, p.cad, p.n
    Ia, Fv, Fc, offset, friction, dt, step, lim, q0 = p.Ia, p.Fv, p.Fc, p.offset, p.friction, p.dt, p.step, p.lim, p.q0
    elastic = np.array([False, True, False, True, False, False, False])
    data = model.createData()
    mjj = np.diag(pin.crba(model, data, q0))
    modes = {1: 11.0, 3: 17.0}  # locked-rotor modes at q0 (Hz)
    zeta = {1: 0.03, 3: 0.02}
    K = np.ones(n)
    Dm = np.zeros(n)
    for j, f in modes.items():
        K[j] = mjj[j] * (2 * math.pi * f) ** 2
        Dm[j] = 2 * zeta[j] * math.sqrt(K[j] * mjj[j])
    ctl = [didim.TransferFunction.cascade(kp=2 * math.pi * 3, kv=2 * math.pi * 12 * (mjj[j] + Ia[j]), dt=dt,
                                          ti=4 / (2 * math.pi * 12), kff=1.0, f_lp=50.0, saturation=200.0)
           for j in range(n)]
    truth = {"joint_names": joints, "Ia": list(Ia), "Fv": list(Fv), "Fc": list(Fc), "K": list(K), "D": list(Dm)}
    records = {}
    with tempfile.TemporaryDirectory() as tmp:
        ctl_path = pathlib.Path(tmp) / "panda_controller.json"
        write_controllers(ctl_path, ctl, dt)
        for name, secs, draw in (("train", seconds, 1), ("valid", seconds / 2, 2)):
            qr = excitation(np.random.default_rng(seed + draw), q0, lim[:, 0], lim[:, 1], 0.8, 0.1, secs, dt)
            qr = with_mode_excitation(qr, elastic, max(modes.values()), dt, np.random.default_rng(seed + 5 * draw))
            model.armature = np.where(elastic, 0.0, Ia)
            u0 = pin.computeGeneralizedGravity(model, data, qr[0]) + offset
            rms = np.sqrt(np.mean(np.array([pin.rnea(model, data, qr[k], np.zeros(n), np.zeros(n))
                                            for k in range(0, len(qr), 50)]) ** 2, axis=0))
            noise = np.random.default_rng(seed + 10 * draw).normal(size=(len(qr), n)) * 0.007 * rms
            t0 = time.perf_counter()
            # the integrators hold the static torque of the settled links: gravity there, and the offsets
            force, qm = pin_elastic_loop(model, Ia, Fv, Fc, offset, friction, K, Dm, elastic, ctl, qr, dt, 4, step,
                                         u0, noise)
            clean, _ = pin_elastic_loop(model, Ia, Fv, Fc, offset, friction, K, Dm, elastic, ctl, qr, dt, 4, step,
                                        u0, None)
            gen = time.perf_counter() - t0
            floor = float(np.linalg.norm(force - clean) / np.linalg.norm(force))
            csv = pathlib.Path(tmp) / f"panda_{name}.csv"
            write_record(csv, qr, force, qm, dt)
            records[name] = (didim.load_record(csv, robot=cad, controller=ctl_path), floor, gen)
    rec, _, _ = records["train"]
    val, vfloor, _ = records["valid"]
    lines += ["## An elastic robot of this script's own making: the Panda with joints 2 and 4 elastic", "",
              "The 7 arm joints of example-robot-data's Panda; the truth is the CAD values perturbed (masses ±15 %, "
              "centres ±2 cm, principal inertias ±20 %), rotor inertias, friction and offsets drawn at random (seed "
              f"{seed}); joints 2 and 4 elastic with locked-rotor modes of 11 and 17 Hz at the start pose (damping "
              "ratios 3 % and 2 %); the plant is this script's Python loop over Pinocchio's `aba` (RK4, 4 substeps), "
              "friction through zero speed by the atan law (2/π)·atan(v/0.02) on the motor side, torque noise inside "
              "the loop (0.7 % of each joint's RMS torque), 18-bit motor encoders, one P + PI cascade per joint (3 Hz "
              "position, 12 Hz velocity loop). The reference: Fourier harmonics of 0.1 Hz, and on the elastic joints "
              "six small ones from 2 Hz to 1.4 times the highest mode (`with_mode_excitation`). "
              f"Train {seconds:.0f} s, validation {seconds / 2:.0f} s (another draw); "
              f"generating them took {sum(r[2] for r in records.values()):.0f} s.", "",
              "| method | time | Ia | Fv | Fc | K | D | validation / floor |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    out = {}
    el = [joints[j] for j in range(n) if elastic[j]]
    for method, res, elapsed in three_step_then_oe(rec, cad, el):
        if isinstance(res, didim.DidimError):
            lines.append(f"| {method} | failed: {res} | | | | | | |")
            print(f"Panda {method}: failed: {res}", flush=True)
            continue
        errs = truth_errors(res, truth)
        worst = {p: max(abs(x) for x in v) for p, v in errs.items()}
        err, _ = force_errors(val, simulate_robot(val, res)["force"])
        lines.append(f"| {method} | {elapsed:.1f} s | {worst['Ia']:.2f} | {worst['Fv']:.2f} | {worst['Fc']:.2f} | "
                     f"{worst['K']:.2f} | {worst['D']:.1f} | {err / vfloor:.3f} |")
        out[method] = (elapsed, worst, err / vfloor)
        print(f"Panda {method}: {elapsed:.1f} s, worst {worst}, valid/floor {err / vfloor:.3f}", flush=True)
    lines.append("")
    return out


def three_step_then_oe(rec, cad, elastic):
    """The three-step DIDIM on ``rec`` with the joints ``elastic``, then OE-LM from it: (method, result or the
    DidimError it raised, seconds; OE-LM's with DIDIM's), one at a time; nothing after a failure."""
    from didim.methods.robot import oe_lm

    start = None
    for method in ("didim", "oe-lm"):
        t0 = time.perf_counter()
        try:
            res = didim.identify(rec, cad, "didim", elastic=elastic) if method == "didim" else \
                oe_lm(rec, start.structure, start=start)
        except didim.DidimError as e:
            yield method, e, time.perf_counter() - t0
            return
        yield method, res, time.perf_counter() - t0 + (start.elapsed_s if method == "oe-lm" else 0.0)
        start = res


# ------------------------------------------------------------------------------------------ held-out elastic robots


def _lift_urdf(axis=(0, 0, 1)):
    """A lift on a belt (a prismatic axis: vertical, or along ``axis``) carrying a SCARA shoulder (revolute z) and a
    wrist pitch (revolute y)."""
    chain = [
        dict(name="lift", type="prismatic", xyz=[0, 0, 0.5], rpy=[0, 0, 0], axis=list(axis), lower=-0.25, upper=0.25,
             effort=2000.0, velocity=1.0, link="carriage", mass=9.0, com=[0.05, 0.0, 0.0],
             inertia=box_inertia(9.0, 0.25, 0.2, 0.15)),
        dict(name="shoulder", type="revolute", xyz=[0.1, 0, 0.1], rpy=[0, 0, 0], axis=[0, 0, 1], lower=-2.5,
             upper=2.5, effort=150.0, velocity=3.0, link="arm1", mass=5.0, com=[0.2, 0.0, 0.0],
             inertia=box_inertia(5.0, 0.45, 0.1, 0.08)),
        dict(name="wrist", type="revolute", xyz=[0.4, 0, 0], rpy=[0, 0, 0], axis=[0, 1, 0], lower=-2.0, upper=2.0,
             effort=40.0, velocity=4.0, link="arm2", mass=2.0, com=[0.15, 0.0, 0.0],
             inertia=box_inertia(2.0, 0.3, 0.06, 0.06)),
    ]
    return own_urdf("lift3", f"CAD model written by benches/elastic_robots.py: a lift (prismatic along {axis}, a belt "
                    "spring), a SCARA shoulder (z) and a wrist pitch (y)", 20.0, chain,
                    dict(name="tool", xyz=[0.3, 0, 0]))


#: The held-out elastic robots (issue 39's "robots of other kinds"): each a CAD URDF, which joints are elastic with
#: their locked-rotor modes (Hz, at the start pose, the truth's chain) and damping ratios, the drives' ranges (drawn
#: per seed), the Coulomb law's shape and smoothing speed per joint, the controller, the rate and the encoders.
HELD_OUT = {
    "lift": dict(
        urdf=_lift_urdf, seed=31, dt=1e-3, q0=[0.0, 0.3, -0.4], vmax=[0.15, 1.0, 1.2], seconds=(12.0, 8.0),
        modes={0: 14.0, 1: 19.0}, zeta={0: 0.04, 1: 0.025}, law="exp", eps=[0.003, 0.03, 0.03],
        Ia=[(4.0, 6.0), (0.2, 0.3), (0.015, 0.03)], Fv=[(40.0, 80.0), (1.0, 2.0), (0.2, 0.4)],
        Fc=[(15.0, 30.0), (2.0, 4.0), (0.4, 0.8)], offset=[4.0, 0.0, 0.1], mode_amplitude=[0.01, 0.02, 0.0],
        ctl=dict(kind="cascade", f_p=3.0, ratio=3.0, fc=80.0, kff=1.0), substeps=4,
        text="a vertical lift on a belt (prismatic, elastic, K in N/m), a SCARA shoulder (revolute z, elastic) and a "
             "rigid wrist pitch (revolute y), written as a URDF by this script; 1 kHz; the exponential law "
             "sign(v)(1 − exp(−|v|/ε)) (ε 3 mm/s on the lift, 0.03 rad/s on the others); one P + PI cascade per "
             "joint with a 80 Hz low-passed velocity (`heldout_robots.cascade_tf`: 3 Hz position, 9 Hz velocity "
             "loop); encoders of 1 µm and 2π/2²⁰ rad"),
    "gantry": None,  # the lift's robot with its belt axis horizontal (below)
    "ur10": dict(
        urdf=lambda: _ur_urdf()[0], seed=41, dt=2e-3, q0=[0.0, -1.3, 1.6, -1.9, -1.57, 0.0],
        vmax=[0.8, 0.8, 1.0, 1.2, 1.2, 1.2], seconds=(16.0, 8.0), modes={1: 7.0, 3: 21.0},
        zeta={1: 0.03, 3: 0.02}, law="tanh", eps=[0.05] * 6,
        Ia=[(0.8, 1.6), (1.0, 2.0), (0.4, 0.8), (0.08, 0.16), (0.06, 0.12), (0.05, 0.1)],
        Fv=[(4.0, 8.0), (5.0, 10.0), (3.0, 6.0), (0.8, 1.6), (0.6, 1.2), (0.6, 1.2)],
        Fc=[(6.0, 12.0), (8.0, 15.0), (5.0, 9.0), (1.5, 3.0), (1.0, 2.0), (1.0, 2.0)],
        offset=[0.5, 1.0, 0.5, 0.2, 0.0, 0.1], mode_amplitude=[0.02] * 6,
        ctl=dict(kind="pid", f_bw=2.5, f_d=40.0), substeps=4,
        text="example-robot-data's UR10 (6 joints; shoulder lift and wrist 1 elastic), 500 Hz; friction tanh(v/0.05) "
             "(5 times the flexrobots' smoothing speed); one PID per joint on the motor encoder (`heldout_robots."
             "pid_tf`: poles at 2.5 Hz, derivative filtered at 40 Hz, velocity feedforward of half the nominal "
             "viscous friction), not a cascade; encoders of 2π/2²⁰ rad"),
}

HELD_OUT["gantry"] = dict(
    HELD_OUT["lift"], urdf=lambda: _lift_urdf(axis=(1, 0, 0)), offset=[1.0, 0.0, 0.1],
    text="the lift's robot with its belt axis horizontal (x: a gantry's axis, no gravity along it; the same drives, "
         "modes, law, controllers and encoders)")

#: The lift with a dead zone of 1 mrad between the shoulder's rotor and its link (about three times the spring's
#: stretch under the record's torques): the robot doctor's backlash on an elastic joint (not in the held-out tables,
#: whose elastic models have none).
HELD_OUT["lift_backlash"] = dict(
    HELD_OUT["lift"], backlash={1: 1e-3},
    text="the lift with backlash: a dead zone of 1 mrad between the SCARA shoulder's rotor and its link")

HELD_OUT["ur10_shared"] = dict(
    HELD_OUT["ur10"], own_top=False,
    text="the same UR10, truth and slow references, but each elastic joint's harmonics up to 1.4 times the highest "
         "mode (21 Hz), as on the Panda, not its own: the shoulder lift's (7 Hz) reach 4 times its mode")


def held_out_robot(name, tmp, seconds=None):
    """One held-out elastic robot of :data:`HELD_OUT` and its training and validation records (``seconds``: their
    lengths, by default the robot's), made by :func:`pin_elastic_loop` (with link positions as ``ql_`` columns of the
    elastic joints): the truth (the CAD inertias perturbed as the Panda's, the drives drawn in their ranges), the
    records (clean and with torque noise inside the loop, 0.7 % of each joint's RMS force), their truth floors (the
    force error of the clean record, total and per joint), and the time it took."""
    c = HELD_OUT[name]
    c = dict(c, seconds=seconds or c["seconds"])
    rng = np.random.default_rng(c["seed"])
    pathlib.Path(tmp).mkdir(parents=True, exist_ok=True)
    urdf = pathlib.Path(tmp) / f"{name}_cad.urdf"
    urdf.write_text(c["urdf"]())
    cad = didim.Robot.from_urdf(urdf)
    model = pin.buildModelFromUrdf(str(urdf))
    n = model.nv
    for i in range(1, model.njoints):
        model.inertias[i] = perturb_inertia(model.inertias[i], rng)
    Ia, Fv, Fc = (np.array([rng.uniform(*r) for r in c[k]]) for k in ("Ia", "Fv", "Fc"))
    offset = np.array([rng.uniform(-o, o) for o in c["offset"]])
    eps = np.asarray(c["eps"], float)
    prismatic = np.array([k == "prismatic" for k in cad.joint_kinds])
    step = np.where(prismatic, PRIS_STEP, 2 * math.pi / 2**20)
    dt = c["dt"]
    lim = np.array([lt[:2] for lt in cad.limits])
    q0 = np.round(np.asarray(c["q0"], float) / step) * step
    elastic = np.zeros(n, bool)
    elastic[list(c["modes"])] = True
    data = model.createData()
    model.armature = np.zeros(n)
    mjj = np.diag(pin.crba(model, data, q0))  # the truth's chain: each elastic joint's locked-rotor inertia
    K, Dm = np.ones(n), np.zeros(n)
    for j, f in c["modes"].items():
        K[j] = mjj[j] * (2 * math.pi * f) ** 2
        Dm[j] = 2 * c["zeta"][j] * math.sqrt(K[j] * mjj[j])
    # the controllers from the CAD inertia at q0 and the drawn rotor inertia (a designer's nominal values)
    jd = np.diag(cad.mass_matrix(q0)) + Ia
    ctl = []
    for j in range(n):
        k = c["ctl"]
        if k["kind"] == "pid":
            tf, _ = pid_tf(jd[j], dt, k["f_bw"], k["f_d"], 0.5 * np.mean(c["Fv"][j]), 1e6)
        else:
            tf, _ = cascade_tf(jd[j], dt, k["f_p"], k["ratio"], k["fc"], k["kff"], 1e6)
        ctl.append(types.SimpleNamespace(**tf))
    ctl_path = pathlib.Path(tmp) / f"{name}_controller.json"
    write_controllers(ctl_path, ctl, dt)
    gaps = np.zeros(n)
    for j, g in c.get("backlash", {}).items():
        gaps[j] = g
    truth = {"joint_names": cad.joint_names, "Ia": list(Ia), "Fv": list(Fv), "Fc": list(Fc), "K": list(K),
             "backlash": list(gaps),
             "D": list(Dm), "offset": list(offset), "eps": list(eps), "law": c["law"], "elastic": elastic,
             "prismatic": prismatic, "model": model,
             "pi": np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)])}
    records, t0 = {}, time.perf_counter()
    for part, secs, draw in (("train", c["seconds"][0], 1), ("valid", c["seconds"][1], 2)):
        qr = excitation(np.random.default_rng(c["seed"] + draw), q0, lim[:, 0], lim[:, 1], np.asarray(c["vmax"]),
                        0.1, secs, dt)
        base = qr.copy()
        top = (np.array([c["modes"].get(j, 0.0) for j in range(n)]) if c.get("own_top", True) else
               max(c["modes"].values(), default=0.0))
        qr = with_mode_excitation(qr, elastic, top, dt, np.random.default_rng(c["seed"] + 5 * draw))
        qr = base + (qr - base) * np.asarray(c["mode_amplitude"]) / 0.02
        u0 = pin.computeGeneralizedGravity(model, data, qr[0]) + offset
        args = (model, Ia, Fv, Fc, offset, lambda v: friction_shape(c["law"], v / eps), K, Dm, elastic, ctl, qr, dt,
                c["substeps"], step, u0)
        bl = dict(backlash=gaps) if gaps.any() else {}
        clean, qm0, ql0 = pin_elastic_loop(*args, link=True, **bl)
        rms = np.sqrt(np.mean(clean ** 2, axis=0))
        noise = np.random.default_rng(c["seed"] + 10 * draw).normal(size=(len(qr), n)) * 0.007 * rms
        force, qm, ql = pin_elastic_loop(*args, noise=noise, link=True, **bl)
        floor = float(np.linalg.norm(force - clean) / np.linalg.norm(force))
        floor_j = np.linalg.norm(force - clean, axis=0) / np.linalg.norm(force, axis=0)
        csv = pathlib.Path(tmp) / f"{name}_{part}.csv"
        write_record(csv, qr, force, qm, dt, ql=ql, ql_joints=np.flatnonzero(elastic))
        records[part] = (didim.load_record(csv, robot=cad, controller=ctl_path), floor, floor_j)
    return cad, truth, records, time.perf_counter() - t0


def replay_truth(rec, cad, t):
    """The truth's parameters in didim's elastic closed loop on ``rec`` (its encoders, first force): the force, and the
    deflection where the record has link positions."""
    n = cad.ndof
    K = [k if e else math.inf for k, e in zip(t["K"], t["elastic"])]
    Dm = [d if e else 0.0 for d, e in zip(t["D"], t["elastic"])]
    return _core.simulate_robot(cad.with_inertial_params(t["pi"])._core, t["Ia"], t["Fv"], t["Fc"], t["offset"],
                                rec.core_controllers(), rec.qr, rec.dt, quantization=list(rec.encoder_step),
                                force0=list(rec.force[0]), coulomb_eps=t["eps"], coulomb_law=[t["law"]] * n,
                                stiffness=K, damping=Dm, backlash=t.get("backlash"))


def held_out(lines, names=tuple(k for k in HELD_OUT if not HELD_OUT[k].get("backlash"))):
    """The three-step DIDIM, OE-LM from it, and the rigid DIDIM on the held-out elastic robots (one core), each
    elastic joint against the truth: K, the mode at the method's mid-stroke pose (the truth's chain there), D, Ia, Fv,
    Fc, the validation force over its truth floor, the validation deflection against the link side."""
    lines += ["## Held-out elastic robots: a belt-driven lift and a PID-controlled UR10 (one core)", "",
              "Robots of kinds the methods were not tuned on, made by this script's Python loop over Pinocchio "
              "(`pin_elastic_loop`, RK4, 4 substeps; the truth's CAD values perturbed as the Panda's, the drives "
              "drawn; torque noise inside the loop, 0.7 % of each joint's RMS force), each record's reference "
              "carrying small harmonics on the elastic joints (`with_mode_excitation`: six from 2 Hz to 1.4 times the "
              "joint's own mode, 0.02 rad/s each, 0.01 m/s on the lift). The link positions of the "
              "elastic joints are in the records as `ql_` columns (checked, not fitted). Per elastic joint, the "
              "relative error (%) against the truth; the mode is the method's `f_n_flex` against the truth's "
              "locked-rotor mode √(K/M_jj) at the same pose (its `q_mid`); validation = force error on the "
              "validation record over its truth floor; deflection = RMS error of the simulated link-minus-motor "
              "deflection against the validation record's. Times on one core, wall clock.", ""]
    for name in names:
        c = HELD_OUT[name]
        lines += [f"- **{name}**: {c['text']}. Train {c['seconds'][0]:.0f} s, validation {c['seconds'][1]:.0f} s."]
    lines.append("")
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            cad, t, records, gen = held_out_robot(name, tmp)
            (rec, floor, floor_j), (val, vfloor, vfloor_j) = records["train"], records["valid"]
            joints = t["joint_names"]
            el = [joints[j] for j in np.flatnonzero(t["elastic"])]
            truth_sim = replay_truth(val, cad, t)
            truth_err, _ = force_errors(val, truth_sim["force"])
            lines += [f"### {name}", "",
                      f"Generating the records took {gen:.0f} s. The truth in didim's loop replays the validation "
                      f"record to {100 * truth_err:.3f} % of its force (floor {100 * vfloor:.3f} %); the deflection "
                      "to " + ", ".join(f"{j} {100 * v:.2f} %" for j, v in
                                       deflection_errors(val, truth_sim, didim.Model(robot=cad, elastic=el)).items())
                      + ".", "",
                      "| method | time | joint | K | mode (Hz, truth) | D | Ia | Fv | Fc | validation / floor | "
                      "deflection | converged |", "|---|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---|"]
            print(f"{name}: generated in {gen:.0f} s; truth replay {100 * truth_err:.3f} % (floor "
                  f"{100 * vfloor:.3f} %)", flush=True)
            for method, res, elapsed in three_step_then_oe(rec, cad, el):
                if isinstance(res, didim.DidimError):
                    lines.append(f"| {method} | failed after {elapsed:.0f} s: {res} | | | | | | | | | | |")
                    if method == "didim":
                        lines.append("| oe-lm | not run: it starts from DIDIM's estimate | | | | | | | | | | |")
                    print(f"{name} {method}: failed: {res}", flush=True)
                    break
                vnote, vsim = "", None
                try:
                    vsim = simulate_robot(val, res)
                except didim.DidimError as e:  # the estimate's loop on the validation record, didim's RK4 substeps
                    lines.append(f"| {method} | | (validation with didim's own RK4 substeps: {e}; with 8 substeps "
                                 "below) | | | | | | | | | |")
                    vnote = " (8 substeps)"
                    try:
                        vsim = simulate_robot(val, res, substeps=8)
                    except didim.DidimError as e8:
                        lines.append(f"| {method} | | (validation with 8 substeps: {e8}) | | | | | | | | | |")
                ratio = math.nan if vsim is None else force_errors(val, vsim["force"])[0] / vfloor
                defl = {} if vsim is None else deflection_errors(val, vsim, res.structure)
                rows = {}
                for j in el:
                    i = joints.index(j)
                    qmid = np.full(cad.ndof, np.nan)
                    for jj, m in res.options["modes"].items():
                        qmid[joints.index(jj)] = m["q_mid"]
                    qmid = np.where(np.isnan(qmid), 0.5 * (rec.qm.min(axis=0) + rec.qm.max(axis=0)), qmid)
                    t["model"].armature = np.zeros(cad.ndof)
                    f_true = math.sqrt(t["K"][i] / pin.crba(t["model"], t["model"].createData(), qmid)[i, i]) \
                        / (2 * math.pi)
                    e = {p: 100 * (res.params[f"{p}_{j}"] / t[p][i] - 1) for p in ("K", "D", "Ia", "Fv", "Fc")}
                    f = res.options["modes"][j]["f_n_flex"]
                    e["mode"] = 100 * (f / f_true - 1)
                    rows[j] = e
                    lines.append(f"| {method} | {elapsed:.0f} s | {j} | {e['K']:+.2f} | {f:.2f} ({f_true:.2f}), "
                                 f"{e['mode']:+.2f} % | {e['D']:+.1f} | {e['Ia']:+.2f} | {e['Fv']:+.2f} | "
                                 f"{e['Fc']:+.2f} | {ratio:.3f}{vnote} | {100 * defl.get(j, math.nan):.1f} % | "
                                 f"{'yes' if res.converged else 'no: ' + res.message} |")
                rigid_j = [joints[j] for j in range(cad.ndof) if not t["elastic"][j]]
                worst_rigid = {p: max(abs(100 * (res.params[f"{p}_{j}"] / t[p][joints.index(j)] - 1))
                                      for j in rigid_j) for p in ("Fv", "Fc")}
                lines.append(f"| {method} | | rigid joints (worst) | | | | | {worst_rigid['Fv']:.2f} | "
                             f"{worst_rigid['Fc']:.2f} | | | |")
                out[(name, method)] = (elapsed, rows, ratio, defl, worst_rigid)
                print(f"{name} {method}: {elapsed:.1f} s, {rows}, rigid {worst_rigid}, valid/floor {ratio:.3f}, "
                      f"deflection {defl}, converged {res.converged} {res.message}", flush=True)
            # what a rigid inverse model makes of each elastic joint's inertia (its rotor's and its chain's at the
            # start pose), against the truth's: the rigid step's start when the URDF's values cannot be simulated
            idim = didim.identify(rec, cad, "idim-ls")
            chain, drives = _model_of(idim.structure, idim.base, theta_of(idim))
            m_idim = chain.mass_matrix(rec.qm[0])
            t["model"].armature = np.zeros(cad.ndof)
            m_true = pin.crba(t["model"], t["model"].createData(), rec.qm[0])
            ej = np.flatnonzero(t["elastic"])
            lines += ["", "The rigid inverse model (IDIM-LS, on the motor encoders) takes each elastic joint's inertia "
                      "at the start pose (rotor and chain) as " + ", ".join(
                          f"{joints[j]} {drives['armature'][j] + m_idim[j, j]:.4g} (truth "
                          f"{t['Ia'][j] + m_true[j, j]:.4g}, of which the rotor {t['Ia'][j]:.4g})" for j in ej)
                      + "; its estimate has " + ("no negative mass" if np.all(chain.inertial_params[::10] > 0) else
                                                 "a negative mass (" + ", ".join(f"{x:.3g} kg" for x in
                                                                                 chain.inertial_params[::10]) + ")")
                      + f" (the truth: {', '.join(f'{x:.3g}' for x in t['pi'][::10])} kg)."]
            # the rigid model on the same records: which joint does it fail on?
            t0 = time.perf_counter()
            try:
                rigid = didim.identify(rec, cad, "didim")
            except didim.DidimError as e:
                lines += ["", f"The rigid model (rigid DIDIM) on the same records: failed ({e}).", ""]
                print(f"{name} rigid: failed: {e}", flush=True)
                continue
            t_rigid = time.perf_counter() - t0
            verr, vper = force_errors(val, simulate_robot(val, rigid)["force"])
            lines += ["", f"The rigid model (rigid DIDIM, {t_rigid:.0f} s, converged: "
                      f"{'yes' if rigid.converged else 'no, ' + rigid.message}) on the same records, per joint: "
                      "training force error over the joint's truth floor, validation over its floor:", "",
                      "| joint | elastic | training error / floor | validation error / floor |", "|---|---|---:|---:|"]
            for i, j in enumerate(joints):
                lines.append(f"| {j} | {'yes' if t['elastic'][i] else 'no'} | "
                             f"{100 * rigid.force_error_per_joint[j]:.2f} % / {100 * floor_j[i]:.2f} % = "
                             f"{rigid.force_error_per_joint[j] / floor_j[i]:.1f} | {100 * vper[j]:.2f} % / "
                             f"{100 * vfloor_j[i]:.2f} % = {vper[j] / vfloor_j[i]:.1f} |")
            lines.append(f"| all | | {100 * rigid.force_error:.2f} % / {100 * floor:.2f} % | "
                         f"{100 * verr:.2f} % / {100 * vfloor:.2f} % |")
            lines.append("")
            out[(name, "rigid")] = (t_rigid, rigid.force_error_per_joint, vper, floor_j, vfloor_j)
            print(f"{name} rigid: {t_rigid:.1f} s, per joint {rigid.force_error_per_joint}, floors {floor_j}, "
                  f"valid {vper}, {rigid.converged} {rigid.message}", flush=True)
    return out


def replace_section(path, lines):
    """``lines`` (a section from its "## " heading) in the page at ``path``: in place of the section of the same
    heading, or at the end."""
    page = pathlib.Path(path).read_text().split("\n") if pathlib.Path(path).exists() else []
    head = lines[0]
    if head in page:
        i = page.index(head)
        k = next((m for m in range(i + 1, len(page)) if page[m].startswith("## ")), len(page))
        page = page[:i] + lines + page[k:]
    else:
        page = page + ([""] if page and page[-1] else []) + lines
    pathlib.Path(path).write_text("\n".join(page).rstrip("\n") + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(ROOT / "docs" / "elastic_robots.md"))
    ap.add_argument("--quick", action="store_true", help="the speed comparison only")
    ap.add_argument("--own-only", action="store_true", help="the robot of this script's own making only")
    ap.add_argument("--held-out", nargs="?", const=",".join(k for k in HELD_OUT if not HELD_OUT[k].get("backlash")),
                    default=None, metavar="NAME[,NAME]",
                    help="the held-out elastic robots only (default all of them): their section replaced in --out")
    args = ap.parse_args()
    if args.held_out is not None:
        section = []
        held_out(section, [x for x in args.held_out.split(",") if x])
        replace_section(args.out, section)
        print(f"wrote {args.out}")
        return
    lines = header("Elastic-joint robots: speed and accuracy", "benches/elastic_robots.py",
                   "Worst joint's relative error (%) against the truth.")
    if args.own_only:
        own_robot(lines)
    else:
        t_ours, t_pin, agree = speed(lines)
        print(f"elastic UR5 10 s: didim {1e3 * t_ours:.0f} ms, Pinocchio loop {t_pin:.2f} s ({t_pin / t_ours:.0f}x), "
              f"agree {agree:.1e}", flush=True)
        if not args.quick:
            flexrobots(lines)
            own_robot(lines)
            held_out(lines)
    pathlib.Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
