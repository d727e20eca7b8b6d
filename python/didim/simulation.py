"""Closed-loop simulation of a recording's axis with given parameters (thin layer over the Rust core)."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Dict, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _checks, _core
from ._errors import DataError, DidimError
from .model import COULOMB_LAWS, MODELS, TERM_KINDS, Model, Term, as_model
from .recording import Recording

#: Integration schemes of the simulator: "exponential" (exact discretization of the affine part of the model, the
#: Coulomb terms by implicit second-order exponential time differencing with step control; the default) and "rk4"
#: (classical RK4 with ``substeps`` fixed substeps per sample, the reference).
INTEGRATORS = ("exponential", "rk4")

#: Default velocity scale of the smoothed Coulomb sign (m/s); see :func:`coulomb_sign`.
#: The Coulomb smoothing of didim's own generator (:mod:`didim.scenarios`), 0.1 mm/s (m/s), and of
#: :func:`coulomb_sign` by default. Fits and simulations of a record use :func:`default_coulomb_eps` instead.
DEFAULT_COULOMB_EPS: float = _core.DEFAULT_COULOMB_EPS
#: The Coulomb smoothing speed of a record when none is given, as a fraction of its speed scale
#: (:attr:`Recording.speed_scale`, the reference's top speed): 0.1 mm/s on the EMPS (0.125 m/s). A dimensionless
#: default, so that a record gives the same answer in m, mm, rad, deg or encoder counts; the doctor fits the
#: smoothing speed itself (the friction law's shape through zero speed is not known in advance).
COULOMB_EPS_REL = 8e-4


def default_coulomb_eps(recording: "Recording") -> float:
    """The Coulomb smoothing speed (m/s or rad/s) of ``recording`` when none is given: ``COULOMB_EPS_REL`` of its
    speed scale."""
    return COULOMB_EPS_REL * recording.speed_scale


def coulomb_eps_of(recording: "Recording", coulomb_eps: Optional[float]) -> float:
    """``coulomb_eps`` as given, or the record's default (:func:`default_coulomb_eps`) for None."""
    if coulomb_eps is None:
        return default_coulomb_eps(recording)
    _checks.options(coulomb_eps=coulomb_eps)
    return float(coulomb_eps)

#: Default local tolerance of the exponential integrator, as a fraction of the reference stroke per step.
DEFAULT_TOL: float = _core.DEFAULT_TOL

Params = Union[Mapping[str, float], Sequence[float], np.ndarray]

def coulomb_sign(v, eps: float = DEFAULT_COULOMB_EPS, law: str = "algebraic") -> np.ndarray:
    """The sign used by every Coulomb friction term, the core's own: ``law`` through zero speed with the transition
    speed ``eps`` (m/s or rad/s; "algebraic" is ``v/sqrt(v²+eps²)``), the hard sign for eps = 0."""
    v = _checks.real_array("v", v, None)
    eps = _checks.real("eps", eps, "m/s", lo=0.0, lo_open=False)
    _checks.one_of("law", law, COULOMB_LAWS)
    shape = np.shape(v)
    return _core.coulomb_sign(np.ascontiguousarray(np.ravel(v), dtype=float), eps, law).reshape(shape)


#: :func:`settling_samples`: the bound on the gap between the measured and the simulated position, as a multiple of
#: its 90th percentile over the record. A record starts away from the simulated initial state when its first gap
#: exceeds the bound, or exceeds the usual gap and grows past the bound within ``SETTLE_WINDOW_S``; the start lasts
#: until the gap stays within the bound for ``SETTLE_WINDOW_S``.
SETTLE_GAP_FACTOR = 5.0
SETTLE_WINDOW_S = 0.05


def settling_samples(qm: np.ndarray, q_sim: np.ndarray, dt: float, resolution: Optional[float] = None) -> int:
    """How many first samples the closed-loop simulation (which starts at rest on the reference, or before the
    record's lead-in) takes to join a record that began elsewhere (a log started while the axis moved, or away from
    the reference): 0 when the record starts where the simulation does, or when the two never settle together
    within the first half of the record.
    ``qm`` the measured and ``q_sim`` the simulated motor position (m); ``resolution`` the encoder's step (m): a gap
    within two steps is a start on the reference whatever the later gap."""
    gap = np.abs(np.asarray(q_sim, float) - np.asarray(qm, float))
    n = len(gap)
    if n < 4 or not np.all(np.isfinite(gap)):
        return 0
    p90, floor = float(np.percentile(gap, 90)), 2.0 * float(resolution or 0.0)
    bound = max(SETTLE_GAP_FACTOR * p90, floor)
    w = max(1, int(round(SETTLE_WINDOW_S / dt)))
    # a start off the simulation's: the first gap beyond the bound, or a first gap beyond the record's usual one that
    # grows beyond the bound within a window (a log cut as the reference speeds up: the simulation, at rest on the
    # reference, falls behind the axis that was already tracking it)
    if not (gap[0] > bound or (gap[0] > max(p90, floor) and np.max(gap[:w]) > bound)):
        return 0
    over = gap > bound
    # the first sample after which the gap stays within the bound for a whole window
    # run[i]: how many of over[i:i+w] are set (from the running count, not a convolution of n × w operations)
    csum = np.concatenate(([0], np.cumsum(over, dtype=np.int64)))
    run = csum[np.minimum(np.arange(n) + w, n)] - csum[:n]
    for i in np.flatnonzero(over):
        if i + 1 >= n // 2:
            break
        if run[i + 1] == 0:
            return int(i + 1)
    return 0


def param_names(model: Union[str, Model] = "rigid", offset: bool = False, terms: Sequence[Term] = ()) -> list:
    """Parameter names of a model in the order of its parameter vector (M, Fv, Fc[, OF] or M1, Fv1, Fc1, M2, Fv2, Fc2,
    K12[, OF]), followed by the extra terms'."""
    return as_model(model, offset=offset or None, terms=tuple(terms)).param_names()


def params_vector(model: Model, params: Params) -> Tuple[list, np.ndarray]:
    """Returns ``(names, vector)`` of ``model`` for parameters given as a name → value mapping or a sequence."""
    names = model.param_names()
    if isinstance(params, Mapping):
        missing = [k for k in names if k not in params]
        unknown = [k for k in params if k not in names]
        if missing or unknown:
            raise DataError(
                f"parameters for the {model.describe()} are {', '.join(names)}"
                + (f"; missing {', '.join(missing)}" if missing else "")
                + (f"; unknown {', '.join(map(str, unknown))}" if unknown else "")
            )
        vec = np.array([_checks.real(f"parameter {k}", params[k]) for k in names])
    else:
        if params is None or isinstance(params, (str, bytes, numbers.Number)) or np.iscomplexobj(params):
            raise DataError(f"parameters must be a mapping name -> value or a sequence of real numbers, got {params!r}")
        try:
            vec = np.asarray(params, dtype=float).ravel()
        except (TypeError, ValueError) as e:
            raise DataError(f"parameters must be a mapping name -> value or a sequence of real numbers: {e}") from None
        if vec.size != len(names):
            raise DataError(f"the {model.describe()} takes {len(names)} parameters ({', '.join(names)}), got {vec.size}")
    return names, vec


def entry_model(model, params, **structure) -> Model:
    """The model of a call made with a kind as text and a parameter mapping (``simulate(rec, {"M": …, "OF": …},
    "rigid")``): with ``offset`` not given, the mapping or the sequence's length says whether it has OF. A
    :class:`Model` is taken as it is. The one place where didim reads the structure from the parameters: everything
    behind the entry points carries a Model."""
    if not isinstance(model, Model) and structure.get("offset") is None and params is not None:
        base = as_model(model, **{**structure, "offset": False})
        if isinstance(params, Mapping):
            structure["offset"] = "OF" in params and "OF" not in base.param_names()
        elif not isinstance(params, (str, bytes, numbers.Number)):
            try:
                structure["offset"] = np.asarray(params, dtype=float).size == len(base.param_names()) + 1
            except (TypeError, ValueError):
                pass
    return as_model(model, **structure)


@dataclass(frozen=True)
class SimResult:
    """Outputs of a closed-loop simulation, one value per sample (time is the last axis).

    ``force`` is the commanded motor force (N); ``q``, ``qd``, ``qdd`` have shape (ndof, n): row 0 is the motor
    (q1, m, m/s, m/s²), row 1 the load (q12) for the flexible model. States are noise-free.

    A robot's (``joints``: its joint names): ``force`` (n, joints) as the record's, ``q``, ``qd``, ``qdd`` the link
    sides (joints, n), and ``motor`` the motor sides' positions (joints, n; an elastic joint's rotor, a rigid joint's
    link), SI units per joint (m or rad).
    """

    model: str
    params: Dict[str, float]
    t: np.ndarray
    force: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    joints: Tuple[str, ...] = ()
    motor: Optional[np.ndarray] = None

    @property
    def q1(self) -> np.ndarray:
        return self.q[0]

    @property
    def qd1(self) -> np.ndarray:
        return self.qd[0]

    @property
    def qdd1(self) -> np.ndarray:
        return self.qdd[0]

    @property
    def q12(self) -> Optional[np.ndarray]:
        return self.q[1] if self.q.shape[0] > 1 else None

    @property
    def qd12(self) -> Optional[np.ndarray]:
        return self.qd[1] if self.qd.shape[0] > 1 else None

    @property
    def qdd12(self) -> Optional[np.ndarray]:
        return self.qdd[1] if self.qdd.shape[0] > 1 else None

    def relative_error(self, recording: Recording) -> float:
        """``‖τ − τ_sim‖ / ‖τ‖`` against the recording's measured force (NaN when the measured force is zero); a
        robot's over all its joints."""
        ref = float(np.linalg.norm(recording.force))
        if ref == 0 or not np.isfinite(ref):
            return float("nan")
        return float(np.linalg.norm(recording.force - self.force) / ref)

    def relative_error_per_joint(self, recording: Recording) -> Dict[str, float]:
        """A robot's :meth:`relative_error` joint by joint (NaN for a joint whose measured force is zero); one
        axis's under the name "axis"."""
        if not self.joints:
            return {"axis": self.relative_error(recording)}
        return dict(zip(self.joints, map(float, column_errors(recording.force, self.force))))

    def settled(self, recording: Recording) -> Tuple[int, float]:
        """For a record that began away from this simulation's start (:func:`settling_samples`): how many first samples
        the simulation takes to join it, and the relative force error after them; (0, NaN) for a record that starts
        where the simulation does."""
        if self.joints:
            raise DataError("settled() compares one axis's motor position; a robot's record starts at rest where its "
                            "simulation does")
        k = settling_samples(recording.qm, self.q[0], recording.dt, recording.position_resolution)
        if k == 0:
            return 0, float("nan")
        ref = float(np.linalg.norm(recording.force[k:]))
        if ref == 0 or not np.isfinite(ref):
            return k, float("nan")
        return k, float(np.linalg.norm(recording.force[k:] - self.force[k:]) / ref)

    def plot(self, recording: Optional[Recording] = None, ax=None):
        """Measured (when a recording is given) and simulated force with their difference, like Fig. 6 of the paper."""
        import matplotlib.pyplot as plt

        if self.joints:  # a robot's: one panel per joint
            if recording is None:
                raise DataError("a robot's simulation is plotted against its record: sim.plot(record)")
            return plot_robot_forces(recording, self.force, title=f"{self.model} model on {recording.name}")
        if ax is None:
            fig, ax = plt.subplots(figsize=(10, 4))
        else:
            fig = ax.figure
        if recording is not None:
            ax.plot(self.t, recording.force, color="tab:red", lw=0.8, label="measured")
        ax.plot(self.t, self.force, color="tab:blue", lw=0.8, label="simulated")
        if recording is not None:
            ax.plot(self.t, recording.force - self.force, color="k", lw=0.6, label="error")
            ax.set_title(f"{self.model} model, relative error {100 * self.relative_error(recording):.2f} %")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"motor force ({'N·m' if recording is not None and recording.axis == 'rotary' else 'N'})")
        ax.legend(loc="upper right")
        ax.grid(True, alpha=0.3)
        return fig


def column_errors(force: np.ndarray, force_sim: np.ndarray) -> np.ndarray:
    """Each column's (a robot joint's) relative error ``‖τ − τ_sim‖ / ‖τ‖`` (NaN where its measured force is zero)."""
    ref = np.linalg.norm(force, axis=0)
    err = np.linalg.norm(force - force_sim, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((ref > 0) & np.isfinite(ref), err / ref, np.nan)


def plot_robot_forces(recording, force_sim, *, title: str = ""):
    """One panel per joint: the measured and the simulated force (torque) of a robot's record and their difference,
    with each joint's relative error in its title."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    n = recording.ndof
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.9 * n + 0.6), sharex=True, squeeze=False)
    t = recording.t
    for j, ax in enumerate(axes[:, 0]):
        y, ys = recording.force[:, j], force_sim[:, j]
        err = np.linalg.norm(y - ys) / np.linalg.norm(y)
        unit = "N·m" if recording.joint_kinds[j] == "revolute" else "N"
        # one axis's colours; the simulated line thinner and under the measured one, so that both stay visible
        ax.plot(t, ys, lw=1.2, color="tab:blue", alpha=0.7, label="simulated", zorder=2)
        ax.plot(t, y, lw=0.5, color="tab:red", label="measured", zorder=3)
        ax.plot(t, y - ys, lw=0.6, color="0.4", label="difference", zorder=1)
        ax.set_ylabel(f"{recording.joint_names[j]}\n({unit})", fontsize=8)
        ax.set_title(f"{recording.joint_names[j]}: {100 * err:.2f} %", fontsize=8, loc="right")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper left")
    axes[-1, 0].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


#: The simulator's numerical options (not the model's): see :func:`simulate`.
NUMERICS = ("substeps", "quantization", "integrator", "tol")


def sim_options(recording: Recording, *, substeps: int = 10, quantization: Optional[float] = None,
                integrator: str = "exponential", tol: float = DEFAULT_TOL) -> dict:
    """Validated numerical options of the simulator, with the recording's encoder resolution by default."""
    if quantization is None:
        quantization = recording.position_resolution or 0.0
    quantization = _checks.real("quantization", quantization, "m", lo=0.0, lo_open=False, hint=" (0 for none)")
    _checks.options(substeps=substeps)
    if integrator not in INTEGRATORS:
        raise DataError(f"unknown integrator {integrator!r}: use one of {', '.join(INTEGRATORS)}")
    if not (isinstance(tol, (int, float)) and math.isfinite(tol) and 0 < tol < 1):
        raise DataError(f"tol must be a fraction of the stroke between 0 and 1, got {tol!r}")
    return dict(substeps=int(substeps), quantization=float(quantization), integrator=integrator, tol=float(tol))


def problem(recording: Recording, model: Model, **numerics) -> "_core.Problem":
    """The recording's closed loop held by the Rust core (reference, controller, external input, the model and its
    actuation, the simulator's numerics), for repeated simulations with varying parameters. ``numerics`` as for
    :func:`simulate` (``substeps``, ``quantization``, ``integrator``, ``tol``)."""
    model = as_model(model)  # a kind as text: that kind's model with no extra structure
    _checks.known_options([sim_options], numerics, "the simulator")
    opts = sim_options(recording, **numerics)
    _checks.whole("delay", model.delay, lo=0, hi=recording.n - 1, hint=" (actuation delay in samples)")
    # a log that begins in motion is simulated from the rest before its lead-in, and output from its first sample
    qr, u_ext = recording.lead_in_signals()
    return _core.Problem(model.core(default_coulomb_eps(recording)), qr, recording.dt, recording.controller.kind,
                         list(recording.controller.gains), u_ext=u_ext, lead=int(recording.qr_lead.size), **opts)


def simulate(
    recording: Recording,
    params: Params,
    model: Union[str, Model] = "rigid",
    *,
    offset: Optional[bool] = None,
    substeps: int = 10,
    quantization: Optional[float] = None,
    delay: int = 0,
    force_lag: float = 0.0,
    coulomb_eps: Optional[float] = None,
    coulomb_law: str = "algebraic",
    terms: Sequence[Term] = (),
    backlash_gap: Optional[float] = None,
    integrator: str = "exponential",
    tol: float = DEFAULT_TOL,
    **unknown,
) -> SimResult:
    """Simulates the recording's closed loop (its reference, controller and known external input) with ``params``.

    Args:
        recording: the record whose reference, controller, sample period and external input drive the simulation.
        params: a mapping name → value (SI units, load side) or a sequence in the order of :func:`param_names`, or
            an identification result (its parameters, its model and its simulator's numerics).
        model: a :class:`didim.Model`, or its kind "rigid" (eq. (6)) or "flexible" (eq. (2)) with the structure given
            by the keywords below (``offset``, ``terms``, ``delay``, ``force_lag``, ``backlash_gap``,
            ``coulomb_eps``, ``coulomb_law``: the fields of :class:`didim.Model`).
        offset: rigid model with a constant force OF; by default, when params names OF or has one value more.
        substeps: RK4 substeps per sample period (``integrator="rk4"`` only).
        quantization: resolution of the simulated motor encoder (m); default the recording's ``position_resolution``.
        delay: extra actuation delay in samples.
        force_lag: time constant (s) of a first-order lag from the command to the applied force (a current loop).
        coulomb_eps: velocity scale of the Coulomb sign (m/s or rad/s), 0 for the hard sign; by default the
            record's (:func:`default_coulomb_eps`).
        coulomb_law: the shape of the Coulomb sign through zero speed (``COULOMB_LAWS``: "algebraic"
            ``v/sqrt(v² + ε²)``, "tanh", "atan", "exp"; each with the slope 1/ε at rest).
        terms: extra model terms (:class:`Term`), whose parameters ``params`` must include.
        backlash_gap: flexible model only: total width (m) of a dead zone in the coupling K12.
        integrator: "exponential" (default: exact for the affine part of the model, adaptive where the Coulomb sign
            bends) or "rk4" (fixed substeps, the reference).
        tol: local tolerance of the exponential integrator per step, as a fraction of the reference stroke.
    """
    if unknown:
        _checks.known_options([simulate], unknown, "simulate")
    if not isinstance(recording, Recording):
        raise DataError(f"recording must be a didim.Recording (see didim.load_mat), got {type(recording).__name__}")
    if recording.has_joint_columns or (_is_result(params) and params.robot is not None):
        raise DataError("a robot's record or result: didim.simulate(record, result) simulates it (this is one axis's "
                        "simulator)")
    structure = dict(offset=offset, terms=tuple(terms), delay=delay, force_lag=force_lag, backlash_gap=backlash_gap,
                     coulomb_eps=coulomb_eps, coulomb_law=coulomb_law)
    if _is_result(params):  # a result carries its model structure and its simulator's numerics
        given = [k for k, v in structure.items() if v not in ((), None, 0, "algebraic")]
        if given:
            raise DataError(f"a result carries its model structure: leave {', '.join(given)} out, or simulate "
                            "result.all_params with the structure you want")
        model = _structure(params)
        integrator = params.options.get("integrator", integrator)
        tol = params.options.get("sim_tol", tol)
        substeps = params.options.get("substeps", substeps)
        params = params.all_params
    else:
        model = entry_model(model, params, **structure)
    names, vec = params_vector(model, params)
    out = problem(recording, model, substeps=substeps, quantization=quantization, integrator=integrator,
                  tol=tol).simulate(vec)
    return SimResult(model=model.kind, params=dict(zip(names, map(float, vec))), t=recording.t, force=out["force"],
                     q=out["q"], qd=out["qd"], qdd=out["qdd"])


def _is_result(x) -> bool:
    from .result import IdentificationResult

    return isinstance(x, IdentificationResult)


def _structure(result):
    if result.robot is not None:
        raise DataError(f"this is a robot's result ({result.robot.ndof} joints of {result.robot.name}): simulate it on "
                        "a record of that robot with didim.simulate(record, result) (command line: didim simulate "
                        "REC.csv RESULT.json --controller C)")
    if result.structure is None:
        raise DataError(f"this {result.method} result holds no parameter set of a model ({', '.join(result.params)}); "
                        "simulate the final result of the identification (or one of its steps that has one)")
    missing = [n for n in result.structure.param_names() if n not in result.all_params]
    if missing:
        raise DataError(f"the result lacks the parameter(s) {', '.join(missing)} of its {result.structure.kind} model")
    return result.structure


@dataclass(frozen=True)
class BatchResult:
    """Simulations of many parameter sets against one recording (time is the last axis).

    ``params`` is (m, p) in the order of ``names``; ``force`` (m, n); ``q`` (m, ndof, n); ``qd`` and ``qdd`` likewise
    when the batch was run with ``states=True`` (else None). ``errors[i]`` is None when member i succeeded, else the
    message of its error (a diverging loop or an invalid parameter set); its rows are NaN. ``batch[i]`` is member i
    as a :class:`SimResult` (raises :class:`DidimError` for a failed member).
    """

    model: str
    names: list
    params: np.ndarray
    t: np.ndarray
    force: np.ndarray
    q: np.ndarray
    qd: Optional[np.ndarray]
    qdd: Optional[np.ndarray]
    errors: list

    def __len__(self) -> int:
        return int(self.params.shape[0])

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask of the members that simulated without error."""
        return np.array([e is None for e in self.errors], dtype=bool)

    def relative_errors(self, recording: Recording) -> np.ndarray:
        """``‖τ − τ_sim‖ / ‖τ‖`` of each member against the recording's measured force (NaN for failed members)."""
        return np.linalg.norm(recording.force[None, :] - self.force, axis=1) / np.linalg.norm(recording.force)

    def __getitem__(self, i: int) -> SimResult:
        if self.errors[i] is not None:
            raise DidimError(f"member {i} of the batch failed: {self.errors[i]}")
        nan = np.full_like(self.q[i], np.nan)
        return SimResult(model=self.model, params=dict(zip(self.names, map(float, self.params[i]))), t=self.t,
                         force=self.force[i], q=self.q[i], qd=self.qd[i] if self.qd is not None else nan,
                         qdd=self.qdd[i] if self.qdd is not None else nan)


def simulate_batch(
    recording: Recording,
    params,
    model: Union[str, "Model"] = "rigid",
    *,
    offset: Optional[bool] = None,
    states: bool = False,
    **sim_kw,
) -> BatchResult:
    """Simulates many parameter sets against one recording in one call, spread over the cores (Rust threads, no Python
    in the loop); the result is in input order and does not depend on the number of threads.

    Args:
        params: an (m, p) array in the order of :func:`param_names`, or a sequence of name → value mappings.
        states: also return the velocities and accelerations (memory: 2·m·ndof·n more values).
        sim_kw: simulator options as for :func:`simulate` (integrator, tol, substeps, quantization, delay, coulomb_eps).

    A member whose simulation fails does not fail the batch: its message is in ``errors`` and its rows are NaN.
    """
    if not isinstance(recording, Recording):
        raise DataError(f"recording must be a didim.Recording (see didim.load_record), got {type(recording).__name__}")
    if recording.has_joint_columns:
        raise DataError(f"{recording.name or 'the record'} is a robot's: simulate_batch sweeps one axis's parameter "
                        "sets through the core's threads; simulate each of a robot's results with didim.simulate(rec, "
                        "result)")
    if isinstance(params, Mapping) or _is_result(params):
        raise DataError("simulate_batch takes a sequence of parameter sets; use simulate for one")
    if isinstance(params, (str, bytes)) or not isinstance(params, (Sequence, np.ndarray)):
        raise DataError("simulate_batch takes a sequence of parameter sets (a list of mappings or results, or an "
                        f"(m, p) array), got {type(params).__name__}")
    states = _checks.flag("states", states)
    numerics = {k: sim_kw.pop(k) for k in NUMERICS if k in sim_kw}
    rows = list(params) if not isinstance(params, np.ndarray) else params
    if len(rows) and all(_is_result(r) for r in rows):  # results: one structure for all, its options by default
        structures = {_structure(r) for r in rows}
        if len(structures) > 1:
            raise DataError("the results of a batch must share one model structure (kind, offset, terms, delay, force lag, "
                            "backlash, Coulomb smoothing); simulate them one by one")
        model = as_model(structures.pop(), offset=offset, **sim_kw)
        numerics.setdefault("integrator", rows[0].options.get("integrator", "exponential"))
        rows = [r.all_params for r in rows]
    elif len(rows):
        model = entry_model(model, rows[0], offset=offset, **sim_kw)
    if isinstance(rows, np.ndarray) and rows.ndim == 1:
        raise DataError("params must be 2-D, one parameter set per row (use simulate for one set)")
    if len(rows) == 0:
        raise DataError("params holds no parameter set")
    vecs = [params_vector(model, r) for r in rows]
    names = vecs[0][0]
    mat = np.ascontiguousarray(np.array([v[1] for v in vecs], dtype=float))
    out = problem(recording, model, **numerics).simulate_batch(mat, states=bool(states))
    return BatchResult(model=model.kind, names=names, params=mat, t=recording.t, force=out["force"], q=out["q"],
                       qd=out.get("qd"), qdd=out.get("qdd"), errors=list(out["errors"]))


__all__ = ["simulate", "plot_robot_forces", "column_errors", "settling_samples", "simulate_batch", "problem", "sim_options", "SimResult", "BatchResult", "Term", "TERM_KINDS", "param_names",
           "params_vector", "entry_model", "coulomb_sign", "MODELS", "NUMERICS", "INTEGRATORS", "DEFAULT_COULOMB_EPS", "DEFAULT_TOL",
           "COULOMB_EPS_REL", "COULOMB_LAWS", "default_coulomb_eps", "coulomb_eps_of"]
