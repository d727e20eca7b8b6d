"""didim.Robot against Pinocchio (a test-only dependency): the chain read from a URDF, its inertial parameters, and
rnea, aba, gravity, mass_matrix and the joint-torque regressor on random states of the UR5 (the data folder's and
example-robot-data's), the Panda (7 joints, its fingers locked) and the double pendulum."""

import importlib.metadata
import os

import numpy as np
import pytest

import didim

pin = pytest.importorskip("pinocchio")

#: The issue's bound: every function within 1e-9 of Pinocchio's, relative to the largest entry of what is compared
#: (both sum the same terms in another order: rounding is a few units of 1e-16 times the terms' size).
RTOL = 1e-9


def _example_robot(name):
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    for f in files:
        if str(f).endswith(f"/{name}"):
            return str(f.locate())
    pytest.skip(f"example-robot-data has no {name}")


PANDA_ARM = [f"panda_joint{i}" for i in range(1, 8)]


def _cases(robots_dir):
    return {
        "ur5 (data folder)": (str(robots_dir / "ur5_cad.urdf"), None),
        "pendulum (data folder)": (str(robots_dir / "pendulum_cad.urdf"), None),
        "ur5 (example-robot-data)": (_example_robot("ur5_robot.urdf"), None),
        "panda (example-robot-data)": (_example_robot("panda.urdf"), PANDA_ARM),
    }


def _pin_model(path, joints):
    m = pin.buildModelFromUrdf(path)
    if joints is not None:
        lock = [m.getJointId(n) for n in m.names[1:] if n not in joints]
        m = pin.buildReducedModel(m, lock, pin.neutral(m))
    return m


def _close(got, want, what):
    scale = np.max(np.abs(want))
    err = np.max(np.abs(np.asarray(got) - want)) / scale
    assert err < RTOL, f"{what}: relative difference {err:.2e}"


@pytest.mark.parametrize("case", ["ur5 (data folder)", "pendulum (data folder)", "ur5 (example-robot-data)",
                                  "panda (example-robot-data)"])
def test_the_dynamics_agree_with_pinocchio(robots_dir, case):
    path, joints = _cases(robots_dir)[case]
    robot = didim.Robot.from_urdf(path, joints)
    m = _pin_model(path, joints)
    d = m.createData()
    assert robot.joint_names == list(m.names[1:])
    pi = np.concatenate([m.inertias[i].toDynamicParameters() for i in range(1, m.njoints)])
    _close(robot.inertial_params, pi, "inertial parameters")
    rng = np.random.default_rng(7)
    lo = np.where(np.isfinite(m.lowerPositionLimit), m.lowerPositionLimit, -np.pi)
    hi = np.where(np.isfinite(m.upperPositionLimit), m.upperPositionLimit, np.pi)
    qs, vs, as_, taus = [], [], [], []
    for _ in range(40):
        q = rng.uniform(lo, hi)
        v, a, tau = rng.normal(size=m.nv), rng.normal(size=m.nv), 10 * rng.normal(size=m.nv)
        _close(robot.rnea(q, v, a), pin.rnea(m, d, q, v, a), "rnea")
        _close(robot.gravity(q), pin.computeGeneralizedGravity(m, d, q), "gravity")
        mm = pin.crba(m, d, q)
        _close(robot.mass_matrix(q), np.triu(mm) + np.triu(mm, 1).T, "mass matrix")
        _close(robot.aba(q, v, tau), pin.aba(m, d, q, v, tau), "aba")
        _close(robot.regressor(q, v, a), pin.computeJointTorqueRegressor(m, d, q, v, a), "regressor")
        # the exact derivatives of inverse dynamics (the closed loop's sensitivities need them)
        tau_d, dq_d, dv_d = robot.rnea_derivatives(q, v, a)
        dq_p, dv_p, _ = pin.computeRNEADerivatives(m, d, q, v, a)
        _close(tau_d, pin.rnea(m, d, q, v, a), "rnea with its derivatives")
        _close(dq_d, dq_p, "∂τ/∂q")
        _close(dv_d, dv_p, "∂τ/∂q̇")
        qs.append(q), vs.append(v), as_.append(a), taus.append(tau)
    # many states at once: the same as one by one
    q, v, a = np.array(qs), np.array(vs), np.array(as_)
    many = robot.rnea(q, v, a)
    assert many.shape == (40, robot.ndof)
    _close(many, np.array([pin.rnea(m, d, *x).copy() for x in zip(q, v, a)]), "rnea of many states")
    assert robot.mass_matrix(q).shape == (40, robot.ndof, robot.ndof)
    tau_m, dq_m, dv_m = robot.rnea_derivatives(q, v, a)
    assert tau_m.shape == (40, robot.ndof) and dq_m.shape == dv_m.shape == (40, robot.ndof, robot.ndof)
    assert np.array_equal(dq_m[3], robot.rnea_derivatives(q[3], v[3], a[3])[1])
    assert robot.regressor(q, v, a).shape == (40, robot.ndof, 10 * robot.ndof)
    # only some standard parameters' columns: those of the whole regressor, bit for bit
    cols = [3, 0, 10 * robot.ndof - 1, 3]
    assert np.array_equal(robot.regressor(q, v, a, columns=cols), robot.regressor(q, v, a)[..., cols])
    assert np.array_equal(robot.regressor(q[0], v[0], a[0], columns=cols), robot.regressor(q[0], v[0], a[0])[:, cols])
    # series by series (joint, column, state): the same values
    assert np.array_equal(robot.regressor(q, v, a, columns=cols, by_joint=True),
                          robot.regressor(q, v, a)[..., cols].transpose(1, 2, 0))
    assert np.array_equal(robot.regressor(q, v, a, by_joint=True), robot.regressor(q, v, a).transpose(1, 2, 0))
    with pytest.raises(didim.DataError, match="N states"):
        robot.regressor(q[0], v[0], a[0], by_joint=True)
    with pytest.raises(didim.DataError, match="standard parameters"):
        robot.regressor(q, v, a, columns=[10 * robot.ndof])
    # rotor inertia on the diagonal, as Pinocchio's armature
    arm = np.linspace(0.1, 0.3, m.nv)
    m.armature = arm
    d = m.createData()
    _close(robot.aba(q[0], v[0], np.array(taus[0]), armature=arm), pin.aba(m, d, q[0], v[0], taus[0]), "aba with armature")
    # forward dynamics' exact derivatives, with the armature
    for k in range(5):
        qdd, dq_d, dv_d, dtau_d = robot.aba_derivatives(q[k], v[k], np.array(taus[k]), armature=arm)
        dq_p, dv_p, dtau_p = pin.computeABADerivatives(m, d, q[k], v[k], np.array(taus[k]))
        _close(qdd, pin.aba(m, d, q[k], v[k], taus[k]), "aba with its derivatives")
        _close(dq_d, dq_p, "∂q̈/∂q")
        _close(dv_d, dv_p, "∂q̈/∂q̇")
        _close(dtau_d, np.triu(dtau_p) + np.triu(dtau_p, 1).T, "∂q̈/∂τ")
    assert robot.aba_derivatives(q, v, np.array(taus), armature=arm)[1].shape == (40, robot.ndof, robot.ndof)


def test_a_robot_describes_itself(robots_dir):
    robot = didim.Robot.from_urdf(robots_dir / "ur5_cad.urdf")
    assert robot.ndof == 6 and robot.joint_kinds == ["revolute"] * 6
    assert robot.param_names[:3] == ["m_shoulder_pan_joint", "mx_shoulder_pan_joint", "my_shoulder_pan_joint"]
    lower, upper, vel, effort = robot.limits[0]
    assert lower < 0 < upper and vel > 0 and effort > 0
    heavier = robot.with_inertial_params(robot.inertial_params * 2)
    q = np.zeros(6) + 0.3
    np.testing.assert_allclose(heavier.gravity(q), 2 * robot.gravity(q), rtol=1e-12)


def test_bad_robots_and_states_are_refused_by_name(robots_dir, tmp_path):
    ur5 = robots_dir / "ur5_cad.urdf"
    with pytest.raises(didim.DataError, match="no such file"):
        didim.Robot.from_urdf(tmp_path / "missing.urdf")
    fifo = tmp_path / "robot.urdf"
    os.mkfifo(fifo)
    with pytest.raises(didim.DataError, match="FIFO|special|not a regular file"):
        didim.Robot.from_urdf(fifo)
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/>")
    with pytest.raises(didim.DataError, match="not a URDF"):
        didim.Robot.from_urdf(bad)
    with pytest.raises(didim.DataError, match="no joint elbow"):
        didim.Robot.from_urdf(ur5, ["elbow"])
    with pytest.raises(didim.DataError, match="not a serial chain"):
        didim.Robot.from_urdf(_example_robot("baxter.urdf"))  # two arms and a head on a torso
    # the Panda's fingers are a short branch at the end of its arm: the arm by default, the fingers locked
    panda = didim.Robot.from_urdf(_example_robot("panda.urdf"))
    assert panda.joint_names == PANDA_ARM and panda.locked_joints == ["panda_finger_joint1", "panda_finger_joint2"]
    robot = didim.Robot.from_urdf(ur5)
    with pytest.raises(didim.DataError, match="6 joints"):
        robot.rnea(np.zeros(5), np.zeros(5), np.zeros(5))
    with pytest.raises(didim.DataError, match="same number of rows"):
        robot.rnea(np.zeros((3, 6)), np.zeros((2, 6)), np.zeros((3, 6)))
    with pytest.raises(didim.DataError, match="non-finite"):
        robot.gravity(np.full(6, np.nan))


#: A chain of this test's own: a prismatic joint (a linear axis carrying the arm), revolute joints about tilted axes,
#: rotated placements and a fixed tool, inertias off their principal axes.
MIXED = """<robot name="mixed">
  <link name="base"/>
  <link name="carriage"><inertial><origin xyz="0.05 -0.02 0.1" rpy="0.3 -0.2 0.1"/><mass value="12.0"/>
    <inertia ixx="0.4" ixy="0.01" ixz="-0.02" iyy="0.5" iyz="0.03" izz="0.3"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0.2 0.01 0.03" rpy="0 0.4 0.2"/><mass value="4.0"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0.002" iyy="0.08" iyz="-0.001" izz="0.07"/></inertial></link>
  <link name="fore"><inertial><origin xyz="0.15 0 -0.02"/><mass value="2.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0.001" iyy="0.03" iyz="0" izz="0.025"/></inertial></link>
  <link name="tool"><inertial><origin xyz="0 0 0.05"/><mass value="0.7"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <joint name="slide" type="prismatic"><parent link="base"/><child link="carriage"/><origin xyz="0 0 0.3" rpy="0 0 0.4"/>
    <axis xyz="1 0 0"/><limit lower="-0.5" upper="0.5" effort="800" velocity="1"/></joint>
  <joint name="shoulder" type="revolute"><parent link="carriage"/><child link="upper"/><origin xyz="0.1 0 0.2" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 0.6 0.8"/><limit lower="-2" upper="2" effort="200" velocity="2"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.4 0.02 0" rpy="0.1 0.2 -0.3"/>
    <axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="100" velocity="2"/></joint>
  <joint name="tool_mount" type="fixed"><parent link="fore"/><child link="tool"/><origin xyz="0.3 0 0" rpy="0 -1.5707963267948966 0"/></joint>
</robot>"""


def test_a_prismatic_joint_and_tilted_axes_agree_with_pinocchio(tmp_path):
    path = tmp_path / "mixed.urdf"
    path.write_text(MIXED)
    robot = didim.Robot.from_urdf(path)
    assert robot.joint_kinds == ["prismatic", "revolute", "revolute"]
    m = pin.buildModelFromUrdf(str(path))
    d = m.createData()
    pi = np.concatenate([m.inertias[i].toDynamicParameters() for i in range(1, m.njoints)])
    _close(robot.inertial_params, pi, "inertial parameters")
    rng = np.random.default_rng(3)
    for _ in range(30):
        q = rng.uniform(m.lowerPositionLimit, m.upperPositionLimit)
        v, a, tau = rng.normal(size=3), rng.normal(size=3), 20 * rng.normal(size=3)
        _close(robot.rnea(q, v, a), pin.rnea(m, d, q, v, a), "rnea")
        _close(robot.gravity(q), pin.computeGeneralizedGravity(m, d, q), "gravity")
        mm = pin.crba(m, d, q)
        _close(robot.mass_matrix(q), np.triu(mm) + np.triu(mm, 1).T, "mass matrix")
        _close(robot.aba(q, v, tau), pin.aba(m, d, q, v, tau), "aba")
        _close(robot.regressor(q, v, a), pin.computeJointTorqueRegressor(m, d, q, v, a), "regressor")
        _, dq_d, dv_d = robot.rnea_derivatives(q, v, a)
        dq_p, dv_p, _ = pin.computeRNEADerivatives(m, d, q, v, a)
        _close(dq_d, dq_p, "∂τ/∂q (a prismatic joint, tilted axes)")
        _close(dv_d, dv_p, "∂τ/∂q̇ (a prismatic joint, tilted axes)")


def test_a_urdf_that_is_not_one_tree_is_refused_from_the_api_a_saved_result_and_the_command_line(tmp_path):
    """A URDF whose joints form a loop (a fixed joint back to an earlier link, a joint from a link to itself), NaN in
    an <origin>, XML nested 100,000 deep: each a DataError naming the link or joint (these crashed the interpreter:
    the walk of the tree recursed without end, the XML parser exhausted the stack), also inside a saved result and
    from the command line (exit 2, one line). Run in a child process so that a crash fails the test, not the run."""
    import json
    import subprocess
    import sys

    tree = MIXED.replace("</robot>", '<joint name="back" type="fixed"><parent link="fore"/><child link="upper"/>'
                         "</joint></robot>")
    own = MIXED.replace("</robot>", '<joint name="own" type="fixed"><parent link="fore"/><child link="fore"/>'
                        "</joint></robot>")
    nan = MIXED.replace('<origin xyz="0.4 0.02 0" rpy="0.1 0.2 -0.3"/>', '<origin xyz="0.4 nan 0" rpy="0.1 0.2 -0.3"/>')
    deep = "<robot name='d'>" + "<a>" * 100_000 + "</a>" * 100_000 + "</robot>"
    cases = {"loop": (tree, "link upper is the child of two joints (shoulder and back)"),
             "own": (own, "joint own joins link fore to itself"),
             "nan": (nan, "joint elbow's <origin> holds NaN"),
             "deep": (deep, "nested 100001 elements deep")}
    good = didim.Robot.from_urdf_string(MIXED)
    for name, (text, message) in cases.items():
        path = tmp_path / f"{name}.urdf"
        path.write_text(text)
        code = (f"import didim\ntry:\n    didim.Robot.from_urdf({str(path)!r})\nexcept didim.DataError as e:\n"
                "    print(e)\n")
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert p.returncode == 0 and message in p.stdout, (name, p.returncode, p.stdout, p.stderr[-500:])
        # the same URDF inside a saved robot result
        saved = {"kind": "robot", "method": "didim", "params": {}, "std": {}, "offset": True,
                 "robot": {"name": "mixed", "joints": good.joint_names, "urdf": text},
                 "base": {"names": [], "standard_names": [], "K": [], "independent": []}}
        rpath = tmp_path / f"{name}.json"
        rpath.write_text(json.dumps(saved))
        p = subprocess.run([sys.executable, "-m", "didim", "simulate", str(tmp_path / "none.csv"), str(rpath)],
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 2 and "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1, \
            (name, p.returncode, p.stderr[-500:])
        p = subprocess.run([sys.executable, "-c", f"import didim\ntry:\n    didim.load_result({str(rpath)!r})\n"
                            "except didim.DataError as e:\n    print(e)\n"], capture_output=True, text=True, timeout=120)
        assert p.returncode == 0 and message in p.stdout, (name, p.returncode, p.stdout, p.stderr[-500:])
