"""Robots, measured in one run: didim's closed loop against a Python loop over Pinocchio's forward dynamics with the
same integrator, DIDIM's time on the UR5 record on one core, and identification of robots and trajectories of this
script's own making on an independent plant (Pinocchio's dynamics in the Python loop, another friction law, another
encoder, noise inside the loop). Writes docs/robots.md.

    python benches/robots.py [--out docs/robots.md]

Needs pin (Pinocchio) and example-robot-data (pip install -e '.[test]') and ../shared/data/robots.
"""

from __future__ import annotations

import os

os.environ.setdefault("RAYON_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pathlib  # noqa: E402
import platform  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

import didim  # noqa: E402
from didim import _core  # noqa: E402
from didim.methods.robot import force_errors, simulate_robot  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
DATA = pathlib.Path(os.environ.get("DIDIM_ROBOTS_DIR", ROOT.parent / "shared" / "data" / "robots"))


class Law:
    """One joint's controller as a plain Python filter (the transposed direct form over the common denominator)."""

    def __init__(self, tf):
        b_r, a_r, b_y, a_y = (np.array(x, float) for x in (tf.b_r, tf.a_r, tf.b_y, tf.a_y))
        if not np.array_equal(a_r, a_y):
            b_r, b_y, a_r = np.convolve(b_r, a_y), np.convolve(b_y, a_r), np.convolve(a_r, a_y)
        m = max(len(b_r), len(b_y), len(a_r))
        pad = lambda x: np.concatenate([x, np.zeros(m - len(x))]) / a_r[0]  # noqa: E731
        self.nr, self.ny, self.den = pad(b_r), pad(b_y), pad(a_r)
        self.z = np.zeros(m)
        self.sat, self.gain = tf.saturation, tf.gain

    def step(self, qr, qm, u0):
        u = self.nr[0] * qr - self.ny[0] * qm + self.z[0]
        for i in range(len(self.z) - 1):
            self.z[i] = self.nr[i + 1] * qr - self.ny[i + 1] * qm - self.den[i + 1] * u + self.z[i + 1]
        return self.gain * max(-self.sat, min(self.sat, u + u0 / self.gain))


def pin_loop(model, Ia, Fv, Fc, offset, friction, controllers, qr, dt, substeps, step, force0, noise=None):
    """The closed loop in Python over Pinocchio's aba (armature = Ia), RK4 with ``substeps`` per sample, the torque
    (plus ``noise``) held over the sample; ``friction(v)`` the Coulomb law's sign."""
    data = model.createData()
    model.armature = np.asarray(Ia, float)
    laws = [Law(c) for c in controllers]
    n, N = model.nv, len(qr)
    q, v = qr[0].copy(), np.zeros(n)
    qr0 = qr[0]
    force, qm_log = np.empty((N, n)), np.empty((N, n))
    h = dt / substeps
    Fv, Fc, offset = map(np.asarray, (Fv, Fc, offset))

    def acc(q, v, u):
        return pin.aba(model, data, q, v, u - Fv * v - Fc * friction(v) - offset)

    for k in range(N):
        qm = np.round(q / step) * step if step else q
        u = np.array([laws[j].step(qr[k, j] - qr0[j], qm[j] - qr0[j], force0[j]) for j in range(n)])
        force[k], qm_log[k] = u, qm
        ud = u + (noise[k] if noise is not None else 0.0)
        for _ in range(substeps):
            k1v = acc(q, v, ud)
            k2v = acc(q + 0.5 * h * v, v + 0.5 * h * k1v, ud)
            k3v = acc(q + 0.5 * h * (v + 0.5 * h * k1v), v + 0.5 * h * k2v, ud)
            k4v = acc(q + h * (v + 0.5 * h * k2v), v + h * k3v, ud)
            q = q + h / 6 * (v + 2 * (v + 0.5 * h * k1v) + 2 * (v + 0.5 * h * k2v) + (v + h * k3v))
            v = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return force, qm_log


#: RK4 substeps per 1 ms sample in the speed comparison (both loops): within 1e-9 of a 32-substep reference on the
#: UR5 record (tests/test_robot_identify.py checks didim's own choice against that reference).
SUBSTEPS = 4


def best_of(f, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return min(times), out


def speed(lines):
    """A 20 s UR5 closed loop at 1 kHz: didim's core against the Python loop over Pinocchio, same RK4 substeps."""
    truth = json.loads((DATA / "truth.json").read_text())["robots"]["ur5"]
    robot = didim.Robot.from_urdf(DATA / "ur5_cad.urdf")
    rec = didim.load_record(DATA / "ur5_train.csv", robot=robot, controller=DATA / "ur5_controller.json")
    pi = np.concatenate([truth["links_truth"][j]["dyn10"] for j in truth["joint_names"]])
    true = robot.with_inertial_params(pi)

    def ours(substeps):
        return _core.simulate_robot(true._core, truth["Ia"], truth["Fv"], truth["Fc"], truth["offset"],
                                    rec.core_controllers(), rec.qr, rec.dt, quantization=list(rec.encoder_step),
                                    force0=list(rec.force[0]), substeps=substeps, coulomb_eps=[truth["vs"]] * 6,
                                    coulomb_law=["tanh"] * 6)

    model = pin.buildModelFromUrdf(str(DATA / "ur5_cad.urdf"))
    for i in range(1, model.njoints):
        model.inertias[i] = pin.Inertia.FromDynamicParameters(np.asarray(pi[10 * (i - 1):10 * i]))
    vs = truth["vs"]

    def theirs(substeps):
        return pin_loop(model, truth["Ia"], truth["Fv"], truth["Fc"], truth["offset"], lambda v: np.tanh(v / vs),
                        rec.controllers, rec.qr, rec.dt, substeps, rec.encoder_step[0], rec.force[0])

    t_ours, out = best_of(lambda: ours(SUBSTEPS), 5)
    t_pin, (f_pin, _) = best_of(lambda: theirs(SUBSTEPS), 3)
    agree = float(np.linalg.norm(out["force"] - f_pin) / np.linalg.norm(f_pin))
    # the substeps didim chooses itself on this record (from the friction's stiffness), the same in both loops
    auto = ours(0)["force"]
    chosen = next((k for k in range(1, 9) if np.array_equal(ours(k)["force"], auto)), None)
    rows = []
    if chosen is not None and chosen != SUBSTEPS:
        t_ours2, _ = best_of(lambda: ours(chosen), 5)
        t_pin2, _ = best_of(lambda: theirs(chosen), 3)
        rows = [f"| didim, {chosen} substeps (its own choice on this record) | {1e3 * t_ours2:.0f} ms | 1 |",
                f"| Python loop over `pinocchio.aba`, {chosen} substeps (best of 3) | {t_pin2:.2f} s | "
                f"{t_pin2 / t_ours2:.1f}x slower |"]
    lines += ["## Speed: a 20 s UR5 closed loop at 1 kHz (one core)", "",
              f"Both loops: the data folder's UR5 with its true parameters, its six controllers, RK4 with {SUBSTEPS} "
              "substeps per sample (within 1e-9 of 32), the 20-bit encoder, friction through tanh; the Python loop "
              "calls Pinocchio's `aba` (armature = rotor inertias) at each RK4 stage.", "",
              "| loop | time | |", "|---|---:|---:|",
              f"| didim (`_core.simulate_robot`, best of 5) | {1e3 * t_ours:.0f} ms | 1 |",
              f"| Python loop over `pinocchio.aba` {pin.__version__} (best of 3) | {t_pin:.2f} s | "
              f"{t_pin / t_ours:.1f}x slower |", *rows,
              "", f"The two loops' forces agree to {agree:.1e} (relative; the encoder's rounding flips where the "
              "arithmetic differs in the last digits).", ""]
    # DIDIM on the UR5 record, one core, as the command line runs it
    t0 = time.perf_counter()
    res = didim.identify(rec, robot, "didim", offset=True)
    t_did = time.perf_counter() - t0
    lines += ["## DIDIM on the UR5 record (one core)", "",
              f"`didim.identify(rec, robot, 'didim', offset=True)` from the URDF's CAD values: {t_did:.1f} s, "
              f"{res.iterations} iterations, training force error {100 * res.force_error:.2f} % (floor "
              f"{100 * truth['records']['train']['truth_floor_total']:.2f} %).", ""]
    return t_ours, t_pin, t_did


def excitation(rng, q0, lo, hi, vmax, f0, seconds, dt, harmonics=5):
    """A finite Fourier series per joint starting and ending each period at rest at q0, scaled into the limits' inner
    80 % and under ``vmax`` (one speed for all joints, or one per joint: rad/s, m/s for a prismatic one)."""
    t = np.arange(int(round(seconds / dt)) + 1) * dt
    w = 2 * math.pi * f0
    n = len(q0)
    q = np.zeros((len(t), n))
    for j in range(n):
        a = rng.normal(size=harmonics)
        a -= a.mean()  # v(0) = 0
        b = rng.normal(size=harmonics)
        ls = np.arange(1, harmonics + 1)
        b -= ls * (b @ ls) / (ls @ ls)  # qdd(0) = 0
        x = sum(a[l - 1] / (w * l) * np.sin(w * l * t) - b[l - 1] / (w * l) * (np.cos(w * l * t) - 1) for l in ls)
        v = np.gradient(x, dt)
        room = 0.8 * min(hi[j] - q0[j], q0[j] - lo[j], 1.2)
        vcap = np.broadcast_to(vmax, (n,))[j]
        s = min(room / max(np.max(np.abs(x)), 1e-12), vcap / max(np.max(np.abs(v)), 1e-12))
        q[:, j] = q0[j] + s * x
    return q


class Panda:
    """The Panda arm (7 joints, fingers locked) of example-robot-data with a drawn truth: the CAD masses x(1 ± 15 %),
    centres ± 2 cm, inertias about the centre x(1 ± 20 %); rotor inertias, viscous and Coulomb friction and offsets at
    random; friction through zero speed by the atan law (2/π)·atan(v/0.02) (the slowest law: not tanh, not didim's);
    an 18-bit encoder at 1 kHz; a start pose inside the limits."""

    def __init__(self, seed: int):
        import importlib.metadata

        self.path = next(str(f.locate()) for f in importlib.metadata.files("example-robot-data")
                         if str(f).endswith("/panda.urdf"))
        self.joints = [f"panda_joint{i}" for i in range(1, 8)]
        rng = np.random.default_rng(seed)
        self.full = full = pin.buildModelFromUrdf(self.path)
        self.model = model = pin.buildReducedModel(full, [full.getJointId(x) for x in full.names[1:]
                                                          if x not in self.joints], pin.neutral(full))
        self.cad = didim.Robot.from_urdf(self.path, self.joints)
        n = self.n = self.cad.ndof
        for i in range(1, model.njoints):
            I = model.inertias[i]
            m = I.mass * (1 + rng.uniform(-0.15, 0.15))
            c = I.lever + rng.uniform(-0.02, 0.02, 3)
            ev, evec = np.linalg.eigh(I.inertia)
            Ic = evec @ np.diag(ev * (1 + rng.uniform(-0.2, 0.2, 3))) @ evec.T
            model.inertias[i] = pin.Inertia(m, c, Ic)
        self.Ia = rng.uniform(0.05, 0.3, n) * np.array([1, 1, 1, 1, 0.3, 0.3, 0.3])
        self.Fv = rng.uniform(0.5, 3.0, n) * np.array([1, 1, 1, 1, 0.4, 0.4, 0.4])
        self.Fc = rng.uniform(1.0, 5.0, n) * np.array([1, 1, 1, 1, 0.4, 0.4, 0.4])
        self.offset = np.where(rng.uniform(size=n) < 0.3, rng.uniform(-0.3, 0.3, n), 0.0)
        self.friction = lambda v: (2 / math.pi) * np.arctan(v / 0.02)  # noqa: E731
        self.dt, self.step = 1e-3, 2 * math.pi / 2**18
        lim = self.lim = np.array([lt[:2] for lt in self.cad.limits])
        self.q0 = np.clip(np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8]), lim[:, 0] + 0.3, lim[:, 1] - 0.3)


def write_controllers(path, ctl, dt) -> None:
    """A joints file of didim's transfer functions."""
    pathlib.Path(path).write_text(json.dumps({"type": "joints", "joints": [
        {"type": "transfer_function", "dt": dt, "b_r": list(c.b_r), "a_r": list(c.a_r), "b_y": list(c.b_y),
         "a_y": list(c.a_y), "saturation": c.saturation, "gain": c.gain} for c in ctl]}))


def write_record(path, qr, force, qm, dt, ql=None, ql_joints=()) -> None:
    """A robot record in didim's CSV layout; with ``ql``, the link-side positions of the joints ``ql_joints``
    (indices) as ``ql_<i>`` columns (to check a model's deflection, not to fit)."""
    n = qr.shape[1]
    cols = ["t"] + [f"qr_{j + 1}" for j in range(n)] + [f"force_{j + 1}" for j in range(n)] + \
           [f"qm_{j + 1}" for j in range(n)]
    data = [np.arange(len(qr)) * dt, qr, force, qm]
    if ql is not None:
        cols += [f"ql_{j + 1}" for j in ql_joints]
        data.append(ql[:, list(ql_joints)])
    np.savetxt(path, np.column_stack(data), delimiter=",", header=",".join(cols), comments="", fmt="%.17g")


def own_robot(lines, seed=11):
    """The Panda arm (7 joints) of example-robot-data, its truth the CAD values perturbed, on an independent plant;
    identified by didim from CSV files."""
    p = Panda(seed)
    joints, full, model, cad, n = p.joints, p.full, p.model, p.cad, p.n
    Ia, Fv, Fc, offset, friction, dt, step, lim, q0 = p.Ia, p.Fv, p.Fc, p.offset, p.friction, p.dt, p.step, p.lim, p.q0
    # one P + PI cascade per joint from the CAD inertia at q0: 20 Hz velocity loop, 4 Hz position loop
    mjj = np.diag(pin.crba(pin.buildReducedModel(full, [full.getJointId(x) for x in full.names[1:] if x not in joints],
                                                 pin.neutral(full)), pin.Data(model), q0))
    ctl = [didim.TransferFunction.cascade(kp=2 * math.pi * 4, kv=2 * math.pi * 20 * (mjj[j] + 0.1), dt=dt,
                                          ti=4 / (2 * math.pi * 20), kff=1.0, f_lp=50.0, saturation=200.0)
           for j in range(n)]
    records = {}
    with tempfile.TemporaryDirectory() as tmp:
        ctl_path = pathlib.Path(tmp) / "panda_controller.json"
        write_controllers(ctl_path, ctl, dt)
        for name, seconds, draw in (("train", 20.0, 1), ("valid", 10.0, 2)):
            qr = excitation(np.random.default_rng(seed + draw), q0, lim[:, 0], lim[:, 1], 1.0, 0.1, seconds, dt)
            data = model.createData()
            model.armature = Ia
            u0 = pin.computeGeneralizedGravity(model, data, qr[0]) + offset
            rms = np.sqrt(np.mean(np.array([pin.rnea(model, data, qr[k], np.zeros(n), np.zeros(n))
                                            for k in range(0, len(qr), 50)]) ** 2, axis=0))
            noise = np.random.default_rng(seed + 10 * draw).normal(size=(len(qr), n)) * 0.007 * rms
            t0 = time.perf_counter()
            force, qm = pin_loop(model, Ia, Fv, Fc, offset, friction, ctl, qr, dt, 2, step, u0, noise)
            floor_force, _ = pin_loop(model, Ia, Fv, Fc, offset, friction, ctl, qr, dt, 2, step, u0, None)
            gen = time.perf_counter() - t0
            floor = float(np.linalg.norm(force - floor_force) / np.linalg.norm(force))
            csv = pathlib.Path(tmp) / f"panda_{name}.csv"
            write_record(csv, qr, force, qm, dt)
            records[name] = (didim.load_record(csv, robot=cad, controller=ctl_path), floor, gen)
    lines += ["## A robot of this script's own making: the Panda arm on an independent plant", "",
              "The 7 arm joints of example-robot-data's Panda (fingers locked); the truth is the CAD values perturbed "
              "(masses ±15 %, centres ±2 cm, principal inertias ±20 %), rotor inertias, viscous and Coulomb friction "
              f"and offsets drawn at random (seed {seed}); the plant is a Python loop over Pinocchio's `aba` (RK4, 2 "
              "substeps), friction through zero speed by the atan law (2/π)·atan(v/0.02) (neither the data folder's "
              "tanh nor didim's algebraic law), torque noise inside the loop (0.7 % of each joint's RMS torque), an "
              "18-bit encoder, one P + PI cascade with velocity feedforward per joint (`TransferFunction.cascade`). "
              "Fourier excitation of 5 harmonics of 0.1 Hz under 1 rad/s; train 20 s, validation 10 s (another "
              "draw). The floor: the same loop with the truth and no noise.", "",
              f"Generating the records took {sum(r[2] for r in records.values()):.0f} s in the Python loop.", "",
              "| method | time | Fv error per joint (%) | Fc error per joint (%) | worst Fv, Fc | validation error / floor |",
              "|---|---:|---|---|---:|---:|"]
    rec, _, _ = records["train"]
    val, vfloor, _ = records["valid"]
    out = {}
    for method in ("didim", "idim-ls"):
        t0 = time.perf_counter()
        res = didim.identify(rec, cad, method, offset=True)
        el = time.perf_counter() - t0
        ev = 100 * (np.array([res.params[f"Fv_{j}"] for j in joints]) - Fv) / Fv
        ec = 100 * (np.array([res.params[f"Fc_{j}"] for j in joints]) - Fc) / Fc
        err, _ = force_errors(val, simulate_robot(val, res)["force"])
        out[method] = (ev, ec, err / vfloor)
        lines.append(f"| {method} | {el:.1f} s | {' '.join(f'{x:+.1f}' for x in ev)} | "
                     f"{' '.join(f'{x:+.1f}' for x in ec)} | {np.max(np.abs(ev)):.1f}, {np.max(np.abs(ec)):.1f} | "
                     f"{err / vfloor:.2f} ({100 * err:.2f} % / {100 * vfloor:.2f} %) |")
    lines.append("")
    return out


def header(title: str, script: str, more: str = "") -> list:
    """A benchmark page's title and what it was measured on (machine, load, one core, date)."""
    return [f"# {title}", "",
            f"Measured by `python {script}` on {platform.machine()} with {os.cpu_count()} cores (load average "
            f"{os.getloadavg()[0]:.1f} at the start), one core (RAYON_NUM_THREADS=1), {time.strftime('%Y-%m-%d')}."
            + (f" {more}" if more else ""), ""]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(ROOT / "docs" / "robots.md"))
    ap.add_argument("--seeds", default="12,13,14,15,16,17,18", help="other draws of the Panda set-up")
    args = ap.parse_args()
    lines = header("Robots: speed and accuracy", "benches/robots.py")
    t_ours, t_pin, t_did = speed(lines)
    print(f"UR5 20 s: didim {1e3 * t_ours:.0f} ms, Pinocchio loop {t_pin:.2f} s ({t_pin / t_ours:.0f}x); DIDIM {t_did:.1f} s")
    own = own_robot(lines)
    for m, (ev, ec, ratio) in own.items():
        print(f"Panda {m}: worst Fv {np.max(np.abs(ev)):.1f} %, worst Fc {np.max(np.abs(ec)):.1f} %, valid/floor {ratio:.2f}")
    # other draws of the truth, the excitation and the noise
    seeds = [int(x) for x in args.seeds.split(",") if x]
    rows = []
    for seed in seeds:
        got = own_robot([], seed=seed)
        rows.append((seed, got))
        print(f"Panda seed {seed}: " + "; ".join(f"{m} worst Fv {np.max(np.abs(ev)):.1f} %, Fc {np.max(np.abs(ec)):.1f} %, "
                                                  f"valid/floor {r:.2f}" for m, (ev, ec, r) in got.items()))
    if rows:
        lines += ["Other draws (truth, excitation, noise) of the same Panda set-up:", "",
                  "| seed | DIDIM worst Fv, Fc (%) | DIDIM validation / floor | IDIM-LS worst Fv, Fc (%) | "
                  "IDIM-LS validation / floor |", "|---:|---:|---:|---:|---:|"]
        for seed, got in rows:
            (dv, dc, dr), (iv, ic, ir) = got["didim"], got["idim-ls"]
            lines.append(f"| {seed} | {np.max(np.abs(dv)):.1f}, {np.max(np.abs(dc)):.1f} | {dr:.2f} | "
                         f"{np.max(np.abs(iv)):.1f}, {np.max(np.abs(ic)):.1f} | {ir:.2f} |")
        lines.append("")
    pathlib.Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
