"""QR least squares with covariance, eqs. (11)-(15), against numpy."""

import numpy as np
import pytest

from didim import _core


def problem(r=800, seed=5):
    rng = np.random.default_rng(seed)
    w = np.column_stack([rng.standard_normal(r), rng.uniform(-2, 2, r), np.sign(rng.standard_normal(r)), np.ones(r)])
    chi = np.array([95.0, 203.0, 20.0, -3.0])
    y = w @ chi + 0.7 * rng.standard_normal(r)
    return w, y


def test_solution_sigma_and_relative_error_match_the_textbook_formulas():
    w, y = problem()
    sol = _core.lstsq(w, y)
    x, *_ = np.linalg.lstsq(w, y, rcond=None)
    e = y - w @ x
    r, b = w.shape
    s2 = e @ e / (r - b)  # eq. (13)
    cov = s2 * np.linalg.inv(w.T @ w)  # eq. (14)
    np.testing.assert_allclose(sol["params"], x, rtol=1e-10)
    np.testing.assert_allclose(sol["covariance"], cov, rtol=1e-8)
    np.testing.assert_allclose(sol["std"], np.sqrt(np.diag(cov)), rtol=1e-10)
    np.testing.assert_allclose(sol["rel_std_pct"], 100 * np.sqrt(np.diag(cov)) / np.abs(x), rtol=1e-10)  # eq. (15)
    assert sol["relative_error"] == pytest.approx(np.linalg.norm(e) / np.linalg.norm(y), rel=1e-12)
    assert sol["condition_number"] == pytest.approx(np.linalg.cond(w), rel=1e-8)


def test_sample_std_convention_matches_the_emps_benchmark_formula():
    w, y = problem()
    sol = _core.lstsq(w, y, sigma="sample_std")
    x = sol["params"]
    e = y - w @ x
    ref = np.std(e, ddof=1) * np.sqrt(np.diag(np.linalg.inv(w.T @ w)))
    np.testing.assert_allclose(sol["std"], ref, rtol=1e-10)


def test_rank_deficient_regressor_reports_base_parameters_and_dependencies():
    w, y = problem()
    w = np.column_stack([w, 2 * w[:, 0] - w[:, 2]])
    sol = _core.lstsq(w, y)
    assert sol["rank"] == 4
    assert sol["base_columns"] == [0, 1, 2, 3]
    [(col, comb)] = sol["dependencies"]
    assert col == 4
    assert dict(comb) == pytest.approx({0: 2.0, 2: -1.0}, rel=1e-10)
    x, *_ = np.linalg.lstsq(w[:, :4], y, rcond=None)
    np.testing.assert_allclose(sol["params"][:4], x, rtol=1e-10)
