"""Closed-loop simulation of a recording's axis with given parameters (thin layer over the Rust core)."""

from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Dict, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _checks, _core
from ._errors import DataError, DidimError
from .recording import Recording

if TYPE_CHECKING:
    from .model import Model

MODELS = ("rigid", "flexible")

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
#: The shapes of the Coulomb sign through zero speed the core knows (``coulomb_law``).
COULOMB_LAWS: Tuple[str, ...] = tuple(_core.COULOMB_LAWS)


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

#: Degrees of freedom a term can act on (the load only in the flexible model).
TERM_DOFS = ("motor", "load")
#: Kinds of extra model terms, as the core's model defines them (``Basis::from_kind``): see :class:`Term`.
TERM_KINDS = tuple(_core.TERM_KINDS)


@dataclass(frozen=True)
class Term:
    """An extra term of a model, a parameter ``name`` times a basis function of the motor state:

    - ``offset``: 1 (N); ``viscous``: q̇; ``coulomb``: sign(q̇);
    - ``abs_viscous``: |q̇| and ``abs_coulomb``: |sign(q̇)|, friction that depends on the direction of motion;
    - ``stribeck``: sign(q̇)·exp(−(q̇/vs)²) with ``hyper`` = vs (m/s);
    - ``ripple_sin``/``ripple_cos``: sin/cos(2π q/P) with ``hyper`` = P (m);
    - ``coulomb_ripple_sin``/``coulomb_ripple_cos``: sign(q̇)·sin/cos(2π q/P), ``hyper`` = P (m): Coulomb friction
      that varies along the stroke, always against the motion;
    - ``coulomb_spline_fwd``/``coulomb_spline_bwd``: B((q − c)/w)·s(1 ± s)/2 with s = sign(q̇) (1 or 0 forward, 0 or
      −1 backward, smooth through rest), ``hyper`` = c the knot (m), ``width`` = w the knot spacing (m), B the cubic B-spline (B-splines w
      apart sum to 1): a friction profile along the stroke for each direction, each parameter the friction added near
      its knot (N);
    - ``damper`` (flexible model): coupling damping in parallel with K12, q̇1 − q̇12 on the motor row and its opposite
      on the load row (N/(m/s)).

    ``dof``: the degree of freedom whose state the term reads and whose row it acts on, "motor" (default) or "load"
    (flexible model: e.g. a Stribeck friction of the load, read on q̇12); a ``damper`` always couples the two.
    ``width``: the knot spacing of a spline term (m); 0 for the other kinds.
    """

    name: str
    kind: str
    hyper: float = 0.0
    dof: str = "motor"
    width: float = 0.0

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise DataError(f"a term's name must be a non-empty text, got {self.name!r}")
        if not isinstance(self.kind, str) or self.kind not in TERM_KINDS:
            raise DataError(f"unknown term kind {self.kind!r}: use one of {', '.join(TERM_KINDS)}")
        object.__setattr__(self, "hyper", _checks.real(f"term {self.name}'s hyper-parameter", self.hyper))
        spline = self.kind.startswith("coulomb_spline")
        if spline and isinstance(self.width, (int, float)) and not isinstance(self.width, bool) and self.width == 0:
            raise DataError(f"term {self.name}: a {self.kind} term needs its knot spacing: give width= (m, > 0), e.g. "
                            f"didim.Term({self.name!r}, {self.kind!r}, {self.hyper!r}, width=0.05)")
        object.__setattr__(self, "width", _checks.real(
            f"term {self.name}'s width", self.width, "m", lo=0.0, lo_open=spline,
            hint=" (the knot spacing of a spline term, > 0 m)" if spline else " (only spline terms have a width: 0)"))
        if self.width and not spline:
            raise DataError(f"term {self.name}: only spline terms have a width (knot spacing); leave it 0 for a "
                            f"{self.kind} term")
        _checks.one_of(f"term {self.name}'s dof", self.dof, TERM_DOFS)
        if self.kind == "damper" and self.dof != "motor":
            raise DataError(f"term {self.name}: a damper couples the motor and the load; leave its dof out")

    def spec(self) -> tuple:
        """(name, kind, hyper, dof, width), as the core and a saved model take it."""
        return (self.name, self.kind, float(self.hyper), self.dof, float(self.width))


def _specs(terms) -> Optional[list]:
    if terms is None or (isinstance(terms, (tuple, list)) and not terms):
        return None
    if not isinstance(terms, (tuple, list)) or not all(isinstance(t, Term) for t in terms):
        raise DataError(f"terms must be a list of didim.Term, e.g. [didim.Term('Fs', 'stribeck', 0.01)], got {terms!r}")
    return [t.spec() for t in terms]


def coulomb_sign(v, eps: float = DEFAULT_COULOMB_EPS) -> np.ndarray:
    """The sign used by every Coulomb friction term, identical to the core's: ``v/sqrt(v²+eps²)``, hard sign for eps = 0."""
    v = _checks.real_array("v", v, None)
    eps = _checks.real("eps", eps, "m/s", lo=0.0, lo_open=False)
    if eps > 0:
        with np.errstate(all="ignore"):
            d = v * v + eps * eps
            out = v / np.sqrt(d)
            odd = ~(np.isfinite(d) & (d >= np.finfo(float).tiny))  # v² + eps² under- or overflows: as the core
            if np.any(odd):
                out = np.where(odd, np.where(np.isinf(v), np.sign(v), v / np.hypot(v, eps)), out)
        return out
    return np.sign(v)


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
    run = np.convolve(over.astype(np.int64), np.ones(w, np.int64), "full")[w - 1:n + w - 1]  # over[i:i+w] counts
    for i in np.flatnonzero(over):
        if i + 1 >= n // 2:
            break
        if run[i + 1] == 0:
            return int(i + 1)
    return 0


def cubic_bspline(u) -> np.ndarray:
    """The uniform cubic B-spline of the friction-profile terms (``coulomb_spline_*``), the core's function: support
    ``|u| < 2``, ``B(0) = 2/3``, the B-splines at the integers summing to 1."""
    a = np.abs(np.asarray(u, dtype=float))
    return np.where(a < 1, 2 / 3 - a * a + 0.5 * a * a * a, np.where(a < 2, (2 - a) ** 3 / 6, 0.0))


def _check_model(model: str) -> None:
    if model not in MODELS:
        raise DataError(f"unknown model {model!r}: use one of {', '.join(MODELS)}")


def _is_model(x) -> bool:
    from .model import Model

    return isinstance(x, Model)


def unpack_model(model, offset: Optional[bool], given: Dict[str, Any]) -> Tuple[str, Optional[bool], Dict[str, Any]]:
    """``model`` as a kind name ("rigid", "flexible") or a :class:`didim.Model`: returns the kind, the offset and the
    structure keywords (terms, delay, force_lag, backlash_gap, coulomb_eps) merged into ``given``. A Model carries its structure:
    giving one of its fields again (``offset`` or any of ``given``'s structure keywords, set to anything but its
    default) is an error naming it."""
    if not _is_model(model):
        return model, offset, given
    st = model.sim_kw()
    again = [k for k in ("terms", "delay", "force_lag", "backlash_gap", "coulomb_eps", "coulomb_law") if k in given
             and given[k] not in ((), None, 0, "algebraic")]
    if offset is not None and bool(offset) != model.offset:
        again.insert(0, "offset")
    if again:
        raise DataError(f"a didim.Model ({model.describe()}) carries its structure: leave {', '.join(again)} out, or give "
                        "the model's kind as text with the structure you want")
    return model.kind, model.offset, {**given, **{k: v for k, v in st.items() if k != "offset"}}


def param_names(model: str = "rigid", offset: bool = False, terms: Sequence[Term] = ()) -> list:
    """Parameter names of a model in the order of its parameter vector (M, Fv, Fc[, OF] or M1, Fv1, Fc1, M2, Fv2, Fc2,
    K12[, OF]), followed by the extra terms'."""
    _check_model(model)
    return list(_names(model, bool(offset), tuple(_specs(terms) or ())))


@functools.lru_cache(maxsize=256)
def _names(model: str, offset: bool, specs: tuple) -> tuple:
    """The core's names, kept per structure: identification loops ask for them at every step."""
    return tuple(_core.param_names(model, offset, list(specs) or None))


def params_vector(model: str, params: Params, offset: Optional[bool] = None, terms: Sequence[Term] = ()):
    """Returns ``(names, vector, offset)`` for parameters given as a name → value mapping or a sequence."""
    _check_model(model)
    if isinstance(params, Mapping):
        if offset is None:
            offset = "OF" in params
        names = param_names(model, offset, terms)
        missing = [k for k in names if k not in params]
        unknown = [k for k in params if k not in names]
        if missing or unknown:
            raise DataError(
                f"parameters for the {model} model{' with offset' if offset else ''} are {', '.join(names)}"
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
        if offset is None:
            offset = vec.size == len(param_names(model, False, terms)) + 1
        names = param_names(model, offset, terms)
        if vec.size != len(names):
            raise DataError(f"the {model} model takes {len(names)} parameters ({', '.join(names)}), got {vec.size}")
    return names, vec, bool(offset)


@dataclass(frozen=True)
class SimResult:
    """Outputs of a closed-loop simulation, one value per sample (time is the last axis).

    ``force`` is the commanded motor force (N); ``q``, ``qd``, ``qdd`` have shape (ndof, n): row 0 is the motor
    (q1, m, m/s, m/s²), row 1 the load (q12) for the flexible model. States are noise-free.
    """

    model: str
    params: Dict[str, float]
    t: np.ndarray
    force: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

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
        """``‖τ − τ_sim‖ / ‖τ‖`` against the recording's measured force (NaN when the measured force is zero)."""
        ref = float(np.linalg.norm(recording.force))
        if ref == 0 or not np.isfinite(ref):
            return float("nan")
        return float(np.linalg.norm(recording.force - self.force) / ref)

    def settled(self, recording: Recording) -> Tuple[int, float]:
        """For a record that began away from this simulation's start (:func:`settling_samples`): how many first samples
        the simulation takes to join it, and the relative force error after them; (0, NaN) for a record that starts
        where the simulation does."""
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


def sim_options(
    recording: Recording,
    *,
    substeps: int = 10,
    quantization: Optional[float] = None,
    delay: int = 0,
    force_lag: float = 0.0,
    coulomb_eps: Optional[float] = None,
    coulomb_law: str = "algebraic",
    integrator: str = "exponential",
    tol: float = DEFAULT_TOL,
) -> dict:
    """Validated simulator keyword options for the core, with the recording's encoder resolution by default."""
    if quantization is None:
        quantization = recording.position_resolution or 0.0
    quantization = _checks.real("quantization", quantization, "m", lo=0.0, lo_open=False, hint=" (0 for none)")
    _checks.options(substeps=substeps)
    coulomb_eps = coulomb_eps_of(recording, coulomb_eps)
    _checks.one_of("coulomb_law", coulomb_law, COULOMB_LAWS)
    delay = _checks.whole("delay", delay, lo=0, hi=recording.n - 1, hint=" (actuation delay in samples)")
    if integrator not in INTEGRATORS:
        raise DataError(f"unknown integrator {integrator!r}: use one of {', '.join(INTEGRATORS)}")
    if not (isinstance(tol, (int, float)) and math.isfinite(tol) and 0 < tol < 1):
        raise DataError(f"tol must be a fraction of the stroke between 0 and 1, got {tol!r}")
    force_lag = _checks.real("force_lag", force_lag, "s", lo=0.0, lo_open=False, hint=" (0 for none)")
    return dict(substeps=int(substeps), quantization=float(quantization), delay=int(delay), force_lag=force_lag,
                coulomb_eps=float(coulomb_eps), coulomb_law=coulomb_law, integrator=integrator, tol=float(tol))


def problem(recording: Recording, model: Union[str, "Model"] = "rigid", *, offset: Optional[bool] = None,
            terms: Sequence[Term] = (), backlash_gap: Optional[float] = None, **sim_kw) -> "_core.Problem":
    """The recording's closed loop held by the Rust core (reference, controller, external input, model structure and
    simulator options), for repeated simulations with varying parameters. ``model`` is a kind name or a
    :class:`didim.Model`; ``sim_kw`` as for :func:`simulate`."""
    model, offset, kw = unpack_model(model, offset, dict(sim_kw, terms=terms, backlash_gap=backlash_gap))
    terms, backlash_gap = kw.pop("terms"), kw.pop("backlash_gap")
    sim_kw = kw
    _check_model(model)
    _checks.known_options([sim_options, problem], sim_kw, "the simulator")
    opts = sim_options(recording, **sim_kw)
    # a log that begins in motion is simulated from the rest before its lead-in, and output from its first sample
    qr, u_ext = recording.lead_in_signals()
    return _core.Problem(model, qr, recording.dt, recording.controller.kind, list(recording.controller.gains),
                         u_ext=u_ext, offset=bool(offset), terms=_specs(terms), backlash_gap=backlash_gap,
                         lead=int(recording.qr_lead.size), **opts)


def simulate(
    recording: Recording,
    params: Params,
    model: Union[str, "Model"] = "rigid",
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
        params: a mapping name → value (SI units, load side) or a sequence in the order of :func:`param_names`.
        model: "rigid" (eq. (6)) or "flexible" (eq. (2)), or a :class:`didim.Model` (its kind and structure: offset,
            terms, delay, backlash, Coulomb smoothing).
        offset: rigid model with a constant force OF; by default, when params names OF or has 4 values.
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
    if _is_result(params):  # a result carries its model structure and its simulator's numerics
        given = [k for k, v in (("terms", terms), ("backlash_gap", backlash_gap), ("delay", delay), ("force_lag", force_lag))
                 if v not in ((), None, 0)]
        if given:
            raise DataError(f"a result carries its model structure: leave {', '.join(given)} out, or simulate "
                            "result.all_params with the structure you want")
        st = _structure(params)
        model, offset, terms, backlash_gap, delay, force_lag, coulomb_eps, coulomb_law = (
            st.kind, st.offset, st.terms, st.backlash_gap, st.delay, st.force_lag, st.coulomb_eps, st.coulomb_law)
        integrator = params.options.get("integrator", integrator)
        tol = params.options.get("sim_tol", tol)
        substeps = params.options.get("substeps", substeps)
        params = params.all_params
    model, offset, st = unpack_model(model, offset, dict(terms=terms, delay=delay, force_lag=force_lag,
                                                        backlash_gap=backlash_gap, coulomb_eps=coulomb_eps,
                                                        coulomb_law=coulomb_law))
    terms, delay, force_lag = st["terms"], st["delay"], st["force_lag"]
    backlash_gap, coulomb_eps, coulomb_law = st["backlash_gap"], st["coulomb_eps"], st["coulomb_law"]
    if offset is not None:
        offset = _checks.flag("offset", offset)
    names, vec, offset = params_vector(model, params, offset, terms)
    out = problem(recording, model, offset=offset, terms=terms, backlash_gap=backlash_gap, substeps=substeps,
                  quantization=quantization, delay=delay, force_lag=force_lag, coulomb_eps=coulomb_eps,
                  coulomb_law=coulomb_law,
                  integrator=integrator,
                  tol=tol).simulate(vec)
    return SimResult(
        model=model,
        params=dict(zip(names, map(float, vec))),
        t=recording.t,
        force=out["force"],
        q=out["q"],
        qd=out["qd"],
        qdd=out["qdd"],
    )


def _is_result(x) -> bool:
    from .result import IdentificationResult

    return isinstance(x, IdentificationResult)


def _structure(result):
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
    if isinstance(params, Mapping) or _is_result(params):
        raise DataError("simulate_batch takes a sequence of parameter sets; use simulate for one")
    if isinstance(params, (str, bytes)) or not isinstance(params, (Sequence, np.ndarray)):
        raise DataError("simulate_batch takes a sequence of parameter sets (a list of mappings or results, or an "
                        f"(m, p) array), got {type(params).__name__}")
    states = _checks.flag("states", states)
    model, offset, sim_kw = unpack_model(model, offset, sim_kw)
    rows = list(params) if not isinstance(params, np.ndarray) else params
    if len(rows) and all(_is_result(r) for r in rows):  # results: one structure for all, its options by default
        structures = {_structure(r) for r in rows}
        if len(structures) > 1:
            raise DataError("the results of a batch must share one model structure (kind, offset, terms, delay, force lag, "
                            "backlash, Coulomb smoothing); simulate them one by one")
        st = structures.pop()
        model, offset = st.kind, st.offset
        for k, v in dict(terms=st.terms, delay=st.delay, force_lag=st.force_lag, backlash_gap=st.backlash_gap,
                         coulomb_eps=st.coulomb_eps, coulomb_law=st.coulomb_law).items():
            sim_kw.setdefault(k, v)
        sim_kw.setdefault("integrator", rows[0].options.get("integrator", "exponential"))
        rows = [r.all_params for r in rows]
    if isinstance(rows, np.ndarray) and rows.ndim == 1:
        raise DataError("params must be 2-D, one parameter set per row (use simulate for one set)")
    if len(rows) == 0:
        raise DataError("params holds no parameter set")
    vecs = [params_vector(model, r, offset, sim_kw.get("terms", ())) for r in rows]
    names, _, offset = vecs[0]
    if any(v[2] != offset for v in vecs):
        raise DataError("all parameter sets of a batch must have the same parameters (with or without OF)")
    mat = np.ascontiguousarray(np.array([v[1] for v in vecs], dtype=float))
    out = problem(recording, model, offset=offset, **sim_kw).simulate_batch(mat, states=bool(states))
    return BatchResult(model=model, names=names, params=mat, t=recording.t, force=out["force"], q=out["q"],
                       qd=out.get("qd"), qdd=out.get("qdd"), errors=list(out["errors"]))


__all__ = ["simulate", "settling_samples", "simulate_batch", "problem", "sim_options", "SimResult", "BatchResult", "Term", "TERM_KINDS", "param_names",
           "params_vector", "coulomb_sign", "MODELS", "INTEGRATORS", "DEFAULT_COULOMB_EPS", "DEFAULT_TOL",
           "COULOMB_EPS_REL", "COULOMB_LAWS", "default_coulomb_eps", "coulomb_eps_of"]
