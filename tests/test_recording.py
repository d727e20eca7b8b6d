"""Loading and validating recordings."""

import dataclasses

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


def _columns(emps, joints=("j1", "j2")):
    """A robot-shaped record whose joints are the EMPS's log and the same log shifted: (samples, joints) signals."""
    cut = slice(0, 4000)
    k = len(joints)
    stack = lambda x: np.column_stack([x[cut] + 0.01 * i for i in range(k)])  # noqa: E731
    return didim.Recording(dt=emps.dt, qr=stack(emps.qr), force=stack(emps.force), qm=stack(emps.qm),
                           controller=(emps.controller,) * k, position_resolution=(emps.position_resolution,) * k,
                           joint_names=joints, joint_kinds=("prismatic",) * k, name="twin")


def test_one_recording_type_holds_one_axis_and_a_robots_joints(emps):
    rec = _columns(emps)
    assert rec.has_joint_columns and rec.ndof == 2 and rec.qr.shape == (4000, 2)
    assert not emps.has_joint_columns and emps.ndof == 1 and emps.controllers == (emps.controller,)
    # each joint is a one-axis record of its own column, units and encoder step
    j2 = rec.joint("j2")
    assert not j2.has_joint_columns and j2.axis == "linear" and j2.position_resolution == emps.position_resolution
    np.testing.assert_array_equal(j2.qr, emps.qr[:4000] + 0.01)
    # the lead-in is reconstructed the same way for a joint column as for one axis
    one = didim.Recording(dt=emps.dt, qr=emps.qr[:4000], force=emps.force[:4000], qm=emps.qm[:4000],
                          controller=emps.controller, position_resolution=emps.position_resolution)
    assert one.qr_lead.size == 16  # tests/test_lead_in.py: the EMPS log begins 16 ms after the move
    np.testing.assert_allclose(rec.qr_lead[:, 0], one.qr_lead, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rec.qr_lead[:, 1], one.qr_lead + 0.01, rtol=0, atol=1e-15)
    qr, _ = rec.lead_in_signals()
    assert qr.shape == (4016, 2)


def test_a_robots_record_refuses_what_does_not_fit_its_joints(emps):
    rec = _columns(emps)
    with pytest.raises(didim.DataError, match="joint 'j1' appears twice"):
        _columns(emps, joints=("j1", "j1"))
    with pytest.raises(didim.DataError, match="one controller per joint"):
        dataclasses.replace(rec, controller=emps.controller)
    with pytest.raises(didim.DataError, match="1 controllers for 2 joints"):
        dataclasses.replace(rec, controller=(emps.controller,))
    bad = np.array(rec.force)
    bad[7, 1] = np.nan
    with pytest.raises(didim.DataError, match="force of joint j2 is not finite at sample 7"):
        dataclasses.replace(rec, force=bad)
    with pytest.raises(didim.DataError, match="must be \\(samples, 2\\)"):
        dataclasses.replace(rec, qm=rec.qm[:, :1])
    # a given lead-in must join each joint's first reference, named in the error
    lead = np.array(rec.qr_lead)
    lead[:, 1] += 0.05
    with pytest.raises(didim.DataError, match="joint j2's lead_in ends at .* m but the reference's first sample"):
        dataclasses.replace(rec, lead_in=lead)
    assert dataclasses.replace(rec, lead_in=np.array(rec.qr_lead)).qr_lead.shape == rec.qr_lead.shape
    with pytest.raises(didim.DataError, match="take it on one joint, record.joint"):
        rec.implied_command()


def test_a_robots_record_is_diagnosed_joint_by_joint(emps):
    """The one-axis record checks serve each joint, naming it: a force logged in volts on the second joint is said
    to be so on that joint only (the EMPS's gtau = 35.15 N/V)."""
    rec = _columns(emps)
    assert rec.diagnose() == []
    volts = np.array(rec.force)
    volts[:, 1] /= emps.controller.gtau
    found = dataclasses.replace(rec, force=volts).diagnose()
    assert len(found) == 1 and found[0].startswith("joint j2: the force looks like volts")
