"""Choosing among candidates, for both doctors (one axis's and the robot's): the best variant of a grid of one
effect's hyper-parameters, and the Holm-adjusted ranking across effects. A candidate is either doctor's: it has
``test`` (a :class:`didim.stats.WaldTest`), ``exact`` (its one-by-one test, or None), ``grid`` and ``p_adj``."""

from __future__ import annotations

from typing import Any, Callable, List, Optional

from ..stats import holm


def exact(c: Any) -> Any:
    """``c`` with its one-by-one SVD test (set beside the grouped one by the doctor's ``test_all``)."""
    if c.exact is not None:
        c.test, c.exact = c.exact(), None
    return c


def better(c: Any, top: Optional[Any]) -> bool:
    """Whether ``c`` ranks above ``top``: a lower p-value, or the same and a larger share explained."""
    return top is None or c.test.p_value < top.test.p_value or (
        c.test.p_value == top.test.p_value and c.test.explained > top.test.explained)


def holm_ranked(best: List[Any]) -> List[Any]:
    """Sets the Holm-adjusted p-values (with each candidate's grid as a Bonferroni factor) and ranks."""
    raw = [min(1.0, c.test.p_value * c.grid) for c in best]
    for c, p in zip(best, holm(raw) if raw else []):
        c.p_adj = float(p)
    return sorted(best, key=lambda c: (c.p_adj, -c.test.explained))


def best_variant(variants: list, test_all: Callable[[list], None], refine: Callable[[Any], list]):
    """The best of one effect's variants on one residual, for either plant: ``test_all`` sets each candidate's
    grouped Wald test and its one-by-one SVD test (``exact``); the best by p-value (then by the share it explains)
    is tested again exactly, then ``refine(best)`` lists the variants between its grid neighbours ([]: none), and
    the one that explains most is kept, tested exactly, its grid (the Bonferroni factor) counting both."""
    if not variants:
        return None
    test_all(variants)
    top = None
    for c in variants:
        if better(c, top):
            top = c
    top = exact(top)
    fine = refine(top)
    if fine:
        test_all(fine)
        for c in fine:
            if c.test.explained > top.test.explained:
                top = c
        top = exact(top)
        top.grid = len(variants) + len(fine)
    return top
