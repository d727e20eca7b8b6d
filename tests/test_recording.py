"""Loading and validating recordings."""

import numpy as np
import pytest
import scipy.io

import didim


def test_load_mat_reads_the_emps_layout(emps):
    assert emps.n == 24841
    assert emps.dt == pytest.approx(1e-3, rel=1e-9)
    assert emps.controller == didim.EmpsCascade()
    assert emps.u_ext is None and emps.ql is None
    assert np.sqrt(np.mean(emps.force**2)) == pytest.approx(54.1, abs=0.05)  # README of the data: force RMS 54.1 N


def test_load_mat_converts_the_pulses_to_newtons(emps_pulses, emps_pulses_path):
    # with the gain they enter the logged command with (1.0138, see tests/test_pulses_gain.py), or 1 when asked
    g = didim.load_mat(emps_pulses_path, pulses_gain=1.0).u_ext_gain()[0]
    np.testing.assert_allclose(np.unique(emps_pulses.u_ext), [0.0, g * 5 * 35.15065188248547], rtol=1e-12)
    raw = didim.load_mat(emps_pulses_path, pulses_gain=1.0)
    np.testing.assert_allclose(np.unique(raw.u_ext), [0.0, 5 * 35.15065188248547], rtol=1e-12)
    assert np.flatnonzero(emps_pulses.u_ext)[0] == 344  # first rising edge (data README)


def test_load_mat_errors_name_the_file_and_problem(tmp_path):
    with pytest.raises(didim.DataError, match="no such file"):
        didim.load_mat(tmp_path / "absent.mat")
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"this is not a mat file at all" * 10)
    with pytest.raises(didim.DataError, match="junk.mat: not a readable"):
        didim.load_mat(junk)
    partial = tmp_path / "partial.mat"
    scipy.io.savemat(partial, {"t": np.arange(10.0), "qm": np.zeros(10)})
    with pytest.raises(didim.DataError, match="missing variable"):
        didim.load_mat(partial)


def test_load_mat_rejects_non_uniform_time(tmp_path, emps_path):
    d = scipy.io.loadmat(emps_path)
    d = {k: v for k, v in d.items() if not k.startswith("__")}
    d["t"] = d["t"].copy()
    d["t"][100:] += 5e-4
    p = tmp_path / "jump.mat"
    scipy.io.savemat(p, d)
    with pytest.raises(didim.DataError, match="not uniform.*sample 99"):
        didim.load_mat(p)


def test_recording_validates_signals():
    n = 10
    ok = dict(dt=1e-3, qr=np.zeros(n), force=np.zeros(n), qm=np.zeros(n), controller=didim.EmpsCascade())
    didim.Recording(**ok)
    with pytest.raises(didim.DataError, match="force has 9 samples"):
        didim.Recording(**{**ok, "force": np.zeros(n - 1)})
    bad = np.zeros(n)
    bad[4] = np.nan
    with pytest.raises(didim.DataError, match="first at sample 4"):
        didim.Recording(**{**ok, "qm": bad})
    with pytest.raises(didim.DataError, match="dt"):
        didim.Recording(**{**ok, "dt": 0.0})
    with pytest.raises(didim.DataError, match="kp"):
        didim.PD(kp=-1.0, kd=1.0)
