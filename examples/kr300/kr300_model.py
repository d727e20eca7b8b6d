"""The published model of the KUKA KR300 R2500 ultra (Weigand et al., ``model_KUKA_Quantec_Ultra_KR300.m``, MIT):
its standard Denavit–Hartenberg table as Peter Corke's Robotics Toolbox reads it, a DH table → URDF conversion, an
independent recursive Newton–Euler on the DH table (numpy), and the hydraulic counterbalance of axis 2
(``hydraulic_weight_counterbalance.m``). SI units, link side: rad, m, kg, kg·m², N·m.

RTB's ``Link('revolute', 'd', d, 'a', a, 'alpha', alpha, ...)`` without ``'modified'`` is standard DH: link i's
frame is T_{i-1} · Rz(q_i + offset_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i), joint i turns about z_{i-1}, and link i's
centre of mass ``r`` and inertia ``I`` (about the centre of mass) are given in frame i. The robot's base is
``trotx(180°)`` (the DH chain hangs from a frame turned upside down), gravity is −9.81 m/s² along the world's z.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np

DEG = math.pi / 180.0

#: The payload as the authors put it (the .m file, link 6): axis 6's own 17.78 kg at −50 mm and the 200 kg
#: payload at +100 mm along z of DH frame 6, lumped into one point mass (no inertia tensor: RTB's default zero).
M_AXIS6, R_AXIS6, M_PAYLOAD, R_PAYLOAD = 17.78, -0.050, 200.0, 0.100


@dataclass(frozen=True)
class DHLink:
    """One row of a standard DH table with its body: d, a (m), alpha, offset (rad), mass m (kg), centre of mass r
    (m, in the link's DH frame), inertia I = (Ixx, Iyy, Izz, Ixy, Iyz, Ixz) about the centre of mass (kg·m², DH frame
    axes, RTB's order), joint limits qlim (rad), and the drive: motor inertia Jm (kg·m², motor side), gear ratio G,
    viscous friction B and Coulomb friction Tc as the .m file gives them (see :func:`drive_link_side`)."""

    d: float
    a: float
    alpha: float
    offset: float
    m: float
    r: Tuple[float, float, float]
    I: Tuple[float, float, float, float, float, float]
    qlim: Tuple[float, float]
    Jm: float
    G: float
    B: float
    Tc: float


def _link6_mass_and_com(m_payload: float = M_PAYLOAD) -> Tuple[float, float]:
    m = m_payload + M_AXIS6
    return m, (m_payload * R_PAYLOAD + M_AXIS6 * R_AXIS6) / m


def kr300_dh(m_payload: float = M_PAYLOAD) -> List[DHLink]:
    """The .m file's six links, transcribed (1e-6 kg·m² and mm converted to SI)."""
    m6, z6 = _link6_mass_and_com(m_payload)
    e6, mm = 1e-6, 1e-3
    return [
        DHLink(-0.675, 0.350, math.pi / 2, 0.0, 395.40, (-353 * mm, 174 * mm, -4 * mm),
               tuple(x * e6 for x in (16733765, 29799119, 32814954, -1703664, 129384, 4404062)),
               (-147 * DEG, 147 * DEG), 0.00923, 1798 / 7, 0.001476346, 0.73192436),
        DHLink(-0.189, 1.15, 0.0, 0.0, 339.12, (-709 * mm, -1 * mm, 23 * mm),
               tuple(x * e6 for x in (7507819, 88886691, 88673761, 430046, 173157, -4396607)),
               (-140 * DEG, -5 * DEG), 0.0118, 1872 / 7, 0.010681832, 1.832264957),
        DHLink(0.189, 0.041, -math.pi / 2, 90 * DEG, 105.21, (-18 * mm, -18 * mm, -76 * mm),
               tuple(x * e6 for x in (10783798, 10186135, 1943179, 118474, -606384, -101950)),
               (-112 * DEG, 153 * DEG), 0.0118, 757 / 3, 0.08398663, 1.862615588),
        DHLink(-1.0, 0.0, math.pi / 2, 0.0, 35.80, (0.0, 236 * mm, 1 * mm),
               tuple(x * e6 for x in (425035, 217993, 428465, -4, -11353, -27)),
               (-350 * DEG, 350 * DEG), 0.00173, 221.0, 0.001916077, 0.447963801),
        DHLink(0.0, 0.0, -math.pi / 2, 0.0, 31.46, (0.0, -80 * mm, -9 * mm),
               tuple(x * e6 for x in (283826, 229562, 258266, -4, -19521, -120)),
               (-122.5 * DEG, 122.5 * DEG), 0.00173, 5032 / 21, 0.001629877, 0.413155803),
        DHLink(-0.24, 0.0, math.pi, 0.0, m6, (0.0, 0.0, z6), (0.0,) * 6,
               (-350 * DEG, 350 * DEG), 0.00173, 206793 / 1340, 0.002205322, 0.372594817),
    ]


#: The base transform of the .m file's SerialLink: trotx(180°).
BASE = np.diag([1.0, -1.0, -1.0, 1.0])


def drive_link_side(link: DHLink) -> dict:
    """The drive's published parameters on the link side (SI): rotor inertia Ia = Jm·G² (kg·m²), and the friction as
    the .m file's comments define it ("B: actual value/G²", "Tc: actual value/G"): Fv = B·G² (N·m·s/rad), Fc = Tc·G
    (N·m)."""
    g = link.G
    return {"G": g, "Jm": link.Jm, "Ia": link.Jm * g * g, "B": link.B, "Fv": link.B * g * g, "Tc": link.Tc,
            "Fc": link.Tc * g}


# ------------------------------------------------------------------------------------------ DH table → URDF

def rot_x(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_z(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rpy(R: np.ndarray) -> Tuple[float, float, float]:
    """URDF's roll, pitch, yaw of a rotation matrix (R = Rz(yaw) · Ry(pitch) · Rx(roll))."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(pitch)) < 1e-12:  # gimbal lock: put it all in yaw
        return 0.0, pitch, math.atan2(-R[0, 1], R[1, 1])
    return math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])


def _f(x: float) -> str:
    return "0" if x == 0 else f"{x:.12g}"


def _origin(p, R) -> str:
    p = [0.0 if abs(v) < 1e-15 else float(v) for v in p]
    r = [0.0 if abs(v) < 1e-15 else v for v in rpy(R)]
    return f'<origin xyz="{" ".join(map(_f, p))}" rpy="{" ".join(map(_f, r))}"/>'


def dh_to_urdf(name: str, links: Sequence[DHLink], base: np.ndarray = np.eye(4), tool: Optional[np.ndarray] = None,
               effort: Optional[Sequence[float]] = None, velocity: Optional[Sequence[float]] = None) -> str:
    """A URDF of a standard DH chain. URDF link i's frame is DH frame i−1 turned by the joint: Rz(q_i + offset_i).
    So joint i's origin is the fixed part of the previous row, Tz(d_{i−1})·Tx(a_{i−1})·Rx(alpha_{i−1}) (the base
    for i = 1), times Rz(offset_i): the URDF's joint angle is the DH table's q. Link i's body, given in DH frame i =
    (its URDF frame)·Tz(d_i)·Tx(a_i)·Rx(alpha_i), sits at (a_i, 0, d_i) + Rx(alpha_i)·r_i with its inertia axes
    turned by Rx(alpha_i). A fixed joint to ``flange`` (DH frame n) and, if given, to ``tool``."""
    out = [f'<?xml version="1.0"?>', f'<robot name="{name}">', '  <link name="base_link"/>']
    prev_p, prev_R, parent = base[:3, 3], base[:3, :3], "base_link"
    for i, L in enumerate(links, start=1):
        ixx, iyy, izz, ixy, iyz, ixz = L.I
        lim = f'lower="{_f(L.qlim[0])}" upper="{_f(L.qlim[1])}"'
        lim += f' effort="{_f(effort[i - 1])}"' if effort is not None else ' effort="0"'
        lim += f' velocity="{_f(velocity[i - 1])}"' if velocity is not None else ' velocity="0"'
        com = np.array([L.a, 0.0, L.d]) + rot_x(L.alpha) @ np.array(L.r)
        out += [f'  <joint name="joint_{i}" type="revolute">',
                f'    <parent link="{parent}"/>', f'    <child link="link_{i}"/>',
                f'    {_origin(prev_p, prev_R @ rot_z(L.offset))}', '    <axis xyz="0 0 1"/>',
                f'    <limit {lim}/>', '  </joint>',
                f'  <link name="link_{i}">', '    <inertial>', f'      {_origin(com, rot_x(L.alpha))}',
                f'      <mass value="{_f(L.m)}"/>',
                f'      <inertia ixx="{_f(ixx)}" ixy="{_f(ixy)}" ixz="{_f(ixz)}" iyy="{_f(iyy)}" iyz="{_f(iyz)}" '
                f'izz="{_f(izz)}"/>', '    </inertial>', '  </link>']
        prev_p, prev_R, parent = np.array([L.a, 0.0, L.d]), rot_x(L.alpha), f"link_{i}"
    out += ['  <joint name="flange_joint" type="fixed">', f'    <parent link="{parent}"/>',
            '    <child link="flange"/>', f'    {_origin(prev_p, prev_R)}', '  </joint>', '  <link name="flange"/>']
    if tool is not None:
        out += ['  <joint name="tool_joint" type="fixed">', '    <parent link="flange"/>', '    <child link="tool"/>',
                f'    {_origin(tool[:3, 3], tool[:3, :3])}', '  </joint>', '  <link name="tool"/>']
    return "\n".join(out + ["</robot>", ""])


# ------------------------------------------------------------------------------------------ Newton–Euler on the DH table

def _inertia(L: DHLink) -> np.ndarray:
    ixx, iyy, izz, ixy, iyz, ixz = L.I
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def rnea_dh(links: Sequence[DHLink], q, v, a, base: np.ndarray = BASE, g: float = 9.81) -> np.ndarray:
    """Joint torques M(q)a + C(q, v)v + g(q) of the DH chain, by the recursive Newton–Euler algorithm in world
    coordinates straight from the DH table (no URDF, no other library): an independent reference for the URDF.
    Gravity −g along the world's z. One state (n,) → (n,)."""
    n = len(links)
    R, p = base[:3, :3].copy(), base[:3, 3].copy()
    w, wd, acc = np.zeros(3), np.zeros(3), np.array([0.0, 0.0, g])  # the base accelerates up: gravity
    z_prev, p_prev, frames = [], [], []
    for i, L in enumerate(links):
        z = R[:, 2].copy()
        wd = wd + z * a[i] + np.cross(w, z * v[i])
        w = w + z * v[i]
        Ri = R @ rot_z(q[i] + L.offset) @ rot_x(L.alpha)
        pi = p + R @ rot_z(q[i] + L.offset) @ np.array([L.a, 0.0, L.d])
        dp = pi - p
        acc = acc + np.cross(wd, dp) + np.cross(w, np.cross(w, dp))  # origin i's acceleration
        c = Ri @ np.array(L.r)
        ac = acc + np.cross(wd, c) + np.cross(w, np.cross(w, c))
        Iw = Ri @ _inertia(L) @ Ri.T
        frames.append((L.m * ac, Iw @ wd + np.cross(w, Iw @ w), pi + c, pi))
        z_prev.append(z)
        p_prev.append(p)
        R, p = Ri, pi
    tau = np.zeros(n)
    f_next, n_next, p_next = np.zeros(3), np.zeros(3), None
    for i in reversed(range(n)):
        F, N, c, pi = frames[i]
        o = p_prev[i]  # moments about the joint axis' point
        mom = N + np.cross(c - o, F) + n_next + np.cross(pi - o, f_next)
        f_next, n_next = F + f_next, mom
        tau[i] = z_prev[i] @ mom
    return tau


# ------------------------------------------------------------------------------------------ hydraulic counterbalance

def counterbalance(q2):
    """The torque (N·m, link side) of the hydraulic weight counterbalance on axis 2 at DH angle q2 (rad), as
    ``hydraulic_weight_counterbalance.m`` computes it (its comment says the angle is in deg, but it adds 95·π/180 to
    it: it is in rad). Returns (tau, pressure in Pa)."""
    D, k = 0.8, 0.2
    l0 = D - k
    area = math.pi * (0.055 ** 2 - 0.030 ** 2) / 4
    z, r_n2, temp, m_n2, v_max = 1.01, 296.8, 328.0, 2 * 0.0795, 2 * 0.00048
    delta = np.asarray(q2, dtype=float) + 95 * DEG
    dl = np.sqrt(D * D + k * k - 2 * D * k * np.cos(delta)) - l0
    h = np.sin(delta) * D * k / (dl + l0)
    press = z * r_n2 * temp * m_n2 / (v_max - dl * area)
    return h * press * area, press
