"""Elastic-joint robots, measured in one run (issue 39): didim's elastic closed loop against a Python loop over
Pinocchio's forward dynamics with the same integrator and plant (Spong's model), the three-step DIDIM and OE-LM on the
flexrobots records on one core, and the same on an elastic robot of this script's own making (its own plant: the
Python loop over Pinocchio, another friction law, another encoder and controllers). Writes docs/elastic_robots.md.

    python benches/elastic_robots.py [--out docs/elastic_robots.md] [--quick]

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

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

import didim  # noqa: E402
from didim import _core  # noqa: E402
from didim.methods.robot import deflection_errors, force_errors, simulate_robot  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from robots import Law, Panda, best_of, excitation, header, write_controllers, write_record  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
FLEX = pathlib.Path(os.environ.get("DIDIM_FLEXROBOTS_DIR", ROOT.parent / "shared" / "data" / "flexrobots"))


def pin_elastic_loop(model, Ia, Fv, Fc, offset, friction, K, D, elastic, controllers, qr, dt, substeps, step, force0,
                     noise=None):
    """The closed loop in Python over Pinocchio's aba: rigid joints with their rotor as armature and their friction
    at the link's speed; elastic joints (``elastic``, a mask) with their rotor, friction and the drive's torque on the
    motor side, whose position the encoder reads, and the spring K (θ − q) + D (θ̇ − q̇) on the link. RK4 with
    ``substeps`` per sample on (q, q̇, θ, θ̇), the torque (plus ``noise``) held over the sample; from rest at the first
    reference, the links where the springs hold gravity."""
    data = model.createData()
    el = np.asarray(elastic, bool)
    Ia, Fv, Fc, offset, K, D = (np.asarray(x, float) for x in (Ia, Fv, Fc, offset, K, D))
    model.armature = np.where(el, 0.0, Ia)
    laws = [Law(c) for c in controllers]
    n, N = model.nv, len(qr)
    th = qr[0].copy()
    q = th.copy()
    for _ in range(100):  # K (θ − q) = g(q) on the elastic joints
        q = np.where(el, th - pin.computeGeneralizedGravity(model, data, q) / np.where(el, K, 1.0), th)
    v, w = np.zeros(n), np.zeros(n)
    qr0 = qr[0]
    force, qm_log = np.empty((N, n)), np.empty((N, n))
    h = dt / substeps

    def deriv(q, v, th, w, u):
        spring = K * (th - q) + D * (w - v)
        fr_link = Fv * v + Fc * friction(v) + offset
        fr_motor = Fv * w + Fc * friction(w) + offset
        tau = np.where(el, spring, u - fr_link)
        a = pin.aba(model, data, q, v, tau)
        b = np.where(el, (u - fr_motor - spring) / Ia, a)
        return a, b

    for k in range(N):
        pos = np.where(el, th, q)
        qm = np.round(pos / step) * step if step else pos
        u = np.array([laws[j].step(qr[k, j] - qr0[j], qm[j] - qr0[j], force0[j]) for j in range(n)])
        force[k], qm_log[k] = u, qm
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
    return force, qm_log


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
    (2.94 % both on this Panda)."""
    t = np.arange(len(qr)) * dt
    fade = np.where(t < 1.0, np.sin(0.5 * math.pi * np.minimum(t, 1.0)) ** 2, 1.0)
    out = qr.copy()
    for j in np.flatnonzero(elastic):
        for f in np.geomspace(2.0, 1.4 * top_hz, count):
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
    start = None
    el = [joints[j] for j in range(n) if elastic[j]]
    for method in ("didim", "oe-lm"):
        t0 = time.perf_counter()
        try:
            if method == "didim":
                res = start = didim.identify(rec, cad, "didim", elastic=el)
            else:
                from didim.methods.robot import oe_lm

                res = oe_lm(rec, start.structure, start=start)
        except didim.DidimError as e:
            lines.append(f"| {method} | failed: {e} | | | | | | |")
            print(f"Panda {method}: failed: {e}", flush=True)
            continue
        elapsed = time.perf_counter() - t0 + (start.elapsed_s if method == "oe-lm" else 0.0)
        errs = truth_errors(res, truth)
        worst = {p: max(abs(x) for x in v) for p, v in errs.items()}
        err, _ = force_errors(val, simulate_robot(val, res)["force"])
        lines.append(f"| {method} | {elapsed:.1f} s | {worst['Ia']:.2f} | {worst['Fv']:.2f} | {worst['Fc']:.2f} | "
                     f"{worst['K']:.2f} | {worst['D']:.1f} | {err / vfloor:.3f} |")
        out[method] = (elapsed, worst, err / vfloor)
        print(f"Panda {method}: {elapsed:.1f} s, worst {worst}, valid/floor {err / vfloor:.3f}", flush=True)
    lines.append("")
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(ROOT / "docs" / "elastic_robots.md"))
    ap.add_argument("--quick", action="store_true", help="the speed comparison only")
    ap.add_argument("--own-only", action="store_true", help="the robot of this script's own making only")
    args = ap.parse_args()
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
    pathlib.Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
