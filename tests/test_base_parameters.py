"""Base parameters of a URDF that rounds its quarter turns: example-robot-data's xArm7 writes π/2 as 1.5708, which
breaks a regrouping the exact geometry has by 4.7e-6 of a column's norm. The base parameters must be those of the same
URDF with exact quarter turns, and a fit on either must give the same values within their σ (before, the rounded
URDF kept a direction no torque record can see: Ia_joint2 = −125.6 ± 525 %)."""

import importlib.metadata
import math
import re

import numpy as np
import pytest

import didim
from didim.methods.robot import _full_regressor, base_parameters, random_states


def _xarm7():
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    for f in files:
        if str(f).endswith("/xarm7.urdf"):
            return f.locate().read_text()
    pytest.skip("example-robot-data has no xarm7.urdf")


def test_a_rounded_quarter_turn_gives_the_exact_urdfs_base_parameters():
    text = _xarm7()
    assert "1.5708" in text
    exact_text = re.sub(r"(?<![0-9.])(-?)1\.5708(?![0-9])", lambda m: m.group(1) + repr(math.pi / 2), text)
    rounded, exact = didim.Robot.from_urdf_string(text), didim.Robot.from_urdf_string(exact_text)
    br, be = base_parameters(rounded), base_parameters(exact)
    assert len(br.names) == len(be.names) == 48  # and the mz of its second body, zero but for rounding, is no column
    assert br.independent == be.independent
    # the regroupings' coefficients differ by the rounding (1.5708 − π/2 = 3.7e-6 rad) times the arm's lengths
    assert np.allclose(br.K, be.K, atol=1e-4 * np.abs(be.K).max())

    # the same torques (the exact arm, perturbed inertias, 0.5 % noise) fitted on each URDF's base regressor
    rng = np.random.default_rng(5)
    q, v, a = random_states(exact, 2000, 7)
    pi = np.concatenate([rng.uniform(0.01, 0.05, exact.ndof), exact.inertial_params * rng.uniform(0.9, 1.1, 70)])
    tau = _full_regressor(exact, q, v, a) @ pi
    tau += 0.005 * np.std(tau) * rng.normal(size=tau.shape)
    fits = []
    for robot, base in ((rounded, br), (exact, be)):
        w = _full_regressor(robot, q, v, a)[:, list(base.independent)]
        beta, res, *_ = np.linalg.lstsq(w, tau, rcond=None)
        s2 = float(res[0]) / (len(tau) - w.shape[1])
        fits.append((beta, np.sqrt(s2 * np.diag(np.linalg.inv(w.T @ w)))))
    (b1, s1), (b2, s2) = fits
    assert np.all(np.abs(b1 - b2) <= np.maximum(s1, s2)), np.abs(b1 - b2) / np.maximum(s1, s2)
    assert np.all(s1 < 2 * s2)  # no direction the torques cannot see
