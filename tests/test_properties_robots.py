"""Property-based tests of the robot surfaces (issue 38): URDF structure (trees, loops, names, numbers), the content
of a robot record, and saved robot results. Each input either gives a result or a DataError with a message; where
this file's own reading of the input says what the answer must be (a URDF that is one serial chain of finite numbers
loads with its joints in order; one that is not a tree is refused), it is checked against that.

Examples per test: the "ci" profile of tests/test_properties.py (derandomized), or ``DIDIM_HYPOTHESIS_PROFILE=fuzz``.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from typing import Dict, List, Optional, Tuple

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import didim

settings.register_profile("robots_ci", max_examples=int(os.environ.get("DIDIM_CI_EXAMPLES", "40")), deadline=None,
                          derandomize=True, database=None, suppress_health_check=list(HealthCheck))
settings.register_profile("robots_fuzz", max_examples=int(os.environ.get("DIDIM_FUZZ_EXAMPLES", "2000")),
                          deadline=None, suppress_health_check=list(HealthCheck))
PROFILE = "robots_fuzz" if os.environ.get("DIDIM_HYPOTHESIS_PROFILE") == "fuzz" else "robots_ci"


def prop(test):
    return settings.get_profile(PROFILE)(test)


# ---------------------------------------------------------------------------------------------------------------------
# URDF structure
# ---------------------------------------------------------------------------------------------------------------------

NUMBERS = st.one_of(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), st.floats(-2.0, 2.0),
                    st.sampled_from([math.nan, math.inf, -math.inf, 0.0, 1e300]))
GOOD = st.floats(-1.0, 1.0)


@st.composite
def urdf_graphs(draw):
    """A random tree of links and joints, then (often) one change that may break it: a link or joint named twice,
    a joint to an undefined link or to its own parent, a link with two parents, a joint back up the tree (a loop), a
    second root, a number that is not finite."""
    n = draw(st.integers(1, 6))
    links = [f"l{i}" for i in range(n)]
    joints = []
    for i in range(1, n):
        parent = draw(st.sampled_from(links[:i])) if draw(st.booleans()) else links[i - 1]  # mostly chains
        joints.append({"name": f"j{i}", "type": draw(st.sampled_from(["revolute", "continuous", "prismatic", "fixed"])),
                       "parent": parent, "child": links[i],
                       "xyz": [draw(GOOD) for _ in range(3)], "rpy": [draw(GOOD) for _ in range(3)],
                       "axis": draw(st.sampled_from([[0, 0, 1], [1, 0, 0], [0, 1, 0], [0.6, 0.8, 0]]))})
    inertial = {name: {"mass": draw(st.floats(0.1, 10.0)), "xyz": [draw(GOOD) for _ in range(3)],
                       "diag": [draw(st.floats(0.01, 1.0)) for _ in range(3)]} for name in links}
    change = draw(st.sampled_from(["none", "none", "dup_link", "dup_joint", "undefined", "self", "two_parents",
                                   "loop", "second_root", "nan_origin", "nan_axis", "nan_mass", "zero_axis"]))
    if change == "dup_link":
        links.append(draw(st.sampled_from(links)))
    elif change == "dup_joint" and joints:
        joints.append({**draw(st.sampled_from(joints)), "child": f"x{len(joints)}"})
        links.append(f"x{len(joints) - 1}")
        inertial[links[-1]] = {"mass": 1.0, "xyz": [0, 0, 0], "diag": [0.1] * 3}
    elif change == "undefined" and joints:
        j = draw(st.sampled_from(joints))
        j[draw(st.sampled_from(["parent", "child"]))] = "ghost"
    elif change == "self" and joints:
        j = draw(st.sampled_from(joints))
        j["child"] = j["parent"]
    elif change == "two_parents" and n >= 3:
        joints.append({**joints[0], "name": "jx", "parent": links[-1], "child": links[1]})
    elif change == "loop" and n >= 2:
        joints.append({**joints[0], "name": "jx", "parent": links[-1], "child": links[0]})
    elif change == "second_root":
        links.append("island")
        inertial["island"] = {"mass": 1.0, "xyz": [0, 0, 0], "diag": [0.1] * 3}
    elif change in ("nan_origin", "nan_axis", "zero_axis") and joints:
        j = draw(st.sampled_from(joints))
        if change == "nan_origin":
            j["xyz"] = [draw(NUMBERS) for _ in range(3)]
        elif change == "nan_axis":
            j["axis"] = [draw(NUMBERS) for _ in range(3)]
        else:
            j["axis"] = [0, 0, 0]
    elif change == "nan_mass":
        inertial[draw(st.sampled_from(links))]["mass"] = draw(NUMBERS)
    return links, joints, inertial


def urdf_text(links: List[str], joints: List[dict], inertial: Dict[str, dict]) -> str:
    def v(x):
        return " ".join(repr(float(a)) for a in x)

    out = ['<robot name="r">']
    for name in links:
        i = inertial[name]
        out.append(f'<link name="{name}"><inertial><origin xyz="{v(i["xyz"])}" rpy="0 0 0"/>'
                   f'<mass value="{float(i["mass"])!r}"/><inertia ixx="{i["diag"][0]!r}" ixy="0" ixz="0" '
                   f'iyy="{i["diag"][1]!r}" iyz="0" izz="{i["diag"][2]!r}"/></inertial></link>')
    for j in joints:
        out.append(f'<joint name="{j["name"]}" type="{j["type"]}"><parent link="{j["parent"]}"/>'
                   f'<child link="{j["child"]}"/><origin xyz="{v(j["xyz"])}" rpy="{v(j["rpy"])}"/>'
                   f'<axis xyz="{v(j["axis"])}"/><limit lower="-3" upper="3" effort="100" velocity="3"/></joint>')
    out.append("</robot>")
    return "\n".join(out)


def tree_reading(links, joints, inertial) -> Tuple[bool, Optional[List[str]]]:
    """This file's own reading: (is it one tree of finite numbers, the movable joints in order when the tree is a
    serial chain of them, else None)."""
    if len(set(links)) != len(links) or len({j["name"] for j in joints}) != len(joints):
        return False, None
    parent_of: Dict[str, dict] = {}
    for j in joints:
        if j["parent"] not in links or j["child"] not in links or j["parent"] == j["child"] or j["child"] in parent_of:
            return False, None
        parent_of[j["child"]] = j
    roots = [l for l in links if l not in parent_of]
    if len(roots) != 1:
        return False, None
    reached, todo = set(), [roots[0]]
    while todo:
        l = todo.pop()
        if l not in reached:
            reached.add(l)
            todo += [j["child"] for j in joints if j["parent"] == l]
    if reached != set(links):
        return False, None
    numbers = [x for j in joints for x in (*j["xyz"], *j["rpy"], *j["axis"])]
    numbers += [x for i in inertial.values() for x in (i["mass"], *i["xyz"], *i["diag"])]
    if not all(math.isfinite(float(x)) for x in numbers):
        return False, None
    # the movable joints, in order, when the links form one chain from the root with each link one child at most
    chain, link = [], roots[0]
    while True:
        below = [j for j in joints if j["parent"] == link]
        if len(below) > 1:
            return True, None
        if not below:
            break
        if below[0]["type"] != "fixed":
            if not any(below[0]["axis"]):
                return True, None  # a zero axis: refused by name, not this reading's to say
            chain.append(below[0]["name"])
        link = below[0]["child"]
    return True, chain or None


@prop
@given(graph=urdf_graphs())
def test_a_urdf_loads_when_it_is_one_chain_and_is_refused_by_name_when_it_is_not_a_tree(tmp_path_factory, graph):
    links, joints, inertial = graph
    path = tmp_path_factory.mktemp("u") / "r.urdf"
    path.write_text(urdf_text(links, joints, inertial))
    tree, chain = tree_reading(links, joints, inertial)
    try:
        robot = didim.Robot.from_urdf(path)
    except didim.DataError as e:
        assert str(e).strip() and "internal error" not in str(e)
        assert chain is None, f"a serial chain of finite numbers was refused: {e}"
        return
    assert tree, "a URDF that is not one tree of finite numbers was read"
    if chain is not None:
        assert list(robot.joint_names) == chain
        assert robot.ndof == len(chain)
        assert np.all(np.isfinite(robot.inertial_params))


# ---------------------------------------------------------------------------------------------------------------------
# A robot record's content
# ---------------------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def pendulum(robots_dir):
    import pandas as pd

    robot = didim.Robot.from_urdf(robots_dir / "pendulum_cad.urdf")
    frame = pd.read_csv(robots_dir / "pendulum_train.csv").iloc[:1500]
    return robot, robots_dir / "pendulum_controller.json", frame


CELLS = st.one_of(st.sampled_from(["nan", "inf", "-inf", "", "abc", "1e400", "0"]), st.floats(-1e6, 1e6).map(repr))


@prop
@given(data=st.data())
def test_a_robot_record_with_any_cells_columns_or_time_loads_or_is_refused_by_name(pendulum, tmp_path_factory, data):
    """A pendulum record (its first 1.5 s) with cells replaced by any text or number, a column dropped, renamed or
    duplicated, the time scaled, shuffled or repeated, or rows cut: a Recording with finite signals whose time is
    uniform, or a DataError; never another exception."""
    robot, ctl, frame = pendulum
    df = frame.copy().astype(object)
    for _ in range(data.draw(st.integers(0, 3))):
        what = data.draw(st.sampled_from(["cell", "drop", "rename", "dup", "time", "cut"]))
        col = data.draw(st.sampled_from(list(df.columns)))
        df = df.astype(object)  # any cell may take text
        if what == "cell" and len(df):
            df.iat[data.draw(st.integers(0, len(df) - 1)), list(df.columns).index(col)] = data.draw(CELLS)
        elif what == "drop" and len(df.columns) > 1:
            df = df.drop(columns=[col])
        elif what == "rename":
            df = df.rename(columns={col: data.draw(st.sampled_from(["qr_3", "qm_joint9", "t[ms]", "x", col + "_"]))})
        elif what == "dup":  # a second column of the same values, under the same name or another
            values = df.iloc[:, list(df.columns).index(col)].to_numpy()
            df.insert(len(df.columns), col if data.draw(st.booleans()) else col + "_2", values, allow_duplicates=True)
        elif what == "time" and "t" in df.columns:
            t = np.array(df["t"], dtype=object)
            how = data.draw(st.sampled_from(["ms", "shuffle", "repeat", "epoch"]))
            if how == "ms":
                df["t"] = [float(x) * 1000 if isinstance(x, float) else x for x in t]
            elif how == "shuffle":
                df["t"] = list(np.random.default_rng(0).permutation(t))
            elif how == "repeat":
                df["t"] = list(t[:1]) * len(t)
            else:
                df["t"] = [float(x) + 1.7e9 if isinstance(x, float) else x for x in t]
        elif what == "cut":
            df = df.iloc[:data.draw(st.integers(0, 40))]
    path = tmp_path_factory.mktemp("rec") / "rec.csv"
    df.to_csv(path, index=False)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", didim.DidimWarning)
            rec = didim.load_record(path, robot=robot, controller=ctl)
    except didim.DataError as e:
        assert str(e).strip() and "internal error" not in str(e)
        return
    assert rec.ndof == robot.ndof
    for name in ("qr", "qm", "force"):
        assert np.all(np.isfinite(getattr(rec, name))), name
    assert rec.dt > 0 and math.isfinite(rec.dt)


# ---------------------------------------------------------------------------------------------------------------------
# Saved robot results
# ---------------------------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def saved_robot_result(pendulum, tmp_path_factory):
    robot, ctl, frame = pendulum
    path = tmp_path_factory.mktemp("res") / "rec.csv"
    frame.to_csv(path, index=False)
    rec = didim.load_record(path, robot=robot, controller=ctl)
    res = didim.identify(rec, didim.Model(robot=robot, offset=True), "idim-ls")
    out = tmp_path_factory.mktemp("res") / "r.json"
    res.save(out)
    return json.loads(out.read_text()), res


JSON_VALUES = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=False),
                                     st.text(max_size=5)),
                           lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                   st.dictionaries(st.text(max_size=5), inner, max_size=3)),
                           max_leaves=6)


def _paths(d, prefix=()):
    """Every (path, value) of a JSON document."""
    yield prefix, d
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d[:4]):
            yield from _paths(v, prefix + (i,))


@prop
@given(data=st.data())
def test_a_saved_robot_result_with_any_field_changed_loads_or_is_refused_by_name(saved_robot_result, tmp_path_factory,
                                                                                 data):
    """Any field of a saved robot result (parameters, base map, model, law, URDF text, history) replaced by any JSON
    value or removed: the result loads, with finite parameters its robot takes, or a DataError names the problem."""
    original, res = saved_robot_result
    d = json.loads(json.dumps(original))
    paths = [p for p, _ in _paths(d) if p]
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(paths))
        node = d
        try:
            for k in path[:-1]:
                node = node[k]
            if data.draw(st.booleans()) and isinstance(node, dict):
                node.pop(path[-1], None)
            else:
                node[path[-1]] = data.draw(JSON_VALUES)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier change removed or replaced the path
    path = tmp_path_factory.mktemp("r") / "r.json"
    path.write_text(json.dumps(d))
    try:
        r = didim.load_result(path)
    except didim.DataError as e:
        assert str(e).strip() and "internal error" not in str(e)
        return
    assert isinstance(r, didim.IdentificationResult)
    if r.robot is not None:
        assert all(isinstance(v, float) and math.isfinite(v) for v in r.params.values())
