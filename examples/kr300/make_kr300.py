"""The KUKA KR300 R2500 ultra's real logs made usable by didim, and what the published model explains of them.

    python examples/kr300/make_kr300.py [--data ../shared/data/kr300] [--out examples/kr300]

Writes, into --out: ``kr300.urdf`` (from the published DH table, :mod:`kr300_model`), ``kr300_published.json``
(the drives' published parameters on the link side, SI), ``kr300_A.csv`` and ``kr300_B.csv`` (didim robot records:
``t, qr_1..6, force_1..6, qm_1..6, ql_1..3, ff_1..6``; rad and N·m on the link side, URDF joint angles) and
``kr300_findings.json`` (every number docs/kr300.md quotes, measured here). Needs scipy and didim; Pinocchio if
importable (a second reference for the URDF).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Dict

import numpy as np
import scipy.io

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import kr300_model as km  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "..", "shared", "data", "kr300")
#: The logs' joint angles are measured from the pose the trajectories start and end in; the published DH table's
#: angles are q = Q0 + logged angle (found from the authors' motor-side reference ref_dyn.phi_r_m = u·(phi_r + Q0)
#: and checked on their gravity torques, see ``sides``).
Q0 = np.array([0.0, -math.pi / 2, math.pi / 2, 0.0, 0.0, 0.0])
#: the tool of the .m file: troty(-90°)
TOOL = np.array([[0.0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]])


def rel(err, ref, axis=0):
    """Relative RMS ‖err‖/‖ref‖ (per column)."""
    return np.linalg.norm(err, axis=axis) / np.linalg.norm(ref, axis=axis)


def read(path: str) -> Dict[str, np.ndarray]:
    """One MAT file's structs (rec, para, ref_kin, tau_ff_all, the nominal model's tau_g_all/tau_g_init), arrays as
    (samples, axes), in SI on the link side, angles as the DH table's (Q0 added). The KR300 object is skipped."""
    m = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False,
                         variable_names=["rec", "para", "ref_kin", "ref_dyn", "tau_ff_all", "tau_g_all", "tau_g_init",
                                         "time_data"])
    r, p, k = m["rec"], m["para"], m["ref_kin"]
    d = np.deg2rad
    u = np.asarray(p.u, dtype=float)
    logged_t = np.asarray(r.time_cont, dtype=float)  # stored through float32: 10 s reads 9.99999975
    t = np.arange(len(logged_t)) * float(m["time_data"].dt)
    return {
        "t": t, "t_logged_max_dev": float(np.abs(logged_t - t).max()), "u": u, "para": p,
        "qr": d(r.ref_pos_deg.T) + Q0, "vr": d(r.ref_vel_simple_deg_per_s.T),
        "qm": d(r.act_pos_mot_deg.T) + Q0, "vm": d(r.act_vel_mot_deg_per_s.T),
        "ql": d(r.act_pos_se_deg.T[:, :3]) + Q0[:3], "vl": d(r.act_vel_se_deg_per_s.T[:, :3]),
        "tau_motor": r.act_torque_abs_nm.T.copy(), "tau_rel": r.act_torque_rel_nm.T.copy(),
        "err_pos": d(r.error_pos_deg.T), "err_vel": d(r.error_vel_deg_per_s.T),
        "q": k.phi_r_all + Q0, "v": k.phi_r_all_d1, "a": k.phi_r_all_d2,
        "phi_r_m": m["ref_dyn"].phi_r_m_all, "ff_motor": m["tau_ff_all"].T.copy(),
        "tau_g_nominal": m["tau_g_all"].T + m["tau_g_init"],
    }


def authors_friction(p, v, s_f) -> np.ndarray:
    """The authors' friction (nonlinear_differential_model.m), link side N·m: f_asym + f_vis·v + f_coul·tanh(s_f·v)
    + f_a·tanh(f_b·v)."""
    return p.f_asym + p.f_vis * v + p.f_coul * np.tanh(s_f * v) + p.f_a * np.tanh(p.f_b * v)


def published_torque(robot, d, links) -> Dict[str, np.ndarray]:
    """The published model's link-side torques along the reference (ref_kin's analytic derivatives): rigid body
    (rnea, 200 kg payload), rotor inertia Ia·a, the counterbalance on axis 2, and the authors' friction."""
    Ia = np.array([km.drive_link_side(L)["Ia"] for L in links])
    rb = robot.rnea(d["q"], d["v"], d["a"])
    cb = np.zeros_like(rb)
    cb[:, 1] = km.counterbalance(d["q"][:, 1])[0]
    return {"rb": rb, "Ia": Ia * d["a"], "cb": cb, "fr_ode": authors_friction(d["para"], d["v"], d["para"].s_f_ode),
            "fr_ff": authors_friction(d["para"], d["v"], d["para"].s_f_ff) - d["para"].f_asym}


# ------------------------------------------------------------------------------------------ the URDF and its checks

def write_model(out: str) -> Dict:
    links = km.kr300_dh()
    path = os.path.join(out, "kr300.urdf")
    with open(path, "w", encoding="utf-8") as f:
        f.write(km.dh_to_urdf("kuka_kr300_r2500_ultra", links, km.BASE, TOOL))
    drives = [km.drive_link_side(L) for L in links]
    return {"urdf": path, "links": links, "drives": drives}


def check_urdf(robot, links, path, n=200, seed=0) -> Dict:
    """didim's rnea on the URDF against the numpy Newton–Euler on the DH table (and Pinocchio's on the URDF):
    the largest relative error over random states (‖τ_didim − τ_ref‖∞ / ‖τ_ref‖∞ per state)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([L.qlim for L in links]).T
    q = rng.uniform(lo, hi, (n, 6))
    v, a = rng.uniform(-2, 2, (n, 6)), rng.uniform(-5, 5, (n, 6))
    tau = robot.rnea(q, v, a)
    ref = np.array([km.rnea_dh(links, *s) for s in zip(q, v, a)])
    out = {"states": n, "dh_newton_euler": float(np.max(np.abs(tau - ref).max(1) / np.abs(ref).max(1)))}
    g_ref = np.array([km.rnea_dh(links, s, np.zeros(6), np.zeros(6)) for s in q])
    out["dh_gravity"] = float(np.max(np.abs(robot.gravity(q) - g_ref).max(1) / np.abs(g_ref).max(1)))
    try:
        import pinocchio as pin
    except ImportError:
        out["pinocchio"] = None
        return out
    model = pin.buildModelFromUrdf(path)
    data = model.createData()
    tp = np.array([pin.rnea(model, data, *s) for s in zip(q, v, a)])
    out["pinocchio"] = float(np.max(np.abs(tau - tp).max(1) / np.abs(tp).max(1)))
    out["pinocchio_version"] = pin.__version__
    return out


# ------------------------------------------------------------------------------------------ units, sides, signs

def sides(d, pub, links) -> Dict:
    """What the logged signals are, checked on the data."""
    u = d["u"]
    T = d["tau_motor"]
    model = pub["rb"] + pub["Ia"] + pub["cb"]
    res = {}
    # torque: least squares of the logged torque on the model's link-side torque (with friction terms and a
    # constant): a motor-side torque has slope 1/u, one already times u slope 1
    slope = []
    for j in range(6):
        X = np.column_stack([model[:, j], d["v"][:, j], np.tanh(d["v"][:, j] / 0.01), np.ones(len(T))])
        c, *_ = np.linalg.lstsq(X, T[:, j], rcond=None)
        slope.append(c[0] * u[j])
    res["torque_slope_times_u"] = slope  # ≈ 1: motor side; ≈ u: link side
    res["time_stamps_max_dev_from_4ms_grid_s"] = d["t_logged_max_dev"]
    res["torque_abs_minus_rel"] = (T - d["tau_rel"]).mean(0).tolist()
    res["torque_abs_minus_rel_std"] = (T - d["tau_rel"]).std(0).tolist()
    # positions: the motor encoder divided by u (link side) vs the secondary encoder, and their ranges
    span = lambda x: x.max(0) - x.min(0)  # noqa: E731
    res["range_ratio_mot_over_se"] = (span(d["qm"][:, :3]) / span(d["ql"])).tolist()
    res["range_ratio_mot_over_ref"] = (span(d["qm"]) / span(d["qr"])).tolist()
    res["ref_minus_phi_r_m_over_u_rad"] = np.abs(d["phi_r_m"][:, :3] / u[:3] - d["qr"][:, :3]).max(0).tolist()
    res["err_pos_is_ref_minus_se_axes123"] = float(np.abs(d["err_pos"][:, :3] - (d["qr"][:, :3] - d["ql"])).max())
    res["err_pos_is_ref_minus_mot_axes456"] = float(np.abs(d["err_pos"][:, 3:] - (d["qr"][:, 3:] - d["qm"][:, 3:])).max())
    res["err_vel_all_zero"] = bool(np.all(d["err_vel"] == 0))
    res["tracking_rms_ref_minus_mot_rad"] = np.sqrt(((d["qr"] - d["qm"]) ** 2).mean(0)).tolist()
    # the authors' nominal gravity (tau_g_all + tau_g_init): the payload it implies (axis 3, linear in the payload
    # mass) and the counterbalance's sign (axis 2)
    g0 = np.array([km.rnea_dh(km.kr300_dh(0.0), q, np.zeros(6), np.zeros(6)) for q in d["q"][::25]])
    g1 = np.array([km.rnea_dh(km.kr300_dh(100.0), q, np.zeros(6), np.zeros(6)) for q in d["q"][::25]])
    tg = d["tau_g_nominal"][::25]
    p = float(np.linalg.lstsq(((g1 - g0) / 100.0)[:, 2:3], tg[:, 2] - g0[:, 2], rcond=None)[0][0])
    gp = g0 + (g1 - g0) * p / 100.0
    cb = km.counterbalance(d["q"][::25, 1])[0]
    res["nominal_payload_kg_from_axis3"] = p
    res["nominal_gravity_rel_err_axis3_5"] = rel(tg[:, [2, 4]] - gp[:, [2, 4]], tg[:, [2, 4]]).tolist()
    res["nominal_gravity_axis2_plus_cb_rel_err"] = float(rel(tg[:, 1] - (gp[:, 1] + cb), tg[:, 1]))
    res["nominal_gravity_axis2_minus_cb_rel_err"] = float(rel(tg[:, 1] - (gp[:, 1] - cb), tg[:, 1]))
    return res


# ------------------------------------------------------------------------------------------ what the model explains

def explained(d, pub) -> Dict:
    """The logged torque (link side: motor torque · u) against the published model along the reference, and the
    authors' feedforward tau_ff_all against the same model."""
    u = d["u"]
    T = d["tau_motor"] * u
    ff = d["ff_motor"] * u
    base = pub["rb"] + pub["Ia"] + pub["cb"]
    full = base + pub["fr_ode"]
    out = {"logged_vs_model_rel_rms": rel(T - full, T).tolist(),
           "logged_vs_model_no_friction_rel_rms": rel(T - base, T).tolist(),
           "logged_vs_model_no_cb_rel_rms": rel(T - full + pub["cb"], T).tolist()}
    # with the friction fitted to the log (Fv, Fc, offset per axis): how much the rigid body + Ia + cb explain
    fit, fr = [], []
    for j in range(6):
        v = d["v"][:, j]
        X = np.column_stack([v, np.tanh(v / 0.01), np.ones(len(v))])
        c, *_ = np.linalg.lstsq(X, T[:, j] - base[:, j], rcond=None)
        fit.append(float(rel(T[:, j] - base[:, j] - X @ c, T[:, j])))
        fr.append({"Fv": c[0], "Fc": c[1], "offset": c[2]})
    out["logged_vs_model_fitted_friction_rel_rms"] = fit
    out["friction_fitted_on_log"] = fr
    # tau_ff_all: zero at t = 0 (the torque relative to the start), so compared with the model minus its start value
    ff_model = base - base[0] + pub["fr_ff"]
    out["ff_at_t0"] = d["ff_motor"][0].tolist()
    out["ff_vs_model_minus_start_rel_rms"] = rel(ff - ff_model, ff).tolist()
    out["ff_vs_model_minus_start_no_friction_rel_rms"] = rel(ff - (base - base[0]), ff).tolist()
    out["logged_minus_start_vs_ff_rel_rms"] = rel((T - T[0]) - ff, T - T[0]).tolist()
    return out


# ------------------------------------------------------------------------------------------ the controller

def controller(d, fits: bool = True) -> Dict:
    """The authors' law tau_m = tau_ff + K_vel·(qr' − q') + K_pos·(qr − q) against the logged motor torque (motor
    side, errors in rad and rad/s, also in deg), and didim's linear-law fit u − ff = C_r(z)·qr − C_y(z)·q per axis
    (link side, qm the motor encoder or, on axes 1–3, the link encoder)."""
    from didim import fit_controller

    p = d["para"]
    T, ff = d["tau_motor"], d["ff_motor"]
    e = d["qr"] - d["qm"]
    ev = d["vr"] - d["vm"]
    out = {}
    for unit, k in (("rad", 1.0), ("deg", 180 / math.pi)):
        law = ff + p.K_vel * ev * k + p.K_pos * e * k
        out[f"authors_law_{unit}_rel_rms"] = rel(T - law, T).tolist()
        out[f"authors_law_{unit}_plus_constant_rel_rms"] = rel(T - law - (T - law).mean(0), T - T.mean(0)).tolist()
    free = []
    for j in range(6):
        X = np.column_stack([ff[:, j], e[:, j], ev[:, j], np.ones(len(T))])
        c, *_ = np.linalg.lstsq(X, T[:, j], rcond=None)
        free.append({"c_ff": c[0], "K_pos": c[1], "K_vel": c[2], "const": c[3],
                     "rel_rms": float(rel(T[:, j] - X @ c, T[:, j] - T[:, j].mean()))})
    out["authors_form_fitted"] = free
    if not fits:
        return out
    laws = {}
    u, dt = d["u"], float(d["t"][1] - d["t"][0])
    for label, with_ff in (("with_ff", True), ("without_ff", False)):
        for pos in ("motor", "link"):
            rows = []
            for j in range(6 if pos == "motor" else 3):
                q = d["qm"][:, j] if pos == "motor" else d["ql"][:, j]
                sig = dict(dt=dt, qr=d["qr"][:, j], qm=q, force=T[:, j] * u[j], name=f"axis {j + 1}")
                if with_ff:
                    sig["u_ext"] = ff[:, j] * u[j]
                f = fit_controller(sig, tolerance=math.inf)
                rows.append({"order": f.order, "delay": f.delay, "error": f.error, "heldout_error": f.heldout_error})
            laws[f"{label}_{pos}"] = rows
    out["linear_law_fit"] = laws
    return out


# ------------------------------------------------------------------------------------------ deflection

def deflection(d, pub) -> Dict:
    """Motor minus link position on axes 1–3 and the stiffness it implies: least squares of the deflection on the
    published model's link-side torque (rigid body + counterbalance along the reference) and a constant (the
    encoders' zeros), then with the link speed too (a time skew between the two encoders reads as speed · skew)."""
    defl = d["qm"][:, :3] - d["ql"]
    out = {"rms_rad": np.sqrt((defl ** 2).mean(0)).tolist(), "std_rad": defl.std(0).tolist(),
           "mean_rad": defl.mean(0).tolist(), "max_abs_rad": np.abs(defl).max(0).tolist(),
           "c_rad_published": list(map(float, d["para"].c_rad_ode[:3])), "q_back_published": float(d["para"].q_back[0])}
    tau = (pub["rb"] + pub["cb"])[:, :3]
    one = np.ones(len(tau))
    for name, cols in (("torque", lambda j: [tau[:, j]]), ("speed", lambda j: [d["v"][:, j]]),
                       ("torque_speed", lambda j: [tau[:, j], d["v"][:, j]])):
        fit = []
        for j in range(3):
            X = np.column_stack(cols(j) + [one])
            c, *_ = np.linalg.lstsq(X, defl[:, j], rcond=None)
            r = {"unexplained": float(rel(defl[:, j] - X @ c, defl[:, j] - defl[:, j].mean()))}
            if "torque" in name:
                r["K"] = float(1.0 / c[0])
            if "speed" in name:
                r["skew_s"] = float(c[-2])
            fit.append(r)
        out[f"fit_{name}"] = fit
    pred = tau / d["para"].c_rad_ode[:3]  # what the published stiffness predicts
    out["published_c_rad_predicts_std_rad"] = pred.std(0).tolist()
    return out


# ------------------------------------------------------------------------------------------ the records

def write_record(path: str, d) -> None:
    """t, qr_1..6, force_1..6 (motor torque · u), qm_1..6 (motor encoder / u), ql_1..3 (link encoders), ff_1..6
    (tau_ff_all · u): rad, N·m, link side, URDF joint angles."""
    force, ff = d["tau_motor"] * d["u"], d["ff_motor"] * d["u"]
    cols = [("t", d["t"][:, None])] + [(k, x) for k, x in (("qr", d["qr"]), ("force", force), ("qm", d["qm"]),
                                                           ("ql", d["ql"]), ("ff", ff))]
    names = ["t"] + [f"{k}_{j + 1}" for k, x in cols[1:] for j in range(x.shape[1])]
    data = np.column_stack([x for _, x in cols])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.12g")


def main(data: str = DATA, out: str = HERE, quiet: bool = False, controller_fits: bool = True) -> Dict:
    """Everything above; ``controller_fits=False`` skips the linear-law fits (2 minutes on 2 cores)."""
    import didim

    os.makedirs(out, exist_ok=True)
    made = write_model(out)
    links = made["links"]
    robot = didim.Robot.from_urdf(made["urdf"])
    findings: Dict = {"urdf_check": check_urdf(robot, links, made["urdf"])}
    recs = {n: read(os.path.join(data, f"kr300_{n}.mat")) for n in "AB"}
    para = recs["A"]["para"]
    published = {"source": "model_KUKA_Quantec_Ultra_KR300.m and para of kr300_A.mat (Weigand et al., MIT)",
                 "joints": robot.joint_names, "q0_log_to_dh_rad": Q0.tolist(),
                 "drives_link_side": made["drives"],
                 "authors": {k: np.atleast_1d(getattr(para, k)).tolist() for k in
                             ("u", "J_mr", "k_T", "K_pos", "K_vel", "c_rad_ode", "q_back", "f_vis", "f_coul",
                              "f_asym", "f_a", "f_b", "s_f_ode", "s_f_ff")},
                 "authors_J_mr_times_u2": (para.J_mr * para.u ** 2).tolist(),
                 "units": "Ia kg·m², Fv N·m·s/rad, Fc N·m, c_rad N·m/rad, f_* N·m and N·m·s/rad on the link side"}
    with open(os.path.join(out, "kr300_published.json"), "w", encoding="utf-8") as f:
        json.dump(published, f, indent=1)
    for n, d in recs.items():
        pub = published_torque(robot, d, links)
        findings[n] = {"sides": sides(d, pub, links), "explained": explained(d, pub), "controller": controller(d, controller_fits),
                       "deflection": deflection(d, pub),
                       "qr_within_qlim": bool(np.all((d["qr"] >= np.array([L.qlim[0] for L in links]))
                                                     & (d["qr"] <= np.array([L.qlim[1] for L in links]))))}
        write_record(os.path.join(out, f"kr300_{n}.csv"), d)
    with open(os.path.join(out, "kr300_findings.json"), "w", encoding="utf-8") as f:
        json.dump(findings, f, indent=1, default=float)
    if not quiet:
        print(json.dumps(findings, indent=1, default=lambda x: round(float(x), 6)))
    return findings


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=DATA, help="the folder of kr300_A.mat and kr300_B.mat")
    ap.add_argument("--out", default=HERE, help="where to write the URDF, the records and the findings")
    a = ap.parse_args()
    main(a.data, a.out)
