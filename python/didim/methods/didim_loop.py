"""DIDIM's iterations, once for every plant (eqs. (16)–(21)): simulate the closed loop with the current estimate,
refit the inverse model by least squares on the simulated states, until the estimate settles; with the safeguards
the paper does not have, which never act on an iteration that goes well.

A plant says how (:class:`DidimPlant`): a single axis (:func:`didim.methods.identification.didim_iterate`), a robot
(:func:`didim.robots.didim`) or a payload on a robot's last body (:func:`didim.robots.payload`) each give their
simulation, their least squares, what a physical estimate is and when they have settled; this loop does the rest:

- an LS step that gives an estimate the plant calls non-physical (a mass or a stiffness non-positive or changed by
  more than 4×) is shortened, θ + α(θ_LS − θ) with α = 1/2, 1/4, … 1/64;
- an iterate whose simulation fails (it diverges, or the arm's articulated inertia is not positive), or whose
  output error exceeds ``divergence_factor`` times the best so far, is pulled back halfway to the best iterate, at
  most :data:`MAX_BACKTRACKS` times in a row, before the iteration is declared divergent;
- on a plant that asks for it (``relax_alternation``: a robot's elastic model, whose step-3 rows can overshoot),
  once the iterates alternate between two points (:func:`_alternating`) every step is taken halfway, the same fixed
  point reached where full steps circle it (one axis handles its own alternation, between two sets of rows left out
  around reversals, by freezing both);
- the plant's criterion says when it has converged (eq. (21) for one axis; the output error settled or stalled at
  the encoder's noise for a robot), and the plant may then change its model (a robot's friction law chosen in closed
  loop) and go on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Protocol, Sequence

import numpy as np

from .._errors import DataError, DidimError, IdentifiabilityError, SimulationError

#: Pull-backs toward the best iterate before an iteration is declared divergent.
MAX_BACKTRACKS = 6
#: An iterate whose output error exceeds this factor times the best so far is pulled back (a real rise, not the
#: wandering of DIDIM's fixed point, which is not the output-error minimum).
DIVERGENCE_FACTOR = 1.5
#: The smallest step fraction tried before a non-physical LS estimate stops the iterations.
MIN_ALPHA = 1 / 64
#: The step fraction once the iterates alternate between two points (:func:`_alternating`).
RELAXED_STEP = 0.5
#: The steps (the next one included) that must each reverse the one before to call the iterates alternating.
ALTERNATION_STEPS = 4


class DidimPlant(Protocol):
    """What DIDIM's iterations need of a plant. θ is the plant's whole parameter vector; ``free`` indexes the
    entries the least squares estimate (the others are held)."""

    free: Sequence[int]

    def simulate(self, theta: np.ndarray) -> Any:
        """The closed loop with θ (raises :class:`SimulationError` or :class:`DataError` when it cannot be
        simulated)."""

    def output_error(self, sim: Any) -> float:
        """The simulated output error the iterations compare (relative)."""

    def solve(self, theta: np.ndarray, sim: Any) -> Dict[str, Any]:
        """The least squares on the simulated states: a dict with ``params`` (the free entries), ``std``,
        ``covariance``, ``relative_error`` and ``residual_norm`` (raises :class:`IdentifiabilityError`)."""

    def physical(self, new: np.ndarray, old: Optional[np.ndarray]) -> bool:
        """Whether ``new`` is a physical estimate (and, with ``old``, a step the plant accepts from it)."""

    def converged(self, loop: "DidimLoop") -> bool:
        """Whether the iterations have converged, after the step just taken (``loop.history``, ``loop.errors``)."""

    def settled(self, loop: "DidimLoop") -> str:
        """Called when :meth:`converged` says so: ``"accept"`` ends the iterations, ``"continue"`` goes on,
        ``"restart"`` goes on with the best iterate forgotten (the plant changed its model)."""

    def describe(self, loop: "DidimLoop") -> str:
        """The progress line of the iteration just taken."""


def residual_settled(loop: "DidimLoop", tol: float) -> bool:
    """Criterion (21), every plant's: the least squares' residual ‖y − Wθ̂‖ on the simulated states changed by at
    most ``tol`` of itself over a whole step (a shortened step says nothing of the fixed point), since the plant last
    changed its model. The regression's residual, not the closed loop's output error: the latter wanders at the
    level the encoder's rounding in the loop sets (a UR5's: ±0.2 % of itself from one iterate to the next, where the
    residual moves by 1e-4 of itself)."""
    h = loop.history[loop.since_step:]
    if loop.alpha != 1 or len(h) < 2:
        return False
    rho, rho_prev = float(h[-1]["residual_norm"]), float(h[-2]["residual_norm"])
    return abs(rho - rho_prev) <= tol * rho_prev


@dataclass
class DidimLoop:
    """The state and outcome of DIDIM's iterations: ``theta`` the last estimate, ``best`` the iterate with the lowest
    output error (error, θ, its solution, its index in ``history``), ``errors`` every simulated output error (and
    ``thetas`` the estimates simulated),
    ``history`` the solutions in order, the simulations run, and how it ended."""

    theta: np.ndarray
    best: tuple = (math.inf, None, None, None)
    errors: List[float] = field(default_factory=list)
    #: The estimate each of ``errors`` was simulated with.
    thetas: List[np.ndarray] = field(default_factory=list)
    history: List[Dict[str, Any]] = field(default_factory=list)
    simulations: int = 0
    converged: bool = False
    message: str = ""
    notes: List[str] = field(default_factory=list)
    #: The error that stopped the iterations before any solution (re-raised by the plant's caller).
    stop: Optional[DidimError] = None
    #: The step fraction of the last iteration (1: the full LS step).
    alpha: float = 1.0
    #: The last simulation and its output error.
    sim: Any = None
    error: float = math.nan
    #: Where in ``errors`` the iterations began again after the plant changed its model.
    since: int = 0
    #: Where in ``history`` they began again.
    since_step: int = 0
    #: The best iterate before the plant changed its model (kept when none after it can be simulated).
    before_restart: tuple = (math.inf, None, None, None)
    #: Each iterate the least squares ran on and its output error (``history``'s, one for one).
    solved: List[tuple] = field(default_factory=list)
    #: The steps are taken halfway (:data:`RELAXED_STEP`) since the iterates alternated (:func:`_alternating`).
    relaxed: bool = False


def _alternating(loop: DidimLoop, params: np.ndarray, fi: Sequence[int]) -> bool:
    """Whether DIDIM's iterates alternate between two points: a fixed-point map that overshoots its fixed point
    (a direction of slope below −1: on the flexrobots UR5's step 3, products of inertia of the wrists that the
    elastic joints' motor rows see through the link's simulated mode). The last :data:`ALTERNATION_STEPS` steps,
    the next one included, each reverse the one before (their relative changes point against each other), and the
    output errors of the iterates go up and down in turn without settling (each swing at least half the one before)."""
    k = ALTERNATION_STEPS
    solved = loop.solved[loop.since_step:]  # the iterates the least squares ran on, since the model last changed
    if len(solved) < k:
        return False
    thetas, errs = [t for t, _ in solved], [e for _, e in solved]
    pts = [t[fi] for t in thetas[-k:]] + [np.asarray(params, dtype=float)]
    scale = np.maximum(np.max(np.abs(pts), axis=0), 1e-300)
    steps = [(b - a) / scale for a, b in zip(pts[:-1], pts[1:])]
    if not all(float(a @ b) < 0 for a, b in zip(steps[:-1], steps[1:])):
        return False
    swings = np.diff(errs[-k:])
    return bool(np.all(swings[:-1] * swings[1:] < 0) and np.all(np.abs(swings[1:]) >= 0.5 * np.abs(swings[:-1])))


def didim_loop(plant: DidimPlant, theta0: np.ndarray, *, max_iter: int = 30,
               divergence_factor: float = DIVERGENCE_FACTOR, notes: Optional[List[str]] = None,
               progress: Optional[Callable[[str], None]] = None,
               give_up: Optional[Callable[["DidimLoop"], Optional[str]]] = None) -> DidimLoop:
    """DIDIM's iterations on ``plant`` from θ⁰ (see the module's text): at most ``max_iter`` least squares. The
    safeguards' notes go to ``notes`` (the plant's own list, so that its notes and the loop's keep their order).
    ``give_up``, called after each iteration that has not converged, may end the iterations early: it returns the
    message that says why (the outcome is then that of iterations that did not converge), or None to go on."""
    loop = DidimLoop(theta=np.array(theta0, dtype=float), notes=notes if notes is not None else [])
    fi = list(plant.free)
    backtracks, last_rise = 0, ""
    say = progress or (lambda s: None)

    def pull_back(reason: str) -> bool:
        nonlocal backtracks, last_rise
        best = loop.best
        if best[2] is None or backtracks >= MAX_BACKTRACKS:
            return False
        backtracks += 1
        last_rise = reason
        loop.theta = best[1] + 0.5 * (loop.theta - best[1])
        return True

    for _ in range(max_iter * (MAX_BACKTRACKS + 2)):  # each iteration may be preceded by MAX_BACKTRACKS pull-backs
        if len(loop.history) >= max_iter:
            break
        theta = loop.theta
        try:
            sim = plant.simulate(theta)
        except (SimulationError, DataError) as e:
            loop.simulations += 1
            if pull_back(f"the simulation failed ({e})"):
                continue
            sym = getattr(plant, "symbol", "θ")  # the paper writes χ for one axis's parameters
            loop.message = (f"iteration {len(loop.history)}: the simulation with {sym}{len(loop.history)} failed ({e}); "
                            "stopped")
            loop.stop = e
            break
        loop.simulations += 1
        err = plant.output_error(sim)
        loop.sim, loop.error = sim, err
        loop.errors.append(err)
        loop.thetas.append(theta.copy())
        if not err <= divergence_factor * loop.best[0]:
            if pull_back(f"output error {100 * err:.2f} % against {100 * loop.best[0]:.2f} %"):
                continue
            loop.message = (
                f"diverged: the simulated output error rose from {100 * loop.best[0]:.2f} % to {100 * err:.2f} % and "
                f"stayed above {divergence_factor:g} × the best after {MAX_BACKTRACKS} steps back toward the best "
                "iterate; returning the iterate with the lowest output error. The initial values are probably too far "
                "from the truth, or the model misses a physical effect")
            break
        if loop.best[2] is not None and backtracks:
            loop.notes.append(f"iteration {len(loop.history)}: step shortened {backtracks}× ({last_rise})")
        backtracks = 0
        try:
            sol = plant.solve(theta, sim)
        except IdentifiabilityError as e:
            loop.message = f"iteration {len(loop.history) + 1}: {e}"
            loop.stop = e
            break
        if err < loop.best[0]:
            loop.best = (err, theta.copy(), sol, len(loop.history))
        loop.solved.append((theta.copy(), err))
        if not loop.relaxed and getattr(plant, "relax_alternation", False) and _alternating(loop, sol["params"], fi):
            loop.relaxed = True
            swings = ", ".join(f"{100 * e:.3f} %" for _, e in loop.solved[-ALTERNATION_STEPS:])
            loop.notes.append(f"iteration {len(loop.history) + 1}: the iterates alternate between two points (output "
                              f"errors {swings}): each step is taken halfway from here on (the same fixed point, "
                              "reached where the full steps overshoot it)")
        top = RELAXED_STEP if loop.relaxed else 1.0
        alpha = top
        new = theta.copy()
        new[fi] = theta[fi] + alpha * (np.asarray(sol["params"]) - theta[fi]) if loop.relaxed else sol["params"]
        while not plant.physical(new, theta) and alpha > MIN_ALPHA:
            alpha /= 2
            new = theta.copy()
            new[fi] = theta[fi] + alpha * (np.asarray(sol["params"]) - theta[fi])
        if not plant.physical(new, None):
            loop.message = (f"iteration {len(loop.history) + 1}: the least-squares step gives a non-physical estimate "
                            f"even when shortened {1 / MIN_ALPHA:g}×; stopped")
            break
        if alpha < top:
            why = getattr(plant, "short_step_reason", "the full step gives a non-physical estimate")
            loop.notes.append(f"iteration {len(loop.history) + 1}: step shortened to {alpha:g} ({why})")
        loop.alpha = alpha / top
        loop.theta = new
        loop.history.append(sol)
        say(plant.describe(loop))
        if plant.converged(loop):
            verdict = plant.settled(loop)
            if verdict == "accept":
                loop.converged = True
                break
            if verdict == "restart":
                loop.before_restart = loop.best if loop.best[2] is not None else loop.before_restart
                loop.best = (math.inf, None, None, None)
                loop.since, loop.since_step = len(loop.errors), len(loop.history)
        if give_up is not None and not loop.converged:
            why = give_up(loop)
            if why:
                loop.message = why
                break
    if not loop.converged and not loop.message:
        loop.message = f"no convergence in {max_iter} iterations"
    if loop.best[2] is None and loop.before_restart[2] is not None:
        # nothing after the plant changed its model could be simulated (a friction law chosen in closed loop whose
        # loop then went unstable: the KR300 from its published values): the best before it is the outcome
        loop.best = loop.before_restart
        loop.notes.append("no iterate after the model's change (its friction law chosen in closed loop) could be "
                          "simulated: the best iterate before it is kept")
    return loop


__all__ = ["DidimPlant", "DidimLoop", "didim_loop", "residual_settled", "MAX_BACKTRACKS", "DIVERGENCE_FACTOR"]
