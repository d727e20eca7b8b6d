"""Issue 38's bad inputs on the robot surfaces, each a clear DataError naming what to change (or handled right):
positions off any encoder grid, a record with qr and qm swapped, non-finite inertial parameters, a one-axis result
or a negative substep count where a robot's is due, saved robot results with a parameter missing, renamed, null or a
string, or a base map of the wrong shape. (URDFs that are not one tree: tests/test_robot.py.)"""

import json

import numpy as np
import pandas as pd
import pytest

import didim

D_NAME = "pendulum"


@pytest.fixture(scope="module")
def pendulum(robots_dir):
    robot = didim.Robot.from_urdf(robots_dir / f"{D_NAME}_cad.urdf")
    ctl = robots_dir / f"{D_NAME}_controller.json"
    rec = didim.load_record(robots_dir / f"{D_NAME}_train.csv", robot=robot, controller=ctl)
    return robot, ctl, rec, pd.read_csv(robots_dir / f"{D_NAME}_train.csv")


def test_positions_off_any_encoder_grid_read_without_a_step(pendulum, tmp_path):
    """An analog or filtered encoder (every position off any grid) is a record without an encoder step, not a
    traceback (it was "zero-size array" in detect_resolution)."""
    robot, ctl, rec, df = pendulum
    rng = np.random.default_rng(0)
    for c in ("qm_1", "qm_2"):
        df = df.assign(**{c: df[c] + rng.normal(0, 1e-5, len(df))})
    df.to_csv(tmp_path / "analog.csv", index=False)
    got = didim.load_record(tmp_path / "analog.csv", robot=robot, controller=ctl)
    assert got.encoder_step == (0.0, 0.0)
    np.testing.assert_allclose(got.qm, df[["qm_1", "qm_2"]].to_numpy(), rtol=0, atol=1e-12)


def test_a_record_with_qr_and_qm_swapped_is_refused_naming_the_swap(pendulum, tmp_path):
    robot, ctl, rec, df = pendulum
    swapped = df.rename(columns={"qr_1": "qm_1", "qr_2": "qm_2", "qm_1": "qr_1", "qm_2": "qr_2"})
    swapped.to_csv(tmp_path / "swapped.csv", index=False)
    got = didim.load_record(tmp_path / "swapped.csv", robot=robot, controller=ctl)
    with pytest.raises(didim.DataError, match="likely: the reference and the measured position are swapped"):
        didim.identify(got, robot, "idim-ls")


def test_wrong_objects_and_numbers_are_refused_by_name(pendulum, emps):
    robot, ctl, rec, _ = pendulum
    with pytest.raises(didim.DataError, match="inertial parameter 3 is nan"):
        robot.with_inertial_params(np.where(np.arange(robot.inertial_params.size) == 3, np.nan, robot.inertial_params))
    res = didim.identify(rec, robot, "idim-ls")
    axis = didim.identify(emps, "rigid", "idim-ls")
    with pytest.raises(didim.DataError, match="a robot's result is needed .* got a one-axis result"):
        didim.robots.payload(rec, axis)
    with pytest.raises(didim.DataError, match="a robot's result is needed .* got str"):
        didim.robots.simulate_robot(rec, "r.json")
    with pytest.raises(didim.DataError, match="substeps must be between 0 and 1024, got -1"):
        didim.robots.simulate_robot(rec, res, substeps=-1)
    with pytest.raises(didim.DataError, match="max_iter must be a whole number, got 1.5"):
        didim.identify(rec, robot, "didim", max_iter=1.5)
    with pytest.raises(didim.DataError, match="tol must be a finite number > 0, got nan"):
        didim.identify(rec, robot, "didim", tol=float("nan"))


@pytest.mark.parametrize("mutation, message", [
    ("missing", "its params lack Ia_joint1"),
    ("renamed", "its params lack Ia_joint1"),
    ("null", "its parameter Ia_joint1 is None, not a finite number"),
    ("string", "its parameter Ia_joint1 is 'abc', not a finite number"),
    ("base", "its base map does not fit its 2-joint robot"),
    ("ragged", "its field 'base.K' is not a table of numbers"),
    ("no urdf", "its field 'robot.urdf' is missing"),
    ("kind", "its field 'kind' is 'rigid' but it holds a robot's result"),
])
def test_a_saved_robot_result_that_does_not_fit_its_robot_is_refused(pendulum, tmp_path, mutation, message):
    robot, ctl, rec, _ = pendulum
    res = didim.identify(rec, didim.Model(robot=robot, offset=True), "idim-ls")
    res.save(tmp_path / "r.json")
    d = json.loads((tmp_path / "r.json").read_text())
    assert didim.load_result(tmp_path / "r.json").params == pytest.approx(res.params, rel=1e-15)
    if mutation == "missing":
        del d["params"]["Ia_joint1"]
    elif mutation == "renamed":
        d["params"]["Ia_1"] = d["params"].pop("Ia_joint1")
    elif mutation == "null":
        d["params"]["Ia_joint1"] = None
    elif mutation == "string":
        d["params"]["Ia_joint1"] = "abc"
    elif mutation == "ragged":
        d["base"]["K"][0] = d["base"]["K"][0][:-1]
    elif mutation == "no urdf":
        del d["robot"]["urdf"]
    elif mutation == "kind":
        d["kind"] = "rigid"
    else:
        d["base"]["K"] = [[1.0]]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    head = "" if mutation == "kind" else "not a readable robot result: "
    with pytest.raises(didim.DataError, match=f"bad.json: {head}{message}"):
        didim.load_result(tmp_path / "bad.json")


def test_ambiguous_columns_and_wrapped_encoders_are_refused_by_name(pendulum, tmp_path):
    """Both column forms at once (qr_1.. and qr_<joint>, which one holds a joint's signal would be a guess), an
    encoder that wraps a whole turn between two samples (it read as the units' fault: "probably in deg"), and a
    joint picked out of a record that logged more: each refused naming the columns or the joint."""
    robot, ctl, rec, df = pendulum
    both = df.assign(qr_joint1=df["qr_1"] + 0.1, qr_joint2=df["qr_2"])
    both.to_csv(tmp_path / "both.csv", index=False)
    with pytest.raises(didim.DataError, match="both qr_1 … qr_2 and qr_<joint name> columns"):
        didim.load_record(tmp_path / "both.csv", robot=robot, controller=ctl)
    q = df["qm_2"].to_numpy().copy()
    q[12345:] += 2 * np.pi
    df.assign(qm_2=q).to_csv(tmp_path / "wrap.csv", index=False)
    with pytest.raises(didim.DataError, match="joint joint2's qm jumps by 6.28. rad between samples 12344 and 12345, "
                                              "a whole turn: its encoder wraps"):
        didim.load_record(tmp_path / "wrap.csv", robot=robot, controller=ctl)
    one = didim.Robot.from_urdf(robot.source, ["joint2"])
    with pytest.raises(didim.DataError, match="columns for 2 joints .* but the robot has 1 .joint2.: .* --joints picks"):
        didim.load_record(tmp_path / "wrap.csv", robot=one)


def test_a_time_column_declared_in_ms_is_read_in_ms_and_an_unknown_unit_is_refused(pendulum, tmp_path):
    """``t[ms]`` in the header: the record's time in milliseconds, read as such (it was refused with "convert it");
    a unit didim does not know is refused naming the units it reads."""
    robot, ctl, rec, frame = pendulum
    x = frame.rename(columns={"t": "t[ms]"})
    x["t[ms]"] = x["t[ms]"] * 1000
    x.to_csv(tmp_path / "ms.csv", index=False)
    got = didim.load_record(tmp_path / "ms.csv", robot=robot, controller=ctl)
    assert got.dt == pytest.approx(rec.dt, rel=1e-9)
    np.testing.assert_array_equal(got.force, rec.force)
    frame.rename(columns={"t": "t[fortnight]"}).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(didim.DataError, match=r"bad.csv: the time column's unit \[fortnight\] is not one didim reads"):
        didim.load_record(tmp_path / "bad.csv", robot=robot, controller=ctl)


def test_the_third_campaign_s_tracebacks_are_errors_naming_the_problem(pendulum, tmp_path):
    """A constant record, a URDF whose numbers overflow, one controller for a two-joint robot, a fractional max_iter
    or a negative tol for the payload, a one-axis record given to simulate_robot: each a DataError saying what to
    change (each was a Python traceback)."""
    robot, ctl, rec, frame = pendulum
    still = frame.copy()
    still.iloc[:, 1:] = still.iloc[0, 1:].to_numpy()
    still.to_csv(tmp_path / "still.csv", index=False)
    with pytest.raises(didim.DataError, match="no joint's reference moves"):
        didim.identify(didim.load_record(tmp_path / "still.csv", robot=robot, controller=ctl), robot, "idim-ls")
    assert 'xyz="0 0 -0.5"' in robot.urdf  # the second joint's origin
    with pytest.raises(didim.DataError, match="out of scale"):
        didim.identify(rec, didim.Robot.from_urdf_string(robot.urdf.replace('xyz="0 0 -0.5"', 'xyz="0 0 -1e200"')),
                       "idim-ls")
    one = rec.controller[0]
    with pytest.raises(didim.DataError, match="one controller per joint"):
        didim.load_record(tmp_path / "still.csv", robot=robot, controller=one)
    res = didim.identify(rec, robot, "idim-ls")
    for bad in (dict(max_iter=1.5), dict(tol=-1.0)):
        with pytest.raises(didim.DataError):
            didim.robots.payload(rec, res, **bad)
    with pytest.raises(didim.DataError, match="are not the robot's"):
        didim.robots.simulate_robot(rec.joint(0), res)


def test_a_joint_that_never_moves_is_named_in_the_result(pendulum, tmp_path):
    """A record in which one joint is held still: its friction cannot come from it, and the result says so (IDIM-LS
    gave Fv 287 for a truth of 0.51, with no word)."""
    robot, ctl, rec, frame = pendulum
    held = frame.copy()
    held["qr_2"] = held["qr_2"].iloc[0]
    held.to_csv(tmp_path / "held.csv", index=False)
    res = didim.identify(didim.load_record(tmp_path / "held.csv", robot=robot, controller=ctl), robot, "idim-ls",
                         controller_check="off")
    assert any("joint joint2 does not move in this record" in n for n in res.notes), res.notes


def test_units_declared_joint_by_joint_are_checked_joint_by_joint(pendulum, tmp_path):
    """A joints file declaring one joint in degrees on a record in rad was read without a word (Ia 50.5 for 0.026):
    each joint's declaration is judged on its own against the URDF's dynamics; a right mixed declaration reads the
    same positions as the record in rad."""
    import math

    robot, ctl, rec, frame = pendulum
    spec = json.loads(ctl.read_text())
    spec["joints"][0]["units"] = "deg"
    (tmp_path / "wrong.json").write_text(json.dumps(spec))
    frame.to_csv(tmp_path / "rad.csv", index=False)
    with pytest.raises(didim.DataError, match="joint joint1 is read in deg.*it is probably in rad"):
        didim.load_record(tmp_path / "rad.csv", robot=robot, controller=tmp_path / "wrong.json")
    k = 180 / math.pi
    for key in ("b_r", "b_y"):  # the same law per degree
        spec["joints"][0][key] = [x / k for x in spec["joints"][0][key]]
    (tmp_path / "deg.json").write_text(json.dumps(spec))
    deg = frame.copy()
    deg["qr_1"] *= k
    deg["qm_1"] *= k
    deg.to_csv(tmp_path / "deg.csv", index=False, float_format="%.17g")
    got = didim.load_record(tmp_path / "deg.csv", robot=robot, controller=tmp_path / "deg.json")
    np.testing.assert_allclose(got.qm, rec.qm, rtol=1e-12, atol=1e-15)


def test_a_drive_unit_declared_on_a_force_already_in_newton_metres_is_refused(pendulum, tmp_path):
    """`--units rad,A=2.5` on a record whose force is in N·m multiplied every parameter by 2.5 without a word; the
    same record logged in amps (force / 2.5, the controllers' gain / 2.5) and declared so reads the N·m force."""
    robot, ctl, rec, frame = pendulum
    frame.to_csv(tmp_path / "nm.csv", index=False)
    with pytest.raises(didim.DataError, match="the force is probably already in N·m"):
        didim.load_record(tmp_path / "nm.csv", robot=robot, controller=ctl, units="rad,A=2.5")
    amps = frame.copy()
    amps[["force_1", "force_2"]] /= 2.5
    amps.to_csv(tmp_path / "amps.csv", index=False, float_format="%.17g")
    spec = json.loads(ctl.read_text())
    for j in spec["joints"]:
        j["gain"] = j.get("gain", 1.0) / 2.5
    (tmp_path / "amps.json").write_text(json.dumps(spec))
    got = didim.load_record(tmp_path / "amps.csv", robot=robot, controller=tmp_path / "amps.json", units="rad,A=2.5")
    np.testing.assert_allclose(got.force, rec.force, rtol=1e-12, atol=1e-12 * np.abs(rec.force).max())


def _joints_file(ctl, tmp_path, name, edit):
    spec = json.loads(ctl.read_text())
    edit(spec)
    (tmp_path / name).write_text(json.dumps(spec))
    return tmp_path / name


def test_a_time_column_in_ms_read_as_s_is_refused_by_the_dynamics(pendulum, tmp_path):
    """A robot record whose time is in ms with a plain ``t`` header was read with a 1 s sample period: `controller
    fit` wrote dt = 1 s controllers and DIDIM gave Ia 789723 for 0.03, exit 0. The URDF's dynamics fit it three
    times better in ms (24 % against 8 % of the force unexplained, the drives' inertia left out): refused, naming the
    file and t[ms]; a controller given at that period does not hide it, and the same record declared t[ms] reads."""
    robot, ctl, rec, frame = pendulum
    ms = frame.assign(t=frame["t"] * 1000)
    ms.to_csv(tmp_path / "ms.csv", index=False)
    slow = _joints_file(ctl, tmp_path, "slow.json", lambda s: [j.update(dt=1.0) for j in s["joints"]])
    with pytest.raises(didim.DataError, match=r"ms.csv: read in s, the time column t .* its time is probably in ms; "
                                              r"declare it in the header \(t\[ms\]\)"):
        didim.load_record(tmp_path / "ms.csv", robot=robot, controller=slow)
    ms.rename(columns={"t": "t[ms]"}).to_csv(tmp_path / "declared.csv", index=False)
    assert didim.load_record(tmp_path / "declared.csv", robot=robot, controller=ctl).dt == pytest.approx(rec.dt)


def test_positions_in_revolutions_are_named_among_every_angle_unit(pendulum, tmp_path):
    """Positions in revolutions, undeclared (controller per revolution): the unit check tried deg only and let it
    through (force error 10 %); every angle unit didim knows is tried, and rev named."""
    import math

    robot, ctl, rec, frame = pendulum
    rev = frame.copy()
    for c in ("qr_1", "qr_2", "qm_1", "qm_2"):
        rev[c] /= 2 * math.pi
    rev.to_csv(tmp_path / "rev.csv", index=False, float_format="%.17g")
    k = _joints_file(ctl, tmp_path, "rev.json", lambda s: [j.update(b_r=[x * 2 * math.pi for x in j["b_r"]],
                                                                    b_y=[x * 2 * math.pi for x in j["b_y"]])
                                                           for j in s["joints"]])
    with pytest.raises(didim.DataError, match=r"rev.csv: read in rad.* probably in rev; declare its units \(units='rev'"):
        didim.load_record(tmp_path / "rev.csv", robot=robot, controller=k)
    got = didim.load_record(tmp_path / "rev.csv", robot=robot, controller=k, units="rev")
    np.testing.assert_allclose(got.qm, rec.qm, rtol=1e-12, atol=1e-12)


def test_a_record_that_fits_no_unit_blames_the_urdf_or_its_length_not_degrees(pendulum, tmp_path):
    """Joints relabelled, or a tenth of a second of a record: "probably in deg" where deg fit no better than 86 % (or
    39 %). Now: no unit fits, the URDF is probably not this robot's, naming the worst joint; or the record is too
    short, naming the joints that never reverse."""
    robot, ctl, rec, frame = pendulum
    m = {f"{a}_{i}": f"{a}_{3 - i}" for a in ("qr", "force", "qm") for i in (1, 2)}
    frame.rename(columns=m).to_csv(tmp_path / "relabelled.csv", index=False)
    with pytest.raises(didim.DataError, match=r"relabelled.csv: no unit of position makes the record fit the URDF's "
                                              r"dynamics .* the URDF probably does not describe this record's robot "
                                              r"\(joint joint\d fits worst"):
        didim.load_record(tmp_path / "relabelled.csv", robot=robot, controller=ctl)
    frame.iloc[:100].to_csv(tmp_path / "short.csv", index=False)
    with pytest.raises(didim.DataError, match=r"short.csv: no unit .* the record \(100 samples, 0.1 s\) is probably "
                                              r"too short or too still .* joint1, joint2 never reverses"):
        didim.load_record(tmp_path / "short.csv", robot=robot, controller=ctl)
    frame.iloc[:3].to_csv(tmp_path / "three.csv", index=False)
    with pytest.raises(didim.DataError, match=r"three.csv: the record has 3 samples .* needs at least 16 samples"):
        didim.load_record(tmp_path / "three.csv", robot=robot, controller=ctl)


def test_a_urdf_that_is_not_the_record_s_robot_is_named_when_didim_cannot_simulate(pendulum, tmp_path):
    """A horizontal arm's URDF for the vertical pendulum's record: DIDIM stopped on "articulated inertia is not
    positive"; the message now says the URDF leaves 91 % of the force unexplained and is probably not this robot's."""
    robot, ctl, rec, frame = pendulum
    flat = (robot.urdf.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 1"/>')
            .replace('<origin xyz="0 0 -0.5"', '<origin xyz="0.5 0 0"')
            .replace('<origin xyz="0 0 -0.25"', '<origin xyz="0.25 0 0"'))
    assert flat != robot.urdf
    other = didim.Robot.from_urdf_string(flat)
    got = didim.load_record(robots_record(frame, tmp_path), robot=other, controller=ctl)
    with pytest.raises(didim.SimulationError, match="the URDF probably does not describe this record's robot"):
        didim.identify(got, other, "didim")


def robots_record(frame, tmp_path):
    frame.to_csv(tmp_path / "rec.csv", index=False)
    return tmp_path / "rec.csv"


def test_wraps_at_every_turn_comments_and_a_zero_force_are_named(pendulum, tmp_path):
    """An encoder logged modulo 2π (a wrap at each turn: only a single wrap was caught, the rest blamed on units),
    comment lines above the header (refused as not numeric), a force column of zeros (overflow warnings and "within
    inf %")."""
    import math

    robot, ctl, rec, frame = pendulum
    wrapped = frame.assign(qm_1=np.mod(frame["qm_1"], 2 * math.pi), qr_1=np.mod(frame["qr_1"], 2 * math.pi))
    wrapped.to_csv(tmp_path / "wrapped.csv", index=False)
    with pytest.raises(didim.DataError, match=r"wrapped.csv: joint joint1's qm jumps by .* a whole turn: its encoder "
                                              r"wraps at one turn \(at t = .* s, \d+ times in the record\); unwrap"):
        didim.load_record(tmp_path / "wrapped.csv", robot=robot, controller=ctl)
    text = robots_record(frame, tmp_path).read_text()
    (tmp_path / "commented.csv").write_text("# exported by the logger\n# 2 joints\n" + text)
    got = didim.load_record(tmp_path / "commented.csv", robot=robot, controller=ctl)
    np.testing.assert_array_equal(got.force, rec.force)
    frame.assign(force_1=0.0, force_2=0.0).to_csv(tmp_path / "zero.csv", index=False)
    with pytest.raises(didim.DataError, match="zero, joint joint1: the logged force is zero on every sample"):
        didim.identify(didim.load_record(tmp_path / "zero.csv", robot=robot, controller=ctl), robot, "idim-ls")


def test_a_controller_that_saturates_everywhere_is_explained(pendulum, tmp_path):
    """"check the saturation and gain" where the denominator is unstable, the controller is per rad on a record
    declared in deg, or the reference's sign is flipped: each named."""
    import math

    robot, ctl, rec, frame = pendulum
    unstable = _joints_file(ctl, tmp_path, "unstable.json", lambda s: s["joints"][1].update(a_y=[1.0, -2.5, 1.5]))
    got = didim.load_record(robots_record(frame, tmp_path), robot=robot, controller=unstable)
    with pytest.raises(didim.DataError, match=r"joint joint2: .*pole at \|z\| = 1.5, outside the unit circle: its law "
                                              "is unstable"):
        didim.identify(got, robot, "idim-ls")
    k = 180 / math.pi
    deg = frame.assign(qr_1=frame["qr_1"] * k, qr_2=frame["qr_2"] * k, qm_1=frame["qm_1"] * k, qm_2=frame["qm_2"] * k)
    deg.to_csv(tmp_path / "deg.csv", index=False, float_format="%.17g")
    got = didim.load_record(tmp_path / "deg.csv", robot=robot, controller=ctl, units="deg")
    with pytest.raises(didim.DataError, match="joint joint1: .*the controller acts on positions in deg while the "
                                              "record's are in rad"):
        didim.identify(got, robot, "idim-ls")
    flipped = frame.assign(qr_1=-frame["qr_1"])
    flipped.to_csv(tmp_path / "flipped.csv", index=False)
    got = didim.load_record(tmp_path / "flipped.csv", robot=robot, controller=ctl)
    with pytest.raises(didim.DataError, match=r"joint joint1: .*the reference's sign is reversed .*negate it"):
        didim.identify(got, robot, "idim-ls")


def test_joints_files_options_and_outputs_name_what_to_change(pendulum, tmp_path):
    """A bad field in a joints file's entry names the file and the joint; a joints file's content given as a mapping
    is read as the file; didim.simulate on a robot's record asks for a robot's result; two angle units say how to
    declare them per joint; a mimic joint is refused (the Panda's mimicking fingers, locked, still load); a full
    device is named."""
    import pathlib

    robot, ctl, rec, frame = pendulum
    bad = _joints_file(ctl, tmp_path, "bad.json", lambda s: s["joints"][0].update(saturation=-50))
    with pytest.raises(didim.DataError, match=r"bad.json: joint 1: controller saturation must be a number > 0"):
        didim.load_record(robots_record(frame, tmp_path), robot=robot, controller=bad)
    got = didim.load_record(robots_record(frame, tmp_path), robot=robot, controller=json.loads(ctl.read_text()))
    assert got.controllers == rec.controllers
    with pytest.raises(didim.DataError, match=r"is a robot's .*simulate it with a robot's identification result"):
        didim.simulate(rec, {"M": 1.0, "Fv": 1.0, "Fc": 1.0})
    with pytest.raises(didim.DataError, match="declare them per joint: \"units\" in each joint's entry of the "
                                              "controllers' file"):
        didim.load_record(robots_record(frame, tmp_path), robot=robot, controller=ctl, units="deg,rad")
    mimic = robot.urdf.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 1 0"/><mimic joint="joint1" multiplier="1"/>')
    mimic = mimic.replace('<mimic joint="joint1" multiplier="1"/>', "", 1)  # joint2 mimics joint1
    with pytest.raises(didim.DataError, match="joint joint2 mimics joint joint1 .<mimic>.: didim does not support "
                                              "mimic joints"):
        didim.Robot.from_urdf_string(mimic)
    import site

    for d in site.getsitepackages():  # example-robot-data's Panda, where installed
        panda = pathlib.Path(d) / "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
        if not panda.exists():
            continue
        assert "<mimic" in panda.read_text() and len(didim.Robot.from_urdf(panda).joint_names) == 7
    if pathlib.Path("/dev/full").exists():
        from didim.formats._io import write_text

        with pytest.raises(OSError, match="cannot write /dev/full: No space left on device"):
            write_text("/dev/full", "x" * 100000)


def test_pulses_gain_is_refused_on_a_robot_record(robots_dir):
    from test_cli import run

    out = run("identify", str(robots_dir / "pendulum_train.csv"), "--urdf", str(robots_dir / "pendulum_cad.urdf"),
              "--method", "idim-ls", "--pulses-gain", "2")
    assert out.returncode == 2 and "--pulses-gain does not apply to a robot (--urdf)" in out.stderr, out.stderr


def test_a_joint_kind_the_record_does_not_have_and_a_robot_dataframe(pendulum, tmp_path):
    """A URDF calling the pendulum's second joint prismatic: IDIM-LS printed "closed-loop force error nan %" and
    nothing else; the summary now says the loop could not be simulated, and the note that the URDF leaves 63 % of the
    force unexplained, naming joint2. A robot's record as a DataFrame (from_dataframe(df, robot=...)) reads as its
    CSV does (it was a TypeError)."""
    robot, ctl, rec, frame = pendulum
    slid = didim.Robot.from_urdf_string(robot.urdf.replace('name="joint2" type="revolute"',
                                                           'name="joint2" type="prismatic"'))
    assert slid.joint_kinds == ["revolute", "prismatic"]
    got = didim.load_record(robots_record(frame, tmp_path), robot=slid, controller=ctl)
    res = didim.identify(got, slid, "idim-ls", controller_check="off")
    assert "its closed loop could not be simulated" in res.summary()
    assert any("the URDF probably does not describe this record's robot (joint joint2 fits worst" in n
               for n in res.notes), res.notes
    got = didim.from_dataframe(frame, robot=robot, controller=ctl)
    np.testing.assert_array_equal(got.force, rec.force)
    np.testing.assert_array_equal(got.qm, rec.qm)
    with pytest.raises(didim.DataError, match="dt applies to one axis's record"):
        didim.from_dataframe(frame, robot=robot, controller=ctl, dt=0.001)


def test_a_urdf_whose_dynamics_overflow_on_the_record_is_refused_at_load(pendulum, tmp_path):
    """A link of 1e300 kg: overflow warnings, then "no joint moves above the slow-speed threshold"; now refused when
    the record is read, naming the URDF, without a warning."""
    import warnings

    robot, ctl, rec, frame = pendulum
    heavy = didim.Robot.from_urdf_string(robot.urdf.replace('<mass value="2.0"/>', '<mass value="1e300"/>'),
                                         source="heavy.urdf")
    assert heavy.urdf != robot.urdf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(didim.DataError, match="the URDF's inverse dynamics are not finite on this record's motion "
                                                  ".*heavy.urdf is far out of scale"):
            didim.load_record(robots_record(frame, tmp_path), robot=heavy, controller=ctl)


def test_load_record_names_an_option_it_does_not_take(pendulum):
    """load_record(..., joints=[...]) was Python's TypeError; it now says where joints are picked (the URDF), and a
    misspelt option is named with its nearest."""
    robot, ctl, rec, frame = pendulum
    with pytest.raises(didim.DataError, match=r"load_record takes no joints=: .*didim.Robot.from_urdf\(path, "
                                              r"joints=\[...\]\)"):
        didim.load_record(robot.source, robot=robot, controller=ctl, joints=["joint1"])
    with pytest.raises(didim.DataError, match="'contoller': did you mean 'controller'"):
        didim.load_record(robot.source, contoller=ctl)


def test_an_unreadable_urdf_says_where(pendulum):
    """A URDF cut mid-file ("No elements found") and a mass written "abc" ("custom: invalid float literal", no
    element named): the XML's line and column, or the link and the attribute."""
    robot, *_ = pendulum
    with pytest.raises(didim.DataError, match=r"cut.urdf: not a URDF robot description: its XML is not well formed at "
                                              r"line \d+, column \d+ .*a file cut short"):
        didim.Robot.from_urdf_string(robot.urdf[:600], source="cut.urdf")
    assert '<mass value="2.0"/>' in robot.urdf
    with pytest.raises(didim.DataError, match='link link2\'s <mass value="abc">: not a number'):
        didim.Robot.from_urdf_string(robot.urdf.replace('<mass value="2.0"/>', '<mass value="abc"/>'))


def test_a_declared_delay_the_record_lacks_is_named_in_the_result(pendulum, tmp_path):
    """A one-sample actuation delay declared on joint 1 of a record that has none (the third campaign's C24: mx of
    joint 1 13 % off, not a word): the result's notes name the joint and the declaration, the model simulating the
    record better without it (1.42 % against 1.45 %, Diebold-Mariano p = 0.003); the right declaration gets no such
    note."""
    robot, ctl, rec, _ = pendulum
    spec = json.loads(ctl.read_text())
    spec["joints"][0]["delay"] = 1
    wrong = tmp_path / "delayed_controller.json"
    wrong.write_text(json.dumps(spec))
    res = didim.identify(didim.load_record(rec_path(ctl), robot=robot, controller=wrong), robot, "idim-ls")
    notes = [n for n in res.notes if "declares a delay" in n]
    assert len(notes) == 1 and robot.joint_names[0] in notes[0], res.notes
    right = didim.identify(rec, robot, "idim-ls")
    assert not [n for n in right.notes if "declares" in n]


def rec_path(ctl):
    return ctl.parent / ctl.name.replace("_controller.json", "_train.csv")
