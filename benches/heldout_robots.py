"""Held-out closed-loop robot records, made by a simulator that is independent of didim.

This script does not import didim. It uses numpy, Pinocchio (``import pinocchio as pin``, the PyPI package ``pin``) and
example-robot-data (``pip install pin example-robot-data``), and otherwise the standard library. It writes records of
kinds that the shared data folder does not have: a prismatic joint under gravity, the Panda arm, 500 Hz and 4 kHz
sample rates, PID controllers besides the P/PI cascade, and four shapes of Coulomb friction through zero speed.

    python benches/heldout_robots.py --out /tmp/didim_heldout [--only NAME[,NAME..]] [--jobs 2]

For each case NAME it writes ``NAME_cad.urdf``, ``NAME_controller.json``, ``NAME_train.csv``, ``NAME_valid.csv`` and
``NAME_payload.csv`` in the format of the shared robots folder, and it adds NAME's entry to ``truth.json`` (entries of
the cases not run are kept from an earlier run).

The simulator
-------------
Plant: (M(q) + diag(Ia)) qdd = u + d - nle(q, qd) - Fv qd - Fc s(qd) - offset, through ``pin.aba`` with
``model.armature = Ia`` and gravity (0, 0, -9.81); d is white Gaussian torque (force) noise held over each sample.
s is one of

    algebraic  v / sqrt(v^2 + eps^2)        tanh  tanh(v / eps)
    atan       (2/pi) atan(pi v / (2 eps))  exp   sign(v) (1 - exp(-|v| / eps))

all with slope 1/eps at v = 0; eps per joint in that joint's units (rad/s or m/s). RK4 with S substeps per sample and
u + d held over the sample; S is chosen from the stiffest friction mode (largest eigenvalue of
(M + Ia)^-1 diag(Fv + Fc/eps) over the reference, h * lambda <= 0.5) and the train record is re-run without noise at 2S
to check it. Encoder: qm = round(q/step)*step, 2*pi/2^18 rad (revolute) or 1e-6 m (prismatic).

Controller per joint: the linear law u = force[0] + C_r(z)[qr - qr[0]] - C_y(z)[qm - qr[0]] with zero filter states
(the robot starts at rest at q = qr[0], on the encoder grid, and force[0] = g(qr[0]) + offset), coefficients in
ascending powers of 1/z, exactly as written to NAME_controller.json. Two designs: a PID with Tustin integral and
backward-Euler filtered derivative on the position error (optional velocity feed-forward), and the industrial
cascade (P position loop, PI velocity loop, velocity feed-forward, velocity = first-order low-pass of the backward
difference of qm). Every record's force column is replayed from the CSV and the JSON by a second, independent filter
implementation (direct form I) and the mismatch is printed and stored.

``closed_loop(..., effect=...)`` conceals one effect the rigid model lacks (Stribeck, asymmetric Coulomb, a
counterbalance spring, load-dependent friction, a one-sample delay, a force lag): benches/robot_doctor_heldout.py's
records; this script's own records are rigid.

Truth floor of a record: the same closed loop with the truth and without d (same qr, same encoder);
||force_record - force_sim|| / ||force_record|| over all samples, and per joint.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import multiprocessing
import os
import pathlib
import sys
import time
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

GRAVITY = np.array([0.0, 0.0, -9.81])
REV_STEP = 2 * math.pi / 2**18  # rad
PRIS_STEP = 1e-6  # m
DYN10_ORDER = ("[m, m*cx, m*cy, m*cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (Pinocchio toDynamicParameters; inertia about the "
               "joint frame origin, in the joint frame)")
KAPPA = 0.5  # RK4 substep: h * lambda_max <= KAPPA for the stiffest friction mode
N_TRAIN_DRAWS = 40

# ------------------------------------------------------------------------------------------------------------------
# friction shapes


def friction_shape(law: str, x):
    """s(v) as a function of x = v/eps (slope 1 at 0)."""
    if law == "algebraic":
        return x / np.sqrt(1.0 + x * x)
    if law == "tanh":
        return np.tanh(x)
    if law == "atan":
        return (2.0 / math.pi) * np.arctan((math.pi / 2.0) * x)
    if law == "exp":
        return np.sign(x) * (-np.expm1(-np.abs(x)))
    raise ValueError(law)


FRICTION_FORMULA = {
    "algebraic": "s(v) = v / sqrt(v^2 + eps^2)",
    "tanh": "s(v) = tanh(v / eps)",
    "atan": "s(v) = (2/pi) * atan(pi * v / (2 * eps))",
    "exp": "s(v) = sign(v) * (1 - exp(-|v| / eps))",
}

# ------------------------------------------------------------------------------------------------------------------
# URDFs


def erd_file(rel: str) -> str | None:
    """A file of the example-robot-data package (its data only; the package ships no Python module here)."""
    try:
        for f in importlib.metadata.files("example-robot-data") or []:
            if str(f).endswith(rel):
                return str(f.locate())
    except importlib.metadata.PackageNotFoundError:
        pass
    try:
        import example_robot_data as erd  # noqa: F401

        base = pathlib.Path(erd.getModelPath(rel))
        for cand in (base / rel, base / rel.lstrip("/")):
            if cand.exists():
                return str(cand)
    except Exception:  # noqa: BLE001
        pass
    return None


def erd_version() -> str:
    try:
        return importlib.metadata.version("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def strip_urdf(text: str, comment: str, fix_joints=()) -> str:
    """The URDF without meshes, visual/collision/transmission/gazebo elements and joint dynamics/safety tags; the joints
    in ``fix_joints`` made fixed (at their zero position)."""
    root = ET.fromstring(text)
    for el in list(root):
        if el.tag in ("transmission", "gazebo"):
            root.remove(el)
    for link in root.findall("link"):
        for el in list(link):
            if el.tag in ("visual", "collision"):
                link.remove(el)
    for joint in root.findall("joint"):
        for el in list(joint):
            if el.tag in ("dynamics", "safety_controller", "calibration", "mimic"):
                joint.remove(el)
        if joint.get("name") in fix_joints:
            joint.set("type", "fixed")
            for el in list(joint):
                if el.tag in ("axis", "limit"):
                    joint.remove(el)
    ET.indent(root, space="  ")
    return f'<?xml version="1.0"?>\n<!-- {comment} -->\n' + ET.tostring(root, encoding="unicode") + "\n"


def _fmt(x) -> str:
    return " ".join(repr(float(v)) for v in np.atleast_1d(x))


def own_urdf(name: str, comment: str, base_mass: float, chain: list[dict], tool: dict | None) -> str:
    """A serial-chain URDF: each element of ``chain`` is {name, type, xyz, rpy, axis, lower, upper, effort, velocity,
    link, mass, com, inertia (ixx, ixy, ixz, iyy, iyz, izz)}; ``tool`` an optional massless frame on the last link."""
    lines = ['<?xml version="1.0"?>', f"<!-- {comment} -->", f'<robot name="{name}">', '  <link name="base_link">',
             "    <inertial>", f'      <mass value="{base_mass!r}"/>', '      <origin xyz="0 0 0" rpy="0 0 0"/>',
             '      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>', "    </inertial>",
             "  </link>"]
    parent = "base_link"
    for j in chain:
        ixx, ixy, ixz, iyy, iyz, izz = j["inertia"]
        lines += [f'  <joint name="{j["name"]}" type="{j["type"]}">', f'    <parent link="{parent}"/>',
                  f'    <child link="{j["link"]}"/>', f'    <origin xyz="{_fmt(j["xyz"])}" rpy="{_fmt(j["rpy"])}"/>',
                  f'    <axis xyz="{_fmt(j["axis"])}"/>',
                  f'    <limit lower="{j["lower"]!r}" upper="{j["upper"]!r}" effort="{j["effort"]!r}" '
                  f'velocity="{j["velocity"]!r}"/>', "  </joint>",
                  f'  <link name="{j["link"]}">', "    <inertial>", f'      <mass value="{j["mass"]!r}"/>',
                  f'      <origin xyz="{_fmt(j["com"])}" rpy="0 0 0"/>',
                  f'      <inertia ixx="{ixx!r}" ixy="{ixy!r}" ixz="{ixz!r}" iyy="{iyy!r}" iyz="{iyz!r}" '
                  f'izz="{izz!r}"/>',
                  "    </inertial>", "  </link>"]
        parent = j["link"]
    if tool:
        lines += [f'  <joint name="{tool["name"]}_joint" type="fixed">', f'    <parent link="{parent}"/>',
                  f'    <child link="{tool["name"]}"/>', f'    <origin xyz="{_fmt(tool["xyz"])}" rpy="0 0 0"/>',
                  "  </joint>", f'  <link name="{tool["name"]}"/>']
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def box_inertia(m, a, b, c):
    """Inertia about the centre of a solid box with edges a (x), b (y), c (z): (ixx, ixy, ixz, iyy, iyz, izz)."""
    return (m * (b * b + c * c) / 12, 0.0, 0.0, m * (a * a + c * c) / 12, 0.0, m * (a * a + b * b) / 12)


def cyl_inertia_z(m, r, length):
    """Solid cylinder along z about its centre."""
    t = m * (3 * r * r + length * length) / 12
    return (t, 0.0, 0.0, t, 0.0, m * r * r / 2)


# ------------------------------------------------------------------------------------------------------------------
# cases


def _rpr_urdf():
    chain = [
        dict(name="base_yaw", type="revolute", xyz=[0, 0, 0.45], rpy=[0, 0, 0], axis=[0, 0, 1], lower=-2.6,
             upper=2.6, effort=60.0, velocity=3.0, link="arm", mass=4.0, com=[0.2, 0.0, 0.03],
             inertia=box_inertia(4.0, 0.5, 0.08, 0.08)),
        dict(name="quill", type="prismatic", xyz=[0.4, 0, 0], rpy=[0, 0, 0], axis=[0, 0, 1], lower=-0.15,
             upper=0.15, effort=400.0, velocity=0.5, link="quill_link", mass=5.0, com=[0.0, 0.0, -0.1],
             inertia=cyl_inertia_z(5.0, 0.04, 0.4)),
        dict(name="wrist", type="revolute", xyz=[0, 0, -0.3], rpy=[0, 0, 0], axis=[0, 1, 0], lower=-2.5,
             upper=2.5, effort=15.0, velocity=4.0, link="wrist_link", mass=1.5, com=[0.1, 0.0, -0.02],
             inertia=box_inertia(1.5, 0.25, 0.05, 0.05)),
    ]
    return own_urdf("rpr", "CAD model written by benches/heldout_robots.py: revolute base (z), prismatic vertical "
                    "quill (z) at the end of a 0.4 m arm, revolute wrist (y) with a 0.22 m offset link",
                    10.0, chain, dict(name="tool", xyz=[0.22, 0, 0]))


def _arm2_urdf():
    chain = [
        dict(name="shoulder", type="revolute", xyz=[0, 0, 0.3], rpy=[0, 0, 0], axis=[0, 1, 0], lower=-2.6,
             upper=2.6, effort=80.0, velocity=3.0, link="link1", mass=3.0, com=[0.0, 0.0, 0.25],
             inertia=box_inertia(3.0, 0.06, 0.06, 0.5)),
        dict(name="elbow", type="revolute", xyz=[0, 0, 0.5], rpy=[0, 0, 0], axis=[0, 1, 0], lower=-2.6,
             upper=2.6, effort=30.0, velocity=3.5, link="link2", mass=1.5, com=[0.0, 0.0, 0.2],
             inertia=box_inertia(1.5, 0.05, 0.05, 0.4)),
    ]
    return own_urdf("arm2", "CAD model written by benches/heldout_robots.py: 2-joint arm in a vertical plane, axes "
                    "along y, links 0.5 m and 0.4 m standing up (+z) at q = 0", 5.0, chain,
                    dict(name="tip", xyz=[0, 0, 0.4]))


def _panda_urdf():
    src = erd_file("panda_description/urdf/panda.urdf")
    if src is None:
        raise RuntimeError("example-robot-data's panda.urdf not found: pip install example-robot-data")
    text = strip_urdf(pathlib.Path(src).read_text(),
                      f"CAD model: example-robot-data {erd_version()} panda_description/urdf/panda.urdf, meshes/"
                      "visual/collision/dynamics stripped, finger joints made fixed (closed); 7 arm joints",
                      fix_joints=("panda_finger_joint1", "panda_finger_joint2"))
    return text, f"example-robot-data {erd_version()} panda_description/urdf/panda.urdf (fingers fixed)"


def _ur_urdf():
    for rel, label in (("ur_description/urdf/ur10_robot.urdf", "ur10"), ("ur_description/urdf/ur3_robot.urdf", "ur3")):
        src = erd_file(rel)
        if src is not None:
            text = strip_urdf(pathlib.Path(src).read_text(),
                              f"CAD model: example-robot-data {erd_version()} {rel}, meshes/visual/collision/"
                              "transmission/gazebo/dynamics stripped")
            return text, f"example-robot-data {erd_version()} {rel}", label
    raise RuntimeError("neither ur10_robot.urdf nor ur3_robot.urdf found in example-robot-data")


PANDA_Q0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]


def case_spec(name: str) -> dict:
    """Everything that defines a case except the random draws."""
    if name == "rpr":
        return dict(urdf=_rpr_urdf(), source="own URDF (benches/heldout_robots.py)", seed=101, dt=1e-3,
                    law="algebraic", ctl="pid", q0=[0.0, 0.0, -0.3], vcap=[1.5, 0.25, 2.0], cap=[1.2, None, 1.5],
                    sat=[60.0, 400.0, 15.0], noise_pct=0.7, eps_frac=(0.005, 0.02),
                    drive=dict(Ia=[(0.05, 0.15), (1.5, 3.0), (0.004, 0.01)], Fv=[(0.5, 1.5), (20, 60), (0.05, 0.15)],
                               Fc=[(1.0, 3.0), (8.0, 20.0), (0.15, 0.4)], off=[0.0, 6.0, 0.1]),
                    pid=dict(f_bw=[4.0, 4.0, 4.0], f_d=40.0, kvf="nominal"),
                    payload=dict(mass=1.5, com=[0.22, 0.0, -0.03], box=[0.08, 0.08, 0.08]),
                    train=dict(f0=0.1, periods=2), valid=dict(f0=0.1, periods=1))
    if name in ("panda_alg", "panda_500"):
        text, src = _panda_urdf()
        base = dict(urdf=text, source=src, q0=PANDA_Q0, vcap=[1.0] * 4 + [1.3] * 3, cap=[1.2] * 7,
                    sat=[87.0] * 4 + [12.0] * 3,
                    drive=dict(Ia=[(0.1, 0.4)] * 4 + [(0.02, 0.08)] * 3, Fv=[(0.5, 3.0)] * 4 + [(0.2, 1.0)] * 3,
                               Fc=[(1.0, 4.0)] * 4 + [(0.3, 1.2)] * 3, off=[0.3] * 4 + [0.1] * 3),
                    payload=dict(mass=1.0, com=[0.0, 0.0, 0.18], box=[0.08, 0.08, 0.06]),
                    train=dict(f0=0.1, periods=2), valid=dict(f0=0.1, periods=1), eps_frac=(0.005, 0.02))
        if name == "panda_alg":
            return dict(base, seed=202, dt=1e-3, law="algebraic", ctl="cascade", noise_pct=0.6,
                        cascade=dict(f_p=4.0, ratio=3.0, fc=25.0, kff=1.0))
        return dict(base, seed=303, dt=2e-3, law="exp", ctl="pid", noise_pct=0.8,
                    pid=dict(f_bw=[3.0] * 7, f_d=25.0, kvf="nominal"))
    if name == "ur10_atan":
        text, src, label = _ur_urdf()
        return dict(urdf=text, source=src, robot=label, seed=404, dt=2.5e-4, law="atan", ctl="cascade",
                    q0=[0.0, -1.3, 1.6, -1.9, -1.57, 0.0], vcap=[0.8, 0.8, 1.0, 1.5, 1.5, 1.5], cap=[1.0] * 6,
                    sat=None, noise_pct=0.5, eps_frac=(0.005, 0.02),
                    drive=dict(Ia=[(0.5, 1.5)] * 2 + [(0.2, 0.6)] + [(0.05, 0.15)] * 3,
                               Fv=[(3.0, 10.0)] * 2 + [(2.0, 6.0)] + [(0.5, 2.0)] * 3,
                               Fc=[(5.0, 15.0)] * 2 + [(3.0, 10.0)] + [(1.0, 3.0)] * 3, off=[1.0] * 3 + [0.3] * 3),
                    cascade=dict(f_p=5.0, ratio=3.0, fc=40.0, kff=1.0),
                    payload=dict(mass=5.0, tool_frame="tool0", tool_offset=0.05, box=[0.1, 0.1, 0.1]),
                    train=dict(f0=0.1, periods=1), valid=dict(f0=0.2, periods=2))
    if name == "arm2_tanh":
        return dict(urdf=_arm2_urdf(), source="own URDF (benches/heldout_robots.py)", seed=505, dt=5e-4,
                    law="tanh", ctl="pid", q0=[0.4, -0.8], vcap=[1.5, 1.5], cap=[1.6, 1.6], sat=[80.0, 30.0],
                    noise_pct=1.0, eps_frac=(0.005, 0.02),
                    drive=dict(Ia=[(0.02, 0.06)] * 2, Fv=[(0.3, 1.0)] * 2, Fc=[(0.5, 1.5)] * 2, off=[0.2, 0.2]),
                    pid=dict(f_bw=[4.0, 4.0], f_d=40.0, kvf=None),
                    payload=dict(mass=1.0, com=[0.0, 0.0, 0.4], box=[0.06, 0.06, 0.06]),
                    train=dict(f0=0.1, periods=2), valid=dict(f0=0.1, periods=1))
    raise KeyError(name)


CASES = ("rpr", "panda_alg", "panda_500", "ur10_atan", "arm2_tanh")

# ------------------------------------------------------------------------------------------------------------------
# truth


def perturb_inertia(I: pin.Inertia, rng) -> pin.Inertia:
    """Mass x(1+U(-0.15, 0.15)), COM + U(-0.02, 0.02) m per axis, principal inertias about the COM x(1+U(-0.2, 0.2)),
    redrawn until physically valid (positive, triangle inequalities)."""
    ev, R = np.linalg.eigh(I.inertia)
    for _ in range(1000):
        m = I.mass * (1 + rng.uniform(-0.15, 0.15))
        c = I.lever + rng.uniform(-0.02, 0.02, 3)
        e = ev * (1 + rng.uniform(-0.2, 0.2, 3))
        if m > 0 and np.all(e > 0) and all(e[i] + e[(i + 1) % 3] >= e[(i + 2) % 3] for i in range(3)):
            return pin.Inertia(m, c, R @ np.diag(e) @ R.T)
    raise RuntimeError("no physically valid perturbation")


def inertia_json(I: pin.Inertia) -> dict:
    return {"dyn10": [float(x) for x in I.toDynamicParameters()], "mass": float(I.mass),
            "com": [float(x) for x in I.lever], "inertia_com": [[float(x) for x in r] for r in I.inertia]}


def load_model(urdf_path: str, joints: list[str] | None = None) -> pin.Model:
    model = pin.buildModelFromUrdf(urdf_path)
    model.gravity = pin.Motion(GRAVITY, np.zeros(3))
    assert model.nq == model.nv, "only 1-dof joints"
    if joints is not None:
        assert list(model.names)[1:] == joints
    return model


def with_inertias(model: pin.Model, inertias) -> pin.Model:
    m = model.copy()
    for i, I in enumerate(inertias, start=1):
        m.inertias[i] = I.copy()
    return m


def joint_kinds(model: pin.Model) -> list[str]:
    kinds = []
    for i in range(1, model.njoints):
        sn = model.joints[i].shortname()
        if "Prismatic" in sn or sn.startswith("JointModelP"):
            kinds.append("prismatic")
        elif "Revolute" in sn or sn.startswith("JointModelR"):
            kinds.append("revolute")
        else:
            raise ValueError(sn)
    return kinds


# ------------------------------------------------------------------------------------------------------------------
# controllers (coefficients in ascending powers of 1/z)


def padd(*ps):
    m = max(len(p) for p in ps)
    out = np.zeros(m)
    for p in ps:
        out[: len(p)] += p
    return out


def pid_tf(J, dt, f_bw, f_d, kvf, sat):
    """PID on e = qr - qm: Kp + Ki*Tustin integral + Kd*s/(tau*s + 1) by backward Euler, plus velocity feed-forward
    kvf*(backward difference of qr)/dt on C_r. Gains by pole placement at (s + w)^3 on J s^2.

    (An acceleration feed-forward through the second difference of qr/dt^2 was tried and dropped: its 1/dt^2
    coefficients, integrated by the PID's pole at z = 1, make two correct double-precision realisations of the same
    law differ by ~1e-8 relative over 20 s, so a replay of the JSON could not be held to 1e-9.)"""
    w = 2 * math.pi * f_bw
    Kp, Ki, Kd = 3 * J * w * w, J * w**3, 3 * J * w
    tau = 1 / (2 * math.pi * f_d)
    beta = tau / (tau + dt)
    den = np.convolve([1.0, -1.0], [1.0, -beta])  # (1 - z^-1)(1 - beta z^-1)
    b_y = padd(Kp * den, (Ki * dt / 2) * np.convolve([1.0, 1.0], [1.0, -beta]),
               (Kd / (tau + dt)) * np.convolve([1.0, -1.0], [1.0, -1.0]))
    b_r = padd(b_y, np.convolve((kvf / dt) * np.array([1.0, -1.0]), den)) if kvf else b_y.copy()
    tf = {"type": "transfer_function", "dt": dt, "b_r": list(map(float, b_r)), "a_r": list(map(float, den)),
          "b_y": list(map(float, b_y)), "a_y": list(map(float, den)), "saturation": float(sat), "gain": 1.0,
          "note": "u = C_r(z) qr - C_y(z) qm; force = gain*u; |u| <= saturation"}
    design = dict(Kp=Kp, Ki=Ki, Kd=Kd, tau_d=tau, kvf=kvf, f_bw=f_bw, f_d=f_d, J=J)
    return tf, design


def cascade_tf(J, dt, f_p, ratio, fc, kff, sat):
    """P position loop (Kp), PI velocity loop (Kv, Ti), velocity feed-forward kff*(backward difference of qr),
    velocity estimate = first-order low-pass (alpha = exp(-2 pi fc dt)) of the backward difference of qm."""
    Kp = 2 * math.pi * f_p
    wv = ratio * Kp
    Kv, Ti = J * wv, 4 / wv
    alpha = math.exp(-2 * math.pi * fc * dt)
    pi_num = Kv * np.array([1 + dt / Ti, -1.0])
    b_r = np.convolve(pi_num, [Kp + kff / dt, -kff / dt])
    a_r = np.array([1.0, -1.0])
    b_y = np.convolve(pi_num, padd(Kp * np.array([1.0, -alpha]), ((1 - alpha) / dt) * np.array([1.0, -1.0])))
    a_y = np.convolve([1.0, -1.0], [1.0, -alpha])
    tf = {"type": "transfer_function", "dt": dt, "b_r": list(map(float, b_r)), "a_r": list(map(float, a_r)),
          "b_y": list(map(float, b_y)), "a_y": list(map(float, a_y)), "saturation": float(sat), "gain": 1.0,
          "note": "u = C_r(z) qr - C_y(z) qm; force = gain*u; |u| <= saturation"}
    design = dict(Kp=Kp, Kv=Kv, Ti=Ti, kff=kff, fc=fc, alpha=alpha, wv=wv, J=J)
    return tf, design


def expm(A):
    """Matrix exponential by scaling and squaring of a Taylor series (small matrices)."""
    nrm = np.linalg.norm(A, 1)
    s = max(0, int(math.ceil(math.log2(nrm))) + 1) if nrm > 0 else 0
    X = A / 2**s
    E, T = np.eye(len(A)), np.eye(len(A))
    for k in range(1, 25):
        T = T @ X / k
        E = E + T
    for _ in range(s):
        E = E @ E
    return E


def loop_check(tf, J, fv, kg, dt):
    """One joint's loop with the plant 1/(J s^2 + fv s + kg), zero-order held at dt, and u = -C_y(z) qm (no
    quantisation, no Coulomb friction): closed-loop spectral radius, phase margin at the gain crossover(s), and the
    gain margin at phase crossings above the crossover."""
    A = np.array([[0.0, 1.0], [-kg / J, -fv / J]])
    B = np.array([0.0, 1.0 / J])
    aug = np.zeros((3, 3))
    aug[:2, :2], aug[:2, 2] = A, B
    E = expm(aug * dt)
    Phi, Gam = E[:2, :2], E[:2, 2]
    b, a = np.array(tf["b_y"]), np.array(tf["a_y"])
    m = max(len(b), len(a))
    b, a = padd(b, np.zeros(m)) / a[0], padd(a, np.zeros(m)) / a[0]
    nz = m - 1
    N = 2 + nz
    Cq = np.array([1.0, 0.0])
    Ku = np.zeros(N)
    Ku[:2] = -b[0] * Cq
    Ku[2] = 1.0
    Acl = np.zeros((N, N))
    Acl[:2, :2] = Phi
    Acl[:2, :] += np.outer(Gam, Ku)
    for i in range(nz):
        row = np.zeros(N)
        row[:2] = -b[i + 1] * Cq
        row -= a[i + 1] * Ku
        if i + 1 < nz:
            row[2 + i + 1] += 1.0
        Acl[2 + i] = row
    rho = float(np.max(np.abs(np.linalg.eigvals(Acl))))
    w = np.logspace(-1, math.log10(0.999 * math.pi / dt), 20000)
    zi = np.exp(-1j * w * dt)
    C = np.polyval(b[::-1], zi) / np.polyval(a[::-1], zi)
    z = 1 / zi
    P = np.array([Cq @ np.linalg.solve(zk * np.eye(2) - Phi, Gam) for zk in z])
    L = C * P
    mag = np.log(np.abs(L))
    pms, wcs = [], []
    for k in np.nonzero(np.sign(mag[:-1]) != np.sign(mag[1:]))[0]:
        deg = math.degrees(np.angle(L[k]))
        pms.append(((180 + deg) + 180) % 360 - 180)
        wcs.append(w[k])
    gms = []
    if wcs:
        wc = max(wcs)
        for k in np.nonzero((np.sign(L.imag[:-1]) != np.sign(L.imag[1:])) & (L.real[:-1] < 0))[0]:
            if w[k] > wc:
                gms.append(-20 * math.log10(abs(L[k])))
    return dict(closed_loop_spectral_radius=rho, stable=rho < 1.0,
                phase_margin_deg=float(min(pms)) if pms else None,
                crossover_hz=float(max(wcs) / (2 * math.pi)) if wcs else None,
                upper_gain_margin_db=float(min(gms)) if gms else None)


class Filters:
    """A bank of SISO filters b(z^-1)/a(z^-1), one per joint, in transposed direct form II: the simulator's law. It
    runs in extended precision (np.longdouble, 64-bit mantissa on x86-64) so that the force column is the exact law's
    output rounded to double: a double-precision realisation of these laws (coefficients up to ~1e6 on an integrator)
    drifts from the exact output by ~1e-9..1e-8 relative over 20 s, whichever realisation."""

    def __init__(self, bs, as_, dtype=np.longdouble):
        m = max(max(len(b), len(a)) for b, a in zip(bs, as_))
        pad = lambda x: np.concatenate([np.asarray(x, dtype), np.zeros(m - len(x), dtype)])  # noqa: E731
        self.b = np.array([pad(b) / dtype(a[0]) for b, a in zip(bs, as_)], dtype)
        self.a = np.array([pad(a) / dtype(a[0]) for a in as_], dtype)
        self.z = np.zeros((len(bs), m - 1), dtype)
        self.dtype = dtype

    def step(self, x):
        x = np.asarray(x, self.dtype)
        y = self.b[:, 0] * x + self.z[:, 0]
        zn = self.b[:, 1:] * x[:, None] - self.a[:, 1:] * y[:, None]
        zn[:, :-1] += self.z[:, 1:]
        self.z = zn
        return y


def replay(ctl_json: dict, qr, qm, force0, dtype=np.longdouble):
    """The force column again from the controller JSON by direct form I (a second, independent implementation):
    u = force0 + C_r[qr - qr0] - C_y[qm - qr0], zero initial states, in ``dtype`` (np.longdouble: the exact law's
    output to ~1e-15; np.float64: what a plain double-precision replay gets)."""
    N, n = qr.shape
    js = ctl_json["joints"]
    total = np.zeros((N, n), dtype)
    for key_b, key_a, x, sign in (("b_r", "a_r", qr - qr[0], 1), ("b_y", "a_y", qm - qr[0], -1)):
        m = max(max(len(c[key_b]), len(c[key_a])) for c in js)
        B = np.zeros((n, m), dtype)
        A = np.zeros((n, m), dtype)
        for j, c in enumerate(js):
            B[j, : len(c[key_b])] = np.asarray(c[key_b], dtype)
            A[j, : len(c[key_a])] = np.asarray(c[key_a], dtype)
        X = np.asarray(x, dtype)
        Y = np.zeros((N, n), dtype)
        for k in range(N):
            acc = B[:, 0] * X[k]
            for i in range(1, min(m, k + 1)):
                acc = acc + B[:, i] * X[k - i] - A[:, i] * Y[k - i]
            Y[k] = acc / A[:, 0]
        total += sign * Y
    sat = np.array([c["saturation"] for c in js], dtype)
    gain = np.array([c.get("gain", 1.0) for c in js], dtype)
    return np.asarray(gain * np.clip(total + np.asarray(force0, dtype) / gain, -sat, sat), np.float64)


# ------------------------------------------------------------------------------------------------------------------
# excitation


def fourier_draw(rng, n, harmonics=5):
    """Coefficients a, b (n x harmonics) with sum(a) = 0 (v(0) = 0) and sum(l*b) = 0 (qdd(0) = 0)."""
    ls = np.arange(1, harmonics + 1)
    A = rng.normal(size=(n, harmonics))
    A -= A.mean(axis=1, keepdims=True)
    B = rng.normal(size=(n, harmonics))
    B -= np.outer(B @ ls, ls) / (ls @ ls)
    return A, B


def fourier_eval(A, B, f0, t):
    """x, v, acc (len(t) x n) of x(t) = sum_l a_l/(w l) sin(w l t) - b_l/(w l)(cos(w l t) - 1)."""
    w = 2 * math.pi * f0
    ls = np.arange(1, A.shape[1] + 1)
    wl = w * ls
    S, Cc = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))
    x = S @ (A / wl).T - (Cc - 1) @ (B / wl).T
    v = Cc @ A.T + S @ B.T
    acc = -S @ (A * wl).T + Cc @ (B * wl).T
    return x, v, acc


def scales(A, B, f0, q0, lo, hi, vcap, cap):
    """Per-joint scale keeping q0 + s*x inside the limits' 10 % margins (and within +-cap of q0) and |s*v| <= vcap."""
    t = np.linspace(0, 1 / f0, 4001)
    x, v, _ = fourier_eval(A, B, f0, t)
    s = np.empty(len(q0))
    for j in range(len(q0)):
        lo_m, hi_m = lo[j] + 0.1 * (hi[j] - lo[j]), hi[j] - 0.1 * (hi[j] - lo[j])
        cands = [vcap[j] / np.max(np.abs(v[:, j]))]
        if np.max(x[:, j]) > 0:
            cands.append((hi_m - q0[j]) / np.max(x[:, j]))
        if np.min(x[:, j]) < 0:
            cands.append((q0[j] - lo_m) / -np.min(x[:, j]))
        if cap[j] is not None:
            cands.append(cap[j] / np.max(np.abs(x[:, j])))
        s[j] = min(cands)
        assert s[j] > 0
    return s


def trajectory(A, B, s, f0, q0, seconds, dt):
    N = int(round(seconds / dt)) + 1
    t = np.arange(N) * dt
    x, v, acc = fourier_eval(A, B, f0, t)
    return q0 + s * x, s * v, s * acc


# ------------------------------------------------------------------------------------------------------------------
# regressors


def drive_columns(qd, qdd, sv, n):
    return np.hstack([np.diag(qdd), np.diag(qd), np.diag(sv), np.eye(n)])


def regressor(model, data, qs, vs, accs, law, eps):
    rows = []
    n = model.nv
    for q, v, a in zip(qs, vs, accs):
        Y = pin.computeJointTorqueRegressor(model, data, q, v, a).copy()
        rows.append(np.hstack([Y, drive_columns(v, a, friction_shape(law, v / eps), n)]))
    return np.vstack(rows)


def base_columns(W, tol=1e-7):
    """Indices of a set of independent columns (greedy Gram-Schmidt with pivoting on the unit-norm columns)."""
    nrm = np.linalg.norm(W, axis=0)
    keep = np.nonzero(nrm > 1e-12 * nrm.max())[0]
    R = W[:, keep] / nrm[keep]
    chosen = []
    res = np.linalg.norm(R, axis=0)
    while True:
        res[chosen] = 0.0
        j = int(np.argmax(res))
        if res[j] < tol:
            break
        qv = R[:, j] / res[j]
        for _ in range(2):
            R -= np.outer(qv, qv @ R)
        chosen.append(j)
        res = np.linalg.norm(R, axis=0)
    return np.sort(keep[chosen])


def cond_unit(W):
    Wn = W / np.linalg.norm(W, axis=0)
    sv = np.linalg.svd(Wn, compute_uv=False)
    return float(sv[0] / sv[-1])


def ideal_torque(model, data, Ia, Fv, Fc, off, law, eps, qs, vs, accs):
    return np.array([pin.rnea(model, data, q, v, a) + Ia * a + Fv * v + Fc * friction_shape(law, v / eps) + off
                     for q, v, a in zip(qs, vs, accs)])


# ------------------------------------------------------------------------------------------------------------------
# the closed loop


def load_friction_acc(model, data, q, v, tau, Ia, j, c):
    """The acceleration of (M(q) + diag Ia) qdd + nle(q, v) = tau - x e_j with the load-dependent friction
    x = c |tau_L,j| (c = mu s(v_j)), tau_L = M(q) qdd + nle(q, v) the links' torque (without the rotor's Ia qdd),
    solved exactly: x moves qdd along (M + Ia)^-1 e_j, so tau_L,j = a - b x is affine in x and x = c |a - b x| has
    the root of the sign it takes (unique for |c b| < 1). ``model.armature`` = Ia."""
    e_j = np.zeros(model.nv)
    e_j[j] = 1.0
    a0 = pin.aba(model, data, q, v, tau).copy()
    unit = pin.aba(model, data, q, v, tau + e_j) - a0  # (M + Ia)^-1 e_j
    a, b = tau[j] - Ia[j] * a0[j], 1.0 - Ia[j] * unit[j]
    x = c * a / (1.0 + c * b)
    if a - b * x < 0.0:
        x = -c * a / (1.0 - c * b)
    return a0 - x * unit


def closed_loop(model, Ia, Fv, Fc, off, law, eps, ctl_json, qr, dt, substeps, steps, force0, noise=None,
                effect=None):
    """RK4 over pin.aba (armature = Ia), ``substeps`` per sample, u + noise held over the sample; ``steps`` the encoder
    steps (None: no quantisation, qm = q). Returns force, qm, and the true q and v at the sample instants.

    ``effect`` (None: the rigid plant above) adds ONE effect the rigid model lacks, a dict with ``kind`` and, on one
    joint, ``joint`` (0-based):

    - ``stribeck``: friction += dF exp(-(v/vst)^2) s(v) on the joint (s the Coulomb shape of ``law``);
    - ``asymmetric``: the joint's Coulomb term Fc s(v) becomes Fc_plus max(s, 0) + Fc_minus min(s, 0);
    - ``spring``: the link torque += -k sin(q + phi) + c on the joint (a counterbalance or a cable);
    - ``load``: friction += mu s(v) |tau_L| on the joint, tau_L = M(q) qdd + C qd + g (the links only, without
      the rotor's Ia qdd), solved exactly (tau_L is affine in the added torque x: x = mu s |a - b x|);
    - ``delay``: u[k] (logged at row k) is applied over [t_{k+1}, t_{k+2}) on every joint, u[-1] = force0; the
      noise d[k] still acts over [t_k, t_{k+1});
    - ``lag``: the applied torque tau_a lags u by a first-order lag on every joint, tau_a' = (u - tau_a)/T (solved
      exactly over the sample, u held), tau_a(0) = force0; the plant gets tau_a + d.
    """
    model = model.copy()
    model.armature = np.asarray(Ia, float).copy()
    data = model.createData()
    aba = pin.aba
    n, N = model.nv, len(qr)
    js = ctl_json["joints"]
    Fr = Filters([c["b_r"] for c in js], [c["a_r"] for c in js])
    Fy = Filters([c["b_y"] for c in js], [c["a_y"] for c in js])
    sat = np.array([c["saturation"] for c in js])
    gain = np.array([c["gain"] for c in js])
    qr0 = qr[0].copy()
    q, v = qr0.copy(), np.zeros(n)
    force, qm_log = np.empty((N, n)), np.empty((N, n))
    q_log, v_log = np.empty((N, n)), np.empty((N, n))
    h = dt / substeps
    hh, h6 = 0.5 * h, h / 6.0
    Fv, Fc, off, eps = (np.asarray(x, float) for x in (Fv, Fc, off, eps))
    inv_eps = 1.0 / eps
    shape = {"algebraic": lambda x: x / np.sqrt(1.0 + x * x), "tanh": np.tanh,
             "atan": lambda x: (2.0 / math.pi) * np.arctan((math.pi / 2.0) * x),
             "exp": lambda x: np.sign(x) * (-np.expm1(-np.abs(x)))}[law]
    kind = effect["kind"] if effect else None
    j = effect.get("joint") if effect else None
    e_j = np.zeros(n)
    if j is not None:
        e_j[j] = 1.0

    def acc(q, v, tau):
        """The plant's acceleration under the drive torque ``tau`` (friction and the effect subtracted here)."""
        s = shape(v * inv_eps)
        t = tau - Fv * v - Fc * s
        if kind == "stribeck":
            t = t - e_j * (effect["dF"] * math.exp(-(v[j] / effect["vst"]) ** 2) * s[j])
        elif kind == "asymmetric":
            t = t + e_j * (Fc[j] * s[j] - effect["Fc_plus"] * max(s[j], 0.0) - effect["Fc_minus"] * min(s[j], 0.0))
        elif kind == "spring":
            t = t + e_j * (-effect["k"] * math.sin(q[j] + effect["phi"]) + effect["c"])
        elif kind == "load":
            return load_friction_acc(model, data, q, v, t, Ia, j, effect["mu"] * s[j])
        return aba(model, data, q, v, t)

    saturated = False
    force0_ld = np.asarray(force0, np.longdouble) / np.asarray(gain, np.longdouble)
    u_prev = np.asarray(force0, float).copy()  # the delay's u[k - 1] and the lag's tau_a at t_k
    for k in range(N):
        qm = np.round(q / steps) * steps if steps is not None else q.copy()
        u = np.asarray(Fr.step(qr[k] - qr0) - Fy.step(qm - qr0) + force0_ld, np.float64)
        if np.any(np.abs(u) > sat):
            saturated = True
            u = np.clip(u, -sat, sat)
        u = gain * u
        force[k], qm_log[k], q_log[k], v_log[k] = u, qm, q, v
        d = 0.0 if noise is None else noise[k]
        if kind == "delay":
            tau, u_prev = u_prev + d - off, u
        else:
            tau = u + d - off
        if kind == "lag":
            # tau_a(s) = u + (tau_a(t_k) - u) exp(-s/T) over the sample, s from t_k
            lag0, T = u_prev - u, effect["T"]
            u_prev = u + lag0 * math.exp(-dt / T)
        for i in range(substeps):
            if kind == "lag":
                s0 = i * h
                t1, t2, t4 = (tau + lag0 * math.exp(-(s0 + x) / T) for x in (0.0, hh, h))
            else:
                t1 = t2 = t4 = tau
            k1 = acc(q, v, t1)
            v2 = v + hh * k1
            k2 = acc(q + hh * v, v2, t2)
            v3 = v + hh * k2
            k3 = acc(q + hh * v2, v3, t2)
            v4 = v + h * k3
            k4 = acc(q + h * v3, v4, t4)
            q = q + h6 * (v + 2 * v2 + 2 * v3 + v4)
            v = v + h6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return dict(force=force, qm=qm_log, q=q_log, v=v_log, saturated=saturated)


def friction_lambda(model, Ia, Fv, Fc, eps, qs):
    """Largest eigenvalue of (M(q) + diag Ia)^-1 diag(Fv + Fc/eps) over the poses qs (1/s)."""
    m = model.copy()
    m.armature = np.zeros(m.nv)
    d = m.createData()
    D = np.diag(Fv + Fc / eps)
    lam = 0.0
    for q in qs:
        M = pin.crba(m, d, q)
        M = np.triu(M) + np.triu(M, 1).T + np.diag(Ia)
        lam = max(lam, float(np.max(np.real(np.linalg.eigvals(np.linalg.solve(M, D))))))
    return lam


# ------------------------------------------------------------------------------------------------------------------
# files


def write_csv(path, dt, qr, force, qm):
    N, n = qr.shape
    dec = next(d for d in range(0, 12) if abs(round(dt, d) - dt) < 1e-15)
    t = np.round(np.arange(N) * dt, dec)
    cols = ["t"] + [f"qr_{j + 1}" for j in range(n)] + [f"force_{j + 1}" for j in range(n)] + \
           [f"qm_{j + 1}" for j in range(n)]
    np.savetxt(path, np.column_stack([t, qr, force, qm]), delimiter=",", header=",".join(cols), comments="",
               fmt=[f"%.{dec}f"] + ["%.17g"] * (3 * n))


def read_csv(path, n):
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    X = np.loadtxt(path, delimiter=",", skiprows=1)
    assert header == ["t"] + [f"qr_{j + 1}" for j in range(n)] + [f"force_{j + 1}" for j in range(n)] + \
        [f"qm_{j + 1}" for j in range(n)], header
    return X[:, 0], X[:, 1:1 + n], X[:, 1 + n:1 + 2 * n], X[:, 1 + 2 * n:1 + 3 * n]


def rel(x):
    return [float(v) for v in np.atleast_1d(x)]


# ------------------------------------------------------------------------------------------------------------------
# one case


def run_case(name: str, out: pathlib.Path, check_substeps: bool = True) -> dict:
    t_case = time.perf_counter()
    spec = case_spec(name)
    seed = spec["seed"]
    rng = lambda k: np.random.default_rng([seed, k])  # noqa: E731  one stream per purpose
    dt = spec["dt"]
    def say(msg):
        print(f"[{name}] {msg}", flush=True)

    # ---- CAD model and truth
    cad_path = out / f"{name}_cad.urdf"
    cad_path.write_text(spec["urdf"])
    cad = load_model(str(cad_path))
    n = cad.nv
    names = list(cad.names)[1:]
    kinds = joint_kinds(cad)
    steps = np.array([REV_STEP if k == "revolute" else PRIS_STEP for k in kinds])
    lo, hi = cad.lowerPositionLimit.copy(), cad.upperPositionLimit.copy()
    vlim = cad.velocityLimit.copy()
    sat = np.array(spec["sat"] if spec["sat"] is not None else cad.effortLimit, float)
    r_truth = rng(1)
    truth_I = [perturb_inertia(cad.inertias[i], r_truth) for i in range(1, n + 1)]
    truth = with_inertias(cad, truth_I)
    r_drive = rng(2)
    dr = spec["drive"]
    Ia = np.array([r_drive.uniform(*b) for b in dr["Ia"]])
    Fv = np.array([r_drive.uniform(*b) for b in dr["Fv"]])
    Fc = np.array([r_drive.uniform(*b) for b in dr["Fc"]])
    off = np.array([r_drive.uniform(-b, b) if (b > 0 and r_drive.uniform() < 0.6) else 0.0 for b in dr["off"]])
    vcap = np.array(spec["vcap"], float)
    assert np.all(vcap < vlim), (vcap, vlim)
    eps_frac = r_drive.uniform(*spec["eps_frac"], n)
    eps = vcap * eps_frac  # provisional (for choosing the draws); final: eps_frac * the train reference's top speed
    law = spec["law"]

    # ---- payload (rigid, on the last link, in the last joint's frame)
    pl = spec["payload"]
    if "tool_frame" in pl:
        fr = cad.frames[cad.getFrameId(pl["tool_frame"])]
        assert fr.parentJoint == n
        com = fr.placement.translation + fr.placement.rotation @ np.array([0.0, 0.0, pl["tool_offset"]])
    else:
        com = np.array(pl["com"], float)
    bx = pl["box"]
    bi = box_inertia(pl["mass"], *bx)
    Ip = np.diag([bi[0], bi[3], bi[5]])
    payload = pin.Inertia(pl["mass"], com, Ip)
    truth_pl = with_inertias(truth, truth_I[:-1] + [truth_I[-1] + payload])

    # ---- plant check: aba with armature against (crba + Ia)^-1 (tau - rnea(q, v, 0))
    mt = truth.copy()
    mt.armature = Ia.copy()
    dt_ = mt.createData()
    rq = rng(9)
    worst = 0.0
    for _ in range(5):
        q = rq.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0))
        v, tq = rq.normal(size=n), rq.normal(size=n) * 5
        a1 = pin.aba(mt, dt_, q, v, tq).copy()
        M = pin.crba(mt, dt_, q)
        M = np.triu(M) + np.triu(M, 1).T
        a2 = np.linalg.solve(M, tq - pin.rnea(mt, dt_, q, v, np.zeros(n)))
        worst = max(worst, float(np.max(np.abs(a1 - a2)) / np.max(np.abs(a2))))
    say(f"{n} joints {names} kinds {kinds}; aba vs crba+Ia solve max rel diff {worst:.1e}")

    # ---- excitation: train = best conditioned of N_TRAIN_DRAWS, valid = first admissible draw of another stream
    q0 = np.round(np.array(spec["q0"], float) / steps) * steps
    dtruth, dtruth_pl, dcad = truth.createData(), truth_pl.createData(), cad.createData()
    rb = rng(8)
    Wr = regressor(cad, dcad, rb.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0), size=(300, n)),
                   rb.normal(size=(300, n)), rb.normal(size=(300, n)) * 3, law, eps)
    base = base_columns(Wr)

    def assess(A, B, f0):
        s = scales(A, B, f0, q0, lo, hi, vcap, spec["cap"])
        t = np.linspace(0, 1 / f0, 501)[:-1]
        x, v, acc = fourier_eval(A, B, f0, t)
        qs, vs, accs = q0 + s * x, s * v, s * acc
        W = regressor(cad, dcad, qs, vs, accs, law, eps)[:, base]
        tq = ideal_torque(truth, dtruth, Ia, Fv, Fc, off, law, eps, qs, vs, accs)
        tp = ideal_torque(truth_pl, dtruth_pl, Ia, Fv, Fc, off, law, eps, qs, vs, accs)
        load = float(np.max(np.maximum(np.abs(tq), np.abs(tp)) / sat))
        return s, cond_unit(W), load, tq

    tr = spec["train"]
    rt = rng(3)
    best = None
    tried = 0
    for _ in range(N_TRAIN_DRAWS):
        A, B = fourier_draw(rt, n)
        s, c, load, tq = assess(A, B, tr["f0"])
        tried += 1
        if load <= 0.5 and (best is None or c < best[3]):
            best = (A, B, s, c, load, tq)
    if best is None:
        raise RuntimeError(f"{name}: no train draw keeps the ideal torque under 50 % of saturation")
    A_tr, B_tr, s_tr, cond_tr, load_tr, tq_tr = best
    # the smoothing speed: eps_frac of each joint's top speed on the train reference
    t_fine = np.linspace(0, 1 / tr["f0"], 20001)
    v_top = np.max(np.abs(s_tr * fourier_eval(A_tr, B_tr, tr["f0"], t_fine)[1]), axis=0)
    eps = eps_frac * v_top
    _, cond_tr, load_tr, tq_tr = assess(A_tr, B_tr, tr["f0"])
    va = spec["valid"]
    rv = rng(4)
    for _ in range(200):
        A_va, B_va = fourier_draw(rv, n)
        s_va, cond_va, load_va, _ = assess(A_va, B_va, va["f0"])
        if load_va <= 0.5:
            break
    else:
        raise RuntimeError(f"{name}: no valid draw under 50 % of saturation")
    say(f"{len(base)} base columns (rigid body + Ia, Fv, Fc, offset); train cond {cond_tr:.1f} (best of {tried}), "
        f"valid cond {cond_va:.1f}; ideal |torque|/sat train {load_tr:.2f}, valid {load_va:.2f}")
    qr_tr, v_tr, _ = trajectory(A_tr, B_tr, s_tr, tr["f0"], q0, tr["periods"] / tr["f0"], dt)
    qr_va, v_va, _ = trajectory(A_va, B_va, s_va, va["f0"], q0, va["periods"] / va["f0"], dt)
    assert np.array_equal(qr_tr[0], q0) and np.array_equal(qr_va[0], q0)
    assert np.array_equal(np.round(q0 / steps) * steps, q0)

    # ---- noise level: pct of the RMS of the ideal (truth) torque on the train reference
    rms = np.sqrt(np.mean(tq_tr**2, axis=0))
    noise_std = spec["noise_pct"] / 100 * rms

    # ---- controllers, designed on the truth diag(M(q0) + Ia) and checked per joint
    m0 = truth.copy()
    m0.armature = np.zeros(n)
    d0 = m0.createData()
    Mq0 = pin.crba(m0, d0, q0)
    Jd = np.diag(np.triu(Mq0) + np.triu(Mq0, 1).T) + Ia
    g0 = pin.computeGeneralizedGravity(m0, d0, q0).copy()
    kg = np.zeros(n)
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = 1e-6
        gp = pin.computeGeneralizedGravity(m0, d0, q0 + dq)[j]
        kg[j] = (gp - pin.computeGeneralizedGravity(m0, d0, q0 - dq)[j]) / 2e-6
    tfs, designs, checks = [], [], []
    for j in range(n):
        if spec["ctl"] == "pid":
            p = spec["pid"]
            # velocity feed-forward = a nominal viscous friction (the middle of the range the truth is drawn from),
            # or none
            kvf = 0.5 * sum(dr["Fv"][j]) if p["kvf"] == "nominal" else 0.0
            tf, des = pid_tf(Jd[j], dt, p["f_bw"][j], p["f_d"], kvf, sat[j])
        else:
            p = spec["cascade"]
            tf, des = cascade_tf(Jd[j], dt, p["f_p"], p["ratio"], p["fc"], p["kff"], sat[j])
        chk = loop_check(tf, Jd[j], Fv[j], kg[j], dt)
        if not chk["stable"]:
            raise RuntimeError(f"{name}: joint {names[j]} loop unstable: {chk}")
        tfs.append(tf)
        designs.append(des)
        checks.append(chk)
    ctl_json = {"type": "joints", "joints": tfs}
    ctl_text = json.dumps(ctl_json, indent=1)
    (out / f"{name}_controller.json").write_text(ctl_text + "\n")
    ctl_json = json.loads(ctl_text)  # the simulation runs exactly the doubles written
    say("loops: spectral radius " + ", ".join(f"{c['closed_loop_spectral_radius']:.4f}" for c in checks)
        + "; phase margin " + ", ".join(f"{c['phase_margin_deg']:.0f}" for c in checks) + " deg at "
        + ", ".join(f"{c['crossover_hz']:.1f}" for c in checks) + " Hz")

    # ---- substeps from the stiffest friction mode along the train reference
    lam = friction_lambda(truth_pl, Ia, Fv, Fc, eps, qr_tr[:: max(1, len(qr_tr) // 40)])
    lam = max(lam, friction_lambda(truth, Ia, Fv, Fc, eps, qr_tr[:: max(1, len(qr_tr) // 40)]))
    S = max(1, int(math.ceil(dt * lam / KAPPA)))
    say(f"friction lambda_max {lam:.0f} 1/s, dt*lambda {dt * lam:.2f} -> {S} RK4 substeps per sample")

    # ---- records
    recs = {}
    noise_rng = {"train": rng(5), "valid": rng(6), "payload": rng(7)}
    for rec_name, qr, model_rec in (("train", qr_tr, truth), ("valid", qr_va, truth), ("payload", qr_tr, truth_pl)):
        N = len(qr)
        d_ = model_rec.createData()
        u0 = pin.computeGeneralizedGravity(model_rec, d_, qr[0]).copy() + off
        noise = noise_rng[rec_name].normal(size=(N, n)) * noise_std
        t0 = time.perf_counter()
        sim = closed_loop(model_rec, Ia, Fv, Fc, off, law, eps, ctl_json, qr, dt, S, steps, u0, noise)
        ref = closed_loop(model_rec, Ia, Fv, Fc, off, law, eps, ctl_json, qr, dt, S, steps, u0, None)
        el = time.perf_counter() - t0
        assert not sim["saturated"] and not ref["saturated"]
        assert np.array_equal(sim["qm"][0], qr[0])
        force, qm = sim["force"], sim["qm"]
        fl_tot = float(np.linalg.norm(force - ref["force"]) / np.linalg.norm(force))
        fl_j = np.linalg.norm(force - ref["force"], axis=0) / np.linalg.norm(force, axis=0)
        path = out / f"{name}_{rec_name}.csv"
        write_csv(path, dt, qr, force, qm)
        t_f, qr_f, force_f, qm_f = read_csv(path, n)
        assert np.array_equal(qr_f, qr) and np.array_equal(qm_f, qm) and np.array_equal(force_f, force)
        assert abs(t_f[-1] - (N - 1) * dt) < 1e-9 and t_f[0] == 0.0
        ctl_file = json.loads((out / f"{name}_controller.json").read_text())
        rep = replay(ctl_file, qr_f, qm_f, force_f[0], np.longdouble)
        rep_j = np.max(np.abs(rep - force_f), axis=0) / np.max(np.abs(force_f), axis=0)
        rep2 = replay(ctl_file, qr_f, qm_f, force_f[0], np.float64)
        rep2_j = np.max(np.abs(rep2 - force_f), axis=0) / np.max(np.abs(force_f), axis=0)
        rec = dict(file=path.name, size_bytes=path.stat().st_size, samples=N, duration_s=(N - 1) * dt,
                   u0=rel(u0), qm0_equals_qr0=bool(np.array_equal(qm[0], qr[0])),
                   truth_floor_total=fl_tot, truth_floor_per_joint=rel(fl_j),
                   tf_replay_max_rel_mismatch=float(np.max(rep_j)), tf_replay_max_rel_mismatch_per_joint=rel(rep_j),
                   tf_replay_note="max|replay - force| / max|force| per joint; replay = direct form I of the JSON "
                                  "law on the CSV's qr, qm and force[0], in extended precision (np.longdouble); the "
                                  "_double entries: the same replay in double precision (its own rounding drift)",
                   tf_replay_double_max_rel_mismatch=float(np.max(rep2_j)),
                   tf_replay_double_max_rel_mismatch_per_joint=rel(rep2_j),
                   tracking_rms=rel(np.sqrt(np.mean((qr - sim["q"]) ** 2, axis=0))),
                   tracking_max=rel(np.max(np.abs(qr - sim["q"]), axis=0)),
                   max_u_over_sat=rel(np.max(np.abs(force), axis=0) / sat),
                   max_abs_v=rel(np.max(np.abs(sim["v"]), axis=0)), q_min=rel(sim["q"].min(axis=0)),
                   q_max=rel(sim["q"].max(axis=0)), rms_force=rel(np.sqrt(np.mean(force**2, axis=0))),
                   sim_seconds=el)
        if rec_name in ("train", "valid"):
            rec["base_regressor_cond"] = cond_tr if rec_name == "train" else cond_va
        if np.max(rec["max_u_over_sat"]) >= 0.6:
            raise RuntimeError(f"{name} {rec_name}: |force| reached {np.max(rec['max_u_over_sat']):.2f} of saturation")
        if np.any(rec["max_abs_v"] >= vlim) or np.any(sim["q"].min(axis=0) < lo) or np.any(sim["q"].max(axis=0) > hi):
            raise RuntimeError(f"{name} {rec_name}: left the joint's position or velocity limits")
        if rec["tf_replay_max_rel_mismatch"] > 1e-9:
            raise RuntimeError(f"{name} {rec_name}: controller replay mismatch {rec['tf_replay_max_rel_mismatch']:.1e}")
        say(f"{rec_name}: {N} samples, truth floor {fl_tot:.4f} per joint [{', '.join(f'{x:.4f}' for x in fl_j)}], "
            f"controller replay max rel mismatch {rec['tf_replay_max_rel_mismatch']:.1e} (in double precision "
            f"{rec['tf_replay_double_max_rel_mismatch']:.1e}), max |u|/sat "
            f"{np.max(rec['max_u_over_sat']):.2f}, sim {el:.1f} s")
        if rec_name == "train":
            rec_ref = ref
        recs[rec_name] = rec

    # ---- substeps check: the noise-free train record again at 2S
    integ = dict(method="RK4", control_dt=dt, substeps=S, substep_dt=dt / S,
                 torque="zero-order hold of u + d over each control sample",
                 dynamics="pin.aba with model.armature = Ia (checked equal to (crba+diag(Ia))^-1 (tau - rnea(q,v,0)), "
                          f"max rel diff {worst:.1e})",
                 substep_rule=f"S = ceil(dt * lambda_max / {KAPPA}), lambda_max = largest eigenvalue of "
                              "(M(q)+diag(Ia))^-1 diag(Fv + Fc/eps) over the train reference (with and without "
                              "payload)",
                 lambda_max_per_s=lam,
                 sampling="q sampled at t_k = k*dt, qm[k] = quantised q(t_k); u[k] computed from qr[k], qm[k] and "
                          "applied over [t_k, t_k+dt) (no computation delay)")
    if check_substeps:
        # (i) as recorded (with the encoder): the loop with quantisation is sensitive to any tiny difference (an
        # encoder count flips, the controller reacts), so this difference is bounded below by that sensitivity,
        # whatever the substeps; (ii) without quantisation (qm = q) the loop is smooth and the difference between S
        # and 2S measures the integration error itself.
        t0 = time.perf_counter()
        u0_tr = np.array(recs["train"]["u0"])
        d2 = closed_loop(truth, Ia, Fv, Fc, off, law, eps, ctl_json, qr_tr, dt, 2 * S, steps, u0_tr, None)
        dfo = float(np.linalg.norm(d2["force"] - rec_ref["force"]) / np.linalg.norm(rec_ref["force"]))
        dfo_j = np.linalg.norm(d2["force"] - rec_ref["force"], axis=0) / np.linalg.norm(rec_ref["force"], axis=0)
        dq = np.max(np.abs(d2["q"] - rec_ref["q"]) / steps)
        flips = int(np.sum(d2["qm"] != rec_ref["qm"]))
        c1 = closed_loop(truth, Ia, Fv, Fc, off, law, eps, ctl_json, qr_tr, dt, S, None, u0_tr, None)
        c2 = closed_loop(truth, Ia, Fv, Fc, off, law, eps, ctl_json, qr_tr, dt, 2 * S, None, u0_tr, None)
        cfo = float(np.linalg.norm(c1["force"] - c2["force"]) / np.linalg.norm(c2["force"]))
        cdq = float(np.max(np.abs(c1["q"] - c2["q"]) / steps))
        integ["check_2x_substeps"] = dict(
            record="train reference, no noise", substeps=[S, 2 * S],
            with_encoder=dict(force_rel_diff=dfo, force_rel_diff_per_joint=rel(dfo_j),
                              ratio_to_train_floor=dfo / recs["train"]["truth_floor_total"],
                              max_q_diff_in_encoder_steps=float(dq), qm_entries_differing=flips),
            without_encoder=dict(force_rel_diff=cfo, max_q_diff_in_encoder_steps=cdq),
            seconds=time.perf_counter() - t0)
        say(f"substeps check {S} vs {2 * S} (train, no noise): without encoder force rel diff {cfo:.1e}, max |dq| "
            f"{cdq:.1e} encoder steps; with encoder force rel diff {dfo:.2e} "
            f"({dfo / recs['train']['truth_floor_total']:.2f} of the train floor), max |dq| {dq:.2f} encoder steps, "
            f"{flips} qm entries differ")

    # ---- truth entry
    units = ["rad" if k == "revolute" else "m" for k in kinds]
    f_units = ["N*m" if k == "revolute" else "N" for k in kinds]
    if spec["ctl"] == "pid":
        ctl_info = dict(
            file=f"{name}_controller.json", type="pid",
            structure="PID on e = qr - qm with filtered derivative, plus velocity feed-forward on qr (kvf, 0 = "
                      "none): u = Kp e + Ki I(e) + Kd D(e) + kvf * (qr[k] - qr[k-1]) / dt; I Tustin: "
                      "dt/2 (1 + z^-1)/(1 - z^-1); D backward Euler of s/(tau_d s + 1): (1 - z^-1)/((tau_d + dt) - "
                      "tau_d z^-1); C_y = Kp + Ki I + Kd D; C_r = C_y + kvf (1 - z^-1)/dt; common denominator "
                      "(1 - z^-1)(1 - beta z^-1), beta = tau_d/(tau_d + dt)",
            design="pole placement (s + w)^3 on J s^2: Kp = 3 J w^2, Ki = J w^3, Kd = 3 J w, w = 2 pi f_bw; J = "
                   "diag(M_truth(q0)) + Ia; tau_d = 1/(2 pi f_d); kvf = a nominal viscous friction (middle of the "
                   "range the truth Fv is drawn from), not the truth",
            Kp=[d["Kp"] for d in designs], Ki=[d["Ki"] for d in designs], Kd=[d["Kd"] for d in designs],
            tau_d_s=[d["tau_d"] for d in designs], kvf=[d["kvf"] for d in designs],
            f_bw_hz=[d["f_bw"] for d in designs], f_d_hz=designs[0]["f_d"], J_design=[d["J"] for d in designs])
    else:
        ctl_info = dict(
            file=f"{name}_controller.json", type="cascade",
            structure="P position loop + PI velocity loop + velocity feedforward; v_est = first-order low-pass of "
                      "backward difference of qm; vr = backward difference of qr; e_v = Kp*(qr-qm) + kff*vr - v_est; "
                      "I[k] = I[k-1] + dt*e_v[k]; u = Kv*(e_v + I/Ti); force column = u",
            velocity_filter="v_est[k] = alpha*v_est[k-1] + (1-alpha)*(qm[k]-qm[k-1])/dt, alpha = exp(-2*pi*fc*dt)",
            tf_derivation="PI(z) = Kv*((1+dt/Ti) - z^-1)/(1 - z^-1); C_r = PI*(Kp + kff*(1-z^-1)/dt); "
                          "C_y = PI*(Kp + (1-alpha)(1-z^-1)/(dt(1-alpha z^-1)))",
            design="Kp = 2*pi*f_p; velocity-loop bandwidth wv = ratio*Kp; Kv = J*wv with J = diag(M_truth(q0)) + Ia; "
                   "Ti = 4/wv",
            Kp_per_s=[d["Kp"] for d in designs], Kv=[d["Kv"] for d in designs], Ti_s=[d["Ti"] for d in designs],
            kff=[d["kff"] for d in designs], velocity_filter_cutoff_hz=designs[0]["fc"], alpha=designs[0]["alpha"],
            f_p_hz=spec["cascade"]["f_p"], ratio=spec["cascade"]["ratio"], J_design=[d["J"] for d in designs])
    ctl_info.update(
        saturation=rel(sat), gravity_stiffness_at_q0=rel(kg), g_truth_at_q0=rel(g0),
        loop_check=dict(model="per joint: plant 1/(J s^2 + Fv s + k_g), k_g = d g_j/d q_j at q0, ZOH at dt, "
                              "u = -C_y(z) q (linear: no encoder, no Coulomb)", per_joint=checks),
        initial_state="At t=0 the robot is at rest at q = qr[0] (on the encoder grid, so qm[0] = qr[0]); force[0] = "
                      "g_truth(qr[0]) + offset (with the payload in the payload record). Replay: u = force[0] + "
                      "C_r(z)[qr - qr[0]] - C_y(z)[qm - qr[0]] with zero filter states.")
    excitation = dict(
        type="finite Fourier series per joint, 5 harmonics, base frequency f0; q(t) = q0 + s_j * sum_l a_l/(w l) "
             "sin(w l t) - b_l/(w l)(cos(w l t) - 1), w = 2 pi f0, sum_l a_l = 0 and sum_l l b_l = 0: starts and ends "
             "every period at rest",
        q0=rel(q0), position_limits=[rel(lo), rel(hi)],
        limit_margin="inside 10 % of the range from each limit; excursion from q0 capped at cap (None: limits only)",
        cap=spec["cap"], velocity_cap=rel(vcap), velocity_limit=rel(vlim),
        train=dict(f0_hz=tr["f0"], periods=tr["periods"], a=A_tr.tolist(), b=B_tr.tolist(), scale=rel(s_tr),
                   draws=tried, selection="min base-regressor condition number (500 samples over one period, "
                                          "unit-norm columns) among draws whose ideal torque stays < 50 % of "
                                          "saturation (also with the payload)", cond=cond_tr),
        valid=dict(f0_hz=va["f0"], periods=va["periods"], a=A_va.tolist(), b=B_va.tolist(), scale=rel(s_va),
                   selection="first draw of another random stream with ideal torque < 50 % of saturation",
                   cond=cond_va),
        payload="the train reference",
        base_columns=dict(count=int(len(base)), of=int(Wr.shape[1]),
                          columns="pin.computeJointTorqueRegressor (10 per link) + per joint Ia (qdd), Fv (v), "
                                  "Fc (s(v)), offset (1); base set by pivoted Gram-Schmidt on 300 random samples"))
    entry = dict(
        joint_names=names, joint_kinds=kinds, n_joints=n, dt=dt, sample_rate_hz=1 / dt, units=units,
        force_units=f_units, cad_urdf=cad_path.name, cad_source=spec["source"], gravity=rel(GRAVITY),
        dyn10_order=DYN10_ORDER, seed=seed,
        links_truth={nm: inertia_json(I) for nm, I in zip(names, truth_I)},
        links_cad={nm: inertia_json(cad.inertias[i]) for i, nm in enumerate(names, start=1)},
        Ia=rel(Ia), Fv=rel(Fv), Fc=rel(Fc), offset=rel(off),
        friction_law="tau_f = Fv*v + Fc*s(v) (+ offset, constant); plant: (M(q)+diag(Ia)) qdd = u + d - nle(q,v) - "
                     "tau_f - offset",
        friction_shape=law, friction_formula=FRICTION_FORMULA[law], vs=rel(eps),
        vs_text="eps per joint in that joint's units (rad/s or m/s); slope of s at 0 is 1/eps; eps = "
                "vs_fraction_of_train_top_speed * train_top_speed (the train reference's max |v|)",
        vs_fraction_of_train_top_speed=rel(eps_frac), train_top_speed=rel(v_top),
        noise_std=rel(noise_std), noise_pct_of_rms_torque=spec["noise_pct"],
        noise_model="white Gaussian torque/force d added to u inside the loop, held over each control sample; rms "
                    "torque = RMS of the ideal truth inverse-dynamics torque (incl. Ia, friction, offset) on the "
                    "train reference (500 samples of one period)",
        encoder_step=rel(steps), encoder_step_text="2*pi/2^18 rad (revolute), 1e-6 m (prismatic); "
                                                   "qm = round(q/step)*step",
        controller=ctl_info, excitation=excitation,
        payload=dict(mass=pl["mass"], com=rel(com), inertia_com=[rel(r) for r in Ip],
                     frame=f"joint frame of {names[-1]} (last joint); rigidly added to that link",
                     dyn10=rel(payload.toDynamicParameters()),
                     last_link_truth_with_payload=inertia_json(truth_I[-1] + payload)),
        integration=integ, records=recs, generation_seconds=time.perf_counter() - t_case)
    say(f"done in {entry['generation_seconds']:.0f} s")
    return entry


def _worker(args):
    name, out, check = args
    return name, run_case(name, pathlib.Path(out), check)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="/tmp/didim_heldout")
    ap.add_argument("--only", default="", help="comma-separated case names (default: all): " + ", ".join(CASES))
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="cases run in parallel")
    ap.add_argument("--no-substep-check", action="store_true", help="skip the 2x-substeps re-run of the train record")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = [x for x in args.only.split(",") if x] or list(CASES)
    for x in names:
        if x not in CASES:
            ap.error(f"unknown case {x}; cases: {', '.join(CASES)}")
    t0 = time.perf_counter()
    jobs = [(x, str(out), not args.no_substep_check) for x in names]
    # longest first so two workers finish together
    order = {"ur10_atan": 0, "panda_alg": 1, "arm2_tanh": 2, "rpr": 3, "panda_500": 4}
    jobs.sort(key=lambda j: order.get(j[0], 9))
    if args.jobs > 1 and len(jobs) > 1:
        with multiprocessing.get_context("fork").Pool(min(args.jobs, len(jobs))) as pool:
            results = dict(pool.map(_worker, jobs, chunksize=1))
    else:
        results = dict(_worker(j) for j in jobs)
    truth_path = out / "truth.json"
    old = json.loads(truth_path.read_text()) if truth_path.exists() else {}
    robots = old.get("robots", {})
    robots.update(results)
    robots = {k: robots[k] for k in CASES if k in robots}
    truth = {"generator": "benches/heldout_robots.py: an independent simulator (Pinocchio + numpy + own code; "
                          "does not use didim)",
             "pinocchio": pin.__version__, "example_robot_data": erd_version(), "numpy": np.__version__,
             "python": sys.version.split()[0],
             "units": "per joint: rad or m, rad/s or m/s, N*m or N; s, kg, m, kg*m^2 (Ia of a prismatic joint in kg, "
                      "Fv in N*s/m, Fc and offset in N)",
             "csv_columns": "t, qr_1..qr_n, force_1..force_n, qm_1..qm_n (positions and force written with 17 "
                            "significant digits)",
             "robots": robots}
    truth_path.write_text(json.dumps(truth, indent=1) + "\n")
    print(f"\nwrote {truth_path} ({len(robots)} cases) in {time.perf_counter() - t0:.0f} s")
    print("| case | record | samples | truth floor | per joint | replay mismatch (double) | "
          "substeps (2x check: force diff without / with encoder) |")
    for nm in names:
        e = results[nm]
        chk = e["integration"].get("check_2x_substeps")
        for rn, r in e["records"].items():
            print(f"| {nm} | {rn} | {r['samples']} | {r['truth_floor_total']:.4f} | "
                  f"{' '.join(f'{x:.4f}' for x in r['truth_floor_per_joint'])} | "
                  f"{r['tf_replay_max_rel_mismatch']:.1e} ({r['tf_replay_double_max_rel_mismatch']:.1e}) "
                  f"| {e['integration']['substeps']}"
                  + (f" ({chk['without_encoder']['force_rel_diff']:.1e} / "
                     f"{chk['with_encoder']['force_rel_diff']:.1e})" if chk else "") + " |")


if __name__ == "__main__":
    main()
