"""The robot doctor on held-out robots with concealed effects (issue 40): robots other than the UR5 (example-robot-data's
Panda, 7 joints; its UR10, 6 joints; a revolute-prismatic-revolute arm with a vertical quill), other controllers (P +
PI cascade, PID), rates of 500 Hz, 1 kHz and 2 kHz and other Coulomb laws (atan, exp, tanh), each record pair made by
an independent simulator (the Python RK4 loop over Pinocchio of benches/heldout_robots.py, ``closed_loop`` with its
``effect`` option; the elastic and backlash records by benches/elastic_robots.py's ``pin_elastic_loop``) with ONE
concealed effect as ../shared/data/robotdoctor/README.md describes them, or none (3 clean pairs). Then
``didim.doctor(rec, robot, val)`` on each pair; writes docs/robot_doctor_heldout.md (and a JSON beside it).

    python benches/robot_doctor_heldout.py [--data /tmp/didim_rdoc_heldout] [--only e1,c2] [--make-only]

The records are made once into --data (kept; remade with --remake). The doctor runs on one core
(RAYON_NUM_THREADS=1), one record at a time.
"""

from __future__ import annotations

import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import signal  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pathlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import types  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from heldout_robots import (KAPPA, PANDA_Q0, PRIS_STEP, REV_STEP, _panda_urdf, _rpr_urdf, _ur_urdf,  # noqa: E402
                            cascade_tf, closed_loop, friction_lambda, perturb_inertia, pid_tf, write_csv)
from robots import excitation  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]

#: The robots: CAD URDF, rate, Coulomb law and its smoothing speed per joint, controller, start pose, top speeds, the
#: drives' ranges (drawn per seed), torque noise (share of each joint's RMS force), record lengths.
ROBOTS = {
    "panda": dict(
        urdf=lambda: _panda_urdf()[0], dt=1e-3, law="atan", eps=[0.03] * 7, q0=PANDA_Q0,
        vmax=[0.8] * 4 + [1.0] * 3, ctl=dict(kind="cascade", f_p=3.0, ratio=3.0, fc=40.0, kff=1.0),
        Ia=[(0.1, 0.4)] * 4 + [(0.02, 0.08)] * 3, Fv=[(0.5, 3.0)] * 4 + [(0.2, 1.0)] * 3,
        Fc=[(1.0, 4.0)] * 4 + [(0.3, 1.2)] * 3, off=[0.3] * 4 + [0.1] * 3, noise=0.006, seconds=(12.0, 8.0),
        text="example-robot-data's Panda (7 joints, fingers fixed), 1 kHz, atan law, one P + PI cascade per joint "
             "(3 Hz position, 9 Hz velocity loop, 40 Hz velocity filter), 18-bit encoders"),
    "ur10": dict(
        urdf=lambda: _ur_urdf()[0], dt=2e-3, law="exp", eps=[0.03] * 6, q0=[0.0, -1.3, 1.6, -1.9, -1.57, 0.0],
        vmax=[0.6, 0.6, 0.8, 1.0, 1.0, 1.0], ctl=dict(kind="pid", f_bw=3.0, f_d=40.0),
        Ia=[(0.5, 1.5)] * 2 + [(0.2, 0.6)] + [(0.05, 0.15)] * 3, Fv=[(3.0, 10.0)] * 2 + [(2.0, 6.0)] + [(0.5, 2.0)] * 3,
        Fc=[(5.0, 15.0)] * 2 + [(3.0, 10.0)] + [(1.0, 3.0)] * 3, off=[1.0] * 3 + [0.3] * 3, noise=0.005,
        seconds=(20.0, 10.0),
        text="example-robot-data's UR10 (6 joints), 500 Hz, exponential law sign(v)(1 − exp(−|v|/ε)), one PID per "
             "joint (poles at 3 Hz, derivative filtered at 40 Hz, velocity feedforward of the nominal viscous "
             "friction), 18-bit encoders; a 20 s training record"),
    "rpr": dict(
        urdf=_rpr_urdf, dt=5e-4, law="tanh", eps=[0.03, 0.005, 0.03], q0=[0.0, 0.0, -0.3], vmax=[1.2, 0.2, 1.6],
        ctl=dict(kind="pid", f_bw=4.0, f_d=60.0),
        Ia=[(0.05, 0.15), (1.5, 3.0), (0.004, 0.01)], Fv=[(0.5, 1.5), (20, 60), (0.05, 0.15)],
        Fc=[(1.0, 3.0), (8.0, 20.0), (0.15, 0.4)], off=[0.0, 6.0, 0.1], noise=0.007, seconds=(12.0, 8.0),
        text="an arm of benches/heldout_robots.py's own URDF: revolute base (vertical axis), prismatic vertical "
             "quill, revolute wrist; 2 kHz, tanh law (ε 0.03 rad/s, 5 mm/s on the quill), one PID per joint (poles "
             "at 4 Hz, derivative filtered at 60 Hz, velocity feedforward), encoders of 2π/2¹⁸ rad and 1 µm"),
}

#: The record pairs: robot, seed, the concealed effect (as closed_loop's ``effect``; ``elastic``/``backlash`` through
#: pin_elastic_loop) with its joint (0-based) or None, and the name the doctor should give it.
CASES = {
    "e1": dict(robot="ur10", seed=11, effect=dict(kind="stribeck", joint=2, dF_over_Fc=0.6, vst=0.05),
               want="stribeck"),
    "e2": dict(robot="panda", seed=12, effect=dict(kind="elastic", joint=3, f_hz=16.0, zeta=0.03), want="flexibility"),
    "e3": dict(robot="rpr", seed=13, effect=dict(kind="spring", joint=0, k=2.0, phi=0.4, c=0.3),
               want="position_dependent_torque"),
    "e4": dict(robot="ur10", seed=14, effect=dict(kind="delay"), want="delay"),
    "e5": dict(robot="rpr", seed=15, effect=dict(kind="asymmetric", joint=1, plus=1.2, minus=0.8),
               want="asymmetric_friction"),
    "e6": dict(robot="ur10", seed=16, effect=dict(kind="load", joint=1, mu=0.06), want="load_dependent_friction"),
    "e7": dict(robot="panda", seed=17, effect=dict(kind="backlash", joint=0, b=0.003, f_hz=25.0, zeta=0.05),
               want="backlash"),
    "e8": dict(robot="panda", seed=18, effect=dict(kind="lag", T_samples=3), want="delay"),
    "c1": dict(robot="panda", seed=21, effect=None, want=None),
    "c2": dict(robot="ur10", seed=22, effect=None, want=None),
    "c3": dict(robot="rpr", seed=23, effect=None, want=None),
}


#: What went wrong on the records the doctor missed, from the run the page shows (its progress logs and rankings).
DIAGNOSIS = {
    "e1": "stribeck on elbow_joint ranked first in round 1 (adjusted p = 3.9e-16, 3.1 % of the prewhitened residual), "
          "adopted and refitted, but held out it lowered the elbow's force error only from 0.80 % to 0.79 % (DM p = "
          "0.0008), under the 5 % practical threshold. The record leaves it no room: the elbow's validation truth floor "
          "is 0.77 % and the base model (exp law, its ε and Fc refitted in closed loop) is already at 0.79 %, while "
          "the hump itself is 1.41 % of the elbow's validation force against the rigid plant: the base friction law "
          "absorbed the hump (effect/floor 2.05 on training, 1.84 on validation, the weakest effect of the set). A "
          "miss of size, not of naming.",
}


def mode_harmonics(qr, dt, rng, amplitude, top_hz=25.0, count=6):
    """Six small harmonics (2 Hz to ``top_hz``, log-spaced, velocity amplitude ``amplitude`` per joint, random phases)
    on every joint, faded in over the first second, as the robotdoctor records carry them."""
    t = np.arange(len(qr)) * dt
    fade = np.where(t < 1.0, np.sin(0.5 * math.pi * np.minimum(t, 1.0)) ** 2, 1.0)
    out = qr.copy()
    for j in range(qr.shape[1]):
        for f in np.geomspace(2.0, top_hz, count):
            w = 2 * math.pi * f
            out[:, j] += fade * amplitude[j] / w * np.sin(w * t + rng.uniform(0, 2 * math.pi))
    return out


def make_robot(name, seed, out):
    """The CAD URDF (written to ``out``), the truth (CAD inertias perturbed, drives drawn), the controllers."""
    r = ROBOTS[name]
    rng = np.random.default_rng(seed)
    urdf = pathlib.Path(out) / f"{name}_cad.urdf"
    if not urdf.exists():
        urdf.write_text(r["urdf"]())
    cad = pin.buildModelFromUrdf(str(urdf))
    cad.gravity = pin.Motion(np.array([0.0, 0.0, -9.81]), np.zeros(3))
    truth = cad.copy()
    for i in range(1, cad.njoints):
        truth.inertias[i] = perturb_inertia(cad.inertias[i], rng)
    n = cad.nv
    Ia, Fv, Fc = (np.array([rng.uniform(*b) for b in r[k]]) for k in ("Ia", "Fv", "Fc"))
    off = np.array([rng.uniform(-b, b) if b > 0 else 0.0 for b in r["off"]])
    prism = np.array(["Prismatic" in cad.joints[i].shortname() or cad.joints[i].shortname().startswith("JointModelP")
                      for i in range(1, cad.njoints)])
    steps = np.where(prism, PRIS_STEP, REV_STEP)
    q0 = np.round(np.asarray(r["q0"], float) / steps) * steps
    m = cad.copy()
    m.armature = np.zeros(n)
    J = np.diag(pin.crba(m, m.createData(), q0)) + Ia  # the designer's nominal inertia: CAD chain + drawn rotor
    dt, c = r["dt"], r["ctl"]
    tfs = []
    for j in range(n):
        if c["kind"] == "pid":
            tf, _ = pid_tf(J[j], dt, c["f_bw"], c["f_d"], float(np.mean(r["Fv"][j])), 1e6)
        else:
            tf, _ = cascade_tf(J[j], dt, c["f_p"], c["ratio"], c["fc"], c["kff"], 1e6)
        tfs.append(tf)
    ctl_json = json.loads(json.dumps({"type": "joints", "joints": tfs}))
    return dict(name=name, urdf=urdf, cad=cad, truth=truth, n=n, Ia=Ia, Fv=Fv, Fc=Fc, off=off, steps=steps,
                prism=prism, q0=q0, dt=dt, law=r["law"], eps=np.asarray(r["eps"], float), ctl_json=ctl_json,
                names=list(cad.names)[1:], lim=np.column_stack([cad.lowerPositionLimit, cad.upperPositionLimit]))


def simulate(R, eff, qr, u0, S, noise=None, rigid=False):
    """One closed loop of the robot ``R`` with the concealed effect ``eff`` (``rigid``: without it)."""
    args = (R["Ia"], R["Fv"], R["Fc"], R["off"])
    if eff is not None and not rigid and eff["kind"] in ("elastic", "backlash"):
        from elastic_robots import pin_elastic_loop
        from heldout_robots import friction_shape

        el = np.zeros(R["n"], bool)
        el[eff["joint"]] = True
        ctl = [types.SimpleNamespace(**tf) for tf in R["ctl_json"]["joints"]]
        force, qm = pin_elastic_loop(R["truth"].copy(), *args, lambda v: friction_shape(R["law"], v / R["eps"]),
                                     eff["K_full"], eff["D_full"], el, ctl, qr, R["dt"], S, R["steps"], u0, noise,
                                     backlash=eff.get("b_full"))
        return force, qm
    e = None if rigid else eff
    out = closed_loop(R["truth"], *args, R["law"], R["eps"], R["ctl_json"], qr, R["dt"], S, R["steps"], u0, noise, e)
    return out["force"], out["qm"]


def make_case(key, out):
    """The training and validation records of one case, their truth floors and the effect's size over the floor."""
    c = CASES[key]
    R = make_robot(c["robot"], c["seed"], out)
    r = ROBOTS[c["robot"]]
    n, dt = R["n"], R["dt"]
    eff = None if c["effect"] is None else dict(c["effect"])
    data = R["truth"].createData()
    mt = R["truth"].copy()
    mt.armature = np.zeros(n)
    mjj = np.diag(pin.crba(mt, mt.createData(), R["q0"]))
    params = {}
    if eff is not None:
        j = eff.get("joint")
        k = eff["kind"]
        if k == "stribeck":
            eff["dF"] = eff["dF_over_Fc"] * R["Fc"][j]
            params = dict(dF=eff["dF"], vst=eff["vst"], Fc=R["Fc"][j])
        elif k == "asymmetric":
            eff["Fc_plus"], eff["Fc_minus"] = eff["plus"] * R["Fc"][j], eff["minus"] * R["Fc"][j]
            params = dict(Fc_plus=eff["Fc_plus"], Fc_minus=eff["Fc_minus"])
        elif k == "spring":
            params = dict(k=eff["k"], phi=eff["phi"], c=eff["c"])
        elif k == "load":
            params = dict(mu=eff["mu"])
        elif k == "lag":
            eff["T"] = eff["T_samples"] * dt
            params = dict(T=eff["T"])
        elif k in ("elastic", "backlash"):
            K = mjj[j] * (2 * math.pi * eff["f_hz"]) ** 2
            D = 2 * eff["zeta"] * math.sqrt(K * mjj[j])
            eff["K_full"], eff["D_full"] = np.where(np.arange(n) == j, K, 1.0), np.where(np.arange(n) == j, D, 0.0)
            if k == "backlash":
                eff["b_full"] = np.where(np.arange(n) == j, eff["b"], 0.0)
            params = dict(K=K, D=D, f_hz=eff["f_hz"], zeta=eff["zeta"], **({"b": eff["b"]} if k == "backlash" else {}))
    recs = {}
    noise_std = None
    for part, secs, draw in (("train", r["seconds"][0], 1), ("valid", r["seconds"][1], 2)):
        rng = np.random.default_rng([c["seed"], draw])
        qr = excitation(rng, R["q0"], R["lim"][:, 0], R["lim"][:, 1], np.asarray(r["vmax"]), 0.1, secs, dt)
        qr = mode_harmonics(qr, dt, rng, np.where(R["prism"], 0.002, 0.01))
        # at rest at qr[0], the integrators holding the static torque of the true plant (the effect's too)
        u0 = pin.computeGeneralizedGravity(R["truth"], data, qr[0]) + R["off"]
        if eff is not None and eff["kind"] == "spring":
            u0[eff["joint"]] += eff["k"] * math.sin(qr[0, eff["joint"]] + eff["phi"]) - eff["c"]
        lam = friction_lambda(R["truth"], R["Ia"], R["Fv"], R["Fc"], R["eps"], qr[:: max(1, len(qr) // 20)])
        S = max(2, int(math.ceil(dt * lam / KAPPA)))
        if eff is not None and eff["kind"] in ("elastic", "backlash"):
            S = max(S, int(math.ceil(dt * 2 * math.pi * eff["f_hz"] * 8)))
        t0 = time.perf_counter()
        clean, _ = simulate(R, eff, qr, u0, S)
        if noise_std is None:
            noise_std = r["noise"] * np.sqrt(np.mean(clean ** 2, axis=0))
        noise = np.random.default_rng([c["seed"], 10 + draw]).normal(size=qr.shape) * noise_std
        force, qm = simulate(R, eff, qr, u0, S, noise)
        floor_j = np.linalg.norm(force - clean, axis=0) / np.linalg.norm(force, axis=0)
        rec = dict(samples=len(qr), substeps=S, floor=float(np.linalg.norm(force - clean) / np.linalg.norm(force)),
                   floor_per_joint=floor_j.tolist())
        if eff is not None and part == "train":
            u0r = pin.computeGeneralizedGravity(R["truth"], data, qr[0]) + R["off"]
            rigid, _ = simulate(R, eff, qr, u0r, S, rigid=True)
            size_j = np.linalg.norm(force - rigid, axis=0) / np.linalg.norm(force, axis=0)
            rec.update(effect_size=float(np.linalg.norm(force - rigid) / np.linalg.norm(force)),
                       effect_size_per_joint=size_j.tolist(), effect_over_floor_per_joint=(size_j / floor_j).tolist())
        rec["seconds"] = time.perf_counter() - t0
        write_csv(pathlib.Path(out) / f"{key}_{part}.csv", dt, qr, force, qm)
        recs[part] = rec
        print(f"[{key}] {part}: {len(qr)} samples, {S} substeps, floor {rec['floor']:.4f}"
              + (f", effect/floor per joint {np.round(rec['effect_over_floor_per_joint'], 2).tolist()}"
                 if "effect_over_floor_per_joint" in rec else "") + f", {rec['seconds']:.0f} s", flush=True)
    ctl_path = pathlib.Path(out) / f"{key}_controller.json"
    ctl_path.write_text(json.dumps(R["ctl_json"], indent=1) + "\n")
    j = None if eff is None else eff.get("joint")
    return dict(robot=c["robot"], seed=c["seed"], effect=None if eff is None else eff["kind"],
                joint=None if j is None else R["names"][j], joint_index=j, parameters=params, want=c["want"],
                urdf=R["urdf"].name, controller=ctl_path.name, names=R["names"], Ia=R["Ia"].tolist(),
                Fv=R["Fv"].tolist(), Fc=R["Fc"].tolist(), offset=R["off"].tolist(), law=R["law"],
                eps=R["eps"].tolist(), noise_std=noise_std.tolist(), records=recs)


class Stopped(Exception):
    """The doctor ran past --timeout on one record."""


def run_doctor(key, t, data, timeout=0, log=None):
    """didim.doctor on one pair: what it named, held-out errors, times, each round's ranking (``timeout``: stop it
    after that many seconds, 0: never; ``log``: a file for its progress lines)."""
    import didim

    robot = didim.Robot.from_urdf(data / t["urdf"])
    ctl = data / t["controller"]
    rec = didim.load_record(data / f"{key}_train.csv", robot=robot, controller=ctl)
    val = didim.load_record(data / f"{key}_valid.csv", robot=robot, controller=ctl)
    w0, c0 = time.perf_counter(), time.process_time()
    def stop(*_):
        raise Stopped()

    fh = open(log, "a") if log else None
    say = (lambda s: print(f"{time.perf_counter() - w0:7.1f} s  {s}", file=fh, flush=True)) if fh else None
    old = signal.signal(signal.SIGALRM, stop)
    signal.alarm(int(timeout))
    try:
        d = didim.doctor(rec, robot, val, progress=say)
    except Stopped:
        return dict(stopped=f"stopped after {timeout:.0f} s", wall=time.perf_counter() - w0,
                    cpu=time.process_time() - c0)
    except Exception as e:  # noqa: BLE001  a crash is a result here
        import traceback

        return dict(crash=f"{type(e).__name__}: {e}", traceback=traceback.format_exc(), wall=time.perf_counter() - w0,
                    cpu=time.process_time() - c0)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        if fh:
            fh.close()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    got = [(f.effect, f.joint) for f in d.findings]
    first = d.findings[0] if d.findings else None
    rounds = [[dict(effect=x["effect"], joint=x["joint"], p_adjusted=x["p_adjusted"],
                    explained_pct=x["explained_pct"]) for x in r["candidates"][:6]] for r in d.rounds]
    return dict(named=got, wall=wall, cpu=cpu,
                before=None if first is None else first.fit.get("valid_before"),
                after=None if first is None else first.fit.get("valid_after"),
                rejected=[(f.effect, f.joint, f.evidence) for f in d.rejected], rounds=rounds,
                base_error=d.base.force_error,
                joints_valid={m.joint: m.error_valid for m in d.joints} if hasattr(d.joints[0], "joint") else {},
                summary=d.summary())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/tmp/didim_rdoc_heldout")
    ap.add_argument("--out", default=str(ROOT / "docs" / "robot_doctor_heldout.md"))
    ap.add_argument("--only", default="")
    ap.add_argument("--make-only", action="store_true")
    ap.add_argument("--remake", action="store_true")
    ap.add_argument("--timeout", type=float, default=0, help="stop the doctor on a record after this many seconds")
    args = ap.parse_args()
    data = pathlib.Path(args.data)
    data.mkdir(parents=True, exist_ok=True)
    keys = [k for k in CASES if not args.only or k in args.only.split(",")]
    tpath = data / "truth.json"
    truth = json.loads(tpath.read_text()) if tpath.exists() else {}
    for k in keys:
        if args.remake or k not in truth or not (data / f"{k}_valid.csv").exists():
            truth[k] = make_case(k, data)
            tpath.write_text(json.dumps(truth, indent=1) + "\n")
    if args.make_only:
        return 0
    jpath = pathlib.Path(args.out).with_suffix(".json")
    results = json.loads(jpath.read_text()) if jpath.exists() else {}
    for k in keys:
        res = run_doctor(k, truth[k], data, args.timeout, data / f"{k}_progress.log")
        results[k] = res
        jpath.write_text(json.dumps({k: {x: y for x, y in v.items() if x != "summary"} for k, v in results.items()},
                                    indent=1) + "\n")
        (data / f"{k}_summary.txt").write_text(res.get("summary", res.get("crash", res.get("stopped", ""))))
        print(f"[{k}] {truth[k]['effect']} on {truth[k]['joint']}: named "
              f"{res.get('named', res.get('crash', res.get('stopped')))}, "
              f"{res['wall']:.0f} s wall, {res['cpu']:.0f} s CPU", flush=True)
    write_page(truth, results, data, pathlib.Path(args.out))
    return 0


def write_page(truth, results, data, out):
    rows = []
    named = total = flagged = clean = crashes = 0
    for k in CASES:
        if k not in results or k not in truth:
            continue
        t, r = truth[k], results[k]
        tr = t["records"]["train"]
        eof = ("" if t["joint_index"] is None or "effect_over_floor_per_joint" not in tr else
               f"{tr['effect_over_floor_per_joint'][t['joint_index']]:.1f}")
        if t["effect"] is not None and t["joint_index"] is None:
            eof = f"{max(tr['effect_over_floor_per_joint']):.1f} (largest joint)"
        if "crash" in r or "stopped" in r:
            crashes += "crash" in r
            got, ok = (f"CRASH: {r['crash']}" if "crash" in r else f"nothing: {r['stopped']}"), False
            if t["want"] is None:
                clean += 1
            else:
                total += 1
        else:
            got_l = [tuple(x) for x in r["named"]]
            got = "; ".join(f"{e} on {j or 'every joint'}" for e, j in got_l) or "none"
            if t["want"] is None:
                clean += 1
                flagged += bool(got_l)
                ok = not got_l
            else:
                total += 1
                ok = bool(got_l) and got_l[0] == (t["want"], t["joint"])
                named += ok
        err = ("" if r.get("before") is None else f"{100 * r['before']:.2f} → {100 * r['after']:.2f} %")
        rows.append(f"| {k} | {t['robot']} ({1 / ROBOTS[t['robot']]['dt']:.0f} Hz, {ROBOTS[t['robot']]['law']}, "
                    f"{ROBOTS[t['robot']]['ctl']['kind']}) | {t['effect'] or 'none'} on {t['joint'] or ('every joint' if t['effect'] else '—')} "
                    f"| {eof} | {tr['floor'] * 100:.2f} % | {got} | {'yes' if ok else 'NO'} | {err} | "
                    f"{r['wall']:.0f} s ({r['cpu']:.0f} s CPU) |")
    lines = [
        "# The robot doctor on held-out robots with concealed effects",
        "",
        "Made by `python benches/robot_doctor_heldout.py` (issue 40: \"held-out robots with concealed effects (other "
        "arms, other sizes and joints): at least 7 of 8 effects named with the right joint, at most 1 of 3 clean "
        "records with a finding, no crash\"). The records are made by an independent simulator: "
        "benches/heldout_robots.py's Python RK4 loop over Pinocchio (`closed_loop`, its `effect` option) and, for the "
        "elastic joint and the backlash, benches/elastic_robots.py's `pin_elastic_loop` (Spong's motor and link; its "
        "`backlash` option); the effects as ../shared/data/robotdoctor/README.md describes them. Robots:",
        "",
    ]
    lines += [f"- **{k}**: {v['text']}; training {v['seconds'][0]:.0f} s, validation {v['seconds'][1]:.0f} s (another "
              "draw); torque noise inside the loop, " f"{100 * v['noise']:.1f} % of each joint's RMS force." for k, v in ROBOTS.items()]
    lines += [
        "",
        "Every reference is a 5-harmonic Fourier series of 0.1 Hz plus six small harmonics (2–25 Hz, 0.01 rad/s "
        "or 2 mm/s each) on every joint, as the robotdoctor records carry them. The truth: the CAD inertias "
        "perturbed (masses ±15 %, centres ±2 cm, principal inertias ±20 %), the drives drawn. `effect/floor`: the "
        "robotdoctor README's effect_over_floor on the effect's joint of the training record (‖u_record − u_rigid‖ "
        "over ‖u_record − u_true‖, noise-free closed loops of the base rigid plant and of the true one). `held-out "
        "error`: the first finding's held-out force error of its joints before and after. Times: wall clock and "
        f"process CPU of `didim.doctor`, on one core (RAYON_NUM_THREADS=1), machine shared (load average "
        f"{os.getloadavg()[0]:.1f} at the end).",
        "",
        f"**Named on the right joint (first finding): {named} of {total}; clean records with a finding: {flagged} "
        f"of {clean}; crashes: {crashes}.**",
        "",
        "| record | robot | concealed | effect/floor | train floor | named | right | held-out error | time |",
        "|---|---|---|---:|---:|---|---|---|---:|",
    ] + rows
    lines += ["", "## Parameters of each concealed effect", ""]
    for k in CASES:
        if k in truth and truth[k]["effect"]:
            lines.append(f"- {k}: {truth[k]['effect']} " + ", ".join(f"{a} = {b:.4g}" for a, b in
                                                                     truth[k]["parameters"].items()))
    lines += ["", "## Each round's ranking (first six candidates) and the candidates not confirmed", ""]
    for k in CASES:
        if k not in results or "rounds" not in results[k]:
            continue
        r = results[k]
        lines.append(f"### {k}")
        lines.append("")
        for i, rd in enumerate(r["rounds"], 1):
            lines.append(f"- round {i}: " + ", ".join(f"{x['effect']} on {x['joint'] or 'every joint'} p={x['p_adjusted']:.2g} "
                                                      f"({x['explained_pct']:.1f} %)" for x in rd))
        for e, j, ev in r["rejected"]:
            lines.append(f"- not confirmed: {e} on {j or 'every joint'}: {ev}")
        lines.append("")
    if DIAGNOSIS:
        lines += ["## The misses, diagnosed (written by hand from the run of 2026-11-26; the progress logs and rounds "
                  "above)", ""] + [f"- **{k}**: {v}" for k, v in DIAGNOSIS.items()] + [""]
    lines += ["## Each record's summary", ""]
    for k in CASES:
        p = data / f"{k}_summary.txt"
        if k in results and p.exists():
            lines += [f"### {k}", "", "```", p.read_text(), "```", ""]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}: named {named}/{total}, clean flagged {flagged}/{clean}, crashes {crashes}")


if __name__ == "__main__":
    raise SystemExit(main())
