"""Identification of a robot's dynamics from its record: the base parameters of its rigid bodies (with each joint's
rotor inertia), each joint's viscous and Coulomb friction (and offset), by IDIM-LS on the measured positions or by
DIDIM on the closed loop simulated with the current estimate, weighted per joint.

Base parameters (Gautier's numerical method): the inverse-dynamics regressor of the rotor inertias and the bodies'
standard parameters at random states, its columns scaled to unit norm and taken in order (rotor inertias first, then
the bodies from the base out), is reduced by QR: a column whose diagonal of R is negligible against the largest is a
combination of the columns before it and is regrouped into them. The base parameters are the independent ones plus
those combinations, β = K·π; their names say what each combines."""

from __future__ import annotations

import copy
import math
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .._parallel import serial_blas
from .. import _checks, _core
from . import friction_law
from .didim_loop import didim_loop, residual_settled
from .identification import RIGID_LIMIT_MARGIN, start_notes
from ..stats import diebold_mariano
from .._errors import DataError, IdentifiabilityError, SimulationError
from ..result import IdentificationResult, iterations_of, robot_result
from ..robots.chain import BaseParameters, Robot
from ..model import Model, Term
from ..recording import Recording

#: A regressor column is independent when its R diagonal, after the columns are scaled to unit norm, is above this
#: share of the largest. Exact combinations cancel to rounding (~1e-15); URDFs print their angles and lengths to 4–6
#: digits, and a combination their rounding breaks stays within that of the others' span (the xArm7's 1.5708 for
#: π/2: 4.7e-6), a direction no torque record can see; the weakest independent column of the 24 arms of
#: example-robot-data is 0.5.
BASE_RANK_TOL = 1e-4

#: A regressor column whose norm is below this share of the largest is zero (rounding, 1e-15 of the terms summed).
ZERO_COLUMN = 1e-10

#: Coefficients of a regrouping below this share of the largest are rounding.
COEF_TOL = 1e-9

#: Rows where a joint moves slower than this share of its top speed are left out of its least squares: there the
#: friction's shape through zero speed (unknown, and not the model's) sets the force.
SLOW_SHARE = 0.05

#: The friction law of the simulated loop: algebraic, each joint's smoothing speed this share of its speed scale (its
#: shape only matters in the rows left out).
EPS_SHARE = 0.01


def _standard_names(robot: Robot) -> List[str]:
    return [f"Ia_{j}" for j in robot.joint_names] + robot.param_names


def _full_regressor(robot: Robot, q, v, a) -> np.ndarray:
    """Rows (N·n) × columns (rotor inertias, then the bodies' parameters)."""
    y = robot.regressor(q, v, a)  # (N, n, 10 n)
    n = robot.ndof
    arm = np.zeros((len(q), n, n))
    idx = np.arange(n)
    arm[:, idx, idx] = a
    return np.concatenate([arm, y], axis=2).reshape(len(q) * n, -1)


def random_states(robot: Robot, samples: int, seed: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions within the joint limits (a turn either way for unlimited joints), speeds and accelerations of unit
    spread: the states at which the regressor's column structure (which parameters it can tell apart) is read."""
    rng = np.random.default_rng(seed)
    n = robot.ndof
    lim = np.array([lt[:2] for lt in robot.limits], dtype=float)
    lo = np.where(np.isfinite(lim[:, 0]), lim[:, 0], -math.pi)
    hi = np.where(np.isfinite(lim[:, 1]), lim[:, 1], math.pi)
    q = rng.uniform(lo, hi, (samples, n))
    return q, rng.normal(size=(samples, n)), rng.normal(size=(samples, n))


def base_parameters(robot: Robot, samples: int = 400, seed: int = 0, elastic: Tuple[int, ...] = ()) -> BaseParameters:
    """The base parameters of ``robot`` from its regressor at ``samples`` random states (positions within the joint
    limits, or a turn for unlimited joints; speeds and accelerations of unit spread). ``elastic``: the joints whose
    rotor is a body of its own (its inertia acts on its motor side's rows, a parameter of its own, not the chain's)."""
    q, v, a = random_states(robot, samples, seed)
    with np.errstate(all="ignore"):
        w = _full_regressor(robot, q, v, a)
        if elastic:
            w.reshape(samples, robot.ndof, -1)[:, :, list(elastic)] = 0.0
        norms = np.linalg.norm(w, axis=0)
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(norms)) and norms.max() > 0):
        raise DataError(f"robot {robot.name}: its regressor overflows or vanishes at ordinary speeds: a length, mass or "
                        "inertia of its URDF is far out of scale (1e200 m?); check the URDF's numbers")
    # a column that is zero but for the rounding of the regressor's sums (the xArm7's mz of its second body: 7e-15
    # against 1e2) would be scaled to a unit column of noise and taken for independent
    alive = norms > ZERO_COLUMN * norms.max()
    ws = w[:, alive] / norms[alive]
    r = np.linalg.qr(ws, mode="r")
    d = np.abs(np.diag(r))
    keep_local = d > BASE_RANK_TOL * d.max()
    cols = np.flatnonzero(alive)
    ind, dep = cols[keep_local], cols[~keep_local]
    names = _standard_names(robot)
    p = w.shape[1]
    # dependent columns as combinations of the independent ones: W_dep = W_ind · C
    c, *_ = np.linalg.lstsq(w[:, ind], w[:, dep], rcond=None)
    k = np.zeros((len(ind), p))
    k[np.arange(len(ind)), ind] = 1.0
    for jj, col in enumerate(dep):
        k[:, col] = c[:, jj]
    k[np.abs(k) < COEF_TOL * np.max(np.abs(k), axis=1, keepdims=True)] = 0.0
    base_names = []
    for i, col in enumerate(ind):
        parts = [names[col]] + [f"{k[i, j]:+.4g}*{names[j]}" if abs(k[i, j] - 1) > 1e-9 else f"+{names[j]}"
                                for j in dep if k[i, j] != 0.0]
        base_names.append(" ".join(parts) if len(parts) > 1 else parts[0])
    return BaseParameters(tuple(names), tuple(base_names), k, tuple(int(x) for x in ind))


def elastic_of(model: Model) -> Tuple[int, ...]:
    """The indices of a robot model's elastic joints, in the robot's order."""
    return tuple(model.robot.joint_names.index(j) for j in model.elastic)


def joint_terms(model: Model) -> Tuple[Tuple[int, Term], ...]:
    """A robot model's extra terms, each with the index of the joint it acts on."""
    names = model.robot.joint_names
    return tuple((names.index(t.dof), t) for t in model.terms)


def theta_of(res: IdentificationResult) -> np.ndarray:
    """A robot result's parameter vector θ (:class:`_Layout`): the base parameters, the elastic joints' rotor
    inertias, each joint's viscous and Coulomb friction (and offset), the elastic joints' stiffness and damping, the
    joints' extra terms."""
    return np.array([res.params[k] for k in _theta_names(res.structure, res.base)])


def drives_of(res: IdentificationResult) -> Dict[str, List[float]]:
    """A robot result's drives: each joint's rotor inertia, viscous and Coulomb friction and offset (and, with an
    elastic joint, each joint's stiffness, infinite on rigid joints, and damping; with extra terms, each joint's)."""
    return _model_of(res.structure, res.base, theta_of(res))[1]


def chain_of(res: IdentificationResult) -> Robot:
    """The robot with a result's identified bodies (the standard parameters closest to the URDF's that give its base
    parameters)."""
    return _model_of(res.structure, res.base, theta_of(res))[0]


def joint_regressors(res: IdentificationResult, sim: Dict[str, np.ndarray]) -> List[np.ndarray]:
    """Each joint's columns of a result's inverse model on the simulated states ``sim``, at the full rate on every
    sample (N × k per joint: the columns that act on its rows; an elastic joint's motor side's), the Coulomb and extra
    terms' under the result's law: what the force the model explains is a combination of, joint by joint. An elastic
    joint's motor rows are those DIDIM fits (:func:`_model_columns` with ``substitute``): its rotor, friction and
    offset with its link's columns at the simulated link states, so that what a refit of the model can take is the
    same on an elastic joint as on a rigid one (its link's gravity, for a spring or counterbalance on it). The
    parameters the result holds (its ``frozen``: published bodies, say) are no columns: a refit cannot move them, so
    what they would explain is left for an effect to take (on the KR300 with its published bodies held, joint 2's
    counterbalance is its link's gravity sinusoid, which the held bodies cannot take)."""
    model, base = res.structure, res.base
    law = res.law if res.law is not None else ("algebraic", (0.0,) * model.robot.ndof)
    motor = _Motor.of(sim, elastic_of(model), model.gaps)
    cols, _ = _model_columns(model.robot, base, sim["q"], sim["qd"], sim["qdd"], _Layout.for_model(model, base), motor,
                             substitute=True)
    held = set(_held(model, base, frozen_for(model, res.frozen)))
    if held:
        cols = [(act, m[:, [k not in held for k in act]]) for act, m in cols]
    v = sim["qd"] if motor is None else motor.friction_speeds(sim["qd"])
    x = sim["q"] if motor is None else motor.friction_positions(sim["q"])
    terms = joint_terms(model)
    load = chain_of(res).rnea(sim["q"], sim["qd"], sim["qdd"]) if model.load_friction else None
    out = []
    for j, (_, m) in enumerate(cols):
        extra = [m, _sign(v[:, j], law[0], law[1][j])[:, None]]
        if model.robot.joint_names[j] in model.load_friction:
            extra.append((_sign(v[:, j], law[0], law[1][j]) * np.abs(load[:, j]))[:, None])
        mine = [t for jt, t in terms if jt == j]
        if mine:
            extra.append(term_columns(mine, x[:, j], v[:, j], law[0], law[1][j]))
        out.append(np.column_stack(extra))
    return out


def standard_of(res: IdentificationResult) -> np.ndarray:
    """Standard parameters (rotor inertias, bodies) with a robot result's base parameters, closest to the URDF's."""
    anchor = np.concatenate([np.zeros(res.robot.ndof), res.robot.inertial_params])
    beta = np.array([res.params[b] for b in res.base.names])
    return res.base.standard_from(beta, anchor)


@dataclass(frozen=True)
class _Layout:
    """Where each parameter sits in a robot's θ: the ``nb`` base parameters of the chain (with the rigid joints'
    rotor inertias), the elastic joints' rotor inertias, each of the ``n`` joints' Fv, Fc (and OF), the elastic
    joints' stiffness K and damping D, then the joints' extra terms (``terms``: the joint of each), then the
    load-dependent friction μ of the joints ``load``. Without elastic joints, terms nor load friction: the base
    parameters, Fv, Fc (and OF)."""

    nb: int
    n: int
    elastic: Tuple[int, ...]
    offset: bool
    terms: Tuple[int, ...] = ()
    load: Tuple[int, ...] = ()

    @classmethod
    def for_model(cls, model: Model, base: BaseParameters) -> "_Layout":
        """The layout of a robot model's θ on the base parameters ``base``."""
        names = model.robot.joint_names
        return cls(len(base.names), model.robot.ndof, elastic_of(model), model.offset,
                   tuple(j for j, _ in joint_terms(model)), tuple(names.index(j) for j in model.load_friction))

    @property
    def ne(self) -> int:
        return len(self.elastic)

    def ia(self, e: int) -> int:
        return self.nb + e

    def fv(self, j: int) -> int:
        return self.nb + self.ne + j

    def fc(self, j: int) -> int:
        return self.nb + self.ne + self.n + j

    def of(self, j: int) -> int:
        return self.nb + self.ne + 2 * self.n + j

    def k(self, e: int) -> int:
        return self.nb + self.ne + (3 if self.offset else 2) * self.n + e

    def d(self, e: int) -> int:
        return self.k(e) + self.ne

    def t(self, i: int) -> int:
        return (self.d(0) + self.ne if self.ne else self.k(0)) + i

    def fl(self, i: int) -> int:
        return self.t(len(self.terms)) + i

    @property
    def size(self) -> int:
        return self.fl(len(self.load))


def _theta_names(model: Model, base: BaseParameters) -> List[str]:
    joints, elastic = model.robot.joint_names, elastic_of(model)
    names = list(base.names) + [f"Ia_{joints[j]}" for j in elastic]
    names += [f"Fv_{j}" for j in joints] + [f"Fc_{j}" for j in joints]
    if model.offset:
        names += [f"OF_{j}" for j in joints]
    return (names + [f"{p}_{joints[j]}" for p in ("K", "D") for j in elastic] + [t.name for t in model.terms]
            + [f"Fl_{j}" for j in model.load_friction])


def term_columns(terms, x: np.ndarray, xd: np.ndarray, shape: str, eps: float) -> np.ndarray:
    """The basis functions of one joint's extra terms (:class:`didim.Term`) at its positions ``x`` and speeds ``xd``
    under its friction law (``shape``, ``eps``): the one-axis model's own (the core's), one column per term."""
    from ..model import _core_model, _freeze

    core = _core_model("rigid", False, tuple(_freeze(t.axis_spec()) for t in terms), None, float(eps), shape)
    x = np.ascontiguousarray(x, dtype=float)[None, :]
    w = core.regressor(x, np.ascontiguousarray(xd, dtype=float)[None, :], np.zeros_like(x))
    return np.asarray(w[0, :, 3:])


#: A friction law through zero speed (:data:`didim.methods.friction_law.Law`): its shape, shared by the joints, and each
#: joint's smoothing speed ε in the joint's units (rad/s or m/s: a prismatic quill and a revolute shoulder have no
#: common speed); ε = 0 is the hard sign.
Law = friction_law.Law


def _sign(v: np.ndarray, shape: str, eps: float) -> np.ndarray:
    """One joint's friction law at the speeds ``v``."""
    if eps <= 0:
        return np.sign(v)
    return _core.coulomb_sign(np.ascontiguousarray(v, dtype=float).ravel(), eps, shape).reshape(np.shape(v))


def _coulomb(v: np.ndarray, law: Law) -> np.ndarray:
    """The law at the speeds ``v`` (samples × joints), each joint's column with its own ε."""
    return np.column_stack([_sign(v[:, j], law[0], e) for j, e in enumerate(law[1])])


def _model_regressor(model: Model, base: BaseParameters, q, v, a, law: Law) -> np.ndarray:
    """(N, n, p): the base parameters' columns, then each joint's friction (and offset) and extra terms on its own
    row, written into one array (the dependent columns are combinations of the independent ones: W·π =
    W[:, independent]·β); a rigid model's."""
    robot, offset, lay = model.robot, model.offset, _Layout.for_model(model, base)
    n, nb = robot.ndof, len(base.independent)
    out = np.zeros((len(q), n, lay.size))
    ind = np.asarray(base.independent)
    arm, body = ind[ind < n], ind[ind >= n]  # rotor inertias' columns, then the bodies'
    pos = np.arange(nb)
    # the independent columns are sorted, the rotor inertias' first: the bodies' fill one slice (the core writes
    # only those of the (N, n, 10 n) regressor)
    out[:, :, len(arm):nb] = robot.regressor(q, v, a, columns=body - n)
    idx = np.arange(n)
    for k, col in zip(pos[:len(arm)], arm):
        out[:, col, k] = a[:, col]  # a rotor inertia acts on its own joint's row, times its acceleration
    out[:, idx, nb + idx] = v
    out[:, idx, nb + n + idx] = _coulomb(v, law)
    if offset:
        out[:, idx, nb + 2 * n + idx] = 1.0
    for i, (j, t) in enumerate(joint_terms(model)):
        out[:, j, lay.t(i)] = term_columns([t], q[:, j], v[:, j], law[0], law[1][j])[:, 0]
    return out


def _decimation(rec: Recording, cutoff_hz: Optional[float] = None):
    """The parallel decimation of a robot record: a zero-phase low-pass at ten times the reference's bandwidth (the
    frequency below which 99.9 % of its motion's power lies), within a tenth of the sample rate; or at ``cutoff_hz``
    when given (lower only: within the default)."""
    from ..signal import Decimation

    fs = 1 / rec.dt
    if cutoff_hz is not None:
        default = _decimation(rec)
        cutoff_hz = _checks.real("cutoff_hz", cutoff_hz, "Hz", lo=0.0)
        return default if cutoff_hz >= default.cutoff_hz else Decimation.lowpass(cutoff_hz, fs)
    x = rec.qr - rec.qr.mean(axis=0)
    p = np.sum(np.abs(np.fft.rfft(x, axis=0)) ** 2, axis=1)
    f = np.fft.rfftfreq(rec.n, rec.dt)
    if not np.any(np.ptp(rec.qr, axis=0) > 0):
        raise DataError(f"{rec.name or 'the record'}: no joint's reference moves: there is no motion to identify from")
    c = np.cumsum(p[1:]) / max(np.sum(p[1:]), 1e-300)
    band = float(f[1:][min(np.searchsorted(c, 0.999), len(c) - 1)]) if len(c) else fs / 100
    return Decimation.lowpass(min(max(10 * band, 5 * f[1] if len(f) > 1 else 1.0), fs / 10), fs)


def speed_unit(rec: Recording) -> str:
    """The unit of a robot's smoothing speeds in words: rad/s, m/s, or both for an arm with both kinds of joint."""
    kinds = set(rec.joint_kinds) or {"revolute"}
    return {frozenset({"revolute"}): "rad/s", frozenset({"prismatic"}): "m/s"}.get(
        frozenset(kinds), "rad/s (m/s for the prismatic joints)")


def top_speeds(rec: Recording) -> np.ndarray:
    """Each joint's top reference speed: the scale of the speeds below which the fits leave rows out (the reference's,
    not the states': a simulated state that swings far off would move the threshold with it)."""
    return np.max(np.abs(np.diff(rec.qr, axis=0)), axis=0) / rec.dt


def _weighted_fit(parts: List[Tuple[np.ndarray, np.ndarray]], held: Optional[Dict[int, float]] = None
                  ) -> Tuple[np.ndarray, np.ndarray, Dict[str, float]]:
    """Least squares of the joints' rows, ordinary first, then each joint's rows divided by its residual's σ: the
    estimate, its covariance, and the regression's residual ‖y − Wθ̂‖ on the rows it kept (unweighted: the weights are
    the residuals' own and change with them) with its share of ‖y‖: what criterion (21) follows. ``held``: columns
    (by index) held at given values: their part of the force is taken off y, the rest fitted, and they come back in
    the estimate with no variance."""
    if held:
        p = parts[0][1].shape[1]
        idx = np.array(sorted(held), dtype=int)
        vals = np.array([held[i] for i in idx], dtype=float)
        free = np.setdiff1d(np.arange(p), idx)
        est, cov, res = _weighted_fit([(yd - wd[:, idx] @ vals, wd[:, free]) for yd, wd in parts])
        full, cfull = np.zeros(p), np.zeros((p, p))
        full[free], full[idx] = est, vals
        cfull[np.ix_(free, free)] = cov
        return full, cfull, res
    parts = [p for p in parts if len(p[0]) >= 2]
    if not parts:
        from .._errors import IdentifiabilityError

        raise IdentifiabilityError("no joint moves above the slow-speed threshold on this record: nothing to fit")
    theta, _, _ = _solve(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
    sig = [max(float(np.std(yd - wd @ theta)), 1e-12 * max(float(np.std(yd)), 1e-300)) for yd, wd in parts]
    theta, cov, _ = _solve(np.concatenate([yd / s_ for (yd, _), s_ in zip(parts, sig)]),
                           np.concatenate([wd / s_ for (_, wd), s_ in zip(parts, sig)]))
    rho = math.sqrt(sum(float(np.sum((yd - wd @ theta) ** 2)) for yd, wd in parts))
    norm = math.sqrt(sum(float(yd @ yd) for yd, _ in parts))
    return theta, cov, {"residual_norm": rho, "relative_error": rho / norm if norm > 0 else 0.0}


def _solve(y: np.ndarray, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares by the core's QR: estimate, covariance (eq. (13): σ² (WᵀW)⁻¹, σ² from the residual) and
    residual."""
    out = _core.lstsq(np.ascontiguousarray(w), np.ascontiguousarray(y))
    theta = np.asarray(out["params"], dtype=float)
    return theta, np.asarray(out["covariance"], dtype=float), np.asarray(out["residual"], dtype=float)


#: The measured positions' zero-phase low-pass, as a multiple of the decimation's cutoff: flat over the band the
#: decimation keeps (a 4th-order Butterworth run forward and backward passes a quarter of its cutoff within 2e-5), so
#: that the regression's force and regressor are filtered alike there (the parallel filtering of the paper's IDIM-LS).
#: At the decimation's own cutoff the positions were halved at the band's edge and the force was not: on the held-out
#: 1 kHz Panda, with the truth's friction law, Fv came out 7 % and 10 % off on its third and fourth joints (3 % at
#: most with this filter).
STATE_CUTOFF_RATIO = 4.0
#: The order of that low-pass (Butterworth, run forward and backward).
STATE_FILTER_ORDER = 4
#: The fewest samples a robot's states can be filtered from: the zero-phase filter pads 3·(order + 1) samples at each
#: end (scipy's filtfilt) and needs more than that.
MIN_SAMPLES = 3 * (STATE_FILTER_ORDER + 1) + 1


def _measured_states(rec: Recording, dec) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, speeds and accelerations from the measured positions: a zero-phase low-pass at
    :data:`STATE_CUTOFF_RATIO` times the decimation's cutoff (within the Nyquist frequency), then central
    differences."""
    from ..signal import diffcent, lowpass

    cutoff = min(STATE_CUTOFF_RATIO * dec.cutoff_hz, 0.45 / rec.dt)
    q = np.column_stack([lowpass(rec.qm[:, j], cutoff, 1 / rec.dt, order=STATE_FILTER_ORDER)
                         for j in range(rec.ndof)])
    v = np.column_stack([diffcent(q[:, j], rec.dt) for j in range(rec.ndof)])
    a = np.column_stack([diffcent(v[:, j], rec.dt) for j in range(rec.ndof)])
    return q, v, a


def _joint_columns(w: np.ndarray) -> List[Tuple[np.ndarray, np.ndarray]]:
    """A (N, n, p) regressor as each joint's acting columns: (their indices, the N × k matrix)."""
    acting = np.any(w != 0, axis=0)
    return [(act, w[:, j, act]) for j, act in enumerate(map(np.flatnonzero, acting))]


@dataclass
class _Motor:
    """The motor sides of a robot's elastic joints (their indices ``elastic``), as simulated: each joint's rotor
    position, speed and acceleration (samples × joints; the link side's on rigid joints)."""

    elastic: Tuple[int, ...]
    theta: np.ndarray
    thetad: np.ndarray
    thetadd: np.ndarray
    #: each joint's backlash (total width of the dead zone between rotor and link; 0 for none)
    gaps: Tuple[float, ...] = ()

    @classmethod
    def of(cls, sim: Dict[str, np.ndarray], elastic: Tuple[int, ...], gaps: Sequence[float] = ()
           ) -> Optional["_Motor"]:
        return cls(elastic, sim["theta"], sim["thetad"], sim["thetadd"], tuple(gaps)) if elastic else None

    def coupling(self, q: np.ndarray, v: np.ndarray, j: int) -> Tuple[np.ndarray, np.ndarray]:
        """Elastic joint ``j``'s spring stretch and its rate as the spring and its damping feel them (the columns of
        K and D): ``θ − q`` and ``θ̇ − q̇``; with backlash b, ``dz(θ − q)`` (``sign(x)·max(|x| − b/2, 0)``) and the
        rate in contact only (the core's coupling)."""
        from ..model import dead_zone

        stretch, rate = self.theta[:, j] - q[:, j], self.thetad[:, j] - v[:, j]
        gap = self.gaps[j] if self.gaps else 0.0
        if gap > 0:
            stretch = dead_zone(stretch, gap)
            rate = np.where(stretch != 0, rate, 0.0)
        return stretch, rate

    def friction_speeds(self, v: np.ndarray) -> np.ndarray:
        """Each joint's speed under its friction: the rotor's on an elastic joint, the link's on a rigid one."""
        out = v.copy()
        out[:, list(self.elastic)] = self.thetad[:, list(self.elastic)]
        return out

    def friction_positions(self, q: np.ndarray) -> np.ndarray:
        """Each joint's position under its friction and extra terms: the rotor's on an elastic joint."""
        out = q.copy()
        out[:, list(self.elastic)] = self.theta[:, list(self.elastic)]
        return out


def _model_columns(robot: Robot, base: BaseParameters, q, v, a, lay: "_Layout", motor: Optional[_Motor] = None,
                   substitute: bool = False
                   ) -> Tuple[List[Tuple[np.ndarray, np.ndarray]], List[Tuple[np.ndarray, np.ndarray]]]:
    """:func:`_model_regressor` with a zero Coulomb column (a law's is put in later), as each joint's acting columns
    (:func:`_joint_columns`) built one joint at a time: no (N, n, p) array of mostly zeros (on a 4 kHz UR10 record,
    111 MB written, then read again to find the columns that act), and the bodies' columns from the core series by
    series (``by_joint``), so that a joint's are copied whole, not gathered a row's stride apart.

    With elastic joints (``motor``, their simulated motor sides; θ as :class:`_Layout`), an elastic joint's rows are
    its motor side's, ``u = Ia θ̈ + Fv θ̇ + Fc s(θ̇) + OF + K (θ − q) + D (θ̇ − q̇)``, and the link rows of the elastic
    joints come second: ``0 = [Y(q, q̇, q̈) β]_j − K (θ − q) − D (θ̇ − q̇)``, the chain's torque on the joint against
    the spring's (one axis's load row, eq. (2), on a chain).

    ``substitute`` (DIDIM's step 3): the motor rows carry the link's equation instead of the spring,
    ``u = Ia θ̈ + Fv θ̇ + Fc s(θ̇) + OF + [Y(q, q̇, q̈) β]_j``: the motor's torque regressed on the link's own columns
    at the simulated link states, as a rigid joint's on its states; the link rows then give K and D alone
    (:meth:`_InverseModel.fit`). On the simulated states the link rows hold exactly with the iterate's own β, K and D,
    so with the spring in the motor rows the least squares could scale a link side's parameters with its spring but
    not change them otherwise: the gravity of the links beyond an elastic joint stayed where step 1's rigid model,
    fitted below the modes, put it (the held-out PID-controlled UR10's shoulder lift: its link's first moment 0.032
    for a truth of −0.106, its offset 1.84 N·m for 0.62, the validation record at 1.51 times its floor; 1.03 with
    these rows)."""
    n, offset = robot.ndof, lay.offset
    ind = np.asarray(base.independent)
    arm, body = ind[ind < n], ind[ind >= n]  # rotor inertias' columns, then the bodies'
    yb = robot.regressor(q, v, a, columns=body - n, by_joint=True)  # (n, len(body), N)
    out, links = [], []
    for j in range(n):
        bodies = np.flatnonzero(np.any(yb[j] != 0, axis=1))
        rotor = np.flatnonzero(arm == j)
        e = lay.elastic.index(j) if j in lay.elastic else None
        if e is None:
            act = np.concatenate([rotor, len(arm) + bodies, [lay.fv(j)], [lay.of(j)] if offset else []]).astype(int)
            m = np.empty((len(q), len(act)), order="F")
            m[:, :len(rotor)] = a[:, [j] * len(rotor)]  # a rotor inertia acts on its own joint's row, times its acceleration
            m[:, len(rotor):len(rotor) + len(bodies)] = yb[j, bodies].T
            m[:, len(rotor) + len(bodies)] = v[:, j]
            if offset:
                m[:, -1] = 1.0
            out.append((act, m))
            continue
        assert motor is not None
        stretch, rate = motor.coupling(q, v, j)
        if substitute:
            act = np.concatenate([[lay.ia(e), lay.fv(j)] + ([lay.of(j)] if offset else []), rotor,
                                  len(arm) + bodies]).astype(int)
            cols = [motor.thetadd[:, j, None], motor.thetad[:, j, None]] + ([np.ones((len(q), 1))] if offset else []) \
                + [a[:, [j] * len(rotor)], yb[j, bodies].T]
            out.append((act, np.asfortranarray(np.concatenate(cols, axis=1))))
        else:
            act = np.array([lay.ia(e), lay.fv(j)] + ([lay.of(j)] if offset else []) + [lay.k(e), lay.d(e)])
            cols = [motor.thetadd[:, j], motor.thetad[:, j]] + ([np.ones(len(q))] if offset else []) + [stretch, rate]
            out.append((act, np.asfortranarray(np.column_stack(cols))))
        act = np.concatenate([rotor, len(arm) + bodies, [lay.k(e), lay.d(e)]]).astype(int)
        cols = [a[:, [j] * len(rotor)], yb[j, bodies].T, -stretch[:, None], -rate[:, None]]
        links.append((act, np.asfortranarray(np.concatenate(cols, axis=1))))
    return out, links


def _rows(dec, y: np.ndarray, columns: List[Tuple[np.ndarray, np.ndarray]], p: int, v: np.ndarray,
          vmax: np.ndarray, start_row: int = 0) -> List[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each joint's force and regressor rows decimated (``columns``: each joint's acting columns among ``p``, as
    :func:`_joint_columns` gives them; a chain's joint feels the bodies beyond it and its own drive: half of a
    6-joint arm's columns are zero on its rows, and zero columns decimate to zero), the rows where it moves slowly
    (below :data:`SLOW_SHARE` of its top reference speed ``vmax``) and the ``start_row`` first ones (a simulation
    joining a record that began elsewhere: :func:`didim.methods.identification.settled_row`) left out: (force,
    regressor, the decimated rows kept) per joint."""
    out = []
    speeds = np.abs(dec.columns(v))  # every joint's in one pass of the filter
    for j, (act, mat) in enumerate(columns):
        if len(act):
            # the core reads a C- or Fortran-ordered matrix's columns in place (numpy's gather w[:, j, act] is
            # Fortran-ordered; a C-ordered copy transposed it twice, 3x the cost of its decimation)
            yd, wa = dec.apply(np.ascontiguousarray(y[:, j]), mat)
        else:
            yd, wa = dec(np.ascontiguousarray(y[:, j])), None
        keep = speeds[:, j] > SLOW_SHARE * vmax[j]
        keep[:start_row] = False
        wd = np.zeros((int(keep.sum()), p))
        if wa is not None:
            wd[:, act] = wa[keep]
        out.append((yd[keep], wd, keep))
    return out


class _InverseModel:
    """The inverse model's least squares on one set of states ``q, v, a`` (measured or simulated): each joint's force
    and regressor rows decimated once, the rows where it moves slowly (below :data:`SLOW_SHARE` of its top reference
    speed) left out; a friction law only replaces each joint's Coulomb column (one column decimated per joint), so
    that the laws a search compares, and DIDIM's step of ε, cost a fraction of a fit each."""

    def __init__(self, rec: Recording, model: Model, base: BaseParameters, q, v, a, dec,
                 y: Optional[np.ndarray] = None, start_row: int = 0, motor: Optional[_Motor] = None,
                 chain: Optional[Robot] = None, substitute: bool = False):
        robot = model.robot
        n, nb = robot.ndof, len(base.names)
        self.lay = _Layout.for_model(model, base)
        assert self.lay.elastic == (motor.elastic if motor is not None else ())
        self.terms = joint_terms(model)
        # each joint's friction and extra terms act at its rotor's position and speed (the link's on a rigid joint)
        self.robot, self.base, self.offset, self.dec = robot, base, model.offset, dec
        self.v = v if motor is None else motor.friction_speeds(v)
        self.x = q if motor is None else motor.friction_positions(q)
        self.n, self.nb = n, nb
        # the torque each joint's link asks of it (the chain's, whose parameters ``chain`` holds: the URDF's
        # by default), which a load-dependent friction grows with
        self.tau_load = (chain or robot).rnea(q, v, a) if self.lay.load else None
        # each joint's Coulomb and extra terms' columns are left out here: they are the law's (see rows)
        columns, links = _model_columns(robot, base, q, v, a, self.lay, motor, substitute)
        got = _rows(dec, rec.applied_force() if y is None else y, columns, self.lay.size, self.v, top_speeds(rec),
                    start_row)
        self.parts = [(yd, wd) for yd, wd, _ in got]
        self.keep = [keep for _, _, keep in got]
        # an elastic joint's link rows (against zero) follow its motor rows: every row, at any speed (no friction
        # acts there)
        self.link_rows = [0] * n
        self.links: List[Tuple[int, np.ndarray]] = []
        if links:
            ends = list(self.lay.elastic)
            lk = _rows(dec, np.zeros((len(q), len(ends))), links, self.lay.size, v[:, ends], np.zeros(len(ends)),
                       start_row)
            for e, (j, (yd, wd, keep)) in enumerate(zip(ends, lk)):
                if substitute:
                    self.links.append((e, wd))
                    continue
                self.parts[j] = (np.concatenate([self.parts[j][0], yd]), np.concatenate([self.parts[j][1], wd]))
                self.link_rows[j] = len(yd)

    def columns(self, columns: List[Tuple[int, np.ndarray]]) -> List[np.ndarray]:
        """Full-rate columns, each on joint ``j``'s rows (``(j, values)``), decimated together in one pass of the
        filter (four at a time: a robot's per-joint law columns one by one cost four times as much), each on its
        joint's kept rows (zero on an elastic joint's link rows)."""
        if not columns:
            return []
        dec = self.dec.columns(np.column_stack([c for _, c in columns]))
        out = []
        for i, (j, _) in enumerate(columns):
            c = dec[self.keep[j], i]
            out.append(np.concatenate([c, np.zeros(self.link_rows[j])]) if self.link_rows[j] else c)
        return out

    def rows(self, law: Law, coulomb: Optional[np.ndarray] = None) -> List[Tuple[np.ndarray, np.ndarray]]:
        """Each joint's kept rows with its Coulomb column under ``law``. With ``coulomb`` (each joint's Coulomb
        friction), one more column per joint: the law's derivative in its smoothing speed ε times it, whose
        coefficient is the step of ε that the force asks for (a Gauss–Newton step: ε trades with Fv where the law's
        tail is long, and is estimated with it). Every joint's law columns are decimated together (:meth:`columns`)."""
        n, v = self.n, self.v
        full: List[Tuple[int, np.ndarray]] = []  # (joint, full-rate column)
        where: List[Tuple[int, int]] = []  # (joint, its column in θ, or -1 for the step of ε)
        for j in range(n):
            sign = _sign(v[:, j], law[0], law[1][j])
            full.append((j, sign))
            where.append((j, self.lay.fc(j)))
            if j in self.lay.load:
                full.append((j, sign * np.abs(self.tau_load[:, j])))
                where.append((j, self.lay.fl(self.lay.load.index(j))))
            mine = [i for i, (jt, _) in enumerate(self.terms) if jt == j]
            if mine:
                cols = term_columns([self.terms[i][1] for i in mine], self.x[:, j], v[:, j], law[0], law[1][j])
                for i, c in zip(mine, cols.T):
                    full.append((j, c))
                    where.append((j, self.lay.t(i)))
            if coulomb is not None:
                e = max(float(law[1][j]), 1e-300)
                ds = (_sign(v[:, j], law[0], e * (1 + EPS_STEP)) - _sign(v[:, j], law[0], e * (1 - EPS_STEP)))
                full.append((j, ds / (2 * EPS_STEP * e) * float(coulomb[j])))
                where.append((j, -1))
        decimated = self.columns(full)
        out = []
        for j, (yd, wd) in enumerate(self.parts):
            wl = wd.copy()
            if coulomb is not None:
                wl = np.concatenate([wl, np.zeros((len(yd), n))], axis=1)
            for (jj, at), col in zip(where, decimated):
                if jj == j:
                    wl[:, at if at >= 0 else wd.shape[1] + j] = col
            out.append((yd, wl))
        return out

    def fit(self, law: Law, coulomb: Optional[np.ndarray] = None, held: Optional[Dict[int, float]] = None
            ) -> Tuple[np.ndarray, np.ndarray, Dict[str, float]]:
        """Weighted least squares (:func:`_weighted_fit`) under ``law``: the estimate, its covariance and the
        regression's residual; ``held``: parameters (by index in θ) held at given values. With the link equation in
        the elastic joints' motor rows (``substitute``), every parameter but the springs' from the motor rows, then
        each elastic joint's K and D from its link rows with that β, ``K (θ − q) + D (θ̇ − q̇) = [Y(q, q̇, q̈) β]_j``
        (their covariance that of this second fit alone, β taken as known); the residual is the motor rows'."""
        if not self.links:
            return _weighted_fit(self.rows(law, coulomb), held)
        lay, held = self.lay, dict(held or {})
        springs = {i: held.get(i, 0.0) for e in range(lay.ne) for i in (lay.k(e), lay.d(e))}
        est, cov, res = _weighted_fit(self.rows(law, coulomb), {**held, **springs})
        p = lay.size
        for e, wd in self.links:
            ks = [i for i in (lay.k(e), lay.d(e)) if i not in held]
            if not ks:
                continue
            other = np.setdiff1d(np.arange(p), ks)
            y = -(wd[:, other] @ est[other])
            th, c, _ = _solve(y, wd[:, ks])
            est[ks] = th
            cov[np.ix_(ks, ks)] = c
        return est, cov, res


#: Relative step of ε in the law's central difference.
EPS_STEP = 1e-4
#: ε is moved by the least squares only where they determine it (σ within this share of ε), and by at most a factor
#: of 2 per iteration.
EPS_SIGMA_MAX = 0.1


def urdf_residual(rec: Recording, robot: Robot, angle_factor: float = 1.0, length_factor: float = 1.0,
                  factors: Optional[np.ndarray] = None, time_factor: float = 1.0,
                  force: Optional[np.ndarray] = None, per_joint: bool = False, drive_inertia: bool = True):
    """The share of the force (each joint's scaled alike) that the URDF's bodies leave unexplained once each joint's
    own drive (rotor inertia, viscous and Coulomb friction, offset) is fitted to the rest, on the measured states
    (every ``n/2000``-th sample), the revolute joints' positions taken times ``angle_factor`` and the prismatic ones'
    times ``length_factor``: how well the record's position units fit the URDF's dynamics (its gravity and inertia
    depend on the positions themselves, where units read wrong put them elsewhere). ``factors``: one factor per
    joint instead. ``time_factor``: the sample period taken times it (a time column in another unit: the speeds
    divided by it, the accelerations by its square; the filters follow the sample rate, so nothing else changes).
    ``force``: another reading of the logged force (samples × joints). ``per_joint``: each joint's share instead of
    the whole's. ``drive_inertia`` False: the drive's own inertia is left out of the fit (a time read in another
    unit puts every acceleration a factor off, and a fitted rotor inertia would take the joint's own share of it up:
    on the pendulum, time in ms read as s leaves 12 % with it and 24 % without, against 7 % and 8 % read right)."""
    q, v, a = _measured_states(rec, _decimation(rec))
    if factors is None:
        factors = np.array([length_factor if k == "prismatic" else angle_factor for k in rec.joint_kinds])
    step = max(1, rec.n // 2000)
    q, v, a = (x[::step] * factors / time_factor**i for i, x in enumerate((q, v, a)))
    force = (rec.force if force is None else force)[::step]
    with np.errstate(over="ignore", invalid="ignore"):  # a URDF far out of scale: not finite, said by the caller
        return _residual_shares(robot.rnea(q, v, a), force, v, a, drive_inertia, per_joint)


def _residual_shares(dyn: np.ndarray, force: np.ndarray, v: np.ndarray, a: np.ndarray, drive_inertia: bool,
                     per_joint: bool):
    """:func:`urdf_residual`'s shares from the URDF's torques ``dyn`` on the states, the force and the states' speeds
    and accelerations (infinite where the torques are not finite)."""
    rest = force - dyn
    ndof = force.shape[1]
    if not np.all(np.isfinite(rest)):
        return np.full(ndof, math.inf) if per_joint else math.inf
    scale = np.std(force, axis=0)
    left, total = np.zeros(ndof), np.zeros(ndof)
    for j in range(ndof):
        if not scale[j] > 0:
            continue  # a force that never changes: nothing for the dynamics to explain (the controller check says so)
        w = np.column_stack(([a[:, j]] if drive_inertia else []) + [v[:, j], np.sign(v[:, j]), np.ones(len(v))])
        w = w / scale[j]
        y = rest[:, j] / scale[j]
        r = y - w @ np.linalg.lstsq(w, y, rcond=None)[0]
        left[j] = float(r @ r)
        total[j] = float(np.sum((force[:, j] / scale[j]) ** 2))
    if not np.all(np.isfinite(left)):
        return np.full(ndof, math.inf) if per_joint else math.inf
    if per_joint:
        return np.sqrt(left / np.maximum(total, 1e-300)) * (total > 0)
    return math.sqrt(left.sum() / total.sum()) if total.sum() > 0 else 0.0


#: The URDF describes a record's robot when its dynamics leave at most this share of the force unexplained
#: (:func:`urdf_residual`): the data folder's training and validation records leave 6-7 % (their worst joint 23 %),
#: their payload records, whose payload the URDF lacks, 21 % and 36 %; another robot's URDF, joints relabelled or a
#: joint's kind changed at least 63 % in the campaign's records, and a tenth of a second of a right record 39 %. A
#: unit of position is named as the record's only when it brings the record under it.
FIT_WELL = 0.25


#: Above this share of the force unexplained (:func:`urdf_residual`), the URDF is said to be probably another robot's:
#: another robot's URDF, joints relabelled or a joint's kind changed left at least 63 % in the campaign's records.
OTHER_ROBOT = 0.6


def never_reversing(rec: Recording) -> List[str]:
    """The joints whose reference moves but never reverses its direction in the record (their Coulomb friction and
    offset cannot be told apart, nor their inertia from a drift)."""
    out = []
    for j, name in enumerate(rec.joint_names):
        d = np.diff(rec.qr[:, j])
        d = d[d != 0]
        if d.size and not np.any(np.diff(np.sign(d))):
            out.append(name)
    return out


def unit_readings(rec: Recording, robot: Robot) -> List[Tuple[str, List[int], set, float, float, str]]:
    """For the revolute and the prismatic joints of ``rec``, each kind as a group: ``(kind, joints, read_as, here,
    there, other)``, ``read_as`` the units its joints were read in; when that is one unit with other readings
    (:func:`didim.units.other_readings`), the share of the force the URDF's dynamics leave unexplained as read
    (``here``, :func:`urdf_residual`) and in the best other reading ``other`` (``there``); NaN and "" otherwise. The
    loader's units check and :func:`units_hint` read it."""
    from ..units import other_readings

    out = []
    here = math.nan
    for kind, si in (("revolute", "rad"), ("prismatic", "m")):
        joints = [j for j, k in enumerate(rec.joint_kinds) if (k == "prismatic") == (kind == "prismatic")]
        if not joints:
            continue
        read_as = {rec.units[j].position if rec.units else si for j in joints}
        there, other = math.nan, ""
        if len(read_as) == 1 and other_readings(next(iter(read_as))):
            key = "length_factor" if kind == "prismatic" else "angle_factor"
            here = urdf_residual(rec, robot) if math.isnan(here) else here  # the same for both kinds: once
            there, other = min((urdf_residual(rec, robot, **{key: factor}), u)
                               for u, factor in other_readings(next(iter(read_as))))
        out.append((kind, joints, read_as, here if other else math.nan, there, other))
    return out


def units_hint(rec: Recording, robot: Robot) -> str:
    """A sentence naming another unit of the revolute or the prismatic joints' positions in which the record fits the
    URDF's dynamics better than in the one it was read in (:func:`unit_readings`), or "": for the messages of a fit
    that failed where the loader's units check (a factor :data:`didim.formats.loaders.UNITS_RATIO`) did not refuse,
    as on an elastic arm's record, which no rigid reading fits well (the flexrobots UR5 declared in degrees: 36 % of
    its force unexplained against 23 % read in rad)."""
    return "; ".join(
        f"read in {other}, the {kind} joints' positions fit the URDF's dynamics better than in {next(iter(read_as))} "
        f"({100 * there:.0f} % of the force unexplained against {100 * here:.0f} %): check the record's units "
        "(--units, units=...)"
        for kind, _, read_as, here, there, other in unit_readings(rec, robot) if other and there < here)


def urdf_mismatch(rec: Recording, robot: Robot, verdict: str = "probably does not") -> str:
    """In words, why a record does not fit its URDF's dynamics: the URDF is another robot's (the worst joint named),
    or the record is too short or too still (the joints whose reference never reverses). ``verdict``: how sure the
    sentence about the URDF is ("probably does not", "may not")."""
    each = urdf_residual(rec, robot, per_joint=True)
    j = int(np.argmax(each))
    urdf = (f"the URDF {{}} describe this record's robot (joint {rec.joint_names[j]} fits worst, "
            f"{100 * each[j]:.0f} % of its force unexplained: check the URDF, its joints' kinds and axes, the joints' "
            "order in the record and --joints)")
    still = never_reversing(rec)
    if still:  # too short or too still comes first: a right URDF cannot show on such a record
        return (f"the record ({rec.n} samples, {rec.n * rec.dt:.4g} s) is probably too short or too still to identify "
                f"from: the reference of {', '.join(still)} never reverses (log a motion back and forth, several times "
                "longer); or " + urdf.format("does not"))
    return urdf.format(verdict)


def _mismatch_hint(rec: Recording, robot: Robot) -> str:
    """:func:`urdf_mismatch` after the share the URDF leaves, when it leaves more than :data:`FIT_WELL` or a joint
    never reverses; else nothing."""
    with np.errstate(all="ignore"):
        left = urdf_residual(rec, robot)
        if not (left > FIT_WELL or never_reversing(rec)):
            return ""
        if left >= OTHER_ROBOT:
            return (f"; the URDF's dynamics leave {100 * left:.0f} % of the record's force unexplained (a right URDF "
                    f"under {100 * FIT_WELL:.0f} %): " + urdf_mismatch(rec, robot))
        # a rigid model of an elastic arm leaves its modes' torque too (the held-out UR10 under PID, whose URDF is
        # right): below another robot's share, the URDF is one cause among two
        return (f"; the URDF's dynamics leave {100 * left:.0f} % of the record's force unexplained (a right URDF "
                f"under {100 * FIT_WELL:.0f} %, another robot's above {100 * OTHER_ROBOT:.0f} %): "
                + urdf_mismatch(rec, robot, "may not")
                + "; or the robot's joints are elastic, which a rigid model cannot follow (try elastic=[...], "
                "--elastic)")


def _speed_scales(rec: Recording) -> np.ndarray:
    """Each joint's speed scale: the median top reference speed of the joints of its kind (rad/s for revolute
    joints, m/s for prismatic ones), or, when none of them is driven, its encoder step per sample period. A friction
    law's smoothing speed belongs to the friction, not to how fast one joint's trajectory goes: joints of one kind
    start from one ε, each refined where its rows say so (:func:`fit_law`)."""
    vmax = top_speeds(rec)
    kinds = np.array(rec.joint_kinds)
    out = np.ones(len(vmax))
    for kind in set(rec.joint_kinds):
        same = vmax[(kinds == kind) & (vmax > 0)]
        if len(same):
            out[kinds == kind] = float(np.median(same))
            continue
        # no joint of this kind is driven: the record's own resolution of speed (an encoder step, or the positions'
        # excursion, per sample period); a joint that stays exactly still keeps 1 (of its units: its law never acts)
        for j in np.flatnonzero(kinds == kind):
            res = max(float(rec.encoder_step[j]), float(np.ptp(rec.qm[:, j])))
            out[j] = res / rec.dt if res > 0 else 1.0
    return out


def _default_law(rec: Recording) -> Law:
    """didim's law for a robot's loop when none is fitted: algebraic, each joint's ε a share (:data:`EPS_SHARE`) of
    its speed scale (:func:`_speed_scales`)."""
    return ("algebraic", tuple(float(EPS_SHARE * s) for s in _speed_scales(rec)))


#: The friction laws :func:`fit_law` chooses among: the core's shapes, each joint's ε from 1/300 to 1/3 of its speed
#: scale (a factor of √10 apart, then refined per joint); sharper ones are the hard sign on the rows the fits keep.
LAW_SHAPES = ("algebraic", "tanh", "atan", "exp")
LAW_EPS_REL = tuple(float(x) for x in np.geomspace(1 / 300, 1 / 3, 9))

#: A joint's own ε must lower the inverse model's residual by this many times the joint's residual variance (χ² of
#: one degree of freedom at p = 0.001).
EPS_CHI2 = 10.83

#: Laws that fit the kept rows within this share of the best are equivalent there: the smoothest (largest ε) is kept,
#: the cheapest to simulate.
LAW_TIE = 1e-3


def fit_law(rec: Recording, inverse: "_InverseModel",
            per_shape: Optional[Dict[str, Tuple[float, ...]]] = None) -> Law:
    """The friction law through zero speed that best explains the force: each shape with each joint's ε a share of the
    grid of its speed scale (:func:`_speed_scales`), in the weighted least squares of the inverse model ``inverse``
    (the rows where a joint moves slowly are left out, as in every fit: what is chosen is the law's tail, where a
    slow law such as the atan one is still several percent below its Coulomb level at ten times ε and would bend the
    viscous friction), then each joint's ε refined on its own (a prismatic quill's m/s and a shoulder's rad/s have no
    common scale). ``per_shape`` receives each shape's best ε per joint on the grid."""
    n, v = inverse.n, inverse.v
    scale = _speed_scales(rec)
    fc_cols = [inverse.lay.fc(j) for j in range(n)]
    parts = inverse.rows(("algebraic", (0.0,) * n))  # the hard sign
    # per-joint weights from the hard sign's fit
    y0 = np.concatenate([p[0] for p in parts])
    w0 = np.concatenate([p[1] for p in parts])
    th = np.linalg.lstsq(w0, y0, rcond=None)[0]
    sig = [max(float(np.std(p[0] - p[1] @ th)), 1e-300) for p in parts]
    # the least squares with every column but the Coulomb ones fixed: their span projected out once (an orthonormal
    # basis from the SVD, rank-safe), each law's Coulomb columns projected alike, then a least squares of n columns:
    # the same residual as the whole fit, at a fraction of its cost
    sizes = [len(p_[0]) for p_ in parts]
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    other = [c for c in range(w0.shape[1]) if c not in fc_cols]
    yy = np.concatenate([p_[0] / s_ for p_, s_ in zip(parts, sig)])
    wf = np.concatenate([p_[1][:, other] / s_ for p_, s_ in zip(parts, sig)])
    u, sv, _ = np.linalg.svd(wf, full_matrices=False)
    basis = u[:, sv > max(wf.shape) * np.finfo(float).eps * sv[0]] if len(sv) and sv[0] > 0 else u[:, :0]
    y_perp = yy - basis @ (basis.T @ yy)
    cols: Dict[Tuple[str, int, float], np.ndarray] = {}

    def columns_of(keys: List[Tuple[str, int, float]]) -> List[np.ndarray]:
        """Each joint's Coulomb column under its law (``(shape, j, ε)``), weighted, with the fixed columns' span
        projected out; those not made yet decimated together (:meth:`_InverseModel.columns`)."""
        missing = [k for k in dict.fromkeys(keys) if k not in cols]
        for (shape, j, eps), c in zip(missing, inverse.columns([(j, _sign(v[:, j], shape, eps))
                                                                 for shape, j, eps in missing])):
            c = c / sig[j]
            rows = slice(bounds[j], bounds[j + 1])
            full = -(basis @ (basis[rows].T @ c))
            full[rows] += c
            cols[(shape, j, eps)] = full
        return [cols[k] for k in keys]

    def cost(law: Law) -> Tuple[float, np.ndarray]:
        cp = np.column_stack(columns_of([(law[0], j, law[1][j]) for j in range(n)]))
        r = y_perp - cp @ np.linalg.lstsq(cp, y_perp, rcond=None)[0]
        per = np.array([float(r[bounds[j]:bounds[j + 1]] @ r[bounds[j]:bounds[j + 1]]) for j in range(n)])
        return float(r @ r), per

    def law_of(shape: str, rel: float) -> Law:
        return (shape, tuple(float(rel * s_) for s_ in scale))

    step = math.log(LAW_EPS_REL[1] / LAW_EPS_REL[0])

    def refined(shape: str) -> Tuple[Tuple[float, ...], float]:
        """The shape's best ε on the grid (laws within LAW_TIE of it are alike on these rows: the smoothest, the
        cheapest to simulate), then each joint's between its grid neighbours where its rows ask for it: the residual
        must fall by more than a χ² of one degree of freedom at p = 0.001 times the joint's residual variance (a
        flat tail, tanh's, leaves ε where the kind's grid put it)."""
        table = [(rel, cost(law_of(shape, rel))[0]) for rel in LAW_EPS_REL]
        low = min(c for _, c in table)
        rel = max(r_ for r_, c in table if c <= (1 + LAW_TIE) * low)
        eps = list(law_of(shape, rel)[1])
        total, per = cost((shape, tuple(eps)))
        for j in range(n):
            def cj(x: float, j: int = j) -> float:
                e = list(eps)
                e[j] = math.exp(x)
                return cost((shape, tuple(e)))[0]

            # a grid a ninth of the kind's grid step apart, and the parabola through the lowest and its neighbours
            xs = math.log(eps[j]) + np.linspace(-step, step, 9)
            cs = np.array([cj(float(x_)) for x_ in xs])
            x_best = friction_law.parabola_min(xs, cs)
            c_best = cj(x_best) if x_best != xs[int(np.argmin(cs))] else float(np.min(cs))
            if c_best > float(np.min(cs)):
                x_best, c_best = float(xs[int(np.argmin(cs))]), float(np.min(cs))
            if c_best < total - EPS_CHI2 * per[j] / max(sizes[j] - 1, 1):
                eps[j] = float(math.exp(x_best))
                total, per = cost((shape, tuple(eps)))
        return tuple(eps), total

    # every shape with its joints' ε refined, then the shape that fits best: a shape compared at one ε for all
    # joints takes the place of another whose joints' ε differ (a Panda with an algebraic law chose atan)
    laws = {shape: refined(shape) for shape in LAW_SHAPES}
    if per_shape is not None:
        per_shape.update({sh: eps for sh, (eps, _) in laws.items()})
    shape = min(laws, key=lambda sh: laws[sh][1])
    return (shape, laws[shape][0])


def _first_half(rec: Recording) -> Recording:
    import dataclasses

    m = max(rec.n // 2, 2)
    return dataclasses.replace(rec, qr=rec.qr[:m], force=rec.force[:m], qm=rec.qm[:m],
                               ql=None if rec.ql is None else rec.ql[:m],
                               u_ext=None if rec.u_ext is None else rec.u_ext[:m],
                               lead_in=rec.qr_lead if len(rec.qr_lead) else None)


#: The closed loop's shape replaces the one the inverse model chose on the law's tail only when its force errors are
#: significantly lower (one-sided Diebold-Mariano test at this level, HAC variance): on the rows the inverse model
#: keeps, the tail's shape is evidence too, and the closed loop's differences between shapes can be its parameters'
#: (the held-out 1 kHz Panda, started from IDIM-LS's estimate: exp 1.55 % against algebraic 1.58 % on the first
#: half, and the slow fourth joint's Fv 16 % off with exp).
SHAPE_ALPHA = 0.05


def closed_loop_law(rec: Recording, refit: Callable[[Law], Tuple[Robot, Dict[str, List[float]]]], law: Law,
                    per_shape: Dict[str, Tuple[float, ...]], progress=None,
                    current: Optional[Tuple[Robot, Dict[str, List[float]]]] = None) -> Law:
    """The friction law through zero speed that the closed loop follows best (:func:`didim.methods.friction_law.closed_loop_law`,
    every plant's search), by the joints' relative force errors on the first half of the record: each shape with the
    model's other parameters refitted for it (``refit(law)``: the robot and its drives; parameters fitted with one
    shape have taken its tail into their viscous friction, and would favour it), starting from the smoothing speeds
    the inverse model chose for it. Each law's loop is simulated without encoder quantization (:func:`_simulate`), as
    step 2's search is: the search compares laws a factor √2 apart and fits a parabola to each joint's errors, and the
    encoders' rounding made those errors jump by about 1 % of themselves at any change of ε (the flexrobots UR5's
    shoulder: 4.91-5.05 % in no order over ε from 0.0053 to 0.0126 rad/s), so that the vertex, and step 3's law, moved
    with the last digits of the arithmetic (ε of that joint 0.0084 or 0.011 rad/s with the BLAS on one thread or two;
    now 0.00983 with either, the truth 0.01). The inverse model cannot choose the law: it leaves out the rows where the law acts,
    and on the rows it keeps every sharp law is alike (on the data folder's pendulum, a tanh law of ε = 0.01 rad/s and
    an exp law of 0.015 fit them equally, and the second simulates the validation record at 1.23 times its floor, the
    first at 1.01).

    ``current``: the estimate the search starts from (the robot and its drives, under ``law``). A law is taken only
    when its refitted model fits the first half better than that estimate does with its own law: each law's refit is
    one least squares on the estimate's simulated states, and where that step alone is unstable in closed loop (the
    KR300's bodies held, every law's refit at 10⁵ % where the estimate was at 30 %) no law should replace it."""
    part = _first_half(rec)
    say = progress or (lambda s: None)
    starts: Dict[str, Tuple[float, ...]] = {}
    for sh, eps in list(per_shape.items()) + [(law[0], law[1])]:
        starts.setdefault(sh, tuple(eps))
    models: Dict[str, Any] = {}
    norms = np.maximum(np.linalg.norm(part.force, axis=0), 1e-300)

    def errors(lw: Law) -> Optional[np.ndarray]:
        if lw[0] not in models:
            try:
                models[lw[0]] = refit((lw[0], starts[lw[0]]))
            except (SimulationError, DataError, IdentifiabilityError):
                models[lw[0]] = None
        if models[lw[0]] is None:
            return None
        robot, d = models[lw[0]]
        try:
            sim = _simulate(part, robot, d, lw, quantize=False)
        except (SimulationError, DataError):
            return None
        r = (part.force - sim["force"]) / norms
        residuals[lw] = np.sqrt(np.sum(r * r, axis=1))  # each sample's share of the joints' errors together
        return np.sqrt(np.sum(r * r, axis=0))

    residuals: Dict[Law, np.ndarray] = {}
    found = friction_law.closed_loop_law(starts, errors)
    if found.law[0] != law[0] and law[0] in starts and found.law in residuals:
        # the tail's shape (the inverse model's choice) is kept unless the closed loop's is significantly better
        kept = friction_law.closed_loop_law({law[0]: starts[law[0]]}, errors, known=found.tried)
        if kept.law in residuals:
            _, p, _ = diebold_mariano(residuals[kept.law], residuals[found.law])
            if p >= SHAPE_ALPHA:
                say(f"friction law through zero speed: the closed loop's {found.law[0]} is not significantly better "
                    f"than the tail's {law[0]} (Diebold-Mariano p = {p:.2g}): {law[0]} kept")
                found = kept
    if current is not None and found.law != law:
        try:
            sim = _simulate(part, *current, law, quantize=False)
            now = friction_law.rms(np.linalg.norm(part.force - sim["force"], axis=0) / norms)
        except (SimulationError, DataError):
            now = math.inf
        if not found.error < now:
            say(f"friction law through zero speed: no law's refit fits the first half better than the estimate with "
                f"its own law ({friction_law.describe(found.law, speed_unit(rec))}: RMS {100 * found.error:.3f} % "
                f"against {100 * now:.3f} %): {friction_law.describe(law, speed_unit(rec))} kept")
            return law
    say(f"friction law through zero speed, in closed loop: {friction_law.describe(found.law, speed_unit(rec))} "
        "(joints' force errors "
        f"on the first half, RMS {100 * found.error:.3f} %)")
    return found.law


def simulate_robot(rec: Recording, result: IdentificationResult, substeps: int = 0,
                   quantize: bool = True) -> Dict[str, np.ndarray]:
    """The closed loop of ``rec`` (its references, controllers, encoders, first force) with the model of ``result``
    (its friction law): q, qd, qdd the link side's, force the commands, and with elastic joints theta, thetad, thetadd
    the motor side's. ``quantize=False``: the encoders read the exact positions (:func:`_simulate`)."""
    _robot_result(result)
    _check(rec, result.structure)
    substeps = _checks.whole("substeps", substeps, lo=0, hi=1024, hint=" (RK4 steps per sample; 0 chooses)")
    robot, d = _model_of(result.structure, result.base, theta_of(result))
    return _simulate(rec, robot, d, result.law if result.law is not None else _default_law(rec), substeps,
                     quantize=quantize)


def deflection_errors(rec: Recording, sim: Dict[str, np.ndarray], model: Model) -> Dict[str, float]:
    """Each elastic joint's relative RMS error of the simulated link-minus-motor deflection ``q − θ`` against the
    logged one ``ql − qm``, where the record has the joint's link-side position (``ql_<joint>``)."""
    if rec.ql is None or not model.elastic or "theta" not in sim:
        return {}
    out = {}
    for j in elastic_of(model):
        if np.all(np.isnan(rec.ql[:, j])):
            continue
        logged = rec.ql[:, j] - rec.qm[:, j]
        norm = float(np.linalg.norm(logged))
        out[rec.joint_names[j]] = (float(np.linalg.norm(sim["q"][:, j] - sim["theta"][:, j] - logged)) / norm
                                   if norm > 0 else math.nan)
    return out


#: How many closed loops this thread has simulated (a method's result reports the difference over its run).
_count = threading.local()


def _simulations() -> int:
    return getattr(_count, "n", 0)


def _force0(rec: Recording, robot: Robot, d: Dict[str, List[float]], law: Law) -> np.ndarray:
    """Each drive's force held at the first sample of :func:`_simulate`'s loop: the logged first force, or through a
    lead-in (:attr:`Recording.qr_lead`) the model's static torque at its start (gravity, offset and the terms that
    hold at rest, less the feedforward)."""
    qr, u_ext = rec.lead_in_signals()
    if len(qr) == rec.n:
        return np.asarray(rec.force[0], dtype=float)
    rest = np.zeros(rec.ndof)
    force0 = robot.rnea(qr[0], rest, rest) + np.asarray(d["offset"]) - (0.0 if u_ext is None else u_ext[0])
    for j, terms in enumerate(d.get("terms") or ()):  # a torque along the stroke holds at rest too
        for kind, hypers, value in terms:
            force0[j] += value * term_columns([Term("at_rest", kind, **dict(hypers))], qr[0, j:j + 1], rest[:1],
                                              law[0], law[1][j])[0, 0]
    return force0


def _physical(robot: Robot, d: Dict[str, List[float]], law: Law) -> np.ndarray:
    """The physical parameters of the closed loop of ``robot`` with the drives ``d`` under ``law``, flattened as the
    core's ``PhysLayout``: each joint's rotor inertia, the bodies' inertial parameters, each joint's Fv, Fc, offset,
    stiffness (0 on a rigid joint), damping, backlash, load-dependent friction μ and smoothing speed ε, then the terms'
    values joint by joint."""
    n = robot.ndof

    def get(key: str) -> np.ndarray:
        v = d.get(key)
        return np.zeros(n) if v is None else np.asarray(v, dtype=float)

    k = get("stiffness")
    values = [v for joint in (d.get("terms") or ()) for (_, _, v) in joint]
    return np.concatenate([get("armature"), robot.inertial_params, get("viscous"), get("coulomb"), get("offset"),
                           np.where(np.isfinite(k), k, 0.0), get("damping"), get("backlash"), get("load_friction"),
                           np.asarray(law[1], dtype=float), np.asarray(values, dtype=float)])


def _simulate(rec: Recording, robot: Robot, d: Dict[str, List[float]], law: Law, substeps: int = 0,
              quantize: bool = True, directions: Optional[np.ndarray] = None, dforce0: Optional[np.ndarray] = None):
    """The closed loop of ``rec`` with the robot ``robot`` and drives ``d`` under ``law``: from rest at the first
    reference, each controller's integrator holding the logged first force; through the record's lead-in
    (:attr:`Recording.qr_lead`) when it begins in motion, from rest at the lead-in's start, each integrator then
    holding the model's static torque there (gravity and offset, less the feedforward), the lead-in's samples dropped
    from the outputs. ``quantize=False``: the encoders read the exact positions (a simulation smooth in the
    parameters, for a search that differentiates it: a parameter's change flips encoder counts, and the closed loop
    turns each flip into a step of force, so that the force error of the quantized loop jumps by about its noise at
    any step of a parameter, 0.7 % of the force on the flexrobots' arm at steps from 1e-4 to 1e-2). With
    ``directions`` (:func:`_physical`'s length × p, ``∂φ/∂χ``) and ``dforce0`` (n × p, ``∂force0/∂χ``): ``dforce``
    (n, p, N), the exact sensitivities of the simulated forces (the core's forward sensitivity equations of the
    loop)."""
    _count.n = _simulations() + 1
    qr, u_ext = rec.lead_in_signals()
    lead = len(qr) - rec.n
    force0 = _force0(rec, robot, d, law)
    try:
        sim = _core.simulate_robot(robot._core, d["armature"], d["viscous"], d["coulomb"], d["offset"],
                                   rec.core_controllers(), qr, rec.dt,
                                   quantization=list(rec.encoder_step) if quantize else [0.0] * rec.ndof,
                                   force0=list(map(float, force0)), substeps=substeps, coulomb_eps=list(law[1]),
                                   coulomb_law=[law[0]] * len(law[1]), u_ext=u_ext,
                                   delay=list(rec.delay) or None, force_lag=list(rec.force_lag) or None,
                                   stiffness=d.get("stiffness"), damping=d.get("damping"), terms=d.get("terms"),
                                   load_friction=d.get("load_friction"), backlash=d.get("backlash"),
                                   directions=directions, dforce0=dforce0)
    except DataError as e:
        raise SimulationError(f"the robot's closed loop cannot be simulated with these parameters: {e}") from None
    if not lead:
        return sim
    return {k: (v[..., lead:] if k == "dforce" else v[lead:]) for k, v in sim.items()}


#: A declared delay or force lag is questioned when the model simulates its joint significantly better without it
#: (one-sided Diebold-Mariano at this level on the joint's force residuals) and by at least this share of its error.
ACTUATION_ALPHA = 0.01
ACTUATION_GAIN = 0.01


def actuation_notes(rec: Recording, res: IdentificationResult) -> List[str]:
    """Each joint whose declared actuation delay or force lag (its controller entry's "delay", "force_lag") the
    identified model simulates significantly worse with than without: a declaration the record may not have (a
    one-sample delay declared on a record without one moved the pendulum's mx by 13 % and its force error from 1.34 %
    to 1.42 %, and nothing said so). One simulation without the declarations; a note per joint, not a refusal (the
    model was fitted with them)."""
    import dataclasses

    declared = [j for j in range(rec.ndof) if (rec.delay and rec.delay[j]) or (rec.force_lag and rec.force_lag[j])]
    if not declared or res.structure is None or res.structure.robot is None:
        return []
    try:
        with_ = simulate_robot(rec, res)["force"]
        bare = dataclasses.replace(rec, delay=(), force_lag=())
        without = simulate_robot(bare, res)["force"]
    except (SimulationError, DataError):
        return []
    out = []
    for j in declared:
        e1, e0 = rec.force[:, j] - with_[:, j], rec.force[:, j] - without[:, j]
        n1, n0 = float(np.linalg.norm(e1)), float(np.linalg.norm(e0))
        _, p, _ = diebold_mariano(e1, e0)
        if n0 < (1 - ACTUATION_GAIN) * n1 and p < ACTUATION_ALPHA:
            norm = float(np.linalg.norm(rec.force[:, j]))
            what = " and ".join(x for x in (f"a delay of {rec.delay[j]} sample(s)" if rec.delay and rec.delay[j] else "",
                                            f"a force lag of {1e3 * rec.force_lag[j]:g} ms"
                                            if rec.force_lag and rec.force_lag[j] else "") if x)
            out.append(f"joint {rec.joint_names[j]}: its controller entry declares {what}, but the identified model "
                       f"simulates the record better without (force error {100 * n0 / norm:.2f} % against "
                       f"{100 * n1 / norm:.2f} %, Diebold-Mariano p = {p:.2g}): the record may not have it; check the "
                       "declaration (the parameters were fitted with it)")
    return out


def force_errors(rec: Recording, force_sim: np.ndarray) -> Tuple[float, Dict[str, float]]:
    """‖τ − τ_sim‖/‖τ‖ over all joints, and per joint (:func:`didim.simulation.column_errors`)."""
    from ..simulation import column_errors

    total = float(np.linalg.norm(rec.force - force_sim) / np.linalg.norm(rec.force))
    return total, dict(zip(rec.joint_names, map(float, column_errors(rec.force, force_sim))))


def _result(method: str, rec: Recording, model: Model, base: BaseParameters, theta, cov,
            **kw) -> IdentificationResult:
    robot, offset = model.robot, model.offset
    elastic = elastic_of(model)
    names = _theta_names(model, base)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    params = dict(zip(names, map(float, theta)))
    stds = dict(zip(names, map(float, std)))
    # each joint's rotor inertia: its own base parameter, or (regrouped with link inertias) the base value minus the
    # URDF's values of what it combines
    notes = list(kw.pop("notes", []))
    pi0 = np.concatenate([np.zeros(robot.ndof), robot.inertial_params])
    for j, jn in enumerate(robot.joint_names):
        if j in elastic:
            continue  # an elastic joint's rotor inertia is a parameter of its own
        i = base.independent.index(j) if j in base.independent else None
        if i is None:
            notes.append(f"Ia_{jn} is not identifiable on its own (no base parameter holds it)")
            continue
        bname = base.names[i]
        if bname == f"Ia_{jn}":
            continue
        others = base.K[i].copy()
        others[j] = 0.0
        params[f"Ia_{jn}"] = params[bname] - float(others @ pi0)
        stds[f"Ia_{jn}"] = stds[bname]
        notes.append(f"Ia_{jn} is regrouped with body parameters ({bname}): its value takes the URDF's values of "
                     "those")
    ordered = {k: params[k] for k in [f"{p}_{j}" for p in ("Ia", "Fv", "Fc") + (("OF",) if offset else ())
                                      for j in robot.joint_names]}
    ordered.update({k: v for k, v in params.items() if k not in ordered})
    for jn, span in zip(robot.joint_names, np.ptp(rec.qr, axis=0)):
        if not span > 0:
            notes.append(f"joint {jn} does not move in this record (its reference is constant): its rotor inertia and "
                         f"friction (Ia_{jn}, Fv_{jn}, Fc_{jn}) are not identified by it and their values mean nothing; "
                         "record a move of every joint")
    res = robot_result(method, ordered, stds, model, base, notes=notes, **kw)
    res.notes += plausibility(res, rec)
    return res


#: A base parameter whose standard deviation exceeds this share of its value is reported as poorly excited
#: (Gautier's rule of thumb: a relative standard deviation above 10 %).
POOR_EXCITATION = 0.1


def plausibility(res: IdentificationResult, rec: Optional[Recording] = None) -> List[str]:
    """What a robotics engineer checks before trusting the estimate: the base parameters the record excites poorly
    (relative standard deviation above :data:`POOR_EXCITATION`), whether the standard parameters closest to the
    URDF's that give these base parameters are those of physical bodies (mass > 0, pseudo-inertia positive definite:
    a density can have them) and of physical drives (rotor inertia, friction ≥ 0), and, given the record, whether the
    arm's mass matrix is positive definite at its poses and around them (:func:`check_poses`; it follows from the base
    parameters alone: where it is not, the estimate is no physical arm whatever its split, and a closed loop that
    goes there cannot be simulated)."""
    out = []
    if rec is not None:
        robot, d = _model_of(res.structure, res.base, theta_of(res))
        poses = check_poses(rec, robot)
        if not mass_matrix_positive(robot, d, poses, elastic_of(res.structure)):
            where = "at the record's own poses" if not mass_matrix_positive(robot, d, poses[:-POSE_DRAWS],
                                                                            elastic_of(res.structure)) else \
                f"at poses within {100 * POSE_MARGIN:.0f} % of each joint's range beyond the record's"
            out.append(f"the estimate's mass matrix is not positive definite {where}: no physical arm has these base "
                       "parameters, and a trajectory that goes there cannot be simulated with them (poorly excited "
                       "inertial parameters: a record that moves further would pin them down)")
    poor = sorted(((res.std[b] / abs(res.params[b]), b) for b in res.base.names
                   if res.params[b] != 0 and res.std.get(b, 0) > POOR_EXCITATION * abs(res.params[b])), reverse=True)
    if poor:
        out.append(f"{len(poor)} of {len(res.base.names)} base parameters are poorly excited (relative standard "
                   "deviation): " + "; ".join(f"{b} ±{100 * r:.0f} %" for r, b in poor[:8])
                   + ("; …" if len(poor) > 8 else "") + " (they change the torques little: another trajectory "
                   "would pin them down)")
    n = res.robot.ndof
    pi = standard_of(res)
    bad = []
    for j, name in enumerate(res.robot.joint_names):
        p = pi[n + 10 * j:n + 10 * j + 10]
        m, h = p[0], p[1:4]
        inertia = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
        pseudo = np.zeros((4, 4))
        pseudo[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
        pseudo[:3, 3] = pseudo[3, :3] = h
        pseudo[3, 3] = m
        if m <= 0 or np.min(np.linalg.eigvalsh(pseudo)) <= 0:
            bad.append(name)
    if bad:
        out.append("the standard parameters closest to the URDF's with these base parameters are not those of "
                   f"physical bodies for {', '.join(bad)} (mass or pseudo-inertia not positive): the base parameters "
                   "may still be right (they are what the torques fix), the URDF's split of them is not")
    for kind in ("Ia", "Fv", "Fc", "K", "D"):
        neg = [f"{kind}_{j} = {res.params[f'{kind}_{j}']:.4g}" for j in res.robot.joint_names
               if res.params.get(f"{kind}_{j}", 0.0) < 0]
        if neg:
            what = {"Ia": "rotor inertia", "Fv": "viscous friction", "Fc": "Coulomb friction", "K": "stiffness",
                    "D": "spring damping"}[kind]
            more = (" (a regrouped rotor inertia takes the URDF's values of the body parameters it is regrouped with: "
                    "those are off by at least this much)") if kind == "Ia" else ""
            out.append(f"negative {what}: {', '.join(neg)}{more}")
    return out


@serial_blas
def idim_ls(rec: Recording, model: Model) -> IdentificationResult:
    """IDIM-LS: the inverse dynamic model on the measured positions (zero-phase low-passed, differentiated twice),
    weighted least squares per joint, the rows where a joint moves slowly left out; the friction law's tail fitted
    with it (:func:`fit_law`), its shape through zero speed chosen in closed loop (:func:`closed_loop_law`) for the
    simulations of the result."""
    t0, sims0 = time.perf_counter(), _simulations()
    robot, offset = _check(rec, model)
    if model.elastic:
        raise DataError(f"idim-ls regresses the measured positions, and the link side of elastic joints "
                        f"({', '.join(model.elastic)}) is not what the encoders measure: use method 'didim' (the "
                        "three-step DIDIM simulates it)")
    base = base_parameters(robot)
    dec = _decimation(rec)
    q, v, a = _measured_states(rec, dec)
    inverse = _InverseModel(rec, model, base, q, v, a, dec)
    per_shape: Dict[str, Tuple[float, ...]] = {}
    law = fit_law(rec, inverse, per_shape)
    # the law through zero speed is the closed loop's to choose (the inverse model leaves out where it acts), each
    # shape compared with the parameters the inverse model gives with it

    def refit(lw: Law):
        return _model_of(model, base, inverse.fit(lw)[0])

    sim_law = law
    try:
        sim_law = closed_loop_law(rec, refit, law, per_shape)
    except SimulationError:
        pass
    # the parameters with the law the inverse model chose on the rows it fits (the law's tail); the closed loop's law
    # simulates them. Refitted with the closed loop's shape instead (at the inverse model's smoothing speeds for it),
    # the held-out 1 kHz Panda's slow fourth joint came out 17 % off: the closed loop of the regression's estimate,
    # itself a few percent off, chose exp for a truth of algebraic, which the inverse model had chosen
    theta, cov, _ = inverse.fit(law)
    res = _result("idim-ls", rec, model.with_law(sim_law), base, theta, cov)
    try:
        sim = simulate_robot(rec, res)
        res.force_error, res.force_error_per_joint = force_errors(rec, sim["force"])
    except SimulationError as e:
        res.notes.append(f"its closed loop cannot be simulated: {e}{_mismatch_hint(rec, robot)}")
    res.elapsed_s, res.simulations = time.perf_counter() - t0, _simulations() - sims0
    return res


#: A closed-loop force error above this (100 %: worse than predicting no force at all) is no start for DIDIM.
ABSURD_ERROR = 1.0


def _urdf_bodies_with_drives(theta_urdf: np.ndarray, theta_ls: np.ndarray, model: Model, base: BaseParameters
                             ) -> np.ndarray:
    """θ with the bodies' base parameters of ``theta_urdf`` (the URDF's values) and every drive parameter of
    ``theta_ls`` (IDIM-LS's estimate): the rotor inertias (a rigid joint's base parameter ``Ia_*``, regrouped with
    whatever body parameters it carries), the friction, the offsets, the springs and the terms."""
    names = _theta_names(model, base)
    nb = len(base.names)
    return np.array([theta_ls[i] if i >= nb or nm.startswith("Ia_") else theta_urdf[i] for i, nm in enumerate(names)])


def _model_of(model: Model, base: BaseParameters, theta: np.ndarray):
    """The robot with the standard parameters closest to the URDF's that give θ's base parameters, and its drives
    (rotor inertias, each joint's viscous and Coulomb friction and offset; with elastic joints, each joint's
    stiffness, infinite on rigid ones, and damping; with extra terms, each joint's list of (kind, hyper-parameters,
    value) as the core takes them)."""
    robot, offset, elastic = model.robot, model.offset, elastic_of(model)
    n, nb = robot.ndof, len(base.names)
    lay = _Layout.for_model(model, base)
    pi = base.standard_from(theta[:nb], np.concatenate([np.zeros(n), robot.inertial_params]))
    arm = pi[:n].copy()
    for e, j in enumerate(elastic):
        arm[j] = theta[lay.ia(e)]
    d: Dict[str, List[float]] = {
        "armature": list(arm), "viscous": list(theta[lay.fv(0):lay.fv(0) + n]),
        "coulomb": list(theta[lay.fc(0):lay.fc(0) + n]),
        "offset": list(theta[lay.of(0):lay.of(0) + n]) if offset else [0.0] * n}
    if elastic:
        d["stiffness"], d["damping"] = [math.inf] * n, [0.0] * n
        for e, j in enumerate(elastic):
            d["stiffness"][j], d["damping"][j] = float(theta[lay.k(e)]), float(theta[lay.d(e)])
    if model.terms:
        d["terms"] = [[] for _ in range(n)]
        for i, (j, t) in enumerate(joint_terms(model)):
            d["terms"][j].append((t.kind, list(t.hyper_values), float(theta[lay.t(i)])))
        d["term_values"] = [float(theta[lay.t(i)]) for i in range(len(lay.terms))]
    if model.backlash_gap is not None:
        d["backlash"] = list(model.gaps)
    if lay.load:
        d["load_friction"] = [0.0] * n
        for i, j in enumerate(lay.load):
            d["load_friction"][j] = float(theta[lay.fl(i)])
    return robot.with_inertial_params(pi[n:]), d


#: How far beyond the record's range of each joint :func:`check_poses` looks, as a share of that range on each side.
POSE_MARGIN = 0.25
#: Poses drawn in that box (beside the record's own).
POSE_DRAWS = 128


def check_poses(rec: Recording, robot: Robot) -> np.ndarray:
    """Poses at which an estimate's mass matrix must be positive definite: the record's own (its motor positions, at
    most 512 spread over it) and ``POSE_DRAWS`` drawn (with a fixed seed: the same for every call) in the box of each
    joint's range widened by ``POSE_MARGIN`` of it on each side, within the URDF's limits (a validation record moves
    elsewhere in the workspace than the training one; a physical arm's mass matrix is positive everywhere)."""
    q = np.asarray(rec.qm, dtype=float)
    own = q[np.linspace(0, len(q) - 1, min(len(q), 512)).astype(int)]
    lo, hi = q.min(axis=0), q.max(axis=0)
    span = hi - lo
    lim = np.array([(l[0], l[1]) for l in robot.limits], dtype=float)
    lo = np.maximum(lo - POSE_MARGIN * span, np.where(np.isfinite(lim[:, 0]), lim[:, 0], -np.inf))
    hi = np.minimum(hi + POSE_MARGIN * span, np.where(np.isfinite(lim[:, 1]), lim[:, 1], np.inf))
    lo, hi = np.minimum(lo, q.min(axis=0)), np.maximum(hi, q.max(axis=0))  # limits a record exceeds: its range
    drawn = lo + (hi - lo) * np.random.default_rng(0).random((POSE_DRAWS, q.shape[1]))
    return np.vstack([own, drawn])


def mass_matrix_positive(robot: Robot, d: Dict[str, List[float]], poses: np.ndarray,
                         elastic: Tuple[int, ...] = ()) -> bool:
    """Whether the mass matrix of ``robot`` with the drives ``d`` (its rigid joints' rotor inertias on the diagonal;
    an elastic joint's rotor moves on its own) is positive definite at every pose of ``poses``."""
    arm = np.asarray(d["armature"], dtype=float).copy()
    arm[list(elastic)] = 0.0
    m = robot.mass_matrix(poses) + np.diag(arm)
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(np.isfinite(m)))


class _RobotPlant:
    """A robot as DIDIM's loop (:func:`didim.methods.didim_loop.didim_loop`) sees it: θ holds the base parameters, each
    joint's viscous and Coulomb friction (and offset); the closed loop of the arm with the standard parameters
    closest to the URDF's that give θ's base parameters; the least squares weighted per joint on the rows where
    each joint moves; an estimate whose loop cannot be simulated (an articulated inertia not positive) is pulled
    back by the loop. Once settled, the friction law's shape and smoothing speeds are chosen in closed loop
    (:func:`closed_loop_law`) and the iterations go on until they settle again, each joint's ε estimated with the
    parameters where the closed loop kept the shape the tail chose (:func:`_fit`)."""

    def __init__(self, rec, model: Model, base, dec, law, per_shape, tol, say, held: Optional[Dict[int, float]] = None):
        self.rec, self.structure, self.robot, self.base, self.dec = rec, model, model.robot, base, dec
        self.held = dict(held or {})  # parameters held at given values (by index in θ): every fit keeps them
        self.offset = model.offset
        self.law, self.per_shape, self.tol, self.say = law, per_shape, tol, say
        self.n, self.nb = self.robot.ndof, len(base.names)
        self.elastic = elastic_of(model)
        self.lay = _Layout.for_model(model, base)
        self.tail_shape = law[0]  # the shape the inverse model chose on the rows the fits keep (the law's tail)
        # a law the model gives is held: neither chosen in closed loop nor its ε refined (the doctor's searches hold
        # the grown model's law while they compare sizes of an effect, as one axis's do)
        self.hold_law = model.law is not None
        self.law_chosen = self.hold_law
        self.inverses: List[Tuple[np.ndarray, Any, _InverseModel]] = []
        self.last: Optional[Tuple[np.ndarray, Law, Any]] = None  # the last simulation (θ, law, its outputs)
        self.free = list(range(self.lay.size))
        self.start_row = 0  # the decimated rows before the simulation joins the record, left out (set_start)
        self.skip = 0  # the same, in samples, left out of the output error
        self.norm = float(np.linalg.norm(rec.force))
        self.norms = np.maximum(np.sum(rec.force ** 2, axis=0), 1e-300)

    @property
    def relax_alternation(self) -> bool:
        """An elastic model's rows (each elastic joint's motor rows with its link's equation, :func:`_model_columns`)
        can overshoot their fixed point: :func:`didim_loop` takes half steps once its iterates alternate."""
        return bool(self.elastic)

    def set_start(self, theta: np.ndarray) -> None:
        """Leaves out of the fits and the output error the samples the simulation of ``theta`` takes to join a record
        that began elsewhere than at rest on its first reference (a log cut in a cruise: how long the arm cruised is
        not in the log; :func:`didim.methods.identification.settled_row`, the last joint to join setting it), as one axis's
        DIDIM does."""
        from .identification import settled_row

        try:
            q = self.simulate(theta)["q"]
        except (SimulationError, DataError):
            return
        self.start_row = settled_row(self.rec, q, self.dec)
        self.skip = min(self.start_row * self.dec.factor, self.rec.n - 2)
        self.norm = float(np.linalg.norm(self.rec.force[self.skip:]))
        self.norms = np.maximum(np.sum(self.rec.force[self.skip:] ** 2, axis=0), 1e-300)

    def model(self, theta: np.ndarray):
        """The robot with θ's standard parameters and its drives."""
        return _model_of(self.structure, self.base, theta)

    def simulate(self, theta: np.ndarray):
        key = (self.law, self.structure.backlash_gap)
        if self.last is not None and self.last[1] == key and np.array_equal(self.last[0], theta):
            return self.last[2]
        robot, d = self.model(theta)
        sim = _simulate(self.rec, robot, d, self.law)
        sim["law"] = self.law
        sim["backlash_gap"] = self.structure.backlash_gap
        self.last = (theta.copy(), key, sim)
        return sim

    def output_error(self, sim) -> float:
        """The joints' relative force errors in closed loop, their RMS (each joint counts alike, whatever its torque,
        as in the weighted least squares: by the whole force's error a wrist's rotor inertia drifted 24 % between two
        fits of the same UR5 record, its error from 0.46 % to 1.5 %, and the shoulders' torques did not see it)."""
        r = (self.rec.force - sim["force"])[self.skip:]
        return float(np.sqrt(np.mean(np.sum(r * r, axis=0) / self.norms)))

    def force_error(self, sim) -> float:
        """The whole force's relative error in closed loop (the result's ``force_error_after_start``)."""
        return float(np.linalg.norm((self.rec.force - sim["force"])[self.skip:]) / self.norm)

    def inverse(self, theta: np.ndarray, sim) -> _InverseModel:
        """The inverse model on the simulated states of θ (the last few kept: the law's search refits on the best
        iterate's)."""
        gaps = sim.get("backlash_gap")
        for th, g, im in self.inverses:
            if g == gaps and np.array_equal(th, theta):
                return im
        structure = replace(self.structure, backlash_gap=gaps)
        im = _InverseModel(self.rec, structure, self.base, sim["q"], sim["qd"], sim["qdd"], self.dec,
                           start_row=self.start_row, motor=_Motor.of(sim, self.elastic, structure.gaps),
                           chain=self.model(theta)[0] if self.lay.load else None, substitute=bool(self.elastic))
        self.inverses = [(theta.copy(), gaps, im)] + self.inverses[:3]
        return im

    def solve(self, theta: np.ndarray, sim) -> Dict[str, Any]:
        n, nb, rec = self.n, self.nb, self.rec
        inverse = self.inverse(theta, sim)
        if self.law_chosen and not self.hold_law and min(self.law[1]) > 0 and self.law[0] == self.tail_shape \
                and not self.elastic:
            # each joint's ε with the parameters, once the closed loop has confirmed the shape that the tail chose:
            # the fits keep the tail's rows, and a shape the closed loop chose against it has its ε set near zero speed
            theta_e, cov_e, _ = inverse.fit(self.law, coulomb=theta[nb + n:nb + 2 * n], held=self.held)
            step = theta_e[-n:]
            sd = np.sqrt(np.maximum(np.diag(cov_e)[-n:], 0.0))
            eps = np.asarray(self.law[1])
            moved = sd <= EPS_SIGMA_MAX * eps
            if np.any(moved):
                new = np.where(moved, np.clip(eps + step, eps / 2, 2 * eps), eps)
                self.law = (self.law[0], tuple(float(e) for e in new))
                self.say("the next iterate's smoothing speed ε = " + ", ".join(f"{e:.4g}" for e in new)
                         + f" {speed_unit(rec)} (the result keeps the law of the iterate it returns)")
        est, cov, res = inverse.fit(self.law, held=self.held)
        # a spring's damping is not negative: where the least squares ask for less than none, it is held at none and
        # the rest fitted again (the bound active for this iteration only). Shortening the step cannot keep it
        # there from an iterate at or near zero, and stopped step 3 on the flexrobots UR5 (the elbow's D, 4 % of
        # its critical damping, asked below zero by the torque noise that rings its mode) before it converged
        lay = self.lay
        below = {lay.d(e): 0.0 for e in range(lay.ne) if est[lay.d(e)] < 0 and lay.d(e) not in self.held}
        if below:
            est, cov, res = inverse.fit(self.law, held={**self.held, **below})
        return {"params": est, "covariance": cov, "std": np.sqrt(np.maximum(np.diag(cov), 0.0)), "law": sim["law"],
                "backlash_gap": sim.get("backlash_gap"), "force_errors": force_errors(rec, sim["force"]), **res}

    def physical(self, new: np.ndarray, old) -> bool:
        """Finite, and each elastic joint's rotor inertia and stiffness positive, its damping not negative (the
        loop pulls an iterate that is not back toward the best). The arm's mass matrix is not required positive
        beyond the poses the record's simulation visits (:func:`plausibility` reports it): required in a box around
        them, DIDIM on the held-out elastic Panda's rigid model stopped on steps it could not shorten into it."""
        lay = self.lay
        return bool(np.all(np.isfinite(new))) and all(
            new[lay.ia(e)] > 0 and new[lay.k(e)] > 0 and new[lay.d(e)] >= 0 for e in range(lay.ne))

    def converged(self, loop) -> bool:
        return residual_settled(loop, self.tol)

    def settled(self, loop) -> str:
        if self.law_chosen:
            return "accept"
        self.law_chosen = True
        best = loop.best[1]
        # where the simulation joins a record that began in motion, judged again on the settled estimate: the start's
        # (the URDF's values, no friction) can be too far off everywhere for its start to stand out
        start = self.start_row
        self.set_start(best)
        if self.start_row != start:
            self.inverses = []
            self.say(f"the simulation joins the record after {1e3 * self.skip * self.rec.dt:.0f} ms: the samples "
                     "before are left out of the fits")
        # each shape with the parameters one least squares gives with it on the best iterate's simulated states
        inverse = next((im for th, _, im in self.inverses if np.array_equal(th, best)), None)
        if inverse is None:
            inverse = self.inverse(best, self.simulate(best))

        def refit(lw: Law):
            return self.model(inverse.fit(lw, held=self.held)[0])

        if self.elastic and not self.per_shape:
            # an elastic model starts from its rigid step's law: each shape's smoothing speeds from the tail of the
            # elastic model's rows, for the closed loop to choose among
            fit_law(self.rec, inverse, self.per_shape)
        new_law = closed_loop_law(self.rec, refit, self.law, self.per_shape, self.say, current=self.model(best))
        if new_law != self.law or self.start_row != start:
            self.law = new_law
            return "restart"
        return "continue"

    def describe(self, loop) -> str:
        return f"DIDIM iteration {len(loop.history) - 1}: joints' force errors in closed loop, RMS {100 * loop.error:.3f} %"


def _start_error(plant: _RobotPlant, theta: np.ndarray) -> float:
    """The closed-loop force error of ``theta`` (infinite when its loop cannot be simulated); the plant keeps the
    simulation for its first iteration."""
    try:
        return plant.output_error(plant.simulate(theta))
    except (SimulationError, DataError):
        return math.inf


def _didim_run(rec, model, base, dec, theta, law, per_shape, max_iter, tol, say, plant=None, held=None):
    """DIDIM's iterations on the robot (:class:`_RobotPlant`) from ``theta``: the loop's outcome and the plant."""
    if plant is None:
        plant = _RobotPlant(rec, model, base, dec, law, per_shape, tol, say, held)
        plant.set_start(theta)
    return didim_loop(plant, theta, max_iter=max_iter, progress=say, give_up=_stalled(DIDIM_PATIENCE)), plant


@serial_blas
def didim(rec: Recording, model: Model, *, max_iter: int = 30, tol: float = 1e-3,
          progress: Optional[Callable[[str], None]] = None, start: Optional[IdentificationResult] = None,
          frozen: Optional[Dict[str, float]] = None, cutoff_hz: Optional[float] = None,
          rigid_cutoff_hz: Optional[float] = None) -> IdentificationResult:
    """DIDIM from the URDF's values (rotor inertias and friction 0): the closed loop simulated with the current
    estimate, weighted least squares of the measured force on the simulated states, until the regression's residual
    changes by less than ``tol`` of itself over a step (the paper's criterion (21), every plant's); the iterations and their safeguards are those of every plant (:func:`didim.methods.didim_loop.didim_loop`): an iterate whose
    loop cannot be simulated, or whose error rises above 1.5 times the best, is pulled back toward the best.

    When the URDF's values are no start (their closed loop cannot be simulated or is worse than predicting no force:
    a joint whose rotor inertia the controller was tuned for is far lighter without it, and its loop unstable), DIDIM
    starts from IDIM-LS's estimate; when the run from the URDF's values fails (an iterate that cannot be simulated
    even pulled back, or that is not physical) or ends where the closed loop fits worse than IDIM-LS's estimate as it
    is, it runs again from IDIM-LS's estimate and keeps the run that fits the training record better. The result says
    so.

    ``start``: a result of the same robot (the model it grows by a term, as the doctor does): DIDIM starts from its
    parameters where the model has them (a new term's at 0) instead of the URDF's values; with elastic joints, the
    three-step DIDIM's step 3 (:func:`didim_elastic`).

    ``frozen``: parameters (by their names in the result: base parameters, ``Fv_<joint>``, ...) held at the values
    given, the others fitted around them, as one axis's ``frozen``: e.g. a manufacturer's body parameters trusted and
    the drives' identified (a record too short to pin every body parameter: the KR300's). Their σ is 0; the result
    lists them in ``frozen`` too.

    ``cutoff_hz``: the parallel decimation's low-pass (Hz), below the default (ten times the reference's band): the
    rigid step of the three-step DIDIM fits the rigid model below the elastic joints' modes
    (:data:`RIGID_STEP_BELOW_MODES`; ``rigid_cutoff_hz`` sets it, as for one axis's three steps).

    A friction law in ``model`` (:meth:`didim.Model.with_law`: its shape and each joint's ε) is held, as one axis's
    ``coulomb_eps``; without one, the law is chosen by the inverse model and then in closed loop.
    """
    t0, sims0 = time.perf_counter(), _simulations()
    robot, offset = _check(rec, model)
    _checks.options(max_iter=max_iter, tol=tol, cutoff_hz=cutoff_hz, rigid_cutoff_hz=rigid_cutoff_hz)
    if rigid_cutoff_hz is not None and not model.elastic:
        raise DataError("rigid_cutoff_hz is the rigid step's low-pass in the three-step DIDIM of a robot with elastic "
                        "joints; this model has none: give cutoff_hz for a rigid robot's decimation")
    if model.elastic:
        # a rigid start of the same model is step 1's result; an elastic one, step 3's start
        rigid = start if start is not None and not start.structure.elastic and start.structure.terms == model.terms \
            and start.offset == model.offset and start.structure.robot is robot else None
        return didim_elastic(rec, model, max_iter=max_iter, tol=tol, progress=progress, rigid=rigid,
                             start=None if rigid is not None else start, frozen=frozen,
                             rigid_cutoff_hz=rigid_cutoff_hz)
    say = progress or (lambda s: None)
    base = base_parameters(robot)
    dec = _decimation(rec, cutoff_hz)
    measured = _InverseModel(rec, model, base, *_measured_states(rec, dec), dec)
    per_shape: Dict[str, Tuple[float, ...]] = {}
    if model.law is not None:  # held (see _RobotPlant.hold_law)
        law = model.law  # one ε per joint (_check)
        say("friction law through zero speed, held: " + friction_law.describe(law, speed_unit(rec)))
    else:
        law = fit_law(rec, measured, per_shape)
        say("friction law through zero speed, by the inverse model: " + friction_law.describe(law, speed_unit(rec)))
    n = robot.ndof
    pi0 = np.concatenate([np.zeros(n), robot.inertial_params])
    theta0 = np.concatenate([base.of(pi0), np.zeros(_Layout.for_model(model, base).size - len(base.names))])
    origin = "the URDF's values"
    if start is not None and start.structure.robot is robot and not start.structure.elastic \
            and tuple(start.base.names) == tuple(base.names):
        theta0 = np.array([start.params.get(k, 0.0) for k in _theta_names(model, base)])
        origin = "its start (the result given)"
        say("DIDIM starts from the model it grows")
    held = _held(model, base, frozen)
    theta0[list(held)] = list(held.values())
    notes: List[str] = []
    if held:
        notes.append(f"{len(held)} parameter(s) held at the values given (frozen), the others fitted around them")
    # a start whose closed loop is worse than predicting no force (or cannot be simulated) is no start: DIDIM begins
    # at IDIM-LS's estimate instead, without iterating from it first
    first = _RobotPlant(rec, model, base, dec, law, per_shape, tol, say, held)
    first.set_start(theta0)
    e0 = _start_error(first, theta0)
    theta_ls = None
    if e0 > ABSURD_ERROR and start is None:
        # a URDF carries the bodies, not the drives: with no rotor inertia, friction or offset the loop can run away
        # (a held-out Panda under cascades: 10534 %). The bodies of the URDF with the drives' parameters of IDIM-LS's
        # estimate are a start whose bodies are physical at every pose; from IDIM-LS's estimate alone DIDIM can end
        # where the bodies are no physical arm at poses the record did not visit (that Panda's backlash record: its
        # validation record could not be simulated, and nothing was judged; from this start it names the backlash,
        # 21.35 -> 6.13 % held out)
        theta_ls = measured.fit(law, held=held)[0]
        hybrid = _urdf_bodies_with_drives(theta0, theta_ls, model, base)
        mixed = _RobotPlant(rec, model, base, dec, law, per_shape, tol, say, held)
        mixed.set_start(hybrid)
        e_mixed = _start_error(mixed, hybrid)
        if e_mixed <= ABSURD_ERROR:
            why = (f"their closed-loop force error is {100 * e0:.0f} %" if math.isfinite(e0)
                   else "their closed loop cannot be simulated")
            say(f"DIDIM starts from the URDF's bodies with IDIM-LS's drive parameters: not from {origin} ({why})")
            notes.append(f"DIDIM started from the URDF's bodies with the drives' parameters (rotor inertias, friction, "
                         f"offsets, terms) of IDIM-LS's estimate, not from {origin} ({why})")
            theta0, first, e0 = hybrid, mixed, e_mixed
            origin = "the URDF's bodies with IDIM-LS's drives"
    if e0 > ABSURD_ERROR:
        why = (f"their closed-loop force error is {100 * e0:.0f} %" if math.isfinite(e0)
               else "their closed loop cannot be simulated")
        say(f"DIDIM starts from IDIM-LS's estimate: not from {origin} ({why})")
        notes.append(f"DIDIM started from IDIM-LS's estimate, not from {origin} ({why})")
        run, plant = _didim_run(rec, model, base, dec, measured.fit(law, held=held)[0], law, per_shape, max_iter,
                                tol, say, held=held)
    else:
        run, plant = _didim_run(rec, model, base, dec, theta0, law, per_shape, max_iter, tol, say, plant=first)
        failed = run.best[2] is None or (not run.converged and not run.message.startswith("no convergence"))
        why = f"failed ({run.message})" if failed else ""
        ls = None
        if theta_ls is None and (failed or start is None):
            theta_ls = measured.fit(law, held=held)[0]
        if not failed and start is None:
            # DIDIM is a fixed-point iteration: from the URDF's values it can settle where the closed loop fits worse
            # than IDIM-LS's estimate as it is (held-out Panda records: 6.1-6.5 % against about 2 %, its bodies not
            # physical at the validation record's poses); such an end is no result while the other start is better
            ls = _RobotPlant(rec, model, base, dec, law, per_shape, tol, say, held)
            ls.set_start(theta_ls)
            e_ls = _start_error(ls, theta_ls)  # the plant keeps this simulation for its first iteration
            if e_ls < run.best[0]:
                why = (f"ended at joints' force errors RMS {100 * run.best[0]:.3g} %, above IDIM-LS's estimate's "
                       f"{100 * e_ls:.3g} % in closed loop")
        if why:
            say(f"DIDIM from {origin} {why}: again from IDIM-LS's estimate")
            again, plant_again = _didim_run(rec, model, base, dec, theta_ls, law, per_shape, max_iter, tol, say,
                                            plant=ls, held=held)
            if again.best[2] is not None and (run.best[2] is None or again.best[0] < run.best[0]):
                notes.append(f"DIDIM from {origin} {why}; it started from IDIM-LS's estimate")
                run, plant = again, plant_again
    if run.best[2] is None:
        raise SimulationError(f"DIDIM could not simulate the robot's closed loop: {run.message}"
                              f"{_mismatch_hint(rec, robot)}")
    err, theta, sol, _ = run.best
    res = _result("didim", rec, model.with_law(sol["law"]), base, theta, sol["covariance"], converged=run.converged,
                  iterations=len(run.history), message="" if run.converged else run.message,
                  history=iterations_of(run.errors), notes=notes + start_notes(plant.start_row, dec, rec, "the fits", option=False)
                  + run.notes)
    res.force_error, res.force_error_per_joint = sol["force_errors"]
    if plant.skip:
        res.start_s, res.force_error_after_start = plant.skip * rec.dt, plant.force_error(plant.simulate(theta))
    res.elapsed_s, res.simulations = time.perf_counter() - t0, _simulations() - sims0
    names = _theta_names(model, base)
    res.frozen = {names[i]: float(v) for i, v in held.items()}
    return res


def frozen_for(model: Model, frozen: Dict[str, float]) -> Dict[str, float]:
    """The parameters of ``frozen`` that ``model`` has (its rigid or elastic base, its drives and terms): what a refit
    of a grown model holds of a result's ``frozen`` (an elastic joint's rotor is its own parameter there, so a base
    parameter that regrouped it with body parameters is not the elastic model's)."""
    base = base_parameters(model.robot, elastic=elastic_of(model))
    names = set(_theta_names(model, base))
    return {k: v for k, v in (frozen or {}).items() if k in names}


def _held(model: Model, base: BaseParameters, frozen: Optional[Dict[str, float]]) -> Dict[int, float]:
    """``frozen`` (parameter names → values) as indices in θ; an unknown name or a value that is not a finite number
    is refused, naming it."""
    if not frozen:
        return {}
    if not isinstance(frozen, dict):
        raise DataError(f"frozen is a dict of parameter names and values (e.g. {{'Fv_joint_1': 2.0}}), got "
                        f"{type(frozen).__name__}")
    names = _theta_names(model, base)
    unknown = [k for k in frozen if k not in names]
    if unknown:
        raise DataError(f"frozen names parameter(s) the model does not have: {', '.join(map(str, unknown[:5]))}"
                        f"{' …' if len(unknown) > 5 else ''}; its parameters are {', '.join(names[:8])}, … (a "
                        "result's params and base.names)")
    held = {}
    for k, v in frozen.items():
        try:
            x = float(v)
        except (TypeError, ValueError):
            x = math.nan
        if not math.isfinite(x):
            raise DataError(f"frozen value of {k} must be a finite number, got {v!r}")
        held[names.index(k)] = x
    if len(held) == len(names):
        raise DataError("frozen holds every parameter of the model: nothing is left to identify")
    return held


# ------------------------------------------------------------------------------------------------ elastic joints

#: Step 2's grid, eq. (28) for every elastic joint at once: the share λ of the joint's inertia at mid-stroke on its
#: motor side, and its locked-rotor mode from fs/100 to fs/12.5, geometric (the paper's [0.1, 0.9] and [10, 80] Hz at
#: the EMPS's 1 kHz). Each joint takes the grid point where its own force error is least.
ELASTIC_GRID_LAMBDA = (0.1, 0.3, 0.5, 0.7, 0.9)
#: Step 2's search keeps each rotor's share λ within [this, 1 - this]
SPLIT_LAMBDA_BOUND = 1e-3
ELASTIC_GRID_F_SHARE = tuple(float(x) for x in np.geomspace(1 / 100, 1 / 12.5, 8))
#: The springs' damping ratio where step 2 starts (a transmission's is 1-5 %).
ELASTIC_ZETA0 = 0.03
#: Step 2's model damps each spring at most this share of critical (:meth:`_ElasticSplit.theta`): a ratio of 1 or
#: more is no oscillation, which :func:`no_mode` reports as no mode the record shows, and a search that wandered
#: beyond (the held-out UR10 with a shared excitation: its wrist at ζ ≈ 2.3, then about 50, D = 19,296 N·m·s/rad
#: against a link of 0.017 kg·m²) simulated a loop so stiff in its damping that one simulation took up to 136 s
#: against 0.1 s. Beyond it the criterion is flat in ζ (a cap in the model, not a bound of the least squares, whose
#: scaling near a bound would change their path where ζ never comes near it).
ELASTIC_ZETA_MAX = 1.0


def _own_inertia(robot: Robot, j: int, q: np.ndarray) -> Tuple[int, float]:
    """The standard parameter of joint ``j``'s own body that adds most to its inertia ``M_jj`` at ``q`` (the moment
    about its axis: Iyy for a y axis; the mass for a prismatic joint), as an index among the standard parameters
    (rotor inertias first), and its coefficient in ``M_jj``."""
    n = robot.ndof
    zero, unit = np.zeros(n), np.eye(n)[j]
    row = robot.regressor(q[None], zero[None], unit[None])[0, j] - robot.regressor(q[None], zero[None], zero[None])[0, j]
    body = row[10 * j:10 * j + 10]
    cand = [0] + list(range(4, 10))  # the mass or an inertia of the body
    k = max(cand, key=lambda c: abs(body[c]))
    return n + 10 * j + k, float(body[k])


class _ElasticSplit:
    """Step 2's model, the paper's eqs. (23)-(27) for each elastic joint j: a model's standard parameters (a rigid
    step's, or an elastic model's) with the joint split at (λ_j, f_j, ζ_j): its total inertia at mid-stroke T_j (its
    rotor's and its chain's, M_jj(q_mid)) kept (or scaled by s_j, a row's fourth value when given: see
    :meth:`search`), the rotor's share λ_j T_j, the rest its own body's (the moment about its
    axis, :func:`_own_inertia`: where the rigid step regrouped its rotor inertia with that moment, the rigid dynamics
    are unchanged); K_j = M_jj(q_mid) (2π f_j)² and D_j = 2 ζ_j √(K_j M_jj) with the split chain's M_jj (f_j is the
    joint's locked-rotor mode there, ζ_j its damping ratio); the friction and offsets the model's, on the motor side
    (eq. (27): all friction on the motor)."""

    def __init__(self, rec: Recording, model: Model, pi: np.ndarray, drives: Dict[str, List[float]],
                 keep_chain: bool = False):
        robot, elastic = model.robot, elastic_of(model)
        self.rec, self.model, self.robot, self.elastic, self.offset = rec, model, robot, elastic, model.offset
        self.pi1, self.d1 = np.asarray(pi, dtype=float), drives
        n = robot.ndof
        self.qmid = 0.5 * (rec.qm.min(axis=0) + rec.qm.max(axis=0))
        chain = robot.with_inertial_params(self.pi1[n:])
        m = chain.mass_matrix(self.qmid)
        self.total = np.array([self.pi1[j] + m[j, j] for j in elastic])
        self.partner = [_own_inertia(chain, j, self.qmid) for j in elastic]
        # a partner that gravity acts on (a prismatic joint's mass on a vertical axis): the rigid step fixed it by the
        # static force it carries, not by the inertia the motor sees; moving the rotor's share into it would change the
        # weight the joint holds (the vertical lift's rigid step: 17.2 kg from gravity, 10.5 kg seen by the motor above
        # the belt's mode, and every split of that total needed a negative mass). Such a joint keeps its chain and
        # takes its rotor from λ alone: Ia = λ/(1 − λ) M_jj(q_mid).
        grav = chain.regressor(self.qmid[None], np.zeros((1, n)), np.zeros((1, n)))[0]
        g = max(float(np.linalg.norm(chain.gravity_vector)), 1e-300)
        self.holds = [keep_chain or bool(np.max(np.abs(grav[:, c - n])) > 1e-9 * g) for c, _ in self.partner]
        self.chain_jj = np.array([m[j, j] for j in elastic])
        self.base = base_parameters(robot, elastic=elastic)
        self.lay = _Layout.for_model(model, self.base)

    @classmethod
    def of_rigid(cls, rec: Recording, rigid: IdentificationResult, model: Model) -> "_ElasticSplit":
        """The split of the rigid step's result ``rigid`` into the elastic ``model`` (its structure but the springs);
        where the rigid step held body parameters (``frozen``), every joint keeps its chain."""
        chain, d = _model_of(rigid.structure, rigid.base, theta_of(rigid))
        held_bodies = any(k in rigid.base.bodies_only for k in rigid.frozen)
        return cls(rec, model, np.concatenate([d["armature"], chain.inertial_params]), d, keep_chain=held_bodies)

    @classmethod
    def of_elastic(cls, rec: Recording, plant: "_RobotPlant", theta: np.ndarray) -> "_ElasticSplit":
        chain, d = plant.model(theta)
        held_bodies = any(i < plant.nb and plant.base.names[i] in plant.base.bodies_only for i in plant.held)
        return cls(rec, plant.structure, np.concatenate([d["armature"], chain.inertial_params]), d,
                   keep_chain=held_bodies)

    def x_of(self, theta: np.ndarray) -> np.ndarray:
        """Each elastic joint's (λ, f, ζ) in an elastic model's θ (of this split's layout)."""
        n, lay = self.robot.ndof, self.lay
        pi = self.base.standard_from(theta[:lay.nb], np.concatenate([np.zeros(n), self.robot.inertial_params]))
        m = self.robot.with_inertial_params(pi[n:]).mass_matrix(self.qmid)
        out = np.zeros((len(self.elastic), 3))
        for e, j in enumerate(self.elastic):
            k, ia = theta[lay.k(e)], theta[lay.ia(e)]
            out[e] = (ia / (ia + m[j, j]), math.sqrt(k / m[j, j]) / (2 * math.pi),
                      theta[lay.d(e)] / (2 * math.sqrt(k * m[j, j])))
        return out

    def modes(self, x: np.ndarray) -> Dict[str, Dict[str, float]]:
        """Each elastic joint's row of ``x`` (λ, f in Hz, ζ) by name, with the mid-stroke position it is taken at:
        a result's ``options["modes"]``."""
        return {self.robot.joint_names[j]: {"lambda": float(x[e, 0]), "f_n_flex": float(x[e, 1]),
                                            "zeta": float(x[e, 2]), "q_mid": float(self.qmid[j])}
                for e, j in enumerate(self.elastic)}

    def theta(self, x: np.ndarray) -> np.ndarray:
        """θ of the elastic model (:class:`_Layout`) at ``x`` (one row (λ, f in Hz, ζ) per elastic joint, or
        (λ, f, ζ, s) with its total inertia's factor s)."""
        n, lay = self.robot.ndof, self.lay
        pi = self.pi1.copy()
        for e, j in enumerate(self.elastic):
            if self.holds[e]:
                pi[j] = x[e, 0] / (1 - x[e, 0]) * self.chain_jj[e]
                continue
            scale = x[e, 3] if x.shape[1] > 3 else 1.0
            ia = x[e, 0] * scale * self.total[e]
            c, coef = self.partner[e]
            pi[c] += ((scale - 1) * self.total[e] + pi[j] - ia) / coef
            pi[j] = ia
        m = self.robot.with_inertial_params(pi[n:]).mass_matrix(self.qmid)
        th = np.zeros(lay.size)
        th[:lay.nb] = self.base.of(pi)
        for j in range(n):
            th[lay.fv(j)], th[lay.fc(j)] = self.d1["viscous"][j], self.d1["coulomb"][j]
            if self.offset:
                th[lay.of(j)] = self.d1["offset"][j]
        for i in range(len(lay.terms)):
            th[lay.t(i)] = self.d1["term_values"][i]
        for i, j in enumerate(lay.load):
            th[lay.fl(i)] = self.d1["load_friction"][j]
        for e, j in enumerate(self.elastic):
            th[lay.ia(e)] = pi[j]
            k = m[j, j] * (2 * math.pi * x[e, 1]) ** 2
            # the damping at most ELASTIC_ZETA_MAX of critical: beyond, no oscillation is left to fit, only a stiffer loop
            zeta = min(float(x[e, 2]), ELASTIC_ZETA_MAX)
            th[lay.k(e)], th[lay.d(e)] = k, 2 * zeta * math.sqrt(max(k * m[j, j], 0.0))
        return th

    def errors(self, x: np.ndarray, law: Law) -> Optional[np.ndarray]:
        """Each joint's relative force error in closed loop at ``x``; None where the loop cannot be simulated."""
        if not (np.all(x[:, 0] > 0) and np.all(x[:, 0] < 1) and np.all(x[:, 1] > 0) and np.all(x[:, 2] >= 0)):
            return None
        try:
            robot, d = _model_of(self.model, self.base, self.theta(x))
            sim = _simulate(self.rec, robot, d, law)
        except (SimulationError, DataError):
            return None
        r = np.linalg.norm(self.rec.force - sim["force"], axis=0) / np.maximum(np.linalg.norm(self.rec.force, axis=0),
                                                                                1e-300)
        return r if np.all(np.isfinite(r)) else None

    def search(self, x0: np.ndarray, law: Law, sims: List[int], totals: bool = False) -> Tuple[np.ndarray, float]:
        """Least squares of the elastic joints' relative force residuals over every elastic joint's (λ, ln f, ζ) from
        ``x0``, and each dead zone's ln b from the model's width (:func:`_spring_search`, :func:`_joints_error`): the
        best rows, and the widths found in the split's ``model``. A width acts on the force through the states it
        shapes, as the mode does: it is step 2's, by the closed loop, and step 3's DIDIM holds it (the inverse
        model's derivative in b at the simulated states, a Gauss–Newton column as ε's, held a width started at 2
        mrad on the held-out Panda with 3 mrad: its force at those states hardly depends on it).

        ``totals``: each elastic joint's total inertia at mid-stroke T_j too, as a factor s_j of the model's (a fourth
        column of the rows; a joint that keeps its chain has none): a rotor that carries most of its joint's inertia
        leaves its link (1 − λ)T_j, and T_j a few per cent off is that link, and the spring carrying it, several
        times as far off; DIDIM keeps the link's inertia where the split put it (its link rows fit the simulated
        states exactly), so the rounds' step 2 fits it where the mode shows it (the held-out UR10's wrist 1, its
        rotor 88 % of the joint: K +7.6 → +4.3 %; the flexrobots UR5's elbow +4.9 → +1.9 %). Step 2 from the rigid
        step keeps T_j (measured with it there too: the UR10's wrist +4.7 %, with the shared excitation +6.8 %
        against +9.0 % from the rounds alone; not kept: one more column in every first search, the robot doctor's
        screens' included, for a gain on one record of the two)."""
        ne, fs = len(self.elastic), 1 / self.rec.dt
        gapped = [j for j in self.elastic if self.model.gaps[j] > 0] if self.model.backlash_gap is not None else []

        tot = [e for e in range(ne) if not self.holds[e]] if totals else []
        ng = len(gapped)

        def unpack(u: np.ndarray) -> Tuple[np.ndarray, Model]:
            x = np.column_stack([u[0:3 * ne:3], np.exp(u[1:3 * ne:3]), u[2:3 * ne:3]])
            if tot:
                scale = np.ones(ne)
                scale[tot] = np.exp(u[3 * ne + ng:])
                x = np.column_stack([x, scale])
            if not gapped:
                return x, self.model
            gaps = list(self.model.gaps)
            for i, j in enumerate(gapped):
                gaps[j] = float(np.exp(u[3 * ne + i]))
            return x, replace(self.model, backlash_gap=tuple(gaps))

        def model_of(u: np.ndarray):
            x, model = unpack(u)
            return _model_of(model, self.base, self.theta(x))

        u0 = np.concatenate([np.column_stack([x0[:, 0], np.log(x0[:, 1]), x0[:, 2]]).ravel(),
                             np.log([self.model.gaps[j] for j in gapped]), np.zeros(len(tot))])
        lower = np.concatenate([np.tile([SPLIT_LAMBDA_BOUND, -np.inf, 0.0], ne), np.full(len(gapped), -np.inf),
                                np.full(len(tot), -TOTAL_LOG_BOUND)])
        upper = np.concatenate([np.tile([1 - SPLIT_LAMBDA_BOUND, math.log(0.5 * fs), np.inf], ne),
                                np.full(len(gapped), np.inf), np.full(len(tot), TOTAL_LOG_BOUND)])
        # a start at a bound (a mode at the Nyquist frequency: a joint the record shows rigid) inside it, as the
        # least squares need (a step 3 that ran to 499.99 Hz at 1 kHz stopped the held-out Panda's doctor)
        span = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
        u0 = np.clip(u0, lower + 1e-6 * span, upper - 1e-6 * span)
        u, best = _spring_search(self.rec, model_of, u0, lower, upper, law, sims, self.elastic)
        x, self.model = unpack(u)
        return x, best


def _joints_error(per: Optional[np.ndarray], joints: Optional[Sequence[int]] = None) -> float:
    """The RMS of the joints' relative force errors (each joint counts alike, whatever its torque), of ``joints``
    only when given; infinite where the loop cannot be simulated.

    Step 2's criterion is the elastic joints' (the paper's criterion (25) is one axis's force): the rigid joints'
    errors hold what step 1's rigid chain, fitted below the modes, got wrong, and a spring can lower them through the
    chain's coupling without being the joint's. On the held-out UR10 (PID, 500 Hz), wrist 1's own error was least at
    22 Hz on the grid (truth 21 Hz), but every joint's RMS fell as it stiffened (1.394 % at 22 Hz, 1.383 % at 100
    Hz): the search ended at 240 Hz, "no mode"."""
    if per is None:
        return math.inf
    per = per if joints is None else per[list(joints)]
    return float(np.sqrt(np.mean(per ** 2)))


def _residuals(rec: Recording, sim: Dict[str, np.ndarray], joints: Optional[Sequence[int]] = None) -> np.ndarray:
    """Each joint's force residual over its norm, over √n (of ``joints`` only when given, n their count): the vector
    whose norm is :func:`_joints_error` of the simulation."""
    cols = slice(None) if joints is None else list(joints)
    force, simf = rec.force[:, cols], sim["force"][:, cols]
    norms = np.maximum(np.linalg.norm(force, axis=0), 1e-300)
    return ((force - simf) / norms / math.sqrt(force.shape[1])).ravel(order="F")


#: Step 2's Levenberg-Marquardt (scipy's trust-region reflective) on the elastic joints' (λ, ln f, ζ): the relative
#: step of its finite differences, and its stopping tolerance on the criterion and on the step (relative).
SPRING_FD_STEP = 1e-3
SPRING_TOL = 1e-4
SPRING_MAX_ITER = 25


def _output_least_squares(rec: Recording, simulate_u: Callable[[np.ndarray], Dict[str, np.ndarray]], u0: np.ndarray,
                          lower: np.ndarray, upper: np.ndarray, sims: List[int], max_nfev: int = 0,
                          joints: Optional[Sequence[int]] = None,
                          sensitivities: Optional[Callable[[np.ndarray], np.ndarray]] = None):
    """Least squares of the joints' relative force residuals in closed loop (:func:`_residuals`) over ``u``, the loop
    ``simulate_u(u)`` (simulated without encoder quantization: see :func:`_simulate`): scipy's trust-region
    reflective Levenberg-Marquardt within the bounds. Its Jacobian: ``sensitivities(u)``, the exact ``∂force/∂u``
    (n, len(u), N) of the loop, when given (a loop whose sensitivities cannot be computed falls back to differences);
    otherwise forward differences of relative step :data:`SPRING_FD_STEP`, simulated in parallel. Returns scipy's
    result (``x``, ``fun``, ``jac``, ``nfev``)."""
    from .._parallel import cores, map_threads
    from scipy.optimize import least_squares

    cache: Dict[bytes, np.ndarray] = {}
    nj = rec.ndof if joints is None else len(joints)
    bad = np.full(rec.n * nj, 1.0 / math.sqrt(nj))  # a loop that cannot be simulated: 100 % per joint

    def res(u: np.ndarray) -> np.ndarray:
        key = np.asarray(u, dtype=float).tobytes()
        if key not in cache:
            sims[0] += 1
            try:
                cache[key] = _residuals(rec, simulate_u(np.asarray(u, dtype=float)), joints)
            except (SimulationError, DataError):
                cache[key] = bad
            if len(cache) > 8:
                cache.pop(next(iter(cache)))
        return cache[key]

    kept = list(range(rec.ndof)) if joints is None else list(joints)
    norms = np.maximum(np.linalg.norm(rec.force[:, kept], axis=0), 1e-300)

    def jac(u: np.ndarray) -> np.ndarray:
        if sensitivities is not None:
            try:
                dforce = sensitivities(np.asarray(u, dtype=float))[kept]  # (nj, p, N)
            except (SimulationError, DataError):
                pass
            else:
                sims[0] += 1
                # the residual's order (_residuals): joint by joint, each over its samples
                scaled = -dforce / norms[:, None, None] / math.sqrt(nj)
                return scaled.transpose(0, 2, 1).reshape(nj * rec.n, len(u))
        r0 = res(u)
        steps = SPRING_FD_STEP * np.maximum(np.abs(u), 1.0)
        steps = np.where(u + steps > upper, -steps, steps)

        def column(k: int) -> np.ndarray:
            du = np.zeros(len(u))
            du[k] = steps[k]
            return (res(u + du) - r0) / steps[k]

        cols = map_threads(column, range(len(u)), cores())
        return np.column_stack(cols)

    return least_squares(res, u0, jac=jac, bounds=(lower, upper), method="trf", x_scale="jac", ftol=SPRING_TOL,
                         xtol=SPRING_TOL, gtol=None, max_nfev=max_nfev or SPRING_MAX_ITER)


#: :func:`polish_joint`: its evaluations of the Jacobian at most (a handful of parameters: it settles in 2-4).
POLISH_MAX_ITER = 20


def polish_joint(rec: Recording, res: IdentificationResult, joint: int, extra: Sequence[str] = ()
                 ) -> IdentificationResult:
    """``res`` with one joint's own parameters fitted to the output error of that joint: its viscous and Coulomb
    friction, offset and rotor inertia where they are parameters of ``res`` (a regrouped rotor inertia is not: it
    lives in a base parameter of the bodies), its friction smoothing speed, and the parameters named in ``extra``
    (a term's on that joint): :func:`oe_lm` from ``res`` on those parameters and that joint's residual alone; every
    other parameter held, and those ``res`` holds (its ``frozen``). DIDIM's fixed
    point is not the output-error optimum when the loop is noisy (a 7-joint arm under cascades with torque noise inside
    the loop: 1.1-1.6 times each joint's floor where OE-LM reaches 0.98-1.03), and a term compared with it gains from
    that difference; compared at this optimum, on the same joint, only what the term itself adds counts."""
    jn = res.robot.joint_names[joint]
    held = set(getattr(res, "frozen", None) or {})  # what the caller holds stays held
    own = [nm for nm in _theta_names(res.structure, res.base)
           if (nm in (f"Fv_{jn}", f"Fc_{jn}", f"OF_{jn}", f"Ia_{jn}") or nm in set(extra)) and nm not in held]
    return oe_lm(rec, res.structure, start=res, free=own, joints=[joint], max_iter=POLISH_MAX_ITER)


def _spring_search(rec: Recording, model_of_u, u0: np.ndarray, lower: np.ndarray, upper: np.ndarray, law: Law,
                   sims: List[int], joints: Sequence[int]) -> Tuple[np.ndarray, float]:
    """:func:`_output_least_squares` of the residuals of ``joints`` over ``u``, the robot and drives
    ``model_of_u(u)`` under ``law``: the best ``u`` and its criterion."""

    def simulate_u(u: np.ndarray) -> Dict[str, np.ndarray]:
        robot, d = model_of_u(u)
        return _simulate(rec, robot, d, law, quantize=False)

    out = _output_least_squares(rec, simulate_u, u0, lower, upper, sims, joints=joints)
    return out.x, float(np.linalg.norm(out.fun))


def elastic_modes(rec: Recording, rigid: IdentificationResult, model: Model, say=None, search: bool = True,
                  start=None, width_starts: Sequence[float] = (1.0,)) -> Tuple[np.ndarray, _ElasticSplit, Dict[str, Any]]:
    """Step 2 for a robot's elastic joints: from eq. (28)'s grid (every joint at once, each taking the point where its
    own force error is least), the least squares of the joints' relative closed-loop force residuals over every
    elastic joint's (λ, ln f, ζ) at once (:func:`_spring_search`: Levenberg-Marquardt, where the paper's Nelder-Mead
    searched one joint's two; the criterion is the paper's (25), the RMS of the joints' relative force errors).
    Returns each joint's (λ, f in Hz, ζ), the split model, and the search's record (criterion, simulations).
    ``search=False``: the grid's best point alone (its criterion; no least squares): a screen for a mode. ``start``:
    the grid's best point when it is known (that screen's, one row (λ, f, ζ) per elastic joint): the search starts
    there and the grid is not run again. ``width_starts``: with dead zones in ``model``, the least squares run from
    each of their widths times these factors, the best kept (:data:`WIDTH_STARTS`)."""
    from .._parallel import cores, map_threads

    say = say or (lambda s: None)
    split = _ElasticSplit.of_rigid(rec, rigid, model)
    elastic = split.elastic
    law = rigid.law if rigid.law is not None else _default_law(rec)
    ne, fs = len(elastic), 1 / rec.dt
    names = [rigid.robot.joint_names[j] for j in elastic]
    sims = [0]

    def errors(x):
        sims[0] += 1
        return split.errors(x, law)

    grid = [(lam, share * fs) for lam in ELASTIC_GRID_LAMBDA for share in ELASTIC_GRID_F_SHARE]
    # joints already elastic in the start (an elastic result: the doctor screening one more joint) keep their split
    held = {e: rigid.options["modes"][nm] for e, nm in enumerate(names) if nm in rigid.structure.elastic}
    if held and start is None and not search:
        x = np.array([[held[e]["lambda"], held[e]["f_n_flex"], held[e]["zeta"]] if e in held
                      else [0.5, 0.1 * fs, ELASTIC_ZETA0] for e in range(ne)])
        free = [e for e in range(ne) if e not in held]
        best = _grid_each(x, free, grid, errors, elastic)
        say("step 2 start (eq. (28)'s grid, the joints added at their best points): " + "; ".join(
            f"{names[e]} λ = {x[e, 0]:.2f}, f = {x[e, 1]:.1f} Hz" for e in free))
        return x, split, {"criterion": best, "simulations": sims[0]}
    if held:
        raise DataError("step 2 from an elastic result screens the joints it adds (search=False); the three steps "
                        "start from the rigid model's result")
    if start is not None:
        x = np.asarray(start, dtype=float)
        if x.shape != (ne, 3):
            raise DataError(f"step 2's start holds one row (λ, f in Hz, ζ) per elastic joint ({ne}), got shape "
                            f"{x.shape}")
        return _step2_search(split, x, law, names, sims, say)
    points = [np.array([[lam, f, ELASTIC_ZETA0]] * ne) for lam, f in grid]
    got = map_threads(errors, points, min(len(points), cores()))
    if all(g is None for g in got):
        hint = units_hint(rec, model.robot)
        raise SimulationError(
            f"step 2: no point of eq. (28)'s grid (λ {ELASTIC_GRID_LAMBDA[0]}-{ELASTIC_GRID_LAMBDA[-1]}, locked-rotor "
            f"modes {ELASTIC_GRID_F_SHARE[0] * fs:.3g}-{ELASTIC_GRID_F_SHARE[-1] * fs:.3g} Hz) of "
            f"{', '.join(names)} gives a closed loop that can be simulated with the rigid step's estimate: the loop is "
            "unstable with any such spring (check the controller's gains and the rigid step's fit; its force error "
            f"was {100 * rigid.force_error:.1f} %)" + (f"; {hint}" if hint else ""))
    x = np.zeros((ne, 3))
    for e, j in enumerate(elastic):
        vals = [g[j] if g is not None else math.inf for g in got]
        i = int(np.argmin(vals))
        x[e] = (grid[i][0], grid[i][1], ELASTIC_ZETA0)
    if ne > 1:  # each joint's grid again with the others at their best points: the modes of a chain couple
        _grid_each(x, range(ne), grid, errors, elastic)
    say("step 2 start (eq. (28)'s grid, each elastic joint at its best point): " + "; ".join(
        f"{nm} λ = {x[e, 0]:.2f}, f = {x[e, 1]:.1f} Hz" for e, nm in enumerate(names)))
    if not search:
        return x, split, {"criterion": _joints_error(errors(x)), "simulations": sims[0]}
    return _step2_search(split, x, law, names, sims, say, width_starts)


#: The rigid step of the three-step DIDIM fits the rigid model below the elastic joints' modes, where the rigid and the
#: elastic arm move alike: its decimation's low-pass at the lowest mode step 2's grid considers
#: (``ELASTIC_GRID_F_SHARE[0]`` of the sample rate) over this factor, at most the default decimation's. At the default
#: (ten times the reference's band, 100 Hz on records whose references carry small harmonics through the modes) the
#: rigid model is fitted through the modes it cannot have: on the held-out vertical lift its rigid wrist ended at
#: 46.5 % of its force, not converged; at 2.5 Hz it converges, the wrist at 3.8 %.
RIGID_STEP_BELOW_MODES = 4.0


def rigid_step_cutoff(rec: Recording) -> float:
    """The rigid step's decimation cutoff (Hz) for the three-step DIDIM on ``rec`` (:data:`RIGID_STEP_BELOW_MODES`)."""
    return min(ELASTIC_GRID_F_SHARE[0] / rec.dt / RIGID_STEP_BELOW_MODES, _decimation(rec).cutoff_hz)


def _grid_each(x: np.ndarray, joints, grid: List[Tuple[float, float]], errors, elastic: Sequence[int]) -> float:
    """Eq. (28)'s ``grid`` of each elastic joint of ``joints`` in turn (rows of ``x``), the others at their rows: each
    row set in place to its best point by the ``elastic`` joints' criterion (:func:`_joints_error`); the last point's
    criterion of every joint."""
    from .._parallel import cores, map_threads

    best = math.inf
    for e in joints:
        pts = []
        for lam, f in grid:
            xx = x.copy()
            xx[e] = (lam, f, ELASTIC_ZETA0)
            pts.append(xx)
        got = map_threads(errors, pts, min(len(pts), cores()))
        i = int(np.argmin([_joints_error(g, elastic) for g in got]))
        x[e], best = pts[i][e], _joints_error(got[i])
    return best


def _step2_search(split: _ElasticSplit, x: np.ndarray, law: Law, names: List[str], sims: List[int], say,
                  width_starts: Sequence[float] = (1.0,)) -> Tuple[np.ndarray, _ElasticSplit, Dict[str, Any]]:
    """:func:`elastic_modes`' least squares from ``x``; with dead zones in the model, from each of their widths times
    ``width_starts`` in turn, the best kept."""
    gapped = [j for j in split.elastic if split.model.backlash_gap is not None and split.model.gaps[j] > 0]
    starts = width_starts if gapped else (1.0,)
    tried = []
    for k in starts:
        one = copy.copy(split)
        if k != 1.0:
            one.model = replace(split.model, backlash_gap=tuple(g * k for g in split.model.gaps))
        got = one.search(x, law, sims)
        if len(starts) > 1:
            say(f"step 2 from the dead zones' widths times {k:g}: joints' force errors RMS {100 * got[1]:.3f} %"
                + "".join(_width_words(one.model, j) for j in one.elastic))
        tried.append((got[1], got, one))
    _, (x, best), split = min(tried, key=lambda t: t[0])
    say("step 2: " + "; ".join(f"{nm} λ = {x[e, 0]:.3f}, f = {x[e, 1]:.2f} Hz, ζ = {x[e, 2]:.3f}"
                               + _width_words(split.model, j)
                               for (e, nm), j in zip(enumerate(names), split.elastic))
        + f"; joints' force errors RMS {100 * best:.3f} %")
    return x, split, {"criterion": best, "simulations": sims[0]}


#: The three steps' step 2 with dead zones in the model runs from their given widths times each of these (the best
#: fit kept): a width started above the truth's leaves the model's rotor and link apart where the record's are in
#: contact, and the least squares stay there (the held-out lift with 1 mrad, from 2 mrad: 2.0 mrad, K 8 times the
#: truth's; now 1.003 mrad, K -0.2 %). Stopping at the first start that ends above itself was tried: on the 12 s lift
#: from 2 mrad the start at 1 mrad ended at 1.003 mrad but 20.6 % of the force (the grid's split was made at 2 mrad),
#: and the three steps at K +14 %; the lower starts reach 1.95 %.
WIDTH_STARTS = (1.0, 0.5, 0.25, 0.125)

#: Step 2 in the rounds (:func:`_refine_springs`) fits each elastic joint's total inertia at mid-stroke too, within a
#: factor e^TOTAL_LOG_BOUND of the model's (dimensionless; see :meth:`_ElasticSplit.search`).
TOTAL_LOG_BOUND = 1.0

#: Rounds of step 2 and 3 again after the first (:func:`didim_elastic`), while each lowers the closed-loop force error
#: by this share at least.
ELASTIC_ROUNDS = 3
ELASTIC_ROUND_GAIN = 0.01
#: A robot's DIDIM ends when its closed-loop force error has not improved on its best for this many iterations (its
#: best iterate is the result): a DIDIM whose iterates cycle would otherwise run its whole ``max_iter`` (the flexrobots
#: UR5's step 3 once its friction law was chosen again: between 3.9 and 4.7 %, against 3.1 % at its best; the
#: held-out Panda with a 3 ms force lag, every refit of the robot doctor's late-force search: 7.5 % at its start,
#: 8.2-8.4 % at each of the 8 to 30 iterations after it). A cycle whose best still creeps down (5.77, 5.57, 5.52 %
#: every seventh iteration) goes on.
DIDIM_PATIENCE = 8


def _stalled(patience: int):
    """A ``give_up`` for :func:`didim_loop`: the iterations end when the best output error (since the plant last
    changed its model) is ``patience`` iterations old."""

    def give_up(loop) -> Optional[str]:
        if loop.best[2] is None or len(loop.history) - 1 - loop.best[3] < patience:
            return None
        return (f"no convergence: the closed-loop force error has not improved on iteration {loop.best[3]}'s in "
                f"{patience} iterations: stopped, its best iterate kept")

    return give_up


def _round_handoff(run) -> Optional[np.ndarray]:
    """Where the next round's step 2 starts when a round's DIDIM (``run``) kept its start, step 2's optimum: its first
    step, when that step's closed-loop error is within a round's gain (:data:`ELASTIC_ROUND_GAIN`) of the start's: the
    step moved the chain and the friction for the new springs, and the encoders' rounding in the loop cannot tell
    the two apart (the flexrobots UR5's round 2: 2.520 % at its start, 2.521 % after its step, kept or not as the BLAS
    ran on one thread or two, the result's K 6.6 or 3.0 % off: step 2 again from the step found the springs of 2.49 %).
    None when the round's best is not its start (the next round starts there) or the step is worse by more."""
    e, th = run.errors[run.since:], run.thetas[run.since:]
    if run.best[3] != 0 or len(e) < 2 or not e[1] <= (1 + ELASTIC_ROUND_GAIN) * e[0]:
        return None
    return th[1]


def _width_words(model: Model, j: int) -> str:
    """", backlash 0.001 rad" for a joint of ``model`` with a dead zone, else ""."""
    if model.backlash_gap is None or not model.gaps[j] > 0:
        return ""
    return f", backlash {model.gaps[j]:.4g} {'m' if model.robot.joint_kinds[j] == 'prismatic' else 'rad'}"


def _refine_springs(rec: Recording, plant: "_RobotPlant", theta: np.ndarray, law: Law, search: Dict[str, Any]
                    ) -> np.ndarray:
    """Step 2's search again from step 3's estimate ``theta``: each elastic joint's split, mode, damping ratio and
    total inertia (:class:`_ElasticSplit` of the elastic model, ``totals``), the rest held."""
    split = _ElasticSplit.of_elastic(rec, plant, theta)
    sims = [0]
    x, _ = split.search(split.x_of(theta), law, sims, totals=True)
    search["simulations"] += sims[0]
    plant.structure = replace(plant.structure, backlash_gap=split.model.backlash_gap)  # the widths step 2 found
    th = split.theta(x)
    th[list(plant.held)] = list(plant.held.values())  # exactly (the split's round trip through π rounds them)
    return th


@serial_blas
def didim_elastic(rec: Recording, model: Model, *, max_iter: int = 30, tol: float = 1e-3,
                  progress: Optional[Callable[[str], None]] = None, rigid: Optional[IdentificationResult] = None,
                  modes: Optional[Tuple[np.ndarray, "_ElasticSplit", Dict[str, Any]]] = None,
                  start: Optional[IdentificationResult] = None,
                  frozen: Optional[Dict[str, float]] = None,
                  rigid_cutoff_hz: Optional[float] = None) -> IdentificationResult:
    """The three-step DIDIM of the paper's section V for a robot with elastic joints (``model.elastic``): step 1,
    DIDIM on the rigid model (:func:`didim`); step 2, each elastic joint's mass ratio, mode and damping by
    Nelder-Mead on the closed-loop force error (:func:`elastic_modes`); step 3, DIDIM on the whole model from there:
    each elastic joint's motor rows carry its link's equation (the motor torque on the link's own columns at the
    simulated link states, :func:`_model_columns`' ``substitute``), and its link rows then give its K and D with the
    new body parameters; step 2's search again on the springs, then step 3 again, while the force error falls
    (:func:`_elastic_steps`). ``rigid``: step 1's
    result when it is at hand (DIDIM on the same model with every joint rigid); ``modes``: step 2's
    (:func:`elastic_modes` from it). ``start``: an elastic result of the same robot and elastic joints (a model it
    grows by a term, as the doctor does): steps 1 and 2 are its, step 3 starts from its parameters (a new term's at 0)
    and law. ``frozen``: parameters of the elastic model held at the values given (as :func:`didim`'s): step 1 holds
    those the rigid model has; where body parameters are held, step 2's split keeps the chain and takes each rotor
    from λ alone; step 3 holds them all."""
    from dataclasses import replace

    t0, sims0 = time.perf_counter(), _simulations()
    robot, offset = _check(rec, model)
    say = progress or (lambda s: None)
    held = _held(model, base_parameters(robot, elastic=elastic_of(model)), frozen)
    if rigid_cutoff_hz is not None and (rigid is not None or start is not None):
        raise DataError("rigid_cutoff_hz is step 1's low-pass, and step 1 is not run when its result (rigid=) or a "
                        "start of the elastic model (start=) is given: leave rigid_cutoff_hz out, or the result")
    if start is not None and start.structure.robot is robot and start.structure.elastic == model.elastic \
            and start.offset == offset and "rigid_force_error_per_joint" in start.options:
        return _elastic_from(rec, model, start, max_iter, tol, say, t0, sims0, held)
    if rigid is None:
        cut = rigid_step_cutoff(rec) if rigid_cutoff_hz is None else rigid_cutoff_hz
        say(f"step 1: DIDIM on the rigid model, below the modes (decimation's low-pass at {cut:.3g} Hz)")
        rigid_model = replace(model, elastic=(), kind="rigid", backlash_gap=None)
        names_r = set(_theta_names(rigid_model, base_parameters(robot)))
        rigid = didim(rec, rigid_model, max_iter=max_iter, tol=tol, progress=progress,
                      frozen={k: v for k, v in (frozen or {}).items() if k in names_r} or None, cutoff_hz=cut)
    elif rigid.structure.elastic or rigid.structure.terms != model.terms or rigid.offset != model.offset:
        raise DataError("step 1's result is the rigid DIDIM of the same model (its terms and offset, no elastic "
                        f"joint), got {rigid.structure.describe()}")
    say(f"step 1: closed-loop force error {100 * rigid.force_error:.3f} %")
    x, split, search = modes if modes is not None else elastic_modes(rec, rigid, model, say, width_starts=WIDTH_STARTS)
    theta0 = split.theta(x)
    theta0[list(held)] = list(held.values())
    law = rigid.law if rigid.law is not None else _default_law(rec)
    why = no_mode(x, [robot.joint_names[j] for j in split.elastic], rec.dt)
    if why and len(why) < len(split.elastic) and modes is None:
        again = _second_split(rec, model, rigid, why, max_iter, tol, say, frozen, search)
        if again is not None:
            x, split, search = again
            theta0 = split.theta(x)
            theta0[list(held)] = list(held.values())
            why = no_mode(x, [robot.joint_names[j] for j in split.elastic], rec.dt)
    if why:
        return _no_mode_result(rec, model, split, theta0, law, why, rigid, search, t0, sims0)
    # the widths of the dead zones step 2 found (split.model's)
    plant = _RobotPlant(rec, split.model, split.base, _decimation(rec), law, {}, tol, say, held)
    return _elastic_steps(rec, model, plant, theta0, split, search, rigid.force_error, rigid.force_error_per_joint,
                          max_iter, say, t0, sims0)


def _second_split(rec: Recording, model: Model, rigid: IdentificationResult, why: Dict[str, str], max_iter: int,
                  tol: float, say, frozen: Optional[Dict[str, float]], search: Dict[str, Any]):
    """Step 2 again for the elastic joints whose mode the rigid step's split does not show (``why``), from the model
    with the others elastic, fitted by steps 2 and 3 on the same rigid step: its split of them (their total inertia
    the full band's, not the rigid step's below the modes) and its modes of the others held, eq. (28)'s grid of the
    joints added, then step 2's search of them all. The rigid step sees little of a light joint's inertia beside its
    gravity and friction: on the held-out UR10 with a shared excitation it put wrist 1's total 16 % high, the link's
    share (12 % of it) twice the truth's, and step 2 from there found the rigid wrist better than any mode; from the
    model with the shoulder lift elastic, the wrist's total is 4.8 % high and step 2 finds its mode within 0.4 %.
    Returns (x, split, search) for all the elastic joints, or None when the model of the others cannot be fitted."""
    names = [model.robot.joint_names[j] for j in elastic_of(model)]
    others = tuple(nm for nm in names if nm not in why)
    say(f"step 2 finds no mode of {', '.join(why)} from the rigid step's split: the three steps with "
        f"{', '.join(others)} elastic first, then step 2 again from that model's split")
    gaps = None if model.backlash_gap is None else {nm: g for nm, g in zip(model.robot.joint_names, model.gaps)
                                                    if nm in others and g > 0} or None
    partial = replace(model, elastic=others, backlash_gap=gaps)
    try:
        first = didim_elastic(rec, partial, max_iter=max_iter, tol=tol, progress=say, rigid=rigid,
                              frozen=frozen_for(partial, frozen or {}) or None)
    except (SimulationError, DataError, IdentifiabilityError):
        return None
    if first.options.get("no_mode"):
        return None
    x, split, grid = elastic_modes(rec, first, model, say, search=False)
    sims = [grid["simulations"]]
    x, split, found = _step2_search(split, x, first.law if first.law is not None else rigid.law, names, sims, say)
    found["simulations"] += search.get("simulations", 0) + first.simulations
    return x, split, found


def no_mode(x: np.ndarray, names: Sequence[str], dt: float) -> Dict[str, str]:
    """Why step 2's best split and mode of each elastic joint (rows of ``x``: λ, f in Hz, ζ) is no mode the record
    shows, by joint name (the joints whose mode it is are left out): a rotor's share at a bound of λ (within twice
    :data:`SPLIT_LAMBDA_BOUND`: the search's answer, not the joint's), a damping ratio of 1 or more (no oscillation),
    or a mode at the Nyquist frequency (0.45 of the sample rate). One axis's step 2 says the same of its optimum
    (a mass ratio at 0 or 1, a mode above the analysed band). Step 3 from such a point is a loop as stiff as it is
    meaningless (on robotdoctor's d5: λ = 0.001, 143 Hz, ζ = 2.8, 90 s per iteration)."""
    out = {}
    edge = 2 * SPLIT_LAMBDA_BOUND
    for name, (lam, f, zeta) in zip(names, np.asarray(x, dtype=float)[:, :3]):
        why = []
        if not edge < lam < 1 - edge:
            why.append(f"the rotor's share of its inertia λ = {lam:.3g} at the search's bound")
        if not zeta < 1:
            why.append(f"its damping ratio {zeta:.3g} is not below 1 (no oscillation)")
        if not f < 0.45 / dt:
            why.append(f"its mode {f:.4g} Hz is at the Nyquist frequency {0.5 / dt:.4g} Hz")
        if why:
            out[name] = "; ".join(why)
    return out


def _no_better_than_rigid(robot, elastic: Sequence[int], per: Dict[str, float], rigid_per: Dict[str, float]
                          ) -> List[str]:
    """The elastic joints whose force the elastic model explains no better than the rigid one (their errors ``per``
    against ``rigid_per``, by joint name; :data:`RIGID_LIMIT_MARGIN`): the record shows no mode of them."""
    names = [robot.joint_names[j] for j in elastic]
    return [nm for nm in names if nm in per and nm in rigid_per and per[nm] >= RIGID_LIMIT_MARGIN * rigid_per[nm]]


def _step3_verdict(robot, elastic: Sequence[int], per: Dict[str, float], rigid_per: Dict[str, float], x: np.ndarray,
                   dt: float, message: str) -> Tuple[List[str], str]:
    """The elastic joints whose mode the final model does not show, and the result's message (``message``: the
    iterations' own, empty when they converged): those whose force the elastic model explains no better than the
    rigid one (errors ``per`` against ``rigid_per``; one axis's step 2 says the same, :data:`RIGID_LIMIT_MARGIN`), and
    those whose final split, mode or damping (rows of ``x``: λ, f in Hz, ζ) is no mode the record shows
    (:func:`no_mode`). Step 3 moves the springs with the bodies (:func:`_model_columns`): where the record does not hold
    a mode they can end where step 2 would have said so (the KR300 at 250 Hz, step 3 from its published springs: axis
    2's rotor at λ = 0.001 of its inertia, ζ = 1.3). Their K and D mean nothing."""
    flat = _no_better_than_rigid(robot, elastic, per, rigid_per)
    if flat:
        message = (f"the record shows no elastic mode of {', '.join(flat)}: the elastic model explains their force no "
                   "better than the rigid one (" + "; ".join(
                       f"{j} {100 * per[j]:.2f} % against {100 * rigid_per[j]:.2f} %" for j in flat)
                   + "); their K and D mean nothing: model them rigid")
    gone = no_mode(x, [robot.joint_names[j] for j in elastic], dt)
    if gone:
        flat = flat + [j for j in gone if j not in flat]
        said = ("step 3 ends at no elastic mode of " + "; ".join(f"{j}: {w}" for j, w in gone.items())
                + ": their K and D mean nothing; model them rigid, or record a trajectory that excites their modes")
        message = f"{message}; {said}" if message else said
    return flat, message


def _no_mode_result(rec: Recording, model: Model, split: "_ElasticSplit", theta0: np.ndarray, law: Law,
                    why: Dict[str, str], rigid: IdentificationResult, search: Dict[str, Any], t0: float,
                    sims0: int) -> IdentificationResult:
    """:func:`didim_elastic`'s result when step 2 finds no mode of some elastic joints (:func:`no_mode`): step 3 is
    not run (as for one axis); the result holds step 2's parameters, not converged, its message naming the joints,
    why, and what to do; ``options["no_mode"]`` the reasons by joint. The other elastic joints whose force step 2's
    model explains no better than the rigid one (:data:`RIGID_LIMIT_MARGIN`, as step 3's verdict) are named too."""
    nt = len(_theta_names(model, split.base))
    res = _result("didim", rec, model.with_law(law), split.base, theta0, np.full((nt, nt), np.nan), converged=False,
                  iterations=0, message="")
    try:
        res.force_error, res.force_error_per_joint = force_errors(rec, simulate_robot(rec, res)["force"])
    except (SimulationError, DataError):
        res.force_error, res.force_error_per_joint = math.nan, {}
    per, rigid_per = res.force_error_per_joint, rigid.force_error_per_joint
    why = dict(why)
    for nm in _no_better_than_rigid(model.robot, split.elastic, per, rigid_per):
        if nm not in why:
            why[nm] = (f"the elastic model explains its force no better than the rigid one ({100 * per[nm]:.2f} % "
                       f"against {100 * rigid_per[nm]:.2f} %)")
    message = ("step 2 finds no elastic mode of " + "; ".join(f"{j}: {w}" for j, w in why.items())
               + ": step 3 was not run, and these parameters are step 2's. Model "
               + ("that joint" if len(why) == 1 else "those joints") + " rigid, or record a trajectory that excites "
               "the mode (a chirp of the joint's reference through its expected frequencies)")
    res.message = message
    res.notes = [f"step 1 (rigid DIDIM): closed-loop force error {100 * rigid.force_error:.2f} %", message]
    res.options["modes"] = split.modes(split.x_of(theta0))
    res.options["no_mode"] = dict(why)
    res.options["rigid_force_error"] = rigid.force_error
    res.options["rigid_force_error_per_joint"] = dict(rigid.force_error_per_joint)
    res.elapsed_s, res.simulations = time.perf_counter() - t0, _simulations() - sims0
    return res


def _elastic_from(rec: Recording, model: Model, start: IdentificationResult, max_iter: int, tol: float, say, t0: float,
                  sims0: int, held: Optional[Dict[int, float]] = None) -> IdentificationResult:
    """Step 3 (and its rounds) of :func:`didim_elastic` from an elastic result ``start`` of the same robot and elastic
    joints: its parameters where the model has them (a new term's at 0), its law, its step 1's errors."""
    base = base_parameters(model.robot, elastic=elastic_of(model))
    theta0 = np.array([start.params.get(k, 0.0) for k in _theta_names(model, base)])
    held = held or {}
    theta0[list(held)] = list(held.values())
    law = start.law if start.law is not None else _default_law(rec)
    plant = _RobotPlant(rec, model, base, _decimation(rec), law, {}, tol, say, held)
    split = _ElasticSplit.of_elastic(rec, plant, theta0)
    return _elastic_steps(rec, model, plant, theta0, split, {"criterion": math.nan, "simulations": 0},
                          start.options["rigid_force_error"], start.options["rigid_force_error_per_joint"], max_iter,
                          say, t0, sims0)


def _elastic_steps(rec: Recording, model: Model, plant: "_RobotPlant", theta0: np.ndarray, split: "_ElasticSplit",
                   search: Dict[str, Any], rigid_error: float, rigid_per: Dict[str, float], max_iter: int, say,
                   t0: float, sims0: int) -> IdentificationResult:
    """Step 3 of :func:`didim_elastic` from ``theta0`` and its rounds with step 2 again, and the result (the verdict
    of a joint whose mode the record does not show from the rigid step's errors ``rigid_error``, ``rigid_per``)."""
    robot, elastic = model.robot, elastic_of(model)
    say("step 3: DIDIM on the elastic model")
    # the friction law is chosen again in closed loop once the rounds below start: from step 2's estimate the
    # iterations can settle at once (its body parameters are step 1's, already a fixed point of the motor rows), and
    # a law chosen there stays (on the flexrobots UR5, exp at 0.7 times the truth's tanh ε)
    plant.law_chosen = True
    run = didim_loop(plant, theta0, max_iter=max_iter, progress=say, give_up=_stalled(DIDIM_PATIENCE))
    if run.best[2] is None:
        raise SimulationError(f"step 3 (DIDIM on the elastic model) could not simulate the robot's closed loop: "
                              f"{run.message}")
    # DIDIM keeps the modes (each link row fits the simulated spring exactly): with step 3's friction and chain,
    # step 2's search again on each elastic joint's rotor inertia, mode and damping, then step 3 again, while the
    # closed-loop force error falls
    handoff = None  # where the next round's step 2 starts, when not at the best iterate (see _round_handoff)
    for rnd in range(ELASTIC_ROUNDS):
        # under the law step 3 chose (once it converged, the law is chosen again on the elastic model)
        theta_r = _refine_springs(rec, plant, run.best[1] if handoff is None else handoff, plant.law, search)
        say(f"step 2 again (round {rnd + 2}): " + ", ".join(
            f"{robot.joint_names[j]} Ia = {theta_r[plant.lay.ia(e)]:.4g}, K = {theta_r[plant.lay.k(e)]:.4g}, "
            f"D = {theta_r[plant.lay.d(e)]:.4g}" + _width_words(plant.structure, j) for e, j in enumerate(elastic)))
        law_r = plant.law
        plant.law_chosen = plant.hold_law  # the law chosen again once this round settles (its model has changed)
        again = didim_loop(plant, theta_r, max_iter=max_iter, progress=say)
        if again.best[2] is None or again.best[0] >= (1 - ELASTIC_ROUND_GAIN) * run.best[0]:
            if again.best[2] is not None and again.best[0] < run.best[0]:
                run = again
            break
        run = again
        nxt = _round_handoff(again)  # None unless the round kept its start
        if again.best[3] == 0 and nxt is None and plant.law == law_r:
            # the round's best is its start, step 2's optimum, under the same law, and its DIDIM's first step is
            # worse by more than a round's gain: step 2 again would start from its own optimum and DIDIM from the same
            # point (on the flexrobots UR5 round 4 repeated round 3 to 4 digits, 13 s of its 85)
            break
        handoff = nxt
    err, theta, sol, _ = run.best
    if run.errors and err < run.errors[-1]:
        say(f"step 3: the iterate with the lowest joints' force errors is kept, RMS {100 * err:.3f} % (the last "
            f"{100 * run.errors[-1]:.3f} %: DIDIM's iterations settle where the least squares do, not at the lowest "
            "force error)")
    x = _ElasticSplit.of_elastic(rec, plant, theta).x_of(theta)  # the final model's split, modes and damping
    modes = split.modes(x)
    notes = [f"step 1 (rigid DIDIM): closed-loop force error {100 * rigid_error:.2f} %"
             + "".join(f"; {j} {100 * v:.2f} %" for j, v in rigid_per.items()),
             "steps 2 and 3 (each elastic joint's mass ratio λ, locked-rotor mode f_n_flex at mid-stroke and damping "
             f"ratio ζ by least squares in closed loop, {search['simulations']} simulations): " + "; ".join(
                 f"{nm} λ = {m['lambda']:.3f}, f_n_flex = {m['f_n_flex']:.2f} Hz, ζ = {m['zeta']:.3f}"
                 for nm, m in modes.items())]
    flat, message = _step3_verdict(robot, elastic, sol["force_errors"][1], rigid_per, x, rec.dt,
                                   "" if run.converged else run.message)
    res = _result("didim", rec, replace(model.with_law(sol["law"]), backlash_gap=sol.get("backlash_gap")), split.base,
                  theta, sol["covariance"],
                  converged=run.converged and not flat,
                  iterations=len(run.history), message=message,
                  history=iterations_of(run.errors), notes=notes + run.notes)
    res.options["modes"] = modes
    res.options["rigid_force_error"] = rigid_error
    res.options["rigid_force_error_per_joint"] = dict(rigid_per)
    res.force_error, res.force_error_per_joint = sol["force_errors"]
    res.elapsed_s, res.simulations = time.perf_counter() - t0, _simulations() - sims0
    names = _theta_names(model, split.base)
    res.frozen = {names[i]: float(v) for i, v in plant.held.items()}
    return res


class _LoopSensitivities:
    """``∂force/∂v`` of OE-LM's loop (n, len(v), N), v the fitted components of u (``full(v)`` the whole u): the core's
    exact forward sensitivities along ``∂φ/∂v``, φ the loop's physical parameters (:func:`_physical`). θ's part of
    ``∂φ/∂v`` is constant (φ is affine in θ: the bases' standard parameters, the drives' own values), taken once as
    differences of unit steps of u, exact but for rounding; each smoothing speed's and backlash width's, fitted in
    their logs, is the value itself. The drives' first forces move with θ through a lead-in's static torque
    (:func:`_force0`, affine in θ too); they do not depend on ε (the terms at rest are at zero speed) nor on the
    widths."""

    def __init__(self, rec: Recording, start: IdentificationResult, split, full, mask: np.ndarray, p: int,
                 gapped: np.ndarray):
        self.rec, self.start, self.split, self.full, self.p, self.gapped = rec, start, split, full, p, gapped
        self.free = np.flatnonzero(mask)
        self.n = rec.ndof
        self.theta_part: Optional[Tuple[np.ndarray, np.ndarray]] = None

    def model(self, u: np.ndarray):
        th, lw, gaps = self.split(u)
        robot, d = _model_of(replace(self.start.structure, backlash_gap=gaps), self.start.base, th)
        return robot, d, lw

    def _theta_part(self, u: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        if self.theta_part is None:
            phys, f0 = [], []
            for c in self.free[self.free < self.p]:
                ends = []
                for step in (1.0, -1.0):
                    v = u.copy()
                    v[c] += step
                    robot, d, lw = self.model(v)
                    ends.append((_physical(robot, d, lw), _force0(self.rec, robot, d, lw)))
                phys.append(0.5 * (ends[0][0] - ends[1][0]))
                f0.append(0.5 * (ends[0][1] - ends[1][1]))
            self.theta_part = (np.reshape(np.array(phys).T, (-1, len(phys))),
                               np.reshape(np.array(f0).T, (self.n, len(f0))))
        return self.theta_part

    def __call__(self, v: np.ndarray) -> np.ndarray:
        u = self.full(v)
        robot, d, lw = self.model(u)
        phys = _physical(robot, d, lw)
        n, p, k = self.n, self.p, len(self.free)
        theta_dirs, theta_f0 = self._theta_part(u)
        dirs, dforce0 = np.zeros((len(phys), k)), np.zeros((n, k))
        nt = theta_dirs.shape[1]
        if nt:
            dirs[:, :nt], dforce0[:, :nt] = theta_dirs, theta_f0
        eps_at, gap_at = 18 * n, 16 * n  # the core's PhysLayout: ε and the backlash widths, one per joint
        for col, c in enumerate(self.free):
            if p <= c < p + n:
                dirs[eps_at + c - p, col] = math.exp(u[c])
            elif c >= p + n:
                dirs[gap_at + int(self.gapped[c - p - n]), col] = math.exp(u[c])
        # the directions in one chunk per core, each chunk a loop of its own (the simulation repeated: the tangent
        # costs each direction most of a simulation)
        from .._parallel import cores, map_threads

        if k == 0:
            return np.zeros((n, 0, self.rec.n))
        chunks = [c for c in np.array_split(np.arange(k), min(cores(), k)) if len(c)]
        parts = map_threads(lambda c: _simulate(self.rec, robot, d, lw, quantize=False, directions=dirs[:, c],
                                                dforce0=dforce0[:, c])["dforce"], chunks, len(chunks))
        return np.concatenate(parts, axis=1)


@serial_blas
def oe_lm(rec: Recording, model: Model, *, max_iter: int = 30, tol: float = 1e-3,
          progress: Optional[Callable[[str], None]] = None, start: Optional[IdentificationResult] = None,
          free: Optional[Sequence[str]] = None, joints: Optional[Sequence[int]] = None) -> IdentificationResult:
    """Output-error Levenberg-Marquardt on a robot (rigid or with elastic joints): the least squares of the joints'
    relative force residuals in closed loop over every parameter of the model (θ of :class:`_Layout`) and each joint's
    friction smoothing speed ε, from DIDIM's estimate (``start``, by default :func:`didim`: the three-step DIDIM for
    elastic joints); at most ``max_iter`` evaluations of the Jacobian. The Jacobian is the exact sensitivities of the
    loop simulated without encoder quantization (:func:`_simulate`, :class:`_LoopSensitivities`: the core's tangent of
    the loop along the parameters' directions, in one chunk per core). The covariance is σ² (JᵀJ)⁻¹ at the solution, σ² from the residual
    (correlated in time: the standard deviations are optimistic). ``free``: only the parameters of θ so named are
    fitted, with the smoothing speeds of ``joints`` (the dead zones' widths held), the others held at ``start``'s;
    ``joints``: only these joints' residuals count (:func:`polish_joint`)."""
    t0, sims0 = time.perf_counter(), _simulations()
    robot, offset = _check(rec, model)
    _checks.options(max_iter=max_iter, tol=tol)
    say = progress or (lambda s: None)
    if start is None:
        say("oe-lm: its start, DIDIM")
        start = didim(rec, model, max_iter=max_iter, tol=tol, progress=progress)
    if start.structure.robot is not robot or start.offset != offset or start.structure.elastic != model.elastic \
            or start.structure.terms != model.terms:
        raise DataError(f"oe-lm's start is a result of another model ({start.structure.describe()}) than the one to "
                        f"fit ({model.describe()}): give a start of the same robot, offset, elastic joints and terms")
    if (start.structure.backlash_gap is None) != (model.backlash_gap is None):
        raise DataError(f"oe-lm's start ({start.structure.describe()}) and the model to fit ({model.describe()}) differ "
                        "in their backlash: give a start with a dead zone on the same joints")
    elastic = elastic_of(start.structure)
    theta0 = theta_of(start)
    law0 = start.law if start.law is not None else _default_law(rec)
    scale = np.where(np.abs(theta0) > 0, np.abs(theta0), 1.0)
    p, n = len(theta0), robot.ndof
    # each dead zone's width is fitted too, in its log (as each joint's ε), from the start's
    gaps0 = np.asarray(start.structure.gaps if start.structure.backlash_gap is not None else (0.0,) * n)
    gapped = np.flatnonzero(gaps0 > 0)

    def split(u: np.ndarray) -> Tuple[np.ndarray, Law, Any]:
        gaps = gaps0.copy()
        gaps[gapped] = np.where(mask[p + n:], np.exp(u[p + n:]), gaps0[gapped])
        # a held value is the start's itself (u's round trip through the scale and the log would move its last bit)
        eps = np.where(mask[p:p + n], np.exp(u[p:p + n]), law0[1])
        return (np.where(mask[:p], u[:p] * scale, theta0), (law0[0], tuple(float(e) for e in eps)),
                tuple(float(g) for g in gaps) if len(gapped) else None)

    def simulate_u(u: np.ndarray) -> Dict[str, np.ndarray]:
        return _simulate(rec, *sens.model(u), quantize=False)

    u0 = np.concatenate([theta0 / scale, np.log(np.maximum(law0[1], 1e-300)), np.log(gaps0[gapped])])
    # the components of u fitted (all by default), the others held at the start's
    names = _theta_names(start.structure, start.base)
    mask = np.ones(len(u0), bool)
    if free is not None:
        unknown = set(free) - set(names)
        if unknown:
            raise DataError(f"oe-lm: no parameter {', '.join(sorted(unknown))} in {model.describe()}")
        mask[:p] = np.isin(names, list(free))
        mask[p:p + n] = np.isin(np.arange(n), list(joints if joints is not None else range(n)))
        mask[p + n:] = False

    def full(v: np.ndarray) -> np.ndarray:
        u = u0.copy()
        u[mask] = v
        return u

    # the loop at u (its robot, drives and law) and its exact sensitivities
    sens = _LoopSensitivities(rec, start, split, full, mask, p, gapped)
    sims = [0]
    say(f"oe-lm: Levenberg-Marquardt on {int(mask[:p].sum())} parameters and {int(mask[p:p + n].sum())} smoothing "
        "speeds" + (f" and {len(gapped)} backlash width(s)" if mask[p + n:].any() else ""))
    out = _output_least_squares(rec, lambda v: simulate_u(full(v)), u0[mask], np.full(int(mask.sum()), -np.inf),
                                np.full(int(mask.sum()), np.inf), sims, max_nfev=max_iter, joints=joints,
                                sensitivities=sens)
    theta, law, gaps = split(full(out.x))
    r, jac = out.fun, out.jac
    cov_u = np.zeros((len(u0), len(u0)))
    cov_u[np.ix_(mask, mask)] = float(r @ r) / max(len(r) - int(mask.sum()), 1) * np.linalg.pinv(jac.T @ jac)
    cov = cov_u[:p, :p] * np.outer(scale, scale)
    flat = "no elastic mode" in (start.message or "")
    res = _result("oe-lm", rec, replace(model.with_law(law), backlash_gap=gaps), start.base, theta, cov,
                  converged=bool(out.status > 0) and not flat,
                  iterations=int(out.nfev), message=start.message if flat else
                  ("" if out.status > 0 else str(out.message)),
                  notes=[f"started from {start.method}'s estimate (closed-loop force error "
                         f"{100 * start.force_error:.2f} %)",
                         "exact sensitivities of the loop without encoder quantization (its forward sensitivity "
                         "equations)"]
                  + ([] if free is None else [
                      f"fitted: {', '.join(k for k, m in zip(names, mask) if m) or 'no parameter'} and the smoothing "
                      f"speed of {', '.join(robot.joint_names[j] for j in np.flatnonzero(mask[p:p + n]))}, on the "
                      f"residual of {', '.join(robot.joint_names[j] for j in (joints or range(n)))}; the others "
                      "held at the start's"]))
    if elastic:
        chain, d = _model_of(start.structure, start.base, theta)
        split_final = _ElasticSplit(rec, start.structure, np.concatenate([d["armature"], chain.inertial_params]), d)
        x = split_final.x_of(theta)
        res.options["modes"] = {robot.joint_names[j]: {"lambda": float(x[e, 0]), "f_n_flex": float(x[e, 1]),
                                                       "zeta": float(x[e, 2]), "q_mid": float(split_final.qmid[j])}
                                for e, j in enumerate(elastic)}
        res.options["rigid_force_error"] = start.options.get("rigid_force_error")
    res.force_error, res.force_error_per_joint = force_errors(rec, simulate_robot(rec, res)["force"])
    res.elapsed_s, res.simulations = time.perf_counter() - t0, _simulations() - sims0
    say(f"oe-lm: closed-loop force error {100 * res.force_error:.3f} % ({sims[0]} simulations in its search)")
    return res


@dataclass
class PayloadResult:
    """A payload on the last link, identified with the robot's parameters of ``base_result``: its mass (kg), centre
    of mass (m, in the last joint's frame) and their standard deviations; the inertial parameters it adds to the last
    body (``delta``, with ``delta_std``; NaN where the joints' torques do not depend on one), and the fit."""

    mass: float
    mass_sigma: float
    com: List[float]
    com_sigma: List[float]
    delta: Dict[str, float]
    delta_std: Dict[str, float]
    force_error: float
    force_error_without: float
    converged: bool
    iterations: int
    elapsed_s: float
    notes: List[str] = field(default_factory=list)

    def to_dict(self) -> Dict[str, Any]:
        from ..formats._io import jsonable

        return jsonable(dict(self.__dict__))

    def summary(self) -> str:
        # each coordinate to its σ's first two digits (a σ of 0.02 mm printed "0.0" carried nothing)
        com = ", ".join(f"{1e3 * c:.{max(1, 1 - int(math.floor(math.log10(1e3 * s))))}f} ± {1e3 * s:.2g}"
                        if s > 0 and math.isfinite(s) else f"{1e3 * c:.1f} ± {1e3 * s:.2g}"
                        for c, s in zip(self.com, self.com_sigma))
        lines = [f"payload: mass {self.mass:.5f} ± {self.mass_sigma:.2g} kg, centre of mass ({com}) mm in the last "
                 f"joint's frame; closed-loop force error {100 * self.force_error_without:.2f} % without it -> "
                 f"{100 * self.force_error:.2f} % with it ({'converged' if self.converged else 'NOT converged'} in "
                 f"{self.iterations} iterations, {self.elapsed_s:.1f} s)"]
        return "\n".join(lines + [f"note: {x}" for x in self.notes])


class _PayloadPlant:
    """A payload on the robot's last body as DIDIM's loop sees it: θ the 10 inertial parameters it adds (those the
    torques cannot tell held at 0), the rest of the model kept; the least squares of the force the known model
    leaves, on the last body's columns; a loop that cannot be simulated (the body's inertia not positive) is pulled
    back; settled as a robot's DIDIM."""

    def __init__(self, rec, result, pi, drives, theta, dec, law, free, tol):
        self.rec, self.result, self.pi, self.drives, self.theta = rec, result, pi, drives, theta
        self.dec, self.law, self.free, self.tol = dec, law, list(free), tol
        self.n = result.robot.ndof
        self.norm = float(np.linalg.norm(rec.force))

    def simulate(self, delta: np.ndarray):
        bodies = self.pi[self.n:].copy()
        bodies[-10:] += delta
        return _simulate(self.rec, self.result.robot.with_inertial_params(bodies), self.drives, self.law)

    def output_error(self, sim) -> float:
        return float(np.linalg.norm(self.rec.force - sim["force"]) / self.norm)

    def solve(self, delta: np.ndarray, sim) -> Dict[str, Any]:
        res, rec = self.result, self.rec
        q, v, a = sim["q"], sim["qd"], sim["qdd"]
        known = np.einsum("kjp,p->kj", _model_regressor(res.structure, res.base, q, v, a, self.law), self.theta)
        w = res.robot.regressor(q, v, a)[:, :, -10:][:, :, self.free]
        rows = _rows(self.dec, rec.applied_force() - known, _joint_columns(w), w.shape[2], v, top_speeds(rec))
        est, cov, fit = _weighted_fit([(yd, wd) for yd, wd, _ in rows])
        return {"params": est, "covariance": cov, "std": np.sqrt(np.maximum(np.diag(cov), 0.0)), **fit}

    def physical(self, new: np.ndarray, old) -> bool:
        return bool(np.all(np.isfinite(new)) and self.pi[-10] + new[0] > 0)  # the last body keeps a mass

    def converged(self, loop) -> bool:
        return residual_settled(loop, self.tol)

    def settled(self, loop) -> str:
        return "accept"

    def describe(self, loop) -> str:
        return f"payload iteration {len(loop.history) - 1}: closed-loop force error {100 * loop.error:.3f} %"


@serial_blas
def payload(rec: Recording, result: IdentificationResult, *, max_iter: int = 30, tol: float = 1e-3,
            progress: Optional[Callable[[str], None]] = None) -> PayloadResult:
    """The payload on the last link of the robot of ``result`` (identified without it) from ``rec`` (recorded with
    it): DIDIM on the parameters the payload adds to the last body, the rest of the model kept; the parameters the
    joints' torques do not depend on (the regressor's columns of the last body, at random states, that are zero or
    combinations of the others) are left out and reported as NaN."""
    t0 = time.perf_counter()
    _robot_result(result)
    _checks.options(max_iter=max_iter, tol=tol)
    if result.structure.load_friction or result.structure.elastic:
        raise DataError("a payload is identified on a rigid robot's result without load-dependent friction (the "
                        "payload changes the torques such friction grows with); identify the model without them")
    robot, n = result.robot, result.robot.ndof
    _check(rec, result.structure)
    say = progress or (lambda s: None)
    pi = standard_of(result)
    drives = drives_of(result)
    drives["armature"] = list(pi[:n])
    theta = theta_of(result)
    dec = _decimation(rec)
    law = result.law if result.law is not None else _default_law(rec)
    # the last body's identifiable parameters (the rest of the robot known)
    yl = robot.regressor(*random_states(robot, 400, 0))[:, :, -10:].reshape(-1, 10)
    norms = np.linalg.norm(yl, axis=0)
    free: List[int] = []
    for k in range(10):
        if norms[k] <= ZERO_COLUMN * norms.max():
            continue
        cols = yl[:, free + [k]] / norms[free + [k]]
        d = np.abs(np.diag(np.linalg.qr(cols, mode="r")))
        if d[-1] > BASE_RANK_TOL * d.max():
            free.append(k)
    last = robot.joint_names[-1]
    pnames = [f"{x}_{last}" for x in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")]

    plant = _PayloadPlant(rec, result, pi, drives, theta, dec, law, free, tol)
    loop = didim_loop(plant, np.zeros(10), max_iter=max_iter, progress=say)
    if loop.best[2] is None:
        raise SimulationError(f"the payload's closed loop cannot be simulated: {loop.message}")
    err, delta, sol, _ = loop.best
    cov, converged = sol["covariance"], loop.converged
    history = loop.errors
    bodies = pi[n:]
    sim0 = _simulate(rec, robot.with_inertial_params(bodies), drives, law)
    err0 = float(np.linalg.norm(rec.force - sim0["force"]) / np.linalg.norm(rec.force))
    std = np.full(10, np.nan)
    std[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    full_cov = np.full((10, 10), np.nan)
    full_cov[np.ix_(free, free)] = cov
    notes = []
    fixed = [pnames[k] for k in range(10) if k not in free]
    if fixed:
        notes.append("not identifiable from the joints' torques (left at 0, reported as NaN): " + ", ".join(fixed))
    m = delta[0] if 0 in free else math.nan
    com, com_sigma = [], []
    for i in (1, 2, 3):
        if 0 in free and i in free and m > 0:
            c = delta[i] / m
            g = np.zeros(10)
            g[0], g[i] = -delta[i] / m**2, 1 / m
            idx = [0, i]
            var = float(g[idx] @ full_cov[np.ix_(idx, idx)] @ g[idx])
            com.append(c)
            com_sigma.append(math.sqrt(max(var, 0.0)))
        else:
            com.append(math.nan)
            com_sigma.append(math.nan)
    return PayloadResult(mass=m, mass_sigma=float(std[0]), com=com, com_sigma=com_sigma,
                         delta={k: (float(delta[i]) if i in free else math.nan) for i, k in enumerate(pnames)},
                         delta_std={k: float(std[i]) for i, k in enumerate(pnames)}, force_error=err,
                         force_error_without=err0, converged=converged, iterations=len(history),
                         elapsed_s=time.perf_counter() - t0, notes=notes)


def _robot_result(result) -> None:
    """Refuses what is not a robot's result (a one-axis result, another object), naming what was given."""
    if not isinstance(result, IdentificationResult) or result.robot is None:
        what = ("a one-axis result" if isinstance(result, IdentificationResult) else type(result).__name__)
        raise DataError(f"a robot's result is needed (didim.identify on a robot's record, or didim.load_result of one), "
                        f"got {what}")


def _check(rec: Recording, model: Model) -> Tuple[Robot, bool]:
    """The model's robot and offset, once the record is checked to be of its joints."""
    if not isinstance(model, Model) or model.robot is None:
        raise DataError(f"a robot's record is identified with a model of its robot (didim.Model(robot=...) or the "
                        f"didim.Robot itself), got {type(model).__name__}")
    robot = model.robot
    if not rec.has_joint_columns or list(rec.joint_names) != robot.joint_names:
        raise DataError(f"the record's joints ({', '.join(rec.joint_names)}) are not the robot's "
                        f"({', '.join(robot.joint_names)}), in the same order")
    return robot, model.offset


__all__ = ["BaseParameters", "PayloadResult", "payload", "base_parameters", "idim_ls", "didim", "didim_elastic",
           "elastic_modes", "deflection_errors", "oe_lm", "polish_joint", "simulate_robot", "force_errors",
           "theta_of", "drives_of", "standard_of"]
