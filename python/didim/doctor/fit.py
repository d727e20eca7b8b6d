"""The model as the doctor grows it (:class:`State`), the training and validation views of the data, and the DIDIM
refit every effect uses."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .. import units
from ..methods.identification import didim_iterate
from ..model import Model
from ..recording import Recording
from ..result import IdentificationResult
from ..signal import Decimation
from ..simulation import DEFAULT_COULOMB_EPS, SimResult, Term, simulate


@dataclass(frozen=True)
class State:
    """The model as the doctor grows it: the structure (:class:`didim.Model`: kind, offset, terms, delay, force lag,
    backlash, friction law), its parameters, the frozen ones, and the axis whose units the words use. The friction
    law (``model.coulomb_eps``, ``model.coulomb_law``) is part of the base model, fitted before any effect is looked
    for."""

    model: Model
    params: Dict[str, float]
    frozen: Dict[str, float]
    #: "linear" or "rotary": the units the words say.
    axis: str = "linear"

    @property
    def kind(self) -> str:
        return self.model.kind

    def with_(self, **fields) -> "State":
        """This state with some of its structure's fields (``terms=…``, ``force_lag=…``) or its own
        (``params=…``, ``frozen=…``) replaced."""
        own = {k: fields.pop(k) for k in ("params", "frozen", "axis") if k in fields}
        return replace(self, model=replace(self.model, **fields), **own) if fields else replace(self, **own)

    def all_params(self) -> Dict[str, float]:
        return {**self.frozen, **self.params}

    def simulate(self, rec: Recording) -> SimResult:
        """The closed loop of ``rec`` with this state's model and parameters."""
        return simulate(rec, self.all_params(), self.model)

    def coulomb(self) -> float:
        """The Coulomb friction on the motor side (Fc or Fc1)."""
        return self.params.get("Fc", self.params.get("Fc1", 1.0))


class Data:
    """Training and validation views of the data, in the decimated domain of the doctor."""

    def __init__(self, rec: Recording, validate: Optional[Recording], dec: Decimation, holdout: float):
        self.rec, self.validate, self.dec = rec, validate, dec
        self.y = dec(rec.force)
        if validate is None:
            self.n_train = int(round(rec.n * (1 - holdout)))
            self.m_train = -(-self.n_train // dec.factor)
            self.yv = self.y[self.m_train:]
        else:
            self.n_train = rec.n
            self.m_train = len(self.y)
            self.yv = dec(validate.force)
        # the first decimated training and held-out rows the tests and errors use (see settle)
        self.t0, self.v0 = 0, 0
        self._sims: List[Tuple[State, Recording, SimResult]] = []  # see simulate

    #: How many recent simulations :meth:`simulate` keeps.
    KEEP = 8

    def simulate(self, state: State, rec: Recording) -> SimResult:
        """``state.simulate(rec)``, kept for the states simulated last: the doctor asks for the same model's residuals,
        force errors and views one after the other (a state is immutable; it is kept with its simulation, so an
        identity match is the same model)."""
        for st, r, sim in self._sims:
            if st is state and r is rec:
                return sim
        sim = state.simulate(rec)
        self._sims = [(state, rec, sim)] + self._sims[:self.KEEP - 1]
        return sim

    def settle(self, state: State) -> None:
        """Leaves out of the decimated residuals the rows a record's start reaches when it began away from the
        simulated initial state (a log started while the axis moved): there the simulation answers a start the axis
        never had, whatever the model, and those rows would dominate the tests and the held-out comparison
        (on the EMPS, 47-61 % of the residual energy in the first 33-56 ms)."""
        from ..methods.identification import settled_row

        sim = self.simulate(state, self.rec)
        self.t0 = min(settled_row(self.rec, sim.q[0], self.dec), self.m_train // 2)
        if self.validate is not None:
            simv = self.simulate(state, self.validate)
            self.v0 = min(settled_row(self.validate, simv.q[0], self.dec), len(self.yv) // 2)

    @property
    def train_rows(self) -> slice:
        return slice(self.t0, self.m_train)

    def errors(self, state: State) -> Tuple[np.ndarray, np.ndarray, SimResult]:
        """Decimated residuals on the training and validation rows past a record's start (see :meth:`settle`), and
        the training simulation."""
        sim = self.simulate(state, self.rec)
        ys = self.dec(sim.force)
        rt = self.y[self.train_rows] - ys[self.train_rows]
        if self.validate is None:
            rv = self.yv - ys[self.m_train:]
        else:
            simv = self.simulate(state, self.validate)
            rv = self.yv[self.v0:] - self.dec(simv.force)[self.v0:]
        return rt, rv, sim

    def force_errors(self, state: State) -> Tuple[float, float]:
        """Closed-loop force errors ‖τ − τ_sim‖/‖τ‖ at the full rate on the training and the validation samples: the
        measure of ``result.force_error`` and of the EMPS benchmark (the residual tests work on the decimated force)."""
        def rel(y, ys):
            return float(np.linalg.norm(y - ys) / np.linalg.norm(y))

        ys = self.simulate(state, self.rec).force
        y, n = self.rec.force, self.n_train
        if self.validate is None:
            return rel(y[:n], ys[:n]), rel(y[n:], ys[n:])
        yv = self.simulate(state, self.validate).force
        return rel(y, ys), rel(self.validate.force, yv)

    def views(self, state: State) -> List[Tuple[SimResult, slice]]:
        """The simulations of ``state`` behind the training and the held-out residual, each with the decimated rows
        that residual covers (the held-out rows are the tail of the training record's simulation when no separate
        record validates)."""
        sim = self.simulate(state, self.rec)
        if self.validate is None:
            return [(sim, self.train_rows), (sim, slice(self.m_train, None))]
        simv = self.simulate(state, self.validate)
        return [(sim, self.train_rows), (simv, slice(self.v0, None))]

    def decimated_columns(self, columns: np.ndarray, rows: slice) -> np.ndarray:
        """Full-rate regressor columns (n × k) of any record of this rate, decimated, on ``rows``."""
        return self.dec.columns(columns)[rows]

    def train_record(self) -> Recording:
        """The training samples as a record of their own (the whole record when a separate one validates): for fits
        that take a whole record, so that they never see the held-out samples (the closed loop is causal, so its
        simulation on the first samples is the first samples of the whole one)."""
        if self.validate is not None:
            return self.rec
        n, rec = self.n_train, self.rec
        cut = {k: (None if getattr(rec, k) is None else getattr(rec, k)[:n]) for k in ("qr", "force", "qm", "ql", "u_ext")}
        return replace(rec, **cut)

    def rel(self, r: np.ndarray, train: bool) -> float:
        y = self.y[self.train_rows] if train else self.yv[self.v0:]
        return float(np.linalg.norm(r) / np.linalg.norm(y))

    def train_columns(self, columns: np.ndarray) -> np.ndarray:
        """Full-rate regressor columns (n × k), decimated, on the training rows."""
        return self.decimated_columns(columns, self.train_rows)

    def train_motor_columns(self, state: State, sim: SimResult, groups: Sequence[Sequence[Term]]) -> List[np.ndarray]:
        """:func:`motor_columns_many` decimated on the training rows, as :meth:`train_columns` gives them (bit for
        bit), from the core without the full-rate columns (:func:`_decimated_motor_columns`)."""
        core, first, ends = _extra_core(state, groups)
        x = _decimated_motor_columns(core, sim, list(range(first, len(core.names))), self.dec)[self.train_rows]
        return [x[:, e - len(g):e] for g, e in zip(groups, ends)]

    def train_base_columns(self, state: State, sim: SimResult) -> np.ndarray:
        """:func:`base_columns` decimated on the training rows (as :meth:`train_motor_columns`)."""
        core, keep = _base_core(state)
        return _decimated_motor_columns(core, sim, keep, self.dec)[self.train_rows]


def refit(data: Data, state: State, init: Dict[str, float], progress,
          give_up_above: Optional[float] = None) -> Tuple[State, IdentificationResult]:
    """DIDIM refit of ``state`` (with its new terms) from ``init``, on the training samples; ``give_up_above`` as for
    :func:`didim.methods.identification.didim_iterate`."""
    free_init = {k: v for k, v in {**state.params, **init}.items() if k not in state.frozen}
    # every sample: the effects the doctor looks for (Stribeck, backlash, ...) live around reversals and stops
    r = didim_iterate(data.rec, state.model, free_init, frozen=state.frozen, decimation=data.dec, tol=1e-4,
                      max_iter=30, fit_samples=data.n_train, reversals="keep", give_up_above=give_up_above)
    r.set_axis(state.axis)
    return replace(state, params=dict(r.params)), r


def refit_each(data: Data, jobs: Sequence[Tuple[State, Dict[str, float]]], progress) -> List[Any]:
    """:func:`refit` of independent (state, init) pairs on the cores of the machine (the core releases the interpreter
    while it simulates): ``(state, result)`` for each, or the :class:`DidimError` it raised, in the order given."""
    from .._parallel import cores, map_threads

    from .._errors import DidimError

    def one(job):
        try:
            return refit(data, job[0], job[1], progress)
        except DidimError as e:
            return e

    workers = max(1, min(len(jobs), cores()))
    if workers == 1:
        return [one(j) for j in jobs]
    return map_threads(one, jobs, workers)


def motor_columns(state: State, sim: SimResult, extra: Sequence[Term]) -> np.ndarray:
    """Columns (n × k) of the motor-row regressor of ``extra`` terms on the simulated states, from the core."""
    return motor_columns_many(state, sim, [extra])[0]


def motor_columns_many(state: State, sim: SimResult, groups: Sequence[Sequence[Term]]) -> List[np.ndarray]:
    """:func:`motor_columns` of each group of extra terms (the variants of a grid), from one core call: the columns
    of every group are computed together, each exactly as alone (a term's column depends on that term only)."""
    core, first, ends = _extra_core(state, groups)
    # the extra terms' columns on the motor's rows only (the whole regressor of both dofs is 2 × p columns)
    cols = np.asarray(core.regressor_columns(sim.q, sim.qd, sim.qdd, list(range(first, len(core.names))), 0))
    return [cols[:, e - len(g):e] for g, e in zip(groups, ends)]


def _extra_core(state: State, groups: Sequence[Sequence[Term]]):
    """The core model of ``state`` with every group's terms (renamed apart), the index of the first of them and the
    groups' ends among them."""
    extra = [Term(f"{t.name}_{i}", t.kind, dof=t.dof, **t.hypers) for i, g in enumerate(groups) for t in g]
    core = state.model.with_terms(*extra).core(DEFAULT_COULOMB_EPS)
    return core, len(core.names) - len(extra), np.cumsum([len(g) for g in groups], dtype=int)


def _decimated_motor_columns(core, sim: SimResult, cols: List[int], dec) -> np.ndarray:
    """The core model's columns ``cols`` on the motor's rows, decimated by ``dec`` (m × k)."""
    return np.asarray(core.decimated_columns(sim.q, sim.qd, sim.qdd, cols, 0, dec.core))


def _base_core(state: State):
    core = state.model.core(DEFAULT_COULOMB_EPS)
    return core, [i for i, n in enumerate(core.names) if n not in state.frozen]


def base_columns(state: State, sim: SimResult) -> np.ndarray:
    """Columns of the motor-row regressor of the state's free parameters."""
    core, keep = _base_core(state)
    return np.asarray(core.regressor_columns(sim.q, sim.qd, sim.qdd, keep, 0))


#: The Coulomb smoothing speeds the base fit tries, as fractions of the record's speed scale
#: (:attr:`Recording.speed_scale`): from far sharper than any encoder resolves to a law that bends over a percent
#: of the top speed, a factor of √10 apart.
EPS_GRID_REL = tuple(float(x) for x in np.geomspace(1e-6, 1e-2, 9))


#: The shapes the doctor chooses among. Not "atan": its tail (1 − 4/(π² x) at x = v/ε) keeps friction 6 % below its
#: Coulomb level at ten smoothing speeds, a broad low-speed deficit rather than a transition through zero speed; fitted
#: on the EMPS it took the place of the axis's real deficit (8.8 N below 14 mm/s) and the validation error rose from
#: 3.27 % to 3.59 %.
DOCTOR_LAWS = ("algebraic", "tanh", "exp")


def fit_friction_law(data: Data, state: State, progress, around: Optional[float] = None,
                     shapes: Optional[Sequence[str]] = None) -> Tuple[State, IdentificationResult]:
    """The base model's friction law through zero speed, fitted before any effect is looked for: the shape of the
    Coulomb sign (``DOCTOR_LAWS``: algebraic ``v/sqrt(v² + ε²)``, tanh, exp, each with the slope 1/ε at rest)
    and its transition speed ε, chosen by closed-loop DIDIM refits on the training samples (lowest decimated output
    error). Real friction's shape through zero speed is not known in advance (another smoothing, sticking): an ε fixed
    in m/s is a hidden scale that a rotary axis or a record in mm reads as another law, and whatever the law misses
    shows up as a "low-speed effect" that is only the law's shape.

    The start: ε on ``EPS_GRID_REL`` with the algebraic law (or the first of ``shapes``), its best point (or, given
    ``around``, that smoothing speed in m/s or rad/s); then every plant's search (:func:`didim.methods.friction_law.
    closed_loop_law`) from it, for each shape (``shapes``, all by default), each law a DIDIM refit, a batch of them
    on the cores of the machine."""
    from .._parallel import cores, map_threads

    from ..methods import friction_law
    from .._errors import DidimError
    scale = data.rec.speed_scale
    say = progress or (lambda s: None)
    say("friction law: fitting the Coulomb law's shape and smoothing speed")
    shapes = tuple(shapes or DOCTOR_LAWS)
    fitted: Dict[Any, Tuple[State, IdentificationResult]] = {}
    known: Dict[Any, Optional[np.ndarray]] = {}
    start = state
    workers = max(1, min(len(shapes) * 3, cores()))

    def evaluate(f, laws):
        if workers == 1 or len(laws) == 1:
            return [f(lw) for lw in laws]
        return map_threads(f, laws, workers)

    def errors(law) -> Optional[np.ndarray]:
        try:
            got = refit(data, start.with_(coulomb_law=law[0], coulomb_eps=law[1][0]), {}, progress)
        except DidimError:
            return None
        if not np.isfinite(got[1].output_error):
            return None
        fitted[law] = got
        return np.array([got[1].output_error])

    if around is not None:
        eps0 = float(around)
    else:
        first = shapes[0]
        grid = [(first, (rel * scale,)) for rel in EPS_GRID_REL]
        for lw, e in zip(grid, evaluate(errors, grid)):
            known[lw] = e
        good = [lw for lw in grid if known[lw] is not None]
        if not good:  # keep the law the base model came with
            return refit(data, state, {}, progress)
        best0 = min(good, key=lambda lw: float(known[lw][0]))
        eps0, start = best0[1][0], fitted[best0][0]
    # the grid's points √10 apart, the search's a fraction of that: it reaches the grid's neighbours of the start
    reach = int(math.ceil(math.log(float(EPS_GRID_REL[1] / EPS_GRID_REL[0])) / (2 * friction_law.QUARTER)))
    found = friction_law.closed_loop_law({sh: (eps0,) for sh in shapes}, errors, reach=reach, evaluate=evaluate,
                                         known=known)
    if not math.isfinite(found.error):
        return refit(data, state, {}, progress)
    law = found.law
    if law not in fitted and errors(law) is None:
        return refit(data, state, {}, progress)
    eps = float(fitted[law][0].model.coulomb_eps)
    say(f"friction law: the search's best is {law[0]}, smoothing speed {units.speed(eps, data.rec.axis)} "
        f"({eps / scale:.3g} of the top speed; output error {100 * found.error:.2f} %)")
    return fitted[law]
