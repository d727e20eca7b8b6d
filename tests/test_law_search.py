"""The friction law's search in closed loop (:func:`didim.methods.friction_law.closed_loop_law`), every plant's: on error
surfaces whose minimum is known (each joint's error a parabola in log ε about its own best speed, each shape offset),
it finds the shape, each joint's speed to a fraction of its grid's step, and stops where the error has turned."""

from __future__ import annotations

import math

import numpy as np
import pytest

from didim.methods.friction_law import QUARTER, REACH, closed_loop_law

#: each shape's error floor; each joint's best ε (a joint's error a parabola in log ε, a curvature per joint)
FLOOR = {"algebraic": 0.010, "tanh": 0.012, "exp": 0.015}
BEST = np.array([0.02, 0.0013, 0.05])
CURVE = np.array([0.02, 0.01, 0.03])


def surface(law):
    x = np.log(np.asarray(law[1]) / BEST)
    return FLOOR[law[0]] + CURVE * x**2


def test_the_search_finds_the_shape_and_each_joints_speed():
    calls = []

    def errors(law):
        calls.append(law)
        return surface(law)

    # starts within the coarse grid's reach of each joint's best, off by different factors
    starts = {sh: tuple(BEST * np.array([1.3, 0.7, 1.6])) for sh in FLOOR}
    found = closed_loop_law(starts, errors)
    assert found.law[0] == "algebraic"
    # a parabola through a parabola's points is exact: each joint's own speed to rounding
    np.testing.assert_allclose(found.law[1], BEST, rtol=1e-9)
    assert found.error == pytest.approx(FLOOR["algebraic"], rel=1e-9)
    # each law simulated once; the coarse grids stop where the error has turned (at most 2 REACH + 1 points per
    # shape), at most 3 finer points per shape (two between coarse points and a vertex), and the joints' own factors
    assert len(calls) == len(set(calls))
    assert len(calls) <= 3 * (2 * REACH + 1 + 3) + 1


def test_one_joint_and_a_common_factor():
    """One joint (one axis, the doctor's): the vertex of the fine grid; per_joint=False keeps the joints' ratios."""
    starts = {"tanh": (BEST[0] * 1.5,)}
    found = closed_loop_law(starts, lambda law: surface(("tanh", (law[1][0], *BEST[1:])))[:1])
    assert found.law[1][0] == pytest.approx(BEST[0], rel=1e-9)
    ratios = np.array([1.3, 0.7, 1.6])
    found = closed_loop_law({"tanh": tuple(BEST * ratios)}, surface, per_joint=False)
    got = np.asarray(found.law[1]) / (BEST * ratios)
    assert np.ptp(got) == pytest.approx(0.0, abs=1e-12)  # one factor for every joint


def test_the_reach_bounds_the_search_and_a_law_that_cannot_be_simulated_is_skipped():
    far = {"tanh": (BEST[0] * 100,)}

    def errors(law):
        return None if law[1][0] > BEST[0] * 150 else surface(("tanh", (law[1][0], *BEST[1:])))[:1]

    found = closed_loop_law(far, errors, reach=2)
    # the coarse grid goes down a factor 2 at most (2 steps of √2), the fine grid around its lowest point one more √2:
    # not to the truth 100 times lower
    assert math.log(found.law[1][0] / far["tanh"][0]) == pytest.approx(-(2 * 2 + 2) * QUARTER, abs=1e-12)
    nothing = closed_loop_law(far, lambda law: None)
    assert nothing.error == math.inf and nothing.law == ("tanh", far["tanh"])


def test_known_laws_are_not_simulated_again():
    starts = {"exp": (BEST[0],)}
    calls = []

    def errors(law):
        calls.append(law)
        return surface(("exp", (law[1][0], *BEST[1:])))[:1]

    first = closed_loop_law(starts, errors)
    again = closed_loop_law(starts, lambda law: pytest.fail(f"{law} simulated again"), known=first.tried)
    assert again.law == first.law and again.error == first.error


def test_a_shape_second_on_the_coarse_grid_but_first_between_its_points_is_found():
    """A sharp error (it doubles over a factor √2, as on the truthbench's portal axis): tanh's minimum lies halfway
    between two coarse points, algebraic's on one; tanh's coarse points are above algebraic's, its minimum below."""
    step = 2 * QUARTER  # the coarse grid's step in log ε
    best = {"algebraic": 1.0, "tanh": math.exp(step / 2)}
    floor = {"algebraic": 0.0100, "tanh": 0.0095}
    curve = 0.01 / step**2  # 0.01 up over one coarse step

    def errors(law):
        return np.array([floor[law[0]] + curve * math.log(law[1][0] / best[law[0]]) ** 2])

    found = closed_loop_law({"algebraic": (1.0,), "tanh": (1.0,)}, errors)
    assert found.law[0] == "tanh" and found.law[1][0] == pytest.approx(best["tanh"], rel=1e-9)
    assert found.error == pytest.approx(floor["tanh"], rel=1e-9)
