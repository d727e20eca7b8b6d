"""A robot joint's drive between its controller and the joint, as one axis has it: a known force added to the command
(``u_ext_<joint>`` columns: a feedforward), an actuation delay and a current loop's lag (``"delay"``, ``"force_lag"``
in the joint's entry of the controllers' file). The core's loop is checked against two other computations: the
controllers' replay of the logged positions (the one-axis law in Python, through scipy's lfilter form) for the
commands, and the inverse dynamics of the simulated states (Newton-Euler) for the force the joints received, which
must be the commands delayed and lagged as :func:`didim.recording.applied_force` writes them. DIDIM recovers the
truth from a record with a delay and a lag when the file declares them."""

import json

import numpy as np
import pytest

import didim
from didim import _core
from didim.recording import applied_force


@pytest.fixture(scope="module")
def pendulum(robots_dir):
    t = json.loads((robots_dir / "truth.json").read_text())["robots"]["pendulum"]
    robot = didim.Robot.from_urdf(robots_dir / t["cad_urdf"])
    rec = didim.load_record(robots_dir / "pendulum_train.csv", robot=robot,
                            controller=robots_dir / "pendulum_controller.json")
    pi = np.concatenate([t["links_truth"][j]["dyn10"] for j in t["joint_names"]])
    return t, robot.with_inertial_params(pi), rec


def _simulate(t, robot, rec, n, **drive):
    return _core.simulate_robot(robot._core, t["Ia"], t["Fv"], t["Fc"], t["offset"], rec.core_controllers(),
                                rec.qr[:n], rec.dt, quantization=list(rec.encoder_step), force0=list(rec.force[0]),
                                coulomb_eps=[t["vs"]] * 2, coulomb_law=["tanh"] * 2, **drive)


def test_the_loop_applies_the_commands_delayed_and_lagged_with_the_feedforward(pendulum):
    t, robot, rec = pendulum
    n = 3000
    k = np.arange(n) * rec.dt
    u_ext = np.column_stack([0.3 * np.sin(2 * np.pi * 0.7 * k), -0.2 * np.cos(2 * np.pi * 1.3 * k)])
    delay, lag = (1, 2), (0.0, 2e-3)
    out = _simulate(t, robot, rec, n, u_ext=u_ext, delay=list(delay), force_lag=list(lag))
    scale = float(np.max(np.abs(out["force"])))
    # the commands: each joint's law replayed on the quantized simulated positions, from the first force, with the
    # feedforward added before saturation (the core's step against the one-axis replay)
    for j in range(2):
        step = rec.encoder_step[j]
        qm = np.round(out["q"][:, j] / step) * step
        tf = rec.controllers[j].transfer_function(rec.dt)
        want = tf.command(rec.qr[:n, j], qm, u_ext[:, j] + rec.force[0, j])
        # the core runs the law on one denominator, whose double pole at 1 (the integrator and the derivative's
        # filter) turns each step's rounding (ε times the gains times the positions) into a ramp of a ramp: bounded
        # by n² of it (measured: a fifth of the bound)
        gains = max(np.max(np.abs(tf.b_r)), np.max(np.abs(tf.b_y)))
        bound = np.finfo(float).eps * gains * max(1.0, float(np.max(np.abs(rec.qr[:n, j])))) * n**2
        err = np.max(np.abs(out["force"][:, j] - want))
        assert err <= bound, (j, err, bound)
    # the force the joints received: the inverse dynamics of the recorded states (the direct model's acceleration at
    # each sample) equals the commands delayed and lagged
    tau = robot.rnea(out["q"], out["qd"], out["qdd"])
    tau += np.asarray(t["Ia"]) * out["qdd"] + np.asarray(t["Fv"]) * out["qd"]
    tau += np.asarray(t["Fc"]) * np.tanh(out["qd"] / t["vs"]) + np.asarray(t["offset"])
    want = applied_force(out["force"], delay, lag, rec.dt)
    assert np.max(np.abs(tau - want)) <= 1e-9 * scale
    # and not the commands themselves: the delay and the lag move the force by far more than that
    assert np.max(np.abs(tau - out["force"])) > 1e-3 * scale


def test_a_constant_feedforward_is_the_first_force_moved(pendulum):
    t, robot, rec = pendulum
    n = 1500
    c = np.array([0.4, -0.25])
    a = _simulate(t, robot, rec, n, u_ext=np.tile(c, (n, 1)))
    b = _core.simulate_robot(robot._core, t["Ia"], t["Fv"], t["Fc"], t["offset"], rec.core_controllers(), rec.qr[:n],
                             rec.dt, quantization=list(rec.encoder_step), force0=list(rec.force[0] + c),
                             coulomb_eps=[t["vs"]] * 2, coulomb_law=["tanh"] * 2)
    np.testing.assert_array_equal(a["force"], b["force"])


def test_bad_drive_options_are_refused_by_name(pendulum):
    t, robot, rec = pendulum
    with pytest.raises(ValueError, match=r"u_ext must be \(samples, joints\)"):
        _simulate(t, robot, rec, 100, u_ext=np.zeros((2, 100)))
    with pytest.raises(ValueError, match="joint 2's delay of 100 samples"):
        _simulate(t, robot, rec, 100, delay=[0, 100])
    with pytest.raises(ValueError, match="joint 1's force lag"):
        _simulate(t, robot, rec, 100, force_lag=[-1e-3, 0.0])


def _soft(rec):
    """The pendulum's controllers at half their gains: its cascades were tuned without a delay, and one sample of it
    makes them oscillate (the force's sample-to-sample change 30 times larger); at half the gains a delay and a
    1 ms lag move the force by 1 %, as a drive does."""
    from didim.controllers import TransferFunction

    out = []
    for c in rec.controllers:
        tf = c.transfer_function(rec.dt)
        out.append(TransferFunction(dt=rec.dt, b_r=list(0.5 * np.asarray(tf.b_r)), a_r=list(tf.a_r),
                                    b_y=list(0.5 * np.asarray(tf.b_y)), a_y=list(tf.a_y), saturation=tf.saturation,
                                    gain=tf.gain))
    return out


def _record_with_drive(tmp_path, t, robot, rec, delay, lag, u_ext=None, declare=True):
    """The pendulum's training references run again in didim's loop with the truth's parameters, softer controllers
    (:func:`_soft`) and a drive with a delay and a lag, written as a CSV with its controllers' file (declaring the
    drive or not)."""
    soft = _soft(rec)
    out = _core.simulate_robot(robot._core, t["Ia"], t["Fv"], t["Fc"], t["offset"],
                               [(c.kind, list(c.gains)) for c in soft], rec.qr, rec.dt,
                               quantization=list(rec.encoder_step), force0=list(rec.force[0]),
                               coulomb_eps=[t["vs"]] * 2, coulomb_law=["tanh"] * 2, delay=list(delay),
                               force_lag=list(lag), u_ext=u_ext)
    steps = np.asarray(rec.encoder_step)
    qm = np.round(out["q"] / steps) * steps
    cols = {"t": rec.t}
    for j in range(2):
        cols[f"qr_{j + 1}"], cols[f"force_{j + 1}"], cols[f"qm_{j + 1}"] = rec.qr[:, j], out["force"][:, j], qm[:, j]
        if u_ext is not None:
            cols[f"u_ext_{j + 1}"] = u_ext[:, j]
    path = tmp_path / "drive.csv"
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
               fmt="%.17g")
    ctl = [c.to_dict() for c in soft]
    if declare:
        for c, d, g in zip(ctl, delay, lag):
            c["delay"], c["force_lag"] = d, g
    (tmp_path / "drive_controller.json").write_text(json.dumps({"type": "joints", "joints": ctl}))
    return path


def test_the_loader_reads_the_feedforward_and_the_drives(pendulum, tmp_path):
    t, robot, rec = pendulum
    u_ext = np.column_stack([0.1 * np.sin(rec.t), 0.05 * np.cos(rec.t)])
    path = _record_with_drive(tmp_path, t, robot, rec, (1, 0), (0.0, 1e-3), u_ext)
    got = didim.load_record(path, robot=robot)
    assert got.delay == (1, 0) and got.force_lag == (0.0, 1e-3)
    np.testing.assert_allclose(got.u_ext, u_ext, rtol=1e-15, atol=0)
    # a feedforward for one joint only is refused, naming the columns it lacks
    text = path.read_text().splitlines()
    head = text[0].split(",")
    keep = [i for i, c in enumerate(head) if c != "u_ext_2"]
    bad = tmp_path / "partial.csv"
    bad.write_text("\n".join(",".join(row.split(",")[i] for i in keep) for row in text) + "\n")
    with pytest.raises(didim.DataError, match="u_ext_1 … u_ext_2"):
        didim.load_record(bad, robot=robot, controller=tmp_path / "drive_controller.json")


def test_didim_recovers_the_truth_through_a_declared_delay_and_lag(pendulum, tmp_path):
    """A drive with one sample of delay and a 1 ms current loop on each joint (a record without noise): declared in
    the controllers' file, DIDIM's friction is within 1 % of the truth and the second joint's rotor inertia (the
    first's is regrouped with the bodies) within 2 %, its loop reproducing the record below the noisy record's truth
    floor; without the declaration that inertia takes the delay's phase (13 % off measured) and the force error is
    larger by half (0.64 and 1.10 % measured: the quantized loop's own divergence sets the first)."""
    t, robot, rec = pendulum
    path = _record_with_drive(tmp_path, t, robot, rec, (1, 1), (1e-3, 1e-3))
    declared = didim.load_record(path, robot=robot)
    r = didim.identify(declared, robot, "didim")
    for i, j in enumerate(robot.joint_names):
        assert r.params[f"Fv_{j}"] == pytest.approx(t["Fv"][i], rel=0.01)
        assert r.params[f"Fc_{j}"] == pytest.approx(t["Fc"][i], rel=0.01)
    assert r.params["Ia_joint2"] == pytest.approx(t["Ia"][1], rel=0.02)
    assert r.force_error < t["records"]["train"]["truth_floor_total"]
    assert not [n for n in r.notes if "declares" in n], r.notes  # the right declaration is not questioned
    _record_with_drive(tmp_path, t, robot, rec, (1, 1), (1e-3, 1e-3), declare=False)
    plain = didim.load_record(path, robot=robot, controller=tmp_path / "drive_controller.json")
    assert plain.delay == (0, 0)
    r0 = didim.identify(plain, robot, "didim", controller_check="off")
    assert abs(r0.params["Ia_joint2"] / t["Ia"][1] - 1) > 0.05
    assert r0.force_error > 1.4 * r.force_error
