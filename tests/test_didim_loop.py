"""DIDIM's one loop (didim.methods.didim_loop), on a plant small enough to follow by hand: the safeguards act where they
should and never where an iteration goes well."""

import math

import numpy as np
import pytest

from didim._errors import SimulationError
from didim.methods.didim_loop import MAX_BACKTRACKS, didim_loop


class Toy:
    """θ = (m,): the 'simulation' fails for m <= 0.5 (a loop that cannot be simulated); its error is |m − 2|; the
    least squares jump to ``jumps`` in turn, then to the truth 2."""

    free = [0]

    def __init__(self, jumps, tol=1e-9):
        self.jumps, self.tol, self.sims = list(jumps), tol, []

    def simulate(self, theta):
        self.sims.append(float(theta[0]))
        if theta[0] <= 0.5:
            raise SimulationError("articulated inertia is not positive")
        return float(theta[0])

    def output_error(self, sim):
        return abs(sim - 2.0) + 1e-3

    def solve(self, theta, sim):
        nxt = self.jumps.pop(0) if self.jumps else 2.0
        return {"params": np.array([nxt]), "std": np.array([0.1]), "covariance": np.eye(1) * 0.01}

    def physical(self, new, old):
        return bool(np.isfinite(new[0]))

    def converged(self, loop):
        return len(loop.errors) >= 2 and abs(loop.errors[-1] - loop.errors[-2]) <= self.tol

    def settled(self, loop):
        return "accept"

    def describe(self, loop):
        return f"iteration {len(loop.history)}"


def test_an_iterate_that_cannot_be_simulated_is_pulled_back_toward_the_best():
    plant = Toy([0.1])  # from 1.5 the least squares jump to 0.1, where the loop cannot be simulated
    loop = didim_loop(plant, np.array([1.5]))
    assert loop.converged
    assert loop.theta[0] == pytest.approx(2.0)
    # 0.1 failed, then halfway back to the best (1.5): 0.8 simulates but its error is above 1.5 times the best, so
    # back again, until 1.325 is within it
    assert plant.sims[:5] == [1.5, 0.1, 0.8, pytest.approx(1.15), pytest.approx(1.325)]
    assert loop.notes == ["iteration 1: step shortened 3× (output error 85.10 % against 50.10 %)"]


def test_a_rising_error_is_pulled_back_and_divergence_declared_after_the_budget():
    plant = Toy([40.0] * 50)  # every step jumps far off: the error rises more than 1.5× the best each time
    loop = didim_loop(plant, np.array([1.9]), max_iter=10)
    assert not loop.converged
    assert loop.message.startswith("diverged")
    assert loop.best[1][0] == pytest.approx(1.9)
    assert len(plant.sims) == 1 + 1 + MAX_BACKTRACKS  # the start, the jump, and the pull-backs


def test_an_iteration_that_goes_well_is_left_alone():
    plant = Toy([1.95, 1.99])
    loop = didim_loop(plant, np.array([1.5]))
    assert loop.converged and not loop.notes
    assert plant.sims == [1.5, 1.95, 1.99, 2.0, 2.0]
    assert math.isclose(loop.theta[0], 2.0)


def test_give_up_ends_an_iteration_that_wanders_with_its_best_iterate():
    plant = Toy([1.4, 1.3, 1.45, 1.35, 1.42, 1.38] * 5, tol=0.0)  # wanders far from the truth, never settles

    def stop(loop):
        return "stopped: far off" if len(loop.history) >= 3 and loop.best[0] > 0.5 else None

    loop = didim_loop(plant, np.array([1.5]), max_iter=30, give_up=stop)
    assert not loop.converged and loop.message == "stopped: far off"
    assert len(loop.history) == 3 and plant.sims == [1.5, 1.4, 1.3]
    assert loop.best[1][0] == pytest.approx(1.5)  # the iterate closest to the truth so far


def test_give_up_is_not_asked_once_the_iteration_has_converged():
    asked = []
    loop = didim_loop(Toy([1.95, 1.99]), np.array([1.5]), give_up=lambda lp: asked.append(len(lp.history)))
    assert loop.converged and asked == [1, 2, 3, 4]  # after each iteration before the one that converged


def test_a_robot_didim_that_cycles_above_its_best_ends_after_its_patience():
    """methods.robot's patience (every robot DIDIM's): iterations that cycle above the best end DIDIM_PATIENCE
    iterations after it, the best kept, with a message that robot DIDIM reads as "no convergence" (not a failure that
    sends it again from IDIM-LS's estimate); a cycle whose best still creeps down goes on."""
    from didim.methods.robot import DIDIM_PATIENCE, _stalled

    cycle = [1.2, 1.4, 1.25, 1.35] * 10  # from its start at 1.9 (error 0.1) every step lands farther from 2
    plant = Toy(cycle, tol=0.0)
    loop = didim_loop(plant, np.array([1.9]), max_iter=30, give_up=_stalled(DIDIM_PATIENCE))
    assert not loop.converged and loop.message.startswith("no convergence")
    assert len(loop.history) == DIDIM_PATIENCE + 1 and loop.best[1][0] == pytest.approx(1.9)
    # creeping toward 2 every few iterations, below each earlier best: never stalled for the patience
    creep = []
    for k in range(7):
        creep += [1.0 + 0.1 * k, 0.8, 0.9]
    loop = didim_loop(Toy(creep, tol=0.0), np.array([0.9]), max_iter=20, give_up=_stalled(DIDIM_PATIENCE))
    assert loop.message == "no convergence in 20 iterations" and loop.best[1][0] == pytest.approx(1.6)


class Overshoot(Toy):
    """A fixed-point map of slope ``slope`` around the truth 2 (the least squares from m land at 2 + slope·(m − 2)):
    at −1 or below the full steps circle the truth, as the flexrobots UR5's step 3 did with the link's equation in
    its motor rows. Its output error is lower on one side of the truth than on the other."""

    def __init__(self, slope, relax):
        super().__init__([], tol=1e-12)
        self.slope, self.relax_alternation = slope, relax

    def output_error(self, sim):
        d = sim - 2.0
        return 0.1 + 0.05 * abs(d) + 0.02 * d

    def solve(self, theta, sim):
        return {"params": np.array([2.0 + self.slope * (theta[0] - 2.0)]), "std": np.array([0.1]),
                "covariance": np.eye(1) * 0.01}


@pytest.mark.parametrize("slope", [-1.0, -1.1])
def test_iterates_that_alternate_are_taken_halfway_where_the_plant_asks(slope):
    """Two points in turn (slope −1), or a widening circle (−1.1): the plant that asks for it (a robot's elastic model)
    takes half steps once four steps in a row have each reversed the one before and the errors swing without settling,
    and reaches the fixed point (the half step's slope (1 + slope)/2 is within ±1); a plant that does not ask keeps
    its full steps (one axis's own remedy, rows frozen, is its plant's), and circles."""
    loop = didim_loop(Overshoot(slope, relax=True), np.array([2.5]), max_iter=30)
    assert loop.relaxed and loop.converged
    assert loop.theta[0] == pytest.approx(2.0, abs=1e-9)
    # the fourth least squares ran on the fourth iterate: its step is the first taken halfway
    assert [n.split(":")[0] for n in loop.notes] == ["iteration 4"]
    plain = didim_loop(Overshoot(slope, relax=False), np.array([2.5]), max_iter=30)
    assert not plain.relaxed and not plain.converged
    if slope == -1.0:
        assert plain.thetas[-2:] == [pytest.approx([2.5]), pytest.approx([1.5])] or \
            plain.thetas[-2:] == [pytest.approx([1.5]), pytest.approx([2.5])]


def test_an_iteration_that_converges_is_never_relaxed():
    """A map of slope −0.5 overshoots too, but its circle narrows: the swings shrink below half the one before, and
    the steps stay whole."""
    loop = didim_loop(Overshoot(-0.5, relax=True), np.array([2.5]), max_iter=60)
    assert loop.converged and not loop.relaxed and not loop.notes
